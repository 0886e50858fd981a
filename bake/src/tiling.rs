//! Which periodic copies of the tile a light needs.
//!
//! Derivation: a shadow ray from a receiver at height z ≥ z_min towards a distant light l
//! (l_z > 0) leaves the swatch's slab at z_max after a horizontal run of at most
//! s = (l_x, l_y)·H_z / l_z, H_z = z_max − z_min. Every shadow ray of the central tile therefore
//! stays inside the Minkowski sum of the tile [0, W]×[0, H] and the segment [0, s] (a convex
//! hexagon). A copy (a, b) can shadow the central tile only if its bounding box, shifted by
//! (a·W, b·H), meets that hexagon; all others are left out. The copies kept reach out
//! k = ⌈|s_x| / W⌉ rings in x (similarly in y), the (2k+1)² rule of the issue, minus the
//! copies on the far side of the light. For a point light the receiver-to-light segments are
//! cut where they cross z_max; the region is the hull of the tile and its corners moved along
//! those segments.
use crate::swatch::{Bounds, MAX_TILES_TALL};

/// Copies (a, b) whose geometry can meet a ray that starts over the central tile and runs
/// inside the convex hull of the tile and the points `extra` (xy, mesh units). `margin`
/// widens every copy's bounding box (mesh units) so that float round-off cannot drop a copy.
pub fn copies_meeting(
    tile: [f64; 2],
    bounds: &Bounds,
    extra: &[[f64; 2]],
    margin: f64,
) -> Vec<[i32; 2]> {
    let mut pts = vec![
        [0.0, 0.0],
        [tile[0], 0.0],
        [tile[0], tile[1]],
        [0.0, tile[1]],
    ];
    pts.extend_from_slice(extra);
    let hull = convex_hull(pts);
    let (lo, hi) = extent(&hull);
    // Candidate range of a: the copy's x-range [min + aW, max + aW] must meet [lo, hi].
    let range = |axis: usize| {
        let a0 = ((lo[axis] - bounds.max[axis] - margin) / tile[axis]).floor() as i32;
        let a1 = ((hi[axis] - bounds.min[axis] + margin) / tile[axis]).ceil() as i32;
        a0..=a1
    };
    let mut out = Vec::new();
    for b in range(1) {
        for a in range(0) {
            let off = [a as f64 * tile[0], b as f64 * tile[1]];
            let rmin = [
                bounds.min[0] + off[0] - margin,
                bounds.min[1] + off[1] - margin,
            ];
            let rmax = [
                bounds.max[0] + off[0] + margin,
                bounds.max[1] + off[1] + margin,
            ];
            if rect_meets_convex(rmin, rmax, &hull) {
                out.push([a, b]);
            }
        }
    }
    out
}

/// Longest horizontal shadow run, in tiles, that the copies follow. A light a hair above the
/// horizon would otherwise need millions of copies; beyond this run a ray counts as lit and
/// the light is reported as capped ([`run_is_capped`]). As long as a mesh may be tall, so that
/// a light at 45° is never capped.
pub const MAX_RUN_TILES: f64 = MAX_TILES_TALL;

/// Whether direction `l`'s shadow run exceeds [`MAX_RUN_TILES`].
pub fn run_is_capped(tile: [f64; 2], bounds: &Bounds, l: [f64; 3]) -> bool {
    let hz = bounds.max[2] - bounds.min[2];
    hz * l[0].hypot(l[1]) > MAX_RUN_TILES * tile[0].min(tile[1]) * l[2]
}

/// Copies a distant light towards unit direction `l` (l_z > 0) needs.
pub fn copies_for_direction(
    tile: [f64; 2],
    bounds: &Bounds,
    l: [f64; 3],
    margin: f64,
) -> Vec<[i32; 2]> {
    let hz = bounds.max[2] - bounds.min[2];
    // The run along the horizontal direction of l, capped before it is formed: l[0] / l[2]
    // overflows to infinity for a subnormal l_z, and ∞·0 would make the hull NaN.
    let horiz = l[0].hypot(l[1]);
    let max_run = MAX_RUN_TILES * tile[0].min(tile[1]);
    let run = if horiz > 0.0 && hz > 0.0 {
        (hz * horiz / l[2]).min(max_run)
    } else {
        0.0
    };
    let s = if run > 0.0 {
        [l[0] / horiz * run, l[1] / horiz * run]
    } else {
        [0.0, 0.0]
    };
    let moved: Vec<[f64; 2]> = [
        [0.0, 0.0],
        [tile[0], 0.0],
        [tile[0], tile[1]],
        [0.0, tile[1]],
    ]
    .iter()
    .map(|c| [c[0] + s[0], c[1] + s[1]])
    .collect();
    copies_meeting(tile, bounds, &moved, margin)
}

/// Copies a point light at `pos` needs: receivers at z ≥ z_min, segments cut at z_max (or at
/// the light when it is below z_max).
pub fn copies_for_point(
    tile: [f64; 2],
    bounds: &Bounds,
    pos: [f64; 3],
    margin: f64,
) -> Vec<[i32; 2]> {
    let (z0, z1) = (bounds.min[2], bounds.max[2]);
    // Largest fraction of the receiver→light segment travelled below z_max, over receivers
    // at z_min (the lowest, so the longest run).
    let mut f = if pos[2] > z1 {
        ((z1 - z0) / (pos[2] - z0)).min(1.0)
    } else {
        1.0
    };
    let run = (pos[0] - tile[0] / 2.0).hypot(pos[1] - tile[1] / 2.0) * f;
    let max_run = MAX_RUN_TILES * tile[0].min(tile[1]);
    if run > max_run {
        f *= max_run / run;
    }
    let moved: Vec<[f64; 2]> = [
        [0.0, 0.0],
        [tile[0], 0.0],
        [tile[0], tile[1]],
        [0.0, tile[1]],
    ]
    .iter()
    .map(|c| [c[0] + f * (pos[0] - c[0]), c[1] + f * (pos[1] - c[1])])
    .collect();
    copies_meeting(tile, bounds, &moved, margin)
}

