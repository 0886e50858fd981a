//! Meshes for the mesh path (`ptm preview --mesh`): the built-in `plane`, `sphere`, `cylinder`
//! and `drape`, a Wavefront OBJ through the workspace's one reader (`ptm_swatches::obj`), their
//! MikkTSpace tangents (`bevy_mikktspace`, the algorithm Blender and glTF use), and the vertex
//! buffer both the GPU and the CPU twin read ([`MeshVertex`]).
//!
//! A mesh is a triangle soup of corners (three per triangle, never shared: MikkTSpace's
//! tangents are per corner, and the GPU draws it unindexed). World space is z up, lengths in
//! mesh units. **UVs are lengths on the cloth**: the built-ins' UVs are arc lengths in mesh units
//! (a 1 × 1 drape is one unit of cloth each way), so a PTM tiled at `repeat` tiles per unit keeps
//! its physical scale wherever the cloth is not stretched; an OBJ's UVs are taken as written.
//!
//! It lives in the runtime rather than in `ptm-swatches` because what it adds to the OBJ
//! reader (tangent frames, the vertex layout, the memory bound) exists only to be rendered.

use std::f32::consts::PI;
use std::path::Path;

use crate::layout::MeshVertex;
use crate::scene::{Scene, SceneBuffers};
use crate::{Error, Result};

/// One corner of a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Corner {
    /// Position (mesh units).
    pub position: [f32; 3],
    /// Unit shading normal.
    pub normal: [f32; 3],
    /// Texture coordinates (cloth length units for the built-ins).
    pub uv: [f32; 2],
}

/// A triangle soup: `corners[3t..3t + 3]` is triangle t (counter-clockwise seen from the side
/// its normals point to).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Three corners per triangle.
    pub corners: Vec<Corner>,
}

/// How an OBJ without texture coordinates gets them (`--uv-projection`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UvProjection {
    /// Refuse an OBJ without `vt` (the default): a made-up map is rarely what an artist wants.
    None,
    /// Planar along z: uv = (x, y).
    Planar,
    /// Box: each triangle projected along the axis its normal is closest to (tri-planar
    /// without the blend): uv = (y, z), (x, z) or (x, y).
    Box,
}

impl UvProjection {
    /// Every projection, as the CLI names them.
    pub const ALL: [UvProjection; 3] =
        [UvProjection::None, UvProjection::Planar, UvProjection::Box];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            UvProjection::None => "none",
            UvProjection::Planar => "planar",
            UvProjection::Box => "box",
        }
    }
}

/// What building the tangent frames found (reported in `--json`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TangentReport {
    /// Triangles of the mesh.
    pub triangles: usize,
    /// Triangles whose UVs span no area (a degenerate map) or whose positions span none: their
    /// corners got the fallback tangent (any unit vector perpendicular to the normal, sign +1)
    /// instead of MikkTSpace's.
    pub fallback_triangles: usize,
}

/// The built-in meshes `--mesh` names.
pub const BUILTINS: [&str; 4] = ["plane", "sphere", "cylinder", "drape"];

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        a.map(|x| x / n)
    } else {
        [0.0, 0.0, 1.0]
    }
}

impl Mesh {
    /// Triangles in the mesh.
    pub fn triangles(&self) -> usize {
        self.corners.len() / 3
    }

