//! `ptm-bake`: Embree 4 occlusion baking of tileable swatches from a dome of lights.
//!
//! Data flow: [`PreparedMesh`] (checked mesh and tile) → [`Baker::new`] (Embree scene of the tile,
//! instanced copies, primary hits of an orthographic camera over the central tile) →
//! [`Baker::trace`] (per light, the occluded fraction K of every texel, handed to a sink light
//! by light, so a fitter can stream without holding the whole sample stack). With
//! [`Baker::with_surface`] the primary hits are also summed per texel for the companion maps
//! ([`maps`]: height, tangent-space normal, AO and bent normal, ids and masks; no new rays).
//!
//! Conventions (docs/FORMAT.md): tile [0, W]×[0, H], z up; image row 0 at y = H; K = 0 lit,
//! 1 occluded; lights are unit vectors towards the light.

pub mod dome;
pub mod embree;
mod facing;
pub mod maps;
mod ring;
pub mod swatch;
mod tally;
pub mod tiling;
pub mod visibility;

pub use swatch::{Diagnostic, PreparedMesh};
pub use visibility::{
    bake_planes, baker_bytes, centred_bytes, check_config, sample_xy, BakeConfig, BakeReport,
    Baker, Frame, Planes, PrimarySample, Sink, Tracer,
};

/// Errors of the bake crate; messages name the input and the fact, and no command-line flag
/// (the `ptm` binary maps the variants it knows to its flags).
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
    /// The tile (given, from the mesh's `# tile` header, or the mesh's x/y extent) makes no bake
    /// of this mesh; `stray`: stray vertices may be the cause instead.
    #[error("{path}: {reason}: give the tile (the `# tile` header) in the mesh's units{}",
        if *.stray { ", or remove stray vertices" } else { "" })]
    Tile {
        /// The swatch as given.
        path: String,
        /// The mesh's extent against the tile.
        reason: String,
        /// Whether a few stray vertices could explain the extent.
        stray: bool,
    },
    /// A light dome that cannot be built or read.
    #[error("{0}")]
    Dome(String),
    /// A Fibonacci dome of no light.
    #[error("a Fibonacci dome needs at least 1 light")]
    NoLights,
    /// A minimum elevation (degrees above the swatch plane) outside [0, 90).
    #[error("the minimum elevation {deg}° must lie in [0, 90) degrees")]
    MinElevation {
        /// The elevation given, in degrees.
        deg: f64,
    },
    /// A dome spec (`rings:…`, `fibonacci:N`) that does not parse or is too large.
    #[error("dome {spec}: {reason}")]
    BadDome {
        /// The spec as given.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A light distance (mesh units from the tile centre) inside the swatch's bounds, which
    /// reach `reach` from the tile centre.
    #[error("a light distance of {distance:e} puts lights inside the swatch, whose bounds reach {reach:.4e} (mesh units) from the tile centre: give a distance above that")]
    LightsInside {
        /// The light distance given, in mesh units.
        distance: f64,
        /// How far the swatch's bounds reach from the tile centre, in mesh units.
        reach: f64,
    },
    /// A light distance over `times` the swatch size `scale`: distant to f32 precision.
    #[error("a light distance of {distance:e} is over {times:e} times the swatch size ({scale:.4e}): such lights are distant to f32 precision; bake distant lights instead")]
    LightsTooFar {
        /// The light distance given, in mesh units.
        distance: f64,
        /// The largest distance allowed, in swatch sizes.
        times: f64,
        /// The swatch size, in mesh units.
        scale: f64,
    },
    /// More tracing threads than the bake allows (0 uses one per core).
    #[error("{threads} threads: at most {max} (0 uses one per core; the output is the same for any count)")]
    TooManyThreads {
        /// The thread count asked for.
        threads: usize,
        /// The most the bake allows.
        max: usize,
    },
    /// Bake settings that make no bake (resolution, samples, memory).
    #[error("{0}")]
    Config(String),
    /// Embree refused a device, scene or geometry.
    #[error("embree: {0}")]
    Embree(String),
    /// An error of the file layer (`ptm-format`: writing samples, reading light files).
    #[error(transparent)]
    Format(#[from] ptm_format::Error),
    /// Another tracer of the bake (the GPU's, `ptm-gpubake`) failed; its error, as it said it.
    #[error(transparent)]
    Tracer(Box<dyn std::error::Error + Send + Sync + 'static>),
    /// The consumer of the K planes (a [`Sink`]: a streaming fit, a stack being collected)
    /// failed; its error, as it said it.
    #[error(transparent)]
    Sink(Box<dyn std::error::Error + Send + Sync + 'static>),
}

impl Error {
    /// Wraps the error of a [`Sink`] (e.g. the fit crate's), for `.map_err(Error::sink)`.
    pub fn sink(e: impl std::error::Error + Send + Sync + 'static) -> Error {
        Error::Sink(Box::new(e))
    }
}

/// The bake crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
