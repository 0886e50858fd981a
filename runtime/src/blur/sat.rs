//! The summed-area-table blur: the mean over a box of any half-sides from four corners per
//! texel span of a table of u32 counts (constant cost, exact sums). WGSL `blur/sat.wgsl` (the
//! lookup) and `blur/sat_build.wgsl` (the table's two passes); this module is the twin of both,
//! same names and (wrapping) arithmetic. A WGSL entry point runs one thread; its twin runs every
//! thread in order.
//!
//! Why integers: an f32 table of 8-bit alpha at 4096² loses 1e-3–1e-2 in box means (large
//! nearly equal corners cancel); u32 counts are exact, and because u32 arithmetic wraps, the
//! 4-corner difference is exact for any box whose true sum is below 2³² — every box up to
//! 4096×4096 texels of 8-bit data — even when the table's total overflows.

use std::any::Any;

use wgpu::util::DeviceExt;

use crate::bindings::{sat_build as pass, shade as b};
use crate::blur::Blur;
use crate::blur::{own, Bound, Built, Kernel, Method, Plane, Prepared};
use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, PlaneGpu, SatParams};
use crate::Result;

/// The lookup included into the shading pass.
pub const WGSL: &str = include_str!("sat.wgsl");

/// The table's passes.
pub const BUILD_WGSL: &str = include_str!("sat_build.wgsl");

/// The SAT method.
pub struct Sat;

/// Row pass, every (row, channel) thread: running sums along each row into the
/// (w + 1) × (h + 1) × channels table (row 0 and column 0 stay zero).
pub fn sat_rows(params: &SatParams, opacity: &[u32], sat: &mut [u32]) {
    let [w, h] = params.size.map(|x| x as usize);
    let channels = params.channels as usize;
    for j in 0..h {
        for ch in 0..channels {
            let mut acc = 0u32;
            for i in 0..w {
                acc = acc.wrapping_add((opacity[j * w + i] >> (8 * ch)) & 255);
                sat[((j + 1) * (w + 1) + i + 1) * channels + ch] = acc;
            }
        }
    }
}

/// Column pass, every (column, channel) thread: running sums down each column of the table.
pub fn sat_columns(params: &SatParams, sat: &mut [u32]) {
    let [w, h] = params.size.map(|x| x as usize);
    let channels = params.channels as usize;
    for i in 1..=w {
        for ch in 0..channels {
            let mut acc = 0u32;
            for j in 1..=h {
                let at = (j * (w + 1) + i) * channels + ch;
                acc = acc.wrapping_add(sat[at]);
                sat[at] = acc;
            }
        }
    }
}

/// The whole table, as the GPU builds it (`sat_rows`, then `sat_columns`). `opacity` packs
/// channel c in bits 8c..8c+8.
pub fn build(opacity: &[u32], w: usize, h: usize, channels: usize) -> Vec<u32> {
    let params = SatParams {
        size: [w as u32, h as u32],
        channels: channels as u32,
        pad: 0,
    };
    let mut sat = vec![0u32; (w + 1) * (h + 1) * channels];
    sat_rows(&params, opacity, &mut sat);
    sat_columns(&params, &mut sat);
    sat
}

/// Table entry (i, j), channel `ch`, of the summed-area table of a image `w` texels wide.
pub fn sat_load(sat: &[u32], w: u32, channels: u32, i: u32, j: u32, ch: u32) -> u32 {
    sat[((j * (w + 1) + i) * channels + ch) as usize]
}

/// One axis of a box [lo, hi] (texel units, within [0, n]) split into whole-texel spans:
/// corner indices and the weights of the spans inner (c1→c2), right (c2→c3), left (c0→c1).
pub fn sat_spans(lo: f32, hi: f32, n: u32) -> ([u32; 4], [f32; 3]) {
    let i0 = lo.floor() as u32;
    let i1 = hi.floor() as u32;
    let a0 = lo - lo.floor();
    let a1 = hi - hi.floor();
    if i1 > i0 {
        (
            [i0, (i0 + 1).min(n), i1, (i1 + 1).min(n)],
            [1.0, a1, 1.0 - a0],
        )
    } else {
        ([i0, i1, i1, (i1 + 1).min(n)], [0.0, a1 - a0, 0.0])
    }
}

