//! Benchmark of the mesh path: a ~1M-triangle drape at 1920×1080 (ptm11 with its MIP chain,
//! normal map, sheen, one light) against the plane preview of the same PTM at the same size on
//! the same adapter. Prints the vertex buffer's memory, the setup times (tangents, upload) and
//! the frame time of each as the median after a warm-up, and their ratio. Run: `cargo run
//! --release -p ptm-runtime --example bench_mesh` (`-- --quick`: 3 frames instead of 7;
//! `-- --detail N`: the drape's N² quads, default 708 → 1.0M triangles).
//!
//! On lavapipe the "GPU" is the CPU: the ratio, not the absolute time, is what carries over.

use std::time::Instant;

use ptm_format::Basis;
use ptm_runtime::gpu::Renderer;
use ptm_runtime::mesh::{vertex_bytes, Mesh, MeshScene};
use ptm_runtime::scene::Perspective;
use ptm_runtime::{Gpu, Light, Scene};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn frame_median(r: &Renderer, frames: usize) -> f64 {
    r.frame().unwrap(); // warm-up (first-use JIT on lavapipe)
    median((0..frames).map(|_| r.frame().unwrap()).collect())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let detail: usize = args
        .iter()
        .position(|a| a == "--detail")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(708);
    let frames = if quick { 3 } else { 7 };
    let gpu = Gpu::new().expect("a wgpu adapter");
    println!("adapter: {}", gpu.describe());
    let size = [1920u32, 1080];
    let ptm = ptm_runtime::synthetic::random_ptm(Basis::Ptm11, 64, 64, 0);
    let light = Light {
        position: [-3.0, -4.0, 5.0],
        radius: 0.3,
        rect: None,
        square_box: false,
        intensity: 50.0,
        color: [1.0; 3],
    };

    // The plane preview: the same PTM seen in perspective at the same size.
    let mut plane = Scene::over_ptm(ptm.clone(), 8, size);
    plane.lights = vec![light];
    plane.perspective = Some(Perspective {
        eye: [4.0, -3.0, 5.0],
        target: [4.0, 4.0, 0.0],
        fov_y_deg: 45.0,
    });
    let p = plane.prepare().unwrap();
    let r = Renderer::new(&gpu, &p).unwrap();
    let plane_s = frame_median(&r, frames);
    drop(r);

    let t = Instant::now();
    let mesh = Mesh::drape(detail);
    let build_s = t.elapsed().as_secs_f64();
    let triangles = mesh.triangles();
    let mut scene = plane.clone();
    scene.perspective = Some(Perspective {
        eye: [0.0, -5.2, 3.0],
        target: [0.0, 0.0, 0.45],
        fov_y_deg: 40.0,
    });
    let mut ms = MeshScene::plain(scene, mesh, [8.0, 8.0]);
    ms.sheen_color = [0.25; 3];
    ms.fill = [0.12; 3];
    ms.normal_map = Some((
        16,
        16,
        (0..256)
            .map(|i| {
                let x = 0.2 * ((i % 16) as f32 / 7.5 - 1.0);
                [x, 0.0, (1.0 - x * x).sqrt()]
            })
            .collect(),
    ));
    let t = Instant::now();
    let (mp, report) = ms.prepare().unwrap();
    let prepare_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let r = Renderer::new(&gpu, &mp).unwrap();
    let upload_s = t.elapsed().as_secs_f64();
    let mesh_s = frame_median(&r, frames);
    let bytes = vertex_bytes(triangles);
    println!(
        "mesh: drape {detail}² quads = {triangles} triangles, {} tangent fallbacks",
        report.fallback_triangles
    );
    println!(
        "memory: vertex buffer {:.1} MiB ({} B per corner × 3 per triangle) + depth {:.1} MiB + \
         target {:.1} MiB; CPU side the same vertices once more while preparing",
        bytes as f64 / 1048576.0,
        std::mem::size_of::<ptm_runtime::layout::MeshVertex>(),
        (size[0] * size[1] * 4) as f64 / 1048576.0,
        (size[0] * size[1] * 16) as f64 / 1048576.0
    );
    println!(
        "setup: mesh {build_s:.2} s, prepare (MikkTSpace tangents, vertices) {prepare_s:.2} s, \
         pipeline + upload {upload_s:.2} s"
    );
    println!(
        "frame at {}×{}: plane preview {:.1} ms, mesh {:.1} ms, ratio mesh/plane {:.2}",
        size[0],
        size[1],
        plane_s * 1e3,
        mesh_s * 1e3,
        mesh_s / plane_s
    );
}
