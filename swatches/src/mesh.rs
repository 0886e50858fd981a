//! The triangle mesh of one swatch tile, its OBJ writer and a few measurements.

use std::io::Write;
use std::path::Path;

use crate::{Error, Result};

/// A swatch: triangles in the swatch frame (z up) and the periodic tile [0, W]×[0, H] they
/// repeat over.
///
/// Periodicity contract (see the crate docs): the union of copies translated by (a·W, b·H) for
/// all integers a, b is the infinite cloth. A yarn tube that leaves the tile through a border is
/// cut exactly on that border and its copy re-enters through the opposite one (the two border
/// rings coincide after translation); geometry that does not cross a border as a tube (knit
/// loops reaching into the next course, pile tufts near the border) may stick out of the tile,
/// but never by more than one tile, so a 3×3 block of copies covers the central tile.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Tile size (W, H) in the swatch's units.
    pub tile: [f32; 2],
}

impl Mesh {
    /// Axis-aligned bounds `(min, max)` of the vertices; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        let mut lo = first;
        let mut hi = first;
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Some((lo, hi))
    }

    /// `(z_min, z_max)` of the vertices: where an orthographic camera above the swatch must
    /// start its rays; `None` for an empty mesh.
    pub fn z_range(&self) -> Option<(f32, f32)> {
        self.bounds().map(|(lo, hi)| (lo[2], hi[2]))
    }

    /// Enclosed volume of the periodic cloth per tile, Σ over triangles of the flux of
    /// F = (0, 0, z) (divergence 1). Unlike the usual (p0 × p1)·p2 / 6 formula this stays exact
    /// for tubes cut open on the tile borders, because F has no x or y component and so no flux
    /// through the (vertical) border planes. Positive when normals point outwards.
    pub fn signed_volume(&self) -> f64 {
        let mut v = 0.0;
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.positions[i as usize].map(f64::from));
            // z-average times the signed area of the xy projection.
            let area_xy = 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]));
            v += area_xy * (a[2] + b[2] + c[2]) / 3.0;
        }
        v
    }

    /// Appends another mesh's triangles (its tile is ignored).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
    }

    /// Writes the mesh as Wavefront OBJ (`v`, then `f` with 1-based indices), atomically: to a
    /// temporary file beside `path`, then renamed over it. The tile size goes in a leading
    /// comment (`# tile W H`), which [`Mesh::read_obj`] reads back. Uses `ptm_format::atomic`, as
    /// every writer of the workspace does.
    pub fn write_obj(&self, path: &Path) -> Result<()> {
        ptm_format::atomic::write_atomic(path, |w| self.write_obj_to(w)).map_err(|e| match e {
            ptm_format::Error::Io { source, .. } => Error::Io {
                path: path.to_path_buf(),
                source,
            },
            other => Error::Invalid(other.to_string()),
        })
    }

    /// The OBJ text of [`Mesh::write_obj`] into any writer.
    pub fn write_obj_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        writeln!(w, "# ptm swatch: tile spans [0, W]x[0, H], z up")?;
        writeln!(w, "# tile {} {}", self.tile[0], self.tile[1])?;
        writeln!(
            w,
            "# {} vertices, {} triangles",
            self.positions.len(),
            self.triangles.len()
        )?;
        // `{:?}` on f32 prints the shortest string that reads back to the same f32, with an
        // exponent for tiny values (rounding noise like 5.551115e-17 stays short).
        for p in &self.positions {
            writeln!(w, "v {:?} {:?} {:?}", p[0], p[1], p[2])?;
        }
        for t in &self.triangles {
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    }

    /// Reads an OBJ file: `v` lines, `f` lines (polygons fan-triangulated, `/vt/vn` parts and
    /// negative relative indices allowed) and the `# tile W H` comment [`Mesh::write_obj`]
    /// writes (tile [0, 0] when absent); other lines are ignored.
    pub fn read_obj(path: &Path) -> Result<Mesh> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Mesh::parse_obj(&text).map_err(|reason| Error::InvalidMesh {
            path: path.to_path_buf(),
            reason,
        })
    }

    /// [`Mesh::read_obj`] on text; the error is the reason with its line number.
    pub fn parse_obj(text: &str) -> std::result::Result<Mesh, String> {
        let mut mesh = Mesh::default();
        for (n, line) in text.lines().enumerate() {
            let n = n + 1;
            let mut it = line.split_whitespace();
            match it.next() {
                Some("#") if line.starts_with("# tile ") => {
                    mesh.tile = obj_tile_line(line)
                        .ok_or_else(|| format!("line {n}: `# tile` needs two numbers W H"))?;
                }
                Some("v") => {
                    let v: Vec<f32> = it
                        .map(|s| s.parse::<f32>())
                        .collect::<std::result::Result<_, _>>()
                        .map_err(|e| format!("line {n}: bad vertex coordinate: {e}"))?;
                    if v.len() < 3 {
                        return Err(format!("line {n}: a vertex needs 3 coordinates"));
                    }
                    mesh.positions.push([v[0], v[1], v[2]]);
                }
                Some("f") => {
                    let nv = mesh.positions.len() as i64;
                    let idx: Vec<u32> = it
                        .map(|s| {
                            let first = s.split('/').next().unwrap_or("");
                            // 1-based, or negative: relative to the vertices read so far.
                            match first.parse::<i64>().ok()? {
                                k if k >= 1 => u32::try_from(k - 1).ok(),
                                k if k < 0 && nv + k >= 0 => u32::try_from(nv + k).ok(),
                                _ => None,
                            }
                        })
                        .collect::<Option<_>>()
                        .ok_or_else(|| {
                            format!("line {n}: face indices must be non-zero integers within the vertices so far")
                        })?;
                    if idx.len() < 3 {
                        return Err(format!("line {n}: a face needs at least 3 vertices"));
                    }
                    for k in 1..idx.len() - 1 {
                        mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                    }
                }
                _ => {}
            }
        }
        let nv = mesh.positions.len() as u32;
        if let Some((i, t)) = mesh
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&k| k >= nv))
        {
            return Err(format!(
                "face {} has index {} but the mesh has {nv} vertices",
                i + 1,
                t.iter().max().unwrap() + 1
            ));
        }
        Ok(mesh)
    }
}

/// The tile size from the `# tile W H` header comment [`Mesh::write_obj`] writes, for readers
/// that parse the rest of an OBJ themselves; `None` when there is no such line.
pub fn obj_tile(text: &str) -> Option<[f32; 2]> {
    text.lines()
        .take_while(|l| l.starts_with('#') || l.trim().is_empty())
        .find(|l| l.starts_with("# tile "))
        .and_then(obj_tile_line)
}

fn obj_tile_line(line: &str) -> Option<[f32; 2]> {
    let v: Vec<f32> = line
        .split_whitespace()
        .skip(2)
        .map(|s| s.parse().ok())
        .collect::<Option<_>>()?;
    (v.len() == 2 && v.iter().all(|t| t.is_finite() && *t > 0.0)).then(|| [v[0], v[1]])
}
