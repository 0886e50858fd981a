//! What a fit is asked for ([`FitOptions`], [`Weight`]) and what it reports beside the PTM
//! ([`FitReport`], [`ErrorStats`], [`LogisticStats`]).
use crate::logistic;
use crate::simd::Isa;
use crate::{Diagnostic, Error, Result};
use ptm_format::{Basis, LearnedTable, Link, UvMap};

/// How each light's squared error counts in the fit. Under either, lights at or below the
/// horizon get weight 0 (left out: K = 1 there by definition).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weight {
    /// Every light above the horizon counts the same.
    Uniform,
    /// Weight = l_z = sin(elevation): grazing lights carry less light, so their errors matter
    /// less for shading.
    Cosine,
}

impl Weight {
    /// The weighting in words (`uniform`, `cosine`), as the CLI and file headers spell it.
    pub fn name(self) -> &'static str {
        match self {
            Weight::Uniform => "uniform",
            Weight::Cosine => "cosine",
        }
    }
}

/// Options of a fit. Defaults live in the CLI; [`FitOptions::new`] gives the documented ones.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// The polynomial basis to fit.
    pub basis: Basis,
    /// K = p (least squares) or K = σ(p) (maximum likelihood, [`crate::logistic`]).
    pub link: Link,
    /// How light directions map to (u, v).
    pub uv: UvMap,
    /// How much each light's residual counts.
    pub weight: Weight,
    /// Ridge λ, relative to the mean eigenvalue trace(AᵀWA)/terms: minimises
    /// |W½(Ac − k)|² + λ·trace(AᵀWA)/terms·|c|². `None`: truncated SVD (minimum norm) for the
    /// identity link, [`logistic::DEFAULT_RIDGE`] for the logistic link.
    pub regularize: Option<f64>,
    /// Logistic link: Newton stops when the decrement per unit light weight is below this.
    pub tolerance: f64,
    /// Logistic link: at most this many Newton iterations per texel.
    pub max_iterations: u32,
    /// Also fit MIP levels (each to the box-filtered K of its footprint) for the file.
    pub mips: bool,
    /// Logistic link: force the kernel's instruction set (tests and benchmarks); `None` = the
    /// widest this CPU runs ([`Isa::detect`]).
    pub isa: Option<Isa>,
    /// Singular values below `rcond · σ_max` are treated as zero (their directions undetermined).
    pub rcond: f64,
    /// Any warning about the light set becomes an error.
    pub strict: bool,
    /// Drop non-finite samples (counted) instead of failing.
    pub skip_bad: bool,
    /// Number of lights kept out of the fit to measure the error honestly (0 = none).
    pub holdout: usize,
    /// A learned basis: fit every texel against these tables, and report these statistics of
    /// their learning, instead of learning them from this fit's samples. A farm shard's fit,
    /// whose basis was learned from the whole bake's subsample ([`crate::Accumulator::learn_basis`]),
    /// and the merge's deeper MIP levels. `None`: learn them (a whole fit).
    pub given_basis: Option<Box<(LearnedTable, LearnedStats)>>,
}

/// Default relative singular-value cutoff. Well-spread domes have condition numbers of 6 (ptm6)
/// to 25 (ptm11), domes above 60° about 400 (ptm11): all kept. A dome 1e-3 off a single ring has
/// about 2400; fitting that direction amplified bake noise into a held-out RMS error of K of 0.50
/// on the plain weave, against 0.32 with it dropped (`ptm report`, stability tables).
pub const DEFAULT_RCOND: f64 = 1e-3;

/// Condition number above which the fit is reported as ill-conditioned.
pub const COND_WARN: f64 = 100.0;

impl FitOptions {
    /// The documented defaults for `basis`: identity link, projected (u, v), uniform weights, truncated SVD at [`DEFAULT_RCOND`], the
    /// logistic defaults, no MIP levels, no hold-out.
    pub fn new(basis: Basis) -> Self {
        FitOptions {
            basis,
            link: Link::Identity,
            uv: UvMap::Projected,
            weight: Weight::Uniform,
            regularize: None,
            tolerance: logistic::DEFAULT_TOLERANCE,
            max_iterations: logistic::DEFAULT_MAX_ITERATIONS,
            mips: false,
            isa: None,
            rcond: DEFAULT_RCOND,
            strict: false,
            skip_bad: false,
            holdout: 0,
            given_basis: None,
        }
    }
}

