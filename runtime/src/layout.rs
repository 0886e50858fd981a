//! Every struct the GPU reads, byte for byte with its WGSL declaration: `#[repr(C)]` + bytemuck,
//! named fields in WGSL's order, explicit padding where WGSL aligns (a `vec3` is 16-byte
//! aligned, a `vec2` 8-byte). The tests compare naga's reflected member offsets and struct sizes
//! with `offset_of!` for every field, so a field added on one side only fails without a GPU.
//!
//! World-space lengths are swatch units, image sizes pixels, texture sizes texels.

/// The shading pass's uniform block: `struct Frame` in `shader/shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Frame {
    /// World rectangle x0, y0, x1, y1 seen by the orthographic camera.
    pub view: [f32; 4],
    /// Output width, height (pixels).
    pub screen: [f32; 2],
    /// Tile period W, H (swatch units) of the PTM and the albedo texture.
    pub tile: [f32; 2],
    /// Constant linear albedo (rgb).
    pub albedo: [f32; 3],
    /// Lights in the light buffer that are shaded.
    pub light_count: u32,
    /// World rectangle x0, y0, x1, y1 of the caster (its untilted footprint).
    pub caster_rect: [f32; 4],
    /// Height d_ca of the caster's centre line above the acceptor.
    pub caster_height: f32,
    /// sin and cos of the caster's tilt about its centre line (parallel to X).
    pub caster_sin_tilt: f32,
    /// cos of the tilt (see `caster_sin_tilt`).
    pub caster_cos_tilt: f32,
    /// Padding (the plane's own fields are in [`PlaneGpu`]).
    pub pad3: u32,
    /// PTM texels (level 0) nx, ny.
    pub ptm_size: [u32; 2],
    /// Albedo texture texels nx, ny.
    pub albedo_size: [u32; 2],
    /// PTM texels under one pixel (at unit depth along the view direction for a perspective
    /// camera): the level of detail's base.
    pub ptm_texels_per_pixel: f32,
    /// Levels of the PTM's MIP chain (0 without a chain).
    pub ptm_level_count: u32,
    /// Padding to the WGSL vec3's 16-byte alignment.
    pub pad4: [u32; 2],
    /// Perspective camera eye (world).
    pub eye: [f32; 3],
    /// 1 for the perspective camera, 0 for the orthographic top view of `view`.
    pub perspective: u32,
    /// Camera right × tan(fov/2)·aspect.
    pub cam_right: [f32; 3],
    /// Padding to the WGSL vec3's 16-byte stride.
    pub pad0: f32,
    /// Camera up × tan(fov/2).
    pub cam_up: [f32; 3],
    /// Padding to the WGSL vec3's 16-byte stride.
    pub pad1: f32,
    /// Camera forward (unit).
    pub cam_forward: [f32; 3],
    /// Padding to the WGSL vec3's 16-byte stride.
    pub pad2: f32,
    /// Mesh path: the fill light's radiance scale (linear rgb): albedo · fill · (½ + ½ n_z), a
    /// sky-over-floor ambient that K does not touch (K darkens the key lights only).
    pub fill: [f32; 3],
    /// Mesh path: the sheen roughness (glTF `sheenRoughnessFactor`; α = roughness²).
    pub sheen_roughness: f32,
    /// Mesh path: the sheen colour (glTF `sheenColorFactor`, linear rgb; 0 = no sheen).
    pub sheen_color: [f32; 3],
    /// Mesh path: the near plane's forward distance (depth 0).
    pub near: f32,
    /// Mesh path: the normal map's texels nx, ny (tiled with the PTM).
    pub normal_size: [u32; 2],
    /// Mesh path: the far plane's forward distance (depth 1).
    pub far: f32,
    /// Padding to 16 bytes.
    pub pad5: f32,
    /// Mesh path: the low corner of the box that bounds the mesh, which every light's shadow
    /// map frames (world).
    pub shadow_lo: [f32; 3],
    /// Mesh path: the shadow maps' side in texels (0: no macro shadow).
    pub shadow_size: u32,
    /// Mesh path: the box's high corner.
    pub shadow_hi: [f32; 3],
    /// Padding to 16 bytes.
    pub pad6: f32,
    /// Glossy receiver: the background's linear radiance, reflected where the lobe misses the
    /// caster (`scene::Glossy`).
    pub glossy_background: [f32; 3],
    /// Glossy receiver: the lobe's cone half-angle α (radians).
    pub glossy_alpha: f32,
    /// Glossy receiver: how many nested cones the lobe is averaged as (1 to 4; 0 without).
    pub glossy_rings: u32,
    /// Padding to 16 bytes.
    pub pad7: f32,
    /// Padding to 16 bytes.
    pub pad8: f32,
    /// Glossy receiver: Schlick's reflectance at normal incidence F0.
    pub glossy_f0: f32,
}

