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
//! the per-texel weights times the distinct products mᵢmⱼ of the basis ([`crate::basis::products`]):
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

use crate::basis::products;
use crate::simd::{Portable, Simd};
use crate::Basis;

/// Default ridge λ of the logistic fit (relative to the mean eigenvalue of AᵀΩA).
pub const DEFAULT_RIDGE: f64 = 1e-5;
/// Default stopping tolerance: a texel stops when its Newton decrement (the objective's
/// predicted fall) is at most this per unit of light weight, or its step is below 1e-6.
pub const DEFAULT_TOLERANCE: f64 = 1e-10;
/// Default cap on Newton iterations per texel (texels that hit it are counted).
pub const DEFAULT_MAX_ITERATIONS: u32 = 30;

/// Largest Newton step (max-norm of the coefficient change) taken at once: far from the optimum
/// a full step can overshoot; the cap keeps every iterate bounded without a line search.
const MAX_STEP: f64 = 8.0;

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
        }
    }
}

/// Per-texel result of the kernel.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TexelFit {
    pub c: [f32; 16],
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
        if !(s > 1e-13 * scale) {
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

/// Fits one tile of `S::LANES` texels whose K values are packed `[used light][lane]` (a value
/// < 0 marks a sample to leave out: a masked texel, or a non-finite sample dropped by
/// --skip-bad). `live[q]`: lane q holds a texel to fit.
#[inline(always)]
fn tile<S: Simd, const M: usize, const D: usize>(
    t: &Tables,
    kt: &[f32],
    live: &[bool; 16],
    out: &mut [TexelFit],
) {
    let l = S::LANES;
    let nfit = t.nfit;
    let (zero, one) = (S::splat(0.0), S::splat(1.0));
    let (lo, hi) = (S::splat(WARM_EPS), S::splat(1.0 - WARM_EPS));
    // Warm start: least squares of the clamped logits, c = Σₙ Pₙ·logit(kₙ).
    let mut c = [zero; M];
    for n in 0..nfit {
        let kv = S::load(&kt[n * l..]);
        let k = S::min(S::max(kv, lo), hi);
        let lg = S::where_nonneg(kv, S::sub(S::ln(k), S::ln(S::sub(one, k))));
        let pw = &t.warm[n * M..(n + 1) * M];
        for j in 0..M {
            c[j] = S::fma(S::splat(pw[j]), lg, c[j]);
        }
    }
    let mut cl = [[0f32; 16]; M];
    for j in 0..M {
        S::store(c[j], &mut cl[j]);
    }
    let mut active = *live;
    let mut iterations = [0u32; 16];
    let mut converged = [false; 16];
    let mut lanes = [0f32; 16];
    for _ in 0..t.max_iterations {
        if !active[..l].iter().any(|&x| x) {
            break;
        }
        for j in 0..M {
            c[j] = S::load(&cl[j]);
        }
        let mut g = [zero; M];
        let mut h = [zero; D];
        for n in 0..nfit {
            let kv = S::load(&kt[n * l..]);
            let an = &t.a[n * M..(n + 1) * M];
            let qn = &t.q[n * D..(n + 1) * D];
            let mut z = zero;
            for j in 0..M {
                z = S::fma(S::splat(an[j]), c[j], z);
            }
            let p = S::sigmoid(z);
            let o = S::where_nonneg(kv, S::splat(t.omega[n]));
            let r = S::mul(o, S::sub(p, kv));
            let w = S::mul(S::mul(o, p), S::sub(one, p));
            for j in 0..M {
                g[j] = S::fma(r, S::splat(an[j]), g[j]);
            }
            for e in 0..D {
                h[e] = S::fma(w, S::splat(qn[e]), h[e]);
            }
        }
        let mut gl = [[0f32; 16]; M];
        for j in 0..M {
            S::store(g[j], &mut gl[j]);
        }
        let mut hl = [[0f32; 16]; D];
        for e in 0..D {
            S::store(h[e], &mut hl[e]);
        }
        for q in 0..l {
            if !active[q] {
                continue;
            }
            let mut hp = [0f64; 136];
            for (e, &k) in t.pair.iter().enumerate() {
                hp[e] = hl[k][q] as f64;
            }
            let mut grad = [0f64; 16];
            for j in 0..M {
                grad[j] = gl[j][q] as f64 + t.ridge * cl[j][q] as f64;
            }
            let mut delta = solve_spd::<M>(&hp[..t.pair.len()], &grad[..M], t.ridge);
            let big = delta[..M].iter().fold(0.0f64, |a, &b| a.max(b.abs()));
            if !big.is_finite() {
                active[q] = false;
                continue;
            }
            if big > MAX_STEP {
                for x in &mut delta[..M] {
                    *x *= MAX_STEP / big;
                }
            }
            let decrement: f64 = (0..M).map(|j| delta[j] * grad[j]).sum();
            for j in 0..M {
                cl[j][q] = (cl[j][q] as f64 - delta[j]) as f32;
            }
            iterations[q] += 1;
            if decrement <= t.tolerance * t.omega_sum || big <= 1e-6 {
                active[q] = false;
                converged[q] = true;
            }
        }
    }
    for j in 0..M {
        c[j] = S::load(&cl[j]);
    }
    // Final pass: residuals of σ(p) over the fitting lights, classification, held-out error.
    let mut ss = [0f32; 16];
    let mut mx = [0f32; 16];
    let mut sep = [true; 16];
    let mut ones = [0u32; 16];
    let mut zeros = [0u32; 16];
    let mut valid = [0u32; 16];
    let mut hs = [0f32; 16];
    let mut hn = [0u32; 16];
    let mut zl = [0f32; 16];
    let mut pl = [0f32; 16];
    for n in 0..t.used.len() {
        let an = &t.a[n * M..(n + 1) * M];
        let mut z = zero;
        for j in 0..M {
            z = S::fma(S::splat(an[j]), c[j], z);
        }
        S::store(z, &mut zl);
        S::store(S::sigmoid(z), &mut pl);
        let kv = &kt[n * l..(n + 1) * l];
        for q in 0..l {
            if kv[q] < 0.0 {
                continue;
            }
            let e = pl[q] - kv[q];
            if n < nfit {
                ss[q] += t.omega[n] * e * e;
                mx[q] = mx[q].max(e.abs());
                valid[q] += 1;
                if kv[q] == 1.0 {
                    ones[q] += 1;
                    sep[q] &= zl[q] > 0.0;
                } else if kv[q] == 0.0 {
                    zeros[q] += 1;
                    sep[q] &= zl[q] < 0.0;
                } else {
                    sep[q] = false;
                }
            } else {
                hs[q] += e * e;
                hn[q] += 1;
            }
        }
    }
    let _ = &mut lanes;
    for q in 0..l.min(out.len()) {
        let o = &mut out[q];
        if !live[q] {
            *o = TexelFit::default();
            continue;
        }
        for j in 0..M {
            o.c[j] = cl[j][q];
        }
        o.iterations = iterations[q];
        o.converged = converged[q];
        o.constant = valid[q] > 0 && (ones[q] == valid[q] || zeros[q] == valid[q]);
        o.separable = valid[q] > 0 && sep[q] && !o.constant;
        o.rms = if t.omega_sum > 0.0 {
            (ss[q] / t.omega_sum as f32).sqrt()
        } else {
            0.0
        };
        o.max = mx[q];
        o.holdout = if hn[q] > 0 {
            (hs[q] / hn[q] as f32).sqrt()
        } else {
            0.0
        };
    }
}

/// Fits every tile of a packed block (`packed`: tiles of `[used light][lane]`).
#[inline(always)]
fn block_body<S: Simd, const M: usize, const D: usize>(
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    let (nu, l) = (t.used.len(), S::LANES);
    for (ti, kt) in packed.chunks_exact(nu * l).enumerate() {
        let b0 = ti * l;
        let mut lv = [false; 16];
        for q in 0..l {
            lv[q] = live.get(b0 + q).copied().unwrap_or(false);
        }
        let end = (b0 + l).min(out.len());
        tile::<S, M, D>(t, kt, &lv, &mut out[b0..end]);
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
    Portable,
    Avx2,
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

    pub fn lanes(self) -> usize {
        match self {
            Kernel::Avx512 => 16,
            _ => 8,
        }
    }

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

/// Where the K of a fit comes from, per (light, texel) of level 0.
pub(crate) enum Source<'a> {
    /// A stored stack: K planes `[light][texel]`, coverage per texel (the box filter's weight).
    Planes {
        k: &'a [Vec<f32>],
        coverage: &'a [f32],
    },
    /// A streaming bake: occluded sample counts `[light][texel]` and covered samples per texel.
    Counts8 {
        occ: &'a [Vec<u8>],
        cov: &'a [u16],
    },
    Counts16 {
        occ: &'a [Vec<u16>],
        cov: &'a [u16],
    },
}

/// The footprint of level-ℓ texels in level-0 texels: (width, height, fx, fy) with texel (x, y)
/// covering columns [x·fx, (x+1)·fx) and rows [y·fy, (y+1)·fy).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Footprint {
    pub width: usize,
    pub height: usize,
    pub fx: usize,
    pub fy: usize,
}

impl Footprint {
    pub fn base(width: usize, height: usize) -> Footprint {
        Footprint {
            width,
            height,
            fx: 1,
            fy: 1,
        }
    }

    /// Level 0, then every MIP level down to 1×1 (sizes halved and rounded down; a side that is
    /// already 1 stays 1 and stops widening its footprint).
    pub fn chain(width: usize, height: usize) -> Vec<Footprint> {
        let mut out = vec![Footprint::base(width, height)];
        let mut f = out[0];
        while f.width > 1 || f.height > 1 {
            let (sx, sy) = (
                if f.width > 1 { 2 } else { 1 },
                if f.height > 1 { 2 } else { 1 },
            );
            f = Footprint {
                width: f.width / sx,
                height: f.height / sy,
                fx: f.fx * sx,
                fy: f.fy * sy,
            };
            out.push(f);
        }
        out
    }
}

impl Source<'_> {
    /// K of light `l` for the `out.len()` level texels from index `start` of level `fp` (of a
    /// level-0 image `w0` wide): the box-filtered K of each footprint (coverage-weighted for a
    /// stack, pooled counts for a bake), or −1 where nothing of the footprint is covered (or,
    /// for a stack, where every sample of it is not finite).
    fn fill(&self, l: usize, fp: Footprint, w0: usize, start: usize, out: &mut [f32]) {
        let base = fp.fx == 1 && fp.fy == 1;
        match self {
            Source::Planes { k, coverage } if base => {
                let (k, c) = (
                    &k[l][start..start + out.len()],
                    &coverage[start..start + out.len()],
                );
                for ((o, &kv), &cv) in out.iter_mut().zip(k).zip(c) {
                    *o = if cv > 0.0 && kv.is_finite() {
                        kv.clamp(0.0, 1.0)
                    } else {
                        -1.0
                    };
                }
            }
            Source::Planes { k, coverage } => {
                for (i, o) in out.iter_mut().enumerate() {
                    let ti = start + i;
                    let (x0, y0) = ((ti % fp.width) * fp.fx, (ti / fp.width) * fp.fy);
                    let (mut num, mut den) = (0f64, 0f64);
                    for yy in y0..y0 + fp.fy {
                        let r = yy * w0 + x0;
                        for (&kv, &cv) in k[l][r..r + fp.fx].iter().zip(&coverage[r..r + fp.fx]) {
                            if cv > 0.0 && kv.is_finite() {
                                num += (cv * kv.clamp(0.0, 1.0)) as f64;
                                den += cv as f64;
                            }
                        }
                    }
                    *o = if den > 0.0 { (num / den) as f32 } else { -1.0 };
                }
            }
            Source::Counts8 { occ, cov } => pooled(&occ[l], cov, fp, w0, start, out),
            Source::Counts16 { occ, cov } => pooled(&occ[l], cov, fp, w0, start, out),
        }
    }
}

