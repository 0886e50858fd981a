//! Twin of `shader/shade.wgsl`: every WGSL function under its name, same maths, same f32
//! arithmetic, reading the same [`SceneBuffers`] buffers (functions that read only the uniform
//! block take it as `f`; those that read storage buffers are methods of [`Twin`]). Tests
//! compare the GPU image with it (≤ 1e-3 linear radiance); `cpu::TWINS` lists the pairs.

use ptm_format::{Link, UvMap};

use std::any::Any;

use crate::blur::{Bound, Kernel, Method};
use crate::layout::{Frame, LightGpu, PlaneGpu, PtmLevel};
use crate::scene::SceneBuffers;

/// The least half-side of a rectangular light's box kernel, in texels (`RECT_MIN` in WGSL): a
/// thin light's kernel is a line, which sees the texel it crosses.
pub const RECT_MIN: f32 = 1.0 / 256.0;

/// What replaces the blur method's caster opacity for (cloth point, light): the Monte Carlo
/// reference ([`crate::reference`]) plugs in here.
pub type OpacityFn<'a> = dyn Fn([f32; 2], &LightGpu) -> [f32; 3] + Sync + 'a;

/// The full-screen triangle's clip-space vertex `i`: (−1, −1), (3, −1), (−1, 3).
pub fn vs_main(i: u32) -> [f32; 4] {
    let x = ((i & 1) as i32 * 4 - 1) as f32;
    let y = ((i >> 1) as i32 * 4 - 1) as f32;
    [x, y, 0.0, 1.0]
}

/// Perspective ray direction through pixel `frag` (forward component 1).
pub fn view_dir(f: &Frame, frag: [f32; 2]) -> [f32; 3] {
    let t = [frag[0] / f.screen[0], frag[1] / f.screen[1]];
    std::array::from_fn(|k| {
        f.cam_forward[k] + (2.0 * t[0] - 1.0) * f.cam_right[k] + (1.0 - 2.0 * t[1]) * f.cam_up[k]
    })
}

