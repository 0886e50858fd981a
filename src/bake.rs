//! `ptm bake`: ray-trace a tileable swatch from a dome of lights into a sample stack
//! (`samples.exr`, K per light + coverage) or, with `--fit`, straight into a PTM without ever
//! holding the whole stack.
use std::io::IsTerminal;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_bake::{dome, BakeConfig, BakeReport, Baker, PreparedMesh, Tracer};
use ptm_fit::shard::{BakeIdentity, PartMeta};
use ptm_fit::{Accumulator, FitOptions, SampleStack};
use ptm_format::atomic::{same_file, Transaction};
use ptm_format::{Basis, Layout, LightSet, Link, SaveOptions};

use crate::args::{choice, parse_threads, ModelArgs};
use crate::auto::BasisChoice;
use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// Swatch: an OBJ file (polygons are triangulated) or builtin:NAME[?k=v&...].
    #[arg(long, default_value = "builtin:plain-weave")]
    pub swatch: String,
    /// Tile size W,H in mesh units. Default: a builtin's own tile; for an OBJ its `# tile W H`
    /// comment (which `ptm swatch` writes before the first vertex; some OBJ editors drop it),
    /// else the x/y bounding box, which is larger than the tile when yarns overhang it.
    #[arg(
        long,
        value_name = "W,H",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub tile: Option<Vec<f64>>,
    /// Texels over the central tile: W,H, or N along the tile's longer side and the other side
    /// in proportion, so that texels are square (N×N on a square tile).
    #[arg(long, value_name = "N|W,H", value_delimiter = ',', num_args = 1..=2, default_values_t = [64])]
    pub res: Vec<usize>,
    /// N spherical Fibonacci light directions above --min-elevation (default 32 when neither
    /// --dome nor --lights is given).
    #[arg(long, value_name = "N", conflicts_with_all = ["dome", "lights"])]
    pub dirs: Option<usize>,
    /// Dome layout: rings:E1xC1,E2xC2,... (elevation in degrees x light count) or fibonacci:N.
    #[arg(long, value_name = "SPEC", conflicts_with = "lights")]
    pub dome: Option<String>,
    /// Light directions from an RTI .lp file (N, then `name x y z` per line).
    #[arg(long, value_name = "FILE.lp")]
    pub lights: Option<PathBuf>,
    /// Lowest elevation of Fibonacci directions, in degrees above the swatch plane.
    #[arg(long, value_name = "DEG", default_value_t = 5.0)]
    pub min_elevation: f64,
    /// Point lights on a hemisphere of this radius (mesh units) over the tile centre instead
    /// of distant lights; each texel's direction is recorded for the fit.
    #[arg(long, value_name = "R")]
    pub light_distance: Option<f64>,
    /// Stratified jittered footprint samples per texel.
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    /// Seed of the sample positions (the output is identical for any thread count).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fit a PTM while baking (streaming; -o is then the .ptm.exr): ptm6, ptm11, a basis
    /// learned from the bake, learned6 or learned11 (docs/model.md), or `auto`: each of ptm6,
    /// learned6, ptm11, learned11 fitted from the same counts, scored on the same held-out
    /// lights, the first (cheapest) within --auto-margin of the best kept (as `ptm fit
    /// --basis auto`).
    #[arg(long, value_name = "BASIS", value_parser = crate::auto::parse_choice)]
    pub fit: Option<BasisChoice>,
    /// With --fit: lights held out of the fit and scored (its error on lights it did not see).
    /// Default: none for a given basis; with --fit auto an eighth, as `ptm fit`.
    #[arg(long, value_name = "N", requires = "fit")]
    pub holdout: Option<usize>,
    /// With --fit auto: keep the cheapest candidate whose held-out error is at most
    /// (1 + MARGIN) × the best candidate's.
    #[arg(long, value_name = "MARGIN", default_value_t = crate::auto::AUTO_MARGIN, requires = "fit")]
    pub auto_margin: f64,
    #[command(flatten)]
    pub model: ModelArgs,
    /// With --fit: ridge λ relative to the mean eigenvalue (see `ptm fit --regularize`).
    #[arg(long, value_name = "LAMBDA", requires = "fit")]
    pub regularize: Option<f64>,
    /// With --fit: file layout, channels or rgba (the renderer layout; see `ptm fit --layout`).
    #[arg(long, value_name = "channels|rgba", hide_possible_values = true, value_parser = choice::<Layout>(), default_value = "channels", requires = "fit")]
    pub layout: Layout,
    /// Worker threads (0: one per core; at most 1024).
    #[arg(long, default_value_t = 0, value_parser = parse_threads)]
    pub threads: usize,
    /// Device that traces: cpu (Embree), gpu (wgpu ray queries) or auto (a GPU with hardware
    /// ray queries if there is one, else the CPU). The choice and why go to stderr and --json.
    #[arg(long, value_name = "cpu|gpu|auto", hide_possible_values = true, value_parser = choice::<ptm_gpubake::Asked>(), default_value = "auto")]
    pub device: ptm_gpubake::Asked,
    /// Trace shadow rays one by one instead of in 16-ray packets (same result, slower).
    #[arg(long, hide = true)]
    pub single_rays: bool,
    /// Output: samples.exr, or NAME.ptm.exr with --fit. The dome is written beside it (.lp).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Also write the companion maps from the same rays beside the output: NAME.maps.exr with
    /// height, tangent-space normal (MikkTSpace of the flat tile, +Y up), ambient occlusion,
    /// bent normal and coverage (docs/FORMAT.md, "Companion maps").
    #[arg(long)]
    pub maps: bool,
    /// With the maps, also 16-bit PNGs for painting tools: NAME.height.png, NAME.normal.png,
    /// NAME.ao.png, NAME.bent.png (normals as n·0.5 + 0.5, +Y up). Implies --maps.
    #[arg(long)]
    pub maps_png: bool,
    /// Farm bake: trace only shard I of N (0-based; a block of texel rows) and write the part
    /// file OUTPUT-stem.part-IIII-of-NNNN.exr for `ptm merge`; a complete, valid part is kept.
    #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
    pub shard: Option<ptm_fit::shard::Shard>,
}

