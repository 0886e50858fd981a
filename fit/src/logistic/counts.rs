//! The logistic link's streaming data: per texel its covered footprint samples and per light
//! its occluded ones, exact (u8 while the bake's samples per texel are at most 255, else u16):
//! texels × lights bytes where a stored f32 stack would take four times that. K from a
//! streaming bake is a fraction of whole samples, so the counts lose nothing.
use super::pool::Source;
use crate::{Error, Result};

/// Exact sample counts of a streaming logistic fit ([`crate::Accumulator`] holds one).
#[derive(Default)]
pub(crate) struct Counts {
    /// Footprint samples per texel (the bake's spp), once set.
    spp: Option<u32>,
    /// Covered samples per texel (coverage × spp), from the first light added.
    cov: Vec<u32>,
    /// Occluded samples `[light][texel]`, in u8 while spp ≤ 255 …
    occ8: Vec<Vec<u8>>,
    /// … else in u16.
    occ16: Vec<Vec<u16>>,
}

/// Occluded counts of one K plane, K × covered rounded, without branches or a call to `round`
/// (which on the x86-64 baseline is a libm call per texel): 0 for masked or uncovered texels.
/// False when some other texel's K is no fraction of its covered samples (the product lies
/// more than 0.01 from an integer in 0..=covered, or K is not finite); the plane is then not
/// to be kept. Adding 2⁵² + 2⁵¹ and taking it away again rounds to the nearest integer (ties
/// to even, where `round` takes them away from zero: both agree within 0.01 of an integer, the
/// only products kept). The counts were 0.6 s of a 4.5 s `ptm bake --fit` of jersey at 512² ×
/// 256 lights; in straight lines they vectorize.
fn exact_counts<T>(
    plane: &mut [T],
    k: &[f32],
    masked: &[bool],
    cov: &[u32],
    to: impl Fn(f64) -> T,
) -> bool {
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let mut bad = false;
    for (((x, &k), &masked), &cov) in plane.iter_mut().zip(k).zip(masked).zip(cov) {
        let c = cov as f64;
        let v = k as f64 * c;
        let n = (v + ROUND) - ROUND;
        // Not finite: NaN fails every comparison.
        let exact = (v - n).abs() <= 1e-2 && n >= 0.0 && n <= c;
        let skip = masked || cov == 0;
        *x = to(if skip || !exact { 0.0 } else { n });
        bad |= !skip && !exact;
    }
    !bad
}

impl Counts {
    /// Sets the footprint samples per texel of the bake (1 ..= 65535).
    pub fn set_spp(&mut self, spp: u32) -> Result<()> {
        if spp == 0 || spp > u16::MAX as u32 {
            return Err(Error::Invalid(format!(
                "samples per texel {spp} must lie in 1..=65535"
            )));
        }
        self.spp = Some(spp);
        Ok(())
    }

    /// Stores light `index`'s K plane (`width` texels a row) as exact occluded counts of each
    /// texel's covered samples (`coverage` × spp; empty: every texel covered, one of `lights`).
    pub fn add(
        &mut self,
        index: usize,
        k: &[f32],
        masked: &[bool],
        coverage: &[f32],
        lights: usize,
        width: usize,
    ) -> Result<()> {
        let spp = self.spp.ok_or_else(|| {
            Error::Invalid(
                "the logistic link's streaming fit needs the samples per texel (Accumulator::set_spp) to hold exact counts"
                    .into(),
            )
        })?;
        let t = masked.len();
        if self.cov.is_empty() {
            self.cov = (0..t)
                .map(|ti| {
                    let c = coverage.get(ti).copied().unwrap_or(1.0);
                    (c as f64 * spp as f64).round() as u32
                })
                .collect();
            if spp <= u8::MAX as u32 {
                self.occ8 = vec![Vec::new(); lights];
            } else {
                self.occ16 = vec![Vec::new(); lights];
            }
        }
        let cov = &self.cov;
        let count = |ti: usize| -> Result<u16> {
            if masked[ti] || cov[ti] == 0 {
                return Ok(0);
            }
            let x = k[ti] as f64 * cov[ti] as f64;
            let n = x.round();
            if !k[ti].is_finite() || (x - n).abs() > 1e-2 || !(0.0..=cov[ti] as f64).contains(&n) {
                return Err(Error::Invalid(format!(
                    "light {index}: K = {} at texel (column {}, row {}) is not a fraction of its {} covered samples (spp {spp}): the logistic streaming fit needs the bake's exact sample counts",
                    k[ti],
                    ti % width,
                    ti / width,
                    cov[ti]
                )));
            }
            Ok(n as u16)
        };
        if k.len() != t {
            return Err(Error::Invalid(format!(
                "light {index}: {} K values for {t} texels",
                k.len()
            )));
        }
        // Filled in place: the plane is allocated at exactly its size (`memory_bytes`). The
        // counts in straight lines first (`exact_counts`); only where some texel's K is no
        // fraction of its samples, the loop above names the first such texel.
        if spp <= u8::MAX as u32 {
            let mut plane = vec![0u8; t];
            if !exact_counts(&mut plane, k, masked, cov, |n| n as u8) {
                for (ti, x) in plane.iter_mut().enumerate() {
                    *x = count(ti)? as u8;
                }
            }
            self.occ8[index] = plane;
        } else {
            let mut plane = vec![0u16; t];
            if !exact_counts(&mut plane, k, masked, cov, |n| n as u16) {
                for (ti, x) in plane.iter_mut().enumerate() {
                    *x = count(ti)?;
                }
            }
            self.occ16[index] = plane;
        }
        Ok(())
    }

