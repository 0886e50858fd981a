//! Pile (velvet tufts, terry loops) on a plain ground weave, and corduroy-like grooves.

// SplitMix64: a seed gives the same pile everywhere.
use ptm_format::hash::SplitMix as Rng;
use ptm_format::vec3::{cross, norm};

use crate::mesh::Mesh;
use crate::params::Params;
use crate::weave::{self, Pattern, WovenParams};
use crate::yarn::{Cloth, Ends, Yarn};
use crate::Result;

/// Distance between 2D segments [p0, p1] and [q0, q1].
fn segment_distance(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> f64 {
    let point_seg = |p: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        let ab = [b[0] - a[0], b[1] - a[1]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1];
        let t = if len2 > 0.0 {
            (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p[0] - a[0] - t * ab[0]).hypot(p[1] - a[1] - t * ab[1])
    };
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let (d1, d2) = (orient(p0, p1, q0), orient(p0, p1, q1));
    let (d3, d4) = (orient(q0, q1, p0), orient(q0, q1, p1));
    if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
        return 0.0; // proper crossing
    }
    point_seg(p0, q0, q1)
        .min(point_seg(p1, q0, q1))
        .min(point_seg(q0, p0, p1))
        .min(point_seg(q1, p0, p1))
}

/// Velvet (`velvet`: straight tufts, leaning up to `tilt` degrees) or terry (`terry`: upright
/// loops) pile on a plain ground weave of `repeat` × 2 yarns per side.
///
/// Tufts stand on the top of the ground (its highest point, crimp + height/2, lifted by
/// whatever keeps a leaning tuft's flat foot above it), so they never cut a ground yarn. They
/// are placed by dart throwing from `seed`: a candidate is kept when the xy shadows of its
/// centre line keep 2·radius (+5 %) from every tuft placed so far, periodic copies included,
/// which keeps the tubes apart in 3D as well. Tufts are capped tubes and are not cut at the
/// tile border: one near a border sticks out and its copy fills the neighbour.
pub fn from_params(name: &str, p: &Params) -> Result<(Cloth, usize)> {
    let loops = name == "terry";
    let repeat = p.int("repeat", 2, 1, 32)? as usize;
    let wp = WovenParams::from_params(p)?;
    let s = wp.spacing;
    let pile = p.positive("pile", if loops { 0.6 } else { 0.8 } * s, 20.0 * s)?;
    let radius = p.positive("radius", 0.05 * s, 0.5 * s)?;
    let density = p.positive(
        "density",
        if loops { 6.0 } else { 20.0 } / (s * s),
        1e4 / (s * s),
    )?;
    let tilt = if loops {
        0.0
    } else {
        p.real("tilt", 10.0, 0.0, 60.0)?.to_radians()
    };
    let half = if loops {
        p.positive("loop", 0.2 * s, 2.0 * s)?
    } else {
        0.0
    };
    let seed = p.int("seed", 1, 0, i64::MAX)? as u64;
    let rings = p.int("rings", if loops { 16 } else { 4 }, 2, 1024)? as usize;

    let base = Pattern::from_fn(2 * repeat, 2 * repeat, |i, j| (i + j).is_multiple_of(2));
    let mut cloth = weave::woven(&base, &wp);
    let [w, h] = cloth.tile;
    // A leaning foot dips radius·sin(tilt) below its centre; 2 % of the radius more for rounding.
    let z0 = wp.crimp + 0.5 * wp.height + radius * (tilt.sin() + 0.02);
    let target = (density * w * h).round() as usize;

    // Footprints: the xy segment under each tuft's centre line. Discs of diameter `min_gap`
    // around the feet cannot pack denser than the hexagonal packing: refuse beyond it at once.
    let min_gap = 2.1 * radius;
    let packing = 2.0 / (3.0f64.sqrt() * min_gap * min_gap);
    if density > packing {
        return Err(p.invalid(
            "density",
            density,
            format!("at most about {packing:.3} tufts per unit area with radius {radius} (hexagonal packing)"),
        ));
    }
    let longest = if loops { 2.0 * half } else { pile * tilt.sin() };
    // A grid of cells at least one interaction reach wide, by the first endpoint of each foot:
    // two feet within `min_gap` of each other have first endpoints within both lengths + gap.
    let reach = 2.0 * longest + min_gap;
    let cells = [
        (w / reach).floor().max(1.0) as usize,
        (h / reach).floor().max(1.0) as usize,
    ];
    let mut grid: Vec<Vec<usize>> = vec![Vec::new(); cells[0] * cells[1]];
    let cell_of = |q: [f64; 2]| {
        let cx = ((q[0] / w * cells[0] as f64) as usize).min(cells[0] - 1);
        let cy = ((q[1] / h * cells[1] as f64) as usize).min(cells[1] - 1);
        [cx, cy]
    };
    let mut feet: Vec<([f64; 2], [f64; 2])> = Vec::with_capacity(target);
    let mut rng = Rng(seed ^ 0x005E_ED0F_F1B5);
    let mut attempts = 0;
    while feet.len() < target && attempts < 30 * target.max(1) {
        attempts += 1;
        let c = [rng.uniform() * w, rng.uniform() * h];
        let phi = rng.uniform() * std::f64::consts::TAU;
        let (sp, cp) = phi.sin_cos();
        let seg = if loops {
            (
                [c[0] - half * cp, c[1] - half * sp],
                [c[0] + half * cp, c[1] + half * sp],
            )
        } else {
            let lean = pile * (rng.uniform() * tilt).sin();
            (c, [c[0] + lean * cp, c[1] + lean * sp])
        };
        // Neighbouring cells, wrapped and deduplicated (small grids wrap onto themselves).
        let home = cell_of(c);
        let mut near: Vec<usize> = Vec::with_capacity(9);
        for dx in [cells[0] - 1, 0, 1] {
            for dy in [cells[1] - 1, 0, 1] {
                let k = ((home[1] + dy) % cells[1]) * cells[0] + (home[0] + dx) % cells[0];
                if !near.contains(&k) {
                    near.push(k);
                }
            }
        }
        let ok = near.iter().flat_map(|&k| grid[k].iter()).all(|&f| {
            let (a, b) = feet[f];
            (-1..=1).all(|ox| {
                (-1..=1).all(|oy| {
                    let o = [ox as f64 * w, oy as f64 * h];
                    let a = [a[0] + o[0], a[1] + o[1]];
                    let b = [b[0] + o[0], b[1] + o[1]];
                    segment_distance(seg.0, seg.1, a, b) >= min_gap
                })
            })
        });
        if ok {
            let [cx, cy] = home;
            grid[cy * cells[0] + cx].push(feet.len());
            feet.push(seg);
        }
    }
    if feet.len() < target {
        let reached = feet.len() as f64 / (w * h);
        return Err(p.invalid(
            "density",
            density,
            format!(
                "at most about {reached:.3} tufts per unit area with radius {radius} (only {} of {target} fit)",
                feet.len()
            ),
        ));
    }
    for (a, b) in feet {
        let (centre, tangents, reference) = if loops {
            // A half ellipse standing on its two feet: width 2·half, height `pile`.
            let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
            let dir = [(b[0] - a[0]) / (2.0 * half), (b[1] - a[1]) / (2.0 * half)];
            let mut centre = Vec::with_capacity(rings + 1);
            let mut tangents = Vec::with_capacity(rings + 1);
            for k in 0..=rings {
                let phi = std::f64::consts::PI * (1.0 - k as f64 / rings as f64);
                let (sn, cs) = phi.sin_cos();
                centre.push([
                    mid[0] + half * cs * dir[0],
                    mid[1] + half * cs * dir[1],
                    z0 + pile * sn,
                ]);
                // d/dk of the above (phi decreasing): from foot a up and over to foot b.
                tangents.push([half * sn * dir[0], half * sn * dir[1], -pile * cs]);
            }
            let normal = cross([dir[0], dir[1], 0.0], [0.0, 0.0, 1.0]);
            (centre, tangents, normal)
        } else {
            let lean = (b[0] - a[0]).hypot(b[1] - a[1]);
            let up = (pile * pile - lean * lean).max(0.0).sqrt();
            let t = [b[0] - a[0], b[1] - a[1], up];
            let centre = (0..=rings)
                .map(|k| {
                    let f = k as f64 / rings as f64;
                    [a[0] + f * t[0], a[1] + f * t[1], z0 + f * up]
                })
                .collect();
            // Any horizontal axis is off a tuft leaning less than 90°; take the one across it.
            let reference = if lean > 1e-12 * pile {
                let n = norm([t[0], t[1], 0.0]);
                [-t[1] / n, t[0] / n, 0.0]
            } else {
                [1.0, 0.0, 0.0]
            };
            (centre, vec![t; rings + 1], reference)
        };
        cloth.yarns.push(Yarn::round(
            centre,
            &tangents,
            radius,
            Ends::Capped,
            reference,
        ));
    }
    Ok((cloth, wp.segments))
}