/// `ptm bake`: checks the input, traces the dome light by light into the fit or the stack,
/// writes it (or a farm part) and the `.lp`; returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Bake> {
    let t_all = Instant::now();
    // Everything that can refuse the input runs before any output is written; outputs that
    // are inputs are refused before any input is read.
    let destinations = destinations(args)?;
    let (swatch, t_load) = resolve_swatch(args)?;
    let (res, rows) = resolve_rows(args, swatch.tile)?;
    let device = choose_device(args)?;
    let lights = build_dome(
        args,
        [res[0], rows.len()],
        swatch.material_names.len(),
        device.used,
    )?;
    let part = match check_outputs(args, res, &swatch, &lights)? {
        Output::Complete(path) => {
            return Ok(json::Bake::Skipped(json::SkippedPart {
                part: json::path(&path),
                skipped: true,
            }))
        }
        Output::Whole => None,
        Output::Part(meta, path) => Some((meta, path)),
    };
    let products = ProductKind::of(args)
        .into_iter()
        .map(|kind| Product::new(kind, args, &lights, res[0], rows.len()))
        .collect::<anyhow::Result<Vec<_>>>()?;
    // A part's MIP levels are finished by the merge (`Accumulator::finish_part`).
    let shard_mips = args.shard.is_some() && args.fit.is_some() && !args.model.no_mips;
    announce(args, &swatch, res, &lights);
    let (kept, report) = trace(args, &swatch, res, rows.clone(), &lights, &device, products)?;
    let written = write_outputs(&swatch, &lights, kept, &part, destinations, shard_mips)?;
    print_summary(&report, &written);
    let mut baked = bake_json(
        args, &swatch, res, rows, &lights, &report, written, t_load, t_all,
    );
    baked.device = json::BakeDevice::of(&device);
    Ok(json::Bake::Baked(Box::new(baked)))
}

/// Which device traces (`--device`), said on stderr with the adapter and the reason.
fn choose_device(args: &Args) -> anyhow::Result<ptm_gpubake::Choice> {
    let choice = ptm_gpubake::choose(args.device)
        .with_context(|| format!("--device {}", args.device.name()))?;
    // The reason names the adapter wherever one was chosen or passed over.
    eprintln!("ptm bake: device {}: {}", choice.used.name(), choice.reason);
    Ok(choice)
}

/// Parses `--tile`, loads and checks the swatch, and prints its warnings. Returns the swatch
/// and the seconds loading took.
fn resolve_swatch(args: &Args) -> anyhow::Result<(PreparedMesh, f64)> {
    let tile = match args.tile.as_deref() {
        None => None,
        Some(&[w, h]) => Some([w, h]),
        Some(t) => bail!("--tile takes W,H (two numbers), got {t:?}"),
    };
    let t0 = Instant::now();
    let swatch = PreparedMesh::load(&args.swatch, tile)?;
    let t_load = t0.elapsed().as_secs_f64();
    for w in &swatch.warnings() {
        eprintln!("ptm bake: warning: {}", crate::errors::swatch_warning(w));
    }
    Ok((swatch, t_load))
}

/// `--res N` on a `tile`: N texels along its longer side and the other side in proportion
/// (rounded, at least 1), so that texels are square to within half a texel over the tile.
pub fn square_texels(n: usize, tile: [f64; 2]) -> [usize; 2] {
    let other = |short: f64, long: f64| ((n as f64 * short / long).round() as usize).max(1);
    if tile[0] >= tile[1] {
        [n, other(tile[1], tile[0])]
    } else {
        [other(tile[0], tile[1]), n]
    }
}

/// The whole bake's texels (`--res`: W,H, or N along the tile's longer side with square
/// texels) and the rows this run traces and holds: all of them, or a farm shard's block.
/// Refuses the flag combinations a shard cannot bake.
fn resolve_rows(args: &Args, tile: [f64; 2]) -> anyhow::Result<([usize; 2], Range<usize>)> {
    let res = match args.res[..] {
        [n] => square_texels(n, tile),
        [w, h] => [w, h],
        _ => bail!("--res takes N or W,H"),
    };
    if args.res.len() == 1 && res[0] != res[1] {
        eprintln!(
            "ptm bake: --res {} on the {}×{} tile: {}×{} texels, square ({:.4}×{:.4} mesh units; \
             --res W,H sets both)",
            args.res[0],
            tile[0],
            tile[1],
            res[0],
            res[1],
            tile[0] / res[0] as f64,
            tile[1] / res[1] as f64
        );
    }
    // A shard traces and holds only its rows.
    let rows = match args.shard {
        Some(s) => s.rows(res[1])?,
        None => 0..res[1],
    };
    if args.shard.is_some() && args.fit.is_some() && args.light_distance.is_some() {
        bail!(
            "--shard with --fit and --light-distance is not supported (the per-texel fit's rank \
             diagnostics span all texels): bake the sample stack in shards, merge, then `ptm fit`"
        );
    }
    if let Some(BasisChoice::Auto) = args.fit {
        if args.shard.is_some() {
            bail!(
                "--shard with --fit auto: the candidates include learned bases, learned from the \
                 whole bake, which a shard does not see: bake the sample stack in shards, merge, \
                 then `ptm fit --basis auto`, or give the basis"
            );
        }
        if args.model.link != Link::Logistic {
            bail!(
                "--fit auto with --link {}: the candidates are fitted from the logistic link's \
                 sample counts (the identity link's sums belong to one basis); use the default \
                 --link logistic, or give the basis",
                args.model.link.name()
            );
        }
    }
    if args.shard.is_some() && args.holdout.is_some_and(|h| h > 0) {
        bail!(
            "--shard with --holdout: a part keeps no per-texel error on held-out lights; bake \
             the whole image, or the sample stack in shards and `ptm fit --holdout N` the merge"
        );
    }
    if args.maps_png && args.shard.is_some() {
        bail!(
            "--maps-png with --shard: a part carries the maps as EXR; merge the parts, then bake \
             or convert the PNGs from the merged NAME.maps.exr (or shard with --maps)"
        );
    }
    if wants_maps(args) && args.light_distance.is_some() {
        bail!(
            "--maps with --light-distance is not supported: ambient occlusion and the bent normal \
             integrate distant light over the dome; bake the maps with distant lights"
        );
    }
    if args.shard.is_some() && args.layout != Layout::Channels {
        bail!("--shard writes part files: merge them, then `ptm convert` to --layout rgba");
    }
    Ok((res, rows))
}

