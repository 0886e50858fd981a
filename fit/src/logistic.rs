//! Maximum-likelihood fit of the logistic link K = σ(p(u, v)) per texel.
//!
//! K is the fraction of a texel's covered footprint samples that are occluded, so each light's
//! value is a binomial proportion. Per texel the fit minimises the binomial deviance (the
//! cross-entropy of σ(p) against K, weighted per light as the identity fit is) plus a ridge:
//!
//!   J(c) = Σₙ ωₙ·[−kₙ·ln σ(zₙ) − (1 − kₙ)·ln(1 − σ(zₙ))] + ½·ρ·|c|²,   zₙ = aₙ·c,
//!
//! with ρ = λ·tr(AᵀΩA)/M (λ relative to the mean eigenvalue, as the identity ridge). The
//! number of samples per texel scales J uniformly, so it does not move the optimum: fractions
//! from a stored stack and exact counts from a streaming bake fit the same. Newton (IRLS) per
//! texel: ∇J = Σ ωₙ(σₙ − kₙ)·aₙ + ρc, H = Σ ωₙσₙ(1 − σₙ)·aₙaₙᵀ + ρI. H's packed entries are
//! the per-texel weights times the distinct products mᵢmⱼ of the basis ([`ptm_format::basis::products`]):
//! a [texels × lights] · [lights × products] matrix product, done tile by tile in registers.
//!
//! Texels whose samples a polynomial boundary separates exactly (always lit, always occluded,
//! a clean step) have their unregularised optimum at infinity; the ridge keeps it finite, and
//! they are counted (`separable`, `constant`). The warm start is the least-squares fit of the
//! clamped logits with the shared pseudo-inverse of the identity fit (one more product).
//!
//! The kernel is generic over the basis size, the product count and the tile width; it is
//! compiled three times — portable (8 lanes), AVX2 + FMA (8) and AVX-512F (16) — and picked at
//! run time. All three run the same arithmetic in the same order; they differ only in FMA
//! contraction and width.
use rayon::prelude::*;

use crate::simd::{Portable, Simd};
use ptm_format::basis::products;
use ptm_format::Basis;

/// Default ridge λ of the logistic fit (relative to the mean eigenvalue of AᵀΩA).
pub const DEFAULT_RIDGE: f64 = 1e-5;
/// Default stopping tolerance: a texel stops when its Newton decrement (the objective's
/// predicted fall) is at most this per unit of light weight, or its step is below 1e-6. Newton
/// converges quadratically, so the step that meets it leaves far less: on the plain weave,
/// 1e-5 … 1e-10 give the same held-out error to five digits and K within 3e-6 of an f64 solve
/// (tests/logistic.rs); 1e-7 saves 0.6 iterations per texel against 1e-10.
pub const DEFAULT_TOLERANCE: f64 = 1e-7;
/// Default cap on Newton iterations per texel (texels that hit it are counted).
pub const DEFAULT_MAX_ITERATIONS: u32 = 30;

/// Largest Newton step (max-norm of the coefficient change) taken at once: far from the optimum
/// a full step can overshoot; the cap keeps every iterate bounded without a line search.
const MAX_STEP: f64 = 16.0;

/// Constant coefficient of a texel with no covered sample (a hole in the cloth): σ(−30) ≈ 1e-13,
/// so a hole reads as K = 0, "lit", as zero coefficients do under the identity link.
pub const HOLE_LOGIT: f32 = -30.0;

/// Logit of the warm start is taken of K clamped to [EPS, 1 − EPS].
const WARM_EPS: f32 = 0.02;

/// Shared tables of one fit (one design: distant lights, one MIP level or all).
pub(crate) struct Tables {
    pub m: usize,
    /// Fitting lights (ω > 0, not held out), then held-out lights: indices into the light set.
    pub used: Vec<usize>,
    pub nfit: usize,
    /// Per used light: its design row (M terms at its mapped (u, v)).
    pub a: Vec<f32>,
    /// Per fitting light: the distinct products of its terms (D).
    pub q: Vec<f32>,
    /// Per fitting light: its weight ω.
    pub omega: Vec<f32>,
    /// Per fitting light: its row of the identity fit's operator P (c₀ = Σₙ Pₙ·logit kₙ).
    pub warm: Vec<f32>,
    /// Packed upper-triangle entry (i ≤ j, row-major) → index of its product.
    pub pair: Vec<usize>,
    /// Absolute ridge ρ.
    pub ridge: f64,
    pub tolerance: f64,
    pub max_iterations: u32,
    /// Σ ω over the fitting lights.
    pub omega_sum: f64,
    /// Index of the constant term.
    pub constant_term: usize,
}

