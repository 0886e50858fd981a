//! The streaming [`Accumulator`] of `ptm bake --fit`: samples arrive light by light and are
//! checked and reduced to per-texel sums (identity link, `normal.rs`) or exact counts
//! (logistic link, `logistic/counts.rs`); then `finish` solves every texel.
use std::time::Instant;

use super::factor::{prepare, SharedDesign};
use super::normal::{Image, NormalSums};
use super::options::{
    holdout_indices, partial_coverage, ptm_coverage, FitOptions, FitReport, LearnedStats,
};
use crate::logistic::counts::Counts;
use crate::logistic::image::fit_image;
use crate::logistic::pool::Pooled;
use crate::mip::identity_mips;
use crate::shard::partition::PartLevels;
use crate::{Diagnostic, Error, Result};
use ptm_format::{LightSet, Link, Ptm};

/// Streaming accumulator used by `ptm bake --fit`: samples are added light by light, memory is
/// O(texels × terms) (plus the held-out lights' samples, if asked), never O(texels × lights).
pub struct Accumulator {
    opts: FitOptions,
    lights: LightSet,
    width: usize,
    height: usize,
    prep: SharedDesign,
    seen: Vec<bool>,
    mode: Mode,
    masked: Vec<bool>,
    started: Instant,
    /// Identity link: the per-texel sums of the normal equations.
    sums: NormalSums,
    /// Logistic link: exact sample counts (texels × lights bytes where a stored f32 stack
    /// would take four times that).
    counts: Counts,
    /// The coverage given to [`Accumulator::set_coverage`] (empty: every texel covered).
    full_coverage: Vec<f32>,
}

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
            counts: Counts::default(),
            full_coverage: Vec::new(),
            opts: opts.clone(),
            lights: lights.clone(),
            width,
            height,
            prep,
            sums: NormalSums::new(opts.link, t, opts.basis.len()),
            seen: vec![false; lights.len()],
            mode: Mode::Empty,
            masked: vec![false; t],
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
        self.counts.set_spp(spp)
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
        self.sums.held_bytes()
            + self.counts.held_bytes()
            + cap(&self.seen)
            + cap(&self.masked)
            + cap(&self.full_coverage)
    }

    /// What the identity link's sums are of.
    fn image(&self) -> Image<'_> {
        Image {
            opts: &self.opts,
            lights: &self.lights,
            prep: &self.prep,
            width: self.width,
            height: self.height,
            masked: &self.masked,
            coverage: &self.full_coverage,
        }
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
            // The logistic link keeps counts (`Counts::add`), not sums.
            Mode::Empty if self.opts.link == Link::Logistic => self.mode = mode,
            Mode::Empty => {
                self.mode = mode;
                self.sums.start(per_texel, t);
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

    /// Adds the K plane (row-major, one value per texel) of distant light `index`.
    pub fn add_light(&mut self, index: usize, k: &[f32]) -> Result<()> {
        self.begin(index, k.len(), false)?;
        if self.opts.link == Link::Logistic {
            let (lights, width) = (self.lights.len(), self.width);
            let (masked, coverage) = (&self.masked, &self.full_coverage);
            return self.counts.add(index, k, masked, coverage, lights, width);
        }
        let img = Image {
            opts: &self.opts,
            lights: &self.lights,
            prep: &self.prep,
            width: self.width,
            height: self.height,
            masked: &self.masked,
            coverage: &self.full_coverage,
        };
        self.sums.add_distant(index, k, &img)
    }

    /// Adds light `index` with per-texel (u, v) (finite-distance lights).
    pub fn add_light_uv(&mut self, index: usize, k: &[f32], uv: &[[f32; 2]]) -> Result<()> {
        if self.opts.link == Link::Logistic {
            return Err(Error::LogisticNeedsDistantLights);
        }
        self.begin(index, k.len(), true)?;
        if uv.len() != k.len() {
            return Err(Error::Invalid(format!(
                "light {index}: {} (u, v) pairs for {} samples",
                uv.len(),
                k.len()
            )));
        }
        let img = Image {
            opts: &self.opts,
            lights: &self.lights,
            prep: &self.prep,
            width: self.width,
            height: self.height,
            masked: &self.masked,
            coverage: &self.full_coverage,
        };
        self.sums.add_per_texel(index, k, uv, &img)
    }

    /// Solves every texel and returns the PTM and its report. Every light must have been added.
    pub fn finish(self, tile: [f64; 2]) -> Result<(Ptm, FitReport)> {
        self.check_complete()?;
        let t_acc = self.started.elapsed().as_secs_f64();
        if self.opts.link == Link::Logistic {
            let (ptm, report, _) = self.finish_logistic(tile, t_acc, None)?;
            return Ok((ptm, report));
        }
        let per_texel = self.mode == Mode::PerTexel;
        let (mut ptm, mut report) = self.sums.solve(&self.image(), per_texel, tile)?;
        report.seconds.insert(0, ("accumulate", t_acc));
        if self.opts.mips {
            let t0 = Instant::now();
            ptm.mips = identity_mips(&ptm, &self.full_coverage);
            report.mip_levels = ptm.mips.len();
            report
                .seconds
                .push(("mip levels", t0.elapsed().as_secs_f64()));
        }
        Ok((ptm, report))
    }

    /// Solves every texel as [`Accumulator::finish`] would under other options `opts` (another
    /// basis, another hold-out), from the same exact counts, leaving the accumulator as it is:
    /// `ptm bake --fit auto` fits each candidate model from one trace. The logistic link only
    /// (its counts do not depend on the basis; the identity link's sums do), in both the
    /// accumulator and `opts`. The hold-out count is `opts`' (the held-out lights are those
    /// [`crate::solve::options::holdout_indices`] picks).
    pub fn finish_as(&self, tile: [f64; 2], opts: &FitOptions) -> Result<(Ptm, FitReport)> {
        if self.opts.link != Link::Logistic || opts.link != Link::Logistic {
            return Err(Error::Invalid(format!(
                "refitting the same samples under another model needs the logistic link's \
                 counts (this accumulator sums for the {} link, the model asks for the {} link)",
                self.opts.link.name(),
                opts.link.name()
            )));
        }
        self.check_complete()?;
        let t_acc = self.started.elapsed().as_secs_f64();
        let prep = prepare(&self.lights, opts)?;
        let src = self.counts.source();
        let (mut ptm, mut report, _) = fit_image(
            &src,
            &prep,
            &self.lights,
            (self.width, self.height),
            tile,
            &self.masked,
            opts,
            None,
        )?;
        report.coverage = partial_coverage(&self.full_coverage);
        ptm.coverage = ptm_coverage(&self.full_coverage);
        report.seconds.insert(0, ("accumulate", t_acc));
        Ok((ptm, report))
    }

    /// Fits against `table` (learned elsewhere, with `stats`) instead of learning a basis: a
    /// farm shard's fit ([`FitOptions::given_basis`]).
    pub fn set_given_basis(&mut self, table: ptm_format::LearnedTable, stats: LearnedStats) {
        self.opts.given_basis = Some(Box::new((table, stats)));
    }

    /// Learns the basis of this accumulator's learned options from its samples and returns the
    /// tables and what the learning did, fitting no texel: a farm shard's first step, on the
    /// whole bake's subsample of texels (traced apart, in increasing image order: the learning
    /// then sees exactly the texels, in the order, a fit of the whole image learns from).
    /// Its tables go to the shard's fit as [`FitOptions::given_basis`].
    pub fn learn_basis(&self) -> Result<(ptm_format::LearnedTable, LearnedStats)> {
        if self.opts.link != Link::Logistic || !self.opts.basis.is_learned() {
            return Err(Error::Invalid(format!(
                "learning a basis needs a learned basis and the logistic link, not {} with the \
                 {} link",
                self.opts.basis.name(),
                self.opts.link.name()
            )));
        }
        self.check_complete()?;
        crate::logistic::image::learn_basis(
            &self.counts.source(),
            &self.prep,
            &self.lights,
            &self.masked,
            &self.opts,
        )
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
    ) -> Result<(Ptm, FitReport, PartLevels)> {
        let weight = self.opts.weight;
        if self.opts.link == Link::Identity {
            self.opts.mips = false;
            let (ptm, report) = self.finish(tile)?;
            return Ok((ptm, report, PartLevels::default()));
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
        let part = PartLevels {
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

    fn finish_logistic(
        self,
        tile: [f64; 2],
        t_acc: f64,
        part: Option<(std::ops::Range<usize>, usize)>,
    ) -> Result<(Ptm, FitReport, Option<Pooled>)> {
        let src = self.counts.source();
        let (mut ptm, mut report, pooled) = fit_image(
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
}
