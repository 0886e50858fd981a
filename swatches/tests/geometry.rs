//! Geometry properties of every generator over ranges of parameters: exact periodicity,
//! closed tubes with outward normals, no yarn through another, resolution control.

use std::collections::HashMap;

use ptm_swatches::obj::parse_obj;
use ptm_swatches::yarn::Ends;
use ptm_swatches::{build, Mesh, Swatch, Yarn};

/// Specs covering every generator and a spread of their parameters, at low resolution so the
/// suite stays fast in debug builds.
const SPECS: &[&str] = &[
    "plain-weave?segments=6&along=6",
    "plain-weave?spacing=2.5&width=2.2&height=0.5&segments=5&along=8",
    "plain-weave?spacing=0.3&width=0.15&height=0.1&crimp=0.1&segments=7&along=5",
    "plain-weave?width=0.9&height=0.3&flat=0.5&segments=6&along=10",
    "twill?segments=6&along=6",
    "twill?n=3&m=3&flat=0.3&segments=5&along=6",
    "twill?n=3&m=1&dir=s&segments=5&along=5",
    "twill?n=1&m=3&segments=5&along=4",
    "twill?n=2&m=2&dir=s&width=0.9&height=0.25&segments=5&along=4",
    "satin?segments=5&along=4",
    "satin?n=5&step=3&segments=5&along=4",
    "satin?n=7&step=3&segments=4&along=4",
    "basket?n=1&segments=6&along=5",
    "basket?n=2&segments=5&along=4",
    "basket?n=3&height=0.25&segments=4&along=4",
    "grid?rows=110/011/101&segments=5&along=4",
    "jersey?segments=6&along=32",
    "jersey?wales=2&courses=2&wale=3&segments=5&along=24",
    "jersey?radius=0.6&a=1.6&segments=6&along=32",
    "stockinette?h=3.5&row=4&radius=0.45&segments=5&along=32",
    "rib?segments=6&along=32",
    "rib?k=2&courses=2&segments=5&along=24",
    "rib?k=3&segments=4&along=24",
    "velvet?segments=6&along=4&density=2",
    "velvet?seed=7&tilt=30&pile=0.8&radius=0.08&segments=5&along=4&density=3",
    "terry?segments=6&along=4&rings=8",
    "terry?seed=3&loop=0.3&pile=0.5&segments=5&along=4&rings=6&density=1",
    "corduroy",
    "corduroy?spacing=2&radius=0.9&slab=0.3&segments=16&along=3",
];

fn tile_size(m: &Mesh) -> f64 {
    f64::from(m.tile[0].max(m.tile[1]))
}

/// Every vertex on one border plane has a partner on the opposite plane, one tile along, to
/// 1e-6 of the tile; returns how many border vertices there were.
fn border_matches(m: &Mesh, axis: usize) -> usize {
    let period = f64::from(m.tile[axis]);
    let tol = 1e-6 * tile_size(m);
    let on = |p: &[f32; 3], at: f64| (f64::from(p[axis]) - at).abs() <= 1e-7 * period;
    let low: Vec<[f64; 3]> = m
        .positions
        .iter()
        .filter(|p| on(p, 0.0))
        .map(|p| p.map(f64::from))
        .collect();
    let high: Vec<[f64; 3]> = m
        .positions
        .iter()
        .filter(|p| on(p, period))
        .map(|p| {
            let mut q = p.map(f64::from);
            q[axis] -= period;
            q
        })
        .collect();
    assert_eq!(
        low.len(),
        high.len(),
        "border vertex counts differ on axis {axis}"
    );
    for (from, to) in [(&low, &high), (&high, &low)] {
        for p in from.iter() {
            let best = to
                .iter()
                .map(|q| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt())
                .fold(f64::INFINITY, f64::min);
            assert!(
                best <= tol,
                "border vertex {p:?} on axis {axis} has no partner (nearest {best:e})"
            );
        }
    }
    low.len()
}

