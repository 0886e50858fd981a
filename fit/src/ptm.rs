//! The occlusion PTM in memory (one coefficient plane per basis monomial), its EXR file, and
//! CPU evaluation.
//!
//! File layout (docs/FORMAT.md): single-part scanline EXR, ZIP compressed, float32 (or half),
//! one channel per coefficient named `ptm.<monomial>` (`ptm.u2`, `ptm.u`, `ptm.uv`, `ptm.v`,
//! `ptm.v2`, `ptm.1` for ptm6), optional `coverage`, `err.rms` / `err.max`, header attributes `ptm:*`.
//!
//! Loading a PTM needs this crate only:
//! ```no_run
//! use ptm_fit::Ptm;
//! let ptm = Ptm::load("weave.ptm.exr".as_ref())?;
//! // A light at 30° elevation along +X: l = (cos 30°, 0, sin 30°), so (u, v) = (0.866, 0).
//! let k = ptm.eval(10, 20, 0.866, 0.0); // occluded fraction at column 10, row 20, in [0, 1]
//! let visibility = 1.0 - k;
//! // Raw coefficients of texel (10, 20) in basis order, for a shader upload:
//! let names: Vec<&str> = ptm.basis.monomials().iter().map(|m| m.name).collect();
//! let c = ptm.coeffs(10, 20);
//! # let _ = (visibility, names, c);
//! # Ok::<(), ptm_fit::Error>(())
//! ```
use std::path::Path;

use half::f16;

use crate::exrio::{self, Attr, Samples};
use crate::{Basis, Error, FitReport, Result};

/// Value of `ptm:version`.
pub const PTM_VERSION: &str = "occlusion-ptm/1";

/// An occlusion PTM: per texel, the coefficients of K(u, v) in `basis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Ptm {
    pub basis: Basis,
    /// Texels per row.
    pub width: usize,
    /// Rows; row 0 is the far edge y = H of the tile.
    pub height: usize,
    /// Tile size (W, H) in swatch units.
    pub tile: [f64; 2],
    /// `planes[i]` holds coefficient i (basis order) for every texel, row-major.
    pub planes: Vec<Vec<f32>>,
}

/// How [`Ptm::save`] writes the file.
#[derive(Clone, Copy, Debug, Default)]
pub struct SaveOptions<'a> {
    /// Store coefficients as half floats (see [`Ptm::half_error_bound`] for the added error).
    pub half: bool,
    /// The fit's diagnostics, recorded in the header (light count, solver, rank, errors).
    pub report: Option<&'a FitReport>,
    /// Also write the per-texel residual maps `err.rms` and `err.max` from `report`.
    pub error_map: bool,
}

/// Header facts of a PTM file beside the coefficients.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PtmInfo {
    /// `"float32"` or `"half"`.
    pub storage: String,
    pub lights: Option<usize>,
    pub solver: Option<String>,
    pub rank: Option<usize>,
    pub cond: Option<f64>,
    pub rms_mean: Option<f64>,
    /// Per-texel error maps when the file has them (`err.rms`, `err.max`).
    pub err_rms: Option<Vec<f32>>,
    pub err_max: Option<Vec<f32>>,
    /// Per-texel coverage when the file has it (`coverage`: 0 = no cloth under the texel).
    pub coverage: Option<Vec<f32>>,
}

/// EXR channel name of a monomial.
pub fn channel_name(monomial: &str) -> String {
    format!("ptm.{monomial}")
}

impl Ptm {
    /// Coefficients of texel (x, y) in basis order.
    pub fn coeffs(&self, x: usize, y: usize) -> Vec<f32> {
        let i = y * self.width + x;
        self.planes.iter().map(|p| p[i]).collect()
    }

    /// Unclamped K at texel (x, y) for light projection (u, v).
    pub fn eval_unclamped(&self, x: usize, y: usize, u: f32, v: f32) -> f32 {
        let i = y * self.width + x;
        let mut c = [0f32; 16];
        for (k, p) in self.planes.iter().enumerate() {
            c[k] = p[i];
        }
        self.basis.eval(&c[..self.basis.len()], u, v)
    }

    /// K at texel (x, y) (column x, row y; row 0 at y = H) for light projection
    /// (u, v) = (l·X, l·Y), clamped to [0, 1].
    pub fn eval(&self, x: usize, y: usize, u: f32, v: f32) -> f32 {
        self.eval_unclamped(x, y, u, v).clamp(0.0, 1.0)
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
        Ok(())
    }

    /// Largest change of K anywhere on the unit disk caused by storing the coefficients as half
    /// floats: max over texels of Σ|c − half(c)| (every term is at most 1 in magnitude there).
    pub fn half_error_bound(&self) -> f64 {
        let n = self.width * self.height;
        (0..n)
            .map(|i| {
                self.planes
                    .iter()
                    .map(|p| (p[i] as f64 - f16::from_f32(p[i]).to_f64()).abs())
                    .sum::<f64>()
            })
            .fold(0.0, f64::max)
    }