/// The light directions (`--lights`, `--dome` or `--dirs` Fibonacci), each refused before it
/// is built when the bake of `mem_res` texels (of a swatch of `materials` materials, for the
/// maps' masks) would not fit in memory.
fn build_dome(
    args: &Args,
    mem_res: [usize; 2],
    materials: usize,
    device: ptm_gpubake::Used,
) -> anyhow::Result<LightSet> {
    let lights: LightSet = match (&args.lights, &args.dome) {
        (Some(p), _) => LightSet::read_lp(p)?,
        (None, Some(spec)) => dome::parse(spec, args.min_elevation)?,
        (None, None) => {
            // Checked before the dome exists: --dirs 100000000 must not exhaust memory first.
            let n = args.dirs.unwrap_or(32);
            check_memory(args, mem_res, n, materials, device)?;
            dome::fibonacci(n, args.min_elevation)?
        }
    };
    if args.lights.is_some() || args.dome.is_some() {
        check_memory(args, mem_res, lights.len(), materials, device)?;
    }
    Ok(lights)
}

/// What identifies this bake in a farm part: every setting that changes the output, in the
/// words of the library's [`BakeIdentity`] (parts of different settings never merge).
fn settings(args: &Args, res: [usize; 2], tile: [f64; 2], lights: &LightSet) -> String {
    let fit = args.fit.map(|f| fit_options(args, f.for_paths()));
    BakeIdentity {
        res,
        tile,
        spp: args.spp,
        seed: args.seed,
        lights,
        light_distance: args.light_distance,
        fit: fit.as_ref(),
        maps: wants_maps(args).then(|| ptm_bake::maps::words(quadrature(args))),
    }
    .settings()
}

/// Where the bake goes.
enum Output {
    /// `--output` itself.
    Whole,
    /// A farm part: what identifies the bake in it, and its path.
    Part(PartMeta, PathBuf),
    /// A farm part that is already complete and valid: nothing to bake.
    Complete(PathBuf),
}

/// Decides where the bake goes: `--output`, or with `--shard` the part file, unless that part
/// is already complete (said on stderr).
fn check_outputs(
    args: &Args,
    res: [usize; 2],
    swatch: &PreparedMesh,
    lights: &LightSet,
) -> anyhow::Result<Output> {
    let Some(s) = args.shard else {
        return Ok(Output::Whole);
    };
    let meta = crate::shard::meta(s, res, settings(args, res, swatch.tile, lights), swatch)?;
    let path = s.part_path(&args.output);
    // Every product's part: the maps' beside K's.
    let maps = wants_maps(args).then(|| s.part_path(&ptm_bake::maps::maps_path(&args.output)));
    if crate::shard::is_complete(&path, &meta)
        && maps
            .as_deref()
            .is_none_or(|m| crate::shard::is_complete(m, &meta))
    {
        eprintln!("ptm bake: {} is complete; skipped", path.display());
        return Ok(Output::Complete(path));
    }
    Ok(Output::Part(meta, path))
}

/// Where a bake's files go, checked before any work.
struct Destinations {
    /// `--output` and the `.lp` beside it, published together; for a farm part, the part
    /// alone (it carries its lights).
    tx: Transaction,
    output: PathBuf,
    /// The `.lp` written beside the output: none for a part or a device (`-o /dev/null`), and
    /// none when it is the `--lights` file itself, which already holds exactly these lights
    /// and is left as the user wrote it.
    lp: Option<PathBuf>,
    /// The `.lp` that describes the output's lights (written, or the user's `--lights`).
    lights_file: Option<PathBuf>,
    /// The PTM's file layout (`--layout`; the renderer layout writes parts beside `output`).
    layout: Layout,
    /// `--output`, beside which the companion maps go.
    maps_of: PathBuf,
}

/// The companion maps' files beside `--output` (none without `--maps`): the EXR, then with
/// `--maps-png` the PNGs.
fn maps_files(args: &Args) -> Vec<PathBuf> {
    if !wants_maps(args) {
        return Vec::new();
    }
    let exr = ptm_bake::maps::maps_path(&args.output);
    if let Some(s) = args.shard {
        return vec![s.part_path(&exr)];
    }
    let mut files = vec![exr];
    if args.maps_png {
        files.extend(
            ptm_bake::maps::PNG_MAPS
                .iter()
                .map(|n| ptm_bake::maps::png_path(&args.output, n)),
        );
    }
    files
}

/// Refuses an output that is an input (the swatch OBJ, its draft, the `--lights` file) and checks
/// every destination (an existing directory, a directory that does not exist) before the work.
fn destinations(args: &Args) -> anyhow::Result<Destinations> {
    let mut inputs: Vec<(&str, PathBuf)> = Vec::new();
    match args.swatch.strip_prefix("builtin:") {
        Some(spec) => inputs.extend(
            crate::swatch::spec_files(spec)
                .into_iter()
                .map(|p| ("swatch draft", p)),
        ),
        None => inputs.push(("swatch", PathBuf::from(&args.swatch))),
    }
    if let Some(lp) = &args.lights {
        inputs.push(("light file", lp.clone()));
    }
    let inputs: Vec<(&str, &Path)> = inputs.iter().map(|(w, p)| (*w, p.as_path())).collect();
    let (output, beside) = match args.shard {
        Some(s) => (s.part_path(&args.output), None),
        None => (args.output.clone(), crate::outputs::lp_beside(&args.output)),
    };
    let user_lp = |p: &Path| args.lights.as_deref().is_some_and(|l| same_file(p, l));
    let lp = beside.clone().filter(|p| !user_lp(p));
    // The renderer layout's parts replace the one file (not for a farm part: refused above).
    let rgba = match (args.fit, args.layout) {
        (Some(f), Layout::Rgba) if args.shard.is_none() => {
            ptm_format::layout::rgba_paths(&output, f.for_paths())
        }
        _ => vec![output.clone()],
    };
    let mut outputs: Vec<&Path> = rgba.iter().map(PathBuf::as_path).collect();
    outputs.extend(lp.as_deref());
    let maps = maps_files(args);
    outputs.extend(maps.iter().map(PathBuf::as_path));
    crate::outputs::refuse_inputs(&outputs, &inputs)?;
    let tx = Transaction::new(&outputs)?;
    Ok(Destinations {
        tx,
        output,
        lp,
        lights_file: beside,
        layout: args.layout,
        maps_of: args.output.clone(),
    })
}

