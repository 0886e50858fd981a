//! The separable blur: per light, a horizontal then a vertical box pass of half-side w (texels)
//! with running sums over the image, padded by the largest radius so the penumbra can extend
//! past the image's edge (`blur/separable_passes.wgsl`), then a bilinear lookup in the light's
//! map (`blur/separable.wgsl`); cost per light ∝ image texels, not w. This module is the twin
//! of both files, same names and arithmetic (a WGSL entry point runs one thread; its twin runs
//! every thread in order), and holds the plan of radii and margins.
//!
//! For a caster parallel to the cloth w = R·d_ca/(d_lc + d_ca) is the same for every acceptor
//! pixel, so one pre-blurred map per light is exact for the box kernel (a tilted caster would
//! need the spatially varying passes of US 7,982,734).

use std::any::Any;

use wgpu::util::DeviceExt;

use crate::bindings::{separable_passes as pass, shade as b};
use crate::blur::Blur;
use crate::blur::{own, Bound, Built, Kernel, Method, Plane, Prepared};
use crate::caster::Caster;
use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, PlaneGpu, SepParams};
use crate::{Error, Result};

/// The lookup included into the shading pass.
pub const WGSL: &str = include_str!("separable.wgsl");

/// The per-light box passes.
pub const PASSES_WGSL: &str = include_str!("separable_passes.wgsl");

/// The separable method.
pub struct Separable;

/// Per-light radii and the padded map layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    /// Per light: box half-sides (wt.x, wt.y) in caster texels (½ texel, the least, for a light
    /// not above the caster plane, whose map `light_opacity` never reads).
    pub radii: Vec<[f32; 2]>,
    /// Texels of padding left/right (x) and above/below (y) of the caster.
    pub margin: [u32; 2],
    /// Padded map size.
    pub padded: [u32; 2],
}

impl Plan {
    /// The passes' uniform block for a `size` caster of `channels` opacity channels.
    pub fn params(&self, size: [u32; 2], channels: u32) -> SepParams {
        SepParams {
            size,
            channels,
            lights: self.radii.len() as u32,
            margin: self.margin,
            padded: self.padded,
        }
    }
}

/// Radii per light of a `size` image as `light_opacity` computes them; margins cover the largest (capped at the
/// caster's own size: beyond that the map is nearly uniform and treated as transparent).
pub fn plan(f: &Frame, size: [u32; 2], lights: &[LightGpu]) -> Plan {
    let [w, h] = size;
    let texel = [
        (f.caster_rect[2] - f.caster_rect[0]) / w as f32,
        (f.caster_rect[3] - f.caster_rect[1]) / h as f32,
    ];
    let radii: Vec<[f32; 2]> = lights
        .iter()
        .map(|l| {
            let (lz, r) = (l.position[2], l.radius);
            let hgt = f.caster_height;
            // A distant light (`position` its direction) is always beyond the caster: its cone
            // has radius sin ρ·s at s = hgt/lz along it, as a sphere's R·hgt/lz.
            let active = lz > hgt || (l.shape == LightGpu::DISTANT && lz > 0.0);
            if l.shape == LightGpu::RECT || l.shape == LightGpu::GAUSSIAN {
                // A rectangle: a box of half-sides s·half (s = d_ca/d_lc); a Gaussian of σ =
                // half: the box of its variance (half-sides √3·σ·s).
                let s = if active { hgt / lz } else { 0.0 };
                let k = if l.shape == LightGpu::RECT {
                    1.0
                } else {
                    3f32.sqrt()
                };
                return [
                    (k * l.half[0] * s / texel[0]).max(0.5),
                    (k * l.half[1] * s / texel[1]).max(0.5),
                ];
            }
            let wl = if active { r * hgt / lz } else { 0.0 };
            [(wl / texel[0]).max(0.5), (wl / texel[1]).max(0.5)]
        })
        .collect();
    let max_x = radii.iter().map(|r| r[0]).fold(0.5, f32::max);
    let max_y = radii.iter().map(|r| r[1]).fold(0.5, f32::max);
    let margin = [
        (max_x.ceil() as u32 + 1).min(w),
        (max_y.ceil() as u32 + 1).min(h),
    ];
    Plan {
        radii,
        margin,
        padded: [w + 2 * margin[0], h + 2 * margin[1]],
    }
}

/// 8-bit opacity count of channel `ch` of caster texel (i, j); 0 right of the caster.
pub fn texel(params: &SepParams, opacity: &[u32], j: u32, i: u32, ch: u32) -> u32 {
    if i >= params.size[0] {
        return 0;
    }
    (opacity[(j * params.size[0] + i) as usize] >> (8 * ch)) & 255
}

