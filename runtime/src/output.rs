//! Rendered images: linear float RGBA in memory, written as an sRGB PNG with an exposure
//! setting or as a linear float EXR, atomically.

use std::path::Path;

use crate::{Error, Result};

/// Linear radiance, row-major, row 0 at the top of the picture (the far edge y1 of the view).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Linear rgba per pixel.
    pub pixels: Vec<[f32; 4]>,
}

/// sRGB transfer function of a linear value in [0, 1].
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse sRGB transfer function (8-bit texture values to linear).
pub fn srgb_decode(x: f32) -> f32 {
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

impl Image {
    /// Largest |a − b| over all pixels and RGB channels; `None` if the sizes differ.
    pub fn max_abs_diff(&self, other: &Image) -> Option<f32> {
        if (self.width, self.height) != (other.width, other.height) {
            return None;
        }
        let mut m = 0f32;
        for (a, b) in self.pixels.iter().zip(&other.pixels) {
            for c in 0..3 {
                m = m.max((a[c] - b[c]).abs());
            }
        }
        Some(m)
    }

    /// Tiles `images` (all the same size) left to right, top to bottom, `columns` per row;
    /// unused cells stay black.
    pub fn contact_sheet(images: &[Image], columns: usize) -> Option<Image> {
        let first = images.first()?;
        let (w, h) = (first.width, first.height);
        if images.iter().any(|i| (i.width, i.height) != (w, h)) || columns == 0 {
            return None;
        }
        let rows = images.len().div_ceil(columns);
        let width = w * columns;
        let mut pixels = vec![[0.0, 0.0, 0.0, 1.0]; width * h * rows];
        for (n, img) in images.iter().enumerate() {
            let (cx, cy) = (n % columns, n / columns);
            for y in 0..h {
                let dst = (cy * h + y) * width + cx * w;
                pixels[dst..dst + w].copy_from_slice(&img.pixels[y * w..(y + 1) * w]);
            }
        }
        Some(Image {
            width,
            height: h * rows,
            pixels,
        })
    }

    /// A turntable sheet: `frames` (all the same size) in a grid of [`sheet_columns`] columns,
    /// each under a strip with its label (`labels[i]`, digits and `°` drawn in a 3×5 pixel
    /// font scaled with the frame), separated and framed by grey gutters so that adjacent
    /// frames read as separate pictures; cells without a frame are gutter-grey, not black.
    /// `None` when the frames differ in size or there are none.
    pub fn labelled_sheet(frames: &[Image], labels: &[String]) -> Option<Image> {
        let first = frames.first()?;
        let (w, h) = (first.width, first.height);
        if frames.iter().any(|i| (i.width, i.height) != (w, h)) {
            return None;
        }
        let l = sheet_layout(frames.len(), w, h);
        let mut pixels = vec![SHEET_GUTTER; l.width * l.height];
        for (n, img) in frames.iter().enumerate() {
            let (x0, y0) = l.cell(n);
            for y in 0..l.strip {
                pixels[(y0 + y) * l.width + x0..][..w].fill(SHEET_STRIP);
            }
            let text = labels.get(n).map_or("", String::as_str);
            draw_label(
                &mut pixels,
                l.width,
                (x0 + 2 * l.scale, y0 + l.scale),
                l.scale,
                text,
            );
            for y in 0..h {
                let dst = (y0 + l.strip + y) * l.width + x0;
                pixels[dst..dst + w].copy_from_slice(&img.pixels[y * w..(y + 1) * w]);
            }
        }
        Some(Image {
            width: l.width,
            height: l.height,
            pixels,
        })
    }

    /// 8-bit sRGB RGBA: linear × 2^exposure, clamped, encoded; alpha 255.
    pub fn to_srgb8(&self, exposure: f32) -> Vec<u8> {
        let scale = exposure.exp2();
        let mut out = Vec::with_capacity(self.pixels.len() * 4);
        for p in &self.pixels {
            for &c in &p[..3] {
                out.push((srgb_encode(c * scale) * 255.0 + 0.5) as u8);
            }
            out.push(255);
        }
        out
    }

    /// Writes an sRGB PNG (see [`Image::to_srgb8`]) atomically.
    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<()> {
        write_png_rgba8(path, self.width, self.height, &self.to_srgb8(exposure))
    }

    /// Writes the linear radiance as an RGB f32 EXR atomically.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        use exr::prelude::*;
        // A failed EXR write publishes nothing (the temporary file is removed).
        ptm_format::atomic::write_path(path, |tmp| {
            write_rgb_file(tmp, self.width, self.height, |x, y| {
                let p = self.pixels[y * self.width + x];
                (p[0], p[1], p[2])
            })
            .map_err(|e| crate::Error::Image {
                path: path.display().to_string(),
                reason: e.to_string(),
            })
        })
    }
}

