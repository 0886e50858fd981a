//! `ptm fit`: a PTM per texel (logistic maximum likelihood by default, least squares with the
//! identity link) from a stored sample stack or an RTI image stack.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_fit::images::{read_image_stack, Decoding, ImageStackInfo};
use ptm_fit::solve::{fit_stack, FitOptions, FitReport, Weight};
use ptm_fit::SampleStack;
use ptm_format::atomic::Transaction;
use ptm_format::hp::{encode_hp_lrgb, HpExport};
use ptm_format::{Basis, Layout, Link, Ptm, SaveOptions, UvMap};

use crate::args::{choice, ModelArgs};
use crate::auto::{self, default_holdout, parse_choice, BasisChoice, Chosen, AUTO_MARGIN};
use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// Sample stack written by `ptm bake` (samples.exr). Omit with --images.
    pub input: Option<PathBuf>,
    /// Output PTM: NAME.ptm.exr (`ptm.<monomial>` channels; with --layout rgba the parts
    /// NAME.ptm.c0.exr, … instead).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Basis: ptm6 (u², u, uv, v, v², 1), ptm11 (cubic + u²v²), or a basis learned from the
    /// stack, learned6 or learned11 (k tables over the hemispherical (u, v) square shared by
    /// the swatch, stored in the file; docs/model.md). `auto` fits ptm6, learned6, ptm11 and
    /// learned11 on the same lights, scores each on the same held-out lights and keeps the
    /// first (cheapest) within --auto-margin of the best.
    #[arg(long, value_name = "BASIS", value_parser = parse_choice, default_value = "ptm6")]
    pub basis: BasisChoice,
    /// With --basis auto: keep the cheapest candidate whose held-out error is at most
    /// (1 + MARGIN) × the best candidate's.
    #[arg(long, value_name = "MARGIN", default_value_t = AUTO_MARGIN)]
    pub auto_margin: f64,
    #[command(flatten)]
    pub model: ModelArgs,
    /// Weight of each light's squared error.
    #[arg(long, value_parser = choice::<Weight>(), default_value = "uniform")]
    pub weight: Weight,
    /// Ridge regularisation λ, relative to the mean eigenvalue of AᵀWA. Identity link: instead
    /// of truncation (default: none). Logistic link: default 1e-5, which keeps separable texels
    /// (always lit, always occluded, a clean step) finite.
    #[arg(long, value_name = "LAMBDA")]
    pub regularize: Option<f64>,
    /// Singular values below RCOND·σmax count as zero (their basis directions are undetermined).
    /// The default keeps every direction of any dome with condition number < 1000 and drops
    /// near-ring directions whose noise amplification made held-out error worse (docs/report).
    #[arg(long, default_value_t = ptm_fit::solve::DEFAULT_RCOND)]
    pub rcond: f64,
    /// Fail instead of warning when the light set cannot determine the basis well.
    #[arg(long)]
    pub strict: bool,
    /// Drop NaN or infinite samples (counted) instead of failing.
    #[arg(long)]
    pub skip_bad: bool,
    /// Keep N evenly spread lights out of the fit and report the RMS error of K on them: the
    /// error a render under an unseen light sees (the residual on the fitted lights is lower).
    /// Default: an eighth of the lights where the rest still number 4× the coefficients (from
    /// 27 lights for ptm6, 50 for ptm11), else none; 0 fits every light (the file of older
    /// versions).
    #[arg(long, value_name = "N")]
    pub holdout: Option<usize>,
    /// Also write K of the fitted PTM under one light as a grey PNG (K·255: white = occluded).
    #[arg(long, value_name = "FILE.png")]
    pub png_k: Option<PathBuf>,
    /// The light of --png-k (an index into the stack's lights). Default: the first held-out
    /// light, else light 0.
    #[arg(long, value_name = "I", requires = "png_k")]
    pub png_light: Option<usize>,
    /// Also write the per-texel RMS residual over the fitted lights as a grey PNG (black 0,
    /// white 0.25 or more).
    #[arg(long, value_name = "FILE.png")]
    pub png_error: Option<PathBuf>,
    /// Also write per-texel residual maps as channels `err.rms` and `err.max`.
    #[arg(long)]
    pub error_map: bool,
    /// Store half floats instead of float32 (the added error bound is reported).
    #[arg(long)]
    pub half: bool,
    /// Fit an RTI image stack instead (glob, e.g. 'dir/*.png'; white = lit, K = 1 − value).
    #[arg(long, value_name = "GLOB", requires = "lights")]
    pub images: Option<String>,
    /// With --images: take 8-bit values as they are instead of decoding them from sRGB to
    /// linear light before K = 1 − value (16-bit images are always taken as linear).
    #[arg(long, requires = "images")]
    pub raw_values: bool,
    /// `.lp` light file for --images (N, then `file x y z` per line).
    #[arg(long, value_name = "FILE.lp")]
    pub lights: Option<PathBuf>,
    /// Tile size W,H in swatch units for --images.
    #[arg(long, value_name = "W,H", value_delimiter = ',', default_values_t = [1.0, 1.0], allow_hyphen_values = true)]
    pub tile: Vec<f64>,
    /// File layout: channels (one `ptm.<monomial>` channel each) or rgba (the renderer layout:
    /// RGB(A) parts NAME.ptm.c0.exr, … that texture systems, OSL, MaterialX and Blender read).
    #[arg(long, value_name = "channels|rgba", hide_possible_values = true, value_parser = choice::<Layout>(), default_value = "channels")]
    pub layout: Layout,
    /// Also write a 6-term map in HP's PTM 1.2 LRGB format (visibility 1 − K, 8-bit).
    #[arg(long, value_name = "OUT.ptm")]
    pub export_hp: Option<PathBuf>,
}

