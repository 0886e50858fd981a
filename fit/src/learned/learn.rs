//! Learning the tables of a learned basis (the maths: `learned.rs`): the deterministic
//! subsample, damped Newton on the coefficients per texel and on the tables, the alternation,
//! and the logistic kernel's tables for the learned rows (the gauge: `gauge.rs`).
use std::time::Instant;

use rayon::prelude::*;

use super::band::Band;
use super::gauge::gauge;
use super::problem::{rows, Problem};
use super::rough::{roughness, roughness_matrix};
use super::{
    start_basis, EXTRAPOLATION, EXTRAPOLATION_GROWTH, EXTRAPOLATION_MAX, GRID, MAX_ALTERNATIONS,
    MAX_SUBSAMPLE, MIN_DEVIANCE, ROUGHNESS, STOP,
};
use crate::logistic::pool::Source;
use crate::logistic::tables::Tables;
use crate::solve::options::{FitOptions, LearnedStats};
use crate::{Error, Result};
use ptm_format::basis::sigmoid64;
use ptm_format::hash::splitmix64;
use ptm_format::learned::bilinear;
use ptm_format::{LearnedTable, LightSet, UvMap};

/// Seed of the subsample's hash.
const SEED: u64 = 0x6c65_6172_6e65_6421;

/// The subsample: up to [`MAX_SUBSAMPLE`] of the texels `live`, those whose hash of their
/// index is smallest, in increasing index order.
fn subsample(texels: usize, live: &dyn Fn(usize) -> bool) -> Vec<usize> {
    let mut cand: Vec<(u64, usize)> = (0..texels)
        .filter(|&t| live(t))
        .map(|t| (splitmix64(SEED ^ t as u64), t))
        .collect();
    if cand.len() > MAX_SUBSAMPLE {
        cand.select_nth_unstable(MAX_SUBSAMPLE);
        cand.truncate(MAX_SUBSAMPLE);
    }
    let mut out: Vec<usize> = cand.into_iter().map(|(_, t)| t).collect();
    out.sort_unstable();
    out
}

/// The `n` texels of `0..texels` of smallest subsample hash, by hash. `learn`'s subsample is
/// the first [`MAX_SUBSAMPLE`] live ones of this order, by index: a farm shard finds the whole
/// bake's by testing texels in this order, tracing no more. O(texels) time, O(n) memory.
pub fn subsample_order(texels: usize, n: usize) -> Vec<usize> {
    let mut heap = std::collections::BinaryHeap::with_capacity(n + 1);
    for t in 0..texels {
        let h = splitmix64(SEED ^ t as u64);
        if heap.len() < n {
            heap.push((h, t));
        } else if heap.peek().is_some_and(|&(top, _)| h < top) {
            heap.pop();
            heap.push((h, t));
        }
    }
    heap.into_sorted_vec().into_iter().map(|(_, t)| t).collect()
}

/// Binomial deviance of fraction k at logit z: softplus(z) − k·z, stable in both tails.
#[inline]
fn dev(k: f64, z: f64) -> f64 {
    z.max(0.0) + (-z.abs()).exp().ln_1p() - k * z
}

/// Solves the k × k SPD system `h` (dense, row-major) · x = g by Cholesky; `None` when not
/// positive definite.
fn chol_solve(h: &mut [f64], g: &[f64], k: usize) -> Option<Vec<f64>> {
    for j in 0..k {
        let mut s = h[j * k + j];
        for q in 0..j {
            s -= h[j * k + q] * h[j * k + q];
        }
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        let d = s.sqrt();
        h[j * k + j] = d;
        for i in j + 1..k {
            let mut s = h[i * k + j];
            for q in 0..j {
                s -= h[i * k + q] * h[j * k + q];
            }
            h[i * k + j] = s / d;
        }
    }
    let mut y = g.to_vec();
    for i in 0..k {
        for q in 0..i {
            y[i] -= h[i * k + q] * y[q];
        }
        y[i] /= h[i * k + i];
    }
    for i in (0..k).rev() {
        for q in i + 1..k {
            y[i] -= h[q * k + i] * y[q];
        }
        y[i] /= h[i * k + i];
    }
    Some(y)
}

