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
}