/// Cloth point seen through a pixel centre (`frag` = pixel index + 0.5), `None` when a
/// perspective ray misses the plane z = 0 (the WGSL returns z = 0 for that).
pub fn pixel_world(f: &Frame, frag: [f32; 2]) -> Option<[f32; 2]> {
    let t = [frag[0] / f.screen[0], frag[1] / f.screen[1]];
    if f.perspective == 0 {
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

/// Texel indices (x0y0, x1y0, x0y1, x1y1) and bilinear weights of a texture of `n` texels tiled
/// with period `f.tile`.
pub fn tile_bilinear(f: &Frame, p: [f32; 2], n: [u32; 2]) -> ([usize; 4], [f32; 4]) {
    let s = [p[0] / f.tile[0], p[1] / f.tile[1]];
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

/// log2 of the PTM texels under pixel `frag`, clamped to the chain; 0 without a chain.
pub fn ptm_lod(f: &Frame, frag: [f32; 2]) -> f32 {
    let levels = f.ptm_level_count as f32;
    if levels < 2.0 {
        return 0.0;
    }
    let mut texels = f.ptm_texels_per_pixel;
    if f.perspective != 0 {
        let dir = view_dir(f, frag);
        let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        texels = texels * f.eye[2] * len / (dir[2] * dir[2]);
    }
    texels.max(1.0).log2().clamp(0.0, levels - 1.0)
}

/// One axis of [`level_bilinear`]: texel indices (x0, x1) and the weight of x1 (the gap between
/// the last texel and the next tile's first spans period − n + 1).
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

/// Texel indices and bilinear weights in a MIP level (indices relative to the level's first
/// texel).
pub fn level_bilinear(f: &Frame, p: [f32; 2], lv: &PtmLevel) -> ([usize; 4], [f32; 4]) {
    let s = [p[0] / f.tile[0], p[1] / f.tile[1]];
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

/// Hemispherical (u, v) of the unit light direction l (l.z > 0): l.xy · θ/((π/2)·r),
/// θ = atan2(r, l.z), r = |l.xy|.
pub fn ptm_hemispherical(l: [f32; 3]) -> [f32; 2] {
    let r = (l[0] * l[0] + l[1] * l[1]).sqrt();
    let s = if r > 1e-6 { r.atan2(l[2]) / r } else { 1.0 };
    let s = s / std::f32::consts::FRAC_PI_2;
    [l[0] * s, l[1] * s]
}

/// σ(p) from e^−|p| (no overflow).
pub fn ptm_sigmoid(p: f32) -> f32 {
    let e = (-p.abs()).exp();
    if p >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    }
}

/// The four table nodes (x0y0, x1y0, x0y1, x1y1) of the cell holding hemispherical `uv` on a
/// `grid` × `grid` table and their bilinear weights: `ptm_format::learned::bilinear` in f32
/// ((u, v) clamped to [−1, 1]², grid coordinates clamped to [0, G − 1], the cell's lower node at
/// most G − 2, so u = 1 reads node G − 1 with weight 1).
pub fn learned_bilinear(grid: u32, uv: [f32; 2]) -> ([usize; 4], [f32; 4]) {
    let s = (grid - 1) as f32;
    let x = uv.map(|u| ((u.clamp(-1.0, 1.0) + 1.0) * 0.5 * s).clamp(0.0, s));
    let i0 = x.map(|x| (x.floor() as u32).min(grid - 2));
    let a = [x[0] - i0[0] as f32, x[1] - i0[1] as f32];
    let (c, g) = ((i0[1] * grid + i0[0]) as usize, grid as usize);
    (
        [c, c + 1, c + g, c + g + 1],
        [
            (1.0 - a[0]) * (1.0 - a[1]),
            a[0] * (1.0 - a[1]),
            (1.0 - a[0]) * a[1],
            a[0] * a[1],
        ],
    )
}

/// The predictor's value, gradient (∂/∂u, ∂/∂v) and Hessian (uu, uv, vv) at one (u, v)
/// (`PtmJet` in WGSL).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PtmJet {
    /// p.
    pub p: f32,
    /// ∂p/∂u, ∂p/∂v.
    pub g: [f32; 2],
    /// ∂²p/∂u², ∂²p/∂u∂v, ∂²p/∂v².
    pub h: [f32; 3],
}

/// Where a light's directions fall in the PTM's (u, v), irradiance-weighted: their mean and
/// covariance (uu, uv, vv), zero for a point light (`Footprint` in WGSL).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    /// Weighted mean (u, v).
    pub centre: [f32; 2],
    /// Covariance uu, uv, vv.
    pub cov: [f32; 3],
}

/// Irradiance-weighted moments of a spherical light's cap of angular radius `rho` seen at θ
/// from the zenith (r = sin θ, z = cos θ): mean and variance of the radial angle, variance of
/// the tangential one (radians); the disc |t| ≤ rho under the weight z − r·t_radial, clipped
/// where it reaches 0 (see `cap_moments` in WGSL).
pub fn cap_moments(rho: f32, r: f32, z: f32) -> [f32; 3] {
    let q = rho * r / z;
    let mut e = [-0.25 * q, 0.25, 0.25];
    if q > 1.0 {
        let h = 1.0 / q;
        let s = (1.0 - h * h).max(0.0).sqrt();
        let a = h.asin();
        let s3 = s * s * s;
        let i0 = 0.5 * (h * s + a) + std::f32::consts::FRAC_PI_4;
        let i1 = -s3 / 3.0;
        let i2 = (a - h * s * (1.0 - 2.0 * h * h)) / 8.0 + std::f32::consts::PI / 16.0;
        let i3 = -s3 / 3.0 + s3 * s * s / 5.0;
        let w = h * i0 - i1;
        e = [
            (h * i1 - i2) / w,
            (h * i2 - i3) / w,
            (h * (i0 - i2) - (i1 - i3)) / (3.0 * w),
        ];
    }
    [
        rho * e[0],
        rho * rho * (e[1] - e[0] * e[0]).max(0.0),
        rho * rho * e[2],
    ]
}

/// WGSL's `mix(a, b, t)`.
fn mix(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// Continuous caster texel coordinates (column, row from the far edge) of a caster-plane point.
pub fn caster_texel_coords(f: &Frame, plane: &PlaneGpu, q: [f32; 2]) -> [f32; 2] {
    let r = f.caster_rect;
    let size = [plane.size[0] as f32, plane.size[1] as f32];
    [
        (q[0] - r[0]) / (r[2] - r[0]) * size[0],
        (r[3] - q[1]) / (r[3] - r[1]) * size[1],
    ]
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

/// The shader's storage buffers: the prepared scene and what the GPU builds from it.
pub struct Twin<'a> {
    /// The prepared scene (`Frame`, lights, PTM, the blur's image).
    pub p: &'a SceneBuffers,
    /// With a caster: the blur method and what its passes built ([`crate::blur::Method`]).
    pub blur: Option<(&'static dyn Method, &'a (dyn Any + Send + Sync))>,
    /// Replaces the blur method's estimate when set (the Monte Carlo reference).
    pub opacity: Option<&'a OpacityFn<'a>>,
}

impl Twin<'_> {
    fn f(&self) -> &Frame {
        &self.p.frame
    }

    /// Bilinearly filtered coefficients of MIP level `level` at p.
    pub fn ptm_level(&self, p: [f32; 2], level: usize) -> [f32; 16] {
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        let lv = &self.p.ptm_levels[level];
        let (mut idx, w) = level_bilinear(self.f(), p, lv);
        idx = idx.map(|i| i + lv.offset as usize);
        bilerp::<16>(&self.p.coeffs, n, &(idx, w))
    }

    /// PTM coefficients at p: bilinear, or trilinear in the MIP chain at level of detail `lod`.
    pub fn ptm_coeffs(&self, p: [f32; 2], lod: f32) -> [f32; 16] {
        let f = self.f();
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        if !self.p.variant.ptm_mip {
            let taps = tile_bilinear(f, p, f.ptm_size);
            return bilerp::<16>(&self.p.coeffs, n, &taps);
        }
        let l0 = lod.floor();
        let fr = lod - l0;
        let mut c = self.ptm_level(p, l0 as usize);
        if fr > 0.0 {
            let c1 = self.ptm_level(p, l0 as usize + 1);
            for k in 0..n {
                c[k] += fr * (c1[k] - c[k]);
            }
        }
        c
    }

    /// Terms 4q … 4q + 3 of grid node `node` of the learned table (`learned_node` in WGSL:
    /// one texel of the table's texture, the node-major `learned` buffer's floats
    /// `node·s + 4q …`, s = [`crate::scene::learned_stride`]).
    pub fn learned_node(&self, node: usize, q: usize) -> [f32; 4] {
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        let s = crate::scene::learned_stride(n);
        std::array::from_fn(|lane| self.p.learned[node * s + 4 * q + lane])
    }

    /// p = Σₖ cₖ·Bₖ(u, v) of a learned basis: each table read bilinearly at `uv` (the
    /// node-major `learned` buffer, [`crate::scene::learned_stride`] floats a node), dotted with
    /// the coefficients.
    pub fn learned_eval(&self, c: &[f32], uv: [f32; 2]) -> f32 {
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        let (i, w) = learned_bilinear(self.p.variant.learned_grid, uv);
        let t = &self.p.learned;
        let s = crate::scene::learned_stride(n);
        let mut p = 0f32;
        // The shader's order of operations: the padding terms it adds are c·0 = ±0, which
        // leave p as it is, so this loop stops at n.
        for k in 0..n {
            p += c[k]
                * (w[0] * t[i[0] * s + k]
                    + w[1] * t[i[1] * s + k]
                    + w[2] * t[i[2] * s + k]
                    + w[3] * t[i[3] * s + k]);
        }
        p
    }

    /// The learned predictor's jet at `uv` (`learned_jet` in WGSL): the four nodes' values of
    /// p, then p and its derivatives within the cell.
    pub fn learned_jet(&self, c: &[f32], uv: [f32; 2]) -> PtmJet {
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        let grid = self.p.variant.learned_grid;
        let (i, w) = learned_bilinear(grid, uv);
        let s = crate::scene::learned_stride(n);
        let d: [f32; 4] = std::array::from_fn(|j| {
            // dot(ck, node quad) per quad, summed: the padding adds 0.
            let mut acc = 0f32;
            for q in 0..s / 4 {
                let t = self.learned_node(i[j], q);
                let mut dq = 0f32;
                for (lane, t) in t.iter().enumerate() {
                    let k = 4 * q + lane;
                    let ck = if k < n { c[k] } else { 0.0 };
                    dq += ck * t;
                }
                acc += dq;
            }
            acc
        });
        let a = [w[1] + w[3], w[2] + w[3]];
        let sc = 0.5 * (grid - 1) as f32;
        PtmJet {
            p: w[0] * d[0] + w[1] * d[1] + w[2] * d[2] + w[3] * d[3],
            g: [
                sc * mix(d[1] - d[0], d[3] - d[2], a[1]),
                sc * mix(d[2] - d[0], d[3] - d[1], a[0]),
            ],
            h: [0.0, sc * sc * (d[0] - d[1] - d[2] + d[3]), 0.0],
        }
    }

    /// The predictor's jet at `uv`: from the monomials (the WGSL's generated expressions) or
    /// the learned table.
    pub fn ptm_jet(&self, c: &[f32], uv: [f32; 2]) -> PtmJet {
        let basis = self.p.variant.basis.expect("ptm_jet without a PTM");
        if basis.is_learned() {
            return self.learned_jet(c, uv);
        }
        let [u, v] = uv;
        // c·a!/(a−i)!·u^(a−i) · b!/(b−j)!·v^(b−j): the (i, j)-th derivative of c·u^a·v^b.
        let term = |c: f32, a: u8, b: u8, i: u8, j: u8| {
            if a < i || b < j {
                return 0.0;
            }
            let fall = |n: u8, k: u8| (0..k).map(|t| (n - t) as f32).product::<f32>();
            c * fall(a, i) * fall(b, j) * u.powi((a - i) as i32) * v.powi((b - j) as i32)
        };
        let mut jet = PtmJet::default();
        for (&ci, m) in c.iter().zip(basis.monomials()) {
            let (a, b) = (m.pu, m.pv);
            jet.p += term(ci, a, b, 0, 0);
            jet.g[0] += term(ci, a, b, 1, 0);
            jet.g[1] += term(ci, a, b, 0, 1);
            jet.h[0] += term(ci, a, b, 2, 0);
            jet.h[1] += term(ci, a, b, 1, 1);
            jet.h[2] += term(ci, a, b, 0, 2);
        }
        jet
    }

    /// The footprint of `light` seen from a cloth point in unit direction l at distance d
    /// (`ptm_footprint` in WGSL): mean and covariance of its irradiance-weighted directions in
    /// the variant's (u, v), the map's bend included to second order.
    pub fn ptm_footprint(
        &self,
        l: [f32; 3],
        to_light: [f32; 3],
        d: f32,
        light: &LightGpu,
    ) -> Footprint {
        // (`prepare` refuses a NaN radius.)
        let round = light.shape == LightGpu::SPHERE || light.shape == LightGpu::DISTANT;
        if round && light.radius <= 0.0 {
            return Footprint::default();
        }
        let r = (l[0] * l[0] + l[1] * l[1]).sqrt();
        let axis = if r > 1e-6 {
            [l[0] / r, l[1] / r]
        } else {
            [1.0, 0.0]
        };
        let (ax, ay) = (axis[0], axis[1]);
        // Mean (radial, tangential) angle and covariance (rr, rt, tt), radians.
        // A rectangle (variance half²/3 per axis) or a Gaussian (σ²), weighted by z²/r⁴.
        let planar = light.shape == LightGpu::RECT || light.shape == LightGpu::GAUSSIAN;
        let (mean, cov) = if planar {
            let h = light.half;
            let v0: [f32; 2] = if light.shape == LightGpu::GAUSSIAN {
                [h[0] * h[0], h[1] * h[1]]
            } else {
                [h[0] * h[0] / 3.0, h[1] * h[1] / 3.0]
            };
            // In the light's own frame (a turned rectangle's sides along its axes).
            let [bx, by] = light.axis;
            let tl = [
                to_light[0] * bx + to_light[1] * by,
                bx * to_light[1] - by * to_light[0],
            ];
            let shift: [f32; 2] = std::array::from_fn(|k| {
                (-4.0 * v0[k] * tl[k] / (d * d)).clamp(-0.5 * h[k], 0.5 * h[k])
            });
            let var: [f32; 2] = std::array::from_fn(|k| (v0[k] - shift[k] * shift[k]).max(0.0));
            let sc = [l[2] / d, 1.0 / d];
            // The radial axis in the light's frame.
            let (ax, ay) = (ax * bx + ay * by, bx * ay - by * ax);
            (
                [
                    sc[0] * (ax * shift[0] + ay * shift[1]),
                    sc[1] * (ax * shift[1] - ay * shift[0]),
                ],
                [
                    sc[0] * sc[0] * (ax * ax * var[0] + ay * ay * var[1]),
                    sc[0] * sc[1] * ax * ay * (var[1] - var[0]),
                    sc[1] * sc[1] * (ay * ay * var[0] + ax * ax * var[1]),
                ],
            )
        } else {
            let m = cap_moments((light.radius / d).min(1.0).asin(), r, l[2]);
            ([m[0], 0.0], [m[1], 0.0, m[2]])
        };
        let second = [cov[0] + mean[0] * mean[0], cov[2] + mean[1] * mean[1]];
        let half_pi = std::f32::consts::FRAC_PI_2;
        let (centre, jac, bend) = match self.p.variant.uv {
            UvMap::Hemispherical => {
                let s = if r > 1e-6 { r.atan2(l[2]) / r } else { 1.0 };
                let bend = if r > 1e-4 {
                    (s - l[2]) / (2.0 * r)
                } else {
                    0.0
                };
                (
                    [l[0] * (s / half_pi), l[1] * (s / half_pi)],
                    [1.0 / half_pi, s / half_pi],
                    bend * second[1] / half_pi,
                )
            }
            UvMap::Projected => ([l[0], l[1]], [l[2], 1.0], 0.5 * r * (second[0] + second[1])),
        };
        let m = [jac[0] * mean[0] - bend, jac[1] * mean[1]];
        let c = [
            jac[0] * jac[0] * cov[0],
            jac[0] * jac[1] * cov[1],
            jac[1] * jac[1] * cov[2],
        ];
        let ab = ax * ay;
        Footprint {
            centre: [
                centre[0] + m[0] * ax - m[1] * ay,
                centre[1] + m[0] * ay + m[1] * ax,
            ],
            cov: [
                c[0] * ax * ax - 2.0 * c[1] * ab + c[2] * ay * ay,
                (c[0] - c[2]) * ab + c[1] * (ax * ax - ay * ay),
                c[0] * ay * ay + 2.0 * c[1] * ab + c[2] * ax * ax,
            ],
        }
    }

    /// K averaged over the footprint `f` of a light in direction l (`ptm_k_area` in WGSL):
    /// `ptm_k` for a point light; else, from the predictor's jet at the footprint's mean, its
    /// mean m = p + ½·tr(H·C) and variance v = gᵀ·C·g, σ(m/√(1 + π·v/8)) (logistic) or m
    /// (identity).
    pub fn ptm_k_area(&self, c: &[f32], l: [f32; 3], f: &Footprint) -> f32 {
        let cv = f.cov;
        // Not above 0, NaN included (as WGSL's `!(x > 0.0)`).
        if (cv[0] + cv[2]).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return self.ptm_k(c, l);
        }
        let j = self.ptm_jet(c, f.centre);
        let m = j.p + 0.5 * (j.h[0] * cv[0] + 2.0 * j.h[1] * cv[1] + j.h[2] * cv[2]);
        let k = match self.p.variant.link {
            Link::Logistic => {
                let v = (j.g[0] * j.g[0] * cv[0]
                    + 2.0 * j.g[0] * j.g[1] * cv[1]
                    + j.g[1] * j.g[1] * cv[2])
                    .max(0.0);
                ptm_sigmoid(m / (1.0 + std::f32::consts::FRAC_PI_8 * v).sqrt())
            }
            Link::Identity => m,
        };
        k.clamp(0.0, 1.0)
    }

    /// K under distant light `li` (`distant_k` in WGSL): its mean p̄ = c·m and gradient
    /// g = (c·g_u, c·g_v) from the terms evaluated once per frame ([`distant_terms`]), then as
    /// [`Twin::ptm_k_area`]: σ(p̄/√(1 + π·v/8)) with v = gᵀ·C·g (logistic) or p̄, clamped.
    pub fn distant_k(&self, c: &[f32], li: usize) -> f32 {
        let n = self.p.variant.basis.map_or(0, |b| b.len());
        let quads = n.div_ceil(4);
        let t = &light_terms(self.p)[li * crate::scene::light_term_stride(n)..];
        let cov = t[0];
        let dot4 = |a: [f32; 4], b: [f32; 4]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
        let (mut m, mut g) = (0f32, [0f32; 2]);
        for q in 0..quads {
            let ck: [f32; 4] = std::array::from_fn(|lane| {
                let k = 4 * q + lane;
                if k < n {
                    c[k]
                } else {
                    0.0
                }
            });
            m += dot4(ck, t[1 + q]);
            g[0] += dot4(ck, t[1 + quads + q]);
            g[1] += dot4(ck, t[1 + 2 * quads + q]);
        }
        let k = match self.p.variant.link {
            Link::Logistic => {
                let v = (g[0] * g[0] * cov[0] + 2.0 * g[0] * g[1] * cov[1] + g[1] * g[1] * cov[2])
                    .max(0.0);
                ptm_sigmoid(m / (1.0 + std::f32::consts::FRAC_PI_8 * v).sqrt())
            }
            Link::Identity => m,
        };
        k.clamp(0.0, 1.0)
    }

    /// The variant's (u, v) of unit direction l.
    pub fn ptm_uv(&self, l: [f32; 3]) -> [f32; 2] {
        match self.p.variant.uv {
            UvMap::Projected => [l[0], l[1]],
            UvMap::Hemispherical => ptm_hemispherical(l),
        }
    }

    /// K of the variant's link, (u, v) map and basis (the monomials, or the learned tables)
    /// before the clamp, for the unit light direction l: what `ptm_k` clamps.
    pub fn ptm_k_unclamped(&self, c: &[f32], l: [f32; 3]) -> f32 {
        let v = &self.p.variant;
        let basis = v.basis.expect("ptm_k without a PTM");
        let uv = self.ptm_uv(l);
        let p = if basis.is_learned() {
            self.learned_eval(c, uv)
        } else {
            basis.eval(&c[..basis.len()], uv[0], uv[1])
        };
        match v.link {
            Link::Identity => p,
            Link::Logistic => ptm_sigmoid(p),
        }
    }

    /// K of the variant's link, (u, v) map and basis for the unit light direction l, clamped
    /// to [0, 1].
    pub fn ptm_k(&self, c: &[f32], l: [f32; 3]) -> f32 {
        self.ptm_k_unclamped(c, l).clamp(0.0, 1.0)
    }

    /// Bilinearly filtered coverage of MIP level `level` at p.
    pub fn coverage_level(&self, p: [f32; 2], level: usize) -> f32 {
        let lv = &self.p.ptm_levels[level];
        let (idx, w) = level_bilinear(self.f(), p, lv);
        let c = |k: usize| self.p.coverage[idx[k] + lv.offset as usize];
        w[0] * c(0) + w[1] * c(1) + w[2] * c(2) + w[3] * c(3)
    }

    /// Coverage at p (0 in a hole), filtered as the coefficients are.
    pub fn ptm_coverage(&self, p: [f32; 2], lod: f32) -> f32 {
        let f = self.f();
        if !self.p.variant.ptm_mip {
            let (idx, w) = tile_bilinear(f, p, f.ptm_size);
            let c = |k: usize| self.p.coverage[idx[k]];
            return w[0] * c(0) + w[1] * c(1) + w[2] * c(2) + w[3] * c(3);
        }
        let l0 = lod.floor();
        let fr = lod - l0;
        let mut c = self.coverage_level(p, l0 as usize);
        if fr > 0.0 {
            c += fr * (self.coverage_level(p, l0 as usize + 1) - c);
        }
        c
    }

    /// `albedo_at` of `shade.wgsl`: linear rgb albedo at world point `p`, the texture tiled or the constant.
    pub fn albedo_at(&self, p: [f32; 2]) -> [f32; 3] {
        let f = self.f();
        if !self.p.variant.albedo_texture {
            return f.albedo;
        }
        let taps = tile_bilinear(f, p, f.albedo_size);
        let flat: &[f32] = bytemuck::cast_slice(&self.p.albedo);
        let a = bilerp::<4>(flat, 4, &taps);
        [a[0], a[1], a[2]]
    }

    /// Mean caster opacity seen from p towards light l (see `light_opacity` in WGSL): the
    /// reference's where the twin has one, else [`Twin::light_blur`]'s opacity (its fourth
    /// channel, α, in a glossy scene's premultiplied image).
    pub fn light_opacity(&self, p: [f32; 2], l: &LightGpu, li: usize) -> [f32; 3] {
        if let Some(reference) = self.opacity {
            return reference(p, l);
        }
        let o = self.light_blur(p, l, li);
        if self.p.variant.glossy {
            [o[3]; 3]
        } else {
            [o[0], o[1], o[2]]
        }
    }

    /// Mean caster image seen from p towards light l by the blur method (never the
    /// reference's): where the segment p → light meets the (tilted) caster plane, blurred with
    /// radius R·s there (see `light_blur` in WGSL).
    pub fn light_blur(&self, p: [f32; 2], l: &LightGpu, li: usize) -> [f32; 4] {
        let f = self.f();
        let r = f.caster_rect;
        let (sin_t, cos_t) = (f.caster_sin_tilt, f.caster_cos_tilt);
        let centre = [0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3]), f.caster_height];
        let n = [0.0, -sin_t, cos_t];
        let e2 = [0.0, cos_t, sin_t];
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let pp = [p[0], p[1], 0.0];
        // To the light's centre, or a distant light's unit direction (s is then a distance).
        let ray = l.to_light(p);
        let distant = l.shape == LightGpu::DISTANT;
        let denom = dot(n, ray);
        if denom == 0.0 {
            return [0.0; 4];
        }
        let s = dot(n, [centre[0] - pp[0], centre[1] - pp[1], centre[2]]) / denom;
        let beyond = if distant { 3.4e38 } else { 1.0 };
        if !(s >= 0.0 && s < beyond) {
            return [0.0; 4];
        }
        let off: [f32; 3] = std::array::from_fn(|k| pp[k] + s * ray[k] - centre[k]);
        let q = [centre[0] + off[0], centre[1] + dot(off, e2)];
        let stretch = (cos_t + dot(ray, e2) * sin_t / denom).abs();
        let size = self.p.plane_gpu.size;
        let texel = [
            (r[2] - r[0]) / size[0] as f32,
            (r[3] - r[1]) / size[1] as f32,
        ];
        let t = caster_texel_coords(f, &self.p.plane_gpu, q);
        // A planar light facing down, of half-sides or σ `half`: itself scaled by s, moved to
        // the centroid of its z²/r⁴ weights, −k·var·d/r² with var = half²/3 for a rectangle's
        // box and σ² for a Gaussian (see `light_blur` in WGSL).
        let planar = |k: f32, kernel: Kernel| {
            let h = l.half;
            let k = -k / dot(ray, ray);
            let shift = [k * h[0] * h[0] * ray[0] * s, k * h[1] * h[1] * ray[1] * s];
            let tr = [
                t[0] + shift[0] / texel[0],
                t[1] + -shift[1] * stretch / texel[1],
            ];
            let wr = [
                (h[0] * s / texel[0]).max(RECT_MIN),
                (h[1] * s * stretch / texel[1]).max(RECT_MIN),
            ];
            (tr, wr, 0.0, kernel)
        };
        let (method, built) = self.blur.expect("light_blur without a blur method");
        let bound = Bound {
            plane: &self.p.plane,
            uniform: &self.p.plane_gpu,
            prepared: self.p.prepared.as_ref(),
            built,
        };
        let (t, wt, shear, kernel) = if l.shape == LightGpu::RECT {
            // Turned by θ (axis = (cos θ, sin θ)): the shift in the light's own frame, turned
            // back (as `light_blur` in WGSL; for θ = 0 the same numbers as `planar`).
            let [ax, ay] = l.axis;
            let dl = [ray[0] * ax + ray[1] * ay, ax * ray[1] - ay * ray[0]];
            let k = -4.0 / (3.0 * dot(ray, ray));
            let sl = [
                k * l.half[0] * l.half[0] * dl[0] * s,
                k * l.half[1] * l.half[1] * dl[1] * s,
            ];
            let shift = [sl[0] * ax + sl[1] * -ay, sl[0] * ay + sl[1] * ax];
            let tr = [
                t[0] + shift[0] / texel[0],
                t[1] + -shift[1] * stretch / texel[1],
            ];
            if ay != 0.0 {
                let e1 = [
                    ax * (l.half[0] * s) / texel[0],
                    -ay * stretch * (l.half[0] * s) / texel[1],
                ];
                let e2 = [
                    -ay * (l.half[1] * s) / texel[0],
                    -ax * stretch * (l.half[1] * s) / texel[1],
                ];
                let lookup = |c: [f32; 2], w: [f32; 2]| {
                    method.blur_lookup(&bound, li, c, w, 0.0, Kernel::Box)
                };
                return rect_slabs(&lookup, tr, e1, e2);
            }
            let wr = [
                (l.half[0] * s / texel[0]).max(RECT_MIN),
                (l.half[1] * s * stretch / texel[1]).max(RECT_MIN),
            ];
            (tr, wr, 0.0, Kernel::Box)
        } else if l.shape == LightGpu::GAUSSIAN {
            planar(4.0, Kernel::Gauss)
        } else {
            let w = l.radius * s;
            let wt = [(w / texel[0]).max(0.5), (w * stretch / texel[1]).max(0.5)];
            match sphere_ellipse(f, ray, s, l.radius, texel, l.shape == LightGpu::LOBE) {
                Some(e)
                    if l.shape == LightGpu::SPHERE
                        || l.shape == LightGpu::LOBE
                        || l.shape == LightGpu::DISTANT =>
                {
                    (
                        [t[0] + e.centre[0], t[1] + e.centre[1]],
                        e.radii,
                        e.shear,
                        Kernel::Disc,
                    )
                }
                _ => (t, wt, 0.0, Kernel::Box),
            }
        };
        method.blur_lookup(&bound, li, t, wt, shear, kernel)
    }

    /// Linear radiance leaving acceptor point p:
    /// Σ albedo · I · colour · max(0, n·l)/d² · (1 − opacity) · (1 − K).
    pub fn shade(&self, p: [f32; 2], lod: f32) -> [f32; 3] {
        let albedo = self.albedo_at(p);
        let c = self.p.variant.basis.map(|_| self.ptm_coeffs(p, lod));
        let mut radiance = [0f32; 3];
        for (li, light) in self.p.lights[..self.f().light_count as usize]
            .iter()
            .enumerate()
        {
            let to_light = light.to_light(p);
            // A distant light's d² is 1 exactly, as in WGSL (its normalised direction's |·|²
            // is 1 only to a few ulp).
            let d2 = if light.shape == LightGpu::DISTANT {
                1.0
            } else {
                to_light[0] * to_light[0] + to_light[1] * to_light[1] + to_light[2] * to_light[2]
            };
            if d2 <= 0.0 || to_light[2] <= 0.0 {
                continue;
            }
            let d = d2.sqrt();
            let l = to_light.map(|x| x / d);
            let mut visible = [1f32; 3];
            if let Some(c) = &c {
                let k = if light.shape == LightGpu::DISTANT {
                    self.distant_k(c, li)
                } else {
                    self.ptm_k_area(c, l, &self.ptm_footprint(l, to_light, d, light))
                };
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
        if self.p.variant.basis.is_some() && self.p.variant.coverage {
            // A hole shows nothing; partly covered texels blend.
            let c = self.ptm_coverage(p, lod);
            radiance = radiance.map(|r| r * c);
        }
        radiance
    }

    /// `glossy_reflection` of `shade.wgsl`: the radiance a glossy receiver reflects at p seen
    /// along the unit view direction `dir`: the caster blurred through the imaginary light on
    /// the mirror ray (derivation in the WGSL): mean(α·rgb) + (1 − mean α)·background.
    pub fn glossy_reflection(&self, p: [f32; 2], dir: [f32; 3]) -> [f32; 3] {
        let f = self.f();
        let r = [dir[0], dir[1], -dir[2]];
        let back = self.glossy_background(r);
        let c = f.caster_rect;
        let centre = [0.5 * (c[0] + c[2]), 0.5 * (c[1] + c[3]), f.caster_height];
        let n = [0.0, -f.caster_sin_tilt, f.caster_cos_tilt];
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let pp = [p[0], p[1], 0.0];
        let denom = dot(n, r);
        // Written as `!(x > 0)` in WGSL: NaN also reflects the background.
        if denom.is_nan() || denom <= 0.0 {
            return back;
        }
        let h = dot(n, [centre[0] - pp[0], centre[1] - pp[1], centre[2]]) / denom;
        if h.is_nan() || h <= 0.0 {
            return back;
        }
        let mut l = LightGpu {
            position: std::array::from_fn(|k| pp[k] + 2.0 * h * r[k]),
            radius: 0.0, // per cone below
            color: [0.0; 3],
            shape: LightGpu::LOBE,
            half: [0.0; 2],
            axis: [1.0, 0.0],
        };
        // The lobe as nested cones, each ring between them of its exact solid angle.
        let rings = self.glossy_ring_weights(denom);
        let mut o = [0.0f32; 4];
        for (j, &w) in rings.iter().enumerate().take(f.glossy_rings as usize) {
            if w > 0.0 {
                let a = f.glossy_alpha * (j + 1) as f32 / f.glossy_rings as f32;
                l.radius = 2.0 * h * a.sin();
                let b = self.light_blur(p, &l, 0);
                for k in 0..4 {
                    o[k] += w * b[k].max(0.0);
                }
            }
        }
        std::array::from_fn(|k| o[k] + back[k] * (1.0 - o[3].min(1.0)))
    }

    /// `glossy_ring_weights` of `shade.wgsl`: the nested cones' weights, each ring between two
    /// of them its exact share of the lobe's solid angle (derivation in the WGSL); (1, 0, 0, 0)
    /// for one cone or where the widest does not close on the plane (cos β = `cos_b`).
    pub fn glossy_ring_weights(&self, cos_b: f32) -> [f32; 4] {
        let f = self.f();
        let mut c = [1.0, 0.0, 0.0, 0.0];
        let n = f.glossy_rings as usize;
        if n <= 1 {
            return c;
        }
        let (mut area, mut omega) = ([0.0f32; 5], [0.0f32; 5]);
        for j in 1..=n {
            let a = f.glossy_alpha * j as f32 / n as f32;
            let s = a.sin();
            let q = cos_b * cos_b - s * s;
            if q.is_nan() || q <= 0.0 {
                return c;
            }
            area[j] = s * s * a.cos() / (q * q.sqrt());
            let half = (0.5 * a).sin();
            omega[j] = 2.0 * half * half;
        }
        let mut d = [0.0f32; 5];
        for i in 1..=n {
            d[i - 1] = (omega[i] - omega[i - 1]) / (omega[n] * (area[i] - area[i - 1]));
        }
        let mut total = 0.0;
        for j in 0..n {
            let next = if j + 1 < n { d[j + 1] } else { 0.0 };
            c[j] = (area[j + 1] * (d[j] - next)).max(0.0);
            total += c[j];
        }
        if total.is_nan() || total <= 0.0 {
            return [1.0, 0.0, 0.0, 0.0];
        }
        for cj in c.iter_mut().take(n) {
            *cj /= total;
        }
        c
    }

    /// The background a glossy receiver reflects along the mirror direction r: the colour, or
    /// the background image averaged over the lobe (prefiltered, [`env_lookup`]).
    pub fn glossy_background(&self, r: [f32; 3]) -> [f32; 3] {
        let f = self.f();
        if self.p.variant.env_size == 0 {
            return f.glossy_background;
        }
        env_lookup(self.p.variant.env_size as usize, &self.p.environment, r)
    }

    /// `glossy_fresnel` of `shade.wgsl`: Schlick's Fresnel at the view direction's angle to +Z.
    pub fn glossy_fresnel(&self, dir: [f32; 3]) -> f32 {
        let f0 = self.f().glossy_f0;
        let m = 1.0 - (-dir[2]).clamp(0.0, 1.0);
        f0 + (1.0 - f0) * m * m * m * m * m
    }

    /// The unit view direction through `frag` (straight down for the orthographic camera).
    pub fn view_direction(&self, frag: [f32; 2]) -> [f32; 3] {
        let f = self.f();
        if f.perspective == 0 {
            return [0.0, 0.0, -1.0];
        }
        let d = view_dir(f, frag);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / len)
    }

    /// The pixel at `frag` (pixel index + 0.5): black where a perspective ray misses the cloth.
    pub fn fs_main(&self, frag: [f32; 2]) -> [f32; 4] {
        let f = self.f();
        let Some(p) = pixel_world(f, frag) else {
            return [0.0, 0.0, 0.0, 1.0];
        };
        let r = self.shade(p, ptm_lod(f, frag));
        if self.p.variant.glossy && self.p.variant.caster.is_some() {
            let dir = self.view_direction(frag);
            let fresnel = self.glossy_fresnel(dir);
            let g = self.glossy_reflection(p, dir);
            let m = |k: usize| (1.0 - fresnel) * r[k] + fresnel * g[k];
            return [m(0), m(1), m(2), 1.0];
        }
        [r[0], r[1], r[2], 1.0]
    }
}

