//! The scene (acceptor plane, PTM, albedo, lights, caster) and its preparation into the exact
//! buffers both the GPU shader and the CPU twin consume.
//!
//! World space is the swatch frame: the acceptor is the plane z = 0, tangent +X, bitangent +Y,
//! normal +Z. Lengths are swatch units (the PTM tile is `ptm.tile` = [W, H] of them).

use ptm_format::{LearnedTable, Link, Ptm, UvMap};

pub use crate::blur::Blur;
pub use crate::caster::{Caster, MAX_CASTER_SIDE};
use crate::layout::{Frame, LightGpu, PlaneGpu, PtmLevel};
use crate::{Error, Result};

/// Upper bound on the explicit blur's samples per axis (it grows as 4 × the radius in texels,
/// so it is capped from a radius of 64 texels on). Also a lavapipe limit: Mesa 22.3.6 llvmpipe
/// returned wrong sums for fragment loops of 512² = 262144 iterations (no shadow at all), while
/// 256² matched the CPU twin exactly.
pub const MAX_EXPLICIT_SAMPLES: u32 = 256;

/// Largest output side: wgpu's guaranteed `max_texture_dimension_2d` (8192).
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// The largest angular radius of a distant light, radians (45°): a wider source is a sky, and
/// its cone would not meet a caster plane in a closed ellipse at moderate elevations.
pub const MAX_DISTANT_RADIUS: f32 = std::f32::consts::FRAC_PI_4;

/// vec4s of [`SceneBuffers::light_terms`] the shader's uniform block holds: 64 KiB, the
/// smallest `max_uniform_buffer_binding_size` GPUs are required to offer (409 lights over an
/// 11-term basis, 315 over 16 terms).
pub const MAX_LIGHT_TERMS: usize = 4096;

/// `v` scaled to unit length (a zero vector stays zero; `prepare` refuses it for a light).
fn normalize3(v: [f32; 3]) -> [f32; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > 0.0 {
        v.map(|x| x / n)
    } else {
        v
    }
}

/// A spherical area light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Centre in world space (swatch units; z above the acceptor).
    pub position: [f32; 3],
    /// Sphere radius R in swatch units (0 = point light: a hard shadow); ignored for a
    /// rectangle.
    pub radius: f32,
    /// `Some([a, b])`: a uniform rectangular light of sides a along X and b along Y centred at
    /// `position`, facing straight down (parallel to the cloth), instead of a sphere. Its
    /// penumbra kernel on a caster parallel to the cloth is that rectangle scaled by the
    /// caster's fraction of the way to the light: a box of any aspect ratio, exact with the
    /// summed-area table.
    pub rect: Option<[f32; 2]>,
    /// A rectangle's orientation: its side a turned this many degrees from X towards Y about
    /// the vertical through `position` (0: sides along X and Y). Its kernel is then a
    /// parallelogram on the caster (a turned rectangle, sheared by a tilted caster), which the
    /// per-pixel methods average as six boxes of exact areas (`rect_slabs`); not with
    /// `Blur::Separable`, whose kernels are per light along X and Y.
    pub rect_angle_deg: f32,
    /// A sphere's penumbra kernel: `false` (the default) the ellipse where the cone from the
    /// shaded point to the sphere cuts the caster plane (longer along the direction away from
    /// the light, more so the more oblique the light); `true` the square box of half-side R·s
    /// everywhere that the runtime used before the ellipse, kept for comparisons.
    pub square_box: bool,
    /// `Some([σx, σy])`: a light facing straight down whose radiance falls off from `position`
    /// as a Gaussian of standard deviations σx along X and σy along Y, instead of a sphere (its
    /// total power as a point light's of `intensity`). Its penumbra kernel on a caster parallel
    /// to the cloth is that Gaussian scaled by the caster's fraction of the way to the light.
    pub gaussian: Option<[f32; 2]>,
    /// A distant light (the sun, a key light far away): `position` is then the direction
    /// towards it (normalised; z > 0), the same at every point of the cloth, `radius` its
    /// angular radius in radians (0: a hard shadow; at most 45°), and the irradiance it gives a
    /// surface facing it is `intensity · color` (no falloff). Its penumbra kernel is the ellipse
    /// its cone cuts from the caster plane, as a sphere's; not a rectangle or a Gaussian. On
    /// the plane K under it is the same at every point for given coefficients, so its basis
    /// terms (monomials or learned tables) are evaluated once per frame
    /// ([`SceneBuffers::light_terms`]) and each pixel only dots them with its coefficients; on
    /// a mesh the direction turns with the tangent frame and K is evaluated per pixel, and the
    /// macro shadow's map is orthographic along the direction (`cpu::mesh::shadow_view_ortho`).
    pub distant: bool,
    /// Radiant intensity scale: irradiance at distance d is `intensity · color · cos / d²`.
    pub intensity: f32,
    /// Linear RGB colour.
    pub color: [f32; 3],
}

impl Default for Light {
    /// A white point light of intensity 1 one unit above the origin.
    fn default() -> Light {
        Light {
            position: [0.0, 0.0, 1.0],
            radius: 0.0,
            rect: None,
            rect_angle_deg: 0.0,
            square_box: false,
            gaussian: None,
            distant: false,
            intensity: 1.0,
            color: [1.0; 3],
        }
    }
}

impl Light {
    /// A rectangle whose sides do not run along X and Y (turned other than by a multiple of
    /// 180°): its kernel is a parallelogram.
    pub fn is_turned_rect(&self) -> bool {
        self.rect.is_some() && self.rect_angle_deg.to_radians().sin() != 0.0
    }

    /// The light's largest distance from its centre in the plane of the cloth: the sphere's
    /// radius, or half the rectangle's diagonal (how far a penumbra can spread).
    pub fn extent(&self) -> f32 {
        match (self.rect, self.gaussian) {
            (Some([a, b]), _) => 0.5 * (a * a + b * b).sqrt(),
            // Three standard deviations hold all but 1 % of it.
            (None, Some([a, b])) => 3.0 * (a * a + b * b).sqrt(),
            (None, None) => self.radius,
        }
    }
}

/// A perspective camera (the default camera is orthographic top-down over `Scene::view`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perspective {
    /// Eye position (world, swatch units).
    pub eye: [f32; 3],
    /// Point looked at.
    pub target: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

