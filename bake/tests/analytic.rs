//! Analytic bake tests: scenes whose occlusion is known in closed form (flat plane, an
//! infinitely long wall under grazing lights, a sphere on a plane), plus seams, packets versus
//! single rays, thread-count and scale invariance.
use ptm_bake::{bake_planes, BakeConfig, PreparedMesh};
use ptm_format::LightSet;
use ptm_swatches::Mesh;

mod common;

use common::{cfg, light, sphere_scene};

/// The Embree bake, as the shared cases take it.
fn cpu(
    s: &PreparedMesh,
    l: &LightSet,
    c: &BakeConfig,
) -> (ptm_bake::Planes, Vec<f32>, ptm_bake::BakeReport) {
    bake_planes(s, l, c).unwrap()
}

#[test]
fn flat_plane_is_never_occluded() {
    common::flat_plane(&cpu);
}

/// The ridge: an infinite wall's shadow band across several tiles (`common::infinite_wall`).
#[test]
fn infinite_wall_shadow_band_across_several_tiles() {
    common::infinite_wall(&cpu);
}

/// A sphere on a plane: the floor's elliptic shadow and the terminator (`common::sphere_on_plane`).
#[test]
fn sphere_on_plane_shadow_and_terminator() {
    common::sphere_on_plane(&cpu);
}

/// Seams: bake the sphere scene and a copy shifted by half a tile (the sphere then straddles
/// the x border); the shifted bake's border columns must match the original's interior.
#[test]
fn seams_are_continuous() {
    let m = sphere_scene();
    let mut shifted = m.clone();
    for p in &mut shifted.positions {
        p[0] += 0.5;
    }
    let lights = LightSet::from_dirs([light(20.0, 170.0), light(35.0, -10.0)]);
    let res = 32;
    let bake = |m: Mesh| {
        let s = PreparedMesh::from_mesh(m, None, "sphere").unwrap();
        bake_planes(&s, &lights, &cfg(res, 16)).unwrap().0
    };
    let (a, b) = (bake(m), bake(shifted));
    let column_mean =
        |k: &[f32], i: usize| (0..res).map(|j| k[j * res + i] as f64).sum::<f64>() / res as f64;
    for li in 0..2 {
        for i in 0..res {
            let ia = (i + res / 2) % res; // original column seen at shifted column i
            let (ma, mb) = (column_mean(&a.k[li], ia), column_mean(&b.k[li], i));
            assert!(
                (ma - mb).abs() < 0.02,
                "light {li} column {i}: {ma} vs {mb}"
            );
        }
        // Across the shifted bake's border: column 0 and column res−1 are neighbours.
        let (first, last) = (column_mean(&b.k[li], 0), column_mean(&b.k[li], res - 1));
        let (ia0, ia1) = (res / 2, res / 2 - 1);
        let (fa, la) = (column_mean(&a.k[li], ia0), column_mean(&a.k[li], ia1));
        assert!(
            ((first - last) - (fa - la)).abs() < 0.03,
            "light {li}: step across the seam"
        );
    }
}

#[test]
fn packets_single_rays_and_thread_counts_agree_exactly() {
    let s = PreparedMesh::from_mesh(sphere_scene(), None, "sphere").unwrap();
    let lights = ptm_bake::dome::fibonacci(8, 5.0).unwrap();
    let base = cfg(32, 4);
    let (p2, c2, _) = bake_planes(&s, &lights, &base).unwrap();
    let (p1, c1, _) = bake_planes(
        &s,
        &lights,
        &BakeConfig {
            threads: 1,
            ..base.clone()
        },
    )
    .unwrap();
    let (ps, cs, _) = bake_planes(
        &s,
        &lights,
        &BakeConfig {
            packets: false,
            ..base.clone()
        },
    )
    .unwrap();
    let bits =
        |p: &ptm_bake::Planes| -> Vec<u32> { p.k.iter().flatten().map(|k| k.to_bits()).collect() };
    assert_eq!(bits(&p1), bits(&p2), "1 vs 2 threads");
    assert_eq!(bits(&ps), bits(&p2), "single rays vs packets");
    assert_eq!(c1, c2);
    assert_eq!(cs, c2);
    // And the scene is not trivially lit: some texels are partly occluded.
    assert!(p2.k.iter().flatten().any(|&k| k > 0.0 && k < 1.0));
}

