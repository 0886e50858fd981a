//! Summed-area table of the caster opacity: u32 counts of 8-bit values, built on the GPU
//! (`sat.wgsl`) or on the CPU (the twin), and the box-mean lookup both shade paths use.
//!
//! Why integers: an f32 table of 8-bit alpha at 4096² loses 1e-3–1e-2 in box means (large
//! nearly equal corners cancel); u32 counts are exact, and because u32 arithmetic wraps, the
//! 4-corner difference is exact for any box whose true sum is below 2³² — every box up to
//! 4096×4096 texels of 8-bit data — even when the table's total overflows.

/// The summed-area table shader.
pub const SAT_WGSL: &str = include_str!("sat.wgsl");

/// CPU twin of `sat_rows` + `sat_columns`: a (w + 1) × (h + 1) × channels table, row 0 and
/// column 0 zero, wrapping u32 sums. `opacity` packs channel c in bits 8c..8c+8.
pub fn build_cpu(opacity: &[u32], w: usize, h: usize, channels: usize) -> Vec<u32> {
    let mut sat = vec![0u32; (w + 1) * (h + 1) * channels];
    for j in 0..h {
        for ch in 0..channels {
            let mut acc = 0u32;
            for i in 0..w {
                acc = acc.wrapping_add((opacity[j * w + i] >> (8 * ch)) & 255);
                sat[((j + 1) * (w + 1) + i + 1) * channels + ch] = acc;
            }
        }
    }
    for j in 1..=h {
        for idx in 0..(w + 1) * channels {
            let above = sat[(j - 1) * (w + 1) * channels + idx];
            let here = &mut sat[j * (w + 1) * channels + idx];
            *here = here.wrapping_add(above);
        }
    }
    sat
}

/// One axis of a box [lo, hi] (texel units, within [0, n]) split into whole-texel spans:
/// corner indices and the weights of the spans inner (c1→c2), right (c2→c3), left (c0→c1);
/// the WGSL `sat_spans`.
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

/// Mean opacity (0..1 per channel) over the box t ± wt (texel units, wt > 0) of a w×h caster;
/// outside the caster counts as transparent. The WGSL `blur_sat`.
pub fn box_mean(sat: &[u32], w: u32, h: u32, channels: u32, t: [f32; 2], wt: [f32; 2]) -> [f32; 3] {
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
    let mut out = [0f32; 3];
    for ch in 0..channels as usize {
        let load = |i: u32, j: u32| {
            sat[(j as usize * (w as usize + 1) + i as usize) * channels as usize + ch]
        };
        let mut s = [[0u32; 4]; 4];
        for b in 0..4 {
            for a in 0..4 {
                s[b][a] = load(cx[a], cy[b]);
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
        out[ch] = total / (4.0 * wt[0] * wt[1] * 255.0);
    }
    if channels == 1 {
        [out[0]; 3]
    } else {
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn box_mean_equals_the_exact_area_weighted_mean() {
        let (w, h) = (37, 23);
        let op: Vec<u32> = (0..w * h).map(|i| hash(i as u32) & 0x00FF_FFFF).collect();
        for channels in [1usize, 3] {
            let sat = build_cpu(&op, w, h, channels);
            for s in 0..400u32 {
                let r = |k: u32| (hash(s * 7 + k) % 10_000) as f32 / 10_000.0;
                let t = [r(1) * 45.0 - 4.0, r(2) * 31.0 - 4.0];
                let wt = [0.05 + r(3) * 12.0, 0.05 + r(4) * 9.0];
                let got = box_mean(&sat, w as u32, h as u32, channels as u32, t, wt);
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

    #[test]
    fn wrapping_table_gives_exact_sums_when_the_total_overflows() {
        // 5000 × 4000 texels of 255: total 5.1e9 > 2³², yet a 4000 × 4000 box is exact.
        let (w, h) = (5000usize, 4000usize);
        let op = vec![255u32; w * h];
        let sat = build_cpu(&op, w, h, 1);
        let m = box_mean(
            &sat,
            w as u32,
            h as u32,
            1,
            [2500.0, 2000.0],
            [2000.0, 2000.0],
        );
        assert!((m[0] - 1.0).abs() < 1e-6, "{}", m[0]);
        let m = box_mean(&sat, w as u32, h as u32, 1, [4999.5, 3999.5], [1.0, 1.0]);
        // [4998.5, 5000.5]² keeps 1.5 × 1.5 of its 2 × 2 inside the caster.
        assert_eq!(
            m[0], 0.5625,
            "the part of the box outside the caster is transparent"
        );
    }
}
