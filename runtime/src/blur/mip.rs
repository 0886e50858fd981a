//! The MIP blur: a trilinear lookup in the image's MIP chain at level log2(2·max(wt)) (constant
//! cost; the kernel is a blend of two power-of-two boxes on a fixed grid, so it errs most at
//! edges). The chain is built once on the CPU ([`crate::mip::build_chain`]). WGSL
//! `blur/mip.wgsl`; this module is its twin, function by function.

use std::any::Any;

use crate::bindings::shade as b;
use crate::blur::Blur;
use crate::blur::{own, Bound, Kernel, Method, Plane, Prepared};
use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, MipLevel, PlaneGpu};
use crate::Result;

/// The lookup included into the shading pass.
pub const WGSL: &str = include_str!("mip.wgsl");

/// The MIP method.
pub struct Mip;

/// The image's chain: levels concatenated (its four channels in 0..1) and where each lies.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Chain {
    /// Every level's texels, level 0 first.
    pub texels: Vec<[f32; 4]>,
    /// Offset and size of each level.
    pub levels: Vec<MipLevel>,
}

fn mix4(a: [f32; 4], b: [f32; 4], t: f32) -> [f32; 4] {
    [0, 1, 2, 3].map(|c| a[c] * (1.0 - t) + b[c] * t)
}

/// Texel (x, y) of level `l`; transparent outside.
pub fn mip_texel(mip: &[[f32; 4]], l: &MipLevel, x: i32, y: i32) -> [f32; 4] {
    if x < 0 || y < 0 || x >= l.width as i32 || y >= l.height as i32 {
        return [0.0; 4];
    }
    mip[(l.offset + y as u32 * l.width + x as u32) as usize]
}

/// Bilinear sample of `level` at level-0 texel coordinate t.
pub fn mip_bilinear(mip: &[[f32; 4]], levels: &[MipLevel], level: u32, t: [f32; 2]) -> [f32; 4] {
    let l = &levels[level as usize];
    let scale = (1u32 << level) as f32;
    let c = [t[0] / scale - 0.5, t[1] / scale - 0.5];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let (x, y) = (c0[0] as i32, c0[1] as i32);
    mix4(
        mix4(mip_texel(mip, l, x, y), mip_texel(mip, l, x + 1, y), a[0]),
        mix4(
            mip_texel(mip, l, x, y + 1),
            mip_texel(mip, l, x + 1, y + 1),
            a[0],
        ),
        a[1],
    )
}

/// Trilinear: level log2(2·max(wt)) (the box side in texels), blended between the two nearest.
/// Trilinear at level `lod` (log2 of a box side in texels), blended between the two nearest.
pub fn mip_trilinear(mip: &[[f32; 4]], levels: &[MipLevel], t: [f32; 2], lod: f32) -> [f32; 4] {
    let top = levels.len() as u32 - 1;
    let lod = lod.clamp(0.0, top as f32);
    let l0 = lod as u32;
    let l1 = (l0 + 1).min(top);
    mix4(
        mip_bilinear(mip, levels, l0, t),
        mip_bilinear(mip, levels, l1, t),
        lod - l0 as f32,
    )
}

/// Trilinear at level log2(2·max(wt)) (the box's side in texels).
pub fn blur_mip(mip: &[[f32; 4]], levels: &[MipLevel], t: [f32; 2], wt: [f32; 2]) -> [f32; 4] {
    mip_trilinear(mip, levels, t, (2.0 * wt[0].max(wt[1])).log2())
}

/// Most samples [`blur_mip_ellipse`] takes along the major axis (`MIP_EWA_MAX`).
pub const MIP_EWA_MAX: u32 = 16;

/// Area of the unit disc below η = e, less π/4 (`ewa_area` in WGSL).
pub fn ewa_area(e: f32) -> f32 {
    let c = e.clamp(-1.0, 1.0);
    0.5 * (c * (1.0 - c * c).max(0.0).sqrt() + c.asin())
}

/// Elliptical weighted average from the chain: the minor semi-axis picks the level, major/minor
/// the number of samples along the major axis (see `blur_mip_ellipse` in WGSL).
pub fn blur_mip_ellipse(
    mip: &[[f32; 4]],
    levels: &[MipLevel],
    t: [f32; 2],
    wt: [f32; 2],
    shear: f32,
) -> [f32; 4] {
    let p = wt[0] * wt[0] + shear * shear * wt[1] * wt[1];
    let q = shear * wt[1] * wt[1];
    let r = wt[1] * wt[1];
    let m = 0.5 * (p + r);
    let d = (0.25 * (p - r) * (p - r) + q * q).sqrt();
    let major = (m + d).sqrt();
    let minor = (m - d).max(1e-12).sqrt();
    let mut axis = [1.0, 0.0];
    if d > 1e-6 * m {
        let a = if p >= r {
            [m + d - r, q]
        } else {
            [q, m + d - p]
        };
        let len = (a[0] * a[0] + a[1] * a[1]).sqrt();
        axis = [a[0] / len, a[1] / len];
    }
    let n = ((major / minor - 1e-3).ceil() as u32).min(MIP_EWA_MAX);
    let lod = minor.log2();
    let mut sum = [0f32; 4];
    let mut total = 0f32;
    for i in 0..n {
        let e0 = -1.0 + 2.0 * i as f32 / n as f32;
        let e1 = -1.0 + 2.0 * (i + 1) as f32 / n as f32;
        let w = ewa_area(e1) - ewa_area(e0);
        let c = 0.5 * (e0 + e1) * major;
        let v = mip_trilinear(mip, levels, [t[0] + c * axis[0], t[1] + c * axis[1]], lod);
        for k in 0..4 {
            sum[k] += w * v[k];
        }
        total += w;
    }
    sum.map(|x| x / total)
}

impl Method for Mip {
    fn blur(&self) -> Blur {
        Blur::Mip
    }

    fn kernels(&self) -> &'static [Kernel] {
        &[Kernel::MipBox, Kernel::Ewa]
    }

    fn wgsl(&self) -> &'static str {
        WGSL
    }

    fn prepare(&self, plane: &Plane, _: &Frame, _: &[LightGpu], _: &mut PlaneGpu) -> Prepared {
        let [w, h] = plane.size.map(|x| x as usize);
        let (texels, levels) = crate::mip::build_chain(&plane.texels, w, h);
        std::sync::Arc::new(Chain { texels, levels })
    }

    fn upload(
        &self,
        gpu: &Gpu,
        _: &Plane,
        prepared: &(dyn Any + Send + Sync),
        _: &mut Timings,
    ) -> Result<Vec<(u32, wgpu::Buffer)>> {
        let chain: &Chain = own(prepared, "mip");
        Ok(vec![
            (
                b::MIP.index,
                gpu.storage("mip", bytemuck::cast_slice(&chain.texels)),
            ),
            (
                b::MIP_LEVELS.index,
                gpu.storage("mip levels", bytemuck::cast_slice(&chain.levels)),
            ),
        ])
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
        let chain: &Chain = own(b.prepared, "mip");
        if kernel == Kernel::Disc {
            return blur_mip_ellipse(&chain.texels, &chain.levels, t, wt, shear);
        }
        if kernel == Kernel::Gauss {
            // The ellipse of the Gaussian's variance (a disc of radius r has r²/4 per axis).
            return blur_mip_ellipse(
                &chain.texels,
                &chain.levels,
                t,
                [2.0 * wt[0], 2.0 * wt[1]],
                0.0,
            );
        }
        blur_mip(&chain.texels, &chain.levels, t, wt)
    }
}
