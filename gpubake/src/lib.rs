//! `ptm-gpubake`: the occlusion bake of `ptm-bake` traced on a GPU with hardware ray queries
//! (wgpu's `EXPERIMENTAL_RAY_QUERY`: Vulkan `VK_KHR_ray_query`), for the workstation a lookdev
//! artist bakes on.
//!
//! Data flow: [`adapter::choose`] picks the device (`cpu | gpu | auto`) and says why →
//! [`GpuBaker::new_rows`] (one BLAS of the tile's mesh, a TLAS per set of copies the CPU's tiling
//! rule keeps, primary hits of the orthographic camera at the CPU bake's hashed sample
//! positions, in bands of rows that fit the device) → [`ptm_bake::Tracer::trace`] (per light, one
//! shadow ray per footprint sample in a compute shader, occluded counts summed on the GPU, K
//! handed to the same sink as the CPU bake's). Everything geometric comes from `ptm-bake`
//! ([`ptm_bake::Frame`], [`ptm_bake::tiling`], [`ptm_bake::sample_xy`]), so both tracers trace
//! the same rays; they differ only where two intersectors disagree about a ray grazing an edge.
//!
//! This crate is the only bake crate that links wgpu: `ptm-bake` stays CPU-only.

pub mod adapter;
pub mod baker;
pub mod budget;
pub mod scene;

pub use adapter::{choose, Asked, Choice, Used};
pub use baker::{bake_planes, GpuBaker, GpuConfig};

/// Errors of the GPU bake; messages name the adapter or the figures, and no command-line flag.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// No adapter with ray queries; `found` lists every adapter wgpu saw.
    #[error("no GPU adapter with ray queries (wgpu EXPERIMENTAL_RAY_QUERY, Vulkan VK_KHR_ray_query) was found; {}",
        if found.is_empty() { "wgpu found no adapter at all".to_string() } else { format!("found: {}", found.join("; ")) })]
    NoRayQueries {
        /// Every adapter found, described ([`adapter::describe`]).
        found: Vec<String>,
    },
    /// The adapter refused a device with ray queries.
    #[error("{adapter}: cannot open a device with ray queries: {reason}")]
    Device {
        /// The adapter, described.
        adapter: String,
        /// wgpu's reason.
        reason: String,
    },
    /// The mesh or the tile copies exceed one of the device's limits (checked before upload).
    #[error("{what}: {need} exceeds the device's {limit_name} of {limit} ({adapter})")]
    TooBig {
        /// What is too big, in words.
        what: String,
        /// Its size, in the limit's unit.
        need: u64,
        /// The device limit.
        limit: u64,
        /// wgpu's name of the limit.
        limit_name: &'static str,
        /// The adapter, described.
        adapter: String,
    },
    /// Even the smallest band of rows does not fit the device (checked before upload).
    #[error("a band of {rows} rows × {width} texels × {spp} samples needs {need} bytes of {what}, over the device's {limit_name} of {limit} bytes ({adapter})")]
    BandTooBig {
        /// Rows in the smallest band.
        rows: usize,
        /// Texels per row.
        width: usize,
        /// Samples per texel.
        spp: u32,
        /// The buffer, in words.
        what: &'static str,
        /// Bytes it needs.
        need: u64,
        /// The limit in bytes.
        limit: u64,
        /// wgpu's name of the limit (or `band budget`).
        limit_name: &'static str,
        /// The adapter, described.
        adapter: String,
    },
    /// The device was lost or failed mid-bake (a driver reset, out of memory, a validation
    /// error): nothing of the bake is usable.
    #[error("the GPU failed while {stage} ({adapter}): {reason}")]
    Lost {
        /// What the bake was doing.
        stage: &'static str,
        /// The adapter, described.
        adapter: String,
        /// What wgpu said.
        reason: String,
    },
    /// An error of the bake itself (settings, the sink).
    #[error(transparent)]
    Bake(#[from] ptm_bake::Error),
}

impl From<Error> for ptm_bake::Error {
    /// As the bake crate's error: its own errors unwrapped, the GPU's as [`ptm_bake::Error::Tracer`].
    fn from(e: Error) -> ptm_bake::Error {
        match e {
            Error::Bake(b) => b,
            other => ptm_bake::Error::Tracer(Box::new(other)),
        }
    }
}

/// The GPU bake's result type.
pub type Result<T> = std::result::Result<T, Error>;