/// A glossy receiver: the cloth also reflects the planar caster (seen from below) over a
/// background, blurred by a lobe that is a uniform cone of half-angle
/// [`Glossy::cone_half_angle`] around the mirror direction. Its kernel on the caster is the
/// ellipse that cone cuts from the caster plane, which grows linearly with the distance from
/// the reflection point to the plane: the blur method averages the caster's opacity over it as
/// for a spherical "imaginary light" on the mirror ray whose cone is the lobe's. Where the
/// kernel runs off the caster, the background is reflected. The pixel is
/// (1 − F)·diffuse + F·(mean(α·rgb) + (1 − ᾱ)·background), F Schlick's Fresnel of F0 at the
/// view angle, mean(α·rgb) the mean over the kernel of each texel's premultiplied linear colour
/// and ᾱ of its opacity (the caster's image then has four channels,
/// `caster::reflection_texels`; its shadows use α). With [`Glossy::environment`] the
/// background is a sky image, averaged over the same lobe (`environment.rs`).
#[derive(Clone, Debug, PartialEq)]
pub struct Glossy {
    /// 0 (a mirror) ..= 1 (a cone of half-angle 45°): the half-angle is roughness × 45°.
    pub roughness: f32,
    /// Linear RGB radiance reflected where the lobe misses the caster (finite, ≥ 0).
    pub background: [f32; 3],
    /// Reflectance at normal incidence F0, in [0, 1].
    pub f0: f32,
    /// A background image (a sky) reflected instead of the colour `background`: looked up
    /// along the mirror direction, averaged over the lobe's cone by its MIP chain.
    pub environment: Option<std::sync::Arc<crate::environment::Environment>>,
}

impl Glossy {
    /// The lobe's cone half-angle in radians: roughness × π/4.
    pub fn cone_half_angle(&self) -> f32 {
        self.roughness * std::f32::consts::FRAC_PI_4
    }

    /// How many nested cones the shader averages the lobe as: one per 10° of half-angle started,
    /// at most 4 (a 4.5° lobe is one cone, 22.5° three, 45° four). A uniform-area kernel is a
    /// uniform-solid-angle lobe only for narrow cones; the cones' weights give each ring between
    /// them its exact solid angle (`glossy_ring_weights` in `shade.wgsl`).
    pub fn rings(&self) -> u32 {
        (self.cone_half_angle().to_degrees() / 10.0)
            .ceil()
            .clamp(1.0, 4.0) as u32
    }
}

/// Everything one frame shows.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Output size in pixels.
    pub size: [u32; 2],
    /// World rectangle [x0, y0, x1, y1] seen by the top-down orthographic camera; pixel row 0
    /// is the far edge y1.
    pub view: [f32; 4],
    /// The occlusion PTM tiled over the plane with period `ptm.tile`; `None` renders without K.
    pub ptm: Option<Ptm>,
    /// Linear RGB albedo used when `albedo_texture` is `None`.
    pub albedo: [f32; 3],
    /// Optional albedo texture (linear RGB, row 0 at the far edge), tiled with the PTM's period
    /// (or the view's size without a PTM): (width, height, texels).
    pub albedo_texture: Option<(usize, usize, Vec<[f32; 3]>)>,
    /// The spherical (or point) lights shading the cloth.
    pub lights: Vec<Light>,
    /// A planar caster above the cloth whose soft shadow is rendered, if any.
    pub caster: Option<Caster>,
    /// With a caster: its RGB transmits coloured light (stained glass) instead of grey.
    pub colored_shadow: bool,
    /// How the caster's shadow is blurred (ignored without a caster).
    pub blur: Blur,
    /// Perspective camera; `None` = orthographic top view of `view`. Pixels whose ray misses
    /// the cloth plane are black.
    pub perspective: Option<Perspective>,
    /// A glossy receiver reflecting the caster ([`Glossy`]); needs a caster.
    pub glossy: Option<Glossy>,
}

impl Scene {
    /// A scene with no PTM (the shading alone, K = 0), one unit tile viewed from above at 1×1
    /// pixels, no lights, no caster: for a preview without a file, or a placeholder.
    pub fn without_ptm() -> Scene {
        let placeholder = Ptm {
            basis: ptm_format::Basis::Ptm6,
            width: 1,
            height: 1,
            link: Link::Identity,
            uv: UvMap::Projected,
            mips: Vec::new(),
            coverage: None,
            tile: [1.0, 1.0],
            planes: vec![vec![0.0]; 6],
            learned: None,
        };
        let mut s = Scene::over_ptm(placeholder, 1, [1, 1]);
        s.ptm = None;
        s
    }

    /// A scene viewing `repeat`×`repeat` tiles of `ptm` from above, no lights, no caster.
    pub fn over_ptm(ptm: Ptm, repeat: u32, size: [u32; 2]) -> Scene {
        let view = [
            0.0,
            0.0,
            (ptm.tile[0] * repeat as f64) as f32,
            (ptm.tile[1] * repeat as f64) as f32,
        ];
        Scene {
            size,
            view,
            ptm: Some(ptm),
            albedo: [0.8, 0.8, 0.8],
            albedo_texture: None,
            lights: Vec::new(),
            caster: None,
            colored_shadow: false,
            blur: Blur::Sat,
            perspective: None,
            glossy: None,
        }
    }

    /// Some light is a turned rectangle ([`Light::is_turned_rect`]).
    pub fn turned_rect(&self) -> bool {
        self.lights.iter().any(Light::is_turned_rect)
    }

    /// The scene with every light turned by `angle` radians about the vertical axis through the
    /// centre of the view (a turntable frame).
    pub fn with_lights_turned(&self, angle: f32) -> Scene {
        let c = [
            0.5 * (self.view[0] + self.view[2]),
            0.5 * (self.view[1] + self.view[3]),
        ];
        let (s, co) = angle.sin_cos();
        let mut out = self.clone();
        for l in &mut out.lights {
            // A distant light's direction turns about the vertical itself.
            let c = if l.distant { [0.0; 2] } else { c };
            let d = [l.position[0] - c[0], l.position[1] - c[1]];
            l.position[0] = c[0] + co * d[0] - s * d[1];
            l.position[1] = c[1] + s * d[0] + co * d[1];
        }
        out
    }

