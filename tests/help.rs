//! The help texts against what the commands do (issue #25.9): the first line of every
//! subcommand's `--help` is pinned, and the defaults that help texts state are checked by
//! running the command with them.
mod common;

use std::path::Path;

use common::{json, ok};

/// The first line of `ptm ARGS --help`.
fn first_line(args: &[&str]) -> String {
    let out = ok([args, &["--help"][..]].concat(), Path::new("."));
    out.lines().next().unwrap_or_default().to_string()
}

/// The help paragraph of flag `--name` in `ptm SUB --help`, joined into one line.
fn flag_help(sub: &str, name: &str) -> String {
    let out = ok([sub, "--help"], Path::new("."));
    let mut lines = out
        .lines()
        .skip_while(|l| !l.trim_start().starts_with(name));
    let head = lines.next().unwrap_or_else(|| panic!("no {name} in {out}"));
    std::iter::once(head)
        .chain(lines.take_while(|l| {
            // The next option's line: `--name` or `-o, --output`.
            let t = l.trim_start();
            !(t.starts_with("--") || t.get(2..3) == Some(","))
        }))
        .filter(|l| !l.trim().is_empty())
        .map(str::trim)
        .collect::<Vec<_>>()
        .join(" ")
}

#[test]
fn every_subcommand_says_first_what_it_does() {
    for (sub, line) in [
        (
            "bake",
            "Ray-trace a tileable swatch from a dome of lights: per texel and light the occluded \
             fraction K (a sample stack, or with --fit a PTM)",
        ),
        (
            "fit",
            "Fit a PTM per texel (K as a polynomial in the light's (u, v)): logistic maximum \
             likelihood by default, least squares with --link identity",
        ),
        (
            "preview",
            "Render the swatch plane under area lights on the GPU, shaded by 1 − K of a PTM and \
             the soft shadow of a planar caster",
        ),
        (
            "swatch",
            "Generate a procedural tileable swatch as an OBJ file",
        ),
        (
            "report",
            "Measured study: error of K against run time per setting, and stiff/extreme cases",
        ),
        (
            "merge",
            "Assemble the parts of a farm bake (`ptm bake --shard I/N`) into the stack or PTM",
        ),
        (
            "batch",
            "Run a manifest of bakes locally, or write a Slurm array job for them (--slurm DIR)",
        ),
        (
            "convert",
            "Rewrite a PTM in the other layout (renderer RGB(A) parts ↔ named channels), \
             losslessly",
        ),
    ] {
        assert_eq!(first_line(&[sub]), line, "ptm {sub} --help");
    }
}

/// `ptm fit`'s help says the default is the logistic maximum-likelihood fit: it is, and
/// `--link identity` is the least-squares one; `--dirs` says its default count, and a bake
/// without it traces that many lights.
#[test]
fn the_defaults_help_states_are_the_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert!(flag_help("bake", "--dirs").contains("default 32"));
    let bake = json(["bake", "--res", "4", "--spp", "1", "-o", "s.exr"], d);
    assert_eq!(bake["lights"], 32, "{bake}");
    let fit = json(["fit", "s.exr", "-o", "a.ptm.exr"], d);
    assert_eq!(fit["link"], "logistic");
    assert!(fit["logistic"].is_object(), "{fit}");
    let fit = json(["fit", "s.exr", "-o", "b.ptm.exr", "--link", "identity"], d);
    assert_eq!(fit["link"], "identity");
    assert!(first_line(&["fit"]).contains("logistic maximum likelihood by default"));
    assert!(flag_help("fit", "--link").contains("[default: logistic]"));
}
