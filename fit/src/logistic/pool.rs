//! Where the K of a logistic fit comes from ([`Source`]: a stored stack's planes, a pooled
//! stack level, exact sample counts), and the pooling of MIP levels: each level's data is the
//! box filter of the level above ([`pool`]), exact for counts.
use rayon::prelude::*;

use crate::mip::Footprint;

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

impl Source<'_> {
    /// K of light `l` for the `out.len()` texels from index `start`, or −1 where the texel has
    /// no covered sample (or, for a stack, a non-finite one).
    pub(crate) fn fill(&self, l: usize, start: usize, out: &mut [f32]) {
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
    pub(super) fn prefetch(&self, l: usize, start: usize, len: usize) {
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
