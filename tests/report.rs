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
        "### Geometry",
        "## Runtime: soft shadows",
    ] {
        assert!(md.contains(section), "report.md lacks {section}");
    }

    // Each swatch: every setting measured, errors are fractions, a Pareto front exists.
    for name in ["plain-weave", "jersey", "velvet"] {
        let rows = csv(dir.path(), &format!("study_{name}"));
        assert!(rows.len() > 10, "{name}: {} rows", rows.len());
        let col = |h: &str| rows[0].iter().position(|c| c == h).unwrap();
        let (rms, pareto) = (col("RMS err K"), col("Pareto"));
        for r in &rows[1..] {
            let e: f64 = r[rms].parse().unwrap();
            assert!(e > 0.0 && e < 1.0, "{name}: rms {e}");
        }
        assert!(rows[1..].iter().any(|r| !r[pareto].is_empty()));
    }

    // A single ring cannot determine u²+v² against the constant: rank 5 of 6, said in words,
    // and the minimum-norm answer stays small.
    let layouts = csv(dir.path(), "stability_layouts");
    let ring = layouts
        .iter()
        .find(|r| r[0].starts_with("single ring") && r[1] == "ptm6")
        .expect("single-ring row");
    assert_eq!(ring[2], "5/6");
    assert!(ring[4].contains("ring"), "{}", ring[4]);
    assert!(
        ring[5].parse::<f64>().unwrap() < 10.0,
        "coefficients blew up: {}",
        ring[5]
    );
    let reference = layouts
        .iter()
        .find(|r| r[0].starts_with("Fibonacci 64") && r[1] == "ptm6")
        .unwrap();
    assert_eq!(reference[2], "6/6");
    assert_eq!(reference[4], "ok");

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