impl Frame {
    /// All fields 0 (every field is then filled by `scene::prepare`).
    pub fn zeroed() -> Frame {
        bytemuck::Zeroable::zeroed()
    }
}

/// The filtered planar image's uniform block (`struct Plane` in `shader/shade.wgsl`): what the
/// blur methods read of the image they convolve, apart from its texels and tables. Bound only
/// in variants with a caster ([`crate::bindings`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PlaneGpu {
    /// Image texels w, h (after downsampling).
    pub size: [u32; 2],
    /// Separable blur: margins mx, my (texels) around the image in the pre-blurred map.
    pub margin: [u32; 2],
    /// Separable blur: the padded map's w, h (texels).
    pub padded: [u32; 2],
    /// Explicit blur: the cap on samples per axis.
    pub samples: u32,
    /// Padding to 32 bytes, as the WGSL struct.
    pub pad: u32,
}

/// One light as the shader reads it: `struct Light` in `shader/shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightGpu {
    /// Centre (world).
    pub position: [f32; 3],
    /// Sphere radius R (0: a point light).
    pub radius: f32,
    /// Colour × intensity (linear rgb).
    pub color: [f32; 3],
    /// [`LightGpu::SPHERE`], [`LightGpu::RECT`], [`LightGpu::SPHERE_SQUARE_BOX`],
    /// [`LightGpu::GAUSSIAN`], [`LightGpu::LOBE`] or [`LightGpu::DISTANT`].
    pub shape: u32,
    /// A rectangle's half-sides along X and Y, a Gaussian's σ (0 for a sphere).
    pub half: [f32; 2],
    /// A rectangle's side-a direction (cos θ, sin θ) in the plane of the cloth ((1, 0): along
    /// X); (1, 0) for every other shape.
    pub axis: [f32; 2],
}

impl LightGpu {
    /// A sphere of `radius`, its kernel the ellipse its cone cuts from the caster plane.
    pub const SPHERE: u32 = 0;
    /// A rectangle of half-sides `half`, facing down.
    pub const RECT: u32 = 1;
    /// A sphere whose kernel is the square box of half-side R·s (the runtime before the ellipse).
    pub const SPHERE_SQUARE_BOX: u32 = 2;
    /// A Gaussian of standard deviations `half`, facing down.
    pub const GAUSSIAN: u32 = 3;
    /// A glossy lobe's imaginary light (never in the light list): a sphere whose ellipse is
    /// moved to the centroid of solid angle alone, not of irradiance.
    pub const LOBE: u32 = 4;
    /// A distant light (the sun): `position` is the unit direction towards it, the same at
    /// every point, and `radius` the sine of its angular radius; its kernel is the ellipse its
    /// cone cuts from the caster plane, as a sphere's.
    pub const DISTANT: u32 = 5;

    /// The vector from cloth point p (z = 0) towards the light: to its centre, or for a
    /// [`LightGpu::DISTANT`] light its unit direction. Its length is the distance d of the
    /// `cos/d²` falloff (a distant light's is 1: the shader takes d² = 1).
    pub fn to_light(&self, p: [f32; 2]) -> [f32; 3] {
        if self.shape == LightGpu::DISTANT {
            return self.position;
        }
        let lp = self.position;
        [lp[0] - p[0], lp[1] - p[1], lp[2]]
    }
}

/// One level of the PTM's MIP chain: `struct PtmLevel` in `shader/shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PtmLevel {
    /// First texel of the level in `SceneBuffers::coeffs` (texels, not floats).
    pub offset: u32,
    /// Width of the level, texels.
    pub width: u32,
    /// Height of the level, texels.
    pub height: u32,
    /// Padding to 16 bytes, as the WGSL struct.
    pub pad: u32,
    /// The tile's extent in this level's texels (x, y): (width, height) when the level tiles
    /// exactly; w/2^k, h/2^k (up to one texel more) for a stored level of an odd side.
    pub period: [f32; 2],
    /// Padding to 32 bytes, as the WGSL struct.
    pub pad2: [f32; 2],
}

impl PtmLevel {
    /// A level that tiles exactly (its period is its size).
    pub fn exact(offset: u32, width: u32, height: u32) -> PtmLevel {
        PtmLevel {
            offset,
            width,
            height,
            pad: 0,
            period: [width as f32, height as f32],
            pad2: [0.0; 2],
        }
    }
}

