//! Integration tests of `ptm preview`: a PTM file written by ptm-fit rendered on the GPU
//! (lavapipe in CI), the JSON report, turntable sheets, the blur comparison, and errors.
mod common;

use std::path::{Path, PathBuf};

use common::{p, ptm};
use ptm_format::{Basis, Ptm, SaveOptions};
use serde_json::Value;

/// A 16×16 ptm6 whose K varies with the light's u (so the image depends on the PTM).
fn write_ptm(dir: &Path) -> PathBuf {
    let (w, h) = (16, 16);
    let mut planes = vec![vec![0.0f32; w * h]; 6];
    planes[1] = (0..w * h)
        .map(|t| 0.6 * (t % w) as f32 / w as f32)
        .collect(); // u
    planes[5] = (0..w * h) // 1
        .map(|t| 0.2 + 0.3 * (t / w) as f32 / h as f32)
        .collect();
    let p = Ptm {
        basis: Basis::Ptm6,
        width: w,
        height: h,
        link: ptm_format::Link::Identity,
        uv: ptm_format::UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
        learned: None,
    };
    let path = dir.join("weave.ptm.exr");
    p.save(&path, &SaveOptions::default()).unwrap();
    path
}

/// A 32×32 RGBA caster: an opaque disc, red, on transparent.
fn write_caster(dir: &Path) -> PathBuf {
    let mut rgba = Vec::new();
    for j in 0..32 {
        for i in 0..32 {
            let (x, y) = (i as f32 - 15.5, j as f32 - 15.5);
            rgba.extend_from_slice(&[220, 40, 40, if x * x + y * y < 100.0 { 255 } else { 0 }]);
        }
    }
    let path = dir.join("caster.png");
    ptm_runtime::output::write_png_rgba8(&path, 32, 32, &rgba).unwrap();
    path
}

/// `ptm --json preview args…`: the one JSON object it printed.
fn run_json(args: &[&str]) -> Value {
    common::json([&["preview"][..], args].concat(), Path::new("."))
}

/// `ptm preview ARGS…` fails and its error says `says`.
fn assert_refused(dir: &Path, args: &[&str], says: &str) {
    let out = ptm([&["preview"][..], args].concat(), dir);
    assert!(
        !out.ok && out.stderr.contains(says),
        "{args:?}: {}",
        out.stderr
    );
}

fn png_size(path: &Path) -> (usize, usize) {
    let (w, h, _) = ptm_runtime::output::read_rgba8(path).unwrap();
    (w, h)
}

#[test]
fn preview_renders_a_ptm_with_a_caster_and_reports_passes() {
    let dir = tempfile::tempdir().unwrap();
    let ptm_path = write_ptm(dir.path());
    let caster = write_caster(dir.path());
    let png = dir.path().join("preview.png");
    let exr = dir.path().join("preview.exr");
    let j = run_json(&[
        "--ptm",
        ptm_path.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--exr",
        exr.to_str().unwrap(),
        "--size",
        "96,64",
        "--light",
        "0.5,1.5,1.5",
        "--light-radius",
        "0.2",
        "--intensity",
        "3",
        "--light",
        "-1,-1,2",
        "--color",
        "1,0.5,0.2",
        "--caster",
        caster.to_str().unwrap(),
        "--caster-height",
        "0.4",
        "--caster-size",
        "1,1",
        "--blur",
        "sat",
    ]);
    assert_eq!(png_size(&png), (96, 64));
    assert!(exr.exists());
    assert_eq!(j["variant"], "ptm6+sat");
    assert_eq!(j["lights"], 2);
    assert!(j["adapter"].as_str().unwrap().len() > 3);
    for pass in ["compile", "upload", "sat_build", "shade", "readback"] {
        assert!(
            j["seconds_passes"][pass].as_f64().unwrap() >= 0.0,
            "missing pass {pass}: {j}"
        );
    }
    assert!(j["k_unclamped"]["evaluations"].as_u64().unwrap() > 0);
}

#[test]
fn preview_without_ptm_and_turntable_sheet() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("sheet.png");
    let j = run_json(&[
        "-o",
        png.to_str().unwrap(),
        "--size",
        "40,30",
        "--turntable",
        "5",
    ]);
    assert_eq!(j["variant"], "nok");
    assert_eq!(j["turntable"]["frames"], 5);
    // 5 frames in one row of 40 × 30 under 7-pixel label strips, 2-pixel gutters.
    assert_eq!(png_size(&png), (5 * 40 + 6 * 2, 37 + 2 * 2));
}

