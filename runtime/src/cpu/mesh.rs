//! Twin of `shader/mesh.wgsl`: every WGSL function under its name, same maths, and a small
//! software rasteriser standing in for the GPU's (pixel centres, edge functions, a strict
//! `Less` depth test on depth z/w interpolated in screen space, varyings interpolated
//! perspective-correctly). Pixels whose centre lies on a triangle's edge can go to either
//! triangle (fill rules differ), so a comparison with the GPU masks pixels the two cover
//! differently ([`Image`] alpha: 1 covered, 0 not).
//!
//! Triangles are clipped against the near plane (clip z ≥ 0) as the GPU clips them, before the
//! divide by w, and to a guard band around the viewport (as GPUs do, to keep the rasteriser's
//! coordinates small): a triangle that crosses them is cut into a fan, whose corners carry the
//! original triangle's barycentric weights so the varyings are interpolated from its corners.
//! The far plane is a per-pixel depth test (z/w ≤ 1), which is the same cut. The macro shadow's
//! depth maps go through the same rasteriser from each light ([`shadow_maps`]).

use rayon::prelude::*;

use super::shade::{tile_bilinear, Twin};
use crate::layout::{Frame, LightGpu, MeshVertex};
use crate::output::Image;
use crate::scene::SceneBuffers;

const PI: f32 = std::f32::consts::PI;

type V3 = [f32; 3];

fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: V3, s: f32) -> V3 {
    a.map(|x| x * s)
}
fn length(a: V3) -> f32 {
    dot(a, a).sqrt()
}
fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / length(a))
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn mix(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// The vertex stage's output (`struct MeshOut`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshOut {
    /// Clip coordinates.
    pub clip: [f32; 4],
    /// World position.
    pub world: V3,
    /// Interpolated normal (not unit between corners).
    pub normal: V3,
    /// Interpolated tangent and sign.
    pub tangent: [f32; 4],
    /// PTM coordinates.
    pub uv: [f32; 2],
    /// PTM units per mesh unit.
    pub uv_scale: f32,
    /// The triangle is counter-clockwise in normalised device coordinates (y up): the front
    /// face, `@builtin(front_facing)` (set by the rasteriser; true out of the vertex stage).
    pub front: bool,
}

/// Clip coordinates of world point q (x, y in units of the camera's right/up extents, w the
/// forward distance, z 0 at `near` … 1 at `far` times w).
pub fn mesh_clip(f: &Frame, q: V3) -> [f32; 4] {
    let d = sub(q, f.eye);
    let w = dot(d, f.cam_forward);
    let x = dot(d, f.cam_right) / dot(f.cam_right, f.cam_right);
    let y = dot(d, f.cam_up) / dot(f.cam_up, f.cam_up);
    let z = (w - f.near) * f.far / (f.far - f.near);
    [x, y, z, w]
}

/// The vertex stage.
pub fn vs_mesh(f: &Frame, v: &MeshVertex) -> MeshOut {
    MeshOut {
        clip: mesh_clip(f, v.position),
        world: v.position,
        normal: v.normal,
        tangent: v.tangent,
        uv: v.uv,
        uv_scale: v.uv_scale,
        front: true,
    }
}

/// Level of detail at a surface point of normal n (`ptm_lod` generalised; 0 without a chain).
pub fn mesh_lod(f: &Frame, world: V3, n: V3, uv_scale: f32) -> f32 {
    let levels = f.ptm_level_count as f32;
    if levels < 2.0 {
        return 0.0;
    }
    let d = sub(world, f.eye);
    let s = dot(d, f.cam_forward);
    let dir = scale(d, 1.0 / s);
    let texels = f.ptm_texels_per_pixel * uv_scale * s * length(dir) / dot(n, dir).abs().max(1e-6);
    texels.max(1.0).log2().clamp(0.0, levels - 1.0)
}

/// (T, B, N): N normalised and turned over on a back face, T Gram–Schmidt against it,
/// B = w·N×T.
pub fn tangent_frame(front: bool, normal: V3, tangent: [f32; 4]) -> [V3; 3] {
    let mut n = normalize(normal);
    let t3 = [tangent[0], tangent[1], tangent[2]];
    let t = normalize(sub(t3, scale(n, dot(n, t3))));
    if !front {
        n = scale(n, -1.0);
    }
    let b = scale(cross(n, t), tangent[3]);
    [t, b, n]
}