    /// The counts as the kernel reads them.
    pub fn source(&self) -> Source<'_> {
        if self.occ16.is_empty() {
            Source::Counts8 {
                occ: &self.occ8,
                cov: &self.cov,
            }
        } else {
            Source::Counts16 {
                occ: &self.occ16,
                cov: &self.cov,
            }
        }
    }

    /// Bytes the per-texel buffers hold now (allocated capacities).
    pub fn held_bytes(&self) -> u128 {
        fn cap<T>(v: &Vec<T>) -> u128 {
            (v.capacity() * std::mem::size_of::<T>()) as u128
        }
        cap(&self.cov)
            + self.occ8.iter().map(cap).sum::<u128>()
            + self.occ16.iter().map(cap).sum::<u128>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The straight-line counts against the definition (`round(K × covered)`, checked) on K
    /// planes of every covered count 0..=255 and 256..=600 samples: fractions of the covered
    /// samples (kept, equal), and one texel with K off by more than 0.01 samples, NaN, ±∞ or
    /// beyond [0, 1] (refused, naming it), masked texels 0.
    #[test]
    fn exact_counts_match_the_definition_and_refuse_what_it_refuses() {
        for spp in [4u32, 255, 600] {
            let t = 2000;
            let cov: Vec<u32> = (0..t).map(|i| (i as u32 * 7919) % (spp + 1)).collect();
            let occ: Vec<u32> = (0..t)
                .map(|i| (i as u32 * 104_729) % (cov[i] + 1))
                .collect();
            let k: Vec<f32> = (0..t)
                .map(|i| {
                    if cov[i] == 0 {
                        0.0
                    } else {
                        occ[i] as f32 / cov[i] as f32
                    }
                })
                .collect();
            let masked: Vec<bool> = (0..t).map(|i| i % 13 == 5).collect();
            let mut counts = Counts::default();
            counts.set_spp(spp).unwrap();
            let coverage: Vec<f32> = cov.iter().map(|&c| c as f32 / spp as f32).collect();
            counts.add(0, &k, &masked, &coverage, 2, 40).unwrap();
            let got: Vec<u32> = match counts.source() {
                Source::Counts8 { occ, .. } => occ[0].iter().map(|&x| x as u32).collect(),
                Source::Counts16 { occ, .. } => occ[0].iter().map(|&x| x as u32).collect(),
                _ => unreachable!("counts hold u8 or u16"),
            };
            for i in 0..t {
                let want = if masked[i] || cov[i] == 0 { 0 } else { occ[i] };
                assert_eq!(got[i], want, "spp {spp}, texel {i}");
            }
            let texel = (0..t).find(|&i| !masked[i] && cov[i] > 2).unwrap();
            let c = cov[texel] as f32;
            for bad in [
                (occ[texel] as f32 + 0.3) / c,
                f32::NAN,
                f32::INFINITY,
                -1.0 / c,
                2.0,
            ] {
                let mut k = k.clone();
                k[texel] = bad;
                let e = counts.add(1, &k, &masked, &coverage, 2, 40).unwrap_err();
                let (col, row) = (texel % 40, texel / 40);
                assert!(
                    e.to_string()
                        .contains(&format!("(column {col}, row {row}) is not a fraction")),
                    "{e}"
                );
            }
        }
    }
}
