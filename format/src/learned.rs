//! The table of a learned basis ([`crate::Basis::Learned`]): k functions Bₖ(u, v) over the
//! hemispherical (u, v) square [−1, 1]², each sampled on a G × G grid and read bilinearly,
//! clamped at the edge. K = σ(Σₖ cₖ·Bₖ(u, v)) with the texel's coefficients cₖ.
//!
//! In the PTM file (docs/FORMAT.md, "Learned basis") the table is two header attributes, so any
//! EXR reader gets at it and both layouts carry it verbatim:
//! - `ptm:learnedGrid` (int): G, 2 ..= [`MAX_GRID`];
//! - `ptm:learnedTable` (string vector): k strings, string k the G·G values of Bₖ separated by
//!   single spaces, grid row j (v = −1 + 2j/(G−1)) after row j − 1, column i
//!   (u = −1 + 2i/(G−1)) within a row: entry j·G + i. Each value is the shortest decimal that
//!   reads back as the same f32, so the text is lossless.
use std::collections::BTreeMap;
use std::path::Path;

use exr::meta::attribute::AttributeValue;

use crate::exrio::{decode_text, Attr};
use crate::{Error, Result};

/// Header attributes by name, as stored (as `header::Attributes`).
type Attributes = BTreeMap<String, AttributeValue>;

/// `(it is an EXR `int` attribute)`: what a value of the wrong type is.
fn kind(v: &AttributeValue) -> String {
    format!(
        "(it is an EXR `{}` attribute)",
        String::from_utf8_lossy(v.kind_name())
    )
}

/// Largest grid side G a file may state.
pub const MAX_GRID: usize = 257;

/// Name of the grid-side attribute.
pub const GRID_ATTR: &str = "ptm:learnedGrid";
/// Name of the table attribute.
pub const TABLE_ATTR: &str = "ptm:learnedTable";
/// Name of the attribute that says in words how the table is read.
pub const FORMULA_ATTR: &str = "ptm:learnedFormula";

/// The words of `ptm:learnedFormula`.
pub const FORMULA: &str = "B_k(u, v) = bilinear read of string k of ptm:learnedTable (G x G values, row j at v = -1 + 2j/(G-1), column i at u = -1 + 2i/(G-1), entry j*G + i; u, v clamped to [-1, 1]), G = ptm:learnedGrid; K = 1 / (1 + exp(-sum_k ptm.b<k> * B_k(u, v))), (u, v) by ptm:uv";

/// A learned basis's k tables over a G × G grid.
#[derive(Clone, Debug, PartialEq)]
pub struct LearnedTable {
    /// Grid side G (≥ 2).
    pub grid: usize,
    /// Number of terms k.
    pub terms: usize,
    /// `values[k·G² + j·G + i]`: Bₖ at column i (u = −1 + 2i/(G−1)), row j (v = −1 + 2j/(G−1)).
    pub values: Vec<f32>,
}

/// The four grid cells and weights of the bilinear read at (u, v), clamped to the square.
#[inline]
pub fn bilinear(grid: usize, u: f64, v: f64) -> [(usize, f64); 4] {
    let s = (grid - 1) as f64;
    let x = ((u.clamp(-1.0, 1.0) + 1.0) * 0.5 * s).clamp(0.0, s);
    let y = ((v.clamp(-1.0, 1.0) + 1.0) * 0.5 * s).clamp(0.0, s);
    let i0 = (x.floor() as usize).min(grid - 2);
    let j0 = (y.floor() as usize).min(grid - 2);
    let (fx, fy) = (x - i0 as f64, y - j0 as f64);
    let c = j0 * grid + i0;
    [
        (c, (1.0 - fx) * (1.0 - fy)),
        (c + 1, fx * (1.0 - fy)),
        (c + grid, (1.0 - fx) * fy),
        (c + grid + 1, fx * fy),
    ]
}

fn bad(path: &Path, reason: String) -> Error {
    Error::Format {
        path: path.display().to_string(),
        reason,
    }
}

