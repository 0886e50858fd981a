//! The shared tables of one logistic fit: per light its design row, the distinct products of
//! its terms (the Hessian's entries), its weight and its row of the warm start operator; and
//! the absolute ridge. One design serves level 0 and every MIP level of a fit.
use ptm_format::basis::products;
use ptm_format::{Basis, LightSet};

use crate::simd::Isa;
use crate::solve::factor::SharedDesign;
use crate::solve::options::FitOptions;
use crate::{Error, Result};

/// Shared tables of one fit (one design: distant lights, one MIP level or all).
pub(crate) struct Tables {
    pub m: usize,
    /// Fitting lights (ω > 0, not held out), then held-out lights: indices into the light set.
    pub used: Vec<usize>,
    pub nfit: usize,
    /// Per used light: its design row (M terms at its mapped (u, v)).
    pub a: Vec<f32>,
    /// Per fitting light: the distinct products of its terms (D).
    pub q: Vec<f32>,
    /// Per fitting light: its weight ω.
    pub omega: Vec<f32>,
    /// Per fitting light: its row of the identity fit's operator P (c₀ = Σₙ Pₙ·logit kₙ).
    pub warm: Vec<f32>,
    /// Packed upper-triangle entry (i ≤ j, row-major) → index of its product.
    pub pair: Vec<usize>,
    /// Absolute ridge ρ.
    pub ridge: f64,
    pub tolerance: f64,
    pub max_iterations: u32,
    /// Σ ω over the fitting lights.
    pub omega_sum: f64,
    /// Coefficients written for a texel with no covered sample: [`super::HOLE_LOGIT`] on the
    /// constant term of a polynomial basis; for a learned basis the least-squares coefficients
    /// of that constant logit over the fitting lights.
    pub hole: [f32; 16],
    /// Entries of the packed Hessian the kernel sums per light (`q`'s row length).
    pub d: usize,
}

impl Tables {
    /// From the design rows of every light (`a`: lights × M, f64), weights, held-out lights and
    /// the identity operator rows `p` (lights × M).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        basis: Basis,
        design: &[Vec<f64>],
        w: &[f64],
        held: &[usize],
        p: &[Vec<f64>],
        lambda: f64,
        tolerance: f64,
        max_iterations: u32,
    ) -> Tables {
        let m = basis.len();
        let (prods, pair) = products(basis);
        let d = prods.len();
        let (fit, used, a) = rows(design, w, held, m);
        // Products from the (u, v) of each light: the same monomials, exponents added.
        let monos = basis.monomials();
        let mut q = Vec::with_capacity(fit.len() * d);
        for &l in &fit {
            // Recover (u, v) from the linear terms' values: every basis has u and v.
            let ju = monos.iter().position(|x| (x.pu, x.pv) == (1, 0)).unwrap();
            let jv = monos.iter().position(|x| (x.pu, x.pv) == (0, 1)).unwrap();
            let (u, v) = (design[l][ju], design[l][jv]);
            q.extend(
                prods
                    .iter()
                    .map(|&(pu, pv)| (u.powi(pu as i32) * v.powi(pv as i32)) as f32),
            );
        }
        let omega: Vec<f32> = fit.iter().map(|&l| w[l] as f32).collect();
        let omega_sum: f64 = fit.iter().map(|&l| w[l]).sum();
        let mut warm = Vec::with_capacity(fit.len() * m);
        for &l in &fit {
            warm.extend(p[l].iter().map(|&x| x as f32));
        }
        // Mean eigenvalue of AᵀΩA: trace / M.
        let trace: f64 = fit
            .iter()
            .map(|&l| w[l] * design[l].iter().map(|x| x * x).sum::<f64>())
            .sum();
        debug_assert_eq!(q.len(), fit.len() * d);
        let mut hole = [0f32; 16];
        hole[monos.iter().position(|x| (x.pu, x.pv) == (0, 0)).unwrap()] = super::HOLE_LOGIT;
        Tables {
            m,
            nfit: fit.len(),
            used,
            a,
            q,
            omega,
            warm,
            pair,
            ridge: lambda * trace / m as f64,
            tolerance,
            max_iterations,
            omega_sum,
            hole,
            d,
        }
    }

    /// The tables of a learned basis from the design rows of every light (`design`: lights ×
    /// k, the learned terms at each light's (u, v)), weights and held-out lights: the Hessian's
    /// entries are every product aᵢaⱼ (i ≤ j), the warm start the weighted least-squares
    /// operator (AᵀΩA)⁻¹AᵀΩ, a hole's coefficients that operator applied to a constant
    /// [`super::HOLE_LOGIT`].
    pub fn learned(
        design: &[Vec<f64>],
        w: &[f64],
        held: &[usize],
        lambda: f64,
        tolerance: f64,
        max_iterations: u32,
    ) -> Tables {
        let m = design.first().map_or(0, Vec::len);
        let d = m * (m + 1) / 2;
        let (fit, used, a) = rows(design, w, held, m);
        let mut q = Vec::with_capacity(fit.len() * d);
        for &l in &fit {
            for i in 0..m {
                for j in i..m {
                    q.push((design[l][i] * design[l][j]) as f32);
                }
            }
        }
        let gram = nalgebra::DMatrix::from_fn(m, m, |i, j| {
            fit.iter()
                .map(|&l| w[l] * design[l][i] * design[l][j])
                .sum::<f64>()
        });
        let trace: f64 = (0..m).map(|i| gram[(i, i)]).sum();
        // A tiny ridge keeps the inverse defined on a degenerate learned basis.
        let reg = gram + nalgebra::DMatrix::identity(m, m) * (1e-12 * trace.max(1e-300));
        let inv = reg
            .clone()
            .cholesky()
            .map(|c| c.inverse())
            .or_else(|| reg.pseudo_inverse(1e-12).ok())
            .unwrap_or_else(|| nalgebra::DMatrix::zeros(m, m));
        let mut warm = Vec::with_capacity(fit.len() * m);
        let mut hole64 = vec![0f64; m];
        for &l in &fit {
            for i in 0..m {
                let x: f64 = (0..m).map(|j| inv[(i, j)] * design[l][j]).sum::<f64>() * w[l];
                warm.push(x as f32);
                hole64[i] += x * super::HOLE_LOGIT as f64;
            }
        }
        let mut hole = [0f32; 16];
        for i in 0..m {
            hole[i] = hole64[i] as f32;
        }
        Tables {
            m,
            nfit: fit.len(),
            used,
            a,
            q,
            omega: fit.iter().map(|&l| w[l] as f32).collect(),
            warm,
            pair: (0..d).collect(),
            ridge: lambda * trace / m as f64,
            tolerance,
            max_iterations,
            omega_sum: fit.iter().map(|&l| w[l]).sum(),
            hole,
            d,
        }
    }
}

