//! The occlusion PTM in memory (one coefficient plane per basis monomial), its EXR file, and
//! CPU evaluation.
//!
//! File layout (docs/FORMAT.md): single-part scanline EXR, ZIP compressed, float32 (or half),
//! one channel per coefficient named `ptm.<monomial>` (`ptm.u2`, `ptm.u`, `ptm.uv`, `ptm.v`,
//! `ptm.v2`, `ptm.1` for ptm6), optional `coverage`, `err.rms` / `err.max`, header attributes `ptm:*`.
//! This module writes it ([`Ptm::encode`]). Reading is the one decoder of both layouts:
//! [`Ptm::load`] and [`Ptm::load_with_info`] are implemented beside `PtmFile` in `layout.rs`
//! (the file decoded into a `PtmFile`, its header parsed by `header::Header::parse`), so this
//! module, which that one builds on, imports neither.
//!
//! Loading a PTM needs this crate only:
//! ```no_run
//! use ptm_format::Ptm;
//! let ptm = Ptm::load("weave.ptm.exr".as_ref())?;
//! // A light at 30° elevation along +X: l = (cos 30°, 0, sin 30°), so (u, v) = (0.866, 0).
//! let k = ptm.eval(10, 20, 0.866, 0.0); // occluded fraction at column 10, row 20, in [0, 1]
//! let visibility = 1.0 - k;
//! // Raw coefficients of texel (10, 20) in basis order, for a shader upload:
//! let names: Vec<&str> = ptm.basis.monomials().iter().map(|m| m.name).collect();
//! let c = ptm.coeffs(10, 20);
//! # let _ = (visibility, names, c);
//! # Ok::<(), ptm_format::Error>(())
//! ```
use std::path::Path;

use half::f16;

use crate::exrio::{self, Attr, Samples};
use crate::{Basis, Error, LearnedTable, Link, Result, UvMap};

/// Value of `ptm:version` for a plain PTM (identity link, projected (u, v)): every reader of
/// version 1 evaluates it correctly.
pub const PTM_VERSION: &str = "occlusion-ptm/1";

/// Value of `ptm:version` for a PTM whose `ptm:link` or `ptm:uv` is not the plain one, so that a
/// version-1 reader refuses it instead of evaluating it as a polynomial.
pub const PTM_VERSION_2: &str = "occlusion-ptm/2";

/// One coarser MIP level of a PTM: coefficients fitted to the box-filtered K of its footprint.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// Width of the level, texels.
    pub width: usize,
    /// Height of the level, texels.
    pub height: usize,
    /// Coefficient planes in basis order, row-major.
    pub planes: Vec<Vec<f32>>,
}

/// An occlusion PTM: per texel, the coefficients of K = link(p(u, v)) in `basis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Ptm {
    /// The polynomial basis p(u, v) the coefficient planes are in.
    pub basis: Basis,
    /// K = p (identity) or K = σ(p) (logistic).
    pub link: Link,
    /// How a light direction maps to (u, v).
    pub uv: UvMap,
    /// Texels per row.
    pub width: usize,
    /// Rows; row 0 is the far edge y = H of the tile.
    pub height: usize,
    /// Tile size (W, H) in swatch units.
    pub tile: [f64; 2],
    /// `planes[i]` holds coefficient i (basis order) for every texel, row-major.
    pub planes: Vec<Vec<f32>>,
    /// MIP levels 1, 2, … down to 1×1 (sizes halved, rounded down, as OpenEXR's
    /// `ROUND_DOWN`), each fitted to the box-filtered K of its footprint; empty when the file
    /// stores none (a renderer may then average coefficients, which is exact only for the
    /// identity link).
    pub mips: Vec<Level>,
    /// Per-texel coverage of level 0, row-major: the fraction of the texel's footprint with
    /// cloth under it (0 = a hole, where the coefficients are 0 and K means nothing). `None`
    /// when every texel is fully covered. Stored as the `coverage` channel (with box-averaged
    /// MIP levels when the file has levels).
    pub coverage: Option<Vec<f32>>,
    /// The tables of a learned basis ([`Basis::Learned`]; shared by every MIP level), `None`
    /// for a polynomial basis. Stored in the header (`ptm:learnedGrid`, `ptm:learnedTable`).
    pub learned: Option<LearnedTable>,
}

