//! The occlusion PTM in memory: one coefficient plane per basis monomial.

use crate::Basis;

/// An occlusion PTM: per texel, the coefficients of K(u, v) in `basis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Ptm {
    pub basis: Basis,
    /// Texels per row.
    pub width: usize,
    /// Rows; row 0 is the far edge y = H of the tile.
    pub height: usize,
    /// Tile size (W, H) in swatch units.
    pub tile: [f64; 2],
    /// `planes[i]` holds coefficient i (basis order) for every texel, row-major.
    pub planes: Vec<Vec<f32>>,
}

impl Ptm {
    /// K at texel (x, y) for light projection (u, v), clamped to [0, 1].
    pub fn eval(&self, x: usize, y: usize, u: f32, v: f32) -> f32 {
        let i = y * self.width + x;
        let mut c = [0f32; 16];
        for (k, p) in self.planes.iter().enumerate() {
            c[k] = p[i];
        }
        self.basis
            .eval(&c[..self.basis.len()], u, v)
            .clamp(0.0, 1.0)
    }
}
