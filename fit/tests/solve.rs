//! Fitting tests: exact polynomials, an independent f64 reference (nalgebra SVD per texel),
//! rank-deficient domes and their diagnostics, bad samples, hold-out, weights, streaming.
use nalgebra::{DMatrix, DVector};
use ptm_fit::diagnostic::Solution;
use ptm_fit::solve::{fit_stack, holdout_indices, Accumulator, FitOptions, Weight};
use ptm_fit::{Diagnostic, Error, SampleStack};
use ptm_format::{Basis, LightSet, Ptm};

mod common;
use common::{fibonacci, Rng};

fn dir(el_deg: f64, az_deg: f64) -> [f64; 3] {
    let (e, a) = (el_deg.to_radians(), az_deg.to_radians());
    [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]
}

fn ring(n: usize, el: f64, jitter_deg: f64, rng: &mut Rng) -> LightSet {
    LightSet::from_dirs((0..n).map(|i| {
        dir(
            el + rng.range(-jitter_deg, jitter_deg),
            360.0 * i as f64 / n as f64,
        )
    }))
}

/// A stack whose texel t has K = poly(c_t) at every light, with random coefficients c_t.
fn poly_stack(
    lights: &LightSet,
    basis: Basis,
    w: usize,
    h: usize,
    rng: &mut Rng,
) -> (SampleStack, Vec<Vec<f64>>) {
    let m = basis.len();
    let coeffs: Vec<Vec<f64>> = (0..w * h)
        .map(|_| (0..m).map(|_| rng.range(-1.0, 1.0)).collect())
        .collect();
    let k = lights
        .dirs
        .iter()
        .map(|d| {
            coeffs
                .iter()
                .map(|c| basis.eval(c, d[0], d[1]) as f32)
                .collect()
        })
        .collect();
    let stack = SampleStack::new(lights.clone(), w, h, [1.0, 1.0], k);
    (stack, coeffs)
}

fn random_stack(lights: &LightSet, w: usize, h: usize, rng: &mut Rng) -> SampleStack {
    let k = (0..lights.len())
        .map(|_| (0..w * h).map(|_| rng.uniform() as f32).collect())
        .collect();
    SampleStack::new(lights.clone(), w, h, [2.0, 1.5], k)
}

fn stream(stack: &SampleStack, opts: &FitOptions) -> Result<(Ptm, ptm_fit::FitReport), Error> {
    let mut acc = Accumulator::new(&stack.lights, stack.width, stack.height, opts)?;
    acc.set_coverage(&stack.coverage)?;
    // Lights arrive in a shuffled order, as a parallel bake might deliver them.
    let n = stack.lights.len();
    for j in 0..n {
        let i = (j * 7 + 3) % n;
        if let Some(uv) = &stack.uv {
            acc.add_light_uv(i, &stack.k[i], &uv[i])?;
        } else {
            acc.add_light(i, &stack.k[i])?;
        }
    }
    acc.finish(stack.tile)
}

/// Independent reference: nalgebra SVD pseudo-inverse of W½A with the same cutoff, per texel.
fn reference(stack: &SampleStack, basis: Basis, w: &[f64], rcond: f64) -> Vec<Vec<f64>> {
    let (n, m) = (stack.lights.len(), basis.len());
    let mut a = DMatrix::zeros(n.max(m), m);
    let mut t = vec![0.0; m];
    for (i, d) in stack.lights.dirs.iter().enumerate() {
        basis.terms(d[0], d[1], &mut t);
        for j in 0..m {
            a[(i, j)] = w[i].sqrt() * t[j];
        }
    }
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let pinv = svd.pseudo_inverse(rcond * smax).unwrap();
    (0..stack.texels())
        .map(|ti| {
            let mut b = DVector::zeros(n.max(m));
            for i in 0..n {
                b[i] = w[i].sqrt() * stack.k[i][ti] as f64;
            }
            (&pinv * b).iter().copied().collect()
        })
        .collect()
}

fn max_diff(ptm: &Ptm, want: &[Vec<f64>]) -> f64 {
    let mut d: f64 = 0.0;
    for (ti, c) in want.iter().enumerate() {
        for (j, &x) in c.iter().enumerate() {
            d = d.max((ptm.planes[j][ti] as f64 - x).abs());
        }
    }
    d
}

