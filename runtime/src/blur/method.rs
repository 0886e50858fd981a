//! What every blur method is ([`Method`]), what it filters ([`Plane`]) and the kernels it can
//! apply ([`Kernel`]); the methods themselves are the sibling modules, chosen by
//! [`super::method`].

use std::any::Any;
use std::sync::Arc;

use crate::caster::Caster;
use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, PlaneGpu};
use crate::Result;

/// How the caster opacity is averaged over the penumbra kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Blur {
    /// The reference: a regular grid of samples (spacing ≤ ½ texel, ≥ 16 per axis) over the
    /// disk of radius w (cost grows as w²).
    Explicit,
    /// Box of half-side w from a summed-area table of u32 counts (constant cost, exact sums).
    Sat,
    /// Trilinear lookup in the caster's MIP chain at level log2(2w) (constant cost; the
    /// kernel is a blend of two power-of-two boxes on a fixed grid, so it errs most at edges).
    Mip,
    /// Per light, a horizontal then a vertical box pass (half-side w) over the caster with
    /// running sums, then a bilinear lookup (cost per light ∝ caster texels, not w).
    Separable,
}

impl Blur {
    /// Every blur method, in the order help texts and reports list them.
    pub const ALL: [Blur; 4] = [Blur::Explicit, Blur::Sat, Blur::Mip, Blur::Separable];

    /// The method in words, as the CLI and reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            Blur::Explicit => "explicit",
            Blur::Sat => "sat",
            Blur::Mip => "mip",
            Blur::Separable => "separable",
        }
    }
}

/// A filtered planar image: what a method convolves. Texels are packed 8-bit values per
/// channel (`r | g << 8 | b << 16 | a << 24`, each 0..=255), row-major, row 0 at the far edge; texels
/// outside the image count as 0 (transparent).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plane {
    /// Texels w, h.
    pub size: [u32; 2],
    /// Channels that differ (1: all four equal, a grey opacity; 3: coloured opacity; 4: a glossy
    /// scene's premultiplied linear colour α·rgb and opacity α, `caster::reflection_texels`).
    pub channels: u32,
    /// The packed texels.
    pub texels: Vec<u32>,
}

/// The shape of the kernel a method averages the image over (half-extents `wt` along the
/// image's axes, in texels). A sphere light asks for [`Kernel::Disc`], a rectangular light for
/// [`Kernel::Box`], a Gaussian light for [`Kernel::Gauss`] (`KERNEL_DISC`, `KERNEL_BOX`,
/// `KERNEL_GAUSS` in WGSL).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// The sheared ellipse ((x − shear·y)/wt.x)² + (y/wt.y)² ≤ 1 (a sphere light's kernel: the
    /// ellipse its cone cuts from the caster plane, `cpu::shade::sphere_ellipse`).
    Disc,
    /// The rectangle of half-sides wt, exact.
    Box,
    /// A box approximated by a blend of the two nearest power-of-two boxes on a fixed grid.
    MipBox,
    /// A [`Kernel::Disc`] ellipse as MIP samples along its major axis (elliptical weighted
    /// averaging: the minor axis picks the level, major/minor the number of samples).
    Ewa,
    /// The Gaussian of standard deviations wt (shear 0), exactly.
    Gauss,
    /// A [`Kernel::Gauss`] as the product of two sums of three boxes
    /// (`blur::sat::GAUSS_HALF`, `GAUSS_WEIGHT`): nine box lookups.
    GaussBoxes,
}

/// What a method prepares on the CPU in `Scene::prepare` (a MIP chain, a separable plan):
/// the method's own type, read back by it with `downcast_ref`.
pub type Prepared = Arc<dyn Any + Send + Sync>;

/// What the twin builds before shading, as the GPU's passes do (a summed-area table, the
/// separable maps): the method's own type.
pub type Built = Box<dyn Any + Send + Sync>;

/// What a method's lookup reads: the image, its uniform block and what was prepared and built.
#[derive(Clone, Copy)]
pub struct Bound<'a> {
    /// The image.
    pub plane: &'a Plane,
    /// Its uniform block, as the shader reads it.
    pub uniform: &'a PlaneGpu,
    /// What [`Method::prepare`] made.
    pub prepared: &'a (dyn Any + Send + Sync),
    /// What [`Method::build_twin`] made.
    pub built: &'a (dyn Any + Send + Sync),
}

/// A blur method: its WGSL, resources, passes and CPU twin.
pub trait Method: Sync {
    /// Which method this is.
    fn blur(&self) -> Blur;

    /// The kernels it applies exactly (any other it is asked for it approximates with the
    /// first).
    fn kernels(&self) -> &'static [Kernel];

    /// Its WGSL, included into `shade.wgsl` where a scene has a caster: its bindings and
    /// `fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) ->
    /// vec4<f32>` (one value per channel; the fourth means something only in a 4-channel image).
    /// `{{CHANNELS}}` is replaced by the image's channel count.
    fn wgsl(&self) -> &'static str;

    /// The compute shaders it runs before shading, (file name, source).
    fn pass_wgsl(&self) -> &'static [(&'static str, &'static str)] {
        &[]
    }

    /// Refuses a caster the method cannot render.
    fn check(&self, _caster: &Caster) -> Result<()> {
        Ok(())
    }

    /// CPU-side preparation from the image: what [`Method::upload`] and the twin read. May set
    /// the method's fields of the image's uniform block.
    fn prepare(
        &self,
        plane: &Plane,
        frame: &Frame,
        lights: &[LightGpu],
        uniform: &mut PlaneGpu,
    ) -> Prepared;

    /// Uploads the image and what was prepared, runs the method's passes (their timings into
    /// `timings`), and returns the shading pass's bindings it declares (`bindings::shade`).
    fn upload(
        &self,
        gpu: &Gpu,
        plane: &Plane,
        prepared: &(dyn Any + Send + Sync),
        timings: &mut Timings,
    ) -> Result<Vec<(u32, wgpu::Buffer)>>;

    /// The twin of the passes: what the shading pass reads besides the prepared data.
    fn build_twin(&self, _plane: &Plane, _prepared: &(dyn Any + Send + Sync)) -> Built {
        Box::new(())
    }

    /// Twin of the WGSL `blur_lookup`: mean image value over the kernel of radii `wt` (texels)
    /// and `shear` ([`Kernel::Disc`]) around texel coordinate t, for light `li`: `kernel`
    /// exactly where [`Method::kernels`] lists it, else the method's own kernel of that size.
    fn blur_lookup(
        &self,
        b: &Bound<'_>,
        li: usize,
        t: [f32; 2],
        wt: [f32; 2],
        shear: f32,
        kernel: Kernel,
    ) -> [f32; 4];

    /// Whether `lights` (moved) can be shaded with what was prepared for the scene's lights,
    /// so a renderer needs only the new light buffer.
    fn keeps(
        &self,
        _prepared: &(dyn Any + Send + Sync),
        _frame: &Frame,
        _uniform: &PlaneGpu,
        _lights: &[LightGpu],
    ) -> bool {
        true
    }
}

/// Nothing prepared (a scene without a caster, or a method that needs nothing).
pub fn nothing() -> Prepared {
    Arc::new(())
}

/// Downcasts what a method prepared or built to its own type.
pub(crate) fn own<'a, T: 'static>(x: &'a (dyn Any + Send + Sync), what: &str) -> &'a T {
    x.downcast_ref::<T>()
        .unwrap_or_else(|| panic!("{what}: prepared by another method"))
}
