//! Benchmark of the mesh path: a ~1M-triangle drape, written as an OBJ and read back as
//! `--mesh FILE.obj` reads it, at 1920×1080 (ptm11 with its MIP chain,
//! normal map, sheen, one light), without and with its macro shadow (2048² depth map), against
//! the plane preview of the same PTM at the same size on the same adapter. Prints the GPU
//! buffers' memory, the process's peak resident memory (on lavapipe the GPU's memory is the
//! process's), the setup times (tangents, upload) and the frame time of each as the median
//! after a warm-up, and their ratios. Run: `cargo run --release --workspace --features
//! ptm-runtime/window --example bench_mesh` (`-- --quick`: 3 frames instead of 7; `-- --detail
//! N`: the drape's N² quads, default 708 → 1.0M triangles; `-- --shadow-size S`, default 2048).
//!
//! On lavapipe the "GPU" is the CPU: the ratio, not the absolute time, is what carries over.

use std::time::Instant;

use ptm_format::Basis;
use ptm_runtime::gpu::Renderer;
use ptm_runtime::mesh::{shadow_bytes, vertex_bytes, Mesh, MeshScene, DEFAULT_SHADOW_SIZE};
use ptm_runtime::scene::Perspective;
use ptm_runtime::{Gpu, Light, Scene};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Resident memory of this process now (`VmRSS`) or at its peak (`VmHWM`), Linux, MiB.
fn rss_mib(key: &str) -> String {
    let kb = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let line = s.lines().find(|l| l.starts_with(key))?;
            line.split_whitespace().nth(1)?.parse::<f64>().ok()
        });
    kb.map_or("unknown".into(), |kb| format!("{:.0} MiB", kb / 1024.0))
}

/// Writes `mesh` as an OBJ with its corners' positions and UVs shared where they are equal
/// (as an exporter writes a welded mesh); returns the bytes written.
fn write_obj(mesh: &Mesh, path: &std::path::Path) -> u64 {
    use std::collections::HashMap;
    use std::fmt::Write as _;
    let (mut v, mut vt) = (HashMap::new(), HashMap::new());
    let (mut vs, mut vts, mut faces) = (String::new(), String::new(), String::new());
    for tri in mesh.corners.chunks_exact(3) {
        faces.push('f');
        for c in tri {
            let nv = v.len() + 1;
            let i = *v.entry(c.position.map(f32::to_bits)).or_insert_with(|| {
                let [x, y, z] = c.position;
                writeln!(vs, "v {x} {y} {z}").unwrap();
                nv
            });
            let nt = vt.len() + 1;
            let j = *vt.entry(c.uv.map(f32::to_bits)).or_insert_with(|| {
                writeln!(vts, "vt {} {}", c.uv[0], c.uv[1]).unwrap();
                nt
            });
            write!(faces, " {i}/{j}").unwrap();
        }
        faces.push('\n');
    }
    let text = format!("# the built-in drape\n{vs}{vts}{faces}");
    std::fs::write(path, &text).unwrap();
    text.len() as u64
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
    let shadow_size: u32 = args
        .iter()
        .position(|a| a == "--shadow-size")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_SHADOW_SIZE);
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
        rect_angle_deg: 0.0,
        gaussian: None,
        distant: false,
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

    // The drape as a user's OBJ (shared `v` and `vt`, `f v/vt`), read back the way
    // `ptm preview --mesh FILE.obj` reads it.
    let t = Instant::now();
    let obj = std::env::temp_dir().join(format!("ptm-bench-mesh-{}.obj", std::process::id()));
    let obj_bytes = write_obj(&Mesh::drape(detail), &obj);
    let build_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mesh = Mesh::from_obj(&obj, ptm_runtime::mesh::UvProjection::None).unwrap();
    let read_s = t.elapsed().as_secs_f64();
    let read_peak = rss_mib("VmHWM:");
    std::fs::remove_file(&obj).unwrap();
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
    let (mut mp, report) = ms.prepare().unwrap();
    let prepare_s = t.elapsed().as_secs_f64();
    let prepared_peak = rss_mib("VmHWM:");
    let t = Instant::now();
    let r = Renderer::new(&gpu, &mp).unwrap();
    let upload_s = t.elapsed().as_secs_f64();
    let mesh_s = frame_median(&r, frames);
    drop(r);
    // The same buffers with the macro shadow switched on (the frame's shadow fields from a
    // prepare without vertices: no second MikkTSpace pass).
    ms.shadow_size = shadow_size;
    let shadowed = ms.prepare_frame().unwrap();
    mp.frame = shadowed.frame;
    mp.variant = shadowed.variant;
    let r = Renderer::new(&gpu, &mp).unwrap();
    let shadow_s = frame_median(&r, frames);
    let rendering = rss_mib("VmRSS:");
    let bytes = vertex_bytes(triangles);
    let shadow = shadow_bytes(shadow_size, 1);
    let mib = |b: u64| b as f64 / 1048576.0;
    println!(
        "mesh: drape {detail}² quads = {triangles} triangles, {} tangent fallbacks",
        report.fallback_triangles
    );
    println!(
        "GPU memory: vertex buffer {:.1} MiB ({} B per corner × 3 per triangle) + depth {:.1} MiB \
         + target {:.1} MiB + shadow map {:.1} MiB ({shadow_size}² × 4 B per light) = \
         {:.1} MiB; resident memory of the process (lavapipe: GPU included) {rendering} while \
         rendering, {prepared_peak} at its peak up to the end of preparing, {} at the end",
        mib(bytes),
        std::mem::size_of::<ptm_runtime::layout::MeshVertex>(),
        mib(size[0] as u64 * size[1] as u64 * 4),
        mib(size[0] as u64 * size[1] as u64 * 16),
        mib(shadow),
        mib(bytes + shadow + size[0] as u64 * size[1] as u64 * 20),
        rss_mib("VmHWM:")
    );
    println!(
        "setup: drape written as a {:.0} MB OBJ {build_s:.2} s, read back {read_s:.2} s (peak \
         resident memory then {read_peak}), prepare (MikkTSpace tangents, vertices) \
         {prepare_s:.2} s, pipeline + upload {upload_s:.2} s",
        obj_bytes as f64 / 1e6
    );
    println!(
        "frame at {}×{}: plane preview {:.1} ms, mesh {:.1} ms (ratio {:.2}), mesh with its \
         macro shadow {:.1} ms (ratio {:.2})",
        size[0],
        size[1],
        plane_s * 1e3,
        mesh_s * 1e3,
        mesh_s / plane_s,
        shadow_s * 1e3,
        shadow_s / plane_s
    );
}