impl LearnedTable {
    /// Values per term (G²).
    pub fn cells(&self) -> usize {
        self.grid * self.grid
    }

    /// Writes B₀(u, v) … B_{k−1}(u, v) into `out[..k]` (bilinear, clamped at the edge).
    pub fn terms(&self, u: f64, v: f64, out: &mut [f64]) {
        let w = bilinear(self.grid, u, v);
        let g2 = self.cells();
        for (k, o) in out.iter_mut().enumerate().take(self.terms) {
            let t = &self.values[k * g2..(k + 1) * g2];
            *o = w.iter().map(|&(c, x)| x * t[c] as f64).sum();
        }
    }

    /// Checks the shape and that every value is finite; `what` names the table in the message.
    pub fn check(&self, terms: usize, what: &str) -> std::result::Result<(), String> {
        if !(2..=MAX_GRID).contains(&self.grid) {
            return Err(format!(
                "{what}: grid side {} is not in 2..={MAX_GRID}",
                self.grid
            ));
        }
        if self.terms != terms {
            return Err(format!(
                "{what} has {} terms but the basis has {terms} coefficient planes",
                self.terms
            ));
        }
        let want = terms * self.cells();
        if self.values.len() != want {
            return Err(format!(
                "{what} holds {} values; {terms} terms on a {g}×{g} grid are {want}",
                self.values.len(),
                g = self.grid
            ));
        }
        if let Some(i) = self.values.iter().position(|x| !x.is_finite()) {
            let g2 = self.cells();
            return Err(format!(
                "{what}: term {} is {} at grid column {}, row {}: not a number a renderer can use",
                i / g2,
                self.values[i],
                (i % g2) % self.grid,
                (i % g2) / self.grid
            ));
        }
        Ok(())
    }

