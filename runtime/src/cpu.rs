//! The CPU twin of `shade.wgsl`: same function names, same maths, same f32 arithmetic, reading
//! the same [`Prepared`] buffers. Tests compare the GPU image with it (≤ 1e-3 linear radiance).

use rayon::prelude::*;

use ptm_fit::{Link, UvMap};

use crate::output::Image;
use crate::scene::{Blur, Frame, LightGpu, Prepared, PtmLevel};
use crate::{mip, penumbra, sat, separable};

/// Renders the prepared scene on the CPU (row-parallel; each pixel is independent, so the
/// result does not depend on the thread count).
pub fn render(p: &Prepared) -> Image {
    render_with(p, 0)
}

/// The ground-truth image: as [`render`], but the caster opacity of each (pixel, light) is the
/// Monte Carlo mean over the spherical light ([`penumbra::mc_opacity`], `samples` rays) instead
/// of the blur method's estimate. K, albedo and the unshadowed light term are unchanged, so the
/// difference to a method's image is its soft-shadow error alone.
pub fn render_reference(p: &Prepared, samples: u32) -> Image {
    render_with(p, samples.max(1))
}

fn render_with(p: &Prepared, mc_samples: u32) -> Image {
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let table = match p.variant.caster {
        Some(Blur::Sat) => sat::build_cpu(
            &p.opacity,
            p.frame.counts[1] as usize,
            p.frame.counts[2] as usize,
            p.variant.sat_channels() as usize,
        ),
        _ => Vec::new(),
    };
    let sep = match p.variant.caster {
        Some(Blur::Separable) => {
            let (w, h, ch) = (
                p.frame.counts[1],
                p.frame.counts[2],
                p.variant.sat_channels(),
            );
            let hmap = separable::pass_h(&p.opacity, w, h, ch, &p.separable);
            separable::pass_v(&hmap, h, ch, &p.separable)
        }
        _ => Vec::new(),
    };
    let twin = Twin {
        p,
        sat: &table,
        sep: &sep,
        mc_samples,
    };
    let mut pixels = vec![[0f32; 4]; w * h];
    pixels.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            let frag = [i as f32 + 0.5, j as f32 + 0.5];
            let r = pixel_world(&p.frame, frag)
                .map_or([0.0; 3], |q| twin.shade(q, ptm_lod(&p.frame, frag)));
            *px = [r[0], r[1], r[2], 1.0];
        }
    });
    Image {
        width: w,
        height: h,
        pixels,
    }
}

/// Cloth point seen through a pixel centre (`frag` = pixel index + 0.5), `None` when a
/// perspective ray misses the plane z = 0.
pub fn pixel_world(f: &Frame, frag: [f32; 2]) -> Option<[f32; 2]> {
    let t = [frag[0] / f.screen[0], frag[1] / f.screen[1]];
    if f.eye[3] == 0.0 {
        return Some([
            f.view[0] + (f.view[2] - f.view[0]) * t[0],
            f.view[3] - (f.view[3] - f.view[1]) * t[1],
        ]);
    }
    let dir = view_dir(f, frag);
    if dir[2] >= 0.0 || f.eye[2] <= 0.0 {
        return None;
    }
    let s = -f.eye[2] / dir[2];
    Some([f.eye[0] + s * dir[0], f.eye[1] + s * dir[1]])
}

/// Perspective ray direction through pixel `frag` (forward component 1), as in WGSL.
fn view_dir(f: &Frame, frag: [f32; 2]) -> [f32; 3] {
    let t = [frag[0] / f.screen[0], frag[1] / f.screen[1]];
    std::array::from_fn(|k| {
        f.cam_forward[k] + (2.0 * t[0] - 1.0) * f.cam_right[k] + (1.0 - 2.0 * t[1]) * f.cam_up[k]
    })
}