/// Issue #25.6: 8 turntable frames make a 4×2 sheet with no empty cell, grey gutters between
/// the frames, and each frame's azimuth written above it.
#[test]
fn a_turntable_of_eight_is_four_by_two_with_gutters_and_labels() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("sheet.png");
    let j = run_json(&["-o", p(&png), "--size", "40,30", "--turntable", "8"]);
    let t = &j["turntable"];
    assert_eq!(
        (t["columns"].as_u64(), t["rows"].as_u64()),
        (Some(4), Some(2)),
        "{j}"
    );
    let az: Vec<f64> = t["azimuths_deg"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_f64().unwrap())
        .collect();
    assert_eq!(az, [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0]);
    let (w, h, rgba) = ptm_runtime::output::read_rgba8(&png).unwrap();
    assert_eq!((w, h), (4 * 40 + 5 * 2, 2 * 37 + 3 * 2));
    let at = |x: usize, y: usize| rgba[y * w + x];
    let grey = at(0, 0);
    assert!(grey[0] > 60 && grey[0] < 200, "gutter {grey:?}");
    for cy in 0..2 {
        for cx in 0..4 {
            let (x0, y0) = (2 + cx * 42, 2 + cy * 39);
            // The gutter before each cell, the label's white pixels in its strip, and a lit frame.
            assert_eq!(at(x0 - 1, y0 + 20), grey);
            let white = (y0..y0 + 7)
                .flat_map(|y| (x0..x0 + 40).map(move |x| (x, y)))
                .filter(|&(x, y)| at(x, y)[..3] == [255, 255, 255])
                .count();
            assert!(white >= 10, "cell {cx},{cy}: {white} label pixels");
            let lit = (y0 + 7..y0 + 37).any(|y| at(x0 + 20, y)[0] > 20);
            assert!(lit, "cell {cx},{cy} is black");
        }
    }
}

#[test]
fn compare_blur_reports_every_method_against_monte_carlo() {
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let png = dir.path().join("c.png");
    let j = run_json(&[
        "-o",
        png.to_str().unwrap(),
        "--size",
        "48,48",
        "--caster",
        caster.to_str().unwrap(),
        "--caster-height",
        "0.5",
        "--light-radius",
        "0.3",
        "--compare-blur",
        "--mc-samples",
        "64",
    ]);
    let rows = j["compare_blur"].as_array().unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    for m in ptm_runtime::Blur::ALL {
        assert!(methods.contains(&m.name()), "{methods:?}");
    }
    for r in rows {
        let e = r["max_abs_error"].as_f64().unwrap();
        assert!(e.is_finite() && e < 0.5, "{r}");
    }
}

#[test]
fn rectangular_lights_render_and_compare_against_monte_carlo() {
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let png = dir.path().join("r.png");
    let j = run_json(&[
        "-o",
        png.to_str().unwrap(),
        "--size",
        "48,48",
        "--caster",
        caster.to_str().unwrap(),
        "--caster-height",
        "0.5",
        "--light-rect",
        "0.8,0.1",
        "--compare-blur",
        "--mc-samples",
        "256",
    ]);
    assert!(png.exists());
    let rows = j["compare_blur"].as_array().unwrap();
    let sat = rows.iter().find(|r| r["method"] == "sat").unwrap();
    let e = sat["mean_abs_error"].as_f64().unwrap();
    assert!(e.is_finite() && e < 0.01, "{sat}");
}

#[test]
fn a_turned_rectangular_light_renders_compares_and_refuses_the_separable_blur() {
    // Side A turned 30° from X: the parallelogram of boxes within 1 % of the lit radiance of
    // the reference that samples the turned rectangle (0.2–0.4 % in tests/rect_light.rs); the
    // separable blur, whose kernels run along X and Y, is refused naming the flag.
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let png = dir.path().join("t.png");
    let args = |blur: &'static str| {
        vec![
            "-o".to_string(),
            png.to_str().unwrap().to_string(),
            "--size".into(),
            "48,48".into(),
            "--caster".into(),
            caster.to_str().unwrap().to_string(),
            "--caster-height".into(),
            "0.5".into(),
            "--light-rect".into(),
            "0.8,0.1,30".into(),
            "--blur".into(),
            blur.into(),
        ]
    };
    let mut a = args("sat");
    a.extend(["--compare-blur".into(), "--mc-samples".into(), "256".into()]);
    let j = run_json(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let rows = j["compare_blur"].as_array().unwrap();
    let sat = rows.iter().find(|r| r["method"] == "sat").unwrap();
    let e = sat["mean_abs_error"].as_f64().unwrap();
    assert!(e.is_finite() && e < 0.01, "{sat}");
    let mut a = vec!["preview".to_string()];
    a.extend(args("separable"));
    let out = ptm(a.iter().map(String::as_str), dir.path());
    assert!(
        !out.ok
            && out.stderr.contains("--light-rect 0.8,0.1,30")
            && out.stderr.contains("separable"),
        "{}",
        out.stderr
    );
}

