//! Swatch input: OBJ files (read by `ptm_swatches::obj`) or builtin meshes, checked before
//! anything is traced. Bad input is refused
//! with an error naming the source; degenerate triangles are dropped and counted; a mesh that is
//! not periodic over its tile gets a warning with the measured seam mismatch.
use std::path::Path;

use ptm_format::vec3::{cross, norm, sub};
use ptm_swatches::{obj, Mesh};

use crate::{Error, Result};

/// Axis-aligned bounds in the swatch frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Smallest x, y, z, in mesh units.
    pub min: [f64; 3],
    /// Largest x, y, z, in mesh units.
    pub max: [f64; 3],
}

/// How well the mesh's cross-sections at opposite tile borders match.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seam {
    /// 0: the sections at x = 0 and x = W; 1: at y = 0 and y = H.
    pub axis: usize,
    /// Largest distance from a point of one section to the other section, in mesh units;
    /// infinite when only one border has geometry, 0 when neither has. `None` when the mesh
    /// reaches across the tile border on this axis: then the neighbours' overhangs complete
    /// each section and the mesh's own sections need not match.
    pub mismatch: Option<f64>,
}

/// The bake's prepared mesh: a swatch's triangles checked and ready to trace (non-degenerate
/// triangles, tile, bounds, seams). Not [`ptm_swatches::Swatch`], the generator's output.
#[derive(Clone, Debug)]
pub struct PreparedMesh {
    /// Where the mesh came from (a path or `builtin:NAME`), for messages.
    pub origin: String,
    /// Vertex positions in the swatch frame (mesh units, after any shift), f32 as Embree takes them.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as 0-based vertex indices, degenerate ones removed.
    pub triangles: Vec<[u32; 3]>,
    /// Tile size (W, H) in mesh units: copies repeat at multiples of it.
    pub tile: [f64; 2],
    /// Bounds of the vertices the kept triangles use (after any shift).
    pub bounds: Bounds,
    /// Zero-area triangles skipped.
    pub degenerate: usize,
    /// Translation applied so that the tile starts at (0, 0) (when the tile defaulted to the
    /// mesh's bounding box), in mesh units.
    pub shift: [f64; 2],
    /// Seam match along x (index 0) and y (index 1).
    pub seams: [Seam; 2],
    /// The tile is the mesh's x/y bounding box: none was given and the OBJ has no
    /// `# tile W H` header.
    pub tile_from_bounds: bool,
    /// Per kept triangle, its material: an index into `material_names` (a builtin's yarn
    /// kinds, an OBJ's `usemtl` groups; `default` for a mesh that names none).
    pub materials: Vec<u32>,
    /// The materials' names.
    pub material_names: Vec<String>,
}

impl PreparedMesh {
    /// Loads `spec`: `builtin:NAME[?k=v…]` or a path to an OBJ file. `tile` overrides the tile
    /// size; by default a builtin's own tile, or the OBJ's x/y bounding box.
    pub fn load(spec: &str, tile: Option<[f64; 2]>) -> Result<Self> {
        match spec.strip_prefix("builtin:") {
            Some(name) => {
                let s = ptm_swatches::build(name).map_err(|e| Error::InvalidMesh {
                    path: spec.to_string(),
                    reason: e.to_string(),
                })?;
                Self::from_parts(s.mesh, Some((s.materials, s.material_names)), tile, spec)
            }
            None => {
                let mut obj = obj::read_obj(Path::new(spec)).map_err(|e| obj_error(e, spec))?;
                let tile = tile.or(obj.tile);
                let materials = (!obj.material_names.is_empty()).then(|| {
                    (
                        std::mem::take(&mut obj.materials),
                        std::mem::take(&mut obj.material_names),
                    )
                });
                let (mesh, shift) = obj.recentred(tile);
                let mut swatch = Self::from_parts(mesh, materials, tile, spec)?;
                swatch.shift = [0, 1].map(|a| swatch.shift[a] + shift[a]);
                Ok(swatch)
            }
        }
    }