/// The shading normal: the normal map's, brought into the frame, or N.
pub fn normal_at(t: &Twin, p: [f32; 2], tbn: &[V3; 3]) -> V3 {
    if !t.p.variant.normal_map {
        return tbn[2];
    }
    let f = &t.p.frame;
    let (idx, w) = tile_bilinear(f, p, f.normal_size);
    let m: V3 = std::array::from_fn(|k| {
        w[0] * t.p.normal_map[idx[0]][k]
            + w[1] * t.p.normal_map[idx[1]][k]
            + w[2] * t.p.normal_map[idx[2]][k]
            + w[3] * t.p.normal_map[idx[3]][k]
    });
    normalize(std::array::from_fn(|k| {
        tbn[0][k] * m[0] + tbn[1][k] * m[1] + tbn[2][k] * m[2]
    }))
}

/// Charlie D = (2 + 1/α) sin(θh)^(1/α) / (2π).
pub fn sheen_d(alpha: f32, n_h: f32) -> f32 {
    let inv = 1.0 / alpha;
    let sin2 = (1.0 - n_h * n_h).max(0.0);
    (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI)
}

/// The Charlie visibility's fitted L(x).
pub fn sheen_l(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let a = mix(21.5473, 25.3245, t);
    let b = mix(3.82987, 3.32435, t);
    let c = mix(0.19823, 0.16801, t);
    let d = mix(-1.97760, -1.27393, t);
    let e = mix(-4.32054, -4.85967, t);
    a / (1.0 + b * x.powf(c)) + d * x + e
}

/// Λ(cos θ).
pub fn sheen_lambda(cos_theta: f32, alpha: f32) -> f32 {
    if cos_theta < 0.5 {
        return sheen_l(cos_theta, alpha).exp();
    }
    (2.0 * sheen_l(0.5, alpha) - sheen_l(1.0 - cos_theta, alpha)).exp()
}

/// V = 1/((1 + Λ(n·v) + Λ(n·l)) · 4 (n·v)(n·l)), clamped to [0, 1].
pub fn sheen_visibility(n_l: f32, n_v: f32, alpha: f32) -> f32 {
    let denom = (1.0 + sheen_lambda(n_v, alpha) + sheen_lambda(n_l, alpha)) * (4.0 * n_v * n_l);
    (1.0 / denom).clamp(0.0, 1.0)
}

/// π · sheenColor · D · V (0 below either horizon).
pub fn sheen_brdf(f: &Frame, n: V3, v: V3, l: V3) -> V3 {
    let n_l = dot(n, l);
    let n_v = dot(n, v);
    if n_l <= 0.0 || n_v <= 0.0 {
        return [0.0; 3];
    }
    let h = normalize([l[0] + v[0], l[1] + v[1], l[2] + v[2]]);
    let alpha = (f.sheen_roughness * f.sheen_roughness).max(1e-3);
    let s = PI * sheen_d(alpha, dot(n, h)) * sheen_visibility(n_l, n_v, alpha);
    f.sheen_color.map(|c| c * s)
}

/// Linear radiance leaving a mesh point (see `shade_mesh` in WGSL); `shadow`: the macro
/// shadow's depth maps when the variant has them ([`shadow_maps`]).
pub fn shade_mesh(t: &Twin, shadow: Option<&ShadowMaps>, m: &MeshOut) -> V3 {
    let (world, p) = (m.world, m.uv);
    let f = &t.p.frame;
    let v_ = &t.p.variant;
    let tbn = tangent_frame(m.front, m.normal, m.tangent);
    let uv_scale = m.uv_scale;
    let lod = if v_.ptm_mip {
        mesh_lod(f, world, tbn[2], uv_scale)
    } else {
        0.0
    };
    let albedo = t.albedo_at(p);
    let c = v_.basis.map(|_| t.ptm_coeffs(p, lod));
    let ns = normal_at(t, p, &tbn);
    let v = normalize(sub(f.eye, world));
    let mut radiance = [0f32; 3];
    for (li, light) in t.p.lights[..f.light_count as usize].iter().enumerate() {
        // A distant light: its unit direction, the same everywhere, and no falloff.
        let (to_light, d2) = if light.shape == LightGpu::DISTANT {
            (light.position, 1.0)
        } else {
            let v = sub(light.position, world);
            (v, dot(v, v))
        };
        if d2 <= 0.0 {
            continue;
        }
        let l = scale(to_light, 1.0 / d2.sqrt());
        let lt = [dot(l, tbn[0]), dot(l, tbn[1]), dot(l, tbn[2])];
        if lt[2] <= 0.0 {
            continue;
        }
        let mut visible = 1.0;
        if let Some(c) = &c {
            // K over the light's footprint as on the plane (see `shade_mesh` in WGSL).
            let d = d2.sqrt();
            let f = t.ptm_footprint(lt, scale(lt, d), d, light);
            visible *= 1.0 - t.ptm_k_area(c, lt, &f);
        }
        if let Some(maps) = shadow {
            visible *= shadow_visibility(f, &t.p.lights, maps, li, world, tbn[2]);
        }
        let cos_l = dot(ns, l).max(0.0);
        let sheen = sheen_brdf(f, ns, v, l);
        for ch in 0..3 {
            radiance[ch] += (albedo[ch] + sheen[ch]) * light.color[ch] * (cos_l / d2) * visible;
        }
    }
    for ch in 0..3 {
        radiance[ch] += albedo[ch] * f.fill[ch] * (0.5 + 0.5 * ns[2]);
    }
    if v_.basis.is_some() && v_.coverage {
        let cov = t.ptm_coverage(p, lod);
        radiance = radiance.map(|r| r * cov);
    }
    radiance
}

