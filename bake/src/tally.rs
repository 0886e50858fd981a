//! K of a texel block under a distant light, from two bit masks: which of the block's entries
//! (its covered samples, texel by texel) faced the light, and which of its rays (the facing
//! entries, in order) came back lit.
//!
//! Texel `t`'s entries follow those of the texels before it and its rays follow theirs alike,
//! so the rays lit up to the end of texel `t` are the ones of `lit` below the number of facing
//! entries below `t`'s end: two masked popcounts per texel, and a texel's lit rays the
//! difference from the texel before. An add per ray into its texel's count, as before, was a
//! chain of read-modify-writes on the same few counters (2.8 % of a jersey bake under `perf`).
//!
//! Three builds, chosen at run time like [`crate::facing`]'s: AVX-512 (F and VPOPCNTDQ), all 16
//! texels in two registers of 64-bit lanes; AVX2, in four, counting bits by nibble lookups
//! (`vpshufb`, `vpsadbw`); and portable Rust, a texel at a time (with `popcnt` where the CPU
//! has it). All end in the same `(covered − lit) / max(covered, 1)` in f32, so they agree to
//! the bit (tested).

use crate::facing::Isa;

/// K of a block's 16 texels (`covered` samples each, at most 64 in all; `ends` their running
/// sums, the same for every light): `facing` marks the entries that faced the light (bit `e`
/// for entry `e`), `lit` the rays that came back lit (bit `r` for the `r`-th facing entry).
/// Uncovered texels get 0.
pub(crate) fn block_k(
    facing: u64,
    lit: u64,
    covered: &[u32; 16],
    ends: &[u32; 16],
    isa: Isa,
) -> [f32; 16] {
    debug_assert!(ends[15] <= 64 && ends[15] == covered.iter().sum::<u32>());
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vpopcntdq") =>
        {
            // SAFETY: the CPU has AVX-512F and VPOPCNTDQ (checked just above).
            unsafe { k_avx512(facing, lit, covered, ends) }
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if std::arch::is_x86_feature_detected!("avx2") => {
            // SAFETY: the CPU has AVX2 (checked just above).
            unsafe { k_avx2(facing, lit, covered, ends) }
        }
        #[cfg(target_arch = "x86_64")]
        _ if std::arch::is_x86_feature_detected!("popcnt") => {
            // SAFETY: the CPU has popcnt (checked just above).
            unsafe { k_portable_popcnt(facing, lit, covered, ends) }
        }
        _ => k_portable(facing, lit, covered, ends),
    }
}

/// The ones of `x` below bit `n` (0 ≤ n ≤ 64): the low `n` bits shifted to the top, without
/// a branch (a shift by 64 wraps to 0, and `n` = 0 then keeps nothing).
#[inline(always)]
pub(crate) fn ones_below(x: u64, n: u32) -> u32 {
    debug_assert!(n <= 64);
    (x.wrapping_shl(64 - n) & 0u64.wrapping_sub((n != 0) as u64)).count_ones()
}

/// Per texel of a block of any size (the baker's path above 64 entries, spp above 4), its rays
/// that came back lit: [`block_k`]'s counts over sets of words (bit `i` is bit `i % 64` of
/// word `i / 64`; words past the end count as clear), a texel at a time.
pub(crate) fn block_lit(facing: &[u64], lit: &[u64], ends: &[u32; 16]) -> [u32; 16] {
    let ones_below_at = |bits: &[u64], at: usize| {
        let (w, b) = (at / 64, at % 64);
        let whole: u32 = bits[..w.min(bits.len())]
            .iter()
            .map(|x| x.count_ones())
            .sum();
        whole + bits.get(w).map_or(0, |&x| ones_below(x, b as u32))
    };
    let mut out = [0; 16];
    let mut below = 0;
    for (out, &end) in out.iter_mut().zip(ends) {
        let upto = ones_below_at(lit, ones_below_at(facing, end as usize) as usize);
        *out = upto - below;
        below = upto;
    }
    out
}

/// K of a texel from its lit rays: its covered samples not found lit, over its covered ones
/// (0 / 1 for an uncovered texel).
pub(crate) fn k_of(covered: u32, lit: u32) -> f32 {
    (covered - lit) as f32 / covered.max(1) as f32
}

/// [`k_portable`] with the CPU's `popcnt` (x86-64 CPUs have had it since 2008; without it a
/// count is a dozen instructions, and the portable build ran 2.5 % slower than with an add
/// per ray).
///
/// # Safety
/// The CPU must have `popcnt`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "popcnt")]
unsafe fn k_portable_popcnt(
    facing: u64,
    lit: u64,
    covered: &[u32; 16],
    ends: &[u32; 16],
) -> [f32; 16] {
    k_portable(facing, lit, covered, ends)
}

