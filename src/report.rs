//! `ptm report`: a measured study written into a folder — what accuracy each bake and fit
//! setting buys and what it costs (error of K on held-out lights against seconds, with the
//! Pareto front), and how the tool behaves on stiff and extreme cases. Markdown, the CSV behind
//! every table, and PNG plots.

mod plot;
mod runtime;
mod sheet;
mod stability;
mod study;
mod table;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use ptm_bake::Swatch;
use ptm_fit::{Basis, Weight};
use serde_json::json;

use study::{pareto, Outcome, Setting, Truth};
use table::{g3, Table};

#[derive(clap::Args)]
pub struct Args {
    /// Output folder: report.md, one CSV per table, error_vs_time.png.
    #[arg(short, long, default_value = "report")]
    pub out: PathBuf,
    /// A small sweep (under 2 minutes on 2 cores; what CI runs) instead of the full study.
    #[arg(long)]
    pub quick: bool,
    /// Builtin swatches to study (a weave, a knit and a pile by default).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "plain-weave,jersey,velvet"
    )]
    pub swatches: Vec<String>,
}

/// Sizes of one study.
struct Plan {
    truth_res: usize,
    truth_spp: u32,
    test_lights: usize,
    settings: Vec<Setting>,
    /// Samples per texel of the stability bakes.
    spp: u32,
}

fn plan(quick: bool) -> Plan {
    let s = |dirs, spp, res, basis, weight| Setting {
        dirs,
        spp,
        res,
        basis,
        weight,
    };
    let (u, c) = (Weight::Uniform, Weight::Cosine);
    let (p6, p11) = (Basis::Ptm6, Basis::Ptm11);
    let mut settings = Vec::new();
    if quick {
        for dirs in [16, 32, 64, 128] {
            for spp in [1, 4, 16] {
                settings.push(s(dirs, spp, 32, p6, u));
            }
        }
        settings.extend([
            s(64, 4, 16, p6, u),
            s(64, 4, 32, p11, u),
            s(64, 4, 32, p6, c),
            s(128, 16, 32, p11, c),
        ]);
        Plan {
            truth_res: 32,
            truth_spp: 32,
            test_lights: 32,
            settings,
            spp: 4,
        }
    } else {
        for dirs in [16, 64, 256, 1024] {
            for spp in [1, 4, 16] {
                settings.push(s(dirs, spp, 64, p6, u));
            }
        }
        settings.push(s(256, 16, 32, p6, u));
        for dirs in [64, 256, 1024] {
            settings.extend([
                s(dirs, 16, 64, p11, u),
                s(dirs, 16, 64, p6, c),
                s(dirs, 16, 64, p11, c),
            ]);
        }
        Plan {
            truth_res: 64,
            truth_spp: 128,
            test_lights: 64,
            settings,
            spp: 8,
        }
    }
}