    /// Axis-aligned bounds (min, max).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for c in &self.corners {
            for a in 0..3 {
                lo[a] = lo[a].min(c.position[a]);
                hi[a] = hi[a].max(c.position[a]);
            }
        }
        (lo, hi)
    }

    /// A built-in mesh by name ([`BUILTINS`]); `detail` scales its resolution (1 = the default
    /// tessellation).
    pub fn builtin(name: &str, detail: f32) -> Option<Mesh> {
        let n = |base: f32| ((base * detail).round() as usize).max(4);
        match name {
            "plane" => Some(Mesh::plane([0.0, 0.0, 1.0, 1.0], n(8.0))),
            "sphere" => Some(Mesh::sphere(0.5, n(96.0), n(48.0))),
            "cylinder" => Some(Mesh::cylinder(0.5, 1.5, n(96.0), n(24.0))),
            "drape" => Some(Mesh::drape(n(200.0))),
            _ => None,
        }
    }

    /// An indexed grid of `nu`×`nv` quads (vertex (i, j) at `f(i/nu, j/nv)` = (position, uv)),
    /// normals from the positions (area-weighted face normals summed at shared vertices;
    /// vertices on a seam where `f` repeats a position are summed together when `wrap_u`).
    fn grid(
        nu: usize,
        nv: usize,
        wrap_u: bool,
        f: impl Fn(f32, f32) -> ([f32; 3], [f32; 2]),
    ) -> Mesh {
        let idx = |i: usize, j: usize| j * (nu + 1) + i;
        let verts: Vec<([f32; 3], [f32; 2])> = (0..=nv)
            .flat_map(|j| (0..=nu).map(move |i| (i, j)))
            .map(|(i, j)| f(i as f32 / nu as f32, j as f32 / nv as f32))
            .collect();
        let mut tris = Vec::with_capacity(nu * nv * 2);
        for j in 0..nv {
            for i in 0..nu {
                let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
        let mut normals = vec![[0f32; 3]; verts.len()];
        for t in &tris {
            let [p0, p1, p2] = t.map(|k| verts[k].0);
            let n = cross(sub(p1, p0), sub(p2, p0));
            for &k in t {
                for a in 0..3 {
                    normals[k][a] += n[a];
                }
            }
        }
        if wrap_u {
            for j in 0..=nv {
                let (a, b) = (idx(0, j), idx(nu, j));
                let s: [f32; 3] = std::array::from_fn(|k| normals[a][k] + normals[b][k]);
                normals[a] = s;
                normals[b] = s;
            }
        }
        let corners = tris
            .iter()
            .flatten()
            .map(|&k| Corner {
                position: verts[k].0,
                normal: normalize(normals[k]),
                uv: verts[k].1,
            })
            .collect();
        Mesh { corners }
    }

    /// The rectangle [x0, y0, x1, y1] of z = 0, normal +Z, with the identity UV map (uv = xy):
    /// the plane path's cloth as a mesh.
    pub fn plane(rect: [f32; 4], n: usize) -> Mesh {
        let [x0, y0, x1, y1] = rect;
        Mesh::grid(n, n, false, |s, t| {
            let p = [x0 + (x1 - x0) * s, y0 + (y1 - y0) * t, 0.0];
            (p, [p[0], p[1]])
        })
    }

    /// A UV sphere of radius r about (0, 0, r) (resting on z = 0), z up: u = r·φ east along the
    /// parallels (0 … 2πr), v = r·(π − θ) north along the meridians (0 … πr), θ from the north
    /// pole. The tangent (+u) is east, the bitangent (+v) north, the normal outward.
    pub fn sphere(r: f32, nu: usize, nv: usize) -> Mesh {
        Mesh::grid(nu, nv, true, |s, t| {
            let phi = 2.0 * PI * s;
            let theta = PI * (1.0 - t);
            let p = [
                r * theta.sin() * phi.cos(),
                r * theta.sin() * phi.sin(),
                r + r * theta.cos(),
            ];
            (p, [r * phi, r * (PI - theta)])
        })
    }

    /// An open cylinder of radius r and height h about the z axis (z from 0 to h): u = r·φ around
    /// (0 … 2πr), v = z. The tangent is +φ, the bitangent +z, the normal outward.
    pub fn cylinder(r: f32, h: f32, nu: usize, nv: usize) -> Mesh {
        Mesh::grid(nu, nv, true, |s, t| {
            let phi = 2.0 * PI * s;
            ([r * phi.cos(), r * phi.sin(), h * t], [r * phi, h * t])
        })
    }

    /// A square of cloth 2.4 × 2.4 units draped over a sphere of radius 0.5 resting on the floor
    /// z = 0: procedural, deterministic, no simulation. Cloth point (x, y) (its UV, in cloth
    /// units, minus 1.2) at radius ρ from the cloth's centre and azimuth φ lies on the upper
    /// hemisphere while ρ < πR/2 (arc length ρ from the top), then hangs from the equator: down
    /// by s = ρ − πR/2, swinging out into radial folds whose depth grows with s (seven of them
    /// with irregular phases: the extra circumference 2πρ − 2πR has to go somewhere), and pools
    /// on the floor once it reaches it (a fillet of 0.06, then outwards). The corners, furthest
    /// from the centre, hang lowest and pool most.
    pub fn drape(n: usize) -> Mesh {
        const R: f32 = 0.5;
        const HALF: f32 = 1.2;
        let cap = 0.5 * PI * R;
        let smooth_max = |a: f32, b: f32, k: f32| {
            let h = (0.5 + 0.5 * (a - b) / k).clamp(0.0, 1.0);
            b + (a - b) * h + k * h * (1.0 - h)
        };
        Mesh::grid(n, n, false, |s, t| {
            let (x, y) = (HALF * (2.0 * s - 1.0), HALF * (2.0 * t - 1.0));
            let rho = (x * x + y * y).sqrt();
            let phi = y.atan2(x);
            let uv = [x + HALF, y + HALF];
            // Folds start softly just above the equator (smoothstep over the last 0.15 of the
            // cap) so the cloth does not crease along a circle.
            let onset = ((rho - (cap - 0.15)) / 0.15).clamp(0.0, 1.0);
            let onset = onset * onset * (3.0 - 2.0 * onset);
            let wave = 0.5
                + 0.5 * (7.0 * phi + 0.9 * (3.0 * phi).sin() + 0.5 * (5.0 * phi + 1.3).cos()).sin();
            if rho < cap {
                let th = rho / R;
                let out = 0.04 * onset * wave;
                let rr = R * th.sin() + out * th.sin();
                return (
                    [rr * phi.cos(), rr * phi.sin(), R + (R + out) * th.cos()],
                    uv,
                );
            }
            let hang = rho - cap;
            // Fold depth grows with the hanging length (the circumference to lose grows with it).
            let depth = 0.04 + 0.16 * (1.0 - (-hang / 0.35).exp());
            // Down from the equator until the floor (with a fillet), then outwards along it.
            let z = smooth_max(R - hang, 0.0, 0.06);
            let along_floor = smooth_max(hang - R, 0.0, 0.06);
            let rr = R + depth * wave + 0.08 * hang + along_floor;
            ([rr * phi.cos(), rr * phi.sin(), z + 0.002], uv)
        })
    }

    /// An OBJ file through `ptm_swatches::obj` (polygons fan-triangulated, `vt` per corner,
    /// NaN coordinates refused with their line): smooth normals (area-weighted over the
    /// triangles sharing a position); without `vt`, `projection` says what to do.
    pub fn from_obj(path: &Path, projection: UvProjection) -> Result<Mesh> {
        let obj = ptm_swatches::obj::read_obj(path).map_err(|e| Error::Scene(e.to_string()))?;
        if obj.triangles.is_empty() {
            return Err(Error::Scene(format!(
                "{}: the OBJ has no faces: a mesh needs `f` lines",
                path.display()
            )));
        }
        let pos = |k: u32| obj.positions[k as usize].map(|c| c as f32);
        let mut normals = vec![[0f32; 3]; obj.positions.len()];
        for t in &obj.triangles {
            let [p0, p1, p2] = t.map(pos);
            let n = cross(sub(p1, p0), sub(p2, p0));
            for &k in t {
                for a in 0..3 {
                    normals[k as usize][a] += n[a];
                }
            }
        }
        let has_uv = !obj.triangle_uvs.is_empty();
        if !has_uv && projection == UvProjection::None {
            return Err(Error::Scene(format!(
                "{}: the OBJ has no texture coordinates (`vt`) on every face, and the PTM is \
                 tiled over the UVs: unwrap it (Blender: UV ▸ Unwrap, then export with UVs), or \
                 pass --uv-projection planar|box",
                path.display()
            )));
        }
        let mut corners = Vec::with_capacity(obj.triangles.len() * 3);
        for (ti, t) in obj.triangles.iter().enumerate() {
            let [p0, p1, p2] = t.map(pos);
            let face_n = normalize(cross(sub(p1, p0), sub(p2, p0)));
            for (c, &k) in t.iter().enumerate() {
                let p = pos(k);
                let uv = if has_uv {
                    obj.uvs[obj.triangle_uvs[ti][c] as usize].map(|x| x as f32)
                } else {
                    project(projection, p, face_n)
                };
                let n = normals[k as usize];
                corners.push(Corner {
                    position: p,
                    normal: if dot(n, n) > 0.0 {
                        normalize(n)
                    } else {
                        face_n
                    },
                    uv,
                });
            }
        }
        Ok(Mesh { corners })
    }

    /// MikkTSpace tangents per corner (xyz unit, w = bitangent sign, B = w·N×T), with the
    /// fallback where a triangle spans no UV or position area.
    pub fn tangents(&self) -> (Vec<[f32; 4]>, TangentReport) {
        struct Geo<'a> {
            m: &'a Mesh,
            out: Vec<[f32; 4]>,
        }
        impl bevy_mikktspace::Geometry for Geo<'_> {
            fn num_faces(&self) -> usize {
                self.m.triangles()
            }
            fn num_vertices_of_face(&self, _face: usize) -> usize {
                3
            }
            fn position(&self, face: usize, vert: usize) -> [f32; 3] {
                self.m.corners[3 * face + vert].position
            }
            fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
                self.m.corners[3 * face + vert].normal
            }
            fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
                self.m.corners[3 * face + vert].uv
            }
            fn set_tangent_encoded(&mut self, tangent: [f32; 4], face: usize, vert: usize) {
                self.out[3 * face + vert] = tangent;
            }
        }
        let mut g = Geo {
            m: self,
            out: vec![[0.0; 4]; self.corners.len()],
        };
        let ok = bevy_mikktspace::generate_tangents(&mut g);
        let mut out = g.out;
        let mut report = TangentReport {
            triangles: self.triangles(),
            fallback_triangles: 0,
        };
        for t in 0..self.triangles() {
            let c = &self.corners[3 * t..3 * t + 3];
            let e1 = sub(c[1].position, c[0].position);
            let e2 = sub(c[2].position, c[0].position);
            let area = dot(cross(e1, e2), cross(e1, e2)).sqrt();
            let d1 = [c[1].uv[0] - c[0].uv[0], c[1].uv[1] - c[0].uv[1]];
            let d2 = [c[2].uv[0] - c[0].uv[0], c[2].uv[1] - c[0].uv[1]];
            let uv_area = (d1[0] * d2[1] - d1[1] * d2[0]).abs();
            let scale = dot(e1, e1).max(dot(e2, e2)).max(f32::MIN_POSITIVE);
            let uv_scale = (d1[0] * d1[0] + d1[1] * d1[1])
                .max(d2[0] * d2[0] + d2[1] * d2[1])
                .max(f32::MIN_POSITIVE);
            let degenerate = !ok || area <= 1e-7 * scale || uv_area <= 1e-7 * uv_scale;
            let bad = |k: usize| {
                let t = out[3 * t + k];
                let n = c[k].normal;
                let txyz = [t[0], t[1], t[2]];
                !t.iter().all(|x| x.is_finite())
                    || dot(txyz, txyz) < 0.25
                    || dot(cross(txyz, n), cross(txyz, n)) < 1e-6
            };
            if degenerate || (0..3).any(bad) {
                report.fallback_triangles += 1;
                for k in 0..3 {
                    out[3 * t + k] = fallback_tangent(c[k].normal);
                }
            }
        }
        (out, report)
    }

    /// The vertex buffer: per corner its position, normal, MikkTSpace tangent, UV multiplied by
    /// `uv_to_ptm` (UV units → the PTM's swatch units: tiles per UV unit × the tile size) and
    /// the triangle's PTM units per mesh unit (√(PTM-space area / world area), what the level
    /// of detail needs).
    pub fn vertices(&self, uv_to_ptm: [f32; 2]) -> (Vec<MeshVertex>, TangentReport) {
        let (tangents, report) = self.tangents();
        let mut out = Vec::with_capacity(self.corners.len());
        for t in 0..self.triangles() {
            let c = &self.corners[3 * t..3 * t + 3];
            let uv = |k: usize| [c[k].uv[0] * uv_to_ptm[0], c[k].uv[1] * uv_to_ptm[1]];
            let e1 = sub(c[1].position, c[0].position);
            let e2 = sub(c[2].position, c[0].position);
            let x = cross(e1, e2);
            let area = dot(x, x).sqrt();
            let (u0, u1, u2) = (uv(0), uv(1), uv(2));
            let d1 = [u1[0] - u0[0], u1[1] - u0[1]];
            let d2 = [u2[0] - u0[0], u2[1] - u0[1]];
            let uv_area = (d1[0] * d2[1] - d1[1] * d2[0]).abs();
            let uv_scale = if area > 0.0 {
                (uv_area / area).sqrt()
            } else {
                0.0
            };
            for k in 0..3 {
                out.push(MeshVertex {
                    position: c[k].position,
                    normal: c[k].normal,
                    tangent: tangents[3 * t + k],
                    uv: uv(k),
                    uv_scale,
                    pad: 0.0,
                });
            }
        }
        (out, report)
    }
}

