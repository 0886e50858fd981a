//! The learning problem on the subsample and its design rows, shared by the alternation
//! (`learn.rs`) and the gauge (`gauge.rs`).

/// The learning problem on the subsample.
pub(super) struct Problem {
    /// Terms k.
    pub(super) k: usize,
    /// Texels S.
    pub(super) s: usize,
    /// Fitting lights N.
    pub(super) n: usize,
    /// K `[texel][light]`, < 0 where a sample is missing.
    pub(super) kv: Vec<f32>,
    /// Per fitting light its weight ω.
    pub(super) omega: Vec<f64>,
    /// Per fitting light its four grid cells and weights.
    pub(super) cells: Vec<[(usize, f64); 4]>,
    /// Per-texel ridge ρ (absolute).
    pub(super) rho: f64,
    /// Roughness weight μ = λ·S/d₀ (`learned.rs`).
    pub(super) mu: f64,
    /// Σ ω over the samples present (the deviance's normaliser).
    pub(super) weight_sum: f64,
}

/// Design rows a_n = Σ w·b[cell] (N × k) of the table `b` (`[cell][term]`).
pub(super) fn rows(p: &Problem, b: &[f64]) -> Vec<f64> {
    let k = p.k;
    let mut a = vec![0f64; p.n * k];
    for (n, cs) in p.cells.iter().enumerate() {
        for &(c, w) in cs {
            for j in 0..k {
                a[n * k + j] += w * b[c * k + j];
            }
        }
    }
    a
}
