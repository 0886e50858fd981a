//! The mesh path (`ptm preview --mesh`): one model with the plane path (a flat plane mesh with
//! the identity UV map renders the plane preview's image), the GPU against its CPU twin, the
//! light direction K sees on a sphere with analytic tangents, and a golden drape.

mod common;

use common::*;
use ptm_format::{Basis, Link, Ptm, UvMap};
use ptm_runtime::mesh::{Mesh, MeshScene};
use ptm_runtime::scene::{Perspective, SceneBuffers};
use ptm_runtime::{cpu, gpu, Image, Scene};

/// The twin tolerance of the plane path (`gpu_twin.rs`): linear radiance.
const TWIN: f32 = 1e-3;

/// A perspective view down onto the plane z = 0 at 37° from the vertical.
fn plane_scene(basis: Option<Basis>) -> Scene {
    let mut s = Scene::over_ptm(
        random_ptm(basis.unwrap_or(Basis::Ptm6), 13, 9, 7),
        3,
        [64, 48],
    );
    if basis.is_none() {
        s.ptm = None;
    }
    s.lights = vec![
        light([1.2, 2.1, 2.0], 0.3, 6.0),
        light([-1.0, 0.5, 1.0], 0.0, 2.0),
        light([1.0, 1.0, -1.0], 0.2, 5.0), // below the cloth: contributes nothing
    ];
    s.perspective = Some(Perspective {
        eye: [1.5, -2.5, 3.0],
        target: [1.5, 1.5, 0.0],
        fov_y_deg: 45.0,
    });
    s
}

/// Largest difference over pixels both images cover (alpha 1), the pixels covered by one only,
/// and the pixels covered by both.
fn covered_diff(a: &Image, b: &Image) -> (f32, usize, usize) {
    let (mut worst, mut one, mut both) = (0f32, 0, 0);
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        match (p[3] > 0.5, q[3] > 0.5) {
            (true, true) => {
                both += 1;
                for c in 0..3 {
                    worst = worst.max((p[c] - q[c]).abs());
                }
            }
            (false, false) => {}
            _ => one += 1,
        }
    }
    (worst, one, both)
}

fn peak(img: &Image) -> f32 {
    img.pixels
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0f32, f32::max)
}

#[test]
fn a_flat_plane_mesh_renders_the_plane_preview() {
    for basis in [Some(Basis::Ptm6), Some(Basis::Ptm11), None] {
        let s = plane_scene(basis);
        let plane = s.prepare().unwrap();
        // Covers everything the view sees of z = 0 (the far edge of the view is at y ≈ 9.2),
        // all of it in front of the eye.
        let mesh = Mesh::plane([-10.0, -2.0, 13.0, 12.0], 24);
        let (mp, report) = MeshScene::plain(s.clone(), mesh, [1.0, 1.0])
            .prepare()
            .unwrap();
        assert_eq!(report.fallback_triangles, 0);
        assert!(mp.variant.mesh && plane.variant.ptm_mip == mp.variant.ptm_mip);
        let cpu_plane = cpu::render(&plane);
        let cpu_mesh = cpu::render(&mp);
        // Every pixel sees the cloth in both.
        assert!(cpu_mesh.pixels.iter().all(|p| p[3] == 1.0));
        let (d_cpu, _, _) = covered_diff(&cpu_plane, &cpu_mesh);
        let g = gpu();
        let (gpu_plane, _) = gpu::render(&g, &plane).unwrap();
        let (gpu_mesh, _) = gpu::render(&g, &mp).unwrap();
        let (d_gpu, one, _) = covered_diff(&gpu_plane, &gpu_mesh);
        eprintln!(
            "{:?}: plane vs plane mesh: CPU {d_cpu:.2e}, GPU {d_gpu:.2e} (peak {:.3}), {one} \
             pixels covered by one only",
            basis,
            peak(&cpu_plane)
        );
        assert!(peak(&cpu_plane) > 0.1, "too dark to test anything");
        assert_eq!(one, 0);
        assert!(
            d_cpu <= TWIN,
            "{basis:?}: CPU plane and plane mesh differ by {d_cpu}"
        );
        assert!(
            d_gpu <= TWIN,
            "{basis:?}: GPU plane and plane mesh differ by {d_gpu}"
        );
    }
}

