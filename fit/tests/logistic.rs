//! The logistic link: exact recovery of K = σ(p), every kernel build against the portable one,
//! an independent f64 Newton solve, separable / constant / one-ring texels, streaming counts
//! against the stored stack, and MIP levels against fits of the box-filtered stack.
use ptm_fit::basis::sigmoid64;
use ptm_fit::logistic::Kernel;
use ptm_fit::solve::{fit_stack, Accumulator, FitOptions};
use ptm_fit::{Basis, LightSet, Link, SampleStack, UvMap};

/// Deterministic uniform numbers in [0, 1) (splitmix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// Fibonacci hemisphere, elevations above `min_el` degrees.
fn fibonacci(n: usize, min_el: f64) -> LightSet {
    let zmin = min_el.to_radians().sin();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    LightSet::from_dirs((0..n).map(|i| {
        let z = zmin + (1.0 - zmin) * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        [r * a.cos(), r * a.sin(), z]
    }))
}

fn options(basis: Basis, uv: UvMap, lambda: f64) -> FitOptions {
    FitOptions {
        link: Link::Logistic,
        uv,
        regularize: Some(lambda),
        ..FitOptions::new(basis)
    }
}

/// Texel t has K = σ(p_t(u, v)) at every light (fractional, as from infinitely many samples).
fn sigmoid_stack(
    lights: &LightSet,
    basis: Basis,
    uv: UvMap,
    w: usize,
    h: usize,
    rng: &mut Rng,
) -> (SampleStack, Vec<Vec<f64>>) {
    let m = basis.len();
    let coeffs: Vec<Vec<f64>> = (0..w * h)
        .map(|_| (0..m).map(|_| rng.range(-1.5, 1.5)).collect())
        .collect();
    let k = lights
        .dirs
        .iter()
        .map(|d| {
            let (u, v) = uv.of_dir(*d);
            coeffs
                .iter()
                .map(|c| sigmoid64(basis.eval(c, u, v)) as f32)
                .collect()
        })
        .collect();
    let stack = SampleStack {
        width: w,
        height: h,
        tile: [1.0, 1.0],
        lights: lights.clone(),
        k,
        coverage: vec![1.0; w * h],
        uv: None,
    };
    (stack, coeffs)
}

#[test]
fn recovers_known_logistic_polynomials() {
    let mut rng = Rng(7);
    let lights = fibonacci(200, 3.0);
    for basis in Basis::ALL {
        for uv in UvMap::ALL {
            let (stack, coeffs) = sigmoid_stack(&lights, basis, uv, 9, 5, &mut rng);
            let (ptm, report) = fit_stack(&stack, &options(basis, uv, 0.0)).unwrap();
            assert_eq!((ptm.link, ptm.uv), (Link::Logistic, uv));
            let mut worst = 0f64;
            for (t, c) in coeffs.iter().enumerate() {
                for (j, &cj) in c.iter().enumerate() {
                    worst = worst.max((ptm.planes[j][t] as f64 - cj).abs());
                }
            }
            let stats = report.logistic.unwrap();
            assert!(
                worst < 1e-4,
                "{basis:?} {uv:?}: coefficient error {worst} after {} iterations (max {})",
                stats.iterations_mean,
                stats.iterations_max
            );
            assert_eq!(stats.not_converged, 0);
            assert!(
                report.rms.max < 1e-4,
                "{basis:?} {uv:?} rms {:?}",
                report.rms
            );
        }
    }
}

/// Binomial samples of a step-like K: the SIMD builds agree with the portable kernel.
#[test]
fn every_kernel_build_agrees_with_the_portable_one() {
    let mut rng = Rng(11);
    let lights = fibonacci(96, 5.0);
    let (w, h) = (37, 3);
    // Texels: a horizon at a random elevation and azimuth, 8 samples, so K ∈ {0, 1/8, …, 1}.
    let k: Vec<Vec<f32>> = {
        let texels: Vec<(f64, f64, f64)> = (0..w * h)
            .map(|_| {
                (
                    rng.range(0.1, 0.8),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                )
            })
            .collect();
        lights
            .dirs
            .iter()
            .map(|d| {
                texels
                    .iter()
                    .map(|&(z0, a, b)| {
                        let s = 8.0 * (d[2] - z0 + 0.2 * (a * d[0] + b * d[1])) + 4.0;
                        (s.round().clamp(0.0, 8.0) / 8.0) as f32
                    })
                    .collect()
            })
            .collect()
    };
    let stack = SampleStack {
        width: w,
        height: h,
        tile: [1.0, 1.0],
        lights,
        k,
        coverage: vec![1.0; w * h],
        uv: None,
    };
    for basis in Basis::ALL {
        let portable = FitOptions {
            kernel: Some(Kernel::Portable),
            holdout: 7,
            ..options(basis, UvMap::Projected, 1e-3)
        };
        let (want, wr) = fit_stack(&stack, &portable).unwrap();
        let mut ran = Vec::new();
        for kernel in [Kernel::Avx2, Kernel::Avx512] {
            if !kernel.supported() {
                eprintln!("skipped: {} kernel (this CPU lacks it)", kernel.name());
                continue;
            }
            ran.push(kernel.name());
            let (got, gr) = fit_stack(
                &stack,
                &FitOptions {
                    kernel: Some(kernel),
                    ..portable.clone()
                },
            )
            .unwrap();
            let mut worst = 0f32;
            for y in 0..h {
                for x in 0..w {
                    for (u, v) in [(0.0, 0.0), (0.7, 0.1), (-0.2, -0.9)] {
                        worst = worst.max((want.eval(x, y, u, v) - got.eval(x, y, u, v)).abs());
                    }
                }
            }
            assert!(
                worst < 1e-4,
                "{basis:?} {}: K differs by {worst}",
                kernel.name()
            );
            let (a, b) = (wr.holdout.unwrap().mean, gr.holdout.unwrap().mean);
            assert!((a - b).abs() < 1e-5, "hold-out {a} vs {b}");
        }
        eprintln!("{basis:?}: kernels compared with portable: {ran:?}");
    }
}