#[test]
fn exact_polynomials_are_recovered_by_both_paths() {
    let mut rng = Rng(1);
    for (basis, n) in [(Basis::Ptm6, 40), (Basis::Ptm11, 96)] {
        // A random well-spread dome: Fibonacci with a random rotation about z.
        let rot = rng.range(0.0, std::f64::consts::TAU);
        let lights = LightSet::from_dirs(fibonacci(n, 5.0).dirs.iter().map(|d| {
            [
                d[0] * rot.cos() - d[1] * rot.sin(),
                d[0] * rot.sin() + d[1] * rot.cos(),
                d[2],
            ]
        }));
        let (stack, coeffs) = poly_stack(&lights, basis, 23, 17, &mut rng);
        let opts = FitOptions::new(basis);
        let (ptm, report) = fit_stack(&stack, &opts).unwrap();
        assert_eq!(report.rank, basis.len());
        assert!(report.warnings.is_empty(), "{:?}", report.warnings);
        let d = max_diff(&ptm, &coeffs);
        assert!(d < 1e-5, "{basis:?} fit_stack coefficient error {d}");
        assert!(report.rms.max < 1e-5 && report.max.unwrap().max < 1e-5);
        let (ptm2, r2) = stream(&stack, &opts).unwrap();
        let d = max_diff(&ptm2, &coeffs);
        assert!(d < 1e-5, "{basis:?} streaming coefficient error {d}");
        assert!(r2.rms.max < 1e-5 && r2.max.is_none());
        // Cosine weighting fits an exact polynomial exactly too.
        let opts = FitOptions {
            weight: Weight::Cosine,
            ..opts
        };
        let d = max_diff(&fit_stack(&stack, &opts).unwrap().0, &coeffs);
        assert!(d < 1e-5, "{basis:?} cosine coefficient error {d}");
    }
}

#[test]
fn agrees_with_independent_f64_svd_on_noisy_data() {
    let mut rng = Rng(2);
    for basis in Basis::ALL {
        let lights = fibonacci(64, 0.0);
        let stack = random_stack(&lights, 19, 11, &mut rng);
        for weight in [Weight::Uniform, Weight::Cosine] {
            let opts = FitOptions {
                weight,
                ..FitOptions::new(basis)
            };
            let w: Vec<f64> = lights
                .dirs
                .iter()
                .map(|d| {
                    if weight == Weight::Cosine {
                        d[2].max(0.0)
                    } else {
                        1.0
                    }
                })
                .collect();
            let want = reference(&stack, basis, &w, opts.rcond);
            let (ptm, rep) = fit_stack(&stack, &opts).unwrap();
            let d = max_diff(&ptm, &want);
            assert!(d < 1e-5, "{basis:?} {weight:?} fit_stack vs nalgebra: {d}");
            let (ptm2, rep2) = stream(&stack, &opts).unwrap();
            let d = max_diff(&ptm2, &want);
            assert!(d < 1e-6, "{basis:?} {weight:?} streaming vs nalgebra: {d}");
            // Both RMS figures agree with a direct evaluation at one texel.
            let ti = 37;
            let (mut ss, mut sw, mut mx) = (0.0, 0.0, 0.0f64);
            for (i, d) in lights.dirs.iter().enumerate() {
                let r = stack.k[i][ti] as f64 - basis.eval(&want[ti], d[0], d[1]);
                ss += w[i] * r * r;
                sw += w[i];
                mx = mx.max(r.abs());
            }
            let rms = (ss / sw).sqrt();
            assert!(
                (rep.rms_map[ti] as f64 - rms).abs() < 1e-5,
                "{} vs {rms}",
                rep.rms_map[ti]
            );
            assert!((rep2.rms_map[ti] as f64 - rms).abs() < 1e-6);
            assert!((rep.max_map[ti] as f64 - mx).abs() < 1e-5);
        }
    }
}

fn assert_sane(ptm: &Ptm) {
    for p in &ptm.planes {
        for &c in p {
            assert!(c.is_finite() && c.abs() < 1e3, "coefficient {c}");
        }
    }
}