#[test]
fn gaussian_lights_render_and_compare_against_monte_carlo() {
    // A Gaussian light 4:1: the SAT's three-box kernel against the reference that draws from
    // the Gaussian (within 1 % of the lit radiance in tests/gaussian.rs of the runtime).
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let png = dir.path().join("g.png");
    let j = run_json(&[
        "-o",
        png.to_str().unwrap(),
        "--size",
        "48,48",
        "--caster",
        caster.to_str().unwrap(),
        "--caster-height",
        "0.5",
        "--light-gaussian",
        "0.2,0.05",
        "--compare-blur",
        "--mc-samples",
        "256",
    ]);
    assert!(png.exists());
    let rows = j["compare_blur"].as_array().unwrap();
    let sat = rows.iter().find(|r| r["method"] == "sat").unwrap();
    let e = sat["mean_abs_error"].as_f64().unwrap();
    assert!(e.is_finite() && e < 0.01, "{sat}");
    // Refused: σ ≤ 0 or not finite, and both shapes at once.
    for (bad, says) in [
        (
            "--light-gaussian=0,0.1",
            "--light-gaussian 0,0.1: both standard deviations",
        ),
        (
            "--light-gaussian=0.1,-1",
            "--light-gaussian 0.1,-1: both standard deviations",
        ),
        (
            "--light-gaussian=nan,0.1",
            "--light-gaussian NaN,0.1: both standard deviations",
        ),
    ] {
        assert_refused(dir.path(), &[bad, "-o", p(&png)], says);
    }
    assert_refused(
        dir.path(),
        &[
            "--light-gaussian=0.1,0.1",
            "--light-rect=0.1,0.1",
            "-o",
            p(&png),
        ],
        "choose one",
    );
}

#[test]
fn distant_lights_render_compare_and_refuse_what_they_cannot_do() {
    // The sun (and a second distant light) over a PTM and a caster: the distant-only variant,
    // its shadow against the Monte Carlo reference over its cone; mixed with a local light
    // the variant has both paths.
    let dir = tempfile::tempdir().unwrap();
    let ptm_path = write_ptm(dir.path());
    let caster = write_caster(dir.path());
    let png = dir.path().join("sun.png");
    let common = [
        "--ptm",
        p(&ptm_path),
        "-o",
        p(&png),
        "--size",
        "48,48",
        "--caster",
        p(&caster),
        "--caster-height",
        "0.4",
    ];
    let j = run_json(
        &[
            &common[..],
            &[
                "--light-distant",
                "50,120,2",
                "--light-distant=20,-30",
                "--compare-blur",
                "--mc-samples",
                "256",
            ],
        ]
        .concat(),
    );
    assert!(png.exists());
    assert_eq!(j["lights"], 2);
    assert!(
        j["variant"].as_str().unwrap().ends_with("distant-only"),
        "{j}"
    );
    let rows = j["compare_blur"].as_array().unwrap();
    let sat = rows.iter().find(|r| r["method"] == "sat").unwrap();
    let e = sat["mean_abs_error"].as_f64().unwrap();
    assert!(e.is_finite() && e < 0.01, "{sat}");
    let j = run_json(
        &[
            &common[..],
            &["--light-distant", "50,120", "--light", "0,0,2"],
        ]
        .concat(),
    );
    assert_eq!(j["lights"], 2);
    assert!(j["variant"].as_str().unwrap().ends_with("+distant"), "{j}");
    for (bad, says) in [
        ("--light-distant=0,10", "the elevation must be above 0°"),
        ("--light-distant=95,10", "the elevation must be above 0°"),
        ("--light-distant=30,inf", "the azimuth must be"),
        (
            "--light-distant=30,10,50",
            "the angular radius must be 0 to 45",
        ),
        ("--light-distant=30", "expected ELEV,AZ or ELEV,AZ,RADIUS"),
    ] {
        assert_refused(dir.path(), &[bad, "-o", p(&png)], says);
    }
    assert_refused(
        dir.path(),
        &["--light-distant=30,10", "--window", "--window-frames", "1"],
        "not with --window",
    );
    // On a mesh: K per pixel in the tangent frame and the macro shadow from the stand-in.
    let obj = write_floor_and_square(dir.path());
    let j = run_json(&[
        "--ptm",
        p(&ptm_path),
        "--mesh",
        p(&obj),
        "--size",
        "48,36",
        "--shadow-size",
        "256",
        "--camera",
        "0,-3.5,4.5",
        "--light-distant",
        "55,20,1",
        "-o",
        p(&png),
    ]);
    assert!(
        j["variant"]
            .as_str()
            .unwrap()
            .ends_with("mesh+shadow+distant"),
        "{j}"
    );
}