/// Mean opacity (0..1 per channel) over the box t ± wt (texel units, wt > 0) of a `size`
/// image from its summed-area table; outside the caster counts as transparent.
pub fn blur_sat(sat: &[u32], size: [u32; 2], channels: u32, t: [f32; 2], wt: [f32; 2]) -> [f32; 4] {
    let [w, h] = size;
    let lo = [
        (t[0] - wt[0]).clamp(0.0, w as f32),
        (t[1] - wt[1]).clamp(0.0, h as f32),
    ];
    let hi = [
        (t[0] + wt[0]).clamp(0.0, w as f32),
        (t[1] + wt[1]).clamp(0.0, h as f32),
    ];
    let (cx, wx) = sat_spans(lo[0], hi[0], w);
    let (cy, wy) = sat_spans(lo[1], hi[1], h);
    // Span m of an axis runs from corner A[m] to B[m]: inner 1→2, right 2→3, left 0→1.
    const A: [usize; 3] = [1, 2, 0];
    const B: [usize; 3] = [2, 3, 1];
    let mut out = [0f32; 4];
    for ch in 0..channels {
        let mut s = [[0u32; 4]; 4];
        for b in 0..4 {
            for a in 0..4 {
                s[b][a] = sat_load(sat, w, channels, cx[a], cy[b], ch);
            }
        }
        let mut total = 0f32;
        for m in 0..3 {
            for k in 0..3 {
                let span_sum = s[B[k]][B[m]]
                    .wrapping_sub(s[B[k]][A[m]])
                    .wrapping_sub(s[A[k]][B[m]])
                    .wrapping_add(s[A[k]][A[m]]);
                total += wx[m] * wy[k] * span_sum as f32;
            }
        }
        out[ch as usize] = total / (4.0 * wt[0] * wt[1] * 255.0);
    }
    if channels == 1 {
        [out[0]; 4]
    } else {
        out
    }
}

/// Boxes the ellipse is cut into (`SAT_SLABS`), their bands' edges (`SLAB_EDGE`, −cos(πk/4))
/// and widths (`SLAB_WIDTH`, the mean chord over the band) in units of the radii.
pub const SAT_SLABS: usize = 4;
const SLAB_EDGE: [f32; 5] = [
    -1.0,
    -std::f32::consts::FRAC_1_SQRT_2,
    0.0,
    std::f32::consts::FRAC_1_SQRT_2,
    1.0,
];
const SLAB_WIDTH: [f32; 4] = [0.487_205_14, 0.908_913_76, 0.908_913_76, 0.487_205_14];

/// The sheared ellipse ((x − shear·y)/wt.x)² + (y/wt.y)² ≤ 1 around t as [`SAT_SLABS`] boxes,
/// one per band of rows, each with its band's exact area (see `blur_sat_ellipse` in WGSL).
pub fn blur_sat_ellipse(
    sat: &[u32],
    size: [u32; 2],
    channels: u32,
    t: [f32; 2],
    wt: [f32; 2],
    shear: f32,
) -> [f32; 4] {
    let mut sum = [0f32; 4];
    let mut area = 0f32;
    for k in 0..SAT_SLABS {
        let mid = 0.5 * (SLAB_EDGE[k] + SLAB_EDGE[k + 1]) * wt[1];
        let half = [
            SLAB_WIDTH[k] * wt[0],
            0.5 * (SLAB_EDGE[k + 1] - SLAB_EDGE[k]) * wt[1],
        ];
        let a = half[0] * half[1];
        let m = blur_sat(sat, size, channels, [t[0] + shear * mid, t[1] + mid], half);
        for c in 0..4 {
            sum[c] += a * m[c];
        }
        area += a;
    }
    sum.map(|x| x / area)
}

/// Boxes per axis of the Gaussian's approximation (`GAUSS_BOXES`), their half-sides in units of
/// σ (`GAUSS_HALF`) and weights (`GAUSS_WEIGHT`): fitted (least maximum error) so that the
/// mixture's CDF is within 0.0071 of the normal CDF; the mixture's variance is 1.001.
pub const GAUSS_BOXES: usize = 3;
/// See [`GAUSS_BOXES`].
pub const GAUSS_HALF: [f32; GAUSS_BOXES] = [0.778_345_1, 1.471_474_3, 2.453_440_1];
/// See [`GAUSS_BOXES`].
pub const GAUSS_WEIGHT: [f32; GAUSS_BOXES] = [0.245_542_78, 0.437_249_12, 0.317_208_1];

