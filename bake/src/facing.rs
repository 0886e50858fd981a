//! A distant light's shadow rays of one texel block, compacted for packets: of a run of a
//! block's samples, the origins of those whose normal faces the light (the others are occluded
//! without a ray), one after another, so that every packet but a block's last is full, and the
//! run's facing samples as a bit mask (which texel a ray came from follows from the mask: no
//! per-ray texel lane is carried).
//!
//! Three builds of the one kernel, chosen at run time ([`Isa::detect`]): AVX-512F, which tests
//! 16 samples at a time and compresses the facing ones into place (`vcompressps`); AVX2, which
//! tests 8 at a time and moves the facing ones to the front with a permutation looked up by the
//! 8-bit mask; and portable Rust, which tests in straight lines (vectorized by the compiler) and
//! compacts without branches. The facing test is the same sum in the same order in all three,
//! `l·n > 0` as `(lx·nx + ly·ny) + lz·nz` without contraction, so they pick the same samples in
//! the same order (tested against each other and against the definition).

/// Room for the rays waiting for a packet: fewer than a packet (16) carried over, plus one call's
/// [`MAX_RUN`] samples, plus the 16-lane store past the end of the AVX-512 build.
const CAP: usize = 128;

/// The most samples one [`Compact::push_facing`] call takes.
pub(crate) const MAX_RUN: usize = 64;

/// Which build of the kernel runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// Plain Rust, on any CPU.
    Portable,
    /// AVX2 (and popcnt, which every CPU with AVX2 has), 8 lanes.
    Avx2,
    /// AVX-512F (and popcnt), 16 lanes.
    Avx512,
}

impl Isa {
    /// The widest build this CPU runs.
    pub(crate) fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if Isa::Avx512.supported() {
                return Isa::Avx512;
            }
            if Isa::Avx2.supported() {
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    /// Whether this CPU runs `self`.
    pub(crate) fn supported(self) -> bool {
        match self {
            Isa::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("popcnt")
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("popcnt")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// Every build this CPU runs, narrowest first (for tests that check each against the
    /// others).
    #[cfg(test)]
    pub(crate) fn every_supported() -> Vec<Isa> {
        let isas = [Isa::Portable, Isa::Avx2, Isa::Avx512].into_iter();
        let isas: Vec<Isa> = isas.filter(|isa| isa.supported()).collect();
        eprintln!("builds checked on this CPU: {isas:?}");
        isas
    }

    /// The build's name, as `Baker::simd` reports it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512f",
        }
    }
}

/// The rays waiting for a packet: their origins.
pub(crate) struct Compact {
    pub(crate) org: [[f32; CAP]; 3],
    pub(crate) len: usize,
}

impl Default for Compact {
    fn default() -> Self {
        Self {
            org: [[0.0; CAP]; 3],
            len: 0,
        }
    }
}

impl Compact {
    /// Appends the samples of `org`, `n` (per component) whose normal faces the light `l`
    /// (l·n > 0), in their order, with `isa`'s build; returns which did, bit `i` for sample
    /// `i`. At most [`MAX_RUN`] samples, onto fewer than 32 waiting.
    pub(crate) fn push_facing(
        &mut self,
        org: [&[f32]; 3],
        n: [&[f32]; 3],
        l: [f32; 3],
        isa: Isa,
    ) -> u64 {
        let m = org[0].len();
        assert!(
            m <= MAX_RUN && self.len < 32,
            "a run of {m} onto {}",
            self.len
        );
        assert!(org.iter().chain(&n).all(|c| c.len() == m));
        match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 if Isa::Avx512.supported() => {
                // SAFETY: the CPU has AVX-512F and popcnt (checked just above).
                unsafe { push_avx512(self, org, n, l) }
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 if Isa::Avx2.supported() => {
                // SAFETY: the CPU has AVX2 and popcnt (checked just above).
                unsafe { push_avx2(self, org, n, l) }
            }
            _ => push_portable(self, org, n, l),
        }
    }

