//! `ptm report --quick`: the measured study runs end to end (as in CI) and its tables say what
//! the stability cases must show.
use std::process::Command;

fn csv(dir: &std::path::Path, name: &str) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(format!("{name}.csv"))).unwrap();
    let mut rows = Vec::new();
    for line in text.lines() {
        // Cells here never contain quotes except whole-cell quoting of commas.
        let mut cells = Vec::new();
        let mut cur = String::new();
        let mut quoted = false;
        for ch in line.chars() {
            match ch {
                '"' => quoted = !quoted,
                ',' if !quoted => cells.push(std::mem::take(&mut cur)),
                c => cur.push(c),
            }
        }
        cells.push(cur);
        rows.push(cells);
    }
    rows
}

#[test]
fn quick_report_writes_every_table_and_the_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ptm"))
        .args(["--json", "report", "--quick", "-o"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["swatches"].as_array().unwrap().len(), 3);

    let png = std::fs::read(dir.path().join("error_vs_time.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    for section in [
        "## Error against run time",
        "## Stability",
        "### Light layouts",
        "### Link and (u, v) map",
        "### Ridge λ of the logistic link",
        "### Geometry",
        "## Runtime: soft shadows",
    ] {
        assert!(md.contains(section), "report.md lacks {section}");
    }

    // Each swatch: every setting measured, errors are fractions, a Pareto front exists, and the
    // sweep holds all four (link, uv) models with their fit seconds.
    for name in ["plain-weave", "jersey", "velvet"] {
        let rows = csv(dir.path(), &format!("study_{name}"));
        assert!(rows.len() > 10, "{name}: {} rows", rows.len());
        let col = |h: &str| {
            rows[0]
                .iter()
                .position(|c| c == h)
                .unwrap_or_else(|| panic!("study_{name}: no column {h}: {:?}", rows[0]))
        };
        let (rms, pareto, link, uv, fit_s) = (
            col("RMS err K"),
            col("Pareto"),
            col("link"),
            col("uv"),
            col("fit s"),
        );
        for r in &rows[1..] {
            let e: f64 = r[rms].parse().unwrap();
            assert!(e > 0.0 && e < 1.0, "{name}: rms {e}");
            let s: f64 = r[fit_s].parse().unwrap();
            assert!(s >= 0.0, "{name}: fit s {s}");
            // σ never leaves [0, 1]: the logistic link's K needs no clamp.
            if r[link] == "logistic" {
                assert!(r[col("K outside [0,1]")].starts_with("0.0%"), "{r:?}");
            }
        }
        for (l, u) in [
            ("identity", "projected"),
            ("identity", "hemispherical"),
            ("logistic", "projected"),
            ("logistic", "hemispherical"),
        ] {
            assert!(
                rows[1..].iter().any(|r| r[link] == l && r[uv] == u),
                "{name}: no {l}, {u} setting"
            );
        }
        assert!(rows[1..].iter().any(|r| !r[pareto].is_empty()));
    }

    // The model table: one row per swatch and basis at least. On the weave the default model
    // (logistic, hemispherical) beats the plain PTM on the same bake by a wide margin.
    let models = csv(dir.path(), "models");
    let col = |h: &str| models[0].iter().position(|c| c == h).unwrap();
    let weave = models
        .iter()
        .find(|r| r[0] == "plain-weave" && r[1].ends_with("ptm6"))
        .expect("a plain-weave ptm6 row in models.csv");
    let plain: f64 = weave[col("RMS identity·projected")].parse().unwrap();
    let default: f64 = weave[col("RMS logistic·hemispherical")].parse().unwrap();
    assert!(default < 0.85 * plain, "{weave:?}");
    assert!(models.len() > 3 * 2, "{models:?}");

    // The ridge sweep: λ from 1e-6 to 10 for both bases; a larger λ shrinks the coefficients,
    // λ = 10 gives back more error than the default, and no texel hits the cap at the default.
    let ridge = csv(dir.path(), "stability_ridge");
    let col = |h: &str| ridge[0].iter().position(|c| c == h).unwrap();
    for basis in ["ptm6", "ptm11"] {
        let rows: Vec<&Vec<String>> = ridge
            .iter()
            .filter(|r| r[0] == basis && r[col("link, uv")].starts_with("logistic"))
            .collect();
        let lambdas: Vec<f64> = rows.iter().map(|r| r[col("λ")].parse().unwrap()).collect();
        assert_eq!(lambdas.first(), Some(&1e-6), "{basis}: {lambdas:?}");
        assert_eq!(lambdas.last(), Some(&10.0), "{basis}: {lambdas:?}");
        let num = |r: &Vec<String>, h: &str| -> f64 { r[col(h)].parse().unwrap() };
        for w in rows.windows(2) {
            assert!(
                num(w[1], "max |coef|") < num(w[0], "max |coef|"),
                "{basis}: coefficients grew with λ: {w:?}"
            );
        }
        let at = |l: f64| {
            *rows
                .iter()
                .find(|r| r[col("λ")].parse::<f64>().unwrap() == l)
                .unwrap()
        };
        assert!(num(at(10.0), "RMS err K (held out)") > num(at(1e-5), "RMS err K (held out)"));
        assert_eq!(at(1e-5)[col("texels at the iteration cap")], "0", "{basis}");
        // Separable texels exist at small λ (their optimum is at infinity) and the counts parse.
        assert!(num(at(1e-6), "separable texels") > 0.0, "{basis}");
        let _: usize = at(10.0)[col("constant texels")].parse().unwrap();
    }

    // A single ring cannot determine u²+v² against the constant: rank 5 of 6, said in words,
    // and the minimum-norm answer stays small; the logistic link reports the same rank, says so
    // too, and its ridge keeps the coefficients finite.
    let layouts = csv(dir.path(), "stability_layouts");
    let col = |h: &str| layouts[0].iter().position(|c| c == h).unwrap();
    let row = |layout: &str, basis: &str, fit: &str| {
        layouts
            .iter()
            .find(|r| r[0].starts_with(layout) && r[1] == basis && r[2] == fit)
            .unwrap_or_else(|| panic!("no {layout} / {basis} / {fit} row"))
    };
    let ring = row("single ring", "ptm6", "identity, projected");
    assert_eq!(ring[col("rank")], "5/6");
    assert!(ring[col("what ptm says")].contains("ring"), "{ring:?}");
    let coef: f64 = ring[col("max |coef|")].parse().unwrap();
    assert!(coef < 10.0, "coefficients blew up: {coef}");
    let ring = row("single ring", "ptm6", "logistic, hemispherical");
    assert_eq!(ring[col("rank")], "5/6");
    assert!(ring[col("what ptm says")].contains("ring"), "{ring:?}");
    assert!(ring[col("what ptm says")].contains("ridge"), "{ring:?}");
    let coef: f64 = ring[col("max |coef|")].parse().unwrap();
    assert!(coef.is_finite() && coef < 1e3, "{ring:?}");
    assert!(ring[col("Newton iterations mean/max")] != "-");
    for fit in ["identity, projected", "logistic, hemispherical"] {
        let reference = row("Fibonacci 64", "ptm6", fit);
        assert_eq!(reference[col("rank")], "6/6");
        assert_eq!(reference[col("what ptm says")], "ok");
    }

    // The scaled swatches bake to the same K.
    let geometry = csv(dir.path(), "stability_geometry");
    for r in geometry.iter().filter(|r| r[0].contains("scaled by")) {
        assert_eq!(r[2], "0", "{r:?}");
    }

    // Runtime: every extreme case renders finite pixels, matches its analytic opacity and the
    // CPU twin; the 8192² caster went through the downsampling; SAT beats MIP against Monte
    // Carlo (times are printed, not asserted: the benchmark owns them).
    let extremes = csv(dir.path(), "runtime_extremes");
    assert_eq!(extremes.len(), 9, "{extremes:?}");
    let col = |h: &str| extremes[0].iter().position(|c| c == h).unwrap();
    for r in &extremes[1..] {
        assert_eq!(r[col("all finite")], "yes", "{r:?}");
        let dev: f64 = r[col("max |opacity − analytic|")].parse().unwrap();
        assert!(dev < 1e-3, "{r:?}");
        let twin: f64 = r[col("GPU vs CPU twin")].parse().unwrap();
        assert!(twin < 1e-3, "{r:?}");
    }
    assert!(extremes[8][col("what ptm does")].contains("downsampled ×2 to 4096×4096"));
    let blur = csv(dir.path(), "runtime_blur");
    let col = |h: &str| blur[0].iter().position(|c| c == h).unwrap();
    let get = |r: &str, m: &str, h: &str| -> f64 {
        let row = blur
            .iter()
            .find(|x| x[0] == r && x[col("method")] == m)
            .unwrap_or_else(|| panic!("no {m} row at R {r}: {blur:?}"));
        row[col(h)].parse().unwrap()
    };
    for r in ["0.100", "0.500"] {
        assert!(get(r, "sat", "mean |err| (radiance)") < get(r, "mip", "mean |err| (radiance)"));
    }
}
