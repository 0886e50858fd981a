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
//! factorisation of the design and the light-set diagnostics), `accumulator` (the streaming
//! [`Accumulator`]), `refit` (stored stacks, texels with dropped samples), `kernel` (the
//! packing and every `unsafe` SIMD kernel of the identity link), and here the two links'
//! per-image drivers shared by the streaming and stored paths.
use std::ops::Range;
use std::time::Instant;

use crate::logistic::{self, Footprint, Kernel, Source, Tables};
use crate::{Diagnostic, Error, Result};
use ptm_format::{LightSet, Link, Ptm};

mod accumulator;
mod factor;
mod kernel;
mod options;
mod refit;

pub use accumulator::Accumulator;
pub use factor::describe_direction;
use factor::Prepared;
use options::check_strict;
pub(crate) use options::ptm_coverage;
pub use options::{
    holdout_indices, ErrorStats, FitOptions, FitReport, LogisticStats, Weight, COND_WARN,
    DEFAULT_RCOND,
};
pub use refit::fit_stack;

/// The logistic fit's shared tables, its kernel and its relative ridge λ, from a prepared
/// distant-light design: what every level of a fit (and a farm merge's coarse levels) uses.
fn logistic_tables(
    prep: &Prepared,
    lights: &LightSet,
    opts: &FitOptions,
) -> Result<(Tables, Kernel, f64)> {
    let m = opts.basis.len();
    let n = lights.len();
    let kernel = opts.kernel.unwrap_or_else(Kernel::detect);
    if !kernel.supported() {
        return Err(Error::Invalid(format!(
            "the {} logistic kernel does not run on this CPU",
            kernel.name()
        )));
    }
    if opts.tolerance.is_nan() || opts.tolerance < 0.0 || opts.max_iterations == 0 {
        return Err(Error::Invalid(format!(
            "logistic tolerance {} must be ≥ 0 and the iteration cap {} at least 1",
            opts.tolerance, opts.max_iterations
        )));
    }
    let lambda = opts.regularize.unwrap_or(logistic::DEFAULT_RIDGE);
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
    Ok((tables, kernel, lambda))
}

/// The warnings a logistic fit's level-0 statistics raise (beside the light set's).
pub(crate) fn logistic_warnings(stats: &LogisticStats) -> Vec<Diagnostic> {
    let mut warnings = Vec::new();
    if stats.not_converged > 0 {
        warnings.push(Diagnostic::NotConverged {
            texels: stats.not_converged,
            max_iterations: stats.max_iterations,
            tolerance: stats.tolerance,
        });
    }
    if stats.lambda == 0.0 && stats.separable + stats.constant > 0 {
        warnings.push(Diagnostic::Separable {
            texels: stats.separable + stats.constant,
        });
    }
    warnings
}

/// Fits the MIP levels `levels` (footprints of the chain below level 0, each pooled from the
/// one before, the first from `src`, `src_w` texels wide), level by level. Returns the levels
/// and the last level's pooled data when `keep_last` (a farm part hands it to the merge).
fn logistic_levels(
    tables: &Tables,
    kernel: Kernel,
    src: &Source,
    src_w: usize,
    levels: &[Footprint],
    keep_last: bool,
) -> (Vec<ptm_format::Level>, Option<logistic::Pooled>) {
    // Each level pools the one above (exact counts, or coverage-weighted K), is fitted, and
    // replaces it: at most two levels' data are alive, the first a quarter of level 0.
    let mut out = Vec::with_capacity(levels.len());
    let mut above: Option<logistic::Pooled> = None;
    let mut above_w = src_w;
    for fp in levels {
        let pooled = match &above {
            None => logistic::pool(src, above_w, *fp),
            Some(p) => logistic::pool(&p.source(), above_w, *fp),
        };
        // A coarse texel is fitted when any of its footprint is covered (the kernel leaves
        // out texels whose every sample is missing).
        let level = logistic::fit_level(
            tables,
            &pooled.source(),
            fp.width * fp.height,
            &|_| true,
            kernel,
        );
        out.push(ptm_format::Level {
            width: fp.width,
            height: fp.height,
            planes: level.planes,
        });
        above = Some(pooled);
        above_w = fp.width;
    }
    (out, above.filter(|_| keep_last))
}

