//! `ptm-fit`: fitting occlusion PTMs — per-texel least squares and logistic maximum
//! likelihood, the sample stack, RTI image stacks, farm parts — over the file layer
//! `ptm-format` (bases, light sets, the PTM EXR format, `Ptm::load` and CPU evaluation of
//! K(u, v)). A render pipeline that only loads PTM files needs `ptm-format` alone; this crate
//! does not re-export it, so every file-layer item has one path (`ptm_format::…`). It depends
//! on neither Embree nor wgpu.
//!
//! Conventions (docs/FORMAT.md): one tile spans [0, W]×[0, H] with z up; tangent +X, bitangent
//! +Y; images have column 0 at x = 0 and **row 0 at the far edge y = H**; K is the fraction of a
//! texel's footprint that cannot see the light (0 = lit, 1 = occluded); (u, v) = (l·X, l·Y) for
//! the unit vector l towards the light.
//!
//! Modules: [`stack`] (the stored sample stack `samples.exr`), [`solve`] (shared-design SVD fit,
//! streaming [`Accumulator`], per-texel solves, diagnostics), [`logistic`] (the maximum-likelihood
//! fit of the logistic link), [`learned`] (a light basis learned per swatch), `mip` (the MIP chain's footprints, the identity link's levels),
//! [`simd`] (the instruction set the kernels run with, [`simd::Isa`]), [`images`] (RTI PNG
//! stacks), [`shard`] (farm bakes: the partition, part files and their merge), [`diagnostic`]
//! (the fit's typed diagnostics). File layouts: docs/FORMAT.md.

// Index loops over terms and lights mirror the maths (cᵢ, Aᵢⱼ) and keep several arrays in step.
#![allow(clippy::needless_range_loop)]

pub mod diagnostic;
pub mod images;
pub mod learned;
pub mod logistic;
mod mip;
pub mod shard;
pub mod simd;
pub mod solve;
pub mod stack;

use ptm_format::{FileFacts, ToFileFacts};

pub use diagnostic::Diagnostic;
pub use solve::{fit_stack, Accumulator, ErrorStats, FitOptions, FitReport, Weight};
pub use stack::SampleStack;

/// Errors of the fit crate. Messages name the input and the fact; they name no command-line
/// flag (the `ptm` binary maps the variants it knows to its flags).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file, as given.
        path: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A malformed line of a light file (`.lp`).
    #[error("{path}: line {line}: {reason}")]
    LightFile {
        /// The light file, as given.
        path: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        reason: String,
    },
    /// A file that is not what it should be (a stack or image set with a missing or bad part).
    #[error("{path}: {reason}")]
    Format {
        /// The file, as given.
        path: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Arguments or data that make no fit (sizes that disagree, an empty light set).
    #[error("{0}")]
    Invalid(String),
    /// A non-finite sample, and the fit was not asked to drop such samples.
    #[error("non-finite sample {value} at texel (column {col}, row {row}) for light {light}")]
    BadSample {
        /// Texel column (0-based).
        col: usize,
        /// Texel row (0-based, row 0 at y = H).
        row: usize,
        /// Light index in the light set (0-based).
        light: usize,
        /// The sample as read.
        value: f32,
    },
    /// A strict fit refuses to return a result with diagnostics; these are they.
    #[error("the fit has warnings and was asked to be strict: {}", diagnostic::words(.0).join("; "))]
    Strict(Vec<Diagnostic>),
    /// Holding out `holdout` of `lights` lights leaves none to fit.
    #[error("holding out {holdout} lights leaves no light to fit ({lights} lights)")]
    HoldoutTooLarge {
        /// Lights asked to be held out.
        holdout: usize,
        /// Lights in the set.
        lights: usize,
    },
    /// The logistic link shares one design per fit; these samples have per-texel light
    /// directions (lights at a finite distance).
    #[error("the logistic link fits distant lights only; these samples have per-texel light directions (lights at a finite distance)")]
    LogisticNeedsDistantLights,
    /// A farm bake of `rows` image rows (`blocks` blocks of [`shard::ROW_BLOCK`]) cannot be
    /// split into `shard.count` non-empty shards.
    #[error(
        "{rows} rows make only {blocks} blocks of {} rows, so at most {blocks} shards",
        shard::ROW_BLOCK
    )]
    TooManyShards {
        /// The shard asked for (its index and count).
        shard: shard::Shard,
        /// Image rows of the whole bake.
        rows: usize,
        /// Blocks of rows they make.
        blocks: usize,
    },
    /// An RTI image stack (a glob `pattern` of images named by a `.lp` file) that makes no
    /// sample stack.
    #[error("images {pattern:?}: {reason}")]
    Images {
        /// The glob pattern as given.
        pattern: String,
        /// What is wrong with the images.
        reason: String,
    },
    /// A photographed stack (RTI images) whose `.lp` file `lp` puts `lights` of its `of`
    /// lights below the horizon (z < 0). A camera photographs the lit side of the surface, so
    /// such a light is almost surely a sign error in the capture's light positions.
    #[error("{}", below_horizon_words(.lp, .of, .lights))]
    LightsBelowHorizon {
        /// The `.lp` file, as given.
        lp: String,
        /// Lights in it.
        of: usize,
        /// The lights below the horizon.
        lights: Vec<ptm_format::HorizonLight>,
    },
    /// An EXR file without `part:version`: not a farm part.
    #[error("{path}: not a ptm part file (no `part:version`)")]
    NotAPart {
        /// The file, as given.
        path: String,
    },
    /// The file layer's typed refusals (an HP export of another basis than ptm6, a coefficient
    /// too large for half floats).
    #[error(transparent)]
    File(ptm_format::Error),
}

