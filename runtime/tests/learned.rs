//! Learned-basis PTMs (#22) in the renderer: the CPU twin's K equals `Ptm::eval_dir` of a learned
//! file (random tables written and read back, and a learned6 fitted by ptm-fit from a
//! synthetic bake), the GPU (lavapipe in CI) equals the twin on the plane path (1:1, minified
//! with stored levels, perspective, coverage; grids of 17 and 5) and the mesh path, and what
//! the renderer refuses of a learned PTM.

mod common;

use common::*;
use ptm_format::{Basis, LearnedTable, Link, Ptm, UvMap};
use ptm_runtime::cpu::shade::Twin;
use ptm_runtime::mesh::{Mesh, MeshScene};
use ptm_runtime::scene::{Perspective, SceneBuffers};
use ptm_runtime::synthetic::learned_ptm;
use ptm_runtime::{cpu, gpu, Image, Scene};

/// The twin tolerance of the plane path (`gpu_twin.rs`): linear radiance.
const TWIN: f32 = 1e-3;

/// Directions from the zenith down to 0.5° above the horizon, all round in azimuth.
fn directions(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let el = (90.0 - 89.5 * i as f64 / (n - 1) as f64).to_radians();
            let az = 2.399 * i as f64;
            [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
        })
        .collect()
}

/// Through a file, as `ptm preview` reads it (`layout::load`): the PTM read back.
fn through_file(ptm: &Ptm, name: &str) -> Ptm {
    let path = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    ptm.save(&path, &Default::default()).unwrap();
    let back = ptm_format::layout::load(&path).unwrap();
    assert_eq!(&back, ptm, "{name}: the file reads back as written");
    back
}

/// Largest |twin K − `Ptm::eval_dir`| over every texel centre of level 0 and `dirs`, and the
/// spread of K seen (so a test knows K varied). The twin reads the prepared scene's buffers:
/// the coefficients filtered at the texel's centre, the node-major table.
fn twin_vs_eval(ptm: &Ptm, dirs: &[[f64; 3]]) -> (f32, f32) {
    let mut s = Scene::over_ptm(ptm.clone(), 1, [ptm.width as u32, ptm.height as u32]);
    s.lights.clear();
    let p = s.prepare().unwrap();
    assert!(!p.variant.ptm_mip, "1:1: level 0 only");
    let twin = Twin {
        p: &p,
        blur: None,
        opacity: None,
    };
    let (mut worst, mut lo, mut hi) = (0f32, 1f32, 0f32);
    for y in 0..ptm.height {
        for x in 0..ptm.width {
            // Row 0 is the far edge y = H.
            let pos = [
                ((x as f64 + 0.5) / ptm.width as f64 * ptm.tile[0]) as f32,
                ((1.0 - (y as f64 + 0.5) / ptm.height as f64) * ptm.tile[1]) as f32,
            ];
            let c = twin.ptm_coeffs(pos, 0.0);
            for (k, want) in ptm.coeffs(x, y).iter().enumerate() {
                assert!(
                    (c[k] - want).abs() < 1e-5,
                    "texel ({x}, {y}) coefficient {k}"
                );
            }
            for l in dirs {
                let want = ptm.eval_dir(x, y, *l);
                let got = twin.ptm_k(&c, l.map(|v| v as f32));
                worst = worst.max((got - want).abs());
                lo = lo.min(want);
                hi = hi.max(want);
            }
        }
    }
    (worst, hi - lo)
}

/// A learned6 PTM fitted by ptm-fit from the synthetic bake (`common::fitted`), with its MIP
/// levels.
fn fitted_learned6(n: usize) -> Ptm {
    let ptm = fitted(
        Basis::Learned(6),
        Link::Logistic,
        UvMap::Hemispherical,
        n,
        true,
    );
    assert!(ptm.learned.is_some() && !ptm.mips.is_empty());
    ptm
}

#[test]
fn twin_k_equals_ptm_eval_for_learned_files() {
    let dirs = directions(60);
    for (terms, grid) in [(11, 17), (6, 17), (3, 5)] {
        let ptm = through_file(
            &learned_ptm(terms, grid, 7, 5, 3),
            &format!("learned{terms}_g{grid}.ptm.exr"),
        );
        let (worst, spread) = twin_vs_eval(&ptm, &dirs);
        eprintln!(
            "learned{terms} grid {grid}: |twin K − eval_dir| ≤ {worst:.1e}, K spread {spread:.2}"
        );
        assert!(spread > 0.5, "K hardly varies ({spread})");
        assert!(
            worst < 2e-5,
            "learned{terms}: twin and Ptm::eval differ by {worst}"
        );
    }
    let fitted = through_file(&fitted_learned6(8), "fitted_learned6.ptm.exr");
    let (worst, spread) = twin_vs_eval(&fitted, &dirs);
    eprintln!("fitted learned6: |twin K − eval_dir| ≤ {worst:.1e}, K spread {spread:.2}");
    assert!(spread > 0.5, "the fitted K hardly varies ({spread})");
    assert!(
        worst < 2e-5,
        "fitted learned6: twin and Ptm::eval differ by {worst}"
    );
}