/// The tangent of a corner MikkTSpace could not give one: +X (or +Y where the normal is
/// nearly X) made perpendicular to the normal, sign +1.
pub fn fallback_tangent(n: [f32; 3]) -> [f32; 4] {
    let a = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t = normalize(sub(a, n.map(|x| x * dot(a, n))));
    [t[0], t[1], t[2], 1.0]
}

fn project(p: UvProjection, q: [f32; 3], n: [f32; 3]) -> [f32; 2] {
    match p {
        UvProjection::None | UvProjection::Planar => [q[0], q[1]],
        UvProjection::Box => {
            let a = n.map(f32::abs);
            if a[0] >= a[1] && a[0] >= a[2] {
                [q[1], q[2]]
            } else if a[1] >= a[2] {
                [q[0], q[2]]
            } else {
                [q[0], q[1]]
            }
        }
    }
}

/// Bytes the mesh's vertex buffer takes on the GPU.
pub fn vertex_bytes(triangles: usize) -> u64 {
    triangles as u64 * 3 * std::mem::size_of::<MeshVertex>() as u64
}

/// Bytes of the shadow maps of a scene: `side`² 32-bit depths per light (at least one layer).
pub fn shadow_bytes(side: u32, lights: usize) -> u64 {
    side as u64 * side as u64 * 4 * lights.max(1) as u64
}

