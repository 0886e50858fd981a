//! The GPU bake against the Embree bake on the same swatches, and its own guarantees:
//! - agreement: per light, mean |ΔK| ≤ 0.002 and no texel off by more than 2/spp (the two
//!   intersectors may disagree only about rays grazing triangle edges);
//! - determinism: the same K to the bit on every run, for any band size, and for a farm shard's
//!   rows against the same rows of the whole bake;
//! - point lights: K and each texel's (u, v) of the mean direction to the light;
//! - faults: bands that cannot fit and a lost device are errors, never output.
#[path = "../../bake/tests/common/mod.rs"]
mod common;
mod gpu;

use ptm_bake::{BakeConfig, Planes, PreparedMesh, Tracer};
use ptm_format::LightSet;
use ptm_gpubake::budget::Rows;
use ptm_gpubake::{Asked, Error, GpuBaker, GpuConfig, Used};

fn cfg(res: usize, spp: u32) -> BakeConfig {
    BakeConfig {
        seed: 7,
        ..common::cfg(res, spp)
    }
}

/// Per light, (mean |ΔK|, max |ΔK|) between two bakes, over texels both cover.
fn deltas(a: &Planes, b: &Planes) -> Vec<(f64, f64)> {
    a.k.iter()
        .zip(&b.k)
        .map(|(a, b)| {
            let mut sum = 0.0;
            let mut max = 0.0f64;
            for (x, y) in a.iter().zip(b) {
                let d = (*x as f64 - *y as f64).abs();
                sum += d;
                max = max.max(d);
            }
            (sum / a.len() as f64, max)
        })
        .collect()
}

/// The agreement the issue asks for, on `s` at 32² × `spp` under a Fibonacci dome plus a light
/// below the horizon; prints the figures.
fn agrees(name: &str, s: &PreparedMesh, spp: u32) {
    let mut dirs = ptm_bake::dome::fibonacci(12, 5.0).unwrap().dirs;
    dirs.push([0.6, 0.0, -0.8]);
    let lights = LightSet::from_dirs(dirs);
    let c = cfg(32, spp);
    let (pc, cc, rc) = gpu::cpu(s, &lights, &c);
    let (pg, cg, rg) = gpu::gpu(s, &lights, &c);
    assert_eq!(pc.k.len(), pg.k.len());
    assert_eq!((rc.rings, rc.copies), (rg.rings.clone(), rg.copies.clone()));
    assert_eq!(rc.below_horizon, vec![12]);
    assert_eq!(rg.below_horizon, vec![12]);
    assert_eq!(rc.primary_rays, rg.primary_rays);
    let cov_differ = cc.iter().zip(&cg).filter(|(a, b)| a != b).count();
    assert!(
        cov_differ * 100 <= cc.len(),
        "{name}: coverage differs in {cov_differ} texels"
    );
    let d = deltas(&pc, &pg);
    let worst_mean = d.iter().map(|x| x.0).fold(0.0, f64::max);
    let worst_max = d.iter().map(|x| x.1).fold(0.0, f64::max);
    eprintln!(
        "{name}: {} lights, 32² × spp {spp}: worst per-light mean |ΔK| {worst_mean:.5}, worst \
         texel |ΔK| {worst_max:.4} (2/spp = {:.4}); coverage differs in {cov_differ} texels; \
         shadow rays {} cpu / {} gpu",
        lights.len(),
        2.0 / spp as f64,
        rc.shadow_rays,
        rg.shadow_rays
    );
    for (li, (mean, max)) in d.iter().enumerate() {
        assert!(*mean <= 0.002, "{name} light {li}: mean |ΔK| {mean}");
        assert!(
            *max <= 2.0 / spp as f64 + 1e-6,
            "{name} light {li}: |ΔK| {max}"
        );
    }
    // Not trivially lit: the comparison saw partial occlusion.
    assert!(pg.k.iter().flatten().any(|&k| k > 0.0 && k < 1.0));
    // Rays traced agree to within the edge cases (facing tests on the same normals).
    let (a, b) = (rc.shadow_rays as f64, rg.shadow_rays as f64);
    assert!((a - b).abs() <= 0.01 * a, "{name}: shadow rays {a} vs {b}");
}

