//! Baselines the PTMs are compared with in the model table (issue #22): not products, only
//! fitted here to say what a PTM's numbers per texel buy over the classic alternatives.
//!
//! - Horizon map: K(l) = σ((h(φ) − e)/w), where e is the light's elevation and φ its azimuth,
//!   h is linear (periodic) between `azimuths` stored horizon elevations, and w is one edge
//!   width: `azimuths + 1` numbers per texel. Fitted per texel by maximum likelihood of the
//!   binomial deviance on the baked occluded fractions (damped Fisher scoring, as the
//!   logistic PTM fit does), so the comparison with the logistic PTM is like for like.
//! - AO micro-shadowing (Filament's `computeMicroShadowing(NoL, visibility)`, also Call of
//!   Duty's): one number per texel, the visibility v; aperture = 1/√(1 − v), s =
//!   saturate(NoL·aperture), K = 1 − s². v is NOT fitted: it is the bake's cosine-weighted
//!   visibility over the training lights, which is what an engine's AO bake stores.
use std::f64::consts::TAU;

/// σ, the logistic function.
fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// Elevation (radians) and azimuth in [0, 2π) of a unit light direction (z up).
pub fn elevation_azimuth(d: [f64; 3]) -> (f64, f64) {
    (
        d[2].clamp(-1.0, 1.0).asin(),
        d[1].atan2(d[0]).rem_euclid(TAU),
    )
}

/// The two stored azimuths `φ` lies between and the weight of the second: h(φ) = (1 − t)·h[a]
/// + t·h[b], periodic in φ.
fn bracket(phi: f64, azimuths: usize) -> (usize, usize, f64) {
    let x = phi.rem_euclid(TAU) / TAU * azimuths as f64;
    let a = (x.floor() as usize).min(azimuths - 1);
    (a, (a + 1) % azimuths, x - a as f64)
}

/// One texel's horizon map: the horizon elevation (radians) at `h.len()` equally spaced
/// azimuths starting at φ = 0, and the edge width `w` (radians).
#[derive(Clone, Debug, PartialEq)]
pub struct Horizon {
    /// Horizon elevations, radians, at azimuths 2π·j/len.
    pub h: Vec<f64>,
    /// Edge width of the logistic step, radians.
    pub w: f64,
}

/// Bounds on the edge width: below the lower one a separable texel (K exactly a step on the
/// training lights) would drive w to 0 and Newton would not stop; above the upper one the step
/// is a flat K (no texel needs wider).
const W_MIN: f64 = 2e-3;
const W_MAX: f64 = 4.0;

impl Horizon {
    /// K at a light of elevation `e` and azimuth `phi`.
    pub fn k(&self, e: f64, phi: f64) -> f64 {
        let (a, b, t) = bracket(phi, self.h.len());
        sigmoid(((1.0 - t) * self.h[a] + t * self.h[b] - e) / self.w)
    }

