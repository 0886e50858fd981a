//! The logistic link: exact recovery of K = σ(p), every kernel build against the portable one,
//! an independent f64 Newton solve, separable / constant / one-ring texels, streaming counts
//! against the stored stack, and MIP levels against fits of the box-filtered stack.
use ptm_fit::diagnostic::Solution;
use ptm_fit::simd::Isa;
use ptm_fit::solve::{fit_stack, Accumulator, FitOptions};
use ptm_fit::{Diagnostic, SampleStack};
use ptm_format::basis::sigmoid64;
use ptm_format::{Basis, LightSet, Link, UvMap};

mod common;
use common::{fibonacci, Rng};

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
    let stack = common::stack(lights, w, h, k);
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
    let stack = SampleStack::new(lights, w, h, [1.0, 1.0], k);
    for basis in Basis::ALL {
        let portable = FitOptions {
            isa: Some(Isa::Portable),
            holdout: 7,
            ..options(basis, UvMap::Projected, 1e-3)
        };
        let (want, wr) = fit_stack(&stack, &portable).unwrap();
        let mut ran = Vec::new();
        for isa in [Isa::Avx2, Isa::Avx512] {
            if !isa.supported() {
                eprintln!("skipped: {} kernel (this CPU lacks it)", isa.name());
                continue;
            }
            ran.push(isa.name());
            let (got, gr) = fit_stack(
                &stack,
                &FitOptions {
                    isa: Some(isa),
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
                isa.name()
            );
            let (a, b) = (wr.holdout.unwrap().mean, gr.holdout.unwrap().mean);
            assert!((a - b).abs() < 1e-5, "hold-out {a} vs {b}");
        }
        eprintln!("{basis:?}: kernels compared with portable: {ran:?}");
    }
}

