//! `ptm`: bake, fit and render occlusion polynomial texture maps of cloth swatches.
//!
//! Glue only: one module per subcommand over the library crates. Only this binary knows clap,
//! stdout and exit codes. With `--json` a subcommand prints exactly one JSON object on stdout;
//! human-readable progress and messages always go to stderr.

mod bake;
mod batch;
mod errors;
mod fit;
mod merge;
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
    /// Ray-trace a tileable swatch from a dome of lights: per-texel occluded fraction K.
    Bake(bake::Args),
    /// Least-squares fit of a PTM (K as a polynomial in the light's (u, v)) per texel.
    Fit(fit::Args),
    /// Render the swatch plane under area lights with the GPU runtime, modulated by 1 − K.
    Preview(preview::Args),
    /// Generate a procedural tileable swatch as an OBJ file.
    Swatch(swatch::Args),
    /// Measured study: error of K against run time per setting, and stiff/extreme cases.
    Report(report::Args),
    /// Assemble the parts of a farm bake (`ptm bake --shard I/N`) into the stack or PTM.
    Merge(merge::Args),
    /// Run a manifest of bakes locally, or write a Slurm array job for them (--slurm DIR).
    Batch(batch::Args),
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
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Bake(a) => bake::run(a),
        Command::Fit(a) => fit::run(a),
        Command::Preview(a) => preview::run(a),
        Command::Swatch(a) => swatch::run(a),
        Command::Report(a) => report::run(a),
        Command::Merge(a) => merge::run(a),
        Command::Batch(a) => batch::run(a),
    };
    match result {
        Ok(report) => {
            if cli.json {
                println!("{report}");
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("ptm: error: {}", errors::explain(&e));
            ExitCode::FAILURE
        }
    }
}