/// The default side of the macro shadow's maps (`--shadow-size`): 2048² texels, 16 MiB a light.
pub const DEFAULT_SHADOW_SIZE: u32 = 2048;

/// Most lights a shadowed mesh scene may have: wgpu's guaranteed `max_texture_array_layers`.
pub const MAX_SHADOW_LIGHTS: usize = 256;

/// A mesh scene: the plane scene's PTM, albedo, lights and perspective camera, with a mesh in
/// place of the plane and the mesh path's shading (sheen, fill, normal map, and the mesh's own
/// macro shadow from every light: `shader/mesh.wgsl`'s `shadow_visibility`). No caster.
#[derive(Clone, Debug)]
pub struct MeshScene {
    /// PTM, albedo (constant or texture, tiled as the PTM), lights, size and the perspective
    /// camera (required); `view` and `blur` are unused and `caster` must be `None`.
    pub scene: Scene,
    /// The mesh.
    pub mesh: Mesh,
    /// UV units → PTM swatch units per axis (tiles per UV unit × the tile's size).
    pub uv_to_ptm: [f32; 2],
    /// glTF `sheenColorFactor` (linear rgb; 0 turns the lobe off).
    pub sheen_color: [f32; 3],
    /// glTF `sheenRoughnessFactor` in (0, 1].
    pub sheen_roughness: f32,
    /// The fill light K does not darken: albedo · fill · (½ + ½ n_z).
    pub fill: [f32; 3],
    /// A tangent-space normal map (+Y up), tiled with the PTM: width, height, texels (row 0
    /// at the far edge, as the PTM's).
    pub normal_map: Option<(usize, usize, Vec<[f32; 3]>)>,
    /// The period (PTM swatch units) the albedo texture and normal map tile with when the
    /// scene has no PTM (the render without K); with a PTM its own tile is used.
    pub tile: [f32; 2],
    /// The macro shadow's depth maps, one per light, `shadow_size`² texels each, framing the
    /// mesh's bounding box from the light's centre; 0 turns the macro shadow off.
    pub shadow_size: u32,
}

