//! The contact sheet: every builtin swatch's visibility 1 − K under one low light (baked by
//! `ptm_report::ContactSheet`), each shown as 2×2 tiles so that a seam would show, with its name.
use std::path::Path;

use anyhow::{Context, Result};
use plotters::prelude::*;
use ptm_report::ContactSheet;

/// Draws `sheet` into the PNG `path` (atomically).
pub fn contact_sheet(path: &Path, sheet: &ContactSheet) -> Result<()> {
    super::plot::register_font()?;
    let texels = sheet.texels;
    let cell = 2 * texels;
    let (cols, label) = (4usize, 26usize);
    let rows = sheet.cells.len().div_ceil(cols);
    let tmp = ptm_fit::atomic::tmp_path(path).with_extension("png");
    {
        let size = (
            (cols * (cell + 8)) as u32,
            (rows * (cell + label + 8)) as u32,
        );
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        root.fill(&WHITE)?;
        for (n, c) in sheet.cells.iter().enumerate() {
            let (x0, y0) = (
                (n % cols) * (cell + 8) + 4,
                (n / cols) * (cell + label + 8) + 4,
            );
            root.draw(&Text::new(
                c.name.to_string(),
                (x0 as i32, y0 as i32 + 4),
                ("sans-serif", 15),
            ))?;
            for ty in 0..2 {
                for j in 0..c.height {
                    for tx in 0..2 {
                        for i in 0..c.width {
                            let color = match c.visibility[j * c.width + i] {
                                Some(v) => {
                                    let v = (255.0 * v).round() as u8;
                                    RGBColor(v, v, v)
                                }
                                None => RGBColor(120, 40, 40), // no surface under this texel
                            };
                            root.draw_pixel(
                                (
                                    (x0 + tx * c.width + i) as i32,
                                    (y0 + label + ty * c.height + j) as i32,
                                ),
                                &color,
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
