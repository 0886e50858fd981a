//! The ground truth the blur methods are judged against: Monte Carlo over the true light (a
//! sphere, or a uniform rectangle: [`mc_opacity_rect`])
//! with exact ray–plane hits on the (tilted) caster, plugged into the CPU twin in place of a
//! blur method ([`render_reference`]).

use std::f64::consts::PI;

use ptm_format::hash::{splitmix64 as hash, unit_f64 as unit};
use ptm_format::vec3::{dot, normalize};

use crate::blur::explicit::opacity_raw;
use crate::blur::Plane;
use crate::layout::{Frame, LightGpu};
use crate::output::Image;
use crate::penumbra::cone_frame;
use crate::scene::SceneBuffers;

/// The opacity per channel of the caster texel at texel coordinate tc: a glossy scene's
/// 4-channel image holds premultiplied colour and casts its shadow by α (the fourth).
fn plane_opacity(plane: &Plane, tc: [f32; 2]) -> [f64; 3] {
    let v = opacity_raw(&plane.texels, plane.size, tc).map(|x| (x as f32 / 255.0) as f64);
    if plane.channels == 4 {
        [v[3]; 3]
    } else {
        [v[0], v[1], v[2]]
    }
}

/// The ground-truth image: as [`crate::cpu::render`], but the caster opacity of each (pixel,
/// light) is the Monte Carlo mean over the spherical light ([`mc_opacity`], `samples` rays)
/// instead of the blur method's estimate. K, albedo and the unshadowed light term are
/// unchanged, so the difference to a method's image is its soft-shadow error alone.
pub fn render_reference(p: &SceneBuffers, samples: u32) -> Image {
    let samples = samples.max(1);
    let opacity = |q: [f32; 2], l: &LightGpu| {
        let key =
            (q[0].to_bits() as u64) << 32 ^ q[1].to_bits() as u64 ^ l.position[0].to_bits() as u64;
        mc_opacity(&p.frame, &p.plane, q, l, samples, key)
    };
    crate::cpu::render_with(p, Some(&opacity))
}