/// Pooled counts Σ occluded / Σ covered over each footprint (exact integer sums).
fn pooled<T: Copy + Into<u32>>(
    occ: &[T],
    cov: &[u16],
    fp: Footprint,
    w0: usize,
    start: usize,
    out: &mut [f32],
) {
    for (i, o) in out.iter_mut().enumerate() {
        let ti = start + i;
        let (x0, y0) = ((ti % fp.width) * fp.fx, (ti / fp.width) * fp.fy);
        let (mut num, mut den) = (0u64, 0u64);
        for yy in y0..y0 + fp.fy {
            let r = yy * w0 + x0;
            num += occ[r..r + fp.fx].iter().map(|&v| v.into()).sum::<u32>() as u64;
            den += cov[r..r + fp.fx].iter().map(|&v| v as u32).sum::<u32>() as u64;
        }
        *o = if den > 0 {
            (num as f64 / den as f64) as f32
        } else {
            -1.0
        };
    }
}

/// Texels per parallel work unit.
const BLOCK: usize = 256;

/// Fits every texel of the level `fp` (of a level-0 image `w0` wide) from `src`: per texel, its
/// fit (coefficients, iterations, class, errors). `live[t]` is false for texels to leave out
/// (coefficients 0). Parallel over blocks; the result does not depend on the thread count.
pub(crate) fn fit_level(
    t: &Tables,
    src: &Source,
    fp: Footprint,
    w0: usize,
    live: &(dyn Fn(usize) -> bool + Sync),
    kernel: Kernel,
) -> Vec<TexelFit> {
    assert!(kernel.supported(), "kernel {} not supported", kernel.name());
    let texels = fp.width * fp.height;
    let lanes = kernel.lanes();
    let nu = t.used.len();
    let mut out = vec![TexelFit::default(); texels];
    out.par_chunks_mut(BLOCK).enumerate().for_each_init(
        Vec::new,
        |packed: &mut Vec<f32>, (bi, chunk)| {
            let start = bi * BLOCK;
            let len = chunk.len();
            let tiles = len.div_ceil(lanes);
            packed.clear();
            packed.resize(tiles * nu * lanes, -1.0);
            let mut live_v: Vec<bool> = (start..start + len).map(live).collect();
            let mut row = vec![0f32; tiles * lanes];
            let mut any = vec![false; len];
            for (li, &l) in t.used.iter().enumerate() {
                src.fill(l, fp, w0, start, &mut row[..len]);
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
            run_block(kernel, t, packed, &live_v, chunk);
        },
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_solver_handles_singular_matrices() {
        // Rank 1: H = e₀e₀ᵀ; g along e₀ and e₁: the pseudo-inverse keeps only e₀.
        let m = 2;
        let hp = [1.0, 0.0, 0.0];
        let x = solve_spd::<2>(&hp, &[2.0, 3.0], 0.0);
        assert!((x[0] - 2.0).abs() < 1e-12 && x[1].abs() < 1e-12);
        let x = solve_spd::<2>(&[4.0, 2.0, 3.0], &[2.0, 1.0], 0.0);
        // [[4,2],[2,3]]·x = [2,1] → x = [0.5, 0]
        assert!((x[0] - 0.5).abs() < 1e-12 && x[1].abs() < 1e-12);
    }

    #[test]
    fn chain_matches_round_down_sizes() {
        for (w, h) in [(13, 7), (64, 64), (4, 16), (1, 5)] {
            let chain = Footprint::chain(w, h);
            let sizes: Vec<(usize, usize)> =
                chain[1..].iter().map(|f| (f.width, f.height)).collect();
            assert_eq!(sizes, crate::ptm::mip_sizes(w, h), "{w}×{h}");
        }
    }
}