/// A sphere under two lights with an albedo texture, a normal map, sheen and fill, seen from
/// the side and above.
fn sphere_scene(basis: Basis, normal_map: bool) -> MeshScene {
    let mut s = Scene::over_ptm(random_ptm(basis, 12, 10, 3), 1, [64, 48]);
    s.lights = vec![
        light([-1.0, -1.5, 2.0], 0.2, 5.0),
        light([1.5, 0.5, 0.8], 0.2, 2.0),
    ];
    s.albedo_texture = Some((
        5,
        4,
        (0..20)
            .map(|i| [0.2 + 0.04 * i as f32, 0.9 - 0.03 * i as f32, 0.5])
            .collect(),
    ));
    s.perspective = Some(Perspective {
        eye: [0.3, -2.2, 1.4],
        target: [0.0, 0.0, 0.5],
        fov_y_deg: 35.0,
    });
    let mut m = MeshScene::plain(s, Mesh::sphere(0.5, 32, 16), [2.0, 2.0]);
    m.sheen_color = [0.3, 0.25, 0.2];
    m.sheen_roughness = 0.4;
    m.fill = [0.1, 0.1, 0.12];
    if normal_map {
        let n: Vec<[f32; 3]> = (0..6 * 5)
            .map(|i| {
                let (x, y) = (
                    0.3 * ((i % 6) as f32 - 2.5) / 2.5,
                    0.3 * ((i / 6) as f32 - 2.0) / 2.0,
                );
                let z = (1.0 - x * x - y * y).sqrt();
                [x, y, z]
            })
            .collect();
        m.normal_map = Some((6, 5, n));
    }
    m
}

#[test]
fn gpu_matches_the_cpu_twin_on_the_mesh_path() {
    let g = gpu();
    for (basis, normal_map) in [(Basis::Ptm6, false), (Basis::Ptm11, true)] {
        let (p, _) = sphere_scene(basis, normal_map).prepare().unwrap();
        let (gi, _) = gpu::render(&g, &p).unwrap();
        let ci = cpu::render(&p);
        let (worst, one, both) = covered_diff(&gi, &ci);
        eprintln!(
            "{}: GPU vs CPU twin on the sphere: max {worst:.2e} over {both} pixels (peak {:.3}); \
             {one} silhouette pixels covered by one rasteriser only (masked)",
            p.variant.name(),
            peak(&ci)
        );
        assert!(peak(&ci) > 0.1);
        assert!(both > 500, "{both}");
        // Edge pixels: fill rules and lavapipe's 8-bit subpixel snapping.
        assert!(one <= both / 100, "{one} pixels covered differently");
        assert!(worst <= TWIN, "GPU and CPU twin differ by {worst}");
    }
}

/// A ptm6 of the identity link whose K is ½ + ½·u everywhere (u = the light's tangent
/// component): the image tells which way each pixel's tangent frame points.
fn k_of_u() -> Ptm {
    let mut planes = vec![vec![0f32]; 6];
    planes[1][0] = 0.5; // c[1]·u
    planes[5][0] = 0.5; // c[5]
    Ptm {
        basis: Basis::Ptm6,
        width: 1,
        height: 1,
        link: Link::Identity,
        uv: UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.0, 1.0],
        planes,
        learned: None,
    }
}