/// How [`Ptm::save`] writes the file.
#[derive(Clone, Copy, Default)]
pub struct SaveOptions<'a> {
    /// Store coefficients as half floats (see [`Ptm::half_error_bound`] for the added error).
    pub half: bool,
    /// The fit's facts, recorded in the header (light count, solver, rank, errors): anything
    /// that can state them as [`FileFacts`] (`ptm_fit::FitReport` does, and so does a
    /// `FileFacts` itself).
    pub report: Option<&'a dyn ToFileFacts>,
    /// Also write the per-texel residual maps `err.rms` and `err.max` from `report`.
    pub error_map: bool,
}

impl std::fmt::Debug for SaveOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SaveOptions")
            .field("half", &self.half)
            .field("report", &self.report.map(|r| r.file_facts()))
            .field("error_map", &self.error_map)
            .finish()
    }
}

/// The file-level facts of a fit that a PTM header records beside the coefficients, borrowed
/// from whatever produced them (the fitter's report). Every figure is the whole file's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FileFacts<'a> {
    /// Lights in the light set (`ptm:nLights`).
    pub lights: usize,
    /// Lights the fit used, hold-out lights excluded (`ptm:nLightsFit`).
    pub lights_fit: usize,
    /// The solver in words (`ptm:solver`).
    pub solver: &'a str,
    /// Rank of the design (`ptm:rank`).
    pub rank: usize,
    /// Condition number of the design; not recorded when infinite (`ptm:cond`).
    pub cond: f64,
    /// Mean and 99th percentile over covered texels of the per-texel RMS error of K
    /// (`ptm:rmsMean`, `ptm:rmsP99`).
    pub rms_mean: f64,
    /// 99th percentile of the same (`ptm:rmsP99`).
    pub rms_p99: f64,
    /// 99th percentile of the per-texel maximum error of K, when measured (`ptm:maxErrP99`).
    pub max_p99: Option<f64>,
    /// Mean and 99th percentile of the RMS error of K on hold-out lights, when some were held
    /// out (`ptm:holdoutRmsMean`, `ptm:holdoutRmsP99`).
    pub holdout: Option<(f64, f64)>,
    /// Indices (in the light set's order) of the lights held out of the fit to measure
    /// `holdout` (`ptm:holdoutLights`, decimal indices separated by spaces; empty when none).
    pub holdout_lights: &'a [usize],
    /// Warnings in words (`ptm:warnings`), as the producer renders its diagnostics.
    pub warnings: Vec<String>,
    /// Where the samples came from when not from a ptm bake (`ptm:samples`), e.g. an RTI image
    /// stack and how its values were decoded.
    pub samples: Option<&'a str>,
    /// Per-texel RMS and maximum error of K, row-major (empty when not computed); written as
    /// `err.rms` / `err.max` when [`SaveOptions::error_map`] is set.
    pub rms_map: &'a [f32],
    /// Per-texel maximum error of K, row-major, beside `rms_map`.
    pub max_map: &'a [f32],
}

/// Something that states the [`FileFacts`] of a PTM file.
pub trait ToFileFacts {
    /// The file-level facts to record in the header.
    fn file_facts(&self) -> FileFacts<'_>;
}

impl ToFileFacts for FileFacts<'_> {
    fn file_facts(&self) -> FileFacts<'_> {
        self.clone()
    }
}

/// Header facts of a PTM file beside the coefficients.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PtmInfo {
    /// How the coefficient channels are stored on disk: `"float32"`, `"half"` or `"mixed"`
    /// (read from the channels' types, whatever `ptm:storage` says).
    pub storage: String,
    /// Lights in the light set (`ptm:nLights`), when recorded.
    pub lights: Option<usize>,
    /// The solver in words (`ptm:solver`), when recorded.
    pub solver: Option<String>,
    /// Rank of the design (`ptm:rank`), when recorded.
    pub rank: Option<usize>,
    /// Condition number of the design (`ptm:cond`), when recorded.
    pub cond: Option<f64>,
    /// Mean per-texel RMS error of K over covered texels (`ptm:rmsMean`), when recorded.
    pub rms_mean: Option<f64>,
    /// Per-texel error maps when the file has them (`err.rms`, `err.max`).
    pub err_rms: Option<Vec<f32>>,
    /// Per-texel maximum error of K (`err.max`), row-major, beside `err_rms`.
    pub err_max: Option<Vec<f32>>,
    /// Per-texel coverage when the file has it (`coverage`: 0 = no cloth under the texel).
    pub coverage: Option<Vec<f32>>,
}

