//! What every subcommand shares: `--json` prints one `error` object on any failure (argument
//! errors included) with the exit code unchanged, OS errors are said once, and no output may be
//! an input or another output.
mod common;

use std::path::Path;
use std::process::Command;

use common::{ptm, Run, BOX_OBJ};

/// The one JSON object a failed `--json` run printed on stdout, and its exit code.
fn json_error(args: &[&str], dir: &Path) -> (serde_json::Value, i32) {
    let out = ptm(args, dir);
    let stdout = out.stdout;
    assert!(!out.ok, "{args:?} should fail");
    assert_eq!(
        stdout.lines().count(),
        1,
        "{args:?}: one line of JSON: {stdout}"
    );
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    assert!(v["error"]["message"].is_string(), "{args:?}: {v}");
    assert!(v["error"]["kind"].is_string(), "{args:?}: {v}");
    (v["error"].clone(), out.code.unwrap())
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
    let out = ptm(["--json", "fit", "--help"], d);
    assert!(out.ok);
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
        let stderr = out.stderr;
        assert!(!out.ok, "{args:?}");
        // The OS's words, or the PTM reader's "no such file (nor a renderer-layout part …)".
        assert_eq!(
            stderr.to_lowercase().matches("no such file").count(),
            1,
            "{args:?}: {stderr}"
        );
    }
}

/// A light file as a user writes it: directions not of unit length, short names.
const CAP_LP: &str = "4\na 1 0 1\nb 0 1 1\nc -1 0 1\nd 0 -1 2\n";

const BAKE: [&str; 5] = ["bake", "--res", "4", "--spp", "1"];

fn bake(extra: &[&str], dir: &Path) -> Run {
    let mut args = BAKE.to_vec();
    args.extend(extra);
    ptm(&args, dir)
}

/// Asserts that the run failed saying `says`; its stderr.
fn refused(out: &Run, says: &str) -> String {
    let stderr = out.stderr.clone();
    assert!(!out.ok, "should fail: {stderr}");
    assert!(stderr.contains(says), "expected {says:?}: {stderr}");
    stderr
}

#[test]
fn no_output_may_be_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("pw.obj"), BOX_OBJ).unwrap();
    std::fs::write(d.join("cap.lp"), CAP_LP).unwrap();
    std::fs::write(d.join("t.wif"), "not a draft, and never overwritten\n").unwrap();
    std::fs::write(d.join("p.ptm.exr"), "stands for a PTM\n").unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink("pw.obj", d.join("link.obj")).unwrap();
    let snapshot = |names: &[&str]| -> Vec<Vec<u8>> {
        names
            .iter()
            .map(|n| std::fs::read(d.join(n)).unwrap())
            .collect()
    };
    let names = ["pw.obj", "cap.lp", "t.wif", "p.ptm.exr"];
    let before = snapshot(&names);
    let o = bake(&["--dirs", "4", "--swatch", "pw.obj", "-o", "pw.obj"], d);
    refused(&o, "is the swatch pw.obj");
    // The same file through a link.
    #[cfg(unix)]
    refused(
        &bake(&["--dirs", "4", "--swatch", "pw.obj", "-o", "link.obj"], d),
        "is the swatch",
    );
    let o = bake(
        &["--swatch", "pw.obj", "--lights", "cap.lp", "-o", "cap.lp"],
        d,
    );
    refused(&o, "is the light file cap.lp");
    let o = bake(&["--swatch", "builtin:draft?path=t.wif", "-o", "t.wif"], d);
    refused(&o, "is the swatch draft t.wif");
    let o = ptm(["swatch", "draft?path=t.wif", "-o", "t.wif"], d);
    refused(&o, "is the draft t.wif");
    let o = ptm(["preview", "--ptm", "p.ptm.exr", "-o", "p.ptm.exr"], d);
    refused(&o, "is the PTM p.ptm.exr");
    let o = ptm(["preview", "--caster", "pw.obj", "-o", "pw.obj"], d);
    refused(&o, "is the caster");
    let o = ptm(["preview", "-o", "x.png", "--exr", "x.png"], d);
    refused(&o, "same file");
    let o = ptm(
        [
            "fit", "--images", "*.png", "--lights", "cap.lp", "-o", "cap.lp",
        ],
        d,
    );
    refused(&o, "is the light file cap.lp");
    let o = ptm(
        [
            "fit", "--images", "*.obj", "--lights", "cap.lp", "-o", "pw.obj",
        ],
        d,
    );
    refused(&o, "is the image");
    // A Slurm job written over its own manifest.
    let manifest = "[[bake]]\nswatch = \"builtin:plain-weave\"\nres = 16\noutput = \"o.exr\"\n";
    std::fs::create_dir(d.join("job")).unwrap();
    std::fs::write(d.join("job/tasks.txt"), manifest).unwrap();
    let o = ptm(["batch", "job/tasks.txt", "--slurm", "job"], d);
    refused(&o, "is the manifest");
    assert_eq!(
        std::fs::read_to_string(d.join("job/tasks.txt")).unwrap(),
        manifest
    );
    assert_eq!(std::fs::read_dir(d.join("job")).unwrap().count(), 1);
    assert_eq!(snapshot(&names), before, "an input was rewritten");
    assert!(!d.join("x.png").exists());

    // Baking from cap.lp into cap.exr: the .lp beside the output would be the user's light
    // file. It already holds these lights, so it is left exactly as written.
    let o = bake(
        &[
            "--swatch", "pw.obj", "--lights", "cap.lp", "--json", "-o", "cap.exr",
        ],
        d,
    );
    assert!(o.ok, "{}", o.stderr);
    assert_eq!(std::fs::read_to_string(d.join("cap.lp")).unwrap(), CAP_LP);
    let j: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(j["lights_file"], "cap.lp");
    let stack = ptm_fit::SampleStack::read(&d.join("cap.exr")).unwrap();
    let user = ptm_format::LightSet::read_lp(&d.join("cap.lp")).unwrap();
    assert_eq!(stack.lights, user);
}

