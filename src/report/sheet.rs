//! The contact sheet: every builtin swatch's visibility 1 − K under one low light (baked by
//! `ptm_report::ContactSheet`), each shown as 2×2 tiles so that a seam would show, with its name.
use anyhow::{Context, Result};
use plotters::prelude::*;
use ptm_report::ContactSheet;

/// Draws `sheet` as a PNG; returns its bytes.
pub fn contact_sheet(sheet: &ContactSheet) -> Result<Vec<u8>> {
    super::plot::register_font()?;
    let texels = sheet.texels;
    let cell = 2 * texels;
    let (cols, label) = (4usize, 26usize);
    let rows = sheet.cells.len().div_ceil(cols);
    let size = (
        (cols * (cell + 8)) as u32,
        (rows * (cell + label + 8)) as u32,
    );
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
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
        root.present().context("drawing the contact sheet")?;
    }
    super::plot::png_bytes(size, rgb)
}
