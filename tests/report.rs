//! `ptm report --quick`'s study (`ptm_report::run`, as in CI) runs end to end, its typed results
//! say what the stability cases must show, and its tables carry the CSV columns the command
//! writes.
mod common;

use ptm_fit::diagnostic::Solution;
use ptm_fit::Diagnostic;
use ptm_format::{Basis, Link, UvMap};
use ptm_report::stability::GeometryCase;
use ptm_report::{Options, Report};

fn quick_study() -> Report {
    let scratch = tempfile::tempdir().unwrap();
    let opts = Options {
        quick: true,
        swatches: ["plain-weave", "jersey", "velvet"]
            .map(String::from)
            .to_vec(),
        scratch: scratch.path().to_owned(),
    };
    ptm_report::run(&opts, &mut |line| eprintln!("report: {line}")).unwrap()
}

/// Each swatch: every setting measured, errors are fractions, a Pareto front exists, and the
/// sweep holds all four (link, uv) models with their fit seconds.
fn check_sweep(report: &Report) {
    let names: Vec<&str> = report.swatches.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["plain-weave", "jersey", "velvet"]);
    for s in &report.swatches {
        let name = &s.name;
        assert!(
            s.outcomes.len() > 9,
            "{name}: {} settings",
            s.outcomes.len()
        );
        for o in &s.outcomes {
            let e = o.errors.rms;
            assert!(e > 0.0 && e < 1.0, "{name}: rms {e}");
            assert!(o.fit_s >= 0.0, "{name}: fit s {}", o.fit_s);
            // σ never leaves [0, 1]: the logistic link's K needs no clamp.
            if o.setting.link == Link::Logistic {
                assert!(100.0 * o.errors.outside < 0.05, "{o:?}");
            }
        }
        for m in ptm_report::MODELS {
            assert!(
                s.outcomes
                    .iter()
                    .any(|o| (o.setting.link, o.setting.uv) == m),
                "{name}: no {m:?} setting"
            );
        }
        assert!(!s.pareto.is_empty(), "{name}: no Pareto front");
        assert!(s.pareto.iter().all(|&i| i < s.outcomes.len()));
    }

    // The model table: one row per swatch and basis at least. On the weave the default model
    // (logistic, hemispherical) beats the plain PTM on the same bake by a wide margin.
    let weave = &report.swatches[0];
    let row = weave
        .models
        .iter()
        .find(|m| m.setting.basis == Basis::Ptm6)
        .expect("a plain-weave ptm6 model row");
    assert!(row.rms[3] < 0.85 * row.rms[0], "{row:?}");
    let rows: usize = report.swatches.iter().map(|s| s.models.len()).sum();
    assert!(rows >= 3 * 2, "{rows} model rows");
}

/// The ridge sweep: λ from 1e-6 to 10 for both bases; a larger λ shrinks the coefficients,
/// λ = 10 gives back more error than the default, and no texel hits the cap at the default.
fn check_ridge(report: &Report) {
    for basis in Basis::ALL {
        let rows: Vec<_> = report
            .stability
            .ridge
            .iter()
            .filter(|r| r.basis == basis && r.link == Link::Logistic)
            .collect();
        let lambdas: Vec<f64> = rows.iter().filter_map(|r| r.lambda).collect();
        assert_eq!(
            lambdas.len(),
            rows.len(),
            "{basis:?}: a logistic row without λ"
        );
        assert_eq!(lambdas.first(), Some(&1e-6), "{basis:?}: {lambdas:?}");
        assert_eq!(lambdas.last(), Some(&10.0), "{basis:?}: {lambdas:?}");
        for w in rows.windows(2) {
            assert!(
                w[1].max_abs_coef < w[0].max_abs_coef,
                "{basis:?}: coefficients grew with λ: {w:?}"
            );
        }
        let at = |l: f64| *rows.iter().find(|r| r.lambda == Some(l)).unwrap();
        assert!(at(10.0).rms > at(1e-5).rms);
        let newton = |l: f64| at(l).logistic.clone().expect("logistic stats");
        assert_eq!(newton(1e-5).not_converged, 0, "{basis:?}");
        // Separable texels exist at small λ (their optimum is at infinity).
        assert!(newton(1e-6).separable > 0, "{basis:?}");
        assert!(newton(10.0).constant <= report.stability.covered);
    }
}

