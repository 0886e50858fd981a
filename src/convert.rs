//! `ptm convert`: a PTM from one on-disk layout to the other (the channel layout, one
//! `ptm.<monomial>` channel per coefficient; the renderer layout, RGB(A) parts `.c0.exr`, …),
//! losslessly: every map with its MIP levels and stored type, every header attribute.
use std::path::PathBuf;

use anyhow::Context;
use ptm_format::layout::{Layout, PtmFile};
use serde_json::{json, Value};

/// `--layout channels|rgba`.
pub fn parse_layout(s: &str) -> Result<Layout, String> {
    Layout::from_name(s).ok_or_else(|| {
        format!(
            "unknown layout {s:?} (one of {})",
            Layout::ALL.map(|l| l.name()).join(", ")
        )
    })
}

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
    #[arg(long, value_name = "channels|rgba", value_parser = parse_layout)]
    pub layout: Option<Layout>,
}

pub fn run(args: &Args) -> anyhow::Result<Value> {
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
    Ok(json!({
        "input": crate::outputs::json_path(&args.input),
        "from": from.name(),
        "to": to.name(),
        "files": written.iter().map(|p| crate::outputs::json_path(p)).collect::<Vec<_>>(),
        "width": file.width,
        "height": file.height,
        "maps": file.maps.keys().collect::<Vec<_>>(),
    }))
}