/// Ground truth: mean caster opacity over a spherical light seen from acceptor point p,
/// cosine-weighted over the light's solid angle (irradiance-weighted), `samples` stratified
/// directions in the cone subtended by the sphere, each ray intersected exactly with the
/// caster plane and the caster's texels looked up (nearest, as the methods see them).
/// Deterministic: the random numbers hash (pixel key, sample).
pub fn mc_opacity(
    frame: &Frame,
    plane: &Plane,
    p: [f32; 2],
    light: &LightGpu,
    samples: u32,
    key: u64,
) -> [f32; 3] {
    if light.shape == LightGpu::RECT || light.shape == LightGpu::GAUSSIAN {
        return mc_opacity_rect(frame, plane, p, light, samples, key, true);
    }
    let h = frame.caster_height as f64;
    let [lx, ly, lz] = light.position.map(|x| x as f64);
    let r = light.radius as f64;
    // A distant light: a cone of half-angle asin(radius) about its direction, its disc at
    // infinity (every caster hit is in front of it).
    let distant = light.shape == LightGpu::DISTANT;
    let c = match distant {
        true => [lx, ly, lz],
        false => [lx - p[0] as f64, ly - p[1] as f64, lz],
    };
    let d = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    if d <= 0.0 || lz <= 0.0 {
        return [0.0; 3];
    }
    let axis = c.map(|x| x / d);
    let cone = cone_frame(axis, r, d);
    let [w, ht] = plane.size;
    let rect = frame.caster_rect.map(|x| x as f64);
    let (sin_t, cos_t) = (frame.caster_sin_tilt as f64, frame.caster_cos_tilt as f64);
    let centre = [0.5 * (rect[0] + rect[2]), 0.5 * (rect[1] + rect[3]), h];
    let (normal, along) = ([0.0, -sin_t, cos_t], [0.0, cos_t, sin_t]);
    // The caster's centre as seen from p (p at the origin of the rays).
    let below = [centre[0] - p[0] as f64, centre[1] - p[1] as f64, h];
    let strata = (samples as f64).sqrt().ceil() as u32;
    let mut sum_w = 0.0;
    let mut sum_o = [0.0f64; 3];
    for s in 0..strata * strata {
        let (si, sj) = (s % strata, s / strata);
        let hs = hash(key.wrapping_mul(0x1000_0001).wrapping_add(s as u64));
        let u1 = (si as f64 + unit(hs)) / strata as f64;
        let u2 = (sj as f64 + unit(hash(hs))) / strata as f64;
        let dir = cone.dir(u1, u2);
        let weight = dir[2];
        if weight <= 0.0 {
            continue;
        }
        // Nearest hit of the sphere along dir (the light surface the ray reaches first).
        let b = dot(dir, c);
        let disc = b * b - (d * d - r * r);
        let t_light = match (distant, disc > 0.0) {
            (true, _) => f64::INFINITY,
            (false, true) => b - disc.sqrt(),
            (false, false) => b,
        };
        // Exact hit of the (tilted) caster plane, in the caster's own axes X and e2.
        let t_caster = dot(normal, below) / dot(normal, dir);
        let mut o = [0.0; 3];
        if t_caster > 0.0 && t_caster < t_light {
            let off: [f64; 3] = std::array::from_fn(|k| t_caster * dir[k] - below[k]);
            let hit = [centre[0] + off[0], centre[1] + dot(off, along)];
            let tc = [
                ((hit[0] - rect[0]) / (rect[2] - rect[0]) * w as f64) as f32,
                ((rect[3] - hit[1]) / (rect[3] - rect[1]) * ht as f64) as f32,
            ];
            o = plane_opacity(plane, tc);
        }
        sum_w += weight;
        for k in 0..3 {
            sum_o[k] += weight * o[k];
        }
    }
    if sum_w <= 0.0 {
        return [0.0; 3];
    }
    sum_o.map(|x| (x / sum_w) as f32)
}

/// As [`mc_opacity`] for a uniform rectangle facing down (half-sides `light.half` along X and
/// Y) or a Gaussian one (σ = `light.half`, points drawn from it: [`planar_offset`]):
/// `samples` stratified points uniform in area, each weighted by cos θ at p · cos θ at the
/// light / r² (the irradiance each patch gives; with `irradiance` false every point weighs the
/// same, the kernel alone: the mean over the rectangle's image on the caster), the ray to each
/// intersected exactly with the caster plane. A sample of a rectangle 1000 times longer than wide still falls in its own
/// stratum, so thin lights need no special care.
pub fn mc_opacity_rect(
    frame: &Frame,
    plane: &Plane,
    p: [f32; 2],
    light: &LightGpu,
    samples: u32,
    key: u64,
    irradiance: bool,
) -> [f32; 3] {
    let h = frame.caster_height as f64;
    let [lx, ly, lz] = light.position.map(|x| x as f64);
    if lz <= 0.0 {
        return [0.0; 3];
    }
    let half = light.half.map(|x| x as f64);
    let [w, ht] = plane.size;
    let rect = frame.caster_rect.map(|x| x as f64);
    let (sin_t, cos_t) = (frame.caster_sin_tilt as f64, frame.caster_cos_tilt as f64);
    let centre = [0.5 * (rect[0] + rect[2]), 0.5 * (rect[1] + rect[3]), h];
    let (normal, along) = ([0.0, -sin_t, cos_t], [0.0, cos_t, sin_t]);
    let below = [centre[0] - p[0] as f64, centre[1] - p[1] as f64, h];
    // Strata in proportion to the sides (at least one each), about `samples` in all; square
    // (radius × angle) for a Gaussian.
    let aspect = if light.shape == LightGpu::GAUSSIAN {
        1.0
    } else {
        (half[0] / half[1].max(1e-30)).clamp(1.0 / samples as f64, samples as f64)
    };
    let nx = ((samples as f64 * aspect).sqrt().round() as u32).clamp(1, samples);
    let ny = (samples / nx).max(1);
    let mut sum_w = 0.0;
    let mut sum_o = [0.0f64; 3];
    for s in 0..nx * ny {
        let (si, sj) = (s % nx, s / nx);
        let hs = hash(key.wrapping_mul(0x1000_0001).wrapping_add(s as u64));
        let u1 = (si as f64 + unit(hs)) / nx as f64;
        let u2 = (sj as f64 + unit(hash(hs))) / ny as f64;
        let o = turned(light.axis, planar_offset(light.shape, half, u1, u2));
        let q = [lx + o[0], ly + o[1], lz];
        let dir = [q[0] - p[0] as f64, q[1] - p[1] as f64, lz];
        let r2 = dot(dir, dir);
        // cos at p = cos at the light = lz / r; the patch's solid angle ∝ cos_l / r².
        let weight = if irradiance { lz * lz / (r2 * r2) } else { 1.0 };
        let t_caster = dot(normal, below) / dot(normal, dir);
        let mut o = [0.0; 3];
        if t_caster > 0.0 && t_caster < 1.0 {
            let off: [f64; 3] = std::array::from_fn(|k| t_caster * dir[k] - below[k]);
            let hit = [centre[0] + off[0], centre[1] + dot(off, along)];
            let tc = [
                ((hit[0] - rect[0]) / (rect[2] - rect[0]) * w as f64) as f32,
                ((rect[3] - hit[1]) / (rect[3] - rect[1]) * ht as f64) as f32,
            ];
            o = plane_opacity(plane, tc);
        }
        sum_w += weight;
        for k in 0..3 {
            sum_o[k] += weight * o[k];
        }
    }
    if sum_w <= 0.0 {
        return [0.0; 3];
    }
    sum_o.map(|x| (x / sum_w) as f32)
}