#[test]
fn single_ring_is_rank_deficient_named_and_min_norm() {
    let mut rng = Rng(3);
    for (basis, rank) in [(Basis::Ptm6, 5), (Basis::Ptm11, 8)] {
        // f32-rounded directions, as a file stores them: the notes' trap for f32 inverses.
        let lights = ring(24, 35.0, 0.0, &mut rng);
        let stack = random_stack(&lights, 9, 7, &mut rng);
        let opts = FitOptions::new(basis);
        let (ptm, rep) = fit_stack(&stack, &opts).unwrap();
        assert_eq!(rep.rank, rank, "{basis:?}");
        let w = &rep.warnings;
        assert!(
            w.iter()
                .any(|d| matches!(d, Diagnostic::Ring { elevation_deg, .. }
                if (elevation_deg - 35.0).abs() < 1e-3)),
            "{w:?}"
        );
        let Some(Diagnostic::RankDeficient {
            rank: r,
            coefficients,
            directions,
            solution,
        }) = w
            .iter()
            .find(|d| matches!(d, Diagnostic::RankDeficient { .. }))
        else {
            panic!("no rank diagnostic: {w:?}");
        };
        assert_eq!((*r, *coefficients), (rank, basis.len()), "{w:?}");
        assert!(
            matches!(solution, Solution::MinimumNorm { rcond, .. } if *rcond == opts.rcond),
            "{solution:?}"
        );
        if basis == Basis::Ptm6 {
            // The missing direction is u² + v² − r²·1 (r² = cos² 35°).
            let all = directions.join("; ");
            assert!(
                all.contains("u2 + v2 - 0.671*1") || all.contains("-0.671*u2"),
                "{all}"
            );
        }
        assert_sane(&ptm);
        let want = reference(&stack, basis, &[1.0; 24], opts.rcond);
        let d = max_diff(&ptm, &want);
        assert!(
            d < 1e-5,
            "{basis:?} ring fit_stack vs min-norm reference: {d}"
        );
        let (ptm2, _) = stream(&stack, &opts).unwrap();
        let d = max_diff(&ptm2, &want);
        assert!(
            d < 1e-6,
            "{basis:?} ring streaming vs min-norm reference: {d}"
        );
        // --strict refuses.
        let strict = FitOptions {
            strict: true,
            ..opts.clone()
        };
        match fit_stack(&stack, &strict).unwrap_err() {
            Error::Strict(ds) => assert_eq!(&ds, w),
            e => panic!("{e}"),
        }
        // Ridge gives finite coefficients too.
        let ridge = FitOptions {
            regularize: Some(1e-3),
            ..opts
        };
        let (p3, r3) = fit_stack(&stack, &ridge).unwrap();
        assert_sane(&p3);
        assert!(r3.solver.contains("ridge"));
    }
}

