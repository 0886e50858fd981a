//! `ptm-runtime`: wgpu/WGSL shading of a cloth plane under spherical area lights, with penumbra-map
//! soft shadows from a planar caster and micro-occlusion from an occlusion PTM; and its CPU twin.
//!
//! Data flow: a [`Scene`] (public-field config) is [`Scene::prepare`]d into [`SceneBuffers`] — the
//! uniform block, light list, texel-major PTM coefficients and the filtered planar image the
//! blur convolves (the caster's opacity), exactly as the GPU sees them ([`layout`] holds every
//! GPU struct, field for field with its WGSL; [`bindings`] every binding, by name). [`gpu::render`]
//! runs the WGSL variant assembled for that scene ([`shader`]); [`cpu::render`] is its twin in
//! Rust (one module per WGSL file, same function names, same maths) and what the tests compare
//! the GPU with. [`blur`] is the convolution's extension point: one module per method owning its
//! WGSL, CPU twin, resources, passes and kernels. [`caster`] prepares the caster's opacity,
//! [`mip`] the MIP chains; [`penumbra`] holds the blur-radius geometry and the analytic profile,
//! [`reference`](mod@reference) the Monte Carlo ground truth; [`device`] the headless device.
//!
//! Imports run one way: `layout`, `bindings` ← `device`, `caster`, `mip` ← `blur` ← `scene` ←
//! `shader`, `cpu`, `gpu` ← `reference`, `window`.

// Per-channel loops index several parallel arrays (rgb of albedo, colour, opacity) at once, as
// the WGSL does with vectors; iterator zips would hide that correspondence.
#![allow(clippy::needless_range_loop)]

pub mod bindings;
pub mod blur;
pub mod caster;
pub mod compare;
pub mod cpu;
pub mod device;
pub mod environment;
pub mod gpu;
pub mod layout;
pub mod mesh;
pub mod mip;
pub mod output;
pub mod penumbra;
pub mod reference;
pub mod scene;
pub mod shader;
pub mod synthetic;
#[cfg(feature = "window")]
pub mod window;

pub use gpu::{Gpu, Timings};
pub use output::Image;
pub use scene::{Blur, Caster, Glossy, Light, Scene, SceneBuffers, Warning};

/// Errors of the runtime crate. Messages name the input and, where there is something to do, what.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// wgpu found no adapter (the reason from wgpu).
    #[error(
        "no GPU adapter found ({0}); install a Vulkan driver (on Debian: apt-get install \
         mesa-vulkan-drivers libvulkan1 for the lavapipe software adapter)"
    )]
    NoAdapter(String),
    /// The adapter refused a device.
    #[error("creating the GPU device on {adapter}: {reason}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's reason.
        reason: String,
    },
    /// A GPU operation failed (validation, mapping a buffer, a lost device).
    #[error("GPU {stage}: {reason}")]
    Gpu {
        /// What was being done, e.g. `readback`.
        stage: &'static str,
        /// wgpu's reason.
        reason: String,
    },
    /// An assembled WGSL variant that naga or wgpu refused.
    #[error("shader variant {variant}: {reason}")]
    Shader {
        /// The variant's short name, e.g. `ptm11+sat`.
        variant: String,
        /// The validator's message.
        reason: String,
    },
    /// An image (caster, albedo, output) that cannot be read or written.
    #[error("{path}: {reason}")]
    Image {
        /// The file, as given.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// A scene that cannot be rendered (sizes, lights, camera), in words.
    #[error("invalid scene: {0}")]
    Scene(String),
    /// The separable blur with a tilted caster (its per-light box passes assume one blur radius
    /// per light).
    #[error("invalid scene: the separable blur needs a caster parallel to the cloth (its per-light box passes assume one blur radius per light), but the caster is tilted {tilt_deg}°: use the sat, mip or explicit blur")]
    SeparableNeedsParallelCaster {
        /// The caster's tilt about its centre line, in degrees.
        tilt_deg: f32,
    },
    /// An error of the file layer (`ptm-format`: loading a PTM, writing images).
    #[error(transparent)]
    Format(#[from] ptm_format::Error),
}

/// The runtime crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
