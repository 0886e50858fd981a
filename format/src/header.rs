//! The one parser of a PTM header: the attributes that say what the coefficients mean
//! (`ptm:version`, `ptm:basis`, `ptm:monomials`, `ptm:link`, `ptm:uv`, `ptm:tileW` and
//! `ptm:tileH`), read from the attributes as stored. Every reader of a PTM goes through
//! [`Header::parse`]: `Ptm::load` and `PtmFile::load` of either layout (`layout.rs`), and the
//! check `PtmFile` makes before it writes, so they refuse the same headers in the same words.
//!
//! A reader refuses what it does not understand: an absent `ptm:link` or `ptm:uv` is the plain
//! PTM's, but one that is not text, or names a link or map this version does not know, is
//! refused, naming the attribute; so is a `ptm:monomials` that is not a text vector or not the
//! basis's list, and a tile that is not a positive size.
use std::collections::BTreeMap;
use std::path::Path;

use exr::meta::attribute::AttributeValue;

use crate::exrio::decode_text;
use crate::ptm::{PTM_VERSION, PTM_VERSION_2};
use crate::{Basis, Error, Link, Result, UvMap};

/// Header attributes by name, as stored (text as the file's bytes).
pub type Attributes = BTreeMap<String, AttributeValue>;

/// What a PTM header says its coefficients mean.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// The polynomial basis (`ptm:basis`).
    pub basis: Basis,
    /// The link (`ptm:link`; absent = identity).
    pub link: Link,
    /// The (u, v) map (`ptm:uv`; absent, or the old formula text, = projected).
    pub uv: UvMap,
    /// Tile size (W, H) in swatch units (`ptm:tileW`, `ptm:tileH`).
    pub tile: [f64; 2],
}

fn bad(path: &Path, reason: impl Into<String>) -> Error {
    Error::Format {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// `(it is an EXR `int` attribute)`: what a value of the wrong type is.
fn kind(v: &AttributeValue) -> String {
    format!(
        "(it is an EXR `{}` attribute)",
        String::from_utf8_lossy(v.kind_name())
    )
}

/// The text attribute `name`: `None` when absent; one of another type is refused.
pub fn text(attrs: &Attributes, name: &str, path: &Path) -> Result<Option<String>> {
    match attrs.get(name) {
        None => Ok(None),
        Some(AttributeValue::Text(t)) => Ok(Some(decode_text(t))),
        Some(v) => Err(bad(path, format!("`{name}` is not text {}", kind(v)))),
    }
}

/// The text-vector attribute `name`: `None` when absent; one of another type is refused.
pub fn texts(attrs: &Attributes, name: &str, path: &Path) -> Result<Option<Vec<String>>> {
    match attrs.get(name) {
        None => Ok(None),
        Some(AttributeValue::TextVector(v)) => Ok(Some(v.iter().map(decode_text).collect())),
        Some(v) => Err(bad(
            path,
            format!("`{name}` is not a text vector {}", kind(v)),
        )),
    }
}

/// The number attribute `name` (a double, a float or an integer): `None` when absent; one of
/// another type is refused.
pub fn number(attrs: &Attributes, name: &str, path: &Path) -> Result<Option<f64>> {
    match attrs.get(name) {
        None => Ok(None),
        Some(AttributeValue::F64(x)) => Ok(Some(*x)),
        Some(AttributeValue::F32(x)) => Ok(Some(*x as f64)),
        Some(AttributeValue::I32(x)) => Ok(Some(*x as f64)),
        Some(v) => Err(bad(path, format!("`{name}` is not a number {}", kind(v)))),
    }
}

impl Header {
    /// Parses the header of the PTM file `path` (named in every refusal). Checked in this
    /// order: `ptm:version` is `occlusion-ptm/1` or `/2` (absent: not a PTM, with a hint when
    /// it is a sample stack or companion maps), `ptm:basis` names a basis, `ptm:monomials` (optional) is its
    /// list, `ptm:link` and `ptm:uv` (optional) name a link and map, `ptm:tileW` and
    /// `ptm:tileH` are positive finite numbers.
    pub fn parse(attrs: &Attributes, path: &Path) -> Result<Header> {
        match text(attrs, "ptm:version", path)? {
            Some(v) if v == PTM_VERSION || v == PTM_VERSION_2 => {}
            Some(v) => {
                return Err(bad(
                    path,
                    format!(
                        "PTM version {v:?} in `ptm:version` is not supported (this version reads \
                         {PTM_VERSION:?} and {PTM_VERSION_2:?})"
                    ),
                ))
            }
            None => {
                let hint = if attrs.contains_key("stack:version") {
                    " (it is a sample stack: fit it first with `ptm fit`)"
                } else if attrs.contains_key("maps:version") {
                    " (it holds the companion maps `ptm bake --maps` writes beside a PTM: pass \
                     the PTM, NAME.ptm.exr)"
                } else {
                    " (no `ptm:version` attribute)"
                };
                return Err(bad(path, format!("not an occlusion PTM{hint}")));
            }
        }
        let name = text(attrs, "ptm:basis", path)?
            .ok_or_else(|| bad(path, "PTM lacks the text attribute `ptm:basis`"))?;
        let basis = Basis::from_name(&name).ok_or_else(|| {
            bad(
                path,
                format!(
                    "unknown basis {name:?} in `ptm:basis` (this version reads {} and learned1 \
                     … learned{})",
                    Basis::ALL.map(|b| b.name()).join(", "),
                    crate::basis::MAX_LEARNED_TERMS
                ),
            )
        })?;
        if let Some(list) = texts(attrs, "ptm:monomials", path)? {
            let want: Vec<&str> = basis.monomials().iter().map(|m| m.name).collect();
            if list != want {
                return Err(bad(
                    path,
                    format!(
                        "monomial list {list:?} in `ptm:monomials` does not match basis {} \
                         ({want:?})",
                        basis.name()
                    ),
                ));
            }
        }
        let link = match text(attrs, "ptm:link", path)? {
            None => Link::Identity,
            Some(name) => Link::from_name(&name).ok_or_else(|| {
                bad(
                    path,
                    format!(
                        "unknown link {name:?} in `ptm:link` (this version reads {})",
                        Link::ALL.map(|l| l.name()).join(", ")
                    ),
                )
            })?,
        };
        let uv = match text(attrs, "ptm:uv", path)? {
            None => UvMap::Projected,
            // Files before the attribute named its map held the projected formula in words.
            Some(name) if name == UvMap::Projected.formula() => UvMap::Projected,
            Some(name) => UvMap::from_name(&name).ok_or_else(|| {
                bad(
                    path,
                    format!(
                        "unknown (u, v) map {name:?} in `ptm:uv` (this version reads {})",
                        UvMap::ALL.map(|m| m.name()).join(", ")
                    ),
                )
            })?,
        };
        let side = |name: &str| -> Result<f64> {
            let x = number(attrs, name, path)?
                .ok_or_else(|| bad(path, format!("PTM lacks the number attribute `{name}`")))?;
            if x.is_finite() && x > 0.0 {
                Ok(x)
            } else {
                Err(bad(
                    path,
                    format!("`{name}` is {x}: a tile side is a positive finite size"),
                ))
            }
        };
        let tile = [side("ptm:tileW")?, side("ptm:tileH")?];
        Ok(Header {
            basis,
            link,
            uv,
            tile,
        })
    }
}