/// Mean, 99th percentile and maximum of a per-texel error over the unmasked texels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    /// Mean over the texels.
    pub mean: f64,
    /// 99th percentile over the texels.
    pub p99: f64,
    /// Largest over the texels.
    pub max: f64,
}

impl ErrorStats {
    /// Over the texels whose `mask` is false; p99 by selection (O(texels)).
    pub(crate) fn of(values: &[f32], mask: &[bool]) -> Self {
        let mut v: Vec<f32> = values
            .iter()
            .zip(mask)
            .filter(|(_, &m)| !m)
            .map(|(&x, _)| x)
            .collect();
        if v.is_empty() {
            return ErrorStats::default();
        }
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        let max = v.iter().copied().fold(f32::MIN, f32::max);
        // Selection, not a sort: O(texels).
        let i99 = ((v.len() as f64 * 0.99).ceil() as usize).clamp(1, v.len()) - 1;
        let (_, p99, _) = v.select_nth_unstable_by(i99, f32::total_cmp);
        ErrorStats {
            mean,
            p99: *p99 as f64,
            max: max as f64,
        }
    }
}

/// Diagnostics of a fit, returned beside the PTM.
#[derive(Clone, Debug, Default)]
pub struct FitReport {
    /// Where the samples came from when not from a ptm bake (an RTI image stack and its
    /// decoding), recorded as `ptm:samples`; set by the caller that read them.
    pub samples: Option<String>,
    /// The basis fitted.
    pub basis: Option<Basis>,
    /// The link fitted.
    pub link: Option<Link>,
    /// The (u, v) map fitted.
    pub uv: Option<UvMap>,
    /// Logistic link: Newton iterations per fitted texel (mean, max), texels stopped by the
    /// iteration cap, texels whose samples a polynomial separates exactly (optimum at infinity
    /// without the ridge) and texels whose samples are all 0 or all 1 (a special separable case).
    pub logistic: Option<LogisticStats>,
    /// Learned basis: what the learning stage did (subsample, alternations, deviance).
    pub learned: Option<LearnedStats>,
    /// MIP levels fitted beside level 0 (0 = none).
    pub mip_levels: usize,
    /// Lights in the set, lights that entered the fit (weight > 0, not held out).
    pub lights: usize,
    /// Lights that entered the fit.
    pub lights_fit: usize,
    /// Indices of held-out lights.
    pub holdout_lights: Vec<usize>,
    /// Texels of level 0.
    pub texels: usize,
    /// Texels with coverage 0: coefficients 0, left out of the statistics.
    pub masked: usize,
    /// Coefficients per texel (the basis's length).
    pub coefficients: usize,
    /// Numerical rank of W½A (for per-texel directions: the lowest over texels).
    pub rank: usize,
    /// σ_max / σ_min of W½A (for per-texel directions: the worst texel); `inf` when singular.
    pub cond: f64,
    /// Absolute singular-value cutoff used (rcond · σ_max), and rcond.
    pub cutoff: f64,
    /// The relative cutoff asked for.
    pub rcond: f64,
    /// Singular values of W½A, descending (distant lights).
    pub singular_values: Vec<f64>,
    /// Solver in words, e.g. `svd-pinv f64 (truncated at 1e-4·σmax), applied in f32`.
    pub solver: String,
    /// Diagnostics of the light set and the data (their words: [`Diagnostic`]'s `Display`).
    pub warnings: Vec<Diagnostic>,
    /// Per-texel weighted RMS residual over the fitting lights.
    pub rms: ErrorStats,
    /// Per-texel max |residual| over the fitting lights (None when streaming: needs the samples).
    pub max: Option<ErrorStats>,
    /// Per-texel RMS error of clamped K on the held-out lights.
    pub holdout: Option<ErrorStats>,
    /// Non-finite samples dropped (`skip_bad`).
    pub skipped_samples: usize,
    /// Texels solved individually (dropped samples) whose rank fell below `coefficients`.
    pub rank_deficient_texels: usize,
    /// Per-texel coverage (fraction of the footprint that saw the swatch) when some texel is
    /// not fully covered; empty when every texel is (nothing to record).
    pub coverage: Vec<f32>,
    /// Per-texel maps: weighted RMS and max residual (max empty when streaming).
    pub rms_map: Vec<f32>,
    /// Per-texel max residual (empty when streaming).
    pub max_map: Vec<f32>,
    /// Seconds per stage, in order.
    pub seconds: Vec<(&'static str, f64)>,
}

/// What the learning stage did (in [`FitReport::learned`]; [`crate::learned`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LearnedStats {
    /// Terms k.
    pub terms: usize,
    /// Grid side G of each table.
    pub grid: usize,
    /// Roughness λ.
    pub roughness: f64,
    /// Texels the basis was learned on (the subsample).
    pub texels: usize,
    /// Alternations run.
    pub alternations: u32,
    /// The alternation whose tables were kept: the one of the lowest held-out RMS error on the
    /// subsample when the fit holds lights out (0: the polynomial start), else the last.
    pub kept: u32,
    /// Mean deviance per fitted sample on the subsample, at the polynomial start and at the end.
    pub deviance_start: f64,
    /// Mean deviance per fitted sample at the end of the learning.
    pub deviance: f64,
    /// RMS of σ − K on the subsample's fitting samples, at the start and at the end.
    pub rms_start: f64,
    /// RMS of σ − K at the end of the learning.
    pub rms: f64,
    /// Seconds of the learning stage (subsample, alternations, gauge).
    pub seconds: f64,
}

