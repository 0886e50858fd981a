//! Benchmark: the baker against a bare Embree loop, in one process, on the same scene, dome and
//! sample positions. The bare loop is what the issue describes: one `rtcIntersect1` per
//! footprint sample, then per light one coherent packet per `W` consecutive samples of an image
//! row (16: 4 texels at spp 4), every covered sample traced (no facing test), `tfar` = ∞,
//! rayon over rows, FTZ/DAZ on.
//! It traces against the baker's per-light scenes of copies of the tile as instances (the
//! scenes `Baker::trace` builds where centred ones do not pay: the same hits), built once
//! and untimed, and keeps its samples as structures of arrays, ready for packets: no
//! bookkeeping.
//!
//! Loops (`--loops=a,b,…`, each run alternates their order; default `ours,bare,bare16`):
//! - `ours`: `Baker::new` + `Baker::trace` at the CPU's native packet width; wall time from
//!   the device and scene builds to the last K plane (the bare loops reuse those scenes free),
//!   its sink counts the occluded samples for the check in the first run only (on the calling
//!   thread while the pool traces the next pass, so its time cannot be taken out; printed), and
//!   takes the planes without reading them in the others, like the bare loops.
//! - `oursN` (N = 1, 4, 8, 16): the baker with N lanes per Embree call.
//! - `ours-BUILD` (or `oursN-BUILD`), BUILD `avx512f`, `avx2` or `portable`: the baker with that
//!   build of its facing test and compaction instead of the widest this CPU has
//!   (`Baker::set_simd`).
//! - `ours…@centred`, `ours…@instances`: the baker with its shadow scenes' central copy as
//!   triangles, or as an instance like every other copy, whatever `centred_pays` says
//!   (`Baker::set_centred_scenes`).
//! - `bare`: the bare loop at the native packet width; `bare16` / `bare8` / `bare4`: at that
//!   width (`bare16` is the C loop: `rtcOccluded16`, one by one inside Embree on a CPU
//!   without AVX-512); `bareclip`: native width with `tfar` at the baker's clamp plane;
//!   `barefair`: that, and no ray for samples facing away (n·l ≤ 0): the baker's rays.
//!
//! Prints per run and loop the wall and CPU seconds of the primary and shadow passes and the
//! shadow rays per second (rays actually traced), then medians over the runs of each ratio
//! against the first bare loop, taken within each run (min–max), and the load average.
//!
//! `--embree=CONFIG` gives every loop's Embree device that config as well: `--embree=isa=avx2`
//! runs Embree's AVX2 kernels (8-ray packets) on a CPU with AVX-512, the code an AVX2-only CPU
//! runs (with `ours-avx2` for the baker's own part).
//!
//! `cargo run --release -p ptm-bake --example bench_bake -- [SWATCH RES LIGHTS SPP MIN_ELEV REPEATS] [--loops=…] [--threads=N] [--embree=CONFIG]`
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use ptm_bake::embree::{self, Packet, Scene, Valid};
use ptm_bake::{dome, sample_xy, BakeConfig, Baker, PreparedMesh};
use rayon::prelude::*;

/// One loop's figures in one run.
#[derive(Clone, Copy, Default)]
struct Timing {
    /// Wall seconds: whole bake, primary pass, shadow pass.
    whole: f64,
    primary: f64,
    shadow: f64,
    /// Process CPU seconds of the shadow pass (all threads).
    cpu_shadow: f64,
    /// Seconds the baker's sink spent counting occluded samples (the benchmark's own check, in
    /// the first run only, on the calling thread while the pool traces the next pass),
    /// included in `whole`, `shadow` and `cpu_shadow`.
    sink: f64,
    /// Shadow rays traced, occluded among them, and samples counted occluded in all.
    traced: u64,
    occluded: u64,
    counted: u64,
    /// The baker's scenes of copies built with the central copy as triangles.
    centred: usize,
}

