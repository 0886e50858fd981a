//! The GPU (lavapipe in CI) against the CPU twin: every shader variant, ≤ 1e-3 linear radiance;
//! and the GPU summed-area table against the CPU one, bit for bit.

mod common;

use common::*;
use ptm_format::Basis;
use ptm_runtime::synthetic::checker;
use ptm_runtime::{cpu, gpu, Blur, Scene};

fn scene(basis: Option<Basis>, size: [u32; 2]) -> Scene {
    let ptm = random_ptm(basis.unwrap_or(Basis::Ptm6), 13, 9, 7);
    let mut s = Scene::over_ptm(ptm, 3, size);
    if basis.is_none() {
        s.ptm = None;
    }
    s.lights = vec![
        light([1.2, 2.1, 2.0], 0.3, 6.0),
        light([-1.0, 0.5, 1.0], 0.0, 2.0),
        light([4.0, 4.0, 0.7], 0.5, 3.0),
        light([1.0, 1.0, -1.0], 0.2, 5.0), // below the acceptor: contributes nothing
    ];
    s
}

fn check(s: &Scene, what: &str) {
    let g = gpu();
    let p = s.prepare().unwrap();
    let (gpu_img, timings) = gpu::render(&g, &p).unwrap();
    let cpu_img = cpu::render(&p);
    let diff = gpu_img.max_abs_diff(&cpu_img).unwrap();
    let peak = cpu_img
        .pixels
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0f32, f32::max);
    eprintln!(
        "{what} [{}]: max |gpu − cpu| = {diff:.2e} (peak {peak:.3}) {timings:?}",
        p.variant.name()
    );
    assert!(peak > 0.1, "{what}: the scene is too dark to test anything");
    assert!(diff <= 1e-3, "{what}: GPU and CPU twin differ by {diff}");
}

#[test]
fn gpu_matches_twin_without_caster() {
    // 70 px rows = 1120 bytes: exercises the 256-byte row padding of the readback.
    check(&scene(Some(Basis::Ptm6), [70, 50]), "ptm6");
    check(&scene(Some(Basis::Ptm11), [64, 64]), "ptm11");
    check(&scene(None, [33, 17]), "no PTM");
}

#[test]
fn gpu_matches_twin_with_albedo_texture_and_casters() {
    let mut s = scene(Some(Basis::Ptm11), [48, 40]);
    s.albedo_texture = Some((
        5,
        4,
        (0..20)
            .map(|i| [0.2 + 0.04 * i as f32, 0.9 - 0.03 * i as f32, 0.5])
            .collect(),
    ));
    s.caster = Some(random_caster(40, 30, [0.3, 0.2, 2.6, 2.4], 0.6, 3));
    // w = 20·0.6/3 = 4 units ≈ 70 texels: the explicit blur at its 256² sample cap.
    s.lights.push(light([1.5, 1.0, 3.0], 20.0, 4.0));
    for blur in Blur::ALL {
        for colored in [false, true] {
            s.blur = blur;
            s.colored_shadow = colored;
            check(&s, &format!("caster {} colored {colored}", blur.name()));
        }
    }
}

#[test]
fn gpu_matches_twin_under_rectangular_lights_for_every_blur() {
    let mut s = scene(Some(Basis::Ptm6), [48, 40]);
    s.caster = Some(random_caster(40, 30, [0.3, 0.2, 2.6, 2.4], 0.6, 3));
    // Aspect 4:1, 1:3 and 1000:1 (a tube light), beside a sphere.
    for (l, rect) in s
        .lights
        .iter_mut()
        .zip([[1.6, 0.4], [0.2, 0.6], [2.0, 0.002]])
    {
        l.rect = Some(rect);
    }
    for blur in Blur::ALL {
        s.blur = blur;
        check(&s, &format!("rectangular lights, {}", blur.name()));
    }
    // Turned 30°, 100° and 45° (parallelograms of boxes), under a flat and a tilted caster,
    // through every per-pixel method (separable refuses a turned rectangle).
    for (l, deg) in s.lights.iter_mut().zip([30.0, 100.0, 45.0]) {
        l.rect_angle_deg = deg;
    }
    for tilt in [0.0, 25.0] {
        s.caster.as_mut().unwrap().tilt_deg = tilt;
        for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
            s.blur = blur;
            check(
                &s,
                &format!("turned rectangles, tilt {tilt}, {}", blur.name()),
            );
        }
    }
}