#[test]
fn a_failed_output_publishes_none() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The .lp beside out.exr is a directory: refused before the bake, out.exr never written.
    std::fs::create_dir(d.join("out.lp")).unwrap();
    let o = bake(&["--dirs", "4", "-o", "out.exr"], d);
    refused(&o, "out.lp");
    assert!(!d.join("out.exr").exists());
    // The EXR's directory does not exist: the PNG is not written either (checked before the
    // scene is built, so this needs no GPU).
    let o = ptm(["preview", "-o", "x.png", "--exr", "nodir/x.exr"], d);
    refused(&o, "nodir");
    assert!(!d.join("x.png").exists());
    // Nothing else was left behind (no temporary files).
    let names: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
    // ptm merge: the .lp beside the merged file is a directory, so the merge does not run.
    let o = bake(&["--dirs", "4", "--shard", "0/1", "-o", "s.exr"], d);
    assert!(o.ok, "{}", o.stderr);
    std::fs::create_dir(d.join("m.lp")).unwrap();
    let o = ptm(["merge", "s.part-0000-of-0001.exr", "-o", "m.exr"], d);
    refused(&o, "m.lp");
    assert!(!d.join("m.exr").exists());
}

#[cfg(unix)]
#[test]
fn a_device_output_is_written_through_with_nothing_beside_it() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    // As root, a null device of our own (so a regression cannot replace the machine's
    // /dev/null); otherwise /dev/null itself, which only root could replace.
    let own = dir.path().join("null");
    let made = Command::new("mknod")
        .arg(&own)
        .args(["c", "1", "3"])
        .status()
        .is_ok_and(|s| s.success());
    let null = if made { own } else { "/dev/null".into() };
    let lp = null.with_file_name("null.lp");
    let null_arg = null.to_str().unwrap();
    let o = bake(&["--dirs", "4", "-o", null_arg], dir.path());
    assert!(o.ok, "{}", o.stderr);
    let o = bake(
        &["--dirs", "4", "--fit", "ptm6", "-o", null_arg],
        dir.path(),
    );
    assert!(o.ok, "{}", o.stderr);
    let o = ptm(["swatch", "twill", "-o", null_arg], dir.path());
    assert!(o.ok, "{}", o.stderr);
    // A farm part merged into the device: no .lp beside it either.
    let work = tempfile::tempdir().unwrap();
    let o = bake(
        &["--dirs", "4", "--shard", "0/1", "-o", "s.exr"],
        work.path(),
    );
    assert!(o.ok, "{}", o.stderr);
    let o = ptm(
        ["merge", "s.part-0000-of-0001.exr", "-o", null_arg],
        work.path(),
    );
    assert!(o.ok, "{}", o.stderr);
    let meta = std::fs::metadata(&null).unwrap();
    assert!(meta.file_type().is_char_device(), "{null:?} was replaced");
    assert!(!lp.exists(), "bake created {lp:?}");
    if made {
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "{left:?}");
    }
}