/// log2 of the PTM texels under pixel `frag`, clamped to the chain, as `ptm_lod` in WGSL;
/// 0 without a chain.
pub fn ptm_lod(f: &Frame, frag: [f32; 2]) -> f32 {
    let levels = f.cam_forward[3];
    if levels < 2.0 {
        return 0.0;
    }
    let mut texels = f.cam_up[3];
    if f.eye[3] != 0.0 {
        let dir = view_dir(f, frag);
        let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        texels = texels * f.eye[2] * len / (dir[2] * dir[2]);
    }
    texels.max(1.0).log2().clamp(0.0, levels - 1.0)
}

/// Texel indices (x0y0, x1y0, x0y1, x1y1) and bilinear weights, as `tile_bilinear` in WGSL.
pub fn tile_bilinear(f: &Frame, p: [f32; 2], n: [u32; 2]) -> ([usize; 4], [f32; 4]) {
    let s = [p[0] / f.screen[2], p[1] / f.screen[3]];
    let fr = [s[0] - s[0].floor(), 1.0 - (s[1] - s[1].floor())];
    let c = [fr[0] * n[0] as f32 - 0.5, fr[1] * n[1] as f32 - 0.5];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let ni = [n[0] as i32, n[1] as i32];
    let x0 = (c0[0] as i32).rem_euclid(ni[0]);
    let y0 = (c0[1] as i32).rem_euclid(ni[1]);
    let x1 = (x0 + 1) % ni[0];
    let y1 = (y0 + 1) % ni[1];
    let idx = |x: i32, y: i32| (y * ni[0] + x) as usize;
    (
        [idx(x0, y0), idx(x1, y0), idx(x0, y1), idx(x1, y1)],
        [
            (1.0 - a[0]) * (1.0 - a[1]),
            a[0] * (1.0 - a[1]),
            (1.0 - a[0]) * a[1],
            a[0] * a[1],
        ],
    )
}

/// One axis of [`level_bilinear`]: texel indices (x0, x1) and the weight of x1, as `level_axis`
/// in WGSL (the gap between the last texel and the next tile's first spans period − n + 1).
pub fn level_axis(c: f32, n: u32, period: f32) -> (usize, usize, f32) {
    let c0 = c.floor();
    let a = c - c0;
    let x0 = c0 as i32;
    let last = n as i32 - 1;
    if x0 >= 0 && x0 < last {
        return (x0 as usize, x0 as usize + 1, a);
    }
    let offset = (x0 - last) as f32 + if x0 < 0 { period } else { 0.0 };
    let gap = period - n as f32 + 1.0;
    (last as usize, 0, (a + offset) / gap)
}

/// Texel indices and bilinear weights in a MIP level, as `level_bilinear` in WGSL (indices are
/// relative to the level's first texel).
pub fn level_bilinear(f: &Frame, p: [f32; 2], lv: &PtmLevel) -> ([usize; 4], [f32; 4]) {
    let s = [p[0] / f.screen[2], p[1] / f.screen[3]];
    let fr = [s[0] - s[0].floor(), 1.0 - (s[1] - s[1].floor())];
    let c = [fr[0] * lv.period[0] - 0.5, fr[1] * lv.period[1] - 0.5];
    let (x0, x1, ax) = level_axis(c[0], lv.width, lv.period[0]);
    let (y0, y1, ay) = level_axis(c[1], lv.height, lv.period[1]);
    let w = lv.width as usize;
    (
        [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1],
        [
            (1.0 - ax) * (1.0 - ay),
            ax * (1.0 - ay),
            (1.0 - ax) * ay,
            ax * ay,
        ],
    )
}

/// Hemispherical (u, v) of the unit light direction l (l.z > 0), as `ptm_hemispherical` in
/// WGSL: l.xy · θ/((π/2)·r), θ = atan2(r, l.z), r = |l.xy|.
pub fn ptm_hemispherical(l: [f32; 3]) -> [f32; 2] {
    let r = (l[0] * l[0] + l[1] * l[1]).sqrt();
    let s = if r > 1e-6 { r.atan2(l[2]) / r } else { 1.0 };
    let s = s / std::f32::consts::FRAC_PI_2;
    [l[0] * s, l[1] * s]
}

/// σ(p) from e^−|p| (no overflow), as `ptm_sigmoid` in WGSL.
pub fn ptm_sigmoid(p: f32) -> f32 {
    let e = (-p.abs()).exp();
    if p >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    }
}

