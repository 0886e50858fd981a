//! A block of texels through the logistic kernel: its K packed into tiles of lanes, Newton on
//! a work copy whose still-active lanes are compacted after every step, and the builds (portable,
//! AVX2 + FMA, AVX-512F) entered with their proof-of-feature tokens; then a whole level's
//! blocks in parallel ([`fit_level`]).
use rayon::prelude::*;

use super::newton::{final_pass, newton_step, warm_start, TexelFit};
use super::pool::Source;
use super::tables::Tables;
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx2, Avx512};
use crate::simd::{Isa, Portable, Simd};

/// Per-slot Newton state of a block: a slot is one lane of one tile of the work buffer.
struct Slots<const M: usize> {
    /// Coefficients per tile, `[term][lane]`.
    c: Vec<[[f32; 16]; M]>,
    /// Block-local texel held by each slot (tile·16 + lane), if any.
    texel: Vec<Option<usize>>,
    active: Vec<bool>,
}

/// Fits every texel of a packed block (`packed`: tiles of `[used light][lane]`). Newton runs on
/// a work copy whose still-active lanes are compacted into the lowest tiles after every step,
/// so a block costs its texels' mean iteration count, not each tile's slowest lane's.
#[inline(always)]
fn block_body<S: Simd, const M: usize, const D: usize>(
    cpu: S,
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
            cpu,
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
                cpu,
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
            cpu,
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
    cpu: Portable,
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<Portable, M, D>(cpu, t, packed, live, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn block_avx2<const M: usize, const D: usize>(
    cpu: Avx2,
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<Avx2, M, D>(cpu, t, packed, live, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn block_avx512<const M: usize, const D: usize>(
    cpu: Avx512,
    t: &Tables,
    packed: &[f32],
    live: &[bool],
    out: &mut [TexelFit],
) {
    block_body::<Avx512, M, D>(cpu, t, packed, live, out)
}

/// One block with the build `isa`, entered with its token: panics where the CPU lacks it
/// (callers check [`Isa::supported`] first and say so as an error).
fn run_block(isa: Isa, t: &Tables, packed: &[f32], live: &[bool], out: &mut [TexelFit]) {
    fn lacks<T>(isa: Isa) -> T {
        panic!("the {} kernel does not run on this CPU", isa.name())
    }
    macro_rules! dispatch {
        ($f:ident, $cpu:expr $(, $unsafe:tt)?) => {{
            let cpu = $cpu;
            match (t.m, t.d) {
                // SAFETY (the unsafe arms): `cpu` is the token of the features `$f` is compiled
                // for, so the CPU has them.
                (6, 15) => $($unsafe)? { $f::<6, 15>(cpu, t, packed, live, out) },
                (11, 33) => $($unsafe)? { $f::<11, 33>(cpu, t, packed, live, out) },
                // Learned bases: every product of two terms is its own Hessian entry.
                (6, 21) => $($unsafe)? { $f::<6, 21>(cpu, t, packed, live, out) },
                (11, 66) => $($unsafe)? { $f::<11, 66>(cpu, t, packed, live, out) },
                _ => unreachable!("bases have 6 or 11 terms"),
            }
        }};
    }
    match isa {
        Isa::Portable => dispatch!(block_portable, Portable),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => dispatch!(
            block_avx2,
            Avx2::detect().unwrap_or_else(|| lacks(isa)),
            unsafe
        ),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => dispatch!(
            block_avx512,
            Avx512::detect().unwrap_or_else(|| lacks(isa)),
            unsafe
        ),
        #[cfg(not(target_arch = "x86_64"))]
        _ => lacks(isa),
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
    isa: Isa,
) -> LevelFit {
    assert!(isa.supported(), "kernel {} not supported", isa.name());
    let lanes = isa.lanes();
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
                run_block(isa, t, packed, &live_v, &mut fits);
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
