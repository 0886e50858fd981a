//! The mesh path (`ptm preview --mesh`): one model with the plane path (a flat plane mesh with
//! the identity UV map renders the plane preview's image), the GPU against its CPU twin, the
//! light direction K sees on a sphere with analytic tangents, the macro shadow of a floating
//! square against its analytic umbra and lit region, near-plane clipping, and a golden drape.

mod common;

use common::*;
use ptm_format::{Basis, Link, Ptm, UvMap};
use ptm_runtime::mesh::{Corner, Mesh, MeshScene};
use ptm_runtime::scene::{Perspective, SceneBuffers};
use ptm_runtime::{cpu, gpu, Image, Light, Scene};

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
    // The third: Gaussian lights (K over their footprint, the GAUSSIAN variant); the fourth
    // a distant light (K per pixel in the tangent frame, MESH_DISTANT) beside a sphere.
    for (basis, normal_map, gaussian, distant) in [
        (Basis::Ptm6, false, false, false),
        (Basis::Ptm11, true, false, false),
        (Basis::Ptm6, false, true, false),
        (Basis::Ptm11, true, false, true),
    ] {
        let mut m = sphere_scene(basis, normal_map);
        if gaussian {
            m.scene.lights[0].gaussian = Some([0.3, 0.1]);
            m.scene.lights[1].gaussian = Some([0.05, 0.2]);
        }
        if distant {
            m.scene.lights[1] = Light {
                position: [0.6, -0.3, 0.5],
                radius: 0.08,
                distant: true,
                intensity: 0.8,
                ..Light::default()
            };
        }
        let (p, _) = m.prepare().unwrap();
        assert_eq!(p.variant.gaussian, gaussian);
        assert_eq!(p.variant.distant, distant);
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

/// A 4 × 4 floor (z = 0) and a 1 × 1 square floating at height `h` above its centre, one mesh.
fn floor_and_square(h: f32) -> Mesh {
    let mut m = Mesh::plane([-2.0, -2.0, 2.0, 2.0], 16);
    let square = Mesh::plane([-0.5, -0.5, 0.5, 0.5], 4);
    m.corners.extend(square.corners.iter().map(|c| Corner {
        position: [c.position[0], c.position[1], h],
        ..*c
    }));
    m
}

/// The floor and square under one sphere light, seen obliquely, no PTM, no fill: each floor
/// pixel's radiance is the light's Lambert term × the macro shadow's visibility.
fn floating_square_scene(shadow_size: u32) -> MeshScene {
    let mut s = Scene::over_ptm(random_ptm(Basis::Ptm6, 4, 4, 1), 1, [96, 72]);
    s.ptm = None;
    s.albedo = [1.0; 3];
    s.lights = vec![light([0.4, 0.3, 3.0], 0.3, 9.0)];
    s.perspective = Some(Perspective {
        eye: [0.5, -3.4, 3.2],
        target: [0.0, -0.1, 0.0],
        fov_y_deg: 50.0,
    });
    let mut m = MeshScene::plain(s, floor_and_square(1.0), [1.0, 1.0]);
    m.shadow_size = shadow_size;
    m
}

/// Where floor point (x, y) stands under the square's shadow: the centre of the light as seen
/// from it crosses the square's plane at q = p + s·(L − p), s = h/L_z, and the light (radius R)
/// covers a disc of radius ≈ R·s there (exact for a disc of light parallel to the floor; the
/// sphere and the light's tilt enlarge it by < 10 % here). Returns the signed distances from q
/// to the square's edges across x and y (> 0 inside) and that radius.
fn square_shadow(p: [f32; 2], l: [f32; 3], r: f32, h: f32) -> ([f32; 2], f32) {
    let s = h / l[2];
    let q = [p[0] + s * (l[0] - p[0]), p[1] + s * (l[1] - p[1])];
    ([0.5 - q[0].abs(), 0.5 - q[1].abs()], r * s)
}

/// The floor pixels of the floating-square scene sorted by where they stand in the square's
/// shadow, and each image's visibility there (its radiance over `unshadowed`'s): `shadow(floor
/// point)` gives the signed distances to the shadow's edges across x and y (> 0 inside), the
/// penumbra's half-width w and how far from an edge a pixel is clear of it. Returns the counts
/// (umbra, lit, the middle line of an edge's penumbra away from the corners) and the worst
/// visibility in the umbra, distance from 1 where lit and from ½ on the middle lines.
fn square_shadow_classes(
    frags: &[Option<cpu::mesh::MeshOut>],
    unshadowed: &Image,
    images: [&Image; 2],
    shadow: impl Fn([f32; 2]) -> ([f32; 2], f32, f32),
) -> ([usize; 3], [f32; 3]) {
    let (mut n, mut worst) = ([0usize; 3], [0f32; 3]);
    for (i, f) in frags.iter().enumerate() {
        let Some(f) = f else { continue };
        if f.world[2].abs() > 1e-4 || unshadowed.pixels[i][0] < 0.05 {
            continue; // the square itself, or a floor point the light barely reaches
        }
        let ([dx, dy], w, clear) = shadow([f.world[0], f.world[1]]);
        let class = if dx.min(dy) > clear {
            0 // umbra
        } else if dx.min(dy) < -clear {
            1 // lit
        } else if (dx.abs() < 0.1 * w && dy > clear) || (dy.abs() < 0.1 * w && dx > clear) {
            2 // the middle of the penumbra
        } else {
            continue;
        };
        let base = unshadowed.pixels[i][0];
        for img in images {
            let v = img.pixels[i][0] / base;
            let off = [v, (1.0 - v).abs(), (v - 0.5).abs()][class];
            worst[class] = worst[class].max(off);
        }
        n[class] += 1;
    }
    (n, worst)
}

#[test]
fn the_macro_shadow_of_a_floating_square_is_dark_in_its_umbra_and_lit_outside() {
    let g = gpu();
    let (lit_scene, _) = floating_square_scene(0).prepare().unwrap();
    let (p, _) = floating_square_scene(512).prepare().unwrap();
    assert!(p.variant.shadow && !lit_scene.variant.shadow);
    let frags = cpu::mesh::rasterise(&p);
    let unshadowed = cpu::render(&lit_scene);
    let ci = cpu::render(&p);
    let r = gpu::Renderer::new(&g, &p).unwrap();
    r.frame().unwrap();
    let gi = r.readback().unwrap();
    let (l, radius) = (p.lights[0].position, p.lights[0].radius);
    // Clear of the penumbra: its half-width < 1.3 w, and a margin of a few map texels.
    let ([umbra, lit, mid], [worst_umbra, worst_lit, worst_mid]) =
        square_shadow_classes(&frags, &unshadowed, [&ci, &gi], |q| {
            let (d, w) = square_shadow(q, l, radius, 1.0);
            (d, w, 1.3 * w + 0.03)
        });
    eprintln!(
        "floating square: umbra visibility ≤ {worst_umbra:.2e} over {umbra} pixels, lit region \
         off 1 by ≤ {worst_lit:.2e} over {lit}, penumbra's middle off ½ by ≤ {worst_mid:.3} over \
         {mid} (GPU and CPU)"
    );
    assert!(umbra > 100 && lit > 1000 && mid > 10, "{umbra} {lit} {mid}");
    assert!(worst_umbra < 0.01, "light in the umbra: {worst_umbra}");
    assert!(worst_lit < 1e-4, "shadow outside the penumbra: {worst_lit}");
    assert!(worst_mid < 0.15, "penumbra's middle at {worst_mid} from ½");
    twin_with_shadow(&r, &p, &gi, &ci, "floating square");
}

#[test]
fn a_gaussian_lights_macro_shadow_is_that_of_the_disc_of_its_variance() {
    // The macro shadow filters a light as a disc: a Gaussian of σx × σy as the disc of its
    // variance, radius 2·√(σx·σy). Without a PTM nothing else sees the light's shape, so σ
    // 0.1 × 0.225 renders as the 0.3 sphere does; and the GPU matches the twin.
    let g = gpu();
    let (sphere, _) = floating_square_scene(512).prepare().unwrap();
    let mut m = floating_square_scene(512);
    m.scene.lights[0].gaussian = Some([0.1, 0.225]);
    // A Gaussian's radius is unused: 0 here, so a Gaussian read as a sphere would be a point.
    m.scene.lights[0].radius = 0.0;
    let (p, _) = m.prepare().unwrap();
    assert!(p.variant.gaussian && p.variant.shadow);
    let r = gpu::Renderer::new(&g, &p).unwrap();
    r.frame().unwrap();
    let gi = r.readback().unwrap();
    let ci = cpu::render(&p);
    let d = ci.max_abs_diff(&cpu::render(&sphere)).unwrap();
    assert!(d < 1e-5, "Gaussian vs its variance's sphere: {d}");
    twin_with_shadow(&r, &p, &gi, &ci, "floating square, Gaussian light");
}

#[test]
fn a_distant_lights_macro_shadow_is_its_cones_and_matches_the_twin() {
    // The sun 60° up over the floating square (ρ 0.05): its shadow is the square moved by
    // h·cot e down the azimuth, with a penumbra of half-width ≈ sin ρ·h/sin e across each
    // edge: dark in the umbra, lit outside, about half lit on the edges' middle lines; the
    // GPU matches the twin (the orthographic shadow map and its PCSS); a far sphere subtending
    // the same cone renders nearly the same frame.
    let g = gpu();
    let (e, az, rho) = (60f32.to_radians(), 0.6f32, 0.05f32);
    let dir = [e.cos() * az.cos(), e.cos() * az.sin(), e.sin()];
    let mut m = floating_square_scene(512);
    m.scene.lights = vec![Light {
        position: dir,
        radius: rho,
        distant: true,
        intensity: 1.0,
        ..Light::default()
    }];
    let (p, _) = m.prepare().unwrap();
    assert!(p.variant.distant && p.variant.mesh && p.variant.shadow);
    let mut open = m.clone();
    open.shadow_size = 0;
    let (lit_scene, _) = open.prepare().unwrap();
    let unshadowed = cpu::render(&lit_scene);
    let frags = cpu::mesh::rasterise(&p);
    let ci = cpu::render(&p);
    let r = gpu::Renderer::new(&g, &p).unwrap();
    r.frame().unwrap();
    let gi = r.readback().unwrap();
    let h = 1.0f32;
    // The square's shadow: each floor point's ray along dir crosses the square's plane at q; the
    // cone's radius there is sin ρ·s, stretched by up to 1/sin e on the floor.
    let ([umbra, lit, mid], [worst_umbra, worst_lit, worst_mid]) =
        square_shadow_classes(&frags, &unshadowed, [&ci, &gi], |pt| {
            let s = h / dir[2];
            let q = [pt[0] + s * dir[0], pt[1] + s * dir[1]];
            let w = rho.sin() * s;
            (
                [0.5 - q[0].abs(), 0.5 - q[1].abs()],
                w,
                1.3 * w / e.sin() + 0.03,
            )
        });
    eprintln!(
        "sun over the floating square: umbra ≤ {worst_umbra:.2e} over {umbra} pixels, lit off 1 \
         by ≤ {worst_lit:.2e} over {lit}, penumbra's middle off ½ by ≤ {worst_mid:.3} over {mid}"
    );
    assert!(umbra > 100 && lit > 1000 && mid > 5, "{umbra} {lit} {mid}");
    assert!(worst_umbra < 0.01, "light in the umbra: {worst_umbra}");
    assert!(worst_lit < 1e-4, "shadow outside the penumbra: {worst_lit}");
    assert!(worst_mid < 0.15, "penumbra's middle at {worst_mid} from ½");
    twin_with_shadow(&r, &p, &gi, &ci, "floating square, distant light");
    // A sphere 1000 box diagonals away in its direction, subtending its cone: its shadow map
    // is perspective (the rays within 0.03° of parallel), so they agree but for the odd edge
    // texel, on average to 0.5 % of the peak.
    let f = &p.frame;
    let diag = (0..3)
        .map(|k| (f.shadow_hi[k] - f.shadow_lo[k]).powi(2))
        .sum::<f32>()
        .sqrt();
    let far = 1000.0 * diag;
    let mut sphere = m.clone();
    sphere.scene.lights = vec![Light {
        position: std::array::from_fn(|k| 0.5 * (f.shadow_lo[k] + f.shadow_hi[k]) + far * dir[k]),
        radius: far * rho.sin(),
        intensity: far * far,
        ..Light::default()
    }];
    let (ps, _) = sphere.prepare().unwrap();
    let d = ptm_runtime::compare::mean_abs_diff(&ci, &cpu::render(&ps));
    eprintln!("sun vs a far sphere: mean {d:.2e} (peak {:.3})", peak(&ci));
    assert!(d < 5e-3 * peak(&ci), "sun vs a far sphere: {d}");
}

/// The macro shadow on the GPU against the twin, in two parts: the depth maps (rasterised by
/// each), and the shading from the same maps (the GPU's read back into the twin).
fn twin_with_shadow(r: &gpu::Renderer, p: &SceneBuffers, gi: &Image, ci: &Image, what: &str) {
    let gpu_maps = r.read_shadow_maps().unwrap().expect("shadow maps");
    let cpu_maps = cpu::mesh::shadow_maps(p);
    assert_eq!(gpu_maps.len(), cpu_maps.depth.len());
    let differ = gpu_maps
        .iter()
        .zip(&cpu_maps.depth)
        .filter(|(a, b)| (*a - *b).abs() > 1e-5)
        .count();
    let covered = cpu_maps.depth.iter().filter(|&&z| z < 1.0).count();
    let same = cpu::mesh::ShadowMaps {
        side: cpu_maps.side,
        depth: gpu_maps,
    };
    let shaded = cpu::mesh::render_with_shadow_maps(p, Some(&same));
    let (worst_same, one, both) = covered_diff(gi, &shaded);
    let far: Vec<f32> = gi
        .pixels
        .iter()
        .zip(&ci.pixels)
        .filter(|(a, b)| a[3] > 0.5 && b[3] > 0.5)
        .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0f32, f32::max))
        .collect();
    let outliers = far.iter().filter(|&&d| d > TWIN).count();
    eprintln!(
        "{what}: shadow maps GPU vs twin: {differ} of {covered} covered texels differ by > 1e-5; \
         shading from the same maps: max {worst_same:.2e} over {both} pixels ({one} covered by \
         one only); each with its own maps: {outliers} of {} pixels differ by > {TWIN}",
        far.len()
    );
    assert!(covered > 1000, "{covered}");
    // Texels a silhouette edge passes through: fill rules and lavapipe's subpixel snapping.
    assert!(
        differ * 100 <= covered,
        "{differ} of {covered} depth texels differ"
    );
    assert!(one <= both / 100);
    assert!(
        worst_same <= TWIN,
        "{what}: GPU and twin shade the same maps {worst_same} apart"
    );
    assert!(
        outliers * 100 <= far.len(),
        "{outliers} of {} pixels",
        far.len()
    );
}