/// The logistic fit's shared tables, its instruction set and its relative ridge λ, from a
/// shared distant-light design: what every level of a fit (and a farm merge's coarse levels)
/// uses.
pub(crate) fn for_fit(
    prep: &SharedDesign,
    lights: &LightSet,
    opts: &FitOptions,
) -> Result<(Tables, Isa, f64)> {
    let m = opts.basis.len();
    let n = lights.len();
    let isa = opts.isa.unwrap_or_else(Isa::detect);
    if !isa.supported() {
        return Err(Error::Invalid(format!(
            "the {} logistic kernel does not run on this CPU",
            isa.name()
        )));
    }
    if opts.tolerance.is_nan() || opts.tolerance < 0.0 || opts.max_iterations == 0 {
        return Err(Error::Invalid(format!(
            "logistic tolerance {} must be ≥ 0 and the iteration cap {} at least 1",
            opts.tolerance, opts.max_iterations
        )));
    }
    let lambda = opts.regularize.unwrap_or(super::DEFAULT_RIDGE);
    // Warm start operator: the identity fit's P = S·AᵀW, rows per light.
    let f = &prep.factor;
    let rows: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..m).map(|j| prep.a[(i, j)]).collect())
        .collect();
    let p: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..m)
                .map(|j| {
                    let x: f64 = (0..m).map(|q| f.s[(j, q)] * prep.a[(i, q)]).sum();
                    x * prep.w[i]
                })
                .collect()
        })
        .collect();
    let tables = Tables::new(
        opts.basis,
        &rows,
        &prep.w,
        &prep.held,
        &p,
        lambda,
        opts.tolerance,
        opts.max_iterations,
    );
    Ok((tables, isa, lambda))
}

/// The lights a design fits (weight > 0, not held out), those followed by the held-out ones
/// (the lights every texel's K is read for), and the design rows of the latter in f32
/// (`used` × `m`).
fn rows(
    design: &[Vec<f64>],
    w: &[f64],
    held: &[usize],
    m: usize,
) -> (Vec<usize>, Vec<usize>, Vec<f32>) {
    let fit: Vec<usize> = (0..w.len())
        .filter(|&i| w[i] > 0.0 && !held.contains(&i))
        .collect();
    let used: Vec<usize> = fit.iter().chain(held).copied().collect();
    let mut a = Vec::with_capacity(used.len() * m);
    for &l in &used {
        a.extend(design[l].iter().map(|&x| x as f32));
    }
    (fit, used, a)
}