    /// The light buffer as the shader reads it (what [`Scene::prepare`] puts in
    /// [`SceneBuffers::lights`]; a moved light needs only this, see `gpu::Renderer::set_lights`).
    pub fn gpu_lights(&self) -> Vec<LightGpu> {
        self.lights
            .iter()
            .map(|l| LightGpu {
                position: match l.distant {
                    true => normalize3(l.position),
                    false => l.position,
                },
                radius: match l.distant {
                    true => l.radius.clamp(0.0, MAX_DISTANT_RADIUS).sin(),
                    false => l.radius.max(0.0),
                },
                color: l.color.map(|c| c * l.intensity),
                shape: match (l.rect, l.gaussian, l.square_box) {
                    _ if l.distant => LightGpu::DISTANT,
                    (Some(_), _, _) => LightGpu::RECT,
                    (None, Some(_), _) => LightGpu::GAUSSIAN,
                    (None, None, false) => LightGpu::SPHERE,
                    (None, None, true) => LightGpu::SPHERE_SQUARE_BOX,
                },
                half: match (l.rect, l.gaussian) {
                    (Some(r), _) => r.map(|x| 0.5 * x),
                    (None, Some(sigma)) => sigma,
                    (None, None) => [0.0; 2],
                },
                axis: match l.rect {
                    Some(_) => {
                        let (s, c) = l.rect_angle_deg.to_radians().sin_cos();
                        [c, s]
                    }
                    None => [1.0, 0.0],
                },
            })
            .collect()
    }

