//! Integration tests of `ptm bake`: outputs and their `.lp`, streaming `--fit` against a fit of
//! the stored stack, identical bytes for any thread count, and refusals that write nothing.
mod common;

use common::{ptm, Run, BOX_OBJ};
use ptm_fit::SampleStack;
use ptm_format::{LightSet, Ptm};

#[test]
fn bake_writes_stack_and_lp_and_json() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.obj"), BOX_OBJ).unwrap();
    let Run {
        ok, stdout, stderr, ..
    } = ptm(
        [
            "--json",
            "bake",
            "--swatch",
            "box.obj",
            "--res",
            "24,16",
            "--dirs",
            "12",
            "--spp",
            "4",
            "-o",
            "samples.exr",
        ],
        dir.path(),
    );
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["triangles"], 12);
    assert_eq!(j["lights"], 12);
    assert_eq!(j["rays"]["primary"], 24 * 16 * 4);
    assert_eq!(j["rings"].as_array().unwrap().len(), 12);
    assert!(j["mrays_per_s"].as_f64().unwrap() > 0.0);
    assert_eq!(j["uncovered_texels"], 0);
    let stack = SampleStack::read(&dir.path().join("samples.exr")).unwrap();
    assert_eq!(
        (stack.width, stack.height, stack.tile),
        (24, 16, [1.0, 1.0])
    );
    assert_eq!(stack.k.len(), 12);
    assert!(stack.coverage.iter().all(|&c| c == 1.0));
    let lp = LightSet::read_lp(&dir.path().join("samples.lp")).unwrap();
    assert_eq!(lp, stack.lights);
    assert!(lp.dirs.iter().all(|d| d[2] > 5f64.to_radians().sin()));
    // The box top is never occluded; the floor beside it sometimes is.
    let top = 8 * 24 + 12; // row 8 (y ≈ 0.47), column 12 (x ≈ 0.52)
    assert!(stack.k.iter().all(|k| k[top] == 0.0));
    assert!(stack.k.iter().any(|k| k.iter().any(|&v| v > 0.0)));
}

#[test]
fn streaming_fit_matches_fitting_the_stack_and_threads_give_identical_samples() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.obj"), BOX_OBJ).unwrap();
    let common = [
        "bake",
        "--swatch",
        "box.obj",
        "--res",
        "16",
        "--dome",
        "rings:15x6,40x8,75x4",
        "--spp",
        "4",
    ];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = common.iter().chain(extra).copied().collect();
        let Run { ok, stderr, .. } = ptm(&args, dir.path());
        assert!(ok, "{stderr}");
    };
    run(&["--threads", "1", "-o", "one.exr"]);
    run(&["--threads", "2", "-o", "two.exr"]);
    // Identical files, byte for byte, and so identical samples bit for bit.
    assert!(
        std::fs::read(dir.path().join("one.exr")).unwrap()
            == std::fs::read(dir.path().join("two.exr")).unwrap(),
        "1 and 2 threads wrote different bytes"
    );
    let one = SampleStack::read(&dir.path().join("one.exr")).unwrap();
    let two = SampleStack::read(&dir.path().join("two.exr")).unwrap();
    let bits = |s: &SampleStack| -> Vec<u32> {
        s.k.iter()
            .flatten()
            .chain(&s.coverage)
            .map(|v| v.to_bits())
            .collect()
    };
    assert!(bits(&one) == bits(&two), "1 and 2 threads differ");
    assert_eq!(one.lights, two.lights);
    run(&["--fit", "ptm6", "-o", "stream.ptm.exr"]);
    assert!(dir.path().join("stream.lp").exists());
    let Run { ok, stderr, .. } = ptm(
        ["fit", "one.exr", "--basis", "ptm6", "-o", "stored.ptm.exr"],
        dir.path(),
    );
    assert!(ok, "{stderr}");
    let a = Ptm::load(&dir.path().join("stream.ptm.exr")).unwrap();
    let b = Ptm::load(&dir.path().join("stored.ptm.exr")).unwrap();
    assert_eq!(a.planes.len(), 6);
    for (pa, pb) in a.planes.iter().zip(&b.planes) {
        for (x, y) in pa.iter().zip(pb) {
            assert!((x - y).abs() < 1e-4, "{x} vs {y}");
        }
    }
}

