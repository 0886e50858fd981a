//! The partition of a bake into shards: blocks of whole image rows, starting at multiples of
//! [`ROW_BLOCK`], split as evenly as whole blocks allow; and what that means for the MIP chain
//! of a logistic fit (`local_levels`, [`PartLevels`]): the levels a shard fits itself, and the
//! pooled counts it hands the merge for the rest. The solver (a part's fit) and the part file
//! and merge code (`shard.rs`, `shard/merge.rs`) all take the partition from here.
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::mip::Footprint;
use crate::solve::options::Weight;
use crate::{Error, Result};

/// Shards start at multiples of this many rows: the 16 scanlines of an OpenEXR ZIP chunk (so
/// a stack merges by copying compressed chunks), a multiple of the tracer's 4×4 texel blocks.
pub const ROW_BLOCK: usize = 16;

/// Shard `index` of `count` (0-based), as `--shard I/N` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, 0-based, below `count`.
    pub index: usize,
    /// How many shards the bake is split into.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// Parses `I/N` with 0 ≤ I < N.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = |why: &str| format!("{s:?}: {why} (expected I/N with 0 <= I < N, e.g. 0/4)");
        let (i, n) = s.split_once('/').ok_or_else(|| bad("no `/`"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| bad(&format!("shard index {i:?} is not a whole number >= 0")))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| bad(&format!("shard count {n:?} is not a whole number >= 1")))?;
        if count == 0 {
            return Err(bad("the shard count must be at least 1"));
        }
        if index >= count {
            return Err(bad(&format!(
                "shard index {index} is out of range: shards of {count} are numbered 0 to {}",
                count - 1
            )));
        }
        Ok(Shard { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// Image rows of this shard in a bake of `height` rows: blocks of [`ROW_BLOCK`] rows split
    /// as evenly as whole blocks allow (shard i gets blocks ⌊i·B/N⌋ … ⌊(i+1)·B/N⌋). An error
    /// when there are fewer blocks than shards (a shard would be empty).
    pub fn rows(&self, height: usize) -> Result<Range<usize>> {
        let blocks = height.div_ceil(ROW_BLOCK);
        if self.count > blocks {
            return Err(Error::TooManyShards {
                shard: *self,
                rows: height,
                blocks,
            });
        }
        let at = |i: usize| (i * blocks / self.count * ROW_BLOCK).min(height);
        Ok(at(self.index)..at(self.index + 1))
    }

    /// The part file of this shard for final output `out`: `samples.exr` →
    /// `samples.part-0002-of-0004.exr`, `weave.ptm.exr` → `weave.ptm.part-0002-of-0004.exr`.
    pub fn part_path(&self, out: &Path) -> PathBuf {
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem = name.strip_suffix(".exr").unwrap_or(&name);
        out.with_file_name(format!(
            "{stem}.part-{:04}-of-{:04}.exr",
            self.index, self.count
        ))
    }
}

/// A logistic part's share of the MIP chain. A coarse texel is fitted to the pooled counts of
/// its footprint; the levels whose footprints span at most [`ROW_BLOCK`] rows lie inside one
/// shard, so the part fits them for its rows exactly as a whole bake does. The deeper levels'
/// footprints cross shard borders: the part carries the pooled counts of its last level
/// (1/256 of level 0's texels, exact), and the merge joins them and fits the rest.
#[derive(Clone, Debug, PartialEq)]
pub struct PartLevels {
    /// Levels 1 … S for the part's rows (sizes from `local_levels`).
    pub levels: Vec<ptm_format::Level>,
    /// Pooled counts of level S for the part's rows, when the chain goes deeper:
    /// (covered samples per texel, occluded samples `[light][texel]`).
    pub counts: Option<(Vec<u32>, Vec<Vec<u32>>)>,
    /// The fit's light weighting (the merge rebuilds the fit's tables with it).
    pub weight: Weight,
}

impl Default for PartLevels {
    fn default() -> Self {
        PartLevels {
            levels: Vec::new(),
            counts: None,
            weight: Weight::Uniform,
        }
    }
}

/// The MIP levels below level 0 whose every texel pools rows of one [`ROW_BLOCK`] only, for
/// rows `rows` (a shard's: starting at a multiple of [`ROW_BLOCK`]) of an image
/// `width × height`: per level, its footprint restricted to those rows (the whole level's
/// width, the rows of the level that pool them, the pooling factors); and whether the chain
/// goes deeper (levels whose footprints cross shard borders, left to the merge).
pub(crate) fn local_levels(
    width: usize,
    height: usize,
    rows: Range<usize>,
) -> (Vec<Footprint>, bool) {
    let chain = Footprint::chain(width, height);
    let mut span = 1;
    let mut out = Vec::new();
    for fp in &chain[1..] {
        span *= fp.fy;
        if !ROW_BLOCK.is_multiple_of(span) {
            return (out, true);
        }
        // rows.start is a multiple of the span: level rows [start/span, end/span).
        let local = (rows.end / span)
            .min(fp.height)
            .saturating_sub(rows.start / span);
        out.push(Footprint {
            height: local,
            ..*fp
        });
    }
    (out, false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_refuse() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { index: 2, count: 4 }));
        for bad in ["0/0", "5/4", "4/4", "-1/3", "x/3", "1", "1/y", ""] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains("expected I/N"), "{bad}: {e}");
        }
    }

    #[test]
    fn partition_covers_every_row_once_block_aligned() {
        for h in [4usize, 5, 63, 64, 1000, 1024] {
            for n in 1..=h.div_ceil(ROW_BLOCK).min(9) {
                let mut next = 0;
                for i in 0..n {
                    let r = Shard { index: i, count: n }.rows(h).unwrap();
                    assert_eq!(r.start, next);
                    assert_eq!(r.start % ROW_BLOCK, 0);
                    assert!(!r.is_empty());
                    next = r.end;
                }
                assert_eq!(next, h);
            }
        }
        assert!(Shard { index: 0, count: 3 }.rows(8).is_err());
    }

    #[test]
    fn part_names() {
        let s = Shard { index: 2, count: 4 };
        assert_eq!(
            s.part_path(Path::new("d/w.ptm.exr")),
            Path::new("d/w.ptm.part-0002-of-0004.exr")
        );
        assert_eq!(
            s.part_path(Path::new("samples.exr")),
            Path::new("samples.part-0002-of-0004.exr")
        );
    }
}
