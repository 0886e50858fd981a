//! The logistic link on real bakes of the built-in weave: agreement with an independent f64
//! Newton solve written here, and the held-out accuracy it buys over the identity link.
mod common;

use std::path::Path;

use common::{p, ptm};

use ptm_fit::solve::{fit_stack, FitOptions};
use ptm_fit::SampleStack;
use ptm_format::basis::sigmoid64;
use ptm_format::{Basis, Link, Ptm, UvMap};

fn bake(dir: &Path, res: &str, dirs: &str, spp: &str) -> SampleStack {
    let samples = dir.join("samples.exr");
    let out = ptm(
        [
            "bake",
            "--swatch",
            "builtin:plain-weave",
            "--res",
            res,
            "--dirs",
            dirs,
            "--spp",
            spp,
            "-o",
            p(&samples),
        ],
        dir,
    );
    assert!(out.ok, "bake failed: {}", out.stderr);
    SampleStack::read(&samples).unwrap()
}

/// Independent per-texel Newton in f64 on J(c) = Σ CE(kₙ, σ(aₙ·c)) + ½ρ|c|², from c = 0, with
/// a backtracking line search, to a gradient of 1e-12: a different start, precision and step
/// rule from the library's solver.
fn newton_f64(rows: &[Vec<f64>], k: &[f64], rho: f64) -> Vec<f64> {
    let m = rows[0].len();
    let objective = |c: &[f64]| -> f64 {
        let mut j = 0.5 * rho * c.iter().map(|x| x * x).sum::<f64>();
        for (r, &kk) in rows.iter().zip(k) {
            let z: f64 = r.iter().zip(c).map(|(a, b)| a * b).sum();
            // −k ln σ(z) − (1−k) ln(1−σ(z)) = softplus(z) − k z, stable.
            j += z.max(0.0) + (-z.abs()).exp().ln_1p() - kk * z;
        }
        j
    };
    let mut c = vec![0.0; m];
    for _ in 0..200 {
        let mut g: Vec<f64> = c.iter().map(|x| rho * x).collect();
        let mut h = vec![vec![0.0; m]; m];
        for (i, row) in h.iter_mut().enumerate() {
            row[i] = rho;
        }
        for (r, &kk) in rows.iter().zip(k) {
            let z: f64 = r.iter().zip(&c).map(|(a, b)| a * b).sum();
            let p = sigmoid64(z);
            for i in 0..m {
                g[i] += (p - kk) * r[i];
                for j in 0..m {
                    h[i][j] += p * (1.0 - p) * r[i] * r[j];
                }
            }
        }
        if g.iter().map(|x| x.abs()).fold(0.0, f64::max) < 1e-12 {
            break;
        }
        let step = gauss(h, g.clone());
        let j0 = objective(&c);
        let mut t = 1.0;
        loop {
            let trial: Vec<f64> = c.iter().zip(step.iter()).map(|(x, s)| x - t * s).collect();
            if objective(&trial) <= j0 || t < 1e-8 {
                c = trial;
                break;
            }
            t *= 0.5;
        }
    }
    c
}

/// Solves h·x = g by Gaussian elimination with partial pivoting.
fn gauss(mut h: Vec<Vec<f64>>, mut g: Vec<f64>) -> Vec<f64> {
    let m = g.len();
    for col in 0..m {
        let piv = (col..m)
            .max_by(|&a, &b| h[a][col].abs().total_cmp(&h[b][col].abs()))
            .unwrap();
        h.swap(col, piv);
        g.swap(col, piv);
        let (pivot_row, pivot_g) = (h[col].clone(), g[col]);
        for (row, gr) in h.iter_mut().zip(g.iter_mut()).skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (x, &y) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * y;
            }
            *gr -= f * pivot_g;
        }
    }
    let mut x = vec![0.0; m];
    for i in (0..m).rev() {
        let s: f64 = (i + 1..m).map(|j| h[i][j] * x[j]).sum();
        x[i] = (g[i] - s) / h[i][i];
    }
    x
}