/// The fragment stage (alpha 1: covered).
pub fn fs_mesh(t: &Twin, shadow: Option<&ShadowMaps>, m: &MeshOut) -> [f32; 4] {
    let r = shade_mesh(t, shadow, m);
    [r[0], r[1], r[2], 1.0]
}

/// A light's shadow view (`struct ShadowView`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowView {
    /// Right × tan of the frustum's half-angle.
    pub right: V3,
    /// Up × the same.
    pub up: V3,
    /// Forward (unit).
    pub forward: V3,
    /// Near plane (forward distance).
    pub near: f32,
    /// Far plane.
    pub far: f32,
    /// The light is not at the box's centre (else it casts no macro shadow).
    pub ok: bool,
    /// A distant light's orthographic view ([`shadow_view_ortho`]).
    pub ortho: bool,
}

/// The widest half-angle's tangent of a shadow map (`SHADOW_MAX_TAN`, tan 76°).
pub const SHADOW_MAX_TAN: f32 = 4.0;

/// A shadow view's unit right and up axes across the unit forward direction (see
/// `shadow_axes` in WGSL).
pub fn shadow_axes(f: V3) -> [V3; 2] {
    let world_up = if f[2].abs() > 0.999 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let right = normalize(cross(f, world_up));
    [right, cross(right, f)]
}

/// The shadow view of the light at `lp`: the square frustum from it through the outermost
/// corner of the mesh's bounding box (see the WGSL).
pub fn shadow_view(f: &Frame, lp: V3) -> ShadowView {
    let mut s = ShadowView {
        right: [0.0; 3],
        up: [0.0; 3],
        forward: [0.0; 3],
        near: 0.0,
        far: 0.0,
        ok: false,
        ortho: false,
    };
    let (lo, hi) = (f.shadow_lo, f.shadow_hi);
    let to_c: V3 = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]) - lp[k]);
    let d = length(to_c);
    let diag = length(sub(hi, lo));
    s.ok = d > 1e-6 * diag;
    if !s.ok {
        return s;
    }
    let fw = scale(to_c, 1.0 / d);
    let [right, up] = shadow_axes(fw);
    let (mut t, mut near, mut far) = (0f32, 3.4e38f32, 0f32);
    for k in 0..8 {
        let q: V3 = std::array::from_fn(|a| if k >> a & 1 == 1 { hi[a] } else { lo[a] });
        let v = sub(q, lp);
        let w = dot(v, fw);
        near = near.min(w);
        far = far.max(w);
        t = t.max(dot(v, right).abs().max(dot(v, up).abs()) / w.max(1e-30));
    }
    let eps = 1e-3 * diag;
    s.right = scale(right, t.min(SHADOW_MAX_TAN));
    s.up = scale(up, t.min(SHADOW_MAX_TAN));
    s.forward = fw;
    s.near = (0.99 * near).max(eps);
    s.far = (1.01 * far).max(s.near + eps);
    s
}

/// Clip coordinates of q in a light's shadow view.
pub fn shadow_clip(sv: &ShadowView, lp: V3, q: V3) -> [f32; 4] {
    let d = sub(q, lp);
    let w = dot(d, sv.forward);
    let x = dot(d, sv.right) / dot(sv.right, sv.right);
    let y = dot(d, sv.up) / dot(sv.up, sv.up);
    if sv.ortho {
        return [x, y, (w - sv.near) / (sv.far - sv.near), 1.0];
    }
    let z = (w - sv.near) * sv.far / (sv.far - sv.near);
    [x, y, z, w]
}

