//! The instruction sets the fit's hot kernels run with ([`Isa`]: the choice, as options and
//! reports name it), and a minimal vector abstraction over f32 lanes (`Simd`), so that each
//! kernel is written once and compiled for AVX-512F (16 lanes), AVX2 + FMA (8) and portable code
//! (8 lanes of plain arrays). The identity link's stored-stack refit (`solve/kernel.rs`) and the
//! logistic Newton kernel (`logistic/block.rs`) both take their build from here.
//!
//! Safety: the x86 implementations call intrinsics of their feature set, which is undefined
//! behaviour on a CPU without it. The type system holds that rule. `Simd` is an `unsafe trait`
//! whose implementors are proof-of-feature tokens: every method takes `self`, and a value of
//! `Avx2` or `Avx512` is made only by its `detect`, which checks the CPU at run time (the
//! field that would let other code build one is private to this module). So safe code can call
//! a method only with a token in hand, and a token in hand means the CPU has the features. The
//! kernels are compiled inside `#[target_feature(enable = …)]` functions (so the intrinsics
//! inline) that take the token as an argument: the one `unsafe` at each entry cites the token.

/// Which instruction set the fit's SIMD kernels run with: the widest the CPU has
/// ([`Isa::detect`]), unless forced (`FitOptions::isa`, for tests and benchmarks). Every build
/// runs the same arithmetic in the same order; they differ only in FMA contraction and width.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// Plain Rust over 8-lane arrays, on any CPU.
    Portable,
    /// AVX2 with FMA, 8 f32 lanes.
    Avx2,
    /// AVX-512F, 16 f32 lanes.
    Avx512,
}