#[test]
fn preview_errors_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("x.png");
    let out = ptm(["preview", "-o", p(&png), "--compare-blur"], dir.path());
    assert!(!out.ok);
    assert!(out.stderr.contains("--compare-blur needs a caster"));
    let out = ptm(
        ["preview", "--ptm", "/nonexistent.ptm.exr", "-o", p(&png)],
        dir.path(),
    );
    assert!(!out.ok);
    assert!(out.stderr.contains("nonexistent.ptm.exr"));
    // Values that would render an all-black image are refused, naming the value.
    for (args, says) in [
        (["--albedo=nan,0.5,0.5"], "--albedo [NaN, 0.5, 0.5]"),
        (["--albedo=-0.2,0.5,0.5"], "--albedo [-0.2, 0.5, 0.5]"),
        (
            ["--camera=0.5,0.5,-2"],
            "--camera [0.5, 0.5, -2.0]: the eye must be",
        ),
        (["--light-rect=0,1"], "--light-rect 0,1: both sides must be"),
        (
            ["--light-rect=1,-2"],
            "--light-rect 1,-2: both sides must be",
        ),
        (
            ["--light-rect=inf,1"],
            "--light-rect inf,1: both sides must be",
        ),
        (
            ["--light-rect=1,1,nan"],
            "--light-rect 1,1,NaN: the turn must be",
        ),
        (["--light-rect=1,1,2,3"], "expected A,B or A,B,DEG"),
    ] {
        let out = ptm(["preview", args[0], "-o", p(&png)], dir.path());
        let err = out.stderr;
        assert!(!out.ok && err.contains(says), "{args:?}: {err}");
        assert!(!dir.path().join("x.png").exists());
    }
}

/// Issue #25.1: the renderer layout `ptm fit --layout rgba` writes renders as the channel
/// layout does, named by its first part or by the stem when only the parts exist; an error
/// never calls a renderer-layout part truncated.
#[test]
fn preview_reads_the_renderer_layout_by_either_name() {
    let dir = tempfile::tempdir().unwrap();
    let channels = write_ptm(dir.path());
    let loaded = Ptm::load(&channels).unwrap();
    let rgba = dir.path().join("parts.ptm.exr");
    ptm_format::layout::save(
        &loaded,
        &rgba,
        &SaveOptions::default(),
        ptm_format::Layout::Rgba,
    )
    .unwrap();
    assert!(!rgba.exists() && dir.path().join("parts.ptm.c0.exr").exists());
    let render = |input: &Path, name: &str| {
        let png = dir.path().join(name);
        let out = ptm(
            [
                "preview",
                "--ptm",
                p(input),
                "-o",
                p(&png),
                "--size",
                "32,32",
            ],
            dir.path(),
        );
        assert!(
            out.ok && !out.stderr.contains("truncated"),
            "{}: {}",
            input.display(),
            out.stderr
        );
        ptm_runtime::output::read_rgba8(&png).unwrap()
    };
    let want = render(&channels, "channels.png");
    assert_eq!(render(&rgba, "stem.png"), want);
    assert_eq!(render(&dir.path().join("parts.ptm.c0.exr"), "c0.png"), want);
}

