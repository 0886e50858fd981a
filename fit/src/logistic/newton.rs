//! One tile of the logistic kernel: a lane per texel, `S::LANES` of them, the coefficients in
//! registers. The warm start, a Newton step (gradient and Hessian from the tables' rows and
//! products, the f32 Cholesky solve lane by lane, its f64 fallback), and the final pass
//! (residuals, classes, held-out error). Written once over [`Simd`]; the token `cpu` proves the
//! instruction set (see `crate::simd`).
use super::tables::Tables;
use crate::simd::Simd;

/// Largest Newton step (max-norm of the coefficient change) taken at once: far from the optimum
/// a full step can overshoot; the cap keeps every iterate bounded without a line search.
const MAX_STEP: f64 = 16.0;

/// Logit of the warm start is taken of K clamped to [EPS, 1 − EPS].
const WARM_EPS: f32 = 0.02;

/// Per-texel result of the kernel.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TexelFit {
    pub c: [f32; 11],
    pub iterations: u32,
    pub converged: bool,
    /// Every fitting light's K is 0 or 1 and σ(p) classifies each on the right side of ½.
    pub separable: bool,
    /// Every fitting light's K is the same 0 or 1.
    pub constant: bool,
    /// Weighted RMS of σ(p) − K over the fitting lights, max |σ(p) − K|, RMS on held-out lights.
    pub rms: f32,
    pub max: f32,
    pub holdout: f32,
}