/// A distant light's orthographic shadow view along `dir`, from the box's centre (see
/// `shadow_view_ortho` in WGSL).
pub fn shadow_view_ortho(f: &Frame, dir: V3) -> ShadowView {
    let (lo, hi) = (f.shadow_lo, f.shadow_hi);
    let c: V3 = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let diag = length(sub(hi, lo));
    let fw = scale(dir, -1.0);
    let [right, up] = shadow_axes(fw);
    let (mut h, mut near, mut far) = (0f32, 3.4e38f32, -3.4e38f32);
    for k in 0..8 {
        let q: V3 = std::array::from_fn(|a| if k >> a & 1 == 1 { hi[a] } else { lo[a] });
        let v = sub(q, c);
        let w = dot(v, fw);
        near = near.min(w);
        far = far.max(w);
        h = h.max(dot(v, right).abs().max(dot(v, up).abs()));
    }
    let eps = 1e-3 * diag;
    ShadowView {
        right: scale(right, (1.01 * h).max(eps)),
        up: scale(up, (1.01 * h).max(eps)),
        forward: fw,
        near: near - eps,
        far: far + eps,
        ok: diag > 0.0,
        ortho: true,
    }
}

/// Light `l`'s shadow view: perspective from its centre, or a distant light's orthographic one.
pub fn light_shadow_view(f: &Frame, l: &LightGpu) -> ShadowView {
    if l.shape == LightGpu::DISTANT {
        return shadow_view_ortho(f, l.position);
    }
    shadow_view(f, l.position)
}

/// The depth pass's vertex stage for light `li` (clipped away for a light at the box's
/// centre).
pub fn vs_shadow(f: &Frame, lights: &[LightGpu], v: &MeshVertex, li: usize) -> [f32; 4] {
    let lp = shadow_source(f, &lights[li]).0;
    let sv = light_shadow_view(f, &lights[li]);
    if !sv.ok {
        return [0.0, 0.0, -1.0, 1.0];
    }
    shadow_clip(&sv, lp, v.position)
}

/// Forward distance of a stored depth.
pub fn shadow_distance(sv: &ShadowView, z: f32) -> f32 {
    if sv.ortho {
        return sv.near + z * (sv.far - sv.near);
    }
    sv.near * sv.far / (sv.far - z * (sv.far - sv.near))
}

/// The stored depth of forward distance w.
pub fn shadow_depth(sv: &ShadowView, w: f32) -> f32 {
    if sv.ortho {
        return (w - sv.near) / (sv.far - sv.near);
    }
    (w - sv.near) * sv.far / ((sv.far - sv.near) * w)
}

/// The macro shadow's depth maps as the depth pass leaves them: `side`² z/w values per light,
/// layer-major, row 0 at the top of the light's view, 1 where no surface is.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowMaps {
    /// Texels a side.
    pub side: usize,
    /// The depths.
    pub depth: Vec<f32>,
}

/// (bilinear weight of the 2×2 texels nearer the light than depth zr, weighted sum of their
/// distances) around texel coordinates t of layer li.
pub fn shadow_taps(
    maps: &ShadowMaps,
    li: usize,
    sv: &ShadowView,
    t: [f32; 2],
    zr: f32,
) -> [f32; 2] {
    let n = maps.side as i32;
    let c = [t[0] - 0.5, t[1] - 0.5];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let i0 = [c0[0] as i32, c0[1] as i32];
    let (mut blocked, mut dist) = (0f32, 0f32);
    for k in 0..4 {
        let o = [k & 1, k >> 1];
        let q = [i0[0] + o[0], i0[1] + o[1]];
        if q[0] < 0 || q[1] < 0 || q[0] >= n || q[1] >= n {
            continue;
        }
        let wx = if o[0] == 1 { a[0] } else { 1.0 - a[0] };
        let wy = if o[1] == 1 { a[1] } else { 1.0 - a[1] };
        let z = maps.depth[(li * maps.side + q[1] as usize) * maps.side + q[0] as usize];
        if z < zr {
            blocked += wx * wy;
            dist += wx * wy * shadow_distance(sv, z);
        }
    }
    [blocked, dist]
}

