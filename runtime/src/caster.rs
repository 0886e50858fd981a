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

impl Caster {
    /// The rectangle [x0, y0, x1, y1] on the cloth (z = 0) that the caster's shadow under a
    /// spherical light at `position` of `radius` can darken: its corners projected from the
    /// light's centre, widened by the widest penumbra. `None` when the light is not above every
    /// corner (the caster does not shadow it).
    pub fn shadow_rect(&self, position: [f32; 3], radius: f32) -> Option<[f32; 4]> {
        self.corner_bounds(|x, y, z| {
            let above = position[2] - z;
            if above.is_nan() || above <= 0.0 {
                return None;
            }
            let t = position[2] / above;
            let spread = radius.max(0.0) * z.max(0.0) / above;
            let hit = [
                position[0] + (x - position[0]) * t,
                position[1] + (y - position[1]) * t,
            ];
            Some((hit, spread))
        })
    }

    /// As [`Caster::shadow_rect`] for a distant light in unit direction `dir` at elevation e
    /// whose angular radius ρ has sine `sin_radius`: each corner projected along `dir`, widened
    /// by how far its cone's other directions reach on the cloth, z·(cot(e − ρ) − cot e) down
    /// the slope plus z·cot(e − ρ) times the widest azimuth turn, asin(sin ρ/cos e), across.
    /// `None` when the light is not above the horizon, or its cone reaches within a degree of
    /// it (the shadow then has no useful bound).
    pub fn shadow_rect_distant(&self, dir: [f32; 3], sin_radius: f32) -> Option<[f32; 4]> {
        let e = dir[2].clamp(-1.0, 1.0).asin();
        let rho = sin_radius.clamp(0.0, 1.0).asin();
        if e.is_nan() || e - rho < 1f32.to_radians() {
            return None;
        }
        let cot = |a: f32| a.cos() / a.sin();
        let turn = (sin_radius.max(0.0) / e.cos().max(1e-6)).min(1.0).asin();
        self.corner_bounds(|x, y, z| {
            let z = z.max(0.0);
            let along = z / dir[2];
            let spread = z * (cot(e - rho) - cot(e)) + z * cot(e - rho) * turn;
            Some(([x - along * dir[0], y - along * dir[1]], spread))
        })
    }

    /// The bounds of the caster's four (tilted) corners' shadows: `shadow(x, y, z)` gives a
    /// corner's point on the cloth and its spread, or `None` when it casts none (then so does
    /// the caster).
    fn corner_bounds(
        &self,
        shadow: impl Fn(f32, f32, f32) -> Option<([f32; 2], f32)>,
    ) -> Option<[f32; 4]> {
        let [x0, y0, x1, y1] = self.rect;
        let (cy, hh) = (0.5 * (y0 + y1), 0.5 * (y1 - y0));
        let (s, c) = self.tilt_deg.to_radians().sin_cos();
        let mut out = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        for x in [x0, x1] {
            for side in [-1.0f32, 1.0] {
                let (y, z) = (cy + side * hh * c, self.elevation + side * hh * s);
                let (hit, spread) = shadow(x, y, z)?;
                out = [
                    out[0].min(hit[0] - spread),
                    out[1].min(hit[1] - spread),
                    out[2].max(hit[0] + spread),
                    out[3].max(hit[1] + spread),
                ];
            }
        }
        Some(out)
    }
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

/// A glossy scene's caster image: premultiplied linear colour and opacity per texel,
/// `α·rgb | α << 24` (rgb sRGB-decoded, each channel rounded to the nearest 1/255), so the
/// blur's mean over a kernel is mean(α·rgb) and mean α (`glossy_reflection`), and α alone
/// casts the shadows.
pub fn reflection_texels(rgba: &[[u8; 4]]) -> Vec<u32> {
    rgba.iter()
        .map(|p| {
            let a = p[3] as f32 / 255.0;
            let c = [0, 1, 2].map(|k| {
                let lin = crate::output::srgb_decode(p[k] as f32 / 255.0);
                (a * lin * 255.0).round().clamp(0.0, 255.0) as u32
            });
            c[0] | (c[1] << 8) | (c[2] << 16) | ((p[3] as u32) << 24)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shadow_rectangle_is_the_projected_caster_widened_by_the_penumbra() {
        let c = Caster {
            width: 1,
            height: 1,
            rgba: vec![[0, 0, 0, 255]],
            rect: [-0.5, -0.5, 0.5, 0.5],
            elevation: 1.0,
            tilt_deg: 0.0,
        };
        // Light at height 2 over the centre: the shadow is twice the caster; the penumbra of a
        // sphere of radius 0.1 adds 0.1·1/(2 − 1) on each side.
        assert_eq!(
            c.shadow_rect([0.0, 0.0, 2.0], 0.0),
            Some([-1.0, -1.0, 1.0, 1.0])
        );
        assert_eq!(
            c.shadow_rect([0.0, 0.0, 2.0], 0.1),
            Some([-1.1, -1.1, 1.1, 1.1])
        );
        // Off to +x at height 2: the shadow is thrown to −x.
        let s = c.shadow_rect([4.0, 0.0, 2.0], 0.0).unwrap();
        assert_eq!(s, [-5.0, -1.0, -3.0, 1.0]);
        // A light on or below the caster plane is not shadowed by it.
        assert_eq!(c.shadow_rect([0.0, 0.0, 1.0], 0.0), None);
    }
}
