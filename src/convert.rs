//! `ptm convert`: a PTM from one on-disk layout to the other (the channel layout, one
//! `ptm.<monomial>` channel per coefficient; the renderer layout, RGB(A) parts `.c0.exr`, …),
//! losslessly: every map with its MIP levels and stored type, every header attribute.
use std::path::PathBuf;

use anyhow::Context;
use ptm_format::layout::{Layout, PtmFile};

use crate::args::choice;
use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// A PTM in either layout: NAME.ptm.exr (channels), or any part of the renderer layout
    /// (NAME.ptm.c0.exr; NAME.ptm.exr when only its parts exist).
    #[arg(value_name = "INPUT")]
    pub input: PathBuf,
    /// Output, named as the input: NAME.ptm.exr (the renderer layout writes NAME.ptm.c0.exr, …).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Layout to write: channels or rgba (default: the one the input is not in).
    #[arg(long, value_name = "channels|rgba", hide_possible_values = true, value_parser = choice::<Layout>())]
    pub layout: Option<Layout>,
}

/// `ptm convert`: reads the PTM, encodes it in the other layout, refuses an output that is one
/// of the input's files, and publishes; returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Convert> {
    let (file, from) =
        PtmFile::load(&args.input).with_context(|| format!("reading {}", args.input.display()))?;
    let to = args.layout.unwrap_or(match from {
        Layout::Channels => Layout::Rgba,
        Layout::Rgba => Layout::Channels,
    });
    let files = file
        .encode(&args.output, to)
        .with_context(|| format!("writing {}", args.output.display()))?;
    // The input's files (one, or the renderer layout's parts) must survive the conversion.
    let mut inputs = vec![args.input.clone()];
    if from == Layout::Rgba {
        let basis = file.basis(&args.input)?;
        inputs.extend(ptm_format::layout::rgba_paths(&args.input, basis));
        inputs.push(ptm_format::layout::err_path(&args.input));
    }
    let inputs: Vec<(&str, &std::path::Path)> =
        inputs.iter().map(|p| ("PTM", p.as_path())).collect();
    let outputs: Vec<&std::path::Path> = files.iter().map(|(p, _)| p.as_path()).collect();
    crate::outputs::refuse_inputs(&outputs, &inputs)?;
    let written = ptm_format::layout::publish(&files)
        .with_context(|| format!("writing {}", args.output.display()))?;
    ptm_format::layout::remove_stale_errors(&args.output, to, &written);
    for p in &written {
        eprintln!("ptm convert: wrote {}", p.display());
    }
    Ok(json::Convert {
        input: json::path(&args.input),
        from: from.name(),
        to: to.name(),
        files: json::paths(&written),
        width: file.width,
        height: file.height,
        maps: file.maps.keys().cloned().collect(),
    })
}