/// The Vogel disc both PCSS steps sample (`SHADOW_DISC`, the same literals).
pub const SHADOW_DISC: [[f32; 2]; 16] = [
    [0.17677669, 0.0],
    [-0.22577219, 0.20682582],
    [0.03455805, -0.39377117],
    [0.28457123, 0.37117276],
    [-0.5222232, -0.09237393],
    [0.4946954, -0.31468472],
    [-0.16546592, 0.615525],
    [-0.31556147, -0.60759443],
    [0.68464214, 0.25003022],
    [-0.7122561, 0.29400897],
    [0.3433545, -0.73372865],
    [0.25373024, 0.808932],
    [-0.7647459, -0.44318587],
    [0.897134, -0.1972324],
    [-0.5475069, 0.77877223],
    [-0.12648678, -0.9760897],
];

/// The normal offset and depth bias in texel footprints (`SHADOW_NORMAL_OFFSET`,
/// `SHADOW_BIAS`).
pub const SHADOW_NORMAL_OFFSET: f32 = 1.0;
/// See [`SHADOW_NORMAL_OFFSET`].
pub const SHADOW_BIAS: f32 = 1.5;

/// Where light `l`'s shadow view starts and how its disc spreads (see `shadow_source` in
/// WGSL): a local light's centre and [`shadow_light_radius`]; for a distant light the box's
/// centre and tan ρ.
pub fn shadow_source(f: &Frame, l: &LightGpu) -> (V3, f32) {
    if l.shape == LightGpu::DISTANT {
        let tan_rho = l.radius / (1.0 - l.radius * l.radius).max(1e-12).sqrt();
        let centre: V3 = std::array::from_fn(|k| 0.5 * (f.shadow_lo[k] + f.shadow_hi[k]));
        return (centre, tan_rho);
    }
    (l.position, shadow_light_radius(l))
}

/// The disc radius a light is filtered as.
pub fn shadow_light_radius(l: &LightGpu) -> f32 {
    if l.shape == 1 {
        return (4.0 * l.half[0] * l.half[1] / PI).sqrt();
    }
    if l.shape == LightGpu::GAUSSIAN {
        return 2.0 * (l.half[0] * l.half[1]).sqrt();
    }
    l.radius
}

/// Fraction of light li's disc the mesh leaves visible from `world` (PCSS; see the WGSL).
pub fn shadow_visibility(
    f: &Frame,
    lights: &[LightGpu],
    maps: &ShadowMaps,
    li: usize,
    world: V3,
    n: V3,
) -> f32 {
    let light = &lights[li];
    let (lp, radius) = shadow_source(f, light);
    let sv = light_shadow_view(f, light);
    if !sv.ok {
        return 1.0;
    }
    let size = f.shadow_size as f32;
    let tan_half = length(sv.right);
    // Orthographic (a distant light): a texel spans the same length at every distance, and
    // the cone widens by tan ρ a unit of distance (see the WGSL).
    let footprint = if sv.ortho {
        2.0 * tan_half / size
    } else {
        2.0 * tan_half * dot(sub(world, lp), sv.forward) / size
    };
    let moved: V3 = std::array::from_fn(|k| world[k] + n[k] * (SHADOW_NORMAL_OFFSET * footprint));
    let clip = shadow_clip(&sv, lp, moved);
    let fwd = if sv.ortho {
        dot(sub(moved, lp), sv.forward)
    } else {
        clip[3]
    };
    let wr = fwd - SHADOW_BIAS * footprint;
    let zr = shadow_depth(&sv, wr);
    let t = [
        (clip[0] / clip[3] + 1.0) * (0.5 * size),
        (1.0 - clip[1] / clip[3]) * (0.5 * size),
    ];
    let scale_ = 0.5 * size / tan_half;
    let cap = size / 16.0;
    let search = if sv.ortho {
        radius * (wr - sv.near).max(0.0) * scale_
    } else {
        radius * (wr - sv.near).max(0.0) / (wr * sv.near) * scale_
    }
    .min(cap);
    let (mut blocked, mut dist) = (0f32, 0f32);
    for d in &SHADOW_DISC {
        let b = shadow_taps(
            maps,
            li,
            &sv,
            [t[0] + d[0] * search, t[1] + d[1] * search],
            zr,
        );
        blocked += b[0];
        dist += b[1];
    }
    if blocked <= 0.0 {
        return 1.0;
    }
    if blocked > SHADOW_DISC.len() as f32 - 1e-3 {
        return 0.0;
    }
    let wb = dist / blocked;
    let penumbra = if sv.ortho {
        radius * (wr - wb).max(0.0) * scale_
    } else {
        radius * (wr - wb).max(0.0) / (wr * wb) * scale_
    }
    .min(cap);
    let mut occluded = 0f32;
    for d in &SHADOW_DISC {
        occluded += shadow_taps(
            maps,
            li,
            &sv,
            [t[0] + d[0] * penumbra, t[1] + d[1] * penumbra],
            zr,
        )[0];
    }
    1.0 - occluded / SHADOW_DISC.len() as f32
}

