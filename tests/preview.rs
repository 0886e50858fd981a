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
    // 5 frames, 3 columns: 3 × 2 cells of 40 × 30.
    assert_eq!(png_size(&png), (120, 60));
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
    ] {
        let out = ptm(["preview", args[0], "-o", p(&png)], dir.path());
        let err = out.stderr;
        assert!(!out.ok && err.contains(says), "{args:?}: {err}");
        assert!(!dir.path().join("x.png").exists());
    }
}