/// Horizontal pass, every (light, caster row, channel) thread: the mean over x ± radii.x of the
/// row (transparent outside) at each padded column centre. Layout `[light][row][padded col][ch]`.
pub fn sep_h(params: &SepParams, opacity: &[u32], radii: &[[f32; 2]]) -> Vec<f32> {
    let [w, h] = params.size;
    let channels = params.channels;
    let pw = params.padded[0];
    let mx = params.margin[0] as f32;
    let mut hmap = vec![0f32; (params.lights * h * pw * channels) as usize];
    for li in 0..params.lights {
        let r = radii[li as usize][0];
        for j in 0..h {
            for ch in 0..channels {
                // Running prefix sums at the box's left and right edges (both only move right).
                let (mut il, mut pl, mut ir, mut pr) = (0u32, 0u32, 0u32, 0u32);
                for i in 0..pw {
                    let x = i as f32 - mx + 0.5;
                    let lo = (x - r).clamp(0.0, w as f32);
                    let hi = (x + r).clamp(0.0, w as f32);
                    while (il as f32) < lo.floor() {
                        pl += texel(params, opacity, j, il, ch);
                        il += 1;
                    }
                    while (ir as f32) < hi.floor() {
                        pr += texel(params, opacity, j, ir, ch);
                        ir += 1;
                    }
                    let sum = (pr - pl) as f32
                        + (hi - hi.floor()) * texel(params, opacity, j, ir, ch) as f32
                        - (lo - lo.floor()) * texel(params, opacity, j, il, ch) as f32;
                    hmap[(((li * h + j) * pw + i) * channels + ch) as usize] =
                        sum / (2.0 * r * 255.0);
                }
            }
        }
    }
    hmap
}

/// Light `li`'s horizontal pass at caster row j, padded column i; 0 below the caster.
pub fn hval(params: &SepParams, hmap: &[f32], li: u32, j: u32, i: u32, ch: u32) -> f32 {
    let h = params.size[1];
    if j >= h {
        return 0.0;
    }
    hmap[(((li * h + j) * params.padded[0] + i) * params.channels + ch) as usize]
}

/// Vertical pass over the horizontal one, every (light, padded column, channel) thread:
/// layout `[light][padded row][padded col][ch]`.
pub fn sep_v(params: &SepParams, hmap: &[f32], radii: &[[f32; 2]]) -> Vec<f32> {
    let h = params.size[1];
    let channels = params.channels;
    let [pw, ph] = params.padded;
    let my = params.margin[1] as f32;
    let mut vmap = vec![0f32; (params.lights * ph * pw * channels) as usize];
    for li in 0..params.lights {
        let r = radii[li as usize][1];
        for i in 0..pw {
            for ch in 0..channels {
                let (mut jl, mut pl, mut jr, mut pr) = (0u32, 0f32, 0u32, 0f32);
                for row in 0..ph {
                    let y = row as f32 - my + 0.5;
                    let lo = (y - r).clamp(0.0, h as f32);
                    let hi = (y + r).clamp(0.0, h as f32);
                    while (jl as f32) < lo.floor() {
                        pl += hval(params, hmap, li, jl, i, ch);
                        jl += 1;
                    }
                    while (jr as f32) < hi.floor() {
                        pr += hval(params, hmap, li, jr, i, ch);
                        jr += 1;
                    }
                    let sum = (pr - pl) + (hi - hi.floor()) * hval(params, hmap, li, jr, i, ch)
                        - (lo - lo.floor()) * hval(params, hmap, li, jl, i, ch);
                    vmap[(((li * ph + row) * pw + i) * channels + ch) as usize] = sum / (2.0 * r);
                }
            }
        }
    }
    vmap
}

/// Texel (x, y), channel `ch`, of light `li`'s pre-blurred map (`u.padded` texels); 0
/// outside.
pub fn sep_tap(
    u: &PlaneGpu,
    map: &[f32],
    channels: u32,
    li: usize,
    x: i32,
    y: i32,
    ch: u32,
) -> f32 {
    let (pw, ph) = (u.padded[0] as i32, u.padded[1] as i32);
    if x < 0 || y < 0 || x >= pw || y >= ph {
        return 0.0;
    }
    map[(((li as i32 * ph + y) * pw + x) as u32 * channels + ch) as usize]
}

/// Bilinear lookup of light `li`'s pre-blurred map (`sep_h`, `sep_v`) at caster texel
/// coordinate t.
pub fn blur_separable(
    u: &PlaneGpu,
    map: &[f32],
    channels: u32,
    li: usize,
    t: [f32; 2],
) -> [f32; 3] {
    let c = [
        t[0] + u.margin[0] as f32 - 0.5,
        t[1] + u.margin[1] as f32 - 0.5,
    ];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let (x, y) = (c0[0] as i32, c0[1] as i32);
    let tap = |x: i32, y: i32, ch: u32| sep_tap(u, map, channels, li, x, y, ch);
    let mut out = [0f32; 3];
    for ch in 0..channels {
        let top = tap(x, y, ch) * (1.0 - a[0]) + tap(x + 1, y, ch) * a[0];
        let bottom = tap(x, y + 1, ch) * (1.0 - a[0]) + tap(x + 1, y + 1, ch) * a[0];
        out[ch as usize] = top * (1.0 - a[1]) + bottom * a[1];
    }
    if channels == 1 {
        [out[0]; 3]
    } else {
        out
    }
}

