//! A symmetric positive definite banded matrix and its Cholesky solve: the Hessian of the
//! learned basis's table step (each light touches 4 grid cells, the roughness couples cells 2
//! apart along each axis, so in grid-major order the half-bandwidth is 2G cells).
/// A symmetric banded matrix (lower band, half-bandwidth `bw`) and its Cholesky solve.
pub(crate) struct Band {
    pub(crate) n: usize,
    pub(crate) bw: usize,
    /// `v[i·(bw + 1) + (i − j)]` = A[i][j] for j ≤ i ≤ j + bw.
    pub(crate) v: Vec<f64>,
}

impl Band {
    pub(crate) fn new(n: usize, bw: usize) -> Band {
        Band {
            n,
            bw,
            v: vec![0.0; n * (bw + 1)],
        }
    }

    /// Adds x to A[i][j] (i ≥ j; the upper triangle is implied).
    #[inline]
    pub(crate) fn add(&mut self, i: usize, j: usize, x: f64) {
        debug_assert!(i >= j && i - j <= self.bw);
        self.v[i * (self.bw + 1) + (i - j)] += x;
    }

    /// Solves A·x = g in place of a copy (banded Cholesky); `None` when not positive definite.
    pub(crate) fn solve(&self, g: &[f64]) -> Option<Vec<f64>> {
        let (n, bw) = (self.n, self.bw);
        let s1 = bw + 1;
        let mut l = self.v.clone();
        for j in 0..n {
            let lo = j.saturating_sub(bw);
            let mut s = l[j * s1];
            for q in lo..j {
                let x = l[j * s1 + (j - q)];
                s -= x * x;
            }
            if s.is_nan() || s <= 0.0 {
                return None;
            }
            let d = s.sqrt();
            l[j * s1] = d;
            for i in j + 1..(j + bw + 1).min(n) {
                let lo = i.saturating_sub(bw);
                let mut s = l[i * s1 + (i - j)];
                for q in lo..j {
                    s -= l[i * s1 + (i - q)] * l[j * s1 + (j - q)];
                }
                l[i * s1 + (i - j)] = s / d;
            }
        }
        let mut y = g.to_vec();
        for i in 0..n {
            for q in i.saturating_sub(bw)..i {
                y[i] -= l[i * s1 + (i - q)] * y[q];
            }
            y[i] /= l[i * s1];
        }
        for i in (0..n).rev() {
            for q in i + 1..(i + bw + 1).min(n) {
                y[i] -= l[q * s1 + (q - i)] * y[q];
            }
            y[i] /= l[i * s1];
        }
        Some(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn band_cholesky_matches_a_dense_solve() {
        let n = 40;
        let bw = 5;
        let mut band = Band::new(n, bw);
        let mut dense = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in i.saturating_sub(bw)..=i {
                let x = if i == j {
                    10.0 + i as f64 * 0.1
                } else {
                    ((i * 7 + j * 3) % 11) as f64 * 0.1 - 0.5
                };
                band.add(i, j, x);
                dense[(i, j)] = x;
                dense[(j, i)] = x;
            }
        }
        let g: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let x = band.solve(&g).unwrap();
        let want = dense
            .cholesky()
            .unwrap()
            .solve(&nalgebra::DVector::from_vec(g));
        for i in 0..n {
            assert!((x[i] - want[i]).abs() < 1e-12, "{i}");
        }
    }
}