/// `ptm fit`: checks the flags and every output, reads the stack (or the RTI images), fits,
/// writes the PTM (and the HP export) in one transaction; returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Fit> {
    let t_all = Instant::now();
    check_export(args)?;
    // Every output is checked before the work (an output that is an input, two outputs that
    // are one file, a missing directory) and all are published together at the end.
    let mut tx = destinations(args, args.basis.for_paths())?;
    let t0 = Instant::now();
    let input = read_input(args)?;
    let t_read = t0.elapsed().as_secs_f64();
    let dirs = input.stack.lights.dirs.clone();
    let (opts, holdout, ptm, report, auto) = match args.basis {
        BasisChoice::Fixed(basis) => {
            let (opts, holdout) = fit_options(args, &input.stack, basis);
            let (ptm, report) = fit(input.stack, &input.source, input.samples, &opts)?;
            (opts, holdout, ptm, report, None)
        }
        BasisChoice::Auto => {
            let (c, holdout) = choose(args, input.stack, &input.source, input.samples)?;
            tx = destinations(args, c.basis)?;
            (c.opts, holdout, c.ptm, c.report, Some(c.json))
        }
    };
    let t1 = Instant::now();
    let png_light = quick_look_light(args, &report, dirs.len())?;
    let pngs = quick_looks(args, &ptm, &report, png_light.map(|i| dirs[i]))?;
    let (files, hp) = write_outputs(args, &ptm, &report, tx, &pngs)?;
    let t_write = t1.elapsed().as_secs_f64();
    let half_bound = args.half.then(|| ptm.half_error_bound());
    print_summary(&report, &files, half_bound, holdout);
    for (p, _) in &pngs {
        eprintln!("ptm fit: wrote {}", p.display());
    }
    if let Some((p, e)) = &hp {
        eprintln!(
            "ptm fit: wrote {} (HP PTM 1.2 LRGB, visibility 1 − K; 8-bit quantisation adds at most {:.2e} to K, {:.2e} on average)",
            p.display(),
            e.max_error,
            e.mean_error
        );
    }
    let timing = Timing {
        all: t_all.elapsed().as_secs_f64(),
        read: t_read,
        write: t_write,
    };
    let mut out = fit_json(
        args,
        input.source,
        input.images,
        &ptm,
        report,
        &opts,
        files,
        half_bound,
        hp,
        timing,
    );
    out.holdout_default = holdout == Holdout::Default;
    out.auto = auto;
    out.png_k = args.png_k.as_deref().map(json::path);
    out.png_light = png_light;
    out.png_error = args.png_error.as_deref().map(json::path);
    Ok(out)
}