/// The MIP levels `levels` of a farm merge whose footprints cross shard borders, fitted from
/// the pooled counts `cov` / `occ` (`[light][texel]`) of the level above them (`src_w` texels
/// wide), with the fit's tables rebuilt from `opts` and `lights` as the bake built them.
pub(crate) fn logistic_coarse_levels(
    lights: &LightSet,
    opts: &FitOptions,
    cov: &[u32],
    occ: &[Vec<u32>],
    src_w: usize,
    levels: &[Footprint],
) -> Result<Vec<ptm_format::Level>> {
    let prep = factor::prepare(lights, opts)?;
    let (tables, kernel, _) = logistic_tables(&prep, lights, opts)?;
    let src = Source::Counts32 { occ, cov };
    Ok(logistic_levels(&tables, kernel, &src, src_w, levels, false).0)
}

/// The logistic fit of one image from `src` (level 0 and, with `opts.mips`, every MIP level),
/// on a prepared distant-light design: the PTM and its report (errors, iterations, classes).
/// `part`: the image is rows `rows` of one `height` rows tall (a farm shard, see
/// [`crate::shard`]): only the levels whose footprints lie in those rows are fitted, and the
/// last one's pooled counts are returned when the merge must pool deeper levels from them.
#[allow(clippy::too_many_arguments)]
fn fit_logistic(
    src: &Source,
    prep: &Prepared,
    lights: &LightSet,
    size: (usize, usize),
    tile: [f64; 2],
    masked: &[bool],
    opts: &FitOptions,
    part: Option<(Range<usize>, usize)>,
) -> Result<(Ptm, FitReport, Option<logistic::Pooled>)> {
    let (w, h) = size;
    let t = w * h;
    let m = opts.basis.len();
    let n = lights.len();
    let t0 = Instant::now();
    let (tables, kernel, lambda) = logistic_tables(prep, lights, opts)?;
    let f = &prep.factor;
    let t_factor = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let fits = logistic::fit_level(&tables, src, t, &|ti| !masked[ti], kernel);
    let t_level0 = t1.elapsed().as_secs_f64();
    let fitted: Vec<usize> = (0..t).filter(|&ti| !masked[ti]).collect();
    let iterations_total: u64 = fitted.iter().map(|&ti| fits.iterations[ti] as u64).sum();
    let stats = LogisticStats {
        iterations_mean: iterations_total as f64 / fitted.len().max(1) as f64,
        iterations_total,
        iterations_max: fitted
            .iter()
            .map(|&ti| fits.iterations[ti])
            .max()
            .unwrap_or(0),
        not_converged: fitted.iter().filter(|&&ti| !fits.converged[ti]).count(),
        separable: fitted.iter().filter(|&&ti| fits.separable[ti]).count(),
        constant: fitted.iter().filter(|&&ti| fits.constant[ti]).count(),
        lambda,
        ridge: tables.ridge,
        tolerance: opts.tolerance,
        max_iterations: opts.max_iterations,
        kernel: kernel.name(),
    };
    drop(fitted);
    let logistic::LevelFit {
        planes,
        rms: rms_map,
        max: max_map,
        holdout: hold_map,
        ..
    } = fits;
    let t2 = Instant::now();
    let (mips, pooled) = match (&part, opts.mips) {
        (_, false) => (Vec::new(), None),
        (None, true) => {
            let chain = Footprint::chain(w, h);
            logistic_levels(&tables, kernel, src, w, &chain[1..], false)
        }
        (Some((rows, height)), true) => {
            let (local, deeper) = crate::shard::local_levels(w, *height, rows.clone());
            logistic_levels(&tables, kernel, src, w, &local, deeper)
        }
    };
    let t_mips = t2.elapsed().as_secs_f64();
    let mut warnings = prep.warnings.clone();
    warnings.extend(logistic_warnings(&stats));
    check_strict(opts, &warnings)?;
    let mask_vec = masked.to_vec();
    let mut report = FitReport {
        basis: Some(opts.basis),
        link: Some(Link::Logistic),
        uv: Some(opts.uv),
        logistic: Some(stats),
        mip_levels: mips.len(),
        lights: n,
        lights_fit: tables.nfit,
        holdout_lights: prep.held.clone(),
        texels: t,
        masked: masked.iter().filter(|&&x| x).count(),
        coefficients: m,
        rank: f.rank,
        cond: f.cond,
        cutoff: f.cutoff,
        rcond: opts.rcond,
        singular_values: f.sigma.clone(),
        solver: format!(
            "logistic maximum likelihood (binomial deviance), Newton per texel from the least-squares logit fit, ridge lambda={lambda:e} x mean eigenvalue (rho={:.3e}), tolerance {:e} per unit weight, at most {} iterations, weight={}",
            tables.ridge,
            opts.tolerance,
            opts.max_iterations,
            opts.weight.name(),
        ),
        warnings,
        ..FitReport::default()
    };
    report.rms = ErrorStats::of(&rms_map, &mask_vec);
    report.max = Some(ErrorStats::of(&max_map, &mask_vec));
    if !prep.held.is_empty() {
        report.holdout = Some(ErrorStats::of(&hold_map, &mask_vec));
    }
    report.rms_map = rms_map;
    report.max_map = max_map;
    report.seconds = vec![("factor", t_factor), ("newton", t_level0)];
    if opts.mips {
        report.seconds.push(("mip levels", t_mips));
    }
    let ptm = Ptm {
        basis: opts.basis,
        link: Link::Logistic,
        uv: opts.uv,
        width: w,
        height: h,
        tile,
        planes,
        mips,
        coverage: None, // set by the caller, which knows the coverage
    };
    Ok((ptm, report, pooled))
}