impl Tables {
    /// From the design rows of every light (`a`: lights × M, f64), weights, held-out lights and
    /// the identity operator rows `p` (lights × M).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        basis: Basis,
        design: &[Vec<f64>],
        w: &[f64],
        held: &[usize],
        p: &[Vec<f64>],
        lambda: f64,
        tolerance: f64,
        max_iterations: u32,
    ) -> Tables {
        let m = basis.len();
        let (prods, pair) = products(basis);
        let d = prods.len();
        let fit: Vec<usize> = (0..w.len())
            .filter(|&i| w[i] > 0.0 && !held.contains(&i))
            .collect();
        let used: Vec<usize> = fit.iter().chain(held).copied().collect();
        let mut a = Vec::with_capacity(used.len() * m);
        for &l in &used {
            a.extend(design[l].iter().map(|&x| x as f32));
        }
        // Products from the (u, v) of each light: the same monomials, exponents added.
        let monos = basis.monomials();
        let mut q = Vec::with_capacity(fit.len() * d);
        for &l in &fit {
            // Recover (u, v) from the linear terms' values: every basis has u and v.
            let ju = monos.iter().position(|x| (x.pu, x.pv) == (1, 0)).unwrap();
            let jv = monos.iter().position(|x| (x.pu, x.pv) == (0, 1)).unwrap();
            let (u, v) = (design[l][ju], design[l][jv]);
            q.extend(
                prods
                    .iter()
                    .map(|&(pu, pv)| (u.powi(pu as i32) * v.powi(pv as i32)) as f32),
            );
        }
        let omega: Vec<f32> = fit.iter().map(|&l| w[l] as f32).collect();
        let omega_sum: f64 = fit.iter().map(|&l| w[l]).sum();
        let mut warm = Vec::with_capacity(fit.len() * m);
        for &l in &fit {
            warm.extend(p[l].iter().map(|&x| x as f32));
        }
        // Mean eigenvalue of AᵀΩA: trace / M.
        let trace: f64 = fit
            .iter()
            .map(|&l| w[l] * design[l].iter().map(|x| x * x).sum::<f64>())
            .sum();
        debug_assert_eq!(q.len(), fit.len() * d);
        Tables {
            m,
            nfit: fit.len(),
            used,
            a,
            q,
            omega,
            warm,
            pair,
            ridge: lambda * trace / m as f64,
            tolerance,
            max_iterations,
            omega_sum,
            constant_term: monos.iter().position(|x| (x.pu, x.pv) == (0, 0)).unwrap(),
        }
    }
}

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

/// Per-slot Newton state of a block: a slot is one lane of one tile of the work buffer.
struct Slots<const M: usize> {
    /// Coefficients per tile, `[term][lane]`.
    c: Vec<[[f32; 16]; M]>,
    /// Block-local texel held by each slot (tile·16 + lane), if any.
    texel: Vec<Option<usize>>,
    active: Vec<bool>,
}

/// Warm start of one tile: least squares of the clamped logits, c = Σₙ Pₙ·logit(kₙ).
#[inline(always)]
fn warm_start<S: Simd, const M: usize>(t: &Tables, kt: &[f32]) -> [[f32; 16]; M] {
    let l = S::LANES;
    let one = S::splat(1.0);
    let (lo, hi) = (S::splat(WARM_EPS), S::splat(1.0 - WARM_EPS));
    let mut c = [S::splat(0.0); M];
    for n in 0..t.nfit {
        let kv = S::load(&kt[n * l..]);
        let k = S::min(S::max(kv, lo), hi);
        let lg = S::where_nonneg(kv, S::ln(S::mul(k, S::recip(S::sub(one, k)))));
        let pw = &t.warm[n * M..(n + 1) * M];
        for j in 0..M {
            c[j] = S::fma(S::splat(pw[j]), lg, c[j]);
        }
    }
    let mut cl = [[0f32; 16]; M];
    for j in 0..M {
        S::store(c[j], &mut cl[j]);
    }
    cl
}

/// For fitting light n of a tile: ω(σ(z) − k) and ωσ(z)(1 − σ(z)), z = aₙ·c (0 where the sample
/// is left out). z is summed in two chains to halve its latency.
#[inline(always)]
fn residual_weight<S: Simd, const M: usize>(
    t: &Tables,
    kt: &[f32],
    c: &[S::V; M],
    n: usize,
) -> (S::V, S::V) {
    let l = S::LANES;
    let kv = S::load(&kt[n * l..]);
    let an = &t.a[n * M..(n + 1) * M];
    let (mut z0, mut z1) = (S::splat(0.0), S::splat(0.0));
    let mut j = 0;
    while j + 1 < M {
        z0 = S::fma(S::splat(an[j]), c[j], z0);
        z1 = S::fma(S::splat(an[j + 1]), c[j + 1], z1);
        j += 2;
    }
    if j < M {
        z0 = S::fma(S::splat(an[j]), c[j], z0);
    }
    let p = S::sigmoid(S::add(z0, z1));
    let o = S::where_nonneg(kv, S::splat(t.omega[n]));
    let r = S::mul(o, S::sub(p, kv));
    let w = S::mul(S::mul(o, p), S::sub(S::splat(1.0), p));
    (r, w)
}

