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
use ptm_fit::{Basis, Link, UvMap, Weight};
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

/// The (link, (u, v) map) pairs: the patent's plain PTM first, `ptm fit`'s default last.
pub(crate) const MODELS: [(Link, UvMap); 4] = [
    (Link::Identity, UvMap::Projected),
    (Link::Identity, UvMap::Hemispherical),
    (Link::Logistic, UvMap::Projected),
    (Link::Logistic, UvMap::Hemispherical),
];

fn plan(quick: bool) -> Plan {
    let s = |dirs, spp, res, basis, weight, (link, uv): (Link, UvMap)| Setting {
        dirs,
        spp,
        res,
        basis,
        weight,
        link,
        uv,
    };
    let (u, c) = (Weight::Uniform, Weight::Cosine);
    let (p6, p11) = (Basis::Ptm6, Basis::Ptm11);
    let (plain, default) = (MODELS[0], MODELS[3]);
    let mut settings = Vec::new();
    // Rays against error for the plain PTM and for the default model; then all four models at
    // the bakes where the model, not the rays, limits the error.
    let (dirs, spps, res, all_four): (&[usize], &[u32], usize, &[usize]) = if quick {
        (&[16, 32, 64, 128], &[1, 4, 16], 32, &[64])
    } else {
        (&[16, 64, 256, 1024], &[1, 4, 16], 64, &[64, 256, 1024])
    };
    for &d in dirs {
        for &spp in spps {
            for m in [plain, default] {
                settings.push(s(d, spp, res, p6, u, m));
            }
        }
    }
    let spp = if quick { 4 } else { 16 };
    for &d in all_four {
        for basis in [p6, p11] {
            for m in MODELS {
                settings.push(s(d, spp, res, basis, u, m));
            }
        }
    }
    let mid = all_four[all_four.len() / 2];
    for basis in [p6, p11] {
        for m in [plain, default] {
            settings.push(s(mid, spp, res, basis, c, m));
        }
    }
    for m in [plain, default] {
        settings.push(s(mid, spp, res / 2, p6, u, m));
    }
    // Each setting once (the sweeps overlap), in first-seen order.
    let mut seen = Vec::new();
    settings.retain(|x| {
        let new = !seen.contains(x);
        if new {
            seen.push(x.clone());
        }
        new
    });
    if quick {
        Plan {
            truth_res: 32,
            truth_spp: 32,
            test_lights: 32,
            settings,
            spp: 4,
        }
    } else {
        Plan {
            truth_res: 64,
            truth_spp: 128,
            test_lights: 64,
            settings,
            spp: 8,
        }
    }
}

/// The 1-minute load average (Linux `/proc/loadavg`), or "unknown": how busy the machine was
/// while the report timed things.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_owned))
        .unwrap_or_else(|| "unknown".into())
}