    /// Checks `mesh`; `origin` names it in errors. A zero `mesh.tile` means "not given".
    pub fn from_mesh(mesh: Mesh, tile: Option<[f64; 2]>, origin: &str) -> Result<Self> {
        Self::from_parts(mesh, None, tile, origin)
    }

    /// As [`PreparedMesh::from_mesh`], with each triangle's material (an index into the names)
    /// where the mesh has them.
    pub fn from_parts(
        mesh: Mesh,
        materials: Option<(Vec<u32>, Vec<String>)>,
        tile: Option<[f64; 2]>,
        origin: &str,
    ) -> Result<Self> {
        let bad = |reason: String| Error::InvalidMesh {
            path: origin.to_string(),
            reason,
        };
        let bad_tile = |reason: String, stray: bool| Error::Tile {
            path: origin.to_string(),
            reason,
            stray,
        };
        if mesh.triangles.is_empty() {
            return Err(bad("no triangles (is the file empty or not an OBJ?)".into()));
        }
        for (i, p) in mesh.positions.iter().enumerate() {
            if let Some(c) = p.iter().find(|c| !c.is_finite()) {
                return Err(bad(format!(
                    "vertex {} has a non-finite coordinate {c}",
                    i + 1
                )));
            }
        }
        let nv = mesh.positions.len();
        for (i, t) in mesh.triangles.iter().enumerate() {
            if let Some(&k) = t.iter().find(|&&k| k as usize >= nv) {
                return Err(bad(format!(
                    "triangle {} has vertex index {} but the mesh has {nv} vertices",
                    i + 1,
                    k as u64 + 1
                )));
            }
        }
        let all = bounds(&mesh.positions, &mesh.triangles);
        let given = tile.or((mesh.tile[0] > 0.0 && mesh.tile[1] > 0.0)
            .then(|| [mesh.tile[0] as f64, mesh.tile[1] as f64]));
        let (tile, shift) = match given {
            Some(t) => (t, [0.0, 0.0]),
            None => (
                [all.max[0] - all.min[0], all.max[1] - all.min[1]],
                [-all.min[0], -all.min[1]],
            ),
        };
        let extent = [0, 1, 2].map(|a| all.max[a] - all.min[a]);
        if !(tile[0] > 0.0 && tile[1] > 0.0 && tile[0].is_finite() && tile[1].is_finite()) {
            return Err(bad_tile(
                format!(
                    "tile size {}×{} must be positive and finite; the mesh's x/y extent is {}×{}",
                    tile[0], tile[1], extent[0], extent[1]
                ),
                false,
            ));
        }
        // Tolerances are fractions of the longer side: a tile 1e13 times longer than wide
        // widened every copy's box by 1e7 tiles of the short side.
        let aspect = tile[0].max(tile[1]) / tile[0].min(tile[1]);
        if aspect > MAX_TILE_ASPECT {
            return Err(bad_tile(
                format!(
                    "tile {:e}×{:e} is {aspect:.3e} times longer than wide; at most \
                     {MAX_TILE_ASPECT:e} (the mesh's x/y extent is {:.4e}×{:.4e})",
                    tile[0], tile[1], extent[0], extent[1]
                ),
                false,
            ));
        }
        // Every tile the mesh spans is a copy in every scene: a mesh thousands of tiles wide (a
        // tile given in other units, a stray vertex) would build millions of copies.
        if (0..2).any(|a| extent[a] > MAX_TILES_SPANNED * tile[a]) {
            return Err(bad_tile(
                format!(
                    "the mesh is {:.4e}×{:.4e} wide ({:.3e}×{:.3e} tiles of {:e}×{:e}); a mesh \
                     may span at most {MAX_TILES_SPANNED} tiles per axis",
                    extent[0],
                    extent[1],
                    extent[0] / tile[0],
                    extent[1] / tile[1],
                    tile[0],
                    tile[1]
                ),
                true,
            ));
        }
        // Heights are bounded too: tolerances are fractions of the largest of width, height
        // and depth, and a mesh 1e12 tall over a unit tile widened every copy's box by 1e6 tiles.
        if extent[2] > MAX_TILES_TALL * tile[0].min(tile[1]) {
            return Err(bad_tile(
                format!(
                    "the mesh is {:.4e} tall, {:.3e} times the smaller side of the {:e}×{:e} \
                     tile; a mesh may be at most {MAX_TILES_TALL} tiles tall",
                    extent[2],
                    extent[2] / tile[0].min(tile[1]),
                    tile[0],
                    tile[1]
                ),
                true,
            ));
        }
        let mut positions = mesh.positions;
        if shift != [0.0, 0.0] {
            for p in &mut positions {
                p[0] = (p[0] as f64 + shift[0]) as f32;
                p[1] = (p[1] as f64 + shift[1]) as f32;
            }
        }
        // Degenerate: the doubled area is below what f32 vertex coordinates can resolve at
        // this scene size (relative, so the test is scale-invariant).
        let scale = tile[0].max(tile[1]).max(all.max[2] - all.min[2]);
        let min_area2 = (1e-7 * scale) * (1e-7 * scale);
        let total = mesh.triangles.len();
        let (mats, material_names) = match materials {
            Some((m, names))
                if m.len() == total && m.iter().all(|&i| (i as usize) < names.len()) =>
            {
                (m, names)
            }
            Some((m, names)) => {
                return Err(bad(format!(
                    "{} triangle materials for {total} triangles and {} names",
                    m.len(),
                    names.len()
                )))
            }
            None => (vec![0; total], vec!["default".to_string()]),
        };
        let (triangles, materials): (Vec<[u32; 3]>, Vec<u32>) = mesh
            .triangles
            .into_iter()
            .zip(mats)
            .filter(|(t, _)| {
                let [a, b, c] = t.map(|k| positions[k as usize].map(f64::from));
                norm(cross(sub(b, a), sub(c, a))) > min_area2
            })
            .unzip();
        if triangles.is_empty() {
            let size = extent[0].max(extent[1]).max(extent[2]);
            if size < 1e-6 * scale {
                return Err(bad_tile(
                    format!(
                        "the mesh ({:e}×{:e}×{:e}) is too small for f32 against the {:e}×{:e} \
                         tile",
                        extent[0], extent[1], extent[2], tile[0], tile[1]
                    ),
                    false,
                ));
            }
            return Err(bad(format!("all {total} triangles have zero area")));
        }
        let bounds = bounds(&positions, &triangles);
        let tol = 1e-6 * scale;
        let seams = [0, 1].map(|axis| Seam {
            axis,
            mismatch: (bounds.min[axis] >= -tol && bounds.max[axis] <= tile[axis] + tol)
                .then(|| seam_mismatch(&positions, &triangles, axis, tile[axis])),
        });
        Ok(Self {
            origin: origin.to_string(),
            degenerate: total - triangles.len(),
            positions,
            triangles,
            tile,
            bounds,
            shift,
            seams,
            tile_from_bounds: given.is_none(),
            materials,
            material_names,
        })
    }