/// Step-like K from `samples` samples: texel t is occluded below a tilted horizon.
fn step_stack(lights: &LightSet, w: usize, h: usize, samples: u32, rng: &mut Rng) -> SampleStack {
    let texels: Vec<(f64, f64, f64)> = (0..w * h)
        .map(|_| {
            (
                rng.range(0.1, 0.8),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
        })
        .collect();
    let s = samples as f64;
    let k = lights
        .dirs
        .iter()
        .map(|d| {
            texels
                .iter()
                .map(|&(z0, a, b)| {
                    let x = s * (z0 - d[2] + 0.3 * (a * d[0] + b * d[1])) * 3.0 + s / 2.0;
                    (x.round().clamp(0.0, s) / s) as f32
                })
                .collect()
        })
        .collect();
    common::stack(lights, w, h, k)
}

/// Always lit, always occluded and a clean step: the unregularised optimum is at infinity; the
/// ridge keeps the coefficients finite, and the texels are counted.
#[test]
fn separable_and_constant_texels_stay_finite_and_are_counted() {
    let lights = fibonacci(120, 5.0);
    let (w, h) = (3, 1);
    let k: Vec<Vec<f32>> = lights
        .dirs
        .iter()
        .map(|d| vec![0.0, 1.0, if d[0] > 0.1 { 1.0 } else { 0.0 }])
        .collect();
    let stack = common::stack(&lights, w, h, k);
    for basis in Basis::ALL {
        let (ptm, report) = fit_stack(&stack, &options(basis, UvMap::Projected, 1e-5)).unwrap();
        let s = report.logistic.clone().unwrap();
        assert_eq!((s.constant, s.separable), (2, 1), "{basis:?}: {s:?}");
        assert_eq!(s.not_converged, 0, "{basis:?}: {s:?}");
        let big = ptm
            .planes
            .iter()
            .flatten()
            .fold(0f32, |a, &x| a.max(x.abs()));
        assert!(big.is_finite() && big < 1e3, "{basis:?}: max |c| {big}");
        // Still the right answer: lit, occluded, and the step on the right side.
        assert!(ptm.eval(0, 0, 0.3, 0.3) < 0.01 && ptm.eval(1, 0, 0.3, 0.3) > 0.99);
        assert!(ptm.eval(2, 0, 0.6, 0.0) > 0.95 && ptm.eval(2, 0, -0.6, 0.0) < 0.05);
        // Without a ridge the same texels are diagnosed, not silently returned.
        let (_, r0) = fit_stack(&stack, &options(basis, UvMap::Projected, 0.0)).unwrap();
        assert!(
            r0.warnings
                .iter()
                .any(|w| matches!(w, Diagnostic::Separable { texels: 3 })),
            "{basis:?}: {:?}",
            r0.warnings
        );
    }
}

/// A one-ring dome is rank-deficient for the logistic link exactly as for the identity link:
/// the same named direction, finite coefficients.
#[test]
fn one_ring_dome_is_diagnosed_like_the_identity_link() {
    let lights = LightSet::from_dirs((0..24).map(|i| {
        let (e, a) = (30f64.to_radians(), (15.0 * i as f64).to_radians());
        [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]
    }));
    let mut rng = Rng(5);
    let stack = step_stack(&lights, 8, 4, 8, &mut rng);
    let (ptm, report) = fit_stack(&stack, &options(Basis::Ptm6, UvMap::Projected, 1e-5)).unwrap();
    let (_, identity) = fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap();
    let ring = |ws: &[Diagnostic]| {
        ws.iter()
            .find(|w| matches!(w, Diagnostic::Ring { .. }))
            .cloned()
    };
    assert!(ring(&report.warnings).is_some(), "{:?}", report.warnings);
    assert_eq!(ring(&report.warnings), ring(&identity.warnings));
    assert_eq!(report.rank, identity.rank);
    assert!(report.warnings.iter().any(|w| matches!(
        w,
        Diagnostic::RankDeficient { rank: 5, coefficients: 6, directions, solution: Solution::LogisticRidge { .. } }
            if directions.join(" ").contains("u2 + v2")
    )));
    assert!(ptm.planes.iter().flatten().all(|c| c.is_finite()));
}

/// The streaming fit (exact counts, as `ptm bake --fit --link logistic` holds them) agrees with
/// the fit of the stored stack, MIP levels included.
#[test]
fn streaming_counts_agree_with_the_stored_stack() {
    let mut rng = Rng(3);
    let lights = fibonacci(64, 5.0);
    for (samples, basis) in [(8u32, Basis::Ptm6), (300, Basis::Ptm11)] {
        let mut stack = step_stack(&lights, 16, 12, samples, &mut rng);
        // Some holes and a partly covered texel: K is a fraction of the covered samples.
        let cov_samples = samples / 2;
        stack.coverage[5] = 0.0;
        stack.coverage[17] = cov_samples as f32 / samples as f32;
        for plane in &mut stack.k {
            plane[5] = f32::NAN;
            plane[17] = (plane[17] * cov_samples as f32).round() / cov_samples as f32;
        }
        let opts = FitOptions {
            mips: true,
            holdout: 6,
            ..options(basis, UvMap::Hemispherical, 1e-5)
        };
        let (want, wr) = fit_stack(&stack, &opts).unwrap();
        let mut acc = Accumulator::new(&lights, 16, 12, &opts).unwrap();
        acc.set_coverage(&stack.coverage).unwrap();
        acc.set_spp(samples).unwrap();
        for (i, k) in stack.k.iter().enumerate() {
            acc.add_light(i, k).unwrap();
        }
        let (got, gr) = acc.finish([1.0, 1.0]).unwrap();
        assert_eq!(got.mips.len(), want.mips.len());
        assert_eq!(want.mips.len(), 4);
        let close = |a: &[Vec<f32>], b: &[Vec<f32>]| {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .all(|(x, y)| (x - y).abs() <= 1e-4 * (1.0 + x.abs()))
        };
        assert!(close(&want.planes, &got.planes), "{basis:?} level 0");
        for (a, b) in want.mips.iter().zip(&got.mips) {
            assert!(
                close(&a.planes, &b.planes),
                "{basis:?} level {}×{}",
                a.width,
                a.height
            );
        }
        assert!((wr.holdout.unwrap().mean - gr.holdout.unwrap().mean).abs() < 1e-5);
        // The hole reads as lit (K = 0), as zero coefficients do under the identity link.
        assert!(got.eval(5, 0, 0.3, 0.2) < 1e-9 && want.eval(5, 0, 0.3, 0.2) < 1e-9);
    }
}

/// Each MIP level of a logistic PTM is the fit of the box-filtered stack of its footprint.
#[test]
fn mip_levels_are_fits_of_the_box_filtered_stack() {
    let mut rng = Rng(9);
    let lights = fibonacci(48, 5.0);
    let stack = step_stack(&lights, 8, 8, 8, &mut rng);
    let opts = FitOptions {
        mips: true,
        ..options(Basis::Ptm6, UvMap::Projected, 1e-5)
    };
    let (ptm, _) = fit_stack(&stack, &opts).unwrap();
    assert_eq!(
        ptm.mips
            .iter()
            .map(|l| (l.width, l.height))
            .collect::<Vec<_>>(),
        vec![(4, 4), (2, 2), (1, 1)]
    );
    // Downsample the stack by hand, 2^l × 2^l boxes, and fit it as a plain stack.
    for (li, level) in ptm.mips.iter().enumerate() {
        let f = 2usize << li;
        let (w, h) = (8 / f, 8 / f);
        let k: Vec<Vec<f32>> = stack
            .k
            .iter()
            .map(|plane| {
                (0..w * h)
                    .map(|t| {
                        let (x, y) = (t % w, t / w);
                        let mut s = 0f64;
                        for yy in y * f..(y + 1) * f {
                            for xx in x * f..(x + 1) * f {
                                s += plane[yy * 8 + xx] as f64;
                            }
                        }
                        (s / (f * f) as f64) as f32
                    })
                    .collect()
            })
            .collect();
        let small = common::stack(&lights, w, h, k);
        let (direct, _) = fit_stack(&small, &options(Basis::Ptm6, UvMap::Projected, 1e-5)).unwrap();
        for (a, b) in direct
            .planes
            .iter()
            .flatten()
            .zip(level.planes.iter().flatten())
        {
            assert!(
                (a - b).abs() <= 1e-4 * (1.0 + a.abs()),
                "level {li}: {a} vs {b}"
            );
        }
    }
    // And averaged coefficients would not be (σ is not linear): the test can fail.
    let avg: f32 = (0..4).map(|t| ptm.planes[5][[0, 1, 8, 9][t]]).sum::<f32>() / 4.0;
    assert!((avg - ptm.mips[0].planes[5][0]).abs() > 1e-3);
}
