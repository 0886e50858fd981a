//! The roughness of a learned basis's tables (`learned.rs`): ‖D b‖², D the second
//! differences along both grid axes, and its DᵀD.

/// The second-difference operator's DᵀD over the G × G grid (dense G² × G²).
pub(super) fn roughness_matrix(g: usize) -> Vec<f64> {
    let g2 = g * g;
    let mut dtd = vec![0f64; g2 * g2];
    let mut add = |cells: [usize; 3]| {
        let coef = [1.0, -2.0, 1.0];
        for a in 0..3 {
            for b in 0..3 {
                dtd[cells[a] * g2 + cells[b]] += coef[a] * coef[b];
            }
        }
    };
    for j in 0..g {
        for i in 1..g - 1 {
            add([j * g + i - 1, j * g + i, j * g + i + 1]);
        }
    }
    for j in 1..g - 1 {
        for i in 0..g {
            add([(j - 1) * g + i, j * g + i, (j + 1) * g + i]);
        }
    }
    dtd
}

/// ‖D b‖² of the tables through DᵀD: bᵀ(DᵀD ⊗ I)b.
pub(super) fn roughness(dtd: &[f64], b: &[f64], g2: usize, k: usize) -> f64 {
    let mut s = 0.0;
    for c1 in 0..g2 {
        for c2 in 0..g2 {
            let d = dtd[c1 * g2 + c2];
            if d != 0.0 {
                for j in 0..k {
                    s += d * b[c1 * k + j] * b[c2 * k + j];
                }
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::super::learn::node;
    use super::super::GRID;
    use super::*;

    #[test]
    fn roughness_is_zero_on_bilinear_tables_and_positive_else() {
        let g2 = GRID * GRID;
        let dtd = roughness_matrix(GRID);
        let mut b = vec![0f64; g2];
        for j in 0..GRID {
            for i in 0..GRID {
                let (u, v) = node(i, j);
                b[j * GRID + i] = 1.0 + 2.0 * u - v + 0.5 * u * v;
            }
        }
        assert!(roughness(&dtd, &b, g2, 1).abs() < 1e-9);
        for j in 0..GRID {
            for i in 0..GRID {
                let (u, _) = node(i, j);
                b[j * GRID + i] = u * u;
            }
        }
        assert!(roughness(&dtd, &b, g2, 1) > 1e-3);
    }
}
