//! Analytic bake tests: scenes whose occlusion is known in closed form (flat plane, an
//! infinitely long wall under grazing lights, a sphere on a plane), plus seams, packets versus
//! single rays, thread-count and scale invariance.
use ptm_bake::{bake_planes, BakeConfig, PreparedMesh};
use ptm_format::LightSet;
use ptm_swatches::Mesh;

fn cfg(res: usize, spp: u32) -> BakeConfig {
    BakeConfig {
        res: [res, res],
        spp,
        seed: 1,
        light_distance: None,
        packets: true,
        threads: 2,
    }
}

/// Unit direction at elevation `e` and azimuth `phi` (degrees, from +X towards +Y).
fn light(e: f64, phi: f64) -> [f64; 3] {
    let (e, phi) = (e.to_radians(), phi.to_radians());
    [e.cos() * phi.cos(), e.cos() * phi.sin(), e.sin()]
}

/// An n×n grid of quads at height z over the unit tile.
fn plane(m: &mut Mesh, n: usize, z: f32) {
    let base = m.positions.len() as u32;
    for j in 0..=n {
        for i in 0..=n {
            m.positions
                .push([i as f32 / n as f32, j as f32 / n as f32, z]);
        }
    }
    let k = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            m.triangles.push([k(i, j), k(i + 1, j), k(i + 1, j + 1)]);
            m.triangles.push([k(i, j), k(i + 1, j + 1), k(i, j + 1)]);
        }
    }
}

fn sphere(m: &mut Mesh, c: [f32; 3], r: f32, nu: usize, nv: usize) {
    use std::f32::consts::PI;
    let base = m.positions.len() as u32;
    for j in 0..=nv {
        let th = PI * j as f32 / nv as f32;
        for i in 0..nu {
            let ph = 2.0 * PI * i as f32 / nu as f32;
            m.positions.push([
                c[0] + r * th.sin() * ph.cos(),
                c[1] + r * th.sin() * ph.sin(),
                c[2] + r * th.cos(),
            ]);
        }
    }
    let k = |i: usize, j: usize| base + (j * nu + i % nu) as u32;
    for j in 0..nv {
        for i in 0..nu {
            m.triangles.push([k(i, j), k(i, j + 1), k(i + 1, j + 1)]);
            m.triangles.push([k(i, j), k(i + 1, j + 1), k(i + 1, j)]);
        }
    }
}

fn unit_mesh() -> Mesh {
    Mesh {
        tile: [1.0, 1.0],
        ..Default::default()
    }
}

fn sphere_scene() -> Mesh {
    let mut m = unit_mesh();
    plane(&mut m, 4, 0.0);
    sphere(&mut m, [0.5, 0.5, 0.2], 0.2, 64, 32);
    m
}

#[test]
fn flat_plane_is_never_occluded() {
    let mut m = unit_mesh();
    plane(&mut m, 8, 0.0);
    let s = PreparedMesh::from_mesh(m, None, "plane").unwrap();
    let lights = ptm_bake::dome::fibonacci(32, 5.0).unwrap();
    let (planes, coverage, rep) = bake_planes(&s, &lights, &cfg(32, 4)).unwrap();
    assert!(coverage.iter().all(|&c| c == 1.0));
    assert_eq!(rep.uncovered_texels, 0);
    for (i, k) in planes.k.iter().enumerate() {
        assert!(k.iter().all(|&k| k == 0.0), "light {i} occluded somewhere");
    }
    assert_eq!(rep.shadow_rays, 32 * 32 * 4 * 32);
}