    /// Validates and lays the scene out as the shader's buffers.
    pub fn prepare(&self) -> Result<SceneBuffers> {
        let [w, h] = self.size;
        if w == 0 || h == 0 {
            return Err(Error::Scene(format!("output size {w}×{h} is empty")));
        }
        if w.max(h) > MAX_IMAGE_SIDE {
            return Err(Error::Scene(format!(
                "output size {w}×{h} exceeds {MAX_IMAGE_SIDE} pixels a side (the largest render \
                 target GPUs are required to offer): lower the size"
            )));
        }
        for (i, l) in self.lights.iter().enumerate() {
            let finite = l.position.iter().chain(&l.color).all(|x| x.is_finite());
            if !(finite
                && l.radius.is_finite()
                && l.radius >= 0.0
                && l.intensity.is_finite()
                && l.intensity >= 0.0
                && l.color.iter().all(|&c| c >= 0.0))
            {
                return Err(Error::Scene(format!(
                    "light {i} (position {:?}, radius {}, intensity {}, colour {:?}) must have a \
                     finite position and a finite radius, intensity and colour ≥ 0",
                    l.position, l.radius, l.intensity, l.color
                )));
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            if let Some(r) = l.rect {
                if !r.iter().all(|x| x.is_finite() && *x > 0.0) {
                    return Err(Error::Scene(format!(
                        "light {i} is a rectangle of sides {} × {}: both must be finite and > 0",
                        r[0], r[1]
                    )));
                }
            }
            if !l.rect_angle_deg.is_finite() {
                return Err(Error::Scene(format!(
                    "light {i}'s rectangle is turned {}°: the angle must be finite",
                    l.rect_angle_deg
                )));
            }
            if self.caster.is_some() && self.blur == Blur::Separable && l.is_turned_rect() {
                return Err(Error::Scene(format!(
                    "light {i} is a rectangle turned {}°: the separable blur filters along X and \
                     Y only; use sat, mip or explicit (or sides along X and Y)",
                    l.rect_angle_deg
                )));
            }
            if l.distant {
                let n2: f32 = l.position.iter().map(|x| x * x).sum();
                if !(n2 > 0.0 && n2.is_finite()) {
                    return Err(Error::Scene(format!(
                        "distant light {i}'s direction {:?} must be a finite non-zero vector \
                         towards the light",
                        l.position
                    )));
                }
                if l.radius > MAX_DISTANT_RADIUS {
                    return Err(Error::Scene(format!(
                        "distant light {i}'s angular radius {:.2}° exceeds {}°: a source that \
                         wide is a sky (use a glossy background image), not a light",
                        l.radius.to_degrees(),
                        MAX_DISTANT_RADIUS.to_degrees()
                    )));
                }
                if l.rect.is_some() || l.gaussian.is_some() {
                    return Err(Error::Scene(format!(
                        "light {i} is distant and a rectangle or Gaussian: a distant light is a \
                         disc of an angular radius; drop one"
                    )));
                }
            }
            if let Some(sigma) = l.gaussian {
                if !sigma.iter().all(|x| x.is_finite() && *x > 0.0) {
                    return Err(Error::Scene(format!(
                        "light {i} is a Gaussian of σ {} × {}: both must be finite and > 0 (a \
                         point light is radius 0)",
                        sigma[0], sigma[1]
                    )));
                }
                if l.rect.is_some() {
                    return Err(Error::Scene(format!(
                        "light {i} is both a rectangle and a Gaussian: give it one shape"
                    )));
                }
            }
        }
        if let (Some(ptm), true) = (&self.ptm, self.lights.iter().any(|l| l.distant)) {
            let stride = light_term_stride(ptm.basis.len());
            if self.lights.len() * stride > MAX_LIGHT_TERMS {
                return Err(Error::Scene(format!(
                    "{} lights with a distant one over a {}-term basis need {} vec4s of \
                     per-frame terms, more than the {MAX_LIGHT_TERMS} (64 KiB) a uniform block \
                     holds on every GPU: use at most {} lights",
                    self.lights.len(),
                    ptm.basis.len(),
                    self.lights.len() * stride,
                    MAX_LIGHT_TERMS / stride
                )));
            }
        }
        if let Some(g) = &self.glossy {
            if !(0.0..=1.0).contains(&g.roughness) {
                return Err(Error::Scene(format!(
                    "glossy roughness {} must lie in [0, 1] (0 a mirror, 1 a 45° cone)",
                    g.roughness
                )));
            }
            if !g.background.iter().all(|x| x.is_finite() && *x >= 0.0) {
                return Err(Error::Scene(format!(
                    "glossy background {:?} must be finite and ≥ 0 (linear RGB)",
                    g.background
                )));
            }
            if !(0.0..=1.0).contains(&g.f0) {
                return Err(Error::Scene(format!(
                    "glossy reflectance F0 {} must lie in [0, 1]",
                    g.f0
                )));
            }
            if let Some(e) = &g.environment {
                let n = e.size;
                let levels = crate::environment::level_count(n.max(1));
                if !n.is_power_of_two()
                    || n > crate::environment::MAX_SIZE
                    || e.texels.len() != crate::environment::level_offset(n, levels)
                    || !e
                        .texels
                        .iter()
                        .flatten()
                        .all(|x| x.is_finite() && *x >= 0.0)
                {
                    return Err(Error::Scene(format!(
                        "glossy background image: a {n}² map with {} texels (a power-of-two side \
                         ≤ {}, every level, finite and ≥ 0): build it with Environment::load",
                        e.texels.len(),
                        crate::environment::MAX_SIZE
                    )));
                }
            }
            if self.caster.is_none() {
                return Err(Error::Scene(
                    "a glossy receiver reflects the caster: give it a caster".into(),
                ));
            }
            if self.blur == Blur::Separable {
                return Err(Error::Scene(
                    "a glossy receiver needs a kernel per pixel; the separable blur has one per \
                     light: use sat, mip or explicit"
                        .into(),
                ));
            }
            if self.colored_shadow {
                return Err(Error::Scene(
                    "a glossy receiver reflects a grey-opacity caster; coloured shadows use the \
                     image's three channels"
                        .into(),
                ));
            }
        }
        let [x0, y0, x1, y1] = self.view;
        if !(x1 > x0 && y1 > y0) {
            return Err(Error::Scene(format!(
                "view rectangle {:?} must have x1 > x0 and y1 > y0",
                self.view
            )));
        }
        let mut frame = Frame {
            view: self.view,
            screen: [w as f32, h as f32],
            tile: [x1 - x0, y1 - y0],
            albedo: self.albedo,
            light_count: self.lights.len() as u32,
            ..Frame::zeroed()
        };
        if let Some(cam) = &self.perspective {
            let [right, up, forward] = camera_basis(cam, w as f32 / h as f32)?;
            frame.perspective = 1;
            frame.eye = cam.eye;
            frame.cam_right = right;
            frame.cam_up = up;
            frame.cam_forward = forward;
        }

        let mut coeffs = Vec::new();
        let mut ptm_levels: Vec<PtmLevel> = Vec::new();
        let mut nonfinite_coeffs = 0;
        let mut warnings = Vec::new();
        let mut basis = None;
        let mut coverage = Vec::new();
        let mut learned = Vec::new();
        let mut learned_grid = 0;
        let (mut link, mut uv) = (Link::Identity, UvMap::Projected);
        if let Some(ptm) = &self.ptm {
            check_ptm(ptm)?;
            let n = ptm.basis.len();
            if ptm.basis.is_learned() {
                let table = learned_table(ptm)?;
                learned = node_major(table);
                learned_grid = table.grid as u32;
            }
            // Texel-major (all coefficients of a texel together): one cache line per lookup.
            let texels = ptm.width * ptm.height;
            coeffs.reserve(texels * n);
            for t in 0..texels {
                coeffs.extend(ptm.planes.iter().map(|p| p[t]));
            }
            // A NaN coefficient would make K (and the pixel) NaN on some GPUs and 0 on others:
            // zero it (K = 0, lit) and report how many there were.
            for c in coeffs.iter_mut().filter(|c| !c.is_finite()) {
                *c = 0.0;
                nonfinite_coeffs += 1;
            }
            frame.tile = [ptm.tile[0] as f32, ptm.tile[1] as f32];
            frame.ptm_size = [ptm.width as u32, ptm.height as u32];
            basis = Some(ptm.basis);
            link = ptm.link;
            uv = ptm.uv;
            // PTM texels under one pixel: everywhere for the orthographic view, at unit depth
            // along the view direction for a perspective one (see `ptm_lod`). A view that never
            // shows more than one texel per pixel reads level 0 only: no chain, no binding.
            let texels_per_unit =
                (ptm.width as f64 / ptm.tile[0]).max(ptm.height as f64 / ptm.tile[1]) as f32;
            let pixel = if self.perspective.is_some() {
                let u = frame.cam_up;
                2.0 * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt() / h as f32
            } else {
                ((x1 - x0) / w as f32).max((y1 - y0) / h as f32)
            };
            frame.ptm_texels_per_pixel = pixel * texels_per_unit;
            if self.perspective.is_some() || frame.ptm_texels_per_pixel > 1.0 {
                let levels = if ptm.mips.is_empty() {
                    // Averaged coefficients average K only for the identity link.
                    let levels = crate::mip::build_ptm_chain(&mut coeffs, n, ptm.width, ptm.height);
                    levels
                        .iter()
                        .map(|l| PtmLevel::exact(l[0], l[1], l[2]))
                        .collect()
                } else {
                    stored_levels(ptm, &mut coeffs, &mut nonfinite_coeffs)
                };
                // Odd sides give no level beyond 0: then there is no chain at all.
                if levels.len() > 1 {
                    frame.ptm_level_count = levels.len() as u32;
                    if ptm.mips.is_empty() && ptm.link == Link::Logistic {
                        warnings.push(Warning::LogisticMipsDerived {
                            levels: levels.len(),
                        });
                    }
                    ptm_levels = levels;
                }
            }
            if let Some(cov) = &ptm.coverage {
                coverage = crate::mip::coverage_chain(cov, &ptm_levels);
            }
        }

        let mut albedo = Vec::new();
        if let Some((aw, ah, texels)) = &self.albedo_texture {
            if *aw == 0 || *ah == 0 || texels.len() != aw * ah {
                return Err(Error::Scene(format!(
                    "albedo texture {aw}×{ah} has {} texels",
                    texels.len()
                )));
            }
            albedo = texels.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
            frame.albedo_size = [*aw as u32, *ah as u32];
        }

        let lights = self.gpu_lights();

        let mut plane = crate::blur::Plane::default();
        let mut plane_gpu = PlaneGpu::default();
        let mut prepared = crate::blur::nothing();
        let mut caster_downsample = 1;
        let (mut environment, mut env_size) = (Vec::new(), 0);
        if let Some(c) = &self.caster {
            if c.width == 0 || c.height == 0 || c.rgba.len() != c.width * c.height {
                return Err(Error::Scene(format!(
                    "caster image {}×{} has {} texels",
                    c.width,
                    c.height,
                    c.rgba.len()
                )));
            }
            let [cx0, cy0, cx1, cy1] = c.rect;
            if !(cx1 > cx0 && cy1 > cy0 && c.elevation >= 0.0) {
                return Err(Error::Scene(format!(
                    "caster rectangle {:?} must be non-empty and its height {} ≥ 0",
                    c.rect, c.elevation
                )));
            }
            let tilt = c.tilt_deg.to_radians();
            // The lowest point of the tilted caster: its near or far edge.
            let lowest = c.elevation - 0.5 * (cy1 - cy0) * tilt.sin().abs();
            if c.tilt_deg.is_nan() || c.tilt_deg.abs() >= 90.0 || lowest < 0.0 {
                return Err(Error::Scene(format!(
                    "caster tilt {}° (height {}, depth {}) must be below 90° and keep the whole \
                     caster above the cloth (its lowest edge is at {lowest}): lower the tilt or \
                     raise the caster",
                    c.tilt_deg,
                    c.elevation,
                    cy1 - cy0
                )));
            }
            let method = crate::blur::method(self.blur);
            method.check(c)?;
            let (cw, ch, texels, factor) = crate::caster::fit_caster(c);
            caster_downsample = factor;
            // The image the blur filters: the caster's opacity (grey, or rgb for stained glass),
            // or with a glossy receiver its premultiplied colour and opacity.
            plane = crate::blur::Plane {
                size: [cw as u32, ch as u32],
                channels: match (self.glossy.is_some(), self.colored_shadow) {
                    (true, _) => 4,
                    (false, true) => 3,
                    (false, false) => 1,
                },
                texels: if self.glossy.is_some() {
                    crate::caster::reflection_texels(&texels)
                } else {
                    crate::caster::opacity_texels(&texels, self.colored_shadow)
                },
            };
            if let Some(g) = &self.glossy {
                frame.glossy_background = g.background;
                frame.glossy_alpha = g.cone_half_angle();
                frame.glossy_rings = g.rings();
                frame.glossy_f0 = g.f0;
                if let Some(e) = &g.environment {
                    let (m, map) = e.prefiltered(g.cone_half_angle().sin());
                    (env_size, environment) = (m as u32, map);
                }
            }
            frame.caster_rect = c.rect;
            frame.caster_height = c.elevation;
            frame.caster_sin_tilt = tilt.sin();
            frame.caster_cos_tilt = tilt.cos();
            plane_gpu.size = plane.size;
            plane_gpu.samples = MAX_EXPLICIT_SAMPLES;
            prepared = method.prepare(&plane, &frame, &lights, &mut plane_gpu);
        }

        let variant = Variant {
            basis,
            learned_grid,
            albedo_texture: self.albedo_texture.is_some(),
            caster: self.caster.as_ref().map(|_| self.blur),
            colored: self.caster.is_some() && self.colored_shadow,
            ptm_mip: !ptm_levels.is_empty(),
            coverage: !coverage.is_empty(),
            link,
            uv,
            mesh: false,
            normal_map: false,
            shadow: false,
            gaussian: self
                .lights
                .iter()
                .any(|l| l.rect.is_none() && l.gaussian.is_some()),
            turned_rect: self.turned_rect(),
            glossy: self.glossy.is_some(),
            env_size,
            distant: self.lights.iter().any(|l| l.distant),
            distant_only: !self.lights.is_empty() && self.lights.iter().all(|l| l.distant),
        };
        // A caster whose shadow misses the orthographic view (a perspective view sees more).
        if let (Some(c), None) = (&self.caster, &self.perspective) {
            for (i, (l, g)) in self.lights.iter().zip(&lights).enumerate() {
                let rect = match l.distant {
                    true => c.shadow_rect_distant(g.position, g.radius),
                    false => c.shadow_rect(l.position, l.extent()),
                };
                let Some(s) = rect else {
                    continue;
                };
                if s[2] < x0 || s[0] > x1 || s[3] < y0 || s[1] > y1 {
                    warnings.push(Warning::CasterShadowMissesView {
                        light: i,
                        shadow: s,
                        view: self.view,
                    });
                }
            }
        }
        Ok(SceneBuffers {
            frame,
            lights,
            coeffs,
            ptm_levels,
            coverage,
            learned,
            albedo,
            environment,
            plane,
            plane_gpu,
            prepared,
            variant,
            caster_downsample,
            nonfinite_coeffs,
            warnings,
            mesh_vertices: Vec::new(),
            normal_map: Vec::new(),
            light_terms: std::sync::OnceLock::new(),
        })
    }
}

/// What [`Scene::prepare`] requires of a PTM before it lays it out (the shader trusts the
/// sizes): planes for every term of a non-empty image, stored MIP levels of the round-down
/// chain with every plane and coverage a fraction per texel ([`Ptm::validate`], when it has
/// either), a learned basis's table of its term count, a positive tile. A caller that read the
/// PTM from a file can check it first to name the file in the error.
pub fn check_ptm(ptm: &Ptm) -> Result<()> {
    let n = ptm.basis.len();
    if ptm.width == 0 || ptm.height == 0 || ptm.planes.len() != n {
        return Err(Error::Scene(format!(
            "PTM is {}×{} with {} planes; {} needs {n} and a non-empty image",
            ptm.width,
            ptm.height,
            ptm.planes.len(),
            ptm.basis.name()
        )));
    }
    if !ptm.mips.is_empty() || ptm.coverage.is_some() {
        // Stored levels must be the round-down chain with every plane, coverage a fraction per
        // texel: the lookups trust their sizes.
        ptm.validate()?;
    }
    if ptm.basis.is_learned() {
        learned_table(ptm)?;
    }
    if !(ptm.tile[0] > 0.0 && ptm.tile[1] > 0.0) {
        return Err(Error::Scene(format!(
            "PTM tile size {:?} must be positive",
            ptm.tile
        )));
    }
    Ok(())
}

/// The table of a learned PTM, checked as the shader trusts it: present, `basis.len()` terms of
/// finite values on a grid of 2 ..= [`ptm_format::learned::MAX_GRID`] nodes a side, for the
/// logistic link over the hemispherical map (the only file a learned basis makes).
fn learned_table(ptm: &Ptm) -> Result<&LearnedTable> {
    let what = format!("the {} table", ptm.basis.name());
    let Some(table) = &ptm.learned else {
        return Err(Error::Scene(format!(
            "the PTM's basis is {} but it carries no table (`Ptm::learned`)",
            ptm.basis.name()
        )));
    };
    table
        .check(ptm.basis.len(), &what)
        .map_err(|e| Error::Scene(format!("the PTM's basis is {}: {e}", ptm.basis.name())))?;
    if ptm.link != Link::Logistic || ptm.uv != UvMap::Hemispherical {
        return Err(Error::Scene(format!(
            "the PTM's basis is {}: a learned basis is defined for the logistic link over the \
             hemispherical (u, v) map, not {} over {}",
            ptm.basis.name(),
            ptm.link.name(),
            ptm.uv.name()
        )));
    }
    Ok(table)
}

/// A learned table node-major, as the shader reads it: the k values B₀ … B_{k−1} of grid node
/// (column i, row j) at `(j·G + i)·s`, s = 4·⌈k/4⌉ (the stride [`learned_stride`]) and zeros
/// after the k values (the file's `LearnedTable::values` are term-major). The shader reads each
/// of the four bilinear taps as ⌈k/4⌉ `vec4`s, so 11 terms cost 12 loads a light, not 44 scalar
/// ones; the GPU holds it as a texture of G·⌈k/4⌉ × G such texels (`learned_node` in
/// shade.wgsl: lavapipe fetches texels in SIMD where it gathers storage loads lane by lane).
fn node_major(table: &LearnedTable) -> Vec<f32> {
    let (k, g2) = (table.terms, table.cells());
    let s = learned_stride(k);
    (0..g2 * s)
        .map(|i| {
            let (node, t) = (i / s, i % s);
            if t < k {
                table.values[t * g2 + node]
            } else {
                0.0
            }
        })
        .collect()
}

/// Floats per grid node in [`SceneBuffers::learned`] for a basis of `terms` terms: `terms`
/// rounded up to a multiple of 4 (whole `vec4`s; the padding is zero).
pub fn learned_stride(terms: usize) -> usize {
    terms.div_ceil(4) * 4
}

/// Appends a PTM's stored MIP levels (sizes halved and rounded down, to 1×1) to its texel-major
/// coefficients, zeroing non-finite ones as for level 0; returns every level, level 0 first.
/// Texel i of level k covers level-0 texels 2^k·i … 2^k·(i + 1) (an odd last row or column of
/// the level above is left out), so the tile spans w/2^k of its texels (`PtmLevel::period`).
fn stored_levels(ptm: &Ptm, coeffs: &mut Vec<f32>, nonfinite: &mut usize) -> Vec<PtmLevel> {
    let n = ptm.basis.len();
    let mut levels = vec![PtmLevel::exact(0, ptm.width as u32, ptm.height as u32)];
    for (k, level) in ptm.mips.iter().enumerate() {
        let offset = coeffs.len() / n;
        let start = coeffs.len();
        for t in 0..level.width * level.height {
            coeffs.extend(level.planes.iter().map(|p| p[t]));
        }
        for c in coeffs[start..].iter_mut().filter(|c| !c.is_finite()) {
            *c = 0.0;
            *nonfinite += 1;
        }
        let scale = (1u64 << (k + 1)) as f32;
        // An axis of one texel reads that texel everywhere: its period does not matter.
        let period = |size: usize, texels: usize| {
            if texels == 1 {
                1.0
            } else {
                size as f32 / scale
            }
        };
        levels.push(PtmLevel {
            offset: offset as u32,
            width: level.width as u32,
            height: level.height as u32,
            pad: 0,
            period: [
                period(ptm.width, level.width),
                period(ptm.height, level.height),
            ],
            pad2: [0.0; 2],
        });
    }
    levels
}

/// Data-dependent trouble found while preparing a scene, reported beside it (never an error).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Warning {
    /// The view minifies a logistic PTM whose file stores no MIP levels: the `levels`-level
    /// chain averages coefficients, which does not average K (σ is not linear).
    LogisticMipsDerived {
        /// Levels of the derived chain.
        levels: usize,
    },
    /// The caster's shadow under light `light` falls wholly outside the (orthographic) view:
    /// `shadow` is the rectangle on the cloth it can darken ([`Caster::shadow_rect`]), `view`
    /// the view's.
    CasterShadowMissesView {
        /// Index of the light.
        light: usize,
        /// The shadow's rectangle [x0, y0, x1, y1] on the cloth, swatch units.
        shadow: [f32; 4],
        /// The view's rectangle.
        view: [f32; 4],
    },
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Warning::LogisticMipsDerived { levels } => write!(
                f,
                "the view minifies a logistic PTM that stores no MIP levels, so its {levels}-level \
                 chain averages coefficients, which does not average K (σ is not linear) and \
                 misrenders distant cloth; minified logistic PTMs need stored levels: refit with \
                 `ptm fit`, which writes them"
            ),
            Warning::CasterShadowMissesView {
                light,
                shadow,
                view,
            } => write!(
                f,
                "the caster's shadow under light {light} falls on [{:.3}, {:.3}]×[{:.3}, {:.3}] \
                 of the cloth, wholly outside the view [{:.3}, {:.3}]×[{:.3}, {:.3}]: none of it \
                 shows; lower the caster, move it or the light, or scale the placement to the \
                 tile",
                shadow[0], shadow[2], shadow[1], shadow[3], view[0], view[2], view[1], view[3]
            ),
        }
    }
}

