//! End-to-end tests of `ptm bake --device`: the GPU bake (lavapipe's ray queries in CI) writes
//! the same products as the CPU bake (the stack, the streaming fit, the companion maps, farm
//! parts that merge with CPU parts) within the agreement the GPU crate's tests pin, `auto`
//! picks the CPU over a software adapter and says why, and a missing adapter is refused with
//! the flag that avoids it, writing nothing.
mod common;

use common::{json, ok, ptm};
use ptm_fit::SampleStack;

/// The bake every test varies: a small weave, few lights (CI time).
const BAKE: [&str; 10] = [
    "bake",
    "--swatch",
    "builtin:plain-weave",
    "--res",
    "32",
    "--dirs",
    "6",
    "--spp",
    "4",
    "--seed=3",
];

fn bake(extra: &[&str]) -> Vec<String> {
    BAKE.iter().chain(extra).map(|s| s.to_string()).collect()
}

/// Worst per-light mean |ΔK| and worst texel |ΔK| between two stacks.
fn worst(a: &SampleStack, b: &SampleStack) -> (f64, f64) {
    let (mut mean, mut max) = (0.0f64, 0.0f64);
    for (x, y) in a.k.iter().zip(&b.k) {
        let d: Vec<f64> = x.iter().zip(y).map(|(p, q)| (p - q).abs() as f64).collect();
        mean = mean.max(d.iter().sum::<f64>() / d.len() as f64);
        max = max.max(d.iter().copied().fold(0.0, f64::max));
    }
    (mean, max)
}

#[test]
fn gpu_bake_writes_the_cpu_bakes_products() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let j = json(bake(&["--device", "gpu", "-o", "gpu.exr"]), d);
    assert_eq!(j["device"]["asked"], "gpu");
    assert_eq!(j["device"]["used"], "gpu");
    let adapter = j["device"]["adapter"].as_str().unwrap().to_string();
    assert!(j["device"]["reason"].as_str().unwrap().contains(&adapter));
    assert_eq!(j["rays"]["primary"], 32 * 32 * 4);
    assert!(j["rays"]["shadow"].as_u64().unwrap() > 0);
    let run = ptm(bake(&["--device", "gpu", "-o", "gpu2.exr"]), d);
    assert!(
        run.ok
            && run
                .stderr
                .contains("ptm bake: device gpu: asked for the GPU: ")
            && run.stderr.contains(&adapter),
        "{}",
        run.stderr
    );
    // The same bytes on every run of one device.
    assert_eq!(
        std::fs::read(d.join("gpu.exr")).unwrap(),
        std::fs::read(d.join("gpu2.exr")).unwrap()
    );
    ok(bake(&["--device", "cpu", "-o", "cpu.exr"]), d);
    let g = SampleStack::read(&d.join("gpu.exr")).unwrap();
    let c = SampleStack::read(&d.join("cpu.exr")).unwrap();
    let (mean, max) = worst(&c, &g);
    assert!(mean <= 0.002 && max <= 0.5 + 1e-6, "mean {mean}, max {max}");
    assert_eq!(g.lights, c.lights);
    // The streaming fit and the companion maps from the GPU's planes and primary hits.
    let j = json(
        bake(&[
            "--device",
            "gpu",
            "--fit",
            "ptm6",
            "--maps",
            "-o",
            "weave.ptm.exr",
        ]),
        d,
    );
    assert_eq!(j["fit"]["basis"], "ptm6");
    assert!(d.join("weave.ptm.exr").exists() && d.join("weave.maps.exr").exists());
    assert!(j["maps"]["dome_fraction"].as_f64().unwrap() > 0.0);
    // The maps agree with the CPU's: the same hits, heights and normals to an f32 rounding
    // (the two intersectors' t and the normal's cross product), the same ids and AO here.
    ok(
        bake(&[
            "--device",
            "cpu",
            "--fit",
            "ptm6",
            "--maps",
            "-o",
            "c.ptm.exr",
        ]),
        d,
    );
    let mut g = ptm_format::exrio::read(&d.join("weave.maps.exr")).unwrap();
    let mut c = ptm_format::exrio::read(&d.join("c.maps.exr")).unwrap();
    for (name, tol) in [
        ("height", 1e-6),
        ("normal.X", 1e-6),
        ("normal.Z", 1e-6),
        ("id", 0.0),
        ("coverage", 0.0),
        ("ao", 1e-6),
    ] {
        let a = g.take_f32(name, "maps").unwrap();
        let b = c.take_f32(name, "maps").unwrap();
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(worst <= tol, "{name}: {worst}");
    }
}