#[cfg(unix)]
#[test]
fn output_names_need_not_be_utf8() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |args: &[&OsStr]| ptm(args, d);
    let name = |s: &[u8]| OsStr::from_bytes(s).to_owned();
    let obj = name(b"w\xff.obj");
    let stack = name(b"s\xff.exr");
    let fitted = name(b"f\xff.ptm.exr");
    let os = |s: &'static str| OsStr::new(s);
    let o = run(&[os("--json"), os("swatch"), os("twill"), os("-o"), &obj]);
    assert!(o.ok, "{}", o.stderr);
    let mut bake: Vec<&OsStr> = ["--json", "bake", "--res", "4", "--spp", "1", "--dirs", "8"]
        .into_iter()
        .map(os)
        .collect();
    bake.extend([os("-o"), &stack]);
    let o = run(&bake);
    assert!(o.ok, "{}", o.stderr);
    let j: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(j["output"], "s\u{fffd}.exr");
    let o = run(&[os("--json"), os("fit"), &stack, os("-o"), &fitted]);
    assert!(o.ok, "{}", o.stderr);
    let j: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(j["output"], "f\u{fffd}.ptm.exr");
    for f in [&obj, &stack, &name(b"s\xff.lp"), &fitted] {
        assert!(d.join(f).is_file(), "{f:?} missing");
    }
}

/// Every key of a JSON value, nested ones included.
fn keys(v: &serde_json::Value, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                out.push(k.clone());
                keys(x, out);
            }
        }
        serde_json::Value::Array(a) => a.iter().for_each(|x| keys(x, out)),
        _ => {}
    }
}

#[test]
fn timings_are_seconds_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut reports = Vec::new();
    for args in [
        &["--json", "swatch", "twill", "-o", "t.obj"][..],
        &[
            "--json", "bake", "--res", "4", "--spp", "1", "--dirs", "8", "-o", "s.exr",
        ],
        &[
            "--json",
            "bake",
            "--res",
            "4",
            "--spp",
            "1",
            "--dirs",
            "8",
            "--fit",
            "ptm6",
            "-o",
            "b.ptm.exr",
        ],
        &["--json", "fit", "s.exr", "-o", "f.ptm.exr"],
        // Renders on whatever adapter wgpu finds (lavapipe in CI), as tests/preview.rs does.
        &[
            "--json",
            "preview",
            "--ptm",
            "f.ptm.exr",
            "--size",
            "16,16",
            "-o",
            "p.png",
        ],
        &[
            "--json",
            "preview",
            "--size",
            "16,16",
            "--turntable",
            "2",
            "-o",
            "t.png",
        ],
    ] {
        let o = ptm(args, d);
        assert!(o.ok, "{args:?}: {}", o.stderr);
        let j: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
        assert!(j["seconds"].as_f64().unwrap() >= 0.0, "{args:?}: {j}");
        reports.push(j);
    }
    assert!(reports[1]["seconds_shadow"].is_f64());
    let fit = reports[2]["fit"].as_object().unwrap();
    assert!(fit.contains_key("seconds_newton"), "{fit:?}");
    assert!(reports[4]["seconds_device"].is_f64(), "{}", reports[4]);
    assert!(
        reports[4]["seconds_passes"]["shade"].is_f64(),
        "{}",
        reports[4]
    );
    for j in &reports {
        let mut all = Vec::new();
        keys(j, &mut all);
        for k in all {
            let rate = k.ends_with("_per_s");
            let timing = k.ends_with("_s") || k.contains("secs") || k.contains("time");
            assert!(
                rate || !timing,
                "timing key {k:?}: use seconds / seconds_<stage>"
            );
            assert!(
                !k.contains("seconds") || k == "seconds" || k.starts_with("seconds_"),
                "{k:?}"
            );
        }
    }
}

/// A PNG header (signature, IHDR, an empty IDAT, IEND) for an RGBA8 image of `w`×`h`: enough
/// for a decoder to read the size.
fn png_header(w: u32, h: u32) -> Vec<u8> {
    fn crc(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let chunk = |kind: &[u8], data: &[u8], out: &mut Vec<u8>| {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc(&body).to_be_bytes());
    };
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 6, 0, 0, 0]); // 8-bit RGBA, no interlace
    chunk(b"IHDR", &ihdr, &mut png);
    chunk(b"IDAT", &[], &mut png);
    chunk(b"IEND", &[], &mut png);
    png
}