    /// The scene's length scale: the largest of tile width, tile height and z-range. Ray
    /// offsets and tolerances are fractions of it, so a scaled swatch bakes the same.
    pub fn scale(&self) -> f64 {
        self.tile[0]
            .max(self.tile[1])
            .max(self.bounds.max[2] - self.bounds.min[2])
    }

    /// The same swatch with every length multiplied by `k` (a power of two keeps it exact).
    pub fn scaled(&self, k: f64) -> PreparedMesh {
        let kf = k as f32;
        PreparedMesh {
            origin: self.origin.clone(),
            positions: self.positions.iter().map(|p| p.map(|c| c * kf)).collect(),
            triangles: self.triangles.clone(),
            tile: self.tile.map(|t| t * k),
            bounds: Bounds {
                min: self.bounds.min.map(|c| c * k),
                max: self.bounds.max.map(|c| c * k),
            },
            degenerate: self.degenerate,
            shift: self.shift.map(|c| c * k),
            seams: self.seams.map(|s| Seam {
                axis: s.axis,
                mismatch: s.mismatch.map(|m| m * k),
            }),
            tile_from_bounds: self.tile_from_bounds,
            materials: self.materials.clone(),
            material_names: self.material_names.clone(),
        }
    }

    /// Diagnostics of the input (skipped triangles, non-periodic seams); the bake still runs.
    pub fn warnings(&self) -> Vec<Diagnostic> {
        let mut w = Vec::new();
        if self.degenerate > 0 {
            w.push(Diagnostic::DegenerateTriangles {
                origin: self.origin.clone(),
                triangles: self.degenerate,
            });
        }
        let tolerance = 1e-4 * self.scale();
        for s in &self.seams {
            if let Some(mismatch) = s.mismatch.filter(|&m| m > tolerance) {
                w.push(Diagnostic::NotPeriodic {
                    origin: self.origin.clone(),
                    axis: s.axis,
                    tile: self.tile,
                    mismatch,
                    tolerance,
                    tile_from_bounds: self.tile_from_bounds,
                });
            }
        }
        w
    }
}

