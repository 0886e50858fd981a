//! Wavefront OBJ, the swatch's file: the workspace's one OBJ reader, in f64 (`ptm bake` reads
//! swatch files with it, recentring a mesh far from the origin before f32 can round it), and
//! the mesh's writer ([`Mesh::write_obj`]), whose files [`Mesh::read_obj`] reads back. Errors
//! name the file and the line.
use std::io::Write;
use std::path::Path;

use crate::mesh::Mesh;
use crate::{Error, Result};

/// An OBJ file as read, in f64: coordinates far from the origin keep their precision until
/// [`Obj::recentred`] moves the mesh next to it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Obj {
    /// Vertex positions as written, in the file's units.
    pub positions: Vec<[f64; 3]>,
    /// 0-based, checked against `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// The `# tile W H` header `ptm swatch` writes, when present.
    pub tile: Option<[f64; 2]>,
    /// Per triangle, its `usemtl` group: an index into `material_names`. Empty when the file
    /// names no material; faces before the first `usemtl` are the group `default`.
    pub materials: Vec<u32>,
    /// The `usemtl` names, in order of first use.
    pub material_names: Vec<String>,
    /// Texture coordinates (`vt u v`) as written.
    pub uvs: Vec<[f64; 2]>,
    /// Per triangle, the `vt` index (0-based, checked against `uvs`) of each corner; empty
    /// unless every face gives one for every corner (`f v/vt …`).
    pub triangle_uvs: Vec<[u32; 3]>,
}

/// Reads an OBJ file: see [`parse_obj`].
pub fn read_obj(path: &Path) -> Result<Obj> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_obj(&bytes, &path.display().to_string())
}

/// Fills `out` with the next finite numbers of a line; the reason when one is missing
/// (`missing(found)`) or is not a finite number (named as a `what`).
fn finite_numbers<'a>(
    it: &mut impl Iterator<Item = &'a str>,
    out: &mut [f64],
    what: &str,
    missing: impl Fn(usize) -> String,
) -> std::result::Result<(), String> {
    for (k, c) in out.iter_mut().enumerate() {
        let t = it.next().ok_or_else(|| missing(k))?;
        *c = t
            .parse::<f64>()
            .ok()
            .filter(|c| c.is_finite())
            .ok_or_else(|| format!("{what} {t:?} is non-finite or not a number"))?;
    }
    Ok(())
}

/// Parses OBJ bytes (`origin` names them in errors): `v x y z` lines, `f` lines (polygons
/// fan-triangulated, negative indices relative to the vertices so far; the `/vt` part read into
/// [`Obj::triangle_uvs`] when every face has one, `/vn` ignored), `vt u v` lines (NaN refused),
/// every object into one mesh, a `# tile W H` comment before the first vertex, and `usemtl`
/// groups (the materials of the faces that follow). Other lines (`vn`, `o`, `g`, …) are
/// ignored, and so are bytes that are not UTF-8
/// outside `v` and `f` lines (a Latin-1 comment).
pub fn parse_obj(bytes: &[u8], origin: &str) -> Result<Obj> {
    let bad = |line: usize, reason: String| Error::InvalidMesh {
        path: origin.into(),
        reason: format!("line {line}: {reason}"),
    };
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(Error::InvalidMesh {
            path: origin.into(),
            reason: "empty file".into(),
        });
    }
    let mut obj = Obj::default();
    // Line of each triangle's face, for an index checked at the end.
    let mut face_lines: Vec<usize> = Vec::new();
    // The current `usemtl` group (none before the first).
    let mut material = u32::MAX;
    // Whether every face so far gave a `vt` for every corner.
    let mut all_vt = true;
    for (n, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let n = n + 1;
        let line = String::from_utf8_lossy(raw);
        let mut it = line.split_whitespace();
        match it.next() {
            Some("#") if obj.positions.is_empty() && line.starts_with("# tile ") => {
                let v: Vec<f64> = it.filter_map(|t| t.parse().ok()).collect();
                match v[..] {
                    [w, h] if w > 0.0 && h > 0.0 && w.is_finite() && h.is_finite() => {
                        obj.tile = Some([w, h])
                    }
                    _ => {
                        return Err(bad(
                            n,
                            format!(
                                "{:?} needs two positive numbers W H (the tile size)",
                                line.trim()
                            ),
                        ))
                    }
                }
            }
            Some("v") => {
                let mut v = [0.0; 3];
                finite_numbers(&mut it, &mut v, "vertex coordinate", |k| {
                    format!("a vertex needs 3 coordinates, found {k}")
                })
                .map_err(|reason| bad(n, reason))?;
                obj.positions.push(v);
            }
            Some("vt") => {
                let mut v = [0.0; 2];
                finite_numbers(&mut it, &mut v, "texture coordinate", |k| {
                    format!("a texture coordinate needs u v, found {k} numbers")
                })
                .map_err(|reason| bad(n, reason))?;
                obj.uvs.push(v);
            }
            Some("f") => {
                let nv = obj.positions.len() as i64;
                let nt = obj.uvs.len() as i64;
                let mut idx = Vec::with_capacity(4);
                let mut vts = Vec::with_capacity(4);
                for t in it {
                    let mut parts = t.split('/');
                    let first = parts.next().unwrap_or("");
                    match parts.next().filter(|s| !s.is_empty()) {
                        None => all_vt = false,
                        Some(vt) => {
                            let k = vt.parse::<i64>().map_err(|_| {
                                bad(
                                    n,
                                    format!("texture coordinate index {vt:?} is not an integer"),
                                )
                            })?;
                            let k = if k > 0 { k - 1 } else { nt + k };
                            // A texture index with no `vt` line behind it (foreign files
                            // write `f 1/1/1` with no texture coordinates at all): the face
                            // has no UVs, as the bake never needed them; `ptm preview --mesh`
                            // then says the mesh has none.
                            if k < 0 || k >= nt {
                                all_vt = false;
                            } else {
                                vts.push(k as u32);
                            }
                        }
                    }
                    let k = first
                        .parse::<i64>()
                        .map_err(|_| bad(n, format!("face index {t:?} is not an integer")))?;
                    let k = match k {
                        0 => {
                            return Err(bad(
                                n,
                                "face index 0: OBJ indices start at 1 (negative ones count \
                                 back from the last vertex)"
                                    .into(),
                            ))
                        }
                        k if k > 0 => k - 1,
                        k => nv + k,
                    };
                    let k = u32::try_from(k).map_err(|_| {
                        bad(
                            n,
                            format!("face index {first} is outside the {nv} vertices so far"),
                        )
                    })?;
                    idx.push(k);
                }
                if idx.len() < 3 {
                    return Err(bad(
                        n,
                        format!("a face needs at least 3 vertices, found {}", idx.len()),
                    ));
                }
                for k in 1..idx.len() - 1 {
                    if all_vt && vts.len() == idx.len() {
                        obj.triangle_uvs.push([vts[0], vts[k], vts[k + 1]]);
                    }
                    obj.triangles.push([idx[0], idx[k], idx[k + 1]]);
                    obj.materials.push(material);
                    face_lines.push(n);
                }
            }
            Some("usemtl") => {
                let name = it.collect::<Vec<_>>().join(" ");
                let name = if name.is_empty() {
                    "default".to_string()
                } else {
                    name
                };
                material = match obj.material_names.iter().position(|m| *m == name) {
                    Some(i) => i as u32,
                    None => {
                        obj.material_names.push(name);
                        obj.material_names.len() as u32 - 1
                    }
                };
            }
            _ => {}
        }
    }
    let nv = obj.positions.len();
    if let Some((t, &n)) = obj
        .triangles
        .iter()
        .zip(&face_lines)
        .find(|(t, _)| t.iter().any(|&k| k as usize >= nv))
    {
        let k = t.iter().max().copied().unwrap_or(0) as u64 + 1;
        return Err(bad(
            n,
            format!("face index {k} but the file has {nv} vertices"),
        ));
    }
    if !all_vt || obj.triangle_uvs.len() != obj.triangles.len() {
        obj.triangle_uvs.clear();
    }
    if obj.material_names.is_empty() {
        obj.materials.clear();
    } else if obj.materials.contains(&u32::MAX) {
        let default = match obj.material_names.iter().position(|m| m == "default") {
            Some(i) => i as u32,
            None => {
                obj.material_names.push("default".into());
                obj.material_names.len() as u32 - 1
            }
        };
        for m in &mut obj.materials {
            if *m == u32::MAX {
                *m = default;
            }
        }
    }
    Ok(obj)
}