/// One Newton step for the active lanes of one tile (K packed `[used light][lane]`; a value
/// < 0 marks a sample to leave out). Returns, per lane, whether it converged or failed now.
#[inline(always)]
fn newton_step<S: Simd, const M: usize, const D: usize>(
    t: &Tables,
    kt: &[f32],
    cl: &mut [[f32; 16]; M],
    active: &[bool],
    tolerance: f64,
) -> [bool; 16] {
    let l = S::LANES;
    let (zero, one) = (S::splat(0.0), S::splat(1.0));
    let mut c = [zero; M];
    for j in 0..M {
        c[j] = S::load(&cl[j]);
    }
    let mut g = [zero; M];
    let mut h = [zero; D];
    // Two lights at a time: their chains (z, σ, r, w) are independent, so the core overlaps
    // them instead of waiting out one light's latency before the next.
    let pairs = t.nfit / 2;
    for np in 0..pairs {
        let n = 2 * np;
        let (r0, w0) = residual_weight::<S, M>(t, kt, &c, n);
        let (r1, w1) = residual_weight::<S, M>(t, kt, &c, n + 1);
        let (a0, a1) = (&t.a[n * M..(n + 1) * M], &t.a[(n + 1) * M..(n + 2) * M]);
        let (q0, q1) = (&t.q[n * D..(n + 1) * D], &t.q[(n + 1) * D..(n + 2) * D]);
        for j in 0..M {
            g[j] = S::fma(r1, S::splat(a1[j]), S::fma(r0, S::splat(a0[j]), g[j]));
        }
        for e in 0..D {
            h[e] = S::fma(w1, S::splat(q1[e]), S::fma(w0, S::splat(q0[e]), h[e]));
        }
    }
    if t.nfit % 2 == 1 {
        let n = t.nfit - 1;
        let (r, w) = residual_weight::<S, M>(t, kt, &c, n);
        let (an, qn) = (&t.a[n * M..(n + 1) * M], &t.q[n * D..(n + 1) * D]);
        for j in 0..M {
            g[j] = S::fma(r, S::splat(an[j]), g[j]);
        }
        for e in 0..D {
            h[e] = S::fma(w, S::splat(qn[e]), h[e]);
        }
    }
    // The Newton system (H + ρI)·δ = ∇J, lane-parallel: Cholesky in f32. An inexact step is
    // still a descent step and the gradient, not the step, fixes the converged point; a lane
    // whose pivot is not safely positive (no ridge on a rank-deficient dome) is solved again in
    // f64 with a pseudo-inverse.
    let rho = S::splat(t.ridge as f32);
    let mut grad = [zero; M];
    for j in 0..M {
        grad[j] = S::fma(rho, c[j], g[j]);
    }
    let mut lo = [[zero; M]; M];
    {
        let mut q = 0;
        for i in 0..M {
            for j in i..M {
                lo[j][i] = h[t.pair[q]];
                q += 1;
            }
            lo[i][i] = S::add(lo[i][i], rho);
        }
    }
    let mut scale = zero;
    for i in 0..M {
        scale = S::max(scale, lo[i][i]);
    }
    let floor = S::mul(scale, S::splat(1e-6));
    let mut bad = zero;
    for j in 0..M {
        let mut p = lo[j][j];
        for k in 0..j {
            p = S::sub(p, S::mul(lo[j][k], lo[j][k]));
        }
        bad = S::add(bad, S::where_nonneg(S::sub(floor, p), one));
        let d = S::sqrt(S::max(p, floor));
        let inv = S::recip(d);
        lo[j][j] = d;
        for i in j + 1..M {
            let mut x = lo[i][j];
            for k in 0..j {
                x = S::sub(x, S::mul(lo[i][k], lo[j][k]));
            }
            lo[i][j] = S::mul(x, inv);
        }
    }
    let mut y = [zero; M];
    for i in 0..M {
        let mut x = grad[i];
        for k in 0..i {
            x = S::sub(x, S::mul(lo[i][k], y[k]));
        }
        y[i] = S::div(x, lo[i][i]);
    }
    let mut dv = [zero; M];
    for i in (0..M).rev() {
        let mut x = y[i];
        for k in i + 1..M {
            x = S::sub(x, S::mul(lo[k][i], dv[k]));
        }
        dv[i] = S::div(x, lo[i][i]);
    }
    let mut dl = [[0f32; 16]; M];
    let mut gl = [[0f32; 16]; M];
    for j in 0..M {
        S::store(dv[j], &mut dl[j]);
        S::store(grad[j], &mut gl[j]);
    }
    let mut badl = [0f32; 16];
    S::store(bad, &mut badl);
    let fallback = (0..l).any(|q| active[q] && badl[q] > 0.0);
    let mut hl = [[0f32; 16]; D];
    if fallback {
        for e in 0..D {
            S::store(h[e], &mut hl[e]);
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
fn final_pass<S: Simd, const M: usize>(
    t: &Tables,
    kt: &[f32],
    cl: &[[f32; 16]; M],
    live: &[bool],
    out: &mut [TexelFit],
) {
    let l = S::LANES;
    let mut c = [S::splat(0.0); M];
    for j in 0..M {
        c[j] = S::load(&cl[j]);
    }
    // All in vectors: a masked-out sample (k < 0) adds nothing; equality tests on K (exactly 0
    // or 1) are sign tests, since valid K lies in [0, 1].
    let (zero, one) = (S::splat(0.0), S::splat(1.0));
    let (mut ss, mut mx, mut hs, mut hn) = (zero, zero, zero, zero);
    let (mut valid, mut ones, mut zeros, mut wrong) = (zero, zero, zero, zero);
    for n in 0..t.used.len() {
        let an = &t.a[n * M..(n + 1) * M];
        // z in two chains, as in `residual_weight`.
        let (mut z0, mut z1) = (zero, zero);
        let mut j = 0;
        while j + 1 < M {
            z0 = S::fma(S::splat(an[j]), c[j], z0);
            z1 = S::fma(S::splat(an[j + 1]), c[j + 1], z1);
            j += 2;
        }
        if j < M {
            z0 = S::fma(S::splat(an[j]), c[j], z0);
        }
        let z = S::add(z0, z1);
        let kv = S::load(&kt[n * l..]);
        let e = S::sub(S::sigmoid(z), kv);
        let e2 = S::where_nonneg(kv, S::mul(e, e));
        let v = S::where_nonneg(kv, one);
        if n < t.nfit {
            ss = S::fma(S::splat(t.omega[n]), e2, ss);
            mx = S::max(mx, S::where_nonneg(kv, S::max(e, S::sub(zero, e))));
            valid = S::add(valid, v);
            // k = 1 ⇔ k − 1 ≥ 0; k = 0 ⇔ k ≥ 0 and −k ≥ 0.
            let is1 = S::where_nonneg(S::sub(kv, one), one);
            let is0 = S::where_nonneg(kv, S::where_nonneg(S::sub(zero, kv), one));
            ones = S::add(ones, is1);
            zeros = S::add(zeros, is0);
            // Misclassified binary samples: k = 1 with z ≤ 0, k = 0 with z ≥ 0. Fractional
            // samples (valid − ones − zeros) are added once after the loop: the counts are
            // small integers, exact in f32, so the sum is the same in any order.
            let w1 = S::where_nonneg(S::sub(zero, z), is1);
            let w0 = S::where_nonneg(z, is0);
            wrong = S::add(wrong, S::add(w1, w0));
        } else {
            hs = S::add(hs, e2);
            hn = S::add(hn, v);
        }
    }
    wrong = S::add(wrong, S::sub(S::sub(valid, ones), zeros));
    let mut lanes = [[0f32; 16]; 8];
    for (dst, v) in lanes
        .iter_mut()
        .zip([ss, mx, hs, hn, valid, ones, zeros, wrong])
    {
        S::store(v, dst);
    }
    let [ss, mx, hs, hn, valid, ones, zeros, wrong] = lanes;
    for q in 0..l.min(out.len()) {
        let o = &mut out[q];
        if !live[q] {
            *o = TexelFit::default();
            o.c[t.constant_term] = HOLE_LOGIT;
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

/// Fits every texel of a packed block (`packed`: tiles of `[used light][lane]`). Newton runs on
/// a work copy whose still-active lanes are compacted into the lowest tiles after every step,
/// so a block costs its texels' mean iteration count, not each tile's slowest lane's.
#[inline(always)]
fn block_body<S: Simd, const M: usize, const D: usize>(
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    let (nu, l) = (t.used.len(), S::LANES);
    let stride_k = nu * l;
    let tiles = packed.len() / stride_k;
    let len = out.len();
    let mut work = packed.to_vec();
    // Plain loops, not closures, around SIMD code: a closure does not inherit the caller's
    // target features, so intrinsics inside it would not inline.
    let mut warm = Vec::with_capacity(tiles);
    for ti in 0..tiles {
        warm.push(warm_start::<S, M>(
            t,
            &packed[ti * stride_k..(ti + 1) * stride_k],
        ));
    }
    let mut st = Slots::<M> {
        c: warm,
        texel: (0..tiles * l).map(|s| (s < len).then_some(s)).collect(),
        active: (0..tiles * l).map(|s| s < len && live[s]).collect(),
    };
    let mut final_c = vec![[0f32; 16]; len];
    let mut iterations = vec![0u32; len];
    let mut converged = vec![false; len];
    let retire = |st: &Slots<M>, s: usize, final_c: &mut Vec<[f32; 16]>| {
        if let Some(i) = st.texel[s] {
            for j in 0..M {
                final_c[i][j] = st.c[s / l][j][s % l];
            }
        }
    };
    loop {
        let count = st.active.iter().filter(|&&a| a).count();
        if count == 0 {
            break;
        }
        // Compact: move active lanes beyond the first `count` slots into free slots below.
        let mut holes = (0..count)
            .filter(|&s| !st.active[s])
            .collect::<Vec<_>>()
            .into_iter();
        for s in count..tiles * l {
            if !st.active[s] {
                continue;
            }
            let f = holes.next().expect("as many holes below as actives above");
            let (ts, qs, tf, qf) = (s / l, s % l, f / l, f % l);
            for li in 0..nu {
                work[tf * stride_k + li * l + qf] = work[ts * stride_k + li * l + qs];
            }
            for j in 0..M {
                st.c[tf][j][qf] = st.c[ts][j][qs];
            }
            // A retired texel in the hole keeps its result in final_c; the slot is reused.
            st.texel.swap(f, s);
            st.active[f] = true;
            st.active[s] = false;
        }
        for ti in 0..count.div_ceil(l) {
            let act = &st.active[ti * l..(ti + 1) * l];
            let done = newton_step::<S, M, D>(
                t,
                &work[ti * stride_k..(ti + 1) * stride_k],
                &mut st.c[ti],
                act,
                t.tolerance,
            );
            for q in 0..l {
                let s = ti * l + q;
                if !st.active[s] {
                    continue;
                }
                let i = st.texel[s].expect("an active slot holds a texel");
                iterations[i] += 1;
                if done[q] || iterations[i] >= t.max_iterations {
                    converged[i] = done[q];
                    st.active[s] = false;
                    retire(&st, s, &mut final_c);
                }
            }
        }
    }
    // Lanes still active at the cap keep their last iterate.
    for s in 0..tiles * l {
        if st.active[s] {
            retire(&st, s, &mut final_c);
        }
    }
    for ti in 0..tiles {
        let mut cl = [[0f32; 16]; M];
        for q in 0..l {
            if let Some(c) = final_c.get(ti * l + q) {
                for j in 0..M {
                    cl[j][q] = c[j];
                }
            }
        }
        let b0 = ti * l;
        let end = (b0 + l).min(len);
        let mut lv = [false; 16];
        for q in 0..l {
            lv[q] = live.get(b0 + q).copied().unwrap_or(false);
        }
        final_pass::<S, M>(
            t,
            &packed[ti * stride_k..(ti + 1) * stride_k],
            &cl,
            &lv,
            &mut out[b0..end],
        );
        for (q, o) in out[b0..end].iter_mut().enumerate() {
            o.iterations = iterations[b0 + q];
            o.converged = converged[b0 + q];
        }
    }
}

fn block_portable<const M: usize, const D: usize>(
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<Portable, M, D>(t, packed, live, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn block_avx2<const M: usize, const D: usize>(
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<crate::simd::Avx2, M, D>(t, packed, live, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn block_avx512<const M: usize, const D: usize>(
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<crate::simd::Avx512, M, D>(t, packed, live, out)
}

/// Which build of the kernel runs: the widest the CPU supports, unless forced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Plain Rust over 8-lane arrays, on any CPU.
    Portable,
    /// AVX2 with FMA, 8 f32 lanes.
    Avx2,
    /// AVX-512F, 16 f32 lanes.
    Avx512,
}

impl Kernel {
    /// The widest kernel this CPU runs.
    pub fn detect() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                return Kernel::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Kernel::Avx2;
            }
        }
        Kernel::Portable
    }

    /// Whether this CPU can run the kernel.
    pub fn supported(self) -> bool {
        match self {
            Kernel::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// Texels one kernel call fits side by side.
    pub fn lanes(self) -> usize {
        match self {
            Kernel::Avx512 => 16,
            _ => 8,
        }
    }

    /// The kernel [`Kernel::name`] names.
    pub fn from_name(name: &str) -> Option<Kernel> {
        [Kernel::Portable, Kernel::Avx2, Kernel::Avx512]
            .into_iter()
            .find(|k| k.name() == name)
    }

    /// The build in words, as reports print it.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Portable => "portable",
            Kernel::Avx2 => "avx2+fma",
            Kernel::Avx512 => "avx512f",
        }
    }
}

fn run_block(kernel: Kernel, t: &Tables, packed: &[f32], live: &[bool], out: &mut [TexelFit]) {
    macro_rules! dispatch {
        ($f:ident $(, $unsafe:tt)?) => {
            match t.m {
                // SAFETY (the unsafe arms): `Kernel::supported` was checked by the caller.
                6 => $($unsafe)? { $f::<6, 15>(t, packed, live, out) },
                11 => $($unsafe)? { $f::<11, 33>(t, packed, live, out) },
                _ => unreachable!("bases have 6 or 11 terms"),
            }
        };
    }
    match kernel {
        Kernel::Portable => dispatch!(block_portable),
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2 => dispatch!(block_avx2, unsafe),
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx512 => dispatch!(block_avx512, unsafe),
        #[cfg(not(target_arch = "x86_64"))]
        _ => dispatch!(block_portable),
    }
}

/// Where the K of a fit comes from, per (light, texel) of the level being fitted.
pub(crate) enum Source<'a> {
    /// A stored stack: K planes `[light][texel]`, coverage per texel (the box filter's weight).
    Planes {
        k: &'a [Vec<f32>],
        coverage: &'a [f32],
    },
    /// A pooled stack level: K per light (−1 = nothing covered) and the pooled weight per texel.
    Weighted {
        k: &'a [Vec<f32>],
        w: &'a [f32],
    },
    /// Exact counts: occluded samples `[light][texel]` and covered samples per texel (a
    /// streaming bake's level 0 in u8 or u16, pooled levels in u16 or u32).
    Counts8 {
        occ: &'a [Vec<u8>],
        cov: &'a [u32],
    },
    Counts16 {
        occ: &'a [Vec<u16>],
        cov: &'a [u32],
    },
    Counts32 {
        occ: &'a [Vec<u32>],
        cov: &'a [u32],
    },
}

/// The sizes of level 0 and of every MIP level down to 1×1 (halved, rounded down; a side that is
/// already 1 stays 1), with the pooling factors (fx, fy) ∈ {1, 2} from the level above.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Footprint {
    pub width: usize,
    pub height: usize,
    pub fx: usize,
    pub fy: usize,
}

impl Footprint {
    pub fn chain(width: usize, height: usize) -> Vec<Footprint> {
        let mut out = vec![Footprint {
            width,
            height,
            fx: 1,
            fy: 1,
        }];
        let mut f = out[0];
        while f.width > 1 || f.height > 1 {
            let (fx, fy) = (
                if f.width > 1 { 2 } else { 1 },
                if f.height > 1 { 2 } else { 1 },
            );
            f = Footprint {
                width: f.width / fx,
                height: f.height / fy,
                fx,
                fy,
            };
            out.push(f);
        }
        out
    }
}

impl Source<'_> {
    /// K of light `l` for the `out.len()` texels from index `start`, or −1 where the texel has
    /// no covered sample (or, for a stack, a non-finite one).
    fn fill(&self, l: usize, start: usize, out: &mut [f32]) {
        let r = start..start + out.len();
        match self {
            Source::Planes { k, coverage } => {
                for ((o, &kv), &cv) in out.iter_mut().zip(&k[l][r.clone()]).zip(&coverage[r]) {
                    *o = if cv > 0.0 && kv.is_finite() {
                        kv.clamp(0.0, 1.0)
                    } else {
                        -1.0
                    };
                }
            }
            Source::Weighted { k, .. } => out.copy_from_slice(&k[l][r]),
            Source::Counts8 { occ, cov } => ratio(&occ[l][r.clone()], &cov[r], out),
            Source::Counts16 { occ, cov } => ratio(&occ[l][r.clone()], &cov[r], out),
            Source::Counts32 { occ, cov } => ratio(&occ[l][r.clone()], &cov[r], out),
        }
    }

    /// Asks the CPU to start loading what `fill(l, start, len)` will read: a block reads one
    /// short run of every light's plane, too many streams for the hardware prefetcher, so the
    /// loads would otherwise wait on memory one light after another.
    #[inline]
    fn prefetch(&self, l: usize, start: usize, len: usize) {
        fn lines<T>(s: &[T]) {
            #[cfg(target_arch = "x86_64")]
            {
                let bytes = std::mem::size_of_val(s);
                let p = s.as_ptr() as *const i8;
                for o in (0..bytes).step_by(64) {
                    // SAFETY: a prefetch only hints the cache; the address lies within `s`.
                    unsafe {
                        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                            p.add(o),
                        )
                    };
                }
            }
            #[cfg(not(target_arch = "x86_64"))]
            let _ = s;
        }
        let r = start..start + len;
        match self {
            Source::Planes { k, .. } | Source::Weighted { k, .. } => lines(&k[l][r]),
            Source::Counts8 { occ, .. } => lines(&occ[l][r]),
            Source::Counts16 { occ, .. } => lines(&occ[l][r]),
            Source::Counts32 { occ, .. } => lines(&occ[l][r]),
        }
    }

    fn lights(&self) -> usize {
        match self {
            Source::Planes { k, .. } | Source::Weighted { k, .. } => k.len(),
            Source::Counts8 { occ, .. } => occ.len(),
            Source::Counts16 { occ, .. } => occ.len(),
            Source::Counts32 { occ, .. } => occ.len(),
        }
    }
}

#[inline]
fn ratio<T: Copy + Into<u32>>(occ: &[T], cov: &[u32], out: &mut [f32]) {
    for ((o, &n), &c) in out.iter_mut().zip(occ).zip(cov) {
        *o = if c > 0 {
            (n.into() as f64 / c as f64) as f32
        } else {
            -1.0
        };
    }
}

/// A MIP level's K data, pooled from the level above: what [`Source`] borrows for that level.
pub(crate) enum Pooled {
    Weighted { k: Vec<Vec<f32>>, w: Vec<f32> },
    Counts8 { occ: Vec<Vec<u8>>, cov: Vec<u32> },
    Counts16 { occ: Vec<Vec<u16>>, cov: Vec<u32> },
    Counts32 { occ: Vec<Vec<u32>>, cov: Vec<u32> },
}

impl Pooled {
    /// Pooled counts as (covered per texel, occluded `[light][texel]`), widened to u32; None
    /// for a pooled stack level.
    pub fn into_counts(self) -> Option<(Vec<u32>, Vec<Vec<u32>>)> {
        fn wide<T: Into<u32>>(occ: Vec<Vec<T>>) -> Vec<Vec<u32>> {
            occ.into_iter()
                .map(|p| p.into_iter().map(Into::into).collect())
                .collect()
        }
        match self {
            Pooled::Weighted { .. } => None,
            Pooled::Counts8 { occ, cov } => Some((cov, wide(occ))),
            Pooled::Counts16 { occ, cov } => Some((cov, wide(occ))),
            Pooled::Counts32 { occ, cov } => Some((cov, occ)),
        }
    }

    pub fn source(&self) -> Source<'_> {
        match self {
            Pooled::Weighted { k, w } => Source::Weighted { k, w },
            Pooled::Counts8 { occ, cov } => Source::Counts8 { occ, cov },
            Pooled::Counts16 { occ, cov } => Source::Counts16 { occ, cov },
            Pooled::Counts32 { occ, cov } => Source::Counts32 { occ, cov },
        }
    }
}

/// The children (level-above texel indices) of texel (x, y) of level `to`.
#[inline]
fn children(from_w: usize, to: Footprint, x: usize, y: usize) -> [Option<usize>; 4] {
    let mut out = [None; 4];
    let mut i = 0;
    for dy in 0..to.fy {
        for dx in 0..to.fx {
            out[i] = Some((y * to.fy + dy) * from_w + x * to.fx + dx);
            i += 1;
        }
    }
    out
}

/// Pools `src` (a level `from_w` texels wide) into level `to`: the box filter of the MIP chain.
/// Counts add exactly (u16 while the pooled covered count fits, else u32); stack levels take
/// the weighted mean of the covered children's K, weights the coverage (then the pooled
/// weights). Parallel over lights; exact or order-independent, so thread counts do not matter.
pub(crate) fn pool(src: &Source, from_w: usize, to: Footprint) -> Pooled {
    let n = to.width * to.height;
    let kids = |t: usize| children(from_w, to, t % to.width, t / to.width);
    let sum_cov = |cov: &[u32]| -> Vec<u32> {
        (0..n)
            .map(|t| kids(t).iter().flatten().map(|&c| cov[c]).sum())
            .collect()
    };
    fn add<T: Copy + Into<u32> + Sync, U: TryFrom<u32> + Send>(
        occ: &[Vec<T>],
        n: usize,
        kids: &(dyn Fn(usize) -> [Option<usize>; 4] + Sync),
    ) -> Vec<Vec<U>> {
        occ.par_iter()
            .map(|plane| {
                (0..n)
                    .map(|t| {
                        let s: u32 = kids(t).iter().flatten().map(|&c| plane[c].into()).sum();
                        U::try_from(s)
                            .ok()
                            .expect("pooled count fits by construction")
                    })
                    .collect()
            })
            .collect()
    }
    match src {
        Source::Planes { .. } | Source::Weighted { .. } => {
            let wsrc: &[f32] = match src {
                Source::Planes { coverage, .. } => coverage,
                Source::Weighted { w, .. } => w,
                _ => unreachable!("a stack source"),
            };
            let w: Vec<f32> = (0..n)
                .map(|t| kids(t).iter().flatten().map(|&c| wsrc[c]).sum())
                .collect();
            let from_len = wsrc.len();
            let k = (0..src.lights())
                .into_par_iter()
                .map(|l| {
                    let mut row = vec![0f32; from_len];
                    src.fill(l, 0, &mut row);
                    (0..n)
                        .map(|t| {
                            let (mut num, mut den) = (0f64, 0f64);
                            for &c in kids(t).iter().flatten() {
                                if row[c] >= 0.0 && wsrc[c] > 0.0 {
                                    num += (wsrc[c] * row[c]) as f64;
                                    den += wsrc[c] as f64;
                                }
                            }
                            if den > 0.0 {
                                (num / den) as f32
                            } else {
                                -1.0
                            }
                        })
                        .collect()
                })
                .collect();
            Pooled::Weighted { k, w }
        }
        Source::Counts8 { cov, .. }
        | Source::Counts16 { cov, .. }
        | Source::Counts32 { cov, .. } => {
            let cov = sum_cov(cov);
            // The narrowest type that holds every pooled count (occluded ≤ covered).
            let top = cov.iter().copied().max().unwrap_or(0);
            macro_rules! pooled_as {
                ($variant:ident) => {
                    match src {
                        Source::Counts8 { occ, .. } => Pooled::$variant {
                            occ: add(occ, n, &kids),
                            cov,
                        },
                        Source::Counts16 { occ, .. } => Pooled::$variant {
                            occ: add(occ, n, &kids),
                            cov,
                        },
                        Source::Counts32 { occ, .. } => Pooled::$variant {
                            occ: add(occ, n, &kids),
                            cov,
                        },
                        _ => unreachable!("a counts source"),
                    }
                };
            }
            if top <= u8::MAX as u32 {
                pooled_as!(Counts8)
            } else if top <= u16::MAX as u32 {
                pooled_as!(Counts16)
            } else {
                pooled_as!(Counts32)
            }
        }
    }
}

/// Texels per parallel work unit.
const BLOCK: usize = 512;

/// Lights ahead whose block rows are prefetched while one is filled.
const PREFETCH_AHEAD: usize = 8;

/// Fits every texel of the level `fp` (of a level-0 image `w0` wide) from `src`: per texel, its
/// fit (coefficients, iterations, class, errors). `live[t]` is false for texels to leave out
/// (coefficients 0). Parallel over blocks; the result does not depend on the thread count.
pub(crate) fn fit_level(
    t: &Tables,
    src: &Source,
    texels: usize,
    live: &(dyn Fn(usize) -> bool + Sync),
    kernel: Kernel,
) -> LevelFit {
    assert!(kernel.supported(), "kernel {} not supported", kernel.name());
    let lanes = kernel.lanes();
    let nu = t.used.len();
    let mut out = LevelFit {
        planes: vec![vec![0f32; texels]; t.m],
        rms: vec![0f32; texels],
        max: vec![0f32; texels],
        holdout: vec![0f32; texels],
        iterations: vec![0u32; texels],
        converged: vec![false; texels],
        separable: vec![false; texels],
        constant: vec![false; texels],
    };
    // Blocks run in parallel a batch at a time and are scattered into the planes, so per-texel
    // results never take more than a batch's worth of memory beside the planes.
    const BATCH: usize = 64;
    let blocks = texels.div_ceil(BLOCK);
    for b0 in (0..blocks).step_by(BATCH) {
        let results: Vec<Vec<TexelFit>> = (b0..(b0 + BATCH).min(blocks))
            .into_par_iter()
            .map_init(Vec::new, |packed: &mut Vec<f32>, bi| {
                let start = bi * BLOCK;
                let len = BLOCK.min(texels - start);
                let tiles = len.div_ceil(lanes);
                packed.clear();
                packed.resize(tiles * nu * lanes, -1.0);
                let mut live_v: Vec<bool> = (start..start + len).map(live).collect();
                let mut row = vec![0f32; tiles * lanes];
                let mut any = vec![false; len];
                for (li, &l) in t.used.iter().enumerate() {
                    if let Some(&ahead) = t.used.get(li + PREFETCH_AHEAD) {
                        src.prefetch(ahead, start, len);
                    }
                    src.fill(l, start, &mut row[..len]);
                    for i in 0..len {
                        if !live_v[i] {
                            row[i] = -1.0;
                        }
                        any[i] |= li < t.nfit && row[i] >= 0.0;
                    }
                    for (tile, r) in row.chunks_exact(lanes).enumerate() {
                        let o = (tile * nu + li) * lanes;
                        packed[o..o + lanes].copy_from_slice(r);
                    }
                }
                for (lv, a) in live_v.iter_mut().zip(&any) {
                    *lv &= a;
                }
                let mut fits = vec![TexelFit::default(); len];
                run_block(kernel, t, packed, &live_v, &mut fits);
                fits
            })
            .collect();
        for (bi, fits) in (b0..).zip(results) {
            for (i, f) in fits.iter().enumerate() {
                let ti = bi * BLOCK + i;
                for j in 0..t.m {
                    out.planes[j][ti] = f.c[j];
                }
                out.rms[ti] = f.rms;
                out.max[ti] = f.max;
                out.holdout[ti] = f.holdout;
                out.iterations[ti] = f.iterations;
                out.converged[ti] = f.converged;
                out.separable[ti] = f.separable;
                out.constant[ti] = f.constant;
            }
        }
    }
    out
}

/// Per-texel results of a level's fit, as planes.
pub(crate) struct LevelFit {
    pub planes: Vec<Vec<f32>>,
    pub rms: Vec<f32>,
    pub max: Vec<f32>,
    pub holdout: Vec<f32>,
    pub iterations: Vec<u32>,
    pub converged: Vec<bool>,
    pub separable: Vec<bool>,
    pub constant: Vec<bool>,
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

    #[test]
    fn chain_matches_round_down_sizes() {
        // Against the exr crate's own MIP level sizes (what its reader and writer expect).
        for (w, h) in [(13, 7), (64, 64), (4, 16), (1, 5)] {
            let chain = Footprint::chain(w, h);
            let sizes: Vec<(usize, usize)> = chain.iter().map(|f| (f.width, f.height)).collect();
            let want: Vec<(usize, usize)> =
                exr::meta::mip_map_levels(exr::math::RoundingMode::Down, exr::math::Vec2(w, h))
                    .map(|(_, s)| (s.0, s.1))
                    .collect();
            assert_eq!(sizes, want, "{w}×{h}");
        }
    }
}
