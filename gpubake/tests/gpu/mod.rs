//! What the GPU bake's tests share: the adapter they bake on (lavapipe's software ray queries
//! in CI), found loudly or not at all.
#![allow(dead_code)] // each test crate uses a part
use ptm_bake::{BakeConfig, BakeReport, Planes, PreparedMesh};
use ptm_format::LightSet;
use ptm_gpubake::{Asked, GpuConfig};

/// The adapter `--device gpu` picks. Without one the test fails saying why: CI installs Mesa 25
/// (lavapipe with VK_KHR_ray_query) in scripts/setup.sh.
pub fn adapter() -> wgpu::Adapter {
    match ptm_gpubake::choose(Asked::Gpu) {
        Ok(c) => c.adapter.expect("a GPU choice has an adapter"),
        Err(e) => panic!(
            "GPU bake tests need an adapter with ray queries (Mesa >= 25 lavapipe: run \
             scripts/setup.sh): {e}"
        ),
    }
}

/// The GPU bake of `s`, as the shared analytic cases take a bake.
pub fn gpu(s: &PreparedMesh, l: &LightSet, c: &BakeConfig) -> (Planes, Vec<f32>, BakeReport) {
    ptm_gpubake::bake_planes(&adapter(), s, l, c, &GpuConfig::default()).unwrap()
}

/// The Embree bake of `s`.
pub fn cpu(s: &PreparedMesh, l: &LightSet, c: &BakeConfig) -> (Planes, Vec<f32>, BakeReport) {
    ptm_bake::bake_planes(s, l, c).unwrap()
}

/// Every K of `p` as bits, for exact comparisons.
pub fn bits(p: &Planes) -> Vec<u32> {
    p.k.iter().flatten().map(|k| k.to_bits()).collect()
}
