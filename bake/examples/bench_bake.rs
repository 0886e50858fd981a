//! Benchmark: our bake against a minimal loop straight on Embree, in one process, on the same
//! scene and the same rays (primary `rtcIntersect1` per footprint sample, then per light the
//! same `rtcOccluded16` packets over 4×4 texel blocks, no bookkeeping). Prints both
//! throughputs and their ratio (target ≥ 0.9).
//!
//! `cargo run --release -p ptm-bake --example bench_bake [-- SWATCH RES LIGHTS SPP REPEATS]`
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use ptm_bake::embree::{self, Scene, Valid16};
use ptm_bake::{dome, sample_xy, BakeConfig, Baker, PreparedMesh};
use rayon::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    let spec = arg(0, "builtin:plain-weave?segments=48&along=144");
    let res: usize = arg(1, "256").parse()?;
    let n_lights: usize = arg(2, "64").parse()?;
    let spp: usize = arg(3, "4").parse()?;
    let repeats: usize = arg(4, "6").parse()?;

    let swatch = PreparedMesh::load(&spec, None)?;
    let lights = dome::fibonacci(n_lights, 5.0)?;
    let cfg = BakeConfig {
        res: [res, res],
        spp: spp as u32,
        seed: 0,
        light_distance: None,
        packets: true,
        threads: 0,
    };
    println!(
        "scene: {spec}: {} triangles, tile {:?}, {res}² texels, {n_lights} lights, spp {spp}, {} threads",
        swatch.triangles.len(),
        swatch.tile,
        rayon::current_num_threads()
    );

    let mut cpu_ratios = Vec::new();
    let mut best_ours = f64::INFINITY;
    let mut best_raw = f64::INFINITY;
    let mut ours_rays = 0;
    let mut raw_rays = 0;
    let mut ours_occluded = 0.0;
    let mut raw_occluded = 0;
    for rep in 0..repeats {
        // Ours: scene build excluded (the raw loop reuses our scenes), primary + shadow timed.
        let mut baker = Baker::new(&swatch, &cfg)?;
        let covered: Vec<f64> = baker
            .coverage()
            .iter()
            .map(|&c| c as f64 * spp as f64)
            .collect();
        // Raw: the same scenes, sample positions and shadow rays, straight on Embree. Runs
        // alternate which loop goes first, so neither profits from a warmer cache or a quieter
        // machine by position.
        let raw_run = |baker: &mut Baker| -> Result<(f64, f64, f64, u64, u64), ptm_bake::Error> {
            for &l in &lights.dirs {
                baker.prepare_direction(l)?;
            }
            let scenes: Vec<&Scene> = lights
                .dirs
                .iter()
                .map(|&l| baker.direction_scene(l).expect("prepared"))
                .collect();
            Ok(raw_loop(baker, &scenes, &lights.dirs, res, spp))
        };
        let raw_first = rep % 2 == 1;
        let early = if raw_first {
            Some(raw_run(&mut baker)?)
        } else {
            None
        };
        let mut sum = 0.0f64;
        let cpu0 = cpu_seconds();
        let report = baker.trace(&lights, &mut |_, k, _| {
            // Occluded samples = K × covered samples per texel (rounded once at the end).
            sum += k
                .iter()
                .zip(&covered)
                .map(|(&v, &c)| v as f64 * c)
                .sum::<f64>();
            Ok(())
        })?;
        let cpu_ours = cpu_seconds() - cpu0;
        let (t_raw, t_raw_primary, cpu_raw, rays, occluded) = match early {
            Some(r) => r,
            None => raw_run(&mut baker)?,
        };
        let skipped = report.shadow_rays_skipped;
        let t_ours = report.seconds_primary + report.seconds_shadow;
        ours_rays = report.primary_rays + report.shadow_rays;
        ours_occluded = sum.round();
        best_ours = best_ours.min(t_ours);
        raw_rays = rays;
        // Samples facing away from the light count as occluded in ours but are not traced.
        raw_occluded = occluded + skipped;
        best_raw = best_raw.min(t_raw);
        // Shadow rays per CPU second, ours over raw.
        cpu_ratios.push(
            (report.shadow_rays as f64 / cpu_ours)
                / ((raw_rays - (res * res * spp) as u64) as f64 / cpu_raw),
        );
        println!(
            "run {rep}{}: ours {:.3} s (primary {:.3} s) {:.2} Mrays/s; raw {:.3} s (primary {:.3} s) {:.2} Mrays/s",
            if raw_first { " (raw first)" } else { "" },
            t_ours,
            report.seconds_primary,
            ours_rays as f64 / t_ours / 1e6,
            t_raw,
            t_raw_primary,
            raw_rays as f64 / t_raw / 1e6
        );
    }
    let ours = ours_rays as f64 / best_ours / 1e6;
    let raw = raw_rays as f64 / best_raw / 1e6;
    println!("rays: ours {ours_rays}, raw {raw_rays} (occluded samples: raw {raw_occluded}, ours {ours_occluded:.0})");
    cpu_ratios.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!(
        "shadow pass, CPU time: ours/raw throughput ratio median {:.3} (min {:.3}, max {:.3})",
        cpu_ratios[cpu_ratios.len() / 2],
        cpu_ratios[0],
        cpu_ratios[cpu_ratios.len() - 1]
    );
    println!(
        "best of {repeats}: ours {ours:.2} Mrays/s, raw Embree {raw:.2} Mrays/s, ratio {:.3}",
        ours / raw
    );
    Ok(())
}

