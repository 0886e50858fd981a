//! Issue #22's model-comparison table: `cargo run --release -p ptm-report --example compare --
//! RES SPP DIRS [SWATCH…]` (the configuration is `96 8 256`; every builtin swatch when
//! none is named). Prints one Markdown row per swatch: held-out RMS error of K (fit seconds).
use ptm_bake::PreparedMesh;
use ptm_report::{compare::compare, study};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: compare RES SPP DIRS [SWATCH…] (e.g. compare 96 8 256 plain-weave)";
    let num = |i: usize| -> Result<usize, String> {
        args.get(i)
            .and_then(|a| a.parse().ok())
            .ok_or_else(|| format!("argument {} missing or not a number; {usage}", i + 1))
    };
    let (res, spp, dirs) = (num(0)?, num(1)? as u32, num(2)?);
    let names: Vec<String> = if args.len() > 3 {
        args[3..].to_vec()
    } else {
        // Every builtin that builds without parameters (draft and grid need a draft).
        ptm_swatches::NAMES
            .iter()
            .map(|n| n.0.to_string())
            .filter(|n| n != "draft" && n != "grid")
            .collect()
    };
    let test = study::test_lights(64)?;
    let mut header = false;
    for name in &names {
        let swatch = PreparedMesh::load(&format!("builtin:{name}"), None)?;
        let t = std::time::Instant::now();
        // Truth at the fitted resolution, 4× the training samples, two independent bakes.
        let truth = study::Truth::bake(&swatch, res, spp * 4, test.clone())?;
        let row = compare(name, &swatch, &truth, dirs, spp, res)?;
        if !header {
            let cols: Vec<String> = row
                .models
                .iter()
                .map(|m| format!("{} ({})", m.name, m.numbers))
                .collect();
            println!("| swatch | {} | truth noise |", cols.join(" | "));
            println!("|---|{}---|", "---|".repeat(cols.len()));
            header = true;
        }
        let cells: Vec<String> = row
            .models
            .iter()
            .map(|m| format!("{:.3} ({:.2} s)", m.rms, m.fit_s))
            .collect();
        println!("| {name} | {} | {:.3} |", cells.join(" | "), truth.noise);
        eprintln!(
            "{name}: {:.1} s in all (training bake {:.2} s)",
            t.elapsed().as_secs_f64(),
            row.bake_s
        );
    }
    Ok(())
}
