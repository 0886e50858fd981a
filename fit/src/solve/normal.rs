//! The identity link's streaming data and its solve: per texel the sums of its normal
//! equations, AᵀW·k and kᵀW·k (per-texel directions: also the packed AᵀWA and Σw), accumulated
//! light by light in f64, beside the held-out lights' planes and the dropped samples; then per
//! texel c = S·g with the shared S (distant lights), or its own normal matrix factored
//! (per-texel directions, or texels with dropped samples), and the weighted residual from the
//! same sums: s − 2cᵀg + cᵀGc, exact for any c.
use std::collections::BTreeMap;
use std::time::Instant;

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::factor::{remove_light, solver_words, unpack, Factor, SharedDesign};
use super::kernel::accumulate;
use super::options::{
    check_strict, partial_coverage, ptm_coverage, ErrorStats, FitOptions, FitReport, COND_WARN,
};
use crate::{Diagnostic, Error, Result};
use ptm_format::{LightSet, Link, Ptm};

/// Texels per parallel work unit of the sums.
const CHUNK: usize = 4096;

/// A held-out light's K plane and, for per-texel directions, its (u, v) plane.
type HeldLight = (Vec<f32>, Option<Vec<[f32; 2]>>);

/// What the sums are of: the fit asked for and the image, as the [`crate::Accumulator`] holds
/// them.
pub(super) struct Image<'a> {
    pub opts: &'a FitOptions,
    pub lights: &'a LightSet,
    pub prep: &'a SharedDesign,
    pub width: usize,
    pub height: usize,
    /// Texels left out (coverage 0).
    pub masked: &'a [bool],
    /// The coverage map given (empty: every texel covered).
    pub coverage: &'a [f32],
}

/// The texels of the slow path that decide the per-texel diagnostics: the lowest rank, the
/// worst condition number, and the texel that has them.
struct Worst {
    rank: usize,
    cond: f64,
    texel: usize,
}

/// The identity link's per-texel sums, held-out planes and dropped samples.
pub(super) struct NormalSums {
    m: usize,
    /// Texel-major AᵀW·k, m per texel.
    g: Vec<f64>,
    /// Per-texel packed upper triangle of AᵀWA, m(m+1)/2 per texel (per-texel directions).
    gram: Vec<f64>,
    /// Per-texel Σ w·k².
    s: Vec<f64>,
    /// Per-texel Σ w over the lights added (per-texel directions).
    wsum: Vec<f64>,
    /// Held-out light index → its K plane and, per texel, (u, v) when per-texel.
    held: BTreeMap<usize, HeldLight>,
    /// Dropped samples per texel (skip_bad).
    bad: BTreeMap<usize, Vec<usize>>,
    skipped: usize,
}

impl NormalSums {
    /// Empty sums of `texels` texels and `m` terms (the logistic link keeps none: `Σ w·k²` is
    /// allocated here only for the identity link).
    pub fn new(link: Link, texels: usize, m: usize) -> NormalSums {
        NormalSums {
            m,
            g: Vec::new(),
            gram: Vec::new(),
            s: if link == Link::Logistic {
                Vec::new()
            } else {
                vec![0.0; texels]
            },
            wsum: Vec::new(),
            held: BTreeMap::new(),
            bad: BTreeMap::new(),
            skipped: 0,
        }
    }

    /// Allocates the sums the first light's kind needs (`per_texel`: (u, v) per texel).
    pub fn start(&mut self, per_texel: bool, texels: usize) {
        let (t, m) = (texels, self.m);
        if per_texel {
            self.gram = vec![0.0; t * m * (m + 1) / 2];
            self.g = vec![0.0; t * m];
            self.wsum = vec![0.0; t];
        } else {
            self.g = vec![0.0; t * m];
        }
    }

    /// Bytes the per-texel buffers hold now (allocated capacities).
    pub fn held_bytes(&self) -> u128 {
        fn cap<T>(v: &Vec<T>) -> u128 {
            (v.capacity() * std::mem::size_of::<T>()) as u128
        }
        let held: u128 = self
            .held
            .values()
            .map(|(k, uv)| cap(k) + uv.as_ref().map_or(0, cap))
            .sum();
        cap(&self.g) + cap(&self.gram) + cap(&self.s) + cap(&self.wsum) + held
    }

    /// Finds non-finite samples of unmasked texels: an error naming the first, or (skip_bad)
    /// records them. Returns the texels whose sample must be left out.
    fn scan_bad(
        &mut self,
        index: usize,
        k: &[f32],
        uv: Option<&[[f32; 2]]>,
        img: &Image<'_>,
    ) -> Result<()> {
        let bad: Vec<usize> = (0..k.len())
            .filter(|&t| {
                !img.masked[t]
                    && (!k[t].is_finite()
                        || uv.is_some_and(|uv| !(uv[t][0].is_finite() && uv[t][1].is_finite())))
            })
            .collect();
        if let Some(&t) = bad.first() {
            if !img.opts.skip_bad {
                return Err(Error::bad_sample(t, img.width, index, k[t]));
            }
            self.skipped += bad.len();
            for &t in &bad {
                self.bad.entry(t).or_default().push(index);
            }
        }
        Ok(())
    }