/// What the bake warns of its light set: lights at or below the horizon.
fn light_warnings(lights: &LightSet) -> Vec<ptm_bake::Diagnostic> {
    let below = lights.below_horizon();
    match below.is_empty() {
        true => Vec::new(),
        false => vec![ptm_bake::Diagnostic::BelowHorizon { lights: below }],
    }
}

/// Says on stderr what is about to be baked (and that lights below the horizon bake to K = 1).
fn announce(args: &Args, swatch: &PreparedMesh, res: [usize; 2], lights: &LightSet) {
    for w in light_warnings(lights) {
        eprintln!("ptm bake: warning: {w}");
    }
    eprintln!(
        "ptm bake: {}: {} triangles, tile {}×{}, {}×{} texels × {} spp, {} lights",
        swatch.origin,
        swatch.triangles.len(),
        swatch.tile[0],
        swatch.tile[1],
        res[0],
        res[1],
        args.spp,
        lights.len()
    );
}

/// What the bake makes, before it is made: each kind knows the memory its buffers take (the
/// memory check sums them) and what it says of them when they do not fit.
#[derive(Clone, Copy, Debug, PartialEq)]
enum ProductKind {
    /// K of every light kept and written as the sample stack.
    Stack,
    /// K streamed into the per-texel fit and written as the PTM.
    Fit(BasisChoice),
    /// The companion maps: height and normal from the primary hits, AO and bent normal from
    /// every light's K.
    Maps,
}

impl ProductKind {
    /// The products `args` ask for, in the order they are fed and written.
    fn of(args: &Args) -> Vec<ProductKind> {
        let mut kinds = vec![match args.fit {
            Some(f) => ProductKind::Fit(f),
            None => ProductKind::Stack,
        }];
        if wants_maps(args) {
            kinds.push(ProductKind::Maps);
        }
        kinds
    }

    /// Bytes this product holds for a bake of `res` texels and `lights` lights, and its
    /// buffers in words. In f64: absurd requests must be measured, not overflow.
    fn memory(
        self,
        args: &Args,
        res: [usize; 2],
        lights: usize,
        materials: usize,
    ) -> (f64, &'static str) {
        match self {
            // What the accumulator will hold (its sums, or the logistic link's counts).
            ProductKind::Fit(f) => {
                let counts = Accumulator::count_bytes(args.model.link, args.spp) as f64;
                let bytes = Accumulator::memory_bytes(
                    res[0].saturating_mul(res[1]),
                    lights,
                    &fit_options(args, f.for_paths()),
                    args.spp,
                    args.light_distance.is_some(),
                );
                (
                    bytes as f64,
                    if counts > 0.0 {
                        "the streaming fit's sums and the logistic link's exact sample counts"
                    } else {
                        "the streaming fit's sums"
                    },
                )
            }
            // K per light (handed to the EXR writer, not copied); for point lights also (u, v).
            ProductKind::Stack => (
                SampleStack::memory_bytes(res[0], res[1], lights, args.light_distance.is_some()),
                "the sample stack (K of every light, written as samples.exr)",
            ),
            ProductKind::Maps => {
                let texels = res[0] as f64 * res[1] as f64;
                let spp = args.spp as f64;
                (
                    ptm_bake::maps::Surface::memory_bytes(texels, spp)
                        + ptm_bake::maps::Occlusion::memory_bytes(texels)
                        + ptm_bake::maps::Maps::memory_bytes(texels, materials as f64)
                        // The per-block sums of the primary pass, gathered into the image's.
                        + ptm_bake::maps::Surface::memory_bytes(texels, spp),
                    "the companion maps (height, normal, AO, bent normal, ids and masks)",
                )
            }
        }
    }
}

/// Whether the bake writes the companion maps (`--maps`, or `--maps-png`).
fn wants_maps(args: &Args) -> bool {
    args.maps || args.maps_png
}

/// The dome's quadrature rule: how its lights share the hemisphere (the maps' AO weights).
fn quadrature(args: &Args) -> dome::Quadrature {
    match (&args.lights, &args.dome) {
        (Some(_), _) => dome::Quadrature::Equal,
        (None, Some(spec)) if spec.starts_with("rings:") => dome::Quadrature::Rings,
        _ => dome::Quadrature::Fibonacci {
            min_elevation_deg: args.min_elevation,
        },
    }
}

/// The companion maps being made: the primary hits' sums (handed over by the baker once its
/// primary pass is done) and the occlusion integrated light by light.
struct MapsProduct {
    surface: Option<ptm_bake::maps::Surface>,
    occlusion: ptm_bake::maps::Occlusion,
    quadrature: dome::Quadrature,
    /// Also the 16-bit PNGs.
    png: bool,
}

/// One product of the bake, being made: fed the texels' coverage, then every light's K plane
/// as it is traced, then written as a file of its own or as a farm part.
enum Product {
    /// K of every light, kept for the sample stack.
    Stack(ptm_bake::Planes),
    /// K streamed into the per-texel fit (boxed: its fields are large beside a `Planes`), and
    /// with `--fit auto` the candidates it is finished as.
    Fit(Box<Accumulator>, Option<AutoFit>),
    /// The companion maps.
    Maps(Box<MapsProduct>),
}

