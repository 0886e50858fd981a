//! Companion maps against closed forms: a periodic ridge (a triangle wave in x, exact in the
//! mesh) and a sphere resting on a floor (tessellated 64×32). Per footprint sample the exact
//! hit height, normal and visibility of every light are computed from the sample positions the
//! baker uses (`sample_xy`); the reference maps average them over each texel as the bake does,
//! and AO integrates the analytic visibility with the dome's own quadrature weights.
use ptm_bake::dome::{fibonacci, rings, Quadrature};
use ptm_bake::maps::{Maps, Occlusion};
use ptm_bake::{sample_xy, BakeConfig, Baker, PreparedMesh};
use ptm_format::LightSet;
use ptm_swatches::Mesh;

const RES: usize = 32;
const SPP: u32 = 4;
const SEED: u64 = 1;

fn cfg() -> BakeConfig {
    BakeConfig {
        res: [RES, RES],
        spp: SPP,
        seed: SEED,
        light_distance: None,
        packets: true,
        threads: 2,
    }
}

fn unit_mesh() -> Mesh {
    Mesh {
        tile: [1.0, 1.0],
        ..Default::default()
    }
}

/// Ridge height.
const H: f64 = 0.3;

/// z = H·(1 − |2x − 1|) over the unit tile: peak at x = ½, valleys at x = 0 and 1, constant in
/// y, so tiled it is an infinite corrugation.
fn ridge() -> Mesh {
    let mut m = unit_mesh();
    for y in [0.0f32, 1.0] {
        for (x, z) in [(0.0f32, 0.0f32), (0.5, H as f32), (1.0, 0.0)] {
            m.positions.push([x, y, z]);
        }
    }
    // Vertices: bottom row 0, 1, 2 (y = 0), top row 3, 4, 5 (y = 1).
    for q in 0..2u32 {
        m.triangles.push([q, q + 1, q + 4]);
        m.triangles.push([q, q + 4, q + 3]);
    }
    m
}

fn ridge_z(x: f64) -> f64 {
    let x = x.rem_euclid(1.0);
    H * (1.0 - (2.0 * x - 1.0).abs())
}

fn ridge_normal(x: f64) -> [f64; 3] {
    let s = if x.rem_euclid(1.0) < 0.5 {
        -2.0 * H
    } else {
        2.0 * H
    };
    let len = (1.0 + s * s).sqrt();
    [s / len, 0.0, 1.0 / len]
}

/// Whether the ridge point above x sees distant light l: it faces the light, and the ray
/// clears the nearest peak towards the light (beyond it the profile is lower and the ray
/// keeps rising).
fn ridge_visible(x: f64, l: [f64; 3]) -> bool {
    let n = ridge_normal(x);
    if n[0] * l[0] + n[2] * l[2] <= 0.0 || l[2] <= 0.0 {
        return false;
    }
    if l[0] == 0.0 {
        return true;
    }
    let xl = x.rem_euclid(1.0);
    let xp = match (l[0] > 0.0, xl < 0.5) {
        (true, true) => 0.5,
        (true, false) => 1.5,
        (false, true) => -0.5,
        (false, false) => 0.5,
    };
    ridge_z(x) + (xp - xl) / l[0] * l[2] >= H
}

const C: [f64; 3] = [0.5, 0.5, 0.2];
const R: f64 = 0.2;

fn sphere_scene() -> Mesh {
    let mut m = unit_mesh();
    let n = 4;
    for j in 0..=n {
        for i in 0..=n {
            m.positions
                .push([i as f32 / n as f32, j as f32 / n as f32, 0.0]);
        }
    }
    let k = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            m.triangles.push([k(i, j), k(i + 1, j), k(i + 1, j + 1)]);
            m.triangles.push([k(i, j), k(i + 1, j + 1), k(i, j + 1)]);
        }
    }
    use std::f32::consts::PI;
    let (nu, nv) = (64usize, 32usize);
    let base = m.positions.len() as u32;
    let c = C.map(|c| c as f32);
    let r = R as f32;
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
    m
}

/// The exact first hit straight down at (x, y): the sphere's top or the floor.
fn sphere_hit(x: f64, y: f64) -> ([f64; 3], [f64; 3]) {
    let d2 = (x - C[0]).powi(2) + (y - C[1]).powi(2);
    if d2 < R * R {
        let p = [x, y, C[2] + (R * R - d2).sqrt()];
        (p, [0, 1, 2].map(|a| (p[a] - C[a]) / R))
    } else {
        ([x, y, 0.0], [0.0, 0.0, 1.0])
    }
}

/// Whether point p with normal n sees distant light l past every copy of the sphere.
fn sphere_visible(p: [f64; 3], n: [f64; 3], l: [f64; 3]) -> bool {
    if n[0] * l[0] + n[1] * l[1] + n[2] * l[2] <= 0.0 {
        return false;
    }
    for a in -6..=6 {
        for b in -6..=6 {
            let c = [C[0] + a as f64, C[1] + b as f64, C[2]];
            let o = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let bq = o[0] * l[0] + o[1] * l[1] + o[2] * l[2];
            let cq = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - R * R;
            // A point on this copy's surface (cq ≈ 0) facing the light does not re-hit it.
            if cq < 1e-9 {
                continue;
            }
            let disc = bq * bq - cq;
            if disc > 0.0 && -bq - disc.sqrt() > 0.0 {
                return false;
            }
        }
    }
    true
}

