//! Light domes: spherical Fibonacci directions above a minimum elevation, RTI-style rings, or a
//! `.lp` file. Every dome is a `ptm_format::LightSet` of unit vectors towards the lights (z up).
use std::f64::consts::PI;

use ptm_format::LightSet;

use crate::{Error, Result};

/// The most lights a dome may have. Each light is a K plane of the stack and a row of the
/// fit's design matrix; RTI domes have tens to hundreds (relight's `.lp` reader allows 1000).
/// Checked before a dome is built, so `fibonacci:1000000000000` is refused, not allocated.
pub const MAX_LIGHTS: usize = 1 << 20;

/// `n` spherical Fibonacci directions, equal-area in z over the cap above `min_elevation_deg`
/// degrees: zᵢ = z_min + (1 − z_min)·(1 − (i + ½)/n), φᵢ = i·golden angle (Keinert et al.
/// 2015). The ½ keeps every light strictly above the minimum elevation and off the pole.
pub fn fibonacci(n: usize, min_elevation_deg: f64) -> Result<LightSet> {
    if n == 0 {
        return Err(Error::NoLights);
    }
    if n > MAX_LIGHTS {
        return Err(Error::Dome(format!(
            "{n} lights: a dome has at most {MAX_LIGHTS}"
        )));
    }
    if !(0.0..90.0).contains(&min_elevation_deg) {
        return Err(Error::MinElevation {
            deg: min_elevation_deg,
        });
    }
    let z_min = min_elevation_deg.to_radians().sin();
    let golden = PI * (3.0 - 5f64.sqrt()); // 2π(1 − 1/Φ) ≈ 2.39996 rad
    Ok(LightSet::from_dirs((0..n).map(|i| {
        let z = z_min + (1.0 - z_min) * (1.0 - (i as f64 + 0.5) / n as f64);
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = golden * i as f64;
        [r * phi.cos(), r * phi.sin(), z]
    })))
}

/// Rings `E1xC1,E2xC2,…`: Cᵢ lights evenly spaced in azimuth at elevation Eᵢ degrees, the
/// first light of each ring at azimuth 0 (+X). `spec` is the part after `rings:`.
pub fn rings(spec: &str) -> Result<LightSet> {
    let bad = |reason: String| Error::BadDome {
        spec: format!("rings:{spec}"),
        reason,
    };
    let mut dirs = Vec::new();
    for part in spec.split(',').map(str::trim) {
        let (e, c) = part
            .split_once(['x', 'X'])
            .ok_or_else(|| bad(format!("{part:?} is not ELEVATIONxCOUNT, e.g. 30x8")))?;
        let e: f64 = e
            .trim()
            .parse()
            .ok()
            .filter(|e: &f64| *e > 0.0 && *e <= 90.0)
            .ok_or_else(|| bad(format!("elevation {e:?} must be a number in (0, 90]")))?;
        let c: usize = c
            .trim()
            .parse()
            .ok()
            .filter(|c| *c > 0)
            .ok_or_else(|| bad(format!("count {c:?} must be a positive integer")))?;
        if c > MAX_LIGHTS - dirs.len() {
            return Err(bad(format!(
                "{} lights or more: a dome has at most {MAX_LIGHTS}",
                dirs.len() as u128 + c as u128
            )));
        }
        let (z, r) = (e.to_radians().sin(), e.to_radians().cos());
        for k in 0..c {
            let phi = 2.0 * PI * k as f64 / c as f64;
            dirs.push([r * phi.cos(), r * phi.sin(), z]);
        }
    }
    Ok(LightSet::from_dirs(dirs))
}

/// A dome from a `--dome` spec: `rings:…` or `fibonacci:N` (the same as `--dirs N`).
pub fn parse(spec: &str, min_elevation_deg: f64) -> Result<LightSet> {
    if let Some(r) = spec.strip_prefix("rings:") {
        rings(r)
    } else if let Some(n) = spec.strip_prefix("fibonacci:") {
        let n = n.trim().parse().map_err(|_| Error::BadDome {
            spec: spec.into(),
            reason: format!("{n:?} is not a light count"),
        })?;
        fibonacci(n, min_elevation_deg)
    } else {
        Err(Error::BadDome {
            spec: format!("{spec:?}"),
            reason: "expected rings:E1xC1,E2xC2,... or fibonacci:N".into(),
        })
    }
}