/// CPU seconds (user + system) this process has used, from /proc/self/stat (10 ms ticks on
/// Linux); NaN elsewhere. On a loaded machine CPU time compares the two loops' work more
/// fairly than wall time.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|v| v.parse().ok())
        .collect();
    if f.len() == 2 {
        (f[0] + f[1]) / 100.0
    } else {
        f64::NAN
    }
}

/// Minimal loop: primary `rtcIntersect1` per sample into a flat array, then per light one
/// coherent `rtcOccluded16` packet per (4×4 block, sample); returns (seconds, seconds of the
/// primary pass, CPU seconds of the shadow pass, rays, occluded).
fn raw_loop(
    baker: &Baker,
    scenes: &[&Scene],
    dirs: &[[f64; 3]],
    res: usize,
    spp: usize,
) -> (f64, f64, f64, u64, u64) {
    let pool = rayon::ThreadPoolBuilder::new()
        .start_handler(|_| embree::set_ftz_daz())
        .build()
        .unwrap();
    let tile = baker.tile();
    let (z_top, eps) = (baker.z_cap() as f32, baker.ray_offset() as f32);
    let primary = baker.primary_scene();
    let b = res / 4;
    let occluded = AtomicU64::new(0);
    let t0 = Instant::now();
    // Per (block, sample, lane): origin and normal; NaN origin marks a miss.
    let mut hits = vec![([f32::NAN; 3], [0.0f32; 3]); b * b * spp * 16];
    pool.install(|| {
        hits.par_chunks_mut(spp * 16)
            .enumerate()
            .for_each(|(blk, out)| {
                for s in 0..spp {
                    for lane in 0..16 {
                        let (i, j) = ((blk % b) * 4 + lane % 4, (blk / b) * 4 + lane / 4);
                        let [x, y] = sample_xy([res, res], tile, spp, 0, [i, j], s);
                        let (x, y) = (x as f32, y as f32);
                        if let Some(h) =
                            primary.intersect1([x, y, z_top], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
                        {
                            let len =
                                (h.ng[0] * h.ng[0] + h.ng[1] * h.ng[1] + h.ng[2] * h.ng[2]).sqrt();
                            // Face-forward towards the camera, as ours does.
                            let sign = if h.ng[2] < 0.0 { -1.0 } else { 1.0 } / len;
                            let n = h.ng.map(|c| c * sign);
                            out[s * 16 + lane] = (
                                [x + eps * n[0], y + eps * n[1], z_top - h.t + eps * n[2]],
                                n,
                            );
                        }
                    }
                }
            })
    });
    let t_primary = t0.elapsed().as_secs_f64();
    let cpu0 = cpu_seconds();
    let mut rays = (res * res * spp) as u64;
    let shadow = AtomicU64::new(0);
    for (l, scene) in dirs.iter().zip(scenes) {
        let l = l.map(|c| c as f32);
        pool.install(|| {
            hits.par_chunks(spp * 16).for_each(|blk| {
                let (mut occ, mut traced) = (0u64, 0u64);
                for s in 0..spp {
                    let mut valid = Valid16::default();
                    let mut rays = embree::empty_ray16();
                    for lane in 0..16 {
                        let (o, n) = blk[s * 16 + lane];
                        if o[0].is_nan() || n[0] * l[0] + n[1] * l[1] + n[2] * l[2] <= 0.0 {
                            continue;
                        }
                        valid.0[lane] = -1;
                        rays.org_x[lane] = o[0];
                        rays.org_y[lane] = o[1];
                        rays.org_z[lane] = o[2];
                        rays.dir_x[lane] = l[0];
                        rays.dir_y[lane] = l[1];
                        rays.dir_z[lane] = l[2];
                        rays.tfar[lane] = (z_top - o[2]) / l[2];
                    }
                    if valid.0 == [0; 16] {
                        continue;
                    }
                    scene.occluded16(&valid, &mut rays);
                    for lane in 0..16 {
                        traced += (valid.0[lane] != 0) as u64;
                        occ += Scene::lane_occluded(&rays, lane) as u64;
                    }
                }
                occluded.fetch_add(occ, Ordering::Relaxed);
                shadow.fetch_add(traced, Ordering::Relaxed);
            })
        });
    }
    rays += shadow.load(Ordering::Relaxed);
    let occluded = occluded.load(Ordering::Relaxed);
    let t = t0.elapsed().as_secs_f64();
    (t, t_primary, cpu_seconds() - cpu0, rays, occluded)
}