/// K of `link` and `uv` before the clamp for the unit light direction l: what `ptm_k` clamps.
pub fn ptm_k_unclamped(
    basis: ptm_fit::Basis,
    link: Link,
    uv: UvMap,
    c: &[f32],
    l: [f32; 3],
) -> f32 {
    let [u, v] = match uv {
        UvMap::Projected => [l[0], l[1]],
        UvMap::Hemispherical => ptm_hemispherical(l),
    };
    let p = basis.eval(&c[..basis.len()], u, v);
    match link {
        Link::Identity => p,
        Link::Logistic => ptm_sigmoid(p),
    }
}

/// Mean of `n` values per texel at the four bilinear taps.
fn bilerp<const N: usize>(data: &[f32], n: usize, taps: &([usize; 4], [f32; 4])) -> [f32; N] {
    let mut out = [0f32; N];
    for (k, o) in out.iter_mut().enumerate().take(n) {
        let (i, w) = taps;
        *o = w[0] * data[i[0] * n + k]
            + w[1] * data[i[1] * n + k]
            + w[2] * data[i[2] * n + k]
            + w[3] * data[i[3] * n + k];
    }
    out
}

struct Twin<'a> {
    p: &'a Prepared,
    sat: &'a [u32],
    /// Separable blur: the per-light blurred maps.
    sep: &'a [f32],
    /// > 0: Monte Carlo ground truth with this many rays instead of the blur method.
    mc_samples: u32,
}

