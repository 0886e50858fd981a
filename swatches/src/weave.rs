//! Woven cloth: interlacement patterns (plain, twill, satin, basket, drafts) and the crimped
//! warp and weft tubes that weave them.

use crate::params::Params;
use crate::yarn::{Cloth, Ends, Yarn};
use crate::{Error, Result};

/// An interlacement pattern over one repeat: which of warp `i` (running along +y, at
/// x = (i + ½)·spacing) and weft `j` (along +x, at y = (j + ½)·spacing) is on top where they cross.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pattern {
    /// Warps (threads along +y) in the repeat.
    pub warps: usize,
    /// Wefts (threads along +x) in the repeat.
    pub wefts: usize,
    /// Row-major by weft: `over[j * warps + i]` is true when warp i passes over weft j.
    pub over: Vec<bool>,
}

impl Pattern {
    /// The pattern with `f(i, j)` true where warp i passes over weft j.
    pub fn from_fn(warps: usize, wefts: usize, f: impl Fn(usize, usize) -> bool) -> Pattern {
        let mut over = Vec::with_capacity(warps * wefts);
        for j in 0..wefts {
            for i in 0..warps {
                over.push(f(i, j));
            }
        }
        Pattern { warps, wefts, over }
    }

    /// True when warp `i` passes over weft `j` (indices wrap around the repeat).
    pub fn warp_over(&self, i: usize, j: usize) -> bool {
        self.over[(j % self.wefts) * self.warps + i % self.warps]
    }

    /// Plain weave: over one, under one.
    pub fn plain() -> Pattern {
        Pattern::from_fn(2, 2, |i, j| (i + j).is_multiple_of(2))
    }

    /// `n/m` twill: each warp over `n` wefts then under `m`, the float moving one weft per warp;
    /// `z` twill lines rise to the right, `s` to the left.
    pub fn twill(n: usize, m: usize, z_twill: bool) -> Pattern {
        let p = n + m;
        Pattern::from_fn(p, p, |i, j| {
            let k = if z_twill { j + p - i % p } else { j + i };
            k % p < n
        })
    }

    /// Warp-faced `n`-end satin with move `step` (coprime to n): each warp goes under one weft
    /// in n, the binding points of neighbouring warps `step` wefts apart so none touch.
    pub fn satin(n: usize, step: usize) -> Pattern {
        Pattern::from_fn(n, n, |i, j| (i * step) % n != j % n)
    }

    /// The same interlacement seen from the back: every crossing swapped (a warp-faced satin
    /// becomes weft-faced).
    pub fn inverted(&self) -> Pattern {
        Pattern {
            over: self.over.iter().map(|o| !o).collect(),
            ..self.clone()
        }
    }

    /// Basket weave: plain weave on groups of `n` warps and `n` wefts.
    pub fn basket(n: usize) -> Pattern {
        Pattern::from_fn(2 * n, 2 * n, |i, j| (i / n + j / n).is_multiple_of(2))
    }
}

/// Geometry of a woven swatch, in user units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WovenParams {
    /// Distance between neighbouring warps (and between neighbouring wefts).
    pub spacing: f64,
    /// Yarn width (cross-section ellipse axis in the cloth plane), at most `spacing`.
    pub width: f64,
    /// Yarn height (cross-section ellipse axis normal to the yarn, out of the cloth plane).
    pub height: f64,
    /// Half the vertical distance between warp and weft centres at a crossing.
    pub crimp: f64,
    /// Vertices per ring (around the yarn).
    pub segments: usize,
    /// Rings per yarn spacing (along the yarn).
    pub along: usize,
    /// Fraction of each spacing, centred on a crossing, over which the yarn stays level before
    /// bending to the other side (0: a half cosine from crossing to crossing). Flat tops let
    /// wide yarns (width near the spacing) wrap each other.
    pub flat: f64,
}

impl WovenParams {
    /// Reads `spacing, width, height, flat, crimp, segments, along` with their defaults and
    /// ranges.
    pub fn from_params(p: &Params) -> Result<WovenParams> {
        let spacing = p.positive("spacing", 1.0, f64::INFINITY)?;
        let width = p.positive("width", 0.8 * spacing, spacing)?;
        let height = p.positive("height", 0.35 * spacing, spacing)?;
        let flat = p.real("flat", 0.0, 0.0, 0.8)?;
        // Yarns bend around each other: the centres must be at least about one yarn height
        // apart at a crossing; see `min_crimp` for the exact bound used.
        let Some(lo) = min_crimp(spacing, width, height, flat) else {
            return Err(p.invalid(
                "height",
                height,
                format!("a smaller height: no crimp separates yarns {height} high and {width} wide at spacing {spacing} (flat = {flat}; a larger flat may help)"),
            ));
        };
        let crimp = p.real("crimp", 1.05 * lo, lo, spacing)?;
        let segments = p.int("segments", 12, 3, 1024)? as usize;
        let along = p.int("along", segments as i64, 2, 1024)? as usize;
        Ok(WovenParams {
            spacing,
            width,
            height,
            crimp,
            segments,
            along,
            flat,
        })
    }
}

