//! Distant lights (`Light::distant`): K from the basis terms evaluated once per frame
//! (`cpu::shade::distant_terms`, the shader's `distant_k`) equal to K over the footprint
//! evaluated per pixel and to the Monte Carlo mean of `Ptm::eval_dir` over the light's cone, for
//! a learned basis, a logistic ptm11 and an identity ptm6; a whole frame equal to a sphere so
//! far away that its direction barely changes over the view; the caster's penumbra against
//! the Monte Carlo reference; the GPU equal to the twin; and what is refused.

mod common;

use common::*;
use ptm_format::{Basis, Ptm};
use ptm_runtime::compare::mean_abs_diff;
use ptm_runtime::cpu::shade::Twin;
use ptm_runtime::reference::{mc_k, render_reference};
use ptm_runtime::synthetic::leaves;
use ptm_runtime::{cpu, gpu, Blur, Light, Scene};

/// A white distant light `elevation_deg` above the horizon at azimuth `azimuth` (radians),
/// of angular radius `rho` (radians).
fn distant(elevation_deg: f32, azimuth: f32, rho: f32, intensity: f32) -> Light {
    let e = elevation_deg.to_radians();
    Light {
        position: [e.cos() * azimuth.cos(), e.cos() * azimuth.sin(), e.sin()],
        radius: rho,
        distant: true,
        intensity,
        ..Light::default()
    }
}

/// The centre of texel (x, y) on the plane (row 0 at the far edge).
fn texel_centre(ptm: &Ptm, x: usize, y: usize) -> [f32; 2] {
    [
        ((x as f64 + 0.5) / ptm.width as f64 * ptm.tile[0]) as f32,
        ((1.0 - (y as f64 + 0.5) / ptm.height as f64) * ptm.tile[1]) as f32,
    ]
}

