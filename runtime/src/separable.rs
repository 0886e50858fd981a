//! The plan of the separable blur of the caster opacity: per light, a horizontal then a vertical
//! box pass of half-side w (texels) with running sums (`shader/separable.wgsl`, twin
//! `cpu/separable.rs`), over a map padded by the largest radius so the penumbra can extend past
//! the caster's edge.
//!
//! For a caster parallel to the cloth w = R·d_ca/(d_lc + d_ca) is the same for every acceptor
//! pixel, so one pre-blurred map per light is exact for the box kernel (a tilted caster would
//! need the spatially varying passes of US 7,982,734).

use crate::layout::{Frame, LightGpu, SepParams};

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

/// Radii per light as `light_opacity` computes them; margins cover the largest (capped at the
/// caster's own size: beyond that the map is nearly uniform and treated as transparent).
pub fn plan(f: &Frame, lights: &[LightGpu]) -> Plan {
    let [w, h] = f.caster_size;
    let texel = [
        (f.caster_rect[2] - f.caster_rect[0]) / w as f32,
        (f.caster_rect[3] - f.caster_rect[1]) / h as f32,
    ];
    let radii: Vec<[f32; 2]> = lights
        .iter()
        .map(|l| {
            let (lz, r) = (l.position[2], l.radius);
            let hgt = f.caster_height;
            let active = lz > hgt;
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
