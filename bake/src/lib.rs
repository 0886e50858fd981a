//! `ptm-bake`: Embree 4 occlusion baking of tileable swatches from a dome of lights.
//!
//! Data flow: [`PreparedMesh`] (checked mesh and tile) → [`Baker::new`] (Embree scene of the tile,
//! instanced copies, primary hits of an orthographic camera over the central tile) →
//! [`Baker::trace`] (per light, the occluded fraction K of every texel, handed to a sink light
//! by light, so a fitter can stream without holding the whole sample stack).
//!
//! Conventions (docs/FORMAT.md): tile [0, W]×[0, H], z up; image row 0 at y = H; K = 0 lit,
//! 1 occluded; lights are unit vectors towards the light.

pub mod dome;
pub mod embree;
pub mod swatch;
pub mod tiling;
pub mod visibility;

pub use swatch::PreparedMesh;
pub use visibility::{
    bake_planes, baker_bytes, sample_xy, BakeConfig, BakeReport, Baker, Planes, Sink,
};

/// Errors of the bake crate; messages name the input and what to do.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading a file failed.
    #[error("cannot read {path}")]
    Io {
        /// The file, as given.
        path: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A swatch that cannot be baked (unreadable OBJ, no triangles, a bad tile).
    #[error("{path}: {reason}")]
    InvalidMesh {
        /// The swatch as given (a path or `builtin:NAME`).
        path: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A light dome that cannot be built or read.
    #[error("{0}")]
    Dome(String),
    /// Bake settings that make no bake (resolution, samples, memory).
    #[error("{0}")]
    Config(String),
    /// Embree refused a device, scene or geometry.
    #[error("embree: {0}")]
    Embree(String),
    /// An error of the fit crate or the file layer under it (writing samples, fitting on the fly).
    #[error(transparent)]
    Fit(#[from] ptm_fit::Error),
}

/// The PTM file layer's errors (loading, saving, atomic output) arrive as fit errors.
impl From<ptm_fit::FormatError> for Error {
    fn from(e: ptm_fit::FormatError) -> Error {
        Error::Fit(e.into())
    }
}

/// The bake crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