/// A single ring cannot determine u²+v² against the constant: rank 5 of 6, said in words, and
/// the minimum-norm answer stays small; the logistic link reports the same rank, says so too,
/// and its ridge keeps the coefficients finite.
fn check_layouts(report: &Report) {
    let row = |layout: &str, link: Link, uv: UvMap| {
        report
            .stability
            .layouts
            .iter()
            .find(|r| {
                r.layout.starts_with(layout)
                    && r.basis == Basis::Ptm6
                    && (r.link, r.uv) == (link, uv)
            })
            .unwrap_or_else(|| panic!("no {layout} / ptm6 / {link:?}, {uv:?} row"))
            .fit
            .clone()
            .unwrap_or_else(|e| panic!("{layout}: {e}"))
    };
    let ring = row("single ring", Link::Identity, UvMap::Projected);
    assert_eq!(ring.rank, 5);
    assert!(
        ring.warnings
            .iter()
            .any(|w| matches!(w, Diagnostic::Ring { .. })),
        "{ring:?}"
    );
    assert!(ring.max_abs_coef < 10.0, "coefficients blew up: {ring:?}");
    let ring = row("single ring", Link::Logistic, UvMap::Hemispherical);
    assert_eq!(ring.rank, 5);
    let w = &ring.warnings;
    assert!(
        w.iter().any(|w| matches!(w, Diagnostic::Ring { .. }))
            && w.iter().any(|w| matches!(
                w,
                Diagnostic::RankDeficient {
                    solution: Solution::LogisticRidge { .. },
                    ..
                }
            )),
        "{ring:?}"
    );
    assert!(
        ring.max_abs_coef.is_finite() && ring.max_abs_coef < 1e3,
        "{ring:?}"
    );
    assert!(ring.logistic.is_some());
    for (link, uv) in [
        (Link::Identity, UvMap::Projected),
        (Link::Logistic, UvMap::Hemispherical),
    ] {
        let reference = row("Fibonacci 64", link, uv);
        assert_eq!(reference.rank, 6);
        assert!(reference.warnings.is_empty(), "{reference:?}");
    }

    // The scaled swatches bake to the same K.
    let mut scaled = 0;
    for c in &report.stability.geometry.cases {
        if let GeometryCase::Scaled { max_dk, differ, .. } = c {
            assert_eq!((*max_dk, *differ), (0.0, 0), "{c:?}");
            scaled += 1;
        }
    }
    assert_eq!(scaled, 4);
}

/// Runtime: every extreme case renders finite pixels, matches its analytic opacity and the CPU
/// twin; the 8192² caster went through the downsampling; SAT beats MIP against Monte Carlo
/// (times are printed, not asserted: the benchmark owns them).
fn check_runtime(report: &Report) {
    let extremes = &report.runtime.extremes;
    assert_eq!(extremes.len(), 8, "{extremes:?}");
    for r in extremes {
        assert!(r.all_finite, "{r:?}");
        assert!(r.max_deviation < 1e-3, "{r:?}");
        assert!(r.gpu_vs_twin.is_some_and(|d| d < 1e-3), "{r:?}");
    }
    let big = &extremes[7];
    assert_eq!(
        (big.caster_downsample, big.caster_texels),
        (2, [4096, 4096]),
        "{big:?}"
    );
    let blur = &report.runtime.blur;
    let mean = |radius: f32, method: &str| {
        blur.iter()
            .find(|r| {
                r.light_radius == radius && r.light_rect.is_none() && r.measured.method == method
            })
            .unwrap_or_else(|| panic!("no {method} row at R {radius}: {blur:?}"))
            .measured
            .mean_abs_error
    };
    for r in [0.1, 0.5] {
        assert!(mean(r, "sat") < mean(r, "mip"), "R {r}");
    }
    // Rectangles: the box kernel the table sums exactly beats the MIP's power-of-two square.
    for rect in [[0.8f32, 0.2], [1.0, 0.001]] {
        let rows: Vec<_> = blur.iter().filter(|r| r.light_rect == Some(rect)).collect();
        let of = |m: &str| {
            rows.iter()
                .find(|r| r.measured.method == m)
                .unwrap()
                .measured
                .mean_abs_error
        };
        assert_eq!(
            rows.len(),
            ptm_runtime::Blur::ALL.len(),
            "rect {rect:?}: {blur:?}"
        );
        assert!(of("sat") < of("mip"), "rect {rect:?}");
    }
    // Gaussians: the SAT's three boxes per axis and the explicit grid beat MIP's ellipse of the
    // same variance and the separable box of it.
    for g in [[0.2f32, 0.2], [0.4, 0.1]] {
        let rows: Vec<_> = blur
            .iter()
            .filter(|r| r.light_gaussian == Some(g))
            .collect();
        let of = |m: &str| {
            rows.iter()
                .find(|r| r.measured.method == m)
                .unwrap()
                .measured
                .mean_abs_error
        };
        assert_eq!(
            rows.len(),
            ptm_runtime::Blur::ALL.len(),
            "σ {g:?}: {blur:?}"
        );
        for exact in ["sat", "explicit"] {
            for other in ["mip", "separable"] {
                assert!(of(exact) < of(other), "σ {g:?}: {exact} vs {other}");
            }
        }
    }
    // Glossy reflections: explicit, sat and mip at three roughnesses, over a colour and over a
    // sky image; sat and explicit within 2 % of the mean reflected radiance of the ray-traced
    // lobe.
    let glossy: Vec<_> = blur.iter().filter(|r| r.glossy.is_some()).collect();
    assert_eq!(glossy.len(), 2 * 3 * 3, "{glossy:?}");
    assert_eq!(glossy.iter().filter(|r| r.sky).count(), 3 * 3);
    for r in glossy {
        let (roughness, level) = r.glossy.unwrap();
        assert!(level > 0.0 && r.measured.mean_abs_error.is_finite());
        if matches!(r.measured.method, "sat" | "explicit") {
            assert!(
                (r.measured.mean_abs_error as f64) <= 0.02 * level,
                "roughness {roughness}, {}: {} vs {level}",
                r.measured.method,
                r.measured.mean_abs_error
            );
        }
    }
}

