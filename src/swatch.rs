//! `ptm swatch`: generate a procedural tileable swatch (ptm-swatches) and write it as OBJ.

use std::path::PathBuf;

use anyhow::Context;

use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// Swatch generator, optionally with parameters: NAME[?key=value&...] (e.g. `twill?n=3`).
    /// Generators: plain-weave, twill, satin, basket, draft, grid, jersey, rib, velvet, terry,
    /// corduroy.
    pub name: String,
    /// A generator parameter key=value (repeatable), e.g. `--param segments=24`.
    #[arg(long = "param", short = 'p', value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    /// Output OBJ file (written atomically).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
}

/// The full spec: NAME's own `?k=v` parameters followed by the `--param` ones.
pub fn spec(args: &Args) -> String {
    let mut spec = args.name.clone();
    for (k, p) in args.params.iter().enumerate() {
        let sep = if k == 0 && !spec.contains('?') {
            '?'
        } else {
            '&'
        };
        spec.push(sep);
        spec.push_str(p);
    }
    spec
}

/// The files a swatch spec reads: the `path=` of a `draft` (a WIF or 0/1 grid).
pub fn spec_files(spec: &str) -> Vec<PathBuf> {
    let query = spec.split_once('?').map_or("", |(_, q)| q);
    query
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .filter(|(k, _)| k.trim() == "path")
        .map(|(_, v)| PathBuf::from(v.trim()))
        .collect()
}

/// `ptm swatch`: generates the swatch and writes its OBJ; returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Swatch> {
    let spec = spec(args);
    let start = std::time::Instant::now();
    let drafts = spec_files(&spec);
    let inputs: Vec<_> = drafts.iter().map(|p| ("draft", p.as_path())).collect();
    crate::outputs::refuse_inputs(&[&args.output], &inputs)?;
    let swatch =
        ptm_swatches::build(&spec).with_context(|| format!("generating swatch {spec:?}"))?;
    let mesh = &swatch.mesh;
    mesh.write_obj(&args.output)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let (lo, hi) = mesh.bounds().unwrap_or_default();
    eprintln!(
        "{}: {} triangles, {} vertices, tile {} x {}, z in [{}, {}], min yarn gap {}; wrote {}",
        swatch.name,
        mesh.triangles.len(),
        mesh.positions.len(),
        mesh.tile[0],
        mesh.tile[1],
        lo[2],
        hi[2],
        if swatch.clearance.gap.is_finite() {
            format!("{:.4}", swatch.clearance.gap)
        } else {
            "(no two yarns near)".to_string()
        },
        args.output.display()
    );
    Ok(json::Swatch {
        swatch: swatch.name.clone(),
        spec,
        output: json::path(&args.output),
        triangles: mesh.triangles.len(),
        vertices: mesh.positions.len(),
        yarns: swatch.cloth.yarns.len(),
        tile: mesh.tile,
        bounds: json::Bounds { min: lo, max: hi },
        volume_per_tile: mesh.signed_volume(),
        min_yarn_gap: swatch
            .clearance
            .gap
            .is_finite()
            .then_some(swatch.clearance.gap),
        seconds: start.elapsed().as_secs_f64(),
    })
}
