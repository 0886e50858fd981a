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
}