pub fn run(args: &Args) -> Result<serde_json::Value> {
    let started = Instant::now();
    let load_at_start = load_average();
    let plan = plan(args.quick);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let test = study::test_lights(plan.test_lights)?;
    let mut md = format!(
        "# ptm report{}\n\nRegenerate with `ptm report{} -o {}`. Machine: {} cores. Error is |K_fit − K_true| \
         on {} held-out directions (Fibonacci above 5°, turned 0.7 rad so none is a training light), over \
         covered texels; K_true is the mean of two independent bakes at {}² texels and {} samples per texel each; K_fit is clamped to [0, 1] \
         as a renderer uses it. Seconds are bake (scene, primary hits, shadow rays; one bake serves every \
         fit of the same lights, spp and texels) plus the streaming fit (accumulate + solve, MIP levels \
         not fitted), on all cores. Each setting names its link (identity: K = p, least squares; \
         logistic: K = σ(p), maximum likelihood) and (u, v) map (projected or hemispherical).\n\n",
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
    let mut models = Table::new(
        "models",
        &[
            "swatch",
            "bake",
            "RMS identity·projected",
            "RMS identity·hemispherical",
            "RMS logistic·projected",
            "RMS logistic·hemispherical",
            "fit s identity·projected",
            "fit s identity·hemispherical",
            "fit s logistic·projected",
            "fit s logistic·hemispherical",
            "bake s",
            "logistic·hemispherical vs identity·projected",
        ],
    );
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
        // One bake per (lights, spp, texels), every setting that shares it fitted from it.
        let mut keys = Vec::new();
        for s in &plan.settings {
            if !keys.contains(&s.bake_key()) {
                keys.push(s.bake_key());
            }
        }
        for key in keys {
            let group: Vec<Setting> = plan
                .settings
                .iter()
                .filter(|s| s.bake_key() == key)
                .cloned()
                .collect();
            let c = coarse.entry(key.2).or_insert_with(|| truth.at(key.2));
            for o in study::run_settings(&swatch, &truth, c, &group)? {
                eprintln!(
                    "report: {name}: {:<70} bake {:>7.3} s  fit {:>7.3} s  rms {:.4}",
                    o.setting.label(),
                    o.bake_s,
                    o.fit_s,
                    o.errors.rms
                );
                outcomes.push(o);
            }
        }
        let front = pareto(&outcomes);
        let mut t = Table::new(
            format!("study_{name}"),
            &[
                "lights",
                "spp",
                "texels",
                "basis",
                "weight",
                "link",
                "uv",
                "bake s",
                "fit s",
                "RMS err K",
                "p99 err K",
                "max err K",
                "K outside [0,1]",
                "Newton iterations mean/max",
                "separable/constant texels",
                "Pareto",
            ],
        );
        for (i, o) in outcomes.iter().enumerate() {
            let s = &o.setting;
            let (iters, sep) = match &o.logistic {
                Some(l) => (
                    format!("{:.1}/{}", l.iterations_mean, l.iterations_max),
                    format!("{}/{}", l.separable, l.constant),
                ),
                None => ("-".into(), "-".into()),
            };
            t.push(vec![
                s.dirs.to_string(),
                s.spp.to_string(),
                format!("{}²", s.res),
                s.basis.name().into(),
                s.weight.name().into(),
                s.link.name().into(),
                s.uv.name().into(),
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
                iters,
                sep,
                if front.contains(&i) {
                    "★".into()
                } else {
                    String::new()
                },
            ]);
        }
        // Every bake and basis measured under all four models: one row of the model table.
        for o in outcomes.iter().filter(|o| {
            (o.setting.link, o.setting.uv) == MODELS[0] && o.setting.weight == Weight::Uniform
        }) {
            let same = |m: (Link, UvMap)| {
                outcomes.iter().find(|x| {
                    x.setting
                        == Setting {
                            link: m.0,
                            uv: m.1,
                            ..o.setting.clone()
                        }
                })
            };
            let four: Vec<&Outcome> = MODELS.iter().filter_map(|&m| same(m)).collect();
            if four.len() < MODELS.len() {
                continue;
            }
            let mut row = vec![
                name.clone(),
                format!(
                    "{} lights, spp {}, {}², {}",
                    o.setting.dirs,
                    o.setting.spp,
                    o.setting.res,
                    o.setting.basis.name()
                ),
            ];
            row.extend(four.iter().map(|x| g3(x.errors.rms)));
            row.extend(four.iter().map(|x| g3(x.fit_s)));
            row.push(g3(o.bake_s));
            row.push(format!(
                "{:.0}%",
                100.0 * (1.0 - four[3].errors.rms / four[0].errors.rms)
            ));
            models.push(row);
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
        "### Link and (u, v) map\n\nThe same bake fitted four ways: K = p(u, v) by least squares (identity, the \
         patent's PTM) or K = σ(p(u, v)) by maximum likelihood (logistic, Newton per texel, ridge λ = {}), with \
         (u, v) the projection of the light on the tangent plane (projected) or its azimuthal-equidistant \
         map (hemispherical). Fit seconds are the streaming fit alone (accumulate + solve, no MIP levels); \
         the bake is shared. The last column is the logistic·hemispherical model's (`ptm fit`'s default) \
         reduction of RMS error against the plain PTM.\n\n{}\n",
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        models.markdown()
    );
    tables.push(models);
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
    let ridge_dirs = if args.quick { 64 } else { 256 };
    let ridge = stability::ridge(swatch, truth, plan.spp, ridge_dirs)?;
    let precision = stability::precision(swatch, truth, plan.spp, &scratch)?;
    let _ = std::fs::remove_dir_all(&scratch);
    let geometry = stability::geometry(&args.swatches[0], truth.res, plan.spp)?;
    let covered = truth.coverage.iter().filter(|&&c| c > 0.0).count();
    md += &format!(
        "## Stability on stiff and extreme cases\n\nOn {} at {}² texels ({} covered), {} samples per texel.\n\n\
         ### Light layouts\n\nRank and condition number of the (weighted) design matrix, what `ptm fit` \
         reports, and the error on the held-out lights, for the plain PTM (identity link, projected (u, v)) \
         and `ptm fit`'s default (logistic link, hemispherical (u, v)). Rank-deficient layouts get the \
         minimum-norm (truncated SVD) solution under the identity link: finite, small coefficients, with \
         the undetermined directions named; under the logistic link the ridge λ = {} holds the undetermined \
         directions (and the separable texels, whose unregularised optimum lies at infinity) finite. \
         Newton's iterations are per covered texel; the cap is {}.\n\n{}\n\
         ### Ridge λ of the logistic link\n\nFibonacci {} lights above 5°, the ridge λ relative to the mean \
         eigenvalue of AᵀΩA (default {}), against the identity link's least-squares fit of the same bake. A \
         separable texel is one whose samples a polynomial of the basis splits exactly into lit and \
         occluded (its likelihood has no finite maximum); a constant texel is always lit or always occluded.\n\n{}\n\
         ### Precision\n\n{}\n### Geometry\n\n{}\n",
        args.swatches[0],
        truth.res,
        covered,
        plan.spp,
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        ptm_fit::logistic::DEFAULT_MAX_ITERATIONS,
        layouts.markdown(),
        ridge_dirs,
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        ridge.markdown(),
        precision.markdown(),
        geometry.markdown()
    );
    tables.extend([layouts, ridge, precision, geometry]);

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
        "\n_Generated in {:.0} s; load average {} at the start, {} at the end (other work on the \
         machine inflates the seconds, not the errors, which are deterministic)._\n",
        started.elapsed().as_secs_f64(),
        load_at_start,
        load_average()
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
