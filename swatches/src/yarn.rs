//! Yarns as swept tubes (centre-line samples with elliptical cross-sections), the cloth they
//! make over one periodic tile, its triangle mesh and the yarn-to-yarn clearance.

use ptm_format::vec3::{cross, dot, norm, scale, sub};

use crate::mesh::Mesh;

/// How a yarn's tube ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ends {
    /// The yarn crosses the tile: its last ring is its first ring translated by `shift` (a whole
    /// number of tiles), and both lie in opposite border planes. The tube is left open there:
    /// the copy in the next tile continues it, so the tiled surface is closed.
    Periodic {
        /// The translation from first to last ring, whole tiles, user units.
        shift: [f64; 3],
    },
    /// A closed tube with flat caps at both ends (pile tufts, loops).
    Capped,
}

/// One yarn: ring centres along its centre line and the cross-section ellipse at each.
#[derive(Clone, Debug)]
pub struct Yarn {
    /// Ring centres in the swatch frame (user units).
    pub centre: Vec<[f64; 3]>,
    /// Semi-axis vectors (e1, e2) of the cross-section at each ring: the ring is
    /// centre + cos θ·e1 + sin θ·e2. Sections need not be perpendicular to the yarn (woven yarns
    /// are sliced by planes of constant y or x so that border rings lie in the border plane),
    /// but e1 × e2 must point along the yarn, which makes the triangle normals point outwards.
    pub axes: Vec<[[f64; 3]; 2]>,
    /// How the tube ends.
    pub ends: Ends,
}

/// A set of yarns over one periodic tile, plus closed non-yarn parts (a ground slab).
#[derive(Clone, Debug, Default)]
pub struct Cloth {
    /// Tile size (W, H) in user units.
    pub tile: [f64; 2],
    /// The yarns, each a tube.
    pub yarns: Vec<Yarn>,
    /// Non-yarn geometry (already closed on the tile torus), excluded from the clearance.
    pub extra: Mesh,
}

/// The closest approach between two distinct yarns (or copies of one yarn in another tile).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearance {
    /// Separation of the two closest cross-sections along the best of the tried separating axes
    /// (see [`Cloth::clearance`]); negative means the tubes overlap there. Infinity when
    /// nothing is near.
    pub gap: f64,
    /// Indices of the two yarns and the tile offset of the second one's copy.
    pub yarns: (usize, usize),
    /// Tile offset (a, b) of the second yarn's copy.
    pub offset: [i32; 2],
    /// Midpoint of the two section centres.
    pub at: [f64; 3],
}

const AXES: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Half-extent of an ellipse with semi-axis vectors (e1, e2) along the unit direction u: the
/// support function sqrt((e1·u)² + (e2·u)²).
pub fn support(axes: &[[f64; 3]; 2], u: [f64; 3]) -> f64 {
    dot(axes[0], u).hypot(dot(axes[1], u))
}

impl Yarn {
    /// Yarn with a round section of `radius`, perpendicular to the centre line, from samples
    /// of a centre curve; the frame is fixed to the tangent (e1 horizontal), so two samples with
    /// equal tangents get equal rings: periodic curves give exactly periodic tubes.
    ///
    /// `reference` must never be parallel to the tangent (ẑ for yarns that run along the cloth,
    /// the normal of its plane for a loop standing in a plane): e1 = reference × t.
    pub fn round(
        centre: Vec<[f64; 3]>,
        tangents: &[[f64; 3]],
        radius: f64,
        ends: Ends,
        reference: [f64; 3],
    ) -> Yarn {
        let axes = tangents
            .iter()
            .map(|&t| {
                let t = scale(t, 1.0 / norm(t));
                let side = cross(reference, t);
                let e1 = scale(side, radius / norm(side));
                let e2 = scale(cross(t, e1), 1.0);
                [e1, e2]
            })
            .collect();
        Yarn { centre, axes, ends }
    }

    /// Largest semi-axis over the yarn, for culling.
    fn max_radius(&self) -> f64 {
        self.axes
            .iter()
            .map(|a| norm(a[0]).max(norm(a[1])))
            .fold(0.0, f64::max)
    }