pub fn run(args: &Args) -> Result<serde_json::Value> {
    let started = Instant::now();
    let plan = plan(args.quick);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let test = study::test_lights(plan.test_lights)?;
    let mut md = format!(
        "# ptm report{}\n\nRegenerate with `ptm report{} -o {}`. Machine: {} cores. Error is |K_fit − K_true| \
         on {} held-out directions (Fibonacci above 5°, turned 0.7 rad so none is a training light), over \
         covered texels; K_true is the mean of two independent bakes at {}² texels and {} samples per texel each; K_fit is clamped to [0, 1] \
         as a renderer uses it. Seconds are bake (scene, primary hits, shadow rays) plus the streaming \
         fit, on all cores.\n\n",
        if args.quick { " (quick)" } else { "" },
        if args.quick { " --quick" } else { "" },
        args.out.display(),
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        plan.test_lights,
        plan.truth_res,
        plan.truth_spp,
    );
    let mut tables: Vec<Table> = Vec::new();
    let mut series: Vec<(String, Vec<Outcome>)> = Vec::new();
    let mut truths = Vec::new();
    let mut recommend = Table::new(
        "recommendations",
        &[
            "swatch",
            "time budget (s)",
            "best setting within it",
            "seconds",
            "RMS err K",
            "p99 err K",
        ],
    );
    md += "## Swatches under a low light\n\nEvery builtin swatch at its default parameters, visibility 1 − K \
           under one light at 20° elevation from azimuth 30°, each tile repeated 2×2 (a seam would show as a \
           line); dark red marks texels with no surface below them.\n\n![contact sheet](contact_sheet.png)\n\n\
           ## Error against run time\n\n![error against time](error_vs_time.png)\n\n";
    for name in &args.swatches {
        let spec = format!("builtin:{name}");
        let swatch = Swatch::load(&spec, None)?;
        eprintln!(
            "report: {name}: {} triangles, baking the truth",
            swatch.triangles.len()
        );
        let truth = Truth::bake(&swatch, plan.truth_res, plan.truth_spp, test.clone())?;
        let mut coarse = std::collections::HashMap::new();
        let mut outcomes = Vec::new();
        for s in &plan.settings {
            let c = coarse.entry(s.res).or_insert_with(|| truth.at(s.res));
            let o = study::run_setting(&swatch, &truth, c, s)?;
            eprintln!(
                "report: {name}: {:<45} {:>8.3} s  rms {:.4}",
                s.label(),
                o.seconds(),
                o.errors.rms
            );
            outcomes.push(o);
        }
        let front = pareto(&outcomes);
        let mut t = Table::new(
            format!("study_{name}"),
            &[
                "setting",
                "bake s",
                "fit s",
                "RMS err K",
                "p99 err K",
                "max err K",
                "K outside [0,1]",
                "Pareto",
            ],
        );
        for (i, o) in outcomes.iter().enumerate() {
            t.push(vec![
                o.setting.label(),
                g3(o.bake_s),
                g3(o.fit_s),
                g3(o.errors.rms),
                g3(o.errors.p99),
                g3(o.errors.max),
                format!(
                    "{:.1}% (max {})",
                    100.0 * o.errors.outside,
                    g3(o.errors.outside_max)
                ),
                if front.contains(&i) {
                    "★".into()
                } else {
                    String::new()
                },
            ]);
        }
        md += &format!(
            "### {name} ({} triangles, tile {} × {}; truth baked in {:.1} s, its own RMS sampling noise {})\n\n{}\n",
            swatch.triangles.len(),
            g3(swatch.tile[0]),
            g3(swatch.tile[1]),
            truth.seconds,
            g3(truth.noise),
            t.markdown()
        );
        // Budgets spanning the measured range, one per half decade.
        let (lo, hi) = outcomes.iter().fold((f64::MAX, 0f64), |(a, b), o| {
            (a.min(o.seconds()), b.max(o.seconds()))
        });
        let mut budget = 10f64.powf((lo.log10() * 2.0).ceil() / 2.0);
        while budget <= hi * 1.5 {
            if let Some(best) = outcomes
                .iter()
                .filter(|o| o.seconds() <= budget)
                .min_by(|a, b| a.errors.rms.total_cmp(&b.errors.rms))
            {
                recommend.push(vec![
                    name.clone(),
                    g3(budget),
                    best.setting.label(),
                    g3(best.seconds()),
                    g3(best.errors.rms),
                    g3(best.errors.p99),
                ]);
            }
            budget *= 10f64.sqrt();
        }
        tables.push(t);
        series.push((name.clone(), outcomes));
        truths.push((swatch, truth));
    }
    plot::error_vs_time(&args.out.join("error_vs_time.png"), &series)?;
    eprintln!("report: contact sheet");
    let sheet_texels = if args.quick { 64 } else { 128 };
    sheet::contact_sheet(&args.out.join("contact_sheet.png"), sheet_texels, 4, 20.0)?;
    md += &format!(
        "### Which setting for which budget\n\nThe most accurate measured setting that fits each time budget \
         (the Pareto front of the plot, read off per swatch):\n\n{}\n",
        recommend.markdown()
    );
    tables.push(recommend);

    // Stability cases, on the first swatch (a weave by default).
    eprintln!("report: stability cases");
    let (swatch, truth) = &truths[0];
    let scratch = args.out.join(".scratch");
    std::fs::create_dir_all(&scratch)?;
    let layouts = stability::layouts(swatch, truth, plan.spp)?;
    let precision = stability::precision(swatch, truth, plan.spp, &scratch)?;
    let _ = std::fs::remove_dir_all(&scratch);
    let geometry = stability::geometry(&args.swatches[0], truth.res, plan.spp)?;
    md += &format!(
        "## Stability on stiff and extreme cases\n\nOn {} at {}² texels, {} samples per texel.\n\n\
         ### Light layouts\n\nRank and condition number of the (weighted) design matrix, what `ptm fit` \
         reports, and the error on the held-out lights. Rank-deficient layouts get the minimum-norm \
         (truncated SVD) solution: finite, small coefficients, with the undetermined directions named.\n\n{}\n\
         ### Precision\n\n{}\n### Geometry\n\n{}\n",
        args.swatches[0],
        truth.res,
        plan.spp,
        layouts.markdown(),
        precision.markdown(),
        geometry.markdown()
    );
    tables.extend([layouts, precision, geometry]);

    eprintln!("report: runtime (blur methods against Monte Carlo, extreme cases)");
    let gpu = ptm_runtime::Gpu::new().context(
        "the runtime part of the report needs a wgpu adapter (lavapipe: scripts/setup.sh)",
    )?;
    let blur = runtime::blur_methods(&gpu, args.quick)?;
    let extremes = runtime::extremes(&gpu)?;
    md += &format!(
        "## Runtime: soft shadows\n\nOn {}. Times are wall clock around submit + wait (on lavapipe the \
         \"GPU\" is this machine's CPU; ratios carry over to a real GPU, absolute figures do not).\n\n\
         ### Each blur method against the Monte Carlo ground truth\n\nA leafy 512² caster 0.6 above a \
         ptm11 cloth, one spherical light 2 above it; error in linear radiance (the light gives about 1 at \
         the centre) against a CPU Monte Carlo integration over the sphere with exact ray–caster hits. \
         `explicit` is the disk kernel the ground truth integrates (its error is sampling); `sat` and \
         `separable` use a box of the same half-width, `mip` a blend of power-of-two boxes.\n\n{}\n\
         ### Extreme cases\n\nA half-plane caster edge (opaque for x < 0, 8 × 8 units) over a strip of \
         cloth; opacity = 1 − radiance/radiance without caster along the strip. The analytic profile is \
         the box (sat) or disk (explicit) average of the half-plane around the point where the ray to the \
         light centre meets the caster plane; the two pixels over the edge texel are skipped.\n\n{}\n",
        gpu.describe(),
        blur.markdown(),
        extremes.markdown()
    );
    tables.extend([blur, extremes]);

    for t in &tables {
        t.write_csv(&args.out)?;
    }
    let md_path = args.out.join("report.md");
    md += &format!(
        "\n_Generated in {:.0} s._\n",
        started.elapsed().as_secs_f64()
    );
    ptm_fit::atomic::write_atomic(&md_path, |f| {
        use std::io::Write;
        f.write_all(md.as_bytes())
    })?;
    eprintln!(
        "report: wrote {} ({:.0} s)",
        md_path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(json!({
        "report": md_path,
        "plot": args.out.join("error_vs_time.png"),
        "csv": tables.iter().map(|t| args.out.join(format!("{}.csv", t.name))).collect::<Vec<_>>(),
        "seconds": started.elapsed().as_secs_f64(),
        "swatches": series.iter().map(|(name, o)| {
            let best = o.iter().min_by(|a, b| a.errors.rms.total_cmp(&b.errors.rms)).unwrap();
            json!({ "swatch": name, "settings": o.len(), "best_rms": best.errors.rms, "best": best.setting.label() })
        }).collect::<Vec<_>>(),
    }))
}