/// EXR channel name of a monomial.
pub fn channel_name(monomial: &str) -> String {
    format!("ptm.{monomial}")
}

/// Sizes of MIP levels 1, 2, … of a width × height image down to 1×1, halving a side while it
/// is above 1 and rounding down, as OpenEXR's `MIPMAP_LEVELS` with `ROUND_DOWN` (tested against
/// the exr crate; the logistic fitter's pooling chain is tested against this).
pub fn mip_sizes(width: usize, height: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let (mut w, mut h) = (width, height);
    while w > 1 || h > 1 {
        w = if w > 1 { w / 2 } else { 1 };
        h = if h > 1 { h / 2 } else { 1 };
        out.push((w, h));
    }
    out
}

impl Ptm {
    /// A plain PTM (identity link, projected (u, v), no MIP levels) from its planes.
    pub fn new(
        basis: Basis,
        width: usize,
        height: usize,
        tile: [f64; 2],
        planes: Vec<Vec<f32>>,
    ) -> Ptm {
        Ptm {
            basis,
            link: Link::Identity,
            uv: UvMap::Projected,
            width,
            height,
            tile,
            planes,
            mips: Vec::new(),
            coverage: None,
            learned: None,
        }
    }

    /// Coefficients of texel (x, y) in basis order.
    pub fn coeffs(&self, x: usize, y: usize) -> Vec<f32> {
        let i = y * self.width + x;
        self.planes.iter().map(|p| p[i]).collect()
    }

    /// The link's K before the clamp at texel (x, y) for a light whose projection on the
    /// tangent plane is (l·X, l·Y) = (u, v) (mapped by `self.uv` first). For the identity link this
    /// is the raw polynomial, which may leave [0, 1]; σ never does.
    pub fn eval_unclamped(&self, x: usize, y: usize, u: f32, v: f32) -> f32 {
        let (mu, mv) = self.uv.of_projected(u, v);
        self.link.apply(self.poly(y * self.width + x, mu, mv))
    }

    /// p(u, v) = Σ cᵢ·termᵢ(u, v) of texel index i at mapped (u, v): the monomials, or the
    /// learned tables read bilinearly.
    fn poly(&self, i: usize, u: f32, v: f32) -> f32 {
        let mut c = [0f32; 16];
        for (k, p) in self.planes.iter().enumerate() {
            c[k] = p[i];
        }
        let m = self.basis.len();
        match &self.learned {
            Some(t) if self.basis.is_learned() => {
                let mut b = [0f64; 16];
                t.terms(u as f64, v as f64, &mut b[..m]);
                (0..m).map(|k| c[k] as f64 * b[k]).sum::<f64>() as f32
            }
            _ => self.basis.eval(&c[..m], u, v),
        }
    }

    /// K at texel (x, y) (column x, row y; row 0 at y = H) for a light in the upper hemisphere
    /// whose projection is (u, v) = (l·X, l·Y), clamped to [0, 1]. The file's `uv` map and `link`
    /// are applied here: callers always pass the projected components.
    pub fn eval(&self, x: usize, y: usize, u: f32, v: f32) -> f32 {
        self.eval_unclamped(x, y, u, v).clamp(0.0, 1.0)
    }

    /// K at texel (x, y) for the unit direction l towards the light (swatch frame), clamped.
    /// Lights at or below the horizon are fully occluded (K = 1).
    pub fn eval_dir(&self, x: usize, y: usize, l: [f64; 3]) -> f32 {
        if l[2] <= 0.0 {
            return 1.0;
        }
        let (u, v) = self.uv.of_dir(l);
        self.link
            .apply(self.poly(y * self.width + x, u as f32, v as f32))
            .clamp(0.0, 1.0)
    }