/// What the logistic fit did, over the fitted texels of level 0.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LogisticStats {
    /// Mean Newton iterations per fitted texel.
    pub iterations_mean: f64,
    /// Iterations summed over the fitted texels (the mean's numerator: a farm merge adds
    /// the parts').
    pub iterations_total: u64,
    /// Most Newton iterations any texel took.
    pub iterations_max: u32,
    /// Texels stopped by the iteration cap.
    pub not_converged: usize,
    /// Texels whose samples a polynomial separates exactly.
    pub separable: usize,
    /// Texels whose samples are all 0 or all 1.
    pub constant: usize,
    /// Ridge λ (relative) and ρ (absolute, λ·mean eigenvalue of AᵀΩA).
    pub lambda: f64,
    /// Ridge ρ, absolute (λ times the mean eigenvalue of AᵀΩA).
    pub ridge: f64,
    /// The Newton stopping tolerance used.
    pub tolerance: f64,
    /// The iteration cap used.
    pub max_iterations: u32,
    /// The kernel build that ran (`avx512f`, `avx2+fma`, `portable`: [`Isa::name`]).
    pub kernel: &'static str,
}

/// `coverage` when some texel is not fully covered, else nothing (a file needs no channel of 1s).
pub(super) fn partial_coverage(coverage: &[f32]) -> Vec<f32> {
    if coverage.iter().any(|&c| c < 1.0) {
        coverage.to_vec()
    } else {
        Vec::new()
    }
}

/// The coverage a fitted [`Ptm`](ptm_format::Ptm) carries: the map when some texel is not fully
/// covered.
pub(crate) fn ptm_coverage(coverage: &[f32]) -> Option<Vec<f32>> {
    coverage.iter().any(|&c| c < 1.0).then(|| coverage.to_vec())
}

/// Evenly spread hold-out lights: index ⌊(j + ½)·n / h⌋ for j < h.
pub fn holdout_indices(n: usize, h: usize) -> Vec<usize> {
    (0..h.min(n))
        .map(|j| ((j as f64 + 0.5) * n as f64 / h as f64) as usize)
        .collect()
}

pub(crate) fn check_strict(opts: &FitOptions, warnings: &[Diagnostic]) -> Result<()> {
    if opts.strict && !warnings.is_empty() {
        return Err(Error::Strict(warnings.to_vec()));
    }
    Ok(())
}
