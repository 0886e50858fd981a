//! Fit throughput: texel·lights per second for the streaming accumulator and for refitting a
//! stored stack, beside a plain f32 matrix product of the same shape (matrixmultiply's sgemm,
//! terms × lights times lights × texels) in the same run; then the logistic link's maximum-
//! likelihood fit of the same stack (ptm6, ptm11; level 0 alone and with its MIP levels) and
//! its ratio to the identity refit.
//!
//! `cargo run --release -p ptm-fit --example bench_fit [-- RES LIGHTS]` (default 1024 256).
use std::time::Instant;

use ptm_fit::solve::{fit_stack, Accumulator, FitOptions};
use ptm_fit::SampleStack;
use ptm_format::{Basis, LightSet, Link};

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
    // Occlusion-like data, deterministic: per texel a tilted horizon (hashed height and tilt),
    // K = the fraction of 8 samples below it, so most texels step from lit to occluded.
    let hash = |i: u64| {
        let mut z = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        ((z ^ (z >> 27)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let horizon: Vec<[f64; 3]> = (0..t as u64)
        .map(|i| {
            [
                0.1 + 0.6 * hash(3 * i),
                hash(3 * i + 1) - 0.5,
                hash(3 * i + 2) - 0.5,
            ]
        })
        .collect();
    let k: Vec<Vec<f32>> = lights
        .dirs
        .iter()
        .map(|d| {
            horizon
                .iter()
                .map(|h| {
                    let s = 8.0 * (h[0] - d[2] + 0.4 * (h[1] * d[0] + h[2] * d[1])) + 4.0;
                    (s.round().clamp(0.0, 8.0) / 8.0) as f32
                })
                .collect()
        })
        .collect();
    drop(horizon);
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
    // The logistic link on the same stack, against the identity refit measured here too.
    let identity = best(3, || {
        std::hint::black_box(fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap());
    });
    for basis in Basis::ALL {
        let id = best(3, || {
            std::hint::black_box(fit_stack(&stack, &FitOptions::new(basis)).unwrap());
        });
        for mips in [false, true] {
            let opts = FitOptions {
                link: Link::Logistic,
                mips,
                ..FitOptions::new(basis)
            };
            let mut report = None;
            let lg = best(1, || {
                let (ptm, r) = fit_stack(&stack, &opts).unwrap();
                std::hint::black_box(ptm);
                report = Some(r);
            });
            let r = report.unwrap();
            let s = r.logistic.unwrap();
            println!(
                "{:6} logistic{} {:.3} s = {:.2}x the {} identity refit ({:.3} s; ptm6 identity {:.3} s) | {:.1} Newton iterations per texel (max {}), {} at the cap, {} separable, {} constant, {} kernel",
                basis.name(),
                if mips { " + MIP levels" } else { "" },
                lg,
                lg / id,
                basis.name(),
                id,
                identity,
                s.iterations_mean,
                s.iterations_max,
                s.not_converged,
                s.separable,
                s.constant,
                s.kernel
            );
        }
    }
}