/// `rect_chord` of `shade.wgsl`: a parallelogram's horizontal chord at height y, (length,
/// midpoint x).
pub fn rect_chord(y: f32, top: f32, inner: f32, len: f32, slope: f32, apex_x: f32) -> [f32; 2] {
    let ay = y.abs();
    if ay <= inner {
        return [len, y * slope];
    }
    let f = (ay - inner) / (top - inner);
    let sg = if y > 0.0 { 1.0 } else { -1.0 };
    let (a, b) = (sg * inner * slope, sg * apex_x);
    [len * (1.0 - f), a * (1.0 - f) + b * f]
}

/// `RECT_TRI` of `shade.wgsl`: bands across each corner triangle of a turned rectangle.
const RECT_TRI: u32 = 3;
/// `RECT_MID_MAX` of `shade.wgsl`: most bands across its middle.
const RECT_MID_MAX: u32 = 16;

/// `rect_slabs` of `shade.wgsl`: a turned rectangle light's parallelogram kernel (centre t,
/// half-edges e1, e2 in texels) as boxes of exact band areas, each looked up by `lookup`
/// (centre, half-sides) with the scene's method.
pub fn rect_slabs(
    lookup: &dyn Fn([f32; 2], [f32; 2]) -> [f32; 4],
    t: [f32; 2],
    e1: [f32; 2],
    e2: [f32; 2],
) -> [f32; 4] {
    let (y1, y2) = (e1[1].abs(), e2[1].abs());
    let top = y1 + y2;
    let inner = (y1 - y2).abs();
    let area = 4.0 * (e1[0] * e2[1] - e1[1] * e2[0]).abs();
    if !(top > RECT_MIN && area > 0.0) {
        let w = [e1[0].abs() + e2[0].abs(), top];
        return lookup(t, w.map(|x| x.max(RECT_MIN)));
    }
    let ea = if y1 >= y2 { e1 } else { e2 };
    let slope = ea[0] / ea[1];
    let len = area / (top + inner);
    let sgn = |y: f32| if y >= 0.0 { 1.0 } else { -1.0 };
    let apex_x = sgn(e1[1]) * e1[0] + sgn(e2[1]) * e2[0];
    let shear = 2.0 * inner * slope.abs() / (0.5 * len);
    let n_mid = shear.ceil().clamp(1.0, RECT_MID_MAX as f32) as u32;
    let tri = (top - inner) / RECT_TRI as f32;
    let mid = 2.0 * inner / n_mid as f32;
    let mut sum = [0.0f32; 4];
    let mut total = 0.0;
    for k in 0..2 * RECT_TRI + n_mid {
        let (y0, h) = if k >= RECT_TRI + n_mid {
            (inner + (k - RECT_TRI - n_mid) as f32 * tri, tri)
        } else if k >= RECT_TRI {
            (-inner + (k - RECT_TRI) as f32 * mid, mid)
        } else {
            (-top + k as f32 * tri, tri)
        };
        if h.is_nan() || h <= 0.0 {
            continue;
        }
        let chord = |y: f32| rect_chord(y, top, inner, len, slope, apex_x);
        let (c0, cm, c1) = (chord(y0), chord(y0 + 0.5 * h), chord(y0 + h));
        let w = h / 6.0 * (c0[0] + 4.0 * cm[0] + c1[0]);
        if w.is_nan() || w <= 0.0 {
            continue;
        }
        let cx = h / 6.0 * (c0[0] * c0[1] + 4.0 * cm[0] * cm[1] + c1[0] * c1[1]) / w;
        let half = [(0.5 * w / h).max(RECT_MIN), (0.5 * h).max(RECT_MIN)];
        let o = lookup([t[0] + cx, t[1] + (y0 + 0.5 * h)], half);
        for c in 0..4 {
            sum[c] += w * o[c];
        }
        total += w;
    }
    sum.map(|x| x / total)
}