/// Which source-level shader variant a scene needs (features it lacks have no code and no
/// bindings).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Variant {
    /// The PTM's basis; `None` without a PTM (unoccluded cloth).
    pub basis: Option<ptm_format::Basis>,
    /// A learned basis's grid side G (a constant of its source: `LEARNED_GRID`); 0 for a
    /// polynomial basis or without a PTM.
    pub learned_grid: u32,
    /// Albedo from a texture rather than a constant.
    pub albedo_texture: bool,
    /// The blur method when there is a caster.
    pub caster: Option<Blur>,
    /// Three opacity channels (stained glass) instead of one.
    pub colored: bool,
    /// The PTM is minified somewhere in the view: trilinear lookups in its MIP chain.
    pub ptm_mip: bool,
    /// The PTM's file has per-texel coverage: radiance is scaled by it (0 in holes).
    pub coverage: bool,
    /// The PTM's link (identity without a PTM): only its code is compiled.
    pub link: Link,
    /// The PTM's (u, v) map (projected without a PTM): only its code is compiled.
    pub uv: UvMap,
    /// The mesh path (`shader/mesh.wgsl`: a vertex buffer, a depth buffer) instead of the
    /// full-screen plane; never with a caster.
    pub mesh: bool,
    /// Mesh path: a tangent-space normal map.
    pub normal_map: bool,
    /// Mesh path: the mesh's macro shadow (a depth pass per light, `shadow_visibility`).
    pub shadow: bool,
    /// Some light is a Gaussian ([`Light::gaussian`]): only then is its code compiled (its
    /// kernel, `KERNEL_GAUSS`, and its footprint).
    pub gaussian: bool,
    /// Some light is a turned rectangle ([`Light::is_turned_rect`]): only then is its kernel's
    /// code (`rect_slabs`) compiled.
    pub turned_rect: bool,
    /// A glossy receiver reflects the caster ([`Glossy`]): only then is `glossy_reflection`
    /// compiled.
    pub glossy: bool,
    /// A glossy receiver's background image ([`Glossy::environment`]): the side of its map
    /// prefiltered for the lobe (a constant of the source, `ENV_SIZE`), 0 for a colour.
    pub env_size: u32,
    /// Some light is distant ([`Light::distant`]): only then is its code compiled (its
    /// direction, and with a PTM the per-frame basis terms, `distant_k`).
    pub distant: bool,
    /// Every light is distant: the local lights' code (their direction, footprint and the
    /// basis's jet per pixel) is left out, with the branch between the two and, for a
    /// learned basis, the table's binding (no pixel reads it).
    pub distant_only: bool,
}