#[test]
fn gpu_matches_twin_under_gaussian_lights_for_every_blur() {
    let mut s = scene(Some(Basis::Ptm6), [48, 40]);
    s.caster = Some(random_caster(40, 30, [0.3, 0.2, 2.6, 2.4], 0.6, 3));
    // Round, 4:1 and a σ far below a texel, beside a sphere.
    for (l, sigma) in s
        .lights
        .iter_mut()
        .zip([[0.5, 0.5], [0.8, 0.2], [1e-4, 1e-4]])
    {
        l.gaussian = Some(sigma);
    }
    for colored in [false, true] {
        s.colored_shadow = colored;
        for blur in Blur::ALL {
            s.blur = blur;
            check(
                &s,
                &format!("Gaussian lights, {}, colored {colored}", blur.name()),
            );
        }
    }
}

#[test]
fn gpu_matches_twin_with_a_glossy_receiver() {
    // The caster tilted 30° (the blur grows across the view), seen from above and in
    // perspective, through every method with a kernel per pixel.
    let mut s = scene(Some(Basis::Ptm6), [48, 40]);
    let mut c = random_caster(40, 30, [0.3, 0.2, 2.6, 2.4], 1.2, 3);
    c.tilt_deg = 30.0;
    s.caster = Some(c);
    s.glossy = Some(ptm_runtime::Glossy {
        roughness: 0.3,
        background: [0.2, 0.3, 0.5],
        f0: 0.4,
        environment: None,
    });
    let oblique = ptm_runtime::scene::Perspective {
        eye: [1.5, -2.0, 2.5],
        target: [1.5, 1.5, 0.0],
        fov_y_deg: 60.0,
    };
    let sky = std::sync::Arc::new(ptm_runtime::synthetic::sky());
    for perspective in [None, Some(oblique)] {
        s.perspective = perspective;
        for blur in [Blur::Sat, Blur::Explicit, Blur::Mip] {
            s.blur = blur;
            // Over the background colour, and over a sky (the background image's lookup).
            for env in [None, Some(sky.clone())] {
                s.glossy.as_mut().unwrap().environment = env.clone();
                check(
                    &s,
                    &format!(
                        "glossy, {}, perspective {}, sky {}",
                        blur.name(),
                        perspective.is_some(),
                        env.is_some()
                    ),
                );
            }
        }
    }
}

#[test]
fn a_renderer_without_the_gaussian_code_refuses_gaussian_lights() {
    // Moving lights in place keeps the shader: one compiled without the Gaussian's code (no
    // Gaussian light when it was built) must not be handed one; a window then rebuilds.
    let g = gpu();
    let mut s = scene(Some(Basis::Ptm6), [16, 16]);
    s.caster = Some(random_caster(16, 16, [0.3, 0.2, 2.6, 2.4], 0.6, 3));
    let r = gpu::Renderer::new(&g, &s.prepare().unwrap()).unwrap();
    assert!(r.set_lights(&s.gpu_lights()).is_ok());
    s.lights[0].gaussian = Some([0.2, 0.3]);
    let e = r.set_lights(&s.gpu_lights()).unwrap_err().to_string();
    assert!(e.contains("Gaussian") && e.contains("rebuild"), "{e}");
    let r = gpu::Renderer::new(&g, &s.prepare().unwrap()).unwrap();
    assert!(r.set_lights(&s.gpu_lights()).is_ok());
}