#[test]
fn bad_inputs_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = [
        ("empty.obj", "", "empty file"),
        (
            "nan.obj",
            "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "non-finite",
        ),
        ("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "index"),
        ("none.obj", "v 0 0 0\nv 1 0 0\n", "no triangles"),
        ("bad.lp", "2\na 0 0 1\n", "2 lights"),
    ];
    for (name, text, _) in &inputs {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    std::fs::write(dir.path().join("ok.obj"), BOX_OBJ).unwrap();
    let before: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (
            vec!["--swatch", "missing.obj"],
            "missing.obj",
            "cannot read",
        ),
        (vec!["--swatch", "empty.obj"], "empty.obj", "empty file"),
        (vec!["--swatch", "nan.obj"], "nan.obj", "non-finite"),
        (vec!["--swatch", "range.obj"], "range.obj", "index"),
        (vec!["--swatch", "none.obj"], "none.obj", "no triangles"),
        (
            vec!["--swatch", "ok.obj", "--tile", "0,1"],
            "ok.obj",
            "tile",
        ),
        (
            vec!["--swatch", "ok.obj", "--tile", "-1,1"],
            "ok.obj",
            "tile size -1×1 must be positive and finite",
        ),
        (
            vec!["--swatch", "ok.obj", "--tile", "inf,1"],
            "ok.obj",
            "tile size inf×1 must be positive and finite",
        ),
        (
            vec!["--swatch", "ok.obj", "--tile", "1e-30,1e-30"],
            "ok.obj",
            "at most 16 tiles per axis",
        ),
        (
            vec!["--swatch", "ok.obj", "--threads", "100000"],
            "'100000' for '--threads",
            "at most 1024",
        ),
        (
            vec!["--swatch", "ok.obj", "--light-distance", "1e-30"],
            "--light-distance 1e-30",
            "inside the swatch",
        ),
        (
            vec!["--swatch", "ok.obj", "--dome", "fibonacci:1000000000000"],
            "1000000000000 lights",
            "at most 1048576",
        ),
        (
            vec!["--swatch", "builtin:no-such-weave"],
            "no-such-weave",
            "unknown",
        ),
        (
            vec!["--swatch", "ok.obj", "--lights", "bad.lp"],
            "bad.lp",
            "2 lights",
        ),
        (
            vec!["--swatch", "ok.obj", "--dome", "rings:10x"],
            "--dome",
            "count",
        ),
        // Far beyond any machine's memory: refused before anything is allocated.
        (
            vec!["--swatch", "ok.obj", "--dirs", "100000000000"],
            "100000000000 lights",
            "memory is available",
        ),
        (
            vec!["--swatch", "ok.obj", "--res", "10000000"],
            "10000000×10000000 texels",
            "--fit ptm6",
        ),
    ];
    for (args, names, says) in cases {
        let mut all = vec!["bake", "--res", "8", "--dirs", "4"];
        if args.contains(&"--lights") || args.contains(&"--dome") || args.contains(&"--dirs") {
            all.truncate(3);
        }
        if args.contains(&"--res") {
            all.drain(1..3);
        }
        all.extend(&args);
        all.extend(["-o", "out.exr"]);
        let Run { ok, stderr, .. } = ptm(&all, dir.path());
        assert!(!ok, "{args:?} should fail");
        assert!(
            stderr.contains(names) && stderr.contains(says),
            "{args:?}: {stderr}"
        );
    }
    let after: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(before.len(), after.len(), "a refused bake wrote {after:?}");
}

