//! Benchmark: the same bake on the CPU (Embree, `ptm_bake::bake_planes`) and on the GPU (wgpu
//! ray queries, `ptm_gpubake::bake_planes`), in one process, on the same scene, dome and sample
//! positions, and a bare loop over the same ray queries on the same device and TLASes.
//!
//! The bare loop is the device's limit for these rays: one invocation per ray, origins on a
//! jittered grid over the tile at mid-height of the swatch, towards each light, `t_far` at the
//! clamp plane, a hit counter and nothing else (no sample loads, facing test or per-texel sums).
//!
//! Prints per run the wall seconds of each bake's shadow pass and its shadow rays per second,
//! then medians: GPU / CPU (the speed-up an artist sees) and GPU bake / bare loop (what the
//! bake's bookkeeping costs), naming the adapter, and the two bakes' agreement (mean and max
//! |ΔK|). On lavapipe the "GPU" runs on the same cores as Embree: this checks correctness and
//! overheads, not GPU speed.
//!
//! `cargo run --release -p ptm-gpubake --example bench_gpubake -- [SWATCH RES LIGHTS SPP MIN_ELEV REPEATS]`
use std::time::Instant;

use ptm_bake::{dome, tiling, BakeConfig, Frame, PreparedMesh};
use ptm_gpubake::adapter::Gpu;
use ptm_gpubake::scene::Scene;
use ptm_gpubake::{Asked, GpuConfig};
use wgpu::util::DeviceExt;

const BARE: &str = r#"
enable wgpu_ray_query;
struct Params { dir: vec3<f32>, z0: f32, tile: vec2<f32>, side: u32, z_cap: f32 }
@group(0) @binding(0) var acc: acceleration_structure;
@group(0) @binding(1) var<uniform> p: Params;
@group(0) @binding(2) var<storage, read_write> hits: array<atomic<u32>>;
@compute @workgroup_size(64)
fn bare(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) g: vec3<u32>) {
    let i = id.x + id.y * g.x * 64u;
    if i >= p.side * p.side { return; }
    // A jittered grid over the tile (a cheap integer hash for the jitter).
    var h = i * 747796405u + 2891336453u;
    h = ((h >> ((h >> 28u) + 4u)) ^ h) * 277803737u;
    let jx = f32(h & 0xffffu) / 65536.0;
    let jy = f32(h >> 16u) / 65536.0;
    let x = (f32(i % p.side) + jx) / f32(p.side) * p.tile.x;
    let y = (f32(i / p.side) + jy) / f32(p.side) * p.tile.y;
    let org = vec3<f32>(x, y, p.z0);
    var rq: ray_query;
    rayQueryInitialize(&rq, acc, RayDesc(RAY_FLAG_TERMINATE_ON_FIRST_HIT, 0xFFu, 0.0, (p.z_cap - p.z0) / p.dir.z, org, p.dir));
    while rayQueryProceed(&rq) {}
    if rayQueryGetCommittedIntersection(&rq).kind != RAY_QUERY_INTERSECTION_NONE {
        atomicAdd(&hits[0], 1u);
    }
}
"#;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dir: [f32; 3],
    z0: f32,
    tile: [f32; 2],
    side: u32,
    z_cap: f32,
}