impl Variant {
    /// Every distinct variant, for validation tests: no PTM, ptm6 and ptm11 with every link
    /// and map, and the learned bases the fitter makes (6 and 11 terms on its 17 × 17 grid),
    /// logistic over the hemispherical map as every learned file is.
    pub fn all() -> Vec<Variant> {
        use ptm_format::Basis;
        let mut out = Vec::new();
        for basis in [
            None,
            Some(Basis::Ptm6),
            Some(Basis::Ptm11),
            Some(Basis::Learned(6)),
            Some(Basis::Learned(11)),
        ] {
            let learned = basis.is_some_and(Basis::is_learned);
            let learned_grid = if learned { 17 } else { 0 };
            let (links, uvs): (&[Link], &[UvMap]) = if learned {
                (&[Link::Logistic], &[UvMap::Hemispherical])
            } else {
                (&Link::ALL, &UvMap::ALL)
            };
            // Link, map, MIP chain and coverage exist only with a PTM.
            let mut ptm_kinds = vec![(Link::Identity, UvMap::Projected, false, false)];
            if basis.is_some() {
                ptm_kinds.clear();
                for &link in links {
                    for &uv in uvs {
                        for ptm_mip in [false, true] {
                            for coverage in [false, true] {
                                ptm_kinds.push((link, uv, ptm_mip, coverage));
                            }
                        }
                    }
                }
            }
            for albedo_texture in [false, true] {
                for caster in std::iter::once(None).chain(Blur::ALL.map(Some)) {
                    for colored in [false, true] {
                        if caster.is_none() && colored {
                            continue;
                        }
                        for &(link, uv, ptm_mip, coverage) in &ptm_kinds {
                            out.push(Variant {
                                basis,
                                learned_grid,
                                albedo_texture,
                                caster,
                                colored,
                                ptm_mip,
                                coverage,
                                link,
                                uv,
                                mesh: false,
                                normal_map: false,
                                shadow: false,
                                gaussian: false,
                                turned_rect: false,
                                glossy: false,
                                env_size: 0,
                                distant: false,
                                distant_only: false,
                            });
                        }
                    }
                }
                // The mesh path: no caster, with or without a normal map and a macro shadow.
                for (normal_map, shadow) in
                    [(false, false), (true, false), (false, true), (true, true)]
                {
                    for &(link, uv, ptm_mip, coverage) in &ptm_kinds {
                        out.push(Variant {
                            basis,
                            learned_grid,
                            albedo_texture,
                            caster: None,
                            colored: false,
                            ptm_mip,
                            coverage,
                            link,
                            uv,
                            mesh: true,
                            normal_map,
                            shadow,
                            gaussian: false,
                            turned_rect: false,
                            glossy: false,
                            env_size: 0,
                            distant: false,
                            distant_only: false,
                        });
                    }
                }
            }
        }
        // A Gaussian light's code with every blur method, channel count, link, map and mesh
        // option (albedo, the PTM's MIP chain and coverage do not meet it).
        let gaussian: Vec<Variant> = out
            .iter()
            .filter(|v| !v.albedo_texture && !v.ptm_mip && !v.coverage)
            .map(|v| Variant {
                gaussian: true,
                ..*v
            })
            .collect();
        out.extend(gaussian);
        // The plain variants with a per-pixel kernel (a caster blurred by any method but
        // separable; no albedo texture, PTM MIP chain, coverage or Gaussian light).
        let per_pixel = |v: &Variant| {
            v.caster.is_some_and(|b| b != Blur::Separable)
                && !v.albedo_texture
                && !v.ptm_mip
                && !v.coverage
                && !v.gaussian
        };
        // A turned rectangle's code with each of them, either channel count (separable refuses
        // a turned rectangle).
        let turned: Vec<Variant> = out
            .iter()
            .filter(|v| per_pixel(v))
            .map(|v| Variant {
                turned_rect: true,
                ..*v
            })
            .collect();
        out.extend(turned);
        // A glossy receiver with each of them, over a grey caster.
        let glossy: Vec<Variant> = out
            .iter()
            .filter(|v| per_pixel(v) && !v.colored && !v.turned_rect)
            .map(|v| Variant { glossy: true, ..*v })
            .collect();
        // … and each of them over a background image (an 8² map: its size is a constant).
        let env: Vec<Variant> = glossy
            .iter()
            .map(|v| Variant { env_size: 8, ..*v })
            .collect();
        out.extend(glossy);
        out.extend(env);
        // A distant light with each plain plane variant (every basis, link and map, every
        // blur method, either channel count, or no caster).
        let distant: Vec<Variant> = out
            .iter()
            .filter(|v| {
                !v.mesh
                    && !v.albedo_texture
                    && !v.ptm_mip
                    && !v.coverage
                    && !v.gaussian
                    && !v.turned_rect
                    && v.env_size == 0
            })
            .map(|v| Variant {
                distant: true,
                ..*v
            })
            .collect();
        // … and with every light distant.
        let only: Vec<Variant> = distant
            .iter()
            .map(|v| Variant {
                distant_only: true,
                ..*v
            })
            .collect();
        out.extend(distant);
        out.extend(only);
        // A distant light on the mesh path (K per pixel in the tangent frame, the macro
        // shadow's stand-in light), with and without a normal map and the shadow.
        let mesh: Vec<Variant> = out
            .iter()
            .filter(|v| v.mesh && !v.albedo_texture && !v.ptm_mip && !v.coverage && !v.gaussian)
            .map(|v| Variant {
                distant: true,
                ..*v
            })
            .collect();
        out.extend(mesh);
        out
    }

