//! Rectangular lights: the summed-area table's box kernel against Monte Carlo references that
//! sample the uniform rectangle, at aspect ratios from 1:1 to 1:1000, and the numerical extremes
//! (a rectangle shrinking to a point, one far larger than the caster, refused sizes).

mod common;

use common::*;
use ptm_runtime::compare::mean_abs_diff;
use ptm_runtime::layout::LightGpu;
use ptm_runtime::output::Image;
use ptm_runtime::reference::{mc_opacity_rect, render_reference};
use ptm_runtime::synthetic::leaves;
use ptm_runtime::{cpu, Blur, Scene, SceneBuffers};

/// Aspect ratios 1:1, 4:1, 1:9 and 1000:1 (a tube light), sides for a light 3 above the cloth.
const RECTS: [[f32; 2]; 4] = [[0.6, 0.6], [0.8, 0.2], [0.1, 0.9], [0.9, 0.0009]];

/// A 48² view of plain cloth under a leafy caster 0.4 above it and one rectangular light of
/// sides `rect` `lz` above the cloth, off to one side of the view's centre.
fn scene_at(rect: [f32; 2], lz: f32) -> Scene {
    let mut l = light([0.1 * lz, -0.07 * lz, lz], 0.0, lz * lz);
    l.rect = Some(rect);
    Scene {
        size: [48, 48],
        view: [-1.0, -1.0, 1.0, 1.0],
        ptm: None,
        albedo: [1.0; 3],
        albedo_texture: None,
        lights: vec![l],
        caster: Some(leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4)),
        colored_shadow: false,
        blur: Blur::Sat,
        perspective: None,
        glossy: None,
    }
}

fn scene(rect: [f32; 2]) -> Scene {
    scene_at(rect, 3.0)
}

/// The reference with every point of the rectangle weighted the same (`irradiance` false) or
/// by the irradiance it gives (true, as `render_reference`).
fn reference(p: &SceneBuffers, samples: u32, irradiance: bool) -> Image {
    let opacity = |q: [f32; 2], l: &LightGpu| {
        let key = (q[0].to_bits() as u64) << 32 ^ q[1].to_bits() as u64;
        mc_opacity_rect(&p.frame, &p.plane, q, l, samples, key, irradiance)
    };
    cpu::render_with(p, Some(&opacity))
}

/// Mean radiance of the unshadowed image (the lit radiance errors are measured against).
fn lit(s: &Scene) -> f32 {
    let mut open = s.clone();
    open.caster = None;
    let img = cpu::render(&open.prepare().unwrap());
    let sum: f64 = img.pixels.iter().map(|p| p[0] as f64).sum();
    (sum / img.pixels.len() as f64) as f32
}

/// Per rectangle (sides scaled with `lz`, so the penumbrae stay as wide): the SAT's mean error
/// against a 16384-sample reference, the 1024-sample reference's against it (its noise), the
/// square box of today's sphere of the same area against it, and the lit radiance.
fn errors(lz: f32, irradiance: bool) -> Vec<([f32; 2], f32, f32, f32, f32)> {
    RECTS
        .iter()
        .map(|r| {
            let rect = r.map(|x| x * lz / 3.0);
            let s = scene_at(rect, lz);
            let p = s.prepare().unwrap();
            let fine = reference(&p, 16384, irradiance);
            let noise = mean_abs_diff(&reference(&p, 1024, irradiance), &fine);
            let err = mean_abs_diff(&cpu::render(&p), &fine);
            let mut sphere = s.clone();
            sphere.lights[0].rect = None;
            sphere.lights[0].square_box = true;
            sphere.lights[0].radius = (rect[0] * rect[1] / std::f32::consts::PI).sqrt();
            let square = mean_abs_diff(&cpu::render(&sphere.prepare().unwrap()), &fine);
            let lit = lit(&s);
            eprintln!(
                "light at {lz}, rect {rect:?}, irradiance-weighted {irradiance}: sat {err:.2e}, \
                 reference noise (1024 samples) {noise:.2e}, sphere of equal area {square:.2e}, \
                 lit {lit:.3}"
            );
            (rect, err, noise, square, lit)
        })
        .collect()
}

#[test]
fn sat_box_of_any_aspect_is_within_the_noise_or_a_quarter_percent_of_the_light() {
    // The kernel alone (every point of the light weighted the same) is the rectangle's image,
    // a box the table sums exactly (`blur::sat`'s tests). The true light weights its patches
    // by the irradiance they give (z²/r⁴: up to 30 % more from the near side across a light 3
    // above a view 2 wide); the box, moved to those weights' centroid, leaves their skew. So:
    // within 3 × the 1024-sample reference's noise or 0.25 % of the lit radiance, whichever is
    // larger, and a tenth of the error of today's sphere of the same area or less.
    for lz in [3.0, 8.0] {
        for (rect, err, noise, square, lit) in errors(lz, true) {
            assert!(
                err <= (3.0 * noise).max(2.5e-3 * lit),
                "rect {rect:?} at {lz}: SAT error {err}, reference noise {noise}, lit {lit}"
            );
            assert!(
                err < 0.1 * square,
                "rect {rect:?}: {err} vs sphere {square}"
            );
        }
    }
}

