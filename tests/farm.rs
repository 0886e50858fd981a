//! Integration tests of farm bakes: `ptm bake --shard I/N` parts merged by `ptm merge` are
//! byte for byte the one-machine file (stack, ptm6, ptm11; N = 1, 3, 4; a swatch with holes),
//! logistic ptm6 and ptm11 with and without MIP levels; refusals of bad shards and bad part sets name the files, and `ptm batch` runs a manifest
//! and writes a Slurm job.
mod common;

use common::{ok, ptm, refused, Run};

/// Bakes `bake` whole and as N shards for each N, merges, and compares the bytes of the output
/// and of the `.lp`. Returns the whole file's bytes.
fn sharded_equals_whole(bake: &[&str], out: &str, counts: &[usize]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let whole = format!("whole-{out}");
    ok([&["bake"], bake, &["-o", &whole]].concat(), d);
    let want = std::fs::read(d.join(&whole)).unwrap();
    let lp = |f: &str| {
        f.strip_suffix(".exr")
            .unwrap()
            .trim_end_matches(".ptm")
            .to_string()
            + ".lp"
    };
    let want_lp = std::fs::read(d.join(lp(&whole))).unwrap();
    for &n in counts {
        let name = format!("n{n}-{out}");
        let mut parts = Vec::new();
        for i in 0..n {
            let s = format!("{i}/{n}");
            let j = ok(
                [&["--json", "bake"], bake, &["-o", &name, "--shard", &s]].concat(),
                d,
            );
            let j: serde_json::Value = serde_json::from_str(&j).unwrap();
            parts.push(j["output"].as_str().unwrap().to_string());
        }
        let merged = format!("merged-{name}");
        let mut args = vec!["merge"];
        args.extend(parts.iter().map(|s| s.as_str()));
        args.extend(["-o", &merged]);
        ok(&args, d);
        let got = std::fs::read(d.join(&merged)).unwrap();
        assert!(
            got == want,
            "{bake:?} in {n} shards: merged {merged} differs from {whole}"
        );
        assert_eq!(
            std::fs::read(d.join(lp(&merged))).unwrap(),
            want_lp,
            "{n} shards: .lp"
        );
    }
    want
}

const BAKE: &[&str] = &[
    "--res", "40,60", "--dirs", "12", "--spp", "4", "--seed", "3",
];

#[test]
fn sharded_stack_is_byte_identical() {
    sharded_equals_whole(BAKE, "samples.exr", &[1, 3, 4]);
}

/// Identity link, hemispherical (u, v), MIP levels (computed by the merge from the whole image).
/// Merged and whole alike record that no light was held out (`ptm:holdoutLights` empty).
#[test]
fn sharded_ptm6_is_byte_identical() {
    let whole = sharded_equals_whole(
        &[BAKE, &["--fit", "ptm6", "--link", "identity"]].concat(),
        "w.ptm.exr",
        &[1, 3, 4],
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("w.ptm.exr"), whole).unwrap();
    let attrs = ptm_format::exrio::read(&dir.path().join("w.ptm.exr"))
        .unwrap()
        .attrs;
    assert_eq!(
        attrs.get("ptm:holdoutLights"),
        Some(&ptm_format::exrio::Attr::Text(String::new()))
    );
}

/// Identity link, projected (u, v), no MIP levels: the patent's PTM.
#[test]
fn sharded_ptm11_is_byte_identical() {
    let fit = [
        "--fit",
        "ptm11",
        "--link",
        "identity",
        "--uv",
        "projected",
        "--no-mips",
    ];
    sharded_equals_whole(&[BAKE, &fit].concat(), "w.ptm.exr", &[1, 3, 4]);
}

/// Logistic link, hemispherical (u, v), MIP levels: levels 1–4 are fitted by the parts (their
/// footprints lie in one 16-row block), level 5 (1×1) by the merge from the parts' pooled
/// counts; at N = 4 the last part holds no row of level 4.
#[test]
fn sharded_logistic_ptm6_with_mips_is_byte_identical() {
    let fit = [
        "--fit",
        "ptm6",
        "--link",
        "logistic",
        "--uv",
        "hemispherical",
    ];
    sharded_equals_whole(&[BAKE, &fit].concat(), "w.ptm.exr", &[1, 3, 4]);
}

