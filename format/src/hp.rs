//! Export to HP's PTM 1.2 file format as `PTM_FORMAT_LRGB`, the format RTI viewers read.
//!
//! The luminance polynomial encodes the visibility V = 1 − K in HP's coefficient order
//! (a0..a5 = u², v², uv, u, v, 1; ours is u², u, uv, v, v², 1), in units where 255 leaves the
//! stored RGB unchanged (colour = L(u, v)/255 · RGB). Each coefficient plane is quantised to 8
//! bits with one scale and bias for the whole image: a = scale · (byte − bias). Rows are written
//! bottom to top (HP's "reversed scanline order"); our row 0 is the top (y = H), so the file's
//! first row is our last. Layout: ASCII header `PTM_1.2`, `PTM_FORMAT_LRGB`, width, height,
//! 6 scales, 6 biases (one token group per line), then 6 bytes per texel (a0..a5), then 3 bytes
//! per texel (R, G, B).
use std::path::Path;

use crate::{Basis, Error, Ptm, Result};

/// HP slot i takes our ptm6 coefficient `HP_FROM_PTM6[i]`.
pub const HP_FROM_PTM6: [usize; 6] = [0, 4, 2, 1, 3, 5];

/// What the export wrote and the error its 8-bit quantisation adds.
#[derive(Clone, Debug, PartialEq)]
pub struct HpExport {
    /// Per-coefficient scale of the 8-bit quantisation (HP's `scale` line), in HP slot order.
    pub scales: [f32; 6],
    /// Per-coefficient bias of the quantisation (HP's `bias` line), in HP slot order.
    pub biases: [i32; 6],
    /// Max over texels of Σ|a − dequantised a| / 255: a bound on the change of V (= of K)
    /// anywhere on the unit disk (every term is at most 1 in magnitude there).
    pub max_error: f64,
    /// Mean over texels of the same bound.
    pub mean_error: f64,
}

/// Writes `ptm` (ptm6 only) as an HP PTM 1.2 LRGB file, atomically. `rgb`, when given, is the
/// per-texel albedo in our row order; otherwise the RGB block is white.
pub fn write_hp_lrgb(ptm: &Ptm, path: &Path, rgb: Option<&[[u8; 3]]>) -> Result<HpExport> {
    let (bytes, export) = encode_hp_lrgb(ptm, path, rgb)?;
    crate::atomic::write_bytes(path, &bytes)?;
    Ok(export)
}

/// The bytes [`write_hp_lrgb`] writes (`path` names the file in errors only), to stage in an
/// [`atomic::Transaction`](crate::atomic::Transaction).
pub fn encode_hp_lrgb(
    ptm: &Ptm,
    path: &Path,
    rgb: Option<&[[u8; 3]]>,
) -> Result<(Vec<u8>, HpExport)> {
    ptm.validate()?;
    if ptm.basis != Basis::Ptm6 {
        return Err(Error::HpNeedsPtm6 {
            path: path.display().to_string(),
            basis: ptm.basis,
        });
    }
    let (w, h) = (ptm.width, ptm.height);
    let n = w * h;
    if let Some(rgb) = rgb {
        if rgb.len() != n {
            return Err(Error::Invalid(format!(
                "albedo has {} texels, the PTM {n}",
                rgb.len()
            )));
        }
    }
    // HP coefficients of 255·(1 − K).
    let hp = |slot: usize, t: usize| -> f64 {
        let c = ptm.planes[HP_FROM_PTM6[slot]][t] as f64;
        if slot == 5 {
            255.0 * (1.0 - c)
        } else {
            -255.0 * c
        }
    };
    let mut scales = [0f32; 6];
    let mut biases = [0i32; 6];
    for slot in 0..6 {
        // The range includes 0 so the bias is a byte value (0..=255), as readers expect.
        let (lo, hi) = (0..n).fold((0f64, 0f64), |(lo, hi), t| {
            let a = hp(slot, t);
            (lo.min(a), hi.max(a))
        });
        let scale = if hi > lo { (hi - lo) / 255.0 } else { 1.0 };
        scales[slot] = scale as f32;
        biases[slot] = (-lo / scale).round().clamp(0.0, 255.0) as i32;
    }
    let quant = |slot: usize, a: f64| -> u8 {
        (a / scales[slot] as f64 + biases[slot] as f64)
            .round()
            .clamp(0.0, 255.0) as u8
    };
    let mut coeff_bytes = Vec::with_capacity(n * 6);
    let mut rgb_bytes = Vec::with_capacity(n * 3);
    let (mut max_error, mut sum_error) = (0f64, 0f64);
    for row in (0..h).rev() {
        for col in 0..w {
            let t = row * w + col;
            let mut err = 0.0;
            for slot in 0..6 {
                let a = hp(slot, t);
                let b = quant(slot, a);
                coeff_bytes.push(b);
                err += (scales[slot] as f64 * (b as f64 - biases[slot] as f64) - a).abs();
            }
            let err = err / 255.0;
            max_error = max_error.max(err);
            sum_error += err;
            rgb_bytes.extend_from_slice(&rgb.map_or([255, 255, 255], |c| c[t]));
        }
    }
    let mut header = format!("PTM_1.2\nPTM_FORMAT_LRGB\n{w}\n{h}\n");
    // Plain decimals (Rust prints the shortest exact form, never an exponent): every reader parses them.
    header += &scales.map(|s| format!("{s}")).join(" ");
    header += "\n";
    header += &biases.map(|b| b.to_string()).join(" ");
    header += "\n";
    let mut bytes = header.into_bytes();
    bytes.extend_from_slice(&coeff_bytes);
    bytes.extend_from_slice(&rgb_bytes);
    Ok((
        bytes,
        HpExport {
            scales,
            biases,
            max_error,
            mean_error: sum_error / n as f64,
        },
    ))
}