impl Product {
    /// The product of `kind` for `width × height` traced texels. Prints the fit's warnings
    /// about the light set.
    fn new(
        kind: ProductKind,
        args: &Args,
        lights: &LightSet,
        width: usize,
        height: usize,
    ) -> anyhow::Result<Product> {
        Ok(match kind {
            ProductKind::Stack => Product::Stack(ptm_bake::Planes::default()),
            ProductKind::Fit(f) => {
                let auto = match f {
                    BasisChoice::Fixed(_) => None,
                    BasisChoice::Auto => Some(AutoFit::new(args, lights)?),
                };
                // With auto the counts are kept under the cheapest candidate's options; each
                // candidate is finished from them under its own (`Accumulator::finish_as`).
                let basis = f.fixed().unwrap_or(crate::auto::AUTO_CANDIDATES[0]);
                let mut opts = fit_options(args, basis);
                if let Some(a) = &auto {
                    opts.holdout = a.holdout;
                }
                let mut acc = Accumulator::new(lights, width, height, &opts)?;
                acc.set_spp(args.spp)?;
                for w in acc.warnings() {
                    eprintln!("ptm bake: fit warning: {}", crate::errors::fit_warning(w));
                }
                Product::Fit(Box::new(acc), auto)
            }
            ProductKind::Maps => {
                let q = quadrature(args);
                let occlusion =
                    ptm_bake::maps::Occlusion::new(lights, &q.weights(lights), width * height)?;
                Product::Maps(Box::new(MapsProduct {
                    surface: None,
                    occlusion,
                    quadrature: q,
                    png: args.maps_png,
                }))
            }
        })
    }

    /// Whether the product needs the primary hits' per-texel sums.
    fn needs_surface(&self) -> bool {
        matches!(self, Product::Maps(_))
    }

    /// Takes the traced texels' coverage, before any light.
    fn set_coverage(&mut self, coverage: &[f32]) -> anyhow::Result<()> {
        match self {
            Product::Stack(_) | Product::Maps(_) => {}
            Product::Fit(acc, _) => acc.set_coverage(coverage)?,
        }
        Ok(())
    }

    /// Takes light `i`'s K plane (and, for point lights, each texel's (u, v)).
    fn add_light(&mut self, i: usize, k: &[f32], uv: Option<&[[f32; 2]]>) -> ptm_bake::Result<()> {
        match self {
            Product::Stack(planes) => planes.push(i, k, uv),
            Product::Fit(acc, _) => match uv {
                Some(uv) => acc.add_light_uv(i, k, uv),
                None => acc.add_light(i, k),
            }
            .map_err(ptm_bake::Error::sink),
            Product::Maps(m) => m.occlusion.add_light(i, k),
        }
    }
}

/// What a trace keeps for the output: its products, the texels' coverage, and the traced
/// size (width × the rows traced).
struct Kept {
    products: Vec<Product>,
    coverage: Vec<f32>,
    size: [usize; 2],
}

