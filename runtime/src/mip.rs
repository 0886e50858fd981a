//! MIP chains: of the caster opacity (looked up by `blur_mip`), and of a PTM's coefficients for
//! files that store no levels.
//!
//! Built once per caster on the CPU (a static caster needs no per-frame rebuild; wgpu has no
//! automatic mip generation). Level k texel covers 2^k × 2^k level-0 texels; texels beyond the
//! caster count as transparent, so every level keeps "outside = 0".

use crate::layout::{MipLevel, PtmLevel};

/// Levels concatenated (the four 8-bit channels in 0..1) and where each level lies in them.
pub fn build_chain(opacity: &[u32], w: usize, h: usize) -> (Vec<[f32; 4]>, Vec<MipLevel>) {
    let mut texels: Vec<[f32; 4]> = opacity
        .iter()
        .map(|o| [o & 255, (o >> 8) & 255, (o >> 16) & 255, o >> 24].map(|c| c as f32 / 255.0))
        .collect();
    let mut levels = vec![MipLevel::new(0, w, h)];
    let (mut lw, mut lh, mut off) = (w, h, 0usize);
    while lw > 1 || lh > 1 {
        let (nw, nh) = (lw.div_ceil(2), lh.div_ceil(2));
        let next_off = texels.len();
        for y in 0..nh {
            for x in 0..nw {
                let mut s = [0f32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (cx, cy) = (2 * x + dx, 2 * y + dy);
                    if cx < lw && cy < lh {
                        let t = texels[off + cy * lw + cx];
                        for c in 0..4 {
                            s[c] += t[c];
                        }
                    }
                }
                texels.push(s.map(|v| 0.25 * v));
            }
        }
        levels.push(MipLevel::new(next_off, nw, nh));
        (lw, lh, off) = (nw, nh, next_off);
    }
    (texels, levels)
}

/// Appends the MIP chain of a tiled PTM to its texel-major coefficients (`n` per texel, `w`×`h`
/// texels) and returns per level (texel offset, w, h, 0), level 0 first. Each level halves
/// every even side by averaging 2 (or 2×2) texels; K is linear in the coefficients, so the
/// average of the coefficients is the coefficients of the average K. The PTM tiles, so the
/// chain stops when no side can be halved exactly (a 96² map: 96, 48, 24, 12, 6, 3).
pub fn build_ptm_chain(coeffs: &mut Vec<f32>, n: usize, w: usize, h: usize) -> Vec<[u32; 4]> {
    let mut levels = vec![[0, w as u32, h as u32, 0]];
    let (mut lw, mut lh, mut off) = (w, h, 0usize);
    while (lw > 1 && lw % 2 == 0) || (lh > 1 && lh % 2 == 0) {
        let (sx, sy) = (
            1 + (lw > 1 && lw % 2 == 0) as usize,
            1 + (lh > 1 && lh % 2 == 0) as usize,
        );
        let (nw, nh) = (lw / sx, lh / sy);
        let next_off = coeffs.len() / n;
        let scale = 1.0 / (sx * sy) as f32;
        for j in 0..nh {
            for i in 0..nw {
                for k in 0..n {
                    let mut sum = 0.0f32;
                    for dy in 0..sy {
                        for dx in 0..sx {
                            let t = off + (j * sy + dy) * lw + i * sx + dx;
                            sum += coeffs[t * n + k];
                        }
                    }
                    coeffs.push(sum * scale);
                }
            }
        }
        levels.push([next_off as u32, nw as u32, nh as u32, 0]);
        (lw, lh, off) = (nw, nh, next_off);
    }
    levels
}