/// MIP levels of an identity-link PTM: the least-squares fit of box-filtered K equals the
/// coverage-weighted box average of the coefficients (K is linear in them and every texel
/// shares the design), so no refit is needed.
pub(crate) fn identity_mips(ptm: &Ptm, coverage: &[f32]) -> Vec<ptm_format::Level> {
    let m = ptm.basis.len();
    let chain = Footprint::chain(ptm.width, ptm.height);
    let mut planes: Vec<Vec<f32>> = ptm.planes.clone();
    let mut weight: Vec<f64> = (0..ptm.width * ptm.height)
        .map(|t| coverage.get(t).copied().unwrap_or(1.0).max(0.0) as f64)
        .collect();
    let mut above_w = ptm.width;
    let mut out = Vec::new();
    for fp in &chain[1..] {
        let n = fp.width * fp.height;
        let mut next = vec![vec![0f32; n]; m];
        let mut next_w = vec![0f64; n];
        for t in 0..n {
            let (x, y) = (t % fp.width, t / fp.width);
            let mut num = [0f64; 16];
            let mut den = 0f64;
            for dy in 0..fp.fy {
                for dx in 0..fp.fx {
                    let c = (y * fp.fy + dy) * above_w + x * fp.fx + dx;
                    den += weight[c];
                    for j in 0..m {
                        num[j] += weight[c] * planes[j][c] as f64;
                    }
                }
            }
            next_w[t] = den;
            if den > 0.0 {
                for j in 0..m {
                    next[j][t] = (num[j] / den) as f32;
                }
            }
        }
        out.push(ptm_format::Level {
            width: fp.width,
            height: fp.height,
            planes: next.clone(),
        });
        planes = next;
        weight = next_w;
        above_w = fp.width;
    }
    out
}