#[test]
fn a_renderer_without_the_turned_rectangle_code_refuses_turned_rectangles() {
    // Likewise for a rectangle turned about the vertical (its parallelogram's code); one along
    // X and Y needs none.
    let g = gpu();
    let mut s = scene(Some(Basis::Ptm6), [16, 16]);
    s.caster = Some(random_caster(16, 16, [0.3, 0.2, 2.6, 2.4], 0.6, 3));
    s.lights[0].rect = Some([0.4, 0.2]);
    let r = gpu::Renderer::new(&g, &s.prepare().unwrap()).unwrap();
    assert!(r.set_lights(&s.gpu_lights()).is_ok());
    s.lights[0].rect_angle_deg = 30.0;
    let e = r.set_lights(&s.gpu_lights()).unwrap_err().to_string();
    assert!(e.contains("turned") && e.contains("rebuild"), "{e}");
    let r = gpu::Renderer::new(&g, &s.prepare().unwrap()).unwrap();
    assert!(r.set_lights(&s.gpu_lights()).is_ok());
}

#[test]
fn gpu_sat_equals_cpu_sat_bit_for_bit() {
    let g = gpu();
    let (w, h) = (301usize, 97usize);
    let op: Vec<u32> = (0..w * h)
        .map(|i| hash(i as u64) as u32 & 0x00FF_FFFF)
        .collect();
    for channels in [1u32, 3] {
        let gpu_table =
            ptm_runtime::blur::sat::sat_table(&g, &op, w as u32, h as u32, channels).unwrap();
        let cpu_table = ptm_runtime::blur::sat::build(&op, w, h, channels as usize);
        assert_eq!(gpu_table.len(), cpu_table.len());
        let first = gpu_table.iter().zip(&cpu_table).position(|(a, b)| a != b);
        assert_eq!(
            first, None,
            "channels {channels}: first mismatch at index {first:?}"
        );
    }
}

#[test]
fn perspective_straight_down_equals_the_orthographic_view_and_matches_twin() {
    // Looking straight down from height 3 with fov_y = 2·atan(0.75/3) sees exactly the square
    // [0, 1.5]² (a plane under a pinhole camera parallel to it maps affinely), so the image is
    // the orthographic one.
    let mut s = scene(Some(Basis::Ptm6), [48, 48]);
    s.view = [0.0, 0.0, 1.5, 1.5];
    let ortho = gpu::render(&gpu(), &s.prepare().unwrap()).unwrap().0;
    s.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [0.75, 0.75, 3.0],
        target: [0.75, 0.75, 0.0],
        fov_y_deg: 2.0 * (0.75f32 / 3.0).atan().to_degrees(),
    });
    let persp = gpu::render(&gpu(), &s.prepare().unwrap()).unwrap().0;
    let d = persp.max_abs_diff(&ortho).unwrap();
    assert!(
        d < 1e-3,
        "perspective top view differs from orthographic by {d}"
    );
    // An oblique view with the horizon in the picture: GPU = twin, sky black.
    s.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [-1.0, 0.5, 0.6],
        target: [1.0, 1.0, 0.0],
        fov_y_deg: 70.0,
    });
    check(&s, "perspective oblique");
    let img = cpu::render(&s.prepare().unwrap());
    assert_eq!(
        img.pixels[0][..3],
        [0.0; 3],
        "the top-left pixel looks at the sky"
    );
}

#[test]
fn no_lights_render_black() {
    let mut s = scene(Some(Basis::Ptm6), [16, 16]);
    s.lights.clear();
    let p = s.prepare().unwrap();
    let (img, _) = gpu::render(&gpu(), &p).unwrap();
    assert!(img.pixels.iter().all(|px| px[..3] == [0.0; 3]));
}