    /// Fits `azimuths` horizon elevations and the width to occluded fractions `k[i]` seen at
    /// lights `(e[i], phi[i])`, by maximum likelihood of the binomial deviance.
    pub fn fit(azimuths: usize, lights: &[(f64, f64)], k: &[f32]) -> Horizon {
        assert!(azimuths >= 1 && lights.len() == k.len());
        let n = azimuths + 1;
        // Start: per azimuth, the elevation below which the occluded fraction of its lights
        // would lie if lights were uniform in sin(e) (a Fibonacci dome is), so a pure step
        // starts at its horizon.
        let (mut occ, mut wt) = (vec![0.0; azimuths], vec![0.0; azimuths]);
        let (mut zlo, mut zhi) = (1f64, -1f64);
        for (&(e, phi), &kk) in lights.iter().zip(k) {
            let (a, b, t) = bracket(phi, azimuths);
            occ[a] += (1.0 - t) * kk as f64;
            wt[a] += 1.0 - t;
            occ[b] += t * kk as f64;
            wt[b] += t;
            zlo = zlo.min(e.sin());
            zhi = zhi.max(e.sin());
        }
        let mut h: Vec<f64> = occ
            .iter()
            .zip(&wt)
            .map(|(o, w)| {
                let f = if *w > 0.0 { o / w } else { 0.5 };
                (zlo + f * (zhi - zlo)).clamp(-1.0, 1.0).asin()
            })
            .collect();
        let mut lw = 0.1f64.ln();
        let loss = |h: &[f64], lw: f64| -> f64 {
            let m = Horizon {
                h: h.to_vec(),
                w: lw.exp(),
            };
            lights
                .iter()
                .zip(k)
                .map(|(&(e, phi), &kk)| {
                    let p = m.k(e, phi).clamp(1e-12, 1.0 - 1e-12);
                    let kk = kk as f64;
                    -(kk * p.ln() + (1.0 - kk) * (1.0 - p).ln())
                })
                .sum()
        };
        let mut cur = loss(&h, lw);
        let mut damp = 1e-3;
        for _ in 0..60 {
            // Fisher scoring in (h, ln w): gradient Jᵀ(p − k), information JᵀWJ, W = p(1 − p).
            let w = lw.exp();
            let mut g = vec![0.0; n];
            let mut info = vec![0.0; n * n];
            for (&(e, phi), &kk) in lights.iter().zip(k) {
                let (a, b, t) = bracket(phi, azimuths);
                let z = ((1.0 - t) * h[a] + t * h[b] - e) / w;
                let p = sigmoid(z);
                let r = p - kk as f64;
                let wi = (p * (1.0 - p)).max(1e-9);
                let jac = [(a, (1.0 - t) / w), (b, t / w), (azimuths, -z)];
                for &(i, ji) in &jac {
                    g[i] += r * ji;
                    for &(j, jj) in &jac {
                        info[i * n + j] += wi * ji * jj;
                    }
                }
            }
            let mut improved = false;
            for _ in 0..12 {
                let mut m = info.clone();
                for i in 0..n {
                    m[i * n + i] += damp * (1.0 + info[i * n + i]);
                }
                let Some(step) = solve(&mut m, &g, n) else {
                    damp *= 10.0;
                    continue;
                };
                let h2: Vec<f64> = h
                    .iter()
                    .zip(&step)
                    .map(|(x, s)| (x - s).clamp(-1.6, 1.6))
                    .collect();
                let lw2 = (lw - step[azimuths]).clamp(W_MIN.ln(), W_MAX.ln());
                let l2 = loss(&h2, lw2);
                if l2 <= cur {
                    improved = cur - l2 > 1e-10 * (1.0 + cur);
                    (h, lw, cur) = (h2, lw2, l2);
                    damp = (damp * 0.3).max(1e-9);
                    break;
                }
                damp *= 10.0;
            }
            if !improved {
                break;
            }
        }
        Horizon { h, w: lw.exp() }
    }
}

/// Solves the `n`×`n` system `m`·x = `b` by Gaussian elimination with partial pivoting; None
/// if it is singular.
fn solve(m: &mut [f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut x = b.to_vec();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i * n + c].abs().total_cmp(&m[j * n + c].abs()))?;
        if m[p * n + c].abs() < 1e-300 {
            return None;
        }
        for j in 0..n {
            m.swap(c * n + j, p * n + j);
        }
        x.swap(c, p);
        for r in c + 1..n {
            let f = m[r * n + c] / m[c * n + c];
            for j in c..n {
                m[r * n + j] -= f * m[c * n + j];
            }
            x[r] -= f * x[c];
        }
    }
    for c in (0..n).rev() {
        let s: f64 = (c + 1..n).map(|j| m[c * n + j] * x[j]).sum();
        x[c] = (x[c] - s) / m[c * n + c];
    }
    Some(x)
}

/// Filament's micro-shadowing as occlusion: K = 1 − saturate(NoL/√(1 − v))² for visibility
/// `v` (1 = unoccluded, where K is 0 for every light above the plane).
pub fn micro_shadow_k(nol: f64, visibility: f64) -> f64 {
    let open = 1.0 - visibility.clamp(0.0, 1.0);
    if nol <= 0.0 {
        return 1.0;
    }
    if open <= 0.0 {
        return 0.0;
    }
    let s = (nol / open.sqrt()).clamp(0.0, 1.0);
    1.0 - s * s
}