    /// Writes the PTM EXR atomically.
    pub fn save(&self, path: &Path, opts: &SaveOptions) -> Result<()> {
        self.validate()?;
        if opts.half {
            let big = self
                .planes
                .iter()
                .flatten()
                .fold(0f32, |a, &x| a.max(x.abs()));
            if big.is_nan() || big >= 65504.0 {
                return Err(Error::Invalid(format!(
                    "{}: a coefficient of magnitude {big:e} does not fit in a half float; save as float32 (drop --half)",
                    path.display()
                )));
            }
        }
        let store = |v: &Vec<f32>| {
            if opts.half {
                Samples::F16(v.iter().map(|&x| f16::from_f32(x)).collect())
            } else {
                Samples::F32(v.clone())
            }
        };
        let mut channels: Vec<(String, Samples)> = self
            .basis
            .monomials()
            .iter()
            .zip(&self.planes)
            .map(|(m, p)| (channel_name(m.name), store(p)))
            .collect();
        let mut attrs = vec![
            ("ptm:version", Attr::Text(PTM_VERSION.into())),
            ("ptm:basis", Attr::Text(self.basis.name().into())),
            (
                "ptm:monomials",
                Attr::Texts(self.basis.monomials().iter().map(|m| m.name.to_string()).collect()),
            ),
            (
                "ptm:value",
                Attr::Text(
                    "K = sum_i ptm.<m_i> * m_i(u, v); K = occluded fraction, 0 lit, 1 occluded; clamp to [0,1]"
                        .into(),
                ),
            ),
            (
                "ptm:uv",
                Attr::Text("u = dot(l, T), v = dot(l, B), l = unit vector towards the light".into()),
            ),
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
                Attr::Text(format!("ptm-fit {}", env!("CARGO_PKG_VERSION"))),
            ),
        ];
        if let Some(r) = opts.report {
            attrs.push(("ptm:nLights", Attr::I32(r.lights as i32)));
            attrs.push(("ptm:nLightsFit", Attr::I32(r.lights_fit as i32)));
            attrs.push(("ptm:solver", Attr::Text(r.solver.clone())));
            attrs.push(("ptm:rank", Attr::I32(r.rank as i32)));
            if r.cond.is_finite() {
                attrs.push(("ptm:cond", Attr::F64(r.cond)));
            }
            attrs.push(("ptm:rmsMean", Attr::F64(r.rms.mean)));
            attrs.push(("ptm:rmsP99", Attr::F64(r.rms.p99)));
            if let Some(m) = r.max {
                attrs.push(("ptm:maxErrP99", Attr::F64(m.p99)));
            }
            if let Some(h) = r.holdout {
                attrs.push(("ptm:holdoutRmsMean", Attr::F64(h.mean)));
                attrs.push(("ptm:holdoutRmsP99", Attr::F64(h.p99)));
            }
            if !r.warnings.is_empty() {
                attrs.push(("ptm:warnings", Attr::Texts(r.warnings.clone())));
            }
            if r.coverage.len() == self.width * self.height {
                // Holes in the cloth: coefficients 0 there, which reads as "lit" without this.
                channels.push(("coverage".into(), store(&r.coverage)));
            }
            if opts.error_map {
                let n = self.width * self.height;
                if r.rms_map.len() == n {
                    channels.push(("err.rms".into(), store(&r.rms_map)));
                }
                if r.max_map.len() == n {
                    channels.push(("err.max".into(), store(&r.max_map)));
                }
            }
        }
        exrio::write(path, self.width, self.height, channels, attrs)
    }

    /// Loads a PTM EXR. A file that is not a PTM, lacks a coefficient channel or names an
    /// unknown basis is an error saying which.
    pub fn load(path: &Path) -> Result<Ptm> {
        Ok(Self::load_with_info(path)?.0)
    }

    /// Loads a PTM EXR and its header facts and error maps.
    pub fn load_with_info(path: &Path) -> Result<(Ptm, PtmInfo)> {
        let mut c = exrio::read(path)?;
        const WHAT: &str = "PTM";
        match c.attrs.get("ptm:version") {
            Some(Attr::Text(v)) if v == PTM_VERSION => {}
            Some(Attr::Text(v)) => {
                return Err(c.error(format!(
                    "PTM version {v:?} is not supported (expected {PTM_VERSION:?})"
                )))
            }
            _ => {
                let hint = if c.attrs.contains_key("stack:version") {
                    " (it is a sample stack: fit it first with `ptm fit`)"
                } else {
                    " (no `ptm:version` attribute)"
                };
                return Err(c.error(format!("not an occlusion PTM{hint}")));
            }
        }
        let name = c.text("ptm:basis", WHAT)?;
        let basis = Basis::from_name(&name).ok_or_else(|| {
            c.error(format!(
                "unknown basis {name:?} (this version reads {})",
                Basis::ALL.map(|b| b.name()).join(", ")
            ))
        })?;
        if let Ok(list) = c.texts("ptm:monomials", WHAT) {
            let want: Vec<&str> = basis.monomials().iter().map(|m| m.name).collect();
            if list != want {
                return Err(c.error(format!(
                    "monomial list {list:?} does not match basis {name} ({want:?})"
                )));
            }
        }
        let tile = [c.f64("ptm:tileW", WHAT)?, c.f64("ptm:tileH", WHAT)?];
        let storage = match c.text("ptm:storage", WHAT) {
            Ok(s) => s,
            Err(_) => "float32".into(),
        };
        let mut planes = Vec::with_capacity(basis.len());
        for m in basis.monomials() {
            planes.push(c.take_f32(&channel_name(m.name), WHAT)?);
        }
        let info = PtmInfo {
            storage,
            lights: c.f64("ptm:nLights", WHAT).ok().map(|x| x as usize),
            solver: c.text("ptm:solver", WHAT).ok(),
            rank: c.f64("ptm:rank", WHAT).ok().map(|x| x as usize),
            cond: c.f64("ptm:cond", WHAT).ok(),
            rms_mean: c.f64("ptm:rmsMean", WHAT).ok(),
            err_rms: c.take_f32("err.rms", WHAT).ok(),
            coverage: c.take_f32("coverage", WHAT).ok(),
            err_max: c.take_f32("err.max", WHAT).ok(),
        };
        let ptm = Ptm {
            basis,
            width: c.width,
            height: c.height,
            tile,
            planes,
        };
        Ok((ptm, info))
    }
}