    /// Drops the first `at` rays, of which fewer than 16 remain after them. (16 are moved
    /// whatever remains, in straight lines: a copy of the remainder's length was a `memmove`
    /// call.)
    pub(crate) fn shift(&mut self, at: usize) {
        assert!(self.len - at < 16 && at + 16 <= CAP, "{at} of {}", self.len);
        for a in 0..3 {
            self.org[a].copy_within(at..at + 16, 0);
        }
        self.len -= at;
    }
}

/// The facing test in straight lines, then the compaction without branches: each sample is
/// written at the end, and the end moves past it only if it faces the light.
fn push_portable(c: &mut Compact, org: [&[f32]; 3], n: [&[f32]; 3], l: [f32; 3]) -> u64 {
    let mut up = [0u8; MAX_RUN];
    let normals = n[0].iter().zip(n[1]).zip(n[2]);
    for (((&x, &y), &z), up) in normals.zip(&mut up) {
        *up = (l[0] * x + l[1] * y + l[2] * z > 0.0) as u8;
    }
    let mut mask = 0u64;
    let origins = org[0].iter().zip(org[1]).zip(org[2]);
    for (i, (((&px, &py), &pz), &up)) in origins.zip(&up).enumerate() {
        let k = c.len & (CAP - 1);
        c.org[0][k] = px;
        c.org[1][k] = py;
        c.org[2][k] = pz;
        c.len += up as usize;
        mask |= (up as u64) << i;
    }
    mask
}

/// 16 samples at a time: the test as a lane mask, the facing lanes compressed to the front of
/// each register and stored at the end (16 lanes wide: the rest is overwritten later).
///
/// # Safety
/// The CPU must have AVX-512F and popcnt.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,popcnt")]
unsafe fn push_avx512(c: &mut Compact, org: [&[f32]; 3], n: [&[f32]; 3], l: [f32; 3]) -> u64 {
    use std::arch::x86_64::*;
    let m = org[0].len();
    let mut mask = 0u64;
    let (lx, ly, lz) = (
        _mm512_set1_ps(l[0]),
        _mm512_set1_ps(l[1]),
        _mm512_set1_ps(l[2]),
    );
    for s in (0..m).step_by(16) {
        let k = (m - s).min(16);
        let tail: __mmask16 = if k == 16 { !0 } else { (1 << k) - 1 };
        // SAFETY: masked loads read only the `k` elements from `s` of slices of length `m`;
        // stores write 16 lanes from `len` < 32 + MAX_RUN, within CAP.
        unsafe {
            let load = |v: &[f32]| _mm512_maskz_loadu_ps(tail, v.as_ptr().add(s));
            let d = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(lx, load(n[0])), _mm512_mul_ps(ly, load(n[1]))),
                _mm512_mul_ps(lz, load(n[2])),
            );
            let up = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(tail, d, _mm512_setzero_ps());
            let at = c.len;
            for (dst, src) in c.org.iter_mut().zip(org) {
                let v = _mm512_maskz_compress_ps(up, load(src));
                _mm512_storeu_ps(dst.as_mut_ptr().add(at), v);
            }
            c.len = at + up.count_ones() as usize;
            mask |= (up as u64) << s;
        }
    }
    mask
}

/// For each 8-bit mask, the lanes whose bit is set, in order, then the others: the
/// `vpermps` indices that move the set lanes to the front.
#[cfg(target_arch = "x86_64")]
static FRONT: [[u32; 8]; 256] = {
    let mut t = [[0u32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let mut k = 0;
        let mut i = 0;
        while i < 8 {
            if m & (1 << i) != 0 {
                t[m][k] = i as u32;
                k += 1;
            }
            i += 1;
        }
        let mut i = 0;
        while i < 8 {
            if m & (1 << i) == 0 {
                t[m][k] = i as u32;
                k += 1;
            }
            i += 1;
        }
        m += 1;
    }
    t
};

/// 8 samples at a time: the test as a lane mask (`vmovmskps`), the facing lanes moved to the
/// front of each register by the permutation [`FRONT`] holds for the mask and stored at the
/// end (8 lanes wide: the rest is overwritten later).
///
/// # Safety
/// The CPU must have AVX2 and popcnt.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn push_avx2(c: &mut Compact, org: [&[f32]; 3], n: [&[f32]; 3], l: [f32; 3]) -> u64 {
    use std::arch::x86_64::*;
    let m = org[0].len();
    let mut mask = 0u64;
    let (lx, ly, lz) = (
        _mm256_set1_ps(l[0]),
        _mm256_set1_ps(l[1]),
        _mm256_set1_ps(l[2]),
    );
    for s in (0..m).step_by(8) {
        let k = (m - s).min(8);
        // A short tail loads under a mask: its missing lanes read as 0 (n = 0 does not face
        // the light). (Copying the tail into an array and loading that stalls on store
        // forwarding: the AVX2 build then ran slower than the portable one.)
        let tail = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(k as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        let load = |v: &[f32]| {
            // SAFETY: a full load reads the 8 floats from `s` (k = 8, so s + 8 <= m); a masked
            // one only the first k.
            unsafe {
                if k == 8 {
                    _mm256_loadu_ps(v.as_ptr().add(s))
                } else {
                    _mm256_maskload_ps(v.as_ptr().add(s), tail)
                }
            }
        };
        let d = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(lx, load(n[0])), _mm256_mul_ps(ly, load(n[1]))),
            _mm256_mul_ps(lz, load(n[2])),
        );
        let up = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(d, _mm256_setzero_ps())) as usize;
        let up = up & ((1 << k) - 1);
        let at = c.len;
        // SAFETY: `FRONT[up]` holds 8 indices; stores write 8 lanes from `len` < 32 + MAX_RUN,
        // within CAP.
        unsafe {
            let idx = _mm256_loadu_si256(FRONT[up].as_ptr().cast());
            for (dst, src) in c.org.iter_mut().zip(org) {
                let v = _mm256_permutevar8x32_ps(load(src), idx);
                _mm256_storeu_ps(dst.as_mut_ptr().add(at), v);
            }
        }
        c.len = at + up.count_ones() as usize;
        mask |= (up as u64) << s;
    }
    mask
}