/// A texel at a time: two masked popcounts, then K of all 16 (one division each, which the
/// compiler vectorizes; a division per texel in the counting loop cost more than the counts).
#[inline(always)]
fn k_portable(facing: u64, lit: u64, covered: &[u32; 16], ends: &[u32; 16]) -> [f32; 16] {
    let mut lit_here = [0u32; 16];
    let mut below = 0;
    for (lit_here, &end) in lit_here.iter_mut().zip(ends) {
        let upto = ones_below(lit, ones_below(facing, end));
        *lit_here = upto - below;
        below = upto;
    }
    let mut k = [0.0; 16];
    for ((k, &c), &l) in k.iter_mut().zip(covered).zip(&lit_here) {
        *k = k_of(c, l);
    }
    k
}

/// # Safety
/// The CPU must have AVX-512F and AVX-512 VPOPCNTDQ.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vpopcntdq")]
unsafe fn k_avx512(facing: u64, lit: u64, covered: &[u32; 16], ends: &[u32; 16]) -> [f32; 16] {
    use std::arch::x86_64::*;
    let mut k = [0.0f32; 16];
    // SAFETY: loads and stores of 16 lanes of 16-element arrays.
    unsafe {
        let ones = _mm512_set1_epi64(-1);
        // x & the bits below n, per 64-bit lane: a shift by 64 or more is 0 (all bits kept).
        let below = |x: __m512i, n: __m512i| {
            _mm512_popcnt_epi64(_mm512_andnot_si512(_mm512_sllv_epi64(ones, n), x))
        };
        let (f, l) = (
            _mm512_set1_epi64(facing as i64),
            _mm512_set1_epi64(lit as i64),
        );
        let e = _mm512_loadu_si512(ends.as_ptr().cast());
        let upto = |e: __m256i| {
            let e = _mm512_cvtepu32_epi64(e);
            _mm512_cvtepi64_epi32(below(l, below(f, e)))
        };
        let lo = upto(_mm512_castsi512_si256(e));
        let hi = upto(_mm512_extracti64x4_epi64::<1>(e));
        let upto = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(lo), hi);
        // Each texel's lit rays: its count less the texel before's (lanes moved up by one).
        let before = _mm512_alignr_epi32::<15>(upto, _mm512_setzero_si512());
        let lit = _mm512_sub_epi32(upto, before);
        let c = _mm512_loadu_si512(covered.as_ptr().cast());
        let num = _mm512_cvtepi32_ps(_mm512_sub_epi32(c, lit));
        let den = _mm512_cvtepi32_ps(_mm512_max_epu32(c, _mm512_set1_epi32(1)));
        _mm512_storeu_ps(k.as_mut_ptr(), _mm512_div_ps(num, den));
    }
    k
}

/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn k_avx2(facing: u64, lit: u64, covered: &[u32; 16], ends: &[u32; 16]) -> [f32; 16] {
    use std::arch::x86_64::*;
    let mut k = [0.0f32; 16];
    // SAFETY: loads of 4 lanes within 16-element arrays, stores of 8 lanes within `k`.
    unsafe {
        let (f, l) = (
            _mm256_set1_epi64x(facing as i64),
            _mm256_set1_epi64x(lit as i64),
        );
        // Lit rays up to the end of texels 4j..4j + 4, one 64-bit lane each (in straight
        // lines: a closure here is not inlined, and a call costs more than the count).
        let mut upto = [_mm256_setzero_si256(); 4];
        for (j, upto) in upto.iter_mut().enumerate() {
            let e = _mm256_cvtepu32_epi64(_mm_loadu_si128(ends.as_ptr().add(4 * j).cast()));
            *upto = below_avx2(l, below_avx2(f, e));
        }
        // The low halves of the lanes of two such vectors: 8 texels as 32-bit lanes.
        let pick = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);
        let mut halves = [_mm256_setzero_si256(); 2];
        for (h, half) in halves.iter_mut().enumerate() {
            *half = _mm256_permute2x128_si256::<0x20>(
                _mm256_permutevar8x32_epi32(upto[2 * h], pick),
                _mm256_permutevar8x32_epi32(upto[2 * h + 1], pick),
            );
        }
        // Texel 7's count, for the texel after it.
        let mut carry = _mm256_setzero_si256();
        for (h, upto) in halves.into_iter().enumerate() {
            // Lanes moved up by one, the carry into lane 0.
            let up = _mm256_permutevar8x32_epi32(upto, _mm256_setr_epi32(7, 0, 1, 2, 3, 4, 5, 6));
            let before = _mm256_blend_epi32::<1>(up, carry);
            carry = _mm256_permutevar8x32_epi32(upto, _mm256_set1_epi32(7));
            let lit = _mm256_sub_epi32(upto, before);
            let c = _mm256_loadu_si256(covered.as_ptr().add(8 * h).cast());
            let num = _mm256_cvtepi32_ps(_mm256_sub_epi32(c, lit));
            let den = _mm256_cvtepi32_ps(_mm256_max_epu32(c, _mm256_set1_epi32(1)));
            _mm256_storeu_ps(k.as_mut_ptr().add(8 * h), _mm256_div_ps(num, den));
        }
    }
    k
}