/// The CSV files of a report on `swatches`, with their header lines, in the order
/// `ptm report` lists them.
fn expected_csv_headers(swatches: &[&str]) -> Vec<(String, String)> {
    let study =
        "lights,spp,texels,basis,weight,link,uv,bake s,fit s,RMS err K,p99 err K,max err K,\
                 \"K outside [0,1]\",Newton iterations mean/max,separable/constant texels,Pareto";
    let want: Vec<(String, &str)> = swatches
        .iter()
        .map(|s| (format!("study_{s}"), study))
        .chain(
            [
                (
                    "models",
                    "swatch,bake,RMS identity·projected,RMS identity·hemispherical,\
                     RMS logistic·projected,RMS logistic·hemispherical,fit s identity·projected,\
                     fit s identity·hemispherical,fit s logistic·projected,\
                     fit s logistic·hemispherical,bake s,\
                     logistic·hemispherical vs identity·projected",
                ),
                (
                    "recommendations",
                    "swatch,time budget (s),best setting within it,seconds,RMS err K,p99 err K",
                ),
                (
                    "alternatives",
                    "swatch,RMS ptm6 identity (6),RMS ptm6 logistic (6),RMS ptm11 identity (11),\
                     RMS ptm11 logistic (11),RMS learned6 logistic (6),RMS learned11 logistic (11),\
                     RMS horizon 8 (9),RMS horizon 10 (11),RMS AO micro-shadowing (1),\
                     fit s ptm6 identity (6),fit s ptm6 logistic (6),fit s ptm11 identity (11),\
                     fit s ptm11 logistic (11),fit s learned6 logistic (6),\
                     fit s learned11 logistic (11),fit s horizon 8 (9),fit s horizon 10 (11),\
                     fit s AO micro-shadowing (1),bake s,truth noise",
                ),
                (
                    "stability_layouts",
                    "light layout,basis,\"link, uv\",rank,cond,what ptm says,max |coef|,\
                     RMS err K (held out),\"K outside [0,1]\",Newton iterations mean/max,\
                     separable/constant texels",
                ),
                (
                    "stability_ridge",
                    "basis,\"link, uv\",λ,RMS err K (held out),max |coef|,\
                     Newton iterations mean/max,texels at the iteration cap,separable texels,\
                     constant texels,fit s",
                ),
                (
                    "stability_precision",
                    "case,basis,cond,max |ΔK| vs f64 SVD,\"RMS err K, f64 SVD\",\
                     \"RMS err K, this variant\"",
                ),
                (
                    "stability_geometry",
                    "case,what ptm does,max |ΔK| vs reference bake,texel·lights that differ",
                ),
                (
                    "runtime_blur",
                    "light,kernel,penumbra radius on the caster (texels),method,\
                     max |err| (radiance),mean |err| (radiance),shade ms,setup ms",
                ),
                (
                    "runtime_extremes",
                    "case,what ptm does,blur,analytic penumbra width on the cloth,\
                     measured 10–90 % width,caster texel on the cloth,max |opacity − analytic|,\
                     GPU vs CPU twin,all finite,setup + shade ms",
                ),
            ]
            .map(|(n, c)| (n.to_string(), c)),
        )
        .collect();
    want.into_iter().map(|(n, c)| (n, c.into())).collect()
}