    /// Appends the tube to `mesh` with `segments` vertices per ring.
    fn mesh_into(&self, segments: usize, mesh: &mut Mesh) {
        let n = self.centre.len();
        let s = segments;
        // Flip the angular direction if e1 × e2 runs against the yarn, so normals face out.
        let dir = sub(self.centre[1.min(n - 1)], self.centre[0]);
        let sign = if dot(cross(self.axes[0][0], self.axes[0][1]), dir) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        let base = mesh.positions.len() as u32;
        let ring_point = |k: usize, m: usize| -> [f64; 3] {
            let th = std::f64::consts::TAU * m as f64 / s as f64;
            let [e1, e2] = self.axes[k];
            let (sn, cs) = th.sin_cos();
            let c = self.centre[k];
            [0, 1, 2].map(|i| c[i] + cs * e1[i] + sign * sn * e2[i])
        };
        for k in 0..n {
            for m in 0..s {
                let p = match self.ends {
                    // The last ring is the first one moved by the shift, computed that way so
                    // the two borders match to rounding.
                    Ends::Periodic { shift } if k == n - 1 => {
                        let q = ring_point(0, m);
                        [q[0] + shift[0], q[1] + shift[1], q[2] + shift[2]]
                    }
                    _ => ring_point(k, m),
                };
                mesh.positions.push(p.map(|v| v as f32));
            }
        }
        let id = |k: usize, m: usize| base + (k * s + m % s) as u32;
        for k in 0..n - 1 {
            for m in 0..s {
                let (a, b, c, d) = (id(k, m), id(k, m + 1), id(k + 1, m + 1), id(k + 1, m));
                mesh.triangles.push([a, b, c]);
                mesh.triangles.push([a, c, d]);
            }
        }
        if self.ends == Ends::Capped {
            for (k, last) in [(0, false), (n - 1, true)] {
                let c = mesh.positions.len() as u32;
                mesh.positions.push(self.centre[k].map(|v| v as f32));
                for m in 0..s {
                    let (p, q) = (id(k, m), id(k, m + 1));
                    mesh.triangles
                        .push(if last { [c, p, q] } else { [c, q, p] });
                }
            }
        }
    }
}

impl Cloth {
    /// The triangle mesh: every yarn as a tube with `segments` vertices per ring.
    pub fn mesh(&self, segments: usize) -> Mesh {
        self.mesh_parts(segments).0
    }

    /// [`Cloth::mesh`], and per triangle the part it belongs to: the index of its yarn, or
    /// `yarns.len()` for the non-yarn geometry (`extra`).
    pub fn mesh_parts(&self, segments: usize) -> (Mesh, Vec<u32>) {
        let mut mesh = Mesh {
            tile: self.tile.map(|v| v as f32),
            ..Mesh::default()
        };
        let mut parts = Vec::new();
        for (i, y) in self.yarns.iter().enumerate() {
            y.mesh_into(segments, &mut mesh);
            parts.resize(mesh.triangles.len(), i as u32);
        }
        mesh.append(&self.extra);
        parts.resize(mesh.triangles.len(), self.yarns.len() as u32);
        (mesh, parts)
    }