#[test]
fn k_on_a_sphere_sees_the_light_in_the_analytic_tangent_frame() {
    // The sphere's UVs (r·φ, r·(π − θ)) make T = east, B = north, N = outward exactly; its
    // MikkTSpace tangents must reproduce that frame.
    let r = 0.5;
    let mut s = Scene::over_ptm(k_of_u(), 1, [96, 96]);
    let lp = [-1.2, -1.6, 1.9];
    s.lights = vec![light(lp, 0.0, 4.0)];
    s.albedo = [1.0; 3];
    s.perspective = Some(Perspective {
        eye: [0.0, -2.4, 1.2],
        target: [0.0, 0.0, 0.5],
        fov_y_deg: 32.0,
    });
    let ms = MeshScene::plain(s, Mesh::sphere(r, 64, 32), [1.0, 1.0]);
    let (p, _) = ms.prepare().unwrap();
    let frags = cpu::mesh::rasterise(&p);
    let seen = cpu::mesh::tangent_light(&p, 0);
    let (gi, _) = gpu::render(&gpu(), &p).unwrap();
    let ci = cpu::render(&p);
    let (mut worst_deg, mut worst_rad, mut n) = (0f32, 0f32, 0);
    for (i, f) in frags.iter().enumerate() {
        let Some(f) = f else { continue };
        let w = f.world;
        let c = [w[0], w[1], w[2] - r];
        let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let nrm = c.map(|x| x / len);
        let rxy = (nrm[0] * nrm[0] + nrm[1] * nrm[1]).sqrt();
        if rxy < 0.3 {
            continue; // east is ill defined near the poles
        }
        // MikkTSpace does not weld across the UV seam at φ = 0: the tangents of the seam's
        // corners are half a segment off east, and so is the frame within a segment of it.
        if nrm[1].atan2(nrm[0]).abs() < 2.0 * std::f32::consts::TAU / 64.0 {
            continue;
        }
        let east = [-nrm[1] / rxy, nrm[0] / rxy, 0.0];
        let north = [
            nrm[1] * east[2] - nrm[2] * east[1],
            nrm[2] * east[0] - nrm[0] * east[2],
            nrm[0] * east[1] - nrm[1] * east[0],
        ];
        let d = [lp[0] - w[0], lp[1] - w[1], lp[2] - w[2]];
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let l = d.map(|x| x / d2.sqrt());
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let want = [dot(l, east), dot(l, north), dot(l, nrm)];
        let got = seen[i].unwrap();
        let cos = dot(want, got) / (dot(got, got).sqrt());
        let deg = cos.clamp(-1.0, 1.0).acos().to_degrees();
        if deg > 5.0 && std::env::var_os("DEBUG_MESH").is_some() {
            eprintln!("pixel {i}: world {w:?} want {want:?} got {got:?} frag {f:?}");
        }
        worst_deg = worst_deg.max(deg);
        // The image: Lambert on albedo 1 × (1 − K), K = ½ + ½ u, u the analytic tangent
        // component (the PTM clamps K to [0, 1]).
        if want[2] > 0.05 {
            let k = (0.5 + 0.5 * want[0]).clamp(0.0, 1.0);
            let expect = 4.0 * want[2] / d2 * (1.0 - k);
            for img in [&gi, &ci] {
                let px = img.pixels[i];
                if px[3] > 0.5 {
                    worst_rad = worst_rad.max((px[0] - expect).abs());
                }
            }
            n += 1;
        }
    }
    eprintln!(
        "sphere: tangent-frame light off the analytic by ≤ {worst_deg:.3}°; radiance under \
         K = ½ + ½u off the analytic by ≤ {worst_rad:.2e} over {n} pixels (GPU and CPU)"
    );
    assert!(n > 1500, "{n} pixels checked");
    assert!(worst_deg < 1.0, "tangent frame off by {worst_deg}°");
    assert!(worst_rad < 0.02, "radiance off by {worst_rad}");
}

#[test]
fn golden_drape() {
    // The built-in drape at a low tessellation under one light with sheen and fill.
    let mut s = Scene::over_ptm(random_ptm(Basis::Ptm6, 12, 10, 5), 1, [64, 48]);
    s.lights = vec![light([-2.0, -2.5, 3.0], 0.3, 16.0)];
    s.perspective = Some(Perspective {
        eye: [0.0, -4.5, 2.6],
        target: [0.0, 0.0, 0.45],
        fov_y_deg: 40.0,
    });
    let mut m = MeshScene::plain(s, Mesh::drape(40), [4.0, 4.0]);
    m.sheen_color = [0.25; 3];
    m.fill = [0.12; 3];
    let (p, report) = m.prepare().unwrap();
    assert_eq!(report.fallback_triangles, 0);
    golden::check("mesh_drape", &p);
}

mod golden {
    use super::*;
    use ptm_runtime::output::{read_rgba8, write_png_rgba8};
    use std::path::PathBuf;

    /// As `golden.rs`: 8-bit sRGB within 3 of the blessed PNG, `UPDATE_GOLDEN=1` re-blesses.
    pub fn check(name: &str, p: &SceneBuffers) {
        let (img, _) = gpu::render(&gpu(), p).unwrap();
        let actual = img.to_srgb8(0.0);
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/golden")
            .join(format!("{name}.png"));
        if std::env::var_os("UPDATE_GOLDEN").is_some() {
            write_png_rgba8(&path, img.width, img.height, &actual).unwrap();
            eprintln!("blessed {}", path.display());
            return;
        }
        let (w, h, want) = read_rgba8(&path).unwrap_or_else(|e| {
            panic!("{e}: missing golden image; run with UPDATE_GOLDEN=1 to create it")
        });
        assert_eq!((w, h), (img.width, img.height));
        let want: Vec<u8> = want.concat();
        let worst = actual
            .iter()
            .zip(&want)
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        if worst > 3 {
            let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("golden");
            std::fs::create_dir_all(&out).unwrap();
            let actual_path = out.join(format!("{name}-actual.png"));
            write_png_rgba8(&actual_path, w, h, &actual).unwrap();
            panic!(
                "{name}: differs from {} by up to {worst}/255 (tolerance 3); see {}",
                path.display(),
                actual_path.display()
            );
        }
    }
}
