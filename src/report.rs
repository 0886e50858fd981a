//! `ptm report`: the measured study of `ptm-report` written into a folder — what accuracy each
//! bake and fit setting buys and what it costs (error of K on held-out lights against seconds,
//! with the Pareto front), and how the tool behaves on stiff and extreme cases. This module
//! parses the arguments, runs the study, and writes its typed results: Markdown, the CSV behind
//! every table, and PNG plots.

mod plot;
mod sheet;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use ptm_format::atomic::Transaction;
use ptm_report::{g3, Options, Report};

use crate::json;

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

/// The 1-minute load average (Linux `/proc/loadavg`), or "unknown": how busy the machine was
/// while the report timed things.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_owned))
        .unwrap_or_else(|| "unknown".into())
}

/// `ptm report`: runs the study, then writes its figures, CSVs and `report.md` into `--out`;
/// returns what `--json` prints.
pub fn run(args: &Args) -> Result<json::Report> {
    let started = Instant::now();
    let load_at_start = load_average();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let md_path = args.out.join("report.md");
    let plot_path = args.out.join("error_vs_time.png");
    let sheet_path = args.out.join("contact_sheet.png");
    // The fixed names are checked before the study (minutes); every file is published at the
    // end, all or none.
    drop(Transaction::new(&[&md_path, &plot_path, &sheet_path])?);
    let scratch = args.out.join(".scratch");
    std::fs::create_dir_all(&scratch)?;
    let opts = Options {
        quick: args.quick,
        swatches: args.swatches.clone(),
        scratch: scratch.clone(),
    };
    let report = ptm_report::run(&opts, &mut |line| eprintln!("report: {line}"));
    let _ = std::fs::remove_dir_all(&scratch);
    let report = report?;

    let tables = report.tables();
    let csv_paths: Vec<PathBuf> = tables
        .all()
        .map(|t| args.out.join(format!("{}.csv", t.name)))
        .collect();
    let mut paths = vec![md_path.clone(), plot_path.clone(), sheet_path.clone()];
    paths.extend(csv_paths.iter().cloned());
    let mut tx = Transaction::new(&paths)?;
    tx.stage_bytes(&plot_path, &plot::error_vs_time(&report.swatches)?)?;
    tx.stage_bytes(&sheet_path, &sheet::contact_sheet(&report.contact_sheet)?)?;
    for (t, path) in tables.all().zip(&csv_paths) {
        tx.stage_bytes(path, t.csv().as_bytes())?;
    }
    let mut md = markdown(args, &report, &tables);
    md += &format!(
        "\n_Generated in {:.0} s; load average {} at the start, {} at the end (other work on the \
         machine inflates the seconds, not the errors, which are deterministic)._\n",
        started.elapsed().as_secs_f64(),
        load_at_start,
        load_average()
    );
    tx.stage_bytes(&md_path, md.as_bytes())?;
    tx.commit()?;
    eprintln!(
        "report: wrote {} ({:.0} s)",
        md_path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(json::Report {
        report: json::path(&md_path),
        plot: json::path(&plot_path),
        contact_sheet: json::path(&sheet_path),
        csv: json::paths(&csv_paths),
        seconds: started.elapsed().as_secs_f64(),
        swatches: report
            .swatches
            .iter()
            .map(|s| {
                let best = s.best();
                json::ReportSwatch {
                    swatch: s.name.clone(),
                    settings: s.outcomes.len(),
                    best_rms: best.errors.rms,
                    best: best.setting.label(),
                }
            })
            .collect(),
    })
}

/// `report.md` without its closing line: the prose around every table.
fn markdown(args: &Args, report: &Report, tables: &ptm_report::Tables) -> String {
    let plan = &report.plan;
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
    md += "## Swatches under a low light\n\nEvery builtin swatch at its default parameters, visibility 1 − K \
           under one light at 20° elevation from azimuth 30°, each tile repeated 2×2 (a seam would show as a \
           line); dark red marks texels with no surface below them.\n\n![contact sheet](contact_sheet.png)\n\n\
           ## Error against run time\n\n![error against time](error_vs_time.png)\n\n";
    for (s, t) in report.swatches.iter().zip(&tables.studies) {
        md += &format!(
            "### {} ({} triangles, tile {} × {}; truth baked in {:.1} s, its own RMS sampling noise {})\n\n{}\n",
            s.name,
            s.triangles,
            g3(s.tile[0]),
            g3(s.tile[1]),
            s.truth_seconds,
            g3(s.truth_noise),
            t.markdown()
        );
    }
    md += &format!(
        "### Link and (u, v) map\n\nThe same bake fitted four ways: K = p(u, v) by least squares (identity, the \
         patent's PTM) or K = σ(p(u, v)) by maximum likelihood (logistic, Newton per texel, ridge λ = {}), with \
         (u, v) the projection of the light on the tangent plane (projected) or its azimuthal-equidistant \
         map (hemispherical). Fit seconds are the streaming fit alone (accumulate + solve, no MIP levels); \
         the bake is shared. The last column is the logistic·hemispherical model's (`ptm fit`'s default) \
         reduction of RMS error against the plain PTM.\n\n{}\n",
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        tables.models.markdown()
    );
    md += &format!(
        "### Which setting for which budget\n\nThe most accurate measured setting that fits each time budget \
         (the Pareto front of the plot, read off per swatch):\n\n{}\n",
        tables.recommendations.markdown()
    );
    let (res, spp, dirs) = report.plan.alternatives;
    md += &format!(
        "### Against the classic alternatives\n\n{}, trained on a Fibonacci dome of {dirs} lights \
         above 5° at {res}², spp {spp}, scored on the held-out lights against a truth baked twice at \
         {res}², spp {}: held-out RMS error of K (clamped), then each model's fit seconds; numbers per \
         texel in brackets. The PTMs and learned bases use the hemispherical (u, v); the learned \
         bases (k tables shared by the swatch, docs/model.md) are fitted without lights held out. \
         The horizon map is K = σ((h(φ) − elevation)/w), h linear (periodic) between 8 or 10 \
         azimuths and one edge width w, fitted per texel by maximum likelihood; AO \
         micro-shadowing is Filament's `computeMicroShadowing` with the bake's cosine-weighted \
         visibility (one number, not fitted).\n\n{}\n",
        if report.plan.alternatives_all {
            "Every parameterless builtin"
        } else {
            "The study's swatches"
        },
        spp * 4,
        tables.alternatives.markdown()
    );
    let st = &report.stability;
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
        st.swatch,
        st.res,
        st.covered,
        st.spp,
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        ptm_fit::logistic::DEFAULT_MAX_ITERATIONS,
        tables.layouts.markdown(),
        st.ridge_dirs,
        g3(ptm_fit::logistic::DEFAULT_RIDGE),
        tables.ridge.markdown(),
        tables.precision.markdown(),
        tables.geometry.markdown()
    );
    md += &format!(
        "## Runtime: soft shadows\n\nOn {}. Times are wall clock around submit + wait (on lavapipe the \
         \"GPU\" is this machine's CPU; ratios carry over to a real GPU, absolute figures do not).\n\n\
         ### Each blur method against the Monte Carlo ground truth\n\nA leafy 512² caster 0.6 above a \
         ptm11 cloth, one light 2 above it: a sphere, or a rectangle facing down; error in linear \
         radiance (the light gives about 1 at the centre) against a CPU Monte Carlo integration over \
         the true light (the sphere, or the uniform rectangle weighted by the irradiance each patch \
         gives) with exact ray–caster hits. A sphere asks for the disc kernel: `explicit` samples the \
         disc the ground truth integrates (its error is sampling); `sat` and `separable` use a box of \
         the same half-width, `mip` a blend of power-of-two boxes. A rectangle asks for the box of its \
         own sides, which `sat` sums exactly and `explicit` samples; `mip` blurs a square of the \
         longer side.\n\n{}\n\
         ### Extreme cases\n\nA half-plane caster edge (opaque for x < 0, 8 × 8 units) over a strip of \
         cloth; opacity = 1 − radiance/radiance without caster along the strip. The analytic profile is \
         the box (sat) or disk (explicit) average of the half-plane around the point where the ray to the \
         light centre meets the caster plane; the two pixels over the edge texel are skipped.\n\n{}\n",
        report.runtime.adapter,
        tables.blur.markdown(),
        tables.extremes.markdown()
    );
    md
}
