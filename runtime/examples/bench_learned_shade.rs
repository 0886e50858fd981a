//! Benchmark of the learned basis's shader cost (#22: within 1.3× of logistic ptm11 at 1080p):
//! one built-in swatch baked once (RES², SPP samples per texel, 256 Fibonacci lights above 5°),
//! fitted from the same counts as logistic ptm11 and as learned11 (both logistic over the
//! hemispherical map, with MIP levels, as `ptm bake --fit` writes them), each written to a PTM
//! file and read back, then the same 1920×1080 scene rendered with each: the plane seen from
//! above (the tile magnified, level 0 only) and in perspective (minified towards the horizon:
//! trilinear in the stored levels), under 1 and 4 spherical lights and 1 and 4 distant lights
//! (the premise: the basis evaluated once per light per frame). Prints the shade time of
//! each file, its ratio learned11 / ptm11, and what K itself costs over the same scene without
//! a PTM.
//!
//! `cargo run --release -p ptm-runtime --example bench_learned_shade [-- SWATCH RES SPP FRAMES
//! RADIUS]` (default jersey 96 8 9 0.3; RADIUS the spheres' radius, 0 for point lights; the
//! example links Embree without the `ptm` binary's rpath: run the
//! built binary with `LD_LIBRARY_PATH=.deps/embree/lib` when cargo does not find it). Times are wall clock around submit + blocking wait, as in
//! `bench_runtime`: the two files' frames interleaved, the fastest and the median of FRAMES
//! after a warm-up each. On lavapipe the "GPU" is the CPU (its name is printed): the ratio, not
//! the absolute time, is what carries over.

use std::time::Instant;