/// `Ellipse` of `shade.wgsl`: a sphere's kernel on the caster plane in caster texels (centre
/// offset from the axis's hit point, radii, shear; see [`sphere_ellipse`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipse {
    /// Offset of the ellipse's centre from where the ray to the light's centre meets the plane.
    pub centre: [f32; 2],
    /// Half-width of the chord through the centre along the rows, half-height (≥ ½ texel).
    pub radii: [f32; 2],
    /// Columns the chords' midpoints move per row down.
    pub shear: f32,
}

/// `sphere_ellipse` of `shade.wgsl`: the ellipse the cone from the shaded point to a sphere of
/// `radius` (towards `ray`, its axis meeting the caster plane at fraction s) cuts from the
/// (tilted) caster plane, in texels of size `texel`; `None` when the cone does not meet the
/// plane in a closed curve. Derivation in the WGSL.
pub fn sphere_ellipse(
    f: &Frame,
    ray: [f32; 3],
    s: f32,
    radius: f32,
    texel: [f32; 2],
    lobe: bool,
) -> Option<Ellipse> {
    let (sin_t, cos_t) = (f.caster_sin_tilt, f.caster_cos_tilt);
    let d2 = ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2];
    let d = d2.sqrt();
    let a = ray.map(|x| x / d);
    let sigma2 = radius * radius / d2;
    let ax = a[0];
    let a2 = a[1] * cos_t + a[2] * sin_t;
    let an = -a[1] * sin_t + a[2] * cos_t;
    // (Not `<=`: a NaN must return here too.)
    if (an * an).partial_cmp(&(1.0001 * sigma2)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let m00 = a[1] * a[1] + a[2] * a[2] - sigma2;
    let m01 = -ax * a2;
    let m11 = ax * ax + an * an - sigma2;
    let det = m00 * m11 - m01 * m01;
    let b = [
        sigma2 * s * ray[0],
        sigma2 * s * (ray[1] * cos_t + ray[2] * sin_t),
    ];
    let x0 = [
        (m11 * b[0] - m01 * b[1]) / det,
        (m00 * b[1] - m01 * b[0]) / det,
    ];
    let g = sigma2 * s * s * d2 + (b[0] * x0[0] + b[1] * x0[1]);
    if !(g > 0.0 && det > 0.0) {
        return None;
    }
    let radii = [
        (g / m00).sqrt() / texel[0],
        (m00 * g / det).sqrt() / texel[1],
    ];
    let shear = m01 * texel[1] / (m00 * texel[0]);
    // Moved to the centroid of the light's weight over the plane (see the WGSL).
    let e2 = [0.0, cos_t, sin_t];
    let y: [f32; 3] = std::array::from_fn(|k| s * ray[k] + x0[1] * e2[k]);
    let y = [y[0] + x0[0], y[1], y[2]];
    let yy = y[0] * y[0] + y[1] * y[1] + y[2] * y[2];
    let ye2 = y[0] * e2[0] + y[1] * e2[1] + y[2] * e2[2];
    // A glossy lobe: solid angle alone, ∇ln = −3(y·e)/|y|² (see the WGSL).
    let grad = if lobe {
        [-3.0 * y[0] / yy * texel[0], 3.0 * ye2 / yy * texel[1]]
    } else {
        [
            -4.0 * y[0] / yy * texel[0],
            -(e2[2] / y[2] - 4.0 * ye2 / yy) * texel[1],
        ]
    };
    let [rx, ry] = radii;
    let sxx = 0.25 * (rx * rx + shear * shear * ry * ry);
    let sxy = 0.25 * shear * ry * ry;
    let syy = 0.25 * ry * ry;
    let shift = [sxx * grad[0] + sxy * grad[1], sxy * grad[0] + syy * grad[1]];
    let v = shift[1] / ry;
    let u = (shift[0] - shear * shift[1]) / rx;
    let k = (0.5 / (u * u + v * v).sqrt().max(1e-20)).min(1.0);
    Some(Ellipse {
        centre: [
            x0[0] / texel[0] + k * shift[0],
            -x0[1] / texel[1] + k * shift[1],
        ],
        radii: radii.map(|r| r.max(0.5)),
        shear,
    })
}

