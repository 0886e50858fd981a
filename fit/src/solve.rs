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
use std::collections::BTreeMap;
use std::time::Instant;

use nalgebra::{DMatrix, SymmetricEigen};
use rayon::prelude::*;

use crate::logistic::{self, Footprint, Kernel, Source, Tables};
use crate::{Basis, Error, LightSet, Link, Ptm, Result, SampleStack, UvMap};

/// How each light's squared error counts in the fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weight {
    /// Every light counts the same.
    Uniform,
    /// Weight = l_z = sin(elevation): grazing lights carry less light, so their errors matter
    /// less for shading. Lights at or below the horizon get weight 0 (left out).
    Cosine,
}

impl Weight {
    pub fn name(self) -> &'static str {
        match self {
            Weight::Uniform => "uniform",
            Weight::Cosine => "cosine",
        }
    }
}

/// Options of a fit. Defaults live in the CLI; [`FitOptions::new`] gives the documented ones.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    pub basis: Basis,
    /// K = p (least squares) or K = σ(p) (maximum likelihood, [`crate::logistic`]).
    pub link: Link,
    /// How light directions map to (u, v).
    pub uv: UvMap,
    pub weight: Weight,
    /// Ridge λ, relative to the mean eigenvalue trace(AᵀWA)/terms: minimises
    /// |W½(Ac − k)|² + λ·trace(AᵀWA)/terms·|c|². `None`: truncated SVD (minimum norm) for the
    /// identity link, [`logistic::DEFAULT_RIDGE`] for the logistic link.
    pub regularize: Option<f64>,
    /// Logistic link: Newton stops when the decrement per unit light weight is below this.
    pub tolerance: f64,
    /// Logistic link: at most this many Newton iterations per texel.
    pub max_iterations: u32,
    /// Also fit MIP levels (each to the box-filtered K of its footprint) for the file.
    pub mips: bool,
    /// Logistic link: force a kernel build (tests and benchmarks); `None` = the widest.
    pub kernel: Option<Kernel>,
    /// Singular values below `rcond · σ_max` are treated as zero (their directions undetermined).
    pub rcond: f64,
    /// Any warning about the light set becomes an error.
    pub strict: bool,
    /// Drop non-finite samples (counted) instead of failing.
    pub skip_bad: bool,
    /// Number of lights kept out of the fit to measure the error honestly (0 = none).
    pub holdout: usize,
}

/// Default relative singular-value cutoff. Well-spread domes have condition numbers of 6 (ptm6)
/// to 25 (ptm11), domes above 60° about 400 (ptm11): all kept. A dome 1e-3 off a single ring has
/// about 2400; fitting that direction amplified bake noise into a held-out RMS error of K of 0.50
/// on the plain weave, against 0.32 with it dropped (`ptm report`, stability tables).
pub const DEFAULT_RCOND: f64 = 1e-3;

/// Condition number above which the fit is reported as ill-conditioned.
pub const COND_WARN: f64 = 100.0;

impl FitOptions {
    pub fn new(basis: Basis) -> Self {
        FitOptions {
            basis,
            link: Link::Identity,
            uv: UvMap::Projected,
            weight: Weight::Uniform,
            regularize: None,
            tolerance: logistic::DEFAULT_TOLERANCE,
            max_iterations: logistic::DEFAULT_MAX_ITERATIONS,
            mips: false,
            kernel: None,
            rcond: DEFAULT_RCOND,
            strict: false,
            skip_bad: false,
            holdout: 0,
        }
    }
}

/// Mean, 99th percentile and maximum of a per-texel error over the unmasked texels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    pub mean: f64,
    pub p99: f64,
    pub max: f64,
}

impl ErrorStats {
    /// Over the texels whose `mask` is false; p99 by selection (O(texels)).
    pub(crate) fn of(values: &[f32], mask: &[bool]) -> Self {
        let mut v: Vec<f32> = values
            .iter()
            .zip(mask)
            .filter(|(_, &m)| !m)
            .map(|(&x, _)| x)
            .collect();
        if v.is_empty() {
            return ErrorStats::default();
        }
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        let max = v.iter().copied().fold(f32::MIN, f32::max);
        // Selection, not a sort: O(texels).
        let i99 = ((v.len() as f64 * 0.99).ceil() as usize).clamp(1, v.len()) - 1;
        let (_, p99, _) = v.select_nth_unstable_by(i99, f32::total_cmp);
        ErrorStats {
            mean,
            p99: *p99 as f64,
            max: max as f64,
        }
    }
}

/// Diagnostics of a fit, returned beside the PTM.
#[derive(Clone, Debug, Default)]
pub struct FitReport {
    pub basis: Option<Basis>,
    pub link: Option<Link>,
    pub uv: Option<UvMap>,
    /// Logistic link: Newton iterations per fitted texel (mean, max), texels stopped by the
    /// iteration cap, texels whose samples a polynomial separates exactly (optimum at infinity
    /// without the ridge) and texels whose samples are all 0 or all 1 (a special separable case).
    pub logistic: Option<LogisticStats>,
    /// MIP levels fitted beside level 0 (0 = none).
    pub mip_levels: usize,
    /// Lights in the set, lights that entered the fit (weight > 0, not held out).
    pub lights: usize,
    pub lights_fit: usize,
    /// Indices of held-out lights.
    pub holdout_lights: Vec<usize>,
    pub texels: usize,
    /// Texels with coverage 0: coefficients 0, left out of the statistics.
    pub masked: usize,
    pub coefficients: usize,
    /// Numerical rank of W½A (for per-texel directions: the lowest over texels).
    pub rank: usize,
    /// σ_max / σ_min of W½A (for per-texel directions: the worst texel); `inf` when singular.
    pub cond: f64,
    /// Absolute singular-value cutoff used (rcond · σ_max), and rcond.
    pub cutoff: f64,
    pub rcond: f64,
    /// Singular values of W½A, descending (distant lights).
    pub singular_values: Vec<f64>,
    /// Solver in words, e.g. `svd-pinv f64 (truncated at 1e-4·σmax), applied in f32`.
    pub solver: String,
    /// Plain-word warnings about the light set and the data.
    pub warnings: Vec<String>,
    /// Per-texel weighted RMS residual over the fitting lights.
    pub rms: ErrorStats,
    /// Per-texel max |residual| over the fitting lights (None when streaming: needs the samples).
    pub max: Option<ErrorStats>,
    /// Per-texel RMS error of clamped K on the held-out lights.
    pub holdout: Option<ErrorStats>,
    /// Non-finite samples dropped (`skip_bad`).
    pub skipped_samples: usize,
    /// Texels solved individually (dropped samples) whose rank fell below `coefficients`.
    pub rank_deficient_texels: usize,
    /// Per-texel coverage (fraction of the footprint that saw the swatch) when some texel is
    /// not fully covered; empty when every texel is (nothing to record).
    pub coverage: Vec<f32>,
    /// Per-texel maps: weighted RMS and max residual (max empty when streaming).
    pub rms_map: Vec<f32>,
    pub max_map: Vec<f32>,
    /// Seconds per stage, in order.
    pub seconds: Vec<(&'static str, f64)>,
}

/// What the logistic fit did, over the fitted texels of level 0.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LogisticStats {
    pub iterations_mean: f64,
    pub iterations_max: u32,
    pub not_converged: usize,
    pub separable: usize,
    pub constant: usize,
    /// Ridge λ (relative) and ρ (absolute, λ·mean eigenvalue of AᵀΩA).
    pub lambda: f64,
    pub ridge: f64,
    pub tolerance: f64,
    pub max_iterations: u32,
    /// The kernel build that ran (`avx512f`, `avx2+fma`, `portable`).
    pub kernel: &'static str,
}

/// `coverage` when some texel is not fully covered, else nothing (a file needs no channel of 1s).
fn partial_coverage(coverage: &[f32]) -> Vec<f32> {
    if coverage.iter().any(|&c| c < 1.0) {
        coverage.to_vec()
    } else {
        Vec::new()
    }
}

/// The coverage a fitted [`Ptm`] carries: the map when some texel is not fully covered.
pub(crate) fn ptm_coverage(coverage: &[f32]) -> Option<Vec<f32>> {
    coverage.iter().any(|&c| c < 1.0).then(|| coverage.to_vec())
}

/// Evenly spread hold-out lights: index ⌊(j + ½)·n / h⌋ for j < h.
pub fn holdout_indices(n: usize, h: usize) -> Vec<usize> {
    (0..h.min(n))
        .map(|j| ((j as f64 + 0.5) * n as f64 / h as f64) as usize)
        .collect()
}

