//! Image stacks rendered or photographed elsewhere (RTI convention): one PNG or JPEG per light,
//! white = lit, so K = 1 − luminance; light directions from an `.lp` file.
//!
//! Photographs and RTIBuilder exports are 8-bit sRGB: their values are decoded to linear light
//! before K = 1 − value (a lit texel at sRGB 0.5 sees 21 % of the light, not 50 %), unless the
//! caller keeps the raw values. 16-bit and float images are taken as linear.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::{Diagnostic, Error, Result, SampleStack};
use ptm_format::LightSet;

/// How 8-bit image values become visibility before K = 1 − visibility.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoding {
    /// 8-bit values are sRGB-encoded: decoded to linear first (the default).
    Srgb,
    /// Values are taken as they are (already linear, or the caller wants the raw numbers).
    Raw,
}

impl Decoding {
    /// `"srgb"` or `"raw"`, as reports and headers spell it.
    pub fn name(self) -> &'static str {
        match self {
            Decoding::Srgb => "srgb",
            Decoding::Raw => "raw",
        }
    }
}

/// What [`read_image_stack`] found beside the stack.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageStackInfo {
    /// Images the pattern matched that the `.lp` does not list (ignored).
    pub unused: Vec<PathBuf>,
    /// Images whose 8-bit values were decoded from sRGB (0 with [`Decoding::Raw`]).
    pub srgb_decoded: usize,
    /// Images taken as linear values (16-bit or float, or all of them with [`Decoding::Raw`]).
    pub linear: usize,
}

impl ImageStackInfo {
    /// What the fit should warn of the stack read with the `.lp` file `lp`: the images it does
    /// not list, by file name.
    pub fn warnings(&self, lp: &Path) -> Vec<Diagnostic> {
        if self.unused.is_empty() {
            return Vec::new();
        }
        let images = self
            .unused
            .iter()
            .map(|p| {
                p.file_name()
                    .unwrap_or(p.as_os_str())
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        vec![Diagnostic::UnusedImages {
            lp: lp.display().to_string(),
            images,
        }]
    }
}

/// The file-name part of an `.lp` entry: RTIBuilder writes Windows paths
/// (`C:\Users\…\IMG_0001.JPG`), so both separators end a directory.
pub fn lp_file_name(entry: &str) -> &str {
    entry.rsplit(['/', '\\']).next().unwrap_or(entry)
}

/// Builds a sample stack from the images matching `pattern` (a glob such as `dir/*.png`) and
/// the lights of the `.lp` file `lp`. Each `.lp` entry is matched to the image with the same
/// file name (directories in the entry, `/` or `\`, are ignored), or, when no name matches
/// exactly, to the one image whose name matches ignoring case. Two matched images with one
/// name (from two folders) are refused: which one the entry means is unknown. Image row 0 is
/// the top of the image = the far edge y = H; `tile` is the tile size (W, H).
pub fn read_image_stack(
    pattern: &str,
    lp: &Path,
    tile: [f64; 2],
    decoding: Decoding,
) -> Result<(SampleStack, ImageStackInfo)> {
    let lights = LightSet::read_lp(lp)?;
    // On the horizon (z = 0) is a grazing light the fit leaves out; below it is a sign error.
    let below: Vec<_> = lights
        .below_horizon()
        .into_iter()
        .filter(|l| lights.dirs[l.index][2] < 0.0)
        .collect();
    if !below.is_empty() {
        return Err(Error::LightsBelowHorizon {
            lp: lp.display().to_string(),
            of: lights.len(),
            lights: below,
        });
    }
    let paths = glob::glob(pattern).map_err(|e| images(pattern, format!("bad pattern: {e}")))?;
    let mut by_name: HashMap<String, PathBuf> = HashMap::new();
    for p in paths {
        let p = p.map_err(|e| images(pattern, e.to_string()))?;
        if let Some(name) = p.file_name() {
            let name = name.to_string_lossy().into_owned();
            if let Some(first) = by_name.get(&name) {
                return Err(images(
                    pattern,
                    format!(
                        "matches {} and {}, both named {name:?}: the .lp names images by file \
                         name only; give a pattern that matches one folder",
                        first.display(),
                        p.display()
                    ),
                ));
            }
            by_name.insert(name, p);
        }
    }
    if by_name.is_empty() {
        return Err(images(pattern, "matches no file".into()));
    }
    let mut k = Vec::with_capacity(lights.len());
    let (mut width, mut height) = (0, 0);
    let mut info = ImageStackInfo {
        unused: Vec::new(),
        srgb_decoded: 0,
        linear: 0,
    };
    let srgb_table: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f32 / 255.0)).collect();
    for (i, name) in lights.names.iter().enumerate() {
        let base = lp_file_name(name);
        let key = match by_name.contains_key(base) {
            true => base.to_string(),
            false => {
                let lower = base.to_lowercase();
                let mut hits = by_name.keys().filter(|n| n.to_lowercase() == lower);
                match (hits.next(), hits.next()) {
                    (Some(n), None) => n.clone(),
                    (Some(a), Some(b)) => {
                        return Err(images(
                            pattern,
                            format!(
                                "light {i} of {} names {name:?}: no file has that name, but both \
                                 {a:?} and {b:?} match it ignoring case: rename one",
                                lp.display()
                            ),
                        ))
                    }
                    _ => {
                        return Err(images(
                            pattern,
                            format!(
                                "light {i} of {} names {name:?}, which matches no file",
                                lp.display()
                            ),
                        ))
                    }
                }
            }
        };
        let path = by_name.remove(&key).expect("key found above");
        let img = image::open(&path).map_err(|e| Error::Format {
            path: path.display().to_string(),
            reason: format!("cannot read the image (PNG 8 or 16 bit, or JPEG): {e}"),
        })?;
        let eight_bit = matches!(
            img,
            image::DynamicImage::ImageLuma8(_)
                | image::DynamicImage::ImageLumaA8(_)
                | image::DynamicImage::ImageRgb8(_)
                | image::DynamicImage::ImageRgba8(_)
        );
        let (w, h) = (img.width() as usize, img.height() as usize);
        if i == 0 {
            (width, height) = (w, h);
        } else if (w, h) != (width, height) {
            return Err(Error::Format {
                path: path.display().to_string(),
                reason: format!("image is {w}×{h}, the first image {width}×{height}"),
            });
        }
        let plane: Vec<f32> = if eight_bit && decoding == Decoding::Srgb {
            // Linear luminance of the decoded channels (Rec. 709 weights), as to_luma32f
            // weighs the raw ones.
            info.srgb_decoded += 1;
            let rgb = img.to_rgb8();
            rgb.pixels()
                .map(|p| {
                    let [r, g, b] = p.0.map(|c| srgb_table[c as usize]);
                    1.0 - (0.2126 * r + 0.7152 * g + 0.0722 * b).clamp(0.0, 1.0)
                })
                .collect()
        } else {
            info.linear += 1;
            img.to_luma32f()
                .into_raw()
                .into_iter()
                .map(|l| 1.0 - l)
                .collect()
        };
        k.push(plane);
    }
    info.unused = by_name.into_values().collect();
    info.unused.sort();
    let stack = SampleStack::new(lights, width, height, tile, k);
    stack.validate()?;
    Ok((stack, info))
}

