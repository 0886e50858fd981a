//! The gauge of a learned basis (`learned.rs`): the tables turned orthonormal over the fitting
//! lights, ordered by the variance of the coefficients and signed, as stored.
use nalgebra::{DMatrix, SymmetricEigen};

use super::problem::{rows, Problem};
use super::GRID;
use ptm_format::LearnedTable;

/// The tables in the documented gauge (module docs), as stored.
pub(super) fn gauge(p: &Problem, b: &[f64], c: &[f64]) -> LearnedTable {
    let k = p.k;
    let g2 = GRID * GRID;
    let a = rows(p, b);
    let wsum: f64 = p.omega.iter().sum();
    // Gram of the terms over the fitting lights, normalised: G = Σ ω a aᵀ / Σ ω = L Lᵀ.
    let gram = DMatrix::from_fn(k, k, |i, j| {
        (0..p.n)
            .map(|q| p.omega[q] * a[q * k + i] * a[q * k + j])
            .sum::<f64>()
            / wsum
    });
    let l = gram
        .clone()
        .cholesky()
        .map(|ch| ch.l())
        .unwrap_or_else(|| DMatrix::identity(k, k));
    let linv = l
        .clone()
        .try_inverse()
        .unwrap_or_else(|| DMatrix::identity(k, k));
    // Orthonormal terms B' = B L⁻ᵀ carry coefficients c' = Lᵀ c; their second moments' eigenvectors V.
    let mut sm = DMatrix::<f64>::zeros(k, k);
    for x in 0..p.s {
        let cx = nalgebra::DVector::from_column_slice(&c[x * k..(x + 1) * k]);
        let cp = l.transpose() * cx;
        sm += &cp * cp.transpose();
    }
    let eig = SymmetricEigen::new(sm);
    let mut order: Vec<usize> = (0..k).collect();
    order.sort_by(|&x, &y| {
        eig.eigenvalues[y]
            .partial_cmp(&eig.eigenvalues[x])
            .unwrap_or(std::cmp::Ordering::Equal)
            .then(x.cmp(&y))
    });
    // Final transform T (k × k): b''[cell] = T b[cell], T = Vᵀ L⁻¹ with V's columns reordered.
    let mut t = DMatrix::<f64>::zeros(k, k);
    let vt_linv = eig.eigenvectors.transpose() * &linv;
    for (r, &o) in order.iter().enumerate() {
        for j in 0..k {
            t[(r, j)] = vt_linv[(o, j)];
        }
    }
    // Signs: each term's mean over the fitting lights positive (its largest entry when the
    // mean is zero).
    let mut values = vec![0f32; k * g2];
    let mut tb = vec![0f64; g2 * k];
    for cell in 0..g2 {
        for r in 0..k {
            tb[cell * k + r] = (0..k).map(|j| t[(r, j)] * b[cell * k + j]).sum();
        }
    }
    let a2 = rows(p, &tb);
    for r in 0..k {
        let mean: f64 = (0..p.n).map(|q| p.omega[q] * a2[q * k + r]).sum();
        let sign = if mean.abs() > 1e-9 * wsum {
            mean.signum()
        } else {
            let big = (0..g2).map(|cell| tb[cell * k + r]).fold(0f64, |m, x| {
                if x.abs() > m.abs() {
                    x
                } else {
                    m
                }
            });
            if big < 0.0 {
                -1.0
            } else {
                1.0
            }
        };
        for cell in 0..g2 {
            values[r * g2 + cell] = (sign * tb[cell * k + r]) as f32;
        }
    }
    LearnedTable {
        grid: GRID,
        terms: k,
        values,
    }
}