    /// The header attributes that store the table.
    pub fn attrs(&self) -> Vec<(&'static str, Attr)> {
        let g2 = self.cells();
        let texts = (0..self.terms)
            .map(|k| {
                self.values[k * g2..(k + 1) * g2]
                    .iter()
                    .map(|x| format!("{x:?}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect();
        vec![
            (GRID_ATTR, Attr::I32(self.grid as i32)),
            (TABLE_ATTR, Attr::Texts(texts)),
            (FORMULA_ATTR, Attr::Text(FORMULA.into())),
        ]
    }

    /// The table of a learned basis of `terms` terms from the file's attributes (`path` named
    /// in every refusal): a missing or mistyped attribute, a grid side out of range, a term
    /// count that does not match the coefficient planes, a string of the wrong length, a value
    /// that does not parse or is not finite.
    pub fn from_attrs(attrs: &Attributes, terms: usize, path: &Path) -> Result<LearnedTable> {
        let grid = match attrs.get(GRID_ATTR) {
            Some(AttributeValue::I32(x)) => *x as f64,
            Some(AttributeValue::F32(x)) => *x as f64,
            Some(AttributeValue::F64(x)) => *x,
            Some(v) => {
                return Err(bad(
                    path,
                    format!("`{GRID_ATTR}` is not a number {}", kind(v)),
                ))
            }
            None => {
                return Err(bad(
                    path,
                    format!(
                        "a learned basis needs the int attribute `{GRID_ATTR}` (its grid side)"
                    ),
                ))
            }
        };
        if grid.fract() != 0.0 || !(2.0..=MAX_GRID as f64).contains(&grid) {
            return Err(bad(
                path,
                format!("`{GRID_ATTR}` is {grid}: a grid side is a whole number in 2..={MAX_GRID}"),
            ));
        }
        let grid = grid as usize;
        let texts: Vec<String> = match attrs.get(TABLE_ATTR) {
            Some(AttributeValue::TextVector(v)) => v.iter().map(decode_text).collect(),
            Some(v) => {
                return Err(bad(
                    path,
                    format!("`{TABLE_ATTR}` is not a text vector {}", kind(v)),
                ))
            }
            None => {
                return Err(bad(
                    path,
                    format!("a learned basis needs the string-vector attribute `{TABLE_ATTR}`"),
                ))
            }
        };
        if texts.len() != terms {
            return Err(bad(
                path,
                format!(
                    "`{TABLE_ATTR}` holds {} tables but the basis learned{terms} has {terms} \
                     coefficient planes",
                    texts.len()
                ),
            ));
        }
        let g2 = grid * grid;
        let mut values = Vec::with_capacity(terms * g2);
        for (k, t) in texts.iter().enumerate() {
            let before = values.len();
            for (i, word) in t.split(' ').enumerate() {
                let x: f32 = word.parse().map_err(|_| {
                    bad(
                        path,
                        format!("`{TABLE_ATTR}` term {k}, value {i}: {word:?} is not a number"),
                    )
                })?;
                values.push(x);
            }
            let n = values.len() - before;
            if n != g2 {
                return Err(bad(
                    path,
                    format!(
                        "`{TABLE_ATTR}` term {k} holds {n} values; a {grid}×{grid} grid \
                         (`{GRID_ATTR}`) has {g2}"
                    ),
                ));
            }
        }
        let table = LearnedTable {
            grid,
            terms,
            values,
        };
        table
            .check(terms, &format!("`{TABLE_ATTR}`"))
            .map_err(|e| bad(path, e))?;
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_weights_interpolate_and_clamp() {
        let g = 5;
        // A table holding the plane 2u − v + 0.5 reads back exactly anywhere inside.
        let mut values = vec![0f32; g * g];
        for j in 0..g {
            for i in 0..g {
                let (u, v) = (-1.0 + 0.5 * i as f64, -1.0 + 0.5 * j as f64);
                values[j * g + i] = (2.0 * u - v + 0.5) as f32;
            }
        }
        let t = LearnedTable {
            grid: g,
            terms: 1,
            values,
        };
        let mut out = [0f64];
        for (u, v) in [
            (0.3, -0.7),
            (-1.0, 1.0),
            (1.0, -1.0),
            (0.0, 0.0),
            (0.99, 0.51),
        ] {
            t.terms(u, v, &mut out);
            assert!((out[0] - (2.0 * u - v + 0.5)).abs() < 1e-6, "({u}, {v})");
        }
        // Outside the square it reads the edge.
        t.terms(1.7, -3.0, &mut out);
        assert!((out[0] - (2.0 + 1.0 + 0.5)).abs() < 1e-6);
        let w = bilinear(g, 0.1, 0.2);
        assert!((w.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn attributes_round_trip_exactly_and_refuse_bad_tables() {
        let t = LearnedTable {
            grid: 3,
            terms: 2,
            values: (0..18)
                .map(|i| (i as f32 * 0.1).sin() * 1e3 + 1e-7)
                .collect(),
        };
        let attrs: Attributes = t
            .attrs()
            .into_iter()
            .map(|(k, v)| (k.to_string(), crate::exrio::attribute_value(v)))
            .collect();
        let p = Path::new("t.ptm.exr");
        assert_eq!(LearnedTable::from_attrs(&attrs, 2, p).unwrap(), t);
        let e = LearnedTable::from_attrs(&attrs, 3, p)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.ptm.exr") && e.contains("2 tables") && e.contains("3 coefficient planes"),
            "{e}"
        );
        let mut short = attrs.clone();
        short.insert(
            GRID_ATTR.into(),
            crate::exrio::attribute_value(Attr::I32(4)),
        );
        let e = LearnedTable::from_attrs(&short, 2, p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("holds 9 values") && e.contains("has 16"), "{e}");
        let mut nan = t.clone();
        nan.values[13] = f32::NAN;
        let attrs: Attributes = nan
            .attrs()
            .into_iter()
            .map(|(k, v)| (k.to_string(), crate::exrio::attribute_value(v)))
            .collect();
        let e = LearnedTable::from_attrs(&attrs, 2, p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("term 1 is NaN at grid column 1, row 1"), "{e}");
    }
}