#[test]
fn gpu_agrees_with_embree_on_the_sphere() {
    let s = PreparedMesh::from_mesh(common::sphere_scene(), None, "sphere").unwrap();
    agrees("sphere", &s, 4);
}

#[test]
fn gpu_agrees_with_embree_on_a_weave() {
    let s = PreparedMesh::load("builtin:plain-weave", None).unwrap();
    agrees("plain-weave", &s, 8);
}

#[test]
fn gpu_bake_is_deterministic_across_runs_bands_and_shards() {
    let s = PreparedMesh::load("builtin:plain-weave", None).unwrap();
    let lights = ptm_bake::dome::fibonacci(6, 10.0).unwrap();
    let c = cfg(32, 4);
    let adapter = gpu::adapter();
    let whole = GpuConfig::default();
    let (a, ca, _) = ptm_gpubake::bake_planes(&adapter, &s, &lights, &c, &whole).unwrap();
    let (b, cb, _) = ptm_gpubake::bake_planes(&adapter, &s, &lights, &c, &whole).unwrap();
    assert_eq!(gpu::bits(&a), gpu::bits(&b), "two runs");
    assert_eq!(ca, cb);
    // A budget of one 16-row block: two bands, each re-uploaded per pass.
    let one_block = GpuConfig {
        band_bytes: Rows {
            width: 32,
            spp: 4,
            per_pass: ptm_gpubake::budget::lights_per_pass(32, 32, false),
            point: false,
        }
        .bytes()
            * 16,
    };
    let mut banded = GpuBaker::new_rows(&adapter, &s, &c, 0..32, &one_block, false).unwrap();
    assert_eq!(banded.bands(), &[0..16, 16..32]);
    let mut p = Planes::default();
    banded
        .trace(&lights, &mut |i, k, uv| p.push(i, k, uv))
        .unwrap();
    assert_eq!(gpu::bits(&p), gpu::bits(&a), "two bands vs one");
    assert_eq!(banded.coverage(), &ca[..]);
    // A farm shard's rows are the whole bake's rows.
    let mut shard = GpuBaker::new_rows(&adapter, &s, &c, 16..32, &whole, false).unwrap();
    let mut q = Planes::default();
    shard
        .trace(&lights, &mut |i, k, uv| q.push(i, k, uv))
        .unwrap();
    for (l, (k, whole)) in q.k.iter().zip(&a.k).enumerate() {
        assert_eq!(k[..], whole[16 * 32..], "light {l}: shard rows 16..32");
    }
}

#[test]
fn a_band_too_big_is_refused_before_upload() {
    let s = PreparedMesh::load("builtin:plain-weave", None).unwrap();
    let adapter = gpu::adapter();
    let c = cfg(64, 16);
    let tiny = GpuConfig { band_bytes: 1000 };
    let e = GpuBaker::new_rows(&adapter, &s, &c, 0..64, &tiny, false)
        .err()
        .unwrap();
    match &e {
        Error::BandTooBig {
            rows: 16,
            width: 64,
            spp: 16,
            limit: 1000,
            need,
            ..
        } => assert_eq!(
            *need,
            Rows {
                width: 64,
                spp: 16,
                per_pass: 32,
                point: false
            }
            .bytes()
                * 16
        ),
        other => panic!("{other}"),
    }
    let msg = e.to_string();
    assert!(
        msg.contains("band of 16 rows") && msg.contains("1000"),
        "{msg}"
    );
}

