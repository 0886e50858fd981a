//! Cross-check against an independent brute-force tracer (Möller–Trumbore over every triangle
//! of a full (2k+1)² block of copies, k = ⌈H_z / (W·tan e)⌉, in f64): same sample positions,
//! same offsets, no Embree and none of the baker's copy selection.
use ptm_bake::{bake_planes, dome, sample_xy, BakeConfig, PreparedMesh};
use ptm_format::vec3::{cross, dot, sub};

/// Distance t ∈ (0, tfar) to triangle `v` along `o + t·d`, if hit.
fn hit(o: [f64; 3], d: [f64; 3], v: [[f64; 3]; 3], tfar: f64) -> Option<(f64, [f64; 3])> {
    let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det.abs() < 1e-300 {
        return None;
    }
    let s = sub(o, v[0]);
    let u = dot(s, p) / det;
    let q = cross(s, e1);
    let w = dot(d, q) / det;
    let t = dot(e2, q) / det;
    (u >= 0.0 && w >= 0.0 && u + w <= 1.0 && t > 0.0 && t < tfar).then(|| (t, cross(e1, e2)))
}

#[test]
fn plain_weave_matches_a_brute_force_tracer() {
    compare_with_brute_force(None);
}

/// Point lights on a hemisphere of radius 3 (1.5 tiles) over the tile centre.
#[test]
fn point_lights_match_a_brute_force_tracer() {
    compare_with_brute_force(Some(3.0));
}

fn compare_with_brute_force(light_distance: Option<f64>) {
    let swatch = PreparedMesh::load("builtin:plain-weave", None).unwrap();
    let lights = dome::fibonacci(6, 12.0).unwrap();
    let (res, spp) = (8usize, 1usize);
    let cfg = BakeConfig {
        res: [res, res],
        spp: spp as u32,
        seed: 3,
        light_distance,
        packets: true,
        threads: 1,
    };
    let (planes, coverage, rep) = bake_planes(&swatch, &lights, &cfg).unwrap();
    let [w, h] = swatch.tile;
    let (z0, z1) = (swatch.bounds.min[2], swatch.bounds.max[2]);
    let scale = swatch.scale();
    // The baker's documented conventions: camera and clamp plane 1e-3·scale above the top,
    // shadow origins 1e-5·scale along the normal face-forwarded to the camera.
    let (z_cap, eps) = (z1 + 1e-3 * scale, 1e-5 * scale);
    let tris: Vec<[[f64; 3]; 3]> = swatch
        .triangles
        .iter()
        .map(|t| t.map(|k| swatch.positions[k as usize].map(f64::from)))
        .collect();
    let shifted = |k: i32| -> Vec<[[f64; 3]; 3]> {
        let mut out = Vec::new();
        for b in -k..=k {
            for a in -k..=k {
                let off = [a as f64 * w, b as f64 * h, 0.0];
                out.extend(
                    tris.iter()
                        .map(|t| t.map(|p| [p[0] + off[0], p[1] + off[1], p[2]])),
                );
            }
        }
        out
    };
    let near = shifted(1);
    let (mut compared, mut differ) = (0, 0);
    let mut seen = [false; 2]; // some lit and some occluded texel values
    for (li, l) in lights.dirs.iter().enumerate() {
        // Longest horizontal run of a shadow ray below z_max, and the block it needs.
        let light_pos = light_distance.map(|r| [w / 2.0 + r * l[0], h / 2.0 + r * l[1], r * l[2]]);
        let run = match light_pos {
            None => (z1 - z0) / l[2].asin().tan(),
            Some(q) => {
                assert!(q[2] > z1, "test lights must be above the swatch");
                let reach = (q[0] - w / 2.0).hypot(q[1] - h / 2.0) + w.hypot(h) / 2.0;
                (z1 - z0) * reach / (q[2] - z0)
            }
        };
        let k = (run / w.min(h)).ceil().max(1.0) as i32;
        assert!(
            rep.rings[li] as i32 <= k + 1,
            "light {li}: {} rings",
            rep.rings[li]
        );
        let block = shifted(k);
        for j in 0..res {
            for i in 0..res {
                let mut occluded = 0;
                let mut covered = 0;
                for s in 0..spp {
                    let [x, y] = sample_xy([res, res], swatch.tile, spp, 3, [i, j], s);
                    let o = [x, y, z_cap];
                    let first = near
                        .iter()
                        .filter_map(|t| hit(o, [0.0, 0.0, -1.0], *t, f64::INFINITY))
                        .min_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
                    let Some((t, ng)) = first else { continue };
                    covered += 1;
                    let len = dot(ng, ng).sqrt() * if ng[2] < 0.0 { -1.0 } else { 1.0 };
                    let n = ng.map(|c| c / len);
                    let p = [x + eps * n[0], y + eps * n[1], z_cap - t + eps * n[2]];
                    // Distant: unit direction, tfar at the clamp plane. Point: direction to
                    // the light (t = 1 at the light), tfar also at the clamp plane.
                    let (d, tfar) = match light_pos {
                        None => (*l, (z_cap - p[2]) / l[2]),
                        Some(q) => {
                            let d = sub(q, p);
                            (d, ((z_cap - p[2]) / d[2]).min(1.0))
                        }
                    };
                    if dot(n, d) <= 0.0 {
                        occluded += 1;
                        continue;
                    }
                    occluded += block.iter().any(|t| hit(p, d, *t, tfar).is_some()) as usize;
                }
                let texel = j * res + i;
                assert_eq!(
                    coverage[texel],
                    covered as f32 / spp as f32,
                    "coverage ({i},{j})"
                );
                if covered > 0 {
                    compared += 1;
                    let k_ref = occluded as f32 / covered as f32;
                    seen[(k_ref > 0.0) as usize] = true;
                    differ += (planes.k[li][texel] != k_ref) as usize;
                }
            }
        }
    }
    // f32 (Embree) against f64 (here): a sample grazing an edge may go either way.
    eprintln!("{differ} of {compared} texel values differ from the f64 reference");
    assert!(
        compared > 300 && seen == [true, true],
        "{compared} {seen:?}"
    );
    assert!(
        differ * 50 <= compared,
        "{differ} of {compared} texels differ from the reference"
    );
}