/// Traces `rows` of the bake light by light into the fit (or keeps the planes) on the chosen
/// device, with a progress bar on a terminal; reports uncovered texels and lights whose shadows
/// were capped.
fn trace(
    args: &Args,
    swatch: &PreparedMesh,
    res: [usize; 2],
    rows: Range<usize>,
    lights: &LightSet,
    device: &ptm_gpubake::Choice,
    mut products: Vec<Product>,
) -> anyhow::Result<(Kept, BakeReport)> {
    let cfg = BakeConfig {
        res,
        spp: args.spp,
        seed: args.seed,
        light_distance: args.light_distance,
        packets: !args.single_rays,
        threads: args.threads,
    };
    // A farm shard fitting a learned basis first learns it as the whole bake learns it (on the
    // CPU: a few thousand texels), then fits its rows against it.
    if let (Some(_), Some(BasisChoice::Fixed(b))) = (args.shard, args.fit) {
        if b.is_learned() {
            let (table, stats, secs) =
                crate::shard::learned_basis(swatch, &cfg, lights, &fit_options(args, b))?;
            eprintln!(
                "ptm bake: learned the {} basis on {} texels of the whole image in {secs:.1} s \
                 (every shard learns the same tables)",
                b.name(),
                stats.texels
            );
            for p in &mut products {
                if let Product::Fit(acc, _) = p {
                    acc.set_given_basis(table.clone(), stats.clone());
                }
            }
        }
    }
    let surface = products.iter().any(Product::needs_surface);
    let mut baker: Box<dyn Tracer> = match &device.adapter {
        Some(adapter) => {
            let gpu = ptm_gpubake::GpuBaker::new_rows(
                adapter,
                swatch,
                &cfg,
                rows.clone(),
                &ptm_gpubake::GpuConfig::default(),
                surface,
            )?;
            let bands = gpu.bands();
            eprintln!(
                "ptm bake: on the GPU in {} band(s) of up to {} rows, {} lights per pass",
                bands.len(),
                bands.iter().map(|b| b.len()).max().unwrap_or(0),
                gpu.lights_per_pass().min(lights.len())
            );
            Box::new(gpu)
        }
        None if surface => Box::new(Baker::with_surface(swatch, &cfg, rows.clone())?),
        None => Box::new(Baker::new_rows(swatch, &cfg, rows.clone())?),
    };
    let coverage = baker.coverage().to_vec();
    let mut surface = baker.take_surface();
    for p in &mut products {
        if let Product::Maps(m) = p {
            m.surface = surface.take();
        }
    }
    for p in &mut products {
        p.set_coverage(&coverage)?;
    }
    let bar = if std::io::stderr().is_terminal() {
        let b = indicatif::ProgressBar::new(lights.len() as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "ptm bake: {bar:40} {pos}/{len} lights, {eta} left",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Some(b)
    } else {
        None
    };
    let report = baker.trace(lights, &mut |i, k, uv| {
        if let Some(b) = &bar {
            b.inc(1);
        }
        for p in &mut products {
            p.add_light(i, k, uv)?;
        }
        Ok(())
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    // The primary samples are not needed past the trace: free them before the fit's solve.
    drop(baker);
    if report.uncovered_texels > 0 {
        eprintln!(
            "ptm bake: {} of {} texels see no swatch (coverage 0, masked)",
            report.uncovered_texels,
            res[0] * rows.len()
        );
    }

    if !report.capped.is_empty() {
        eprintln!(
            "ptm bake: warning: light(s) {:?} are so low that their shadows were followed only {} \
             tiles; K there may be too small",
            report.capped,
            ptm_bake::tiling::MAX_RUN_TILES
        );
    }
    let kept = Kept {
        products,
        coverage,
        size: [res[0], rows.len()],
    };
    Ok((kept, report))
}

/// What was written, and the seconds the solve and the writing took.
struct Written {
    /// The fit's summary for the JSON (none without `--fit`).
    fit: Option<json::BakeFit>,
    /// The companion maps written (none without `--maps`).
    maps: Option<json::BakeMaps>,
    /// The file written (the part, for a farm shard).
    output: PathBuf,
    /// Every file of the sample stack or PTM written: `output`, or the renderer layout's parts.
    files: Vec<PathBuf>,
    /// The `.lp` written beside a whole bake.
    lp: Option<PathBuf>,
    /// The `.lp` holding the output's lights: `lp`, or the user's `--lights` file.
    lights_file: Option<PathBuf>,
    t_fit: f64,
    t_write: f64,
}

/// `--fit auto`: the candidates' options and the margin, set before the trace; after it each
/// candidate is finished from the accumulator's counts and the choice made
/// (`crate::auto::choose`).
struct AutoFit {
    /// The lights every candidate holds out (`crate::auto::shared_holdout`).
    holdout: usize,
    margin: f64,
    /// Each candidate's options (the shared hold-out in them).
    candidates: Vec<FitOptions>,
}

impl AutoFit {
    fn new(args: &Args, lights: &LightSet) -> anyhow::Result<AutoFit> {
        let holdout = crate::auto::shared_holdout(&args.swatch, lights.len(), args.holdout)?;
        let candidates = crate::auto::AUTO_CANDIDATES
            .iter()
            .map(|&b| FitOptions {
                holdout,
                ..fit_options(args, b)
            })
            .collect();
        Ok(AutoFit {
            holdout,
            margin: args.auto_margin,
            candidates,
        })
    }

    /// Finishes every candidate from `acc` and keeps the choice; `output` names the bake.
    fn choose(
        &self,
        acc: &Accumulator,
        tile: [f64; 2],
        output: &Path,
    ) -> anyhow::Result<crate::auto::Chosen> {
        let source = output.display().to_string();
        crate::auto::choose(
            "ptm bake",
            &source,
            self.holdout,
            self.margin,
            |basis, _| {
                let opts = self
                    .candidates
                    .iter()
                    .find(|o| o.basis == basis)
                    .expect("one options per candidate")
                    .clone();
                acc.finish_as(tile, &opts).map(|(ptm, r)| (opts, ptm, r))
            },
        )
    }
}

/// Where and how the products of a bake are written: the swatch and lights they describe,
/// the traced texels' coverage and size, the farm part (if any), and the output's layout.
struct WriteTo<'a> {
    swatch: &'a PreparedMesh,
    lights: &'a LightSet,
    coverage: &'a [f32],
    size: [usize; 2],
    part: &'a Option<(PartMeta, PathBuf)>,
    /// A farm part defers the MIP levels to the merge.
    shard_mips: bool,
    output: &'a Path,
    /// `--output`, beside which the companion maps go.
    maps_of: &'a Path,
    layout: Layout,
}

/// What one product wrote: its files (staged in the transaction, or a farm part written) and,
/// for the fit, its summary and the seconds the solve took.
#[derive(Default)]
struct ProductWritten {
    files: Vec<PathBuf>,
    fit: Option<json::BakeFit>,
    maps: Option<json::BakeMaps>,
    t_fit: f64,
}

impl Product {
    /// Finishes the product and stages its files for a whole bake in `tx`, or writes its farm
    /// part.
    fn write(self, to: &WriteTo, tx: &mut Transaction) -> anyhow::Result<ProductWritten> {
        let output = to.output;
        let writing = || crate::outputs::Named::new("writing", output);
        match self {
            Product::Fit(acc, auto) => {
                let t0 = Instant::now();
                let mut chosen = None;
                let (ptm, fit, levels) = match (to.part, auto) {
                    (Some((meta, _)), _) => {
                        acc.finish_part(to.swatch.tile, meta.rows.clone(), meta.height)?
                    }
                    (None, None) => {
                        let (ptm, fit) = acc.finish(to.swatch.tile)?;
                        (ptm, fit, Default::default())
                    }
                    (None, Some(auto)) => {
                        let c = auto.choose(&acc, to.swatch.tile, output)?;
                        chosen = Some(c.json);
                        (c.ptm, c.report, Default::default())
                    }
                };
                // The per-light accumulation ran inside the shadow stage; this is the solve.
                let t_fit = t0.elapsed().as_secs_f64();
                for w in &fit.warnings {
                    eprintln!("ptm bake: fit warning: {}", crate::errors::fit_warning(w));
                }
                crate::fit::print_logistic("ptm bake", &fit);
                if let Some(h) = &fit.holdout {
                    eprintln!(
                        "ptm bake: RMS error of K on the {} held-out lights (the fit did not see \
                         them): mean {:.4}, 99th percentile {:.4}",
                        fit.holdout_lights.len(),
                        h.mean,
                        h.p99
                    );
                }
                let summary = json::BakeFit {
                    basis: fit.basis.map(|b| b.name()),
                    link: ptm.link.name(),
                    uv: ptm.uv.name(),
                    mip_levels: fit.mip_levels,
                    logistic: json::Logistic::of(&fit),
                    learned: json::Learned::of(&fit),
                    solver: fit.solver.clone(),
                    rank: fit.rank,
                    condition_number: json::finite(fit.cond),
                    rms_error_mean: fit.rms.mean,
                    rms_error_p99: fit.rms.p99,
                    warnings: crate::errors::fit_warnings(&fit.warnings),
                    holdout_lights: fit.holdout_lights.clone(),
                    holdout_rms_error: fit.holdout.as_ref().map(Into::into),
                    auto: chosen,
                    stages: json::Stages(fit.seconds.clone()),
                };
                let files = match to.part {
                    // The part takes the fit itself: no copy of its planes.
                    Some((meta, path)) => {
                        crate::shard::write_ptm(
                            path,
                            meta,
                            ptm,
                            fit,
                            to.coverage.to_vec(),
                            to.lights,
                            to.shard_mips,
                            levels,
                        )
                        .with_context(writing)?;
                        vec![output.to_path_buf()]
                    }
                    None => {
                        let save = SaveOptions {
                            half: false,
                            report: Some(&fit),
                            error_map: false,
                        };
                        let encoded = ptm_format::layout::encode(&ptm, output, &save, to.layout)
                            .with_context(writing)?;
                        for (p, bytes) in &encoded {
                            tx.add(p).with_context(writing)?;
                            tx.stage_bytes(p, bytes).with_context(writing)?;
                        }
                        encoded.into_iter().map(|(p, _)| p).collect()
                    }
                };
                Ok(ProductWritten {
                    files,
                    fit: Some(summary),
                    t_fit,
                    ..Default::default()
                })
            }
            Product::Maps(m) => {
                let MapsProduct {
                    surface,
                    occlusion,
                    quadrature,
                    png,
                } = *m;
                let surface = surface.context("the baker kept no primary hits for the maps")?;
                let b = &to.swatch.bounds;
                let maps = ptm_bake::maps::Maps::finish(
                    &surface,
                    &occlusion,
                    to.coverage,
                    [b.min[2], b.max[2]],
                    quadrature,
                    &to.swatch.material_names,
                )?;
                let path = ptm_bake::maps::maps_path(to.maps_of);
                let named = |p: &Path| crate::outputs::Named::new("writing", p);
                if let Some((meta, _)) = to.part {
                    // A farm part of its own, beside K's; `ptm merge` joins the rows.
                    let part = meta.shard.part_path(&path);
                    let attrs = maps.attrs.clone();
                    ptm_fit::shard::write_rows_part(
                        &part,
                        meta,
                        "maps",
                        maps.width,
                        maps.channels,
                        &attrs,
                    )
                    .with_context(|| named(&part))?;
                    return Ok(ProductWritten {
                        maps: Some(json::BakeMaps {
                            file: json::path(&part),
                            png: Vec::new(),
                            dome_fraction: occlusion.dome_fraction(),
                        }),
                        ..Default::default()
                    });
                }
                let bytes = maps.encode(&path).with_context(|| named(&path))?;
                tx.stage_bytes(&path, &bytes)
                    .with_context(|| named(&path))?;
                let mut pngs = Vec::new();
                if png {
                    for (name, channels, data) in maps.png16() {
                        let p = ptm_bake::maps::png_path(to.maps_of, &name);
                        if name.starts_with("mask.") {
                            // The masks' names come with the swatch: checked here.
                            tx.add(&p).with_context(|| named(&p))?;
                        }
                        let bytes = png16(maps.width, maps.height, channels, data)
                            .with_context(|| named(&p))?;
                        tx.stage_bytes(&p, &bytes).with_context(|| named(&p))?;
                        pngs.push(p);
                    }
                }
                let info = json::BakeMaps {
                    file: json::path(&path),
                    png: json::paths(&pngs),
                    dome_fraction: occlusion.dome_fraction(),
                };
                Ok(ProductWritten {
                    files: Vec::new(),
                    maps: Some(info),
                    ..Default::default()
                })
            }
            Product::Stack(planes) => {
                let stack = SampleStack {
                    width: to.size[0],
                    height: to.size[1],
                    tile: to.swatch.tile,
                    lights: to.lights.clone(),
                    k: planes.k,
                    coverage: to.coverage.to_vec(),
                    uv: planes.uv,
                };
                match to.part {
                    Some((meta, path)) => {
                        crate::shard::write_stack(path, meta, stack).with_context(writing)?
                    }
                    None => {
                        let bytes = stack.encode_into(output).with_context(writing)?;
                        tx.stage_bytes(output, &bytes).with_context(writing)?;
                    }
                }
                Ok(ProductWritten {
                    files: vec![output.to_path_buf()],
                    ..Default::default()
                })
            }
        }
    }
}

/// Finishes every product and stages its files for `--output` (or writes the farm part), and
/// the dome's `.lp` beside a whole bake (a part carries its lights; `ptm merge` writes the
/// `.lp` beside the merged output); publishes them together.
fn write_outputs(
    swatch: &PreparedMesh,
    lights: &LightSet,
    kept: Kept,
    part: &Option<(PartMeta, PathBuf)>,
    dest: Destinations,
    shard_mips: bool,
) -> anyhow::Result<Written> {
    let Kept {
        products,
        coverage,
        size,
    } = kept;
    let Destinations {
        mut tx,
        output,
        lp,
        lights_file,
        layout,
        maps_of,
    } = dest;
    let maps_of = maps_of.as_path();
    let t0 = Instant::now();
    let to = WriteTo {
        swatch,
        lights,
        coverage: &coverage,
        size,
        part,
        shard_mips,
        output: &output,
        maps_of,
        layout,
    };
    let (mut files, mut fit_json, mut maps, mut t_fit) = (Vec::new(), None, None, 0.0);
    for p in products {
        let w = p.write(&to, &mut tx)?;
        files.extend(w.files);
        fit_json = fit_json.or(w.fit);
        maps = maps.or(w.maps);
        t_fit += w.t_fit;
    }
    if part.is_none() {
        if let Some(lp) = &lp {
            tx.stage_bytes(lp, lights.to_lp().as_bytes())
                .with_context(|| crate::outputs::Named::new("writing", lp))?;
        }
        tx.commit()?;
    }
    Ok(Written {
        fit: fit_json,
        maps,
        output,
        files,
        lp,
        lights_file: if part.is_none() { lights_file } else { None },
        t_fit,
        t_write: t0.elapsed().as_secs_f64() - t_fit,
    })
}

/// A 16-bit grey (`channels` 1) or RGB (3) PNG of `width × height` samples, top row first.
fn png16(width: usize, height: usize, channels: u8, data: Vec<u16>) -> anyhow::Result<Vec<u8>> {
    let (w, h) = (width as u32, height as u32);
    let mut out = std::io::Cursor::new(Vec::new());
    let bad = || anyhow::anyhow!("{width}×{height} image of {channels} channels");
    match channels {
        1 => image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, data)
            .ok_or_else(bad)?
            .write_to(&mut out, image::ImageFormat::Png)?,
        _ => image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, data)
            .ok_or_else(bad)?
            .write_to(&mut out, image::ImageFormat::Png)?,
    }
    Ok(out.into_inner())
}