impl Isa {
    /// The widest instruction set this CPU runs.
    pub fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if Avx512::detect().is_some() {
                return Isa::Avx512;
            }
            if Avx2::detect().is_some() {
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    /// Whether this CPU runs it.
    pub fn supported(self) -> bool {
        match self {
            Isa::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => Avx2::detect().is_some(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => Avx512::detect().is_some(),
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// Texels one kernel call fits side by side.
    pub(crate) fn lanes(self) -> usize {
        match self {
            Isa::Avx512 => 16,
            _ => 8,
        }
    }

    /// The instruction set [`Isa::name`] names.
    pub fn from_name(name: &str) -> Option<Isa> {
        [Isa::Portable, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .find(|k| k.name() == name)
    }

    /// The build in words, as reports and file headers print it (`portable`, `avx2+fma`,
    /// `avx512f`).
    pub fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx2 => "avx2+fma",
            Isa::Avx512 => "avx512f",
        }
    }
}

/// Lane-parallel f32 operations. `fma(a, b, c)` = a·b + c (fused where the hardware has it).
///
/// # Safety
///
/// An implementor is a proof of CPU features: a value of it may exist only on a CPU that has
/// every feature its methods use (its constructor checks at run time, and nothing else can make
/// one), so that its methods, which take `self`, are sound wherever a value is at hand.
pub(crate) unsafe trait Simd: Copy {
    const LANES: usize;
    type V: Copy;
    fn splat(self, x: f32) -> Self::V;
    /// Loads `LANES` values from the start of `s`.
    fn load(self, s: &[f32]) -> Self::V;
    /// Stores `LANES` values to the start of `out`.
    fn store(self, v: Self::V, out: &mut [f32]);
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    fn div(self, a: Self::V, b: Self::V) -> Self::V;
    fn fma(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    fn min(self, a: Self::V, b: Self::V) -> Self::V;
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    fn sqrt(self, a: Self::V) -> Self::V;
    /// |a| (the sign bit cleared).
    fn abs(self, a: Self::V) -> Self::V;
    /// x where k ≥ 0, else 0 (k < 0 or NaN).
    fn where_nonneg(self, k: Self::V, x: Self::V) -> Self::V;
    /// 2ⁿ for integer-valued n in [−126, 127].
    fn pow2i(self, n: Self::V) -> Self::V;
    /// 1/x to about 2e-7 relative (a division where the hardware's is slow: an estimate and one
    /// Newton–Raphson step).
    #[inline(always)]
    fn recip(self, x: Self::V) -> Self::V {
        self.div(self.splat(1.0), x)
    }
    /// (e, m) with x = m·2ᵉ, m ∈ [1, 2), for positive normal x.
    fn split_exponent(self, x: Self::V) -> (Self::V, Self::V);

    /// eˣ, x clamped to [−87, 87]; relative error below 2e-7.
    #[inline(always)]
    fn exp(self, x: Self::V) -> Self::V {
        let x = self.min(self.max(x, self.splat(-87.0)), self.splat(87.0));
        // n = round(x / ln 2) by the 1.5·2²³ trick, then r = x − n·ln 2 in two parts.
        let magic = self.splat(12_582_912.0);
        let n = self.sub(
            self.fma(x, self.splat(std::f32::consts::LOG2_E), magic),
            magic,
        );
        let r = self.fma(n, self.splat(-0.693_145_75), x);
        let r = self.fma(n, self.splat(-1.428_606_8e-6), r);
        // e^r on [−ln2/2, ln2/2]: degree-6 Taylor in Horner form.
        let mut p = self.splat(0.001_388_889);
        for c in [0.008_333_334, 0.041_666_668, 0.166_666_67, 0.5, 1.0, 1.0] {
            p = self.fma(p, r, self.splat(c));
        }
        self.mul(p, self.pow2i(n))
    }

    /// σ(z) = 1 / (1 + e^−z).
    #[inline(always)]
    fn sigmoid(self, z: Self::V) -> Self::V {
        let one = self.splat(1.0);
        self.recip(self.add(one, self.exp(self.sub(self.splat(0.0), z))))
    }

    /// ln x for positive normal x, absolute error below 1e-5 (enough for a warm start).
    #[inline(always)]
    fn ln(self, x: Self::V) -> Self::V {
        let (e, m) = self.split_exponent(x);
        let one = self.splat(1.0);
        // ln m = 2·atanh(s), s = (m − 1)/(m + 1) ∈ [0, 1/3].
        let s = self.div(self.sub(m, one), self.add(m, one));
        let s2 = self.mul(s, s);
        let mut p = self.splat(1.0 / 9.0);
        for c in [1.0 / 7.0, 1.0 / 5.0, 1.0 / 3.0, 1.0] {
            p = self.fma(p, s2, self.splat(c));
        }
        let lnm = self.mul(self.mul(self.splat(2.0), s), p);
        self.fma(e, self.splat(std::f32::consts::LN_2), lnm)
    }
}

/// Plain arrays of 8 lanes: what every CPU runs.
#[derive(Clone, Copy)]
pub(crate) struct Portable;

// SAFETY: plain Rust, no CPU feature needed.
unsafe impl Simd for Portable {
    const LANES: usize = 8;
    type V = [f32; 8];
    #[inline(always)]
    fn splat(self, x: f32) -> [f32; 8] {
        [x; 8]
    }
    #[inline(always)]
    fn load(self, s: &[f32]) -> [f32; 8] {
        s[..8].try_into().unwrap()
    }
    #[inline(always)]
    fn store(self, v: [f32; 8], out: &mut [f32]) {
        out[..8].copy_from_slice(&v);
    }
    #[inline(always)]
    fn add(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] + b[i])
    }
    #[inline(always)]
    fn sub(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] - b[i])
    }
    #[inline(always)]
    fn mul(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] * b[i])
    }
    #[inline(always)]
    fn div(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] / b[i])
    }
    #[inline(always)]
    fn fma(self, a: [f32; 8], b: [f32; 8], c: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i] * b[i] + c[i])
    }
    #[inline(always)]
    fn min(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if a[i] < b[i] { a[i] } else { b[i] })
    }
    #[inline(always)]
    fn max(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if a[i] > b[i] { a[i] } else { b[i] })
    }
    #[inline(always)]
    fn sqrt(self, a: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i].sqrt())
    }
    #[inline(always)]
    fn abs(self, a: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| a[i].abs())
    }
    #[inline(always)]
    fn where_nonneg(self, k: [f32; 8], x: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if k[i] >= 0.0 { x[i] } else { 0.0 })
    }
    #[inline(always)]
    fn pow2i(self, n: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| f32::from_bits((((n[i] as i32) + 127) as u32) << 23))
    }
    #[inline(always)]
    fn split_exponent(self, x: [f32; 8]) -> ([f32; 8], [f32; 8]) {
        let e = std::array::from_fn(|i| ((x[i].to_bits() >> 23) as i32 - 127) as f32);
        let m =
            std::array::from_fn(|i| f32::from_bits((x[i].to_bits() & 0x007f_ffff) | 0x3f80_0000));
        (e, m)
    }
}

