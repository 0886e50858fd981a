//! Twin of `shader/separable.wgsl`: the per-light horizontal and vertical box passes, same names
//! and arithmetic. A WGSL entry point runs one thread; its twin runs every thread in order.

use crate::layout::SepParams;

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