#[test]
fn a_gpu_shard_merges_with_cpu_shards() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        bake(&["--device", "gpu", "--shard", "0/2", "-o", "s.exr"]),
        d,
    );
    ok(
        bake(&["--device", "cpu", "--shard", "1/2", "-o", "s.exr"]),
        d,
    );
    ok(["merge", ".", "-o", "merged.exr"], d);
    ok(bake(&["--device", "cpu", "-o", "whole.exr"]), d);
    let m = SampleStack::read(&d.join("merged.exr")).unwrap();
    let w = SampleStack::read(&d.join("whole.exr")).unwrap();
    // The CPU shard's rows are the whole CPU bake's to the bit; the GPU's agree as bakes do.
    for (k, kw) in m.k.iter().zip(&w.k) {
        assert_eq!(k[16 * 32..], kw[16 * 32..]);
    }
    let (mean, max) = worst(&w, &m);
    assert!(mean <= 0.002 && max <= 0.5 + 1e-6, "mean {mean}, max {max}");
}

#[test]
fn auto_prefers_embree_to_software_ray_queries_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let j = json(bake(&["-o", "auto.exr"]), d);
    assert_eq!(j["device"]["asked"], "auto");
    let gpu = json(bake(&["--device", "gpu", "-o", "g.exr"]), d);
    let adapter = gpu["device"]["adapter"].as_str().unwrap();
    if adapter.contains("Cpu") {
        // lavapipe: the CPU bakes, and the reason names the software adapter.
        assert_eq!(j["device"]["used"], "cpu");
        let reason = j["device"]["reason"].as_str().unwrap();
        assert!(
            reason.contains("CPU device") && reason.contains(adapter),
            "{reason}"
        );
        ok(bake(&["--device", "cpu", "-o", "cpu.exr"]), d);
        assert_eq!(
            std::fs::read(d.join("auto.exr")).unwrap(),
            std::fs::read(d.join("cpu.exr")).unwrap()
        );
    } else {
        assert_eq!(j["device"]["used"], "gpu");
    }
    // Point lights bake on the GPU too, with their (u, v) planes.
    ok(
        bake(&["--device", "gpu", "--light-distance", "5", "-o", "pg.exr"]),
        d,
    );
    ok(
        bake(&["--device", "cpu", "--light-distance", "5", "-o", "pc.exr"]),
        d,
    );
    let g = SampleStack::read(&d.join("pg.exr")).unwrap();
    let c = SampleStack::read(&d.join("pc.exr")).unwrap();
    let (mean, max) = worst(&c, &g);
    assert!(mean <= 0.002 && max <= 0.5 + 1e-6, "mean {mean}, max {max}");
    let (ug, uc) = (g.uv.unwrap(), c.uv.unwrap());
    let du = ug
        .iter()
        .flatten()
        .zip(uc.iter().flatten())
        .map(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()))
        .fold(0.0, f32::max);
    assert!(du <= 1e-5, "(u, v) {du}");
}

#[test]
fn no_ray_query_adapter_names_what_was_found() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::command()
        .args(bake(&["--device", "gpu", "-o", "x.exr"]))
        .env("WGPU_ADAPTER_NAME", "no-such-adapter")
        .current_dir(dir.path())
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        e.contains("no GPU adapter with ray queries")
            && e.contains("no-such-adapter")
            && e.contains("--device cpu"),
        "{e}"
    );
    assert!(!dir.path().join("x.exr").exists());
}

#[test]
fn gpu_bands_are_farm_row_blocks() {
    // The GPU crate keeps its own copy (it does not depend on the fit crate).
    assert_eq!(ptm_gpubake::budget::ROW_BLOCK, ptm_fit::shard::ROW_BLOCK);
}
