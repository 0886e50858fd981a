//! The analytic bake cases, shared by every tracer's tests: `bake/tests/analytic.rs` runs them
//! on the Embree bake, `gpubake/tests/analytic.rs` on the GPU's, with the same scenes and the
//! same tolerances. A case takes the bake to test as a function.
#![allow(dead_code, unused_imports)] // each test crate uses a part
use ptm_bake::{BakeConfig, BakeReport, Planes, PreparedMesh};
use ptm_format::LightSet;
use ptm_swatches::Mesh;

/// A tracer under test: (planes, coverage, report) of a bake.
pub type Bake = dyn Fn(&PreparedMesh, &LightSet, &BakeConfig) -> (Planes, Vec<f32>, BakeReport);

pub fn cfg(res: usize, spp: u32) -> BakeConfig {
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
pub fn light(e: f64, phi: f64) -> [f64; 3] {
    let (e, phi) = (e.to_radians(), phi.to_radians());
    [e.cos() * phi.cos(), e.cos() * phi.sin(), e.sin()]
}

/// An n×n grid of quads at height z over the unit tile.
pub fn plane(m: &mut Mesh, n: usize, z: f32) {
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

pub fn sphere(m: &mut Mesh, c: [f32; 3], r: f32, nu: usize, nv: usize) {
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

pub fn unit_mesh() -> Mesh {
    Mesh {
        tile: [1.0, 1.0],
        ..Default::default()
    }
}

pub fn sphere_scene() -> Mesh {
    let mut m = unit_mesh();
    plane(&mut m, 4, 0.0);
    sphere(&mut m, [0.5, 0.5, 0.2], 0.2, 64, 32);
    m
}

pub fn flat_plane(bake: &Bake) {
    let mut m = unit_mesh();
    plane(&mut m, 8, 0.0);
    let s = PreparedMesh::from_mesh(m, None, "plane").unwrap();
    let lights = ptm_bake::dome::fibonacci(32, 5.0).unwrap();
    let (planes, coverage, rep) = bake(&s, &lights, &cfg(32, 4));
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
pub fn infinite_wall(bake: &Bake) {
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
    let (planes, _, rep) = bake(&s, &lights, &cfg(res, spp));
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
pub fn sphere_on_plane(bake: &Bake) {
    let s = PreparedMesh::from_mesh(sphere_scene(), None, "sphere").unwrap();
    let (e, phi) = (40.0f64, 30.0f64);
    let l = light(e, phi);
    let lights = LightSet::from_dirs([l]);
    let res = 64;
    let (planes, coverage, _) = bake(&s, &lights, &cfg(res, 4));
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

/// Point lights: on a flat plane nothing is occluded, and each texel records the direction
/// from its own footprint to the light.
pub fn point_lights(bake: &Bake) {
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
    let (planes, _, _) = bake(&s, &lights, &c);
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
