//! The logistic fit of one image: level 0 from its samples and, when asked, every MIP level,
//! each pooled from the one above and fitted (a farm part only those inside its rows; the
//! merge the deeper ones from the parts' pooled counts): the PTM and its report (errors,
//! iterations, classes, warnings).
use std::ops::Range;
use std::time::Instant;

use super::block::{fit_level, LevelFit};
use super::pool::{pool, Pooled, Source};
use super::tables::{self, Tables};
use crate::learned::learn;
use crate::mip::Footprint;
use crate::shard::partition::local_levels;
use crate::simd::Isa;
use crate::solve::factor::{self, SharedDesign};
use crate::solve::options::{
    check_strict, ErrorStats, FitOptions, FitReport, LearnedStats, LogisticStats,
};
use crate::{Diagnostic, Result};
use ptm_format::{LearnedTable, Level, LightSet, Link, Ptm};

/// The warnings a logistic fit's level-0 statistics raise (beside the light set's).
pub(crate) fn data_warnings(stats: &LogisticStats) -> Vec<Diagnostic> {
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
fn fit_levels(
    tables: &Tables,
    isa: Isa,
    src: &Source,
    src_w: usize,
    levels: &[Footprint],
    keep_last: bool,
) -> (Vec<Level>, Option<Pooled>) {
    // Each level pools the one above (exact counts, or coverage-weighted K), is fitted, and
    // replaces it: at most two levels' data are alive, the first a quarter of level 0.
    let mut out = Vec::with_capacity(levels.len());
    let mut above: Option<Pooled> = None;
    let mut above_w = src_w;
    for fp in levels {
        let pooled = match &above {
            None => pool(src, above_w, *fp),
            Some(p) => pool(&p.source(), above_w, *fp),
        };
        // A coarse texel is fitted when any of its footprint is covered (the kernel leaves
        // out texels whose every sample is missing).
        let level = fit_level(
            tables,
            &pooled.source(),
            fp.width * fp.height,
            &|_| true,
            isa,
        );
        out.push(Level {
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
pub(crate) fn coarse_levels(
    lights: &LightSet,
    opts: &FitOptions,
    cov: &[u32],
    occ: &[Vec<u32>],
    src_w: usize,
    levels: &[Footprint],
) -> Result<Vec<Level>> {
    let prep = factor::prepare(lights, opts)?;
    let (tables, isa) = if opts.basis.is_learned() {
        let (isa, lambda) = learned_ridge(&prep, lights, opts)?;
        let l = learn::given(lights, &prep.w, &prep.held, opts, lambda)?.ok_or_else(|| {
            crate::Error::Invalid("the coarse levels of a learned basis need its tables".into())
        })?;
        (l.tables, isa)
    } else {
        let (tables, isa, _) = tables::for_fit(&prep, lights, opts)?;
        (tables, isa)
    };
    let src = Source::Counts32 { occ, cov };
    Ok(fit_levels(&tables, isa, &src, src_w, levels, false).0)
}

/// The kernel and the ridge λ of a learned basis's fit: those of its polynomial start (the
/// basis it is learned from, of as many terms).
fn learned_ridge(prep: &SharedDesign, lights: &LightSet, opts: &FitOptions) -> Result<(Isa, f64)> {
    let start = FitOptions {
        basis: crate::learned::start_basis(opts.basis.len()).expect("checked when prepared"),
        given_basis: None,
        ..opts.clone()
    };
    let (_, isa, lambda) = tables::for_fit(prep, lights, &start)?;
    Ok((isa, lambda))
}

/// Learns the basis of `opts` (a learned one) from `src` (`texels` texels, `masked` those not
/// to fit) and returns its tables and statistics, fitting no texel against them: the first
/// step of a farm shard's fit, on the whole bake's subsample ([`crate::Accumulator::learn_basis`]).
pub(crate) fn learn_basis(
    src: &Source,
    prep: &SharedDesign,
    lights: &LightSet,
    masked: &[bool],
    opts: &FitOptions,
) -> Result<(LearnedTable, LearnedStats)> {
    let (_, lambda) = learned_ridge(prep, lights, opts)?;
    let l = learn_unmasked(src, prep, lights, masked, opts, lambda)?;
    Ok((l.table, l.stats))
}

/// [`learn::learn`] on the texels of `src` that `masked` does not mask.
fn learn_unmasked(
    src: &Source,
    prep: &SharedDesign,
    lights: &LightSet,
    masked: &[bool],
    opts: &FitOptions,
    lambda: f64,
) -> Result<learn::Learned> {
    let live = |ti: usize| !masked[ti];
    learn::learn(
        src,
        masked.len(),
        &live,
        lights,
        &prep.w,
        &prep.held,
        opts,
        lambda,
    )
}

/// The logistic fit of one image from `src` (level 0 and, with `opts.mips`, every MIP level),
/// on a prepared distant-light design: the PTM and its report (errors, iterations, classes).
/// `part`: the image is rows `rows` of one `height` rows tall (a farm shard, see
/// [`crate::shard`]): only the levels whose footprints lie in those rows are fitted, and the
/// last one's pooled counts are returned when the merge must pool deeper levels from them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_image(
    src: &Source,
    prep: &SharedDesign,
    lights: &LightSet,
    size: (usize, usize),
    tile: [f64; 2],
    masked: &[bool],
    opts: &FitOptions,
    part: Option<(Range<usize>, usize)>,
) -> Result<(Ptm, FitReport, Option<Pooled>)> {
    let (w, h) = size;
    let t = w * h;
    let m = opts.basis.len();
    let n = lights.len();
    let t0 = Instant::now();
    let (tables, isa, lambda, learned) = if opts.basis.is_learned() {
        let (isa, lambda) = learned_ridge(prep, lights, opts)?;
        let l = match learn::given(lights, &prep.w, &prep.held, opts, lambda)? {
            Some(l) => l,
            None if part.is_some() => {
                return Err(crate::Error::Invalid(format!(
                    "a learned basis ({}) is learned from the whole bake's subsample: a farm \
                     shard fits against the basis it is given (FitOptions::given_basis)",
                    opts.basis.name()
                )))
            }
            None => learn_unmasked(src, prep, lights, masked, opts, lambda)?,
        };
        (l.tables, isa, lambda, Some((l.table, l.stats)))
    } else {
        let (tables, isa, lambda) = tables::for_fit(prep, lights, opts)?;
        (tables, isa, lambda, None)
    };
    let f = &prep.factor;
    let t_factor = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let fits = fit_level(&tables, src, t, &|ti| !masked[ti], isa);
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
        kernel: isa.name(),
    };
    drop(fitted);
    let LevelFit {
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
            fit_levels(&tables, isa, src, w, &chain[1..], false)
        }
        (Some((rows, height)), true) => {
            let (local, deeper) = local_levels(w, *height, rows.clone());
            fit_levels(&tables, isa, src, w, &local, deeper)
        }
    };
    let t_mips = t2.elapsed().as_secs_f64();
    let mut warnings = prep.warnings.clone();
    warnings.extend(data_warnings(&stats));
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
            "{prefix}logistic maximum likelihood (binomial deviance), Newton per texel from the least-squares logit fit, ridge lambda={lambda:e} x mean eigenvalue (rho={:.3e}), tolerance {:e} per unit weight, at most {} iterations, weight={}",
            tables.ridge,
            opts.tolerance,
            opts.max_iterations,
            opts.weight.name(),
            prefix = match &learned {
                Some((_, st)) => format!(
                    "learned basis of {} terms ({}x{} bilinear tables over the hemispherical (u, v) square, roughness {:e} x texels, alternating Newton on {} texels, {} alternations), then ",
                    st.terms, st.grid, st.grid, st.roughness, st.texels, st.alternations
                ),
                None => String::new(),
            },
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
    let (table, stats) = learned.map_or((None, None), |(t, s)| (Some(t), Some(s)));
    if let Some(st) = &stats {
        report.seconds.insert(1, ("learn", st.seconds));
    }
    report.learned = stats;
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
        learned: table,
    };
    Ok((ptm, report, pooled))
}