/// The closing lines on stderr: ray throughput, then what was written.
fn print_summary(report: &BakeReport, written: &Written) {
    let rays = report.primary_rays + report.shadow_rays;
    let t_trace = report.seconds_primary + report.seconds_shadow;
    let max_rings = report.rings.iter().copied().max().unwrap_or(0);
    eprintln!(
        "ptm bake: {:.2} Mrays in {:.2} s ({:.2} Mrays/s), up to {} rings of copies ({}×{})",
        rays as f64 / 1e6,
        t_trace,
        rays as f64 / 1e6 / t_trace.max(1e-9),
        max_rings,
        2 * max_rings + 1,
        2 * max_rings + 1
    );
    let mut all = written.files.clone();
    if let Some(m) = &written.maps {
        all.push(PathBuf::from(&m.file));
        all.extend(m.png.iter().map(PathBuf::from));
    }
    let files = crate::outputs::list(&all);
    match (&written.lp, &written.lights_file) {
        (Some(lp), _) => eprintln!(
            "ptm bake: wrote {}",
            crate::outputs::list(&[&all[..], std::slice::from_ref(lp)].concat())
        ),
        (None, Some(user)) => eprintln!(
            "ptm bake: wrote {files}; its lights are in {} (the --lights file, left as it is)",
            user.display()
        ),
        (None, None) => eprintln!("ptm bake: wrote {files}"),
    }
}

