//! A glossy receiver's background image: the sky a glossy cloth reflects where its lobe misses
//! the caster ([`crate::scene::Glossy::environment`]).
//!
//! Read from a latitude-longitude (equirectangular) image, the format HDR skies come in, and
//! resampled once into an **equal-area map of the upper hemisphere**: direction r (unit, z up)
//! sits at (u, v) = (r.x, r.y)/√(1 + r.z) in the unit disc (Lambert's azimuthal projection,
//! scaled so the horizon is the unit circle; below it, the horizon at r's azimuth), on an N×N
//! grid over [−1, 1]² (N a power of two; texels outside the disc hold the horizon at their
//! azimuth), with a 2×2 box MIP chain. Every solid angle keeps its area there: a lobe's cone of
//! half-angle α covers π(1 − cos α) wherever it points.
//!
//! A scene has one roughness, so the lobe's average is computed once, when the scene is
//! prepared ([`Environment::prefiltered`]): a map whose every texel is the sky averaged over the
//! cone of half-angle α around the texel's direction (a product midpoint rule in (cos θ, φ)
//! over the cone, each point read bilinearly from the level whose texels match the points'
//! spacing), at a resolution the blurred sky needs (texels at most ρ/4 apart, ρ = √(1 − cos α)
//! the cone's radius in the map). The shader reads only that map, bilinearly along the mirror
//! direction (`env_lookup` in `shade.wgsl`; twin `cpu::shade::env_lookup`): one read per
//! pixel, no MIP chain on the GPU. A mirror (α = 0) reads level 0.
//!
//! The lat-long convention: column x at azimuth φ = 2π(x + ½)/W − π, measured from +X towards
//! +Y (the centre column looks along +X); row y at polar angle θ = π(y + ½)/H from +Z (row 0
//! the zenith); only the upper half of the image (θ ≤ 90°) is reflected.

use std::path::Path;

use crate::{Error, Result};

/// Largest side N of the level-0 map (a 2048 × 1024 sky gives 512²: 5.6 MB with its levels).
pub const MAX_SIZE: usize = 512;

/// The upper hemisphere of a background image as an equal-area map with its MIP chain.
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    /// Side N of level 0 (a power of two, 1 ..= [`MAX_SIZE`]).
    pub size: usize,
    /// Every level, level 0 first, each row-major (row j at v = −1 + 2(j + ½)/side):
    /// linear RGB and 0. Level k (side N/2^k) starts at [`level_offset`]`(N, k)`.
    pub texels: Vec<[f32; 4]>,
}

/// Where level k of a chain whose level 0 has side `n` starts: Σ_{i<k} (n/2^i)² =
/// 4(n² − (n/2^k)²)/3 (exact for a power of two).
pub fn level_offset(n: usize, k: u32) -> usize {
    let s = n >> k;
    4 * (n * n - s * s) / 3
}

/// The number of levels of a chain whose level 0 has side `n` (a power of two): log2(n) + 1.
pub fn level_count(n: usize) -> u32 {
    n.trailing_zeros() + 1
}

/// Equal-area (u, v) of unit direction r: (r.x, r.y)/√(1 + r.z); below the horizon (r.z < 0)
/// the horizon at r's azimuth.
pub fn direction_to_uv(r: [f32; 3]) -> [f32; 2] {
    let s = if r[2] >= 0.0 {
        1.0 / (1.0 + r[2]).sqrt()
    } else {
        1.0 / (r[0] * r[0] + r[1] * r[1]).sqrt().max(f32::MIN_POSITIVE)
    };
    [r[0] * s, r[1] * s]
}

/// The unit direction at (u, v) of the equal-area map; points outside the unit disc give the
/// horizon at their azimuth.
pub fn uv_to_direction(uv: [f64; 2]) -> [f64; 3] {
    let rho2 = uv[0] * uv[0] + uv[1] * uv[1];
    if rho2 > 1.0 {
        let rho = rho2.sqrt();
        return [uv[0] / rho, uv[1] / rho, 0.0];
    }
    let s = (2.0 - rho2).sqrt();
    [uv[0] * s, uv[1] * s, 1.0 - rho2]
}

