//! What a GPU bake holds, and the bands of rows it traces in: every per-sample buffer covers one
//! band, so the device's memory is bounded by the band, not the image. Bands are whole row
//! blocks of a farm shard ([`ROW_BLOCK`] rows), sized from a byte budget and the device's buffer
//! limits, and checked before anything is uploaded.
use std::ops::Range;

use crate::{Error, Result};

/// Bands start at multiples of this many rows past the traced rows' start: `ptm_fit::shard`'s
/// `ROW_BLOCK`, the farm's row block (this crate does not depend on the fit crate; the `ptm`
/// command's tests check that the two agree).
pub const ROW_BLOCK: usize = 16;

/// Bytes per footprint sample on the device: the shadow sample (origin, normal, flag: 32), its
/// position (8) and its primary hit (8).
pub const SAMPLE_BYTES: u64 = 32 + 8 + 8;

/// Largest K planes held on the host for one pass of lights (the sink gets whole planes).
pub const PASS_PLANE_BYTES: f64 = 256.0 * (1u64 << 20) as f64;

/// Most lights traced per pass over the bands.
pub const MAX_LIGHTS_PER_PASS: usize = 32;

/// Host bytes per texel and light of a pass: K, and for point lights (`point`) its (u, v).
pub fn plane_bytes(point: bool) -> u64 {
    if point {
        12
    } else {
        4
    }
}

/// Lights per pass over the bands for `width × rows` traced texels: as many as fit in
/// [`PASS_PLANE_BYTES`] of planes ([`plane_bytes`]), 1 to [`MAX_LIGHTS_PER_PASS`]. With several
/// bands, each pass uploads every band's samples again, so fewer passes upload less.
pub fn lights_per_pass(width: usize, rows: usize, point: bool) -> usize {
    let plane = width as f64 * rows as f64 * plane_bytes(point) as f64;
    (PASS_PLANE_BYTES / plane)
        .floor()
        .clamp(1.0, MAX_LIGHTS_PER_PASS as f64) as usize
}

/// What a band's buffers hold per row.
#[derive(Clone, Copy, Debug)]
pub struct Rows {
    /// Texels per row.
    pub width: usize,
    /// Footprint samples per texel.
    pub spp: u32,
    /// Lights per pass ([`lights_per_pass`]).
    pub per_pass: usize,
    /// Point lights: (u, v) planes beside K.
    pub point: bool,
}

impl Rows {
    /// Device bytes per band row: the samples' buffers and each light slot's counts (and, for
    /// point lights, (u, v)) with their readback.
    pub fn bytes(&self) -> u64 {
        self.width as u64
            * (self.spp as u64 * SAMPLE_BYTES + self.per_pass as u64 * 2 * plane_bytes(self.point))
    }
}

/// Host bytes of a GPU bake of `width × rows` texels: K planes of a pass, coverage and covered
/// counts, and (with more than one band) every band's samples kept for the next pass.
pub fn host_bytes(width: usize, rows: usize, spp: u32, bands: usize, point: bool) -> f64 {
    let texels = width as f64 * rows as f64;
    let per_pass = lights_per_pass(width, rows, point) as f64;
    let samples = if bands > 1 { 32.0 * spp as f64 } else { 0.0 };
    texels * (per_pass * plane_bytes(point) as f64 + 8.0 + samples)
}

/// The bands of image rows `rows` of `shape` within `budget` bytes and the limits `l` of the
/// device on `adapter` (described): as few as fit, each a whole number of [`ROW_BLOCK`]s but the
/// last. An error, with the figures, when even one block does not fit.
pub fn bands(
    l: &wgpu::Limits,
    adapter: &str,
    budget: u64,
    rows: Range<usize>,
    shape: &Rows,
) -> Result<Vec<Range<usize>>> {
    let &Rows {
        width,
        spp,
        per_pass,
        point,
    } = shape;
    let buffer_limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size);
    let n = rows.len();
    // The rows one band may hold under each bound, and what is measured against it.
    let row = shape.bytes();
    let samples_row = width as u64 * spp as u64 * 32;
    let counts_row = width as u64 * per_pass as u64 * plane_bytes(point);
    let checks: [(u64, u64, &'static str, &'static str); 3] = [
        (row, budget, "device memory for a band", "band budget"),
        (
            samples_row,
            buffer_limit,
            "the shadow samples' buffer",
            "max_storage_buffer_binding_size",
        ),
        (
            counts_row,
            buffer_limit,
            "the occluded counts' (or (u, v)'s) buffer",
            "max_storage_buffer_binding_size",
        ),
    ];
    let mut band = n.next_multiple_of(ROW_BLOCK);
    for &(per_row, limit, what, limit_name) in &checks {
        let fit_rows = (limit / per_row.max(1)) as usize;
        if fit_rows >= n {
            continue;
        }
        let fit = fit_rows / ROW_BLOCK * ROW_BLOCK;
        if fit == 0 {
            let smallest = ROW_BLOCK.min(n);
            return Err(Error::BandTooBig {
                rows: smallest,
                width,
                spp,
                what,
                need: per_row * smallest as u64,
                limit,
                limit_name,
                adapter: adapter.to_string(),
            });
        }
        band = band.min(fit);
    }
    Ok(rows
        .clone()
        .step_by(band)
        .map(|r| r..(r + band).min(rows.end))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_are_whole_row_blocks_within_the_budget_and_limits() {
        let l = wgpu::Limits::default();
        let shape = Rows {
            width: 64,
            spp: 4,
            per_pass: 8,
            point: false,
        };
        let row = shape.bytes();
        let bands = |budget, rows| super::bands(&l, "dev", budget, rows, &shape).unwrap();
        // Everything fits: one band, however many rows.
        assert_eq!(bands(u64::MAX, 0..64), vec![(0..64)]);
        assert_eq!(bands(row * 8, 0..8), vec![(0..8)]);
        // Two blocks' worth: bands of 32 rows; a shard's rows keep their start.
        assert_eq!(bands(row * 40, 0..64), [0..32, 32..64]);
        assert_eq!(bands(row * 16, 16..56), [16..32, 32..48, 48..56]);
        // Not even one block: refused, with the figures of one block.
        let e = super::bands(&l, "dev", row * 15, 0..64, &shape).unwrap_err();
        assert!(
            matches!(e, Error::BandTooBig { rows: 16, need, limit_name: "band budget", .. } if need == row * 16),
            "{e}"
        );
        // The device's buffer limit binds too: 16 rows of samples exceed it.
        let small = wgpu::Limits {
            max_storage_buffer_binding_size: 64 * 4 * 32 * 16 - 1,
            ..l.clone()
        };
        let e = super::bands(&small, "dev", u64::MAX, 0..64, &shape).unwrap_err();
        assert!(
            matches!(
                e,
                Error::BandTooBig {
                    limit_name: "max_storage_buffer_binding_size",
                    ..
                }
            ),
            "{e}"
        );
    }
}