#[test]
fn bake_fit_writes_the_renderer_layout_and_convert_round_trips_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let Run {
        ok, stderr: err, ..
    } = ptm(
        [
            "bake",
            "--res",
            "16",
            "--spp",
            "2",
            "--dirs",
            "24",
            "--fit",
            "ptm11",
            "--link",
            "logistic",
            "--layout",
            "rgba",
            "-o",
            "w.ptm.exr",
        ],
        d,
    );
    assert!(ok, "{err}");
    for k in 0..3 {
        assert!(d.join(format!("w.ptm.c{k}.exr")).exists());
    }
    assert!(!d.join("w.ptm.exr").exists());
    let Run {
        ok,
        stdout: out,
        stderr: err,
        ..
    } = ptm(["convert", "w.ptm.exr", "-o", "c.ptm.exr", "--json"], d);
    assert!(ok, "{err}");
    assert!(out.contains("\"to\":\"channels\""), "{out}");
    let direct = ptm_format::layout::load(&d.join("w.ptm.c0.exr")).unwrap();
    assert_eq!(Ptm::load(&d.join("c.ptm.exr")).unwrap(), direct);
    let Run {
        ok, stderr: err, ..
    } = ptm(["convert", "c.ptm.exr", "-o", "r.ptm.exr"], d);
    assert!(ok, "{err}");
    for k in 0..3 {
        let a = std::fs::read(d.join(format!("w.ptm.c{k}.exr"))).unwrap();
        let b = std::fs::read(d.join(format!("r.ptm.c{k}.exr"))).unwrap();
        assert!(a == b, "part c{k} differs after channels → rgba");
    }
    // A missing part is an error naming it; nothing is written.
    std::fs::remove_file(d.join("w.ptm.c2.exr")).unwrap();
    let Run {
        ok, stderr: err, ..
    } = ptm(["convert", "w.ptm.c0.exr", "-o", "x.ptm.exr"], d);
    assert!(!ok);
    assert!(
        err.contains("w.ptm.c2.exr") && err.contains("part c2"),
        "{err}"
    );
    assert!(!d.join("x.ptm.exr").exists());
}

/// Issue #25.7: an OBJ whose `# tile` header was dropped (as some OBJ tools do) bakes over its
/// bounding box; when that tile is not periodic the warning names the likely cause and what to
/// do, on stderr and in `--json`; `ptm bake --help` documents the header.
#[test]
fn a_dropped_tile_header_is_named_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A knit: its loops reach past the tile, so its bounding box is larger than the tile.
    common::ok(["swatch", "jersey", "-o", "pw.obj"], d);
    let obj = std::fs::read_to_string(d.join("pw.obj")).unwrap();
    assert!(obj.contains("# tile "));
    let edited: String = obj
        .lines()
        .filter(|l| !l.starts_with("# tile"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(d.join("edited.obj"), edited).unwrap();
    let args = [
        "bake",
        "--swatch",
        "edited.obj",
        "--res",
        "4",
        "--dirs",
        "4",
    ];
    let run = common::ptm([&args[..], &["--spp", "1", "-o", "s.exr"]].concat(), d);
    assert!(run.ok, "{}", run.stderr);
    for says in ["not periodic", "bounding box", "`# tile W H`", "--tile W,H"] {
        assert!(run.stderr.contains(says), "no {says:?} in {}", run.stderr);
    }
    let j = common::json([&args[..], &["--spp", "1", "-o", "t.exr"]].concat(), d);
    let w = j["warnings"].to_string();
    assert!(w.contains("bounding box") && w.contains("--tile"), "{w}");
    // With the header the same mesh bakes without a seam warning.
    let run = common::ptm(
        [
            "bake", "--swatch", "pw.obj", "--res", "4", "--dirs", "4", "--spp", "1", "-o", "u.exr",
        ],
        d,
    );
    assert!(
        run.ok && !run.stderr.contains("not periodic"),
        "{}",
        run.stderr
    );
    let help = common::ok(["bake", "--help"], d);
    assert!(help.contains("# tile W H"), "{help}");
}

/// Issue #25.8: `--res N` on a non-square tile keeps texels square (N along the longer side),
/// says so, and `--json` gives the texel's size; `--res W,H` is taken as given.
#[test]
fn res_n_keeps_texels_square_on_a_non_square_tile() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let flat = "# tile 2 0.716\nv 0 0 0\nv 2 0 0\nv 2 0.716 0\nv 0 0.716 0\nf 1 2 3 4\n";
    std::fs::write(d.join("strip.obj"), flat).unwrap();
    let bake = |res: &str, out: &str| {
        let args = ["bake", "--swatch", "strip.obj", "--res", res, "--dirs", "4"];
        common::ptm(
            [&["--json"][..], &args, &["--spp", "1", "-o", out]].concat(),
            d,
        )
    };
    let run = bake("64", "a.exr");
    assert!(run.ok, "{}", run.stderr);
    let j: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(64), Some(23)),
        "{j}"
    );
    let texel = [
        j["texel"][0].as_f64().unwrap(),
        j["texel"][1].as_f64().unwrap(),
    ];
    assert!((texel[0] / texel[1] - 1.0).abs() < 0.01, "{texel:?}");
    assert!(
        run.stderr.contains("64×23 texels, square"),
        "{}",
        run.stderr
    );
    let run = bake("64,64", "b.exr");
    let j: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(64), Some(64))
    );
}