/// Rings used: the largest |a| or |b| among the copies.
pub fn rings(copies: &[[i32; 2]]) -> u32 {
    copies
        .iter()
        .map(|c| c[0].unsigned_abs().max(c[1].unsigned_abs()))
        .max()
        .unwrap_or(0)
}

fn extent(pts: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in pts {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// Andrew's monotone chain; counter-clockwise, no repeated points.
fn convex_hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(pts.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Separating-axis test of an axis-aligned rectangle against a convex polygon.
fn rect_meets_convex(rmin: [f64; 2], rmax: [f64; 2], poly: &[[f64; 2]]) -> bool {
    let (lo, hi) = extent(poly);
    if rmax[0] < lo[0] || rmin[0] > hi[0] || rmax[1] < lo[1] || rmin[1] > hi[1] {
        return false;
    }
    let corners = [rmin, [rmax[0], rmin[1]], rmax, [rmin[0], rmax[1]]];
    for i in 0..poly.len() {
        let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
        let n = [q[1] - p[1], p[0] - q[0]]; // outward normal of a CCW edge
        let dot = |c: [f64; 2]| (c[0] - p[0]) * n[0] + (c[1] - p[1]) * n[1];
        if corners.iter().all(|&c| dot(c) > 0.0) {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_bounds(hz: f64) -> Bounds {
        Bounds {
            min: [0.0, 0.0, 0.0],
            max: [1.0, 1.0, hz],
        }
    }

    #[test]
    fn overhead_light_needs_only_the_neighbours_it_touches() {
        // Tile-filling bounds touch the 8 neighbours at their shared edges; the margin keeps
        // them (a ray along the border can graze them).
        let c = copies_for_direction([1.0, 1.0], &unit_bounds(0.4), [0.0, 0.0, 1.0], 1e-9);
        assert_eq!(c.len(), 9);
        // Bounds strictly inside the tile: only the centre.
        let inner = Bounds {
            min: [0.1, 0.1, 0.0],
            max: [0.9, 0.9, 0.4],
        };
        assert_eq!(
            copies_for_direction([1.0, 1.0], &inner, [0.0, 0.0, 1.0], 1e-9),
            vec![[0, 0]]
        );
    }

    #[test]
    fn low_light_widens_to_k_rings_on_its_side_only() {
        // Light along +x at 10°: run = 0.4 / tan 10° ≈ 2.27 tiles → copies 0..=3 in x
        // (bounds touching), y only the touching neighbours.
        let e = 10f64.to_radians();
        let l = [e.cos(), 0.0, e.sin()];
        let inner = Bounds {
            min: [0.05, 0.05, 0.0],
            max: [0.95, 0.95, 0.4],
        };
        let c = copies_for_direction([1.0, 1.0], &inner, l, 1e-9);
        let xs: Vec<i32> = c.iter().map(|c| c[0]).collect();
        assert_eq!(c.iter().map(|c| c[1]).max(), Some(0));
        assert_eq!(xs, vec![0, 1, 2, 3]);
        assert_eq!(rings(&c), 3);
        assert_eq!((0.4 / (1.0 * e.tan())).ceil() as u32, 3);
        // Diagonal light: the hexagon misses the copies at (+k, −1) and (−1, +k).
        let d = [0.5f64.sqrt() * e.cos(), 0.5f64.sqrt() * e.cos(), e.sin()];
        let c = copies_for_direction([1.0, 1.0], &unit_bounds(0.4), d, 1e-9);
        assert!(
            c.contains(&[2, 2]) && !c.contains(&[2, -1]) && !c.contains(&[-2, 0]),
            "{c:?}"
        );
    }

    #[test]
    fn grazing_runs_are_capped() {
        let l = [1.0, 0.0, 1e-9];
        assert!(run_is_capped([1.0, 1.0], &unit_bounds(0.5), l));
        let c = copies_for_direction([1.0, 1.0], &unit_bounds(0.5), l, 1e-9);
        assert_eq!(rings(&c), MAX_RUN_TILES as u32 + 1);
        assert!(c.len() < 4 * MAX_RUN_TILES as usize);
        // A subnormal l_z (an `.lp` line `a 1 0 1e-320`) overflows l_x / l_z: the same capped
        // run, not a NaN hull.
        let sub = copies_for_direction([1.0, 1.0], &unit_bounds(0.5), [1.0, 0.0, 1e-320], 1e-9);
        assert_eq!(sub, c);
        let diag = [0.5f64.sqrt(), 0.5f64.sqrt(), 5e-324];
        let d = copies_for_direction([1.0, 1.0], &unit_bounds(0.5), diag, 1e-9);
        let k = (MAX_RUN_TILES / 2f64.sqrt()).ceil() as u32;
        assert!(
            (k..=k + 1).contains(&rings(&d)) && d.contains(&[0, 0]),
            "{}",
            rings(&d)
        );
    }

    #[test]
    fn point_light_region_contains_the_distant_limit() {
        let b = unit_bounds(0.2);
        let far = copies_for_point([1.0, 1.0], &b, [1e9, 0.5, 2e8], 1e-9);
        let dir = copies_for_direction(
            [1.0, 1.0],
            &b,
            [5.0 / 26f64.sqrt(), 0.0, 1.0 / 26f64.sqrt()],
            1e-9,
        );
        assert_eq!(far, dir);
    }
}
