//! A light basis learned per swatch ([`Basis::Learned`]): K(x, l) = σ(Σₖ cₖ(x)·Bₖ(u, v)), the
//! k functions Bₖ shared by the whole swatch, each a G × G table over the hemispherical (u, v)
//! square read bilinearly ([`ptm_format::LearnedTable`]), the k coefficients per texel as a PTM stores them
//! (logistic PCA; Collins, Dasgupta and Schapire, NIPS 2001).
//!
//! Learning (on a deterministic subsample of at most [`MAX_SUBSAMPLE`] covered texels, chosen
//! by the workspace hash of their index, so the same input gives the same subsample on any
//! machine and thread count) minimises the binomial deviance of the logistic fit plus a
//! roughness penalty on the tables,
//!
//!   J(b, c) = Σₓ Σₙ ωₙ·dev(kₓₙ, cₓ·B(lₙ)) + ½·ρ·Σₓ|cₓ|² + ½·μ·‖(D ⊗ I) b‖²,   μ = λ·S/d₀,
//!
//! D the second differences along both grid axes, S the subsample's texel count, λ =
//! [`ROUGHNESS`], d₀ the polynomial start's mean deviance per fitted sample (at least
//! [`MIN_DEVIANCE`]): smooth *while* fitting, and the smoother the less the polynomial leaves
//! unexplained (a swatch it already fits well, as corduroy, has little to learn and most to
//! overfit between the lights; docs/model.md). It starts from the polynomial basis
//! of the same size (ptm6 for 6 terms, ptm11 for 11) sampled on the grid, so iteration 0 is the
//! logistic polynomial fit, and alternates damped Newton steps: one on the tables for fixed
//! coefficients (z is linear in b, so this Newton step is exact: the Hessian is
//! Σₙ (wₙwₙᵀ) ⊗ Mₙ + μ·DᵀD ⊗ I, Mₙ = Σₓ ωₙσ(1−σ)cₓcₓᵀ, wₙ the 4 bilinear weights of light n,
//! block-banded with half-bandwidth 2G cells, solved by a banded Cholesky), then one per texel
//! on the coefficients. From the second alternation on, the step since the previous
//! alternation is extrapolated β = [`EXTRAPOLATION`] times further and kept when that lowers J
//! (β then grows, else resets; Bro's line search for alternating least squares): jersey
//! converges in 14 alternations instead of 32. It stops when J falls by less than
//! [`STOP`] of itself in an alternation (or after [`MAX_ALTERNATIONS`]).
//!
//! The gauge: the basis is defined up to an invertible k × k transform (B → B·A, c → A⁻¹c).
//! It is fixed so that the terms are orthonormal over the fitting lights (Σₙ ωₙ B(lₙ)B(lₙ)ᵀ =
//! Σₙ ωₙ · I), ordered by decreasing variance of the subsample's coefficients (the
//! eigenvectors of their second moments), each signed so its mean over the fitting lights is
//! positive. Then every texel (and every MIP level) is fitted against the learned tables with
//! the logistic kernel ([`crate::logistic`]), as a polynomial basis is.
//!
//! Files: this one (constants, what a fit needs of the options and the dome), `learn.rs` (the
//! subsample, the alternation, early stopping on held-out lights, the kernel's tables),
//! `gauge.rs` (the gauge), `problem.rs` (the problem and its design rows), `band.rs` (the banded Cholesky solve of the table step), `rough.rs` (the roughness).
pub(crate) mod band;
pub(crate) mod gauge;
pub(crate) mod learn;
pub(crate) mod problem;
pub(crate) mod rough;

pub use learn::subsample_order;

use crate::solve::options::FitOptions;
use crate::{Error, Result};
use ptm_format::{Basis, Link, UvMap};

/// Grid side G of the learned tables.
pub const GRID: usize = 17;
/// Roughness λ of the tables: the penalty is λ·S/d₀·‖D b‖², S texels, d₀ the polynomial
/// start's mean deviance per fitted sample (at least [`MIN_DEVIANCE`]).
pub const ROUGHNESS: f64 = 0.1;
/// Floor of d₀ in the roughness weight.
pub const MIN_DEVIANCE: f64 = 1e-3;
/// Extrapolation β of an alternation's step (tried from the second alternation, kept when it
/// lowers J), grown by [`EXTRAPOLATION_GROWTH`] up to [`EXTRAPOLATION_MAX`] while kept.
pub const EXTRAPOLATION: f64 = 1.0;
/// Growth of β after a kept extrapolation.
pub const EXTRAPOLATION_GROWTH: f64 = 1.5;
/// Largest β.
pub const EXTRAPOLATION_MAX: f64 = 4.0;
/// Most texels the basis is learned on.
pub const MAX_SUBSAMPLE: usize = 4096;
/// Most alternations of the learning.
pub const MAX_ALTERNATIONS: u32 = 40;
/// The learning stops when an alternation lowers J by less than this fraction of J.
pub const STOP: f64 = 2e-4;
/// Fitting lights a learned basis needs per term.
pub const LIGHTS_PER_TERM: usize = 4;
/// Numbers of terms the fitter learns (the logistic kernel's builds).
pub const FIT_TERMS: [usize; 2] = [6, 11];

/// The polynomial basis a learned one of `terms` terms starts from.
pub fn start_basis(terms: usize) -> Option<Basis> {
    match terms {
        6 => Some(Basis::Ptm6),
        11 => Some(Basis::Ptm11),
        _ => None,
    }
}

/// Checks that `opts` can learn its basis over `lights` (weights `w`, 0 = not fitted): the
/// link, the map, a supported number of terms, and a dome of at least
/// [`LIGHTS_PER_TERM`]·k fitting lights. Returns the options of the start basis.
pub(crate) fn check(opts: &FitOptions, w: &[f64]) -> Result<FitOptions> {
    let k = opts.basis.len();
    if opts.link != Link::Logistic || opts.uv != UvMap::Hemispherical {
        return Err(Error::Invalid(format!(
            "a learned basis ({}) is fitted with the logistic link over the hemispherical (u, v) \
             map, not the {} link over the {} map",
            opts.basis.name(),
            opts.link.name(),
            opts.uv.name()
        )));
    }
    let Some(start) = start_basis(k) else {
        return Err(Error::Invalid(format!(
            "{}: this version learns bases of {} terms (learned6, learned11); a file of any \
             term count 1..=16 is read and evaluated",
            opts.basis.name(),
            FIT_TERMS.map(|t| t.to_string()).join(" or ")
        )));
    };
    let nfit = w.iter().filter(|&&x| x > 0.0).count();
    let need = LIGHTS_PER_TERM * k;
    if nfit < need {
        return Err(Error::Invalid(format!(
            "a learned basis of {k} terms needs at least {need} fitting lights ({LIGHTS_PER_TERM} \
             per term, so that the dome pins the learned functions instead of their interpolating \
             it); this light set has {nfit} above the horizon and not held out: bake at least \
             {need} lights, or fit fewer terms or a polynomial basis"
        )));
    }
    Ok(FitOptions {
        basis: start,
        ..opts.clone()
    })
}