/// Writes 8-bit RGBA pixels as a PNG atomically.
pub fn write_png_rgba8(path: &Path, width: usize, height: usize, rgba: &[u8]) -> Result<()> {
    let img = image::RgbaImage::from_raw(width as u32, height as u32, rgba.to_vec()).ok_or_else(
        || Error::Image {
            path: path.display().to_string(),
            reason: format!(
                "{} bytes do not make a {width}×{height} RGBA image",
                rgba.len()
            ),
        },
    )?;
    ptm_format::atomic::write_atomic(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// Reads a PNG (or any format the `image` crate was built with) as 8-bit RGBA.
pub fn read_rgba8(path: &Path) -> Result<(usize, usize, Vec<[u8; 4]>)> {
    let img = image::open(path).map_err(|e| Error::Image {
        path: path.display().to_string(),
        reason: match e {
            // The decoder's allocation limit (512 MB), not the bit depth, refused it.
            image::ImageError::Limits(_) => {
                let size = image::ImageReader::open(path)
                    .ok()
                    .and_then(|r| r.with_guessed_format().ok())
                    .and_then(|r| r.into_dimensions().ok())
                    .map_or("its".into(), |(w, h)| format!("its {w}×{h}"));
                format!(
                    "{size} pixels need more than the decoder's 512 MB: downscale the image \
                     (a caster is blurred over its penumbra anyway; 4096×4096 is plenty)"
                )
            }
            e => format!("{e}; give an 8-bit PNG"),
        },
    })?;
    let rgba = img.to_rgba8();
    let (w, h) = rgba.dimensions();
    let texels = rgba.pixels().map(|p| p.0).collect();
    Ok((w as usize, h as usize, texels))
}

/// Linear colour of a turntable sheet's gutters and empty cells (mid grey).
pub const SHEET_GUTTER: [f32; 4] = [0.18, 0.18, 0.18, 1.0];
/// Linear colour of the label strip above each frame.
pub const SHEET_STRIP: [f32; 4] = [0.02, 0.02, 0.02, 1.0];
/// Linear colour of the label text.
pub const SHEET_TEXT: [f32; 4] = [1.0, 1.0, 1.0, 1.0];

/// Columns of a sheet of `n` frames: from ⌈√n⌉ up to twice that, the first that fills every
/// cell (8 → 4×2, 6 → 3×2, 5 → 5×1), else the one that leaves the fewest empty (7 → 4×2).
pub fn sheet_columns(n: usize) -> usize {
    let base = (1..=n.max(1)).find(|c| c * c >= n).unwrap_or(1);
    let empty = |c: usize| c * n.div_ceil(c) - n;
    (base..=(2 * base).min(n.max(1)))
        .min_by_key(|&c| (empty(c), c))
        .unwrap_or(1)
}

/// Where a labelled sheet puts its frames (pixels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SheetLayout {
    /// Frames per row.
    pub columns: usize,
    /// Rows of frames.
    pub rows: usize,
    /// Gutter between cells and around the sheet.
    pub gutter: usize,
    /// Height of the label strip above each frame.
    pub strip: usize,
    /// Pixels per font pixel of the labels.
    pub scale: usize,
    /// One frame's width and height.
    pub frame: [usize; 2],
    /// The sheet's width.
    pub width: usize,
    /// The sheet's height.
    pub height: usize,
}

impl SheetLayout {
    /// Top-left pixel of cell `n` (its label strip; the frame starts `strip` rows below).
    pub fn cell(&self, n: usize) -> (usize, usize) {
        let (cx, cy) = (n % self.columns, n / self.columns);
        (
            self.gutter + cx * (self.frame[0] + self.gutter),
            self.gutter + cy * (self.strip + self.frame[1] + self.gutter),
        )
    }
}

/// The layout of a labelled sheet of `n` frames of `w`×`h`: gutters of 1/32 of the frame's
/// shorter side (at least 2 pixels), label font pixels of 1/96 of it (at least 1).
pub fn sheet_layout(n: usize, w: usize, h: usize) -> SheetLayout {
    let columns = sheet_columns(n);
    let rows = n.max(1).div_ceil(columns);
    let short = w.min(h);
    let gutter = (short / 32).max(2);
    let scale = (short / 96).max(1);
    let strip = 7 * scale;
    SheetLayout {
        columns,
        rows,
        gutter,
        strip,
        scale,
        frame: [w, h],
        width: columns * w + (columns + 1) * gutter,
        height: rows * (strip + h) + (rows + 1) * gutter,
    }
}

/// 3×5 glyphs (rows top down, bit 2 the left column) of the digits and `°`; other characters
/// are drawn as a space.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '°' => [7, 5, 7, 0, 0],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        _ => [0; 5],
    }
}

