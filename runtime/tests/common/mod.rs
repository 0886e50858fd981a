//! Shared helpers of the runtime tests: deterministic in-memory PTMs, casters and the GPU.
#![allow(dead_code)]

use ptm_format::{Basis, Ptm};
use ptm_runtime::{Caster, Gpu, Light};

pub use ptm_format::hash::splitmix64 as hash;

/// Uniform in [lo, hi) from a key.
pub fn rand(key: u64, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * ((hash(key) >> 40) as f32 / (1u64 << 24) as f32)
}

/// A PTM with smooth-ish random coefficients whose K leaves [0, 1] in places (tests clamping).
pub fn random_ptm(basis: Basis, width: usize, height: usize, seed: u64) -> Ptm {
    let n = basis.len();
    let planes = (0..n)
        .map(|k| {
            (0..width * height)
                .map(|t| {
                    let key = seed * 1_000_003 + (k * 65_537 + t) as u64;
                    if basis.monomials()[k].pu + basis.monomials()[k].pv == 0 {
                        rand(key, -0.2, 0.9)
                    } else {
                        rand(key, -0.8, 0.8)
                    }
                })
                .collect()
        })
        .collect();
    Ptm {
        basis,
        width,
        height,
        link: ptm_format::Link::Identity,
        uv: ptm_format::UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
    }
}

/// The GPU, or a loud failure: these tests must not pass silently without an adapter.
pub fn gpu() -> Gpu {
    match Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            panic!("GPU tests need a wgpu adapter (lavapipe in CI): {e}. Run scripts/setup.sh.")
        }
    }
}

pub fn light(position: [f32; 3], radius: f32, intensity: f32) -> Light {
    Light {
        position,
        radius,
        intensity,
        color: [1.0, 1.0, 1.0],
    }
}

/// A w×h caster of random 8-bit RGBA with some fully transparent and opaque blobs.
pub fn random_caster(w: usize, h: usize, rect: [f32; 4], elevation: f32, seed: u64) -> Caster {
    let rgba = (0..w * h)
        .map(|t| {
            let r = hash(seed ^ (t as u64 * 0x1234_5677));
            let (i, j) = ((t % w) as f32 / w as f32, (t / w) as f32 / h as f32);
            let blob = ((i * 6.0).sin() * (j * 5.0).cos() * 2.0).clamp(0.0, 1.0);
            let a = (blob * 255.0) as u8 | ((r & 0x3F) as u8);
            [(r >> 8) as u8, (r >> 16) as u8, (r >> 24) as u8, a]
        })
        .collect();
    Caster {
        width: w,
        height: h,
        rgba,
        rect,
        elevation,
        tilt_deg: 0.0,
    }
}

/// `random_ptm` with a hole: coverage 0 (and coefficients 0, as the fit writes holes) on the
/// texels of columns 4..8, rows 3..6, ½ on the ring of texels around it, 1 elsewhere. The PTM
/// must be at least 10×8 texels.
pub fn holed_ptm(basis: Basis, width: usize, height: usize, seed: u64) -> Ptm {
    let mut ptm = random_ptm(basis, width, height, seed);
    let mut coverage = vec![1.0f32; width * height];
    for (t, c) in coverage.iter_mut().enumerate() {
        let (x, y) = (t % width, t / width);
        if (4..8).contains(&x) && (3..6).contains(&y) {
            *c = 0.0;
            for p in &mut ptm.planes {
                p[t] = 0.0;
            }
        } else if (3..9).contains(&x) && (2..7).contains(&y) {
            *c = 0.5;
        }
    }
    ptm.coverage = Some(coverage);
    ptm
}