/// The Gaussian of standard deviations wt around t as [`GAUSS_BOXES`]² boxes, the product of
/// the per-axis mixtures (see `blur_sat_gauss` in WGSL).
pub fn blur_sat_gauss(
    sat: &[u32],
    size: [u32; 2],
    channels: u32,
    t: [f32; 2],
    wt: [f32; 2],
) -> [f32; 4] {
    let mut sum = [0f32; 4];
    let mut total = 0f32;
    for j in 0..GAUSS_BOXES {
        for i in 0..GAUSS_BOXES {
            let a = GAUSS_WEIGHT[i] * GAUSS_WEIGHT[j];
            let m = blur_sat(
                sat,
                size,
                channels,
                t,
                [GAUSS_HALF[i] * wt[0], GAUSS_HALF[j] * wt[1]],
            );
            for c in 0..4 {
                sum[c] += a * m[c];
            }
            total += a;
        }
    }
    sum.map(|x| x / total)
}

impl Method for Sat {
    fn blur(&self) -> Blur {
        Blur::Sat
    }

    fn kernels(&self) -> &'static [Kernel] {
        &[Kernel::Box, Kernel::Disc, Kernel::GaussBoxes]
    }

    fn wgsl(&self) -> &'static str {
        WGSL
    }

    fn pass_wgsl(&self) -> &'static [(&'static str, &'static str)] {
        &[("sat_build.wgsl", BUILD_WGSL)]
    }

    fn prepare(&self, _: &Plane, _: &Frame, _: &[LightGpu], _: &mut PlaneGpu) -> Prepared {
        crate::blur::nothing()
    }

    fn upload(
        &self,
        gpu: &Gpu,
        plane: &Plane,
        _: &(dyn Any + Send + Sync),
        timings: &mut Timings,
    ) -> Result<Vec<(u32, wgpu::Buffer)>> {
        let texels = gpu.storage_copyable("opacity", bytemuck::cast_slice(&plane.texels));
        let t = std::time::Instant::now();
        let table = build_sat(gpu, &texels, plane.size[0], plane.size[1], plane.channels)?;
        timings
            .passes
            .push(("sat_build", t.elapsed().as_secs_f64()));
        Ok(vec![(b::SAT.index, table)])
    }

    fn build_twin(&self, plane: &Plane, _: &(dyn Any + Send + Sync)) -> Built {
        let [w, h] = plane.size.map(|x| x as usize);
        Box::new(build(&plane.texels, w, h, plane.channels as usize))
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
        let table: &Vec<u32> = own(b.built, "sat");
        if kernel == Kernel::Disc {
            return blur_sat_ellipse(table, b.plane.size, b.plane.channels, t, wt, shear);
        }
        if kernel == Kernel::Gauss {
            return blur_sat_gauss(table, b.plane.size, b.plane.channels, t, wt);
        }
        blur_sat(table, b.plane.size, b.plane.channels, t, wt)
    }
}

/// Builds the u32 summed-area table of a packed-image buffer on the GPU (`sat_build.wgsl`).
pub fn build_sat(
    gpu: &Gpu,
    opacity: &wgpu::Buffer,
    w: u32,
    h: u32,
    channels: u32,
) -> Result<wgpu::Buffer> {
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sat_build.wgsl"),
            source: wgpu::ShaderSource::Wgsl(BUILD_WGSL.into()),
        });
    let params = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sat params"),
            contents: bytemuck::bytes_of(&SatParams {
                size: [w, h],
                channels,
                pad: 0,
            }),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    // wgpu zero-initialises buffers: row 0 and column 0 of the table stay 0.
    let table = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("sat"),
        size: ((w + 1) as u64 * (h + 1) as u64 * channels as u64 * 4).max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    for (entry, threads) in [("sat_rows", h * channels), ("sat_columns", w * channels)] {
        // Auto layouts hold only what the entry point uses: the column pass reads no image.
        let mut bindings = vec![(pass::PARAMS.index, &params), (pass::SAT.index, &table)];
        if entry == "sat_rows" {
            bindings.push((pass::OPACITY.index, opacity));
        }
        gpu.dispatch(&mut enc, &module, entry, &bindings, threads);
    }
    gpu.queue.submit([enc.finish()]);
    gpu.wait("sat_build")?;
    Ok(table)
}