/// How a dome's lights share the hemisphere: the solid angle each stands for, as the
/// quadrature weights of integrals over the dome (the companion maps' ambient occlusion and
/// bent normal: `crate::maps`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quadrature {
    /// Spherical Fibonacci above `min_elevation_deg` (equal-area in z): each light stands for
    /// 2π(1 − sin e_min)/n sr of the cap it samples.
    Fibonacci {
        /// The dome's lowest elevation, degrees.
        min_elevation_deg: f64,
    },
    /// Rings: a ring at elevation eᵢ stands for the band between the midpoints to its
    /// neighbours' elevations (the lowest ring's band reaches as far below it as half the gap
    /// to the next, at most to the horizon; the highest's as far above, at most to the zenith;
    /// a single ring the whole hemisphere), shared equally by its lights.
    Rings,
    /// Lights of a file (`.lp`), whose cells are unknown: equal weights of 2π/n sr each.
    Equal,
}

impl Quadrature {
    /// The solid angle (sr) each light of `lights` stands for; 0 for lights at or below the
    /// horizon.
    pub fn weights(self, lights: &LightSet) -> Vec<f64> {
        let n = lights.len().max(1) as f64;
        let above = |d: &[f64; 3]| d[2] > 0.0;
        match self {
            Quadrature::Fibonacci { min_elevation_deg } => {
                let w = 2.0 * PI * (1.0 - min_elevation_deg.to_radians().sin()) / n;
                lights
                    .dirs
                    .iter()
                    .map(|d| if above(d) { w } else { 0.0 })
                    .collect()
            }
            Quadrature::Equal => {
                let w = 2.0 * PI / n;
                lights
                    .dirs
                    .iter()
                    .map(|d| if above(d) { w } else { 0.0 })
                    .collect()
            }
            Quadrature::Rings => {
                // Rings by their z (equal to rounding: a light set normalises its directions).
                const SAME: f64 = 1e-9;
                let mut zs: Vec<f64> = lights
                    .dirs
                    .iter()
                    .map(|d| d[2])
                    .filter(|z| *z > 0.0)
                    .collect();
                zs.sort_by(f64::total_cmp);
                zs.dedup_by(|a, b| (*a - *b).abs() < SAME);
                let e: Vec<f64> = zs.iter().map(|z| z.clamp(-1.0, 1.0).asin()).collect();
                let half = PI / 2.0;
                let band = |i: usize| -> f64 {
                    let lo = match i {
                        0 if e.len() > 1 => (e[0] - (e[1] - e[0]) / 2.0).max(0.0),
                        0 => 0.0,
                        _ => (e[i - 1] + e[i]) / 2.0,
                    };
                    let last = e.len() - 1;
                    let hi = match i {
                        _ if i == last && last > 0 => (e[i] + (e[i] - e[i - 1]) / 2.0).min(half),
                        _ if i == last => half,
                        _ => (e[i] + e[i + 1]) / 2.0,
                    };
                    2.0 * PI * (hi.sin() - lo.sin())
                };
                let ring = |z: f64| zs.iter().position(|r| (r - z).abs() < SAME);
                let mut count = vec![0usize; zs.len()];
                for d in &lights.dirs {
                    if let Some(i) = ring(d[2]).filter(|_| above(d)) {
                        count[i] += 1;
                    }
                }
                lights
                    .dirs
                    .iter()
                    .map(|d| match ring(d[2]) {
                        Some(i) if above(d) => band(i) / count[i] as f64,
                        _ => 0.0,
                    })
                    .collect()
            }
        }
    }