/// A light at or below the horizon is named in `warnings` (bake and streaming fit alike, with
/// `--json`), keeps its index in `below_horizon`, bakes to K = 1, and is left out of the fit.
#[test]
fn lights_below_the_horizon_are_named_and_left_out_of_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("box.obj"), BOX_OBJ).unwrap();
    let mut lights = common::dome(12);
    lights.dirs[3] = ptm_format::vec3::normalize([0.954, 0.0, -0.3]); // a sign error in z
    lights.names[3] = "low".into();
    std::fs::write(d.join("dome.lp"), lights.to_lp()).unwrap();
    let bake = |extra: &[&str]| {
        let mut args = vec![
            "bake", "--swatch", "box.obj", "--res", "16", "--spp", "2", "--lights", "dome.lp",
        ];
        args.extend(extra);
        common::json(args, d)
    };
    let named =
        "1 light at or below the horizon bake to K = 1 (fully occluded): light 3 \"low\" at -17.";
    let j = bake(&["-o", "s.exr"]);
    assert_eq!(j["below_horizon"], serde_json::json!([3]));
    let w = j["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w.as_str().unwrap().starts_with(named)),
        "{w:?}"
    );
    let stack = SampleStack::read(&d.join("s.exr")).unwrap();
    assert!(stack.k[3].iter().all(|&k| k == 1.0));

    let j = bake(&["-o", "w.ptm.exr", "--fit", "ptm6", "--link", "identity"]);
    let w = j["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w.as_str().unwrap().starts_with(named)),
        "{w:?}"
    );
    let left_out = "1 light at or below the horizon left out of the fit (K = 1 there by \
                    definition): light 3 \"low\" at -17.";
    let fw = j["fit"]["warnings"].as_array().unwrap();
    assert!(
        fw.iter().any(|w| w.as_str().unwrap().starts_with(left_out)),
        "{fw:?}"
    );
    // The file records it too, and fitted 11 lights.
    let attrs = ptm_format::exrio::read(&d.join("w.ptm.exr")).unwrap().attrs;
    assert_eq!(
        attrs.get("ptm:nLightsFit"),
        Some(&ptm_format::exrio::Attr::I32(11))
    );
    match attrs.get("ptm:warnings") {
        Some(ptm_format::exrio::Attr::Texts(t)) => {
            assert!(t.iter().any(|w| w.starts_with(left_out)), "{t:?}")
        }
        other => panic!("ptm:warnings is {other:?}"),
    }
}