/// Something about a swatch worth telling the user; the bake still runs. `Display` is the one
/// place the words live. Each variant's doc names its fields, so the fields carry none of
/// their own.
#[allow(missing_docs)]
#[derive(Clone, Debug, PartialEq)]
pub enum Diagnostic {
    /// Lights of the dome at or below the horizon (z ≤ 0): the bake traces none of them and
    /// records K = 1 (fully occluded) wherever the swatch is covered.
    BelowHorizon {
        lights: Vec<ptm_format::HorizonLight>,
    },
    /// `triangles` zero-area triangles of the mesh `origin` were skipped.
    DegenerateTriangles { origin: String, triangles: usize },
    /// The mesh's cross-sections at the tile's opposite borders along `axis` (0 = x, 1 = y)
    /// differ by up to `mismatch` (mesh units), over the `tolerance`: seams will show.
    /// `tile_from_bounds`: the tile is the bounding box (no tile given, no `# tile` header),
    /// the likely cause when the mesh overhangs its true tile.
    NotPeriodic {
        origin: String,
        axis: usize,
        tile: [f64; 2],
        mismatch: f64,
        tolerance: f64,
        tile_from_bounds: bool,
    },
}

impl std::fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            Diagnostic::BelowHorizon { lights } => write!(
                f,
                "{} {} at or below the horizon bake to K = 1 (fully occluded): {}",
                lights.len(),
                if lights.len() == 1 { "light" } else { "lights" },
                ptm_format::lights::horizon_words(lights, 8)
            ),
            Diagnostic::DegenerateTriangles { origin, triangles } => write!(
                f,
                "{origin}: skipped {triangles} degenerate (zero-area) triangles"
            ),
            Diagnostic::NotPeriodic {
                origin,
                axis,
                tile,
                mismatch,
                tolerance,
                tile_from_bounds,
            } => {
                let (a, b) = if *axis == 0 { ("x", "W") } else { ("y", "H") };
                write!(
                    f,
                    "{origin}: not periodic over the {}×{} tile: its cross-sections at {a} = 0 \
                     and {a} = {b} differ by up to {mismatch:.3e} (tolerance {tolerance:.1e}); \
                     seams will show",
                    tile[0], tile[1]
                )?;
                if *tile_from_bounds {
                    write!(
                        f,
                        ". The tile was taken from the mesh's x/y bounding box because the OBJ \
                         has no `# tile W H` header (`ptm swatch` writes one; an OBJ editor that \
                         drops comments loses it), and a mesh whose yarns overhang their tile \
                         has a larger bounding box than its tile: put the header back or give \
                         the tile size"
                    )?;
                }
                Ok(())
            }
        }
    }
}