impl Twin<'_> {
    fn f(&self) -> &Frame {
        &self.p.frame
    }

    /// PTM coefficients at p: bilinear, or trilinear in the MIP chain at level of detail `lod`.
    fn ptm_coeffs(&self, p: [f32; 2], lod: f32) -> [f32; 16] {
        let f = self.f();
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        if !self.p.variant.ptm_mip {
            let taps = tile_bilinear(f, p, [f.sizes[0], f.sizes[1]]);
            return bilerp::<16>(&self.p.coeffs, n, &taps);
        }
        let level = |l: usize| {
            let lv = &self.p.ptm_levels[l];
            let (mut idx, w) = level_bilinear(f, p, lv);
            idx = idx.map(|i| i + lv.offset as usize);
            bilerp::<16>(&self.p.coeffs, n, &(idx, w))
        };
        let l0 = lod.floor();
        let fr = lod - l0;
        let mut c = level(l0 as usize);
        if fr > 0.0 {
            let c1 = level(l0 as usize + 1);
            for k in 0..n {
                c[k] += fr * (c1[k] - c[k]);
            }
        }
        c
    }

    /// K of the file's link and (u, v) map for the unit light direction l, clamped to [0, 1].
    fn ptm_k(&self, c: &[f32; 16], l: [f32; 3]) -> f32 {
        let v = &self.p.variant;
        let basis = v.basis.expect("ptm_k without a PTM");
        ptm_k_unclamped(basis, v.link, v.uv, c, l).clamp(0.0, 1.0)
    }

    fn albedo_at(&self, p: [f32; 2]) -> [f32; 3] {
        let f = self.f();
        if !self.p.variant.albedo_texture {
            return [f.albedo[0], f.albedo[1], f.albedo[2]];
        }
        let taps = tile_bilinear(f, p, [f.sizes[2], f.sizes[3]]);
        let flat: &[f32] = bytemuck::cast_slice(&self.p.albedo);
        let a = bilerp::<4>(flat, 4, &taps);
        [a[0], a[1], a[2]]
    }

    fn caster_texel_coords(&self, q: [f32; 2]) -> [f32; 2] {
        let f = self.f();
        let r = f.caster_rect;
        let size = [f.counts[1] as f32, f.counts[2] as f32];
        [
            (q[0] - r[0]) / (r[2] - r[0]) * size[0],
            (r[3] - q[1]) / (r[3] - r[1]) * size[1],
        ]
    }

    fn blur_explicit(&self, t: [f32; 2], wt: [f32; 2]) -> [f32; 3] {
        let f = self.f();
        let n = ((4.0 * wt[0].max(wt[1])).ceil() as u32).clamp(16, f.counts[3]);
        let mut sum = [0u32; 3];
        let mut count = 0u32;
        for j in 0..n {
            for i in 0..n {
                let o = [
                    (i as f32 + 0.5) / n as f32 * 2.0 - 1.0,
                    (j as f32 + 0.5) / n as f32 * 2.0 - 1.0,
                ];
                if o[0] * o[0] + o[1] * o[1] <= 1.0 {
                    let v = opacity_raw(
                        &self.p.opacity,
                        f.counts[1],
                        f.counts[2],
                        [t[0] + o[0] * wt[0], t[1] + o[1] * wt[1]],
                    );
                    for c in 0..3 {
                        sum[c] += v[c];
                    }
                    count += 1;
                }
            }
        }
        sum.map(|s| s as f32 / (count as f32 * 255.0))
    }

    fn blur_sat(&self, t: [f32; 2], wt: [f32; 2]) -> [f32; 3] {
        let f = self.f();
        sat::box_mean(
            self.sat,
            f.counts[1],
            f.counts[2],
            self.p.variant.sat_channels(),
            t,
            wt,
        )
    }

    /// Mean caster opacity seen from p towards light l (see `light_opacity` in WGSL).
    fn light_opacity(&self, p: [f32; 2], l: &LightGpu, li: usize) -> [f32; 3] {
        let f = self.f();
        let [lx, ly, lz, radius] = l.position_radius;
        if self.mc_samples > 0 {
            let key = (p[0].to_bits() as u64) << 32 ^ p[1].to_bits() as u64 ^ lx.to_bits() as u64;
            return penumbra::mc_opacity(f, &self.p.opacity, p, l, self.mc_samples, key);
        }
        // As light_opacity in WGSL: where the segment p → light meets the (tilted) caster plane.
        let r = f.caster_rect;
        let [h, sin_t, cos_t, _] = f.caster;
        let centre = [0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3]), h];
        let n = [0.0, -sin_t, cos_t];
        let e2 = [0.0, cos_t, sin_t];
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let pp = [p[0], p[1], 0.0];
        let ray = [lx - pp[0], ly - pp[1], lz];
        let denom = dot(n, ray);
        if denom == 0.0 {
            return [0.0; 3];
        }
        let s = dot(n, [centre[0] - pp[0], centre[1] - pp[1], centre[2]]) / denom;
        if !(0.0..1.0).contains(&s) {
            return [0.0; 3];
        }
        let off: [f32; 3] = std::array::from_fn(|k| pp[k] + s * ray[k] - centre[k]);
        let q = [centre[0] + off[0], centre[1] + dot(off, e2)];
        let w = radius * s;
        let stretch = (cos_t + dot(ray, e2) * sin_t / denom).abs();
        let texel = [
            (r[2] - r[0]) / f.counts[1] as f32,
            (r[3] - r[1]) / f.counts[2] as f32,
        ];
        let wt = [(w / texel[0]).max(0.5), (w * stretch / texel[1]).max(0.5)];
        let t = self.caster_texel_coords(q);
        match self.p.variant.caster {
            Some(Blur::Sat) => self.blur_sat(t, wt),
            Some(Blur::Mip) => mip::blur_mip(&self.p.mip, &self.p.mip_levels, t, wt),
            Some(Blur::Separable) => separable::blur_separable(
                self.sep,
                &self.p.separable,
                self.p.variant.sat_channels(),
                li,
                t,
            ),
            _ => self.blur_explicit(t, wt),
        }
    }

    /// Linear radiance leaving acceptor point p.
    fn shade(&self, p: [f32; 2], lod: f32) -> [f32; 3] {
        let albedo = self.albedo_at(p);
        let c = self.p.variant.basis.map(|_| self.ptm_coeffs(p, lod));
        let mut radiance = [0f32; 3];
        for (li, light) in self.p.lights[..self.f().counts[0] as usize]
            .iter()
            .enumerate()
        {
            let lp = light.position_radius;
            let to_light = [lp[0] - p[0], lp[1] - p[1], lp[2]];
            let d2 =
                to_light[0] * to_light[0] + to_light[1] * to_light[1] + to_light[2] * to_light[2];
            if d2 <= 0.0 || to_light[2] <= 0.0 {
                continue;
            }
            let d = d2.sqrt();
            let l = to_light.map(|x| x / d);
            let mut visible = [1f32; 3];
            if let Some(c) = &c {
                let k = self.ptm_k(c, l);
                visible = visible.map(|v| v * (1.0 - k));
            }
            if self.p.variant.caster.is_some() {
                let o = self.light_opacity(p, light, li);
                for ch in 0..3 {
                    visible[ch] *= 1.0 - o[ch].clamp(0.0, 1.0);
                }
            }
            for ch in 0..3 {
                radiance[ch] += albedo[ch] * light.color[ch] * (l[2] / d2) * visible[ch];
            }
        }
        radiance
    }
}