/// The sRGB transfer function inverted (IEC 61966-2-1): encoded value in [0, 1] → linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn images(pattern: &str, reason: String) -> Error {
    Error::Images {
        pattern: pattern.to_string(),
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gray(dir: &Path, name: &str, v: u8) {
        image::GrayImage::from_pixel(2, 2, image::Luma([v]))
            .save(dir.join(name))
            .unwrap();
    }

    #[test]
    fn rti_captures_as_photographers_make_them() {
        let dir = std::env::temp_dir().join(format!("ptm-fit-images-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("a")).unwrap();
        std::fs::create_dir_all(dir.join("b")).unwrap();
        gray(&dir.join("a"), "IMG_0000.png", 255);
        gray(&dir.join("a"), "img_0001.JPG", 128);
        // Windows paths, a BOM and a comment, names in another case.
        let lp = dir.join("cap.lp");
        std::fs::write(
            &lp,
            "\u{feff}# RTIBuilder\n2\nC:\\Users\\me\\IMG_0000.png 0 0 1\nC:\\Users\\me\\IMG_0001.jpg 1 0 1\n",
        )
        .unwrap();
        let pat = format!("{}/a/*", dir.display());
        let (s, info) = read_image_stack(&pat, &lp, [1.0, 1.0], Decoding::Srgb).unwrap();
        assert_eq!(
            (info.srgb_decoded, info.linear, info.unused.len()),
            (2, 0, 0)
        );
        assert_eq!(s.k[0], [0.0; 4]);
        // JPEG is lossy on a flat grey only by rounding; sRGB 128 is 21.6 % linear light.
        let want = 1.0 - srgb_to_linear(128.0 / 255.0);
        assert!(
            s.k[1].iter().all(|k| (k - want).abs() < 0.01),
            "{:?}",
            s.k[1]
        );
        let (raw, info) = read_image_stack(&pat, &lp, [1.0, 1.0], Decoding::Raw).unwrap();
        assert_eq!((info.srgb_decoded, info.linear), (0, 2));
        assert!(
            raw.k[1].iter().all(|k| (k - 127.0 / 255.0).abs() < 0.01),
            "{:?}",
            raw.k[1]
        );
        // One name in two folders: refused, naming both.
        gray(&dir.join("b"), "IMG_0000.png", 0);
        let e = read_image_stack(
            &format!("{}/*/*", dir.display()),
            &lp,
            [1.0, 1.0],
            Decoding::Srgb,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("both named \"IMG_0000.png\""), "{e}");
        // Two names that match only ignoring case: ambiguous.
        gray(&dir.join("a"), "IMG_0001.Jpg", 0);
        let e = read_image_stack(&pat, &lp, [1.0, 1.0], Decoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(e.contains("ignoring case"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(lp_file_name("C:\\x\\y/IMG.png"), "IMG.png");
        assert_eq!(lp_file_name("plain.png"), "plain.png");
    }
}