/// The cosine-weighted visibility Σ(1 − kᵢ)·cos θᵢ / Σ cos θᵢ over the training lights (`nol`
/// their cosines): the AO a bake stores, the one number of the micro-shadowing baseline.
pub fn cosine_visibility(nol: &[f64], k: &[f32]) -> f64 {
    let (s, w) = nol.iter().zip(k).fold((0.0, 0.0), |(s, w), (&c, &kk)| {
        (s + c.max(0.0) * (1.0 - kk as f64), w + c.max(0.0))
    });
    if w > 0.0 {
        s / w
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Fibonacci-like dome above 5°: (elevation, azimuth) pairs, uniform in sin(e).
    fn dome(n: usize) -> Vec<(f64, f64)> {
        let z0 = 5f64.to_radians().sin();
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = z0 + (1.0 - z0) * (i as f64 + 0.5) / n as f64;
                (z.asin(), (i as f64 * golden).rem_euclid(TAU))
            })
            .collect()
    }

    #[test]
    fn horizon_fit_recovers_an_exact_step() {
        let truth = Horizon {
            h: (0..8)
                .map(|j| 0.35 + 0.25 * (TAU * j as f64 / 8.0).cos())
                .collect(),
            w: 1e-6,
        };
        let lights = dome(2000);
        let k: Vec<f32> = lights
            .iter()
            .map(|&(e, phi)| if truth.k(e, phi) > 0.5 { 1.0 } else { 0.0 })
            .collect();
        let fit = Horizon::fit(8, &lights, &k);
        for (a, b) in fit.h.iter().zip(&truth.h) {
            assert!((a - b).abs() < 0.04, "h {a} vs {b}");
        }
        assert!(fit.w < 0.02, "a step fits a narrow edge, got w = {}", fit.w);
    }

    #[test]
    fn horizon_fit_recovers_a_soft_edge() {
        let truth = Horizon {
            h: vec![0.2, 0.5, 0.3, 0.6, 0.25, 0.4, 0.45, 0.3, 0.5, 0.35],
            w: 0.08,
        };
        let lights = dome(4000);
        let k: Vec<f32> = lights
            .iter()
            .map(|&(e, phi)| truth.k(e, phi) as f32)
            .collect();
        let fit = Horizon::fit(10, &lights, &k);
        for (a, b) in fit.h.iter().zip(&truth.h) {
            assert!((a - b).abs() < 0.02, "h {a} vs {b}");
        }
        assert!((fit.w - truth.w).abs() < 0.01, "w {}", fit.w);
    }

    #[test]
    fn horizon_of_an_unoccluded_texel_lies_below_every_light() {
        let lights = dome(300);
        let fit = Horizon::fit(8, &lights, &vec![0.0; lights.len()]);
        for &(e, phi) in &lights {
            assert!(fit.k(e, phi) < 0.05, "K {} at e = {e}", fit.k(e, phi));
        }
    }

    #[test]
    fn micro_shadowing_of_a_lit_texel_is_unoccluded() {
        let lights = dome(200);
        let nol: Vec<f64> = lights.iter().map(|l| l.0.sin()).collect();
        let v = cosine_visibility(&nol, &vec![0.0; nol.len()]);
        assert!((v - 1.0).abs() < 1e-12);
        assert!(nol.iter().all(|&c| micro_shadow_k(c, v) == 0.0));
        // Fully occluded: visibility 0, aperture 1, K = 1 − cos²θ.
        let v0 = cosine_visibility(&nol, &vec![1.0; nol.len()]);
        assert_eq!(v0, 0.0);
        assert!((micro_shadow_k(0.6, v0) - 0.64).abs() < 1e-12);
        // K falls as the visibility rises, at every elevation.
        assert!(micro_shadow_k(0.3, 0.2) > micro_shadow_k(0.3, 0.7));
    }
}