    /// Short name, e.g. `ptm11+albedo+sat+colored`.
    pub fn name(&self) -> String {
        let mut parts = vec![self.basis.map_or("nok", |b| b.name()).to_string()];
        if self.learned_grid > 0 {
            parts.push(format!("grid{}", self.learned_grid));
        }
        if self.link != Link::Identity {
            parts.push(self.link.name().into());
        }
        if self.uv != UvMap::Projected {
            parts.push(self.uv.name().into());
        }
        if self.ptm_mip {
            parts.push("ptm-mip".into());
        }
        if self.coverage {
            parts.push("coverage".into());
        }
        if self.albedo_texture {
            parts.push("albedo".into());
        }
        if let Some(b) = self.caster {
            parts.push(b.name().into());
        }
        if self.colored {
            parts.push("colored".into());
        }
        if self.mesh {
            parts.push("mesh".into());
        }
        if self.normal_map {
            parts.push("normal-map".into());
        }
        if self.shadow {
            parts.push("shadow".into());
        }
        if self.gaussian {
            parts.push("gaussian".into());
        }
        if self.turned_rect {
            parts.push("turned-rect".into());
        }
        if self.glossy {
            parts.push("glossy".into());
        }
        if self.env_size > 0 {
            parts.push(format!("env{}", self.env_size));
        }
        if self.distant_only {
            parts.push("distant-only".into());
        } else if self.distant {
            parts.push("distant".into());
        }
        parts.join("+")
    }