/// A plane scene over `ptm` (3 tiles across, 70×50 px) under three lights and a grazing one.
fn scene(ptm: Ptm, size: [u32; 2]) -> Scene {
    let mut s = Scene::over_ptm(ptm, 3, size);
    s.lights = vec![
        light([1.2, 2.1, 2.0], 0.3, 6.0),
        light([-1.0, 0.5, 1.0], 0.0, 2.0),
        light([4.0, 4.0, 0.7], 0.5, 3.0),
        light([12.0, 1.5, 1.0], 0.1, 80.0), // ≈ 5° above the horizon
    ];
    s
}

fn peak(img: &Image) -> f32 {
    img.pixels
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0f32, f32::max)
}

fn check(p: &SceneBuffers, what: &str) {
    let (g, _) = gpu::render(&gpu(), p).unwrap();
    let c = cpu::render(p);
    let d = g.max_abs_diff(&c).unwrap();
    eprintln!(
        "{what} [{}]: max |gpu − cpu| = {d:.2e} (peak {:.3})",
        p.variant.name(),
        peak(&c)
    );
    assert!(peak(&c) > 0.1, "{what}: too dark to test anything");
    assert!(d <= TWIN, "{what}: GPU and CPU twin differ by {d}");
}

/// `ptm` with stored MIP levels of random coefficients (sizes rounded down) and, with `hole`,
/// coverage 0 on a block of texels and ½ around it.
fn with_levels(mut ptm: Ptm, hole: bool) -> Ptm {
    let terms = ptm.basis.len();
    let grid = ptm.learned.as_ref().unwrap().grid;
    ptm.mips = ptm_format::ptm::mip_sizes(ptm.width, ptm.height)
        .into_iter()
        .enumerate()
        .map(|(k, (w, h))| ptm_format::ptm::Level {
            width: w,
            height: h,
            planes: learned_ptm(terms, grid, w, h, 40 + k as u64).planes,
        })
        .collect();
    if hole {
        let w = ptm.width;
        ptm.coverage = Some(
            (0..ptm.width * ptm.height)
                .map(|t| match (t % w, t / w) {
                    (4..8, 3..6) => 0.0,
                    (3..9, 2..7) => 0.5,
                    _ => 1.0,
                })
                .collect(),
        );
    }
    ptm
}

#[test]
fn gpu_matches_twin_for_learned_ptms_on_the_plane() {
    // 1:1 (13 texels over 70/3 px a tile: no chain), for both grids the fitter and the format
    // allow and 3, 6, 11 terms.
    for (terms, grid) in [(11, 17), (6, 17), (3, 5)] {
        let p = scene(learned_ptm(terms, grid, 13, 9, 7), [70, 50])
            .prepare()
            .unwrap();
        assert!(!p.variant.ptm_mip);
        // Whole vec4s a node (11 → 12, 6 → 8, 3 → 4 floats), the padding zero.
        let stride = terms.div_ceil(4) * 4;
        assert_eq!(p.learned.len(), stride * grid * grid);
        assert!(p
            .learned
            .chunks(stride)
            .all(|n| n[terms..].iter().all(|&x| x == 0.0)));
        check(&p, &format!("learned{terms} grid {grid}, 1:1"));
    }
    // Minified by the view (8 tiles of 16 texels over 64 px): the file's stored levels, the
    // table shared by every level; no warning (the levels are stored).
    let ptm = with_levels(learned_ptm(11, 17, 16, 12, 9), false);
    let mut s = scene(ptm, [64, 48]);
    s.view = [0.0, 0.0, 8.0, 6.0];
    let p = s.prepare().unwrap();
    assert!(p.variant.ptm_mip && p.ptm_levels.len() == 5 && p.warnings.is_empty());
    check(&p, "learned11, minified, stored levels");
    // Perspective over stored levels of odd sizes, with coverage (a hole renders black).
    let ptm = with_levels(learned_ptm(6, 17, 13, 9, 5), true);
    let mut s = scene(ptm, [96, 64]);
    s.perspective = Some(Perspective {
        eye: [-2.0, 0.5, 0.8],
        target: [3.0, 1.5, 0.0],
        fov_y_deg: 60.0,
    });
    let p = s.prepare().unwrap();
    assert!(p.variant.ptm_mip && p.variant.coverage && p.ptm_levels.len() == 4);
    check(
        &p,
        "learned6, perspective, stored odd-size levels, coverage",
    );
    // The fitted file, 1:1 and minified through its own levels.
    let fitted = fitted_learned6(8);
    check(
        &scene(fitted.clone(), [48, 48]).prepare().unwrap(),
        "fitted learned6, 1:1",
    );
    let mut s = scene(fitted, [32, 32]);
    s.view = [0.0, 0.0, 16.0, 16.0];
    let p = s.prepare().unwrap();
    assert!(p.variant.ptm_mip);
    check(&p, "fitted learned6, minified");
}