impl MeshScene {
    /// The mesh scene of `scene`, no sheen, no fill, no normal map, no macro shadow: shaded
    /// exactly as the plane path shades (what the plane-mesh equivalence test renders).
    pub fn plain(scene: Scene, mesh: Mesh, uv_to_ptm: [f32; 2]) -> MeshScene {
        MeshScene {
            scene,
            mesh,
            uv_to_ptm,
            sheen_color: [0.0; 3],
            sheen_roughness: 0.5,
            fill: [0.0; 3],
            normal_map: None,
            tile: [1.0, 1.0],
            shadow_size: 0,
        }
    }

    /// Lays the scene out as the shader's buffers (the plane scene's, then the mesh's vertex
    /// buffer, the normal map and the mesh fields of the uniform block).
    pub fn prepare(&self) -> Result<(SceneBuffers, TangentReport)> {
        let mut p = self.prepare_frame()?;
        let (vertices, report) = self.mesh.vertices(self.uv_to_ptm);
        p.mesh_vertices = vertices;
        Ok((p, report))
    }

    /// [`MeshScene::prepare`] without the vertex buffer (left empty; no MikkTSpace pass): the
    /// uniform block, lights and textures, what a moved camera needs
    /// ([`crate::gpu::Renderer::set_frame`]).
    pub fn prepare_frame(&self) -> Result<SceneBuffers> {
        let Some(cam) = self.scene.perspective else {
            return Err(Error::Scene(
                "a mesh needs the perspective camera (set Scene::perspective)".into(),
            ));
        };
        if self.scene.caster.is_some() {
            return Err(Error::Scene(
                "a caster over a mesh is not supported: the caster's penumbra map assumes the \
                 plane z = 0; drop --caster or --mesh"
                    .into(),
            ));
        }
        if self.mesh.corners.is_empty() {
            return Err(Error::Scene("the mesh has no triangles".into()));
        }

        let roughness_ok = self.sheen_roughness > 0.0 && self.sheen_roughness <= 1.0;
        let colours_ok = self
            .sheen_color
            .iter()
            .chain(&self.fill)
            .all(|c| c.is_finite() && *c >= 0.0);
        if !(roughness_ok && colours_ok) {
            return Err(Error::Scene(format!(
                "sheen colour {:?} and fill {:?} must be finite and ≥ 0, sheen roughness {} in \
                 (0, 1]",
                self.sheen_color, self.fill, self.sheen_roughness
            )));
        }
        if let Some(c) = self.mesh.corners.iter().find(|c| {
            !c.position
                .iter()
                .chain(&c.normal)
                .chain(&c.uv)
                .all(|x| x.is_finite())
        }) {
            return Err(Error::Scene(format!(
                "the mesh has a non-finite corner {c:?}"
            )));
        }
        let mut p = self.scene.prepare()?;
        let (lo, hi) = self.mesh.bounds();
        // Near and far planes around the mesh's bounding box along the view direction.
        let f = p.frame.cam_forward;
        let mut dmin = f32::INFINITY;
        let mut dmax = f32::NEG_INFINITY;
        for k in 0..8 {
            let q = [0, 1, 2].map(|a| if k >> a & 1 == 0 { lo[a] } else { hi[a] });
            let d = dot(sub(q, cam.eye), f);
            dmin = dmin.min(d);
            dmax = dmax.max(d);
        }
        if dmax <= 0.0 {
            return Err(Error::Scene(format!(
                "the mesh (bounds {lo:?} … {hi:?}) is behind the camera at {:?}: move the camera",
                cam.eye
            )));
        }
        p.frame.far = dmax * 1.01 + 1e-6;
        p.frame.near = (dmin * 0.99).max(p.frame.far * 1e-4);
        p.frame.sheen_color = self.sheen_color;
        p.frame.sheen_roughness = self.sheen_roughness;
        p.frame.fill = self.fill;
        if let Some((w, h, texels)) = &self.normal_map {
            if *w == 0 || *h == 0 || texels.len() != w * h {
                return Err(Error::Scene(format!(
                    "normal map {w}×{h} has {} texels",
                    texels.len()
                )));
            }
            p.normal_map = texels.iter().map(|n| [n[0], n[1], n[2], 0.0]).collect();
            p.frame.normal_size = [*w as u32, *h as u32];
        }
        if p.variant.basis.is_none() {
            // Without a PTM the frame's tile is the plane view's: textures tile as the PTM
            // would have.
            p.frame.tile = self.tile;
        }
        if self.shadow_size > 0 && !self.scene.lights.is_empty() {
            if self.shadow_size > crate::scene::MAX_IMAGE_SIDE {
                return Err(Error::Scene(format!(
                    "shadow maps of {0}×{0} texels exceed {1} a side (the largest texture GPUs \
                     are required to offer): lower the shadow map size",
                    self.shadow_size,
                    crate::scene::MAX_IMAGE_SIDE
                )));
            }
            if self.scene.lights.len() > MAX_SHADOW_LIGHTS {
                return Err(Error::Scene(format!(
                    "{} lights cast the mesh's shadow, one shadow map each, more than the {} \
                     layers GPUs are required to offer: use fewer lights or turn the macro \
                     shadow off",
                    self.scene.lights.len(),
                    MAX_SHADOW_LIGHTS
                )));
            }
            p.frame.shadow_lo = lo;
            p.frame.shadow_hi = hi;
            p.frame.shadow_size = self.shadow_size;
            p.variant.shadow = true;
        }
        p.variant.mesh = true;
        // A distant light's direction turns with the surface's tangent frame: K is evaluated
        // per pixel (MESH_DISTANT), with no per-frame terms and every path compiled.
        p.variant.distant_only = false;
        p.variant.normal_map = self.normal_map.is_some();
        Ok(p)
    }
}