/// Logistic link without MIP levels, ptm11 over projected (u, v); and a taller image whose
/// chain has two levels past the parts' (1×3 and 1×1), and a zero ridge (counted texels
/// raise a warning the merge words from the parts' sums).
#[test]
fn sharded_logistic_ptm11_is_byte_identical() {
    let fit = [
        "--fit",
        "ptm11",
        "--link",
        "logistic",
        "--uv",
        "projected",
        "--no-mips",
    ];
    sharded_equals_whole(&[BAKE, &fit].concat(), "w.ptm.exr", &[1, 3, 4]);
    let tall = [
        "--res",
        "32,96",
        "--dirs",
        "10",
        "--spp",
        "3",
        "--fit",
        "ptm11",
        "--link",
        "logistic",
        "--regularize",
        "0",
        "--max-iterations",
        "4",
    ];
    let whole = sharded_equals_whole(&tall, "t.ptm.exr", &[3, 5]);
    for says in [
        &b"stopped at the logistic iteration cap"[..],
        b"are separable",
    ] {
        assert!(
            whole.windows(says.len()).any(|w| w == says),
            "the whole file warns {:?}",
            String::from_utf8_lossy(says)
        );
    }
}

/// A floor over the lower 60 % of a 1×1 tile with a box on it: rows near y = H see no swatch
/// (coverage 0) and one row has partial coverage.
const HALF_FLOOR_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 0.6 0\nv 0 0.6 0\n\
v 0.3 0.1 0.2\nv 0.7 0.1 0.2\nv 0.7 0.5 0.2\nv 0.3 0.5 0.2\n\
v 0.3 0.1 0\nv 0.7 0.1 0\nv 0.7 0.5 0\nv 0.3 0.5 0\n\
f 1 2 3 4\nf 5 6 7 8\nf 9 10 6 5\nf 10 11 7 6\nf 11 12 8 7\nf 12 9 5 8\n";

#[test]
fn sharded_bakes_with_holes_and_point_lights_are_byte_identical() {
    // Holes in some shards only: the coverage channel and the masked statistics are
    // file-level. The swatch path is absolute: each case bakes in its own directory.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("half.obj");
    std::fs::write(&obj, HALF_FLOOR_OBJ).unwrap();
    let obj = obj.to_str().unwrap();
    let holes = [
        "--swatch", obj, "--tile", "1,1", "--res", "32,60", "--dirs", "8", "--spp", "5",
    ];
    sharded_equals_whole(
        &[&holes[..], &["--fit", "ptm6", "--link", "identity"]].concat(),
        "h.ptm.exr",
        &[3],
    );
    sharded_equals_whole(
        &[&holes[..], &["--fit", "ptm6", "--link", "logistic"]].concat(),
        "l.ptm.exr",
        &[3],
    );
    sharded_equals_whole(
        &[&holes[..], &["--light-distance", "3"]].concat(),
        "h.exr",
        &[4],
    );
}

/// A learned basis in shards: each shard learns the tables the whole bake learns (the same
/// subsample of texels, traced apart, in the same order), fits its rows against them, and the
/// merge joins the rows and fits the deeper MIP levels with those tables. Then a floor under a
/// third of the tile at 96² (9,216 texels): a shard finds the subsample's covered texels only
/// after testing more than the first 8,192 of the subsample order.
#[test]
fn sharded_learned_basis_is_byte_identical() {
    let fit = ["--dirs", "32", "--fit", "learned6"];
    sharded_equals_whole(
        &[&BAKE[..2], &BAKE[4..], &fit].concat(),
        "l.ptm.exr",
        &[1, 3],
    );
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("third.obj");
    std::fs::write(&obj, THIRD_FLOOR_OBJ).unwrap();
    let third = [
        "--swatch",
        obj.to_str().unwrap(),
        "--tile",
        "1,1",
        "--res",
        "96",
        "--spp",
        "2",
    ];
    sharded_equals_whole(&[&third[..], &fit].concat(), "t.ptm.exr", &[2]);
}