impl Timing {
    fn rays_per_s(&self) -> f64 {
        self.traced as f64 / self.shadow
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let all: Vec<String> = std::env::args().skip(1).collect();
    let (flags, args): (Vec<&String>, Vec<&String>) = all.iter().partition(|a| a.starts_with("--"));
    let flag = |name: &str| {
        flags
            .iter()
            .find_map(|f| f.strip_prefix(&format!("--{name}=")).map(str::to_string))
    };
    let arg = |i: usize, d: &str| args.get(i).map_or(d.to_string(), |s| s.to_string());
    let spec = arg(0, "builtin:plain-weave?segments=32&along=96");
    let res: usize = arg(1, "256").parse()?;
    let n_lights: usize = arg(2, "64").parse()?;
    let spp: usize = arg(3, "4").parse()?;
    let min_elev: f64 = arg(4, "10").parse()?;
    let repeats: usize = arg(5, "5").parse()?;
    let loops: Vec<String> = flag("loops")
        .unwrap_or_else(|| "ours,bare,bare16".into())
        .split(',')
        .map(str::to_string)
        .collect();
    let threads: usize = flag("threads").map_or(Ok(0), |t| t.parse())?;

    let swatch = PreparedMesh::load(&spec, None)?;
    let lights = dome::fibonacci(n_lights, min_elev)?;
    let cfg = BakeConfig {
        res: [res, res],
        spp: spp as u32,
        seed: 0,
        light_distance: None,
        packets: true,
        threads,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(|_| embree::set_ftz_daz())
        .build()?;
    let embree_config = flag("embree").unwrap_or_default();
    // The bare loops' scenes: the baker's per-light scenes of copies, built once, untimed.
    let mut scenes_owner = Baker::with_embree_config(&swatch, &cfg, &embree_config)?;
    for &l in &lights.dirs {
        scenes_owner.prepare_direction(l)?;
    }
    let native = scenes_owner.packet_width();
    println!(
        "cpu: {}; {} threads; Embree native packet width {native}{}; facing test {}",
        cpu_name(),
        pool.current_num_threads(),
        if embree_config.is_empty() {
            String::new()
        } else {
            format!(" (Embree device config {embree_config:?})")
        },
        scenes_owner.simd()
    );
    println!(
        "scene: {spec}: {} triangles, tile {:?}, {res}² texels, {n_lights} Fibonacci lights above {min_elev}°, spp {spp}; loops {}",
        swatch.triangles.len(),
        swatch.tile,
        loops.join(", ")
    );
    let scenes: Vec<&Scene> = lights
        .dirs
        .iter()
        .map(|&l| scenes_owner.direction_scene(l).expect("prepared"))
        .collect();
    let bare = Bare {
        baker: &scenes_owner,
        scenes: &scenes,
        dirs: &lights.dirs,
        res,
        spp,
        pool: &pool,
    };

    let mut runs: Vec<Vec<Timing>> = Vec::new();
    let load0 = loadavg();
    for rep in 0..repeats {
        let mut row = vec![Timing::default(); loops.len()];
        // Rotate the order, so that no loop profits from a warmer cache or a quieter machine
        // by its position.
        for k in 0..loops.len() {
            let i = (k + rep) % loops.len();
            let (name, scenes) = loops[i].split_once('@').unwrap_or((&loops[i], "auto"));
            row[i] = if let Some(w) = name.strip_prefix("ours") {
                let (w, simd) = match w.split_once('-') {
                    Some((w, build)) => (w, build),
                    None => (w, "auto"),
                };
                let width = if w.is_empty() { None } else { Some(w.parse()?) };
                let centred = match scenes {
                    "auto" => None,
                    "centred" => Some(true),
                    "instances" => Some(false),
                    s => return Err(format!("{s}: @centred or @instances").into()),
                };
                let check = rep == 0;
                let variant = Variant {
                    width,
                    simd,
                    centred,
                };
                ours(&swatch, &lights, &cfg, &embree_config, &variant, check)?
            } else if let Some(w) = name.strip_prefix("bare") {
                match w {
                    "" => bare.run(native, false, false),
                    "clip" => bare.run(native, true, false),
                    "fair" => bare.run(native, true, true),
                    w => bare.run(w.parse()?, false, false),
                }
            } else {
                return Err(format!("unknown loop {name}").into());
            };
        }
        print!("run {rep}:");
        for (name, t) in loops.iter().zip(&row) {
            print!(
                " | {name} {:.3} s (primary {:.3}, shadow {:.3} s, {:.2} cpu-s) {:.2} Mrays/s",
                t.whole,
                t.primary,
                t.shadow,
                t.cpu_shadow,
                t.rays_per_s() / 1e6
            );
            if t.sink > 0.0 {
                print!(" (sink's count {:.3} s, concurrent)", t.sink);
            }
            if t.centred > 0 {
                print!(" ({} scenes centred)", t.centred);
            }
        }
        println!();
        runs.push(row);
    }
    let load1 = loadavg();
    let first = &runs[0];
    println!("rays traced per loop (occluded among them; samples counted occluded in all):");
    for (name, t) in loops.iter().zip(first) {
        println!("  {name}: {} ({}; {})", t.traced, t.occluded, t.counted);
    }
    let base = loops
        .iter()
        .position(|l| l.starts_with("bare"))
        .unwrap_or(0);
    let median = |mut v: Vec<f64>| -> (f64, f64, f64) {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[0], v[v.len() - 1])
    };
    println!(
        "medians of {repeats} runs (min–max); ratios against {} within each run:",
        loops[base]
    );
    for (i, name) in loops.iter().enumerate() {
        let rate = median(runs.iter().map(|r| r[i].rays_per_s() / 1e6).collect());
        let whole = median(runs.iter().map(|r| r[i].whole).collect());
        let r_rate = median(
            runs.iter()
                .map(|r| r[i].rays_per_s() / r[base].rays_per_s())
                .collect(),
        );
        let r_cpu = median(
            runs.iter()
                .map(|r| {
                    (r[i].traced as f64 / r[i].cpu_shadow)
                        / (r[base].traced as f64 / r[base].cpu_shadow)
                })
                .collect(),
        );
        let r_whole = median(runs.iter().map(|r| r[i].whole / r[base].whole).collect());
        println!(
            "  {name}: {:.2} Mrays/s ({:.2}–{:.2}), whole {:.3} s ({:.3}–{:.3}); rays/s ratio {:.3} ({:.3}–{:.3}), per CPU-s {:.3} ({:.3}–{:.3}); whole-time ratio {:.3} ({:.3}–{:.3})",
            rate.0, rate.1, rate.2, whole.0, whole.1, whole.2, r_rate.0, r_rate.1, r_rate.2,
            r_cpu.0, r_cpu.1, r_cpu.2, r_whole.0, r_whole.1, r_whole.2
        );
    }
    println!("load average before {load0}, after {load1}");
    Ok(())
}

/// Which baker an `ours…` loop runs: lanes per call, build of the facing test, and scenes of
/// copies centred or not (`None`: the CPU's own choice, `centred_pays`).
struct Variant<'a> {
    width: Option<usize>,
    simd: &'a str,
    centred: Option<bool>,
}