#[test]
fn gpu_matches_twin_for_a_learned_ptm_on_the_mesh_path() {
    // A sphere from the side and above: every tangent frame, lights above and below it.
    let g = gpu();
    for (terms, mips) in [(11, false), (6, true)] {
        let mut ptm = learned_ptm(terms, 17, 12, 10, 3);
        if mips {
            ptm = with_levels(ptm, false);
        }
        let mut s = Scene::over_ptm(ptm, 1, [64, 48]);
        s.lights = vec![
            light([-1.0, -1.5, 2.0], 0.2, 5.0),
            light([1.5, 0.5, 0.8], 0.2, 2.0),
        ];
        s.perspective = Some(Perspective {
            eye: [0.3, -2.2, 1.4],
            target: [0.0, 0.0, 0.5],
            fov_y_deg: 35.0,
        });
        let mut m = MeshScene::plain(s, Mesh::sphere(0.5, 32, 16), [2.0, 2.0]);
        m.sheen_color = [0.3, 0.25, 0.2];
        m.fill = [0.1, 0.1, 0.12];
        let (p, _) = m.prepare().unwrap();
        assert!(p.variant.mesh && p.variant.basis == Some(Basis::Learned(terms as u8)));
        let (gi, _) = gpu::render(&g, &p).unwrap();
        let ci = cpu::render(&p);
        let (mut worst, mut one, mut both) = (0f32, 0, 0);
        for (a, b) in gi.pixels.iter().zip(&ci.pixels) {
            match (a[3] > 0.5, b[3] > 0.5) {
                (true, true) => {
                    both += 1;
                    for c in 0..3 {
                        worst = worst.max((a[c] - b[c]).abs());
                    }
                }
                (false, false) => {}
                _ => one += 1,
            }
        }
        eprintln!(
            "{}: GPU vs twin on the sphere: max {worst:.2e} over {both} pixels (peak {:.3}), {one} \
             silhouette pixels masked",
            p.variant.name(),
            peak(&ci)
        );
        assert!(peak(&ci) > 0.1 && both > 500, "{both} pixels");
        // Edge pixels: fill rules and lavapipe's subpixel snapping (as `mesh.rs`).
        assert!(one <= both / 100, "{one} pixels covered differently");
        assert!(worst <= TWIN, "GPU and CPU twin differ by {worst}");
    }
}

#[test]
fn a_learned_ptm_the_shader_cannot_trust_is_refused() {
    let good = learned_ptm(6, 17, 4, 4, 1);
    let refused = |ptm: Ptm| {
        Scene::over_ptm(ptm, 1, [8, 8])
            .prepare()
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    // A table of 5 terms for 6 coefficient planes.
    let mut ptm = good.clone();
    let t = ptm.learned.as_mut().unwrap();
    t.terms = 5;
    t.values.truncate(5 * 17 * 17);
    let e = refused(ptm);
    assert!(
        e.contains("learned6") && e.contains("5 terms") && e.contains("6 coefficient planes"),
        "{e}"
    );
    // Values that do not fill the grid.
    let mut ptm = good.clone();
    ptm.learned.as_mut().unwrap().values.pop();
    let e = refused(ptm);
    assert!(e.contains("1733 values") && e.contains("1734"), "{e}");
    // A non-finite value.
    let mut ptm = good.clone();
    ptm.learned.as_mut().unwrap().values[17 * 17 + 3] = f32::INFINITY;
    let e = refused(ptm);
    assert!(e.contains("term 1 is inf at grid column 3, row 0"), "{e}");
    // No table, or another link or map.
    let mut ptm = good.clone();
    ptm.learned = None;
    assert!(refused(ptm).contains("carries no table"));
    let mut ptm = good.clone();
    ptm.link = Link::Identity;
    let e = refused(ptm);
    assert!(e.contains("logistic link over the hemispherical"), "{e}");
    // The good one prepares, its table node-major: node (i, j)'s 6 values together, padded to
    // 8 (two vec4s).
    let p = Scene::over_ptm(good.clone(), 1, [8, 8]).prepare().unwrap();
    let table: &LearnedTable = good.learned.as_ref().unwrap();
    for (node, term) in [(0, 0), (5, 3), (17 * 17 - 1, 5), (40, 1)] {
        assert_eq!(
            p.learned[node * 8 + term],
            table.values[term * 17 * 17 + node]
        );
    }
    assert_eq!(p.variant.learned_grid, 17);
}