/// A floor over the lower third of a 1×1 tile with a ridge on it.
const THIRD_FLOOR_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 0.33 0\nv 0 0.33 0\n\
v 0 0.1 0\nv 1 0.1 0\nv 1 0.2 0.1\nv 0 0.2 0.1\n\
f 1 2 3 4\nf 5 6 7 8\n";

#[test]
fn bad_shards_are_refused_clearly() {
    let dir = tempfile::tempdir().unwrap();
    for (bad, says) in [
        ("0/0", "at least 1"),
        ("5/4", "out of range"),
        ("4/4", "out of range"),
        ("-1/3", "not a whole number"),
        ("one/3", "not a whole number"),
        ("2", "no `/`"),
    ] {
        let e = refused(
            ["bake", "--res", "16", "-o", "s.exr", "--shard", bad],
            dir.path(),
        );
        assert!(e.contains(says), "--shard {bad}: {e}");
    }
    let e = refused(
        ["bake", "--res", "40", "-o", "s.exr", "--shard", "0/4"],
        dir.path(),
    );
    assert!(e.contains("at most 3 shards"), "{e}");
    let e = refused(
        [
            "bake",
            "--res",
            "32",
            "--fit",
            "ptm6",
            "--light-distance",
            "2",
            "-o",
            "s.ptm.exr",
            "--shard",
            "0/2",
        ],
        dir.path(),
    );
    assert!(e.contains("not supported"), "{e}");
    let e = refused(
        [
            "bake",
            "--res",
            "32",
            "--fit",
            "ptm6",
            "--holdout",
            "2",
            "-o",
            "s.ptm.exr",
            "--shard",
            "0/2",
        ],
        dir.path(),
    );
    assert!(e.contains("--shard with --holdout"), "{e}");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "refusals write nothing"
    );
}

#[test]
fn merge_refuses_incomplete_mixed_and_damaged_sets() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bake = ["bake", "--res", "48", "--dirs", "6", "--spp", "1"];
    for i in 0..3 {
        ok(
            [&bake[..], &["-o", "a.exr", "--shard", &format!("{i}/3")]].concat(),
            d,
        );
    }
    ok(
        [&bake[..], &["--seed", "9", "-o", "b.exr", "--shard", "1/3"]].concat(),
        d,
    );
    let p = |s: &str| format!("a.part-000{s}-of-0003.exr");
    let e = refused(["merge", &p("0"), &p("2"), "-o", "m.exr"], d);
    assert!(e.contains("missing shard(s) 1/3"), "{e}");
    let e = refused(
        ["merge", &p("0"), &p("1"), &p("1"), &p("2"), "-o", "m.exr"],
        d,
    );
    assert!(e.contains("shard 1/3 given twice"), "{e}");
    let e = refused(
        [
            "merge",
            &p("0"),
            "b.part-0001-of-0003.exr",
            &p("2"),
            "-o",
            "m.exr",
        ],
        d,
    );
    assert!(
        e.contains("different bakes: settings") && e.contains("seed=0") && e.contains("seed=9"),
        "both values shown: {e}"
    );
    // A part altered after writing (here a light's name) fails its checksum.
    let bytes = std::fs::read(d.join(p("1"))).unwrap();
    let at = bytes.windows(9).position(|w| w == b"light0003").unwrap();
    let mut forged = bytes.clone();
    forged[at + 8] = b'9';
    std::fs::write(d.join("forged.exr"), &forged).unwrap();
    let e = refused(["merge", &p("0"), "forged.exr", &p("2"), "-o", "m.exr"], d);
    assert!(
        e.contains("forged.exr") && e.contains("checksum mismatch"),
        "{e}"
    );
    // A truncated part (a task killed while copying, a full disk) is named.
    std::fs::write(d.join("cut.exr"), &bytes[..bytes.len() / 2]).unwrap();
    let e = refused(["merge", &p("0"), "cut.exr", &p("2"), "-o", "m.exr"], d);
    assert!(e.contains("cut.exr"), "{e}");
    assert!(!d.join("m.exr").exists(), "nothing written");
    // The complete set merges, from the directory too.
    std::fs::remove_file(d.join("b.part-0001-of-0003.exr")).unwrap();
    std::fs::remove_file(d.join("forged.exr")).unwrap();
    std::fs::remove_file(d.join("cut.exr")).unwrap();
    ok(["merge", ".", "-o", "m.exr"], d);
    // The output and its .lp are published together or not at all.
    std::fs::create_dir(d.join("n.lp")).unwrap();
    let e = refused(["merge", ".", "-o", "n.exr"], d);
    assert!(e.contains("n.lp"), "{e}");
    assert!(!d.join("n.exr").exists(), "no output without its .lp");
}