/// Point lights on a hemisphere over the tile: K as the CPU's, and each texel's (u, v) of the
/// mean unit direction to the light to f32 rounding; a light below the horizon has no (u, v),
/// as on the CPU.
#[test]
fn point_lights_agree_with_embree() {
    let s = PreparedMesh::from_mesh(common::sphere_scene(), None, "sphere").unwrap();
    let mut dirs = ptm_bake::dome::fibonacci(8, 10.0).unwrap().dirs;
    dirs.push([0.6, 0.0, -0.8]);
    let lights = LightSet::from_dirs(dirs);
    let c = BakeConfig {
        light_distance: Some(1.5),
        ..cfg(32, 4)
    };
    let (pc, cc, rc) = gpu::cpu(&s, &lights, &c);
    let (pg, cg, rg) = gpu::gpu(&s, &lights, &c);
    assert_eq!(cc, cg);
    assert_eq!((&rc.rings, &rc.copies), (&rg.rings, &rg.copies));
    for (li, (mean, max)) in deltas(&pc, &pg).iter().enumerate() {
        assert!(
            *mean <= 0.002 && *max <= 0.5 + 1e-6,
            "light {li}: {mean} {max}"
        );
    }
    let (uc, ug) = (pc.uv.clone().unwrap(), pg.uv.clone().unwrap());
    assert_eq!(uc.len(), 8);
    assert_eq!(ug.len(), 8);
    let mut worst = 0.0f32;
    for (a, b) in uc.iter().flatten().zip(ug.iter().flatten()) {
        worst = worst.max((a[0] - b[0]).abs()).max((a[1] - b[1]).abs());
    }
    eprintln!("point lights: worst |Δ(u, v)| {worst:e}");
    assert!(worst <= 1e-5, "{worst}");
    // Not trivially lit, and the directions vary across the tile.
    assert!(pg.k.iter().flatten().any(|&k| k > 0.0 && k < 1.0));
    assert!(ug[0][0] != ug[0][32 * 32 - 1]);
    // In bands of one row block: the same planes, (u, v) included.
    let one_block = GpuConfig {
        band_bytes: Rows {
            width: 32,
            spp: 4,
            per_pass: ptm_gpubake::budget::lights_per_pass(32, 32, true),
            point: true,
        }
        .bytes()
            * 16,
    };
    let (pb, _, _) =
        ptm_gpubake::bake_planes(&gpu::adapter(), &s, &lights, &c, &one_block).unwrap();
    assert_eq!(gpu::bits(&pb), gpu::bits(&pg));
    assert_eq!(pb.uv.unwrap(), ug);
}

#[test]
fn a_lost_device_is_an_error_not_a_bake() {
    let s = PreparedMesh::from_mesh(common::sphere_scene(), None, "sphere").unwrap();
    // More lights than one pass takes, so tracing goes on after the first pass's planes.
    let lights = ptm_bake::dome::fibonacci(40, 5.0).unwrap();
    let adapter = gpu::adapter();
    let mut b = GpuBaker::new_rows(
        &adapter,
        &s,
        &cfg(16, 1),
        0..16,
        &GpuConfig::default(),
        false,
    )
    .unwrap();
    assert!(b.lights_per_pass() < lights.len());
    let device = b.device().clone();
    let mut seen = 0;
    let e = b
        .trace(&lights, &mut |i, _, _| {
            seen = i + 1;
            if i == 0 {
                device.destroy();
            }
            Ok(())
        })
        .expect_err("tracing on a destroyed device must fail");
    assert!(seen < lights.len(), "every light was handed over");
    let msg = e.to_string();
    assert!(msg.contains("the GPU failed while"), "{msg}");
}

#[test]
fn device_choice_says_why() {
    // No adapter at all: `gpu` is an error naming what was found, `auto` bakes on the CPU.
    let e = ptm_gpubake::adapter::choose_from(Asked::Gpu, Vec::new()).unwrap_err();
    assert!(
        e.to_string().contains("wgpu found no adapter at all"),
        "{e}"
    );
    let c = ptm_gpubake::adapter::choose_from(Asked::Auto, Vec::new()).unwrap();
    assert_eq!(c.used, Used::Cpu);
    assert_eq!(c.reason, "wgpu found no GPU adapter");
    // On this machine: `auto` takes a hardware GPU if the adapter `gpu` takes is one, else the
    // CPU, naming the software adapter.
    let gpu = ptm_gpubake::choose(Asked::Gpu).unwrap();
    let auto = ptm_gpubake::choose(Asked::Auto).unwrap();
    let name = gpu.adapter_name.clone().unwrap();
    let software = gpu.adapter.as_ref().unwrap().get_info().device_type == wgpu::DeviceType::Cpu;
    if software {
        assert_eq!(auto.used, Used::Cpu);
        assert!(
            auto.reason.contains(&name) && auto.reason.contains("CPU device"),
            "{}",
            auto.reason
        );
    } else {
        assert_eq!(auto.used, Used::Gpu);
    }
}
