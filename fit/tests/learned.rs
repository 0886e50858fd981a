//! A learned basis: a known smooth non-polynomial basis with known coefficients, baked to exact
//! counts, is learned back (held-out K error far below the logistic polynomial fit of the same
//! size); the output is the same bytes for any thread count; a dome too sparse for k learned
//! terms and a farm shard are refused in words.
use ptm_fit::solve::{fit_stack, Accumulator, FitOptions};
use ptm_fit::SampleStack;
use ptm_format::basis::sigmoid64;
use ptm_format::{Basis, LightSet, Link, SaveOptions, UvMap};

mod common;
use common::{fibonacci, Rng};

fn options(basis: Basis) -> FitOptions {
    FitOptions {
        link: Link::Logistic,
        uv: UvMap::Hemispherical,
        ..FitOptions::new(basis)
    }
}

/// Six smooth functions of (u, v) on the hemispherical square that no quadratic spans: a knit
/// loop's horizon is not a conic.
fn truth_terms(u: f64, v: f64) -> [f64; 6] {
    [
        1.0,
        (2.5 * u).sin(),
        (2.0 * v).cos(),
        (3.0 * (u + 0.5 * v)).tanh(),
        (-(u * u + v * v) * 3.0).exp(),
        (1.7 * u * v + v).sin(),
    ]
}

/// Texel coefficients of the truth: four groups of texels (a weave's repeat), jittered.
fn truth_coeffs(texels: usize, rng: &mut Rng) -> Vec<[f64; 6]> {
    let groups = [
        [0.5, 3.0, -2.0, 1.5, -1.0, 0.5],
        [-1.0, -2.0, 1.0, 3.0, 2.0, -1.5],
        [1.5, 0.5, 2.5, -2.5, 0.0, 2.0],
        [0.0, -3.0, -1.0, 0.5, 3.0, 1.0],
    ];
    (0..texels)
        .map(|t| {
            let g = groups[t % 4];
            std::array::from_fn(|j| g[j] + rng.range(-0.5, 0.5))
        })
        .collect()
}

fn k_of(c: &[f64; 6], d: [f64; 3]) -> f64 {
    let (u, v) = UvMap::Hemispherical.of_dir(d);
    let b = truth_terms(u, v);
    sigmoid64((0..6).map(|j| c[j] * b[j]).sum())
}

const SPP: u32 = 64;

/// The counts of a bake of `SPP` samples per texel: K = round(σ·spp)/spp.
fn counts_stack(lights: &LightSet, w: usize, h: usize, c: &[[f64; 6]]) -> SampleStack {
    let k = lights
        .dirs
        .iter()
        .map(|&d| {
            c.iter()
                .map(|ct| ((k_of(ct, d) * SPP as f64).round() / SPP as f64) as f32)
                .collect()
        })
        .collect();
    SampleStack::new(lights.clone(), w, h, [1.0, 1.0], k)
}

/// A rotated dome of held-out lights (none of the training directions).
fn held_out() -> LightSet {
    let base = fibonacci(61, 7.0);
    let (s, c) = 0.7f64.sin_cos();
    LightSet::from_dirs(
        base.dirs
            .iter()
            .map(|d| [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]),
    )
}

fn held_rms(ptm: &ptm_format::Ptm, coeffs: &[[f64; 6]], lights: &LightSet) -> f64 {
    let mut s = 0.0;
    let mut n = 0usize;
    for (t, c) in coeffs.iter().enumerate() {
        for &d in &lights.dirs {
            let e = ptm.eval_dir(t % ptm.width, t / ptm.width, d) as f64 - k_of(c, d);
            s += e * e;
            n += 1;
        }
    }
    (s / n as f64).sqrt()
}

