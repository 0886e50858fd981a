//! Shared helpers of the runtime tests: the GPU (or a loud failure) and a light; the synthetic
//! PTMs and casters are `ptm_runtime::synthetic`'s, shared with the benchmark and the report.
#![allow(dead_code, unused_imports)] // each test file uses a part

use ptm_runtime::{Gpu, Light};

pub use ptm_format::hash::splitmix64 as hash;
pub use ptm_runtime::synthetic::{holed_ptm, random_caster, random_ptm};

/// The GPU, or a loud failure: these tests must not pass silently without an adapter.
pub fn gpu() -> Gpu {
    match Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            panic!("GPU tests need a wgpu adapter (lavapipe in CI): {e}. Run scripts/setup.sh.")
        }
    }
}

/// A white spherical light of `radius` at `position` with `intensity`.
pub fn light(position: [f32; 3], radius: f32, intensity: f32) -> Light {
    Light {
        position,
        radius,
        rect: None,
        square_box: false,
        rect_angle_deg: 0.0,
        gaussian: None,
        distant: false,
        intensity,
        color: [1.0, 1.0, 1.0],
    }
}

/// K of a synthetic cloth: texel (x, y) of `n`² sees the sky above a horizon of elevation
/// 0.3 + 0.25·cos(φ − 2πx/n) + 0.1·y/n rad with a soft edge, as a bake of `spp` = 8 samples
/// counts it (multiples of 1/8).
pub fn synthetic_k(n: usize, l: [f64; 3]) -> Vec<f32> {
    let (el, az) = (l[2].asin(), l[1].atan2(l[0]));
    (0..n * n)
        .map(|t| {
            let (x, y) = ((t % n) as f64 / n as f64, (t / n) as f64 / n as f64);
            let horizon = 0.3 + 0.25 * (az - std::f64::consts::TAU * x).cos() + 0.1 * y;
            let k = ((horizon - el) / 0.2 + 0.5).clamp(0.0, 1.0);
            ((k * 8.0).round() / 8.0) as f32
        })
        .collect()
}

/// A PTM of `basis`, `link` and `map` fitted by ptm-fit from [`synthetic_k`] under a 64-light
/// Fibonacci dome above 8° (with its MIP levels when `mips`).
pub fn fitted(
    basis: ptm_format::Basis,
    link: ptm_format::Link,
    uv: ptm_format::UvMap,
    n: usize,
    mips: bool,
) -> ptm_format::Ptm {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let floor = 8f64.to_radians().sin();
    let lights = ptm_format::LightSet::from_dirs((0..64).map(|i| {
        let z = floor + (1.0 - floor) * (i as f64 + 0.5) / 64.0;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        [r * a.cos(), r * a.sin(), z]
    }));
    let opts = ptm_fit::FitOptions {
        link,
        uv,
        mips,
        ..ptm_fit::FitOptions::new(basis)
    };
    let mut acc = ptm_fit::Accumulator::new(&lights, n, n, &opts).unwrap();
    acc.set_spp(8).unwrap();
    for (i, l) in lights.dirs.iter().enumerate() {
        acc.add_light(i, &synthetic_k(n, *l)).unwrap();
    }
    let (ptm, _) = acc.finish([1.0, 1.0]).unwrap();
    assert_eq!(ptm.basis, basis);
    ptm
}

/// The glossy tests' scene (`tests/glossy.rs`, `tests/environment.rs`): a 48² view of plain
/// cloth under a leafy caster and one spherical light, with a glossy receiver of `roughness`
/// over a blue-grey background or the sky `env`. `perspective`: seen from the front and above
/// (oblique mirror rays, the caster 0.4 up and flat); else from straight above with the caster
/// tilted 40° (its distance from the cloth, and so the blur, grows across the view).
pub fn glossy_scene(
    roughness: f32,
    blur: ptm_runtime::Blur,
    perspective: bool,
    env: Option<std::sync::Arc<ptm_runtime::environment::Environment>>,
) -> ptm_runtime::Scene {
    let mut caster = ptm_runtime::synthetic::leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4);
    if !perspective {
        caster.elevation = 0.8;
        caster.tilt_deg = 40.0;
    }
    ptm_runtime::Scene {
        size: [48, 48],
        view: [-1.0, -1.0, 1.0, 1.0],
        ptm: None,
        albedo: [0.8; 3],
        albedo_texture: None,
        lights: vec![light([0.3, -0.2, 3.0], 0.2, 9.0)],
        caster: Some(caster),
        colored_shadow: false,
        blur,
        perspective: perspective.then_some(ptm_runtime::scene::Perspective {
            eye: [0.0, -2.5, 2.0],
            target: [0.0, 0.0, 0.0],
            fov_y_deg: 50.0,
        }),
        glossy: Some(ptm_runtime::Glossy {
            roughness,
            background: [0.2, 0.3, 0.5],
            f0: 0.3,
            environment: env,
        }),
    }
}

/// Mean |a − b| over every channel of two reflected images.
pub fn mean_abs3(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |k| (x[k] - y[k]).abs() as f64))
        .sum();
    sum / (3 * a.len()) as f64
}

/// Mean over every channel of a reflected image.
pub fn mean3(a: &[[f32; 3]]) -> f64 {
    a.iter()
        .flat_map(|x| x.iter().map(|&v| v as f64))
        .sum::<f64>()
        / (3 * a.len()) as f64
}

/// Three files fitted to the same synthetic bake (8², [`fitted`]): learned6 (logistic,
/// hemispherical), logistic ptm11 (hemispherical) and identity ptm6 (projected), named.
pub fn fitted_files() -> Vec<(&'static str, ptm_format::Ptm)> {
    use ptm_format::{Basis, Link, UvMap};
    vec![
        (
            "learned6",
            fitted(
                Basis::Learned(6),
                Link::Logistic,
                UvMap::Hemispherical,
                8,
                false,
            ),
        ),
        (
            "logistic ptm11",
            fitted(Basis::Ptm11, Link::Logistic, UvMap::Hemispherical, 8, false),
        ),
        (
            "identity ptm6",
            fitted(Basis::Ptm6, Link::Identity, UvMap::Projected, 8, false),
        ),
    ]
}