    /// The `ptm:version` this PTM is written with: 1 when it is a plain PTM, else 2.
    pub fn version(&self) -> &'static str {
        if self.link == Link::Identity && self.uv == UvMap::Projected {
            PTM_VERSION
        } else {
            PTM_VERSION_2
        }
    }

    /// Checks plane count and sizes.
    pub fn validate(&self) -> Result<()> {
        let n = self.width * self.height;
        if n == 0
            || self.planes.len() != self.basis.len()
            || self.planes.iter().any(|p| p.len() != n)
        {
            return Err(Error::Invalid(format!(
                "PTM {}×{} {} needs {} planes of {n} texels",
                self.width,
                self.height,
                self.basis.name(),
                self.basis.len()
            )));
        }
        match (&self.learned, self.basis.is_learned()) {
            (None, false) => {}
            (Some(_), false) => {
                return Err(Error::Invalid(format!(
                    "PTM {}×{} {}: a polynomial basis has no learned table",
                    self.width,
                    self.height,
                    self.basis.name()
                )))
            }
            (None, true) => {
                return Err(Error::Invalid(format!(
                    "PTM {}×{} {}: a learned basis needs its table",
                    self.width,
                    self.height,
                    self.basis.name()
                )))
            }
            (Some(t), true) => {
                t.check(
                    self.basis.len(),
                    &format!("the {} table", self.basis.name()),
                )
                .map_err(Error::Invalid)?;
                if self.link != Link::Logistic || self.uv != UvMap::Hemispherical {
                    return Err(Error::Invalid(format!(
                        "PTM {}×{} {}: a learned basis is defined for the logistic link over \
                         the hemispherical (u, v) map, not {} over {}",
                        self.width,
                        self.height,
                        self.basis.name(),
                        self.link.name(),
                        self.uv.name()
                    )));
                }
            }
        }
        if !self.tile.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(Error::Invalid(format!(
                "PTM {}×{}: tile {} × {} is not a positive finite size",
                self.width, self.height, self.tile[0], self.tile[1]
            )));
        }
        let levels = std::iter::once((self.width, &self.planes))
            .chain(self.mips.iter().map(|l| (l.width, &l.planes)));
        for (level, (w, planes)) in levels.enumerate() {
            for (j, plane) in planes.iter().enumerate() {
                if let Some(i) = plane.iter().position(|c| !c.is_finite()) {
                    return Err(Error::Invalid(format!(
                        "PTM {}×{}: coefficient {} is {} at texel (column {}, row {}){}: not a number a renderer can use",
                        self.width,
                        self.height,
                        self.basis.monomials().get(j).map_or("?", |m| m.name),
                        plane[i],
                        i % w.max(1),
                        i / w.max(1),
                        if level > 0 { format!(" of MIP level {level}") } else { String::new() }
                    )));
                }
            }
        }
        if let Some(cov) = &self.coverage {
            if cov.len() != n {
                return Err(Error::Invalid(format!(
                    "PTM {}×{}: coverage has {} texels, not {n}",
                    self.width,
                    self.height,
                    cov.len()
                )));
            }
            if let Some((i, c)) = cov
                .iter()
                .enumerate()
                .find(|(_, c)| !(0.0..=1.0).contains(*c))
            {
                return Err(Error::Invalid(format!(
                    "PTM {}×{}: coverage {c} at texel (column {}, row {}) is not a fraction in [0, 1]",
                    self.width,
                    self.height,
                    i % self.width,
                    i / self.width
                )));
            }
        }
        if !self.mips.is_empty() {
            let want = mip_sizes(self.width, self.height);
            let got: Vec<(usize, usize)> = self.mips.iter().map(|l| (l.width, l.height)).collect();
            if got != want
                || self.mips.iter().any(|l| {
                    l.planes.len() != self.basis.len()
                        || l.planes.iter().any(|p| p.len() != l.width * l.height)
                })
            {
                return Err(Error::Invalid(format!(
                    "PTM {}×{}: MIP levels {got:?} do not match the chain {want:?} (halved, rounded down, to 1×1) with {} planes each",
                    self.width,
                    self.height,
                    self.basis.len()
                )));
            }
        }
        Ok(())
    }

    /// Largest change of K anywhere on the unit disk caused by storing the coefficients as half
    /// floats: max over texels (and MIP levels) of Σ|c − half(c)| (every term is at most 1 in
    /// magnitude there, for either (u, v) map; a learned term at most its table's largest
    /// magnitude), times 1/4 for the logistic link (σ' ≤ 1/4).
    pub fn half_error_bound(&self) -> f64 {
        let term = self.learned.as_ref().map_or(1.0, |t| {
            t.values.iter().fold(0f64, |a, &x| a.max(x.abs() as f64))
        });
        let scale = term
            * match self.link {
                Link::Identity => 1.0,
                Link::Logistic => 0.25,
            };
        std::iter::once(&self.planes)
            .chain(self.mips.iter().map(|l| &l.planes))
            .map(|planes| {
                let n = planes.first().map_or(0, Vec::len);
                (0..n)
                    .map(|i| {
                        planes
                            .iter()
                            .map(|p| (p[i] as f64 - f16::from_f32(p[i]).to_f64()).abs())
                            .sum::<f64>()
                    })
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
            * scale
    }

    /// Writes the PTM EXR atomically.
    pub fn save(&self, path: &Path, opts: &SaveOptions) -> Result<()> {
        let bytes = self.encode(path, opts)?;
        crate::atomic::write_bytes(path, &bytes)
    }

    /// The bytes of the PTM EXR [`Ptm::save`] writes (`path` names the file in errors only), to
    /// stage in an [`atomic::Transaction`](crate::atomic::Transaction) with other outputs.
    pub fn encode(&self, path: &Path, opts: &SaveOptions) -> Result<Vec<u8>> {
        self.validate()?;
        if opts.half {
            let big = std::iter::once(&self.planes)
                .chain(self.mips.iter().map(|l| &l.planes))
                .flatten()
                .flatten()
                .fold(0f32, |a, &x| a.max(x.abs()));
            if big.is_nan() || big >= 65504.0 {
                return Err(Error::HalfOverflow {
                    path: path.display().to_string(),
                    magnitude: big,
                });
            }
        }
        let store = |v: &[f32]| {
            if opts.half {
                Samples::F16(v.iter().map(|&x| f16::from_f32(x)).collect())
            } else {
                Samples::F32(v.to_vec())
            }
        };
        // Every channel of a MIP-mapped file has every level: coefficients carry their fitted
        // levels, the other maps (coverage, errors) their box averages.
        let sizes = if self.mips.is_empty() {
            Vec::new()
        } else {
            mip_sizes(self.width, self.height)
        };
        let with_levels = |v: &[f32]| -> Vec<Samples> {
            let mut out = vec![store(v)];
            let mut cur = (v.to_vec(), self.width, self.height);
            for &(w, h) in &sizes {
                let next = box_down(&cur.0, cur.1, cur.2, w, h);
                out.push(store(&next));
                cur = (next, w, h);
            }
            out
        };
        let mut channels: Vec<(String, Vec<Samples>)> = self
            .basis
            .monomials()
            .iter()
            .enumerate()
            .map(|(j, m)| {
                let mut levels = vec![store(&self.planes[j])];
                levels.extend(self.mips.iter().map(|l| store(&l.planes[j])));
                (channel_name(m.name), levels)
            })
            .collect();
        let mut attrs = vec![
            ("ptm:version", Attr::Text(self.version().into())),
            ("ptm:basis", Attr::Text(self.basis.name().into())),
            ("ptm:link", Attr::Text(self.link.name().into())),
            (
                "ptm:monomials",
                Attr::Texts(self.basis.monomials().iter().map(|m| m.name.to_string()).collect()),
            ),
            (
                "ptm:value",
                Attr::Text(
                    match self.link {
                        Link::Identity => "K = p(u, v) = sum_i ptm.<m_i> * m_i(u, v); K = occluded fraction, 0 lit, 1 occluded; clamp to [0,1]",
                        Link::Logistic if self.basis.is_learned() => "K = 1 / (1 + exp(-p(u, v))), p(u, v) = sum_k ptm.b<k> * B_k(u, v), B_k the learned tables (ptm:learnedFormula); K = occluded fraction, 0 lit, 1 occluded",
                        Link::Logistic => "K = 1 / (1 + exp(-p(u, v))), p(u, v) = sum_i ptm.<m_i> * m_i(u, v); K = occluded fraction, 0 lit, 1 occluded",
                    }
                    .into(),
                ),
            ),
            ("ptm:uv", Attr::Text(self.uv.name().into())),
            ("ptm:uvFormula", Attr::Text(self.uv.formula().into())),
            (
                "ptm:frame",
                Attr::Text(
                    "T = +X, B = +Y, N = +Z; tile [0,W]x[0,H]; row 0 at y = H, column 0 at x = 0"
                        .into(),
                ),
            ),
            ("ptm:tileW", Attr::F64(self.tile[0])),
            ("ptm:tileH", Attr::F64(self.tile[1])),
            (
                "ptm:storage",
                Attr::Text(if opts.half { "half" } else { "float32" }.into()),
            ),
            (
                "ptm:software",
                Attr::Text(format!("ptm {}", env!("CARGO_PKG_VERSION"))),
            ),
        ];
        if let Some(t) = &self.learned {
            attrs.extend(t.attrs());
        }
        if let Some(cov) = &self.coverage {
            // Holes in the cloth: coefficients 0 there, which reads as "lit" without this.
            channels.push(("coverage".into(), with_levels(cov)));
        }
        if let Some(r) = opts.report {
            let r = r.file_facts();
            attrs.push(("ptm:nLights", Attr::I32(r.lights as i32)));
            attrs.push(("ptm:nLightsFit", Attr::I32(r.lights_fit as i32)));
            attrs.push(("ptm:solver", Attr::Text(r.solver.into())));
            attrs.push(("ptm:rank", Attr::I32(r.rank as i32)));
            if r.cond.is_finite() {
                attrs.push(("ptm:cond", Attr::F64(r.cond)));
            }
            attrs.push(("ptm:rmsMean", Attr::F64(r.rms_mean)));
            attrs.push(("ptm:rmsP99", Attr::F64(r.rms_p99)));
            if let Some(m) = r.max_p99 {
                attrs.push(("ptm:maxErrP99", Attr::F64(m)));
            }
            if let Some((mean, p99)) = r.holdout {
                attrs.push(("ptm:holdoutRmsMean", Attr::F64(mean)));
                attrs.push(("ptm:holdoutRmsP99", Attr::F64(p99)));
            }
            attrs.push((
                "ptm:holdoutLights",
                Attr::Text(holdout_text(r.holdout_lights)),
            ));
            if !r.warnings.is_empty() {
                attrs.push(("ptm:warnings", Attr::Texts(r.warnings.to_vec())));
            }
            if let Some(s) = r.samples {
                attrs.push(("ptm:samples", Attr::Text(s.to_string())));
            }
            if opts.error_map {
                let n = self.width * self.height;
                if r.rms_map.len() == n {
                    channels.push(("err.rms".into(), with_levels(r.rms_map)));
                }
                if r.max_map.len() == n {
                    channels.push(("err.max".into(), with_levels(r.max_map)));
                }
            }
        }
        exrio::encode_levels(path, self.width, self.height, channels, attrs)
    }
}

/// The held-out lights as `ptm:holdoutLights` records them: decimal indices separated by
/// single spaces, in increasing order (`"0 5 10"`; `""` when none was held out).
pub fn holdout_text(lights: &[usize]) -> String {
    lights
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(" ")
}

/// How far outside [0, 1] a stored coverage may lie and still be read as a fraction: the
/// ringing of a resampling filter (`oiiotool --resize`, a MIP filter) at a hole's edge.
pub const COVERAGE_RINGING: f32 = 0.25;

/// Clamps coverage values within [`COVERAGE_RINGING`] of [0, 1] into it, as a texture system
/// would; values further out (and NaN) are left for [`Ptm::validate`] to refuse.
pub fn clamp_ringing(coverage: &mut [f32]) {
    for c in coverage {
        if (-COVERAGE_RINGING..=1.0 + COVERAGE_RINGING).contains(c) {
            *c = c.clamp(0.0, 1.0);
        }
    }
}

/// Box average of a w × h map into the next MIP level's nw × nh (2×2 texels, or 2×1 / 1×2 where
/// one side is already 1; an odd last row or column is dropped, as `ROUND_DOWN` sizes imply).
pub fn box_down(v: &[f32], w: usize, h: usize, nw: usize, nh: usize) -> Vec<f32> {
    let (fx, fy) = (if w > 1 { 2 } else { 1 }, if h > 1 { 2 } else { 1 });
    let inv = 1.0 / (fx * fy) as f32;
    let mut out = vec![0f32; nw * nh];
    for y in 0..nh {
        for x in 0..nw {
            let mut s = 0f32;
            for dy in 0..fy {
                for dx in 0..fx {
                    s += v[(y * fy + dy) * w + x * fx + dx];
                }
            }
            out[y * nw + x] = s * inv;
        }
    }
    out
}