#[test]
fn a_known_smooth_basis_is_learned_back_from_counts() {
    let (w, h) = (24, 20);
    let mut rng = Rng(7);
    let coeffs = truth_coeffs(w * h, &mut rng);
    let lights = fibonacci(160, 5.0);
    let stack = counts_stack(&lights, w, h, &coeffs);
    let test = held_out();
    // Streaming from exact counts, as `ptm bake --fit` does.
    let opts = options(Basis::Learned(6));
    let mut acc = Accumulator::new(&lights, w, h, &opts).unwrap();
    acc.set_spp(SPP).unwrap();
    for (i, k) in stack.k.iter().enumerate() {
        acc.add_light(i, k).unwrap();
    }
    let (learned, report) = acc.finish([1.0, 1.0]).unwrap();
    let stats = report.learned.clone().expect("learning statistics");
    assert_eq!((stats.terms, stats.texels), (6, w * h));
    assert!(
        stats.deviance < stats.deviance_start && stats.rms < stats.rms_start,
        "{stats:?}"
    );
    let (poly, _) = fit_stack(&stack, &options(Basis::Ptm6)).unwrap();
    let (e_learned, e_poly) = (
        held_rms(&learned, &coeffs, &test),
        held_rms(&poly, &coeffs, &test),
    );
    eprintln!("held-out RMS of K: learned6 {e_learned:.4}, logistic ptm6 {e_poly:.4}; {stats:?}");
    // The count quantisation alone is 1/(√12·64) ≈ 0.0045 per sample.
    assert!(
        e_learned < 0.5 * e_poly,
        "learned6 {e_learned} vs ptm6 {e_poly}"
    );
    assert!(e_learned < 0.03, "learned6 {e_learned}");
    // The stored stack and the streaming counts fit the same.
    let (from_stack, _) = fit_stack(&stack, &opts).unwrap();
    assert_eq!(from_stack, learned);
    // The file holds what was fitted.
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("l.ptm.exr");
    learned.save(&p, &SaveOptions::default()).unwrap();
    assert_eq!(ptm_format::Ptm::load(&p).unwrap(), learned);
}

#[test]
fn the_learned_fit_is_the_same_bytes_for_any_thread_count() {
    let (w, h) = (16, 12);
    let mut rng = Rng(11);
    let coeffs = truth_coeffs(w * h, &mut rng);
    let lights = fibonacci(90, 5.0);
    let mut stack = counts_stack(&lights, w, h, &coeffs);
    stack.coverage[5] = 0.0; // a hole
    let opts = FitOptions {
        mips: true,
        holdout: 8,
        ..options(Basis::Learned(11))
    };
    let bytes = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (ptm, report) = pool.install(|| fit_stack(&stack, &opts)).unwrap();
        let save = SaveOptions {
            report: Some(&report),
            ..SaveOptions::default()
        };
        let mut b = ptm.encode("t.ptm.exr".as_ref(), &save).unwrap();
        // `ptm:software` and the seconds are not in the header; the bytes are the fit's.
        b.shrink_to_fit();
        (b, ptm)
    };
    let (one, ptm) = bytes(1);
    let (three, _) = bytes(3);
    assert!(one == three, "1 and 3 threads give different files");
    assert_eq!(ptm.basis, Basis::Learned(11));
    assert!(!ptm.mips.is_empty() && ptm.learned.is_some());
    // A hole reads as lit (K ≈ 0), as the polynomial fit writes it.
    let kh = ptm.eval_dir(5, 0, [0.0, 0.0, 1.0]);
    assert!(kh < 1e-3, "hole K {kh}");
}

#[test]
fn a_sparse_dome_and_a_farm_shard_are_refused_in_words() {
    let lights = fibonacci(40, 5.0);
    let e = Accumulator::new(&lights, 4, 4, &options(Basis::Learned(11)))
        .err()
        .expect("40 lights for 11 terms")
        .to_string();
    assert!(
        e.contains("at least 44 fitting lights") && e.contains("has 40"),
        "{e}"
    );
    let e = Accumulator::new(&lights, 4, 4, &options(Basis::Learned(7)))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("learned6, learned11"), "{e}");
    let e = Accumulator::new(
        &lights,
        4,
        4,
        &FitOptions {
            link: Link::Identity,
            ..options(Basis::Learned(6))
        },
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("logistic link"), "{e}");
    // A shard of rows 0..4 of 8 with no basis given: it would be learned from a part of the
    // bake, so it is refused (`ptm bake --shard` learns the whole bake's and gives it).
    let mut acc = Accumulator::new(&lights, 4, 4, &options(Basis::Learned(6))).unwrap();
    acc.set_spp(4).unwrap();
    for i in 0..lights.len() {
        acc.add_light(i, &[0.5; 16]).unwrap();
    }
    let e = acc
        .finish_part([1.0, 1.0], 0..4, 8)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("farm") && e.contains("FitOptions::given_basis"),
        "{e}"
    );
}
