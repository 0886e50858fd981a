//! Golden images: a few small scenes rendered on the GPU and compared with blessed PNGs with a
//! tolerance (never bytes). On a mismatch `<name>-actual.png` and `<name>-diff.png` are written
//! to the test scratch directory and named in the failure; `UPDATE_GOLDEN=1` re-blesses.

mod common;

use std::path::PathBuf;

use common::*;
use ptm_format::Basis;
use ptm_runtime::output::{read_rgba8, write_png_rgba8};
use ptm_runtime::{gpu, Blur, Scene};

/// Largest allowed per-channel difference in 8-bit sRGB (software vs hardware rasterisers,
/// driver versions).
const TOLERANCE: u8 = 3;

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn check_golden(name: &str, scene: &Scene) {
    let (img, _) = gpu::render(&gpu(), &scene.prepare().unwrap()).unwrap();
    let actual = img.to_srgb8(0.0);
    let path = golden_dir().join(format!("{name}.png"));
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        write_png_rgba8(&path, img.width, img.height, &actual).unwrap();
        eprintln!("blessed {}", path.display());
        return;
    }
    let (w, h, want) = read_rgba8(&path).unwrap_or_else(|e| {
        panic!("{e}: missing golden image; run with UPDATE_GOLDEN=1 to create it")
    });
    assert_eq!(
        (w, h),
        (img.width, img.height),
        "{name}: golden size differs"
    );
    let want: Vec<u8> = want.concat();
    let worst = actual
        .iter()
        .zip(&want)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    if worst > TOLERANCE {
        let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("golden");
        std::fs::create_dir_all(&out).unwrap();
        let actual_path = out.join(format!("{name}-actual.png"));
        let diff_path = out.join(format!("{name}-diff.png"));
        write_png_rgba8(&actual_path, w, h, &actual).unwrap();
        let diff: Vec<u8> = actual
            .iter()
            .zip(&want)
            .enumerate()
            .map(|(i, (a, b))| {
                if i % 4 == 3 {
                    255
                } else {
                    a.abs_diff(*b).saturating_mul(16)
                }
            })
            .collect();
        write_png_rgba8(&diff_path, w, h, &diff).unwrap();
        panic!(
            "{name}: differs from {} by up to {worst}/255 (tolerance {TOLERANCE}); see {} and {}",
            path.display(),
            actual_path.display(),
            diff_path.display()
        );
    }
}

fn scene(basis: Basis, blur: Blur, colored: bool) -> Scene {
    let mut s = Scene::over_ptm(random_ptm(basis, 12, 10, 11), 2, [64, 64]);
    s.lights = vec![
        light([-0.5, 2.5, 1.5], 0.4, 5.0),
        light([2.5, 0.5, 2.0], 0.2, 4.0),
    ];
    s.caster = Some(random_caster(24, 24, [0.4, 0.4, 1.6, 1.6], 0.5, 5));
    s.blur = blur;
    s.colored_shadow = colored;
    s
}

#[test]
fn golden_ptm6_sat() {
    check_golden("ptm6_sat", &scene(Basis::Ptm6, Blur::Sat, false));
}

#[test]
fn golden_ptm11_explicit_coloured() {
    check_golden(
        "ptm11_explicit_colored",
        &scene(Basis::Ptm11, Blur::Explicit, true),
    );
}

#[test]
fn golden_ptm6_separable_and_mip() {
    check_golden(
        "ptm6_separable",
        &scene(Basis::Ptm6, Blur::Separable, false),
    );
    check_golden("ptm6_mip_colored", &scene(Basis::Ptm6, Blur::Mip, true));
}

#[test]
fn golden_ptm6_sat_with_a_hole() {
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.ptm = Some(holed_ptm(Basis::Ptm6, 12, 10, 11));
    check_golden("ptm6_sat_hole", &s);
}

#[test]
fn golden_ptm6_sat_under_rectangular_lights() {
    // A 4:1 panel and a 1000:1 tube: the box kernel of each, summed by the table.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.lights[0].rect = Some([1.6, 0.4]);
    s.lights[1].rect = Some([1.0, 0.001]);
    check_golden("ptm6_sat_rect", &s);
}

#[test]
fn golden_ptm6_sat_under_turned_rectangular_lights() {
    // The 4:1 panel turned 35° and a 10:1 strip turned 120°, over a caster tilted 20°: each
    // kernel a parallelogram of boxes, so the penumbrae run along the turned edges.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.lights[0].rect = Some([1.6, 0.4]);
    s.lights[0].rect_angle_deg = 35.0;
    s.lights[1].rect = Some([1.0, 0.1]);
    s.lights[1].rect_angle_deg = 120.0;
    s.caster.as_mut().unwrap().tilt_deg = 20.0;
    check_golden("ptm6_sat_rect_turned", &s);
}

#[test]
fn golden_ptm6_sat_oblique_sphere_ellipse_and_square_box() {
    // One sphere low in the sky (about 70° off the vertical over the view): its kernel is the
    // ellipse its cone cuts from the caster plane, drawn out away from the light; beside it the
    // square box `Light::square_box` keeps, for comparison.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.lights = vec![light([-3.5, 1.0, 1.2], 0.5, 14.0)];
    s.caster = Some(random_caster(24, 24, [0.6, 0.4, 1.8, 1.6], 0.3, 5));
    check_golden("ptm6_sat_oblique", &s);
    s.lights[0].square_box = true;
    check_golden("ptm6_sat_oblique_square_box", &s);
}