/// One corner of the mesh path's vertex buffer: `struct MeshIn` in `shader/mesh.wgsl`
/// (attributes at `@location(0…4)`, [`MeshVertex::ATTRIBUTES`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MeshVertex {
    /// Position (world, mesh units).
    pub position: [f32; 3],
    /// Unit shading normal.
    pub normal: [f32; 3],
    /// MikkTSpace tangent (unit xyz) and bitangent sign w: B = w · N × T.
    pub tangent: [f32; 4],
    /// The PTM's coordinates (swatch units: UV × tiles per UV unit × tile size).
    pub uv: [f32; 2],
    /// PTM units per mesh unit on this triangle (√ of the area ratio): the level of detail's
    /// stretch.
    pub uv_scale: f32,
    /// Padding (56 bytes a corner).
    pub pad: f32,
}

impl MeshVertex {
    /// The vertex attributes as wgpu reads them, location k = field k in declaration order.
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 5] = wgpu::vertex_attr_array![
        0 => Float32x3, 1 => Float32x3, 2 => Float32x4, 3 => Float32x2, 4 => Float32
    ];
}

/// One level of the caster opacity's MIP chain: `struct MipLevel` in `blur/mip.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MipLevel {
    /// First texel of the level in `SceneBuffers::mip`.
    pub offset: u32,
    /// Width of the level, texels.
    pub width: u32,
    /// Height of the level, texels.
    pub height: u32,
    /// Padding to 16 bytes, as the WGSL struct.
    pub pad: u32,
}

impl MipLevel {
    /// Level `width`×`height` whose texels start at `offset` in the chain.
    pub fn new(offset: usize, width: usize, height: usize) -> MipLevel {
        MipLevel {
            offset: offset as u32,
            width: width as u32,
            height: height as u32,
            pad: 0,
        }
    }
}

/// The summed-area table passes' uniform block: `struct SatParams` in `blur/sat_build.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SatParams {
    /// Caster texels w, h.
    pub size: [u32; 2],
    /// Opacity channels in the table (1 grey, 3 coloured).
    pub channels: u32,
    /// Padding to 16 bytes, as the WGSL struct.
    pub pad: u32,
}

/// The separable blur passes' uniform block: `struct SepParams` in `blur/separable_passes.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SepParams {
    /// Caster texels w, h.
    pub size: [u32; 2],
    /// Opacity channels (1 grey, 3 coloured).
    pub channels: u32,
    /// Lights (one pre-blurred map each).
    pub lights: u32,
    /// Margins mx, my (texels) around the caster.
    pub margin: [u32; 2],
    /// The padded map's w, h.
    pub padded: [u32; 2],
}

