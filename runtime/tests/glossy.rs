//! Glossy reflections: a glossy receiver reflects the planar caster over a background, blurred
//! through the "imaginary light" on the mirror ray whose cone is the lobe's. Each method's
//! reflected radiance is judged against a ray-traced reference that samples the lobe (uniform
//! in solid angle over the cone) and composites each hit texel's own colour over the
//! background; and bad input is refused before any GPU work.

mod common;

use common::*;
use ptm_runtime::cpu;
use ptm_runtime::reference::render_reflection_reference;
use ptm_runtime::scene::Perspective;
use ptm_runtime::synthetic::leaves;
use ptm_runtime::{Blur, Scene};

/// Roughnesses tried (cone half-angles 4.5°, 11.25°, 22.5°).
const ROUGHNESS: [f32; 3] = [0.1, 0.25, 0.5];

#[test]
fn glossy_reflection_is_within_two_percent_of_the_ray_traced_lobe() {
    // Against a 4096-ray reference per pixel (its own noise shown by a 256-ray one): the
    // reflected radiance of the SAT (the cone's ellipse as slabs) and of the explicit grid must
    // err by at most 2 % of the mean reflected radiance, at three roughnesses and two views.
    // MIP (elliptical weighted averaging) is printed.
    let caster = leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4);
    for perspective in [false, true] {
        for roughness in ROUGHNESS {
            let p = glossy_scene(roughness, Blur::Sat, perspective, None)
                .prepare()
                .unwrap();
            let fine = render_reflection_reference(&p, &caster.rgba, None, 4096);
            let noise = mean_abs3(
                &render_reflection_reference(&p, &caster.rgba, None, 256),
                &fine,
            );
            let level = mean3(&fine);
            for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
                let p = glossy_scene(roughness, blur, perspective, None)
                    .prepare()
                    .unwrap();
                let got = cpu::render_reflection(&p).unwrap();
                let err = mean_abs3(&got, &fine);
                eprintln!(
                    "{} roughness {roughness}, {}: mean |error| {err:.2e} ({:.2} % of the \
                     reflected {level:.3}), reference noise (256) {noise:.2e}",
                    if perspective { "perspective" } else { "tilted" },
                    blur.name(),
                    100.0 * err / level,
                );
                if matches!(blur, Blur::Sat | Blur::Explicit) {
                    assert!(
                        err <= 0.02 * level,
                        "{} at roughness {roughness}: {err:.2e} > 2 % of {level:.3}",
                        blur.name()
                    );
                }
            }
        }
    }
}

#[test]
fn the_reflection_blurs_with_distance_and_shows_the_background_off_the_caster() {
    // A mirror (roughness 0) reflects the caster's texels sharply: the reflected image varies
    // more from pixel to pixel than a rough one's; with the caster out of every lobe only the
    // background shows.
    let p0 = glossy_scene(0.0, Blur::Sat, false, None).prepare().unwrap();
    let p1 = glossy_scene(0.5, Blur::Sat, false, None).prepare().unwrap();
    let sharp = cpu::render_reflection(&p0).unwrap();
    let blurred = cpu::render_reflection(&p1).unwrap();
    // Total variation of the green channel along the rows (48 pixels each).
    let variation = |a: &[[f32; 3]]| {
        a.chunks(48)
            .flat_map(|row| row.windows(2).map(|w| (w[1][1] - w[0][1]).abs() as f64))
            .sum::<f64>()
    };
    let (tv_sharp, tv_blurred) = (variation(&sharp), variation(&blurred));
    assert!(tv_sharp > 1.5 * tv_blurred, "{tv_sharp} vs {tv_blurred}");
    let mut off = glossy_scene(0.1, Blur::Sat, false, None);
    off.caster.as_mut().unwrap().rect = [5.0, 5.0, 6.0, 6.0];
    off.caster.as_mut().unwrap().tilt_deg = 0.0;
    let r = cpu::render_reflection(&off.prepare().unwrap()).unwrap();
    assert!(r.iter().all(|x| *x == [0.2, 0.3, 0.5]));
}

#[test]
fn bad_glossy_input_is_refused_naming_it() {
    for (mutate, want) in [
        (
            (|s: &mut Scene| s.glossy.as_mut().unwrap().roughness = 1.5) as fn(&mut Scene),
            "roughness",
        ),
        (
            |s: &mut Scene| s.glossy.as_mut().unwrap().roughness = f32::NAN,
            "roughness",
        ),
        (
            |s: &mut Scene| s.glossy.as_mut().unwrap().background = [0.0, -1.0, 0.0],
            "background",
        ),
        (|s: &mut Scene| s.glossy.as_mut().unwrap().f0 = 2.0, "F0"),
        (|s: &mut Scene| s.caster = None, "caster"),
        (|s: &mut Scene| s.blur = Blur::Separable, "separable"),
    ] {
        let mut s = glossy_scene(0.2, Blur::Sat, false, None);
        mutate(&mut s);
        let e = s.prepare().unwrap_err().to_string();
        assert!(e.contains(want), "{want}: {e}");
    }
}