/// Where `--holdout`'s count came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Holdout {
    /// `--holdout N`.
    Given,
    /// The default: an eighth of the lights where the dome allows it ([`default_holdout`]).
    Default,
}

/// The light `--png-k` shows (checked against the stack's `lights`): `--png-light`, the
/// first held-out light, or light 0; `None` without `--png-k`.
fn quick_look_light(
    args: &Args,
    report: &FitReport,
    lights: usize,
) -> anyhow::Result<Option<usize>> {
    if args.png_k.is_none() {
        return Ok(None);
    }
    let i = args
        .png_light
        .or(report.holdout_lights.first().copied())
        .unwrap_or(0);
    if i >= lights {
        bail!(
            "--png-light {i}: the stack has lights 0 to {}",
            lights.saturating_sub(1)
        );
    }
    Ok(Some(i))
}

/// The quick-look PNGs and their bytes: `--png-k` under the light of direction `light`, and
/// `--png-error`. Row 0 is the top (y = H), as in the PTM's own maps.
fn quick_looks<'a>(
    args: &'a Args,
    ptm: &Ptm,
    report: &FitReport,
    light: Option<[f64; 3]>,
) -> anyhow::Result<Vec<(&'a Path, Vec<u8>)>> {
    let grey = |v: f32| {
        let g = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        [g, g, g, 255]
    };
    let mut maps: Vec<(&Path, Vec<u8>)> = Vec::new();
    if let (Some(path), Some(dir)) = (&args.png_k, light) {
        let px = (0..ptm.height)
            .flat_map(|y| (0..ptm.width).map(move |x| (x, y)))
            .flat_map(|(x, y)| grey(ptm.eval_dir(x, y, dir)))
            .collect();
        maps.push((path, px));
    }
    if let Some(path) = &args.png_error {
        let px = report
            .rms_map
            .iter()
            .flat_map(|&e| grey(e / 0.25))
            .collect::<Vec<u8>>();
        if px.len() != ptm.width * ptm.height * 4 {
            bail!("--png-error: this fit kept no per-texel residual map");
        }
        maps.push((path, px));
    }
    maps.into_iter()
        .map(|(path, px)| Ok((path, crate::preview::png_bytes(ptm.width, ptm.height, px)?)))
        .collect()
}

/// `--export-hp` needs what HP's format holds: the 6-term biquadratic in the projected (u, v)
/// with the identity link.
fn check_export(args: &Args) -> anyhow::Result<()> {
    if args.export_hp.is_some() && args.basis != BasisChoice::Fixed(Basis::Ptm6) {
        bail!("--export-hp: HP's .ptm format holds only the 6-term biquadratic; fit with --basis ptm6 to export it");
    }
    if args.export_hp.is_some()
        && (args.model.link != Link::Identity || args.model.uv != UvMap::Projected)
    {
        bail!(
            "--export-hp: HP's .ptm format is a polynomial in the projected (u, v) = (l·T, l·B); \
             a {} PTM with {} (u, v) cannot be written in it. Fit with --link identity --uv projected to export",
            args.model.link.name(),
            args.model.uv.name()
        );
    }
    Ok(())
}

/// Refuses an output that is an input (the stack, the `.lp`, an image) and checks every
/// destination: the PTM (or the renderer layout's parts) and the HP export.
fn destinations(args: &Args, basis: Basis) -> anyhow::Result<Transaction> {
    let mut outputs = match args.layout {
        Layout::Channels => vec![args.output.clone()],
        Layout::Rgba => ptm_format::layout::rgba_paths(&args.output, basis),
    };
    outputs.extend(args.export_hp.iter().cloned());
    outputs.extend(args.png_k.iter().chain(&args.png_error).cloned());
    let mut inputs = Vec::new();
    inputs.extend(args.input.as_deref().map(|p| ("input stack", p)));
    inputs.extend(args.lights.as_deref().map(|p| ("light file", p)));
    // A bad pattern is left for the reader to explain.
    let image_paths: Vec<PathBuf> = match args.images.as_deref().map(glob::glob) {
        Some(Ok(paths)) => paths.filter_map(Result::ok).collect(),
        _ => Vec::new(),
    };
    inputs.extend(image_paths.iter().map(|p| ("image", p.as_path())));
    let output_paths: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    crate::outputs::refuse_inputs(&output_paths, &inputs)?;
    Ok(Transaction::new(&outputs)?)
}