#[test]
fn fewer_lights_than_coefficients_near_ring_and_high_only() {
    let mut rng = Rng(4);
    // N < M: 8 lights, 11 terms.
    let lights = fibonacci(8, 10.0);
    let stack = random_stack(&lights, 6, 5, &mut rng);
    let opts = FitOptions::new(Basis::Ptm11);
    let (ptm, rep) = fit_stack(&stack, &opts).unwrap();
    assert_eq!(rep.rank, 8);
    assert!(
        rep.warnings.iter().any(|w| matches!(
            w,
            Diagnostic::TooFewLights {
                lights: 8,
                coefficients: 11,
                basis: Basis::Ptm11
            }
        )),
        "{:?}",
        rep.warnings
    );
    assert_sane(&ptm);
    let d = max_diff(
        &ptm,
        &reference(&stack, Basis::Ptm11, &[1.0; 8], opts.rcond),
    );
    assert!(d < 1e-5, "N < M vs reference {d}");
    let d = max_diff(
        &stream(&stack, &opts).unwrap().0,
        &reference(&stack, Basis::Ptm11, &[1.0; 8], opts.rcond),
    );
    assert!(d < 1e-6, "N < M streaming vs reference {d}");

    // Near-ring: elevations within ±0.001°.
    let lights = ring(30, 40.0, 1e-3, &mut rng);
    let stack = random_stack(&lights, 6, 5, &mut rng);
    let opts = FitOptions::new(Basis::Ptm6);
    let (ptm, rep) = fit_stack(&stack, &opts).unwrap();
    assert!(
        rep.warnings
            .iter()
            .any(|w| matches!(w, Diagnostic::NearRing { .. })),
        "{:?}",
        rep.warnings
    );
    assert!(
        rep.rank == 5,
        "near-ring rank {} cond {}",
        rep.rank,
        rep.cond
    );
    assert_sane(&ptm);
    let d = max_diff(
        &ptm,
        &reference(&stack, Basis::Ptm6, &[1.0; 30], opts.rcond),
    );
    assert!(d < 1e-5, "near ring vs reference {d}");

    // High-only: every light above 60°.
    let lights = fibonacci(50, 60.0);
    let stack = random_stack(&lights, 6, 5, &mut rng);
    let opts = FitOptions::new(Basis::Ptm11);
    let (ptm, rep) = fit_stack(&stack, &opts).unwrap();
    let w = &rep.warnings;
    assert!(
        w.iter()
            .any(|d| matches!(d, Diagnostic::NoLightBelow { deg } if (60.0..61.0).contains(deg))),
        "{w:?}"
    );
    assert!(
        w.iter().any(|d| matches!(
            d,
            Diagnostic::IllConditioned { .. } | Diagnostic::RankDeficient { .. }
        )),
        "{w:?}"
    );
    assert!(rep.cond > 100.0, "cond {}", rep.cond);
    assert_sane(&ptm);
    let want = reference(&stack, Basis::Ptm11, &[1.0; 50], opts.rcond);
    let d = max_diff(&ptm, &want);
    assert!(
        d < 1e-4 * want.iter().flatten().fold(1.0f64, |a, x| a.max(x.abs())),
        "high-only vs reference {d}"
    );
}

#[test]
fn bad_samples_are_named_or_skipped() {
    let mut rng = Rng(5);
    let lights = fibonacci(30, 5.0);
    let (mut stack, coeffs) = poly_stack(&lights, Basis::Ptm6, 8, 6, &mut rng);
    stack.k[12][3 * 8 + 5] = f32::NAN;
    stack.k[20][3 * 8 + 5] = f32::INFINITY;
    let opts = FitOptions::new(Basis::Ptm6);
    for e in [
        fit_stack(&stack, &opts).unwrap_err(),
        stream(&stack, &opts).unwrap_err(),
    ] {
        // fit_stack names the lowest light; streaming names the first to arrive.
        assert!(
            matches!(e, Error::BadSample { col: 5, row: 3, light: 12 | 20, value }
                if !value.is_finite()),
            "{e}"
        );
    }
    let skip = FitOptions {
        skip_bad: true,
        ..opts
    };
    for (ptm, rep) in [
        fit_stack(&stack, &skip).unwrap(),
        stream(&stack, &skip).unwrap(),
    ] {
        assert_eq!(rep.skipped_samples, 2);
        assert!(
            rep.warnings.iter().any(|w| matches!(
                w,
                Diagnostic::SkippedSamples {
                    samples: 2,
                    texels: 1,
                    lost_rank: Some(0)
                }
            )),
            "{:?}",
            rep.warnings
        );
        // The texel's remaining 28 samples still determine its exact polynomial.
        assert!(max_diff(&ptm, &coeffs) < 1e-5);
    }
    // Masked texels may hold NaN: no error, zero coefficients.
    stack.coverage[3 * 8 + 5] = 0.0;
    let (ptm, rep) = fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap();
    assert_eq!(rep.masked, 1);
    assert!(ptm.coeffs(5, 3).iter().all(|&c| c == 0.0));
}