/// The most tiles a mesh may span along x or y (knits and pile overhang theirs by a fraction).
pub const MAX_TILES_SPANNED: f64 = 16.0;

/// The longest side of a tile over its shortest (a strip of 1024 threads by one is 1024).
pub const MAX_TILE_ASPECT: f64 = 1e4;

/// The most tiles a mesh may be tall (long pile over a small tile); the copies follow shadow
/// runs as long (`tiling::MAX_RUN_TILES` is defined from this).
pub const MAX_TILES_TALL: f64 = 256.0;

/// The OBJ reader's errors as the bake's own, with the same messages (`spec` names a file the
/// reader did not).
fn obj_error(e: ptm_swatches::Error, spec: &str) -> Error {
    match e {
        ptm_swatches::Error::Io { path, source } => Error::Io {
            path: path.display().to_string(),
            source,
        },
        ptm_swatches::Error::InvalidMesh { path, reason } => Error::InvalidMesh {
            path: path.display().to_string(),
            reason,
        },
        other => Error::InvalidMesh {
            path: spec.to_string(),
            reason: other.to_string(),
        },
    }
}

fn bounds(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Bounds {
    let mut b = Bounds {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };
    for &k in triangles.iter().flatten() {
        for (a, &c) in positions[k as usize].iter().enumerate() {
            b.min[a] = b.min[a].min(c as f64);
            b.max[a] = b.max[a].max(c as f64);
        }
    }
    b
}

/// Points and segments of the mesh's section by the plane `p[axis] = c`, in the remaining two
/// coordinates.
fn section(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    axis: usize,
    c: f64,
) -> Vec<[[f64; 2]; 2]> {
    let other = if axis == 0 { [1, 2] } else { [0, 2] };
    let mut segs = Vec::new();
    for t in triangles {
        let v = t.map(|k| positions[k as usize].map(f64::from));
        let d = v.map(|p| p[axis] - c);
        if d.iter().all(|&d| d > 0.0) || d.iter().all(|&d| d < 0.0) || d.iter().all(|&d| d == 0.0) {
            continue;
        }
        let mut pts: Vec<[f64; 2]> = Vec::with_capacity(3);
        for e in 0..3 {
            let (a, b) = (e, (e + 1) % 3);
            if d[a] == 0.0 {
                pts.push(other.map(|o| v[a][o]));
            } else if d[a] * d[b] < 0.0 {
                let s = d[a] / (d[a] - d[b]);
                pts.push(other.map(|o| v[a][o] + s * (v[b][o] - v[a][o])));
            }
        }
        if let (Some(&p), Some(&q)) = (pts.first(), pts.last()) {
            segs.push([p, q]);
        }
    }
    segs
}

fn point_segment_distance(p: [f64; 2], s: [[f64; 2]; 2]) -> f64 {
    let d = [s[1][0] - s[0][0], s[1][1] - s[0][1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 {
        (((p[0] - s[0][0]) * d[0] + (p[1] - s[0][1]) * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [s[0][0] + t * d[0] - p[0], s[0][1] + t * d[1] - p[1]];
    (q[0] * q[0] + q[1] * q[1]).sqrt()
}

/// Symmetric distance between the sections at 0 and at `period` along `axis` (ends and
/// midpoints of each segment against the other section).
fn seam_mismatch(positions: &[[f32; 3]], triangles: &[[u32; 3]], axis: usize, period: f64) -> f64 {
    let a = section(positions, triangles, axis, 0.0);
    let b = section(positions, triangles, axis, period);
    match (a.is_empty(), b.is_empty()) {
        (true, true) => return 0.0,
        (true, false) | (false, true) => return f64::INFINITY,
        _ => {}
    }
    let one_way = |from: &[[[f64; 2]; 2]], to: &[[[f64; 2]; 2]]| {
        let mut worst = 0.0f64;
        for s in from {
            let mid = [(s[0][0] + s[1][0]) / 2.0, (s[0][1] + s[1][1]) / 2.0];
            for p in [s[0], s[1], mid] {
                let d = to
                    .iter()
                    .map(|&q| point_segment_distance(p, q))
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(d);
            }
        }
        worst
    };
    one_way(&a, &b).max(one_way(&b, &a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn obj_is_triangulated_shifted_and_checked() {
        let dir = std::env::temp_dir().join(format!("ptm-bake-swatch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A quad (triangulated) plus a degenerate triangle, offset from the origin.
        let p = write(
            &dir,
            "quad.obj",
            "v 1 1 0\nv 3 1 0\nv 3 2 0\nv 1 2 0\nf 1 2 3 4\nf 1 1 2\n",
        );
        let s = PreparedMesh::load(p.to_str().unwrap(), None).unwrap();
        assert_eq!(s.triangles.len(), 2);
        assert_eq!(s.degenerate, 1);
        assert_eq!(s.tile, [2.0, 1.0]);
        assert_eq!(s.shift, [-1.0, -1.0]);
        assert_eq!(s.bounds.min, [0.0, 0.0, 0.0]);
        // A flat quad is periodic: its sections at opposite borders coincide.
        assert_eq!(s.seams.map(|s| s.mismatch), [Some(0.0), Some(0.0)]);
        assert_eq!(
            s.warnings(),
            [Diagnostic::DegenerateTriangles {
                origin: p.to_str().unwrap().into(),
                triangles: 1
            }]
        );

        let cases = [
            ("missing.obj", None, "cannot read"),
            ("empty.obj", Some(""), "empty file"),
            ("points.obj", Some("v 0 0 0\nv 1 0 0\n"), "no triangles"),
            (
                "nan.obj",
                Some("v 0 0 NaN\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
                "line 1: vertex coordinate \"NaN\" is non-finite or not a number",
            ),
            (
                "inf.obj",
                Some("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n"),
                "line 2: vertex coordinate \"inf\" is non-finite or not a number",
            ),
            (
                "range.obj",
                Some("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
                "line 4: face index 9 but the file has 3 vertices",
            ),
            (
                "zero.obj",
                Some("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
                "line 4: face index 0: OBJ indices start at 1",
            ),
            (
                "back.obj",
                Some("v 0 0 0\nv 1 0 0\nf 1 2 -3\nv 0 1 0\n"),
                "line 3: face index -3 is outside the 2 vertices so far",
            ),
            (
                "short.obj",
                Some("v 0 0 0\nv 1 0\n"),
                "line 2: a vertex needs 3 coordinates, found 2",
            ),
            (
                "tiny-tile.obj",
                Some("# tile 1e-30 1e-30\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
                "a mesh may span at most 16 tiles",
            ),
            (
                "stray.obj",
                Some("# tile 1 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e11 0 0\nf 1 2 3\nf 1 2 4\n"),
                "the mesh is 1.0000e11×1.0000e0 wide (1.000e11×1.000e0 tiles of 1e0×1e0)",
            ),
            (
                "strip.obj",
                Some("v 0 0 0\nv 1 0 0\nv 1 1e13 0\nf 1 2 3\n"),
                "times longer than wide; at most 1e4",
            ),
            (
                "tall.obj",
                Some("v 0 0 0\nv 1 0 0\nv 1 1 1e12\nf 1 2 3\n"),
                "a mesh may be at most 256 tiles tall",
            ),
            (
                "bad-tile.obj",
                Some("# tile 1 nan\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
                "line 1: \"# tile 1 nan\" needs two positive numbers",
            ),
            (
                "line.obj",
                Some("v 0 0 0\nv 1 1 0\nv 2 2 0\nf 1 2 3\n"),
                "zero area",
            ),
            (
                "flat.obj",
                Some("v 0 0 0\nv 0 0 1\nv 0 1 2\nf 1 2 3\n"),
                "`# tile` header",
            ),
        ];
        for (name, text, want) in cases {
            let p = match text {
                Some(t) => write(&dir, name, t),
                None => dir.join(name),
            };
            let e = PreparedMesh::load(p.to_str().unwrap(), None)
                .unwrap_err()
                .to_string();
            assert!(e.contains(name) && e.contains(want), "{name}: {e}");
        }
        // Zero-size, infinite, far too small and far too large tiles given explicitly.
        let p = dir.join("quad.obj");
        for (t, want) in [
            ([0.0, 1.0], "must be positive and finite"),
            (
                [f64::INFINITY, 1.0],
                "tile size inf×1 must be positive and finite",
            ),
            ([1e-30, 1e-30], "(2.000e30×1.000e30 tiles of 1e-30×1e-30)"),
            ([0.01, 0.01], "at most 16 tiles per axis"),
            ([1e30, 1e30], "too small for f32 against the 1e30×1e30 tile"),
        ] {
            let e = PreparedMesh::load(p.to_str().unwrap(), Some(t))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("`# tile` header") && !e.contains("--") && e.contains(want),
                "{t:?}: {e}"
            );
        }
        // A Latin-1 byte in a comment is no reason to refuse the mesh.
        let latin1 = dir.join("latin1.obj");
        std::fs::write(&latin1, b"# caf\xe9\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(
            PreparedMesh::load(latin1.to_str().unwrap(), None)
                .unwrap()
                .triangles
                .len(),
            1
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn far_meshes_are_recentred_in_f64() {
        // A unit quad at x = 1e9 + [0, 1] (f32 steps there are 64): recentred by whole tiles
        // before the f32 conversion, it is the quad at [0, 1] exactly.
        for (off, tile) in [(1e9f64, Some([1.0, 1.0])), (1e6 + 0.25, None)] {
            let text = format!(
                "v {a} 0 {z}\nv {b} 0 {z}\nv {b} 1 {z}\nv {a} 1 {z}\nf 1 2 3 4\n",
                a = off,
                b = off + 1.0,
                z = off
            );
            let obj = obj::parse_obj(text.as_bytes(), "far.obj").unwrap();
            let (mesh, shift) = obj.recentred(tile);
            let want_x = if tile.is_some() { off.floor() } else { off };
            assert_eq!(shift, [-want_x, 0.0]);
            let xs: Vec<f32> = mesh.positions.iter().map(|p| p[0]).collect();
            let x0 = (off - want_x) as f32;
            assert_eq!(xs, [x0, x0 + 1.0, x0 + 1.0, x0], "{off}");
            assert!(mesh.positions.iter().all(|p| p[2] == 0.0));
        }
    }

    #[test]
    fn seam_mismatch_is_measured() {
        // A ramp from z = 0 at x = 0 to z = 0.3 at x = 1: sections differ by 0.3 in z.
        let mesh = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.3],
                [1.0, 1.0, 0.3],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            tile: [1.0, 1.0],
        };
        let s = PreparedMesh::from_mesh(mesh, None, "ramp").unwrap();
        assert!(
            (s.seams[0].mismatch.unwrap() - 0.3).abs() < 1e-6,
            "{:?}",
            s.seams
        );
        assert_eq!(s.seams[1].mismatch, Some(0.0));
        let w = s.warnings();
        assert!(
            matches!(&w[..], [Diagnostic::NotPeriodic { axis: 0, mismatch, .. }]
                if (mismatch - 0.3).abs() < 1e-6),
            "{w:?}"
        );
        assert!(w[0].to_string().contains("x = 0") && w[0].to_string().contains("3.000e-1"));
    }
}
