//! The contact sheet's data: every builtin swatch baked under one low light, as visibility
//! 1 − K per texel (the `ptm report` command draws each as 2×2 tiles so that a seam would show).
use ptm_bake::{bake_planes, PreparedMesh};
use ptm_format::LightSet;

use crate::study::bake_config;
use crate::Result;

/// Builtins that need no parameters (drafts need a file or rows).
pub fn names() -> Vec<&'static str> {
    ptm_swatches::NAMES
        .iter()
        .map(|n| n.0)
        .filter(|n| !matches!(*n, "draft" | "grid"))
        .collect()
}

/// One swatch of the sheet.
#[derive(Clone, Debug)]
pub struct SheetCell {
    /// Builtin name.
    pub name: &'static str,
    /// Texels across and down the tile (down: in proportion to the tile, at most `texels`).
    pub width: usize,
    /// Texels down the tile.
    pub height: usize,
    /// Row-major, `width × height`: 1 − K, or None where no surface lies under the texel.
    pub visibility: Vec<Option<f32>>,
}

/// Every parameterless builtin under one light.
#[derive(Clone, Debug)]
pub struct ContactSheet {
    /// Texels across each swatch's tile width.
    pub texels: usize,
    /// One per builtin of [`names`], in that order.
    pub cells: Vec<SheetCell>,
}

impl ContactSheet {
    /// Bakes each swatch's visibility 1 − K under a light at `elevation_deg` above the swatch
    /// plane from azimuth 30°, `texels` across the tile's width.
    pub fn bake(texels: usize, spp: u32, elevation_deg: f64) -> Result<ContactSheet> {
        let (e, a) = (elevation_deg.to_radians(), 30f64.to_radians());
        let light = LightSet::from_dirs([[e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]]);
        let mut cells = Vec::new();
        for name in names() {
            let sw = PreparedMesh::load(&format!("builtin:{name}"), None)?;
            let ny =
                ((texels as f64 * sw.tile[1] / sw.tile[0]).round() as usize).clamp(1, 4 * texels);
            let mut cfg = bake_config(texels, spp, 1);
            cfg.res = [texels, ny];
            let (planes, cov, _) = bake_planes(&sw, &light, &cfg)?;
            let height = ny.min(texels);
            let visibility = (0..height * texels)
                .map(|t| (cov[t] > 0.0).then(|| 1.0 - planes.k[0][t]))
                .collect();
            cells.push(SheetCell {
                name,
                width: texels,
                height,
                visibility,
            });
        }
        Ok(ContactSheet { texels, cells })
    }
}
