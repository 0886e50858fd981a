//! Area lights on K (#22): the twin's `ptm_k_area` (K averaged over a light's footprint, from
//! the predictor's jet at the footprint's mean) against the Monte Carlo mean of
//! `Ptm::eval_dir` over the light's directions (`reference::mc_k`), for a learned basis, a
//! logistic ptm11 and an identity ptm6 fitted to one synthetic bake, spheres and rectangles of
//! three sizes from 60° down to 4° above the horizon; a point light's K unchanged bit for bit;
//! finite K in [0, 1] at the extremes; and the GPU equal to the twin under area lights.

mod common;

use common::*;
use ptm_format::Ptm;
use ptm_runtime::cpu::shade::{cap_moments, Twin};
use ptm_runtime::layout::LightGpu;
use ptm_runtime::reference::mc_k;
use ptm_runtime::scene::SceneBuffers;
use ptm_runtime::{cpu, gpu, Light, Scene};

/// The scene buffers of `ptm` seen 1:1 (level 0 only), no lights.
fn buffers(ptm: &Ptm) -> SceneBuffers {
    let s = Scene::over_ptm(ptm.clone(), 1, [ptm.width as u32, ptm.height as u32]);
    s.prepare().unwrap()
}

/// The centre of texel (x, y) on the plane (row 0 at the far edge).
fn texel_centre(ptm: &Ptm, x: usize, y: usize) -> [f32; 2] {
    [
        ((x as f64 + 0.5) / ptm.width as f64 * ptm.tile[0]) as f32,
        ((1.0 - (y as f64 + 0.5) / ptm.height as f64) * ptm.tile[1]) as f32,
    ]
}

/// A light at distance 2 from `p` in direction (elevation, azimuth), subtending the angular
/// radius `rho`: a sphere of radius 2·sin ρ, or a square of half-side 2·tan ρ facing down.
fn light_at(p: [f32; 2], elevation_deg: f64, azimuth: f64, rho: f64, rect: bool) -> LightGpu {
    let (e, d) = (elevation_deg.to_radians(), 2.0);
    let c = [
        p[0] as f64 + d * e.cos() * azimuth.cos(),
        p[1] as f64 + d * e.cos() * azimuth.sin(),
        d * e.sin(),
    ];
    LightGpu {
        position: c.map(|x| x as f32),
        radius: if rect { 0.0 } else { (d * rho.sin()) as f32 },
        color: [1.0; 3],
        shape: u32::from(rect),
        half: if rect {
            [(d * rho.tan()) as f32; 2]
        } else {
            [0.0; 2]
        },
        axis: [1.0, 0.0],
    }
}

/// K under `light` from texel (x, y)'s centre: the twin's at the light's centre (`ptm_k`,
/// today's) and over its footprint (`ptm_k_area`).
fn twin_k(twin: &Twin, ptm: &Ptm, x: usize, y: usize, light: &LightGpu) -> (f32, f32) {
    let p = texel_centre(ptm, x, y);
    let c = twin.ptm_coeffs(p, 0.0);
    let to_light = [
        light.position[0] - p[0],
        light.position[1] - p[1],
        light.position[2],
    ];
    let d =
        (to_light[0] * to_light[0] + to_light[1] * to_light[1] + to_light[2] * to_light[2]).sqrt();
    let l = to_light.map(|v| v / d);
    let f = twin.ptm_footprint(l, to_light, d, light);
    (twin.ptm_k(&c, l), twin.ptm_k_area(&c, l, &f))
}

/// RMS of (K at the centre − Monte Carlo, K over the footprint − Monte Carlo) over every texel
/// and three azimuths, for one light size, elevation and shape.
fn errors(twin: &Twin, ptm: &Ptm, rho: f64, elevation: f64, rect: bool) -> (f64, f64) {
    errors_of(twin, ptm, |p, az| light_at(p, elevation, az, rho, rect))
}

/// As [`errors`] for the light `light(cloth point, azimuth)`.
fn errors_of(twin: &Twin, ptm: &Ptm, light: impl Fn([f32; 2], f64) -> LightGpu) -> (f64, f64) {
    let (mut centre, mut area, mut n) = (0.0, 0.0, 0.0);
    for y in 0..ptm.height {
        for x in 0..ptm.width {
            for a in 0..3 {
                let az = 0.3 + 2.1 * a as f64;
                let p = texel_centre(ptm, x, y);
                let light = light(p, az);
                let key = ((y * ptm.width + x) * 3 + a) as u64;
                let mc = mc_k(ptm, [x, y], p, &light, 576, key) as f64;
                let (k0, k) = twin_k(twin, ptm, x, y, &light);
                centre += (k0 as f64 - mc).powi(2);
                area += (k as f64 - mc).powi(2);
                n += 1.0;
            }
        }
    }
    ((centre / n).sqrt(), (area / n).sqrt())
}

