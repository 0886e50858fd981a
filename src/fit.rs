//! `ptm fit`: least-squares PTM per texel from a stored sample stack or an RTI image stack.
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_fit::images::{read_image_stack, Decoding};
use ptm_fit::solve::{fit_stack, ErrorStats, FitOptions, FitReport, Weight};
use ptm_fit::SampleStack;
use ptm_format::atomic::Transaction;
use ptm_format::hp::encode_hp_lrgb;
use ptm_format::{Basis, SaveOptions};
use serde_json::{json, Value};

/// `ptm fit --basis` and `ptm bake --fit`: the polynomial basis (`ptm_format::Basis`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum BasisArg {
    Ptm6,
    Ptm11,
}

impl From<BasisArg> for Basis {
    fn from(b: BasisArg) -> Basis {
        match b {
            BasisArg::Ptm6 => Basis::Ptm6,
            BasisArg::Ptm11 => Basis::Ptm11,
        }
    }
}

/// `--link`: K = p(u, v) or K = σ(p(u, v)).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkArg {
    /// K = p(u, v): the patent's PTM, least squares.
    Identity,
    /// K = 1/(1 + e^−p(u, v)), maximum likelihood: follows cloth's step-like shadows.
    Logistic,
}

impl From<LinkArg> for ptm_format::Link {
    fn from(l: LinkArg) -> Self {
        match l {
            LinkArg::Identity => ptm_format::Link::Identity,
            LinkArg::Logistic => ptm_format::Link::Logistic,
        }
    }
}

/// `--uv`: where a light direction lands in the polynomial's (u, v) plane.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum UvArg {
    /// (u, v) = (l·T, l·B), the patent's and HP's projection.
    Projected,
    /// (u, v) = (θ/(π/2))·(cos φ, sin φ): equal steps of elevation are equal steps of (u, v).
    Hemispherical,
}

impl From<UvArg> for ptm_format::UvMap {
    fn from(u: UvArg) -> Self {
        match u {
            UvArg::Projected => ptm_format::UvMap::Projected,
            UvArg::Hemispherical => ptm_format::UvMap::Hemispherical,
        }
    }
}

/// The model and solver flags shared by `ptm fit` and `ptm bake --fit`.
#[derive(clap::Args, Clone, Debug)]
pub struct ModelArgs {
    /// Link from polynomial to K. The default measured best on every built-in swatch
    /// (README, "What accuracy costs"); `--link identity --uv projected` is the patent's PTM.
    #[arg(long, value_enum, default_value = "logistic")]
    pub link: LinkArg,
    /// Map from light direction to (u, v).
    #[arg(long, value_enum, default_value = "hemispherical")]
    pub uv: UvArg,
    /// Logistic link: Newton stops when the decrement falls below TOL per unit light weight.
    #[arg(long, value_name = "TOL", default_value_t = ptm_fit::logistic::DEFAULT_TOLERANCE)]
    pub tolerance: f64,
    /// Logistic link: at most N Newton iterations per texel (texels that hit it are counted).
    #[arg(long, value_name = "N", default_value_t = ptm_fit::logistic::DEFAULT_MAX_ITERATIONS)]
    pub max_iterations: u32,
    /// Write no MIP levels (a plain scanline file; renderers then average coefficients, which
    /// is exact only for the identity link).
    #[arg(long)]
    pub no_mips: bool,
}

impl ModelArgs {
    /// Fills the model fields of `opts`.
    pub fn apply(&self, opts: &mut FitOptions) {
        opts.link = self.link.into();
        opts.uv = self.uv.into();
        opts.tolerance = self.tolerance;
        opts.max_iterations = self.max_iterations;
        opts.mips = !self.no_mips;
    }
}

