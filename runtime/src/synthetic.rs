//! Deterministic synthetic inputs for benchmarks, reports and tests, the one place they are
//! built: PTMs (random coefficients, a learned basis's random tables, with a hole, a smooth
//! cloth, a texel checkerboard, a constant K), casters (random RGBA, a leafy one whose discs of
//! varying alpha give soft shadows with edges at every scale, the half-plane edge of the
//! analytic penumbra profiles) and the `strip` scene those profiles are measured on. Every
//! value is a hash of its index and a seed, so a test, the benchmark and the report see the
//! same inputs on every machine.

use crate::scene::{Blur, Caster, Light, Scene};

use ptm_format::hash::splitmix64 as hash;
use ptm_format::{Basis, Link, Ptm, UvMap};

/// Uniform in [lo, hi) from a key (24 bits of its hash).
fn rand(key: u64, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * ((hash(key) >> 40) as f32 / (1u64 << 24) as f32)
}

/// A `width × height` PTM of `basis` with random coefficients keyed by `seed`: constant terms in
/// [−0.2, 0.9), the others in [−0.8, 0.8), so K leaves [0, 1] in places (clamping is
/// exercised). Identity link, projected (u, v), tile 1 × 1, no MIP levels or coverage.
pub fn random_ptm(basis: Basis, width: usize, height: usize, seed: u64) -> Ptm {
    let n = basis.len();
    let planes = (0..n)
        .map(|k| {
            (0..width * height)
                .map(|t| {
                    let key = seed * 1_000_003 + (k * 65_537 + t) as u64;
                    if basis.monomials()[k].pu + basis.monomials()[k].pv == 0 {
                        rand(key, -0.2, 0.9)
                    } else {
                        rand(key, -0.8, 0.8)
                    }
                })
                .collect()
        })
        .collect();
    Ptm {
        basis,
        width,
        height,
        link: Link::Identity,
        uv: UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
        learned: None,
    }
}

/// A `width × height` PTM of the learned basis of `terms` terms on a `grid` × `grid` table,
/// keyed by `seed`, logistic over the hemispherical map as every learned file is: term t's
/// table is a wave cos(π(t + 1)u/2 + t)·cos(π(t mod 3)v/2 − t/2) plus a hashed ripple in
/// [−0.2, 0.2) at every node (so reads between nodes matter), the coefficients random in
/// [−2, 2) (K spans much of (0, 1)). Tile 1 × 1, no MIP levels or coverage.
pub fn learned_ptm(terms: usize, grid: usize, width: usize, height: usize, seed: u64) -> Ptm {
    let basis = Basis::learned(terms).expect("1 ..= 16 terms");
    let node = |i: usize| -1.0 + 2.0 * i as f32 / (grid - 1) as f32;
    let half_pi = std::f32::consts::FRAC_PI_2;
    let values = (0..terms * grid * grid)
        .map(|n| {
            let (t, j, i) = (n / (grid * grid), n / grid % grid, n % grid);
            let wave = ((t + 1) as f32 * half_pi * node(i) + t as f32).cos()
                * ((t % 3) as f32 * half_pi * node(j) - 0.5 * t as f32).cos();
            wave + rand(seed ^ 0x7ab1e ^ ((n as u64) << 20), -0.2, 0.2)
        })
        .collect();
    let planes = (0..terms)
        .map(|k| {
            (0..width * height)
                .map(|t| rand(seed * 1_000_003 + (k * 65_537 + t) as u64, -2.0, 2.0))
                .collect()
        })
        .collect();
    Ptm {
        basis,
        width,
        height,
        link: Link::Logistic,
        uv: UvMap::Hemispherical,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
        learned: Some(ptm_format::LearnedTable {
            grid,
            terms,
            values,
        }),
    }
}

/// [`random_ptm`] with a hole: coverage 0 (and coefficients 0, as the fit writes holes) on the
/// texels of columns 4..8, rows 3..6, ½ on the ring of texels around it, 1 elsewhere. The PTM
/// must be at least 10×8 texels.
pub fn holed_ptm(basis: Basis, width: usize, height: usize, seed: u64) -> Ptm {
    let mut ptm = random_ptm(basis, width, height, seed);
    let mut coverage = vec![1.0f32; width * height];
    for (t, c) in coverage.iter_mut().enumerate() {
        let (x, y) = (t % width, t / width);
        if (4..8).contains(&x) && (3..6).contains(&y) {
            *c = 0.0;
            for p in &mut ptm.planes {
                p[t] = 0.0;
            }
        } else if (3..9).contains(&x) && (2..7).contains(&y) {
            *c = 0.5;
        }
    }
    ptm.coverage = Some(coverage);
    ptm
}

/// A smooth `n`² ptm11 over a ½ × ½ tile whose K stays mostly inside [0, 1]: one period of
/// sin(2πx)·cos(2πy) in every coefficient, the cloth a soft shadow falls on.
pub fn cloth(n: usize) -> Ptm {
    let planes = (0..11)
        .map(|k| {
            (0..n * n)
                .map(|t| {
                    let (x, y) = ((t % n) as f32 / n as f32, (t / n) as f32 / n as f32);
                    let wave =
                        (std::f32::consts::TAU * x).sin() * (std::f32::consts::TAU * y).cos();
                    if k == 10 {
                        0.3 + 0.2 * wave
                    } else {
                        0.05 * wave * (k as f32 - 5.0) / 5.0
                    }
                })
                .collect()
        })
        .collect();
    Ptm::new(Basis::Ptm11, n, n, [0.5, 0.5], planes)
}