#[test]
fn k_from_the_per_frame_terms_equals_the_per_pixel_footprint_and_follows_monte_carlo() {
    // Per texel: distant_k (terms once per frame) against ptm_k_area at the same footprint
    // (per pixel, as a local light's): the same expansion, so equal to f32 rounding; and both
    // against the Monte Carlo mean over the cone. A point light (ρ 0) is K at its direction.
    let mut failures = Vec::new();
    for (name, ptm) in fitted_files() {
        for (rho, bound) in [(0.0f32, 2e-5), (0.03, 0.003), (0.1, 0.015), (0.3, 0.06)] {
            for elevation in [60.0f32, 30.0, 10.0, 4.0] {
                let mut s = Scene::over_ptm(ptm.clone(), 1, [8, 8]);
                s.lights = vec![distant(elevation, 0.9, rho, 1.0)];
                let p = s.prepare().unwrap();
                assert!(p.variant.distant, "{name}: no distant variant");
                let twin = Twin {
                    p: &p,
                    blur: None,
                    opacity: None,
                };
                let light = &p.lights[0];
                let l = light.position;
                let (mut same, mut rms, mut n) = (0f64, 0f64, 0f64);
                for y in 0..ptm.height {
                    for x in 0..ptm.width {
                        let c = twin.ptm_coeffs(texel_centre(&ptm, x, y), 0.0);
                        let k = twin.distant_k(&c, 0);
                        let per_pixel = match rho > 0.0 {
                            true => twin.ptm_k_area(&c, l, &twin.ptm_footprint(l, l, 1.0, light)),
                            false => twin.ptm_k(&c, l),
                        };
                        same = same.max((k - per_pixel).abs() as f64);
                        let key = (y * ptm.width + x) as u64;
                        let mc = mc_k(&ptm, [x, y], texel_centre(&ptm, x, y), light, 576, key);
                        rms += (k as f64 - mc as f64).powi(2);
                        n += 1.0;
                    }
                }
                let rms = (rms / n).sqrt();
                let what = format!("{name:>14} ρ {rho:.2} elevation {elevation:>2}°");
                eprintln!("{what}: |terms − per pixel| ≤ {same:.1e}, RMS K − MC {rms:.4}");
                if same > 2e-5 || rms > bound {
                    failures.push(format!("{what}: {same:.1e}, {rms:.4} (bound {bound})"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A 48² view of `ptm` (or plain cloth) repeated twice under a leafy caster 0.4 above it.
fn shaded(ptm: Option<Ptm>, lights: Vec<Light>, blur: Blur) -> Scene {
    let mut s = match ptm {
        Some(p) => Scene::over_ptm(p, 2, [48, 48]),
        None => Scene::without_ptm(),
    };
    s.size = [48, 48];
    let v = s.view;
    let (cx, cy) = (0.5 * (v[0] + v[2]), 0.5 * (v[1] + v[3]));
    let half = 0.6 * (v[2] - v[0]).max(v[3] - v[1]);
    s.lights = lights;
    s.caster = Some(leaves(
        96,
        [cx - half, cy - half, cx + half, cy + half],
        0.4 * half,
    ));
    s.blur = blur;
    s
}

/// The sun `sun` and a sphere 1000 view widths away from the centre of `s`'s view in its
/// direction, subtending the same cone, giving the same irradiance.
fn far_sphere(s: &Scene, sun: &Light) -> Light {
    let v = s.view;
    let centre = [0.5 * (v[0] + v[2]), 0.5 * (v[1] + v[3])];
    let far = 1000.0 * (v[2] - v[0]);
    Light {
        position: [
            centre[0] + far * sun.position[0],
            centre[1] + far * sun.position[1],
            far * sun.position[2],
        ],
        radius: far * sun.radius.sin(),
        intensity: far * far * sun.intensity,
        ..Light::default()
    }
}

#[test]
fn a_distant_light_renders_as_a_sphere_so_far_away_its_direction_does_not_change() {
    // The same frame lit by the sun and by the far sphere: K, shadow and shading agree to what
    // the sphere's direction varies over the view (≈ 1e-3 rad), each part alone and together.
    let mut failures = Vec::new();
    for (name, ptm) in fitted_files() {
        let sun = distant(35.0, 2.2, 0.05, 1.0);
        let full = shaded(Some(ptm), vec![sun], Blur::Sat);
        let mut k_only = full.clone();
        k_only.caster = None;
        let mut shadow_only = full.clone();
        shadow_only.ptm = None;
        for (part, mut s) in [("K", k_only), ("shadow", shadow_only), ("both", full)] {
            let a = cpu::render(&s.prepare().unwrap());
            s.lights = vec![far_sphere(&s, &sun)];
            let b = cpu::render(&s.prepare().unwrap());
            let d = a.max_abs_diff(&b).unwrap();
            let peak = a.pixels.iter().map(|p| p[0]).fold(0f32, f32::max);
            eprintln!("{name}, {part}: max |sun − far sphere| = {d:.2e} (peak {peak:.3})");
            if !(peak > 0.3 && d < 1e-2 * peak) {
                failures.push(format!("{name}, {part}: {d:.2e} (peak {peak:.3})"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn the_suns_penumbra_follows_the_monte_carlo_reference() {
    // The caster's shadow under distant lights of three sizes and three elevations: each
    // method against a Monte Carlo reference over the cone, as a share of the lit radiance,
    // and against the far sphere's error on the same reference (the sun's kernel is the
    // sphere's ellipse with its apex's direction fixed, so it must do as well).
    let mut failures = Vec::new();
    for (rho, elevation) in [(0.02f32, 60.0f32), (0.1, 60.0), (0.1, 30.0), (0.25, 45.0)] {
        let sun = distant(elevation, 0.4, rho, 1.0);
        let s = shaded(None, vec![sun], Blur::Sat);
        let reference = render_reference(&s.prepare().unwrap(), 4096);
        let mut open = s.clone();
        open.caster = None;
        let lit = cpu::render(&open.prepare().unwrap());
        let lit = lit.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / lit.pixels.len() as f64;
        for blur in [Blur::Sat, Blur::Explicit, Blur::Mip, Blur::Separable] {
            let mut m = s.clone();
            m.blur = blur;
            let err = mean_abs_diff(&cpu::render(&m.prepare().unwrap()), &reference);
            let pct = 100.0 * err as f64 / lit;
            m.lights = vec![far_sphere(&m, &sun)];
            let err_far = mean_abs_diff(&cpu::render(&m.prepare().unwrap()), &reference);
            let pct_far = 100.0 * err_far as f64 / lit;
            let what = format!("ρ {rho} at {elevation}°, {}", blur.name());
            eprintln!("{what}: {pct:.2} % of lit (the far sphere {pct_far:.2} %)");
            let bound = match blur {
                Blur::Separable | Blur::Mip => 5.0,
                _ => 3.0,
            };
            if pct > bound || pct > 1.05 * pct_far + 0.05 {
                failures.push(format!("{what}: {pct:.2} % (far sphere {pct_far:.2} %)"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The GPU's image of `p` equals the twin's to 1e-3, and is bright enough (peak > 0.1) for
/// that to test anything.
fn gpu_matches_twin(g: &ptm_runtime::Gpu, p: &ptm_runtime::scene::SceneBuffers, what: &str) {
    let (gi, _) = gpu::render(g, p).unwrap();
    let ci = cpu::render(p);
    let d = gi.max_abs_diff(&ci).unwrap();
    let peak = ci.pixels.iter().map(|p| p[0]).fold(0f32, f32::max);
    eprintln!("{what}: max |gpu − cpu| = {d:.2e} (peak {peak:.3})");
    assert!(peak > 0.1, "{what}: too dark to test anything");
    assert!(d <= 1e-3, "{what}: GPU and CPU twin differ by {d}");
}

#[test]
fn gpu_matches_twin_under_distant_and_local_lights() {
    let g = gpu();
    for (name, ptm) in fitted_files() {
        // Mixed with a local light (both paths, a branch), and every light distant (the
        // distant path alone, `Variant::distant_only`).
        for (blur, local) in [
            (Blur::Sat, true),
            (Blur::Separable, true),
            (Blur::Mip, false),
        ] {
            let mut lights = vec![
                distant(40.0, 0.3, 0.05, 1.0),
                distant(12.0, 2.5, 0.0, 0.8),
                distant(70.0, 4.0, 0.2, 0.5),
            ];
            if local {
                lights.insert(2, light([0.5, 1.5, 0.9], 0.1, 2.0));
            }
            let s = shaded(Some(ptm.clone()), lights, blur);
            let p = s.prepare().unwrap();
            assert_eq!(p.variant.distant_only, !local);
            gpu_matches_twin(&g, &p, &format!("{name}, {}", blur.name()));
        }
    }
}

#[test]
fn a_glossy_cloth_under_distant_lights_alone_matches_its_twin() {
    // Every light distant (the distant-only variant) with a glossy receiver: its reflection's
    // imaginary light is a point, which the distant path must not take for a direction.
    let g = gpu();
    let ptm = fitted_files().remove(1).1;
    for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
        let mut s = shaded(
            Some(ptm.clone()),
            vec![distant(40.0, 0.3, 0.05, 1.0), distant(65.0, 2.0, 0.0, 0.5)],
            blur,
        );
        s.glossy = Some(ptm_runtime::scene::Glossy {
            roughness: 0.2,
            background: [0.2, 0.25, 0.35],
            f0: 0.5,
            environment: None,
        });
        let p = s.prepare().unwrap();
        assert!(p.variant.distant_only && p.variant.glossy);
        gpu_matches_twin(&g, &p, &format!("glossy, {}", blur.name()));
    }
}

#[test]
fn distant_lights_out_of_range_or_where_they_cannot_go_are_refused() {
    let ptm = random_ptm(Basis::Ptm6, 8, 8, 1);
    let mut s = Scene::over_ptm(ptm, 1, [16, 16]);
    for (light, want) in [
        (
            Light {
                position: [0.0; 3],
                distant: true,
                ..Light::default()
            },
            "non-zero vector",
        ),
        (distant(30.0, 0.0, 0.9, 1.0), "exceeds 45°"),
        (
            Light {
                rect: Some([1.0, 1.0]),
                ..distant(30.0, 0.0, 0.1, 1.0)
            },
            "rectangle or Gaussian",
        ),
    ] {
        s.lights = vec![light];
        let e = s.prepare().unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
    // More lights than the per-frame terms' uniform block holds (6 terms: 7 vec4s a light).
    s.lights = vec![distant(30.0, 0.0, 0.1, 1.0); 4096 / 7 + 1];
    let e = s.prepare().unwrap_err().to_string();
    assert!(e.contains("use at most 585 lights"), "{e}");
    // Moving lights in place does not redo the per-frame terms: refused, so a caller rebuilds.
    s.lights = vec![distant(30.0, 0.0, 0.1, 1.0)];
    let p = s.prepare().unwrap();
    let g = gpu();
    let r = gpu::Renderer::new(&g, &p).unwrap();
    let e = r.set_lights(&p.lights).unwrap_err().to_string();
    assert!(e.contains("rebuild the renderer"), "{e}");
}

#[test]
fn a_turntable_turns_a_distant_lights_direction_about_the_vertical() {
    // A local light turns about the view's centre; a direction turns about the vertical
    // itself, keeping its elevation, wherever the view is.
    let mut s = Scene::without_ptm();
    s.view = [5.0, 5.0, 7.0, 7.0];
    s.lights = vec![distant(30.0, 0.0, 0.01, 1.0)];
    let t = s.with_lights_turned(std::f32::consts::FRAC_PI_2);
    let [x, y, z] = t.lights[0].position;
    let e = 30f32.to_radians();
    assert!(x.abs() < 1e-6 && (y - e.cos()).abs() < 1e-6 && (z - e.sin()).abs() < 1e-6);
}

#[test]
fn grazing_wide_and_hard_suns_render_finite_and_in_range() {
    // The sun at 0.1° and 89.9°, with no radius, the sun's and the widest (45°, its cone half
    // under the horizon at the lowest elevation): K in [0, 1], every pixel finite and ≥ 0,
    // GPU = twin, through every blur method.
    let g = gpu();
    let ptm = fitted_files().remove(0).1;
    for (elevation, rho) in [(0.1f32, 0.0f32), (0.1, 0.785), (89.9, 0.785), (3.0, 0.0047)] {
        for blur in [Blur::Sat, Blur::Mip, Blur::Explicit, Blur::Separable] {
            let s = shaded(
                Some(ptm.clone()),
                vec![distant(elevation, 1.0, rho, 1.0)],
                blur,
            );
            let p = s.prepare().unwrap();
            let twin = Twin {
                p: &p,
                blur: None,
                opacity: None,
            };
            for y in 0..ptm.height {
                for x in 0..ptm.width {
                    let k = twin.distant_k(&twin.ptm_coeffs(texel_centre(&ptm, x, y), 0.0), 0);
                    assert!((0.0..=1.0).contains(&k), "{elevation}° ρ {rho}: K {k}");
                }
            }
            let ci = cpu::render(&p);
            let what = format!("{elevation}° ρ {rho} {}", blur.name());
            assert!(
                ci.pixels
                    .iter()
                    .flatten()
                    .all(|v| v.is_finite() && *v >= 0.0),
                "{what}: a pixel is not finite or negative"
            );
            let (gi, _) = gpu::render(&g, &p).unwrap();
            let d = gi.max_abs_diff(&ci).unwrap();
            assert!(d <= 1e-3, "{what}: GPU and twin differ by {d}");
        }
    }
}