/// A point of a planar light as an offset from its centre, from two uniform numbers in [0, 1):
/// uniform over a rectangle of half-sides `half`, or for a Gaussian ([`LightGpu::GAUSSIAN`], σ =
/// `half`) drawn from it by Box–Muller (u1 the radius's quantile, u2 the angle), so stratified
/// (u1, u2) stay stratified.
pub fn planar_offset(shape: u32, half: [f64; 2], u1: f64, u2: f64) -> [f64; 2] {
    if shape == LightGpu::GAUSSIAN {
        let r = (-2.0 * (1.0 - u1).max(1e-300).ln()).sqrt();
        let phi = 2.0 * PI * u2;
        return [half[0] * r * phi.cos(), half[1] * r * phi.sin()];
    }
    [(2.0 * u1 - 1.0) * half[0], (2.0 * u2 - 1.0) * half[1]]
}

/// An offset in a planar light's own frame turned into the cloth's by its `axis` (cos θ, sin θ):
/// a turned rectangle's points.
fn turned(axis: [f32; 2], o: [f64; 2]) -> [f64; 2] {
    let [c, s] = axis.map(|x| x as f64);
    [o[0] * c - o[1] * s, o[0] * s + o[1] * c]
}

/// Ground truth for K under an area light: the mean of [`Ptm::eval_dir`] at texel `texel`
/// (column, row) over the directions from cloth point `p` to `light`, weighted as its
/// irradiance is (cos θ at p over the solid angle; a point light is its centre's K).
/// `samples` stratified directions, as [`mc_opacity`] (sphere: uniform in solid angle within
/// its cone, directions below the horizon weigh 0) and [`mc_opacity_rect`] (rectangle: uniform
/// in area, weighted z²/r⁴; a distant light: its cone, as a sphere's) draw them.
/// Deterministic: the random numbers hash (`key`, sample).
///
/// [`Ptm::eval_dir`]: ptm_format::Ptm::eval_dir
pub fn mc_k(
    ptm: &ptm_format::Ptm,
    texel: [usize; 2],
    p: [f32; 2],
    light: &LightGpu,
    samples: u32,
    key: u64,
) -> f32 {
    // A distant light: its cone about its unit direction, of half-angle asin(radius).
    let c = match light.shape == LightGpu::DISTANT {
        true => light.position.map(|x| x as f64),
        false => [
            light.position[0] as f64 - p[0] as f64,
            light.position[1] as f64 - p[1] as f64,
            light.position[2] as f64,
        ],
    };
    let d = dot(c, c).sqrt();
    if d <= 0.0 || c[2] <= 0.0 {
        return 1.0;
    }
    let axis = c.map(|x| x / d);
    let k = |dir: [f64; 3]| ptm.eval_dir(texel[0], texel[1], dir) as f64;
    let r = light.radius as f64;
    let round = light.shape == LightGpu::SPHERE || light.shape == LightGpu::DISTANT;
    if round && r <= 0.0 {
        return k(axis) as f32;
    }
    let half = light.half.map(|x| x as f64);
    // Strata: square for a sphere or a Gaussian, in proportion to the sides for a rectangle.
    let (nx, ny) = if light.shape == LightGpu::RECT {
        let aspect = (half[0] / half[1].max(1e-30)).clamp(1.0 / samples as f64, samples as f64);
        let nx = ((samples as f64 * aspect).sqrt().round() as u32).clamp(1, samples);
        (nx, (samples / nx).max(1))
    } else {
        let n = (samples as f64).sqrt().ceil() as u32;
        (n, n)
    };
    let cone = cone_frame(axis, r, d);
    let (mut sum_w, mut sum_k) = (0.0, 0.0);
    for s in 0..nx * ny {
        let (si, sj) = (s % nx, s / nx);
        let hs = hash(key.wrapping_mul(0x1000_0001).wrapping_add(s as u64));
        let u1 = (si as f64 + unit(hs)) / nx as f64;
        let u2 = (sj as f64 + unit(hash(hs))) / ny as f64;
        let (dir, weight) = if light.shape == LightGpu::RECT || light.shape == LightGpu::GAUSSIAN {
            let o = turned(light.axis, planar_offset(light.shape, half, u1, u2));
            let q = [c[0] + o[0], c[1] + o[1], c[2]];
            let r2 = dot(q, q);
            (q.map(|x| x / r2.sqrt()), c[2] * c[2] / (r2 * r2))
        } else {
            let dir = cone.dir(u1, u2);
            (dir, dir[2])
        };
        if weight <= 0.0 {
            continue;
        }
        sum_w += weight;
        sum_k += weight * k(dir);
    }
    if sum_w <= 0.0 {
        return 1.0;
    }
    (sum_k / sum_w) as f32
}

