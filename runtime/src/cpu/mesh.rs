//! Twin of `shader/mesh.wgsl`: every WGSL function under its name, same maths, and a small
//! software rasteriser standing in for the GPU's (pixel centres, edge functions, a strict
//! `Less` depth test on depth z/w interpolated in screen space, varyings interpolated
//! perspective-correctly). Pixels whose centre lies on a triangle's edge can go to either
//! triangle (fill rules differ), so a comparison with the GPU masks pixels the two cover
//! differently ([`Image`] alpha: 1 covered, 0 not).
//!
//! Triangles with a corner closer than the near plane are skipped (the GPU clips them): mesh
//! scenes put the near plane in front of the whole mesh unless the camera is inside its bounds.

use rayon::prelude::*;

use super::shade::{tile_bilinear, Twin};
use crate::layout::{Frame, MeshVertex};
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

/// Linear radiance leaving a mesh point (see `shade_mesh` in WGSL).
pub fn shade_mesh(t: &Twin, m: &MeshOut) -> V3 {
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
    for light in &t.p.lights[..f.light_count as usize] {
        let to_light = sub(light.position, world);
        let d2 = dot(to_light, to_light);
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
pub fn fs_mesh(t: &Twin, m: &MeshOut) -> [f32; 4] {
    let r = shade_mesh(t, m);
    [r[0], r[1], r[2], 1.0]
}

/// A triangle set up for rasterising: screen positions, depths, 1/w and its pixel bounds.
struct Setup {
    s: [[f32; 2]; 3],
    z: [f32; 3],
    inv_w: [f32; 3],
    area: f32,
    bbox: [i64; 4],
}

/// Rows per band of the rasteriser's parallel loop.
const BAND: usize = 8;

/// Renders a mesh scene on the CPU: [`rasterise`], then [`fs_mesh`] per covered pixel. Alpha 0
/// where no triangle covers a pixel.
pub fn render(p: &SceneBuffers) -> Image {
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let twin = Twin {
        p,
        blur: None,
        opacity: None,
    };
    let pixels = rasterise(p)
        .par_iter()
        .map(|m| m.as_ref().map_or([0.0; 4], |m| fs_mesh(&twin, m)))
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
            let l = normalize(sub(p.lights[light].position, m.world));
            Some([dot(l, tbn[0]), dot(l, tbn[1]), dot(l, tbn[2])])
        })
        .collect()
}

/// The interpolated fragment each pixel shows (row-major; `None` where no triangle covers it),
/// in row bands of `BAND` in parallel (each band owns its pixels, so the result does not
/// depend on the thread count).
pub fn rasterise(p: &SceneBuffers) -> Vec<Option<MeshOut>> {
    let f = &p.frame;
    let [w, h] = [f.screen[0] as usize, f.screen[1] as usize];
    let out: Vec<MeshOut> = p.mesh_vertices.iter().map(|v| vs_mesh(f, v)).collect();
    let setups: Vec<Option<Setup>> = out
        .par_chunks_exact(3)
        .map(|tri| {
            if tri.iter().any(|v| v.clip[3] < f.near) {
                return None;
            }
            let s: [[f32; 2]; 3] = std::array::from_fn(|k| {
                let c = tri[k].clip;
                [
                    (c[0] / c[3] + 1.0) * 0.5 * f.screen[0],
                    (1.0 - c[1] / c[3]) * 0.5 * f.screen[1],
                ]
            });
            let area = (s[1][0] - s[0][0]) * (s[2][1] - s[0][1])
                - (s[1][1] - s[0][1]) * (s[2][0] - s[0][0]);
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
                s,
                z: std::array::from_fn(|k| tri[k].clip[2] / tri[k].clip[3]),
                inv_w: std::array::from_fn(|k| 1.0 / tri[k].clip[3]),
                area,
                bbox,
            })
        })
        .collect();
    let bands = h.div_ceil(BAND);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (t, s) in setups.iter().enumerate() {
        let Some(s) = s else { continue };
        for band in binned
            .iter_mut()
            .take(s.bbox[3] as usize / BAND + 1)
            .skip(s.bbox[1] as usize / BAND)
        {
            band.push(t as u32);
        }
    }
    let mut frags: Vec<Option<MeshOut>> = vec![None; w * h];
    frags
        .par_chunks_mut(w * BAND)
        .enumerate()
        .for_each(|(b, rows)| {
            let y0 = b * BAND;
            let nrows = rows.len() / w;
            let mut depth = vec![1.0f32; rows.len()];
            let mut hit: Vec<Option<(u32, [f32; 3])>> = vec![None; rows.len()];
            for &t in &binned[b] {
                let s = setups[t as usize]
                    .as_ref()
                    .expect("binned triangles are set up");
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
                        let i = (y - y0) * w + x;
                        if !(0.0..=1.0).contains(&z) || z >= depth[i] {
                            continue;
                        }
                        depth[i] = z;
                        // Perspective-correct: weights λ_k/w_k, normalised.
                        let pw = [l[0] * s.inv_w[0], l[1] * s.inv_w[1], l[2] * s.inv_w[2]];
                        let sum = pw[0] + pw[1] + pw[2];
                        hit[i] = Some((t, pw.map(|x| x / sum)));
                    }
                }
            }
            for (px, hit) in rows.iter_mut().zip(hit) {
                let Some((t, l)) = hit else { continue };
                let v = &out[3 * t as usize..3 * t as usize + 3];
                let lerp = |a: &[f32], b: &[f32], c: &[f32], k: usize| {
                    l[0] * a[k] + l[1] * b[k] + l[2] * c[k]
                };
                *px = Some(MeshOut {
                    clip: [0.0; 4],
                    world: std::array::from_fn(|k| lerp(&v[0].world, &v[1].world, &v[2].world, k)),
                    normal: std::array::from_fn(|k| {
                        lerp(&v[0].normal, &v[1].normal, &v[2].normal, k)
                    }),
                    tangent: std::array::from_fn(|k| {
                        lerp(&v[0].tangent, &v[1].tangent, &v[2].tangent, k)
                    }),
                    uv: std::array::from_fn(|k| lerp(&v[0].uv, &v[1].uv, &v[2].uv, k)),
                    uv_scale: lerp(&[v[0].uv_scale], &[v[1].uv_scale], &[v[2].uv_scale], 0),
                    // Counter-clockwise with y up is clockwise in pixel rows (y down).
                    front: setups[t as usize].as_ref().is_some_and(|s| s.area < 0.0),
                });
            }
        });
    frags
}