#[test]
fn extremes_grazing_views_a_touching_caster_and_a_45_degree_lobe_stay_finite_and_close() {
    // A camera 0.3 above the cloth (mirror rays within a few degrees of grazing), the tilted
    // caster's low edge touching the cloth (h → 0 there: a sharp reflection), and roughness 1
    // (a 45° cone): every reflected value is finite and between the caster's colour and the
    // background, and the mean error against the ray-traced lobe is printed and bounded (MIP
    // printed only).
    let caster = leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4);
    let tint = [40.0f32, 160.0, 60.0].map(|c| ptm_runtime::output::srgb_decode(c / 255.0));
    let back = [0.2f32, 0.3, 0.5];
    let mut grazing = glossy_scene(0.25, Blur::Sat, true, None);
    grazing.perspective = Some(Perspective {
        eye: [0.0, -3.0, 0.3],
        target: [0.0, 0.0, 0.0],
        fov_y_deg: 50.0,
    });
    let mut touching = glossy_scene(0.25, Blur::Sat, false, None);
    let c = touching.caster.as_mut().unwrap();
    c.elevation = 0.8 * 40f32.to_radians().sin() + 1e-5;
    let wide = glossy_scene(1.0, Blur::Sat, false, None);
    for (what, s, bound) in [
        // Measured 1.4 %, 0.5 % and 4.5 % for sat, alike for every method: what grows at a
        // grazing or a 45° lobe is the kernel's shape (each cone's ellipse is uniform in area on
        // the plane, the lobe in solid angle; the nested cones give each ring its exact solid
        // angle, which halved the 45° lobe's 9.9 %), not the method; the bounds keep it in check.
        ("grazing", grazing, 0.02),
        ("touching", touching, 0.02),
        ("roughness 1", wide, 0.06),
    ] {
        let p = s.prepare().unwrap();
        let fine = render_reflection_reference(&p, &caster.rgba, None, 4096);
        let level = mean3(&fine);
        for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
            let mut e = s.clone();
            e.blur = blur;
            let got = cpu::render_reflection(&e.prepare().unwrap()).unwrap();
            for (x, f) in got.iter().zip(&fine) {
                for k in 0..3 {
                    // Pixels whose ray misses the cloth are 0 in both.
                    if *f == [0.0; 3] {
                        assert_eq!(x[k], 0.0);
                        continue;
                    }
                    let (lo, hi) = (tint[k].min(back[k]), tint[k].max(back[k]));
                    assert!(
                        x[k].is_finite() && x[k] >= lo - 1e-5 && x[k] <= hi + 1e-5,
                        "{what}, {}: {x:?}",
                        blur.name()
                    );
                }
            }
            let err = mean_abs3(&got, &fine);
            eprintln!(
                "{what}, {}: mean |error| {err:.2e} ({:.2} % of the reflected {level:.3})",
                blur.name(),
                100.0 * err / level
            );
            if blur != Blur::Mip {
                assert!(err <= bound * level, "{what}, {}: {err:.2e}", blur.name());
            }
        }
    }
}

#[test]
fn each_caster_texel_reflects_its_own_colour() {
    // A caster of two halves, opaque red on the left and half-transparent cyan on the right:
    // the lobe averages each texel's premultiplied colour (α·rgb) and opacity, so the reflection
    // turns from red through their blend to cyan over the background. Against the 4096-ray
    // reference (which composites each hit texel's own colour), SAT and the explicit grid must
    // err by at most 2 % of the mean reflected radiance at three roughnesses, seen from above
    // (the caster tilted) and in perspective; MIP is printed. (The tilted view at roughness 0.5
    // erred 2.04 % with one cone; as three nested cones, 1.45 %.)
    let (w, h) = (64usize, 64usize);
    let rgba: Vec<[u8; 4]> = (0..w * h)
        .map(|i| {
            if i % w < w / 2 {
                [220, 40, 30, 255]
            } else {
                [30, 200, 230, 128]
            }
        })
        .collect();
    let two_halves = |s: &mut Scene| {
        let c = s.caster.as_mut().unwrap();
        c.width = w;
        c.height = h;
        c.rgba = rgba.clone();
    };
    for perspective in [false, true] {
        for roughness in ROUGHNESS {
            let mut s = glossy_scene(roughness, Blur::Sat, perspective, None);
            two_halves(&mut s);
            let p = s.prepare().unwrap();
            let fine = render_reflection_reference(&p, &rgba, None, 4096);
            let level = mean3(&fine);
            // The two colours both show: red dominates some pixels, blue-green others.
            assert!(fine.iter().any(|x| x[0] > 2.0 * x[2]));
            assert!(fine.iter().any(|x| x[2] > 2.0 * x[0] && x[1] > 2.0 * x[0]));
            for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
                let mut s = glossy_scene(roughness, blur, perspective, None);
                two_halves(&mut s);
                let got = cpu::render_reflection(&s.prepare().unwrap()).unwrap();
                let err = mean_abs3(&got, &fine);
                eprintln!(
                    "two colours, {} roughness {roughness}, {}: mean |error| {err:.2e} ({:.2} % \
                     of the reflected {level:.3})",
                    if perspective { "perspective" } else { "tilted" },
                    blur.name(),
                    100.0 * err / level,
                );
                if matches!(blur, Blur::Sat | Blur::Explicit) {
                    assert!(
                        err <= 0.02 * level,
                        "{} at roughness {roughness}: {err:.2e} > 2 % of {level:.3}",
                        blur.name()
                    );
                }
            }
        }
    }
}