/// The baker, whole: device, scenes, primary hits, then every light; with `check`, the sink
/// counts occluded samples (K × covered samples, summed per light).
fn ours(
    swatch: &PreparedMesh,
    lights: &ptm_format::LightSet,
    cfg: &BakeConfig,
    embree: &str,
    variant: &Variant,
    check: bool,
) -> Result<Timing, ptm_bake::Error> {
    let Variant {
        width,
        simd,
        centred,
    } = *variant;
    let t0 = Instant::now();
    let mut baker = Baker::with_embree_config(swatch, cfg, embree)?;
    baker.set_simd(simd)?;
    baker.set_centred_scenes(centred);
    if let Some(w) = width {
        baker.set_packet_width(w)?;
    }
    let spp = cfg.spp as f64;
    let covered: Vec<f64> = baker.coverage().iter().map(|&c| c as f64 * spp).collect();
    let mut counted = 0.0f64;
    let mut in_sink = 0.0f64;
    let cpu0 = cpu_seconds();
    let rep = baker.trace(lights, &mut |_, k, _| {
        let t = Instant::now();
        if check {
            counted += k
                .iter()
                .zip(&covered)
                .map(|(&v, &c)| v as f64 * c)
                .sum::<f64>();
        }
        in_sink += t.elapsed().as_secs_f64();
        Ok(())
    })?;

    Ok(Timing {
        whole: t0.elapsed().as_secs_f64(),
        primary: rep.seconds_primary,
        shadow: rep.seconds_shadow,
        cpu_shadow: cpu_seconds() - cpu0,
        sink: in_sink,
        centred: rep.centred_scenes,
        traced: rep.shadow_rays,
        occluded: (counted.round() as u64).saturating_sub(rep.shadow_rays_skipped),
        counted: counted.round() as u64,
    })
}