#[test]
fn k_over_a_gaussian_footprint_follows_monte_carlo() {
    // A Gaussian light of the variance of the square of half-angle ρ (σ = half/√3), against the
    // reference that draws its points from the Gaussian: the bounds of the square's test, but
    // 0.07 at ρ 0.3 (its tails reach 3σ, 1.7 times the square's half-side, where K's second-order
    // expansion about the mean errs more: 0.065 measured for logistic ptm11 at 20°), and at
    // most ¾ of the error of K at the centre wherever that is visible.
    let mut failures = Vec::new();
    for (name, ptm) in fitted_files() {
        let p = buffers(&ptm);
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        for (rho, bound) in [(0.03, 0.003), (0.1, 0.015), (0.3, 0.07)] {
            for elevation in [30.0, 20.0, 10.0] {
                let (centre, area) = errors_of(&twin, &ptm, |p, az| {
                    let mut l = light_at(p, elevation, az, rho, true);
                    l.shape = LightGpu::GAUSSIAN;
                    l.half = l.half.map(|h| h / 3f32.sqrt());
                    l
                });
                let what = format!("{name:>14} Gaussian ρ {rho:.2} elevation {elevation:>2}°");
                eprintln!("{what}: RMS K − MC centre {centre:.4}, footprint {area:.4}");
                if area > bound || (centre > 0.02 && area > 0.75 * centre) {
                    failures.push(format!("{what}: {area:.4} (centre {centre:.4})"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn k_under_a_turned_rectangle_follows_monte_carlo() {
    // A 3:1 rectangle (the square's area) turned 30° and 60° about the vertical: its footprint's
    // moments are found in its own frame (`ptm_footprint`). Elongated, its second-order error
    // is above the square's (a half-angle √3 times longer), so the bound is the axis-aligned
    // 3:1 and 1:3 rectangles' (turned 0° and 90°, the untouched path) error with 20 % to
    // spare, or the square's bound, against the reference that samples the turned rectangle;
    // and at most ¾ of the error of K at the centre wherever that is visible.
    let mut failures = Vec::new();
    for (name, ptm) in fitted_files() {
        let p = buffers(&ptm);
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        for (rho, bound) in [(0.1, 0.015f64), (0.3, 0.06)] {
            for elevation in [30.0, 10.0] {
                let run = |deg: f32| {
                    errors_of(&twin, &ptm, |p, az| {
                        let mut l = light_at(p, elevation, az, rho, true);
                        l.half = [l.half[0] * 3f32.sqrt(), l.half[1] / 3f32.sqrt()];
                        let (s, c) = deg.to_radians().sin_cos();
                        l.axis = [c, s];
                        l
                    })
                };
                let aligned = run(0.0).1.max(run(90.0).1);
                for deg in [30.0f32, 60.0] {
                    let (centre, area) = run(deg);
                    let what = format!(
                        "{name:>14} 3:1 rectangle turned {deg}° ρ {rho:.2} elevation {elevation:>2}°"
                    );
                    eprintln!(
                        "{what}: RMS K − MC centre {centre:.4}, footprint {area:.4} (axis-aligned \
                         {aligned:.4})"
                    );
                    if area > bound.max(1.2 * aligned) || (centre > 0.02 && area > 0.75 * centre) {
                        failures.push(format!("{what}: {area:.4} (centre {centre:.4})"));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn k_over_the_footprint_follows_monte_carlo_where_k_at_the_centre_does_not() {
    // Angular radii: small (a bulb across the room), medium, large (a softbox close by); the
    // synthetic horizons lie between 3° and 37°.
    let mut failures = Vec::new();
    for (name, ptm) in fitted_files() {
        let p = buffers(&ptm);
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        for rect in [false, true] {
            for (rho, bound) in [(0.03, 0.003), (0.1, 0.015), (0.3, 0.06)] {
                for elevation in [30.0, 20.0, 10.0, 4.0] {
                    let (centre, area) = errors(&twin, &ptm, rho, elevation, rect);
                    let what = format!(
                        "{name:>14} {} ρ {rho:.2} elevation {elevation:>2}°",
                        if rect { "square" } else { "sphere" }
                    );
                    eprintln!("{what}: RMS K − MC centre {centre:.4}, footprint {area:.4}");
                    // Within the bound, and (where the centre is off by a visible 0.02) at
                    // most ¾ of the centre's error.
                    if area > bound || (centre > 0.02 && area > 0.75 * centre) {
                        failures.push(format!("{what}: {area:.4} (centre {centre:.4})"));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn a_point_light_keeps_k_at_its_centre_bit_for_bit() {
    for (name, ptm) in fitted_files() {
        let p = buffers(&ptm);
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        for (i, elevation) in [89.0, 45.0, 10.0, 0.5].into_iter().enumerate() {
            let light = light_at(
                texel_centre(&ptm, 3, 5),
                elevation,
                0.7 * i as f64,
                0.0,
                false,
            );
            let (k0, k) = twin_k(&twin, &ptm, 3, 5, &light);
            assert_eq!(k0.to_bits(), k.to_bits(), "{name} at {elevation}°");
            let mc = mc_k(&ptm, [3, 5], texel_centre(&ptm, 3, 5), &light, 64, 1);
            assert!((mc - k0).abs() < 2e-5, "{name}: reference {mc} vs {k0}");
        }
    }
}

#[test]
fn k_stays_finite_and_in_range_at_the_extremes() {
    for (name, ptm) in fitted_files() {
        let p = buffers(&ptm);
        let twin = Twin {
            p: &p,
            blur: None,
            opacity: None,
        };
        let at = texel_centre(&ptm, 2, 6);
        let mut lights = Vec::new();
        for rect in [false, true] {
            // Grazing the horizon, tiny to huge; at the zenith, huge.
            for elevation in [0.01, 0.5, 3.0, 90.0] {
                for rho in [1e-6, 0.01, 0.5, 1.5] {
                    lights.push(light_at(at, elevation, 1.0, rho, rect));
                }
            }
        }
        // A sphere around the point (R > d), a 1000:1 rectangle, one lying on the cloth.
        let mut around = light_at(at, 30.0, 0.0, 0.5, false);
        around.radius = 5.0;
        let mut thin = light_at(at, 20.0, 2.0, 0.5, true);
        thin.half = [3.0, 0.003];
        let mut flat = light_at(at, 1e-4, 2.0, 0.2, true);
        flat.half = [50.0, 50.0];
        lights.extend([around, thin, flat]);
        for light in &lights {
            let (_, k) = twin_k(&twin, &ptm, 2, 6, light);
            assert!((0.0..=1.0).contains(&k), "{name}: K {k} under {light:?}");
        }
    }
}

#[test]
fn cap_moments_are_those_of_the_clipped_weighted_disc() {
    // Midpoint quadrature over the unit disc (radius rho) of the weight max(0, z − r·x·rho):
    // mean and variance of x and the variance of y, against the closed form, unclipped
    // (q = rho·r/z < 1) and clipped (q > 1) and at the seam.
    let n = 1200;
    for (rho, r, z) in [
        (0.2f64, 0.6f64, 0.8f64),
        (0.5, 0.95, 0.31),
        (1.0, 0.999, 0.045),
        (0.3, 0.8, 0.24),
        (0.7, 1.0, 0.0),
    ] {
        let z = z.max(1e-4);
        let (mut w, mut sx, mut sxx, mut syy) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            for j in 0..n {
                let x = -1.0 + (2.0 * i as f64 + 1.0) / n as f64;
                let y = -1.0 + (2.0 * j as f64 + 1.0) / n as f64;
                if x * x + y * y > 1.0 {
                    continue;
                }
                let wt = (z - r * x * rho).max(0.0);
                w += wt;
                sx += wt * x;
                sxx += wt * x * x;
                syy += wt * y * y;
            }
        }
        let (mx, vx, vy) = (sx / w, sxx / w - (sx / w).powi(2), syy / w);
        let got = cap_moments(rho as f32, r as f32, z as f32);
        let want = [rho * mx, rho * rho * vx, rho * rho * vy];
        for k in 0..3 {
            assert!(
                (got[k] as f64 - want[k]).abs() < 2e-3 * rho * rho.max(0.1),
                "rho {rho}, r {r}, z {z}: moment {k} {} vs {}",
                got[k],
                want[k]
            );
        }
    }
}

#[test]
fn gpu_matches_twin_under_large_and_grazing_area_lights() {
    let g = gpu();
    for (name, ptm) in fitted_files() {
        let mut s = Scene::over_ptm(ptm, 3, [72, 48]);
        s.lights = vec![
            // Large, low: its cap is clipped by the horizon.
            light([0.5, 1.5, 0.4], 1.0, 2.0),
            // A point light and a small one.
            light([2.0, 2.5, 2.0], 0.0, 4.0),
            light([-1.0, -0.5, 1.5], 0.05, 4.0),
            Light {
                position: [3.5, 0.5, 0.6],
                radius: 0.0,
                rect: Some([1.5, 0.4]),
                square_box: false,
                rect_angle_deg: 0.0,
                gaussian: None,
                distant: false,
                intensity: 3.0,
                color: [1.0, 0.9, 0.8],
            },
        ];
        let p = s.prepare().unwrap();
        let (gi, _) = gpu::render(&g, &p).unwrap();
        let ci = cpu::render(&p);
        let d = gi.max_abs_diff(&ci).unwrap();
        let peak = ci.pixels.iter().map(|p| p[0]).fold(0f32, f32::max);
        eprintln!("{name}: max |gpu − cpu| = {d:.2e} (peak {peak:.3})");
        assert!(peak > 0.1, "{name}: too dark to test anything");
        assert!(d <= 1e-3, "{name}: GPU and CPU twin differ by {d}");
    }
}