/// The depth pass on the CPU: each light's view of the mesh rasterised into its layer.
pub fn shadow_maps(p: &SceneBuffers) -> ShadowMaps {
    let f = &p.frame;
    let side = f.shadow_size as usize;
    let layers = p.lights.len().max(1);
    let mut depth = vec![1.0f32; layers * side * side];
    for li in 0..p.lights.len().min(f.light_count as usize) {
        let clips: Vec<[f32; 4]> = p
            .mesh_vertices
            .iter()
            .map(|v| vs_shadow(f, &p.lights, v, li))
            .collect();
        let hits = raster(&clips, [side, side]);
        for (d, h) in depth[li * side * side..(li + 1) * side * side]
            .iter_mut()
            .zip(hits)
        {
            if let Some(h) = h {
                *d = h.z;
            }
        }
    }
    ShadowMaps { side, depth }
}

/// A triangle clipped to the near plane and set up for rasterising: screen positions, depths
/// z/w, 1/w, its pixel bounds, and each corner's weights over the original triangle's corners.
struct Setup {
    /// The original triangle.
    tri: u32,
    s: [[f32; 2]; 3],
    z: [f32; 3],
    inv_w: [f32; 3],
    /// Original-triangle barycentrics of each corner (the unit rows when it was not clipped).
    orig: [[f32; 3]; 3],
    area: f32,
    bbox: [i64; 4],
}

/// Rows per band of the rasteriser's parallel loop.
const BAND: usize = 8;

/// The nearest triangle at a pixel: the original triangle, perspective-correct weights of its
/// three corners, and the depth z/w stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index of the triangle (corners 3t … 3t + 2).
    pub tri: u32,
    /// Perspective-correct weights of its corners at the pixel centre.
    pub weights: [f32; 3],
    /// Depth z/w (0 at the near plane, 1 at the far).
    pub z: f32,
    /// The triangle is counter-clockwise in normalised device coordinates (its front).
    pub front: bool,
}

/// How far outside the viewport the rasteriser's guard band reaches: triangles are clipped to
/// |x|, |y| ≤ `GUARD`·w besides the near plane, so screen coordinates stay within a few
/// viewports and the f32 edge functions keep their precision (a corner just past the near
/// plane projects thousands of viewports away). Clipping there changes no pixel: the band is
/// outside the image.
const GUARD: f32 = 2.0;

/// The planes a triangle is clipped to, as signed distances of a clip-space point (≥ 0 inside):
/// the near plane z ≥ 0 first (it makes w > 0 for the others), then the guard band.
fn clip_distance(plane: usize, c: [f32; 4]) -> f32 {
    match plane {
        0 => c[2],
        1 => GUARD * c[3] - c[0],
        2 => GUARD * c[3] + c[0],
        3 => GUARD * c[3] - c[1],
        _ => GUARD * c[3] + c[1],
    }
}

/// Clips triangle `tri` (clip coordinates of its corners) to the near plane and the guard band,
/// Sutherland–Hodgman: a convex polygon, each corner with clip coordinates and weights over the
/// three original corners (empty when nothing is left).
fn clip_polygon(tri: &[[f32; 4]]) -> Vec<([f32; 4], [f32; 3])> {
    let mut poly: Vec<([f32; 4], [f32; 3])> = vec![
        (tri[0], [1.0, 0.0, 0.0]),
        (tri[1], [0.0, 1.0, 0.0]),
        (tri[2], [0.0, 0.0, 1.0]),
    ];
    for plane in 0..5 {
        if poly.iter().all(|(c, _)| clip_distance(plane, *c) >= 0.0) {
            continue;
        }
        let mut out = Vec::with_capacity(poly.len() + 1);
        for k in 0..poly.len() {
            let (a, wa) = poly[k];
            let (b, wb) = poly[(k + 1) % poly.len()];
            let (da, db) = (clip_distance(plane, a), clip_distance(plane, b));
            if da >= 0.0 {
                out.push((a, wa));
            }
            if (da >= 0.0) != (db >= 0.0) {
                let t = da / (da - db);
                let mut c: [f32; 4] = std::array::from_fn(|i| a[i] + t * (b[i] - a[i]));
                if plane == 0 {
                    c[2] = 0.0; // exactly on the near plane
                }
                out.push((c, std::array::from_fn(|i| wa[i] + t * (wb[i] - wa[i]))));
            }
        }
        poly = out;
        if poly.len() < 3 {
            return Vec::new();
        }
    }
    poly
}

