//! Twin of `shader/sat.wgsl`: the summed-area table of the caster opacity as u32 counts, same
//! names and (wrapping) arithmetic. A WGSL entry point runs one thread; its twin runs every
//! thread in order.
//!
//! Why integers: an f32 table of 8-bit alpha at 4096² loses 1e-3–1e-2 in box means (large
//! nearly equal corners cancel); u32 counts are exact, and because u32 arithmetic wraps, the
//! 4-corner difference is exact for any box whose true sum is below 2³² — every box up to
//! 4096×4096 texels of 8-bit data — even when the table's total overflows.

use crate::layout::SatParams;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::shade::blur_sat;

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
}
