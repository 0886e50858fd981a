//! Separable blur of the caster opacity: per light, a horizontal then a vertical box pass of
//! half-side w (texels) with running sums, over a map padded by the largest radius so the
//! penumbra can extend past the caster's edge. CPU twin of `separable.wgsl`.
//!
//! For a caster parallel to the cloth w = R·d_ca/(d_lc + d_ca) is the same for every acceptor
//! pixel, so one pre-blurred map per light is exact for the box kernel (a tilted caster would
//! need the spatially varying passes of US 7,982,734).

use crate::scene::{Frame, LightGpu};

/// Per-light radii and the padded map layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    /// Per light: box half-sides (wt.x, wt.y) in caster texels, 1 if the caster shadows this
    /// light (light above the caster plane), 0.
    pub radii: Vec<[f32; 4]>,
    /// Texels of padding left/right (x) and above/below (y) of the caster.
    pub margin: [u32; 2],
    /// Padded map size.
    pub padded: [u32; 2],
}

impl Plan {
    /// The `Frame::blur` field: mx, my, padded w, padded h.
    pub fn dims(&self) -> [u32; 4] {
        [
            self.margin[0],
            self.margin[1],
            self.padded[0],
            self.padded[1],
        ]
    }
}

/// Radii per light as `light_opacity` computes them; margins cover the largest (capped at the
/// caster's own size: beyond that the map is nearly uniform and treated as transparent).
pub fn plan(f: &Frame, lights: &[LightGpu]) -> Plan {
    let (w, h) = (f.counts[1], f.counts[2]);
    let texel = [
        (f.caster_rect[2] - f.caster_rect[0]) / w as f32,
        (f.caster_rect[3] - f.caster_rect[1]) / h as f32,
    ];
    let radii: Vec<[f32; 4]> = lights
        .iter()
        .map(|l| {
            let [_, _, lz, r] = l.position_radius;
            let hgt = f.caster[0];
            let active = lz > hgt;
            let wl = if active { r * hgt / lz } else { 0.0 };
            [
                (wl / texel[0]).max(0.5),
                (wl / texel[1]).max(0.5),
                if active { 1.0 } else { 0.0 },
                0.0,
            ]
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

/// Horizontal pass: per light, caster row and channel, the mean over x ± wt.x of the row
/// (transparent outside) at each padded column centre. Layout `[light][row][padded col][ch]`.
pub fn pass_h(opacity: &[u32], w: u32, h: u32, channels: u32, plan: &Plan) -> Vec<f32> {
    let (pw, mx) = (plan.padded[0], plan.margin[0] as f32);
    let mut out = vec![0f32; plan.radii.len() * (h * pw * channels) as usize];
    let v = |j: u32, i: u32, ch: u32| -> u32 {
        if i < w {
            (opacity[(j * w + i) as usize] >> (8 * ch)) & 255
        } else {
            0
        }
    };
    for (li, r) in plan.radii.iter().enumerate() {
        for j in 0..h {
            for ch in 0..channels {
                // Running prefix sums at the box's left and right edges (both only move right).
                let (mut il, mut pl, mut ir, mut pr) = (0u32, 0u32, 0u32, 0u32);
                for i in 0..pw {
                    let x = i as f32 - mx + 0.5;
                    let lo = (x - r[0]).clamp(0.0, w as f32);
                    let hi = (x + r[0]).clamp(0.0, w as f32);
                    while (il as f32) < lo.floor() {
                        pl += v(j, il, ch);
                        il += 1;
                    }
                    while (ir as f32) < hi.floor() {
                        pr += v(j, ir, ch);
                        ir += 1;
                    }
                    let sum = (pr - pl) as f32 + (hi - hi.floor()) * v(j, ir, ch) as f32
                        - (lo - lo.floor()) * v(j, il, ch) as f32;
                    let at = ((li as u32 * h + j) * pw + i) * channels + ch;
                    out[at as usize] = sum / (2.0 * r[0] * 255.0);
                }
            }
        }
    }
    out
}

/// Vertical pass over the horizontal one: layout `[light][padded row][padded col][ch]`.
pub fn pass_v(hmap: &[f32], h: u32, channels: u32, plan: &Plan) -> Vec<f32> {
    let (pw, ph, my) = (plan.padded[0], plan.padded[1], plan.margin[1] as f32);
    let mut out = vec![0f32; plan.radii.len() * (ph * pw * channels) as usize];
    for (li, r) in plan.radii.iter().enumerate() {
        let v = |j: u32, i: u32, ch: u32| -> f32 {
            if j < h {
                hmap[(((li as u32 * h + j) * pw + i) * channels + ch) as usize]
            } else {
                0.0
            }
        };
        for i in 0..pw {
            for ch in 0..channels {
                let (mut jl, mut pl, mut jr, mut pr) = (0u32, 0f32, 0u32, 0f32);
                for row in 0..ph {
                    let y = row as f32 - my + 0.5;
                    let lo = (y - r[1]).clamp(0.0, h as f32);
                    let hi = (y + r[1]).clamp(0.0, h as f32);
                    while (jl as f32) < lo.floor() {
                        pl += v(jl, i, ch);
                        jl += 1;
                    }
                    while (jr as f32) < hi.floor() {
                        pr += v(jr, i, ch);
                        jr += 1;
                    }
                    let sum = (pr - pl) + (hi - hi.floor()) * v(jr, i, ch)
                        - (lo - lo.floor()) * v(jl, i, ch);
                    let at = ((li as u32 * ph + row) * pw + i) * channels + ch;
                    out[at as usize] = sum / (2.0 * r[1]);
                }
            }
        }
    }
    out
}

/// Bilinear lookup of light `li`'s blurred map at caster texel coordinate t (0 outside).
pub fn blur_separable(map: &[f32], plan: &Plan, channels: u32, li: usize, t: [f32; 2]) -> [f32; 3] {
    let (pw, ph) = (plan.padded[0] as i32, plan.padded[1] as i32);
    let c = [
        t[0] + plan.margin[0] as f32 - 0.5,
        t[1] + plan.margin[1] as f32 - 0.5,
    ];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let (x, y) = (c0[0] as i32, c0[1] as i32);
    let tap = |x: i32, y: i32, ch: u32| -> f32 {
        if x < 0 || y < 0 || x >= pw || y >= ph {
            return 0.0;
        }
        map[(((li as i32 * ph + y) * pw + x) as u32 * channels + ch) as usize]
    };
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