/// The object `--json` prints.
#[allow(clippy::too_many_arguments)]
fn bake_json(
    args: &Args,
    swatch: &PreparedMesh,
    res: [usize; 2],
    rows: Range<usize>,
    lights: &LightSet,
    report: &BakeReport,
    written: Written,
    t_load: f64,
    t_all: Instant,
) -> json::Baked {
    let rays = report.primary_rays + report.shadow_rays;
    let t_trace = report.seconds_primary + report.seconds_shadow;
    json::Baked {
        swatch: swatch.origin.clone(),
        output: json::path(&written.output),
        files: json::paths(&written.files),
        shard: args.shard.map(|s| s.to_string()),
        rows: [rows.start, rows.end],
        lights_file: written.lights_file.as_deref().map(json::path),
        triangles: swatch.triangles.len(),
        degenerate_triangles: swatch.degenerate,
        tile: swatch.tile,
        seam_mismatch: swatch.seams.map(|s| s.mismatch.and_then(json::finite)),
        warnings: swatch
            .warnings()
            .into_iter()
            .chain(light_warnings(lights))
            .map(|w| crate::errors::swatch_warning(&w))
            .collect(),
        width: res[0],
        height: res[1],
        texel: [
            swatch.tile[0] / res[0] as f64,
            swatch.tile[1] / res[1] as f64,
        ],
        spp: args.spp,
        seed: args.seed,
        lights: lights.len(),
        light_distance: args.light_distance,
        device: json::BakeDevice::default(),
        rays: json::Rays {
            primary: report.primary_rays,
            shadow: report.shadow_rays,
            shadow_skipped: report.shadow_rays_skipped,
        },
        mrays_per_s: rays as f64 / 1e6 / t_trace.max(1e-9),
        rings: report.rings.clone(),
        copies: report.copies.clone(),
        centred_scenes: report.centred_scenes,
        uncovered_texels: report.uncovered_texels,
        below_horizon: report.below_horizon.clone(),
        capped: report.capped.clone(),
        fit: written.fit,
        maps: written.maps,
        seconds: t_all.elapsed().as_secs_f64(),
        seconds_load: t_load,
        seconds_scene: report.seconds_scene,
        seconds_primary: report.seconds_primary,
        seconds_shadow: report.seconds_shadow,
        seconds_fit: written.t_fit,
        seconds_write: written.t_write,
    }
}

/// The options of the streaming fit `--fit f` asks for.
fn fit_options(args: &Args, f: Basis) -> FitOptions {
    let mut opts = FitOptions {
        regularize: args.regularize,
        holdout: args.holdout.unwrap_or(0),
        ..FitOptions::new(f)
    };
    args.model.apply(&mut opts);
    opts
}

/// Refuses a bake whose buffers cannot fit in the memory this machine has available, naming
/// the parts and what to change, instead of being killed by the kernel half-way.
fn check_memory(
    args: &Args,
    res: [usize; 2],
    lights: usize,
    materials: usize,
    device: ptm_gpubake::Used,
) -> anyhow::Result<()> {
    let Some(available) = available_memory() else {
        return Ok(());
    };
    // In f64: absurd requests must be measured, not overflow.
    // The tracer's host memory: Embree's primary samples, or the GPU bake's pass planes and
    // (with several bands) its samples between passes.
    let baker = match device {
        ptm_gpubake::Used::Cpu => {
            ptm_bake::baker_bytes(res, args.spp) + ptm_bake::centred_bytes(res, args.spp, lights)
        }
        ptm_gpubake::Used::Gpu => ptm_gpubake::budget::host_bytes(
            res[0],
            res[1],
            args.spp,
            2,
            args.light_distance.is_some(),
        ),
    };
    let dome = lights as f64 * 64.0;
    let products: Vec<(f64, &str)> = ProductKind::of(args)
        .into_iter()
        .map(|p| p.memory(args, res, lights, materials))
        .collect();
    let sink: f64 = products.iter().map(|p| p.0).sum();
    let what: String = products
        .iter()
        .map(|(bytes, what)| format!("{what}: {:.1} GiB", bytes / (1u64 << 30) as f64))
        .collect::<Vec<_>>()
        .join("; ");
    let need = baker + dome + sink;
    if need > 0.9 * available as f64 {
        let gib = |b: f64| b / (1u64 << 30) as f64;
        bail!(
            "this bake needs about {:.1} GiB ({}×{} texels × {} spp of primary samples and scenes: {:.1} GiB; \
             {} lights: {:.1} GiB; {}) but only {:.1} GiB of memory is available: lower \
             --res, --spp or the number of lights{}",
            gib(need),
            res[0],
            res[1],
            args.spp,
            gib(baker),
            lights,
            gib(dome),
            what,
            gib(available as f64),
            if args.fit.is_none() {
                ", or fit while baking (--fit ptm6 -o out.ptm.exr) so no stack is stored"
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// `MemAvailable` from /proc/meminfo, in bytes (None where there is no such file).
fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