#[test]
fn golden_ptm6_sat_under_gaussian_lights() {
    // A round Gaussian and one four times longer along X than along Y: the product of two
    // sums of three boxes each, from the table.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.lights[0].gaussian = Some([0.4, 0.4]);
    s.lights[1].gaussian = Some([0.6, 0.15]);
    check_golden("ptm6_sat_gaussian", &s);
}

#[test]
fn golden_learned11_sat() {
    // A learned basis's tables read at every pixel's (u, v), under the same lights and caster.
    let mut s = scene(Basis::Ptm11, Blur::Sat, false);
    s.ptm = Some(ptm_runtime::synthetic::learned_ptm(11, 17, 12, 10, 11));
    check_golden("learned11_sat", &s);
}

#[test]
fn golden_sat_shadow_and_glossy_reflection() {
    // A leafy caster tilted 50° (its far edge highest) over plain glossy cloth, from above: its
    // soft shadow thrown towards −x by the light, and under the caster its green reflection,
    // sharp along the low near edge and blurring towards the high far edge, the background
    // where the lobe misses the leaves.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.ptm = None;
    s.albedo = [0.8; 3];
    s.lights = vec![light([3.0, 1.0, 2.5], 0.3, 9.0)];
    let mut c = ptm_runtime::synthetic::leaves(48, [0.3, 0.3, 1.3, 1.7], 0.7);
    c.tilt_deg = 50.0;
    s.caster = Some(c);
    s.glossy = Some(ptm_runtime::Glossy {
        roughness: 0.15,
        background: [0.15, 0.2, 0.35],
        f0: 0.5,
        environment: None,
    });
    check_golden("sat_glossy", &s);
}

#[test]
fn golden_sat_shadow_and_glossy_reflection_of_a_coloured_caster() {
    // A caster of four opaque squares, red, yellow, blue and white (its quadrants, with clear
    // gaps between them), tilted 20° over plain glossy cloth, lit from +x: its soft grey shadow
    // thrown towards −x, and under it the four colours reflected, sharp near the low edge and
    // blurring towards the high one, the blue background reflected through the gaps.
    let n = 32;
    let colours = [
        [220, 40, 30],
        [230, 210, 40],
        [40, 60, 220],
        [240, 240, 240],
    ];
    let rgba = (0..n * n)
        .map(|t| {
            let (x, y) = (t % n, t / n);
            let (qx, qy) = (x * 2 / n, y * 2 / n);
            let (ix, iy) = (x % (n / 2), y % (n / 2));
            let inside = (2..n / 2 - 2).contains(&ix) && (2..n / 2 - 2).contains(&iy);
            let [r, g, b] = colours[qy * 2 + qx];
            if inside {
                [r, g, b, 255]
            } else {
                [0, 0, 0, 0]
            }
        })
        .collect();
    let caster = ptm_runtime::Caster {
        width: n,
        height: n,
        rgba,
        rect: [0.5, 0.4, 1.5, 1.6],
        elevation: 0.5,
        tilt_deg: 20.0,
    };
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.size = [96, 96];
    s.view = [0.0, 0.0, 2.0, 2.0];
    s.ptm = None;
    s.albedo = [0.8; 3];
    s.lights = vec![light([3.0, 1.0, 2.5], 0.3, 9.0)];
    s.caster = Some(caster);
    s.glossy = Some(ptm_runtime::Glossy {
        roughness: 0.1,
        background: [0.15, 0.2, 0.35],
        f0: 0.6,
        environment: None,
    });
    check_golden("sat_glossy_coloured", &s);
}

#[test]
fn golden_sat_shadow_and_a_reflected_sky() {
    // The leafy caster, flat, over plain glossy cloth seen in perspective from the sun's side
    // of the synthetic sky (the sun 35° up at azimuth 40°, behind the camera), so the mirror
    // rays climb from about 20° above the horizon at the top of the picture to 60° at the
    // bottom: the sky's pale horizon and cloud banks reflected far away, its deeper blue near,
    // the leaves' green reflection and their soft shadow over it.
    let mut s = scene(Basis::Ptm6, Blur::Sat, false);
    s.size = [128, 96];
    s.ptm = None;
    s.albedo = [0.5; 3];
    s.lights = vec![light([2.5, 0.2, 2.5], 0.3, 9.0)];
    s.caster = Some(ptm_runtime::synthetic::leaves(
        48,
        [0.5, 0.6, 1.5, 1.6],
        0.5,
    ));
    s.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [2.9, 2.7, 1.5],
        target: [1.0, 0.9, 0.0],
        fov_y_deg: 60.0,
    });
    s.glossy = Some(ptm_runtime::Glossy {
        roughness: 0.12,
        background: [0.15, 0.2, 0.35],
        f0: 0.35,
        environment: Some(std::sync::Arc::new(ptm_runtime::synthetic::sky())),
    });
    check_golden("sat_glossy_sky", &s);
}