#[test]
fn counts_that_would_allocate_without_bound_are_refused_with_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("big.png"), png_header(16384, 16384)).unwrap();
    let o = ptm(["preview", "--caster", "big.png", "-o", "x.png"], d);
    let e = refused(&o, "big.png");
    assert!(
        e.contains("16384×16384") && e.contains("512 MiB") && e.contains("downscale"),
        "{e}"
    );
    let o = bake(&["--threads", "100000", "-o", "x.exr"], d);
    assert_eq!(o.code, Some(2));
    refused(&o, "at most 1024 threads");
    let o = ptm(["preview", "--size", "100000,100000", "-o", "x.png"], d);
    refused(&o, "1 to 16384 pixels");
    let o = ptm(
        [
            "preview",
            "--size",
            "4096,4096",
            "--turntable",
            "64",
            "-o",
            "x.png",
        ],
        d,
    );
    refused(&o, "lower --size or --turntable");
    assert!(!d.join("x.png").exists() && !d.join("x.exr").exists());
}

/// `kill -9` while an output is being written leaves a temporary file beside it (never a
/// half-written output); the next `ptm` that writes into that directory removes it.
#[test]
fn a_killed_writers_temporary_is_swept_by_the_next_write() {
    use ptm_fit::SampleStack;
    use ptm_format::LightSet;
    let d = tempfile::tempdir().unwrap();
    let (w, h, n) = (512, 512, 48);
    let lights = LightSet::from_dirs((0..n).map(|i| {
        let z = 0.2 + 0.8 * (i as f64 + 0.5) / n as f64;
        let (r, a) = ((1.0 - z * z).sqrt(), 2.4 * i as f64);
        [r * a.cos(), r * a.sin(), z]
    }));
    let k = (0..n)
        .map(|l| {
            (0..w * h)
                .map(|t| ((l * 7 + t) % 11) as f32 / 11.0)
                .collect()
        })
        .collect();
    SampleStack::new(lights, w, h, [1.0, 1.0], k)
        .write(&d.path().join("s.exr"))
        .unwrap();
    let out = d.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let temps = |dir: &Path| -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.starts_with(".ptm-"))
            .collect()
    };
    // Kill the fit the moment its temporary output appears; a machine fast enough to finish
    // first gets another try.
    let mut left = Vec::new();
    for _ in 0..5 {
        let mut child = common::command()
            .args(["fit", "s.exr", "-o", "out/s.ptm.exr", "--link", "identity"])
            .current_dir(d.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        loop {
            left = temps(&out);
            if !left.is_empty() || child.try_wait().unwrap().is_some() {
                break;
            }
        }
        let _ = child.kill(); // SIGKILL
        child.wait().unwrap();
        left = temps(&out);
        if !left.is_empty() {
            break;
        }
        let _ = std::fs::remove_file(out.join("s.ptm.exr"));
    }
    assert!(!left.is_empty(), "never caught the fit writing");
    assert!(
        !out.join("s.ptm.exr").exists(),
        "nothing half-written is published"
    );

    // Any command that writes into the directory sweeps the dead writer's temporary.
    let o = ptm(["swatch", "plain-weave", "-o", "out/w.obj"], d.path());
    assert!(o.ok, "{}", o.stderr);
    assert_eq!(temps(&out), Vec::<String>::new(), "left {left:?}");
}

/// The closing line names the files that exist afterwards: the renderer layout's parts, not
/// the stem given to `-o`.
#[test]
fn the_renderer_layout_reports_its_parts() {
    let d = tempfile::tempdir().unwrap();
    let bake = [
        "bake", "--res", "16", "--dirs", "8", "--spp", "1", "--fit", "ptm6", "--layout", "rgba",
    ];
    let o = ptm([&bake[..], &["-o", "w.ptm.exr"]].concat(), d.path());
    let err = o.stderr;
    assert!(o.ok, "{err}");
    assert!(
        err.contains("wrote w.ptm.c0.exr, w.ptm.c1.exr and w.lp"),
        "{err}"
    );
    let o = ptm(
        [&bake[..], &["--json", "-o", "j.ptm.exr"]].concat(),
        d.path(),
    );
    let v: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(
        v["files"],
        serde_json::json!(["j.ptm.c0.exr", "j.ptm.c1.exr"])
    );
    for f in [
        "w.ptm.c0.exr",
        "w.ptm.c1.exr",
        "j.ptm.c0.exr",
        "j.ptm.c1.exr",
    ] {
        assert!(d.path().join(f).exists(), "{f}");
    }
}