/// Renders a mesh scene on the CPU: [`rasterise`], then [`fs_mesh`] per covered pixel (with
/// the macro shadow's maps from [`shadow_maps`] when the variant has them). Alpha 0 where no
/// triangle covers a pixel.
pub fn render(p: &SceneBuffers) -> Image {
    let maps = p.variant.shadow.then(|| shadow_maps(p));
    render_with_shadow_maps(p, maps.as_ref())
}

/// As [`render`] with the macro shadow's depth maps given (e.g. the GPU's, read back with
/// `gpu::Renderer::read_shadow_maps`, to compare the shading alone).
pub fn render_with_shadow_maps(p: &SceneBuffers, maps: Option<&ShadowMaps>) -> Image {
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let twin = Twin {
        p,
        blur: None,
        opacity: None,
    };
    let pixels = rasterise(p)
        .par_iter()
        .map(|m| m.as_ref().map_or([0.0; 4], |m| fs_mesh(&twin, maps, m)))
        .collect();
    Image {
        width: w,
        height: h,
        pixels,
    }
}

/// The light direction in the tangent frame K sees at each covered pixel (row-major; `None`
/// where no triangle covers it): what the analytic-tangent test checks.
pub fn tangent_light(p: &SceneBuffers, light: usize) -> Vec<Option<[f32; 3]>> {
    rasterise(p)
        .into_iter()
        .map(|m| {
            let m = m?;
            let tbn = tangent_frame(m.front, m.normal, m.tangent);
            let lg = &p.lights[light];
            let l = match lg.shape == LightGpu::DISTANT {
                true => lg.position,
                false => normalize(sub(lg.position, m.world)),
            };
            Some([dot(l, tbn[0]), dot(l, tbn[1]), dot(l, tbn[2])])
        })
        .collect()
}

/// The interpolated fragment each pixel shows (row-major; `None` where no triangle covers it).
pub fn rasterise(p: &SceneBuffers) -> Vec<Option<MeshOut>> {
    let f = &p.frame;
    let out: Vec<MeshOut> = p.mesh_vertices.iter().map(|v| vs_mesh(f, v)).collect();
    let clips: Vec<[f32; 4]> = out.iter().map(|o| o.clip).collect();
    raster(&clips, [f.screen[0] as usize, f.screen[1] as usize])
        .into_iter()
        .map(|hit| {
            let hit = hit?;
            let v = &out[3 * hit.tri as usize..3 * hit.tri as usize + 3];
            let l = hit.weights;
            let lerp =
                |a: &[f32], b: &[f32], c: &[f32], k: usize| l[0] * a[k] + l[1] * b[k] + l[2] * c[k];
            Some(MeshOut {
                clip: [0.0; 4],
                world: std::array::from_fn(|k| lerp(&v[0].world, &v[1].world, &v[2].world, k)),
                normal: std::array::from_fn(|k| lerp(&v[0].normal, &v[1].normal, &v[2].normal, k)),
                tangent: std::array::from_fn(|k| {
                    lerp(&v[0].tangent, &v[1].tangent, &v[2].tangent, k)
                }),
                uv: std::array::from_fn(|k| lerp(&v[0].uv, &v[1].uv, &v[2].uv, k)),
                uv_scale: lerp(&[v[0].uv_scale], &[v[1].uv_scale], &[v[2].uv_scale], 0),
                front: hit.front,
            })
        })
        .collect()
}