/// The bare loop: `side²` rays per light over `lights`, on the same TLASes; (seconds, rays).
fn bare(
    adapter: &wgpu::Adapter,
    swatch: &PreparedMesh,
    lights: &ptm_format::LightSet,
    side: u32,
) -> Result<(f64, u64), Box<dyn std::error::Error>> {
    let gpu = Gpu::open(adapter)?;
    let frame = Frame::new(swatch);
    let mesh = &*frame.swatch;
    let mut scene = Scene::new(&gpu, &mesh.positions, &mesh.triangles, mesh.tile)?;
    let copies: Vec<Vec<[i32; 2]>> = lights
        .dirs
        .iter()
        .map(|&l| tiling::copies_for_direction(mesh.tile, &mesh.bounds, l, frame.margin))
        .collect();
    for c in &copies {
        scene.prepare(&gpu, c)?;
    }
    gpu.wait("building TLASes")?;
    let d = &gpu.device;
    let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("bare"),
        source: wgpu::ShaderSource::Wgsl(BARE.into()),
    });
    let pipeline = d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("bare"),
        layout: None,
        module: &module,
        entry_point: Some("bare"),
        compilation_options: Default::default(),
        cache: None,
    });
    let hits = d.create_buffer(&wgpu::BufferDescriptor {
        label: Some("hits"),
        size: 4,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let n = side * side;
    let g = n.div_ceil(64);
    let (gx, gy) = (g.min(65_535), g.div_ceil(g.min(65_535)));
    let b = &mesh.bounds;
    let binds: Vec<wgpu::BindGroup> = lights
        .dirs
        .iter()
        .zip(&copies)
        .map(|(l, c)| {
            let params = Params {
                dir: l.map(|c| c as f32),
                z0: ((b.min[2] + b.max[2]) / 2.0) as f32,
                tile: mesh.tile.map(|c| c as f32),
                side,
                z_cap: frame.z_cap as f32,
            };
            let u = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("bare"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: scene.tlas(c).as_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: u.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: hits.as_entire_binding(),
                    },
                ],
            })
        })
        .collect();
    let t0 = Instant::now();
    let mut enc = d.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        for bind in &binds {
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
    }
    gpu.queue.submit([enc.finish()]);
    let _: Vec<u32> = gpu.read(&hits, 4, "bare loop")?;
    Ok((t0.elapsed().as_secs_f64(), n as u64 * lights.len() as u64))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| args.get(i).map_or(d.to_string(), |s| s.to_string());
    let spec = arg(0, "builtin:plain-weave");
    let res: usize = arg(1, "128").parse()?;
    let n_lights: usize = arg(2, "32").parse()?;
    let spp: u32 = arg(3, "4").parse()?;
    let min_elev: f64 = arg(4, "10").parse()?;
    let repeats: usize = arg(5, "3").parse()?;

    let swatch = PreparedMesh::load(&spec, None)?;
    let lights = dome::fibonacci(n_lights, min_elev)?;
    let cfg = BakeConfig {
        res: [res, res],
        spp,
        seed: 0,
        light_distance: None,
        packets: true,
        threads: 0,
    };
    let choice = ptm_gpubake::choose(Asked::Gpu)?;
    let adapter = choice.adapter.expect("a GPU choice has an adapter");
    let name = choice.adapter_name.unwrap_or_default();
    println!(
        "{spec}: {} triangles, {res}² × spp {spp} × {n_lights} lights (min elevation \
         {min_elev}°); GPU: {name}",
        swatch.triangles.len()
    );
    let side = (res as u32) * (spp as f64).sqrt().ceil() as u32;
    let (mut cpu_rate, mut gpu_rate, mut bare_rate, mut ratio) = (vec![], vec![], vec![], vec![]);
    let mut agreement = (0.0f64, 0.0f64);
    for run in 0..repeats {
        let t = Instant::now();
        let (pc, _, rc) = ptm_bake::bake_planes(&swatch, &lights, &cfg)?;
        let cpu_whole = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (pg, _, rg) =
            ptm_gpubake::bake_planes(&adapter, &swatch, &lights, &cfg, &GpuConfig::default())?;
        let gpu_whole = t.elapsed().as_secs_f64();
        let (tb, nb) = bare(&adapter, &swatch, &lights, side)?;
        let c = rc.shadow_rays as f64 / rc.seconds_shadow;
        let g = rg.shadow_rays as f64 / rg.seconds_shadow;
        let b = nb as f64 / tb;
        println!(
            "run {run}: cpu {cpu_whole:.2} s (shadow {:.2} s, {:.1} Mrays/s) | gpu {gpu_whole:.2} s \
             (shadow {:.2} s, {:.1} Mrays/s) | bare {tb:.2} s ({:.1} Mrays/s)",
            rc.seconds_shadow,
            c / 1e6,
            rg.seconds_shadow,
            g / 1e6,
            b / 1e6
        );
        cpu_rate.push(c);
        gpu_rate.push(g);
        bare_rate.push(b);
        ratio.push(g / c);
        for (a, b) in pc.k.iter().zip(&pg.k) {
            let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            agreement.0 = agreement.0.max(mean);
            agreement.1 = agreement.1.max(d.iter().copied().fold(0.0, f64::max));
        }
    }
    let (c, g, b) = (median(cpu_rate), median(gpu_rate), median(bare_rate));
    println!(
        "median shadow rays/s: cpu {:.1} M, gpu {:.1} M ({name}), bare ray-query loop {:.1} M",
        c / 1e6,
        g / 1e6,
        b / 1e6
    );
    println!(
        "gpu / cpu {:.2} (median of per-run ratios {:.2}); gpu bake / bare loop {:.2}",
        g / c,
        median(ratio),
        g / b
    );
    println!(
        "agreement: worst per-light mean |ΔK| {:.5}, worst texel |ΔK| {:.4} (2/spp {:.4})",
        agreement.0,
        agreement.1,
        2.0 / spp as f64
    );
    Ok(())
}