/// The words of [`Error::LightsBelowHorizon`].
fn below_horizon_words(lp: &str, of: &usize, lights: &[ptm_format::HorizonLight]) -> String {
    let n = lights.len();
    format!(
        "{lp}: {n} of its {of} lights {} below the horizon (z < 0): {}; a photographed surface is \
         lit from above it, so {}",
        if n == 1 { "is" } else { "are" },
        ptm_format::lights::horizon_words(lights, 8),
        if n == *of {
            "the .lp's z axis is likely flipped (its z points from the swatch towards the camera)"
        } else {
            "the sign of z is likely wrong in the capture's light positions (z points from the \
             swatch towards the camera): correct or remove those lines"
        }
    )
}

/// The fit crate's result type.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// [`Error::BadSample`] of `light`'s sample `value` at texel index `texel` of an image
    /// `width` texels wide.
    pub(crate) fn bad_sample(texel: usize, width: usize, light: usize, value: f32) -> Error {
        Error::BadSample {
            col: texel % width,
            row: texel / width,
            light,
            value,
        }
    }
}

/// The file layer's errors become the same-named variants here, so matches on
/// `Error::Io` / `Error::Format` / `Error::Invalid` see them whichever crate raised them.
impl From<ptm_format::Error> for Error {
    fn from(e: ptm_format::Error) -> Error {
        match e {
            ptm_format::Error::Io { path, source } => Error::Io { path, source },
            ptm_format::Error::Format { path, reason } => Error::Format { path, reason },
            ptm_format::Error::Invalid(s) => Error::Invalid(s),
            ptm_format::Error::LightFile { path, line, reason } => {
                Error::LightFile { path, line, reason }
            }
            e
            @ (ptm_format::Error::HpNeedsPtm6 { .. } | ptm_format::Error::HalfOverflow { .. }) => {
                Error::File(e)
            }
        }
    }
}

/// A fit's report states the facts its PTM file's header records.
impl ToFileFacts for FitReport {
    fn file_facts(&self) -> FileFacts<'_> {
        FileFacts {
            lights: self.lights,
            lights_fit: self.lights_fit,
            solver: &self.solver,
            rank: self.rank,
            cond: self.cond,
            rms_mean: self.rms.mean,
            rms_p99: self.rms.p99,
            max_p99: self.max.map(|m| m.p99),
            holdout: self.holdout.map(|h| (h.mean, h.p99)),
            holdout_lights: &self.holdout_lights,
            warnings: diagnostic::words(&self.warnings),
            samples: self.samples.as_deref(),
            rms_map: &self.rms_map,
            max_map: &self.max_map,
        }
    }
}
