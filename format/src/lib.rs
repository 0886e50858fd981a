//! `ptm-format`: the occlusion PTM file and all a render pipeline needs to use one — the
//! polynomial bases, links and (u, v) maps ([`basis`]), the table of a learned basis ([`learned`]), the PTM in memory with [`Ptm::load`],
//! [`Ptm::save`] and CPU evaluation ([`ptm`]), the EXR layer under it ([`exrio`]), the one
//! parser of a PTM header ([`header`]), the renderer layout of RGB(A) parts, its lossless
//! conversion and the one decoder both layouts are read through ([`layout`]), HP PTM 1.2
//! export ([`hp`]), the atomic file output every writer of the workspace uses ([`atomic`]), the
//! one seeded hash every crate draws its random numbers from ([`hash`]), the 3-vector helpers
//! ([`vec3`]) and the light sets that bakes and fits share, with the RTI `.lp` file ([`lights`]).
//!
//! It depends on `exr`, `half` and `thiserror` only: no solver (nalgebra), no thread pool
//! (rayon), no image codec, no Embree, no wgpu. The fitter (`ptm-fit`), the baker (`ptm-bake`)
//! and the renderer (`ptm-runtime`) build on it; each item has one path, here.
//!
//! Conventions (docs/FORMAT.md): one tile spans [0, W]×[0, H] with z up; tangent +X, bitangent
//! +Y; images have column 0 at x = 0 and **row 0 at the far edge y = H**; K is the fraction of a
//! texel's footprint that cannot see the light (0 = lit, 1 = occluded); (u, v) = (l·X, l·Y) for
//! the unit vector l towards the light.
//!
//! Loading a PTM in a render pipeline:
//! ```no_run
//! let ptm = ptm_format::Ptm::load("weave.ptm.exr".as_ref())?;
//! let (u, v) = (0.5f32, 0.25f32); // (l·X, l·Y) of the unit vector towards the light
//! let k = ptm.eval(3, 7, u, v); // occluded fraction at column 3, row 7, clamped to [0, 1]
//! // Holes in the cloth (coverage 0) have no K: mask them.
//! let hole = ptm.coverage.as_ref().is_some_and(|c| c[7 * ptm.width + 3] <= 0.0);
//! # let _ = (k, hole);
//! # Ok::<(), ptm_format::Error>(())
//! ```

// Index loops over terms mirror the maths (cᵢ) and keep several arrays in step.
#![allow(clippy::needless_range_loop)]

pub mod atomic;
pub mod basis;
pub mod exrio;
pub mod hash;
pub mod header;
pub mod hp;
pub mod layout;
pub mod learned;
pub mod lights;
pub mod ptm;
pub mod vec3;

pub use atomic::{same_file, write_atomic, Transaction};
pub use basis::{Basis, Link, Monomial, UvMap};
pub use layout::{Layout, PtmFile};
pub use learned::LearnedTable;
pub use lights::{HorizonLight, LightSet};
pub use ptm::{FileFacts, Level, Ptm, PtmInfo, SaveOptions, ToFileFacts};

/// Errors of the format crate. Messages name the file and, where there is something to do, what.
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
    /// A file that is not what it should be (not a PTM, a missing channel, a bad attribute).
    #[error("{path}: {reason}")]
    Format {
        /// The file, as given.
        path: String,
        /// What is wrong with it.
        reason: String,
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
    /// Arguments that make no file (plane sizes, mismatched maps).
    #[error("{0}")]
    Invalid(String),
    /// HP's PTM 1.2 holds only the 6-term biquadratic; this PTM has another basis.
    #[error("{path}: HP's .ptm format holds only the 6-term biquadratic, not {}", basis.name())]
    HpNeedsPtm6 {
        /// The HP file asked for.
        path: String,
        /// The PTM's basis.
        basis: Basis,
    },
    /// A coefficient (largest magnitude `magnitude`, or NaN) that a half float cannot hold.
    #[error("{path}: a coefficient of magnitude {magnitude:e} does not fit in a half float; save as float32")]
    HalfOverflow {
        /// The file being written.
        path: String,
        /// The largest coefficient magnitude (NaN if a coefficient is NaN).
        magnitude: f32,
    },
}

/// The format crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
