//! The triangle mesh of one swatch tile.

/// A swatch: triangles in the swatch frame (z up) and the periodic tile [0, W]×[0, H] they
/// repeat over. Geometry may cross the tile border; the baker tiles copies at multiples of W, H.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Tile size (W, H) in the swatch's units.
    pub tile: [f32; 2],
}
