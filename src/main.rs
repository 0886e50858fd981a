//! `ptm`: bake, fit and render occlusion polynomial texture maps of cloth swatches.
//!
//! Glue only: one module per subcommand over the library crates. Only this binary knows clap,
//! stdout and exit codes. With `--json` a subcommand prints exactly one JSON object on stdout;
//! human-readable progress and messages always go to stderr.

mod args;
mod auto;
mod bake;
mod batch;
mod convert;
mod errors;
mod eval;
mod fit;
mod garment;
mod json;
mod merge;
mod outputs;
mod preview;
mod report;
mod shard;
mod swatch;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "ptm",
    version,
    about = "Bake, fit and render occlusion PTMs of cloth swatches"
)]
struct Cli {
    /// Print one JSON object with timings, counts and diagnostics on stdout.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Ray-trace a tileable swatch from a dome of lights: per texel and light the occluded
    /// fraction K (a sample stack, or with --fit a PTM).
    Bake(bake::Args),
    /// Fit a PTM per texel (K as a polynomial in the light's (u, v)): logistic maximum
    /// likelihood by default, least squares with --link identity.
    Fit(fit::Args),
    /// Render the swatch plane under area lights on the GPU, shaded by 1 − K of a PTM and the
    /// soft shadow of a planar caster.
    Preview(Box<preview::Args>),
    /// Generate a procedural tileable swatch as an OBJ file.
    Swatch(swatch::Args),
    /// Measured study: error of K against run time per setting, and stiff/extreme cases.
    Report(report::Args),
    /// Assemble the parts of a farm bake (`ptm bake --shard I/N`) into the stack or PTM.
    Merge(merge::Args),
    /// Run a manifest of bakes locally, or write a Slurm array job for them (--slurm DIR).
    Batch(batch::Args),
    /// Rewrite a PTM in the other layout (renderer RGB(A) parts ↔ named channels), losslessly.
    Convert(convert::Args),
    /// K of every texel of a PTM (any basis) for each light of an .lp file, written as a sample
    /// stack in the bake's layout: score a PTM against any held-out bake.
    Eval(eval::Args),
}

fn main() -> ExitCode {
    // Mesa's implicit Vulkan layer VK_LAYER_MESA_device_select connects to Wayland to pick a
    // default GPU; without a session (no XDG_RUNTIME_DIR, as on headless machines) libwayland
    // prints an error for every instance. With no display there is nothing to select by, so
    // skip the layer. Set here, before any thread exists.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none()
        && std::env::var_os("NODEVICE_SELECT").is_none()
    {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    // `--json` is global: seen before parsing so that argument errors are JSON too.
    let json = std::env::args_os()
        .skip(1)
        .take_while(|a| a != "--")
        .any(|a| a == "--json");
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e, json),
    };
    // Each subcommand returns its `--json` type (src/json.rs).
    let result = match &cli.command {
        Command::Bake(a) => bake::run(a).and_then(|r| json::to_value(&r)),
        Command::Fit(a) => fit::run(a).and_then(|r| json::to_value(&r)),
        Command::Preview(a) => preview::run(a).and_then(|r| json::to_value(&r)),
        Command::Swatch(a) => swatch::run(a).and_then(|r| json::to_value(&r)),
        Command::Report(a) => report::run(a).and_then(|r| json::to_value(&r)),
        Command::Merge(a) => merge::run(a).and_then(|r| json::to_value(&r)),
        Command::Batch(a) => batch::run(a).and_then(|r| json::to_value(&r)),
        Command::Convert(a) => convert::run(a).and_then(|r| json::to_value(&r)),
        Command::Eval(a) => eval::run(a).and_then(|r| json::to_value(&r)),
    };
    match result {
        Ok(report) => {
            if cli.json {
                println!("{report}");
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            let message = errors::explain(&e);
            eprintln!("ptm: error: {message}");
            if cli.json {
                let input = error_input(&e).or_else(|| cli.command.input());
                print_failure(message, error_kind(&e), input);
            }
            ExitCode::FAILURE
        }
    }
}

/// A clap error: help and version print as usual (exit 0); an argument error prints clap's
/// message on stderr and, with `--json`, one `error` object on stdout; exit code 2.
fn usage_error(e: clap::Error, json: bool) -> ExitCode {
    use clap::error::{ContextKind, ContextValue};
    if !e.use_stderr() {
        let _ = e.print();
        return ExitCode::SUCCESS;
    }
    if json {
        let text = e.render().to_string();
        // clap's message is the paragraph before the usage line.
        let message = text
            .lines()
            .take_while(|l| !l.trim().is_empty())
            .map(str::trim)
            .collect::<Vec<_>>()
            .join(" ")
            .trim_start_matches("error: ")
            .to_string();
        let input = [
            ContextKind::InvalidArg,
            ContextKind::InvalidSubcommand,
            ContextKind::InvalidValue,
        ]
        .into_iter()
        .find_map(|k| match e.get(k) {
            Some(ContextValue::String(s)) => Some(s.clone()),
            Some(ContextValue::Strings(v)) => Some(v.join(" ")),
            _ => None,
        });
        print_failure(message, "usage", input);
    }
    let _ = e.print();
    ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2))
}