/// A xorshift64 generator from `seed` (non-zero), for tests' random inputs.
#[cfg(test)]
pub(crate) fn xorshift(seed: u64) -> impl FnMut() -> u64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random runs (lengths 0 to 64, onto 0 to 31 waiting rays) with normals that face the
    /// light, face away, lie in its plane (n·l = 0 exactly), or are ±0 and NaN: every build
    /// keeps exactly the samples whose l·n > 0, in order, with their origins, and says which
    /// in its mask.
    #[test]
    fn builds_keep_the_facing_samples_in_order() {
        let mut rand = xorshift(0x2545_f491_4f6c_dd1d);
        let isas = Isa::every_supported();
        for round in 0..2000 {
            let m = (rand() % (MAX_RUN as u64 + 1)) as usize;
            let waiting = (rand() % 32) as usize;
            let l = [0.3f32, -0.4, (1.0f32 - 0.25).sqrt()];
            let special = [0.0f32, -0.0, f32::NAN, 1e-40, -1e-40];
            let mut n: [Vec<f32>; 3] = Default::default();
            let mut org: [Vec<f32>; 3] = Default::default();
            for i in 0..m {
                let r = rand();
                let v = match r % 5 {
                    0 => [special[(r >> 8) as usize % 5]; 3],
                    // In the light's plane: l·n is 0 exactly for this n.
                    1 => [0.4, 0.3, 0.0],
                    _ => [0, 1, 2].map(|a| ((rand() >> (11 + a)) % 2001) as f32 / 1000.0 - 1.0),
                };
                for a in 0..3 {
                    n[a].push(v[a]);
                    org[a].push(round as f32 + i as f32 * 0.25 + a as f32 * 1e-3);
                }
            }
            let expected: Vec<usize> = (0..m)
                .filter(|&i| l[0] * n[0][i] + l[1] * n[1][i] + l[2] * n[2][i] > 0.0)
                .collect();
            for &isa in &isas {
                let mut c = Compact {
                    len: waiting,
                    ..Compact::default()
                };
                c.org[0][..waiting].fill(-7.0);
                let got = c.push_facing([&org[0], &org[1], &org[2]], [&n[0], &n[1], &n[2]], l, isa);
                let want = expected.iter().fold(0u64, |m, &i| m | 1 << i);
                assert_eq!(got, want, "{isa:?}, round {round}");
                assert_eq!(c.len, waiting + expected.len(), "{isa:?}, round {round}");
                assert!(c.org[0][..waiting].iter().all(|&x| x == -7.0));
                for (j, &i) in expected.iter().enumerate() {
                    for (got, want) in c.org.iter().zip(&org) {
                        assert_eq!(got[waiting + j].to_bits(), want[i].to_bits());
                    }
                }
            }
        }
    }

    #[test]
    fn shift_keeps_the_rest_in_order() {
        let mut c = Compact::default();
        for i in 0..20 {
            c.org[0][i] = i as f32;
        }
        c.len = 20;
        c.shift(16);
        assert_eq!(c.len, 4);
        assert_eq!(&c.org[0][..4], &[16.0, 17.0, 18.0, 19.0]);
    }
}
