//! The identity link's hot loops and every `unsafe` SIMD kernel of the solver: the streaming
//! accumulator's f64 update, and the stored-stack refit (packing a block of K into tiles, then
//! one kernel, written once over [`Simd`] and compiled for AVX-512F, AVX2 + FMA and portable
//! code, that forms c = P·k and the residuals of the same tile while it is in L1).
//!
//! Each build is entered with the proof-of-feature token of its instruction set (see
//! `crate::simd`), made by a run-time check; the result is deterministic on a given machine
//! (FMA changes the last bits against portable code, which the tests below bound).
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx2, Avx512};
use crate::simd::{Isa, Portable, Simd};

/// g += aw·k and s += w·k² per texel (texel-major g, M per texel); masked or non-finite
/// samples add nothing. Branch-free so the M-wide update vectorises.
pub(super) fn accumulate<const M: usize>(
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cpu) = Avx2::detect() {
        // SAFETY: `cpu` proves the CPU has AVX2 and FMA, the features the function is compiled
        // for.
        return unsafe { accumulate_avx2::<M>(cpu, g, s, k, masked, aw, w) };
    }
    accumulate_body::<M>(g, s, k, masked, aw, w)
}

/// The same loop compiled for AVX2 + FMA (which the compiler vectorises 4 f64 wide).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn accumulate_avx2<const M: usize>(
    _cpu: Avx2,
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    accumulate_body::<M>(g, s, k, masked, aw, w)
}

#[inline(always)]
fn accumulate_body<const M: usize>(
    g: &mut [f64],
    s: &mut [f64],
    k: &[f32],
    masked: &[bool],
    aw: &[f64],
    w: f64,
) {
    let aw: &[f64; M] = aw.try_into().unwrap();
    for (((gb, sb), &kb), &mb) in g.chunks_exact_mut(M).zip(s.iter_mut()).zip(k).zip(masked) {
        let kb = if mb || !kb.is_finite() {
            0.0
        } else {
            kb as f64
        };
        let gb: &mut [f64; M] = gb.try_into().unwrap();
        for j in 0..M {
            gb[j] += aw[j] * kb;
        }
        *sb += w * kb * kb;
    }
}
/// Texels per parallel work unit of the fused product + residual kernel (a multiple of the
/// tile widths, 8 and 16).
pub(super) const BLOCK: usize = 256;

/// Results of one texel block: coefficients (term-major, BLOCK stride), weighted squared
/// residual sum, max |residual|, squared held-out error sum.
pub(super) struct Block {
    pub c: Vec<f32>,
    pub ss: Vec<f32>,
    pub mx: Vec<f32>,
    pub hs: Vec<f32>,
}

/// Inputs of the fused kernel shared by all blocks. Lights are taken in `used` order: the
/// fitting lights first (`nfit` of them), then the held-out lights.
pub(super) struct KernelIn<'a> {
    pub k: &'a [Vec<f32>],
    pub used: Vec<usize>,
    pub nfit: usize,
    /// Per used light: its row of P (terms), its row of A in f32 (terms), its weight.
    pub p: Vec<f32>,
    pub a: Vec<f32>,
    pub w: Vec<f32>,
}

/// The widest tile, in texels (AVX-512: 16 f32).
const MAX_LANES: usize = 16;