#[test]
fn minified_ptm_is_mip_mapped_and_averages_k() {
    // 8 tiles of 64 texels across 64 pixels: 8 texels per pixel, level 3, where every texel
    // averages an 8×8 block of the checkerboard: K = 0.5 exactly, so (1 − K) halves every pixel.
    // Without the chain each pixel would sample one texel: 0 or 1, an aliased pattern.
    let mut s = Scene::over_ptm(checker(64), 8, [64, 64]);
    s.lights = vec![light([4.0, 4.0, 50.0], 0.0, 2500.0)];
    let p = s.prepare().unwrap();
    assert!(p.variant.ptm_mip);
    assert_eq!(p.ptm_levels.len(), 7, "64, 32, …, 1");
    let (img, _) = gpu::render(&gpu(), &p).unwrap();
    let twin = cpu::render(&p);
    assert!(img.max_abs_diff(&twin).unwrap() < 1e-3);
    let mut free = s.clone();
    free.ptm = None;
    let (open, _) = gpu::render(&gpu(), &free.prepare().unwrap()).unwrap();
    for (a, b) in img.pixels.iter().zip(&open.pixels) {
        assert!((a[0] / b[0] - 0.5).abs() < 1e-4, "{} vs {}", a[0], b[0]);
    }
    // One texel per pixel or fewer: no chain, no binding.
    let s1 = Scene::over_ptm(checker(64), 1, [64, 64]);
    let p1 = s1.prepare().unwrap();
    assert!(!p1.variant.ptm_mip && p1.ptm_levels.is_empty());
}

#[test]
fn perspective_over_a_mip_mapped_ptm_matches_twin() {
    // Level of detail grows towards the horizon; GPU and twin compute it the same way.
    let mut s = scene(Some(Basis::Ptm11), [96, 64]);
    s.ptm = Some(random_ptm(Basis::Ptm11, 32, 16, 3));
    s.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [-2.0, 0.5, 0.8],
        target: [3.0, 1.5, 0.0],
        fov_y_deg: 60.0,
    });
    let p = s.prepare().unwrap();
    assert!(
        p.variant.ptm_mip && p.ptm_levels.len() == 6,
        "32×16 … 2×1, 1×1"
    );
    check(&s, "perspective, ptm11 MIP chain");
}

/// `random_ptm` with `link` and `uv`; logistic coefficients are scaled ×6 so σ has sharp edges,
/// and every 7th texel's constant term is ±200 (σ saturates: a naive exp(−p) overflows f32).
fn link_ptm(basis: Basis, link: ptm_format::Link, uv: ptm_format::UvMap) -> ptm_format::Ptm {
    let mut ptm = random_ptm(basis, 13, 9, 5);
    ptm.link = link;
    ptm.uv = uv;
    if link == ptm_format::Link::Logistic {
        let one = basis.len() - 1;
        for (k, plane) in ptm.planes.iter_mut().enumerate() {
            for (t, c) in plane.iter_mut().enumerate() {
                *c = if k == one && t % 7 == 0 {
                    if t % 14 == 0 {
                        200.0
                    } else {
                        -200.0
                    }
                } else {
                    6.0 * *c
                };
            }
        }
    }
    ptm
}

#[test]
fn gpu_matches_twin_for_every_link_and_uv_map() {
    use ptm_format::{Link, UvMap};
    for basis in [Basis::Ptm6, Basis::Ptm11] {
        for link in Link::ALL {
            for uv in UvMap::ALL {
                let mut s = scene(Some(basis), [70, 50]);
                s.ptm = Some(link_ptm(basis, link, uv));
                // A grazing light (elevation ≈ 5°) tests the map near the horizon.
                s.lights.push(light([12.0, 1.5, 1.0], 0.1, 80.0));
                let p = s.prepare().unwrap();
                assert_eq!((p.variant.link, p.variant.uv), (link, uv));
                check(
                    &s,
                    &format!("{} {} {}", basis.name(), link.name(), uv.name()),
                );
            }
        }
    }
}

/// A 64² logistic ptm6 whose constant term is a texel checkerboard of p = ±20 (K ≈ 0 and 1),
/// with stored levels of p = ln(1/3) (K = 1/4) that averaged coefficients (p = 0, K = 1/2)
/// would not give.
fn logistic_checker(stored: bool) -> ptm_format::Ptm {
    let mut ptm = checker(64);
    ptm.link = ptm_format::Link::Logistic;
    for c in &mut ptm.planes[5] {
        *c = 40.0 * *c - 20.0;
    }
    if stored {
        ptm.mips = ptm_format::ptm::mip_sizes(64, 64)
            .into_iter()
            .map(|(w, h)| {
                let mut planes = vec![vec![0.0f32; w * h]; 6];
                planes[5].fill((1.0f32 / 3.0).ln());
                ptm_format::ptm::Level {
                    width: w,
                    height: h,
                    planes,
                }
            })
            .collect();
    }
    ptm
}

