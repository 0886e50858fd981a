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
        // Filled in place: the plane is allocated at exactly its size (`memory_bytes`).
        if spp <= u8::MAX as u32 {
            let mut plane = vec![0u8; t];
            for (ti, x) in plane.iter_mut().enumerate() {
                *x = count(ti)? as u8;
            }
            self.occ8[index] = plane;
        } else {
            let mut plane = vec![0u16; t];
            for (ti, x) in plane.iter_mut().enumerate() {
                *x = count(ti)?;
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
