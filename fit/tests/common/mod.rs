//! Helpers shared by the fit crate's integration tests: the seeded generator, a Fibonacci dome,
//! and a fully covered distant-light stack from its K planes.
#![allow(dead_code, unused_imports)] // each test crate uses a part (tests/ of the binary too)
use ptm_fit::SampleStack;
use ptm_format::LightSet;

/// Deterministic uniform numbers (the workspace's splitmix64 stream).
pub use ptm_format::hash::SplitMix as Rng;

/// Fibonacci hemisphere, elevations above `min_el` degrees.
pub fn fibonacci(n: usize, min_el: f64) -> LightSet {
    let zmin = min_el.to_radians().sin();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    LightSet::from_dirs((0..n).map(|i| {
        let z = zmin + (1.0 - zmin) * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        [r * a.cos(), r * a.sin(), z]
    }))
}

/// A w × h stack of distant lights, every texel fully covered, tile 1 × 1.
pub fn stack(lights: &LightSet, w: usize, h: usize, k: Vec<Vec<f32>>) -> SampleStack {
    SampleStack::new(lights.clone(), w, h, [1.0, 1.0], k)
}
