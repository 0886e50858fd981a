//! The measured study behind `ptm report`, as typed results: what accuracy each bake and fit
//! setting buys and what it costs (error of K on held-out lights against seconds, with the
//! Pareto front), how the tool behaves on stiff and extreme cases, and how the runtime's soft
//! shadows compare with Monte Carlo and analytic answers.
//!
//! [`run`] measures and returns a [`Report`]; nothing here writes a file except the scratch
//! PTMs of the precision study. [`Report::tables`] renders every table to text cells (the CSV
//! and Markdown the `ptm report` command writes); the command also draws the plots and the
//! contact sheet from the typed results and writes the prose around them.

pub mod baselines;
pub mod compare;
pub mod runtime;
pub mod sheet;
pub mod stability;
pub mod study;
pub mod table;
mod tables;

use std::path::PathBuf;

use ptm_bake::PreparedMesh;
use ptm_fit::Weight;
use ptm_format::{Basis, Link, UvMap};

pub use runtime::Runtime;
pub use sheet::ContactSheet;
pub use stability::Stability;
pub use study::{Errors, Outcome, Setting, SwatchStudy};
pub use table::{g3, Table};
pub use tables::Tables;

/// What can stop the study (data-dependent numeric trouble is measured, not an error).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A bake of the study failed.
    #[error(transparent)]
    Bake(#[from] ptm_bake::Error),
    /// A fit of the study failed.
    #[error(transparent)]
    Fit(#[from] ptm_fit::Error),
    /// Writing or reading a scratch PTM failed.
    #[error(transparent)]
    Format(#[from] ptm_format::Error),
    /// A builtin swatch could not be built.
    #[error(transparent)]
    Swatch(#[from] ptm_swatches::Error),
    /// A render of the runtime part failed.
    #[error(transparent)]
    Runtime(#[from] ptm_runtime::Error),
    /// `ptm_runtime::Gpu::new` failed: the runtime part needs an adapter.
    #[error("the runtime part of the report needs a wgpu adapter (lavapipe: scripts/setup.sh)")]
    NoAdapter(#[source] ptm_runtime::Error),
    /// The options name no swatch.
    #[error("no swatch to study")]
    NoSwatch,
}

/// The report crate's result type.
pub type Result<T> = std::result::Result<T, Error>;

/// The (link, (u, v) map) pairs: the patent's plain PTM first, `ptm fit`'s default last.
pub const MODELS: [(Link, UvMap); 4] = [
    (Link::Identity, UvMap::Projected),
    (Link::Identity, UvMap::Hemispherical),
    (Link::Logistic, UvMap::Projected),
    (Link::Logistic, UvMap::Hemispherical),
];

/// What to study.
#[derive(Clone, Debug)]
pub struct Options {
    /// The small sweep (what CI runs) instead of the full study.
    pub quick: bool,
    /// Builtin swatch names (`plain-weave`, not `builtin:plain-weave`); the stability cases
    /// run on the first.
    pub swatches: Vec<String>,
    /// An existing folder for the precision study's scratch PTM files (each removed after
    /// it is read back).
    pub scratch: PathBuf,
}

/// Sizes of one study: [`Plan::new`] is the one place they are chosen.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The quick plan (`ptm report --quick`): smaller bakes and fewer settings.
    pub quick: bool,
    /// Texels a side and samples per texel of each of the two ground-truth bakes.
    pub truth_res: usize,
    /// Samples per texel of the truth bakes.
    pub truth_spp: u32,
    /// Held-out light directions the error is measured on.
    pub test_lights: usize,
    /// Every bake and fit setting of the sweep, each once, in first-seen order.
    pub settings: Vec<Setting>,
    /// Samples per texel of the stability bakes.
    pub spp: u32,
    /// Fibonacci lights of the ridge-λ sweep.
    pub ridge_dirs: usize,
    /// Contact sheet: texels across each swatch's tile width, samples per texel, and the
    /// light's elevation in degrees above the swatch plane (azimuth 30°).
    pub sheet_texels: usize,
    /// Contact sheet: samples per texel.
    pub sheet_spp: u32,
    /// Contact sheet: the light's elevation, degrees above the swatch plane.
    pub sheet_elevation_deg: f64,
    /// The models against the classic alternatives (issue #22): texels a side, samples per
    /// texel and Fibonacci training lights above 5° (the truth: 4× the samples).
    pub alternatives: (usize, u32, usize),
    /// … on every parameterless builtin (the full study) or the study's swatches (quick).
    pub alternatives_all: bool,
}

impl Plan {
    /// The full study's sizes, or the quick ones.
    pub fn new(quick: bool) -> Plan {
        let s = |dirs, spp, res, basis, weight, (link, uv): (Link, UvMap)| Setting {
            dirs,
            spp,
            res,
            basis,
            weight,
            link,
            uv,
        };
        let (u, c) = (Weight::Uniform, Weight::Cosine);
        let (p6, p11) = (Basis::Ptm6, Basis::Ptm11);
        let (plain, default) = (MODELS[0], MODELS[3]);
        let mut settings = Vec::new();
        // Rays against error for the plain PTM and for the default model; then all four
        // models at the bakes where the model, not the rays, limits the error.
        let (dirs, spps, res, all_four): (&[usize], &[u32], usize, &[usize]) = if quick {
            (&[16, 32, 64, 128], &[1, 4, 16], 32, &[64])
        } else {
            (&[16, 64, 256, 1024], &[1, 4, 16], 64, &[64, 256, 1024])
        };
        for &d in dirs {
            for &spp in spps {
                for m in [plain, default] {
                    settings.push(s(d, spp, res, p6, u, m));
                }
            }
        }
        let spp = if quick { 4 } else { 16 };
        for &d in all_four {
            for basis in [p6, p11] {
                for m in MODELS {
                    settings.push(s(d, spp, res, basis, u, m));
                }
            }
        }
        let mid = all_four[all_four.len() / 2];
        for basis in [p6, p11] {
            for m in [plain, default] {
                settings.push(s(mid, spp, res, basis, c, m));
            }
        }
        for m in [plain, default] {
            settings.push(s(mid, spp, res / 2, p6, u, m));
        }
        // Each setting once (the sweeps overlap), in first-seen order.
        let mut seen = Vec::new();
        settings.retain(|x| {
            let new = !seen.contains(x);
            if new {
                seen.push(x.clone());
            }
            new
        });
        let (truth_res, truth_spp, test_lights, spp) = if quick {
            (32, 32, 32, 4)
        } else {
            (64, 128, 64, 8)
        };
        Plan {
            quick,
            truth_res,
            truth_spp,
            test_lights,
            settings,
            spp,
            ridge_dirs: if quick { 64 } else { 256 },
            sheet_texels: if quick { 64 } else { 128 },
            sheet_spp: 4,
            sheet_elevation_deg: 20.0,
            alternatives: if quick { (32, 4, 64) } else { (96, 8, 256) },
            alternatives_all: !quick,
        }
    }
}

/// Everything the study measured.
#[derive(Clone, Debug)]
pub struct Report {
    /// The sizes the study ran with.
    pub plan: Plan,
    /// One per swatch of [`Options::swatches`], in order.
    pub swatches: Vec<SwatchStudy>,
    /// Every parameterless builtin under one low light.
    pub contact_sheet: ContactSheet,
    /// The PTMs and learned bases against a horizon map and AO micro-shadowing, per swatch
    /// ([`Plan::alternatives`]), each with its truth's own sampling noise.
    pub alternatives: Vec<(compare::CompareRow, f64)>,
    /// On the first swatch.
    pub stability: Stability,
    /// Blur methods and penumbra extremes on the adapter found.
    pub runtime: Runtime,
}

/// Runs the whole study: the sweep per swatch, the contact sheet, the stability cases on the
/// first swatch, then the runtime part on whatever adapter wgpu finds. `progress` gets one
/// line per step (without a prefix), for a log.
pub fn run(opts: &Options, progress: &mut dyn FnMut(&str)) -> Result<Report> {
    let plan = Plan::new(opts.quick);
    let test = study::test_lights(plan.test_lights)?;
    let mut swatches = Vec::new();
    let mut first = None;
    for name in &opts.swatches {
        let swatch = PreparedMesh::load(&format!("builtin:{name}"), None)?;
        let (s, truth) = SwatchStudy::run(name, &swatch, &plan, &test, progress)?;
        swatches.push(s);
        first.get_or_insert((swatch, truth));
    }
    let (swatch, truth) = first.ok_or(Error::NoSwatch)?;
    let (res, spp, dirs) = plan.alternatives;
    let names: Vec<String> = if plan.alternatives_all {
        sheet::names().into_iter().map(String::from).collect()
    } else {
        opts.swatches.clone()
    };
    let mut alternatives = Vec::new();
    for name in &names {
        progress(&format!("{name}: against the classic alternatives"));
        let mesh = PreparedMesh::load(&format!("builtin:{name}"), None)?;
        let truth = study::Truth::bake(&mesh, res, spp * 4, test.clone())?;
        let row = compare::compare(name, &mesh, &truth, dirs, spp, res)?;
        alternatives.push((row, truth.noise));
    }
    progress("contact sheet");
    let contact_sheet =
        ContactSheet::bake(plan.sheet_texels, plan.sheet_spp, plan.sheet_elevation_deg)?;
    progress("stability cases");
    let stability = Stability::run(&opts.swatches[0], &swatch, &truth, &plan, &opts.scratch)?;
    progress("runtime (blur methods against Monte Carlo, extreme cases)");
    let runtime = Runtime::run(plan.quick)?;
    Ok(Report {
        plan,
        swatches,
        contact_sheet,
        alternatives,
        stability,
        runtime,
    })
}
