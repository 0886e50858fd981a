//! `ptm swatch`: the OBJ it writes is the library's mesh, its JSON report counts it, and bad
//! parameters fail with the parameter's name and allowed range and leave no file behind.

mod common;

use common::{p, ptm};

#[test]
fn swatch_writes_the_library_mesh_and_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pw.obj");
    let run = ptm(
        [
            "--json",
            "swatch",
            "plain-weave?segments=6",
            "--param",
            "along=5",
            "-o",
            p(&out),
        ],
        dir.path(),
    );
    assert!(run.ok, "{}", run.stderr);
    let report: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    // 4 tubes × 2 spacings × 5 rings per spacing × 6 segments × 2 triangles.
    assert_eq!(report["triangles"], 4 * 2 * 5 * 6 * 2);
    assert_eq!(report["swatch"], "plain-weave");
    assert_eq!(report["spec"], "plain-weave?segments=6&along=5");
    assert_eq!(report["tile"], serde_json::json!([2.0, 2.0]));
    assert!(report["min_yarn_gap"].as_f64().unwrap() >= 0.0);
    let stderr = run.stderr;
    assert!(stderr.contains("480 triangles"), "{stderr}");
    let written = ptm_swatches::Mesh::read_obj(&out).unwrap();
    let expect = ptm_swatches::builtin("plain-weave?segments=6&along=5").unwrap();
    assert_eq!(written, expect);
}

#[test]
fn swatch_refuses_bad_parameters_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bad.obj");
    let run = ptm(
        ["swatch", "plain-weave", "-p", "width=2", "-o", p(&out)],
        dir.path(),
    );
    assert!(!run.ok);
    let stderr = run.stderr;
    assert!(
        stderr.contains("width = 2") && stderr.contains("(0, 1]"),
        "{stderr}"
    );
    assert!(!out.exists());
    let run = ptm(["swatch", "tweed", "-o", p(&out)], dir.path());
    assert!(!run.ok);
    let stderr = run.stderr;
    assert!(
        stderr.contains("unknown builtin swatch \"tweed\""),
        "{stderr}"
    );
}