impl Environment {
    /// Resamples a lat-long image (`w`×`h` linear RGB, row-major, see the module doc) into the
    /// equal-area map: N = the power of two nearest `h`, within 8 ..= [`MAX_SIZE`]; each texel
    /// the mean of 4 × 4 stratified points, each a bilinear read of the lat-long (wrapping in
    /// azimuth). Refuses an empty image and non-finite or negative pixels, naming `what`.
    pub fn from_latlong(what: &str, w: usize, h: usize, rgb: &[[f32; 3]]) -> Result<Environment> {
        if w == 0 || h == 0 || rgb.len() != w * h {
            return Err(Error::Scene(format!(
                "{what}: a {w}×{h} background image needs {} pixels, has {}",
                w * h,
                rgb.len()
            )));
        }
        if let Some(i) = rgb
            .iter()
            .position(|p| !p.iter().all(|x| x.is_finite() && *x >= 0.0))
        {
            let bad = rgb
                .iter()
                .filter(|p| !p.iter().all(|x| x.is_finite() && *x >= 0.0))
                .count();
            return Err(Error::Scene(format!(
                "{what}: {bad} pixels are negative or not finite (the first at column {}, row \
                 {}: {:?}); a background is linear RGB radiance ≥ 0: clamp or repair the image",
                i % w,
                i / w,
                rgb[i]
            )));
        }
        let n = h.next_power_of_two().clamp(8, MAX_SIZE);
        let latlong = |d: [f64; 3]| -> [f64; 3] {
            let phi = d[1].atan2(d[0]);
            let theta = d[2].clamp(-1.0, 1.0).acos();
            let x = (phi + std::f64::consts::PI) / (2.0 * std::f64::consts::PI) * w as f64 - 0.5;
            let y = (theta / std::f64::consts::PI * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
            let (x0, y0) = (x.floor(), y.floor());
            let (ax, ay) = (x - x0, y - y0);
            let col = |i: f64| (i as i64).rem_euclid(w as i64) as usize;
            let row = |j: f64| (j as usize).min(h - 1);
            let px = |i: f64, j: f64| rgb[row(j) * w + col(i)].map(f64::from);
            let (a, b, c, e) = (
                px(x0, y0),
                px(x0 + 1.0, y0),
                px(x0, y0 + 1.0),
                px(x0 + 1.0, y0 + 1.0),
            );
            std::array::from_fn(|k| {
                (1.0 - ay) * ((1.0 - ax) * a[k] + ax * b[k]) + ay * ((1.0 - ax) * c[k] + ax * e[k])
            })
        };
        use rayon::prelude::*;
        const SUB: usize = 4;
        let mut texels: Vec<[f32; 4]> = (0..n * n)
            .into_par_iter()
            .map(|t| {
                let (i, j) = (t % n, t / n);
                let mut s = [0.0f64; 3];
                for q in 0..SUB * SUB {
                    let (qi, qj) = (q % SUB, q / SUB);
                    let uv = [
                        -1.0 + 2.0 * (i as f64 + (qi as f64 + 0.5) / SUB as f64) / n as f64,
                        -1.0 + 2.0 * (j as f64 + (qj as f64 + 0.5) / SUB as f64) / n as f64,
                    ];
                    let c = latlong(uv_to_direction(uv));
                    for k in 0..3 {
                        s[k] += c[k];
                    }
                }
                let m = 1.0 / (SUB * SUB) as f64;
                [(s[0] * m) as f32, (s[1] * m) as f32, (s[2] * m) as f32, 0.0]
            })
            .collect();
        // The 2×2 box chain down to 1×1.
        let mut side = n;
        let mut off = 0;
        while side > 1 {
            let half = side / 2;
            for y in 0..half {
                for x in 0..half {
                    let at = |dx: usize, dy: usize| texels[off + (2 * y + dy) * side + 2 * x + dx];
                    let (a, b, c, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
                    texels.push(std::array::from_fn(|k| 0.25 * (a[k] + b[k] + c[k] + d[k])));
                }
            }
            off += side * side;
            side = half;
        }
        debug_assert_eq!(texels.len(), level_offset(n, level_count(n)));
        Ok(Environment { size: n, texels })
    }

    /// A uniform background of radiance `rgb` (every lookup returns it).
    pub fn uniform(rgb: [f32; 3]) -> Environment {
        Environment::from_latlong("uniform background", 2, 1, &[rgb, rgb]).expect("finite")
    }

    /// Reads a lat-long background image: OpenEXR (linear RGB, its first RGB(A) layer) or
    /// anything the `image` crate reads (PNG, JPEG, …: sRGB-encoded, decoded to linear).
    pub fn load(path: &Path) -> Result<Environment> {
        let what = path.display().to_string();
        let is_exr = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let (w, h, rgb) = if is_exr {
            read_exr(path)?
        } else {
            let (w, h, px) = crate::output::read_rgba8(path)?;
            let rgb = px
                .iter()
                .map(|p| std::array::from_fn(|k| crate::output::srgb_decode(p[k] as f32 / 255.0)))
                .collect();
            (w, h, rgb)
        };
        Environment::from_latlong(&what, w, h, &rgb)
    }

    /// The background along unit direction r at full resolution (level 0, bilinear): what a
    /// ray-traced reference sees.
    pub fn radiance(&self, r: [f32; 3]) -> [f32; 3] {
        let c = read(self.size, &self.texels, r);
        [c[0], c[1], c[2]]
    }

    /// The map a lobe of half-angle asin(`sin_a`) reflects: (side M, M×M texels), each the
    /// background averaged over the cone around its direction (see the module doc); level 0
    /// itself for a mirror. Deterministic.
    pub fn prefiltered(&self, sin_a: f32) -> (usize, Vec<[f32; 4]>) {
        let n = self.size;
        // A mirror, or a NaN the scene's checks let through: level 0 itself.
        if sin_a.is_nan() || sin_a <= 0.0 {
            return (n, self.texels[..n * n].to_vec());
        }
        let s = (sin_a as f64).min(1.0);
        let cos_a = (1.0 - s * s).max(0.0).sqrt();
        // The cone's radius in the map, without cancellation: √(1 − cos α) = sin α/√(1 + cos α).
        let rho = s / (1.0 + cos_a).sqrt();
        let m = ((8.0 / rho).ceil() as usize).clamp(4, n);
        // Q × Q points over the cone: about one per level-0 texel it covers, 4² to 16².
        let rho_texels = rho * 0.5 * n as f64;
        let q = ((2.0 * rho_texels).ceil() as usize).clamp(4, 16);
        // Read each point from the level whose texels are the points' spacing.
        let spacing = (std::f64::consts::PI * rho_texels * rho_texels / (q * q) as f64).sqrt();
        let level = (spacing.max(1.0).log2().floor() as u32).min(level_count(n) - 1);
        let side = n >> level;
        let texels = &self.texels[level_offset(n, level)..][..side * side];
        use rayon::prelude::*;
        let map = (0..m * m)
            .into_par_iter()
            .map(|t| {
                let uv = [
                    -1.0 + 2.0 * ((t % m) as f64 + 0.5) / m as f64,
                    -1.0 + 2.0 * ((t / m) as f64 + 0.5) / m as f64,
                ];
                let mut cone = crate::penumbra::cone_frame(uv_to_direction(uv), 0.0, 1.0);
                cone.cos_max = cos_a;
                let mut sum = [0.0f64; 3];
                for k in 0..q * q {
                    let (i, j) = ((k % q) as f64 + 0.5, (k / q) as f64 + 0.5);
                    let d = cone.dir(i / q as f64, j / q as f64).map(|x| x as f32);
                    let c = read(side, texels, d);
                    for c_k in 0..3 {
                        sum[c_k] += c[c_k] as f64;
                    }
                }
                let w = 1.0 / (q * q) as f64;
                [
                    (sum[0] * w) as f32,
                    (sum[1] * w) as f32,
                    (sum[2] * w) as f32,
                    0.0,
                ]
            })
            .collect();
        (m, map)
    }
}

/// Texel (x, y) of an `n`×`n` map, clamped to its edge (`env_texel` of `shade.wgsl`).
pub fn texel(n: usize, texels: &[[f32; 4]], x: i32, y: i32) -> [f32; 4] {
    let s = n as i32;
    let (cx, cy) = (x.clamp(0, s - 1), y.clamp(0, s - 1));
    texels[(cy * s + cx) as usize]
}

/// Bilinear read of an `n`×`n` map at texel coordinate t, clamped to its edge (`env_bilinear`
/// of `shade.wgsl`, same operations).
pub fn bilinear(n: usize, texels: &[[f32; 4]], t: [f32; 2]) -> [f32; 4] {
    let c = [t[0] - 0.5, t[1] - 0.5];
    let c0 = [c[0].floor(), c[1].floor()];
    let a = [c[0] - c0[0], c[1] - c0[1]];
    let (x, y) = (c0[0] as i32, c0[1] as i32);
    let mix = |p: [f32; 4], q: [f32; 4], w: f32| -> [f32; 4] {
        std::array::from_fn(|i| p[i] * (1.0 - w) + q[i] * w)
    };
    let at = |dx: i32, dy: i32| texel(n, texels, x + dx, y + dy);
    mix(
        mix(at(0, 0), at(1, 0), a[0]),
        mix(at(0, 1), at(1, 1), a[0]),
        a[1],
    )
}

/// The `n`×`n` map's value along unit direction r (`env_lookup` of `shade.wgsl`).
pub fn read(n: usize, texels: &[[f32; 4]], r: [f32; 3]) -> [f32; 4] {
    let nf = n as f32;
    let uv = direction_to_uv(r);
    bilinear(
        n,
        texels,
        [(uv[0] + 1.0) * (0.5 * nf), (uv[1] + 1.0) * (0.5 * nf)],
    )
}

/// The first RGB(A) layer of an OpenEXR file as linear RGB.
fn read_exr(path: &Path) -> crate::Result<(usize, usize, Vec<[f32; 3]>)> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0f32; 3]; res.width() * res.height()]),
        |(w, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b];
        },
    )
    .map_err(|e| crate::Error::Image {
        path: path.display().to_string(),
        reason: format!("{e}; give a lat-long OpenEXR with R, G, B channels, or a PNG"),
    })?;
    let size = image.layer_data.size;
    let (_, px) = image.layer_data.channel_data.pixels;
    Ok((size.width(), size.height(), px))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_area_map_round_trips_and_keeps_the_horizon_on_the_unit_circle() {
        for d in [
            [0.0f64, 0.0, 1.0],
            [0.6, 0.0, 0.8],
            [0.3, -0.4, 0.866],
            [0.0, 1.0, 0.0],
        ] {
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let d = d.map(|x: f64| x / n);
            let uv = direction_to_uv(d.map(|x| x as f32));
            let back = uv_to_direction([uv[0] as f64, uv[1] as f64]);
            for k in 0..3 {
                assert!((back[k] - d[k]).abs() < 1e-6, "{d:?} → {uv:?} → {back:?}");
            }
        }
        let uv = direction_to_uv([0.0, 1.0, 0.0]);
        assert!((uv[1] - 1.0).abs() < 1e-7);
        // Equal area: the cap θ ≤ 60° (half the hemisphere's solid angle) is half the disc.
        let rho = direction_to_uv([60f32.to_radians().sin(), 0.0, 0.5])[0];
        assert!((std::f32::consts::PI * rho * rho - 0.5 * std::f32::consts::PI).abs() < 1e-5);
    }

    #[test]
    fn chain_levels_average_and_offsets_add_up() {
        assert_eq!(level_offset(8, 0), 0);
        assert_eq!(level_offset(8, 1), 64);
        assert_eq!(level_offset(8, 3), 64 + 16 + 4);
        assert_eq!(level_count(8), 4);
        // A sky that brightens towards the zenith: the top level is the map's mean.
        let (w, h) = (64, 32);
        let rgb: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                let y = (i / w) as f32;
                [1.0 - y / h as f32, 0.5, 0.0]
            })
            .collect();
        let e = Environment::from_latlong("test", w, h, &rgb).unwrap();
        assert_eq!(e.size, 32);
        let mean0: f32 = e.texels[..32 * 32].iter().map(|t| t[0]).sum::<f32>() / 1024.0;
        let top = e.texels[level_offset(32, 5)];
        assert!((top[0] - mean0).abs() < 1e-5, "{top:?} vs {mean0}");
        // Zenith reads ≈ 1, the horizon ≈ 0.5 (θ = 90°: row h/2); green is 0.5 everywhere.
        let z = e.radiance([0.0, 0.0, 1.0]);
        assert!(
            (z[0] - 1.0).abs() < 0.03 && (z[1] - 0.5).abs() < 1e-6,
            "{z:?}"
        );
        let hz = e.radiance([1.0, 0.0, 0.0]);
        // (The last texel's centre is 3.5° above the horizon.)
        assert!((hz[0] - 0.5).abs() < 0.05, "{hz:?}");
        // A mirror reads level 0; a wide lobe at the zenith averages the sky around it: red
        // is 1 − θ/π + ½/h (row y, centred at θ = π(y + ½)/h, holds 1 − y/h), so over the
        // cone of 45° its mean is 1 − E[θ]/π + ½/h.
        let (n, m) = e.prefiltered(0.0);
        assert_eq!(read(n, &m, [0.0, 0.0, 1.0])[..3], z);
        let (n, m) = e.prefiltered(45f32.to_radians().sin());
        let wide = read(n, &m, [0.0, 0.0, 1.0]);
        let want = 1.0 - mean_theta(45f64.to_radians()) / std::f64::consts::PI + 0.5 / h as f64;
        assert!((wide[0] as f64 - want).abs() < 0.002, "{wide:?} vs {want}");
    }

    /// The mean polar angle over a cone of half-angle a about the zenith (uniform in solid
    /// angle): ∫θ sin θ dθ / ∫sin θ dθ = (sin a − a cos a)/(1 − cos a).
    fn mean_theta(a: f64) -> f64 {
        (a.sin() - a * a.cos()) / (1.0 - a.cos())
    }

    #[test]
    fn uniform_backgrounds_read_back_exactly_at_every_roughness() {
        let e = Environment::uniform([0.2, 0.25, 0.35]);
        for s in [0.0f32, 0.1, 0.5, std::f32::consts::FRAC_1_SQRT_2] {
            let (n, m) = e.prefiltered(s);
            for r in [[0.0, 0.0, 1.0], [0.8, 0.0, 0.6], [0.0, -1.0, 0.0]] {
                let c = read(n, &m, r);
                for k in 0..3 {
                    assert!((c[k] - [0.2, 0.25, 0.35][k]).abs() < 1e-6, "{c:?}");
                }
            }
        }
    }

    #[test]
    fn bad_pixels_and_sizes_are_refused_naming_the_image() {
        let e = Environment::from_latlong("sky.exr", 2, 1, &[[0.0; 3], [f32::NAN, 0.0, 0.0]])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sky.exr") && e.contains("column 1, row 0"),
            "{e}"
        );
        let e = Environment::from_latlong("sky.exr", 2, 1, &[[-1.0, 0.0, 0.0], [0.0; 3]])
            .unwrap_err()
            .to_string();
        assert!(e.contains("negative"), "{e}");
        let e = Environment::from_latlong("sky.png", 3, 2, &[[0.0; 3]; 5])
            .unwrap_err()
            .to_string();
        assert!(e.contains("3×2") && e.contains("sky.png"), "{e}");
    }
}
