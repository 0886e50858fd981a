//! The MIP chain of a fitted PTM: each level's size and pooling factors from the level above
//! ([`Footprint::chain`], sides halved and rounded down as OpenEXR's round-down levels), and the
//! identity link's levels ([`identity_mips`]). The logistic link fits each level instead
//! (`logistic/pool.rs` pools the samples), and a farm part's share of the chain follows from
//! its rows (`shard/partition.rs`).
use ptm_format::{Level, Ptm};

/// The sizes of level 0 and of every MIP level down to 1×1 (halved, rounded down; a side that is
/// already 1 stays 1), with the pooling factors (fx, fy) ∈ {1, 2} from the level above.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Footprint {
    pub width: usize,
    pub height: usize,
    pub fx: usize,
    pub fy: usize,
}

impl Footprint {
    pub fn chain(width: usize, height: usize) -> Vec<Footprint> {
        let mut out = vec![Footprint {
            width,
            height,
            fx: 1,
            fy: 1,
        }];
        let mut f = out[0];
        while f.width > 1 || f.height > 1 {
            let (fx, fy) = (
                if f.width > 1 { 2 } else { 1 },
                if f.height > 1 { 2 } else { 1 },
            );
            f = Footprint {
                width: f.width / fx,
                height: f.height / fy,
                fx,
                fy,
            };
            out.push(f);
        }
        out
    }
}

/// MIP levels of an identity-link PTM: the least-squares fit of box-filtered K equals the
/// coverage-weighted box average of the coefficients (K is linear in them and every texel
/// shares the design), so no refit is needed.
pub(crate) fn identity_mips(ptm: &Ptm, coverage: &[f32]) -> Vec<Level> {
    let m = ptm.basis.len();
    let chain = Footprint::chain(ptm.width, ptm.height);
    let mut planes: Vec<Vec<f32>> = ptm.planes.clone();
    let mut weight: Vec<f64> = (0..ptm.width * ptm.height)
        .map(|t| coverage.get(t).copied().unwrap_or(1.0).max(0.0) as f64)
        .collect();
    let mut above_w = ptm.width;
    let mut out = Vec::new();
    for fp in &chain[1..] {
        let n = fp.width * fp.height;
        let mut next = vec![vec![0f32; n]; m];
        let mut next_w = vec![0f64; n];
        for t in 0..n {
            let (x, y) = (t % fp.width, t / fp.width);
            let mut num = [0f64; 16];
            let mut den = 0f64;
            for dy in 0..fp.fy {
                for dx in 0..fp.fx {
                    let c = (y * fp.fy + dy) * above_w + x * fp.fx + dx;
                    den += weight[c];
                    for j in 0..m {
                        num[j] += weight[c] * planes[j][c] as f64;
                    }
                }
            }
            next_w[t] = den;
            if den > 0.0 {
                for j in 0..m {
                    next[j][t] = (num[j] / den) as f32;
                }
            }
        }
        out.push(Level {
            width: fp.width,
            height: fp.height,
            planes: next.clone(),
        });
        planes = next;
        weight = next_w;
        above_w = fp.width;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chain_matches_round_down_sizes() {
        // Against the exr crate's own MIP level sizes (what its reader and writer expect).
        for (w, h) in [(13, 7), (64, 64), (4, 16), (1, 5)] {
            let chain = Footprint::chain(w, h);
            let sizes: Vec<(usize, usize)> = chain.iter().map(|f| (f.width, f.height)).collect();
            let want: Vec<(usize, usize)> =
                exr::meta::mip_map_levels(exr::math::RoundingMode::Down, exr::math::Vec2(w, h))
                    .map(|(_, s)| (s.0, s.1))
                    .collect();
            assert_eq!(sizes, want, "{w}×{h}");
        }
    }
}
