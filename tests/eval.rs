//! `ptm eval`: K of every texel for each light of an `.lp`, as a sample stack in the bake's
//! layout. A ptm11 logistic file's stack equals `Ptm::eval_dir` bit for bit; `ptm fit` of the
//! stack of a ptm6 identity file recovers its coefficients; a learned file evaluates as
//! `Ptm::eval_dir` reads its table; a PTM given as the output is refused.
mod common;

use common::{dome, json, ok, p, refused};
use ptm_fit::SampleStack;
use ptm_format::{Basis, LearnedTable, Link, Ptm, SaveOptions, UvMap};

fn planes(m: usize, n: usize, scale: f32) -> Vec<Vec<f32>> {
    (0..m)
        .map(|j| {
            (0..n)
                .map(|t| (((t * 7 + j * 5) % 13) as f32 / 6.0 - 1.0) * scale)
                .collect()
        })
        .collect()
}

/// Every K of the stack at `path` against `ptm.eval_dir`, exactly.
fn assert_stack_is_eval(path: &std::path::Path, ptm: &Ptm, lights: &ptm_format::LightSet) {
    let stack = SampleStack::read(path).unwrap();
    assert_eq!((stack.width, stack.height), (ptm.width, ptm.height));
    assert_eq!(stack.lights.len(), lights.len());
    for (l, d) in stack.lights.dirs.iter().enumerate() {
        for t in 0..ptm.width * ptm.height {
            let want = ptm.eval_dir(t % ptm.width, t / ptm.width, *d);
            assert_eq!(stack.k[l][t], want, "light {l} texel {t}");
        }
    }
}

#[test]
fn eval_writes_the_stack_ptm_eval_gives_and_fit_recovers_it() {
    let d = tempfile::tempdir().unwrap();
    let lights = dome(40);
    let lp = d.path().join("l.lp");
    lights.write_lp(&lp).unwrap();
    // Directions as the .lp stores them (its decimal text), so the references match them.
    let lights = ptm_format::LightSet::read_lp(&lp).unwrap();
    let (w, h) = (7, 5);
    let mut p11 = Ptm::new(Basis::Ptm11, w, h, [1.0, 1.0], planes(11, w * h, 2.0));
    p11.link = Link::Logistic;
    p11.uv = UvMap::Hemispherical;
    let f11 = d.path().join("a.ptm.exr");
    p11.save(&f11, &SaveOptions::default()).unwrap();
    let out = d.path().join("k11.exr");
    let j = json(
        ["eval", p(&f11), "--lights", p(&lp), "-o", p(&out)],
        d.path(),
    );
    assert_eq!(j["basis"], "ptm11");
    assert_eq!(j["lights"], 40);
    assert_stack_is_eval(&out, &p11, &lights);

    // A ptm6 identity file: its eval'd stack fitted back gives its coefficients.
    // K within [0, 1] everywhere, so the clamp of evaluation loses nothing.
    let mut c6 = planes(6, w * h, 0.05);
    c6[5].iter_mut().for_each(|c| *c += 0.5);
    let p6 = Ptm::new(Basis::Ptm6, w, h, [1.0, 1.0], c6);
    let f6 = d.path().join("b.ptm.exr");
    p6.save(&f6, &SaveOptions::default()).unwrap();
    let k6 = d.path().join("k6.exr");
    ok(["eval", p(&f6), "--lights", p(&lp), "-o", p(&k6)], d.path());
    let back = d.path().join("back.ptm.exr");
    ok(
        [
            "fit",
            p(&k6),
            "-o",
            p(&back),
            "--basis",
            "ptm6",
            "--link",
            "identity",
            "--uv",
            "projected",
            "--holdout",
            "0",
            "--no-mips",
        ],
        d.path(),
    );
    let fitted = Ptm::load(&back).unwrap();
    for (a, b) in fitted.planes.iter().zip(&p6.planes) {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-4, "{x} vs {y}");
        }
    }

    // A learned basis evaluates from its table.
    let g = 4;
    let mut pl = Ptm::new(Basis::Learned(3), w, h, [1.0, 1.0], planes(3, w * h, 1.5));
    pl.link = Link::Logistic;
    pl.uv = UvMap::Hemispherical;
    pl.learned = Some(LearnedTable {
        grid: g,
        terms: 3,
        values: (0..3 * g * g).map(|i| (i as f32 * 0.7).cos()).collect(),
    });
    let fl = d.path().join("c.ptm.exr");
    pl.save(&fl, &SaveOptions::default()).unwrap();
    let kl = d.path().join("kl.exr");
    ok(["eval", p(&fl), "--lights", p(&lp), "-o", p(&kl)], d.path());
    assert_stack_is_eval(&kl, &pl, &lights);

    // The output may not be the input.
    let e = refused(["eval", p(&fl), "--lights", p(&lp), "-o", p(&fl)], d.path());
    assert!(e.contains("is the PTM"), "{e}");
}