impl Obj {
    /// The mesh in f32, moved in f64 next to the origin first, and the (x, y) shift applied.
    /// With a tile the shift is a whole number of tiles (the periodic bake is unchanged),
    /// without one it puts the bounding box at (0, 0) as the bake's `PreparedMesh::from_mesh`
    /// would; z moves
    /// only when the mesh lies further from z = 0 than its own height. An f32 step at 1e6 is
    /// 0.0625: converting first would bake a different mesh.
    pub fn recentred(self, tile: Option<[f64; 2]>) -> (Mesh, [f64; 2]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &k in self.triangles.iter().flatten() {
            for a in 0..3 {
                lo[a] = lo[a].min(self.positions[k as usize][a]);
                hi[a] = hi[a].max(self.positions[k as usize][a]);
            }
        }
        let mut shift = [0.0; 3];
        if !self.triangles.is_empty() {
            for a in 0..2 {
                shift[a] = match tile {
                    Some(t) if t[a] > 0.0 && t[a].is_finite() => {
                        // floor: a mesh over [0, W] (or overhanging it a little) stays.
                        let whole = (((lo[a] + hi[a]) / 2.0) / t[a]).floor() * t[a];
                        if whole.is_finite() {
                            -whole
                        } else {
                            0.0
                        }
                    }
                    _ => -lo[a],
                };
            }
            if lo[2].abs() > hi[2] - lo[2] {
                shift[2] = -lo[2];
            }
        }
        let mesh = Mesh {
            positions: self
                .positions
                .iter()
                .map(|p| [0, 1, 2].map(|a| (p[a] + shift[a]) as f32))
                .collect(),
            triangles: self.triangles,
            tile: [0.0; 2],
        };
        (mesh, [shift[0], shift[1]])
    }

    /// The mesh in f32 as written (no recentring), its tile from the `# tile W H` header or
    /// [0, 0] without one.
    pub fn into_mesh(self) -> Mesh {
        Mesh {
            positions: self.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
            triangles: self.triangles,
            tile: self.tile.map_or([0.0; 2], |t| t.map(|c| c as f32)),
        }
    }
}

impl Mesh {
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

    /// Reads an OBJ file into a mesh as written (f32, the tile from the `# tile W H` header
    /// [`Mesh::write_obj`] writes, [0, 0] without one), with the workspace's one reader,
    /// [`read_obj`].
    pub fn read_obj(path: &Path) -> Result<Mesh> {
        Ok(read_obj(path)?.into_mesh())
    }
}