/// An `n`² ptm6 whose constant term is a texel checkerboard of K = 0 and 1 (no light
/// dependence): every 2×2 average is exactly ½, so a MIP chain's levels are known exactly.
/// Tile 1 × 1.
pub fn checker(n: usize) -> Ptm {
    let mut planes = vec![vec![0.0f32; n * n]; 6];
    for (t, c) in planes[5].iter_mut().enumerate() {
        *c = ((t % n + t / n) % 2) as f32;
    }
    Ptm {
        basis: Basis::Ptm6,
        width: n,
        height: n,
        link: Link::Identity,
        uv: UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
        learned: None,
    }
}

/// A 2 × 2 ptm6 of constant K = `k` (any value: outside [0, 1] it tests clamping) over a ½ × ½
/// tile.
pub fn constant(k: f32) -> Ptm {
    let mut planes = vec![vec![0.0f32; 4]; 6];
    planes[5] = vec![k; 4];
    Ptm {
        basis: Basis::Ptm6,
        width: 2,
        height: 2,
        link: Link::Identity,
        uv: UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [0.5, 0.5],
        planes,
        learned: None,
    }
}

/// A `w`×`h` caster of random 8-bit RGBA keyed by `seed`, with fully transparent and opaque
/// blobs, over the world rectangle `rect` at height `elevation`, untilted.
pub fn random_caster(w: usize, h: usize, rect: [f32; 4], elevation: f32, seed: u64) -> Caster {
    let rgba = (0..w * h)
        .map(|t| {
            let r = hash(seed ^ (t as u64 * 0x1234_5677));
            let (i, j) = ((t % w) as f32 / w as f32, (t / w) as f32 / h as f32);
            let blob = ((i * 6.0).sin() * (j * 5.0).cos() * 2.0).clamp(0.0, 1.0);
            let a = (blob * 255.0) as u8 | ((r & 0x3F) as u8);
            [(r >> 8) as u8, (r >> 16) as u8, (r >> 24) as u8, a]
        })
        .collect();
    Caster {
        width: w,
        height: h,
        rgba,
        rect,
        elevation,
        tilt_deg: 0.0,
    }
}

/// Pixels along the [`strip`] (its image is `STRIP_PIXELS` × 4).
pub const STRIP_PIXELS: u32 = 256;

/// A 2 × 0.04 strip of white cloth along X (the view [−1, 1] × [−0.02, 0.02], `STRIP_PIXELS` × 4
/// pixels), no PTM, no caster, under one `light`, blurred with `sat`: where the half-plane
/// penumbra profiles are measured (pixel i is at x = −1 + 2(i + ½)/`STRIP_PIXELS`).
pub fn strip(light: Light) -> Scene {
    Scene {
        size: [STRIP_PIXELS, 4],
        view: [-1.0, -0.02, 1.0, 0.02],
        ptm: None,
        albedo: [1.0; 3],
        albedo_texture: None,
        lights: vec![light],
        caster: None,
        colored_shadow: false,
        blur: Blur::Sat,
        perspective: None,
        glossy: None,
    }
}

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

/// A `w`×`h` lat-long sky (linear RGB, the convention of [`crate::environment`]): deep blue at
/// the zenith paling to the horizon, a warm sun 35° up at azimuth 40° with a soft glow, and
/// banks of cloud every 60° of azimuth; the ground (below the horizon) a dull brown.
pub fn sky_latlong(w: usize, h: usize) -> Vec<[f32; 3]> {
    let sun = {
        let (el, az) = (35f64.to_radians(), 40f64.to_radians());
        [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
    };
    (0..w * h)
        .map(|i| {
            let phi = 2.0 * std::f64::consts::PI * ((i % w) as f64 + 0.5) / w as f64
                - std::f64::consts::PI;
            let theta = std::f64::consts::PI * ((i / w) as f64 + 0.5) / h as f64;
            let d = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            if d[2] < 0.0 {
                return [0.12, 0.09, 0.06];
            }
            let t = 1.0 - d[2]; // 0 at the zenith, 1 at the horizon
            let cos_sun = d[0] * sun[0] + d[1] * sun[1] + d[2] * sun[2];
            let glow = 3.0 * ((cos_sun - 1.0) / 0.02).exp();
            let cloud = 0.25 * (0.5 + 0.5 * (6.0 * phi).cos()).powi(4) * (1.0 - d[2]).sqrt();
            let base = [0.10 + 0.55 * t, 0.20 + 0.55 * t, 0.55 + 0.40 * t];
            [
                (base[0] + cloud + glow) as f32,
                (base[1] + cloud + 0.85 * glow) as f32,
                (base[2] + cloud + 0.6 * glow) as f32,
            ]
        })
        .collect()
}

/// [`sky_latlong`] at 128 × 64, as a glossy receiver's background image.
pub fn sky() -> crate::environment::Environment {
    crate::environment::Environment::from_latlong("synthetic sky", 128, 64, &sky_latlong(128, 64))
        .expect("a finite sky")
}