/// What is fitted: the stack, what it is called in messages, and for RTI images how their
/// values became K (for `--json` and for the PTM header's `ptm:samples`).
struct Input {
    stack: SampleStack,
    source: String,
    images: Option<json::Images>,
    samples: Option<String>,
}

/// Reads the sample stack, or the RTI image stack (`--images`, `--lights`, `--tile`).
fn read_input(args: &Args) -> anyhow::Result<Input> {
    match (&args.input, &args.images) {
        (Some(_), Some(_)) => bail!("give either a sample stack or --images, not both"),
        (None, None) => bail!("nothing to fit: give a sample stack (samples.exr) or --images 'dir/*.png' --lights file.lp"),
        (Some(p), None) => Ok(Input {
            stack: SampleStack::read(p).with_context(|| format!("reading {}", p.display()))?,
            source: p.display().to_string(),
            images: None,
            samples: None,
        }),
        (None, Some(pattern)) => {
            let lp = args.lights.as_ref().expect("clap requires --lights");
            if args.tile.len() != 2 || args.tile.iter().any(|&x| !(x.is_finite() && x > 0.0)) {
                bail!(
                    "--tile takes two positive finite sizes W,H, got {:?}",
                    args.tile
                );
            }
            let decoding = if args.raw_values {
                Decoding::Raw
            } else {
                Decoding::Srgb
            };
            let (stack, info) =
                read_image_stack(pattern, lp, [args.tile[0], args.tile[1]], decoding)?;
            for w in info.warnings(lp) {
                eprintln!("ptm fit: warning: {}", crate::errors::fit_warning(&w));
            }
            Ok(Input {
                stack,
                source: pattern.clone(),
                images: Some(json::Images {
                    decoding: decoding.name(),
                    srgb_decoded: info.srgb_decoded,
                    linear: info.linear,
                }),
                samples: Some(image_samples(decoding, &info)),
            })
        }
    }
}

/// The options `args` ask for over `stack`, and where the hold-out count came from.
fn fit_options(args: &Args, stack: &SampleStack, basis: Basis) -> (FitOptions, Holdout) {
    let (holdout, source) = match args.holdout {
        Some(n) => (n, Holdout::Given),
        None => (
            default_holdout(stack.lights.len(), basis.len()),
            Holdout::Default,
        ),
    };
    let mut opts = FitOptions {
        basis,
        weight: args.weight,
        regularize: args.regularize,
        rcond: args.rcond,
        strict: args.strict,
        skip_bad: args.skip_bad,
        holdout,
        ..FitOptions::new(basis)
    };
    args.model.apply(&mut opts);
    (opts, source)
}

/// `--basis auto` over a stored stack: every candidate of [`auto::AUTO_CANDIDATES`] fitted on the
/// same lights, the same ones held out (`auto::shared_holdout`), the first within
/// `--auto-margin` of the best kept (`auto::choose`).
fn choose(
    args: &Args,
    stack: SampleStack,
    source: &str,
    samples: Option<String>,
) -> anyhow::Result<(Chosen, Holdout)> {
    let holdout = auto::shared_holdout(source, stack.lights.len(), args.holdout)?;
    let mut chosen = auto::choose("ptm fit", source, holdout, args.auto_margin, |basis, h| {
        let (mut opts, _) = fit_options(args, &stack, basis);
        opts.holdout = h;
        fit_stack(&stack, &opts).map(|(ptm, report)| (opts, ptm, report))
    })?;
    drop(stack);
    chosen.report.samples = samples;
    for w in &chosen.report.warnings {
        eprintln!("ptm fit: warning: {}", crate::errors::fit_warning(w));
    }
    let from = if args.holdout.is_some() {
        Holdout::Given
    } else {
        Holdout::Default
    };
    Ok((chosen, from))
}