use ptm_bake::{dome, BakeConfig, PreparedMesh};
use ptm_fit::{Accumulator, FitOptions};
use ptm_format::{Basis, Link, Ptm, UvMap};
use ptm_runtime::gpu::Renderer;
use ptm_runtime::scene::Perspective;
use ptm_runtime::{Gpu, Light, Scene};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The CPU's model name from /proc/cpuinfo (what lavapipe runs on), if it says.
fn cpu_name() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find_map(|l| l.strip_prefix("model name")?.split(':').nth(1))
        .map_or("unknown CPU".into(), |m| m.trim().to_string());
    let threads = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {threads} threads")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let swatch_name = args.first().map_or("jersey", String::as_str);
    let num = |i: usize, d: usize| args.get(i).map_or(d, |s| s.parse().expect("a number"));
    let (res, spp, frames) = (num(1, 96), num(2, 8) as u32, num(3, 9));
    // The spheres' radius, swatch units (0: point lights, K at their centres; else K averaged
    // over each light's footprint, `ptm_k_area`).
    let radius: f32 = args.get(4).map_or(0.3, |s| s.parse().expect("a number"));

    // --- one bake, two fits from the same counts, each through a file ---
    let t = Instant::now();
    let swatch = PreparedMesh::load(&format!("builtin:{swatch_name}"), None)?;
    let lights = dome::fibonacci(256, 5.0)?;
    let cfg = BakeConfig {
        res: [res, res],
        spp,
        seed: 1,
        light_distance: None,
        packets: true,
        threads: 0,
    };
    let (planes, coverage, _) = ptm_bake::bake_planes(&swatch, &lights, &cfg)?;
    let bake_s = t.elapsed().as_secs_f64();
    let dir = std::env::temp_dir().join(format!("bench_learned_shade_{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let mut files: Vec<Ptm> = Vec::new();
    for basis in [Basis::Ptm11, Basis::Learned(11)] {
        let opts = FitOptions {
            link: Link::Logistic,
            uv: UvMap::Hemispherical,
            mips: true,
            ..FitOptions::new(basis)
        };
        let t = Instant::now();
        let mut acc = Accumulator::new(&lights, res, res, &opts)?;
        acc.set_spp(spp)?;
        acc.set_coverage(&coverage)?;
        for (i, k) in planes.k.iter().enumerate() {
            acc.add_light(i, k)?;
        }
        let (ptm, _) = acc.finish(swatch.tile)?;
        let path = dir.join(format!("{}.ptm.exr", basis.name()));
        ptm.save(&path, &Default::default())?;
        let back = ptm_format::layout::load(&path)?;
        println!(
            "{}: fitted in {:.1} s, {} ({} bytes)",
            basis.name(),
            t.elapsed().as_secs_f64(),
            path.display(),
            std::fs::metadata(&path)?.len()
        );
        files.push(back);
    }
    std::fs::remove_dir_all(&dir)?;

    let gpu = Gpu::new()?;
    println!("adapter: {}", gpu.describe());
    println!("cpu: {}", cpu_name());
    println!(
        "swatch builtin:{swatch_name}, bake {res}² × 256 lights, spp {spp} ({bake_s:.1} s); \
         1920×1080, fastest | median of {frames} frames after a warm-up, interleaved"
    );
    println!(
        "{:<34} {:>16} {:>16} {:>16} {:>14} {:>16}",
        "scene", "no PTM ms", "ptm11 ms", "learned11 ms", "learned/ptm11", "K: learned/ptm11"
    );

    // --- the same scenes over each file ---
    let size = [1920u32, 1080];
    let light = |p: [f32; 3]| Light {
        position: p,
        radius,
        rect: None,
        square_box: false,
        rect_angle_deg: 0.0,
        gaussian: None,
        distant: false,
        intensity: 8.0,
        color: [1.0; 3],
    };
    let tile = files[0].tile;
    let (tw, th) = (tile[0] as f32, tile[1] as f32);
    let one = vec![light([1.0 * tw, 3.0 * th, 2.5 * th])];
    let four = vec![
        light([1.0 * tw, 3.0 * th, 2.5 * th]),
        light([5.0 * tw, 0.5 * th, 1.0 * th]),
        light([-2.0 * tw, 2.0 * th, 0.6 * th]),
        light([3.0 * tw, 6.0 * th, 4.0 * th]),
    ];
    // Distant lights (the sun; `Light::distant`) in about the same directions, of angular
    // radius 0.1 rad (as the spheres' about the view's centre): K's basis is evaluated once per
    // light per frame, so each pixel only dots its coefficients with it, whatever the basis.
    let sun = |elev: f32, az: f32| Light {
        position: {
            let (e, a) = (elev.to_radians(), az.to_radians());
            [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]
        },
        radius: if radius > 0.0 { 0.1 } else { 0.0 },
        distant: true,
        intensity: 1.0,
        ..Light::default()
    };
    let one_sun = vec![sun(37.0, 110.0)];
    let four_suns = vec![
        sun(37.0, 110.0),
        sun(14.0, -20.0),
        sun(8.0, 160.0),
        sun(45.0, 70.0),
    ];
    let top = None;
    let oblique = Some(Perspective {
        eye: [-tw, -th, 1.5 * th],
        target: [4.0 * tw, 4.0 * th, 0.0],
        fov_y_deg: 60.0,
    });
    let (mut worst, mut worst_distant) = (0f64, 0f64);
    for (name, lights, camera) in [
        ("top view, 1 light", &one, top),
        ("top view, 4 lights", &four, top),
        ("perspective (MIP), 1 light", &one, oblique),
        ("perspective (MIP), 4 lights", &four, oblique),
        ("top view, 1 distant light", &one_sun, top),
        ("top view, 4 distant lights", &four_suns, top),
        ("perspective (MIP), 1 distant", &one_sun, oblique),
        ("perspective (MIP), 4 distant", &four_suns, oblique),
    ] {
        let scene = |ptm: Option<&Ptm>| {
            let base = ptm.unwrap_or(&files[0]).clone();
            let mut s = Scene::over_ptm(base, 4, size);
            s.view = [0.0, 0.0, 4.0 * tw * 16.0 / 9.0, 4.0 * th];
            s.ptm = ptm.cloned();
            s.lights = lights.clone();
            s.perspective = camera;
            s
        };
        let renderers: Vec<Renderer> = [None, Some(&files[0]), Some(&files[1])]
            .into_iter()
            .map(|p| Renderer::new(&gpu, &scene(p).prepare().unwrap()).unwrap())
            .collect();
        for r in &renderers {
            r.frame()?; // warm-up (first-use JIT on lavapipe)
        }
        let mut times = vec![Vec::new(); renderers.len()];
        for _ in 0..frames {
            for (r, t) in renderers.iter().zip(&mut times) {
                t.push(r.frame()?);
            }
        }
        let fastest: Vec<f64> = times
            .iter()
            .map(|t| t.iter().copied().fold(f64::INFINITY, f64::min))
            .collect();
        let medians: Vec<f64> = times.into_iter().map(median).collect();
        let ratio = fastest[2] / fastest[1];
        let k_ratio = (fastest[2] - fastest[0]) / (fastest[1] - fastest[0]);
        match lights[0].distant {
            true => worst_distant = worst_distant.max(ratio),
            false => worst = worst.max(ratio),
        }
        let ms = |i: usize| format!("{:.1} | {:.1}", 1e3 * fastest[i], 1e3 * medians[i]);
        println!(
            "{name:<34} {:>16} {:>16} {:>16} {:>14.2} {:>16.2}",
            ms(0),
            ms(1),
            ms(2),
            ratio,
            k_ratio
        );
    }
    println!(
        "learned11 / logistic ptm11 shade time (fastest frames): at most {worst:.2} under local \
         lights, {worst_distant:.2} under distant lights (target ≤ 1.3)"
    );
    Ok(())
}
