//! A minimal vector abstraction over f32 lanes, so each hot kernel is written once and compiled
//! for AVX-512F (16 lanes), AVX2 + FMA (8) and portable code (8 lanes of plain arrays).
//!
//! The x86 implementations call intrinsics of their feature set. They are only ever
//! instantiated inside functions compiled with `#[target_feature(enable = …)]` of that set and
//! entered after a run-time check (`is_x86_feature_detected!`): that is the safety contract of
//! [`Avx2`] and [`Avx512`], and why the types are private to the crate.

/// Lane-parallel f32 operations. `fma(a, b, c)` = a·b + c (fused where the hardware has it).
pub(crate) trait Simd {
    const LANES: usize;
    type V: Copy;
    fn splat(x: f32) -> Self::V;
    /// Loads `LANES` values from the start of `s`.
    fn load(s: &[f32]) -> Self::V;
    /// Stores `LANES` values to the start of `out`.
    fn store(v: Self::V, out: &mut [f32]);
    fn add(a: Self::V, b: Self::V) -> Self::V;
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    fn div(a: Self::V, b: Self::V) -> Self::V;
    fn fma(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    fn min(a: Self::V, b: Self::V) -> Self::V;
    fn max(a: Self::V, b: Self::V) -> Self::V;
    fn sqrt(a: Self::V) -> Self::V;
    /// |a| (the sign bit cleared).
    fn abs(a: Self::V) -> Self::V;
    /// x where k ≥ 0, else 0 (k < 0 or NaN).
    fn where_nonneg(k: Self::V, x: Self::V) -> Self::V;
    /// 2ⁿ for integer-valued n in [−126, 127].
    fn pow2i(n: Self::V) -> Self::V;
    /// 1/x to about 2e-7 relative (a division where the hardware's is slow: an estimate and one
    /// Newton–Raphson step).
    #[inline(always)]
    fn recip(x: Self::V) -> Self::V {
        Self::div(Self::splat(1.0), x)
    }
    /// (e, m) with x = m·2ᵉ, m ∈ [1, 2), for positive normal x.
    fn split_exponent(x: Self::V) -> (Self::V, Self::V);

    /// eˣ, x clamped to [−87, 87]; relative error below 2e-7.
    #[inline(always)]
    fn exp(x: Self::V) -> Self::V {
        let x = Self::min(Self::max(x, Self::splat(-87.0)), Self::splat(87.0));
        // n = round(x / ln 2) by the 1.5·2²³ trick, then r = x − n·ln 2 in two parts.
        let magic = Self::splat(12_582_912.0);
        let n = Self::sub(
            Self::fma(x, Self::splat(std::f32::consts::LOG2_E), magic),
            magic,
        );
        let r = Self::fma(n, Self::splat(-0.693_145_75), x);
        let r = Self::fma(n, Self::splat(-1.428_606_8e-6), r);
        // e^r on [−ln2/2, ln2/2]: degree-6 Taylor in Horner form.
        let mut p = Self::splat(0.001_388_889);
        for c in [0.008_333_334, 0.041_666_668, 0.166_666_67, 0.5, 1.0, 1.0] {
            p = Self::fma(p, r, Self::splat(c));
        }
        Self::mul(p, Self::pow2i(n))
    }

    /// σ(z) = 1 / (1 + e^−z).
    #[inline(always)]
    fn sigmoid(z: Self::V) -> Self::V {
        let one = Self::splat(1.0);
        Self::recip(Self::add(one, Self::exp(Self::sub(Self::splat(0.0), z))))
    }

    /// ln x for positive normal x, absolute error below 1e-5 (enough for a warm start).
    #[inline(always)]
    fn ln(x: Self::V) -> Self::V {
        let (e, m) = Self::split_exponent(x);
        let one = Self::splat(1.0);
        // ln m = 2·atanh(s), s = (m − 1)/(m + 1) ∈ [0, 1/3].
        let s = Self::div(Self::sub(m, one), Self::add(m, one));
        let s2 = Self::mul(s, s);
        let mut p = Self::splat(1.0 / 9.0);
        for c in [1.0 / 7.0, 1.0 / 5.0, 1.0 / 3.0, 1.0] {
            p = Self::fma(p, s2, Self::splat(c));
        }
        let lnm = Self::mul(Self::mul(Self::splat(2.0), s), p);
        Self::fma(e, Self::splat(std::f32::consts::LN_2), lnm)
    }
}

/// Plain arrays of 8 lanes: what every CPU runs.
pub(crate) struct Portable;

impl Simd for Portable {
    const LANES: usize = 8;
    type V = [f32; 8];
    #[inline(always)]
    fn splat(x: f32) -> [f32; 8] {
        [x; 8]
    }
    #[inline(always)]
    fn load(s: &[f32]) -> [f32; 8] {
        s[..8].try_into().unwrap()
    }
    #[inline(always)]
    fn store(v: [f32; 8], out: &mut [f32]) {
        out[..8].copy_from_slice(&v);
    }
    #[inline(always)]
    fn add(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] + b[i])
    }
    #[inline(always)]
    fn sub(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] - b[i])
    }
    #[inline(always)]
    fn mul(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] * b[i])
    }
    #[inline(always)]
    fn div(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] / b[i])
    }
    #[inline(always)]
    fn fma(a: [f32; 8], b: [f32; 8], c: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] * b[i] + c[i])
    }
    #[inline(always)]
    fn min(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if a[i] < b[i] { a[i] } else { b[i] })
    }
    #[inline(always)]
    fn max(a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if a[i] > b[i] { a[i] } else { b[i] })
    }
    #[inline(always)]
    fn sqrt(a: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i].sqrt())
    }
    #[inline(always)]
    fn abs(a: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i].abs())
    }
    #[inline(always)]
    fn where_nonneg(k: [f32; 8], x: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if k[i] >= 0.0 { x[i] } else { 0.0 })
    }
    #[inline(always)]
    fn pow2i(n: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| f32::from_bits((((n[i] as i32) + 127) as u32) << 23))
    }
    #[inline(always)]
    fn split_exponent(x: [f32; 8]) -> ([f32; 8], [f32; 8]) {
        let e = std::array::from_fn(|i| ((x[i].to_bits() >> 23) as i32 - 127) as f32);
        let m =
            std::array::from_fn(|i| f32::from_bits((x[i].to_bits() & 0x007f_ffff) | 0x3f80_0000));
        (e, m)
    }
}