/// Deviance of texel x with coefficients c under rows a (plus nothing else).
fn texel_dev(p: &Problem, a: &[f64], x: usize, c: &[f64]) -> f64 {
    let k = p.k;
    let kx = &p.kv[x * p.n..(x + 1) * p.n];
    let mut s = 0.0;
    for n in 0..p.n {
        if kx[n] < 0.0 {
            continue;
        }
        let z: f64 = (0..k).map(|j| a[n * k + j] * c[j]).sum();
        s += p.omega[n] * dev(kx[n] as f64, z);
    }
    s
}

/// `steps` damped Newton steps per texel on its coefficients (rows `a` fixed), in parallel.
fn coefficient_steps(p: &Problem, a: &[f64], c: &mut [f64], steps: usize) {
    let k = p.k;
    c.par_chunks_mut(k).enumerate().for_each(|(x, cx)| {
        let kx = &p.kv[x * p.n..(x + 1) * p.n];
        for _ in 0..steps {
            let mut g: Vec<f64> = cx.iter().map(|v| p.rho * v).collect();
            let mut h = vec![0f64; k * k];
            for j in 0..k {
                h[j * k + j] = p.rho;
            }
            let mut f0 = 0.5 * p.rho * cx.iter().map(|v| v * v).sum::<f64>();
            for n in 0..p.n {
                if kx[n] < 0.0 {
                    continue;
                }
                let an = &a[n * k..(n + 1) * k];
                let z: f64 = (0..k).map(|j| an[j] * cx[j]).sum();
                let s = sigmoid64(z);
                let kk = kx[n] as f64;
                f0 += p.omega[n] * dev(kk, z);
                let r = p.omega[n] * (s - kk);
                let w = p.omega[n] * s * (1.0 - s);
                for i in 0..k {
                    g[i] += r * an[i];
                    let wi = w * an[i];
                    for j in 0..=i {
                        h[i * k + j] += wi * an[j];
                    }
                }
            }
            let Some(step) = chol_solve(&mut h, &g, k) else {
                return;
            };
            let mut alpha = 1.0;
            let mut trial = vec![0f64; k];
            let mut accepted = false;
            for _ in 0..12 {
                for j in 0..k {
                    trial[j] = cx[j] - alpha * step[j];
                }
                let f = texel_dev(p, a, x, &trial)
                    + 0.5 * p.rho * trial.iter().map(|v| v * v).sum::<f64>();
                if f <= f0 {
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                return;
            }
            let moved = (0..k).fold(0f64, |m, j| m.max((alpha * step[j]).abs()));
            cx.copy_from_slice(&trial);
            if moved < 1e-7 {
                return;
            }
        }
    });
}

/// Σₓ deviance of the subsample (summed in texel order: the same for any thread count).
fn total_dev(p: &Problem, a: &[f64], c: &[f64]) -> f64 {
    let per: Vec<f64> = (0..p.s)
        .into_par_iter()
        .map(|x| texel_dev(p, a, x, &c[x * p.k..(x + 1) * p.k]))
        .collect();
    per.iter().sum()
}

/// RMS of σ − K over the subsample's fitting samples.
fn rms(p: &Problem, a: &[f64], c: &[f64]) -> f64 {
    let k = p.k;
    let per: Vec<(f64, f64)> = (0..p.s)
        .into_par_iter()
        .map(|x| {
            let (mut s, mut m) = (0.0, 0.0);
            for n in 0..p.n {
                let kv = p.kv[x * p.n + n];
                if kv < 0.0 {
                    continue;
                }
                let z: f64 = (0..k).map(|j| a[n * k + j] * c[x * k + j]).sum();
                let e = sigmoid64(z) - kv as f64;
                s += p.omega[n] * e * e;
                m += p.omega[n];
            }
            (s, m)
        })
        .collect();
    let (s, m) = per.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    (s / m.max(1e-300)).sqrt()
}

/// One damped Newton step on the tables for fixed coefficients. Returns the new objective's
/// table part (deviance + roughness).
fn table_step(p: &Problem, dtd: &[f64], b: &mut Vec<f64>, c: &[f64], f0: f64) -> f64 {
    let (k, g2) = (p.k, GRID * GRID);
    let a = rows(p, b);
    let kk = k * k;
    // Per light: r_n = Σₓ ω(σ − k)cₓ and M_n = Σₓ ωσ(1−σ)cₓcₓᵀ (lower triangle), texels in
    // order within a light: the same sums for any thread count.
    let per: Vec<(Vec<f64>, Vec<f64>)> = (0..p.n)
        .into_par_iter()
        .map(|n| {
            let an = &a[n * k..(n + 1) * k];
            let mut r = vec![0f64; k];
            let mut m = vec![0f64; kk];
            for x in 0..p.s {
                let kv = p.kv[x * p.n + n];
                if kv < 0.0 {
                    continue;
                }
                let cx = &c[x * k..(x + 1) * k];
                let z: f64 = (0..k).map(|j| an[j] * cx[j]).sum();
                let s = sigmoid64(z);
                let rr = p.omega[n] * (s - kv as f64);
                let w = p.omega[n] * s * (1.0 - s);
                for i in 0..k {
                    r[i] += rr * cx[i];
                    let wi = w * cx[i];
                    for j in 0..=i {
                        m[i * k + j] += wi * cx[j];
                    }
                }
            }
            (r, m)
        })
        .collect();
    let np = g2 * k;
    let bw = 2 * GRID * k + k - 1;
    let mut h = Band::new(np, bw);
    let mut grad = vec![0f64; np];
    for (n, (r, m)) in per.iter().enumerate() {
        for &(c1, w1) in &p.cells[n] {
            for i in 0..k {
                grad[c1 * k + i] += w1 * r[i];
            }
            for &(c2, w2) in &p.cells[n] {
                let ww = w1 * w2;
                if ww == 0.0 {
                    continue;
                }
                for i in 0..k {
                    for j in 0..k {
                        let (pi, pj) = (c1 * k + i, c2 * k + j);
                        if pi >= pj {
                            let mij = if i >= j { m[i * k + j] } else { m[j * k + i] };
                            h.add(pi, pj, ww * mij);
                        }
                    }
                }
            }
        }
    }
    for c1 in 0..g2 {
        for c2 in c1.saturating_sub(2 * GRID)..=c1 {
            let d = dtd[c1 * g2 + c2];
            if d == 0.0 {
                continue;
            }
            for j in 0..k {
                h.add(c1 * k + j, c2 * k + j, p.mu * d);
            }
        }
        for c2 in 0..g2 {
            let d = dtd[c1 * g2 + c2];
            if d != 0.0 {
                for j in 0..k {
                    grad[c1 * k + j] += p.mu * d * b[c2 * k + j];
                }
            }
        }
    }
    let trace: f64 = (0..np).map(|i| h.v[i * (bw + 1)]).sum::<f64>() / np as f64;
    let mut eps = 1e-9 * trace.max(1e-300);
    let step = loop {
        let mut hh = Band {
            n: h.n,
            bw: h.bw,
            v: h.v.clone(),
        };
        for i in 0..np {
            hh.add(i, i, eps);
        }
        if let Some(s) = hh.solve(&grad) {
            break s;
        }
        eps *= 100.0;
        if eps > trace {
            return f0;
        }
    };
    let obj = |b: &[f64]| total_dev(p, &rows(p, b), c) + 0.5 * p.mu * roughness(dtd, b, g2, k);
    let mut alpha = 1.0;
    let mut trial = vec![0f64; np];
    while alpha > 1e-4 {
        for i in 0..np {
            trial[i] = b[i] - alpha * step[i];
        }
        let f = obj(&trial);
        if f <= f0 {
            *b = trial;
            return f;
        }
        alpha *= 0.5;
    }
    f0
}

/// The learned tables, the kernel's tables for them, and what the learning did.
pub(crate) struct Learned {
    pub table: LearnedTable,
    pub tables: Tables,
    pub stats: LearnedStats,
}

/// Learns the basis of `opts.basis` from `src` (`texels` texels, `live` those to fit) over
/// `lights` with weights `w` and held-out lights `held`, then builds the kernel's tables.
#[allow(clippy::too_many_arguments)]
pub(crate) fn learn(
    src: &Source,
    texels: usize,
    live: &(dyn Fn(usize) -> bool + Sync),
    lights: &LightSet,
    w: &[f64],
    held: &[usize],
    opts: &FitOptions,
    lambda: f64,
) -> Result<Learned> {
    let t0 = Instant::now();
    let k = opts.basis.len();
    let start = start_basis(k).expect("checked by `check`");
    let fit: Vec<usize> = (0..lights.len()).filter(|&i| w[i] > 0.0).collect();
    let n = fit.len();
    let uv: Vec<(f64, f64)> = lights
        .dirs
        .iter()
        .map(|d| UvMap::Hemispherical.of_dir(*d))
        .collect();
    // The subsample's K, light by light (each light's plane read whole, in parallel).
    let sub = subsample(texels, live);
    let planes: Vec<Vec<f32>> = fit
        .par_iter()
        .map(|&l| {
            let mut buf = vec![0f32; texels];
            src.fill(l, 0, &mut buf);
            sub.iter().map(|&t| buf[t]).collect()
        })
        .collect();
    let mut keep = Vec::new();
    let mut kv = Vec::new();
    for i in 0..sub.len() {
        if planes.iter().any(|p| p[i] >= 0.0) {
            keep.push(i);
            kv.extend(planes.iter().map(|p| p[i]));
        }
    }
    drop(planes);
    // The held-out lights' K on the same texels: the learning keeps the tables of the
    // alternation whose held-out RMS error was lowest (early stopping).
    let held_planes: Vec<Vec<f32>> = held
        .par_iter()
        .map(|&l| {
            let mut buf = vec![0f32; texels];
            src.fill(l, 0, &mut buf);
            keep.iter().map(|&i| buf[sub[i]]).collect()
        })
        .collect();
    let held_check = HeldOut {
        kv: held_planes,
        cells: held
            .iter()
            .map(|&l| bilinear(GRID, uv[l].0, uv[l].1))
            .collect(),
    };
    let s = keep.len();
    if s == 0 {
        return Err(Error::Invalid(
            "no texel has a fitting sample to learn the basis from".into(),
        ));
    }
    let omega: Vec<f64> = fit.iter().map(|&l| w[l]).collect();
    let cells: Vec<[(usize, f64); 4]> = fit
        .iter()
        .map(|&l| bilinear(GRID, uv[l].0, uv[l].1))
        .collect();
    let weight_sum: f64 = (0..s)
        .map(|x| {
            (0..n)
                .filter(|&q| kv[x * n + q] >= 0.0)
                .map(|q| omega[q])
                .sum::<f64>()
        })
        .sum();
    // The start: the polynomial basis sampled on the grid, [cell][term].
    let g2 = GRID * GRID;
    let mut b = vec![0f64; g2 * k];
    let mut mono = vec![0f64; k];
    for j in 0..GRID {
        for i in 0..GRID {
            let (u, v) = node(i, j);
            start.terms(u, v, &mut mono);
            b[(j * GRID + i) * k..(j * GRID + i + 1) * k].copy_from_slice(&mono);
        }
    }
    let mut p = Problem {
        k,
        s,
        n,
        kv,
        omega,
        cells,
        rho: 0.0,
        mu: ROUGHNESS * s as f64,
        weight_sum,
    };
    let ridge = |p: &Problem, a: &[f64]| {
        let trace: f64 = (0..p.n)
            .map(|q| p.omega[q] * (0..k).map(|j| a[q * k + j].powi(2)).sum::<f64>())
            .sum();
        lambda * trace / k as f64
    };
    let dtd = roughness_matrix(GRID);
    let mut c = vec![0f64; s * k];
    let a = rows(&p, &b);
    p.rho = ridge(&p, &a);
    coefficient_steps(&p, &a, &mut c, 30);
    let deviance_start = total_dev(&p, &a, &c);
    let rms_start = rms(&p, &a, &c);
    // The roughness in units of what the polynomial leaves unexplained: μ = λ·S/d₀.
    p.mu /= (deviance_start / p.weight_sum).max(MIN_DEVIANCE);
    let coef_ridge = |p: &Problem, c: &[f64]| 0.5 * p.rho * c.iter().map(|x| x * x).sum::<f64>();
    let mut f_table = deviance_start + 0.5 * p.mu * roughness(&dtd, &b, g2, k);
    let mut j_prev = f_table + coef_ridge(&p, &c);
    let mut alternations = 0;
    // Early stopping on the held-out lights (when the fit holds some out): the tables, the
    // coefficients and the alternation of the lowest held-out RMS error so far.
    let mut best = (held_check.rms(&p, &b, &c), b.clone(), c.clone(), 0u32);
    let mut beta = EXTRAPOLATION;
    // The previous alternation's tables and coefficients, before its extrapolation.
    let mut prev = (b.clone(), c.clone());
    while alternations < MAX_ALTERNATIONS {
        alternations += 1;
        table_step(&p, &dtd, &mut b, &c, f_table);
        let a = rows(&p, &b);
        p.rho = ridge(&p, &a);
        coefficient_steps(&p, &a, &mut c, 1);
        let dv = total_dev(&p, &a, &c);
        f_table = dv + 0.5 * p.mu * roughness(&dtd, &b, g2, k);
        let mut j = f_table + coef_ridge(&p, &c);
        // Extrapolation: β times the step since the previous alternation further, kept when it
        // lowers J (from the second alternation on).
        let trial = (alternations > 1).then(|| {
            let ext = |x: &[f64], x0: &[f64]| -> Vec<f64> {
                x.iter()
                    .zip(x0)
                    .map(|(v, v0)| v + beta * (v - v0))
                    .collect()
            };
            let (bt, ct) = (ext(&b, &prev.0), ext(&c, &prev.1));
            let ft = total_dev(&p, &rows(&p, &bt), &ct) + 0.5 * p.mu * roughness(&dtd, &bt, g2, k);
            let jt = ft + coef_ridge(&p, &ct);
            (bt, ct, ft, jt)
        });
        prev = (b.clone(), c.clone());
        match trial {
            Some((bt, ct, ft, jt)) if jt < j => {
                (b, c, f_table, j) = (bt, ct, ft, jt);
                beta = (beta * EXTRAPOLATION_GROWTH).min(EXTRAPOLATION_MAX);
            }
            Some(_) => beta = EXTRAPOLATION,
            None => {}
        }
        let fell = j_prev - j;
        j_prev = j;
        if let Some(hd) = held_check.rms(&p, &b, &c) {
            if best.0.is_some_and(|b0| hd < b0) {
                best = (Some(hd), b.clone(), c.clone(), alternations);
            } else if alternations >= best.3 + PATIENCE {
                break;
            }
        }
        if fell < STOP * j.abs() {
            break;
        }
    }
    let kept = if best.0.is_some() {
        b = best.1;
        c = best.2;
        best.3
    } else {
        alternations
    };
    let a = rows(&p, &b);
    let deviance = total_dev(&p, &a, &c);
    let rms_end = rms(&p, &a, &c);
    let table = gauge(&p, &b, &c);
    let tables = tables_of(&table, lights, w, held, opts, lambda);
    let stats = LearnedStats {
        terms: k,
        grid: GRID,
        roughness: ROUGHNESS,
        texels: s,
        alternations,
        kept,
        deviance_start: deviance_start / p.weight_sum,
        deviance: deviance / p.weight_sum,
        rms_start,
        rms: rms_end,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok(Learned {
        table,
        tables,
        stats,
    })
}

/// The logistic kernel's tables for fitting texels against the stored (f32) `table` (so a file
/// evaluates what was fitted), with the fit's weights `w`, held-out lights and ridge.
fn tables_of(
    table: &LearnedTable,
    lights: &LightSet,
    w: &[f64],
    held: &[usize],
    opts: &FitOptions,
    lambda: f64,
) -> Tables {
    let mut design = vec![vec![0f64; table.terms]; lights.len()];
    for (d, row) in lights.dirs.iter().zip(design.iter_mut()) {
        let (u, v) = UvMap::Hemispherical.of_dir(*d);
        table.terms(u, v, row);
    }
    Tables::learned(
        &design,
        w,
        held,
        lambda,
        opts.tolerance,
        opts.max_iterations,
    )
}

/// What [`learn`] returns for a basis learned elsewhere (`opts.given_basis`: a farm shard's,
/// from the whole bake's subsample). Refuses a table of another term count than the basis.
pub(crate) fn given(
    lights: &LightSet,
    w: &[f64],
    held: &[usize],
    opts: &FitOptions,
    lambda: f64,
) -> Result<Option<Learned>> {
    let Some(g) = &opts.given_basis else {
        return Ok(None);
    };
    let (table, stats) = (&g.0, &g.1);
    table
        .check(opts.basis.len(), "the given learned basis")
        .map_err(Error::Invalid)?;
    Ok(Some(Learned {
        tables: tables_of(table, lights, w, held, opts, lambda),
        table: table.clone(),
        stats: stats.clone(),
    }))
}

/// Alternations without a lower held-out RMS error before the learning stops.
const PATIENCE: u32 = 3;

/// The held-out lights' K on the subsample and their grid cells.
struct HeldOut {
    /// K `[held light][texel]`, < 0 where a sample is missing.
    kv: Vec<Vec<f32>>,
    cells: Vec<[(usize, f64); 4]>,
}

impl HeldOut {
    /// RMS of σ − K over the held-out samples under tables `b` and coefficients `c` (the
    /// error a render sees; the deviance rewards confidence too much to stop on: it rose on
    /// jersey from the first alternation while this fell); `None` without held-out lights.
    fn rms(&self, p: &Problem, b: &[f64], c: &[f64]) -> Option<f64> {
        if self.kv.is_empty() {
            return None;
        }
        let k = p.k;
        let per: Vec<(f64, f64)> = self
            .kv
            .par_iter()
            .zip(&self.cells)
            .map(|(kv, cells)| {
                let mut a = vec![0f64; k];
                for &(cell, w) in cells {
                    for j in 0..k {
                        a[j] += w * b[cell * k + j];
                    }
                }
                let (mut d, mut m) = (0.0, 0.0);
                for (x, &kx) in kv.iter().enumerate() {
                    if kx < 0.0 {
                        continue;
                    }
                    let z: f64 = (0..k).map(|j| a[j] * c[x * k + j]).sum();
                    d += (sigmoid64(z) - kx as f64).powi(2);
                    m += 1.0;
                }
                (d, m)
            })
            .collect();
        let (d, m) = per.iter().fold((0.0, 0.0), |s, x| (s.0 + x.0, s.1 + x.1));
        (m > 0.0).then(|| (d / m).sqrt())
    }
}

/// (u, v) of grid node (column i, row j).
pub(super) fn node(i: usize, j: usize) -> (f64, f64) {
    let s = (GRID - 1) as f64;
    (-1.0 + 2.0 * i as f64 / s, -1.0 + 2.0 * j as f64 / s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_subsample_is_the_first_live_texels_of_the_subsample_order() {
        for (texels, live_every) in [(100_000usize, 3usize), (5000, 2), (300, 1)] {
            let live = |t: usize| t.is_multiple_of(live_every);
            let want = subsample(texels, &live);
            let order = subsample_order(texels, texels);
            let mut got: Vec<usize> = order.iter().copied().filter(|&t| live(t)).collect();
            got.truncate(MAX_SUBSAMPLE);
            got.sort_unstable();
            assert_eq!(got, want, "{texels} texels, every {live_every}th live");
            // A prefix of the order is the order of a prefix.
            let few = subsample_order(texels, 50.min(texels));
            assert_eq!(few[..], order[..few.len()]);
        }
    }

    #[test]
    fn the_subsample_is_deterministic_and_bounded() {
        let a = subsample(100_000, &|t| t % 3 != 0);
        let b = subsample(100_000, &|t| t % 3 != 0);
        assert_eq!(a, b);
        assert_eq!(a.len(), MAX_SUBSAMPLE);
        assert!(a.windows(2).all(|w| w[0] < w[1]) && a.iter().all(|t| t % 3 != 0));
        assert_eq!(subsample(50, &|_| true), (0..50).collect::<Vec<_>>());
    }
}