/// A wall x = 0.5, z ∈ [0, h], spanning the tile in y (infinite along y once tiled), on a
/// floor. A light nearly along the wall at elevation e casts a band of width
/// D = h·|l_x|/l_z beside it, reached only after the ray has run h·|l_y|/l_z along y: several
/// tiles for the 5° and 10° lights below, so the baker must widen beyond 3×3 copies.
#[test]
fn infinite_wall_shadow_band_across_several_tiles() {
    let h = 0.3f32;
    let mut m = unit_mesh();
    plane(&mut m, 2, 0.0);
    let b = m.positions.len() as u32;
    m.positions.extend([
        [0.5, 0.0, 0.0],
        [0.5, 1.0, 0.0],
        [0.5, 1.0, h],
        [0.5, 0.0, h],
    ]);
    m.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
    let s = PreparedMesh::from_mesh(m, None, "wall").unwrap();
    // Band width D = 0.23 tile (its far edge inside a texel), light towards −x (so the band
    // lies at x > 0.5) and mostly +y.
    let dirs: Vec<[f64; 3]> = [5.0f64, 10.0]
        .iter()
        .map(|&e| {
            let lxy = 0.23 * e.to_radians().tan() / h as f64; // |l_x| / cos e
            light(e, 180.0 - lxy.acos().to_degrees())
        })
        .collect();
    let lights = LightSet::from_dirs(dirs.clone());
    let res = 64;
    let spp = 16;
    let (planes, _, rep) = bake_planes(&s, &lights, &cfg(res, spp)).unwrap();
    for (li, l) in dirs.iter().enumerate() {
        let d = h as f64 * l[0].abs() / l[2];
        assert!((d - 0.23).abs() < 1e-9);
        let run_y = h as f64 * l[1].abs() / l[2];
        let need = run_y.ceil() as u32;
        assert!(need >= 2, "the test must cross several tiles: run {run_y}");
        assert!(
            rep.rings[li] >= need,
            "light {li}: rings {} < {need}",
            rep.rings[li]
        );
        let k = &planes.k[li];
        let mut row_mean = 0.0;
        for j in 0..res {
            for i in 0..res {
                let (x0, x1) = (i as f64 / res as f64, (i + 1) as f64 / res as f64);
                // Exact occluded fraction of the texel's x-range: overlap with (0.5, 0.5 + D).
                let exact = ((x1.min(0.5 + d) - x0.max(0.5)).max(0.0)) / (x1 - x0);
                let got = k[j * res + i] as f64;
                if exact == 0.0 || exact == 1.0 {
                    assert_eq!(got, exact, "light {li} texel ({i},{j})");
                } else {
                    assert!(
                        (got - exact).abs() <= 0.5,
                        "light {li} ({i},{j}): {got} vs {exact}"
                    );
                }
                row_mean += got / (res * res) as f64;
            }
        }
        // Mean over the tile: the band is D wide (within sampling error of 16 jittered
        // samples on the two edge columns).
        assert!(
            (row_mean - d).abs() < 2e-3,
            "light {li}: mean K {row_mean} vs {d}"
        );
    }
}