#[test]
fn holdout_measures_error_on_unseen_lights() {
    let mut rng = Rng(6);
    let lights = fibonacci(60, 5.0);
    assert_eq!(holdout_indices(60, 4), vec![7, 22, 37, 52]);
    // Exact polynomials with K in [0, 1] at every light: the held-out error vanishes.
    let m = Basis::Ptm6.len();
    let (mut stack, _) = poly_stack(&lights, Basis::Ptm6, 5, 4, &mut rng);
    for k in stack.k.iter_mut() {
        for x in k.iter_mut() {
            *x = 0.5 + 0.1 * *x;
        }
    }
    let opts = FitOptions {
        holdout: 4,
        ..FitOptions::new(Basis::Ptm6)
    };
    let (_, rep) = fit_stack(&stack, &opts).unwrap();
    assert_eq!(rep.lights_fit, 56);
    assert!(rep.holdout.unwrap().max < 1e-5, "{:?}", rep.holdout);
    let (_, rep) = stream(&stack, &opts).unwrap();
    assert!(rep.holdout.unwrap().max < 1e-5);
    // Random data: held-out error exceeds the fitting error, and both paths agree.
    let stack = random_stack(&lights, 5, 4, &mut rng);
    let (_, a) = fit_stack(&stack, &opts).unwrap();
    let (_, b) = stream(&stack, &opts).unwrap();
    let (ha, hb) = (a.holdout.unwrap(), b.holdout.unwrap());
    assert!(
        ha.mean > 0.1 && (ha.mean - hb.mean).abs() < 1e-5,
        "{ha:?} {hb:?}"
    );
    let _ = m;
}

#[test]
fn per_texel_directions_fit_exactly_and_report_rank() {
    let mut rng = Rng(7);
    let lights = fibonacci(40, 5.0);
    let (w, h) = (6, 5);
    let basis = Basis::Ptm11;
    let m = basis.len();
    // Each texel sees the lights from slightly different directions (a light at finite
    // distance); K is an exact polynomial of the texel's own (u, v).
    let coeffs: Vec<Vec<f64>> = (0..w * h)
        .map(|_| (0..m).map(|_| rng.range(-1.0, 1.0)).collect())
        .collect();
    let mut uv = Vec::new();
    let mut k = Vec::new();
    for d in &lights.dirs {
        let (mut pu, mut pk) = (Vec::new(), Vec::new());
        for c in &coeffs {
            let p = [
                (d[0] + rng.range(-0.02, 0.02)) as f32,
                (d[1] + rng.range(-0.02, 0.02)) as f32,
            ];
            pk.push(basis.eval(c, p[0] as f64, p[1] as f64) as f32);
            pu.push(p);
        }
        uv.push(pu);
        k.push(pk);
    }
    let stack = SampleStack {
        width: w,
        height: h,
        tile: [1.0, 1.0],
        lights: lights.clone(),
        k,
        coverage: vec![1.0; w * h],
        uv: Some(uv),
    };
    let (ptm, rep) = fit_stack(&stack, &FitOptions::new(basis)).unwrap();
    assert_eq!(rep.rank, m);
    assert!(
        max_diff(&ptm, &coeffs) < 1e-5,
        "{}",
        max_diff(&ptm, &coeffs)
    );
    assert!(rep.max.unwrap().max < 1e-5);
    // Collapse every texel's directions onto one ring: rank 8 everywhere, named.
    let ring_lights = ring(40, 30.0, 0.0, &mut rng);
    let mut s2 = stack.clone();
    s2.lights = ring_lights.clone();
    s2.uv = Some(
        ring_lights
            .dirs
            .iter()
            .map(|d| vec![[d[0] as f32, d[1] as f32]; w * h])
            .collect(),
    );
    let (ptm, rep) = fit_stack(&s2, &FitOptions::new(basis)).unwrap();
    assert_eq!(rep.rank, 8);
    assert!(
        rep.warnings.iter().any(|d| matches!(
            d,
            Diagnostic::TexelsRankDeficient { coefficients: 11, lowest_rank: 8, directions, .. }
                if !directions.is_empty()
        )),
        "{:?}",
        rep.warnings
    );
    assert_sane(&ptm);
}