#[test]
fn complete_parts_are_skipped_and_damaged_ones_rebaked() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bake = [
        "--json", "bake", "--res", "32", "--dirs", "6", "-o", "a.exr", "--shard", "1/2",
    ];
    ok(bake, d);
    let j: serde_json::Value = serde_json::from_str(&ok(bake, d)).unwrap();
    assert_eq!(j["skipped"], true);
    let part = d.join("a.part-0001-of-0002.exr");
    let good = std::fs::read(&part).unwrap();
    std::fs::write(&part, &good[..good.len() - 100]).unwrap();
    let j: serde_json::Value = serde_json::from_str(&ok(bake, d)).unwrap();
    assert!(j["skipped"].is_null(), "a damaged part is baked again");
    assert_eq!(std::fs::read(&part).unwrap(), good);
}

#[test]
fn batch_runs_a_manifest_here_and_writes_a_slurm_job() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("jobs.toml"),
        "[defaults]\nres = 48\ndirs = 8\nspp = 2\nshards = 3\n\n\
         [[bake]]\nswatch = \"builtin:plain-weave\"\noutput = \"out/a.exr\"\n\n\
         [[bake]]\nswatch = \"builtin:jersey\"\nfit = \"ptm6\"\nlink = \"identity\"\noutput = \"out/b.ptm.exr\"\nshards = 2\n",
    )
    .unwrap();
    ok(["batch", "jobs.toml"], d);
    ok(
        [
            "bake", "--res", "48", "--dirs", "8", "--spp", "2", "-o", "a.exr",
        ],
        d,
    );
    assert_eq!(
        std::fs::read(d.join("out/a.exr")).unwrap(),
        std::fs::read(d.join("a.exr")).unwrap()
    );
    assert!(d.join("out/b.ptm.exr").exists());
    let Run { stderr: err, .. } = ptm(
        ["batch", "jobs.toml", "--slurm", "job", "--throttle", "2"],
        d,
    );
    assert!(err.contains("submit.sh"), "{err}");
    let tasks = std::fs::read_to_string(d.join("job/tasks.txt")).unwrap();
    assert_eq!(tasks.lines().count(), 5, "{tasks}");
    assert!(
        tasks.lines().last().unwrap().ends_with("--shard 1/2"),
        "{tasks}"
    );
    let submit = std::fs::read_to_string(d.join("job/submit.sh")).unwrap();
    assert!(
        submit.contains("--array=0-4%2") && submit.contains("afterany"),
        "{submit}"
    );
    // A manifest with a flag ptm bake does not know is refused before anything runs.
    std::fs::write(
        d.join("bad.toml"),
        "[[bake]]\noutput = \"x.exr\"\nresolution = 4\n",
    )
    .unwrap();
    let e = refused(["batch", "bad.toml"], d);
    assert!(
        e.contains("bad.toml: bake 0") && e.contains("--resolution"),
        "{e}"
    );
}