/// AVX2 + FMA, 8 lanes. Only instantiated in `#[target_feature(enable = "avx2,fma")]` code.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx2 {
    const LANES: usize = 8;
    type V = std::arch::x86_64::__m256;
    // SAFETY (every method): the caller runs with AVX2 and FMA (module contract); loads and
    // stores check their slice lengths first.
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self::V {
        assert!(s.len() >= 8);
        unsafe { std::arch::x86_64::_mm256_loadu_ps(s.as_ptr()) }
    }
    #[inline(always)]
    fn store(v: Self::V, out: &mut [f32]) {
        assert!(out.len() >= 8);
        unsafe { std::arch::x86_64::_mm256_storeu_ps(out.as_mut_ptr(), v) }
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_div_ps(a, b) }
    }
    #[inline(always)]
    fn fma(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_min_ps(a, b) }
    }
    #[inline(always)]
    fn max(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_max_ps(a, b) }
    }
    #[inline(always)]
    fn sqrt(a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm256_and_ps(a, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff))) }
    }
    #[inline(always)]
    fn recip(x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        // rcp (relative error < 1.5·2⁻¹²) and one Newton–Raphson step: r·(2 − x·r).
        unsafe {
            let r = _mm256_rcp_ps(x);
            _mm256_mul_ps(r, _mm256_fnmadd_ps(x, r, _mm256_set1_ps(2.0)))
        }
    }
    #[inline(always)]
    fn where_nonneg(k: Self::V, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(k, _mm256_setzero_ps()), x) }
    }
    #[inline(always)]
    fn pow2i(n: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let i = _mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127));
            _mm256_castsi256_ps(_mm256_slli_epi32::<23>(i))
        }
    }
    #[inline(always)]
    fn split_exponent(x: Self::V) -> (Self::V, Self::V) {
        use std::arch::x86_64::*;
        unsafe {
            let b = _mm256_castps_si256(x);
            let e = _mm256_sub_epi32(_mm256_srli_epi32::<23>(b), _mm256_set1_epi32(127));
            let m = _mm256_or_si256(
                _mm256_and_si256(b, _mm256_set1_epi32(0x007f_ffff)),
                _mm256_set1_epi32(0x3f80_0000),
            );
            (_mm256_cvtepi32_ps(e), _mm256_castsi256_ps(m))
        }
    }
}