/// `--maps` writes NAME.maps.exr beside the output with the same texels, whether K is kept as
/// a stack or streamed into a fit, leaves the stack or PTM byte for byte as a bake without
/// maps writes it, and names the yarns of a builtin weave (warp, weft) and an OBJ's `usemtl`
/// groups; `--maps-png` adds the 16-bit PNGs.
#[test]
fn maps_beside_the_stack_and_the_fit() {
    use ptm_format::exrio;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = ["bake", "--res", "16", "--dirs", "12", "--spp", "4"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        common::json(args, d)
    };
    run(&["-o", "plain.exr"]);
    let j = run(&["-o", "samples.exr", "--maps"]);
    assert_eq!(j["maps"]["file"], "samples.maps.exr");
    assert_eq!(
        std::fs::read(d.join("plain.exr")).unwrap(),
        std::fs::read(d.join("samples.exr")).unwrap(),
        "--maps changed the stack"
    );
    let fit = ["--fit", "ptm6", "--link", "identity"];
    run(&[&fit[..], &["-o", "a.ptm.exr"]].concat());
    let j = run(&[&fit[..], &["-o", "b.ptm.exr", "--maps-png"]].concat());
    assert_eq!(j["maps"]["file"], "b.maps.exr");
    assert_eq!(j["maps"]["png"].as_array().unwrap().len(), 4 + 2);
    for png in j["maps"]["png"].as_array().unwrap() {
        let img = image::open(d.join(png.as_str().unwrap())).unwrap();
        assert_eq!((img.width(), img.height()), (16, 16));
        assert!(matches!(
            img.color(),
            image::ColorType::L16 | image::ColorType::Rgb16
        ));
    }
    assert_eq!(
        std::fs::read(d.join("a.ptm.exr")).unwrap(),
        std::fs::read(d.join("b.ptm.exr")).unwrap(),
        "--maps changed the PTM"
    );
    // The same rays: the maps of the stack bake and of the fit bake are the same file.
    assert_eq!(
        std::fs::read(d.join("samples.maps.exr")).unwrap(),
        std::fs::read(d.join("b.maps.exr")).unwrap()
    );
    // A maps file passed where a PTM or a stack belongs is named for what it is.
    for args in [
        &["preview", "--ptm", "b.maps.exr", "-o", "x.png"][..],
        &["convert", "b.maps.exr", "-o", "x.ptm.exr"],
        &["fit", "samples.maps.exr", "-o", "x.ptm.exr"],
    ] {
        let e = common::refused(args, d);
        assert!(
            e.contains("companion maps") && e.contains("ptm bake --maps"),
            "{args:?}: {e}"
        );
    }
    let mut c = exrio::read(&d.join("b.maps.exr")).unwrap();
    assert_eq!((c.width, c.height), (16, 16));
    assert_eq!(c.texts("maps:materials", "maps").unwrap(), ["warp", "weft"]);
    let warp = c.take_f32("mask.warp", "maps").unwrap();
    let weft = c.take_f32("mask.weft", "maps").unwrap();
    let cov = c.take_f32("coverage", "maps").unwrap();
    let id = c.take_f32("id", "maps").unwrap();
    let ao = c.take_f32("ao", "maps").unwrap();
    let nz = c.take_f32("normal.Z", "maps").unwrap();
    for t in 0..256 {
        assert_eq!(warp[t] + weft[t], cov[t], "masks share the footprint");
        let want = if cov[t] == 0.0 {
            -1.0
        } else if weft[t] > warp[t] {
            1.0
        } else {
            0.0
        };
        assert_eq!(id[t], want);
        assert!((0.0..=1.0).contains(&ao[t]) && nz[t] >= 0.0);
    }
    assert!(warp.contains(&1.0) && weft.contains(&1.0));
    // An OBJ's usemtl groups: the box's top face (its second face) is `lid`.
    let obj = BOX_OBJ.replacen("f 5 6 7 8\n", "usemtl lid\nf 5 6 7 8\nusemtl walls\n", 1);
    std::fs::write(d.join("box.obj"), obj).unwrap();
    run(&["--swatch", "box.obj", "-o", "box.exr", "--maps"]);
    let mut c = exrio::read(&d.join("box.maps.exr")).unwrap();
    assert_eq!(
        c.texts("maps:materials", "maps").unwrap(),
        ["lid", "walls", "default"]
    );
    let lid = c.take_f32("mask.lid", "maps").unwrap();
    let floor = c.take_f32("mask.default", "maps").unwrap();
    let h = c.take_f32("height", "maps").unwrap();
    // Row 8, column 8 is the box's middle, at z = 0.2; the corner texel is floor at 0.
    // (z = z_top − t in f32: within 1e-7.)
    assert_eq!((lid[8 * 16 + 8], floor[0]), (1.0, 1.0));
    assert!(
        (h[8 * 16 + 8] - 0.2).abs() < 1e-7 && h[0].abs() < 1e-7,
        "{h:?}"
    );
}

#[test]
fn maps_refuse_what_they_cannot_bake() {
    let dir = tempfile::tempdir().unwrap();
    let e = common::refused(
        [
            "bake",
            "--res",
            "32",
            "--maps-png",
            "--shard",
            "0/2",
            "-o",
            "s.exr",
        ],
        dir.path(),
    );
    assert!(e.contains("--maps-png with --shard"), "{e}");
    let e = common::refused(
        [
            "bake",
            "--res",
            "16",
            "--maps",
            "--light-distance",
            "10",
            "-o",
            "s.exr",
        ],
        dir.path(),
    );
    assert!(e.contains("--light-distance"), "{e}");
    assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
}