/// Bakes `mesh` and returns its maps.
fn bake_maps(mesh: Mesh, lights: &LightSet, q: Quadrature) -> Maps {
    let s = PreparedMesh::from_mesh(mesh, None, "analytic").unwrap();
    let mut baker = Baker::with_surface(&s, &cfg(), 0..RES).unwrap();
    let coverage = baker.coverage().to_vec();
    let surface = baker.take_surface().unwrap();
    let mut occ = Occlusion::new(lights, &q.weights(lights), RES * RES).unwrap();
    baker
        .trace(lights, &mut |i, k, _| occ.add_light(i, k))
        .unwrap();
    let z = [s.bounds.min[2], s.bounds.max[2]];
    Maps::finish(&surface, &occ, &coverage, z, q, &s.material_names).unwrap()
}

/// The reference maps from per-sample closed forms `hit(x, y) → (p, n)` and `vis(p, n, l)`.
struct Reference {
    height: Vec<f64>,
    normal: Vec<[f64; 3]>,
    ao: Vec<f64>,
    bent: Vec<[f64; 3]>,
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

fn reference(
    hit: impl Fn(f64, f64) -> ([f64; 3], [f64; 3]),
    vis: impl Fn([f64; 3], [f64; 3], [f64; 3]) -> bool,
    lights: &LightSet,
    q: Quadrature,
) -> Reference {
    let w: Vec<f64> = q
        .weights(lights)
        .iter()
        .zip(&lights.dirs)
        .map(|(w, d)| w * d[2].max(0.0))
        .collect();
    let norm: f64 = w.iter().sum();
    let n = RES * RES;
    let mut r = Reference {
        height: vec![0.0; n],
        normal: vec![[0.0; 3]; n],
        ao: vec![0.0; n],
        bent: vec![[0.0; 3]; n],
    };
    for j in 0..RES {
        for i in 0..RES {
            let t = j * RES + i;
            let mut nsum = [0.0; 3];
            for s in 0..SPP as usize {
                let [x, y] = sample_xy([RES, RES], [1.0, 1.0], SPP as usize, SEED, [i, j], s);
                let (p, nn) = hit(x, y);
                r.height[t] += p[2] / SPP as f64;
                for (s, c) in nsum.iter_mut().zip(nn) {
                    *s += c;
                }
                for (l, wl) in lights.dirs.iter().zip(&w) {
                    if vis(p, nn, *l) {
                        r.ao[t] += wl / norm / SPP as f64;
                        for (b, c) in r.bent[t].iter_mut().zip(l) {
                            *b += wl * c;
                        }
                    }
                }
            }
            r.normal[t] = normalize(nsum);
            r.bent[t] = normalize(r.bent[t]);
        }
    }
    r
}

/// Errors of the baked maps against the reference: (mean, max) of the normal's angle (degrees),
/// the height (mesh units), AO, and the bent normal's angle (degrees).
fn errors(m: &Maps, r: &Reference) -> [(f64, f64); 4] {
    let ch = |n: &str| m.channel(n).unwrap();
    let v3 = |p: &str, t: usize| [".X", ".Y", ".Z"].map(|c| ch(&format!("{p}{c}"))[t] as f64);
    // atan2(|a × b|, a·b): acos of a dot product near 1 would read f32 rounding as 0.01°.
    let angle = |a: [f64; 3], b: [f64; 3]| {
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let sin = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        sin.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .to_degrees()
    };
    let n = RES * RES;
    let stats = |e: Vec<f64>| {
        (
            e.iter().sum::<f64>() / n as f64,
            e.iter().cloned().fold(0.0, f64::max),
        )
    };
    [
        stats(
            (0..n)
                .map(|t| angle(v3("normal", t), r.normal[t]))
                .collect(),
        ),
        stats(
            (0..n)
                .map(|t| (ch("height")[t] as f64 - r.height[t]).abs())
                .collect(),
        ),
        stats(
            (0..n)
                .map(|t| (ch("ao")[t] as f64 - r.ao[t]).abs())
                .collect(),
        ),
        stats((0..n).map(|t| angle(v3("bent", t), r.bent[t])).collect()),
    ]
}

fn print(name: &str, e: &[(f64, f64); 4]) {
    eprintln!(
        "{name}: normal angle mean {:.2e}° max {:.2e}°; height mean {:.2e} max {:.2e}; \
         AO mean {:.2e} max {:.2e}; bent angle mean {:.2e}° max {:.2e}°",
        e[0].0, e[0].1, e[1].0, e[1].1, e[2].0, e[2].1, e[3].0, e[3].1
    );
}

/// The ridge is exact in the mesh: every map matches its closed form to f32 precision, AO
/// but for samples within the ray offset of a shadow edge.
#[test]
fn ridge_maps_match_closed_forms() {
    let lights = fibonacci(64, 5.0).unwrap();
    let q = Quadrature::Fibonacci {
        min_elevation_deg: 5.0,
    };
    let maps = bake_maps(ridge(), &lights, q);
    let r = reference(
        |x, _| ([x, 0.0, ridge_z(x)], ridge_normal(x)),
        |p, _, l| ridge_visible(p[0], l),
        &lights,
        q,
    );
    let e = errors(&maps, &r);
    print("ridge", &e);
    // Measured: normal 0°, height 4.9e-8, AO 2.9e-8, bent ≤ 1e-5° (f32 rounding).
    assert!(e[0].1 < 1e-3, "normal angle {:?}", e[0]);
    assert!(e[1].1 < 1e-6, "height {:?}", e[1]);
    assert!(e[2].1 < 1e-6, "AO {:?}", e[2]);
    assert!(e[3].1 < 1e-3, "bent {:?}", e[3]);
    // The valley is darker than the peak.
    let ao = maps.channel("ao").unwrap();
    let row = &ao[RES * RES / 2..RES * RES / 2 + RES];
    assert!(row[0] < row[RES / 2] - 0.05, "{row:?}");
}

/// The sphere is tessellated (64×32, inscribed), so its normals, heights and silhouettes
/// differ from the closed form by the facets; the floor is exact.
#[test]
fn sphere_maps_match_closed_forms() {
    let lights = fibonacci(64, 5.0).unwrap();
    let q = Quadrature::Fibonacci {
        min_elevation_deg: 5.0,
    };
    let maps = bake_maps(sphere_scene(), &lights, q);
    let r = reference(sphere_hit, sphere_visible, &lights, q);
    let e = errors(&maps, &r);
    print("sphere", &e);
    // Facets 5.6° wide: their normals lie within about 3° of the sphere's, and the inscribed
    // facets sit up to r(1 − cos 2.8°) = 2.4e-4 below it (more at the silhouette, where a
    // sample on the sphere may hit the floor instead). Measured at 32², spp 4, 64 lights:
    // normal mean 0.11° (max 2.4°), height mean 6.5e-5 (max 2.5e-3), AO mean 1.1e-3 (max
    // 0.025), bent mean 0.10° (max 1.6°).
    assert!(e[0].0 < 0.3 && e[0].1 < 5.0, "normal angle {:?}", e[0]);
    assert!(e[1].0 < 2e-4 && e[1].1 < 5e-3, "height {:?}", e[1]);
    assert!(e[2].0 < 3e-3 && e[2].1 < 0.06, "AO {:?}", e[2]);
    assert!(e[3].0 < 0.3 && e[3].1 < 4.0, "bent {:?}", e[3]);
}

/// A flat floor is open: AO 1 everywhere for any dome, the normal +Z, the bent normal the
/// dome's own cosine-weighted mean direction; the dome fraction is the cap's share of the
/// cosine-weighted hemisphere, 1 − sin² e_min for Fibonacci (to the quadrature's accuracy).
#[test]
fn flat_floor_is_open_for_every_quadrature() {
    for (lights, q) in [
        (
            fibonacci(64, 10.0).unwrap(),
            Quadrature::Fibonacci {
                min_elevation_deg: 10.0,
            },
        ),
        (rings("15x8,45x8,75x8,90x1").unwrap(), Quadrature::Rings),
        (fibonacci(16, 5.0).unwrap(), Quadrature::Equal),
    ] {
        let mut m = unit_mesh();
        let n = 4u32;
        for j in 0..=n {
            for i in 0..=n {
                m.positions
                    .push([i as f32 / n as f32, j as f32 / n as f32, 0.1]);
            }
        }
        let k = |i: u32, j: u32| j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                m.triangles.push([k(i, j), k(i + 1, j), k(i + 1, j + 1)]);
                m.triangles.push([k(i, j), k(i + 1, j + 1), k(i, j + 1)]);
            }
        }
        let maps = bake_maps(m, &lights, q);
        assert!(maps.channel("ao").unwrap().iter().all(|&a| a == 1.0));
        assert!(maps.channel("normal.Z").unwrap().iter().all(|&z| z == 1.0));
        assert!(maps
            .channel("height")
            .unwrap()
            .iter()
            .all(|&h| (h - 0.1).abs() < 1e-7));
        let bz = maps.channel("bent.Z").unwrap();
        assert!(bz.iter().all(|&b| b == bz[0] && b > 0.9), "{}", bz[0]);
    }
    let lights = fibonacci(256, 20.0).unwrap();
    let q = Quadrature::Fibonacci {
        min_elevation_deg: 20.0,
    };
    let occ = Occlusion::new(&lights, &q.weights(&lights), 1).unwrap();
    let want = 1.0 - 20f64.to_radians().sin().powi(2);
    assert!(
        (occ.dome_fraction() - want).abs() < 1e-4,
        "{}",
        occ.dome_fraction()
    );
}
