//! Fit throughput: texel·lights per second for the streaming accumulator and for refitting a
//! stored stack, beside a plain f32 matrix product of the same shape (matrixmultiply's sgemm,
//! terms × lights times lights × texels) in the same run.
//!
//! `cargo run --release -p ptm-fit --example bench_fit [-- RES LIGHTS]` (default 1024 256).
use std::time::Instant;

use ptm_fit::solve::{fit_stack, Accumulator, FitOptions};
use ptm_fit::{Basis, LightSet, SampleStack};

fn dome(n: usize) -> LightSet {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    LightSet::from_dirs((0..n).map(|i| {
        let z = 0.05 + 0.95 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        [r * a.cos(), r * a.sin(), z]
    }))
}

/// Best of `reps` runs, in seconds.
fn best(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::MAX, f64::min)
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let res = args.first().copied().unwrap_or(1024);
    let n = args.get(1).copied().unwrap_or(256);
    let t = res * res;
    let lights = dome(n);
    eprintln!(
        "building a {res}² × {n}-light stack ({:.2} GiB)…",
        (t * n * 4) as f64 / (1u64 << 30) as f64
    );
    // Occlusion-like data: a smooth field plus hash noise, deterministic.
    let k: Vec<Vec<f32>> = (0..n)
        .map(|l| {
            (0..t)
                .map(|i| {
                    let h = (i as u32)
                        .wrapping_mul(2654435761)
                        .wrapping_add(l as u32 * 40503);
                    ((h >> 8) & 0xffff) as f32 / 65535.0
                })
                .collect()
        })
        .collect();
    let stack = SampleStack {
        width: res,
        height: res,
        tile: [1.0, 1.0],
        lights: lights.clone(),
        k,
        coverage: vec![1.0; t],
        uv: None,
    };
    let threads = rayon::current_num_threads();
    println!("bench_fit: {res}x{res} texels x {n} lights, {threads} threads");
    for basis in Basis::ALL {
        let m = basis.len();
        let opts = FitOptions::new(basis);
        // Baseline: C (m × t) = P (m × n) · K (n × t) as one sgemm. K's rows are separate
        // planes in the stack, so the baseline gets a contiguous copy (made outside the timing).
        let p = vec![0.01f32; m * n];
        let mut kk = vec![0f32; n * t];
        for (l, plane) in stack.k.iter().enumerate() {
            kk[l * t..(l + 1) * t].copy_from_slice(plane);
        }
        let mut c = vec![0f32; m * t];
        // Parallel over the same texel blocks as the fit (each sgemm call is single-threaded).
        let t_gemm = best(3, || {
            use rayon::prelude::*;
            const COLS: usize = 4096;
            c.par_chunks_mut(m * COLS).enumerate().for_each(|(bi, cb)| {
                let j0 = bi * COLS;
                let w = cb.len() / m;
                // SAFETY: strides describe p (m × n), the K column slice (n × w, row stride t)
                // and the block of C (m × w, row stride w), all in bounds.
                unsafe {
                    matrixmultiply::sgemm(
                        m,
                        n,
                        w,
                        1.0,
                        p.as_ptr(),
                        n as isize,
                        1,
                        kk.as_ptr().add(j0),
                        t as isize,
                        1,
                        0.0,
                        cb.as_mut_ptr(),
                        w as isize,
                        1,
                    );
                }
            });
        });
        drop(kk);
        let mut stages = Vec::new();
        let t_refit = best(3, || {
            let (ptm, report) = fit_stack(&stack, &opts).unwrap();
            stages = report.seconds;
            std::hint::black_box(ptm);
        });
        let t_stream = best(1, || {
            let mut acc = Accumulator::new(&lights, res, res, &opts).unwrap();
            for (i, plane) in stack.k.iter().enumerate() {
                acc.add_light(i, plane).unwrap();
            }
            std::hint::black_box(acc.finish([1.0, 1.0]).unwrap());
        });
        let tl = (t * n) as f64;
        println!(
            "{:6} sgemm {:.3} s ({:.2e} texel*lights/s) | refit {:.3} s ({:.2e}/s, {:.2}x sgemm) | streaming {:.3} s ({:.2e}/s, {:.3} ms per light)",
            basis.name(),
            t_gemm,
            tl / t_gemm,
            t_refit,
            tl / t_refit,
            t_refit / t_gemm,
            t_stream,
            tl / t_stream,
            t_stream / n as f64 * 1e3
        );
        let stages: Vec<String> = stages
            .iter()
            .map(|(k, v)| format!("{k} {v:.3} s"))
            .collect();
        println!("       refit stages (last run): {}", stages.join(", "));
    }
}
