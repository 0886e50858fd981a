//! What `--json` prints: one serde type per subcommand's object ([`Bake`], [`Fit`], [`Preview`],
//! [`Swatch`], [`Report`], [`Merge`], [`Batch`], [`Convert`]) and [`Failure`], the `error` object
//! of any failed run; nested objects have types of their own, shared where two commands print
//! the same one ([`Logistic`], [`Stats`]). Each key is a field, documented here.
//!
//! [`to_value`] makes the object `main` prints: a `serde_json::Value`, whose maps keep their
//! keys sorted (serde_json without `preserve_order`), so the printed key order is alphabetical
//! whatever the field order below, as it always was. The unit tests pin every object's key
//! paths and their JSON types in `tests/snapshots/json_keys.txt` and write the same list as
//! `docs/json.md`; `UPDATE_SNAPSHOTS=1 cargo test -p ptm --bin ptm json::` rewrites both.
use std::path::Path;

use ptm_fit::solve::{ErrorStats, FitReport};
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};
use serde_json::Value;

/// The value `--json` prints for `t`.
pub fn to_value<T: Serialize>(t: &T) -> anyhow::Result<Value> {
    Ok(serde_json::to_value(t)?)
}

/// A path as `--json` gives it: its text, with bytes that are not UTF-8 replaced (a file name
/// need not be UTF-8; never a panic).
pub fn path(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Paths as `--json` gives them ([`path`] of each).
pub fn paths<P: AsRef<Path>>(ps: &[P]) -> Vec<String> {
    ps.iter().map(|p| path(p.as_ref())).collect()
}

/// `x` where it is finite; null for NaN and ±∞.
pub fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// A library's stage timings, `(stage, seconds)`, as the keys `seconds_<stage>` of the object
/// they are flattened into (spaces as `_`: `"mip levels"` → `seconds_mip_levels`), the one
/// naming every subcommand's timings use.
#[derive(Clone, Debug, Default)]
pub struct Stages(pub Vec<(&'static str, f64)>);

impl Serialize for Stages {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (stage, seconds) in &self.0 {
            map.serialize_entry(&format!("seconds_{}", stage.replace(' ', "_")), seconds)?;
        }
        map.end()
    }
}

/// Seconds per render pass, by the runtime's pass names (`upload`, `shade`, `readback`, …).
#[derive(Clone, Debug, Default)]
pub struct Passes(pub Vec<(&'static str, f64)>);

impl Serialize for Passes {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (pass, seconds) in &self.0 {
            map.serialize_entry(pass, seconds)?;
        }
        map.end()
    }
}

/// Any failed run, argument errors included: `{"error": {…}}`.
#[derive(Serialize, Debug, Default)]
pub struct Failure {
    /// What failed.
    pub error: ErrorInfo,
}

/// The `error` object.
#[derive(Serialize, Debug, Default)]
pub struct ErrorInfo {
    /// The whole error chain in words (what stderr says after `ptm: error:`).
    pub message: String,
    /// `usage`, `io`, `gpu`, `embree` or `invalid`.
    pub kind: &'static str,
    /// The file or argument at fault (null when the error names none).
    pub input: Option<String>,
}

/// A logistic fit's statistics (`logistic` of `ptm fit` and of `ptm bake --fit`; null for the
/// identity link).
#[derive(Serialize, Debug, Default)]
pub struct Logistic {
    /// Newton iterations per covered texel, on average.
    pub iterations_mean: f64,
    /// The most Newton iterations a texel took.
    pub iterations_max: u32,
    /// Texels that reached `max_iterations` before the tolerance.
    pub not_converged_texels: usize,
    /// Texels whose samples a polynomial splits exactly into lit and occluded (held finite by
    /// the ridge).
    pub separable_texels: usize,
    /// Texels always lit or always occluded.
    pub constant_texels: usize,
    /// The ridge λ, relative to the mean eigenvalue.
    pub lambda: f64,
    /// The ridge in absolute terms (λ × the mean eigenvalue).
    pub ridge_absolute: f64,
    /// Newton's tolerance per unit light weight.
    pub tolerance: f64,
    /// Newton's iteration cap per texel.
    pub max_iterations: u32,
    /// The instruction set the kernel ran on (`avx512f`, `avx2+fma`, `portable`).
    pub kernel: &'static str,
}

impl Logistic {
    /// The statistics of `r`'s logistic fit (none for the identity link).
    pub fn of(r: &FitReport) -> Option<Logistic> {
        r.logistic.as_ref().map(|s| Logistic {
            iterations_mean: s.iterations_mean,
            iterations_max: s.iterations_max,
            not_converged_texels: s.not_converged,
            separable_texels: s.separable,
            constant_texels: s.constant,
            lambda: s.lambda,
            ridge_absolute: s.ridge,
            tolerance: s.tolerance,
            max_iterations: s.max_iterations,
            kernel: s.kernel,
        })
    }
}

/// What learning a basis did (`learned` of `ptm fit` and of `ptm bake --fit`; null for a
/// polynomial basis).
#[derive(Serialize, Debug, Default)]
pub struct Learned {
    /// Terms k of the learned basis.
    pub terms: usize,
    /// Side G of each term's G × G table over the hemispherical (u, v) square.
    pub grid: usize,
    /// Roughness λ of the tables (penalty λ × texels ÷ the polynomial start's mean deviance per
    /// fitted sample × the squared second differences).
    pub roughness: f64,
    /// Texels the basis was learned on (a deterministic subsample of the covered ones).
    pub texels: usize,
    /// Alternations of table and coefficient Newton steps run.
    pub alternations: u32,
    /// The alternation whose tables were kept: that of the lowest held-out RMS error on the
    /// subsample when lights are held out (0: the polynomial start), else the last.
    pub kept: u32,
    /// Mean binomial deviance per sample on those texels at the start (the polynomial basis
    /// of the same size).
    pub deviance_start: f64,
    /// Mean binomial deviance per sample on those texels with the learned basis.
    pub deviance: f64,
    /// Weighted RMS of σ − K on those texels' fitting samples at the start.
    pub rms_start: f64,
    /// Weighted RMS of σ − K on those texels' fitting samples with the learned basis.
    pub rms: f64,
    /// Seconds of the learning stage.
    pub seconds: f64,
}

impl Learned {
    /// What `r`'s learning stage did (none for a polynomial basis).
    pub fn of(r: &FitReport) -> Option<Learned> {
        r.learned.as_ref().map(|s| Learned {
            terms: s.terms,
            grid: s.grid,
            roughness: s.roughness,
            texels: s.texels,
            alternations: s.alternations,
            kept: s.kept,
            deviance_start: s.deviance_start,
            deviance: s.deviance,
            rms_start: s.rms_start,
            rms: s.rms,
            seconds: s.seconds,
        })
    }
}

/// Statistics of a per-texel error of K over the covered texels.
#[derive(Serialize, Debug, Default)]
pub struct Stats {
    /// Mean over texels.
    pub mean: f64,
    /// 99th percentile over texels.
    pub p99: f64,
    /// Maximum over texels.
    pub max: f64,
}

impl From<&ErrorStats> for Stats {
    fn from(s: &ErrorStats) -> Stats {
        Stats {
            mean: s.mean,
            p99: s.p99,
            max: s.max,
        }
    }
}

/// `ptm bake`: a bake, or a farm part found complete.
#[derive(Serialize, Debug)]
#[serde(untagged)]
pub enum Bake {
    /// The bake (or farm part) was traced and written.
    Baked(Box<Baked>),
    /// `--shard`: the part was already complete and valid; nothing was baked.
    Skipped(SkippedPart),
}

/// `ptm bake --shard I/N` whose part is already complete.
#[derive(Serialize, Debug, Default)]
pub struct SkippedPart {
    /// The part file, kept as it was.
    pub part: String,
    /// Always true.
    pub skipped: bool,
}

/// `ptm bake --maps`: the companion maps written beside the output.
#[derive(Serialize, Debug, Default)]
pub struct BakeMaps {
    /// The maps' EXR (`NAME.maps.exr`: height, normal, ao, bent, coverage).
    pub file: String,
    /// The 16-bit PNGs (`--maps-png`; empty without).
    pub png: Vec<String>,
    /// Fraction of the cosine-weighted hemisphere the dome samples (Σ w·cos θ / π): what the
    /// elevation cut-off leaves out of the ambient occlusion.
    pub dome_fraction: f64,
}

/// `ptm bake`: what was traced and written.
#[derive(Serialize, Debug, Default)]
pub struct Baked {
    /// The swatch as given (`builtin:…` or the OBJ's path).
    pub swatch: String,
    /// The file written: `--output`, or the farm part.
    pub output: String,
    /// Every file of the stack or PTM (the renderer layout's parts).
    pub files: Vec<String>,
    /// `I/N` of a farm part (null for a whole bake).
    pub shard: Option<String>,
    /// The texel rows traced, [start, end).
    pub rows: [usize; 2],
    /// The `.lp` holding the output's lights: written beside it, or the `--lights` file (null
    /// for a part or a device output).
    pub lights_file: Option<String>,
    /// Triangles traced.
    pub triangles: usize,
    /// Zero-area triangles dropped.
    pub degenerate_triangles: usize,
    /// Tile W, H in mesh units.
    pub tile: [f64; 2],
    /// Per axis (x, y), how far the mesh's sections at the two tile borders differ, in mesh
    /// units (null where the mesh reaches across that border, or where it is infinite).
    pub seam_mismatch: [Option<f64>; 2],
    /// The bake's warnings, in words: the swatch's (degenerate triangles, seams) and the light
    /// set's (lights at or below the horizon, each named).
    pub warnings: Vec<String>,
    /// Texels per row of the whole bake.
    pub width: usize,
    /// Rows of the whole bake.
    pub height: usize,
    /// A texel's width and height in mesh units (tile / texels: square for `--res N`).
    pub texel: [f64; 2],
    /// Footprint samples per texel.
    pub spp: u32,
    /// Seed of the sample positions.
    pub seed: u64,
    /// Lights traced.
    pub lights: usize,
    /// Radius of the point-light hemisphere (null: distant lights).
    pub light_distance: Option<f64>,
    /// The device that traced, and why.
    pub device: BakeDevice,
    /// Rays traced.
    pub rays: Rays,
    /// Million rays (primary + shadow) per second of tracing.
    pub mrays_per_s: f64,
    /// Per light, the rings of neighbour tiles that can shadow the centre tile.
    pub rings: Vec<u32>,
    /// Per light, the tile copies in its scene.
    pub copies: Vec<usize>,
    /// Scenes of copies built with the central copy as the tile's triangles, where that pays (0: instances only, or the GPU).
    pub centred_scenes: usize,
    /// Texels that see no swatch (coverage 0).
    pub uncovered_texels: usize,
    /// Lights at or below the horizon (K = 1).
    pub below_horizon: Vec<usize>,
    /// Lights so low that their shadows were followed only so far.
    pub capped: Vec<usize>,
    /// The streaming fit (null without `--fit`).
    pub fit: Option<BakeFit>,
    /// The companion maps written (absent without `--maps`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub maps: Option<BakeMaps>,
    /// The whole run.
    pub seconds: f64,
    /// Loading the swatch.
    pub seconds_load: f64,
    /// Building the scenes.
    pub seconds_scene: f64,
    /// Primary rays.
    pub seconds_primary: f64,
    /// Shadow rays (the streaming fit's accumulation included).
    pub seconds_shadow: f64,
    /// The fit's solve.
    pub seconds_fit: f64,
    /// Encoding and writing.
    pub seconds_write: f64,
}

/// Which device traced a bake (`--device`) and why.
#[derive(Serialize, Debug, Default)]
pub struct BakeDevice {
    /// What was asked for: `cpu`, `gpu` or `auto`.
    pub asked: String,
    /// What traced: `cpu` (Embree) or `gpu` (wgpu ray queries).
    pub used: String,
    /// The adapter that traced, or for `auto` on the CPU the first adapter seen, described
    /// (null when none was looked for or found).
    pub adapter: Option<String>,
    /// Why, in words.
    pub reason: String,
}

impl BakeDevice {
    /// The `--device` choice in words.
    pub fn of(c: &ptm_gpubake::Choice) -> BakeDevice {
        BakeDevice {
            asked: c.asked.name().into(),
            used: c.used.name().into(),
            adapter: c.adapter_name.clone(),
            reason: c.reason.clone(),
        }
    }
}

/// Rays a bake traced.
#[derive(Serialize, Debug, Default)]
pub struct Rays {
    /// Primary rays (one per footprint sample).
    pub primary: u64,
    /// Shadow rays.
    pub shadow: u64,
    /// Shadow rays not traced (no copy can shadow the sample for that light).
    pub shadow_skipped: u64,
}

/// `ptm bake --fit`: the streaming fit.
#[derive(Serialize, Debug, Default)]
pub struct BakeFit {
    /// `ptm6`, `ptm11` or `learnedN`.
    pub basis: Option<&'static str>,
    /// `identity` or `logistic`.
    pub link: &'static str,
    /// `projected` or `hemispherical`.
    pub uv: &'static str,
    /// MIP levels fitted.
    pub mip_levels: usize,
    /// The logistic fit's statistics (null for the identity link).
    pub logistic: Option<Logistic>,
    /// What learning the basis did (null for a polynomial basis).
    pub learned: Option<Learned>,
    /// The solver, in words.
    pub solver: String,
    /// Rank of the design matrix.
    pub rank: usize,
    /// Condition number of the design matrix (null when infinite).
    pub condition_number: Option<f64>,
    /// RMS residual of K per texel: mean.
    pub rms_error_mean: f64,
    /// RMS residual of K per texel: 99th percentile.
    pub rms_error_p99: f64,
    /// The fit's warnings, in words.
    pub warnings: Vec<String>,
    /// Indices of the lights held out of the fit and scored (`--holdout`; with `--fit auto`
    /// by default an eighth).
    pub holdout_lights: Vec<usize>,
    /// RMS error of K per texel on the held-out lights (null when none are held out).
    pub holdout_rms_error: Option<Stats>,
    /// `--fit auto`: every candidate's held-out error and fit time, and which was kept (null
    /// for a given basis).
    pub auto: Option<Auto>,
    /// Seconds of each stage of the streaming fit (`seconds_accumulate`, `seconds_newton`,
    /// `seconds_mip_levels`, …).
    #[serde(flatten)]
    pub stages: Stages,
}

/// `ptm fit --basis auto` and `ptm bake --fit auto`: every candidate basis fitted on the same lights and scored on the
/// same held-out ones, and which was kept.
#[derive(Serialize, Debug, Default)]
pub struct Auto {
    /// A candidate is kept when its held-out error is at most (1 + margin) × the best one's.
    pub margin: f64,
    /// The basis kept: the first candidate (in the order listed, cheapest first) within the
    /// margin of the best.
    pub chosen: String,
    /// The candidates in the order tried.
    pub candidates: Vec<AutoCandidate>,
}

/// One candidate of `--basis auto`.
#[derive(Serialize, Debug, Default)]
pub struct AutoCandidate {
    /// `ptm6`, `learned6`, `ptm11` or `learned11`.
    pub basis: String,
    /// Mean over texels of the per-texel RMS error of K on the held-out lights (null when the
    /// candidate was not fitted).
    pub holdout_rms_error: Option<f64>,
    /// Seconds of its fit.
    pub seconds: f64,
    /// Why it was not fitted (a learned basis over a dome too sparse for it, or a link or
    /// (u, v) map it does not take); null when it was.
    pub skipped: Option<String>,
}

/// `ptm fit`: the PTM fitted and written.
#[derive(Serialize, Debug, Default)]
pub struct Fit {
    /// The sample stack, or the `--images` pattern.
    pub input: String,
    /// `--output`.
    pub output: String,
    /// `channels` or `rgba`.
    pub layout: &'static str,
    /// Every file of the PTM (the renderer layout's parts, its error map).
    pub files: Vec<String>,
    /// `ptm6`, `ptm11` or `learnedN`.
    pub basis: &'static str,
    /// `identity` or `logistic`.
    pub link: &'static str,
    /// `projected` or `hemispherical`.
    pub uv: &'static str,
    /// MIP levels written.
    pub mip_levels: usize,
    /// The logistic fit's statistics (null for the identity link).
    pub logistic: Option<Logistic>,
    /// What learning the basis did (null for a polynomial basis).
    pub learned: Option<Learned>,
    /// `--basis auto`: the candidates and their held-out errors (null for a given basis).
    pub auto: Option<Auto>,
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Texels fitted.
    pub texels: usize,
    /// Texels with coverage 0.
    pub masked_texels: usize,
    /// Lights in the input.
    pub lights: usize,
    /// Lights fitted (the rest are held out).
    pub lights_fit: usize,
    /// Indices of the held-out lights.
    pub holdout_lights: Vec<usize>,
    /// The hold-out count is the default (an eighth of the lights where the dome allows it),
    /// not `--holdout N`.
    pub holdout_default: bool,
    /// Coefficients per texel.
    pub coefficients: usize,
    /// Rank of the design matrix.
    pub rank: usize,
    /// Condition number of the design matrix (null when infinite).
    pub condition_number: Option<f64>,
    /// Singular values below this count as zero.
    pub cutoff: f64,
    /// `--rcond`: singular values below rcond × the largest count as zero.
    pub rcond: f64,
    /// The design matrix's singular values.
    pub singular_values: Vec<f64>,
    /// The solver, in words.
    pub solver: String,
    /// `uniform` or `cosine`.
    pub weight: &'static str,
    /// The fit's warnings, in words.
    pub warnings: Vec<String>,
    /// RMS residual of K per texel over the fitted lights.
    pub rms_error: Stats,
    /// Largest |residual| of K per texel (null where the fit does not measure it).
    pub max_error: Option<Stats>,
    /// RMS error of K per texel on the held-out lights (null when none are held out).
    pub holdout_rms_error: Option<Stats>,
    /// Non-finite samples dropped (`--skip-bad`).
    pub skipped_samples: usize,
    /// Texels whose own light set is rank deficient (per-texel directions).
    pub rank_deficient_texels: usize,
    /// `float32` or `half`.
    pub storage: &'static str,
    /// With `--half`: the most half floats change K anywhere on the unit disk.
    pub half_error_bound: Option<f64>,
    /// The HP PTM 1.2 export (null without `--export-hp`).
    pub hp_export: Option<HpExport>,
    /// `--png-k`: K of the fit under light `png_light` as a grey PNG (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub png_k: Option<String>,
    /// The light `png_k` shows (absent without `--png-k`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub png_light: Option<usize>,
    /// `--png-error`: the per-texel RMS residual as a grey PNG, white = 0.25 (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub png_error: Option<String>,
    /// How an RTI image stack's values became K (null for a sample stack).
    pub images: Option<Images>,
    /// The whole run.
    pub seconds: f64,
    /// Reading the input.
    pub seconds_read: f64,
    /// Seconds of each stage of the fit (`seconds_factor`, `seconds_newton`,
    /// `seconds_mip_levels`, …).
    #[serde(flatten)]
    pub stages: Stages,
    /// Encoding and writing.
    pub seconds_write: f64,
}

/// `ptm fit --export-hp`: the HP PTM 1.2 LRGB file.
#[derive(Serialize, Debug, Default)]
pub struct HpExport {
    /// The `.ptm` written.
    pub path: String,
    /// The most 8-bit quantisation changes K.
    pub quantisation_error_max: f64,
    /// How much it changes K on average.
    pub quantisation_error_mean: f64,
    /// The file's six coefficient scales.
    pub scales: [f32; 6],
    /// The file's six coefficient biases.
    pub biases: [i32; 6],
}

/// `ptm fit --images`: how the images' values became K.
#[derive(Serialize, Debug, Default)]
pub struct Images {
    /// `srgb` or `raw`.
    pub decoding: &'static str,
    /// 8-bit images decoded from sRGB to linear.
    pub srgb_decoded: usize,
    /// Images taken as linear.
    pub linear: usize,
}

/// `ptm preview`: a render, or the interactive window.
#[derive(Serialize, Debug)]
#[serde(untagged)]
pub enum Preview {
    /// The image (or turntable sheet) rendered and written.
    Render(Box<Render>),
    /// `--window`: the window's session (a build with `--features window`).
    #[cfg_attr(not(feature = "window"), allow(dead_code))]
    Window(Window),
}

/// `ptm preview -o out.png`.
#[derive(Serialize, Debug, Default)]
pub struct Render {
    /// The GPU adapter (name, backend, type).
    pub adapter: String,
    /// The shader variant, e.g. `ptm6+logistic+hemispherical+caster-sat`.
    pub variant: String,
    /// Image width, height in pixels (of one frame).
    pub size: [u32; 2],
    /// The view's rectangle on the cloth [x0, y0, x1, y1], swatch units.
    pub view: [f32; 4],
    /// Tiles of the PTM across and down the view (`--repeat`, widened along one side when
    /// `--size` has another aspect than the tiles).
    pub tiles: [f32; 2],
    /// Lights in the scene.
    pub lights: usize,
    /// The blur method (null without a caster).
    pub blur: Option<&'static str>,
    /// Opening the GPU.
    pub seconds_device: f64,
    /// Factor the caster was box-downsampled by (1: not).
    pub caster_downsample: usize,
    /// PTM coefficients that are NaN or infinite (rendered as 0).
    pub nonfinite_coeffs: usize,
    /// The runtime's warnings about the scene, in words.
    pub warnings: Vec<String>,
    /// K before clamping to [0, 1] (absent without a PTM).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_unclamped: Option<KUnclamped>,
    /// Seconds per render pass (absent with `--turntable`, whose frames have their own).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds_passes: Option<Passes>,
    /// The turntable sheet (absent without `--turntable`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turntable: Option<Turntable>,
    /// Every blur method against the Monte Carlo ground truth (absent without
    /// `--compare-blur`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compare_blur: Option<Vec<BlurRow>>,
    /// The PNG written.
    pub png: String,
    /// The linear EXR written (absent without `--exr`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exr: Option<String>,
    /// `--mesh`: the mesh rendered (absent on the plane).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshReport>,
    /// The whole run.
    pub seconds: f64,
}

/// `ptm preview --mesh`: what was rendered on the mesh.
#[derive(Serialize, Debug, Default)]
pub struct MeshReport {
    /// The built-in's name or the OBJ's path.
    pub mesh: String,
    /// Triangles drawn.
    pub triangles: usize,
    /// Triangles whose UVs or positions span no area: their tangents fell back to one
    /// perpendicular to the normal instead of MikkTSpace's.
    pub tangent_fallback_triangles: usize,
    /// Bytes of the GPU vertex buffer (three corners per triangle).
    pub vertex_buffer_bytes: u64,
    /// The companion maps read (absent without).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub maps: Option<String>,
    /// Whether the companion maps' normal map was applied.
    pub normal_map: bool,
    /// Whether the albedo came from the yarn masks and `--yarn-color`.
    pub yarn_colors: bool,
    /// Whether K darkened the key light (false with `--no-k` or without `--ptm`).
    pub k: bool,
    /// Side of the macro shadow's depth maps, one per light (0: no macro shadow, with
    /// `--no-shadow`, `--shadow-size 0` or no light).
    pub shadow_map_size: u32,
    /// Bytes of those depth maps on the GPU (0 without).
    pub shadow_map_bytes: u64,
}

/// The range of K a preview evaluated before clamping.
#[derive(Serialize, Debug, Default)]
pub struct KUnclamped {
    /// Smallest K.
    pub min: f32,
    /// Largest K.
    pub max: f32,
    /// Fraction of evaluations outside [0, 1].
    pub clamped_fraction: f64,
    /// Evaluations of K.
    pub evaluations: u64,
}

impl From<&ptm_runtime::cpu::KExcursion> for KUnclamped {
    fn from(k: &ptm_runtime::cpu::KExcursion) -> KUnclamped {
        KUnclamped {
            min: k.min,
            max: k.max,
            clamped_fraction: k.clamped_fraction,
            evaluations: k.evaluations,
        }
    }
}

/// `ptm preview --turntable N`: the contact sheet of N light azimuths.
#[derive(Serialize, Debug, Default)]
pub struct Turntable {
    /// Frames rendered.
    pub frames: u32,
    /// Frames per row of the sheet.
    pub columns: usize,
    /// Rows of frames.
    pub rows: usize,
    /// Pixels of grey gutter between frames and around the sheet.
    pub gutter: usize,
    /// Per frame, the azimuth the lights were turned by, degrees (its label on the sheet).
    pub azimuths_deg: Vec<f32>,
    /// Seconds per render pass, per frame.
    pub seconds_passes: Vec<Passes>,
}

/// `ptm preview --compare-blur`: one blur method against the Monte Carlo ground truth.
#[derive(Serialize, Debug, Default)]
pub struct BlurRow {
    /// The blur method.
    pub method: &'static str,
    /// Largest |radiance − ground truth|.
    pub max_abs_error: f32,
    /// Mean |radiance − ground truth|.
    pub mean_abs_error: f32,
    /// Shading.
    pub seconds_shade: f64,
    /// The method's setup passes.
    pub seconds_setup: f64,
}

impl From<&ptm_runtime::compare::BlurRow> for BlurRow {
    fn from(r: &ptm_runtime::compare::BlurRow) -> BlurRow {
        BlurRow {
            method: r.method,
            max_abs_error: r.max_abs_error,
            mean_abs_error: r.mean_abs_error,
            seconds_shade: r.shade_s,
            seconds_setup: r.setup_s,
        }
    }
}

/// `ptm preview --window`: what the session did.
#[derive(Serialize, Debug, Default)]
pub struct Window {
    /// The GPU adapter.
    pub adapter: String,
    /// The window surface's texture format.
    pub surface_format: String,
    /// Frames presented.
    pub frames: u32,
    /// Renders (a frame re-renders only when something changed).
    pub renders: u32,
    /// The last render.
    pub seconds_last_render: f64,
    /// The blur method at the end.
    pub blur: &'static str,
    /// Whether the PTM was shown at the end.
    pub ptm_on: bool,
    /// The first light's position at the end (null without lights).
    pub light: Option<[f32; 3]>,
    /// The perspective camera's eye at the end (orbited on a mesh; null for the orthographic
    /// top view).
    pub camera: Option<[f32; 3]>,
    /// Mean linear RGB of the last frame (null before any).
    pub mean_rgb: Option<[f32; 3]>,
}

/// `ptm swatch`: the mesh generated and written.
#[derive(Serialize, Debug, Default)]
pub struct Swatch {
    /// The generator's canonical name.
    pub swatch: String,
    /// The full spec, `NAME?k=v&…`.
    pub spec: String,
    /// The OBJ written.
    pub output: String,
    /// Triangles.
    pub triangles: usize,
    /// Vertices.
    pub vertices: usize,
    /// Yarns swept.
    pub yarns: usize,
    /// Tile W, H.
    pub tile: [f32; 2],
    /// The mesh's bounding box.
    pub bounds: Bounds,
    /// Signed volume enclosed per tile.
    pub volume_per_tile: f64,
    /// Smallest gap between two yarns (null when no two yarns are near).
    pub min_yarn_gap: Option<f64>,
    /// The whole run.
    pub seconds: f64,
}

/// A mesh's bounding box.
#[derive(Serialize, Debug, Default)]
pub struct Bounds {
    /// Lowest x, y, z.
    pub min: [f32; 3],
    /// Highest x, y, z.
    pub max: [f32; 3],
}

/// `ptm report`: the files written.
#[derive(Serialize, Debug, Default)]
pub struct Report {
    /// `report.md`.
    pub report: String,
    /// The plot of error against time.
    pub plot: String,
    /// The contact sheet of the builtin swatches.
    pub contact_sheet: String,
    /// One CSV per table.
    pub csv: Vec<String>,
    /// The whole run.
    pub seconds: f64,
    /// Per swatch studied, its most accurate setting.
    pub swatches: Vec<ReportSwatch>,
}

/// One swatch of `ptm report`.
#[derive(Serialize, Debug, Default)]
pub struct ReportSwatch {
    /// The builtin swatch.
    pub swatch: String,
    /// Settings measured.
    pub settings: usize,
    /// RMS error of K of the most accurate setting.
    pub best_rms: f64,
    /// The most accurate setting, in words.
    pub best: String,
}

/// `ptm merge`: the file assembled from a farm bake's parts.
#[derive(Serialize, Debug, Default)]
pub struct Merge {
    /// The merged stack or PTM.
    pub output: String,
    /// The `.lp` written beside it (null for a device output).
    pub lights_file: Option<String>,
    /// `stack` or `ptm`.
    pub kind: String,
    /// The part files read.
    pub parts: Vec<String>,
    /// The companion maps merged beside the output (absent where no maps parts were given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub maps: Option<String>,
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Lights.
    pub lights: usize,
    /// Bytes of the parts.
    pub bytes_in: u64,
    /// Bytes of the output.
    pub bytes_out: usize,
    /// Megabytes of parts read per second of the whole run.
    pub mb_per_s: f64,
    /// The whole run.
    pub seconds: f64,
    /// Reading and merging.
    pub seconds_merge: f64,
    /// Writing.
    pub seconds_write: f64,
}

/// `ptm batch`: the manifest run here, or written as a Slurm job.
#[derive(Serialize, Debug)]
#[serde(untagged)]
pub enum Batch {
    /// Every bake of the manifest was run and merged here.
    Here(BatchHere),
    /// `--slurm DIR`: the job files were written.
    Slurm(BatchSlurm),
}

/// `ptm batch manifest.toml`.
#[derive(Serialize, Debug, Default)]
pub struct BatchHere {
    /// The merged outputs, one per bake.
    pub outputs: Vec<String>,
    /// The whole run.
    pub seconds: f64,
}

/// `ptm batch --slurm DIR manifest.toml`.
#[derive(Serialize, Debug, Default)]
pub struct BatchSlurm {
    /// Bakes in the manifest.
    pub bakes: usize,
    /// Array tasks (shards of every bake).
    pub tasks: usize,
    /// The folder of the job files.
    pub dir: String,
    /// The command that submits the job.
    pub submit: String,
}

/// `ptm convert`: the PTM rewritten in the other layout.
#[derive(Serialize, Debug, Default)]
pub struct Convert {
    /// The PTM read.
    pub input: String,
    /// Its layout, `channels` or `rgba`.
    pub from: &'static str,
    /// The layout written.
    pub to: &'static str,
    /// The files written.
    pub files: Vec<String>,
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The maps carried over (`ptm`, `coverage`, `err`, …).
    pub maps: Vec<String>,
}

/// `ptm eval`: the stack of K a PTM gives under a light set.
#[derive(Serialize, Debug, Default)]
pub struct Eval {
    /// The PTM read.
    pub input: String,
    /// The sample stack written.
    pub output: String,
    /// Its basis (`ptm6`, `ptm11`, `learnedN`).
    pub basis: &'static str,
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Lights evaluated (the stack's K channels).
    pub lights: usize,
}

#[cfg(test)]
mod tests;
