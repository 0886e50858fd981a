//! `ptm eval`: K of every texel of a PTM (either layout, any basis) for each light of an `.lp`
//! file, written as a sample stack in the bake's layout (`K.0000`, … and `coverage`,
//! fit/src/stack.rs), so a pipeline or a test can score a PTM against any held-out bake, or
//! fit the stack again.
use std::path::PathBuf;

use anyhow::Context;
use ptm_fit::SampleStack;
use ptm_format::LightSet;
use rayon::prelude::*;

use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// A PTM in either layout: NAME.ptm.exr, or any part of the renderer layout.
    #[arg(value_name = "PTM")]
    pub input: PathBuf,
    /// The lights: an RTI `.lp` file (directions towards the lights, swatch frame).
    #[arg(long, value_name = "L.lp")]
    pub lights: PathBuf,
    /// Output sample stack (K of every texel per light, the bake's layout).
    #[arg(short, long, value_name = "K.exr")]
    pub output: PathBuf,
}

/// `ptm eval`: reads the PTM and the lights, evaluates `Ptm::eval_dir` per texel and light
/// (lights at or below the horizon give K = 1), writes the stack atomically.
pub fn run(args: &Args) -> anyhow::Result<json::Eval> {
    let ptm = ptm_format::layout::load(&args.input)
        .with_context(|| format!("reading {}", args.input.display()))?;
    let lights = LightSet::read_lp(&args.lights)?;
    crate::outputs::refuse_inputs(
        &[args.output.as_path()],
        &[
            ("PTM", args.input.as_path()),
            ("lights", args.lights.as_path()),
        ],
    )?;
    let (w, h) = (ptm.width, ptm.height);
    let k: Vec<Vec<f32>> = lights
        .dirs
        .par_iter()
        .map(|&d| (0..w * h).map(|t| ptm.eval_dir(t % w, t / w, d)).collect())
        .collect();
    let mut stack = SampleStack::new(lights.clone(), w, h, ptm.tile, k);
    if let Some(c) = &ptm.coverage {
        stack.coverage = c.clone();
    }
    stack
        .write_into(&args.output)
        .with_context(|| format!("writing {}", args.output.display()))?;
    eprintln!(
        "ptm eval: wrote {} ({w}×{h} texels, {} lights, basis {})",
        args.output.display(),
        lights.len(),
        ptm.basis.name()
    );
    Ok(json::Eval {
        input: json::path(&args.input),
        output: json::path(&args.output),
        basis: ptm.basis.name(),
        width: w,
        height: h,
        lights: lights.len(),
    })
}
