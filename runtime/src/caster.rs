//! The planar caster: its image and placement, and its opacity as the shaders read it (8-bit
//! counts per channel, packed), box-downsampled when a side exceeds what a u32 summed-area
//! table sums exactly.

/// Largest caster side kept as is. A u32 summed-area table of 8-bit opacity gives exact box sums
/// for any box up to 4096×4096 texels (4096²·255 < 2³²); larger casters are box-downsampled by
/// an integer factor first and the factor is reported.
pub const MAX_CASTER_SIDE: usize = 4096;

/// A planar RGBA caster above the acceptor, parallel to it or tilted about the line through its
/// centre parallel to X.
#[derive(Clone, Debug, PartialEq)]
pub struct Caster {
    /// Texels per row.
    pub width: usize,
    /// Rows; row 0 is the far edge (largest y), as for every image in ptm.
    pub height: usize,
    /// Straight (non-premultiplied) sRGB-encoded RGBA8, row-major.
    pub rgba: Vec<[u8; 4]>,
    /// World rectangle [x0, y0, x1, y1] the caster image covers.
    pub rect: [f32; 4],
    /// Height of the caster plane above the acceptor (d_ca, swatch units, ≥ 0); with a tilt, the
    /// height of its centre line.
    pub elevation: f32,
    /// Rotation in degrees about the caster's centre line parallel to X (|tilt| < 90): positive
    /// lifts the far (+Y) edge. The image keeps its size; `rect` is the untilted footprint.
    pub tilt_deg: f32,
}

/// Box-downsamples a caster whose larger side exceeds [`MAX_CASTER_SIDE`] by the smallest
/// integer factor that fits; returns (width, height, texels, factor).
pub fn fit_caster(c: &Caster) -> (usize, usize, Vec<[u8; 4]>, usize) {
    let factor = c.width.max(c.height).div_ceil(MAX_CASTER_SIDE);
    if factor <= 1 {
        return (c.width, c.height, c.rgba.clone(), 1);
    }
    let (w, h) = (c.width.div_ceil(factor), c.height.div_ceil(factor));
    let mut out = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let mut sum = [0u32; 4];
            let mut n = 0u32;
            for y in j * factor..((j + 1) * factor).min(c.height) {
                for x in i * factor..((i + 1) * factor).min(c.width) {
                    let p = c.rgba[y * c.width + x];
                    for k in 0..4 {
                        sum[k] += p[k] as u32;
                    }
                    n += 1;
                }
            }
            out.push(sum.map(|s| ((s + n / 2) / n) as u8));
        }
    }
    (w, h, out, factor)
}

/// Caster opacity per channel as 8-bit integers (exact in a u32 summed-area table).
/// Grey: o = α. Coloured: o_c = α·(1 − rgb_c), so an opaque red pane passes red light only;
/// rgb is taken as stored (its transmittance), quantised to the nearest 1/255.
pub fn opacity_texels(rgba: &[[u8; 4]], colored: bool) -> Vec<u32> {
    rgba.iter()
        .map(|p| {
            let a = p[3] as u32;
            let o = if colored {
                [0, 1, 2].map(|c| (a * (255 - p[c] as u32) + 127) / 255)
            } else {
                [a; 3]
            };
            o[0] | (o[1] << 8) | (o[2] << 16)
        })
        .collect()
}