/// Draws `text` with its top-left at `at` into a sheet `width` pixels wide, `scale` pixels per
/// font pixel, clipped to the sheet.
fn draw_label(pixels: &mut [[f32; 4]], width: usize, at: (usize, usize), scale: usize, text: &str) {
    let height = pixels.len() / width;
    for (i, c) in text.chars().enumerate() {
        let g = glyph(c);
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let x = at.0 + (4 * i + col) * scale + dx;
                        let y = at.1 + row * scale + dy;
                        if x < width && y < height {
                            pixels[y * width + x] = SHEET_TEXT;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_exr_write_publishes_nothing() {
        let dir = std::env::temp_dir().join(format!("ptm-runtime-output-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("render.exr");
        let one = Image {
            width: 2,
            height: 1,
            pixels: vec![[0.5, 0.25, 1.0, 1.0]; 2],
        };
        one.write_exr(&p).unwrap();
        let good = std::fs::read(&p).unwrap();
        // An empty image is no EXR: the write fails, the old file stays, no temporary is left.
        let empty = Image {
            width: 0,
            height: 0,
            pixels: Vec::new(),
        };
        assert!(empty.write_exr(&p).is_err());
        assert_eq!(std::fs::read(&p).unwrap(), good);
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["render.exr"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_sheet_fills_its_grid_and_separates_its_frames() {
        let cols: Vec<usize> = (1..=9).map(sheet_columns).collect();
        assert_eq!(cols, [1, 2, 3, 2, 5, 3, 4, 4, 3]);
        assert_eq!(sheet_columns(12), 4);
        // 8 white 40×30 frames: 4×2 cells, gutters of 2, strips of 7.
        let frame = Image {
            width: 40,
            height: 30,
            pixels: vec![[1.0, 1.0, 1.0, 1.0]; 1200],
        };
        let labels: Vec<String> = (0..8).map(|k| format!("{}°", 45 * k)).collect();
        let sheet = Image::labelled_sheet(&vec![frame; 8], &labels).unwrap();
        let l = sheet_layout(8, 40, 30);
        assert_eq!((l.columns, l.rows, l.gutter, l.strip), (4, 2, 2, 7));
        assert_eq!(
            (sheet.width, sheet.height),
            (4 * 40 + 5 * 2, 2 * 37 + 3 * 2)
        );
        let at = |x: usize, y: usize| sheet.pixels[y * sheet.width + x];
        for n in 0..8 {
            let (x0, y0) = l.cell(n);
            // The gutter left of and above each cell is grey; the frame starts below its strip.
            assert_eq!(at(x0 - 1, y0 + 10), SHEET_GUTTER);
            assert_eq!(at(x0 + 5, y0 - 1), SHEET_GUTTER);
            assert_eq!(at(x0, y0 + l.strip), [1.0; 4]);
            // Each strip holds its label: as many lit pixels as the glyphs have.
            let lit: usize = (y0..y0 + l.strip)
                .flat_map(|y| (x0..x0 + 40).map(move |x| (x, y)))
                .filter(|&(x, y)| at(x, y) == SHEET_TEXT)
                .count();
            let want: u32 = labels[n]
                .chars()
                .map(|c| glyph(c).iter().map(|b| b.count_ones()).sum::<u32>())
                .sum();
            assert_eq!(lit as u32, want, "label {}", labels[n]);
        }
        // Different labels draw differently.
        let strip = |n: usize| {
            let (x0, y0) = l.cell(n);
            (y0..y0 + l.strip)
                .flat_map(|y| (x0..x0 + 40).map(move |x| (x, y)))
                .map(|(x, y)| at(x, y)[0] > 0.5)
                .collect::<Vec<_>>()
        };
        assert_ne!(strip(1), strip(2));
    }
}