/// A PTM's level-0 coverage followed by its box averages at every further level of `levels`
/// (as `SceneBuffers::coeffs` lays levels out: level k's texels start at `levels[k].offset`). Each
/// level averages blocks of the level above: 2 texels along a side that shrank (an odd last
/// texel of a rounded-down level is dropped, as the file's levels drop it), 1 along a side that
/// did not. Without levels: level 0 alone.
pub fn coverage_chain(coverage: &[f32], levels: &[PtmLevel]) -> Vec<f32> {
    let mut out = coverage.to_vec();
    for pair in levels.windows(2) {
        let (up, lv) = (&pair[0], &pair[1]);
        let (uw, uh) = (up.width as usize, up.height as usize);
        let (w, h) = (lv.width as usize, lv.height as usize);
        let fx = if w < uw { 2 } else { 1 };
        let fy = if h < uh { 2 } else { 1 };
        let scale = 1.0 / (fx * fy) as f32;
        debug_assert_eq!(out.len(), lv.offset as usize);
        for j in 0..h {
            for i in 0..w {
                let mut sum = 0f32;
                for dy in 0..fy {
                    for dx in 0..fx {
                        sum += out[up.offset as usize + (j * fy + dy) * uw + i * fx + dx];
                    }
                }
                out.push(sum * scale);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_chain_box_averages_rounded_down_and_exact_levels() {
        // 5×2 → 2×1 (rounded down: column 4 dropped) → 1×1.
        let cov = [0.0, 1.0, 1.0, 1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.5];
        let levels = [
            PtmLevel::exact(0, 5, 2),
            PtmLevel::exact(10, 2, 1),
            PtmLevel::exact(12, 1, 1),
        ];
        let c = coverage_chain(&cov, &levels);
        assert_eq!(&c[10..], &[0.25, 0.75, 0.5]);
        // An exact chain that keeps an odd side: 4×3 → 2×3 averages pairs along x only.
        let cov: Vec<f32> = (0..12).map(|i| (i % 4) as f32 / 4.0).collect();
        let levels = [PtmLevel::exact(0, 4, 3), PtmLevel::exact(12, 2, 3)];
        let c = coverage_chain(&cov, &levels);
        assert_eq!(&c[12..], &[0.125, 0.625, 0.125, 0.625, 0.125, 0.625]);
        // No chain: level 0 only.
        assert_eq!(coverage_chain(&cov, &[]), cov);
    }

    #[test]
    fn ptm_chain_averages_blocks_and_stops_at_odd_sides() {
        // 4×2 texels, 2 coefficients each: coefficient 0 = texel index, 1 = 10·index.
        let mut c: Vec<f32> = (0..8).flat_map(|t| [t as f32, 10.0 * t as f32]).collect();
        let levels = build_ptm_chain(&mut c, 2, 4, 2);
        assert_eq!(levels, vec![[0, 4, 2, 0], [8, 2, 1, 0], [10, 1, 1, 0]]);
        // Level 1: (0+1+4+5)/4 = 2.5 and (2+3+6+7)/4 = 4.5; level 2: their mean 3.5.
        assert_eq!(&c[16..], &[2.5, 25.0, 4.5, 45.0, 3.5, 35.0]);
        // A 6×3 map halves x once (3×3), then stops: no side can be halved exactly.
        let mut c = vec![0.0f32; 18];
        assert_eq!(build_ptm_chain(&mut c, 1, 6, 3).len(), 2);
    }

    #[test]
    fn chain_halves_to_one_texel_and_keeps_the_mean_over_padded_area() {
        let (w, h) = (5, 3);
        let op: Vec<u32> = (0..15).map(|i| (i * 17) as u32 * 0x010101).collect();
        let (tex, levels) = build_chain(&op, w, h);
        let dims: Vec<(u32, u32)> = levels.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(dims, vec![(5, 3), (3, 2), (2, 1), (1, 1)]);
        // The top texel covers 8 × 8 level-0 texels; outside the 5 × 3 caster is 0.
        let total: f32 = op.iter().map(|o| (o & 255) as f32 / 255.0).sum();
        let top = tex[levels[3].offset as usize][0];
        assert!(
            (top - total / 64.0).abs() < 1e-6,
            "{top} vs {}",
            total / 64.0
        );
    }
}