/// Height of a yarn's centre at distance `t` (in spacings) past a crossing where it sits at
/// `za`, heading to `zb` at the next crossing: level for `flat`/2 on each side of a crossing and
/// a half cosine in between, with zero slope at its ends so floats and crossings join
/// smoothly. Returns (z, dz/dt).
fn crimp_profile(za: f64, zb: f64, t: f64, flat: f64) -> (f64, f64) {
    let pi = std::f64::consts::PI;
    let u = ((t - 0.5 * flat) / (1.0 - flat)).clamp(0.0, 1.0);
    let z = za + (zb - za) * 0.5 * (1.0 - (pi * u).cos());
    let dz = (zb - za) * 0.5 * pi * (pi * u).sin() / (1.0 - flat);
    (z, dz)
}

/// Centre height and slope (per unit length) along one yarn at coordinate `s` along it, given
/// its heights `z_at(k)` at crossing k (crossings at (k + ½)·spacing).
fn yarn_height(s: f64, spacing: f64, flat: f64, z_at: &dyn Fn(i64) -> f64) -> (f64, f64) {
    let tau = s / spacing - 0.5;
    let k = tau.floor();
    let (z, dz) = crimp_profile(z_at(k as i64), z_at(k as i64 + 1), tau - k, flat);
    (z, dz / spacing)
}

/// Smallest crimp with no warp/weft overlap for the given section, or `None` when no crimp up
/// to one spacing separates them. Found by a scan and bisection on the clearance of a plain
/// weave, the tightest case: every crossing is a change of side. (Very large crimps fail again:
/// steep yarns meet their neighbours' sections obliquely.)
pub fn min_crimp(spacing: f64, width: f64, height: f64, flat: f64) -> Option<f64> {
    let ok = |c: f64| {
        let p = WovenParams {
            spacing,
            width,
            height,
            crimp: c,
            segments: 8,
            along: 24,
            flat,
        };
        woven(&Pattern::plain(), &p).clearance().gap >= -1e-9 * spacing
    };
    // At a crossing the centres must be at least one height apart: crimp ≥ height / 2.
    let start = 0.5 * height;
    if ok(start) {
        return Some(start);
    }
    let step = 0.05 * spacing;
    let mut lo = start;
    let mut hi = None;
    while lo < spacing {
        if ok(lo + step) {
            hi = Some(lo + step);
            break;
        }
        lo += step;
    }
    let mut hi = hi?;
    // 20 halvings of a 0.05-spacing bracket: 5e-8 spacings.
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

/// Weaves `pattern` into warp and weft tubes over one repeat.
///
/// The tile is (warps × spacing) by (wefts × spacing). Yarns are cut on the borders, which lie
/// half way between crossings; warp sections are slices at constant y and weft sections at
/// constant x (ellipses of the given width, and of the height stretched by 1/cos of the slope,
/// so the thickness normal to the yarn stays `height`), which puts each border ring exactly in
/// its border plane.
pub fn woven(pattern: &Pattern, p: &WovenParams) -> Cloth {
    let s = p.spacing;
    let (w, h) = (0.5 * p.width, 0.5 * p.height);
    let tile = [pattern.warps as f64 * s, pattern.wefts as f64 * s];
    let mut yarns = Vec::with_capacity(pattern.warps + pattern.wefts);
    let n_warp = pattern.wefts * p.along;
    for i in 0..pattern.warps {
        let x = (i as f64 + 0.5) * s;
        let z_at = |j: i64| {
            let j = j.rem_euclid(pattern.wefts as i64) as usize;
            if pattern.warp_over(i, j) {
                p.crimp
            } else {
                -p.crimp
            }
        };
        let mut yarn = Yarn {
            centre: Vec::with_capacity(n_warp + 1),
            axes: Vec::with_capacity(n_warp + 1),
            ends: Ends::Periodic {
                shift: [0.0, tile[1], 0.0],
            },
        };
        for k in 0..=n_warp {
            let y = tile[1] * k as f64 / n_warp as f64;
            let (z, dz) = yarn_height(y, s, p.flat, &z_at);
            yarn.centre.push([x, y, z]);
            yarn.axes
                .push([[-w, 0.0, 0.0], [0.0, 0.0, h * (1.0 + dz * dz).sqrt()]]);
        }
        yarns.push(yarn);
    }
    let n_weft = pattern.warps * p.along;
    for j in 0..pattern.wefts {
        let y = (j as f64 + 0.5) * s;
        let z_at = |i: i64| {
            let i = i.rem_euclid(pattern.warps as i64) as usize;
            if pattern.warp_over(i, j) {
                -p.crimp
            } else {
                p.crimp
            }
        };
        let mut yarn = Yarn {
            centre: Vec::with_capacity(n_weft + 1),
            axes: Vec::with_capacity(n_weft + 1),
            ends: Ends::Periodic {
                shift: [tile[0], 0.0, 0.0],
            },
        };
        for k in 0..=n_weft {
            let x = tile[0] * k as f64 / n_weft as f64;
            let (z, dz) = yarn_height(x, s, p.flat, &z_at);
            yarn.centre.push([x, y, z]);
            yarn.axes
                .push([[0.0, w, 0.0], [0.0, 0.0, h * (1.0 + dz * dz).sqrt()]]);
        }
        yarns.push(yarn);
    }
    Cloth {
        tile,
        yarns,
        ..Cloth::default()
    }
}

/// Checks a pattern has at least one warp and one weft and returns it.
pub fn checked(pattern: Pattern) -> Result<Pattern> {
    if pattern.warps == 0 || pattern.wefts == 0 {
        return Err(Error::Invalid(
            "a weave pattern needs at least one warp and one weft".into(),
        ));
    }
    Ok(pattern)
}