    /// Adds the K plane of distant light `index` (or keeps it, if held out).
    pub fn add_distant(&mut self, index: usize, k: &[f32], img: &Image<'_>) -> Result<()> {
        self.scan_bad(index, k, None, img)?;
        if img.prep.held.contains(&index) {
            self.held.insert(index, (k.to_vec(), None));
            return Ok(());
        }
        let w = img.prep.w[index];
        if w == 0.0 {
            return Ok(());
        }
        let m = self.m;
        let aw: Vec<f64> = (0..m).map(|j| w * img.prep.a[(index, j)]).collect();
        let masked = img.masked;
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

    /// Adds light `index` with per-texel (u, v) (or keeps it, if held out).
    pub fn add_per_texel(
        &mut self,
        index: usize,
        k: &[f32],
        uv: &[[f32; 2]],
        img: &Image<'_>,
    ) -> Result<()> {
        self.scan_bad(index, k, Some(uv), img)?;
        if img.prep.held.contains(&index) {
            self.held.insert(index, (k.to_vec(), Some(uv.to_vec())));
            return Ok(());
        }
        let w = img.prep.w[index];
        if w == 0.0 {
            return Ok(());
        }
        let (m, basis, uv_map) = (self.m, img.opts.basis, img.opts.uv);
        let np = m * (m + 1) / 2;
        let masked = img.masked;
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

    /// Solves every texel (`per_texel`: the lights came with per-texel (u, v)): the PTM and its
    /// report, without the accumulation's time.
    pub fn solve(
        &self,
        img: &Image<'_>,
        per_texel: bool,
        tile: [f64; 2],
    ) -> Result<(Ptm, FitReport)> {
        let t0 = Instant::now();
        let (m, t) = (self.m, img.width * img.height);
        let mut planes = vec![vec![0f32; t]; m];
        let mut rms_map = vec![0f32; t];
        let mut report = self.base_report(img, per_texel);
        let g_all = if per_texel {
            DMatrix::zeros(m, m)
        } else {
            self.gram_distant(img)
        };
        if !per_texel {
            self.solve_shared(img, &g_all, &mut planes, &mut rms_map);
        }
        let worst = self.solve_each(
            img,
            &g_all,
            per_texel,
            &mut planes,
            &mut rms_map,
            &mut report,
        );
        if per_texel {
            self.warn_per_texel(img, &worst, &mut report)?;
        }
        if self.skipped > 0 {
            report.warnings.push(Diagnostic::SkippedSamples {
                samples: self.skipped,
                texels: self.bad.len(),
                lost_rank: Some(if per_texel {
                    0
                } else {
                    report.rank_deficient_texels
                }),
            });
        }
        report.skipped_samples = self.skipped;
        let ptm = Ptm {
            basis: img.opts.basis,
            width: img.width,
            height: img.height,
            link: Link::Identity,
            uv: img.opts.uv,
            mips: Vec::new(),
            tile,
            planes,
            coverage: ptm_coverage(img.coverage),
            learned: None,
        };
        report.rms = ErrorStats::of(&rms_map, img.masked);
        report.rms_map = rms_map;
        report.coverage = partial_coverage(img.coverage);
        report.masked = img.masked.iter().filter(|&&m| m).count();
        let t_solve = t0.elapsed().as_secs_f64();
        if !self.held.is_empty() {
            let t1 = Instant::now();
            report.holdout = Some(self.holdout_error(img, &ptm));
            report.seconds.push(("holdout", t1.elapsed().as_secs_f64()));
        }
        report.seconds.insert(0, ("solve", t_solve));
        Ok((ptm, report))
    }

    /// The fast path (distant lights): c = S·g and the weighted residual of every unmasked
    /// texel with flat f64 arrays, parallel over texel chunks. Texels with dropped samples are
    /// solved again by [`NormalSums::solve_each`].
    fn solve_shared(
        &self,
        img: &Image<'_>,
        g_all: &DMatrix<f64>,
        planes: &mut [Vec<f32>],
        rms_map: &mut [f32],
    ) {
        let (m, t) = (self.m, img.width * img.height);
        let wtot: f64 = img.prep.w.iter().sum();
        let f = &img.prep.factor;
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
                    if img.masked[ti] {
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

    /// The slow path: a texel of its own normal matrix (per-texel directions: every unmasked
    /// texel; distant lights: those with dropped samples, whose Gram matrix is the shared one
    /// less their lights) factored and solved in f64. Counts rank-deficient texels in
    /// `report` and returns the worst texel.
    fn solve_each(
        &self,
        img: &Image<'_>,
        g_all: &DMatrix<f64>,
        per_texel: bool,
        planes: &mut [Vec<f32>],
        rms_map: &mut [f32],
        report: &mut FitReport,
    ) -> Worst {
        let (m, t) = (self.m, img.width * img.height);
        let wtot: f64 = img.prep.w.iter().sum();
        let slow: Vec<usize> = if per_texel {
            (0..t).filter(|&ti| !img.masked[ti]).collect()
        } else {
            self.bad
                .keys()
                .copied()
                .filter(|&ti| !img.masked[ti])
                .collect()
        };
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
                    let f = Factor::from_normal(gm.clone(), img.opts.rcond, img.opts.regularize);
                    let (c, rms) = finish(&f.s, &gm, self.wsum[ti]);
                    (ti, c, rms, f.rank, f.cond)
                } else {
                    let bad = &self.bad[&ti];
                    let mut gm = g_all.clone();
                    let mut wsum = wtot;
                    for &l in bad {
                        if img.prep.w[l] > 0.0 && !img.prep.held.contains(&l) {
                            remove_light(&mut gm, &img.prep.a, l, img.prep.w[l]);
                            wsum -= img.prep.w[l];
                        }
                    }
                    let f = Factor::from_normal(gm.clone(), img.opts.rcond, img.opts.regularize);
                    let (c, rms) = finish(&f.s, &gm, wsum);
                    (ti, c, rms, f.rank, f.cond)
                }
            })
            .collect();
        let mut worst = Worst {
            rank: m,
            cond: 0.0,
            texel: 0,
        };
        for (ti, c, rms, rank, cond) in results {
            for j in 0..m {
                planes[j][ti] = c[j] as f32;
            }
            rms_map[ti] = rms as f32;
            if rank < worst.rank || (rank == worst.rank && cond > worst.cond) {
                worst.texel = ti;
            }
            worst.rank = worst.rank.min(rank);
            worst.cond = worst.cond.max(cond);
            if rank < m {
                report.rank_deficient_texels += 1;
            }
        }
        worst
    }

    /// Per-texel directions: the report's rank and condition are the worst texel's, and its
    /// weak directions are named, as for a shared design.
    fn warn_per_texel(&self, img: &Image<'_>, worst: &Worst, report: &mut FitReport) -> Result<()> {
        let m = self.m;
        report.rank = worst.rank;
        report.cond = worst.cond;
        let np = m * (m + 1) / 2;
        let gw = unpack(&self.gram[worst.texel * np..], m);
        let fw = Factor::from_normal(gw, img.opts.rcond, img.opts.regularize);
        let (col, row) = (worst.texel % img.width, worst.texel / img.width);
        let basis = img.opts.basis;
        if worst.rank < m {
            report.warnings.push(Diagnostic::TexelsRankDeficient {
                texels: report.rank_deficient_texels,
                coefficients: m,
                lowest_rank: worst.rank,
                col,
                row,
                directions: fw.weak_directions(basis, fw.cutoff),
            });
        } else if worst.cond > COND_WARN {
            report.warnings.push(Diagnostic::TexelsIllConditioned {
                cond: worst.cond,
                limit: COND_WARN,
                col,
                row,
                directions: fw.weak_directions(basis, fw.sigma[0] / COND_WARN),
            });
        }
        check_strict(img.opts, &report.warnings)
    }

    /// The hold-out pass: per texel, the RMS error of clamped K on the held-out lights.
    fn holdout_error(&self, img: &Image<'_>, ptm: &Ptm) -> ErrorStats {
        let t = img.width * img.height;
        let mut hs = vec![0f64; t];
        let mut hn = vec![0u32; t];
        for (&l, (k, uv)) in &self.held {
            let d = img.lights.dirs[l];
            for ti in 0..t {
                if img.masked[ti] || !k[ti].is_finite() {
                    continue;
                }
                let (u, v) = match uv {
                    Some(uv) => (uv[ti][0], uv[ti][1]),
                    None => (d[0] as f32, d[1] as f32),
                };
                let e = ptm.eval(ti % img.width, ti / img.width, u, v) - k[ti];
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
        ErrorStats::of(&map, img.masked)
    }

    fn gram_distant(&self, img: &Image<'_>) -> DMatrix<f64> {
        let a = &img.prep.a;
        let m = self.m;
        let mut g = DMatrix::zeros(m, m);
        for (i, &w) in img.prep.w.iter().enumerate() {
            if w > 0.0 {
                let row = a.row(i);
                g += w * row.transpose() * row;
            }
        }
        g
    }

    fn base_report(&self, img: &Image<'_>, per_texel: bool) -> FitReport {
        let f = &img.prep.factor;
        FitReport {
            basis: Some(img.opts.basis),
            link: Some(Link::Identity),
            uv: Some(img.opts.uv),
            lights: img.lights.len(),
            lights_fit: img.prep.w.iter().filter(|&&w| w > 0.0).count(),
            holdout_lights: img.prep.held.clone(),
            texels: img.width * img.height,
            coefficients: self.m,
            rank: f.rank,
            cond: f.cond,
            cutoff: f.cutoff,
            rcond: img.opts.rcond,
            singular_values: if per_texel {
                Vec::new()
            } else {
                f.sigma.clone()
            },
            solver: solver_words(img.opts, f, per_texel),
            warnings: if per_texel {
                Vec::new()
            } else {
                img.prep.warnings.clone()
            },
            ..FitReport::default()
        }
    }
}