/// The rasteriser: triangles given by the clip coordinates of their corners (three per
/// triangle), clipped to the near plane and the guard band, drawn into `size` pixels with a strict `Less` depth
/// test on z/w (cleared to 1); the nearest hit per pixel (row-major). Row bands of `BAND` run
/// in parallel, each owning its pixels, so the result does not depend on the thread count.
pub fn raster(clips: &[[f32; 4]], size: [usize; 2]) -> Vec<Option<Hit>> {
    let [w, h] = size;
    let setups: Vec<Setup> = clips
        .par_chunks_exact(3)
        .enumerate()
        .flat_map_iter(|(t, tri)| {
            let poly = clip_polygon(tri);
            let fan = poly.len().saturating_sub(2);
            (0..fan).filter_map(move |k| setup(t as u32, [poly[0], poly[k + 1], poly[k + 2]], size))
        })
        .collect();
    let bands = h.div_ceil(BAND);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (i, s) in setups.iter().enumerate() {
        for band in binned
            .iter_mut()
            .take(s.bbox[3] as usize / BAND + 1)
            .skip(s.bbox[1] as usize / BAND)
        {
            band.push(i as u32);
        }
    }
    let mut hits: Vec<Option<Hit>> = vec![None; w * h];
    hits.par_chunks_mut(w * BAND)
        .enumerate()
        .for_each(|(b, rows)| {
            let y0 = b * BAND;
            let nrows = rows.len() / w;
            let mut depth = vec![1.0f32; rows.len()];
            for &i in &binned[b] {
                let s = &setups[i as usize];
                let ys = (s.bbox[1] as usize).max(y0);
                let ye = (s.bbox[3] as usize).min(y0 + nrows - 1);
                for y in ys..=ye {
                    for x in s.bbox[0] as usize..=s.bbox[2] as usize {
                        let q = [x as f32 + 0.5, y as f32 + 0.5];
                        let edge = |a: [f32; 2], c: [f32; 2]| {
                            (c[0] - a[0]) * (q[1] - a[1]) - (c[1] - a[1]) * (q[0] - a[0])
                        };
                        // Screen-space barycentrics of corners 0, 1, 2 (the edges opposite).
                        let l = [
                            edge(s.s[1], s.s[2]) / s.area,
                            edge(s.s[2], s.s[0]) / s.area,
                            edge(s.s[0], s.s[1]) / s.area,
                        ];
                        if l.iter().any(|&x| x < 0.0) {
                            continue;
                        }
                        let z = l[0] * s.z[0] + l[1] * s.z[1] + l[2] * s.z[2];
                        let k = (y - y0) * w + x;
                        if !(0.0..=1.0).contains(&z) || z >= depth[k] {
                            continue;
                        }
                        depth[k] = z;
                        // Perspective-correct: weights λ_k/w_k, normalised, then over the
                        // original triangle's corners.
                        let pw = [l[0] * s.inv_w[0], l[1] * s.inv_w[1], l[2] * s.inv_w[2]];
                        let sum = pw[0] + pw[1] + pw[2];
                        let pw = pw.map(|x| x / sum);
                        let weights = std::array::from_fn(|c| {
                            pw[0] * s.orig[0][c] + pw[1] * s.orig[1][c] + pw[2] * s.orig[2][c]
                        });
                        // Counter-clockwise with y up is clockwise in pixel rows (y down).
                        rows[k] = Some(Hit {
                            tri: s.tri,
                            weights,
                            z,
                            front: s.area < 0.0,
                        });
                    }
                }
            }
        });
    hits
}

/// Screen positions, depths and pixel bounds of one (clipped) triangle; `None` when it has no
/// area on screen or covers no pixel centre's row or column.
fn setup(tri: u32, corners: [([f32; 4], [f32; 3]); 3], size: [usize; 2]) -> Option<Setup> {
    let [w, h] = size;
    let s: [[f32; 2]; 3] = std::array::from_fn(|k| {
        let c = corners[k].0;
        [
            (c[0] / c[3] + 1.0) * 0.5 * w as f32,
            (1.0 - c[1] / c[3]) * 0.5 * h as f32,
        ]
    });
    let area =
        (s[1][0] - s[0][0]) * (s[2][1] - s[0][1]) - (s[1][1] - s[0][1]) * (s[2][0] - s[0][0]);
    if area == 0.0 || !area.is_finite() {
        return None;
    }
    let lo = |a: usize| s.iter().map(|q| q[a]).fold(f32::INFINITY, f32::min);
    let hi = |a: usize| s.iter().map(|q| q[a]).fold(f32::NEG_INFINITY, f32::max);
    let bbox = [
        ((lo(0) - 0.5).floor() as i64).max(0),
        ((lo(1) - 0.5).floor() as i64).max(0),
        ((hi(0) - 0.5).ceil() as i64).min(w as i64 - 1),
        ((hi(1) - 0.5).ceil() as i64).min(h as i64 - 1),
    ];
    (bbox[2] >= bbox[0] && bbox[3] >= bbox[1]).then(|| Setup {
        tri,
        s,
        z: std::array::from_fn(|k| corners[k].0[2] / corners[k].0[3]),
        inv_w: std::array::from_fn(|k| 1.0 / corners[k].0[3]),
        orig: std::array::from_fn(|k| corners[k].1),
        area,
        bbox,
    })
}
