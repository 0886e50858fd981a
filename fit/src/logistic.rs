//! Maximum-likelihood fit of the logistic link K = σ(p(u, v)) per texel.
//!
//! K is the fraction of a texel's covered footprint samples that are occluded, so each light's
//! value is a binomial proportion. Per texel the fit minimises the binomial deviance (the
//! cross-entropy of σ(p) against K, weighted per light as the identity fit is) plus a ridge:
//!
//!   J(c) = Σₙ ωₙ·[−kₙ·ln σ(zₙ) − (1 − kₙ)·ln(1 − σ(zₙ))] + ½·ρ·|c|²,   zₙ = aₙ·c,
//!
//! with ρ = λ·tr(AᵀΩA)/M (λ relative to the mean eigenvalue, as the identity ridge). The
//! number of samples per texel scales J uniformly, so it does not move the optimum: fractions
//! from a stored stack and exact counts from a streaming bake fit the same. Newton (IRLS) per
//! texel: ∇J = Σ ωₙ(σₙ − kₙ)·aₙ + ρc, H = Σ ωₙσₙ(1 − σₙ)·aₙaₙᵀ + ρI. H's packed entries are
//! the per-texel weights times the distinct products mᵢmⱼ of the basis ([`ptm_format::basis::products`]):
//! a [texels × lights] · [lights × products] matrix product, done tile by tile in registers.
//!
//! Texels whose samples a polynomial boundary separates exactly (always lit, always occluded,
//! a clean step) have their unregularised optimum at infinity; the ridge keeps it finite, and
//! they are counted (`separable`, `constant`). The warm start is the least-squares fit of the
//! clamped logits with the shared pseudo-inverse of the identity fit (one more product).
//!
//! The kernel is generic over the basis size, the product count and the tile width; it is
//! compiled three times — portable (8 lanes), AVX2 + FMA (8) and AVX-512F (16) — and picked at
//! run time ([`crate::simd::Isa`]). All three run the same arithmetic in the same order; they
//! differ only in FMA contraction and width.
//!
//! Layout, along the fit's seams: `tables` (what one design shares: rows, products, warm-start
//! operator, ridge), `newton` (one tile of lanes: warm start, Newton steps, final pass),
//! `block` (a block of texels with its lanes compacted as they converge, and a level's blocks
//! in parallel), `pool` (where K comes from, and the pooling of MIP levels), `counts` (the
//! streaming fit's exact sample counts), `image` (one image's fit and its MIP levels: the
//! PTM and its report).

mod block;
pub(crate) mod counts;
pub(crate) mod image;
mod newton;
pub(crate) mod pool;
pub(crate) mod tables;

/// Default ridge λ of the logistic fit (relative to the mean eigenvalue of AᵀΩA).
pub const DEFAULT_RIDGE: f64 = 1e-5;
/// Default stopping tolerance: a texel stops when its Newton decrement (the objective's
/// predicted fall) is at most this per unit of light weight, or its step is below 1e-6. Newton
/// converges quadratically, so the step that meets it leaves far less: on the plain weave,
/// 1e-5 … 1e-10 give the same held-out error to five digits and K within 3e-6 of an f64 solve
/// (tests/logistic.rs); 1e-7 saves 0.6 iterations per texel against 1e-10.
pub const DEFAULT_TOLERANCE: f64 = 1e-7;
/// Default cap on Newton iterations per texel (texels that hit it are counted).
pub const DEFAULT_MAX_ITERATIONS: u32 = 30;

/// Constant coefficient of a texel with no covered sample (a hole in the cloth): σ(−30) ≈ 1e-13,
/// so a hole reads as K = 0, "lit", as zero coefficients do under the identity link.
pub const HOLE_LOGIT: f32 = -30.0;