/// 8-bit opacity counts per channel of the caster texel containing texel coordinate t; 0
/// outside the caster.
pub fn opacity_raw(opacity: &[u32], w: u32, h: u32, t: [f32; 2]) -> [u32; 3] {
    if t[0] < 0.0 || t[1] < 0.0 || t[0] >= w as f32 || t[1] >= h as f32 {
        return [0; 3];
    }
    let o = opacity[t[1] as usize * w as usize + t[0] as usize];
    [o & 255, (o >> 8) & 255, (o >> 16) & 255]
}

/// Opacity (per channel, 0..1) of the caster texel containing t; transparent outside.
pub fn opacity_at(opacity: &[u32], w: u32, h: u32, t: [f32; 2]) -> [f32; 3] {
    opacity_raw(opacity, w, h, t).map(|c| c as f32 / 255.0)
}

/// How far the unclamped K strays from [0, 1] over the rendered pixels and lights: a property
/// of the fit (overshoot at grazing angles), reported beside the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KExcursion {
    pub min: f32,
    pub max: f32,
    /// Fraction of (pixel, light above the horizon) evaluations clamped.
    pub clamped_fraction: f64,
    pub evaluations: u64,
}

/// K before clamping at every pixel for every light, exactly as the shader evaluates it;
/// `None` without a PTM or without a light above the acceptor.
pub fn k_excursion(p: &Prepared) -> Option<KExcursion> {
    let basis = p.variant.basis?;
    let twin = Twin {
        p,
        sat: &[],
        sep: &[],
        mc_samples: 0,
    };
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let lights = &p.lights[..p.frame.counts[0] as usize];
    let rows: Vec<(f32, f32, u64, u64)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let (mut lo, mut hi, mut out, mut n) = (f32::INFINITY, f32::NEG_INFINITY, 0u64, 0u64);
            for i in 0..w {
                let frag = [i as f32 + 0.5, j as f32 + 0.5];
                let Some(pos) = pixel_world(&p.frame, frag) else {
                    continue;
                };
                let c = twin.ptm_coeffs(pos, ptm_lod(&p.frame, frag));
                for l in lights {
                    let lp = l.position_radius;
                    let d = [lp[0] - pos[0], lp[1] - pos[1], lp[2]];
                    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    if d[2] <= 0.0 || len <= 0.0 {
                        continue;
                    }
                    let l = d.map(|x| x / len);
                    let k = ptm_k_unclamped(basis, p.variant.link, p.variant.uv, &c, l);
                    lo = lo.min(k);
                    hi = hi.max(k);
                    out += u64::from(!(0.0..=1.0).contains(&k));
                    n += 1;
                }
            }
            (lo, hi, out, n)
        })
        .collect();
    let (lo, hi, out, n) = rows
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY, 0, 0), |a, r| {
            (a.0.min(r.0), a.1.max(r.1), a.2 + r.2, a.3 + r.3)
        });
    (n > 0).then(|| KExcursion {
        min: lo,
        max: hi,
        clamped_fraction: out as f64 / n as f64,
        evaluations: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ptm_fit::{Basis, Ptm};

    #[test]
    fn twin_k_equals_the_fit_crates_eval_dir_for_every_link_and_map() {
        // The runtime and ptm-fit must agree on what a file means (ptm_hemispherical uses
        // atan2 where UvMap::of_dir does too, in f64).
        for basis in [Basis::Ptm6, Basis::Ptm11] {
            let n = basis.len();
            let planes: Vec<Vec<f32>> = (0..n).map(|k| vec![0.9 - 0.37 * k as f32]).collect();
            for link in Link::ALL {
                for uv in UvMap::ALL {
                    let mut ptm = Ptm::new(basis, 1, 1, [1.0, 1.0], planes.clone());
                    ptm.link = link;
                    ptm.uv = uv;
                    let c: Vec<f32> = planes.iter().map(|p| p[0]).collect();
                    for i in 0..200 {
                        // Elevations from the zenith down to 0.5° above the horizon.
                        let el = (90.0 - 89.5 * i as f64 / 199.0).to_radians();
                        let az = 2.399 * i as f64;
                        let l = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                        let want = ptm.eval_dir(0, 0, l);
                        let lf = l.map(|x| x as f32);
                        let got = ptm_k_unclamped(basis, link, uv, &c, lf).clamp(0.0, 1.0);
                        assert!(
                            (got - want).abs() < 2e-5,
                            "{} {link:?} {uv:?} elevation {:.2}°: twin {got} vs eval_dir {want}",
                            basis.name(),
                            el.to_degrees()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn sigmoid_is_finite_and_saturates_for_large_arguments() {
        assert_eq!(ptm_sigmoid(1e30), 1.0);
        assert_eq!(ptm_sigmoid(-1e30), 0.0);
        assert_eq!(ptm_sigmoid(0.0), 0.5);
        for p in [-30.0f32, -3.0, -0.1, 0.1, 3.0, 30.0] {
            assert!((ptm_sigmoid(p) - ptm_fit::basis::sigmoid(p)).abs() < 1e-7);
        }
    }

    #[test]
    fn a_level_that_tiles_exactly_is_looked_up_as_tile_bilinear_bit_for_bit() {
        let mut f: Frame = bytemuck::Zeroable::zeroed();
        f.screen = [64.0, 64.0, 1.3, 0.7];
        let lv = PtmLevel::exact(0, 5, 3);
        for i in 0..997 {
            let p = [-2.0 + 0.0113 * i as f32, 1.5 - 0.0071 * i as f32];
            assert_eq!(
                level_bilinear(&f, p, &lv),
                tile_bilinear(&f, p, [5, 3]),
                "at {p:?}"
            );
        }
    }

    #[test]
    fn a_rounded_down_level_puts_texels_on_their_footprints_and_bridges_the_gap() {
        // 13 level-0 texels → 6 at level 1: texel i covers level-0 texels 2i, 2i + 1, centred at
        // (2i + 1)/13 of the tile; the tile spans 6.5 level texels, the gap from texel 5 to the
        // next tile's texel 0 is 1.5 of them.
        let (n, period) = (6, 6.5);
        for i in 0..6 {
            let c = (2 * i + 1) as f32 / 13.0 * period - 0.5;
            let (x0, _, a) = level_axis(c, n, period);
            assert!(x0 == i && a.abs() < 1e-6, "texel {i}: {x0} {a}");
        }
        // The gap runs from texel 5's centre (level-0 position 11) to the next tile's texel 0
        // (13 + 1): at 12.5 halfway, at 13.5 (0.5 into the next tile) 5/6 of the way.
        for (x, want) in [(12.5f32, 0.5f32), (0.5, 2.5 / 3.0)] {
            let (x0, x1, a) = level_axis(x / 13.0 * period - 0.5, n, period);
            assert_eq!((x0, x1), (5, 0));
            assert!((a - want).abs() < 1e-6, "at {x}: {a} vs {want}");
        }
        // One texel: itself everywhere.
        for c in [-0.5, 0.0, 0.3] {
            assert_eq!(level_axis(c, 1, 1.0).0, 0);
            assert_eq!(level_axis(c, 1, 1.0).1, 0);
        }
    }
}