/// The bare loop's primary hits, sub-sample by sub-sample in image order (row, column, sample):
/// shadow-ray origins and unit normals as flat arrays, so that a packet of `W` consecutive
/// sub-samples is a copy of `W` floats per coordinate.
struct Hits {
    org: [Vec<f32>; 3],
    n: [Vec<f32>; 3],
    hit: Vec<bool>,
}

struct Bare<'a> {
    baker: &'a Baker,
    scenes: &'a [&'a Scene],
    dirs: &'a [[f64; 3]],
    res: usize,
    spp: usize,
    pool: &'a rayon::ThreadPool,
}

impl Bare<'_> {
    fn run(&self, width: usize, clip: bool, facing: bool) -> Timing {
        match width {
            16 => self.run_w::<16>(clip, facing),
            8 => self.run_w::<8>(clip, facing),
            4 => self.run_w::<4>(clip, facing),
            w => panic!("bare loop of width {w}: 4, 8 or 16"),
        }
    }

    /// The primary pass: per sub-sample the hit point moved off the surface along the normal
    /// face-forwarded to the camera (the baker's arithmetic, so the rays are the same).
    fn primary(&self) -> Hits {
        let (res, spp) = (self.res, self.spp);
        let tile = self.baker.tile();
        let (z_top, eps) = (self.baker.z_cap() as f32, self.baker.ray_offset());
        let scene = self.baker.primary_scene();
        let n = res * res * spp;
        let mut rows: Vec<([Vec<f32>; 6], Vec<bool>)> = Vec::new();
        self.pool.install(|| {
            rows = (0..res)
                .into_par_iter()
                .map(|j| {
                    let mut c: [Vec<f32>; 6] = Default::default();
                    let mut hit = Vec::with_capacity(res * spp);
                    for i in 0..res {
                        for s in 0..spp {
                            let [x, y] = sample_xy([res, res], tile, spp, 0, [i, j], s);
                            let org = [x as f32, y as f32, z_top];
                            let h = scene.intersect1(org, [0.0, 0.0, -1.0], 0.0, f32::INFINITY);
                            let len = h.map_or(0.0, |h| {
                                h.ng.iter()
                                    .map(|&c| c as f64 * c as f64)
                                    .sum::<f64>()
                                    .sqrt()
                            });
                            let (p, n) = match h {
                                Some(h) if len > 0.0 => {
                                    let sign = if h.ng[2] < 0.0 { -1.0 } else { 1.0 } / len;
                                    let n = h.ng.map(|c| c as f64 * sign);
                                    ([x, y, z_top as f64 - h.t as f64], n)
                                }
                                _ => ([0.0; 3], [0.0; 3]),
                            };
                            for a in 0..3 {
                                c[a].push((p[a] + eps * n[a]) as f32);
                                c[3 + a].push(n[a] as f32);
                            }
                            hit.push(h.is_some() && len > 0.0);
                        }
                    }
                    (c, hit)
                })
                .collect()
        });
        let mut hits = Hits {
            org: Default::default(),
            n: Default::default(),
            hit: Vec::with_capacity(n),
        };
        for (c, hit) in rows {
            for a in 0..3 {
                hits.org[a].extend_from_slice(&c[a]);
                hits.n[a].extend_from_slice(&c[3 + a]);
            }
            hits.hit.extend_from_slice(&hit);
        }
        hits
    }

    /// Every light: one coherent packet per `W` consecutive sub-samples (the C loop:
    /// 16 sub-samples, that is 4 texels × spp 4), rayon over image rows.
    fn run_w<const W: usize>(&self, clip: bool, facing: bool) -> Timing {
        let (res, spp) = (self.res, self.spp);
        let z_top = self.baker.z_cap() as f32;
        let t0 = Instant::now();
        let hits = self.primary();
        let t_primary = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let cpu0 = cpu_seconds();
        let (occluded, traced) = (AtomicU64::new(0), AtomicU64::new(0));
        let row = res * spp;
        for (l, scene) in self.dirs.iter().zip(self.scenes) {
            let l = l.map(|c| c as f32);
            self.pool.install(|| {
                (0..res).into_par_iter().for_each(|j| {
                    let (mut occ, mut n) = (0u64, 0u64);
                    let mut rays = Packet::<W>::default();
                    let mut valid = Valid::<W>::default();
                    rays.dir_x = [l[0]; W];
                    rays.dir_y = [l[1]; W];
                    rays.dir_z = [l[2]; W];
                    for k in (j * row..(j + 1) * row).step_by(W) {
                        let m = W.min((j + 1) * row - k);
                        let mut any = false;
                        for i in 0..W {
                            let on = i < m
                                && hits.hit[k + i]
                                && (!facing
                                    || l[0] * hits.n[0][k + i]
                                        + l[1] * hits.n[1][k + i]
                                        + l[2] * hits.n[2][k + i]
                                        > 0.0);
                            valid.0[i] = -(on as i32);
                            any |= on;
                        }
                        if !any {
                            continue;
                        }
                        rays.org_x[..m].copy_from_slice(&hits.org[0][k..k + m]);
                        rays.org_y[..m].copy_from_slice(&hits.org[1][k..k + m]);
                        rays.org_z[..m].copy_from_slice(&hits.org[2][k..k + m]);
                        for i in 0..W {
                            rays.tfar[i] = if clip {
                                (z_top - rays.org_z[i]) / l[2]
                            } else {
                                f32::INFINITY
                            };
                        }
                        scene.occluded_packet(&valid, &mut rays);
                        for i in 0..W {
                            let on = valid.0[i] != 0;
                            occ += (on && rays.occluded(i)) as u64;
                            n += on as u64;
                        }
                    }
                    occluded.fetch_add(occ, Ordering::Relaxed);
                    traced.fetch_add(n, Ordering::Relaxed);
                })
            });
        }
        let shadow = t1.elapsed().as_secs_f64();
        let occluded = occluded.load(Ordering::Relaxed);
        Timing {
            whole: t_primary + shadow,
            primary: t_primary,
            shadow,
            cpu_shadow: cpu_seconds() - cpu0,
            sink: 0.0,
            centred: 0,
            traced: traced.load(Ordering::Relaxed),
            occluded,
            counted: occluded,
        }
    }
}

/// The CPU's model name and family/model, from /proc/cpuinfo.
fn cpu_name() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |k: &str| {
        info.lines()
            .find(|l| l.starts_with(k))
            .and_then(|l| l.split_once(':'))
            .map_or(String::new(), |(_, v)| v.trim().to_string())
    };
    let avx512 = field("flags").split(' ').any(|f| f == "avx512f");
    format!(
        "{} (family {} model {}), {}",
        field("model name"),
        field("cpu family"),
        field("model\t"),
        if avx512 { "AVX-512" } else { "no AVX-512" }
    )
}

/// The 1, 5 and 15 minute load averages.
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
}

/// User + system CPU seconds of this process so far, all threads (`CLOCK_PROCESS_CPUTIME_ID`).
fn cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
    }
    const CLOCK_PROCESS_CPUTIME_ID: i32 = 2;
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: clock_gettime writes one timespec (two i64 on 64-bit Linux) to `ts`.
    if unsafe { clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &mut ts) } != 0 {
        return f64::NAN;
    }
    ts.sec as f64 + ts.nsec as f64 * 1e-9
}