impl Method for Separable {
    fn blur(&self) -> Blur {
        Blur::Separable
    }

    fn kernels(&self) -> &'static [Kernel] {
        &[Kernel::Box]
    }

    fn wgsl(&self) -> &'static str {
        WGSL
    }

    fn pass_wgsl(&self) -> &'static [(&'static str, &'static str)] {
        &[("separable_passes.wgsl", PASSES_WGSL)]
    }

    fn check(&self, caster: &Caster) -> Result<()> {
        if caster.tilt_deg != 0.0 {
            return Err(Error::SeparableNeedsParallelCaster {
                tilt_deg: caster.tilt_deg,
            });
        }
        Ok(())
    }

    fn prepare(
        &self,
        plane: &Plane,
        frame: &Frame,
        lights: &[LightGpu],
        uniform: &mut PlaneGpu,
    ) -> Prepared {
        let plan = plan(frame, plane.size, lights);
        uniform.margin = plan.margin;
        uniform.padded = plan.padded;
        std::sync::Arc::new(plan)
    }

    fn upload(
        &self,
        gpu: &Gpu,
        plane: &Plane,
        prepared: &(dyn Any + Send + Sync),
        timings: &mut Timings,
    ) -> Result<Vec<(u32, wgpu::Buffer)>> {
        let plan: &Plan = own(prepared, "separable");
        let texels = gpu.storage_copyable("opacity", bytemuck::cast_slice(&plane.texels));
        let t = std::time::Instant::now();
        let map = separable_passes(gpu, plan, plane, &texels)?;
        timings
            .passes
            .push(("separable", t.elapsed().as_secs_f64()));
        Ok(vec![(b::SEP_MAP.index, map)])
    }

    fn build_twin(&self, plane: &Plane, prepared: &(dyn Any + Send + Sync)) -> Built {
        let plan: &Plan = own(prepared, "separable");
        let params = plan.params(plane.size, plane.channels);
        let hmap = sep_h(&params, &plane.texels, &plan.radii);
        Box::new(sep_v(&params, &hmap, &plan.radii))
    }

    fn blur_lookup(
        &self,
        b: &Bound<'_>,
        li: usize,
        t: [f32; 2],
        _wt: [f32; 2],
        _shear: f32,
        _kernel: Kernel,
    ) -> [f32; 4] {
        let map: &Vec<f32> = own(b.built, "separable");
        let v = blur_separable(b.uniform, map, b.plane.channels, li, t);
        // No fourth channel: only glossy scenes have one, and they never use this method.
        [v[0], v[1], v[2], 0.0]
    }

    fn keeps(
        &self,
        prepared: &(dyn Any + Send + Sync),
        frame: &Frame,
        uniform: &PlaneGpu,
        lights: &[LightGpu],
    ) -> bool {
        let kept: &Plan = own(prepared, "separable");
        plan(frame, uniform.size, lights).radii == kept.radii
    }
}

/// Runs the separable blur passes (`separable_passes.wgsl`) for every light; returns the padded
/// maps.
pub fn separable_passes(
    gpu: &Gpu,
    plan: &Plan,
    plane: &Plane,
    opacity: &wgpu::Buffer,
) -> Result<wgpu::Buffer> {
    let sep = plan.params(plane.size, plane.channels);
    let (h, channels, lights) = (sep.size[1], sep.channels, sep.lights);
    let [pw, ph] = sep.padded;
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("separable_passes.wgsl"),
            source: wgpu::ShaderSource::Wgsl(PASSES_WGSL.into()),
        });
    let params = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("separable params"),
            contents: bytemuck::bytes_of(&sep),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let radii = gpu.storage("separable radii", bytemuck::cast_slice(&plan.radii));
    let scratch = |label: &str, n: u64| {
        gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (n * 4).max(64),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    };
    let hmap = scratch(
        "separable h",
        lights as u64 * h as u64 * pw as u64 * channels as u64,
    );
    let vmap = scratch(
        "separable v",
        lights as u64 * ph as u64 * pw as u64 * channels as u64,
    );
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    for (entry, threads) in [
        ("sep_h", lights * h * channels),
        ("sep_v", lights * pw * channels),
    ] {
        // Auto layouts hold only what the entry point uses.
        let mut bindings = vec![
            (pass::PARAMS.index, &params),
            (pass::RADII.index, &radii),
            (pass::HMAP.index, &hmap),
        ];
        if entry == "sep_h" {
            bindings.push((pass::OPACITY.index, opacity));
        } else {
            bindings.push((pass::VMAP.index, &vmap));
        }
        gpu.dispatch(&mut enc, &module, entry, &bindings, threads);
    }
    gpu.queue.submit([enc.finish()]);
    gpu.wait("separable")?;
    Ok(vmap)
}
