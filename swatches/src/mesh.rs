//! The triangle mesh of one swatch tile and a few measurements (its OBJ reader and writer,
//! `Mesh::read_obj` and `Mesh::write_obj`, live with the OBJ format in `obj.rs`).

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
    /// Vertex positions in the swatch frame (user units, z up).
    pub positions: Vec<[f32; 3]>,
    /// Triangles as 0-based vertex indices, wound so that normals point outwards.
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
}
