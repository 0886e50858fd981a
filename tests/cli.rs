//! What every subcommand shares: `--json` prints one `error` object on any failure (argument
//! errors included) with the exit code unchanged, OS errors are said once, and no output may be
//! an input or another output.
use std::path::Path;
use std::process::{Command, Output};

fn ptm(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ptm"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("running ptm")
}

/// The one JSON object a failed `--json` run printed on stdout, and its exit code.
fn json_error(args: &[&str], dir: &Path) -> (serde_json::Value, i32) {
    let out = ptm(args, dir);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{args:?} should fail");
    assert_eq!(
        stdout.lines().count(),
        1,
        "{args:?}: one line of JSON: {stdout}"
    );
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    assert!(v["error"]["message"].is_string(), "{args:?}: {v}");
    assert!(v["error"]["kind"].is_string(), "{args:?}: {v}");
    (v["error"].clone(), out.status.code().unwrap())
}

#[test]
fn json_errors_are_one_object_with_the_exit_code_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // clap's argument errors: exit 2, kind usage, the argument named.
    let (e, code) = json_error(&["--json", "bake", "--res", "abc", "-o", "x.exr"], d);
    assert_eq!((code, e["kind"].as_str()), (2, Some("usage")), "{e}");
    assert!(e["input"].as_str().unwrap().contains("--res"), "{e}");
    assert!(e["message"].as_str().unwrap().contains("abc"), "{e}");
    let (e, code) = json_error(&["swatch", "twill", "--json"], d);
    assert_eq!((code, e["kind"].as_str()), (2, Some("usage")), "{e}");
    assert!(e["message"].as_str().unwrap().contains("--output"), "{e}");
    let (e, code) = json_error(&["--json", "no-such-command"], d);
    assert_eq!(code, 2);
    assert_eq!(e["input"], "no-such-command");
    // Errors of the work: exit 1, the input named.
    let (e, code) = json_error(&["--json", "fit", "missing.exr", "-o", "o.ptm.exr"], d);
    assert_eq!((code, e["kind"].as_str()), (1, Some("io")), "{e}");
    assert_eq!(e["input"], "missing.exr");
    std::fs::write(d.join("bad.lp"), "2\na 0 0 1\n").unwrap();
    let (e, code) = json_error(
        &[
            "--json", "bake", "--lights", "bad.lp", "--res", "4", "-o", "o.exr",
        ],
        d,
    );
    assert_eq!((code, e["kind"].as_str()), (1, Some("invalid")), "{e}");
    assert_eq!(e["input"], "bad.lp");
    let (e, code) = json_error(&["--json", "swatch", "no-such-weave", "-o", "o.obj"], d);
    assert_eq!(code, 1);
    assert_eq!(e["input"], "no-such-weave", "{e}");
    let (e, _) = json_error(
        &["--json", "preview", "--ptm", "gone.ptm.exr", "-o", "o.png"],
        d,
    );
    assert_eq!(e["input"], "gone.ptm.exr", "{e}");
    // Help is not an error.
    let out = ptm(&["--json", "fit", "--help"], d);
    assert!(out.status.success());
}

#[test]
fn the_os_error_is_said_once() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        &["fit", "missing.exr", "-o", "o.ptm.exr"][..],
        &["bake", "--lights", "missing.lp", "-o", "o.exr"],
        &["bake", "--swatch", "missing.obj", "-o", "o.exr"],
        &["preview", "--ptm", "missing.ptm.exr", "-o", "o.png"],
        &["swatch", "draft?path=missing.wif", "-o", "o.obj"],
        &["swatch", "twill", "-o", "nodir/o.obj"],
    ] {
        let out = ptm(args, dir.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert_eq!(
            stderr.matches("No such file or directory").count(),
            1,
            "{args:?}: {stderr}"
        );
    }
}