thread_local! {
    /// Per-thread packing buffer, reused across blocks.
    static PACK: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// One block of `len` texels from `start`, with the given build (which the CPU must support:
/// [`Isa::supported`]; callers pass [`Isa::detect`]).
pub(super) fn kernel(inp: &KernelIn, start: usize, len: usize, m: usize, build: Isa) -> Block {
    assert!(
        build.supported(),
        "the {} kernel does not run here",
        build.name()
    );
    PACK.with(|buf| {
        let mut buf = buf.borrow_mut();
        pack(inp, start, len, build.lanes(), &mut buf);
        match m {
            6 => tiles::<6>(inp, &buf, len, build),
            11 => tiles::<11>(inp, &buf, len, build),
            _ => unreachable!("bases have 6 or 11 terms"),
        }
    })
}

/// The build's tile kernel over a packed block, entered with the build's token.
fn tiles<const M: usize>(inp: &KernelIn, packed: &[f32], len: usize, build: Isa) -> Block {
    let lacks = "`kernel` checked that the CPU has the build's features";
    match build {
        Isa::Portable => tiles_body::<Portable, M>(Portable, inp, packed, len),
        // SAFETY (both arms): the token proves the CPU has the features the function is
        // compiled for.
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => unsafe { tiles_avx2::<M>(Avx2::detect().expect(lacks), inp, packed, len) },
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => unsafe {
            tiles_avx512::<M>(Avx512::detect().expect(lacks), inp, packed, len)
        },
        #[cfg(not(target_arch = "x86_64"))]
        _ => unreachable!("x86 builds are never supported elsewhere"),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn tiles_avx2<const M: usize>(cpu: Avx2, inp: &KernelIn, packed: &[f32], len: usize) -> Block {
    tiles_body::<Avx2, M>(cpu, inp, packed, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tiles_avx512<const M: usize>(cpu: Avx512, inp: &KernelIn, packed: &[f32], len: usize) -> Block {
    tiles_body::<Avx512, M>(cpu, inp, packed, len)
}

/// Copies the block's K into tile-major order, `[tile][used light][lane]` with `lanes` texels
/// per tile, zero-padded: the rows stream from memory once, and the tile kernel then reads
/// contiguous memory (as a GEMM packs its panels).
fn pack(inp: &KernelIn, start: usize, len: usize, lanes: usize, buf: &mut Vec<f32>) {
    match lanes {
        8 => pack_lanes::<8>(inp, start, len, buf),
        16 => pack_lanes::<16>(inp, start, len, buf),
        _ => unreachable!("tiles are 8 or 16 texels wide"),
    }
}

fn pack_lanes<const L: usize>(inp: &KernelIn, start: usize, len: usize, buf: &mut Vec<f32>) {
    let nu = inp.used.len();
    let tiles = len.div_ceil(L);
    buf.clear();
    buf.resize(tiles * nu * L, 0.0);
    for (li, &l) in inp.used.iter().enumerate() {
        let row = &inp.k[l][start..start + len];
        let mut chunks = row.chunks_exact(L);
        for (tile, chunk) in chunks.by_ref().enumerate() {
            let o = (tile * nu + li) * L;
            // Fixed-size copy: one vector move, no memmove call.
            let dst: &mut [f32; L] = (&mut buf[o..o + L]).try_into().unwrap();
            *dst = chunk.try_into().unwrap();
        }
        let rest = chunks.remainder();
        let o = ((len / L) * nu + li) * L;
        for (q, &x) in rest.iter().enumerate() {
            buf[o + q] = x;
        }
    }
}

/// Stores the first `n` lanes of `v` at the start of `dst` (a tile may be cut by the block's
/// end).
#[inline(always)]
fn put<S: Simd>(cpu: S, v: S::V, n: usize, dst: &mut [f32]) {
    let mut lanes = [0f32; MAX_LANES];
    cpu.store(v, &mut lanes);
    dst[..n].copy_from_slice(&lanes[..n]);
}

/// Per tile of `S::LANES` texels: c = Σ_l P[l]·k[l] with M accumulators in registers, then the
/// residual pass over the same tile's K (now in L1): weighted squared residuals and max
/// |residual| over the fitting lights, squared error of clamped K over the held-out ones.
/// Plain loops only: a closure would not inherit the caller's target features.
#[inline(always)]
fn tiles_body<S: Simd, const M: usize>(
    cpu: S,
    inp: &KernelIn,
    packed: &[f32],
    len: usize,
) -> Block {
    let l = S::LANES;
    let mut out = Block {
        c: vec![0f32; M * BLOCK],
        ss: vec![0f32; BLOCK],
        mx: vec![0f32; BLOCK],
        hs: vec![0f32; BLOCK],
    };
    let nu = inp.used.len();
    let (zero, one) = (cpu.splat(0.0), cpu.splat(1.0));
    for (tile, kt) in packed.chunks_exact(nu * l).enumerate() {
        let b0 = tile * l;
        let mut acc = [zero; M];
        for li in 0..inp.nfit {
            let kv = cpu.load(&kt[li * l..]);
            let pl: &[f32; M] = inp.p[li * M..(li + 1) * M].try_into().unwrap();
            for j in 0..M {
                acc[j] = cpu.fma(cpu.splat(pl[j]), kv, acc[j]);
            }
        }
        let (mut ss, mut mx, mut hs) = (zero, zero, zero);
        for li in 0..nu {
            let kv = cpu.load(&kt[li * l..]);
            let al: &[f32; M] = inp.a[li * M..(li + 1) * M].try_into().unwrap();
            let mut pred = zero;
            for j in 0..M {
                pred = cpu.fma(cpu.splat(al[j]), acc[j], pred);
            }
            if li < inp.nfit {
                let r = cpu.sub(kv, pred);
                ss = cpu.fma(cpu.mul(cpu.splat(inp.w[li]), r), r, ss);
                // Non-finite samples show up in ss; max only has to order finite values.
                mx = cpu.max(cpu.abs(r), mx);
            } else {
                let r = cpu.sub(cpu.min(cpu.max(pred, zero), one), kv);
                hs = cpu.fma(r, r, hs);
            }
        }
        let n = l.min(len - b0);
        for j in 0..M {
            put::<S>(cpu, acc[j], n, &mut out.c[j * BLOCK + b0..]);
        }
        put::<S>(cpu, ss, n, &mut out.ss[b0..]);
        put::<S>(cpu, mx, n, &mut out.mx[b0..]);
        put::<S>(cpu, hs, n, &mut out.hs[b0..]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of 203 texels (not a multiple of any tile) × 37 lights, the last 3 held out.
    fn input(k: &[Vec<f32>], m: usize) -> KernelIn<'_> {
        let n = k.len();
        KernelIn {
            k,
            used: (0..n).collect(),
            nfit: n - 3,
            p: (0..n * m)
                .map(|i| ((i * 5) % 11) as f32 / 50.0 - 0.1)
                .collect(),
            a: (0..n * m)
                .map(|i| ((i * 3) % 7) as f32 / 7.0 - 0.4)
                .collect(),
            w: (0..n).map(|i| 0.5 + (i % 3) as f32 * 0.25).collect(),
        }
    }

    /// Every SIMD build agrees with the portable code (what non-x86 and pre-AVX2 machines run)
    /// for both bases, on a CPU that has the build's features; a build this CPU lacks is named
    /// as skipped.
    #[test]
    fn simd_kernels_agree_with_portable() {
        let (n, len) = (37usize, 203usize);
        let k: Vec<Vec<f32>> = (0..n)
            .map(|l| {
                (0..len)
                    .map(|t| ((t * 13 + l * 7) % 29) as f32 / 29.0)
                    .collect()
            })
            .collect();
        let mut compared = 0;
        for m in [6usize, 11] {
            let inp = input(&k, m);
            let want = kernel(&inp, 0, len, m, Isa::Portable);
            assert!(want.c[..len].iter().any(|&c| c != 0.0));
            assert!(want.ss[..len].iter().all(|&s| s > 0.0));
            assert!(want.mx[..len].iter().all(|&x| x > 0.0));
            assert!(want.hs[..len].iter().any(|&h| h != 0.0));
            for build in [Isa::Avx2, Isa::Avx512] {
                if !build.supported() {
                    eprintln!(
                        "skipped: {} kernel, ptm{m} (this CPU lacks it)",
                        build.name()
                    );
                    continue;
                }
                let got = kernel(&inp, 0, len, m, build);
                for (name, x, y) in [
                    ("c", &want.c, &got.c),
                    ("ss", &want.ss, &got.ss),
                    ("mx", &want.mx, &got.mx),
                    ("hs", &want.hs, &got.hs),
                ] {
                    assert_eq!(x.len(), y.len());
                    for (i, (a, b)) in x.iter().zip(y.iter()).enumerate() {
                        assert!(
                            (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                            "{} ptm{m} {name}[{i}]: portable {a} vs {b}",
                            build.name()
                        );
                    }
                }
                eprintln!("compared: {} kernel, ptm{m}", build.name());
                compared += 1;
            }
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            assert_eq!(compared, 4, "an x86 CPU with AVX-512F also has AVX2 + FMA");
        }
        let _ = compared;
    }
}