/// [`mc_reflection`] at every pixel of a glossy scene (the twin of
/// [`crate::cpu::render_reflection`]), row-major; `rgba` the caster's texels as laid out
/// (`p.plane.size`); `env` the scene's background image, if it has one (the buffers hold only
/// its map prefiltered for the lobe: the reference reads the image itself along every ray).
pub fn render_reflection_reference(
    p: &SceneBuffers,
    rgba: &[[u8; 4]],
    env: Option<&crate::environment::Environment>,
    samples: u32,
) -> Vec<[f32; 3]> {
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    assert_eq!(
        rgba.len(),
        (p.plane.size[0] * p.plane.size[1]) as usize,
        "the caster's texels as laid out"
    );
    let twin = crate::cpu::shade::Twin {
        p,
        blur: None,
        opacity: None,
    };
    use rayon::prelude::*;
    (0..w * h)
        .into_par_iter()
        .map(|t| {
            let frag = [(t % w) as f32 + 0.5, (t / w) as f32 + 0.5];
            let Some(q) = crate::cpu::shade::pixel_world(&p.frame, frag) else {
                return [0.0; 3];
            };
            let dir = twin.view_direction(frag);
            let frame = &p.frame;
            mc_reflection(frame, p.plane.size, rgba, env, q, dir, samples, t as u64)
        })
        .collect()
}