/// Refuses a stack with nothing to fit, says what is fitted, fits, and prints the fit's
/// warnings.
fn fit(
    stack: SampleStack,
    source: &str,
    samples: Option<String>,
    opts: &FitOptions,
) -> anyhow::Result<(Ptm, FitReport)> {
    if stack.coverage.iter().all(|&c| c <= 0.0) {
        bail!(
            "{source}: every one of its {}×{} texels is masked (coverage 0): there is nothing to \
             fit; was the swatch missed by the camera (check --tile and the mesh's position)?",
            stack.width,
            stack.height
        );
    }
    eprintln!(
        "ptm fit: {source}: {}×{} texels, {} lights{}",
        stack.width,
        stack.height,
        stack.lights.len(),
        if stack.uv.is_some() {
            " (per-texel directions)"
        } else {
            ""
        }
    );
    let (ptm, mut report) = fit_stack(&stack, opts)?;
    report.samples = samples;
    drop(stack);
    for w in &report.warnings {
        eprintln!("ptm fit: warning: {}", crate::errors::fit_warning(w));
    }
    Ok((ptm, report))
}

/// The HP export written and how much its quantisation changed K.
type Hp<'a> = (&'a Path, HpExport);

/// Encodes the PTM in its layout (and the HP export) and publishes them together; returns the
/// PTM's files and the export.
fn write_outputs<'a>(
    args: &'a Args,
    ptm: &Ptm,
    report: &FitReport,
    mut tx: Transaction,
    pngs: &[(&Path, Vec<u8>)],
) -> anyhow::Result<(Vec<PathBuf>, Option<Hp<'a>>)> {
    let save = SaveOptions {
        half: args.half,
        report: Some(report),
        error_map: args.error_map,
    };
    let files = ptm_format::layout::encode(ptm, &args.output, &save, args.layout)
        .with_context(|| format!("writing {}", args.output.display()))?;
    for (p, bytes) in &files {
        tx.add(p)?; // the renderer layout's error-map file, when there is one
        tx.stage_bytes(p, bytes)?;
    }
    let files: Vec<PathBuf> = files.into_iter().map(|(p, _)| p).collect();
    let hp = match &args.export_hp {
        Some(p) => {
            let (bytes, e) =
                encode_hp_lrgb(ptm, p, None).with_context(|| format!("writing {}", p.display()))?;
            tx.stage_bytes(p, &bytes)?;
            Some((p.as_path(), e))
        }
        None => None,
    };
    for (p, bytes) in pngs {
        tx.stage_bytes(p, bytes)?;
    }
    tx.commit()?;
    ptm_format::layout::remove_stale_errors(&args.output, args.layout, &files);
    Ok((files, hp))
}

/// Seconds of the whole run, of reading and of writing.
struct Timing {
    all: f64,
    read: f64,
    write: f64,
}

/// The object `--json` prints.
#[allow(clippy::too_many_arguments)]
fn fit_json(
    args: &Args,
    source: String,
    images: Option<json::Images>,
    ptm: &Ptm,
    report: FitReport,
    opts: &FitOptions,
    files: Vec<PathBuf>,
    half_bound: Option<f64>,
    hp: Option<Hp>,
    t: Timing,
) -> json::Fit {
    json::Fit {
        input: source,
        output: json::path(&args.output),
        layout: args.layout.name(),
        files: json::paths(&files),
        basis: opts.basis.name(),
        link: ptm.link.name(),
        uv: ptm.uv.name(),
        mip_levels: report.mip_levels,
        logistic: json::Logistic::of(&report),
        learned: json::Learned::of(&report),
        auto: None,
        width: ptm.width,
        height: ptm.height,
        texels: report.texels,
        masked_texels: report.masked,
        lights: report.lights,
        lights_fit: report.lights_fit,
        holdout_lights: report.holdout_lights,
        holdout_default: false,
        coefficients: report.coefficients,
        rank: report.rank,
        condition_number: json::finite(report.cond),
        cutoff: report.cutoff,
        rcond: report.rcond,
        singular_values: report.singular_values,
        solver: report.solver,
        weight: opts.weight.name(),
        warnings: crate::errors::fit_warnings(&report.warnings),
        rms_error: (&report.rms).into(),
        max_error: report.max.as_ref().map(Into::into),
        holdout_rms_error: report.holdout.as_ref().map(Into::into),
        skipped_samples: report.skipped_samples,
        rank_deficient_texels: report.rank_deficient_texels,
        storage: if args.half { "half" } else { "float32" },
        half_error_bound: half_bound,
        hp_export: hp.map(|(p, e)| json::HpExport {
            path: json::path(p),
            quantisation_error_max: e.max_error,
            quantisation_error_mean: e.mean_error,
            scales: e.scales,
            biases: e.biases,
        }),
        png_k: None,
        png_light: None,
        png_error: None,
        images,
        seconds: t.all,
        seconds_read: t.read,
        stages: json::Stages(report.seconds),
        seconds_write: t.write,
    }
}