/// `env_texel` of `shade.wgsl`: texel (x, y) of the prefiltered background map, clamped to
/// its edge ([`crate::environment::texel`]).
pub fn env_texel(n: usize, texels: &[[f32; 4]], x: i32, y: i32) -> [f32; 4] {
    crate::environment::texel(n, texels, x, y)
}

/// `env_bilinear` of `shade.wgsl` ([`crate::environment::bilinear`]).
pub fn env_bilinear(n: usize, texels: &[[f32; 4]], t: [f32; 2]) -> [f32; 4] {
    crate::environment::bilinear(n, texels, t)
}

/// `env_lookup` of `shade.wgsl`: the prefiltered background along the mirror direction r
/// ([`crate::environment::read`]).
pub fn env_lookup(n: usize, texels: &[[f32; 4]], r: [f32; 3]) -> [f32; 3] {
    let c = crate::environment::read(n, texels, r);
    [c[0], c[1], c[2]]
}

/// [`SceneBuffers::light_terms`], computed on first use ([`distant_terms`]).
pub fn light_terms(p: &SceneBuffers) -> &[[f32; 4]] {
    p.light_terms.get_or_init(|| distant_terms(p))
}

/// What a distant light's K needs at every pixel, evaluated once per frame
/// ([`SceneBuffers::light_terms`]): per light the footprint's covariance C in (u, v), then per
/// basis term k its jet at the footprint's mean (the predictor is linear in the coefficients,
/// so p̄ = Σ cₖ·(pₖ + ½·tr(Hₖ·C)) and g = Σ cₖ·gₖ): the mean weights, the gradient's u parts
/// and its v parts, each run whole vec4s. A point light's (u, v) is the map of its direction
/// and C = 0. Zeros for a light that is not distant (or below the horizon); empty without a
/// PTM or a distant light.
pub fn distant_terms(p: &SceneBuffers) -> Vec<[f32; 4]> {
    let Some(basis) = p.variant.basis else {
        return Vec::new();
    };
    if !p.lights.iter().any(|l| l.shape == LightGpu::DISTANT) {
        return Vec::new();
    }
    let n = basis.len();
    let quads = n.div_ceil(4);
    let stride = crate::scene::light_term_stride(n);
    let twin = Twin {
        p,
        blur: None,
        opacity: None,
    };
    let mut out = vec![[0f32; 4]; stride * p.lights.len()];
    for (light, block) in p.lights.iter().zip(out.chunks_exact_mut(stride)) {
        let l = light.position;
        if light.shape != LightGpu::DISTANT || l[2].is_nan() || l[2] <= 0.0 {
            continue;
        }
        let f = twin.ptm_footprint(l, l, 1.0, light);
        let (centre, cov) = if f.cov[0] + f.cov[2] > 0.0 {
            (f.centre, f.cov)
        } else {
            (twin.ptm_uv(l), [0.0; 3])
        };
        block[0] = [cov[0], cov[1], cov[2], 0.0];
        for k in 0..n {
            let mut e = [0f32; ptm_format::basis::MAX_LEARNED_TERMS];
            e[k] = 1.0;
            let j = twin.ptm_jet(&e[..n], centre);
            let (q, lane) = (k / 4, k % 4);
            block[1 + q][lane] =
                j.p + 0.5 * (j.h[0] * cov[0] + 2.0 * j.h[1] * cov[1] + j.h[2] * cov[2]);
            block[1 + quads + q][lane] = j.g[0];
            block[1 + 2 * quads + q][lane] = j.g[1];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ptm_format::{Basis, Ptm};

    /// The twin of a prepared 1×1 scene over `ptm`.
    fn twin_k(ptm: &Ptm, l: [f32; 3]) -> f32 {
        let p = crate::Scene::over_ptm(ptm.clone(), 1, [1, 1])
            .prepare()
            .unwrap();
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        twin.ptm_k(&ptm.coeffs(0, 0), l)
    }

    /// Directions from the zenith down to 0.5° above the horizon, azimuths all round.
    fn directions() -> impl Iterator<Item = [f64; 3]> {
        (0..200).map(|i| {
            let el = (90.0 - 89.5 * i as f64 / 199.0).to_radians();
            let az = 2.399 * i as f64;
            [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
        })
    }

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
                    for l in directions() {
                        let want = ptm.eval_dir(0, 0, l);
                        let got = twin_k(&ptm, l.map(|x| x as f32));
                        assert!(
                            (got - want).abs() < 2e-5,
                            "{} {link:?} {uv:?} elevation {:.2}°: twin {got} vs eval_dir {want}",
                            basis.name(),
                            l[2].asin().to_degrees()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn twin_k_of_a_learned_basis_equals_eval_dir() {
        // Tables of hashed values in [−1.5, 1.5) on grids of 2 (one cell: the clamp of the
        // lower node to G − 2 everywhere), 5 and 17 nodes; 1, 6 and 16 terms.
        for (terms, grid) in [(6, 17), (16, 5), (1, 2), (11, 17)] {
            let basis = Basis::learned(terms).unwrap();
            let unit =
                |key: u64| ptm_format::hash::unit_f64(ptm_format::hash::splitmix64(key)) as f32;
            let values = (0..terms * grid * grid)
                .map(|i| 3.0 * unit(i as u64 + 77) - 1.5)
                .collect();
            // |c| in [1, 2), alternating signs: K moves with the direction.
            let planes = (0..terms)
                .map(|k| vec![(1.0 + unit(k as u64)) * if k % 2 == 0 { 1.0 } else { -1.0 }])
                .collect();
            let mut ptm = Ptm::new(basis, 1, 1, [1.0, 1.0], planes);
            ptm.link = Link::Logistic;
            ptm.uv = UvMap::Hemispherical;
            ptm.learned = Some(ptm_format::LearnedTable {
                grid,
                terms,
                values,
            });
            ptm.validate().unwrap();
            let mut spread = (f32::INFINITY, f32::NEG_INFINITY);
            for l in directions() {
                let want = ptm.eval_dir(0, 0, l);
                let got = twin_k(&ptm, l.map(|x| x as f32));
                spread = (spread.0.min(want), spread.1.max(want));
                assert!(
                    (got - want).abs() < 2e-5,
                    "learned{terms} grid {grid} elevation {:.2}°: twin {got} vs eval_dir {want}",
                    l[2].asin().to_degrees()
                );
            }
            // The directions reach across the table: K is not one value.
            assert!(
                spread.1 - spread.0 > 0.02,
                "learned{terms}: K in {spread:?}"
            );
        }
    }

    #[test]
    fn learned_bilinear_takes_the_formats_nodes_and_weights() {
        // On and between nodes, on the edges and corners, outside the square.
        for grid in [2u32, 3, 17] {
            let s = (grid - 1) as f32;
            let mut at: Vec<[f32; 2]> = (0..=2 * (grid - 1))
                .map(|i| -1.0 + i as f32 / s)
                .flat_map(|u| [[u, -1.0], [u, 1.0], [1.0, u], [u, 0.3 * u]])
                .collect();
            at.extend([[1.5, -2.0], [-1.0, -1.0], [1.0, 1.0], [0.999_999, 0.0]]);
            for uv in at {
                // Weights per node: at a node, f32 and f64 may pick adjacent cells, with weight
                // 0 on the nodes they do not share.
                let (idx, w) = learned_bilinear(grid, uv);
                let want = ptm_format::learned::bilinear(grid as usize, uv[0] as f64, uv[1] as f64);
                let mut dense = vec![[0f64; 2]; (grid * grid) as usize];
                for t in 0..4 {
                    dense[idx[t]][0] += w[t] as f64;
                    dense[want[t].0][1] += want[t].1;
                }
                for (node, [got, want]) in dense.iter().enumerate() {
                    assert!(
                        (got - want).abs() < 1e-5,
                        "grid {grid} at {uv:?}, node {node}: weight {got} vs {want}"
                    );
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
            assert!((ptm_sigmoid(p) - ptm_format::basis::sigmoid(p)).abs() < 1e-7);
        }
    }

    #[test]
    fn a_level_that_tiles_exactly_is_looked_up_as_tile_bilinear_bit_for_bit() {
        let f = Frame {
            screen: [64.0, 64.0],
            tile: [1.3, 0.7],
            ..Frame::zeroed()
        };
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