/// Prints the one `error` object of a failed `--json` run on stdout.
fn print_failure(message: String, kind: &'static str, input: Option<String>) {
    let failure = json::Failure {
        error: json::ErrorInfo {
            message,
            kind,
            input,
        },
    };
    match json::to_value(&failure) {
        Ok(v) => println!("{v}"),
        Err(e) => eprintln!("ptm: error: the error object: {e}"),
    }
}

/// What failed, in one word for `--json`: `io` (an OS error reading or writing a file), `gpu`
/// (no adapter, device or shader trouble), `embree` (the ray tracer), or `invalid` (an input
/// file or argument that ptm refuses; the message says which and why).
fn error_kind(e: &anyhow::Error) -> &'static str {
    for cause in e.chain() {
        if cause.is::<std::io::Error>() {
            return "io";
        }
        if let Some(r) = cause.downcast_ref::<ptm_runtime::Error>() {
            use ptm_runtime::Error as R;
            if matches!(
                r,
                R::NoAdapter(_) | R::Device { .. } | R::Gpu { .. } | R::Shader { .. }
            ) {
                return "gpu";
            }
        }
        if let Some(ptm_bake::Error::Embree(_)) = cause.downcast_ref::<ptm_bake::Error>() {
            return "embree";
        }
        let gpubake = cause
            .downcast_ref::<ptm_gpubake::Error>()
            .or_else(|| match cause.downcast_ref::<ptm_bake::Error>() {
                Some(ptm_bake::Error::Tracer(e)) => e.downcast_ref::<ptm_gpubake::Error>(),
                _ => None,
            });
        if let Some(g) = gpubake {
            use ptm_gpubake::Error as G;
            if matches!(
                g,
                G::NoRayQueries { .. } | G::Device { .. } | G::Lost { .. } | G::TooBig { .. }
            ) {
                return "gpu";
            }
        }
    }
    "invalid"
}

/// The file (or swatch spec) a library error names, innermost first.
fn error_input(e: &anyhow::Error) -> Option<String> {
    e.chain()
        .rev()
        .find_map(|cause| {
            if let Some(x) = cause.downcast_ref::<ptm_format::Error>() {
                use ptm_format::Error as F;
                return match x {
                    F::Io { path, .. }
                    | F::Format { path, .. }
                    | F::HpNeedsPtm6 { path, .. }
                    | F::HalfOverflow { path, .. }
                    | F::LightFile { path, .. } => Some(path.clone()),
                    F::Invalid(_) => None,
                };
            }
            if let Some(x) = cause.downcast_ref::<ptm_fit::Error>() {
                use ptm_fit::Error as F;
                return match x {
                    F::Io { path, .. }
                    | F::LightFile { path, .. }
                    | F::Format { path, .. }
                    | F::LightsBelowHorizon { lp: path, .. } => Some(path.clone()),
                    _ => None,
                };
            }
            if let Some(x) = cause.downcast_ref::<ptm_bake::Error>() {
                use ptm_bake::Error as B;
                return match x {
                    B::Io { path, .. } | B::InvalidMesh { path, .. } => Some(path.clone()),
                    _ => None,
                };
            }
            if let Some(x) = cause.downcast_ref::<ptm_swatches::Error>() {
                use ptm_swatches::Error as S;
                return match x {
                    S::InvalidMesh { path, .. } | S::Io { path, .. } => {
                        Some(path.display().to_string())
                    }
                    S::Draft { source_name, .. } => Some(source_name.clone()),
                    S::BadSpec { spec, .. } => Some(spec.clone()),
                    S::UnknownSwatch { name, .. } => Some(name.clone()),
                    S::InvalidParameter { swatch, .. }
                    | S::UnknownParameter { swatch, .. }
                    | S::Overlap { swatch, .. } => Some(swatch.clone()),
                    _ => None,
                };
            }
            if let Some(ptm_runtime::Error::Image { path, .. }) =
                cause.downcast_ref::<ptm_runtime::Error>()
            {
                return Some(path.clone());
            }
            None
        })
        // anyhow finds a context of this type anywhere in the chain.
        .or_else(|| e.downcast_ref::<outputs::Named>().map(|n| n.path.clone()))
}

impl Command {
    /// The subcommand's main input, named in a `--json` error when the error itself names none.
    fn input(&self) -> Option<String> {
        let path = |p: &std::path::Path| Some(p.display().to_string());
        match self {
            Command::Bake(a) => Some(a.swatch.clone()),
            Command::Fit(a) => match (&a.input, &a.images) {
                (Some(p), _) => path(p),
                (None, Some(g)) => Some(g.clone()),
                (None, None) => None,
            },
            Command::Preview(a) => a.ptm.as_deref().and_then(path),
            Command::Swatch(a) => Some(swatch::spec(a)),
            Command::Report(a) => path(&a.out),
            Command::Merge(a) => a.parts.first().and_then(|p| path(p)),
            Command::Batch(a) => path(&a.manifest),
            Command::Convert(a) => path(&a.input),
            Command::Eval(a) => path(&a.input),
        }
    }
}