#[test]
fn accumulator_misuse_is_an_error() {
    let lights = fibonacci(10, 10.0);
    let opts = FitOptions::new(Basis::Ptm6);
    let mut acc = Accumulator::new(&lights, 2, 2, &opts).unwrap();
    assert!(acc.add_light(10, &[0.0; 4]).is_err());
    assert!(acc.add_light(0, &[0.0; 3]).is_err());
    acc.add_light(0, &[0.0; 4]).unwrap();
    assert!(acc.add_light(0, &[0.0; 4]).is_err());
    assert!(acc.add_light_uv(1, &[0.0; 4], &[[0.0; 2]; 4]).is_err());
    let e = acc.finish([1.0, 1.0]).unwrap_err().to_string();
    assert!(e.contains("light 1") && e.contains("never added"), "{e}");
}

#[test]
fn out_of_range_rcond_and_negative_ridge_are_refused_by_both_paths() {
    let lights = fibonacci(32, 5.0);
    let stack = random_stack(&lights, 4, 3, &mut Rng(7));
    let cases: [(f64, Option<f64>, &str); 5] = [
        (2.0, None, "rcond 2"),
        (-0.1, None, "rcond -0.1"),
        (f64::NAN, None, "rcond NaN"),
        (1e-3, Some(-1.0), "λ = -1"),
        (1e-3, Some(f64::INFINITY), "λ = inf"),
    ];
    for (rcond, regularize, says) in cases {
        let mut opts = FitOptions::new(Basis::Ptm6);
        opts.rcond = rcond;
        opts.regularize = regularize;
        for err in [
            fit_stack(&stack, &opts).map(|_| ()).expect_err("stored"),
            stream(&stack, &opts).map(|_| ()).expect_err("streamed"),
        ] {
            assert!(err.to_string().contains(says), "{says}: {err}");
        }
    }
}

/// `Accumulator::memory_bytes` predicts exactly what the accumulator's buffers hold once every
/// light is added, for each link, both kinds of directions, held-out lights and both count
/// widths (spp ≤ 255 and above).
#[test]
fn memory_estimate_matches_the_allocations() {
    use ptm_format::Link;
    let (w, h) = (13usize, 7usize);
    let t = w * h;
    let lights = fibonacci(24, 10.0);
    let n = lights.len();
    let coverage: Vec<f32> = (0..t).map(|i| if i % 9 == 0 { 0.0 } else { 1.0 }).collect();
    let cases = [
        (Basis::Ptm6, Link::Identity, 0, 16, false),
        (Basis::Ptm11, Link::Identity, 3, 16, false),
        (Basis::Ptm6, Link::Identity, 2, 16, true),
        (Basis::Ptm11, Link::Identity, 0, 16, true),
        (Basis::Ptm6, Link::Logistic, 0, 16, false),
        (Basis::Ptm11, Link::Logistic, 2, 300, false),
    ];
    let mut sizes = Vec::new();
    for (basis, link, holdout, spp, per_texel) in cases {
        let opts = FitOptions {
            link,
            holdout,
            ..FitOptions::new(basis)
        };
        let mut acc = Accumulator::new(&lights, w, h, &opts).unwrap();
        acc.set_coverage(&coverage).unwrap();
        acc.set_spp(spp).unwrap();
        for l in 0..n {
            // K a fraction of the covered samples, so the logistic link's counts are exact.
            let k: Vec<f32> = (0..t)
                .map(|i| ((i * 7 + l * 3) % (spp as usize + 1)) as f32 / spp as f32)
                .collect();
            if per_texel {
                let d = lights.dirs[l];
                let uv = vec![[d[0] as f32, d[1] as f32]; t];
                acc.add_light_uv(l, &k, &uv).unwrap();
            } else {
                acc.add_light(l, &k).unwrap();
            }
        }
        let want = Accumulator::memory_bytes(t, n, &opts, spp, per_texel);
        let case = format!("{basis:?} {link:?} holdout {holdout} spp {spp} per-texel {per_texel}");
        assert_eq!(acc.held_bytes(), want, "{case}");
        sizes.push(want);
        acc.finish([1.0, 1.0]).unwrap();
    }
    // The figures grow the way the buffers do: ptm11 over ptm6, held-out planes, Gram matrices,
    // 16-bit counts over 8-bit ones.
    assert!(sizes[1] > sizes[0] && sizes[2] > sizes[0] && sizes[3] > sizes[1]);
    assert_eq!(sizes[5], sizes[4] + (t * n) as u128);
}