/// Corduroy-like grooves: round wales of `radius` along y, `spacing` apart, lying on a flat
/// ground slab (top at z = 0, `slab` thick). The tile is one wale wide and one spacing long.
/// The simple case for analytic shadows. Derivation: under a light l = (cos e, 0, sin e) (across
/// the wales, elevation e) a wale centred on x_c shades the ground plane z = 0 over
/// x ∈ [x_c − r(1 + cos e)/sin e, x_c + r(1 − cos e)/sin e] (the projection of its circular
/// section along l), clipped where the next wale is in the way.
pub fn corduroy(p: &Params) -> Result<(Cloth, usize)> {
    let s = p.positive("spacing", 1.0, f64::INFINITY)?;
    let r = p.positive("radius", 0.4 * s, 0.5 * s)?;
    let slab = p.positive("slab", 0.1 * s, 10.0 * s)?;
    let segments = p.int("segments", 24, 3, 1024)? as usize;
    let along = p.int("along", 4, 3, 1024)? as usize;
    let tile = [s, s];
    let n = along;
    let centre = (0..=n)
        .map(|k| [0.5 * s, s * k as f64 / n as f64, r])
        .collect();
    let wale = Yarn::round(
        centre,
        &vec![[0.0, 1.0, 0.0]; n + 1],
        r,
        Ends::Periodic {
            shift: [0.0, s, 0.0],
        },
        [0.0, 0.0, 1.0],
    );
    // The slab: its top and bottom faces, each a 3×3 grid of squares spanning the tile. On the
    // tile torus the borders are identified and the faces close up (see the crate docs); 3 is
    // the least grid whose torus edges all join distinct vertices, and odd, so no slab vertex
    // sits under the wale's axis x = s/2 where the wale's lowest ring vertices touch z = 0.
    let g = 3;
    let mut extra = Mesh {
        tile: [s as f32; 2],
        ..Mesh::default()
    };
    for (z, up) in [(0.0, true), (-slab, false)] {
        let base = extra.positions.len() as u32;
        for j in 0..=g {
            for i in 0..=g {
                let (x, y) = (s * i as f64 / g as f64, s * j as f64 / g as f64);
                extra.positions.push([x as f32, y as f32, z as f32]);
            }
        }
        let id = |i: usize, j: usize| base + (j * (g + 1) + i) as u32;
        for j in 0..g {
            for i in 0..g {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                // Top faces up (counter-clockwise seen from above), bottom faces down.
                if up {
                    extra.triangles.extend([[a, b, c], [a, c, d]]);
                } else {
                    extra.triangles.extend([[a, c, b], [a, d, c]]);
                }
            }
        }
    }
    Ok((
        Cloth {
            tile,
            yarns: vec![wale],
            extra,
        },
        segments,
    ))
}