/// AVX-512F, 16 lanes. Only instantiated in `#[target_feature(enable = "avx512f")]` code.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx512;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx512 {
    const LANES: usize = 16;
    type V = std::arch::x86_64::__m512;
    // SAFETY (every method): the caller runs with AVX-512F (module contract); loads and stores
    // check their slice lengths first.
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_set1_ps(x) }
    }
    #[inline(always)]
    fn load(s: &[f32]) -> Self::V {
        assert!(s.len() >= 16);
        unsafe { std::arch::x86_64::_mm512_loadu_ps(s.as_ptr()) }
    }
    #[inline(always)]
    fn store(v: Self::V, out: &mut [f32]) {
        assert!(out.len() >= 16);
        unsafe { std::arch::x86_64::_mm512_storeu_ps(out.as_mut_ptr(), v) }
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_div_ps(a, b) }
    }
    #[inline(always)]
    fn fma(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_min_ps(a, b) }
    }
    #[inline(always)]
    fn max(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_max_ps(a, b) }
    }
    #[inline(always)]
    fn sqrt(a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_abs_ps(a) }
    }
    #[inline(always)]
    fn recip(x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        // rcp14 (relative error < 2⁻¹⁴) and one Newton–Raphson step: r·(2 − x·r).
        unsafe {
            let r = _mm512_rcp14_ps(x);
            _mm512_mul_ps(r, _mm512_fnmadd_ps(x, r, _mm512_set1_ps(2.0)))
        }
    }
    #[inline(always)]
    fn where_nonneg(k: Self::V, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GE_OQ>(k, _mm512_setzero_ps()), x) }
    }
    #[inline(always)]
    fn pow2i(n: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let i = _mm512_add_epi32(_mm512_cvtps_epi32(n), _mm512_set1_epi32(127));
            _mm512_castsi512_ps(_mm512_slli_epi32::<23>(i))
        }
    }
    #[inline(always)]
    fn split_exponent(x: Self::V) -> (Self::V, Self::V) {
        use std::arch::x86_64::*;
        unsafe {
            let b = _mm512_castps_si512(x);
            let e = _mm512_sub_epi32(_mm512_srli_epi32::<23>(b), _mm512_set1_epi32(127));
            let m = _mm512_or_si512(
                _mm512_and_si512(b, _mm512_set1_epi32(0x007f_ffff)),
                _mm512_set1_epi32(0x3f80_0000),
            );
            (_mm512_cvtepi32_ps(e), _mm512_castsi512_ps(m))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[inline(always)]
    fn check<S: Simd>(name: &str) {
        let n = S::LANES;
        let mut worst_exp = 0f64;
        let mut worst_ln = 0f64;
        let mut x = -87.0f32;
        let mut buf = vec![0f32; n];
        while x < 87.0 {
            let xs: Vec<f32> = (0..n).map(|i| x + i as f32 * 0.001).collect();
            S::store(S::exp(S::load(&xs)), &mut buf);
            for (a, b) in xs.iter().zip(&buf) {
                let want = (*a as f64).exp();
                // Inputs beyond the clamp are compared with e^±87.
                let want = if a.abs() > 87.0 {
                    (87f64 * a.signum() as f64).exp()
                } else {
                    want
                };
                worst_exp = worst_exp.max(((*b as f64 - want) / want).abs());
            }
            let ps: Vec<f32> = xs.iter().map(|v| (v + 88.0) / 100.0).collect();
            S::store(S::ln(S::load(&ps)), &mut buf);
            for (a, b) in ps.iter().zip(&buf) {
                worst_ln = worst_ln.max((*b as f64 - (*a as f64).ln()).abs());
            }
            x += 0.0137;
        }
        assert!(worst_exp < 1e-6, "{name} exp relative error {worst_exp}");
        assert!(worst_ln < 1e-5, "{name} ln error {worst_ln}");
        let mut worst_sig = 0f64;
        let mut z = -30.0f32;
        while z < 30.0 {
            let zs: Vec<f32> = (0..n).map(|i| z + i as f32 * 0.001).collect();
            S::store(S::sigmoid(S::load(&zs)), &mut buf);
            for (a, b) in zs.iter().zip(&buf) {
                let want = 1.0 / (1.0 + (-*a as f64).exp());
                worst_sig = worst_sig.max(((*b as f64 - want) / want).abs());
            }
            z += 0.0071;
        }
        assert!(
            worst_sig < 1e-6,
            "{name} sigmoid relative error {worst_sig}"
        );
        S::store(S::sigmoid(S::splat(-200.0)), &mut buf);
        assert!(buf[0] >= 0.0 && buf[0] < 1e-30);
        S::store(S::sigmoid(S::splat(200.0)), &mut buf);
        assert!((buf[0] - 1.0).abs() <= 1e-7, "{name}: σ(200) = {}", buf[0]);
    }

    #[test]
    fn elementary_functions_are_accurate_in_every_build() {
        check::<Portable>("portable");
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2() {
                check::<Avx2>("avx2");
            }
            #[target_feature(enable = "avx512f")]
            unsafe fn avx512() {
                check::<Avx512>("avx512f");
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has the features.
                unsafe { avx2() };
            } else {
                eprintln!("skipped: avx2 (this CPU lacks it)");
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has the feature.
                unsafe { avx512() };
            } else {
                eprintln!("skipped: avx512f (this CPU lacks it)");
            }
        }
    }
}