/// `--maps` on a farm: each shard writes a maps part beside its K part
/// (`NAME.maps.part-IIII-of-NNNN.exr`), and `ptm merge` joins them into `NAME.maps.exr`, byte
/// for byte the one-machine file, beside the merged stack or PTM (also byte-identical); a set
/// of maps parts without K's, or from another bake, is refused; a resubmitted shard whose
/// maps part is missing is baked again.
#[test]
fn sharded_maps_are_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bake = [
        "bake",
        "--swatch",
        "builtin:velvet",
        "--res",
        "48",
        "--dirs",
        "12",
        "--maps",
    ];
    for (fit, out, maps) in [
        (&[][..], "samples.exr", "samples.maps.exr"),
        (
            &["--fit", "ptm6", "--link", "identity"][..],
            "w.ptm.exr",
            "w.maps.exr",
        ),
    ] {
        let whole = format!("whole-{out}");
        ok([&bake[..], fit, &["-o", &whole]].concat(), d);
        for n in [1, 3] {
            let name = format!("n{n}-{out}");
            for i in 0..n {
                let s = format!("{i}/{n}");
                ok([&bake[..], fit, &["-o", &name, "--shard", &s]].concat(), d);
            }
            let stem = name.strip_suffix(".exr").unwrap();
            let mstem = stem.trim_end_matches(".ptm").to_string() + ".maps";
            let mut parts = Vec::new();
            for i in 0..n {
                parts.push(format!("{stem}.part-{i:04}-of-{n:04}.exr"));
                parts.push(format!("{mstem}.part-{i:04}-of-{n:04}.exr"));
            }
            let merged = format!("m{n}-{out}");
            let j = common::json(
                [
                    &["merge"][..],
                    &[&parts[..], &["-o".into(), merged.clone()]]
                        .concat()
                        .iter()
                        .map(String::as_str)
                        .collect::<Vec<_>>(),
                ]
                .concat(),
                d,
            );
            let mmaps = merged
                .strip_suffix(".exr")
                .unwrap()
                .trim_end_matches(".ptm")
                .to_string()
                + ".maps.exr";
            assert_eq!(j["maps"], mmaps.as_str());
            assert_eq!(
                std::fs::read(d.join(&merged)).unwrap(),
                std::fs::read(d.join(&whole)).unwrap(),
                "{merged}: K differs"
            );
            let wmaps = format!("whole-{maps}");
            assert_eq!(
                std::fs::read(d.join(&mmaps)).unwrap(),
                std::fs::read(d.join(&wmaps)).unwrap(),
                "{mmaps}: the maps differ from the one-machine bake's"
            );
        }
    }
    // Given K's parts alone, the merge finds the maps' beside them (the documented glob, and
    // what `ptm batch` passes).
    let k_only: Vec<String> = (0..3)
        .map(|i| format!("n3-w.ptm.part-{i:04}-of-0003.exr"))
        .collect();
    let args: Vec<&str> = ["merge"]
        .into_iter()
        .chain(k_only.iter().map(String::as_str))
        .chain(["-o", "k.ptm.exr"])
        .collect();
    let j = common::json(args, d);
    assert_eq!(j["maps"], "k.maps.exr");
    assert_eq!(
        std::fs::read(d.join("k.maps.exr")).unwrap(),
        std::fs::read(d.join("whole-w.maps.exr")).unwrap()
    );
    // Maps parts alone, and maps parts of another bake, are refused.
    let e = refused(
        [
            "merge",
            "n3-samples.maps.part-0000-of-0003.exr",
            "n3-samples.maps.part-0001-of-0003.exr",
            "n3-samples.maps.part-0002-of-0003.exr",
            "-o",
            "x.exr",
        ],
        d,
    );
    assert!(e.contains("only companion-map parts"), "{e}");
    let e = refused(
        [
            "merge",
            "n1-samples.part-0000-of-0001.exr",
            "n1-w.maps.part-0000-of-0001.exr",
            "-o",
            "y.exr",
        ],
        d,
    );
    assert!(e.contains("different bakes"), "{e}");
    // A shard whose maps part is gone is baked again, not skipped.
    std::fs::remove_file(d.join("n3-samples.maps.part-0001-of-0003.exr")).unwrap();
    let Run {
        stderr, ok: done, ..
    } = ptm(
        [&bake[..], &["-o", "n3-samples.exr", "--shard", "1/3"]].concat(),
        d,
    );
    assert!(done && !stderr.contains("skipped"), "{stderr}");
    assert!(d.join("n3-samples.maps.part-0001-of-0003.exr").exists());
}