/// Welds vertices modulo the tile (to 1e-6 of the tile) and returns the canonical index of
/// each vertex: the mesh seen on the tile torus.
fn weld_on_torus(m: &Mesh) -> Vec<usize> {
    let [w, h] = m.tile.map(f64::from);
    let eps = 1e-6 * tile_size(m);
    let cell = |v: f64| (v / (4.0 * eps)).floor() as i64;
    let mut grid: HashMap<[i64; 3], Vec<(usize, [f64; 3])>> = HashMap::new();
    let mut ids = Vec::with_capacity(m.positions.len());
    let mut next = 0;
    for p in &m.positions {
        let mut q = p.map(f64::from);
        q[0] -= w * (q[0] / w).floor();
        q[1] -= h * (q[1] / h).floor();
        // Points just below the period wrap to just below 0, next to their partners at 0.
        if q[0] > w - 2.0 * eps {
            q[0] -= w;
        }
        if q[1] > h - 2.0 * eps {
            q[1] -= h;
        }
        let c = [cell(q[0]), cell(q[1]), cell(q[2])];
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &(id, r) in list {
                            if (0..3).all(|k| (q[k] - r[k]).abs() <= eps) {
                                found = Some(id);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        let id = found.unwrap_or_else(|| {
            next += 1;
            grid.entry(c).or_default().push((next - 1, q));
            next - 1
        });
        ids.push(id);
    }
    ids
}

/// On the torus every edge has exactly two triangles, traversing it in opposite directions.
fn assert_closed_on_torus(spec: &str, m: &Mesh) {
    let ids = weld_on_torus(m);
    let mut directed: HashMap<(usize, usize), u32> = HashMap::new();
    for t in &m.triangles {
        let v = t.map(|i| ids[i as usize]);
        assert!(
            v[0] != v[1] && v[1] != v[2] && v[0] != v[2],
            "{spec}: degenerate triangle {t:?}"
        );
        for k in 0..3 {
            *directed.entry((v[k], v[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        assert_eq!(
            n, 1,
            "{spec}: directed edge {a}->{b} used {n} times (inconsistent orientation)"
        );
        assert!(
            directed.contains_key(&(b, a)),
            "{spec}: edge {a}-{b} has a single triangle (open boundary)"
        );
    }
}

#[test]
fn every_generator_is_exactly_periodic_closed_and_outward() {
    for spec in SPECS {
        let s = build(spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
        let m = &s.mesh;
        assert!(!m.triangles.is_empty(), "{spec}: empty mesh");
        // Yarns that cross the tile leave rings on the borders; the pile and corduroy slab only
        // in their ground, the knits only on x.
        let nx = border_matches(m, 0);
        let ny = border_matches(m, 1);
        let crossing_x = s
            .cloth
            .yarns
            .iter()
            .filter(|y| matches!(y.ends, Ends::Periodic { shift } if shift[0] != 0.0))
            .count();
        let crossing_y = s
            .cloth
            .yarns
            .iter()
            .filter(|y| matches!(y.ends, Ends::Periodic { shift } if shift[1] != 0.0))
            .count();
        assert!(
            nx >= crossing_x * 3,
            "{spec}: {nx} border vertices on x for {crossing_x} yarns"
        );
        assert!(
            ny >= crossing_y * 3,
            "{spec}: {ny} border vertices on y for {crossing_y} yarns"
        );
        assert_closed_on_torus(spec, m);
        let vol = m.signed_volume();
        assert!(
            vol > 0.0,
            "{spec}: signed volume {vol} (normals point inwards)"
        );
        // Each yarn on its own is closed and outward too.
        for (k, y) in s.cloth.yarns.iter().enumerate() {
            let one = ptm_swatches::Cloth {
                tile: s.cloth.tile,
                yarns: vec![y.clone()],
                ..Default::default()
            }
            .mesh(5);
            assert!(one.signed_volume() > 0.0, "{spec}: yarn {k} is inside out");
        }
        // Nothing sticks out by a whole tile: a 3×3 block covers the central tile.
        let (lo, hi) = m.bounds().unwrap();
        for a in 0..2 {
            let t = m.tile[a];
            assert!(
                lo[a] > -t && hi[a] < 2.0 * t,
                "{spec}: bounds {lo:?}..{hi:?} exceed one tile"
            );
        }
    }
}

/// Semi-axis lengths of a section (round yarns have two equal ones).
fn radii(y: &Yarn, k: usize) -> (f64, f64) {
    let n = |v: [f64; 3]| v.iter().map(|c| c * c).sum::<f64>().sqrt();
    (n(y.axes[k][0]), n(y.axes[k][1]))
}

fn is_round(y: &Yarn) -> bool {
    (0..y.centre.len()).all(|k| {
        let (a, b) = radii(y, k);
        (a - b).abs() <= 1e-9 * a
    })
}

/// Distance from p to the polyline through `c`.
fn polyline_distance(p: [f64; 3], c: &[[f64; 3]]) -> f64 {
    c.windows(2)
        .map(|s| {
            let ab = [0, 1, 2].map(|k| s[1][k] - s[0][k]);
            let ap = [0, 1, 2].map(|k| p[k] - s[0][k]);
            let l2: f64 = ab.iter().map(|v| v * v).sum();
            let t = if l2 > 0.0 {
                (ap.iter().zip(&ab).map(|(a, b)| a * b).sum::<f64>() / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (0..3)
                .map(|k| (ap[k] - t * ab[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

/// How deep p lies inside yarn y (> 0 inside), independent of the library's clearance: round
/// yarns by the distance to the centre polyline, sliced woven yarns (sections in the plane
/// normal to their periodic shift) by the ellipse of the interpolated slice at p.
fn depth_inside(p: [f64; 3], y: &Yarn) -> f64 {
    if is_round(y) {
        if y.ends == Ends::Capped {
            // Flat caps: points behind the first or past the last ring's plane are outside.
            let c = &y.centre;
            let n = c.len();
            let dot = |a: [f64; 3], b: [f64; 3], q: [f64; 3]| {
                (0..3).map(|k| (q[k] - a[k]) * (b[k] - a[k])).sum::<f64>()
            };
            if dot(c[0], c[1], p) < 0.0 || dot(c[n - 1], c[n - 2], p) < 0.0 {
                return f64::NEG_INFINITY;
            }
        }
        return radii(y, 0).0 - polyline_distance(p, &y.centre);
    }
    let Ends::Periodic { shift } = y.ends else {
        panic!("an elliptical yarn that is not periodic");
    };
    let axis = if shift[0] != 0.0 { 0 } else { 1 };
    let c = &y.centre;
    let k = c.partition_point(|q| q[axis] <= p[axis]);
    if k == 0 || k == c.len() {
        return f64::NEG_INFINITY;
    }
    let f = (p[axis] - c[k - 1][axis]) / (c[k][axis] - c[k - 1][axis]);
    let lerp = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|i| a[i] + f * (b[i] - a[i]));
    let centre = lerp(c[k - 1], c[k]);
    let e1 = lerp(y.axes[k - 1][0], y.axes[k][0]);
    let e2 = lerp(y.axes[k - 1][1], y.axes[k][1]);
    // e1, e2 are orthogonal in the slice plane: coordinates by projection.
    let d = [0, 1, 2].map(|i| p[i] - centre[i]);
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (al, be) = (dot(d, e1) / dot(e1, e1), dot(d, e2) / dot(e2, e2));
    // 1 − elliptical radius, scaled to a length by the smaller semi-axis.
    (1.0 - al.hypot(be)) * dot(e1, e1).sqrt().min(dot(e2, e2).sqrt())
}

fn check_no_yarn_through_another(spec: &str, s: &Swatch) {
    let cloth = &s.cloth;
    let [w, h] = cloth.tile;
    let scale = w.max(h);
    let mut min_centre_gap = f64::INFINITY;
    for (a, ya) in cloth.yarns.iter().enumerate() {
        let verts = ptm_swatches::Cloth {
            tile: cloth.tile,
            yarns: vec![ya.clone()],
            ..Default::default()
        }
        .mesh(8)
        .positions;
        for (b, yb) in cloth.yarns.iter().enumerate() {
            for ox in -1..=1 {
                for oy in -1..=1 {
                    let off = [ox as f64 * w, oy as f64 * h];
                    if a == b && ox == 0 && oy == 0 {
                        continue;
                    }
                    if let (true, Ends::Periodic { shift }) = (a == b, ya.ends) {
                        let along = |sg: f64| {
                            (off[0] - sg * shift[0]).abs() < 1e-9 * scale
                                && (off[1] - sg * shift[1]).abs() < 1e-9 * scale
                        };
                        if along(1.0) || along(-1.0) {
                            continue; // the same yarn, continued
                        }
                    }
                    // Yarn b's copy, in yarn a's coordinates: move a's samples by −offset.
                    for v in &verts {
                        let p = [
                            f64::from(v[0]) - off[0],
                            f64::from(v[1]) - off[1],
                            f64::from(v[2]),
                        ];
                        let depth = depth_inside(p, yb);
                        assert!(
                            depth <= 2e-3 * scale,
                            "{spec}: a vertex of yarn {a} is {depth:e} inside yarn {b} (copy {ox},{oy}) at {p:?}"
                        );
                    }
                    if is_round(ya) && is_round(yb) {
                        let r = radii(ya, 0).0 + radii(yb, 0).0;
                        for pa in &ya.centre {
                            let p = [pa[0] - off[0], pa[1] - off[1], pa[2]];
                            min_centre_gap =
                                min_centre_gap.min(polyline_distance(p, &yb.centre) - r);
                        }
                    }
                }
            }
        }
    }
    assert!(
        min_centre_gap >= -1e-3 * scale,
        "{spec}: centre curves of round yarns come {min_centre_gap:e} closer than their radii"
    );
}

#[test]
fn no_yarn_passes_through_another() {
    for spec in SPECS {
        let s = build(spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
        assert!(
            s.clearance.gap >= -1e-9,
            "{spec}: library clearance {:?}",
            s.clearance
        );
        check_no_yarn_through_another(spec, &s);
    }
}

#[test]
fn the_independent_overlap_check_catches_overlaps() {
    // Too shallow a loop depth makes the courses collide:
    // the library refuses them, and the test's own check must see it too.
    let Err(err) = build("jersey?d=0.3") else {
        panic!("jersey?d=0.3 was accepted");
    };
    let err = err.to_string();
    assert!(err.contains("overlap"), "{err}");
    let mut s = build("jersey?segments=6&along=32").unwrap();
    // Fatten the yarn to twice its radius: the courses now collide.
    for a in &mut s.cloth.yarns[0].axes {
        *a = a.map(|e| e.map(|v| 2.0 * v));
    }
    assert!(s.cloth.clearance().gap < 0.0);
    let caught = std::panic::catch_unwind(|| check_no_yarn_through_another("moved", &s));
    assert!(
        caught.is_err(),
        "a deformed course passing through its neighbour went unnoticed"
    );
}

#[test]
fn resolution_controls_the_triangle_count() {
    // Plain weave: 4 tubes, each 2 spacings long, `along` rings per spacing, `segments` around.
    for (s, a) in [(6usize, 6usize), (12, 4), (20, 30)] {
        let m = build(&format!("plain-weave?segments={s}&along={a}")).unwrap();
        assert_eq!(
            m.mesh.triangles.len(),
            4 * 2 * a * s * 2,
            "segments={s} along={a}"
        );
    }
    // The benchmark size: along defaults to segments.
    let big = ptm_swatches::builtin("plain-weave?segments=80").unwrap();
    assert!(big.triangles.len() >= 100_000, "{}", big.triangles.len());
    // Knit: one course of `wales` loops, `along` rings per loop.
    let k = build("jersey?segments=10&along=40&wales=2").unwrap();
    assert_eq!(k.mesh.triangles.len(), 2 * 40 * 10 * 2);
}

#[test]
fn corduroy_volume_is_analytic() {
    // A 24-gon wale of radius r along the unit tile plus the slab: area (S/2)·r²·sin(2π/S).
    let (s, r, slab, n) = (2.0f64, 0.7f64, 0.3f64, 24.0f64);
    let m = ptm_swatches::builtin(&format!(
        "corduroy?spacing={s}&radius={r}&slab={slab}&segments=24"
    ))
    .unwrap();
    let expect = slab * s * s + 0.5 * n * r * r * (std::f64::consts::TAU / n).sin() * s;
    let got = m.signed_volume();
    assert!(
        (got - expect).abs() < 1e-5 * expect,
        "volume {got} vs {expect}"
    );
    // The wale rests on the slab: lowest wale vertex at z = 0, top at 2r.
    let (z0, z1) = m.z_range().unwrap();
    assert!((f64::from(z0) + slab).abs() < 1e-6 && (f64::from(z1) - 2.0 * r).abs() < 1e-6);
}

#[test]
fn pile_is_deterministic_from_its_seed() {
    let a = ptm_swatches::builtin("velvet?seed=5&segments=4").unwrap();
    let b = ptm_swatches::builtin("velvet?seed=5&segments=4").unwrap();
    let c = ptm_swatches::builtin("velvet?seed=6&segments=4").unwrap();
    assert_eq!(a, b);
    assert_eq!(a.triangles.len(), c.triangles.len());
    assert_ne!(a.positions, c.positions);
    // Pile stands above the ground: the top is the ground top plus about the pile height.
    let (_, zmax) = a.z_range().unwrap();
    assert!(zmax > 1.0, "velvet top at {zmax}");
}

#[test]
fn obj_round_trip_is_exact() {
    let m = ptm_swatches::builtin("twill?segments=5&along=4").unwrap();
    let dir = std::env::temp_dir().join(format!("ptm-swatches-obj-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("twill.obj");
    m.write_obj(&path).unwrap();
    let back = Mesh::read_obj(&path).unwrap();
    assert_eq!(back, m);
    std::fs::remove_dir_all(&dir).ok();
    let parse = |text: &str| parse_obj(text.as_bytes(), "t.obj");
    let err = parse("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("t.obj: line 3: face index 3 but the file has 2 vertices"),
        "{err}"
    );
    // Foreign OBJs: a quad with texture/normal indices and relative indices, no tile.
    let q = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/1 3/3/1 4/4/1\nf -4 -2 -1\n")
        .unwrap()
        .into_mesh();
    assert_eq!(q.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
    assert_eq!(q.tile, [0.0, 0.0]);
    assert!(parse("v 0 0 0\nf 1 0 1\n").is_err());
    // The `# tile` header of a written file, in f64.
    let text =
        std::fs::read_to_string(env!("CARGO_MANIFEST_DIR").to_string() + "/jersey.obj").unwrap();
    let tile = parse(&text).unwrap().tile.unwrap();
    assert!(
        (tile[0] - 2.0).abs() < 1e-6 && (tile[1] - 2.0 * 4.5 / std::f64::consts::TAU).abs() < 1e-6
    );
}

/// Möller–Trumbore: does the ray o + t·d (t > 0) hit triangle (a, b, c)?
fn ray_hits(o: [f64; 3], d: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [
            p[1] * q[2] - p[2] * q[1],
            p[2] * q[0] - p[0] * q[2],
            p[0] * q[1] - p[1] * q[0],
        ]
    };
    let dot = |p: [f64; 3], q: [f64; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let (e1, e2) = (sub(b, a), sub(c, a));
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    if det.abs() < 1e-15 {
        return false;
    }
    let tv = sub(o, a);
    let u = dot(tv, pv) / det;
    let qv = cross(tv, e1);
    let v = dot(d, qv) / det;
    let t = dot(e2, qv) / det;
    (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && t > 1e-9
}

#[test]
fn corduroy_shadows_match_the_analytic_interval() {
    // Ground points between the wales, lit across them at elevation e: shadowed exactly when
    // x ∈ (x_k − r(1 + cos e)/sin e, x_k + r(1 − cos e)/sin e) for some wale k (pile.rs).
    let (s, r) = (1.0f64, 0.35f64);
    let m = ptm_swatches::builtin(&format!("corduroy?spacing={s}&radius={r}&segments=96")).unwrap();
    let mut tris: Vec<[[f64; 3]; 3]> = Vec::new();
    for ox in -1..=5 {
        for t in &m.triangles {
            tris.push(t.map(|i| {
                let p = m.positions[i as usize].map(f64::from);
                [p[0] + ox as f64 * s, p[1], p[2]]
            }));
        }
    }
    let mut shadowed_count = 0;
    for e_deg in [25.0f64, 50.0, 75.0] {
        let e = e_deg.to_radians();
        let l = [e.cos(), 0.0, e.sin()];
        for k in 0..200 {
            let x = s * (k as f64 + 0.5) / 200.0;
            let centre = 0.5 * s;
            if (x - centre).abs() < r {
                continue; // under the wale, not seen from above
            }
            // Distance of the ground point from the analytic interval ends of each wale.
            let mut analytic = false;
            let mut margin = f64::INFINITY;
            for kk in -1..=5 {
                let xk = centre + kk as f64 * s;
                let (lo, hi) = (
                    xk - r * (1.0 + e.cos()) / e.sin(),
                    xk + r * (1.0 - e.cos()) / e.sin(),
                );
                analytic |= x > lo && x < hi;
                margin = margin.min((x - lo).abs()).min((x - hi).abs());
            }
            // The 96-gon is inside the circle by r(1 − cos(π/96)); skip points that close.
            if margin < 1e-3 * r / e.sin() {
                continue;
            }
            let o = [x, 0.5 * s, 1e-7];
            let hit = tris.iter().any(|t| ray_hits(o, l, t[0], t[1], t[2]));
            assert_eq!(hit, analytic, "x = {x}, elevation {e_deg}°");
            shadowed_count += usize::from(hit);
        }
    }
    assert!(
        shadowed_count > 50,
        "only {shadowed_count} shadowed samples: the test is vacuous"
    );
}

/// Every builtin names what its triangles are, one material per triangle, for the bake's id
/// map and masks; an OBJ's `usemtl` groups are read, faces before the first being `default`.
#[test]
fn builtins_and_obj_groups_name_their_materials() {
    for (spec, names) in [
        ("plain-weave", &["warp", "weft"][..]),
        ("satin", &["warp", "weft"]),
        ("jersey", &["loop"]),
        ("rib", &["loop"]),
        ("velvet", &["warp", "weft", "pile"]),
        ("terry", &["warp", "weft", "loop"]),
        ("corduroy", &["wale", "ground"]),
    ] {
        let s = ptm_swatches::build(spec).unwrap();
        assert_eq!(s.material_names, names, "{spec}");
        assert_eq!(s.materials.len(), s.mesh.triangles.len(), "{spec}");
        for (i, n) in names.iter().enumerate() {
            assert!(s.materials.contains(&(i as u32)), "{spec}: no {n}");
        }
    }
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nusemtl wool\nf 1 3 4\nusemtl silk\nf 1 2 4\nusemtl wool\nf 2 3 4\n";
    let o = ptm_swatches::obj::parse_obj(obj, "groups.obj").unwrap();
    assert_eq!(o.material_names, ["wool", "silk", "default"]);
    assert_eq!(o.materials, [2, 0, 1, 0]);
    let plain = ptm_swatches::obj::parse_obj(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n", "p").unwrap();
    assert!(plain.materials.is_empty() && plain.material_names.is_empty());
}