/// Ground truth for a glossy receiver ([`crate::scene::Glossy`]): the radiance reflected at
/// cloth point p seen along the unit view direction `dir`, ray-traced over its lobe: `samples`
/// stratified directions uniform in solid angle within the cone of half-angle `frame.glossy_alpha`
/// around the mirror direction, each intersected exactly with the (tilted) caster plane; a ray
/// that hits the caster takes its texel (nearest, as the methods see them) composited over the
/// background, α·colour + (1 − α)·background with the texel's own linear colour (sRGB decoded,
/// as the methods' premultiplied image holds it, unquantised); a ray that misses it takes the background. `rgba` is the caster's
/// image as the scene laid it out (`plane.size` texels). With a background image `env` each
/// ray's background is the image along the ray at full resolution
/// ([`crate::environment::Environment::radiance`]), not the lobe's prefiltered average.
/// Deterministic: the random numbers hash (`key`, sample).
#[allow(clippy::too_many_arguments)]
pub fn mc_reflection(
    frame: &Frame,
    size: [u32; 2],
    rgba: &[[u8; 4]],
    env: Option<&crate::environment::Environment>,
    p: [f32; 2],
    dir: [f32; 3],
    samples: u32,
    key: u64,
) -> [f32; 3] {
    let back = frame.glossy_background.map(|x| x as f64);
    let d = [dir[0] as f64, dir[1] as f64, dir[2] as f64];
    let axis = normalize([d[0], d[1], -d[2]]);
    let sin_a = (frame.glossy_alpha as f64).sin();
    let cone = cone_frame(axis, sin_a, 1.0);
    let h = frame.caster_height as f64;
    let [w, ht] = size;
    let rect = frame.caster_rect.map(|x| x as f64);
    let (sin_t, cos_t) = (frame.caster_sin_tilt as f64, frame.caster_cos_tilt as f64);
    let centre = [0.5 * (rect[0] + rect[2]), 0.5 * (rect[1] + rect[3]), h];
    let (normal, along) = ([0.0, -sin_t, cos_t], [0.0, cos_t, sin_t]);
    let below = [centre[0] - p[0] as f64, centre[1] - p[1] as f64, h];
    let strata = (samples.max(1) as f64).sqrt().ceil() as u32;
    let mut sum = [0.0f64; 3];
    for s in 0..strata * strata {
        let (si, sj) = (s % strata, s / strata);
        let hs = hash(key.wrapping_mul(0x1000_0001).wrapping_add(s as u64));
        let u1 = (si as f64 + unit(hs)) / strata as f64;
        let u2 = (sj as f64 + unit(hash(hs))) / strata as f64;
        let ray = cone.dir(u1, u2);
        let back = env.map_or(back, |e| {
            e.radiance(ray.map(|x| x as f32)).map(|x| x as f64)
        });
        let mut c = back;
        let t_caster = dot(normal, below) / dot(normal, ray);
        if t_caster > 0.0 && t_caster.is_finite() {
            let off: [f64; 3] = std::array::from_fn(|k| t_caster * ray[k] - below[k]);
            let hit = [centre[0] + off[0], centre[1] + dot(off, along)];
            let tc = [
                (hit[0] - rect[0]) / (rect[2] - rect[0]) * w as f64,
                (rect[3] - hit[1]) / (rect[3] - rect[1]) * ht as f64,
            ];
            if tc[0] >= 0.0 && tc[1] >= 0.0 && tc[0] < w as f64 && tc[1] < ht as f64 {
                let px = rgba[tc[1] as usize * w as usize + tc[0] as usize];
                let a = px[3] as f64 / 255.0;
                c = std::array::from_fn(|k| {
                    let lin = crate::output::srgb_decode(px[k] as f32 / 255.0) as f64;
                    a * lin + (1.0 - a) * back[k]
                });
            }
        }
        for k in 0..3 {
            sum[k] += c[k];
        }
    }
    sum.map(|x| (x / (strata * strata) as f64) as f32)
}