    /// Channels of the caster's image (the blur's [`crate::blur::Plane`]): 4 with a glossy
    /// receiver (α·rgb, α), 3 for coloured shadows, else 1.
    pub fn sat_channels(&self) -> u32 {
        if self.glossy && self.caster.is_some() {
            4
        } else if self.colored {
            3
        } else {
            1
        }
    }
}

/// Right, up (scaled to the image's half-extent at unit distance) and forward unit vectors.
/// World up is +Z, or +Y when looking straight up or down (then +X is right, +Y up, as the
/// orthographic top view).
fn camera_basis(cam: &Perspective, aspect: f32) -> Result<[[f32; 3]; 3]> {
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let norm = |a: [f32; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|x| x / n)
    };
    let d = sub(cam.target, cam.eye);
    if d == [0.0; 3] || !(cam.fov_y_deg > 0.0 && cam.fov_y_deg < 179.0) {
        return Err(Error::Scene(format!(
            "perspective camera at {:?} looking at {:?} with fov {}°: the target must differ \
             from the eye and the fov lie in (0, 179)",
            cam.eye, cam.target, cam.fov_y_deg
        )));
    }
    let f = norm(d);
    let world_up = if f[0].abs() < 1e-6 && f[1].abs() < 1e-6 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let r = norm(cross(f, world_up));
    let u = cross(r, f);
    let t = (0.5 * cam.fov_y_deg.to_radians()).tan();
    Ok([r.map(|x| x * t * aspect), u.map(|x| x * t), f])
}

/// A scene laid out as shader buffers; the GPU and the CPU twin both read exactly this.
#[derive(Clone, Debug)]
pub struct SceneBuffers {
    /// The uniform block.
    pub frame: Frame,
    /// The lights as the shader reads them.
    pub lights: Vec<LightGpu>,
    /// PTM coefficients, texel-major: `coeffs[(row·nx + col)·n + k]`.
    pub coeffs: Vec<f32>,
    /// PTM MIP chain (levels appended to `coeffs`), level 0 first: the file's stored levels,
    /// or else coefficients averaged 2×2 ([`crate::mip::build_ptm_chain`]); empty when the view
    /// never minifies the PTM.
    pub ptm_levels: Vec<PtmLevel>,
    /// A learned basis's k tables node-major: Bₜ at grid node (column i, row j) at
    /// `learned[(j·G + i)·s + t]` (G = `variant.learned_grid`, s = [`learned_stride`]`(k)`,
    /// zeros at t ≥ k, so a node is whole `vec4`s for the shader), read bilinearly at the
    /// hemispherical (u, v) as `ptm_format::LearnedTable::terms` reads them; shared by every MIP
    /// level; empty for a polynomial basis.
    pub learned: Vec<f32>,
    /// The PTM's coverage (0 = a hole, 1 = all cloth) per texel of every level in
    /// `ptm_levels` (texel offsets as for `coeffs`), box-averaged level by level; level 0 only
    /// without a chain; empty when the file has none ([`crate::mip::coverage_chain`]).
    pub coverage: Vec<f32>,
    /// Linear albedo texels (rgb, a = 1), row-major, row 0 at the far edge.
    pub albedo: Vec<[f32; 4]>,
    /// A glossy receiver's background image: its equal-area map prefiltered for the lobe
    /// ([`crate::environment::Environment::prefiltered`], side `variant.env_size`); empty
    /// without.
    pub environment: Vec<[f32; 4]>,
    /// The image the blur filters: the caster's opacity per texel as packed u8 (r | g << 8 |
    /// b << 16, each 0..=255; all three equal without `colored_shadow`); empty without a caster.
    pub plane: crate::blur::Plane,
    /// The image's uniform block (its size and the method's fields).
    pub plane_gpu: PlaneGpu,
    /// What the scene's blur method prepared from the image ([`crate::blur::Method::prepare`]).
    pub prepared: crate::blur::Prepared,
    /// Which shader variant renders it.
    pub variant: Variant,
    /// Integer factor the caster image was box-downsampled by (1 = as given).
    pub caster_downsample: usize,
    /// PTM coefficients that were NaN or infinite in the input (replaced by 0).
    pub nonfinite_coeffs: usize,
    /// What the caller should tell the user about this scene (each at most once).
    pub warnings: Vec<Warning>,
    /// Mesh path: the vertex buffer (three corners per triangle) and the normal map's texels
    /// (xyz, w = 0; row-major, row 0 at the far edge); empty on the plane path
    /// ([`crate::mesh::MeshScene::prepare`]).
    pub mesh_vertices: Vec<crate::layout::MeshVertex>,
    /// The tangent-space normal map's texels (see `mesh_vertices`).
    pub normal_map: Vec<[f32; 4]>,
    /// With a PTM, per light, what a distant light's K needs at every pixel, evaluated once
    /// per frame on first use (`cpu::shade::light_terms`, which both the GPU upload and the
    /// twin call): [`light_term_stride`]`(k)` vec4s per light, the footprint's covariance (uu,
    /// uv, vv, 0), then per basis term k (whole vec4s, zeros past the last) the predictor's
    /// mean weight p_k + ½·tr(H_k·C), and its gradient's u and v parts, all at the footprint's
    /// mean; zeros for a light that is not distant. Empty without a distant light or a PTM.
    /// Filled from the buffers as they are then: change `lights` before rendering, not after.
    pub light_terms: std::sync::OnceLock<Vec<[f32; 4]>>,
}

/// vec4s per light in [`SceneBuffers::light_terms`] for a basis of `terms` terms: the
/// covariance, then three runs of ⌈terms/4⌉.
pub fn light_term_stride(terms: usize) -> usize {
    1 + 3 * terms.div_ceil(4)
}