fn print_summary(r: &FitReport, files: &[PathBuf], half_bound: Option<f64>, holdout: Holdout) {
    print_logistic("ptm fit", r);
    eprintln!(
        "ptm fit: {} rank {}/{}, condition number {:.3}, {}",
        r.basis.map_or("?", |b| b.name()),
        r.rank,
        r.coefficients,
        r.cond,
        r.solver
    );
    eprintln!(
        "ptm fit: training residual (on the {} lights the fit saw; understates the error): RMS \
         mean {:.4}, p99 {:.4}{}",
        r.lights_fit,
        r.rms.mean,
        r.rms.p99,
        r.max
            .map(|m| format!("; max |error| p99 {:.4}", m.p99))
            .unwrap_or_default()
    );
    match r.holdout {
        Some(h) => eprintln!(
            "ptm fit: error on {} held-out lights{} (what a render under a light the fit did not \
             see gets): RMS of K mean {:.4}, p99 {:.4}",
            r.holdout_lights.len(),
            if holdout == Holdout::Default {
                " (an eighth, by default; --holdout 0 fits them too)"
            } else {
                ""
            },
            h.mean,
            h.p99
        ),
        None => eprintln!(
            "ptm fit: no lights held out{}, so no error on unseen lights is measured (--holdout N)",
            if holdout == Holdout::Default {
                ": too few to spare (the default keeps 4 lights per coefficient in the fit)"
            } else {
                ""
            }
        ),
    }
    eprintln!(
        "ptm fit: reading it: K is the occluded fraction (0 lit, 1 shadowed), so an RMS error of \
         0.1 moves a texel's shading by about a tenth of the light's contribution; on held-out \
         lights `ptm report` measured 0.10–0.13 for logistic fits of a weave, 0.17–0.20 of a \
         knit, 0.16 of velvet and 0.21–0.23 for the plain PTM (docs/model.md); below about 0.12 \
         is as good as interpolating the stored lights"
    );
    if let Some(b) = half_bound {
        eprintln!("ptm fit: half floats change K by at most {b:.2e} anywhere on the unit disk");
    }
    eprintln!("ptm fit: wrote {}", crate::outputs::list(files));
}

/// One line on what the logistic fit did (nothing for the identity link).
pub fn print_logistic(who: &str, r: &FitReport) {
    if let Some(s) = &r.logistic {
        eprintln!(
            "{who}: logistic Newton: {:.1} iterations per texel on average (max {}), {} texels at the cap; {} separable and {} constant texels held finite by the ridge (lambda {:e})",
            s.iterations_mean, s.iterations_max, s.not_converged, s.separable, s.constant, s.lambda
        );
    }
}

/// How an RTI image stack's values became K, in words for the PTM header (`ptm:samples`).
fn image_samples(decoding: Decoding, info: &ImageStackInfo) -> String {
    match decoding {
        Decoding::Srgb => format!(
            "RTI images, K = 1 − value: {} 8-bit images decoded from sRGB to linear, {} taken as linear",
            info.srgb_decoded, info.linear
        ),
        Decoding::Raw => format!(
            "RTI images, K = 1 − value: {} images taken as stored (raw values, no sRGB decoding)",
            info.linear + info.srgb_decoded
        ),
    }
}