/// Issue #25.8: on a non-square tile `--repeat N` shows N tiles each way and the default size
/// keeps the cloth's texels square (512 along the longer side); `--repeat X,Y` picks each;
/// `--json` says how many tiles the view shows.
#[test]
fn repeat_covers_both_axes_of_a_non_square_tile() {
    let dir = tempfile::tempdir().unwrap();
    let mut strip = Ptm::load(&write_ptm(dir.path())).unwrap();
    strip.tile = [2.0, 0.716];
    let path = dir.path().join("strip.ptm.exr");
    strip.save(&path, &SaveOptions::default()).unwrap();
    let png = dir.path().join("r.png");
    let j = run_json(&["--ptm", p(&path), "-o", p(&png), "--repeat", "2"]);
    assert_eq!(png_size(&png), (512, 183), "{j}");
    let tiles = j["tiles"].as_array().unwrap();
    assert!((tiles[0].as_f64().unwrap() - 2.0).abs() < 0.01, "{j}");
    assert!((tiles[1].as_f64().unwrap() - 2.0).abs() < 0.01, "{j}");
    let j = run_json(&["--ptm", p(&path), "-o", p(&png), "--repeat", "3,8"]);
    // 6 × 5.728 swatch units: 512 × 489 pixels, square on the cloth.
    assert_eq!(png_size(&png), (512, 489), "{j}");
    let view = j["view"].as_array().unwrap();
    // Widened by at most the rounding of 489 pixels.
    assert!(
        (view[3].as_f64().unwrap() - 5.728).abs() < 6.0 / 512.0,
        "{j}"
    );
    // A square --size of a wide view shows more tiles down, and says so.
    let j = run_json(&["--ptm", p(&path), "-o", p(&png), "--size", "64,64"]);
    let down = j["tiles"][1].as_f64().unwrap();
    assert!((down - 4.0 / 0.716).abs() < 0.01, "{j}");
}

/// Issue #25.5: `--caster builtin:leaves` needs no file, its default placement (centre, size,
/// height) scales with the view so that its shadow lands in frame on any tile, and a caster
/// whose shadow misses the view is warned about on stderr and in `--json`.
#[test]
fn a_builtin_caster_shadows_the_view_and_a_missed_shadow_is_warned() {
    let dir = tempfile::tempdir().unwrap();
    let mut cloth = Ptm::load(&write_ptm(dir.path())).unwrap();
    let png = |n: &str| dir.path().join(n);
    let plain = png("plain.png");
    let leaves = png("leaves.png");
    for (tile, name) in [([1.0, 1.0], "unit"), ([3.0, 3.0], "three")] {
        cloth.tile = tile;
        let path = dir.path().join(format!("{name}.ptm.exr"));
        cloth.save(&path, &SaveOptions::default()).unwrap();
        let args = ["--ptm", p(&path), "--size", "48,48"];
        run_json(&[&args[..], &["-o", p(&plain)]].concat());
        let j = run_json(&[&args[..], &["--caster", "builtin:leaves", "-o", p(&leaves)]].concat());
        assert_eq!(j["warnings"], serde_json::json!([]), "{name}: {j}");
        let mean = |f: &Path| {
            let (_, _, px) = ptm_runtime::output::read_rgba8(f).unwrap();
            px.iter().map(|p| p[1] as f64).sum::<f64>() / px.len() as f64
        };
        assert!(
            mean(&leaves) < 0.97 * mean(&plain),
            "{name}: no shadow in view"
        );
    }
    let out = ptm(
        [
            "--json",
            "preview",
            "--caster",
            "builtin:leaves",
            "--caster-center",
            "50,50",
            "--size",
            "32,32",
            "-o",
            p(&leaves),
        ],
        dir.path(),
    );
    assert!(out.ok, "{}", out.stderr);
    assert!(
        out.stderr.contains("caster's shadow under light 0"),
        "{}",
        out.stderr
    );
    let j: Value = serde_json::from_str(&out.stdout).unwrap();
    assert!(
        j["warnings"][0]
            .as_str()
            .unwrap()
            .contains("wholly outside the view"),
        "{j}"
    );
    let bad = ptm(
        ["preview", "--caster", "builtin:oak", "-o", p(&leaves)],
        dir.path(),
    );
    assert!(
        !bad.ok && bad.stderr.contains("builtin:leaves"),
        "{}",
        bad.stderr
    );
}

/// Issue #22: a learned file renders on the plane and on a mesh (the variant says so); a learned
/// file whose header disagrees with its table is refused naming the file.
#[test]
fn preview_renders_a_learned_file_and_names_a_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("learned.ptm.exr");
    let learned = ptm_runtime::synthetic::learned_ptm(6, 17, 16, 16, 2);
    learned.save(&path, &SaveOptions::default()).unwrap();
    let png = dir.path().join("l.png");
    let j = run_json(&["--ptm", p(&path), "-o", p(&png), "--size", "48,40"]);
    assert_eq!(j["variant"], "learned6+grid17+logistic+hemispherical");
    assert_eq!(png_size(&png), (48, 40));
    // σ never leaves [0, 1]: nothing clamped.
    assert_eq!(j["k_unclamped"]["clamped_fraction"], 0.0);
    let j = run_json(&[
        "--ptm",
        p(&path),
        "-o",
        p(&png),
        "--size",
        "48,40",
        "--mesh",
        "sphere",
    ]);
    let variant = j["variant"].as_str().unwrap();
    assert!(
        variant.starts_with("learned6+grid17+logistic+hemispherical") && variant.contains("mesh"),
        "{variant}"
    );
    // The same file with `ptm:basis` learned5: its header's table holds 6 terms, its basis 5.
    let bytes = std::fs::read(&path).unwrap();
    let at: Vec<usize> = bytes
        .windows(8)
        .enumerate()
        .filter(|(_, w)| *w == b"learned6")
        .map(|(i, _)| i)
        .collect();
    assert!(!at.is_empty(), "the header names its basis");
    let mut bad = bytes.clone();
    for i in at {
        bad[i + 7] = b'5';
    }
    let bad_path = dir.path().join("bad.ptm.exr");
    std::fs::write(&bad_path, bad).unwrap();
    let out = ptm(
        ["preview", "--ptm", p(&bad_path), "-o", p(&png)],
        dir.path(),
    );
    assert!(!out.ok, "a bad learned file rendered");
    assert!(
        out.stderr.contains("bad.ptm.exr") && out.stderr.contains("learned5"),
        "{}",
        out.stderr
    );
}