#[test]
fn real_bake_logistic_fit_agrees_with_an_independent_f64_newton_solve() {
    let dir = tempfile::tempdir().unwrap();
    let stack = bake(dir.path(), "10", "48", "4");
    for basis in Basis::ALL {
        for uv in UvMap::ALL {
            let lambda = ptm_fit::logistic::DEFAULT_RIDGE;
            let opts = FitOptions {
                link: Link::Logistic,
                uv,
                regularize: Some(lambda),
                ..FitOptions::new(basis)
            };
            let (ptm, report) = fit_stack(&stack, &opts).unwrap();
            let rows: Vec<Vec<f64>> = stack
                .lights
                .dirs
                .iter()
                .map(|d| {
                    let (u, v) = uv.of_dir(*d);
                    let mut t = vec![0.0; basis.len()];
                    basis.terms(u, v, &mut t);
                    t
                })
                .collect();
            // ρ = λ · mean eigenvalue of AᵀA (uniform weights).
            let trace: f64 = rows.iter().flatten().map(|x| x * x).sum();
            let rho = lambda * trace / basis.len() as f64;
            assert!((rho - report.logistic.as_ref().unwrap().ridge).abs() < 1e-9 * rho);
            let mut worst = 0f64;
            for t in 0..stack.texels() {
                if stack.coverage[t] <= 0.0 {
                    continue;
                }
                let k: Vec<f64> = stack.k.iter().map(|plane| plane[t] as f64).collect();
                let want = newton_f64(&rows, &k, rho);
                let (x, y) = (t % stack.width, t / stack.width);
                for (l, r) in stack.lights.dirs.iter().zip(&rows) {
                    let z: f64 = r.iter().zip(&want).map(|(a, b)| a * b).sum();
                    let got = ptm.eval(x, y, l[0] as f32, l[1] as f32) as f64;
                    worst = worst.max((got - sigmoid64(z)).abs());
                }
            }
            assert!(
                worst < 1e-4,
                "{basis:?} {uv:?}: K differs from the f64 solve by {worst}"
            );
            eprintln!("{basis:?} {uv:?}: max |K − K_f64| = {worst:.2e}");
        }
    }
}

/// Held-out RMS error of K on the built-in weave: the logistic fit at the same storage is
/// below 0.75× the identity fit's, for both bases and both (u, v) maps, in this run.
#[test]
fn logistic_link_cuts_held_out_error_on_the_weave() {
    let dir = tempfile::tempdir().unwrap();
    let stack = bake(dir.path(), "32", "128", "8");
    for basis in Basis::ALL {
        for uv in UvMap::ALL {
            let fit = |link| {
                let opts = FitOptions {
                    link,
                    uv,
                    holdout: 16,
                    ..FitOptions::new(basis)
                };
                fit_stack(&stack, &opts).unwrap().1.holdout.unwrap().mean
            };
            let (id, lg) = (fit(Link::Identity), fit(Link::Logistic));
            eprintln!(
                "{basis:?} {uv:?}: held-out RMS identity {id:.4}, logistic {lg:.4} ({:.2}x)",
                lg / id
            );
            assert!(
                lg < 0.75 * id,
                "{basis:?} {uv:?}: logistic {lg} vs identity {id}"
            );
        }
    }
}

/// `ptm bake --fit` writes the default model (logistic, hemispherical, MIP-mapped) and it loads
/// as such; `--link identity --uv projected --no-mips` writes the patent's plain PTM, version 1.
#[test]
fn bake_fit_writes_the_default_model_and_the_plain_ptm_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], out: &str| {
        let mut args = vec![
            "bake", "--res", "16", "--dirs", "32", "--spp", "4", "--fit", "ptm6",
        ];
        args.extend(extra);
        args.extend(["-o", out]);
        let j = common::json(&args, dir.path());
        (Ptm::load(&dir.path().join(out)).unwrap(), j)
    };
    let (p, j) = run(&[], "d.ptm.exr");
    assert_eq!((p.link, p.uv), (Link::Logistic, UvMap::Hemispherical));
    assert_eq!(p.mips.len(), 4);
    assert_eq!(j["fit"]["link"], "logistic");
    assert!(j["fit"]["logistic"]["iterations_mean"].as_f64().unwrap() > 1.0);
    let (q, _) = run(
        &["--link", "identity", "--uv", "projected", "--no-mips"],
        "p.ptm.exr",
    );
    assert_eq!(
        (q.link, q.uv, q.mips.len()),
        (Link::Identity, UvMap::Projected, 0)
    );
    assert_eq!(q.version(), ptm_format::ptm::PTM_VERSION);
}