/// AVX2 + FMA, 8 lanes: the proof that this CPU has both ([`Avx2::detect`] makes the only
/// values). Its kernels run inside `#[target_feature(enable = "avx2,fma")]` functions.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(crate) struct Avx2(());

#[cfg(target_arch = "x86_64")]
impl Avx2 {
    /// The token, where this CPU has AVX2 and FMA.
    #[inline]
    pub(crate) fn detect() -> Option<Avx2> {
        (std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"))
            .then_some(Avx2(()))
    }
}

// SAFETY: values are made only by `Avx2::detect`, on a CPU with AVX2 and FMA, which is all the
// methods need.
#[cfg(target_arch = "x86_64")]
unsafe impl Simd for Avx2 {
    const LANES: usize = 8;
    type V = std::arch::x86_64::__m256;
    // SAFETY (every method): `self` exists, so the CPU has AVX2 and FMA; loads and stores check
    // their slice lengths first.
    #[inline(always)]
    fn splat(self, x: f32) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn load(self, s: &[f32]) -> Self::V {
        assert!(s.len() >= 8);
        unsafe { std::arch::x86_64::_mm256_loadu_ps(s.as_ptr()) }
    }
    #[inline(always)]
    fn store(self, v: Self::V, out: &mut [f32]) {
        assert!(out.len() >= 8);
        unsafe { std::arch::x86_64::_mm256_storeu_ps(out.as_mut_ptr(), v) }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_div_ps(a, b) }
    }
    #[inline(always)]
    fn fma(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn min(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_min_ps(a, b) }
    }
    #[inline(always)]
    fn max(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_max_ps(a, b) }
    }
    #[inline(always)]
    fn sqrt(self, a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(self, a: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm256_and_ps(a, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff))) }
    }
    #[inline(always)]
    fn recip(self, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        // rcp (relative error < 1.5·2⁻¹²) and one Newton–Raphson step: r·(2 − x·r).
        unsafe {
            let r = _mm256_rcp_ps(x);
            _mm256_mul_ps(r, _mm256_fnmadd_ps(x, r, _mm256_set1_ps(2.0)))
        }
    }
    #[inline(always)]
    fn where_nonneg(self, k: Self::V, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(k, _mm256_setzero_ps()), x) }
    }
    #[inline(always)]
    fn pow2i(self, n: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let i = _mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127));
            _mm256_castsi256_ps(_mm256_slli_epi32::<23>(i))
        }
    }
    #[inline(always)]
    fn split_exponent(self, x: Self::V) -> (Self::V, Self::V) {
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

/// AVX-512F, 16 lanes: the proof that this CPU has it ([`Avx512::detect`] makes the only
/// values). Its kernels run inside `#[target_feature(enable = "avx512f")]` functions.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(crate) struct Avx512(());

#[cfg(target_arch = "x86_64")]
impl Avx512 {
    /// The token, where this CPU has AVX-512F.
    #[inline]
    pub(crate) fn detect() -> Option<Avx512> {
        std::arch::is_x86_feature_detected!("avx512f").then_some(Avx512(()))
    }
}

// SAFETY: values are made only by `Avx512::detect`, on a CPU with AVX-512F, which is all the
// methods need.
#[cfg(target_arch = "x86_64")]
unsafe impl Simd for Avx512 {
    const LANES: usize = 16;
    type V = std::arch::x86_64::__m512;
    // SAFETY (every method): `self` exists, so the CPU has AVX-512F; loads and stores check
    // their slice lengths first.
    #[inline(always)]
    fn splat(self, x: f32) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_set1_ps(x) }
    }
    #[inline(always)]
    fn load(self, s: &[f32]) -> Self::V {
        assert!(s.len() >= 16);
        unsafe { std::arch::x86_64::_mm512_loadu_ps(s.as_ptr()) }
    }
    #[inline(always)]
    fn store(self, v: Self::V, out: &mut [f32]) {
        assert!(out.len() >= 16);
        unsafe { std::arch::x86_64::_mm512_storeu_ps(out.as_mut_ptr(), v) }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_div_ps(a, b) }
    }
    #[inline(always)]
    fn fma(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn min(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_min_ps(a, b) }
    }
    #[inline(always)]
    fn max(self, a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_max_ps(a, b) }
    }
    #[inline(always)]
    fn sqrt(self, a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(self, a: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_abs_ps(a) }
    }
    #[inline(always)]
    fn recip(self, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        // rcp14 (relative error < 2⁻¹⁴) and one Newton–Raphson step: r·(2 − x·r).
        unsafe {
            let r = _mm512_rcp14_ps(x);
            _mm512_mul_ps(r, _mm512_fnmadd_ps(x, r, _mm512_set1_ps(2.0)))
        }
    }
    #[inline(always)]
    fn where_nonneg(self, k: Self::V, x: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe { _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GE_OQ>(k, _mm512_setzero_ps()), x) }
    }
    #[inline(always)]
    fn pow2i(self, n: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let i = _mm512_add_epi32(_mm512_cvtps_epi32(n), _mm512_set1_epi32(127));
            _mm512_castsi512_ps(_mm512_slli_epi32::<23>(i))
        }
    }
    #[inline(always)]
    fn split_exponent(self, x: Self::V) -> (Self::V, Self::V) {
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
    fn check<S: Simd>(cpu: S, name: &str) {
        let n = S::LANES;
        let mut worst_exp = 0f64;
        let mut worst_ln = 0f64;
        let mut x = -87.0f32;
        let mut buf = vec![0f32; n];
        while x < 87.0 {
            let xs: Vec<f32> = (0..n).map(|i| x + i as f32 * 0.001).collect();
            cpu.store(cpu.exp(cpu.load(&xs)), &mut buf);
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
            cpu.store(cpu.ln(cpu.load(&ps)), &mut buf);
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
            cpu.store(cpu.sigmoid(cpu.load(&zs)), &mut buf);
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
        cpu.store(cpu.sigmoid(cpu.splat(-200.0)), &mut buf);
        assert!(buf[0] >= 0.0 && buf[0] < 1e-30);
        cpu.store(cpu.sigmoid(cpu.splat(200.0)), &mut buf);
        assert!((buf[0] - 1.0).abs() <= 1e-7, "{name}: σ(200) = {}", buf[0]);
    }

    #[test]
    fn elementary_functions_are_accurate_in_every_build() {
        check(Portable, "portable");
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma")]
            fn avx2(cpu: Avx2) {
                check(cpu, "avx2");
            }
            #[target_feature(enable = "avx512f")]
            fn avx512(cpu: Avx512) {
                check(cpu, "avx512f");
            }
            match Avx2::detect() {
                // SAFETY: the token proves the CPU has the features `avx2` is compiled for.
                Some(cpu) => unsafe { avx2(cpu) },
                None => eprintln!("skipped: avx2 (this CPU lacks it)"),
            }
            match Avx512::detect() {
                // SAFETY: the token proves the CPU has the feature `avx512` is compiled for.
                Some(cpu) => unsafe { avx512(cpu) },
                None => eprintln!("skipped: avx512f (this CPU lacks it)"),
            }
        }
    }
}