#[test]
fn minified_logistic_ptm_renders_from_its_stored_levels() {
    // 8 tiles across 64 px: level 3 everywhere. Stored levels: K = 1/4, (1 − K) = 3/4 of the
    // unoccluded image; the derived chain (no stored levels) gives σ(0) = 1/2 and a warning.
    use ptm_runtime::scene::Warning;
    let mut free = Scene::over_ptm(checker(64), 8, [64, 64]);
    free.lights = vec![light([4.0, 4.0, 50.0], 0.0, 2500.0)];
    free.ptm = None;
    let (open, _) = gpu::render(&gpu(), &free.prepare().unwrap()).unwrap();
    for (stored, want) in [(true, 0.75f32), (false, 0.5)] {
        // Through a file, as `ptm preview` reads it: the levels survive the EXR.
        let path = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("logistic_checker_{stored}.ptm.exr"));
        logistic_checker(stored)
            .save(&path, &Default::default())
            .unwrap();
        let ptm = ptm_format::Ptm::load(&path).unwrap();
        assert_eq!(ptm, logistic_checker(stored));
        let mut s = free.clone();
        s.ptm = Some(ptm);
        let p = s.prepare().unwrap();
        assert!(p.variant.ptm_mip && p.ptm_levels.len() == 7);
        let warned = p.warnings == [Warning::LogisticMipsDerived { levels: 7 }];
        assert_eq!(warned, !stored, "{:?}", p.warnings);
        for w in &p.warnings {
            let text = w.to_string();
            assert!(!text.contains("  ") && text.contains("`ptm fit`"), "{text}");
        }
        let (img, _) = gpu::render(&gpu(), &p).unwrap();
        let twin = cpu::render(&p);
        let d = img.max_abs_diff(&twin).unwrap();
        eprintln!("logistic checker, stored levels {stored}: max |gpu − cpu| = {d:.2e}");
        assert!(d < 1e-3, "stored {stored}: GPU and twin differ by {d}");
        for (a, b) in img.pixels.iter().zip(&open.pixels) {
            assert!(
                (a[0] / b[0] - want).abs() < 1e-4,
                "stored {stored}: {} vs {}",
                a[0],
                b[0]
            );
        }
    }
    // An identity file without levels gets no warning (minified_ptm_is_mip_mapped_and_averages_k).
    let mut s = free.clone();
    s.ptm = Some(checker(64));
    assert!(s.prepare().unwrap().warnings.is_empty());
}

#[test]
fn stored_levels_of_odd_sizes_match_twin_under_perspective() {
    // 13×9 has no derived chain (odd sides) but stores 6×4, 3×2, 1×1 (rounded down): the
    // lookup bridges the gap the dropped row and column leave at the tile seam.
    let mut s = scene(Some(Basis::Ptm11), [96, 64]);
    let mut ptm = link_ptm(
        Basis::Ptm11,
        ptm_format::Link::Logistic,
        ptm_format::UvMap::Hemispherical,
    );
    ptm.mips = ptm_format::ptm::mip_sizes(13, 9)
        .into_iter()
        .enumerate()
        .map(|(k, (w, h))| {
            let level = random_ptm(Basis::Ptm11, w, h, 100 + k as u64);
            ptm_format::ptm::Level {
                width: w,
                height: h,
                planes: level.planes,
            }
        })
        .collect();
    s.ptm = Some(ptm);
    s.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [-2.0, 0.5, 0.8],
        target: [3.0, 1.5, 0.0],
        fov_y_deg: 60.0,
    });
    let p = s.prepare().unwrap();
    let sizes: Vec<(u32, u32, [f32; 2])> = p
        .ptm_levels
        .iter()
        .map(|l| (l.width, l.height, l.period))
        .collect();
    assert_eq!(
        sizes,
        [
            (13, 9, [13.0, 9.0]),
            (6, 4, [6.5, 4.5]),
            (3, 2, [3.25, 2.25]),
            (1, 1, [1.0, 1.0])
        ]
    );
    check(&s, "perspective, stored odd-size levels");
}

