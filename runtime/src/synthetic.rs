//! Deterministic synthetic inputs for benchmarks, reports and tests: a leafy caster whose discs
//! of varying alpha give soft shadows with edges at every scale, and the half-plane edge of the
//! analytic penumbra profiles.

use crate::scene::Caster;

use ptm_format::hash::splitmix64 as hash;

/// A leafy `n`² caster (n ≥ 12): 60 green discs of radius n/40 to n/40 + n/12 texels and alpha
/// 128–255 on transparent, over the world rectangle `rect` at height `elevation`, untilted.
pub fn leaves(n: usize, rect: [f32; 4], elevation: f32) -> Caster {
    let mut rgba = vec![[0u8; 4]; n * n];
    for d in 0..60u64 {
        let cx = (hash(d * 3) % n as u64) as i64;
        let cy = (hash(d * 3 + 1) % n as u64) as i64;
        let r = (n as i64 / 40) + (hash(d * 3 + 2) % (n as u64 / 12).max(1)) as i64;
        let a = 128 + (hash(d) % 128) as u8;
        for y in (cy - r).max(0)..(cy + r).min(n as i64) {
            for x in (cx - r).max(0)..(cx + r).min(n as i64) {
                if (x - cx).pow(2) + (y - cy).pow(2) < r * r {
                    rgba[y as usize * n + x as usize] = [40, 160, 60, a];
                }
            }
        }
    }
    Caster {
        width: n,
        height: n,
        rgba,
        rect,
        elevation,
        tilt_deg: 0.0,
    }
}

/// A straight caster edge: opaque (black) for x < 0, clear for x > 0, `n` × `rows` texels over
/// the world square [−4, 4]² at height `elevation`, untilted (the half-plane of the analytic
/// penumbra profiles).
pub fn half_plane(n: usize, rows: usize, elevation: f32) -> Caster {
    Caster {
        width: n,
        height: rows,
        rgba: (0..n * rows)
            .map(|t| [0, 0, 0, if t % n < n / 2 { 255 } else { 0 }])
            .collect(),
        rect: [-4.0, -4.0, 4.0, 4.0],
        elevation,
        tilt_deg: 0.0,
    }
}