/// A user's OBJ (not a built-in): a 4 × 4 floor and a 1 × 1 square floating above it, both with
/// UVs, and one sliver triangle whose UVs are a single point (a degenerate map).
fn write_floor_and_square(dir: &Path) -> PathBuf {
    let obj = "# floor, a floating square, a degenerate-UV sliver\n\
               v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\n\
               v -0.5 -0.5 1\nv 0.5 -0.5 1\nv 0.5 0.5 1\nv -0.5 0.5 1\n\
               v 1.5 1.5 0.01\nv 1.8 1.5 0.01\nv 1.8 1.8 0.01\n\
               vt 0 0\nvt 4 0\nvt 4 4\nvt 0 4\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
               f 1/1 2/2 3/3 4/4\nf 5/5 6/6 7/7 8/8\nf 9/1 10/1 11/1\n";
    let path = dir.join("user_mesh.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

/// Issue #21: `--turntable` on a mesh turns the light about the mesh's centre, frame by frame,
/// and the mesh's macro shadow turns with it; `--json` counts the degenerate-UV triangle and
/// states the shadow maps. `--window` is no longer refused with `--mesh` by the parser.
#[test]
fn a_mesh_turntable_turns_the_light_and_the_shadow_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let ptm_path = write_ptm(dir.path());
    let obj = write_floor_and_square(dir.path());
    let png = dir.path().join("turn.png");
    let j = run_json(&[
        "--ptm",
        p(&ptm_path),
        "--mesh",
        p(&obj),
        "--size",
        "48,36",
        "--shadow-size",
        "256",
        "--camera",
        "0,-3.5,4.5",
        "--light",
        "1.5,0,3",
        "--turntable",
        "4",
        "-o",
        p(&png),
    ]);
    assert_eq!(j["turntable"]["frames"], 4, "{j}");
    let m = &j["mesh"];
    assert_eq!(m["triangles"], 5, "{j}");
    assert_eq!(m["tangent_fallback_triangles"], 1, "{j}");
    assert_eq!(m["shadow_map_size"], 256, "{j}");
    assert_eq!(m["shadow_map_bytes"], 256 * 256 * 4, "{j}");
    assert!(
        j["variant"].as_str().unwrap().contains("mesh+shadow"),
        "{j}"
    );
    // Four frames, 2 × 2 (48 × 36 under a 7-pixel label, 2-pixel gutters); each frame's floor
    // is shadowed somewhere else.
    let t = &j["turntable"];
    assert_eq!(
        (t["columns"].as_u64(), t["rows"].as_u64()),
        (Some(2), Some(2))
    );
    let (w, h, rgba) = ptm_runtime::output::read_rgba8(&png).unwrap();
    assert_eq!((w, h), (2 * 48 + 3 * 2, 2 * 43 + 3 * 2));
    let frame = |k: usize| -> Vec<u8> {
        let (x0, y0) = (2 + (k % 2) * 50, 2 + (k / 2) * 45 + 7);
        (y0..y0 + 36)
            .flat_map(|y| (x0..x0 + 48).map(move |x| (x, y)))
            .map(|(x, y)| rgba[y * w + x][0])
            .collect()
    };
    for k in 1..4 {
        let differ = frame(0)
            .iter()
            .zip(frame(k))
            .filter(|(a, b)| a.abs_diff(*b) > 8)
            .count();
        assert!(
            differ > 40,
            "frame {k} differs from frame 0 in {differ} pixels"
        );
    }
    // The same without the macro shadow: no shadow maps, and the floor is lighter under the
    // square in frame 0.
    let flat = dir.path().join("flat.png");
    let j = run_json(&[
        "--ptm",
        p(&ptm_path),
        "--mesh",
        p(&obj),
        "--size",
        "48,36",
        "--no-shadow",
        "--camera",
        "0,-3.5,4.5",
        "--light",
        "1.5,0,3",
        "-o",
        p(&flat),
    ]);
    assert_eq!(j["mesh"]["shadow_map_size"], 0, "{j}");
    assert!(!j["variant"].as_str().unwrap().contains("shadow"), "{j}");
    let (_, _, lit) = ptm_runtime::output::read_rgba8(&flat).unwrap();
    let sum = |px: &[[u8; 4]]| px.iter().map(|p| p[0] as u64).sum::<u64>();
    let first: Vec<[u8; 4]> = frame(0).iter().map(|&r| [r, 0, 0, 255]).collect();
    assert!(
        sum(&lit) > sum(&first) + 200,
        "{} vs {}",
        sum(&lit),
        sum(&first)
    );
    // The window is not refused by the parser with a mesh (this build may lack the window).
    let out = ptm(
        [
            "preview",
            "--mesh",
            "drape",
            "--window",
            "--window-frames",
            "1",
        ],
        dir.path(),
    );
    assert!(
        !out.stderr.contains("cannot be used with"),
        "{}",
        out.stderr
    );
}

/// Issue #21's bad input, through the command: an OBJ without UVs is refused with its name and
/// the flag that projects some; `--uv-projection planar` renders it.
#[test]
fn a_mesh_without_uvs_is_refused_by_name_or_projected() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("no_uv.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
    let png = dir.path().join("m.png");
    let out = ptm(
        [
            "preview",
            "--mesh",
            p(&obj),
            "--size",
            "32,24",
            "-o",
            p(&png),
        ],
        dir.path(),
    );
    assert!(!out.ok);
    assert!(
        out.stderr.contains("no_uv.obj") && out.stderr.contains("--uv-projection"),
        "{}",
        out.stderr
    );
    let j = run_json(&[
        "--mesh",
        p(&obj),
        "--uv-projection",
        "planar",
        "--size",
        "32,24",
        "-o",
        p(&png),
    ]);
    assert_eq!(j["mesh"]["triangles"], 2, "{j}");
}

#[test]
fn a_glossy_cloth_reflects_the_caster_over_the_background() {
    // From straight above, Schlick's F is F0: with --reflectance 1 the pixel is the reflection
    // alone, the red disc's colour under its middle and the background where the lobe misses
    // the caster; with --reflectance 0 it is the matte render, byte for byte.
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let render = |name: &str, extra: &[&str]| {
        let png = dir.path().join(name);
        let mut args = vec!["-o", p(&png), "--size", "32,32", "--caster", p(&caster)];
        args.extend_from_slice(extra);
        run_json(&args);
        ptm_runtime::output::read_rgba8(&png).unwrap().2
    };
    let matte = render("matte.png", &[]);
    let none = render("f0.png", &["--glossy", "0", "--reflectance", "0"]);
    assert_eq!(matte, none);
    let mirror = render(
        "mirror.png",
        &[
            "--glossy",
            "0.2",
            "--reflectance",
            "1",
            "--background",
            "0.2,0.3,0.5",
        ],
    );
    let encode = |x: f32| {
        let s = if x <= 0.0031308 {
            12.92 * x
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round() as i32
    };
    let near = |got: [u8; 4], want: [i32; 3], what: &str| {
        for k in 0..3 {
            assert!(
                (got[k] as i32 - want[k]).abs() <= 2,
                "{what}: {got:?} vs {want:?}"
            );
        }
    };
    near(mirror[0], [0.2, 0.3, 0.5].map(encode), "corner");
    near(mirror[16 * 32 + 16], [220, 40, 40], "under the disc");
    assert_ne!(mirror, matte);
    // Refused before any GPU work, naming the flag.
    for (bad, says) in [
        (&["--glossy", "1.5"][..], "--glossy 1.5"),
        (&["--glossy=-0.1"][..], "--glossy -0.1"),
        (&["--glossy", "nan"][..], "--glossy NaN"),
        (
            &["--glossy", "0.2", "--background", "1,-1,0"][..],
            "--background 1,-1,0",
        ),
        (
            &["--glossy", "0.2", "--reflectance", "2"][..],
            "--reflectance 2",
        ),
        (
            &["--glossy", "0.2", "--blur", "separable"][..],
            "--blur separable",
        ),
    ] {
        let png = dir.path().join("bad.png");
        let mut args = vec!["preview", "-o", p(&png), "--caster", p(&caster)];
        args.extend_from_slice(bad);
        let out = ptm(args, dir.path());
        assert!(
            !out.ok && out.stderr.contains(says),
            "{bad:?}: {}",
            out.stderr
        );
    }
    let png = dir.path().join("bad.png");
    let out = ptm(["preview", "-o", p(&png), "--glossy", "0.2"], dir.path());
    assert!(
        !out.ok && out.stderr.contains("--glossy reflects the caster"),
        "{}",
        out.stderr
    );
    // Still refused with a mesh, naming both flags.
    let mut args = vec!["preview", "-o", p(&png), "--caster", p(&caster)];
    args.extend_from_slice(&["--glossy", "0.2", "--mesh", "drape"]);
    let out = ptm(args, dir.path());
    assert!(
        !out.ok && out.stderr.contains("--glossy") && out.stderr.contains("--mesh"),
        "{}",
        out.stderr
    );
    // The window shows a glossy cloth: not refused (this build may lack the window, or the
    // machine a display, and says so; under Xvfb with the window it runs its one frame).
    let out = ptm(
        [
            "preview",
            "--caster",
            p(&caster),
            "--glossy",
            "0.2",
            "--window",
            "--window-frames",
            "1",
        ],
        dir.path(),
    );
    assert!(!out.stderr.contains("--glossy"), "{}", out.stderr);
}

#[test]
fn a_glossy_cloth_reflects_a_background_image() {
    // A lat-long PNG sky of one colour (sRGB 40, 90, 200): with --reflectance 1 the corner,
    // where the lobe misses the caster, is that colour, whatever the roughness; the image is
    // refused without --glossy, missing or unreadable, naming the flag and the file.
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let sky = dir.path().join("sky.png");
    ptm_runtime::output::write_png_rgba8(&sky, 16, 8, &[40, 90, 200, 255].repeat(16 * 8)).unwrap();
    for roughness in ["0", "0.3"] {
        let png = dir.path().join("sky-out.png");
        run_json(&[
            "-o",
            p(&png),
            "--size",
            "32,32",
            "--caster",
            p(&caster),
            "--glossy",
            roughness,
            "--reflectance",
            "1",
            "--background-image",
            p(&sky),
        ]);
        let px = ptm_runtime::output::read_rgba8(&png).unwrap().2;
        for k in 0..3 {
            let want = [40, 90, 200][k];
            assert!(
                (px[0][k] as i32 - want).abs() <= 1,
                "{roughness}: {:?}",
                px[0]
            );
        }
    }
    let not_image = dir.path().join("sky.exr");
    std::fs::write(&not_image, b"no").unwrap();
    let missing = dir.path().join("missing.png");
    for (extra, says) in [
        (
            vec!["--background-image", p(&sky)],
            "add --glossy".to_string(),
        ),
        (
            vec!["--glossy", "0.2", "--background-image", p(&missing)],
            format!("--background-image {}", missing.display()),
        ),
        (
            vec!["--glossy", "0.2", "--background-image", p(&not_image)],
            "sky.exr".to_string(),
        ),
    ] {
        let png = dir.path().join("bad.png");
        let mut args = vec!["preview", "-o", p(&png), "--caster", p(&caster)];
        args.extend_from_slice(&extra);
        let out = ptm(args, dir.path());
        assert!(
            !out.ok && out.stderr.contains(&says),
            "{extra:?}: {}",
            out.stderr
        );
        assert!(!png.exists());
    }
}

#[test]
fn compare_blur_with_glossy_reports_the_reflection_against_the_ray_traced_lobe() {
    // Each per-pixel method's reflected radiance against the ray-traced lobe (runtime
    // tests/glossy.rs holds sat and explicit to 2 % of it); separable has no per-pixel kernel.
    let dir = tempfile::tempdir().unwrap();
    let caster = write_caster(dir.path());
    let png = dir.path().join("g.png");
    let j = run_json(&[
        "-o",
        png.to_str().unwrap(),
        "--size",
        "32,32",
        "--caster",
        caster.to_str().unwrap(),
        "--caster-height",
        "0.5",
        "--glossy",
        "0.25",
        "--compare-blur",
        "--mc-samples",
        "1024",
    ]);
    assert!(png.exists());
    let rows = j["compare_blur"].as_array().unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(methods, ["explicit", "sat", "mip"]);
    for r in rows {
        let e = r["mean_abs_error"].as_f64().unwrap();
        assert!(e.is_finite() && e < 0.02, "{r}");
    }
}