#[test]
fn far_overhead_the_box_is_the_kernel_exactly() {
    // 100 above the view's centre every patch lights every pixel within about 1 % of the same:
    // against the reference that weighs them the same, the box is exact (the sums are): within
    // the 1024-sample reference's own noise (a fifth of it for areas; the 1000:1 tube's noise,
    // stratified along one axis, is itself only 1e-4 of the lit radiance).
    for r in RECTS {
        let rect = r.map(|x| x * 100.0 / 3.0);
        let mut s = scene_at(rect, 100.0);
        s.lights[0].position = [0.0, 0.0, 100.0];
        let p = s.prepare().unwrap();
        let fine = reference(&p, 16384, false);
        let noise = mean_abs_diff(&reference(&p, 1024, false), &fine);
        let err = mean_abs_diff(&cpu::render(&p), &fine);
        eprintln!("overhead, rect {rect:?}: sat {err:.2e}, noise {noise:.2e}");
        let lit = lit(&s);
        assert!(
            err <= (0.5 * noise).max(1.5e-4 * lit),
            "rect {rect:?}: {err} vs noise {noise}"
        );
    }
}

#[test]
fn a_shrinking_rectangle_tends_to_the_hard_shadow_and_a_huge_one_to_the_mean() {
    // A 1e-6 rectangle is a point: its box (1/256 texel) sees the texel its ray crosses, as the
    // reference's rays do.
    let tiny = scene([1e-6, 1e-6]);
    let p = tiny.prepare().unwrap();
    let err = mean_abs_diff(&cpu::render(&p), &render_reference(&p, 16));
    assert!(err < 1e-3 * lit(&tiny), "{err}");
    // A rectangle 1000 times the caster: every pixel sees nearly nothing of it.
    let huge = scene([1600.0, 1600.0]);
    let img = cpu::render(&huge.prepare().unwrap());
    let open = {
        let mut s = huge.clone();
        s.caster = None;
        cpu::render(&s.prepare().unwrap())
    };
    for (a, b) in img.pixels.iter().zip(&open.pixels) {
        assert!(
            a[0].is_finite() && a[0] <= b[0] && a[0] > 0.99 * b[0],
            "{a:?} vs {b:?}"
        );
    }
}

#[test]
fn zero_negative_or_non_finite_rectangles_are_refused() {
    for rect in [
        [0.0, 1.0],
        [1.0, -0.5],
        [f32::NAN, 1.0],
        [1.0, f32::INFINITY],
    ] {
        let err = scene(rect).prepare().expect_err("refused").to_string();
        assert!(err.contains("rectangle") && err.contains("> 0"), "{err}");
    }
}

#[test]
fn a_turned_rectangle_is_its_parallelogram_of_six_boxes_and_a_quarter_turn_swaps_its_sides() {
    // Turned θ about the vertical, the rectangle's image on the caster is a turned rectangle
    // (a parallelogram under a tilted caster), averaged as six boxes of exact band areas. Against
    // the reference that samples the turned rectangle (16384 samples, irradiance-weighted): every
    // per-pixel method within the bound of the untuned box (3 × the 1024-sample reference's noise
    // or 0.25 % of the lit radiance) times 2, for the slabs' shape; a quarter turn is the
    // rectangle with its sides swapped.
    let mut worst = 0.0f32;
    for (rect, deg, tilt) in [
        ([0.8, 0.2], 30.0, 0.0),
        ([0.8, 0.2], 60.0, 0.0),
        ([0.1, 0.9], 45.0, 0.0),
        ([0.8, 0.2], 30.0, 25.0),
        ([0.6, 0.6], 20.0, 0.0),
    ] {
        let mut s = scene(rect);
        s.lights[0].rect_angle_deg = deg;
        s.caster.as_mut().unwrap().tilt_deg = tilt;
        let p = s.prepare().unwrap();
        let fine = reference(&p, 16384, true);
        let noise = mean_abs_diff(&reference(&p, 1024, true), &fine);
        let lit = lit(&s);
        let unturned = {
            let mut u = s.clone();
            u.lights[0].rect_angle_deg = 0.0;
            mean_abs_diff(&cpu::render(&u.prepare().unwrap()), &fine)
        };
        for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
            let mut b = s.clone();
            b.blur = blur;
            let err = mean_abs_diff(&cpu::render(&b.prepare().unwrap()), &fine);
            eprintln!(
                "rect {rect:?} turned {deg}°, caster tilt {tilt}°, {}: {err:.2e} ({:.3} % of lit \
                 {lit:.3}), noise {noise:.2e}, the unturned box {unturned:.2e}",
                blur.name(),
                100.0 * err / lit
            );
            if blur != Blur::Mip {
                worst = worst.max(err / (3.0 * noise).max(2.5e-3 * lit));
            }
        }
    }
    assert!(worst <= 2.0, "worst error / bound {worst}");
    // A quarter turn swaps the sides (sat: the two middle bands are the box's two halves).
    let mut turned = scene([0.8, 0.2]);
    turned.lights[0].rect_angle_deg = 90.0;
    let swapped = scene([0.2, 0.8]);
    let d = mean_abs_diff(
        &cpu::render(&turned.prepare().unwrap()),
        &cpu::render(&swapped.prepare().unwrap()),
    );
    assert!(d < 1e-5 * lit(&swapped), "{d}");
    // Separable has kernels along X and Y only: refused, naming the light.
    let mut sep = scene([0.8, 0.2]);
    sep.lights[0].rect_angle_deg = 30.0;
    sep.blur = Blur::Separable;
    let e = sep.prepare().unwrap_err().to_string();
    assert!(e.contains("light 0") && e.contains("separable"), "{e}");
    let mut nan = scene([0.8, 0.2]);
    nan.lights[0].rect_angle_deg = f32::NAN;
    assert!(nan.prepare().is_err());
}
