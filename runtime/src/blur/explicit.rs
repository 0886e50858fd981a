//! The explicit blur, the methods' reference: a regular grid of samples (spacing ≤ ½ texel,
//! ≥ 16 per axis, at most `PlaneGpu::samples`) over the ellipse of radii wt; cost grows as wt².
//! WGSL `blur/explicit.wgsl`; this module is its twin, function by function.

use std::any::Any;

use crate::bindings::shade as b;
use crate::blur::Blur;
use crate::blur::{Bound, Kernel, Method, Plane, Prepared};
use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, PlaneGpu};
use crate::Result;

/// The lookup included into the shading pass.
pub const WGSL: &str = include_str!("explicit.wgsl");

/// The explicit method.
pub struct Explicit;

/// 8-bit counts per channel of the texel of a `size` image containing texel coordinate t; 0
/// outside.
pub fn opacity_raw(opacity: &[u32], size: [u32; 2], t: [f32; 2]) -> [u32; 4] {
    let [w, h] = size;
    if t[0] < 0.0 || t[1] < 0.0 || t[0] >= w as f32 || t[1] >= h as f32 {
        return [0; 4];
    }
    let o = opacity[t[1] as usize * w as usize + t[0] as usize];
    [o & 255, (o >> 8) & 255, (o >> 16) & 255, o >> 24]
}

/// Reference blur: mean over an n×n grid of samples inside the sheared ellipse of radii wt
/// (texels) around t ([`Kernel::Disc`]), or the whole grid for [`Kernel::Box`],
/// n = clamp(⌈4·max(wt)⌉, 16, `samples`); integer sums divided once.
pub fn blur_explicit(
    plane: &Plane,
    samples: u32,
    t: [f32; 2],
    wt: [f32; 2],
    shear: f32,
    kernel: Kernel,
) -> [f32; 4] {
    let n = ((4.0 * wt[0].max(wt[1])).ceil() as u32).clamp(16, samples);
    let mut sum = [0u32; 4];
    let mut count = 0u32;
    for j in 0..n {
        for i in 0..n {
            let o = [
                (i as f32 + 0.5) / n as f32 * 2.0 - 1.0,
                (j as f32 + 0.5) / n as f32 * 2.0 - 1.0,
            ];
            if kernel == Kernel::Box || o[0] * o[0] + o[1] * o[1] <= 1.0 {
                let v = opacity_raw(
                    &plane.texels,
                    plane.size,
                    [
                        t[0] + (o[0] * wt[0] + shear * o[1] * wt[1]),
                        t[1] + o[1] * wt[1],
                    ],
                );
                for c in 0..4 {
                    sum[c] += v[c];
                }
                count += 1;
            }
        }
    }
    sum.map(|s| s as f32 / (count as f32 * 255.0))
}

/// How far the Gaussian's grid reaches, in σ (`GAUSS_REACH`).
pub const GAUSS_REACH: f32 = 3.5;

/// Reference blur of [`Kernel::Gauss`]: an n×n grid over ±[`GAUSS_REACH`]·wt around t, each
/// sample weighted by exp(−½|o|²), n = clamp(⌈4·GAUSS_REACH·max(wt)⌉, 16, `samples`).
pub fn blur_explicit_gauss(plane: &Plane, samples: u32, t: [f32; 2], wt: [f32; 2]) -> [f32; 4] {
    let n = ((4.0 * GAUSS_REACH * wt[0].max(wt[1])).ceil() as u32).clamp(16, samples);
    let mut sum = [0f32; 4];
    let mut total = 0f32;
    for j in 0..n {
        for i in 0..n {
            let o = [
                ((i as f32 + 0.5) / n as f32 * 2.0 - 1.0) * GAUSS_REACH,
                ((j as f32 + 0.5) / n as f32 * 2.0 - 1.0) * GAUSS_REACH,
            ];
            let w = (-0.5 * (o[0] * o[0] + o[1] * o[1])).exp();
            let v = opacity_raw(
                &plane.texels,
                plane.size,
                [t[0] + o[0] * wt[0], t[1] + o[1] * wt[1]],
            );
            for c in 0..4 {
                sum[c] += w * v[c] as f32;
            }
            total += w;
        }
    }
    sum.map(|s| s / (total * 255.0))
}

impl Method for Explicit {
    fn blur(&self) -> Blur {
        Blur::Explicit
    }

    fn kernels(&self) -> &'static [Kernel] {
        &[Kernel::Disc, Kernel::Box, Kernel::Gauss]
    }

    fn wgsl(&self) -> &'static str {
        WGSL
    }

    fn prepare(&self, _: &Plane, _: &Frame, _: &[LightGpu], _: &mut PlaneGpu) -> Prepared {
        crate::blur::nothing()
    }

    fn upload(
        &self,
        gpu: &Gpu,
        plane: &Plane,
        _: &(dyn Any + Send + Sync),
        _: &mut Timings,
    ) -> Result<Vec<(u32, wgpu::Buffer)>> {
        let texels = gpu.storage_copyable("opacity", bytemuck::cast_slice(&plane.texels));
        Ok(vec![(b::OPACITY.index, texels)])
    }

    fn blur_lookup(
        &self,
        b: &Bound<'_>,
        _li: usize,
        t: [f32; 2],
        wt: [f32; 2],
        shear: f32,
        kernel: Kernel,
    ) -> [f32; 4] {
        if kernel == Kernel::Gauss {
            return blur_explicit_gauss(b.plane, b.uniform.samples, t, wt);
        }
        blur_explicit(b.plane, b.uniform.samples, t, wt, shear, kernel)
    }
}
