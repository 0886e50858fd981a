//! The command words the libraries' typed errors and diagnostics for the command line: the
//! library states the fact (and names no flag), `ptm` adds the flag and the fix.
mod common;

use std::path::Path;

use common::{dome, p, ptm};
use ptm_fit::SampleStack;
use ptm_format::exrio::Attr;
use ptm_format::LightSet;

fn stack(lights: &LightSet, w: usize, h: usize) -> SampleStack {
    let k = (0..lights.len())
        .map(|l| (0..w * h).map(|t| ((l + t) % 5) as f32 / 5.0).collect())
        .collect();
    SampleStack::new(lights.clone(), w, h, [1.0, 1.0], k)
}

/// Runs `ptm fit` with `args` after the input and output; its exit status and stderr.
fn fit(samples: &Path, out: &Path, args: &[&str]) -> (bool, String) {
    let mut all = vec!["fit", p(samples), "-o", p(out), "--link", "identity"];
    all.extend(args);
    let o = ptm(&all, Path::new("."));
    (o.ok, o.stderr)
}

#[test]
fn fit_errors_name_the_flag_that_fixes_them() {
    let dir = tempfile::tempdir().unwrap();
    let samples = dir.path().join("s.exr");
    let out = dir.path().join("s.ptm.exr");
    let mut s = stack(&dome(20), 4, 3);
    s.write(&samples).unwrap();

    // More hold-out lights than lights.
    let (ok, err) = fit(&samples, &out, &["--holdout", "20"]);
    assert!(!ok);
    assert!(
        err.contains("--holdout 20: holding out 20 lights leaves no light to fit (20 lights)"),
        "{err}"
    );

    // A non-finite sample: the texel and light, then the flag that drops such samples.
    s.k[7][2 * 4 + 1] = f32::NAN;
    s.write(&samples).unwrap();
    let (ok, err) = fit(&samples, &out, &[]);
    assert!(!ok);
    assert!(
        err.contains("non-finite sample NaN at texel (column 1, row 2) for light 7: fix the input, or pass --skip-bad"),
        "{err}"
    );
    // Dropped, the diagnostic says by which flag, in the JSON too.
    let j = common::json(
        [
            "fit",
            p(&samples),
            "-o",
            p(&out),
            "--link",
            "identity",
            "--skip-bad",
        ],
        dir.path(),
    );
    let w = j["warnings"].as_array().unwrap();
    assert_eq!(
        w[0],
        "1 non-finite samples in 1 texels were dropped; 0 of those texels lost rank (--skip-bad)"
    );
    // The file records the fact, without the command's flag.
    let c = ptm_format::exrio::read(&out).unwrap();
    assert_eq!(
        c.attrs.get("ptm:warnings"),
        Some(&Attr::Texts(vec![
            "1 non-finite samples in 1 texels were dropped; 0 of those texels lost rank".into()
        ]))
    );

    // HP export of a ptm11 fit.
    s.k[7][2 * 4 + 1] = 0.5;
    s.write(&samples).unwrap();
    let (ok, err) = fit(
        &samples,
        &out,
        &[
            "--basis",
            "ptm11",
            "--export-hp",
            p(&dir.path().join("s.ptm")),
        ],
    );
    assert!(!ok);
    assert!(err.contains("--basis ptm6"), "{err}");
}

/// A file cut short names itself once and says it may be truncated, whichever command reads it
/// (a PTM through `ptm convert`, which reads either layout; a sample stack through `ptm fit`),
/// cut in its header or in its pixels.
#[test]
fn a_truncated_file_is_named_once_and_called_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    stack(&dome(20), 8, 6).write(&d.join("s.exr")).unwrap();
    common::ok(["fit", "s.exr", "-o", "w.ptm.exr", "--link", "identity"], d);
    for (file, command) in [
        ("w.ptm.exr", vec!["convert", "t.exr", "-o", "x.ptm.exr"]),
        ("s.exr", vec!["fit", "t.exr", "-o", "y.ptm.exr"]),
    ] {
        let bytes = std::fs::read(d.join(file)).unwrap();
        for keep in [40, bytes.len() / 2] {
            std::fs::write(d.join("t.exr"), &bytes[..keep]).unwrap();
            let err = common::refused(&command, d);
            assert_eq!(
                err.matches("t.exr").count(),
                1,
                "{file} cut at {keep}: {err}"
            );
            assert!(
                err.contains("truncated or foreign?"),
                "{file} cut at {keep}: {err}"
            );
        }
    }
}