/// The window's blit pass's uniform block: `struct BlitParams` in `shader/blit.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BlitParams {
    /// The frame's width, height (texels).
    pub image: [f32; 2],
    /// The letterboxed image's top-left corner in the window (pixels).
    pub offset: [f32; 2],
    /// The letterboxed image's size in the window (pixels).
    pub fit: [f32; 2],
    /// Radiance scale, 2^exposure.
    pub scale: f32,
    /// 1: encode sRGB in the shader (the surface format is not sRGB); 0: the surface does.
    pub encode: f32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Variant;
    use crate::shader;
    use core::mem::{offset_of, size_of};

    /// Member names and offsets, and the size, of `struct name` in `module`, as naga lays them
    /// out.
    fn reflect(module: &naga::Module, name: &str) -> (Vec<(String, usize)>, usize) {
        module
            .types
            .iter()
            .find_map(|(_, t)| match &t.inner {
                naga::TypeInner::Struct { members, span } if t.name.as_deref() == Some(name) => {
                    Some((
                        members
                            .iter()
                            .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
                            .collect(),
                        *span as usize,
                    ))
                }
                _ => None,
            })
            .unwrap_or_else(|| panic!("no struct {name} in the WGSL"))
    }

    fn check(module: &naga::Module, name: &str, want: &[(&str, usize)], size: usize) {
        let (got, span) = reflect(module, name);
        let want: Vec<(String, usize)> = want.iter().map(|&(n, o)| (n.to_string(), o)).collect();
        assert_eq!(
            got, want,
            "struct {name}: WGSL members (left) vs Rust offset_of! (right)"
        );
        assert_eq!(span, size, "struct {name}: WGSL size vs Rust size_of");
    }

    /// A variant with every optional part that declares a struct (PTM MIP chain, caster).
    fn shade_module() -> naga::Module {
        let v = Variant::all()
            .into_iter()
            .find(|v| v.ptm_mip && v.caster.is_some())
            .expect("a variant with a PTM MIP chain and a caster");
        shader::validate(&v.name(), &shader::shade_source(&v).unwrap()).unwrap()
    }

    /// A variant with the caster's MIP chain.
    fn mip_module() -> naga::Module {
        let v = Variant::all()
            .into_iter()
            .find(|v| v.caster == Some(crate::scene::Blur::Mip))
            .expect("a variant with the MIP blur");
        shader::validate(&v.name(), &shader::shade_source(&v).unwrap()).unwrap()
    }

    macro_rules! fields {
        ($t:ty: $($f:ident),* $(,)?) => {
            &[$((stringify!($f), offset_of!($t, $f))),*]
        };
    }

    #[test]
    fn frame_matches_the_wgsl_struct_field_for_field() {
        let want = fields!(Frame: view, screen, tile, albedo, light_count, caster_rect,
            caster_height, caster_sin_tilt, caster_cos_tilt, pad3, ptm_size, albedo_size,
            ptm_texels_per_pixel, ptm_level_count, pad4, eye, perspective, cam_right, pad0,
            cam_up, pad1, cam_forward, pad2, fill, sheen_roughness, sheen_color, near,
            normal_size, far, pad5, shadow_lo, shadow_size, shadow_hi, pad6,
            glossy_background, glossy_alpha, glossy_rings, pad7, pad8, glossy_f0);
        check(&shade_module(), "Frame", want, size_of::<Frame>());
        // A uniform block's size is a multiple of 16 bytes.
        assert_eq!(size_of::<Frame>() % 16, 0);
    }

    #[test]
    fn mesh_vertex_attributes_match_the_struct_and_the_wgsl_locations() {
        let v = Variant::all()
            .into_iter()
            .find(|v| v.mesh)
            .expect("a mesh variant");
        let m = shader::validate(&v.name(), &shader::shade_source(&v).unwrap()).unwrap();
        let want = fields!(MeshVertex: position, normal, tangent, uv, uv_scale);
        let (got, _) = reflect(&m, "MeshIn");
        let names: Vec<&str> = got.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["position", "normal", "tangent", "uv", "uv_scale"]);
        // wgpu's attributes: locations 0…4 in order, at the Rust offsets.
        for (k, (a, (_, off))) in MeshVertex::ATTRIBUTES.iter().zip(want).enumerate() {
            assert_eq!(a.shader_location, k as u32);
            assert_eq!(a.offset as usize, *off, "attribute {k}");
        }
        // naga's entry point reads each member at the location of its index.
        let ep = m.entry_points.iter().find(|e| e.name == "vs_mesh").unwrap();
        let arg = &ep.function.arguments[0];
        let naga::TypeInner::Struct { members, .. } = &m.types[arg.ty].inner else {
            panic!("vs_mesh takes MeshIn");
        };
        for (k, mem) in members.iter().enumerate() {
            assert!(
                matches!(mem.binding, Some(naga::Binding::Location { location, .. }) if location == k as u32),
                "{:?} at {:?}",
                mem.name,
                mem.binding
            );
        }
    }

    #[test]
    fn light_and_mip_levels_match_the_wgsl_structs() {
        let m = shade_module();
        let want = fields!(LightGpu: position, radius, color, shape, half, axis);
        check(&m, "Light", want, size_of::<LightGpu>());
        let want = fields!(PtmLevel: offset, width, height, pad, period, pad2);
        check(&m, "PtmLevel", want, size_of::<PtmLevel>());
        let want = fields!(PlaneGpu: size, margin, padded, samples, pad);
        check(&m, "Plane", want, size_of::<PlaneGpu>());
        let m = mip_module();
        let want = fields!(MipLevel: offset, width, height, pad);
        check(&m, "MipLevel", want, size_of::<MipLevel>());
    }

    #[test]
    fn compute_pass_params_match_the_wgsl_structs() {
        let m = shader::validate("sat_build.wgsl", crate::blur::sat::BUILD_WGSL).unwrap();
        let want = fields!(SatParams: size, channels, pad);
        check(&m, "SatParams", want, size_of::<SatParams>());
        let m =
            shader::validate("separable_passes.wgsl", crate::blur::separable::PASSES_WGSL).unwrap();
        let want = fields!(SepParams: size, channels, lights, margin, padded);
        check(&m, "SepParams", want, size_of::<SepParams>());
        let m = shader::validate("blit.wgsl", shader::BLIT_WGSL).unwrap();
        let want = fields!(BlitParams: image, offset, fit, scale, encode);
        check(&m, "BlitParams", want, size_of::<BlitParams>());
    }
}