/// A sphere of radius r resting on a floor under a light at elevation e: the floor shadow is
/// the ellipse (centre c − (r/l_z)·l projected, semi-axes r and r / sin e), and the sphere's
/// own half with n·l < 0 is dark.
#[test]
fn sphere_on_plane_shadow_and_terminator() {
    let s = PreparedMesh::from_mesh(sphere_scene(), None, "sphere").unwrap();
    let (e, phi) = (40.0f64, 30.0f64);
    let l = light(e, phi);
    let lights = LightSet::from_dirs([l]);
    let res = 64;
    let (planes, coverage, _) = bake_planes(&s, &lights, &cfg(res, 4)).unwrap();
    let k = &planes.k[0];
    let r = 0.2;
    let c = [0.5, 0.5, r];
    let centre = [c[0] - c[2] * l[0] / l[2], c[1] - c[2] * l[1] / l[2]];
    let (ax, ay) = (phi.to_radians().cos(), phi.to_radians().sin());
    // Normalised ellipse coordinate of a floor point (< 1 inside the shadow), over the
    // shadows of the sphere's copies in the neighbouring tiles too.
    let ellipse = |x: f64, y: f64| {
        let mut q = f64::INFINITY;
        for (a, b) in [-1.0, 0.0, 1.0]
            .iter()
            .flat_map(|&a| [(a, -1.0), (a, 0.0), (a, 1.0)])
        {
            let (dx, dy) = (x - centre[0] - a, y - centre[1] - b);
            let along = dx * ax + dy * ay;
            let across = -dx * ay + dy * ax;
            q = q.min((along / (r / e.to_radians().sin())).powi(2) + (across / r).powi(2));
        }
        q
    };
    let (mut checked_floor, mut checked_sphere) = ([0; 2], [0; 2]);
    let texel = 1.0 / res as f64;
    for j in 0..res {
        for i in 0..res {
            assert_eq!(coverage[j * res + i], 1.0);
            let x = (i as f64 + 0.5) * texel;
            let y = 1.0 - (j as f64 + 0.5) * texel;
            let got = k[j * res + i];
            let rho = ((x - c[0]).powi(2) + (y - c[1]).powi(2)).sqrt();
            let margin = 1.5 * texel;
            if rho > r + margin {
                // Floor texel: inside or outside the ellipse by more than a texel.
                let q = ellipse(x, y);
                if q < 0.8 {
                    assert_eq!(got, 1.0, "floor ({i},{j}) in shadow, q {q}");
                    checked_floor[0] += 1;
                } else if q > 1.25 {
                    assert_eq!(got, 0.0, "floor ({i},{j}) lit, q {q}");
                    checked_floor[1] += 1;
                }
            } else if rho < r - margin {
                // Top hemisphere point seen from above.
                let z = c[2] + (r * r - rho * rho).sqrt();
                let n = [(x - c[0]) / r, (y - c[1]) / r, (z - c[2]) / r];
                let ndl = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
                if ndl < -0.1 {
                    assert_eq!(got, 1.0, "sphere ({i},{j}) n·l {ndl}");
                    checked_sphere[0] += 1;
                } else if ndl > 0.1 {
                    assert_eq!(got, 0.0, "sphere ({i},{j}) n·l {ndl}");
                    checked_sphere[1] += 1;
                }
            }
        }
    }
    assert!(
        checked_floor[0] > 50 && checked_floor[1] > 1000,
        "{checked_floor:?}"
    );
    assert!(
        checked_sphere[0] > 15 && checked_sphere[1] > 200,
        "{checked_sphere:?}"
    );
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

/// Point lights: on a flat plane nothing is occluded, and each texel records the direction
/// from its own footprint to the light.
#[test]
fn point_lights_record_per_texel_directions() {
    let mut m = unit_mesh();
    plane(&mut m, 2, 0.0);
    let s = PreparedMesh::from_mesh(m, None, "plane").unwrap();
    let lights = LightSet::from_dirs([light(45.0, 0.0)]);
    let r = 2.0;
    let res = 16;
    let c = BakeConfig {
        light_distance: Some(r),
        ..cfg(res, 4)
    };
    let (planes, _, _) = bake_planes(&s, &lights, &c).unwrap();
    assert!(planes.k[0].iter().all(|&k| k == 0.0));
    let uv = &planes.uv.as_ref().unwrap()[0];
    let lpos = [0.5 + r * 0.5f64.sqrt(), 0.5, r * 0.5f64.sqrt()];
    for (j, i) in [(0, 0), (8, 3), (15, 15)] {
        let p = [
            (i as f64 + 0.5) / res as f64,
            1.0 - (j as f64 + 0.5) / res as f64,
            0.0,
        ];
        let d = [lpos[0] - p[0], lpos[1] - p[1], lpos[2] - p[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let got = uv[j * res + i];
        assert!(
            (got[0] as f64 - d[0] / len).abs() < 5e-3,
            "({i},{j}) u {got:?}"
        );
        assert!(
            (got[1] as f64 - d[1] / len).abs() < 5e-3,
            "({i},{j}) v {got:?}"
        );
    }
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
