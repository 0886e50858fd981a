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
        // Row r's entries A[r][q] for q = r − 1, r − 2, … lie at v[r·s1 + 1], v[r·s1 + 2], …, so
        // Σ_q L[i][q]·L[j][q] over the columns both rows reach is a dot product of two
        // contiguous runs (t = j − q = 1 …).
        for j in 0..n {
            let m = j - j.saturating_sub(bw);
            let row = &l[j * s1 + 1..j * s1 + 1 + m];
            let s = l[j * s1] - dot(row, row);
            if s.is_nan() || s <= 0.0 {
                return None;
            }
            let d = s.sqrt();
            l[j * s1] = d;
            for i in j + 1..(j + bw + 1).min(n) {
                let (off, m) = (i - j, j - i.saturating_sub(bw));
                let (head, tail) = l.split_at_mut(i * s1);
                let x = tail[off]
                    - dot(
                        &tail[off + 1..off + 1 + m],
                        &head[j * s1 + 1..j * s1 + 1 + m],
                    );
                tail[off] = x / d;
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

/// Σ a·b with four independent partial sums (so that the compiler can keep them in vector
/// lanes; the order is fixed, so the result is the same on every machine).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
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