#[test]
fn a_triangle_crossing_the_near_plane_is_clipped_as_the_gpu_clips_it() {
    // A 20 × 20 floor of two triangles seen from just above it: both reach behind the eye,
    // so both cross the near plane, and the part in front must still be drawn.
    let mut s = plane_scene(Some(Basis::Ptm6));
    s.perspective = Some(Perspective {
        eye: [0.5, -1.0, 0.4],
        target: [0.5, 3.0, 0.0],
        fov_y_deg: 60.0,
    });
    let plane = s.prepare().unwrap();
    let (mp, _) = MeshScene::plain(s, Mesh::plane([-10.0, -10.0, 10.0, 10.0], 1), [1.0, 1.0])
        .prepare()
        .unwrap();
    let eye = [0.5, -1.0, 0.4];
    let behind = mp
        .mesh_vertices
        .iter()
        .filter(|v| {
            let d = [
                v.position[0] - eye[0],
                v.position[1] - eye[1],
                v.position[2] - eye[2],
            ];
            let f = mp.frame.cam_forward;
            d[0] * f[0] + d[1] * f[1] + d[2] * f[2] < mp.frame.near
        })
        .count();
    assert!(
        behind >= 2,
        "a corner of each triangle behind the near plane: {behind}"
    );
    let cpu_mesh = cpu::render(&mp);
    let (gpu_mesh, _) = gpu::render(&gpu(), &mp).unwrap();
    let cpu_plane = cpu::render(&plane);
    let (d_gpu, one, both) = covered_diff(&gpu_mesh, &cpu_mesh);
    // The plane path sees the floor beyond the mesh's far edge too: compare where the mesh is.
    let (d_plane, _, _) = covered_diff(&cpu_plane, &cpu_mesh);
    let n = cpu_mesh.pixels.len();
    eprintln!(
        "near plane: the twin covers {both} of {n} pixels as the GPU ({one} by one only); GPU vs \
         twin {d_gpu:.2e}, plane path vs twin {d_plane:.2e}"
    );
    assert!(both > n / 2, "{both} of {n}");
    assert!(one <= both / 100, "{one}");
    assert!(d_gpu <= TWIN && d_plane <= TWIN, "{d_gpu} {d_plane}");
}

