//! Per-texel weighted least squares of K against the basis terms of (u, v), with diagnostics.
//!
//! Distant lights: every texel shares the design matrix A (lights × terms). It is factored once,
//! in f64, by SVD of W½A (W = light weights); singular values below `rcond · σ_max` are dropped
//! (minimum-norm solution) or, with `regularize`, a ridge term is added. Two ways apply it:
//! - [`fit_stack`] (a stored stack): C = P·K with P = pinv(W½A)·W½ in f32, one blocked product
//!   over all texels, parallel over texel blocks, fused with the residual pass while the block
//!   is in cache;
//! - [`Accumulator`] (streaming, during a bake): per texel g = AᵀW·k and s = kᵀW·k are
//!   accumulated light by light in f64 (memory O(texels × terms)); `finish` solves
//!   c = S·g with S = V·diag(1/σ²)·Vᵀ over the kept singular values, which equals pinv(W½A)·W½·k.
//!
//! Per-texel light directions (finite-distance lights) accumulate each texel's own normal
//! matrix AᵀWA in f64 and solve it by a symmetric eigendecomposition with the same cutoff.
//!
//! Every result is computed without clamping; evaluation clamps K to [0, 1].
//!
//! Layout: `options` (what a fit is asked for and what it reports), `factor` (the f64
//! factorisation of the shared design and the light-set diagnostics), `accumulator` (the
//! streaming [`Accumulator`]: checks and routes each light's samples), `normal` (the identity
//! link's per-texel sums and their solve), `refit` (stored stacks, texels with dropped
//! samples), `kernel` (the packing and every SIMD kernel of the identity link). The logistic
//! link's fit of an image is `crate::logistic`'s; both links' paths start from `factor`.
mod accumulator;
pub(crate) mod factor;
mod kernel;
mod normal;
pub(crate) mod options;
mod refit;

pub use accumulator::Accumulator;
pub use factor::describe_direction;
pub use options::{
    holdout_indices, ErrorStats, FitOptions, FitReport, LearnedStats, LogisticStats, Weight,
    COND_WARN, DEFAULT_RCOND,
};
pub use refit::fit_stack;