#[test]
fn holes_render_black_and_match_twin_plain_minified_and_stored() {
    // 16×12 texels, 1 tile over 64×48 px: 4 px per texel, no chain. The hole's texels span
    // x ∈ [4/16, 8/16), y (from the far edge) ∈ [3/12, 6/12); pixels whose bilinear taps all
    // lie in the hole are black, pixels far from it equal the render without coverage.
    let mut s = scene(Some(Basis::Ptm6), [64, 48]);
    s.ptm = Some(holed_ptm(Basis::Ptm6, 16, 12, 9));
    s.view = [0.0, 0.0, 1.0, 1.0];
    let p = s.prepare().unwrap();
    assert!(p.variant.coverage && !p.variant.ptm_mip);
    assert_eq!(p.coverage.len(), 16 * 12);
    check(&s, "PTM with a hole, 1:1");
    let (img, _) = gpu::render(&gpu(), &p).unwrap();
    let mut full = s.clone();
    full.ptm.as_mut().unwrap().coverage = None;
    let (open, _) = gpu::render(&gpu(), &full.prepare().unwrap()).unwrap();
    let at = |img: &ptm_runtime::Image, x: usize, y: usize| img.pixels[y * 64 + x];
    // Texel columns 5..7, rows 4..5 (centres) → pixels 22..26, 18..19: inside the hole's
    // interior, all four taps have coverage 0.
    for (x, y) in [(22, 18), (25, 19), (23, 18)] {
        assert_eq!(
            at(&img, x, y)[..3],
            [0.0; 3],
            "pixel ({x}, {y}) in the hole"
        );
        assert!(
            at(&open, x, y)[0] > 0.0,
            "the hole's pixel is lit without coverage"
        );
    }
    for (x, y) in [(2, 2), (60, 40), (50, 5)] {
        // Coverage 1 at all four taps: the weights' sum, 1 within an ulp or two.
        let (a, b) = (at(&img, x, y), at(&open, x, y));
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 1e-6 * b[c],
                "pixel ({x}, {y}) far from the hole: {a:?} vs {b:?}"
            );
        }
    }

    // Minified (4 tiles across 32 px: 2 texels per pixel): a derived chain, coverage averaged.
    let mut m = s.clone();
    m.size = [32, 24];
    m.view = [0.0, 0.0, 4.0, 3.0];
    let p = m.prepare().unwrap();
    assert!(p.variant.coverage && p.variant.ptm_mip);
    assert_eq!(p.coverage.len(), p.coeffs.len() / 6);
    check(&m, "PTM with a hole, minified (derived chain)");

    // Stored levels of odd sizes (rounded down) under perspective.
    let mut ptm = holed_ptm(Basis::Ptm6, 13, 9, 4);
    ptm.mips = ptm_format::ptm::mip_sizes(13, 9)
        .into_iter()
        .enumerate()
        .map(|(k, (w, h))| ptm_format::ptm::Level {
            width: w,
            height: h,
            planes: random_ptm(Basis::Ptm6, w, h, 50 + k as u64).planes,
        })
        .collect();
    let mut q = scene(Some(Basis::Ptm6), [96, 64]);
    q.ptm = Some(ptm);
    q.perspective = Some(ptm_runtime::scene::Perspective {
        eye: [-2.0, 0.5, 0.8],
        target: [3.0, 1.5, 0.0],
        fov_y_deg: 60.0,
    });
    let p = q.prepare().unwrap();
    assert!(p.variant.coverage && p.variant.ptm_mip && p.ptm_levels.len() == 4);
    check(&q, "PTM with a hole, stored odd-size levels, perspective");
}
