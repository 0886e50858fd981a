//! The f64 factorisation of a shared (weighted) design matrix or a per-texel normal matrix,
//! and the diagnostics of a light set.
use nalgebra::{DMatrix, SymmetricEigen};

use super::options::{check_strict, holdout_indices, FitOptions, Weight, COND_WARN};
use crate::diagnostic::{Diagnostic, Solution};
use crate::{logistic, Error, Result};
use ptm_format::{Basis, LightSet, Link, UvMap};

pub(super) fn light_weights(
    lights: &LightSet,
    opts: &FitOptions,
) -> Result<(Vec<f64>, Vec<usize>)> {
    if opts.holdout >= lights.len() {
        return Err(Error::HoldoutTooLarge {
            holdout: opts.holdout,
            lights: lights.len(),
        });
    }
    let held = holdout_indices(lights.len(), opts.holdout);
    let mut w: Vec<f64> = lights
        .dirs
        .iter()
        // Lights at or below the horizon are left out: K = 1 there by definition.
        .map(|d| match opts.weight {
            _ if d[2] <= 0.0 => 0.0,
            Weight::Uniform => 1.0,
            Weight::Cosine => d[2],
        })
        .collect();
    for &i in &held {
        w[i] = 0.0;
    }
    Ok((w, held))
}

/// Signed coefficient list of a basis direction, e.g. `u2 + v2 - 0.75*1`.
pub fn describe_direction(basis: Basis, v: &[f64]) -> String {
    let big = v.iter().fold(0.0f64, |a, &x| a.max(x.abs()));
    let lead = v.iter().copied().find(|x| x.abs() == big).unwrap_or(1.0);
    let scale = if lead < 0.0 { -1.0 / big } else { 1.0 / big };
    let mut s = String::new();
    for (x, m) in v.iter().zip(basis.monomials()) {
        let x = x * scale;
        if x.abs() < 1e-3 {
            continue;
        }
        let sign = if x < 0.0 { " - " } else { " + " };
        if s.is_empty() {
            if x < 0.0 {
                s.push('-');
            }
        } else {
            s.push_str(sign);
        }
        if (x.abs() - 1.0).abs() < 5e-4 {
            s.push_str(m.name);
        } else {
            s.push_str(&format!("{:.3}*{}", x.abs(), m.name));
        }
    }
    s
}

/// A factored (weighted) design: right singular vectors and singular values of W½A, and the
/// solve operator S (terms × terms) with c = S · AᵀW·k.
#[derive(Clone, Debug)]
pub(crate) struct Factor {
    pub sigma: Vec<f64>,
    pub v: DMatrix<f64>,
    pub rank: usize,
    pub cutoff: f64,
    pub cond: f64,
    pub s: DMatrix<f64>,
}

impl Factor {
    /// From singular values (descending) and right singular vectors (columns).
    pub(super) fn new(
        sigma: Vec<f64>,
        v: DMatrix<f64>,
        rcond: f64,
        regularize: Option<f64>,
    ) -> Factor {
        let m = sigma.len();
        let smax = sigma.first().copied().unwrap_or(0.0);
        let cutoff = rcond * smax;
        let rank = sigma.iter().filter(|&&s| s > cutoff && s > 0.0).count();
        let smin = sigma.last().copied().unwrap_or(0.0);
        let cond = if smin > 0.0 {
            smax / smin
        } else {
            f64::INFINITY
        };
        let ridge = regularize.map(|l| l * sigma.iter().map(|s| s * s).sum::<f64>() / m as f64);
        let f: Vec<f64> = sigma
            .iter()
            .map(|&s| match ridge {
                Some(l) if s * s + l > 0.0 => 1.0 / (s * s + l),
                Some(_) => 0.0,
                None if s > cutoff && s > 0.0 => 1.0 / (s * s),
                None => 0.0,
            })
            .collect();
        let mut s = DMatrix::zeros(m, m);
        for (k, &fk) in f.iter().enumerate() {
            if fk == 0.0 {
                continue;
            }
            let col = v.column(k);
            s += fk * col * col.transpose();
        }
        Factor {
            sigma,
            v,
            rank,
            cutoff,
            cond,
            s,
        }
    }

