//! `ptm-bake`: Embree 4 occlusion baking of tileable swatches from a dome of lights.
//!
//! Data flow: [`Swatch`] (checked mesh and tile) → [`Baker::new`] (Embree scene of the tile,
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

pub use swatch::{Diagnostic, Swatch};
pub use visibility::{
    bake_planes, baker_bytes, sample_xy, BakeConfig, BakeReport, Baker, Planes, Sink,
};

/// Errors of the bake crate; messages name the input and the fact, and no command-line flag
/// (the `ptm` binary maps the variants it knows to its flags).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read {path}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {reason}")]
    InvalidMesh { path: String, reason: String },
    /// The tile (given, from the mesh's `# tile` header, or the mesh's x/y extent) makes no bake
    /// of this mesh; `stray`: stray vertices may be the cause instead.
    #[error("{path}: {reason}: give the tile (the `# tile` header) in the mesh's units{}",
        if *.stray { ", or remove stray vertices" } else { "" })]
    Tile {
        path: String,
        reason: String,
        stray: bool,
    },
    /// A dome too large to build.
    #[error("{0}")]
    Dome(String),
    /// A Fibonacci dome of no light.
    #[error("a Fibonacci dome needs at least 1 light")]
    NoLights,
    /// A minimum elevation (degrees above the swatch plane) outside [0, 90).
    #[error("the minimum elevation {deg}° must lie in [0, 90) degrees")]
    MinElevation { deg: f64 },
    /// A dome spec (`rings:…`, `fibonacci:N`) that does not parse or is too large.
    #[error("dome {spec}: {reason}")]
    BadDome { spec: String, reason: String },
    /// A light distance (mesh units from the tile centre) inside the swatch's bounds, which
    /// reach `reach` from the tile centre.
    #[error("a light distance of {distance:e} puts lights inside the swatch, whose bounds reach {reach:.4e} (mesh units) from the tile centre: give a distance above that")]
    LightsInside { distance: f64, reach: f64 },
    /// A light distance over `times` the swatch size `scale`: distant to f32 precision.
    #[error("a light distance of {distance:e} is over {times:e} times the swatch size ({scale:.4e}): such lights are distant to f32 precision; bake distant lights instead")]
    LightsTooFar {
        distance: f64,
        times: f64,
        scale: f64,
    },
    /// More tracing threads than the bake allows (0 uses one per core).
    #[error("{threads} threads: at most {max} (0 uses one per core; the output is the same for any count)")]
    TooManyThreads { threads: usize, max: usize },
    #[error("{0}")]
    Config(String),
    #[error("embree: {0}")]
    Embree(String),
    #[error(transparent)]
    Fit(#[from] ptm_fit::Error),
}

/// The PTM file layer's errors (loading, saving, atomic output) arrive as fit errors.
impl From<ptm_fit::FormatError> for Error {
    fn from(e: ptm_fit::FormatError) -> Error {
        Error::Fit(e.into())
    }
}

pub type Result<T> = std::result::Result<T, Error>;