    /// The rule in words, as the maps' file records it.
    pub fn words(self) -> String {
        match self {
            Quadrature::Fibonacci { min_elevation_deg } => {
                format!("fibonacci equal-area above {min_elevation_deg}°")
            }
            Quadrature::Rings => "rings: per-ring band solid angles".into(),
            Quadrature::Equal => "equal weights (light file)".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fibonacci_stays_above_min_elevation_and_is_balanced() {
        let set = fibonacci(64, 5.0).unwrap();
        assert_eq!(set.len(), 64);
        let mut sum = [0.0; 2];
        for (i, d) in set.dirs.iter().enumerate() {
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-12);
            assert!(set.elevation_deg(i) > 5.0 && set.elevation_deg(i) < 90.0);
            sum[0] += d[0];
            sum[1] += d[1];
        }
        // The golden-angle spiral spreads azimuths evenly: the horizontal mean is small.
        assert!(
            sum[0].abs() < 0.1 * 64.0 && sum[1].abs() < 0.1 * 64.0,
            "{sum:?}"
        );
        // Equal area: half the lights lie above the median z of the cap.
        let z_mid = (5f64.to_radians().sin() + 1.0) / 2.0;
        assert_eq!(set.dirs.iter().filter(|d| d[2] > z_mid).count(), 32);
        assert!(fibonacci(0, 5.0).is_err());
        assert!(fibonacci(4, 90.0).is_err());
    }

    #[test]
    fn rings_match_the_spec() {
        let set = parse("rings:10x4, 45x8,90x1", 5.0).unwrap();
        assert_eq!(set.len(), 13);
        assert!((set.elevation_deg(0) - 10.0).abs() < 1e-9);
        assert!((set.elevation_deg(5) - 45.0).abs() < 1e-9);
        assert!((set.dirs[1][1] - 10f64.to_radians().cos()).abs() < 1e-12); // 90° azimuth
        assert!(set.dirs[12][2] == 1.0 && set.dirs[12][0].abs() < 1e-15);
        for bad in [
            "rings:",
            "rings:10",
            "rings:0x4",
            "rings:10x0",
            "rings:95x2",
            "grid:3",
        ] {
            let e = parse(bad, 5.0).unwrap_err();
            assert!(matches!(&e, Error::BadDome { .. }), "{bad}: {e}");
            assert!(!e.to_string().contains("--"), "{bad}: {e}");
        }
        for huge in [
            "rings:30x100000000000",
            "rings:30x1000000,60x1000000",
            "fibonacci:1000000000000",
        ] {
            let e = parse(huge, 5.0).unwrap_err().to_string();
            assert!(e.contains("at most 1048576"), "{huge}: {e}");
        }
        assert_eq!(
            parse("fibonacci:7", 5.0).unwrap(),
            fibonacci(7, 5.0).unwrap()
        );
    }

    #[test]
    fn quadrature_weights_sum_to_the_sampled_solid_angle() {
        let f = fibonacci(100, 10.0).unwrap();
        let w = Quadrature::Fibonacci {
            min_elevation_deg: 10.0,
        }
        .weights(&f);
        let cap = 2.0 * PI * (1.0 - 10f64.to_radians().sin());
        assert!((w.iter().sum::<f64>() - cap).abs() < 1e-12);
        // Rings 15, 45, 75 (8 lights each) and the zenith: bands 0–30, 30–60, 60–82.5, 82.5–90.
        let r = rings("15x8,45x8,75x8,90x1").unwrap();
        let w = Quadrature::Rings.weights(&r);
        let s = |d: f64| d.to_radians().sin();
        let band = |lo: f64, hi: f64| 2.0 * PI * (s(hi) - s(lo));
        assert!(
            (w[0] - band(0.0, 30.0) / 8.0).abs() < 1e-12,
            "{w:?} {}",
            band(0.0, 30.0) / 8.0
        );
        assert!((w[8] - band(30.0, 60.0) / 8.0).abs() < 1e-12);
        assert!((w[16] - band(60.0, 82.5) / 8.0).abs() < 1e-12);
        assert!((w[24] - band(82.5, 90.0)).abs() < 1e-12);
        assert!((w.iter().sum::<f64>() - 2.0 * PI).abs() < 1e-12);
    }
}