    /// From the SVD of W½A (rows padded to at least `terms`, so V is complete).
    pub(super) fn from_design(
        a: &DMatrix<f64>,
        w: &[f64],
        rcond: f64,
        regularize: Option<f64>,
    ) -> Factor {
        let (n, m) = a.shape();
        let mut wa = DMatrix::zeros(n.max(m), m);
        for i in 0..n {
            let sw = w[i].sqrt();
            for j in 0..m {
                wa[(i, j)] = sw * a[(i, j)];
            }
        }
        let svd = nalgebra::SVD::new(wa, false, true);
        let vt = svd.v_t.expect("v requested");
        Factor::new(
            svd.singular_values.iter().copied().collect(),
            vt.transpose(),
            rcond,
            regularize,
        )
    }

    /// From a normal matrix G = AᵀWA (symmetric eigendecomposition; σ = √λ).
    pub(super) fn from_normal(g: DMatrix<f64>, rcond: f64, regularize: Option<f64>) -> Factor {
        let m = g.nrows();
        let eig = SymmetricEigen::new(g);
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let sigma = order
            .iter()
            .map(|&i| eig.eigenvalues[i].max(0.0).sqrt())
            .collect();
        let v = DMatrix::from_fn(m, m, |r, c| eig.eigenvectors[(r, order[c])]);
        Factor::new(sigma, v, rcond, regularize)
    }

    /// Right singular vectors with σ ≤ `limit` (undetermined or poorly determined directions).
    pub(super) fn weak_directions(&self, basis: Basis, limit: f64) -> Vec<String> {
        (0..self.sigma.len())
            .filter(|&k| self.sigma[k] <= limit)
            .map(|k| describe_direction(basis, self.v.column(k).as_slice()))
            .collect()
    }
}

/// Diagnostics of a light set and its factorisation.
pub(super) fn diagnose(
    basis: Basis,
    lights: &LightSet,
    w: &[f64],
    f: &Factor,
    opts: &FitOptions,
) -> Vec<Diagnostic> {
    let m = basis.len();
    let fit: Vec<usize> = (0..lights.len()).filter(|&i| w[i] > 0.0).collect();
    let mut out = Vec::new();
    let below = lights.below_horizon();
    if !below.is_empty() {
        out.push(Diagnostic::BelowHorizon { lights: below });
    }
    if fit.len() < m {
        out.push(Diagnostic::TooFewLights {
            lights: fit.len(),
            coefficients: m,
            basis,
        });
    }
    if !fit.is_empty() {
        let r2: Vec<f64> = fit
            .iter()
            .map(|&i| lights.dirs[i][0].powi(2) + lights.dirs[i][1].powi(2))
            .collect();
        let (lo, hi) = r2
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        let el = |r2: f64| (1.0 - r2).max(0.0).sqrt().asin().to_degrees();
        if fit.len() >= 2 && hi - lo < 1e-9 {
            out.push(Diagnostic::Ring {
                elevation_deg: el(lo),
                r2: lo,
            });
        } else if fit.len() >= 2 && hi - lo < 0.02 {
            out.push(Diagnostic::NearRing {
                highest_deg: el(hi),
                lowest_deg: el(lo),
            });
        }
        let min_el = fit
            .iter()
            .map(|&i| lights.elevation_deg(i))
            .fold(f64::MAX, f64::min);
        if min_el >= 45.0 {
            out.push(Diagnostic::NoLightBelow { deg: min_el });
        }
    }
    if f.rank < m {
        let solution = match (opts.link, opts.regularize) {
            (Link::Logistic, l) => Solution::LogisticRidge {
                lambda: l.unwrap_or(logistic::DEFAULT_RIDGE),
            },
            (Link::Identity, Some(l)) => Solution::Ridge { lambda: l },
            (Link::Identity, None) => Solution::MinimumNorm {
                cutoff: f.cutoff,
                rcond: opts.rcond,
            },
        };
        out.push(Diagnostic::RankDeficient {
            rank: f.rank,
            coefficients: m,
            directions: f.weak_directions(basis, f.cutoff),
            solution,
        });
    } else if f.cond > COND_WARN {
        let smax = f.sigma[0];
        out.push(Diagnostic::IllConditioned {
            cond: f.cond,
            limit: COND_WARN,
            directions: f.weak_directions(basis, smax / COND_WARN),
        });
    }
    out
}