    /// The smallest gap between the cross-sections of two distinct yarns, copies in the 8
    /// neighbouring tiles included (a knit course meets its own copy one course up). For a pair
    /// of ring samples with centre offset d the gap along a unit axis v is
    /// |d·v| − s₁(v) − s₂(v), s the ellipse support functions; a positive gap on any axis
    /// separates the two sections (separating-axis theorem). Axes tried: u = d/|d| and x̂, ŷ, ẑ.
    /// The result is a lower bound of the true gap at the samples (for round sections, u gives
    /// it exactly); between samples it is an estimate.
    ///
    /// Only sample pairs closer than four times the largest semi-axis are examined (found
    /// through a periodic grid over the tile, so large drafts stay fast); farther pairs cannot
    /// overlap. `gap` is infinite when no pair is that close.
    pub fn clearance(&self) -> Clearance {
        let mut best = Clearance {
            gap: f64::INFINITY,
            yarns: (0, 0),
            offset: [0, 0],
            at: [0.0; 3],
        };
        let [w, h] = self.tile;
        let rmax = self.yarns.iter().map(Yarn::max_radius).fold(0.0, f64::max);
        if self.yarns.is_empty() || rmax <= 0.0 {
            return best;
        }
        let reach = 4.0 * rmax;
        // Cells at least `reach` wide over the tile; samples are filed by position modulo it.
        let cells = [
            ((w / reach).floor() as usize).max(1),
            ((h / reach).floor() as usize).max(1),
        ];
        let cell_of = |p: [f64; 3]| {
            let fx = (p[0] / w).rem_euclid(1.0);
            let fy = (p[1] / h).rem_euclid(1.0);
            [
                ((fx * cells[0] as f64) as usize).min(cells[0] - 1),
                ((fy * cells[1] as f64) as usize).min(cells[1] - 1),
            ]
        };
        let mut grid: Vec<Vec<(usize, usize)>> = vec![Vec::new(); cells[0] * cells[1]];
        for (a, y) in self.yarns.iter().enumerate() {
            for (i, &p) in y.centre.iter().enumerate() {
                let [cx, cy] = cell_of(p);
                grid[cy * cells[0] + cx].push((a, i));
            }
        }
        let scale_len = w + h;
        let mut near = Vec::with_capacity(9);
        for (a, ya) in self.yarns.iter().enumerate() {
            for (i, &pa) in ya.centre.iter().enumerate() {
                let [cx, cy] = cell_of(pa);
                near.clear();
                for dx in [cells[0] - 1, 0, 1] {
                    for dy in [cells[1] - 1, 0, 1] {
                        let k = ((cy + dy) % cells[1]) * cells[0] + (cx + dx) % cells[0];
                        if !near.contains(&k) {
                            near.push(k);
                        }
                    }
                }
                for &k in &near {
                    for &(b, j) in &grid[k] {
                        // Each unordered pair of samples once (a sample meets its own copies).
                        if (b, j) < (a, i) {
                            continue;
                        }
                        let yb = &self.yarns[b];
                        for ox in -1..=1 {
                            for oy in -1..=1 {
                                if a == b {
                                    if ox == 0 && oy == 0 {
                                        continue; // a yarn's own samples
                                    }
                                    // A yarn's copy one shift along is the same yarn, continued.
                                    if let Ends::Periodic { shift } = ya.ends {
                                        let off = [ox as f64 * w, oy as f64 * h];
                                        let same = |sg: f64| {
                                            (0..2).all(|q| {
                                                (off[q] - sg * shift[q]).abs() < 1e-9 * scale_len
                                            })
                                        };
                                        if same(1.0) || same(-1.0) {
                                            continue;
                                        }
                                    }
                                }
                                let pb = yb.centre[j];
                                let pb = [pb[0] + ox as f64 * w, pb[1] + oy as f64 * h, pb[2]];
                                let d = sub(pb, pa);
                                let len = norm(d);
                                if len > reach || len - 2.0 * rmax > best.gap {
                                    continue;
                                }
                                let u = scale(d, 1.0 / len.max(1e-300));
                                let (sa, sb) = (&ya.axes[i], &yb.axes[j]);
                                // Separating axes tried: the centre line and the frame axes
                                // (ẑ certifies flat ellipses stacked at a crossing).
                                let mut gap = len - support(sa, u) - support(sb, u);
                                for (q, e) in AXES.iter().enumerate() {
                                    gap = gap.max(d[q].abs() - support(sa, *e) - support(sb, *e));
                                }
                                if gap < best.gap {
                                    best = Clearance {
                                        gap,
                                        yarns: (a, b),
                                        offset: [ox, oy],
                                        at: [0, 1, 2].map(|q| 0.5 * (pa[q] + pb[q])),
                                    };
                                }
                            }
                        }
                    }
                }
            }
        }
        best
    }
}
