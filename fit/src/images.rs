//! Image stacks rendered or photographed elsewhere (RTI convention): one PNG per light, white =
//! lit, so K = 1 − luminance; light directions from an `.lp` file.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::{Error, LightSet, Result, SampleStack};

/// Builds a sample stack from the images matching `pattern` (a glob such as `dir/*.png`) and
/// the lights of the `.lp` file `lp`. Each `.lp` entry is matched to the image with the same
/// file name; images the `.lp` does not list are ignored (returned as the second value).
/// Image row 0 is the top of the image = the far edge y = H; `tile` is the tile size (W, H).
pub fn read_image_stack(
    pattern: &str,
    lp: &Path,
    tile: [f64; 2],
) -> Result<(SampleStack, Vec<PathBuf>)> {
    let lights = LightSet::read_lp(lp)?;
    let paths = glob::glob(pattern)
        .map_err(|e| Error::Invalid(format!("--images {pattern:?}: bad pattern: {e}")))?;
    let mut by_name: HashMap<String, PathBuf> = HashMap::new();
    for p in paths {
        let p = p.map_err(|e| Error::Invalid(format!("--images {pattern:?}: {e}")))?;
        if let Some(name) = p.file_name() {
            by_name.insert(name.to_string_lossy().into_owned(), p);
        }
    }
    if by_name.is_empty() {
        return Err(Error::Invalid(format!(
            "--images {pattern:?} matches no file"
        )));
    }
    let mut k = Vec::with_capacity(lights.len());
    let (mut width, mut height) = (0, 0);
    for (i, name) in lights.names.iter().enumerate() {
        let base = Path::new(name)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let path = by_name.remove(&base).ok_or_else(|| {
            Error::Invalid(format!(
                "light {i} of {} names {name:?}, which matches no file of --images {pattern:?}",
                lp.display()
            ))
        })?;
        let img = image::open(&path).map_err(|e| Error::Format {
            path: path.display().to_string(),
            reason: format!("cannot read the image (PNG, 8 or 16 bit): {e}"),
        })?;
        // Luminance in [0, 1] (Rec. 709 weights for colour images).
        let luma = img.to_luma32f();
        let (w, h) = (luma.width() as usize, luma.height() as usize);
        if i == 0 {
            (width, height) = (w, h);
        } else if (w, h) != (width, height) {
            return Err(Error::Format {
                path: path.display().to_string(),
                reason: format!("image is {w}×{h}, the first image {width}×{height}"),
            });
        }
        k.push(luma.into_raw().into_iter().map(|l| 1.0 - l).collect());
    }
    let mut unused: Vec<PathBuf> = by_name.into_values().collect();
    unused.sort();
    let stack = SampleStack {
        width,
        height,
        tile,
        lights,
        k,
        coverage: vec![1.0; width * height],
        uv: None,
    };
    stack.validate()?;
    Ok((stack, unused))
}