fn light_weights(lights: &LightSet, opts: &FitOptions) -> Result<(Vec<f64>, Vec<usize>)> {
    if opts.holdout >= lights.len() {
        return Err(Error::Invalid(format!(
            "--holdout {} leaves no light to fit ({} lights)",
            opts.holdout,
            lights.len()
        )));
    }
    let held = holdout_indices(lights.len(), opts.holdout);
    let mut w: Vec<f64> = lights
        .dirs
        .iter()
        .map(|d| match opts.weight {
            Weight::Uniform => 1.0,
            Weight::Cosine => d[2].max(0.0),
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
    fn new(sigma: Vec<f64>, v: DMatrix<f64>, rcond: f64, regularize: Option<f64>) -> Factor {
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
    fn from_design(a: &DMatrix<f64>, w: &[f64], rcond: f64, regularize: Option<f64>) -> Factor {
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
    fn from_normal(g: DMatrix<f64>, rcond: f64, regularize: Option<f64>) -> Factor {
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
    fn weak_directions(&self, basis: Basis, limit: f64) -> Vec<String> {
        (0..self.sigma.len())
            .filter(|&k| self.sigma[k] <= limit)
            .map(|k| describe_direction(basis, self.v.column(k).as_slice()))
            .collect()
    }
}

/// Plain-word warnings about a light set and its factorisation.
fn diagnose(
    basis: Basis,
    lights: &LightSet,
    w: &[f64],
    f: &Factor,
    opts: &FitOptions,
) -> Vec<String> {
    let m = basis.len();
    let fit: Vec<usize> = (0..lights.len()).filter(|&i| w[i] > 0.0).collect();
    let mut out = Vec::new();
    if fit.len() < m {
        out.push(format!(
            "only {} lights enter the fit for {} coefficients of {}: at least {} directions of the basis are undetermined",
            fit.len(),
            m,
            basis.name(),
            m - fit.len()
        ));
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
            out.push(format!(
                "all lights lie on one elevation ring ({:.2}°, u²+v² = {:.4}): u2+v2 cannot be told from the constant, and K inside the ring is not determined by the data",
                el(lo),
                lo
            ));
        } else if fit.len() >= 2 && hi - lo < 0.02 {
            out.push(format!(
                "lights lie near one elevation ring (elevations {:.2}°–{:.2}°): terms that differ only by u²+v² are nearly indistinguishable",
                el(hi),
                el(lo)
            ));
        }
        let min_el = fit
            .iter()
            .map(|&i| lights.elevation_deg(i))
            .fold(f64::MAX, f64::min);
        if min_el >= 45.0 {
            out.push(format!(
                "no light below {min_el:.1}° elevation: K at grazing lights, where most occlusion lives, is extrapolated"
            ));
        }
    }
    if f.rank < m {
        let what = match (opts.link, opts.regularize) {
            (Link::Logistic, l) => format!(
                "logistic fit whose ridge (lambda = {:e} x mean eigenvalue) holds them near 0",
                l.unwrap_or(logistic::DEFAULT_RIDGE)
            ),
            (Link::Identity, Some(l)) => format!("ridge solution (lambda = {l:e} x mean eigenvalue)"),
            (Link::Identity, None) => format!(
                "minimum-norm solution (truncated SVD: singular values <= {:.3e} = {:e} x sigma_max dropped)",
                f.cutoff, opts.rcond
            ),
        };
        out.push(format!(
            "rank {} of {}: the light set cannot determine these basis directions: {}; returning the {what}",
            f.rank,
            m,
            f.weak_directions(basis, f.cutoff).join("; ")
        ));
    } else if f.cond > COND_WARN {
        let smax = f.sigma[0];
        out.push(format!(
            "ill-conditioned (condition number {:.1} > {COND_WARN}): poorly determined directions: {}",
            f.cond,
            f.weak_directions(basis, smax / COND_WARN).join("; ")
        ));
    }
    out
}

fn design(basis: Basis, uv: UvMap, lights: &LightSet) -> DMatrix<f64> {
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

fn solver_words(opts: &FitOptions, f: &Factor, per_texel: bool) -> String {
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

fn check_strict(opts: &FitOptions, warnings: &[String]) -> Result<()> {
    if opts.strict && !warnings.is_empty() {
        return Err(Error::Strict(warnings.join("; ")));
    }
    Ok(())
}

/// Shared preparation of a distant-light fit.
struct Prepared {
    a: DMatrix<f64>,
    w: Vec<f64>,
    held: Vec<usize>,
    factor: Factor,
    warnings: Vec<String>,
}

fn prepare(lights: &LightSet, opts: &FitOptions) -> Result<Prepared> {
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
    Ok(Prepared {
        a,
        w,
        held,
        factor,
        warnings,
    })
}

/// The logistic fit of one image from `src` (level 0 and, with `opts.mips`, every MIP level),
/// on a prepared distant-light design: the PTM and its report (errors, iterations, classes).
fn fit_logistic(
    src: &Source,
    prep: &Prepared,
    lights: &LightSet,
    size: (usize, usize),
    tile: [f64; 2],
    masked: &[bool],
    opts: &FitOptions,
) -> Result<(Ptm, FitReport)> {
    let (w, h) = size;
    let t = w * h;
    let m = opts.basis.len();
    let n = lights.len();
    let t0 = Instant::now();
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
    let t_factor = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let chain = Footprint::chain(w, h);
    let fits = logistic::fit_level(&tables, src, t, &|ti| !masked[ti], kernel);
    let t_level0 = t1.elapsed().as_secs_f64();
    let fitted: Vec<usize> = (0..t).filter(|&ti| !masked[ti]).collect();
    let stats = LogisticStats {
        iterations_mean: fitted
            .iter()
            .map(|&ti| fits.iterations[ti] as f64)
            .sum::<f64>()
            / fitted.len().max(1) as f64,
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
    let mut mips = Vec::new();
    if opts.mips {
        // Each level pools the one above (exact counts, or coverage-weighted K), is fitted, and
        // replaces it: at most two levels' data are alive, the first a quarter of level 0.
        let mut above: Option<logistic::Pooled> = None;
        let mut above_w = w;
        for fp in &chain[1..] {
            let pooled = match &above {
                None => logistic::pool(src, above_w, *fp),
                Some(p) => logistic::pool(&p.source(), above_w, *fp),
            };
            // A coarse texel is fitted when any of its footprint is covered (the kernel leaves
            // out texels whose every sample is missing).
            let level = logistic::fit_level(
                &tables,
                &pooled.source(),
                fp.width * fp.height,
                &|_| true,
                kernel,
            );
            mips.push(crate::Level {
                width: fp.width,
                height: fp.height,
                planes: level.planes,
            });
            above = Some(pooled);
            above_w = fp.width;
        }
    }
    let t_mips = t2.elapsed().as_secs_f64();
    let mut warnings = prep.warnings.clone();
    if stats.not_converged > 0 {
        warnings.push(format!(
            "{} texels stopped at the logistic iteration cap ({}) before the tolerance {:e}: raise --max-iterations, or the ridge (--regularize)",
            stats.not_converged, opts.max_iterations, opts.tolerance
        ));
    }
    if lambda == 0.0 && stats.separable + stats.constant > 0 {
        warnings.push(format!(
            "{} texels are separable (K is 0 or 1 and a polynomial boundary splits them exactly) and the ridge is 0: their maximum-likelihood coefficients are infinite, so they stopped where the iteration cap left them; give --regularize > 0",
            stats.separable + stats.constant
        ));
    }
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
    Ok((ptm, report))
}

/// MIP levels of an identity-link PTM: the least-squares fit of box-filtered K equals the
/// coverage-weighted box average of the coefficients (K is linear in them and every texel
/// shares the design), so no refit is needed.
pub(crate) fn identity_mips(ptm: &Ptm, coverage: &[f32]) -> Vec<crate::Level> {
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
        out.push(crate::Level {
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

/// Streaming accumulator used by `ptm bake --fit`: samples are added light by light, memory is
/// O(texels × terms) (plus the held-out lights' samples, if asked), never O(texels × lights).
pub struct Accumulator {
    opts: FitOptions,
    lights: LightSet,
    width: usize,
    height: usize,
    m: usize,
    prep: Prepared,
    /// Texel-major AᵀW·k, m per texel (distant lights).
    g: Vec<f64>,
    /// Per-texel packed upper triangle of AᵀWA, m(m+1)/2 per texel (per-texel directions).
    gram: Vec<f64>,
    /// Per-texel Σ w·k².
    s: Vec<f64>,
    /// Per-texel Σ w over the lights added (differs from the total only for dropped samples).
    wsum: Vec<f64>,
    seen: Vec<bool>,
    mode: Option<bool>,
    masked: Vec<bool>,
    /// Held-out light index → its K plane and, per texel, (u, v) when per-texel.
    held: BTreeMap<usize, HeldLight>,
    /// Dropped samples per texel (skip_bad).
    bad: BTreeMap<usize, Vec<usize>>,
    skipped: usize,
    started: Instant,
    /// Logistic link: footprint samples per texel (the bake's spp), covered samples per texel,
    /// and the occluded counts of every light (u8 while spp ≤ 255, else u16): exact, and
    /// texels × lights bytes where a stored f32 stack would take four times that.
    spp: Option<u32>,
    cov: Vec<u32>,
    occ8: Vec<Vec<u8>>,
    occ16: Vec<Vec<u16>>,
    /// The coverage given to [`Accumulator::set_coverage`] (empty: every texel covered).
    full_coverage: Vec<f32>,
}

const CHUNK: usize = 4096;

/// A held-out light's K plane and, for per-texel directions, its (u, v) plane.
type HeldLight = (Vec<f32>, Option<Vec<[f32; 2]>>);

impl Accumulator {
    /// Factors the shared design matrix once (f64 SVD) and runs the light-set diagnostics.
    pub fn new(lights: &LightSet, width: usize, height: usize, opts: &FitOptions) -> Result<Self> {
        let started = Instant::now();
        if width * height == 0 {
            return Err(Error::Invalid(format!("empty image {width}×{height}")));
        }
        let prep = prepare(lights, opts)?;
        let t = width * height;
        Ok(Accumulator {
            spp: None,
            cov: Vec::new(),
            occ8: Vec::new(),
            occ16: Vec::new(),
            full_coverage: Vec::new(),
            opts: opts.clone(),
            lights: lights.clone(),
            width,
            height,
            m: opts.basis.len(),
            prep,
            g: Vec::new(),
            gram: Vec::new(),
            s: if opts.link == Link::Logistic {
                Vec::new()
            } else {
                vec![0.0; t]
            },
            wsum: Vec::new(),
            seen: vec![false; lights.len()],
            mode: None,
            masked: vec![false; t],
            held: BTreeMap::new(),
            bad: BTreeMap::new(),
            skipped: 0,
            started,
        })
    }

    /// The light-set warnings found when factoring (before any sample is added).
    pub fn warnings(&self) -> &[String] {
        &self.prep.warnings
    }

    /// Marks texels with coverage 0 as masked: their samples are ignored (NaN allowed) and their
    /// coefficients are 0. Call before adding lights.
    pub fn set_coverage(&mut self, coverage: &[f32]) -> Result<()> {
        if coverage.len() != self.masked.len() {
            return Err(Error::Invalid(format!(
                "coverage has {} texels, expected {}",
                coverage.len(),
                self.masked.len()
            )));
        }
        for (m, &c) in self.masked.iter_mut().zip(coverage) {
            *m = c <= 0.0;
        }
        self.full_coverage = coverage.to_vec();
        Ok(())
    }

    /// The footprint samples per texel of the bake (needed by the logistic link, which holds
    /// exact counts: K·covered samples). Call before adding lights.
    pub fn set_spp(&mut self, spp: u32) -> Result<()> {
        if spp == 0 || spp > u16::MAX as u32 {
            return Err(Error::Invalid(format!(
                "samples per texel {spp} must lie in 1..=65535"
            )));
        }
        self.spp = Some(spp);
        Ok(())
    }

    /// Bytes the logistic link holds per texel and light (0 for the identity link).
    pub fn count_bytes(link: Link, spp: u32) -> usize {
        match link {
            Link::Identity => 0,
            Link::Logistic if spp <= u8::MAX as u32 => 1,
            Link::Logistic => 2,
        }
    }

    /// Logistic link: stores light `index`'s K plane as exact occluded counts.
    fn add_counts(&mut self, index: usize, k: &[f32]) -> Result<()> {
        let spp = self.spp.ok_or_else(|| {
            Error::Invalid(
                "the logistic link's streaming fit needs the samples per texel (Accumulator::set_spp) to hold exact counts"
                    .into(),
            )
        })?;
        let t = self.width * self.height;
        if self.cov.is_empty() {
            self.cov = (0..t)
                .map(|ti| {
                    let c = self.full_coverage.get(ti).copied().unwrap_or(1.0);
                    (c as f64 * spp as f64).round() as u32
                })
                .collect();
            if spp <= u8::MAX as u32 {
                self.occ8 = vec![Vec::new(); self.lights.len()];
            } else {
                self.occ16 = vec![Vec::new(); self.lights.len()];
            }
        }
        let (cov, masked, width) = (&self.cov, &self.masked, self.width);
        let count = |ti: usize| -> Result<u16> {
            if masked[ti] || cov[ti] == 0 {
                return Ok(0);
            }
            let x = k[ti] as f64 * cov[ti] as f64;
            let n = x.round();
            if !k[ti].is_finite() || (x - n).abs() > 1e-2 || !(0.0..=cov[ti] as f64).contains(&n) {
                return Err(Error::Invalid(format!(
                    "light {index}: K = {} at texel (column {}, row {}) is not a fraction of its {} covered samples (spp {spp}): the logistic streaming fit needs the bake's exact sample counts",
                    k[ti],
                    ti % width,
                    ti / width,
                    cov[ti]
                )));
            }
            Ok(n as u16)
        };
        if spp <= u8::MAX as u32 {
            let plane: Result<Vec<u8>> = (0..t).map(|ti| count(ti).map(|n| n as u8)).collect();
            self.occ8[index] = plane?;
        } else {
            let plane: Result<Vec<u16>> = (0..t).map(count).collect();
            self.occ16[index] = plane?;
        }
        Ok(())
    }

    fn begin(&mut self, index: usize, len: usize, per_texel: bool) -> Result<()> {
        let t = self.width * self.height;
        if index >= self.lights.len() {
            return Err(Error::Invalid(format!(
                "light index {index} out of range ({} lights)",
                self.lights.len()
            )));
        }
        if self.seen[index] {
            return Err(Error::Invalid(format!("light {index} added twice")));
        }
        if len != t {
            return Err(Error::Invalid(format!(
                "light {index}: {len} samples for {t} texels"
            )));
        }
        match self.mode {
            // The logistic link keeps counts (add_counts), not sums.
            None if self.opts.link == Link::Logistic => self.mode = Some(per_texel),
            None => {
                self.mode = Some(per_texel);
                if per_texel {
                    self.gram = vec![0.0; t * self.m * (self.m + 1) / 2];
                    self.g = vec![0.0; t * self.m];
                    self.wsum = vec![0.0; t];
                } else {
                    self.g = vec![0.0; t * self.m];
                }
            }
            Some(p) if p != per_texel => {
                return Err(Error::Invalid(
                    "add_light and add_light_uv cannot be mixed in one fit".into(),
                ))
            }
            _ => {}
        }
        self.seen[index] = true;
        Ok(())
    }

    /// Finds non-finite samples of unmasked texels: an error naming the first, or (skip_bad)
    /// records them. Returns the texels whose sample must be left out.
    fn scan_bad(&mut self, index: usize, k: &[f32], uv: Option<&[[f32; 2]]>) -> Result<()> {
        let bad: Vec<usize> = (0..k.len())
            .filter(|&t| {
                !self.masked[t]
                    && (!k[t].is_finite()
                        || uv.is_some_and(|uv| !(uv[t][0].is_finite() && uv[t][1].is_finite())))
            })
            .collect();
        if let Some(&t) = bad.first() {
            if !self.opts.skip_bad {
                return Err(bad_sample(t, self.width, index, k[t]));
            }
            self.skipped += bad.len();
            for &t in &bad {
                self.bad.entry(t).or_default().push(index);
            }
        }
        Ok(())
    }

    /// Adds the K plane (row-major, one value per texel) of distant light `index`.
    pub fn add_light(&mut self, index: usize, k: &[f32]) -> Result<()> {
        self.begin(index, k.len(), false)?;
        if self.opts.link == Link::Logistic {
            return self.add_counts(index, k);
        }
        self.scan_bad(index, k, None)?;
        if self.prep.held.contains(&index) {
            self.held.insert(index, (k.to_vec(), None));
            return Ok(());
        }
        let w = self.prep.w[index];
        if w == 0.0 {
            return Ok(());
        }
        let m = self.m;
        let aw: Vec<f64> = (0..m).map(|j| w * self.prep.a[(index, j)]).collect();
        let masked = &self.masked;
        self.g
            .par_chunks_mut(CHUNK * m)
            .zip(self.s.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(ci, (g, s))| {
                let t0 = ci * CHUNK;
                let (k, masked) = (&k[t0..t0 + s.len()], &masked[t0..t0 + s.len()]);
                match m {
                    6 => accumulate::<6>(g, s, k, masked, &aw, w),
                    11 => accumulate::<11>(g, s, k, masked, &aw, w),
                    _ => unreachable!("bases have 6 or 11 terms"),
                }
            });
        Ok(())
    }

    /// Adds light `index` with per-texel (u, v) (finite-distance lights).
    pub fn add_light_uv(&mut self, index: usize, k: &[f32], uv: &[[f32; 2]]) -> Result<()> {
        if self.opts.link == Link::Logistic {
            return Err(refuse_per_texel_logistic());
        }
        self.begin(index, k.len(), true)?;
        if uv.len() != k.len() {
            return Err(Error::Invalid(format!(
                "light {index}: {} (u, v) pairs for {} samples",
                uv.len(),
                k.len()
            )));
        }
        self.scan_bad(index, k, Some(uv))?;
        if self.prep.held.contains(&index) {
            self.held.insert(index, (k.to_vec(), Some(uv.to_vec())));
            return Ok(());
        }
        let w = self.prep.w[index];
        if w == 0.0 {
            return Ok(());
        }
        let (m, basis, uv_map) = (self.m, self.opts.basis, self.opts.uv);
        let np = m * (m + 1) / 2;
        let masked = &self.masked;
        self.gram
            .par_chunks_mut(CHUNK * np)
            .zip(self.g.par_chunks_mut(CHUNK * m))
            .zip(self.s.par_chunks_mut(CHUNK))
            .zip(self.wsum.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(ci, (((gr, g), s), ws))| {
                let t0 = ci * CHUNK;
                let mut a = [0.0f64; 16];
                for b in 0..s.len() {
                    let (kb, p) = (k[t0 + b], uv[t0 + b]);
                    if masked[t0 + b] || !kb.is_finite() || !p[0].is_finite() || !p[1].is_finite() {
                        continue;
                    }
                    let (u, v) = uv_map.of_projected(p[0], p[1]);
                    basis.terms(u as f64, v as f64, &mut a[..m]);
                    let kb = kb as f64;
                    let grb = &mut gr[b * np..(b + 1) * np];
                    let mut q = 0;
                    for i in 0..m {
                        for j in i..m {
                            grb[q] += w * a[i] * a[j];
                            q += 1;
                        }
                        g[b * m + i] += w * a[i] * kb;
                    }
                    s[b] += w * kb * kb;
                    ws[b] += w;
                }
            });
        Ok(())
    }

    /// Solves every texel and returns the PTM and its report. Every light must have been added.
    pub fn finish(self, tile: [f64; 2]) -> Result<(Ptm, FitReport)> {
        if let Some(i) = self.seen.iter().position(|s| !s) {
            return Err(Error::Invalid(format!(
                "light {i} ({}) was never added; the fit needs every light of the set",
                self.lights.names[i]
            )));
        }
        let t_acc = self.started.elapsed().as_secs_f64();
        if self.opts.link == Link::Logistic {
            return self.finish_logistic(tile, t_acc);
        }
        let (mips, coverage) = (self.opts.mips, self.full_coverage.clone());
        let (mut ptm, mut report) = self.finish_identity(tile, t_acc)?;
        if mips {
            let t0 = Instant::now();
            ptm.mips = identity_mips(&ptm, &coverage);
            report.mip_levels = ptm.mips.len();
            report
                .seconds
                .push(("mip levels", t0.elapsed().as_secs_f64()));
        }
        Ok((ptm, report))
    }

    fn finish_identity(self, tile: [f64; 2], t_acc: f64) -> Result<(Ptm, FitReport)> {
        let t0 = Instant::now();
        let per_texel = self.mode == Some(true);
        let (m, t) = (self.m, self.width * self.height);
        let basis = self.opts.basis;
        let wtot: f64 = self.prep.w.iter().sum();
        let mut planes = vec![vec![0f32; t]; m];
        let mut rms_map = vec![0f32; t];
        let mut report = self.base_report(per_texel);
        let g_all = if per_texel {
            DMatrix::zeros(m, m)
        } else {
            self.gram_distant()
        };
        // Common case (distant lights, no dropped sample): c = S·g and the residual with flat
        // f64 arrays, parallel over texel chunks. Other texels take the general path below.
        let slow: Vec<usize> = if per_texel {
            (0..t).filter(|&ti| !self.masked[ti]).collect()
        } else {
            self.bad
                .keys()
                .copied()
                .filter(|&ti| !self.masked[ti])
                .collect()
        };
        if !per_texel {
            let f = &self.prep.factor;
            let sf: Vec<f64> = (0..m * m).map(|q| f.s[(q / m, q % m)]).collect();
            let gf: Vec<f64> = (0..m * m).map(|q| g_all[(q / m, q % m)]).collect();
            let mut cflat = vec![0f32; t * m];
            cflat
                .par_chunks_mut(CHUNK * m)
                .zip(rms_map.par_chunks_mut(CHUNK))
                .enumerate()
                .for_each(|(ci, (cc, rr))| {
                    for (b, r) in rr.iter_mut().enumerate() {
                        let ti = ci * CHUNK + b;
                        if self.masked[ti] {
                            continue;
                        }
                        let g = &self.g[ti * m..(ti + 1) * m];
                        let mut c = [0f64; 16];
                        for i in 0..m {
                            c[i] = (0..m).map(|j| sf[i * m + j] * g[j]).sum();
                        }
                        let cg: f64 = (0..m).map(|i| c[i] * g[i]).sum();
                        let cgc: f64 = (0..m)
                            .map(|i| c[i] * (0..m).map(|j| gf[i * m + j] * c[j]).sum::<f64>())
                            .sum();
                        // Weighted residual: s − 2cᵀg + cᵀGc (exact for any c, in f64).
                        let res = self.s[ti] - 2.0 * cg + cgc;
                        *r = if wtot > 0.0 {
                            (res.max(0.0) / wtot).sqrt() as f32
                        } else {
                            0.0
                        };
                        for i in 0..m {
                            cc[b * m + i] = c[i] as f32;
                        }
                    }
                });
            for (j, plane) in planes.iter_mut().enumerate() {
                for (ti, x) in plane.iter_mut().enumerate() {
                    *x = cflat[ti * m + j];
                }
            }
        }
        let results: Vec<(usize, Vec<f64>, f64, usize, f64)> = slow
            .par_iter()
            .map(|&ti| {
                let gv = nalgebra::DVector::from_column_slice(&self.g[ti * m..(ti + 1) * m]);
                // Weighted residual: s − 2cᵀg + cᵀGc (exact for any c; f64 keeps it accurate).
                let finish = |s_op: &DMatrix<f64>, gmat: &DMatrix<f64>, wsum: f64| {
                    let c = s_op * &gv;
                    let res = self.s[ti] - 2.0 * c.dot(&gv) + c.dot(&(gmat * &c));
                    let rms = if wsum > 0.0 {
                        (res.max(0.0) / wsum).sqrt()
                    } else {
                        0.0
                    };
                    (c.iter().copied().collect::<Vec<f64>>(), rms)
                };
                if per_texel {
                    let gm = unpack(&self.gram[ti * m * (m + 1) / 2..], m);
                    let f = Factor::from_normal(gm.clone(), self.opts.rcond, self.opts.regularize);
                    let (c, rms) = finish(&f.s, &gm, self.wsum[ti]);
                    (ti, c, rms, f.rank, f.cond)
                } else {
                    let bad = &self.bad[&ti];
                    let mut gm = g_all.clone();
                    let mut wsum = wtot;
                    for &l in bad {
                        if self.prep.w[l] > 0.0 && !self.prep.held.contains(&l) {
                            remove_light(&mut gm, &self.prep.a, l, self.prep.w[l]);
                            wsum -= self.prep.w[l];
                        }
                    }
                    let f = Factor::from_normal(gm.clone(), self.opts.rcond, self.opts.regularize);
                    let (c, rms) = finish(&f.s, &gm, wsum);
                    (ti, c, rms, f.rank, f.cond)
                }
            })
            .collect();
        let mut worst_cond: f64 = 0.0;
        let mut min_rank = m;
        let mut worst_texel = 0;
        for (ti, c, rms, rank, cond) in results {
            for j in 0..m {
                planes[j][ti] = c[j] as f32;
            }
            rms_map[ti] = rms as f32;
            if rank < min_rank || (rank == min_rank && cond > worst_cond) {
                worst_texel = ti;
            }
            min_rank = min_rank.min(rank);
            worst_cond = worst_cond.max(cond);
            if rank < m {
                report.rank_deficient_texels += 1;
            }
        }
        if per_texel {
            report.rank = min_rank;
            report.cond = worst_cond;
            // Name the weak directions of the worst texel, as for a shared design.
            let np = m * (m + 1) / 2;
            let gw = unpack(&self.gram[worst_texel * np..], m);
            let fw = Factor::from_normal(gw, self.opts.rcond, self.opts.regularize);
            let (col, row) = (worst_texel % self.width, worst_texel / self.width);
            if min_rank < m {
                report.warnings.push(format!(
                    "{} texels have rank below {m} with their per-texel light directions (lowest rank {min_rank}); they get the minimum-norm solution; undetermined at texel (column {col}, row {row}): {}",
                    report.rank_deficient_texels,
                    fw.weak_directions(basis, fw.cutoff).join("; ")
                ));
            } else if worst_cond > COND_WARN {
                report.warnings.push(format!(
                    "ill-conditioned texels: worst condition number {worst_cond:.1} > {COND_WARN} at texel (column {col}, row {row}); poorly determined: {}",
                    fw.weak_directions(basis, fw.sigma[0] / COND_WARN).join("; ")
                ));
            }
            check_strict(&self.opts, &report.warnings)?;
        }
        if self.skipped > 0 {
            report.warnings.push(format!(
                "{} non-finite samples in {} texels were dropped (--skip-bad); {} of those texels lost rank",
                self.skipped,
                self.bad.len(),
                if per_texel { 0 } else { report.rank_deficient_texels }
            ));
        }
        report.skipped_samples = self.skipped;
        let ptm = Ptm {
            basis,
            width: self.width,
            height: self.height,
            link: Link::Identity,
            uv: self.opts.uv,
            mips: Vec::new(),
            tile,
            planes,
            coverage: ptm_coverage(&self.full_coverage),
        };
        report.rms = ErrorStats::of(&rms_map, &self.masked);
        report.rms_map = rms_map;
        report.coverage = partial_coverage(&self.full_coverage);
        report.masked = self.masked.iter().filter(|&&m| m).count();
        let t_solve = t0.elapsed().as_secs_f64();
        if !self.held.is_empty() {
            let t1 = Instant::now();
            let mut hs = vec![0f64; t];
            let mut hn = vec![0u32; t];
            for (&l, (k, uv)) in &self.held {
                let d = self.lights.dirs[l];
                for ti in 0..t {
                    if self.masked[ti] || !k[ti].is_finite() {
                        continue;
                    }
                    let (u, v) = match uv {
                        Some(uv) => (uv[ti][0], uv[ti][1]),
                        None => (d[0] as f32, d[1] as f32),
                    };
                    let e = ptm.eval(ti % self.width, ti / self.width, u, v) - k[ti];
                    hs[ti] += (e as f64).powi(2);
                    hn[ti] += 1;
                }
            }
            let map: Vec<f32> = hs
                .iter()
                .zip(&hn)
                .map(|(&s, &n)| {
                    if n > 0 {
                        (s / n as f64).sqrt() as f32
                    } else {
                        0.0
                    }
                })
                .collect();
            report.holdout = Some(ErrorStats::of(&map, &self.masked));
            report.seconds.push(("holdout", t1.elapsed().as_secs_f64()));
        }
        report.seconds.insert(0, ("accumulate", t_acc));
        report.seconds.insert(1, ("solve", t_solve));
        Ok((ptm, report))
    }

    fn finish_logistic(self, tile: [f64; 2], t_acc: f64) -> Result<(Ptm, FitReport)> {
        let src = if self.occ16.is_empty() {
            Source::Counts8 {
                occ: &self.occ8,
                cov: &self.cov,
            }
        } else {
            Source::Counts16 {
                occ: &self.occ16,
                cov: &self.cov,
            }
        };
        let (mut ptm, mut report) = fit_logistic(
            &src,
            &self.prep,
            &self.lights,
            (self.width, self.height),
            tile,
            &self.masked,
            &self.opts,
        )?;
        report.coverage = partial_coverage(&self.full_coverage);
        ptm.coverage = ptm_coverage(&self.full_coverage);
        report.seconds.insert(0, ("accumulate", t_acc));
        Ok((ptm, report))
    }

    fn gram_distant(&self) -> DMatrix<f64> {
        let a = &self.prep.a;
        let m = self.m;
        let mut g = DMatrix::zeros(m, m);
        for (i, &w) in self.prep.w.iter().enumerate() {
            if w > 0.0 {
                let row = a.row(i);
                g += w * row.transpose() * row;
            }
        }
        g
    }

    fn base_report(&self, per_texel: bool) -> FitReport {
        let f = &self.prep.factor;
        FitReport {
            basis: Some(self.opts.basis),
            link: Some(Link::Identity),
            uv: Some(self.opts.uv),
            lights: self.lights.len(),
            lights_fit: self.prep.w.iter().filter(|&&w| w > 0.0).count(),
            holdout_lights: self.prep.held.clone(),
            texels: self.width * self.height,
            coefficients: self.m,
            rank: f.rank,
            cond: f.cond,
            cutoff: f.cutoff,
            rcond: self.opts.rcond,
            singular_values: if per_texel {
                Vec::new()
            } else {
                f.sigma.clone()
            },
            solver: solver_words(&self.opts, f, per_texel),
            warnings: if per_texel {
                Vec::new()
            } else {
                self.prep.warnings.clone()
            },
            ..FitReport::default()
        }
    }
}

/// g += aw·k and s += w·k² per texel (texel-major g, M per texel); masked or non-finite
/// samples add nothing. Branch-free so the M-wide update vectorises.
fn accumulate<const M: usize>(
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { accumulate_avx2::<M>(g, s, k, masked, aw, w) };
    }
    accumulate_body::<M>(g, s, k, masked, aw, w)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_avx2<const M: usize>(
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    accumulate_body::<M>(g, s, k, masked, aw, w)
}

#[inline(always)]
fn accumulate_body<const M: usize>(
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    let aw: &[f64; M] = aw.try_into().unwrap();
    for (((gb, sb), &kb), &mb) in g.chunks_exact_mut(M).zip(s.iter_mut()).zip(k).zip(masked) {
        let kb = if mb || !kb.is_finite() {
            0.0
        } else {
            kb as f64
        };
        let gb: &mut [f64; M] = gb.try_into().unwrap();
        for j in 0..M {
            gb[j] += aw[j] * kb;
        }
        *sb += w * kb * kb;
    }
}

fn unpack(packed: &[f64], m: usize) -> DMatrix<f64> {
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

fn remove_light(g: &mut DMatrix<f64>, a: &DMatrix<f64>, l: usize, w: f64) {
    let row = a.row(l);
    *g -= w * row.transpose() * row;
}

fn bad_sample(texel: usize, width: usize, light: usize, value: f32) -> Error {
    Error::BadSample {
        col: texel % width,
        row: texel / width,
        light,
        value,
    }
}

/// Texels per parallel work unit of the fused product + residual kernel (a multiple of the
/// tile widths, 8 and 16).
const BLOCK: usize = 256;

/// Fits a stored stack: one f32 product C = P·K over texel blocks (parallel, deterministic),
/// fused with the exact residual pass (weighted RMS and max over the fitting lights, RMS of
/// clamped K over held-out lights). Per-texel directions go through the [`Accumulator`].
pub fn fit_stack(stack: &SampleStack, opts: &FitOptions) -> Result<(Ptm, FitReport)> {
    stack.validate()?;
    if opts.link == Link::Logistic {
        return fit_stack_logistic(stack, opts);
    }
    let (mut ptm, mut report) = fit_stack_identity(stack, opts)?;
    if opts.mips {
        let t0 = Instant::now();
        ptm.mips = identity_mips(&ptm, &stack.coverage);
        report.mip_levels = ptm.mips.len();
        report
            .seconds
            .push(("mip levels", t0.elapsed().as_secs_f64()));
    }
    Ok((ptm, report))
}

/// The logistic link refuses per-texel light directions (finite-distance lights): its Newton
/// solve shares one design per fit.
fn refuse_per_texel_logistic() -> Error {
    Error::Invalid(
        "the logistic link fits distant lights only; this stack has per-texel light directions (a bake with --light-distance): fit it with the identity link".into(),
    )
}

fn fit_stack_logistic(stack: &SampleStack, opts: &FitOptions) -> Result<(Ptm, FitReport)> {
    if stack.uv.is_some() {
        return Err(refuse_per_texel_logistic());
    }
    let prep = prepare(&stack.lights, opts)?;
    let t0 = Instant::now();
    let mask = masked(stack);
    let mut skipped = 0usize;
    let mut bad_texels = std::collections::BTreeSet::new();
    for (l, k) in stack.k.iter().enumerate() {
        for (ti, &x) in k.iter().enumerate() {
            if !mask[ti] && !x.is_finite() {
                if !opts.skip_bad {
                    return Err(bad_sample(ti, stack.width, l, x));
                }
                skipped += 1;
                bad_texels.insert(ti);
            }
        }
    }
    let t_scan = t0.elapsed().as_secs_f64();
    let src = Source::Planes {
        k: &stack.k,
        coverage: &stack.coverage,
    };
    let (mut ptm, mut report) = fit_logistic(
        &src,
        &prep,
        &stack.lights,
        (stack.width, stack.height),
        stack.tile,
        &mask,
        opts,
    )?;
    report.coverage = partial_coverage(&stack.coverage);
    ptm.coverage = ptm_coverage(&stack.coverage);
    report.skipped_samples = skipped;
    if skipped > 0 {
        report.warnings.push(format!(
            "{skipped} non-finite samples in {} texels were dropped (--skip-bad)",
            bad_texels.len()
        ));
    }
    report.seconds.insert(0, ("scan", t_scan));
    Ok((ptm, report))
}

fn fit_stack_identity(stack: &SampleStack, opts: &FitOptions) -> Result<(Ptm, FitReport)> {
    let (w, h, t) = (stack.width, stack.height, stack.texels());
    if let Some(uv) = &stack.uv {
        let mut acc = Accumulator::new(&stack.lights, w, h, opts)?;
        acc.set_coverage(&stack.coverage)?;
        for (i, (k, uv)) in stack.k.iter().zip(uv).enumerate() {
            acc.add_light_uv(i, k, uv)?;
        }
        let (ptm, mut report) = acc.finish(stack.tile)?;
        let t1 = Instant::now();
        let maxes = residual_max_per_texel(stack, &ptm, opts)?;
        report.max = Some(ErrorStats::of(&maxes, &masked(stack)));
        report.max_map = maxes;
        report
            .seconds
            .push(("max residual", t1.elapsed().as_secs_f64()));
        return Ok((ptm, report));
    }
    let t0 = Instant::now();
    let prep = prepare(&stack.lights, opts)?;
    let m = opts.basis.len();
    let n = stack.lights.len();
    // P = S·AᵀW (terms × lights), f64 → f32; rows of A in f32 for the residual.
    let f = &prep.factor;
    let mut p = vec![0f32; n * m];
    let mut af = vec![0f32; n * m];
    for i in 0..n {
        for j in 0..m {
            af[i * m + j] = prep.a[(i, j)] as f32;
            if prep.w[i] > 0.0 {
                let mut x = 0.0;
                for q in 0..m {
                    x += f.s[(j, q)] * prep.a[(i, q)];
                }
                p[i * m + j] = (x * prep.w[i]) as f32;
            }
        }
    }
    let fit: Vec<usize> = (0..n).filter(|&i| prep.w[i] > 0.0).collect();
    let wf: Vec<f32> = prep.w.iter().map(|&x| x as f32).collect();
    let wtot: f32 = fit.iter().map(|&i| wf[i]).sum();
    let mask = masked(stack);
    let t_factor = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let nb = t.div_ceil(BLOCK);
    let used: Vec<usize> = fit.iter().chain(&prep.held).copied().collect();
    let inp = KernelIn {
        k: &stack.k,
        nfit: fit.len(),
        p: used
            .iter()
            .flat_map(|&l| p[l * m..(l + 1) * m].to_vec())
            .collect(),
        a: used
            .iter()
            .flat_map(|&l| af[l * m..(l + 1) * m].to_vec())
            .collect(),
        w: used.iter().map(|&l| wf[l]).collect(),
        used,
    };
    let blocks: Vec<Block> = (0..nb)
        .into_par_iter()
        .map(|bi| {
            let start = bi * BLOCK;
            kernel(&inp, start, BLOCK.min(t - start), m)
        })
        .collect();
    let t_apply = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let mut planes = vec![vec![0f32; t]; m];
    let mut rms_map = vec![0f32; t];
    let mut max_map = vec![0f32; t];
    let mut hold_map = vec![0f32; t];
    let mut bad_texels = Vec::new();
    for (bi, b) in blocks.iter().enumerate() {
        let start = bi * BLOCK;
        let len = BLOCK.min(t - start);
        for i in 0..len {
            let ti = start + i;
            if mask[ti] {
                continue;
            }
            let ok = (0..m).all(|j| b.c[j * BLOCK + i].is_finite())
                && b.ss[i].is_finite()
                && b.hs[i].is_finite();
            if !ok {
                bad_texels.push(ti);
                continue;
            }
            for j in 0..m {
                planes[j][ti] = b.c[j * BLOCK + i];
            }
            rms_map[ti] = if wtot > 0.0 {
                (b.ss[i] / wtot).max(0.0).sqrt()
            } else {
                0.0
            };
            max_map[ti] = b.mx[i];
            if !prep.held.is_empty() {
                hold_map[ti] = (b.hs[i] / prep.held.len() as f32).sqrt();
            }
        }
    }
    let mut report = FitReport {
        basis: Some(opts.basis),
        link: Some(Link::Identity),
        uv: Some(opts.uv),
        lights: n,
        lights_fit: fit.len(),
        holdout_lights: prep.held.clone(),
        texels: t,
        masked: mask.iter().filter(|&&x| x).count(),
        coefficients: m,
        rank: f.rank,
        cond: f.cond,
        cutoff: f.cutoff,
        rcond: opts.rcond,
        singular_values: f.sigma.clone(),
        solver: solver_words(opts, f, false),
        warnings: prep.warnings.clone(),
        coverage: partial_coverage(&stack.coverage),
        ..FitReport::default()
    };
    // Texels with non-finite samples: name the first, or refit each from its finite samples.
    for &ti in &bad_texels {
        let bad: Vec<usize> = (0..n).filter(|&l| !stack.k[l][ti].is_finite()).collect();
        if !opts.skip_bad {
            return Err(bad_sample(ti, w, bad[0], stack.k[bad[0]][ti]));
        }
        report.skipped_samples += bad.len();
        let (c, rms, mx, hold, rank) = refit_texel(stack, ti, &prep, opts);
        for j in 0..m {
            planes[j][ti] = c[j];
        }
        rms_map[ti] = rms;
        max_map[ti] = mx;
        hold_map[ti] = hold;
        if rank < m {
            report.rank_deficient_texels += 1;
        }
    }
    if !bad_texels.is_empty() {
        report.warnings.push(format!(
            "{} non-finite samples in {} texels were dropped (--skip-bad); {} of those texels lost rank",
            report.skipped_samples,
            bad_texels.len(),
            report.rank_deficient_texels
        ));
    }
    let ((rms, max), hold) = rayon::join(
        || {
            rayon::join(
                || ErrorStats::of(&rms_map, &mask),
                || ErrorStats::of(&max_map, &mask),
            )
        },
        || (!prep.held.is_empty()).then(|| ErrorStats::of(&hold_map, &mask)),
    );
    report.rms = rms;
    report.max = Some(max);
    report.holdout = hold;
    report.rms_map = rms_map;
    report.max_map = max_map;
    report.seconds = vec![
        ("factor", t_factor),
        ("apply", t_apply),
        ("gather", t2.elapsed().as_secs_f64()),
    ];
    let ptm = Ptm {
        basis: opts.basis,
        width: w,
        height: h,
        link: Link::Identity,
        uv: opts.uv,
        mips: Vec::new(),
        tile: stack.tile,
        planes,
        coverage: ptm_coverage(&stack.coverage),
    };
    Ok((ptm, report))
}

fn masked(stack: &SampleStack) -> Vec<bool> {
    stack.coverage.iter().map(|&c| c <= 0.0).collect()
}

/// Results of one texel block: coefficients (term-major, BLOCK stride), weighted squared
/// residual sum, max |residual|, squared held-out error sum.
struct Block {
    c: Vec<f32>,
    ss: Vec<f32>,
    mx: Vec<f32>,
    hs: Vec<f32>,
}

/// Inputs of the fused kernel shared by all blocks. Lights are taken in `used` order: the
/// fitting lights first (`nfit` of them), then the held-out lights.
struct KernelIn<'a> {
    k: &'a [Vec<f32>],
    used: Vec<usize>,
    nfit: usize,
    /// Per used light: its row of P (terms), its row of A in f32 (terms), its weight.
    p: Vec<f32>,
    a: Vec<f32>,
    w: Vec<f32>,
}

/// Texels per register tile: one 256-bit vector of f32.
const LANES: usize = 8;

thread_local! {
    /// Per-thread packing buffer, reused across blocks.
    static PACK: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// One block: dispatches to an AVX2+FMA build of the same code when the CPU has it (the
/// result is deterministic on a given machine; FMA changes the last bits versus SSE2).
fn kernel(inp: &KernelIn, start: usize, len: usize, m: usize) -> Block {
    PACK.with(|buf| {
        let mut buf = buf.borrow_mut();
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            pack::<LANES512>(inp, start, len, &mut buf);
            // SAFETY: the CPU supports AVX-512F.
            return unsafe {
                match m {
                    6 => kernel_avx512::<6>(inp, &buf, len),
                    11 => kernel_avx512::<11>(inp, &buf, len),
                    _ => unreachable!("bases have 6 or 11 terms"),
                }
            };
        }
        pack::<LANES>(inp, start, len, &mut buf);
        match m {
            6 => kernel_m::<6>(inp, &buf, len),
            11 => kernel_m::<11>(inp, &buf, len),
            _ => unreachable!("bases have 6 or 11 terms"),
        }
    })
}

/// Copies the block's K into tile-major order, `[tile][used light][lane]`, zero-padded: the
/// rows stream from memory once, and the tile kernel then reads contiguous memory (as a GEMM
/// packs its panels).
fn pack<const L: usize>(inp: &KernelIn, start: usize, len: usize, buf: &mut Vec<f32>) {
    let nu = inp.used.len();
    let tiles = len.div_ceil(L);
    buf.clear();
    buf.resize(tiles * nu * L, 0.0);
    for (li, &l) in inp.used.iter().enumerate() {
        let row = &inp.k[l][start..start + len];
        let mut chunks = row.chunks_exact(L);
        for (tile, chunk) in chunks.by_ref().enumerate() {
            let o = (tile * nu + li) * L;
            // Fixed-size copy: one 32-byte move, no memmove call.
            let dst: &mut [f32; L] = (&mut buf[o..o + L]).try_into().unwrap();
            *dst = chunk.try_into().unwrap();
        }
        let rest = chunks.remainder();
        let o = ((len / L) * nu + li) * L;
        for (q, &x) in rest.iter().enumerate() {
            buf[o + q] = x;
        }
    }
}

fn kernel_m<const M: usize>(inp: &KernelIn, packed: &[f32], len: usize) -> Block {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { kernel_avx2::<M>(inp, packed, len) };
    }
    kernel_body::<M, false>(inp, packed, len)
}

/// The tile kernel in AVX2 + FMA intrinsics: M accumulators of 8 texels stay in registers.
/// Same maths and order as [`kernel_body`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn kernel_avx2<const M: usize>(inp: &KernelIn, packed: &[f32], len: usize) -> Block {
    use std::arch::x86_64::*;
    let mut out = Block {
        c: vec![0f32; M * BLOCK],
        ss: vec![0f32; BLOCK],
        mx: vec![0f32; BLOCK],
        hs: vec![0f32; BLOCK],
    };
    let nu = inp.used.len();
    let (p, a) = (inp.p.as_ptr(), inp.a.as_ptr());
    let abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    for (tile, kt) in packed.chunks_exact(nu * LANES).enumerate() {
        let b0 = tile * LANES;
        let kp = kt.as_ptr();
        let mut acc = [zero; M];
        for li in 0..inp.nfit {
            // SAFETY (all pointer reads): li < nu, j < M; kt has nu·LANES floats, p and a nu·M.
            let kv = _mm256_loadu_ps(kp.add(li * LANES));
            for j in 0..M {
                acc[j] = _mm256_fmadd_ps(_mm256_broadcast_ss(&*p.add(li * M + j)), kv, acc[j]);
            }
        }
        let (mut ss, mut mx, mut hs) = (zero, zero, zero);
        for li in 0..nu {
            let kv = _mm256_loadu_ps(kp.add(li * LANES));
            let mut pred = zero;
            for j in 0..M {
                pred = _mm256_fmadd_ps(_mm256_broadcast_ss(&*a.add(li * M + j)), acc[j], pred);
            }
            if li < inp.nfit {
                let r = _mm256_sub_ps(kv, pred);
                ss = _mm256_fmadd_ps(_mm256_mul_ps(_mm256_set1_ps(inp.w[li]), r), r, ss);
                // Non-finite samples show up in ss; max only has to order finite values.
                mx = _mm256_max_ps(_mm256_and_ps(r, abs_mask), mx);
            } else {
                let pc = _mm256_min_ps(_mm256_max_ps(pred, zero), one);
                let r = _mm256_sub_ps(pc, kv);
                hs = _mm256_fmadd_ps(r, r, hs);
            }
        }
        let n = LANES.min(len - b0);
        let mut lanes = [0f32; LANES];
        let mut put = |v: __m256, dst: &mut [f32]| {
            _mm256_storeu_ps(lanes.as_mut_ptr(), v);
            dst[..n].copy_from_slice(&lanes[..n]);
        };
        for j in 0..M {
            put(acc[j], &mut out.c[j * BLOCK + b0..]);
        }
        put(ss, &mut out.ss[b0..]);
        put(mx, &mut out.mx[b0..]);
        put(hs, &mut out.hs[b0..]);
    }
    out
}

/// Texels per AVX-512 tile.
#[cfg(target_arch = "x86_64")]
const LANES512: usize = 16;

/// [`kernel_avx2`] with 16-texel tiles in AVX-512 registers (same maths and order).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn kernel_avx512<const M: usize>(inp: &KernelIn, packed: &[f32], len: usize) -> Block {
    use std::arch::x86_64::*;
    const L: usize = LANES512;
    let mut out = Block {
        c: vec![0f32; M * BLOCK],
        ss: vec![0f32; BLOCK],
        mx: vec![0f32; BLOCK],
        hs: vec![0f32; BLOCK],
    };
    let nu = inp.used.len();
    let (p, a) = (inp.p.as_ptr(), inp.a.as_ptr());
    let (zero, one) = (_mm512_setzero_ps(), _mm512_set1_ps(1.0));
    for (tile, kt) in packed.chunks_exact(nu * L).enumerate() {
        let b0 = tile * L;
        let kp = kt.as_ptr();
        let mut acc = [zero; M];
        for li in 0..inp.nfit {
            // SAFETY (all pointer reads): li < nu, j < M; kt has nu·L floats, p and a nu·M.
            let kv = _mm512_loadu_ps(kp.add(li * L));
            for j in 0..M {
                acc[j] = _mm512_fmadd_ps(_mm512_set1_ps(*p.add(li * M + j)), kv, acc[j]);
            }
        }
        let (mut ss, mut mx, mut hs) = (zero, zero, zero);
        for li in 0..nu {
            let kv = _mm512_loadu_ps(kp.add(li * L));
            let mut pred = zero;
            for j in 0..M {
                pred = _mm512_fmadd_ps(_mm512_set1_ps(*a.add(li * M + j)), acc[j], pred);
            }
            if li < inp.nfit {
                let r = _mm512_sub_ps(kv, pred);
                ss = _mm512_fmadd_ps(_mm512_mul_ps(_mm512_set1_ps(inp.w[li]), r), r, ss);
                mx = _mm512_max_ps(_mm512_abs_ps(r), mx);
            } else {
                let pc = _mm512_min_ps(_mm512_max_ps(pred, zero), one);
                let r = _mm512_sub_ps(pc, kv);
                hs = _mm512_fmadd_ps(r, r, hs);
            }
        }
        let n = L.min(len - b0);
        let mut lanes = [0f32; L];
        let mut put = |v: __m512, dst: &mut [f32]| {
            _mm512_storeu_ps(lanes.as_mut_ptr(), v);
            dst[..n].copy_from_slice(&lanes[..n]);
        };
        for j in 0..M {
            put(acc[j], &mut out.c[j * BLOCK + b0..]);
        }
        put(ss, &mut out.ss[b0..]);
        put(mx, &mut out.mx[b0..]);
        put(hs, &mut out.hs[b0..]);
    }
    out
}

#[inline(always)]
fn fma<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Unclamped K of used light `li` from the tile's accumulated coefficients.
#[inline(always)]
fn predict<const M: usize, const FMA: bool>(
    a: &[f32],
    li: usize,
    acc: &[[f32; LANES]; M],
) -> [f32; LANES] {
    let al: &[f32; M] = a[li * M..(li + 1) * M].try_into().unwrap();
    let mut pred = [0f32; LANES];
    for j in 0..M {
        for q in 0..LANES {
            pred[q] = fma::<FMA>(al[j], acc[j][q], pred[q]);
        }
    }
    pred
}

/// Per tile of LANES texels: c = Σ_l P[l]·k[l] with M × LANES accumulators in registers, then
/// the residual pass over the same tile's K (now in L1).
#[inline(always)]
fn kernel_body<const M: usize, const FMA: bool>(
    inp: &KernelIn,
    packed: &[f32],
    len: usize,
) -> Block {
    let mut out = Block {
        c: vec![0f32; M * BLOCK],
        ss: vec![0f32; BLOCK],
        mx: vec![0f32; BLOCK],
        hs: vec![0f32; BLOCK],
    };
    let nu = inp.used.len();
    for (tile, kt) in packed.chunks_exact(nu * LANES).enumerate() {
        let b0 = tile * LANES;
        let mut acc = [[0f32; LANES]; M];
        for li in 0..inp.nfit {
            let kv: &[f32; LANES] = kt[li * LANES..(li + 1) * LANES].try_into().unwrap();
            let pl: &[f32; M] = inp.p[li * M..(li + 1) * M].try_into().unwrap();
            for j in 0..M {
                for q in 0..LANES {
                    acc[j][q] = fma::<FMA>(pl[j], kv[q], acc[j][q]);
                }
            }
        }
        let (mut ss, mut mx, mut hs) = ([0f32; LANES], [0f32; LANES], [0f32; LANES]);
        for li in 0..nu {
            let kv: &[f32; LANES] = kt[li * LANES..(li + 1) * LANES].try_into().unwrap();
            let pred = predict::<M, FMA>(&inp.a, li, &acc);
            if li < inp.nfit {
                let wl = inp.w[li];
                for q in 0..LANES {
                    let r = kv[q] - pred[q];
                    ss[q] = fma::<FMA>(wl * r, r, ss[q]);
                    // A plain compare-select (one vmaxps); non-finite samples show up in ss.
                    let ar = r.abs();
                    mx[q] = if ar > mx[q] { ar } else { mx[q] };
                }
            } else {
                for q in 0..LANES {
                    let r = pred[q].clamp(0.0, 1.0) - kv[q];
                    hs[q] = fma::<FMA>(r, r, hs[q]);
                }
            }
        }
        let n = LANES.min(len - b0);
        for j in 0..M {
            out.c[j * BLOCK + b0..j * BLOCK + b0 + n].copy_from_slice(&acc[j][..n]);
        }
        out.ss[b0..b0 + n].copy_from_slice(&ss[..n]);
        out.mx[b0..b0 + n].copy_from_slice(&mx[..n]);
        out.hs[b0..b0 + n].copy_from_slice(&hs[..n]);
    }
    out
}

/// Refits one texel from its finite samples (f64 normal equations, same cutoff), returning
/// coefficients, weighted RMS, max residual, held-out RMS and rank.
fn refit_texel(
    stack: &SampleStack,
    ti: usize,
    prep: &Prepared,
    opts: &FitOptions,
) -> (Vec<f32>, f32, f32, f32, usize) {
    let m = opts.basis.len();
    let n = stack.lights.len();
    let good = |l: usize| prep.w[l] > 0.0 && stack.k[l][ti].is_finite();
    let mut g = DMatrix::zeros(m, m);
    let mut rhs = nalgebra::DVector::zeros(m);
    let mut wsum = 0.0;
    for l in (0..n).filter(|&l| good(l)) {
        let row = prep.a.row(l);
        g += prep.w[l] * row.transpose() * row;
        rhs += prep.w[l] * stack.k[l][ti] as f64 * row.transpose();
        wsum += prep.w[l];
    }
    let f = Factor::from_normal(g, opts.rcond, opts.regularize);
    let c = &f.s * rhs;
    let (mut ss, mut mx) = (0.0f64, 0.0f64);
    for l in (0..n).filter(|&l| good(l)) {
        let r = stack.k[l][ti] as f64 - (prep.a.row(l) * &c)[0];
        ss += prep.w[l] * r * r;
        mx = mx.max(r.abs());
    }
    let (mut hs, mut hn) = (0.0f64, 0);
    for &l in prep.held.iter().filter(|&&l| stack.k[l][ti].is_finite()) {
        let r = (prep.a.row(l) * &c)[0].clamp(0.0, 1.0) - stack.k[l][ti] as f64;
        hs += r * r;
        hn += 1;
    }
    let rms = if wsum > 0.0 { (ss / wsum).sqrt() } else { 0.0 };
    let hold = if hn > 0 { (hs / hn as f64).sqrt() } else { 0.0 };
    (
        c.iter().map(|&x| x as f32).collect(),
        rms as f32,
        mx as f32,
        hold as f32,
        f.rank,
    )
}

/// Max |residual| per texel over the fitting lights, for per-texel directions.
fn residual_max_per_texel(stack: &SampleStack, ptm: &Ptm, opts: &FitOptions) -> Result<Vec<f32>> {
    let (w, _) = light_weights(&stack.lights, opts)?;
    let uv = stack.uv.as_ref().expect("per-texel stack");
    let m = opts.basis.len();
    Ok((0..stack.texels())
        .into_par_iter()
        .map(|ti| {
            let c: Vec<f32> = (0..m).map(|j| ptm.planes[j][ti]).collect();
            let mut mx = 0f32;
            for l in 0..stack.lights.len() {
                let k = stack.k[l][ti];
                let p = uv[l][ti];
                if w[l] > 0.0 && k.is_finite() && p[0].is_finite() && p[1].is_finite() {
                    let (u, v) = opts.uv.of_projected(p[0], p[1]);
                    mx = mx.max((k - opts.basis.eval(&c, u, v)).abs());
                }
            }
            mx
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The portable tile kernel and the AVX2 one agree (the portable one is what non-x86 and
    /// pre-AVX2 machines run, so it is tested here even where AVX2 exists).
    #[test]
    fn portable_and_simd_kernels_agree() {
        let (n, len, m) = (37usize, 203usize, 6usize);
        let k: Vec<Vec<f32>> = (0..n)
            .map(|l| {
                (0..len)
                    .map(|t| ((t * 13 + l * 7) % 29) as f32 / 29.0)
                    .collect()
            })
            .collect();
        let nu = n;
        let inp = KernelIn {
            k: &k,
            used: (0..n).collect(),
            nfit: n - 3,
            p: (0..nu * m)
                .map(|i| ((i * 5) % 11) as f32 / 50.0 - 0.1)
                .collect(),
            a: (0..nu * m)
                .map(|i| ((i * 3) % 7) as f32 / 7.0 - 0.4)
                .collect(),
            w: (0..nu).map(|i| 0.5 + (i % 3) as f32 * 0.25).collect(),
        };
        let mut buf = Vec::new();
        pack::<LANES>(&inp, 0, len, &mut buf);
        let want = kernel_body::<6, false>(&inp, &buf, len);
        let got = kernel_m::<6>(&inp, &buf, len);
        for (name, x, y) in [
            ("c", &want.c, &got.c),
            ("ss", &want.ss, &got.ss),
            ("mx", &want.mx, &got.mx),
            ("hs", &want.hs, &got.hs),
        ] {
            for (a, b) in x.iter().zip(y.iter()) {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                    "{name}: {a} vs {b}"
                );
            }
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            let mut buf16 = Vec::new();
            pack::<LANES512>(&inp, 0, len, &mut buf16);
            // SAFETY: the CPU supports AVX-512F.
            let got = unsafe { kernel_avx512::<6>(&inp, &buf16, len) };
            for (a, b) in want.c.iter().zip(&got.c) {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                    "avx512 c: {a} vs {b}"
                );
            }
            for (a, b) in want.ss.iter().zip(&got.ss) {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                    "avx512 ss: {a} vs {b}"
                );
            }
        }
        assert!(want.c[..len].iter().any(|&c| c != 0.0));
        assert!(want.hs[..len].iter().any(|&c| c != 0.0));
    }
}