#[test]
fn scale_does_not_change_k() {
    let lights = LightSet::from_dirs([light(15.0, 45.0), light(60.0, 200.0)]);
    let spp = 4;
    let bake = |f: f32| {
        let mut m = sphere_scene();
        for p in &mut m.positions {
            *p = p.map(|c| c * f);
        }
        m.tile = [f, f];
        let s = PreparedMesh::from_mesh(m, None, "sphere").unwrap();
        bake_planes(&s, &lights, &cfg(32, spp)).unwrap().0
    };
    let reference = bake(1.0);
    // Embree alone loses primary hits from about 1e-12 (f32 products underflow with denormals
    // flushed); the baker's power-of-two normalisation keeps even 1e-30 and 1e30 exact.
    for f in [1e-30f32, 1e-12, 1e-4, 1e4, 1e12, 1e30] {
        let scaled = bake(f);
        let mut differ = 0;
        for (a, b) in reference.k.iter().flatten().zip(scaled.k.iter().flatten()) {
            // Scaling by a non-power of two rounds coordinates: a sample exactly at a
            // shadow edge may flip, nothing more.
            assert!(
                (a - b).abs() <= 1.0 / spp as f32 + 1e-6,
                "scale {f}: {a} vs {b}"
            );
            differ += (a != b) as usize;
        }
        let total = reference.k.len() * 32 * 32;
        assert!(
            differ * 100 <= total,
            "scale {f}: {differ} of {total} texels differ"
        );
    }
}

/// Point lights: nothing occluded on a plane, each texel's direction to the light
/// (`common::point_lights`).
#[test]
fn point_lights_record_per_texel_directions() {
    common::point_lights(&cpu);
}

/// An OBJ far from the origin (x = 1e6 or 1e9, where f32 steps are 0.0625 and 64) bakes the
/// K of the same mesh at the origin: the reader recentres in f64 before converting to f32.
#[test]
fn offset_obj_bakes_the_same_k() {
    let lights = LightSet::from_dirs([light(15.0, 45.0), light(60.0, 200.0)]);
    let spp = 4;
    let m = sphere_scene();
    let dir = std::env::temp_dir().join(format!("ptm-bake-offset-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bake = |off: [f64; 3]| {
        let mut text = format!("# tile {} {}\n", m.tile[0], m.tile[1]);
        for p in &m.positions {
            let q = [0, 1, 2].map(|a| p[a] as f64 + off[a]);
            text += &format!("v {:?} {:?} {:?}\n", q[0], q[1], q[2]);
        }
        for t in &m.triangles {
            text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        let path = dir.join(format!("sphere-{}.obj", off[0]));
        std::fs::write(&path, text).unwrap();
        let s = PreparedMesh::load(path.to_str().unwrap(), None).unwrap();
        bake_planes(&s, &lights, &cfg(32, spp)).unwrap()
    };
    let (reference, cov, _) = bake([0.0; 3]);
    for off in [
        [1e6, 0.0, 0.0],
        [1e6, -1e6, 1e6],
        [1e9, 1e9, 0.0],
        [-1e9, 0.0, 1e9],
    ] {
        let (k, c, _) = bake(off);
        // 1e6 + an f32 is exact in f64; at 1e9 the f64 sum rounds below 1e-7: a sample on a
        // shadow edge may flip, nothing more.
        let exact = off.iter().all(|c| c.abs() <= 1e6);
        let mut differ = 0;
        for (a, b) in reference.k.iter().flatten().zip(k.k.iter().flatten()) {
            assert!(
                (a - b).abs() <= 1.0 / spp as f32 + 1e-6,
                "{off:?}: {a} vs {b}"
            );
            differ += (a != b) as usize;
        }
        let total = reference.k.len() * 32 * 32;
        if exact {
            assert_eq!(differ, 0, "{off:?}");
            assert_eq!(c, cov, "{off:?}");
        }
        assert!(
            differ * 200 <= total,
            "{off:?}: {differ} of {total} texels differ"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