/// Refuses a mesh whose vertex buffer exceeds `max_buffer_size` (the device's limit), before
/// anything is built or uploaded, with the figures.
pub fn check_fits(triangles: usize, max_buffer_size: u64) -> Result<()> {
    let bytes = vertex_bytes(triangles);
    if bytes > max_buffer_size {
        return Err(Error::Scene(format!(
            "the mesh's {triangles} triangles need a {:.1} MiB vertex buffer ({} B per corner, \
             3 corners each), more than this GPU's largest buffer ({:.1} MiB): decimate the \
             mesh (Blender: Decimate modifier) below {} triangles",
            bytes as f64 / 1048576.0,
            std::mem::size_of::<MeshVertex>(),
            max_buffer_size as f64 / 1048576.0,
            max_buffer_size / (3 * std::mem::size_of::<MeshVertex>() as u64)
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_tangents_follow_the_parallels_and_bitangents_the_meridians() {
        let m = Mesh::sphere(0.5, 48, 24);
        let (t, report) = m.tangents();
        // The pole rows' triangles have a collapsed edge: no area on one side of them.
        assert!(report.fallback_triangles <= 2 * 48, "{report:?}");
        let mut worst: f32 = 0.0;
        for (c, t) in m.corners.iter().zip(&t) {
            let p = c.position;
            let rxy = (p[0] * p[0] + p[1] * p[1]).sqrt();
            if rxy < 0.2 {
                continue; // near the poles east is ill defined
            }
            // MikkTSpace does not weld across the UV seam (u = 0 and u = 2πr differ): the
            // seam's corners see the faces on one side only, half a segment (3.75°) off east.
            let phi = p[1].atan2(p[0]);
            if phi.abs() < 1e-3 {
                assert!(t[1] > 4f32.to_radians().cos(), "seam tangent {t:?}");
                continue;
            }
            let east = [-p[1] / rxy, p[0] / rxy, 0.0];
            let cos = dot([t[0], t[1], t[2]], east);
            worst = worst.max(cos.clamp(-1.0, 1.0).acos().to_degrees());
            assert_eq!(t[3], 1.0, "east × north is outward: sign +1");
        }
        assert!(worst < 0.5, "tangent off east by {worst}°");
    }

    #[test]
    fn a_plane_has_the_swatch_frame_everywhere() {
        let m = Mesh::plane([0.0, 0.0, 2.0, 1.0], 4);
        let (t, report) = m.tangents();
        assert_eq!(report.fallback_triangles, 0);
        for t in t {
            assert!(
                (t[0] - 1.0).abs() < 1e-6 && t[1].abs() < 1e-6 && t[3] == 1.0,
                "{t:?}"
            );
        }
    }

    #[test]
    fn degenerate_uvs_fall_back_and_are_counted() {
        let mut m = Mesh::plane([0.0, 0.0, 1.0, 1.0], 2);
        // Collapse the UVs of the first triangle onto a point.
        for c in &mut m.corners[..3] {
            c.uv = [0.25, 0.25];
        }
        let (t, report) = m.tangents();
        assert_eq!(report.fallback_triangles, 1);
        for t in &t[..3] {
            assert!(t.iter().all(|x| x.is_finite()));
            assert!(t[2].abs() < 1e-6, "perpendicular to +Z: {t:?}");
        }
    }

    #[test]
    fn the_drape_is_deterministic_finite_and_folded() {
        let a = Mesh::drape(48);
        assert_eq!(a, Mesh::drape(48));
        assert!(a.corners.iter().all(|c| c
            .position
            .iter()
            .chain(&c.normal)
            .all(|x| x.is_finite())));
        let (lo, hi) = a.bounds();
        assert!(
            lo[2] >= 0.0 && hi[2] > 0.99 && hi[2] < 1.01,
            "{lo:?} {hi:?}"
        );
        // Folds: the hanging part's radius at mid height varies with azimuth by centimetres.
        let ring: Vec<f32> = a
            .corners
            .iter()
            .filter(|c| (c.position[2] - 0.3).abs() < 0.02)
            .map(|c| (c.position[0].powi(2) + c.position[1].powi(2)).sqrt())
            .collect();
        let (rmin, rmax) = ring
            .iter()
            .fold((f32::INFINITY, 0f32), |(a, b), &r| (a.min(r), b.max(r)));
        assert!(rmax - rmin > 0.05, "fold depth {}", rmax - rmin);
        let (_, report) = a.tangents();
        assert_eq!(report.fallback_triangles, 0, "{report:?}");
    }

    fn obj(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("ptm-mesh-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn an_obj_without_uvs_is_refused_by_name_or_projected() {
        let p = obj(
            "nouv.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
        );
        let e = Mesh::from_obj(&p, UvProjection::None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nouv.obj") && e.contains("--uv-projection"),
            "{e}"
        );
        let m = Mesh::from_obj(&p, UvProjection::Planar).unwrap();
        assert_eq!(m.triangles(), 2, "the quad is fan-triangulated");
        assert!(m
            .corners
            .iter()
            .all(|c| c.uv == [c.position[0], c.position[1]]));
        let m = Mesh::from_obj(&p, UvProjection::Box).unwrap();
        assert!(m
            .corners
            .iter()
            .all(|c| c.uv == [c.position[0], c.position[1]]));
    }

    #[test]
    fn an_obj_with_uvs_keeps_them_per_corner_and_counts_degenerate_ones() {
        let p = obj(
            "uv.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
             f 1/1 2/2 3/3 4/4\nf 2/2 5/2 3/2\n",
        );
        let m = Mesh::from_obj(&p, UvProjection::None).unwrap();
        assert_eq!(m.triangles(), 3);
        assert_eq!(m.corners[1].uv, [1.0, 0.0]);
        let (_, report) = m.tangents();
        assert_eq!(
            report.fallback_triangles, 1,
            "the triangle whose UVs are one point"
        );
    }

    #[test]
    fn a_nan_vertex_is_refused_with_its_line() {
        let p = obj(
            "nan.obj",
            "v 0 0 0\nv nan 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/1 3/1\n",
        );
        let e = Mesh::from_obj(&p, UvProjection::None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("nan.obj"), "{e}");
    }

    #[test]
    fn shadow_maps_too_large_or_for_too_many_lights_are_refused_with_the_figures() {
        let mut s = Scene::over_ptm(
            crate::synthetic::random_ptm(ptm_format::Basis::Ptm6, 4, 4, 1),
            1,
            [16, 12],
        );
        s.perspective = Some(crate::scene::Perspective {
            eye: [0.0, -3.0, 2.0],
            target: [0.0, 0.0, 0.5],
            fov_y_deg: 40.0,
        });
        s.lights = vec![crate::scene::Light {
            position: [1.0, 1.0, 3.0],
            radius: 0.1,
            rect: None,
            square_box: false,
            rect_angle_deg: 0.0,
            gaussian: None,
            distant: false,
            intensity: 1.0,
            color: [1.0; 3],
        }];
        let mut m = MeshScene::plain(s, Mesh::sphere(0.5, 8, 4), [1.0, 1.0]);
        m.shadow_size = 8193;
        let e = m.prepare_frame().unwrap_err().to_string();
        assert!(e.contains("8193×8193") && e.contains("8192"), "{e}");
        m.shadow_size = 64;
        m.scene.lights = vec![m.scene.lights[0]; 257];
        let e = m.prepare_frame().unwrap_err().to_string();
        assert!(e.contains("257 lights") && e.contains("256"), "{e}");
        m.scene.lights.truncate(1);
        let p = m.prepare_frame().unwrap();
        let (lo, hi) = m.mesh.bounds();
        assert!(p.variant.shadow && p.frame.shadow_size == 64);
        assert_eq!((p.frame.shadow_lo, p.frame.shadow_hi), (lo, hi));
        assert_eq!(shadow_bytes(64, 1), 64 * 64 * 4);
        // Size 0 turns it off; no light, no map.
        m.shadow_size = 0;
        assert!(!m.prepare_frame().unwrap().variant.shadow);
        m.shadow_size = 64;
        m.scene.lights.clear();
        assert!(!m.prepare_frame().unwrap().variant.shadow);
    }

    #[test]
    fn a_mesh_too_large_for_the_gpu_is_refused_with_the_figures() {
        let max = 256 << 20;
        assert!(check_fits(1_000_000, max).is_ok());
        let e = check_fits(2_000_000, max).unwrap_err().to_string();
        assert!(e.contains("2000000 triangles") && e.contains("MiB"), "{e}");
    }
}
