//! The contact sheet: every builtin swatch baked under one low light, each shown as 2×2 tiles
//! so that a seam would show, with its name.
use std::path::Path;

use anyhow::{Context, Result};
use plotters::prelude::*;
use ptm_bake::{bake_planes, Swatch};
use ptm_fit::LightSet;

use super::study::bake_config;

/// Builtins that need no parameters (drafts need a file or rows).
pub fn names() -> Vec<&'static str> {
    ptm_swatches::NAMES
        .iter()
        .map(|n| n.0)
        .filter(|n| !matches!(*n, "draft" | "grid"))
        .collect()
}

/// Bakes each swatch's visibility 1 − K under a light at `elevation_deg` from azimuth 30°
/// (`texels` across the tile's width) and writes the sheet to `path`.
pub fn contact_sheet(path: &Path, texels: usize, spp: u32, elevation_deg: f64) -> Result<()> {
    super::plot::register_font()?;
    let (e, a) = (elevation_deg.to_radians(), 30f64.to_radians());
    let light = LightSet::from_dirs([[e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]]);
    let names = names();
    let cell = 2 * texels;
    let (cols, label) = (4usize, 26usize);
    let rows = names.len().div_ceil(cols);
    let tmp = ptm_fit::atomic::tmp_path(path).with_extension("png");
    {
        let size = (
            (cols * (cell + 8)) as u32,
            (rows * (cell + label + 8)) as u32,
        );
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        root.fill(&WHITE)?;
        for (n, name) in names.iter().enumerate() {
            let sw = Swatch::load(&format!("builtin:{name}"), None)?;
            let ny =
                ((texels as f64 * sw.tile[1] / sw.tile[0]).round() as usize).clamp(1, 4 * texels);
            let mut cfg = bake_config(texels, spp, 1);
            cfg.res = [texels, ny];
            let (planes, cov, _) = bake_planes(&sw, &light, &cfg)?;
            let (x0, y0) = (
                (n % cols) * (cell + 8) + 4,
                (n / cols) * (cell + label + 8) + 4,
            );
            root.draw(&Text::new(
                name.to_string(),
                (x0 as i32, y0 as i32 + 4),
                ("sans-serif", 15),
            ))?;
            for ty in 0..2 {
                for j in 0..ny.min(texels) {
                    for tx in 0..2 {
                        for i in 0..texels {
                            let t = j * texels + i;
                            let c = if cov[t] > 0.0 {
                                let v = (255.0 * (1.0 - planes.k[0][t])).round() as u8;
                                RGBColor(v, v, v)
                            } else {
                                RGBColor(120, 40, 40) // no surface under this texel
                            };
                            root.draw_pixel(
                                (
                                    (x0 + tx * texels + i) as i32,
                                    (y0 + label + ty * ny.min(texels) + j) as i32,
                                ),
                                &c,
                            )?;
                        }
                    }
                }
            }
        }
        root.present()
            .with_context(|| format!("writing {}", tmp.display()))?;
    }
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