/// The `--json` object of a logistic fit's statistics (null for the identity link).
pub fn logistic_json(r: &FitReport) -> Value {
    match &r.logistic {
        None => Value::Null,
        Some(s) => json!({
            "iterations_mean": s.iterations_mean,
            "iterations_max": s.iterations_max,
            "not_converged_texels": s.not_converged,
            "separable_texels": s.separable,
            "constant_texels": s.constant,
            "lambda": s.lambda,
            "ridge_absolute": s.ridge,
            "tolerance": s.tolerance,
            "max_iterations": s.max_iterations,
            "kernel": s.kernel,
        }),
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum WeightArg {
    /// Every light counts the same.
    Uniform,
    /// Weight sin(elevation): errors at grazing lights, which carry less light, count less.
    Cosine,
}

#[derive(clap::Args)]
pub struct Args {
    /// Sample stack written by `ptm bake` (samples.exr). Omit with --images.
    pub input: Option<PathBuf>,
    /// Output PTM (EXR, `ptm.<monomial>` channels).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Polynomial basis: ptm6 (u², u, uv, v, v², 1) or ptm11 (cubic + u²v²).
    #[arg(long, value_enum, default_value = "ptm6")]
    pub basis: BasisArg,
    #[command(flatten)]
    pub model: ModelArgs,
    /// Weight of each light's squared error.
    #[arg(long, value_enum, default_value = "uniform")]
    pub weight: WeightArg,
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
    /// Keep N evenly spread lights out of the fit and report the RMS error of K on them.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub holdout: usize,
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
    #[arg(long, value_name = "channels|rgba", default_value = "channels", value_parser = crate::convert::parse_layout)]
    pub layout: ptm_format::Layout,
    /// Also write a 6-term map in HP's PTM 1.2 LRGB format (visibility 1 − K, 8-bit).
    #[arg(long, value_name = "OUT.ptm")]
    pub export_hp: Option<PathBuf>,
}

fn stats(s: &ErrorStats) -> Value {
    json!({ "mean": s.mean, "p99": s.p99, "max": s.max })
}

/// A number for the JSON: null where it is not finite (NaN, ±∞).
pub fn finite(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

pub fn run(args: &Args) -> anyhow::Result<Value> {
    let t_all = Instant::now();
    let basis: Basis = args.basis.into();
    if args.export_hp.is_some() && basis != Basis::Ptm6 {
        bail!("--export-hp: HP's .ptm format holds only the 6-term biquadratic; fit with --basis ptm6 to export it");
    }
    if args.export_hp.is_some()
        && (args.model.link != LinkArg::Identity || args.model.uv != UvArg::Projected)
    {
        bail!(
            "--export-hp: HP's .ptm format is a polynomial in the projected (u, v) = (l·T, l·B); \
             a {} PTM with {} (u, v) cannot be written in it. Fit with --link identity --uv projected to export",
            ptm_format::Link::from(args.model.link).name(),
            ptm_format::UvMap::from(args.model.uv).name()
        );
    }
    // Every output is checked before the work (an output that is an input, two outputs that
    // are one file, a missing directory) and all are published together at the end.
    let mut outputs = match args.layout {
        ptm_format::Layout::Channels => vec![args.output.clone()],
        ptm_format::Layout::Rgba => ptm_format::layout::rgba_paths(&args.output, args.basis.into()),
    };
    outputs.extend(args.export_hp.iter().cloned());
    let mut inputs = Vec::new();
    inputs.extend(args.input.as_deref().map(|p| ("input stack", p)));
    inputs.extend(args.lights.as_deref().map(|p| ("light file", p)));
    // A bad pattern is left for the reader to explain.
    let image_paths: Vec<PathBuf> = match args.images.as_deref().map(glob::glob) {
        Some(Ok(paths)) => paths.filter_map(Result::ok).collect(),
        _ => Vec::new(),
    };
    inputs.extend(image_paths.iter().map(|p| ("image", p.as_path())));
    let output_paths: Vec<&std::path::Path> = outputs.iter().map(PathBuf::as_path).collect();
    crate::outputs::refuse_inputs(&output_paths, &inputs)?;
    let mut tx = Transaction::new(&outputs)?;
    let t0 = Instant::now();
    let mut images = Value::Null;
    let mut samples = None;
    let (stack, source) = match (&args.input, &args.images) {
        (Some(_), Some(_)) => bail!("give either a sample stack or --images, not both"),
        (None, None) => bail!("nothing to fit: give a sample stack (samples.exr) or --images 'dir/*.png' --lights file.lp"),
        (Some(p), None) => (
            SampleStack::read(p).with_context(|| format!("reading {}", p.display()))?,
            p.display().to_string(),
        ),
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
            if !info.unused.is_empty() {
                eprintln!(
                    "ptm fit: warning: {} images are not listed in {} and were ignored",
                    info.unused.len(),
                    lp.display()
                );
            }
            images = json!({ "decoding": decoding.name(), "srgb_decoded": info.srgb_decoded,
                             "linear": info.linear });
            samples = Some(image_samples(decoding, &info));
            (stack, pattern.clone())
        }
    };
    let t_read = t0.elapsed().as_secs_f64();
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
    let mut opts = FitOptions {
        basis,
        weight: match args.weight {
            WeightArg::Uniform => Weight::Uniform,
            WeightArg::Cosine => Weight::Cosine,
        },
        regularize: args.regularize,
        rcond: args.rcond,
        strict: args.strict,
        skip_bad: args.skip_bad,
        holdout: args.holdout,
        ..FitOptions::new(basis)
    };
    args.model.apply(&mut opts);
    let (ptm, mut report) = fit_stack(&stack, &opts)?;
    report.samples = samples;
    drop(stack);
    for w in &report.warnings {
        eprintln!("ptm fit: warning: {}", crate::errors::fit_warning(w));
    }
    let t1 = Instant::now();
    let save = SaveOptions {
        half: args.half,
        report: Some(&report),
        error_map: args.error_map,
    };
    let files = ptm_format::layout::encode(&ptm, &args.output, &save, args.layout)
        .with_context(|| format!("writing {}", args.output.display()))?;
    for (p, bytes) in &files {
        tx.add(p)?; // the renderer layout's error-map file, when there is one
        tx.stage_bytes(p, bytes)?;
    }
    let files: Vec<PathBuf> = files.into_iter().map(|(p, _)| p).collect();
    let hp = match &args.export_hp {
        Some(p) => {
            let (bytes, e) = encode_hp_lrgb(&ptm, p, None)
                .with_context(|| format!("writing {}", p.display()))?;
            tx.stage_bytes(p, &bytes)?;
            Some((p, e))
        }
        None => None,
    };
    tx.commit()?;
    ptm_format::layout::remove_stale_errors(&args.output, args.layout, &files);
    let t_write = t1.elapsed().as_secs_f64();
    let half_bound = args.half.then(|| ptm.half_error_bound());
    print_summary(&report, &files, half_bound);
    let hp = match hp {
        Some((p, e)) => {
            eprintln!(
                "ptm fit: wrote {} (HP PTM 1.2 LRGB, visibility 1 − K; 8-bit quantisation adds at most {:.2e} to K, {:.2e} on average)",
                p.display(),
                e.max_error,
                e.mean_error
            );
            json!({ "path": crate::outputs::json_path(p), "quantisation_error_max": e.max_error, "quantisation_error_mean": e.mean_error,
                    "scales": e.scales, "biases": e.biases })
        }
        None => Value::Null,
    };
    let mut out = json!({
        "input": source,
        "output": crate::outputs::json_path(&args.output),
        "layout": args.layout.name(),
        "files": files.iter().map(|p| crate::outputs::json_path(p)).collect::<Vec<_>>(),
        "basis": basis.name(),
        "link": ptm.link.name(),
        "uv": ptm.uv.name(),
        "mip_levels": report.mip_levels,
        "logistic": logistic_json(&report),
        "width": ptm.width,
        "height": ptm.height,
        "texels": report.texels,
        "masked_texels": report.masked,
        "lights": report.lights,
        "lights_fit": report.lights_fit,
        "holdout_lights": report.holdout_lights,
        "coefficients": report.coefficients,
        "rank": report.rank,
        "condition_number": finite(report.cond),
        "cutoff": report.cutoff,
        "rcond": report.rcond,
        "singular_values": report.singular_values,
        "solver": report.solver,
        "weight": opts.weight.name(),
        "warnings": crate::errors::fit_warnings(&report.warnings),
        "rms_error": stats(&report.rms),
        "max_error": report.max.as_ref().map(stats),
        "holdout_rms_error": report.holdout.as_ref().map(stats),
        "skipped_samples": report.skipped_samples,
        "rank_deficient_texels": report.rank_deficient_texels,
        "storage": if args.half { "half" } else { "float32" },
        "half_error_bound": half_bound,
        "hp_export": hp,
        "images": images,
        "seconds": t_all.elapsed().as_secs_f64(),
        "seconds_read": t_read,
    });
    stage_seconds(&mut out, &report.seconds);
    out["seconds_write"] = json!(t_write);
    Ok(out)
}

/// Adds the fit's stages to a JSON object as `seconds_<stage>` (spaces as `_`: `"mip levels"`
/// → `seconds_mip_levels`), the one naming every subcommand's timings use.
pub fn stage_seconds(out: &mut Value, stages: &[(&str, f64)]) {
    for (stage, s) in stages {
        out[format!("seconds_{}", stage.replace(' ', "_"))] = json!(s);
    }
}

fn print_summary(r: &FitReport, files: &[PathBuf], half_bound: Option<f64>) {
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
        "ptm fit: residual over {} fitting lights: RMS mean {:.4}, p99 {:.4}{}",
        r.lights_fit,
        r.rms.mean,
        r.rms.p99,
        r.max
            .map(|m| format!("; max |error| p99 {:.4}", m.p99))
            .unwrap_or_default()
    );
    if let Some(h) = r.holdout {
        eprintln!(
            "ptm fit: hold-out RMS error of K on {} unseen lights: mean {:.4}, p99 {:.4}",
            r.holdout_lights.len(),
            h.mean,
            h.p99
        );
    }
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
fn image_samples(decoding: Decoding, info: &ptm_fit::images::ImageStackInfo) -> String {
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