pub(super) fn design(basis: Basis, uv: UvMap, lights: &LightSet) -> DMatrix<f64> {
    let m = basis.len();
    let mut a = DMatrix::zeros(lights.len(), m);
    let mut t = vec![0.0; m];
    for (i, d) in lights.dirs.iter().enumerate() {
        let (u, v) = uv.of_dir(*d);
        basis.terms(u, v, &mut t);
        for j in 0..m {
            a[(i, j)] = t[j];
        }
    }
    a
}

pub(super) fn solver_words(opts: &FitOptions, f: &Factor, per_texel: bool) -> String {
    let how = match opts.regularize {
        Some(l) => format!("ridge lambda={l:e} x mean eigenvalue"),
        None => format!(
            "truncated at rcond={:e} (cutoff {:.3e})",
            opts.rcond, f.cutoff
        ),
    };
    if per_texel {
        format!(
            "per-texel f64 eigen-solve of the weighted normal matrix, {how}, weight={}",
            opts.weight.name()
        )
    } else {
        format!(
            "svd-pinv f64 of the shared design matrix, {how}, weight={}, applied in f32",
            opts.weight.name()
        )
    }
}

/// The design a distant-light fit shares between its texels, factored once: what every texel's
/// solve reads (identity link) or starts from (logistic link), and the light set's diagnostics.
pub(crate) struct SharedDesign {
    /// The design matrix A (lights × terms) at each light's mapped (u, v).
    pub a: DMatrix<f64>,
    /// Per light its weight (0 for lights below the horizon under cosine weights, and for the
    /// held-out lights).
    pub w: Vec<f64>,
    /// The held-out lights.
    pub held: Vec<usize>,
    /// The f64 factorisation of W½A.
    pub factor: Factor,
    /// What the light set's factorisation warns of.
    pub warnings: Vec<Diagnostic>,
}

/// Checks the options, weighs the lights and factors the shared design.
pub(crate) fn prepare(lights: &LightSet, opts: &FitOptions) -> Result<SharedDesign> {
    if lights.is_empty() {
        return Err(Error::Invalid("no lights to fit".into()));
    }
    if !(0.0..1.0).contains(&opts.rcond) {
        return Err(Error::Invalid(format!(
            "rcond {} must lie in [0, 1): singular values below rcond·σmax are dropped",
            opts.rcond
        )));
    }
    if let Some(l) = opts.regularize.filter(|l| !(l.is_finite() && *l >= 0.0)) {
        return Err(Error::Invalid(format!(
            "regularize λ = {l} must be finite and ≥ 0 (a negative ridge makes the normal \
             equations indefinite)"
        )));
    }
    if opts.basis.is_learned() {
        // A learned basis starts from the polynomial one of its size: its design, factor and
        // diagnostics are that basis's, once the learned basis's own needs are met.
        let (w, _) = light_weights(lights, opts)?;
        return prepare(lights, &crate::learned::check(opts, &w)?);
    }
    let (w, held) = light_weights(lights, opts)?;
    let a = design(opts.basis, opts.uv, lights);
    // The logistic link's λ is its own ridge; its factorisation (diagnostics, warm start) is the
    // identity link's truncated one.
    let ridge = match opts.link {
        Link::Identity => opts.regularize,
        Link::Logistic => None,
    };
    let factor = Factor::from_design(&a, &w, opts.rcond, ridge);
    let warnings = diagnose(opts.basis, lights, &w, &factor, opts);
    check_strict(opts, &warnings)?;
    Ok(SharedDesign {
        a,
        w,
        held,
        factor,
        warnings,
    })
}

pub(super) fn unpack(packed: &[f64], m: usize) -> DMatrix<f64> {
    let mut g = DMatrix::zeros(m, m);
    let mut q = 0;
    for i in 0..m {
        for j in i..m {
            g[(i, j)] = packed[q];
            g[(j, i)] = packed[q];
            q += 1;
        }
    }
    g
}

pub(super) fn remove_light(g: &mut DMatrix<f64>, a: &DMatrix<f64>, l: usize, w: f64) {
    let row = a.row(l);
    *g -= w * row.transpose() * row;
}