#[test]
fn golden_drape() {
    // The built-in drape at a low tessellation under one light from the side (its folds shadow
    // the cloth beside them) with sheen and fill.
    let mut s = Scene::over_ptm(random_ptm(Basis::Ptm6, 12, 10, 5), 1, [96, 72]);
    s.lights = vec![light([-2.6, -0.8, 1.5], 0.3, 12.0)];
    s.perspective = Some(Perspective {
        eye: [0.0, -4.5, 2.6],
        target: [0.0, 0.0, 0.45],
        fov_y_deg: 40.0,
    });
    let mut m = MeshScene::plain(s, Mesh::drape(40), [4.0, 4.0]);
    m.sheen_color = [0.25; 3];
    m.fill = [0.12; 3];
    // The folds shadow each other and the floor-level hem under the key light.
    m.shadow_size = 256;
    let (p, report) = m.prepare().unwrap();
    assert_eq!(report.fallback_triangles, 0);
    golden::check("mesh_drape", &p);
    // The macro shadow darkens the drape and matches the twin.
    let g = gpu();
    let r = gpu::Renderer::new(&g, &p).unwrap();
    r.frame().unwrap();
    let gi = r.readback().unwrap();
    let ci = cpu::render(&p);
    let mut unshadowed = m.clone();
    unshadowed.shadow_size = 0;
    let (gu, _) = gpu::render(&g, &unshadowed.prepare().unwrap().0).unwrap();
    let darker = gi
        .pixels
        .iter()
        .zip(&gu.pixels)
        .filter(|(a, b)| a[3] > 0.5 && a[0] < b[0] - 0.01)
        .count();
    let lighter = gi
        .pixels
        .iter()
        .zip(&gu.pixels)
        .filter(|(a, b)| a[3] > 0.5 && a[0] > b[0] + 1e-5)
        .count();
    eprintln!("drape: {darker} pixels darker with the macro shadow, {lighter} lighter");
    assert!(darker > 50 && lighter == 0, "{darker} {lighter}");
    twin_with_shadow(&r, &p, &gi, &ci, "drape");
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