/// The ones of `x` below bit `n`, per 64-bit lane (a shift by 64 or more keeps every bit):
/// nibbles looked up in a table and summed per lane. A function of its own, inlined: as
/// closures of [`k_avx2`] they were calls, 0.9 % of a jersey bake on Embree's AVX2 kernels.
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn below_avx2(
    x: std::arch::x86_64::__m256i,
    n: std::arch::x86_64::__m256i,
) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    let x = _mm256_andnot_si256(_mm256_sllv_epi64(_mm256_set1_epi64x(-1), n), x);
    let nibble = _mm256_set1_epi8(0x0f);
    #[rustfmt::skip]
    let table = _mm256_setr_epi8(
        0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,
        0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,
    );
    let lo = _mm256_shuffle_epi8(table, _mm256_and_si256(x, nibble));
    let hi = _mm256_shuffle_epi8(table, _mm256_and_si256(_mm256_srli_epi16::<4>(x), nibble));
    _mm256_sad_epu8(_mm256_add_epi8(lo, hi), _mm256_setzero_si256())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition: per texel, its facing entries in order, and of those its rays' lit bits.
    fn reference(facing: &[u64], lit: &[u64], covered: &[u32; 16]) -> [f32; 16] {
        let bit = |bits: &[u64], i: usize| bits[i / 64] >> (i % 64) & 1;
        let (mut e, mut r) = (0, 0);
        covered.map(|c| {
            let mut lit_here = 0;
            for _ in 0..c {
                if bit(facing, e) == 1 {
                    lit_here += bit(lit, r) as u32;
                    r += 1;
                }
                e += 1;
            }
            k_of(c, lit_here)
        })
    }

    fn ends(covered: &[u32; 16]) -> [u32; 16] {
        let mut sum = 0;
        covered.map(|c| {
            sum += c;
            sum
        })
    }

    /// Random blocks (0 to 64 entries, texels of 0 to 9 samples, empty and full blocks among
    /// them, all facing or none, all lit or none): every build this CPU runs gives the
    /// definition's K to the bit.
    #[test]
    fn builds_count_as_the_definition() {
        let mut rand = crate::facing::xorshift(0x9e37_79b9_7f4a_7c15);
        let isas = Isa::every_supported();
        for round in 0..20_000 {
            let mut covered = [0u32; 16];
            let full = round % 7 == 0;
            let mut left = 64;
            for c in covered.iter_mut() {
                let want = if full { 4 } else { (rand() % 10) as u32 };
                *c = want.min(left);
                left -= *c;
            }
            let n: u32 = covered.iter().sum();
            let entries = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
            let facing = match round % 5 {
                0 => entries,
                1 => 0,
                _ => rand() & entries,
            };
            let rays = facing.count_ones();
            let rays = if rays == 64 {
                u64::MAX
            } else {
                (1u64 << rays) - 1
            };
            let lit = match round % 3 {
                0 => rays,
                _ => rand() & rays,
            };
            let want = reference(&[facing], &[lit], &covered);
            let ends = ends(&covered);
            for &isa in &isas {
                let got = block_k(facing, lit, &covered, &ends, isa);
                assert_eq!(
                    got.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{isa:?}, round {round}: covered {covered:?}, facing {facing:#x}, lit {lit:#x}"
                );
            }
            // The portable build without `popcnt`, as a CPU without it runs it.
            let got = k_portable(facing, lit, &covered, &ends);
            assert_eq!(
                got.map(f32::to_bits),
                want.map(f32::to_bits),
                "round {round}"
            );
        }
    }

    /// Random blocks of up to 16 samples a texel (256 entries, four words), the word sets
    /// as the baker keeps them: [`block_lit`] gives the definition's K to the bit.
    #[test]
    fn word_sets_count_as_the_definition() {
        let mut rand = crate::facing::xorshift(0x2545_f491_4f6c_dd1d);
        for round in 0..5_000 {
            let spp = [5, 9, 16][round % 3];
            let covered: [u32; 16] = std::array::from_fn(|_| (rand() % (spp + 1)) as u32);
            let n = covered.iter().sum::<u32>() as usize;
            let words = n.div_ceil(64).max(1);
            let clear_past = |bits: &mut Vec<u64>, n: usize| {
                for (w, x) in bits.iter_mut().enumerate() {
                    let keep = n.saturating_sub(64 * w).min(64) as u32;
                    *x &= if keep == 64 {
                        u64::MAX
                    } else {
                        (1u64 << keep) - 1
                    };
                }
            };
            let mut facing: Vec<u64> = (0..words).map(|_| rand()).collect();
            if round % 4 == 0 {
                facing.fill(u64::MAX);
            }
            clear_past(&mut facing, n);
            let rays = facing.iter().map(|x| x.count_ones() as usize).sum();
            let mut lit: Vec<u64> = (0..words).map(|_| rand()).collect();
            clear_past(&mut lit, rays);
            let want = reference(&facing, &lit, &covered);
            let got = block_lit(&facing, &lit, &ends(&covered));
            let got: Vec<f32> = (0..16).map(|t| k_of(covered[t], got[t])).collect();
            assert_eq!(
                got.iter().map(|k| k.to_bits()).collect::<Vec<_>>(),
                want.map(f32::to_bits).to_vec(),
                "round {round}: covered {covered:?}"
            );
        }
    }
}