/// Solves (H + ρI)·δ = g for a symmetric positive semi-definite H given as its packed upper
/// triangle, by Cholesky in f64; where H + ρI is singular (no ridge and a rank-deficient dome),
/// by a pseudo-inverse that drops eigenvalues below 1e-10 of the largest. Returns δ.
fn solve_spd<const M: usize>(hp: &[f64], g: &[f64], ridge: f64) -> [f64; 16] {
    let m = M;
    let mut a = [[0f64; M]; M];
    let mut q = 0;
    for i in 0..M {
        for j in i..M {
            a[i][j] = hp[q];
            a[j][i] = hp[q];
            q += 1;
        }
        a[i][i] += ridge;
    }
    let scale = (0..M).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    let mut l = a;
    let mut ok = scale > 0.0;
    for j in 0..M {
        let mut s = l[j][j];
        for k in 0..j {
            s -= l[j][k] * l[j][k];
        }
        // Not positive (or NaN): not positive definite at this precision.
        if s.is_nan() || s <= 1e-13 * scale {
            ok = false;
            break;
        }
        let d = s.sqrt();
        l[j][j] = d;
        for i in j + 1..M {
            let mut s = l[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / d;
        }
    }
    let mut x = [0f64; 16];
    if ok {
        let mut y = [0f64; M];
        for i in 0..M {
            let mut s = g[i];
            for k in 0..i {
                s -= l[i][k] * y[k];
            }
            y[i] = s / l[i][i];
        }
        for i in (0..M).rev() {
            let mut s = y[i];
            for k in i + 1..M {
                s -= l[k][i] * x[k];
            }
            x[i] = s / l[i][i];
        }
        return x;
    }
    let h = nalgebra::DMatrix::from_fn(m, m, |i, j| a[i][j]);
    let eig = nalgebra::SymmetricEigen::new(h);
    let top = eig.eigenvalues.iter().fold(0.0f64, |a, &b| a.max(b));
    for k in 0..m {
        let e = eig.eigenvalues[k];
        if e > 1e-10 * top && e > 0.0 {
            let v = eig.eigenvectors.column(k);
            let proj: f64 = (0..m).map(|i| v[i] * g[i]).sum::<f64>() / e;
            for i in 0..m {
                x[i] += proj * v[i];
            }
        }
    }
    x
}

/// Warm start of one tile: least squares of the clamped logits, c = Σₙ Pₙ·logit(kₙ).
#[inline(always)]
pub(super) fn warm_start<S: Simd, const M: usize>(
    cpu: S,
    t: &Tables,
    kt: &[f32],
) -> [[f32; 16]; M] {
    let l = S::LANES;
    let one = cpu.splat(1.0);
    let (lo, hi) = (cpu.splat(WARM_EPS), cpu.splat(1.0 - WARM_EPS));
    let mut c = [cpu.splat(0.0); M];
    for n in 0..t.nfit {
        let kv = cpu.load(&kt[n * l..]);
        let k = cpu.min(cpu.max(kv, lo), hi);
        let lg = cpu.where_nonneg(kv, cpu.ln(cpu.mul(k, cpu.recip(cpu.sub(one, k)))));
        let pw = &t.warm[n * M..(n + 1) * M];
        for j in 0..M {
            c[j] = cpu.fma(cpu.splat(pw[j]), lg, c[j]);
        }
    }
    let mut cl = [[0f32; 16]; M];
    for j in 0..M {
        cpu.store(c[j], &mut cl[j]);
    }
    cl
}

/// z = aₙ·c for light n of a tile, summed in two chains (even and odd monomials) to halve its
/// latency; the Newton step and the final pass take z from here, so both see the same sums.
#[inline(always)]
fn z_of<S: Simd, const M: usize>(cpu: S, t: &Tables, c: &[S::V; M], n: usize) -> S::V {
    let an = &t.a[n * M..(n + 1) * M];
    let (mut z0, mut z1) = (cpu.splat(0.0), cpu.splat(0.0));
    let mut j = 0;
    while j + 1 < M {
        z0 = cpu.fma(cpu.splat(an[j]), c[j], z0);
        z1 = cpu.fma(cpu.splat(an[j + 1]), c[j + 1], z1);
        j += 2;
    }
    if j < M {
        z0 = cpu.fma(cpu.splat(an[j]), c[j], z0);
    }
    cpu.add(z0, z1)
}

/// For fitting light n of a tile: ω(σ(z) − k) and ωσ(z)(1 − σ(z)), z = aₙ·c (0 where the sample
/// is left out).
#[inline(always)]
fn residual_weight<S: Simd, const M: usize>(
    cpu: S,
    t: &Tables,
    kt: &[f32],
    c: &[S::V; M],
    n: usize,
) -> (S::V, S::V) {
    let l = S::LANES;
    let kv = cpu.load(&kt[n * l..]);
    let p = cpu.sigmoid(z_of(cpu, t, c, n));
    let o = cpu.where_nonneg(kv, cpu.splat(t.omega[n]));
    let r = cpu.mul(o, cpu.sub(p, kv));
    let w = cpu.mul(cpu.mul(o, p), cpu.sub(cpu.splat(1.0), p));
    (r, w)
}

/// One Newton step for the active lanes of one tile (K packed `[used light][lane]`; a value
/// < 0 marks a sample to leave out). Returns, per lane, whether it converged or failed now.
#[inline(always)]
pub(super) fn newton_step<S: Simd, const M: usize, const D: usize>(
    cpu: S,
    t: &Tables,
    kt: &[f32],
    cl: &mut [[f32; 16]; M],
    active: &[bool],
    tolerance: f64,
) -> [bool; 16] {
    let l = S::LANES;
    let (zero, one) = (cpu.splat(0.0), cpu.splat(1.0));
    let mut c = [zero; M];
    for j in 0..M {
        c[j] = cpu.load(&cl[j]);
    }
    let mut g = [zero; M];
    let mut h = [zero; D];
    // Two lights at a time: their chains (z, σ, r, w) are independent, so the core overlaps
    // them instead of waiting out one light's latency before the next.
    let pairs = t.nfit / 2;
    for np in 0..pairs {
        let n = 2 * np;
        let (r0, w0) = residual_weight::<S, M>(cpu, t, kt, &c, n);
        let (r1, w1) = residual_weight::<S, M>(cpu, t, kt, &c, n + 1);
        let (a0, a1) = (&t.a[n * M..(n + 1) * M], &t.a[(n + 1) * M..(n + 2) * M]);
        let (q0, q1) = (&t.q[n * D..(n + 1) * D], &t.q[(n + 1) * D..(n + 2) * D]);
        for j in 0..M {
            g[j] = cpu.fma(r1, cpu.splat(a1[j]), cpu.fma(r0, cpu.splat(a0[j]), g[j]));
        }
        for e in 0..D {
            h[e] = cpu.fma(w1, cpu.splat(q1[e]), cpu.fma(w0, cpu.splat(q0[e]), h[e]));
        }
    }
    if t.nfit % 2 == 1 {
        let n = t.nfit - 1;
        let (r, w) = residual_weight::<S, M>(cpu, t, kt, &c, n);
        let (an, qn) = (&t.a[n * M..(n + 1) * M], &t.q[n * D..(n + 1) * D]);
        for j in 0..M {
            g[j] = cpu.fma(r, cpu.splat(an[j]), g[j]);
        }
        for e in 0..D {
            h[e] = cpu.fma(w, cpu.splat(qn[e]), h[e]);
        }
    }
    // The Newton system (H + ρI)·δ = ∇J, lane-parallel: Cholesky in f32. An inexact step is
    // still a descent step and the gradient, not the step, fixes the converged point; a lane
    // whose pivot is not safely positive (no ridge on a rank-deficient dome) is solved again in
    // f64 with a pseudo-inverse.
    let rho = cpu.splat(t.ridge as f32);
    let mut grad = [zero; M];
    for j in 0..M {
        grad[j] = cpu.fma(rho, c[j], g[j]);
    }
    let mut lo = [[zero; M]; M];
    {
        let mut q = 0;
        for i in 0..M {
            for j in i..M {
                lo[j][i] = h[t.pair[q]];
                q += 1;
            }
            lo[i][i] = cpu.add(lo[i][i], rho);
        }
    }
    let mut scale = zero;
    for i in 0..M {
        scale = cpu.max(scale, lo[i][i]);
    }
    let floor = cpu.mul(scale, cpu.splat(1e-6));
    let mut bad = zero;
    for j in 0..M {
        let mut p = lo[j][j];
        for k in 0..j {
            p = cpu.sub(p, cpu.mul(lo[j][k], lo[j][k]));
        }
        bad = cpu.add(bad, cpu.where_nonneg(cpu.sub(floor, p), one));
        let d = cpu.sqrt(cpu.max(p, floor));
        let inv = cpu.recip(d);
        lo[j][j] = d;
        for i in j + 1..M {
            let mut x = lo[i][j];
            for k in 0..j {
                x = cpu.sub(x, cpu.mul(lo[i][k], lo[j][k]));
            }
            lo[i][j] = cpu.mul(x, inv);
        }
    }
    let mut y = [zero; M];
    for i in 0..M {
        let mut x = grad[i];
        for k in 0..i {
            x = cpu.sub(x, cpu.mul(lo[i][k], y[k]));
        }
        y[i] = cpu.div(x, lo[i][i]);
    }
    let mut dv = [zero; M];
    for i in (0..M).rev() {
        let mut x = y[i];
        for k in i + 1..M {
            x = cpu.sub(x, cpu.mul(lo[k][i], dv[k]));
        }
        dv[i] = cpu.div(x, lo[i][i]);
    }
    let mut dl = [[0f32; 16]; M];
    let mut gl = [[0f32; 16]; M];
    for j in 0..M {
        cpu.store(dv[j], &mut dl[j]);
        cpu.store(grad[j], &mut gl[j]);
    }
    let mut badl = [0f32; 16];
    cpu.store(bad, &mut badl);
    let fallback = (0..l).any(|q| active[q] && badl[q] > 0.0);
    let mut hl = [[0f32; 16]; D];
    if fallback {
        for e in 0..D {
            cpu.store(h[e], &mut hl[e]);
        }
    }
    let mut done = [false; 16];
    for q in 0..l {
        if !active[q] {
            continue;
        }
        let mut delta = [0f64; 16];
        if badl[q] > 0.0 {
            let mut hp = [0f64; 136];
            for (e, &k) in t.pair.iter().enumerate() {
                hp[e] = hl[k][q] as f64;
            }
            let mut grad = [0f64; 16];
            for j in 0..M {
                grad[j] = gl[j][q] as f64;
            }
            delta = solve_spd::<M>(&hp[..t.pair.len()], &grad[..M], t.ridge);
        } else {
            for j in 0..M {
                delta[j] = dl[j][q] as f64;
            }
        }
        let big = delta[..M].iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        if !big.is_finite() {
            done[q] = true;
            continue;
        }
        if big > MAX_STEP {
            for x in &mut delta[..M] {
                *x *= MAX_STEP / big;
            }
        }
        let decrement: f64 = (0..M).map(|j| delta[j] * gl[j][q] as f64).sum();
        for j in 0..M {
            cl[j][q] = (cl[j][q] as f64 - delta[j]) as f32;
        }
        done[q] = decrement <= tolerance * t.omega_sum || big <= 1e-6;
    }
    done
}

/// Residuals of σ(p) over the fitting lights, classification and held-out error of one tile
/// at its final coefficients.
#[inline(always)]
pub(super) fn final_pass<S: Simd, const M: usize>(
    cpu: S,
    t: &Tables,
    kt: &[f32],
    cl: &[[f32; 16]; M],
    live: &[bool],
    out: &mut [TexelFit],
) {
    let l = S::LANES;
    let mut c = [cpu.splat(0.0); M];
    for j in 0..M {
        c[j] = cpu.load(&cl[j]);
    }
    // All in vectors: a masked-out sample (k < 0) adds nothing; equality tests on K (exactly 0
    // or 1) are sign tests, since valid K lies in [0, 1].
    let (zero, one) = (cpu.splat(0.0), cpu.splat(1.0));
    let (mut ss, mut mx, mut hs, mut hn) = (zero, zero, zero, zero);
    let (mut valid, mut ones, mut zeros, mut wrong) = (zero, zero, zero, zero);
    for n in 0..t.used.len() {
        let z = z_of(cpu, t, &c, n);
        let kv = cpu.load(&kt[n * l..]);
        let e = cpu.sub(cpu.sigmoid(z), kv);
        let e2 = cpu.where_nonneg(kv, cpu.mul(e, e));
        let v = cpu.where_nonneg(kv, one);
        if n < t.nfit {
            ss = cpu.fma(cpu.splat(t.omega[n]), e2, ss);
            mx = cpu.max(mx, cpu.where_nonneg(kv, cpu.max(e, cpu.sub(zero, e))));
            valid = cpu.add(valid, v);
            // k = 1 ⇔ k − 1 ≥ 0; k = 0 ⇔ k ≥ 0 and −k ≥ 0.
            let is1 = cpu.where_nonneg(cpu.sub(kv, one), one);
            let is0 = cpu.where_nonneg(kv, cpu.where_nonneg(cpu.sub(zero, kv), one));
            ones = cpu.add(ones, is1);
            zeros = cpu.add(zeros, is0);
            // Misclassified binary samples: k = 1 with z ≤ 0, k = 0 with z ≥ 0. Fractional
            // samples (valid − ones − zeros) are added once after the loop: the counts are
            // small integers, exact in f32, so the sum is the same in any order.
            let w1 = cpu.where_nonneg(cpu.sub(zero, z), is1);
            let w0 = cpu.where_nonneg(z, is0);
            wrong = cpu.add(wrong, cpu.add(w1, w0));
        } else {
            hs = cpu.add(hs, e2);
            hn = cpu.add(hn, v);
        }
    }
    wrong = cpu.add(wrong, cpu.sub(cpu.sub(valid, ones), zeros));
    let mut lanes = [[0f32; 16]; 8];
    for (dst, v) in lanes
        .iter_mut()
        .zip([ss, mx, hs, hn, valid, ones, zeros, wrong])
    {
        cpu.store(v, dst);
    }
    let [ss, mx, hs, hn, valid, ones, zeros, wrong] = lanes;
    for q in 0..l.min(out.len()) {
        let o = &mut out[q];
        if !live[q] {
            *o = TexelFit::default();
            o.c[..M].copy_from_slice(&t.hole[..M]);
            continue;
        }
        for j in 0..M {
            o.c[j] = cl[j][q];
        }
        o.constant = valid[q] > 0.0 && (ones[q] == valid[q] || zeros[q] == valid[q]);
        o.separable = valid[q] > 0.0 && wrong[q] == 0.0 && !o.constant;
        o.rms = if t.omega_sum > 0.0 {
            (ss[q] / t.omega_sum as f32).sqrt()
        } else {
            0.0
        };
        o.max = mx[q];
        o.holdout = if hn[q] > 0.0 {
            (hs[q] / hn[q]).sqrt()
        } else {
            0.0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_solver_handles_singular_matrices() {
        // Rank 1: H = e₀e₀ᵀ; g along e₀ and e₁: the pseudo-inverse keeps only e₀.
        let hp = [1.0, 0.0, 0.0];
        let x = solve_spd::<2>(&hp, &[2.0, 3.0], 0.0);
        assert!((x[0] - 2.0).abs() < 1e-12 && x[1].abs() < 1e-12);
        let x = solve_spd::<2>(&[4.0, 2.0, 3.0], &[2.0, 1.0], 0.0);
        // [[4,2],[2,3]]·x = [2,1] → x = [0.5, 0]
        assert!((x[0] - 0.5).abs() < 1e-12 && x[1].abs() < 1e-12);
    }
}