/// The comparison with the classic alternatives: one row per study swatch (quick plan), every
/// model with a finite error, the one-number AO worst, and the logistic PTMs and learned bases
/// better than the patent's plain PTM.
fn check_alternatives(report: &Report) {
    let names: Vec<&str> = report
        .alternatives
        .iter()
        .map(|(r, _)| r.swatch.as_str())
        .collect();
    assert_eq!(names, ["plain-weave", "jersey", "velvet"]);
    for (row, noise) in &report.alternatives {
        assert_eq!(row.models.len(), 9, "{}", row.swatch);
        assert!(noise.is_finite() && *noise >= 0.0);
        let rms = |n: &str| row.models.iter().find(|m| m.name == n).unwrap().rms;
        for m in &row.models {
            assert!(
                m.rms > 0.0 && m.rms < 1.0,
                "{} {}: {}",
                row.swatch,
                m.name,
                m.rms
            );
            assert!(m.fit_s >= 0.0);
            assert!(
                m.rms <= rms("AO micro-shadowing"),
                "{} {}",
                row.swatch,
                m.name
            );
        }
        for m in ["ptm11 logistic", "learned6 logistic", "learned11 logistic"] {
            assert!(rms(m) < rms("ptm6 identity"), "{} {m}", row.swatch);
        }
    }
    assert_eq!(
        report.tables().alternatives.rows.len(),
        report.alternatives.len()
    );
}

/// The tables `ptm report` writes as CSV: their names and header lines, and one line per
/// typed row.
fn check_csv_columns(report: &Report) {
    let tables = report.tables();
    let got: Vec<(String, String)> = tables
        .all()
        .map(|t| (t.name.clone(), t.csv().lines().next().unwrap().to_owned()))
        .collect();
    let names: Vec<&str> = report.swatches.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(got, expected_csv_headers(&names));

    let st = &report.stability;
    for (t, rows) in [
        (&tables.layouts, st.layouts.len()),
        (&tables.ridge, st.ridge.len()),
        (&tables.precision, st.precision.len()),
        (&tables.geometry, st.geometry.cases.len()),
        (&tables.blur, report.runtime.blur.len()),
        (&tables.extremes, report.runtime.extremes.len()),
    ] {
        assert_eq!(t.csv().lines().count(), 1 + rows, "{}", t.name);
        assert!(
            t.rows.iter().all(|r| r.len() == t.columns.len()),
            "{}",
            t.name
        );
    }
    for (t, s) in tables.studies.iter().zip(&report.swatches) {
        assert_eq!(t.rows.len(), s.outcomes.len());
        let stars = t.rows.iter().filter(|r| r[15] == "★").count();
        assert_eq!(stars, s.pareto.len(), "{}", t.name);
    }
    // The 8192² caster's row says what was done to it, in words.
    assert!(tables.extremes.rows[7][1].contains("downsampled ×2 to 4096×4096"));
    // The scaled swatches' rows show exactly zero difference.
    for r in tables
        .geometry
        .rows
        .iter()
        .filter(|r| r[0].contains("scaled by"))
    {
        assert_eq!(r[2], "0", "{r:?}");
    }
}

#[test]
fn quick_study_measures_what_the_stability_cases_must_show() {
    let report = quick_study();
    check_sweep(&report);
    check_alternatives(&report);
    check_ridge(&report);
    check_layouts(&report);
    check_runtime(&report);
    check_csv_columns(&report);
}

/// The command writes what the study measured: the plots, `report.md` with every section, and
/// one CSV per table with the expected columns; `--json` names them.
#[test]
fn quick_report_command_writes_every_table_and_the_plots() {
    let dir = tempfile::tempdir().unwrap();
    let json = common::json(
        ["report", "--quick", "-o", common::p(dir.path())],
        dir.path(),
    );
    assert_eq!(json["swatches"].as_array().unwrap().len(), 3);
    for png in ["error_vs_time.png", "contact_sheet.png"] {
        let bytes = std::fs::read(dir.path().join(png)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{png}");
    }
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    for section in [
        "## Error against run time",
        "## Stability",
        "### Light layouts",
        "### Link and (u, v) map",
        "### Against the classic alternatives",
        "### Ridge λ of the logistic link",
        "### Geometry",
        "## Runtime: soft shadows",
    ] {
        assert!(md.contains(section), "report.md lacks {section}");
    }
    let want = expected_csv_headers(&["plain-weave", "jersey", "velvet"]);
    let listed: Vec<String> = json["csv"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap().to_owned())
        .collect();
    assert_eq!(listed.len(), want.len(), "{listed:?}");
    for ((name, header), path) in want.iter().zip(&listed) {
        assert_eq!(
            *path,
            dir.path().join(format!("{name}.csv")).display().to_string()
        );
        let text = std::fs::read_to_string(path).unwrap();
        assert_eq!(text.lines().next(), Some(header.as_str()), "{name}.csv");
        assert!(text.lines().count() > 1, "{name}.csv has no rows");
    }
    assert!(!dir.path().join(".scratch").exists());
}