/// Builds the SAT of `opacity` on the GPU and reads it back (for tests and benchmarks).
pub fn sat_table(gpu: &Gpu, opacity: &[u32], w: u32, h: u32, channels: u32) -> Result<Vec<u32>> {
    let input = gpu.storage_copyable("opacity", bytemuck::cast_slice(opacity));
    let table = build_sat(gpu, &input, w, h, channels)?;
    let n = (w + 1) as u64 * (h + 1) as u64 * channels as u64 * 4;
    gpu.read_buffer(&table, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrapping_table_gives_exact_sums_when_the_total_overflows() {
        // 5000 × 4000 texels of 255: total 5.1e9 > 2³², yet a 4000 × 4000 box is exact.
        let (w, h) = (5000usize, 4000usize);
        let op = vec![255u32; w * h];
        let sat = build(&op, w, h, 1);
        let m = blur_sat(
            &sat,
            [w as u32, h as u32],
            1,
            [2500.0, 2000.0],
            [2000.0, 2000.0],
        );
        assert!((m[0] - 1.0).abs() < 1e-6, "{}", m[0]);
        let m = blur_sat(&sat, [w as u32, h as u32], 1, [4999.5, 3999.5], [1.0, 1.0]);
        // [4998.5, 5000.5]² keeps 1.5 × 1.5 of its 2 × 2 inside the caster.
        assert_eq!(
            m[0], 0.5625,
            "the part of the box outside the caster is transparent"
        );
    }

    fn hash(i: u32) -> u32 {
        let mut x = i.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
        x ^= x >> 15;
        x = x.wrapping_mul(0x2C1B_3C6D);
        x ^ (x >> 12)
    }

    /// Exact mean of the piecewise-constant image over a box, by brute force over texels with
    /// their overlap areas in f64.
    fn brute(op: &[u32], w: usize, h: usize, ch: usize, t: [f32; 2], wt: [f32; 2]) -> f64 {
        let (x0, x1) = ((t[0] - wt[0]) as f64, (t[0] + wt[0]) as f64);
        let (y0, y1) = ((t[1] - wt[1]) as f64, (t[1] + wt[1]) as f64);
        let mut sum = 0.0;
        for j in 0..h {
            for i in 0..w {
                let ox = (x1.min(i as f64 + 1.0) - x0.max(i as f64)).max(0.0);
                let oy = (y1.min(j as f64 + 1.0) - y0.max(j as f64)).max(0.0);
                sum += ox * oy * ((op[j * w + i] >> (8 * ch)) & 255) as f64;
            }
        }
        sum / ((x1 - x0) * (y1 - y0) * 255.0)
    }

    #[test]
    fn blur_sat_equals_the_exact_area_weighted_mean() {
        let (w, h) = (37, 23);
        let op: Vec<u32> = (0..w * h).map(|i| hash(i as u32) & 0x00FF_FFFF).collect();
        for channels in [1usize, 3] {
            let sat = build(&op, w, h, channels);
            for s in 0..400u32 {
                let r = |k: u32| (hash(s * 7 + k) % 10_000) as f32 / 10_000.0;
                let t = [r(1) * 45.0 - 4.0, r(2) * 31.0 - 4.0];
                let wt = [0.05 + r(3) * 12.0, 0.05 + r(4) * 9.0];
                let got = blur_sat(&sat, [w as u32, h as u32], channels as u32, t, wt);
                for ch in 0..channels {
                    let want = brute(&op, w, h, ch, t, wt);
                    assert!(
                        (got[ch] as f64 - want).abs() < 2e-5,
                        "t {t:?} wt {wt:?} ch {ch}: {} vs {want}",
                        got[ch]
                    );
                }
            }
        }
    }
}
