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
        intensity,
        color: [1.0, 1.0, 1.0],
    }
}
