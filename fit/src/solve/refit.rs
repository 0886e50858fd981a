//! Fits of a stored sample stack ([`fit_stack`]): the identity link's blocked f32 product and
//! residual pass (over [`super::kernel`]), the logistic link on the stack's planes, and the
//! per-texel f64 refits of texels whose samples were dropped.
use std::time::Instant;

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::accumulator::Accumulator;
use super::factor::{light_weights, prepare, solver_words, Factor, SharedDesign};
use super::kernel::{kernel, Block, KernelIn, BLOCK};
use super::options::{partial_coverage, ptm_coverage, ErrorStats, FitOptions, FitReport};
use crate::logistic::image::fit_image;
use crate::logistic::pool::Source;
use crate::mip::identity_mips;
use crate::simd::Isa;
use crate::{Diagnostic, Error, Result, SampleStack};
use ptm_format::{Link, Ptm};

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

fn fit_stack_logistic(stack: &SampleStack, opts: &FitOptions) -> Result<(Ptm, FitReport)> {
    if stack.uv.is_some() {
        // Its Newton solve shares one design per fit.
        return Err(Error::LogisticNeedsDistantLights);
    }
    let prep = prepare(&stack.lights, opts)?;
    let t0 = Instant::now();
    let mask = masked(stack);
    let mut skipped = 0usize;
    let mut bad_texels = std::collections::BTreeSet::new();
    // Most stacks have no non-finite sample: a branch-free test per plane, in parallel, finds
    // the planes that do; only those are walked (in order, so the first bad sample is named).
    let has_bad: Vec<bool> = stack
        .k
        .par_iter()
        .map(|k| !k.iter().fold(true, |ok, x| ok & x.is_finite()))
        .collect();
    for (l, k) in stack.k.iter().enumerate().filter(|&(l, _)| has_bad[l]) {
        for (ti, &x) in k.iter().enumerate() {
            if !mask[ti] && !x.is_finite() {
                if !opts.skip_bad {
                    return Err(Error::bad_sample(ti, stack.width, l, x));
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
    let (mut ptm, mut report, _) = fit_image(
        &src,
        &prep,
        &stack.lights,
        (stack.width, stack.height),
        stack.tile,
        &mask,
        opts,
        None,
    )?;
    report.coverage = partial_coverage(&stack.coverage);
    ptm.coverage = ptm_coverage(&stack.coverage);
    report.skipped_samples = skipped;
    if skipped > 0 {
        report.warnings.push(Diagnostic::SkippedSamples {
            samples: skipped,
            texels: bad_texels.len(),
            lost_rank: None,
        });
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
    let build = Isa::detect();
    let blocks: Vec<Block> = (0..nb)
        .into_par_iter()
        .map(|bi| {
            let start = bi * BLOCK;
            kernel(&inp, start, BLOCK.min(t - start), m, build)
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
            return Err(Error::bad_sample(ti, w, bad[0], stack.k[bad[0]][ti]));
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
        report.warnings.push(Diagnostic::SkippedSamples {
            samples: report.skipped_samples,
            texels: bad_texels.len(),
            lost_rank: Some(report.rank_deficient_texels),
        });
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
        learned: None,
    };
    Ok((ptm, report))
}

fn masked(stack: &SampleStack) -> Vec<bool> {
    stack.coverage.iter().map(|&c| c <= 0.0).collect()
}

/// coefficients, weighted RMS, max residual, held-out RMS and rank.
fn refit_texel(
    stack: &SampleStack,
    ti: usize,
    prep: &SharedDesign,
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
