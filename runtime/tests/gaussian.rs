//! Gaussian lights: the penumbra kernel of a light whose intensity falls off as a Gaussian of
//! standard deviations (σx, σy) is that Gaussian scaled onto the caster plane. The summed-area
//! table applies it at constant cost as a product of two sums of three boxes; the explicit grid
//! exactly. Both are judged against Monte Carlo references that draw points from the true
//! Gaussian light; and the extremes: σ → 0 tends to the hard shadow, σ ≤ 0 is refused.

mod common;

use common::*;
use ptm_runtime::compare::mean_abs_diff;
use ptm_runtime::reference::render_reference;
use ptm_runtime::synthetic::leaves;
use ptm_runtime::{cpu, Blur, Scene};

/// Standard deviations of the lights tried, for a light 3 above the cloth: round, 4:1 along X,
/// 1:5 along Y.
const SIGMAS: [[f32; 2]; 3] = [[0.4, 0.4], [0.6, 0.15], [0.08, 0.4]];

/// A 48² view of plain cloth under a leafy caster 0.4 above it and one Gaussian light of
/// standard deviations `sigma` 3 above the cloth, off to one side of the view's centre.
fn scene(sigma: [f32; 2], blur: Blur) -> Scene {
    let lz = 3.0f32;
    let mut l = light([0.3, -0.2, lz], 0.0, lz * lz);
    l.gaussian = Some(sigma);
    Scene {
        size: [48, 48],
        view: [-1.0, -1.0, 1.0, 1.0],
        ptm: None,
        albedo: [1.0; 3],
        albedo_texture: None,
        lights: vec![l],
        caster: Some(leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4)),
        colored_shadow: false,
        blur,
        perspective: None,
        glossy: None,
    }
}

/// Mean radiance of the unshadowed image (the lit radiance errors are measured against).
fn lit(s: &Scene) -> f32 {
    let mut open = s.clone();
    open.caster = None;
    let img = cpu::render(&open.prepare().unwrap());
    let sum: f64 = img.pixels.iter().map(|p| p[0] as f64).sum();
    (sum / img.pixels.len() as f64) as f32
}

#[test]
fn gaussian_kernel_is_within_a_percent_of_the_lit_radiance_of_monte_carlo() {
    // Per light, against a 16384-sample reference drawn from the Gaussian (its own noise shown
    // by a 1024-sample one): the SAT's three-box product and the explicit grid must err by at
    // most 1 % of the lit radiance on the mean, and the SAT must beat the box of the same
    // variance (what a box-only runtime would draw: half-sides √3·σ), which shows the kernel's
    // shape matters here. MIP (the ellipse of the same variance) and separable (the box of the
    // same variance) are printed.
    for sigma in SIGMAS {
        let s = scene(sigma, Blur::Sat);
        let p = s.prepare().unwrap();
        let fine = render_reference(&p, 16384);
        let noise = mean_abs_diff(&render_reference(&p, 1024), &fine);
        let lit = lit(&s);
        let mut boxed = s.clone();
        boxed.lights[0].gaussian = None;
        boxed.lights[0].rect = Some(sigma.map(|x| 2.0 * 3f32.sqrt() * x));
        let same_variance_box = mean_abs_diff(&cpu::render(&boxed.prepare().unwrap()), &fine);
        for blur in Blur::ALL {
            let mut e = s.clone();
            e.blur = blur;
            let err = mean_abs_diff(&cpu::render(&e.prepare().unwrap()), &fine);
            eprintln!(
                "σ {sigma:?}, {}: {err:.2e} ({:.3} % of lit), box of the same variance (SAT) \
                 {same_variance_box:.2e} ({:.3} %), reference noise (1024) {noise:.2e}, lit \
                 {lit:.3}",
                blur.name(),
                100.0 * err / lit,
                100.0 * same_variance_box / lit,
            );
            if matches!(blur, Blur::Sat | Blur::Explicit) {
                assert!(
                    err <= 0.01 * lit,
                    "σ {sigma:?}, {}: mean error {err} > 1 % of lit {lit}",
                    blur.name()
                );
            }
            if blur == Blur::Sat {
                assert!(
                    err < same_variance_box,
                    "σ {sigma:?}: three boxes {err} do no better than one {same_variance_box}"
                );
            }
        }
    }
}

#[test]
fn a_vanishing_gaussian_tends_to_the_hard_shadow_and_a_huge_one_to_the_mean() {
    // σ = 1e-5 on the light is far below a caster texel: the kernel is the texel under the ray,
    // as a point light's hard shadow (the reference's rays to a point, all the same); σ = 1e-3
    // is still within a hundredth of it.
    let mut point = scene([1.0, 1.0], Blur::Sat);
    point.lights[0].gaussian = None;
    let hard = render_reference(&point.prepare().unwrap(), 1);
    let lit = lit(&point);
    let mut last = f32::INFINITY;
    for sigma in [1e-3f32, 1e-4, 1e-5] {
        for blur in [Blur::Sat, Blur::Explicit] {
            let s = scene([sigma, sigma], blur);
            let d = mean_abs_diff(&cpu::render(&s.prepare().unwrap()), &hard);
            eprintln!("σ {sigma:e}, {}: {d:.2e} from the hard shadow", blur.name());
            assert!(d <= 0.01 * lit, "σ {sigma}, {}: {d}", blur.name());
            if blur == Blur::Sat {
                assert!(d <= last + 1e-6, "σ {sigma}: {d} not shrinking ({last})");
                last = d;
            }
        }
    }
    assert!(last <= 1e-3 * lit, "σ 1e-5: {last}");
    // σ 1000 times the caster: every pixel sees nearly nothing of it.
    let huge = scene([1600.0, 1600.0], Blur::Sat);
    let img = cpu::render(&huge.prepare().unwrap());
    let mut open = huge.clone();
    open.caster = None;
    let open = cpu::render(&open.prepare().unwrap());
    for (a, b) in img.pixels.iter().zip(&open.pixels) {
        assert!(
            a[0].is_finite() && a[0] <= b[0] && a[0] > 0.99 * b[0],
            "{a:?} vs {b:?}"
        );
    }
}

#[test]
fn zero_negative_or_non_finite_sigmas_are_refused() {
    for sigma in [
        [0.0, 0.1],
        [0.1, -0.2],
        [f32::NAN, 0.1],
        [0.1, f32::INFINITY],
    ] {
        let s = scene(sigma, Blur::Sat);
        let e = s.prepare().unwrap_err().to_string();
        assert!(
            e.contains("Gaussian") && e.contains("> 0"),
            "{sigma:?}: {e}"
        );
    }
    let mut s = scene([0.1, 0.1], Blur::Sat);
    s.lights[0].rect = Some([0.2, 0.2]);
    let e = s.prepare().unwrap_err().to_string();
    assert!(e.contains("both a rectangle and a Gaussian"), "{e}");
}

#[test]
fn only_a_scene_with_a_gaussian_light_compiles_its_code() {
    for blur in Blur::ALL {
        let mut s = scene([0.2, 0.2], blur);
        let with = ptm_runtime::shader::shade_source(&s.prepare().unwrap().variant).unwrap();
        assert!(with.contains("KERNEL_GAUSS"), "{}", blur.name());
        s.lights[0].gaussian = None;
        s.lights[0].radius = 0.2;
        let without = ptm_runtime::shader::shade_source(&s.prepare().unwrap().variant).unwrap();
        assert!(!without.contains("KERNEL_GAUSS"), "{}", blur.name());
        assert!(!without.contains("shape == 3u"), "{}", blur.name());
    }
}
