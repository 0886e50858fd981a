//! The streaming [`Accumulator`] of `ptm bake --fit`: samples arrive light by light and are
//! reduced to per-texel sums (identity link) or exact counts (logistic link), then `finish`
//! solves every texel.
use std::collections::BTreeMap;
use std::time::Instant;

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::factor::{prepare, remove_light, solver_words, unpack, Factor, Prepared};
use super::kernel::accumulate;
use super::options::{
    check_strict, holdout_indices, partial_coverage, ptm_coverage, ErrorStats, FitOptions,
    FitReport, COND_WARN,
};
use super::refit::{bad_sample, refuse_per_texel_logistic};
use super::{fit_logistic, identity_mips};
use crate::logistic::Source;
use crate::{Diagnostic, Error, Result};
use ptm_format::{LightSet, Link, Ptm};

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
    mode: Mode,
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

/// How the lights added so far give their directions; the first light added decides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// No light added yet.
    Empty,
    /// [`Accumulator::add_light`]: one direction per light, shared by every texel.
    Distant,
    /// [`Accumulator::add_light_uv`]: (u, v) per texel (finite-distance lights).
    PerTexel,
}

/// The texels of the slow path that decide the per-texel diagnostics: the lowest rank, the
/// worst condition number, and the texel that has them.
struct Worst {
    rank: usize,
    cond: f64,
    texel: usize,
}

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
            mode: Mode::Empty,
            masked: vec![false; t],
            held: BTreeMap::new(),
            bad: BTreeMap::new(),
            skipped: 0,
            started,
        })
    }

    /// The light-set warnings found when factoring (before any sample is added).
    pub fn warnings(&self) -> &[Diagnostic] {
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

    /// Bytes a streaming fit of `texels` × `lights` holds once every light is added, with a
    /// coverage map set ([`Accumulator::set_coverage`]) and `spp` footprint samples per texel:
    /// what [`Accumulator::held_bytes`] then measures, less the few per-light and per-term
    /// tables and the samples `skip_bad` drops (data-dependent). `per_texel`: the lights come
    /// with per-texel (u, v) ([`Accumulator::add_light_uv`], finite-distance lights).
    ///
    /// Per texel: a mask byte and the f32 coverage; identity link: the f64 sums AᵀW·k and
    /// Σw·k² (per-texel directions also the packed AᵀWA and Σw) and the K plane (and (u, v))
    /// of each held-out light; logistic link: the u32 covered-sample count and the occluded
    /// counts of every light ([`Accumulator::count_bytes`] each). In u128, so that absurd
    /// requests are measured rather than overflow.
    pub fn memory_bytes(
        texels: usize,
        lights: usize,
        opts: &FitOptions,
        spp: u32,
        per_texel: bool,
    ) -> u128 {
        let (t, n) = (texels as u128, lights as u128);
        let m = opts.basis.len() as u128;
        let f64s = match opts.link {
            Link::Logistic => 0,
            Link::Identity if per_texel => m * (m + 1) / 2 + m + 2,
            Link::Identity => m + 1,
        };
        let per_light = match opts.link {
            Link::Logistic => Self::count_bytes(Link::Logistic, spp) as u128,
            Link::Identity => 0,
        };
        let held = match opts.link {
            Link::Logistic => 0,
            Link::Identity => holdout_indices(lights, opts.holdout).len() as u128,
        };
        let held_per_texel = if per_texel { 4 + 8 } else { 4 };
        let cov = match opts.link {
            Link::Logistic => 4,
            Link::Identity => 0,
        };
        let per_texel_bytes = 1 + 4 + cov + 8 * f64s + per_light * n + held * held_per_texel;
        // The light set's "added" flags.
        t.saturating_mul(per_texel_bytes).saturating_add(n)
    }

    /// Bytes the accumulator's per-texel buffers hold now (allocated capacities): the figure
    /// [`Accumulator::memory_bytes`] predicts.
    pub fn held_bytes(&self) -> u128 {
        fn cap<T>(v: &Vec<T>) -> u128 {
            (v.capacity() * std::mem::size_of::<T>()) as u128
        }
        let held: u128 = self
            .held
            .values()
            .map(|(k, uv)| cap(k) + uv.as_ref().map_or(0, cap))
            .sum();
        [
            cap(&self.g),
            cap(&self.gram),
            cap(&self.s),
            cap(&self.wsum),
            cap(&self.seen),
            cap(&self.masked),
            cap(&self.cov),
            cap(&self.full_coverage),
            held,
        ]
        .iter()
        .sum::<u128>()
            + self.occ8.iter().map(cap).sum::<u128>()
            + self.occ16.iter().map(cap).sum::<u128>()
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
        // Filled in place: the plane is allocated at exactly its size (`memory_bytes`).
        if spp <= u8::MAX as u32 {
            let mut plane = vec![0u8; t];
            for (ti, x) in plane.iter_mut().enumerate() {
                *x = count(ti)? as u8;
            }
            self.occ8[index] = plane;
        } else {
            let mut plane = vec![0u16; t];
            for (ti, x) in plane.iter_mut().enumerate() {
                *x = count(ti)?;
            }
            self.occ16[index] = plane;
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
        let mode = if per_texel {
            Mode::PerTexel
        } else {
            Mode::Distant
        };
        match self.mode {
            // The logistic link keeps counts (add_counts), not sums.
            Mode::Empty if self.opts.link == Link::Logistic => self.mode = mode,
            Mode::Empty => {
                self.mode = mode;
                if per_texel {
                    self.gram = vec![0.0; t * self.m * (self.m + 1) / 2];
                    self.g = vec![0.0; t * self.m];
                    self.wsum = vec![0.0; t];
                } else {
                    self.g = vec![0.0; t * self.m];
                }
            }
            held if held != mode => {
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
        self.check_complete()?;
        let t_acc = self.started.elapsed().as_secs_f64();
        if self.opts.link == Link::Logistic {
            let (ptm, report, _) = self.finish_logistic(tile, t_acc, None)?;
            return Ok((ptm, report));
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

    /// Solves the rows of a farm shard: this accumulator holds rows `rows` of an image
    /// `height` rows tall ([`crate::shard`]). Level 0 is fitted as [`Accumulator::finish`] fits
    /// it. MIP levels: the identity link leaves them all to the merge (averages of the merged
    /// coefficients); the logistic link fits here the levels whose footprints lie in these
    /// rows and returns, when the chain goes deeper, the last one's pooled counts, from which
    /// the merge fits the rest.
    pub fn finish_part(
        mut self,
        tile: [f64; 2],
        rows: std::ops::Range<usize>,
        height: usize,
    ) -> Result<(Ptm, FitReport, crate::shard::PartLevels)> {
        let weight = self.opts.weight;
        if self.opts.link == Link::Identity {
            self.opts.mips = false;
            let (ptm, report) = self.finish(tile)?;
            return Ok((ptm, report, crate::shard::PartLevels::default()));
        }
        if rows.len() != self.height || rows.end > height {
            return Err(Error::Invalid(format!(
                "rows {}..{} of {height} for an accumulator of {} rows",
                rows.start, rows.end, self.height
            )));
        }
        self.check_complete()?;
        let t_acc = self.started.elapsed().as_secs_f64();
        let (mut ptm, report, pooled) = self.finish_logistic(tile, t_acc, Some((rows, height)))?;
        let counts = pooled.and_then(|p| p.into_counts());
        let part = crate::shard::PartLevels {
            levels: std::mem::take(&mut ptm.mips),
            counts,
            weight,
        };
        Ok((ptm, report, part))
    }

    fn check_complete(&self) -> Result<()> {
        if let Some(i) = self.seen.iter().position(|s| !s) {
            return Err(Error::Invalid(format!(
                "light {i} ({}) was never added; the fit needs every light of the set",
                self.lights.names[i]
            )));
        }
        Ok(())
    }

    fn finish_identity(self, tile: [f64; 2], t_acc: f64) -> Result<(Ptm, FitReport)> {
        let t0 = Instant::now();
        let per_texel = self.mode == Mode::PerTexel;
        let (m, t) = (self.m, self.width * self.height);
        let mut planes = vec![vec![0f32; t]; m];
        let mut rms_map = vec![0f32; t];
        let mut report = self.base_report(per_texel);
        let g_all = if per_texel {
            DMatrix::zeros(m, m)
        } else {
            self.gram_distant()
        };
        if !per_texel {
            self.solve_shared(&g_all, &mut planes, &mut rms_map);
        }
        let worst = self.solve_each(&g_all, per_texel, &mut planes, &mut rms_map, &mut report);
        if per_texel {
            self.warn_per_texel(&worst, &mut report)?;
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
            basis: self.opts.basis,
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
            report.holdout = Some(self.holdout_error(&ptm));
            report.seconds.push(("holdout", t1.elapsed().as_secs_f64()));
        }
        report.seconds.insert(0, ("accumulate", t_acc));
        report.seconds.insert(1, ("solve", t_solve));
        Ok((ptm, report))
    }

    /// The fast path (distant lights): c = S·g and the weighted residual of every unmasked
    /// texel with flat f64 arrays, parallel over texel chunks. Texels with dropped samples are
    /// solved again by [`Accumulator::solve_each`].
    fn solve_shared(&self, g_all: &DMatrix<f64>, planes: &mut [Vec<f32>], rms_map: &mut [f32]) {
        let (m, t) = (self.m, self.width * self.height);
        let wtot: f64 = self.prep.w.iter().sum();
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

    /// The slow path: a texel of its own normal matrix (per-texel directions: every unmasked
    /// texel; distant lights: those with dropped samples, whose Gram matrix is the shared one
    /// less their lights) factored and solved in f64. Counts rank-deficient texels in
    /// `report` and returns the worst texel.
    fn solve_each(
        &self,
        g_all: &DMatrix<f64>,
        per_texel: bool,
        planes: &mut [Vec<f32>],
        rms_map: &mut [f32],
        report: &mut FitReport,
    ) -> Worst {
        let (m, t) = (self.m, self.width * self.height);
        let wtot: f64 = self.prep.w.iter().sum();
        let slow: Vec<usize> = if per_texel {
            (0..t).filter(|&ti| !self.masked[ti]).collect()
        } else {
            self.bad
                .keys()
                .copied()
                .filter(|&ti| !self.masked[ti])
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
    fn warn_per_texel(&self, worst: &Worst, report: &mut FitReport) -> Result<()> {
        let m = self.m;
        report.rank = worst.rank;
        report.cond = worst.cond;
        let np = m * (m + 1) / 2;
        let gw = unpack(&self.gram[worst.texel * np..], m);
        let fw = Factor::from_normal(gw, self.opts.rcond, self.opts.regularize);
        let (col, row) = (worst.texel % self.width, worst.texel / self.width);
        let basis = self.opts.basis;
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
        check_strict(&self.opts, &report.warnings)
    }

    /// The hold-out pass: per texel, the RMS error of clamped K on the held-out lights.
    fn holdout_error(&self, ptm: &Ptm) -> ErrorStats {
        let t = self.width * self.height;
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
        ErrorStats::of(&map, &self.masked)
    }

    fn finish_logistic(
        self,
        tile: [f64; 2],
        t_acc: f64,
        part: Option<(std::ops::Range<usize>, usize)>,
    ) -> Result<(Ptm, FitReport, Option<crate::logistic::Pooled>)> {
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
        let (mut ptm, mut report, pooled) = fit_logistic(
            &src,
            &self.prep,
            &self.lights,
            (self.width, self.height),
            tile,
            &self.masked,
            &self.opts,
            part,
        )?;
        report.coverage = partial_coverage(&self.full_coverage);
        ptm.coverage = ptm_coverage(&self.full_coverage);
        report.seconds.insert(0, ("accumulate", t_acc));
        Ok((ptm, report, pooled))
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
