//! Choosing the model by held-out error (`ptm fit --basis auto`, `ptm bake --fit auto`): the
//! candidates, the margin, the default hold-out, and the choice itself over any way of fitting
//! a candidate (a stored stack, or the counts a streaming bake kept).
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_fit::{FitOptions, FitReport};
use ptm_format::{Basis, Ptm};

use crate::json;

/// A basis, or `auto`: the value of `ptm fit --basis` and `ptm bake --fit`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BasisChoice {
    /// This basis.
    Fixed(Basis),
    /// The cheapest of [`AUTO_CANDIDATES`] within the margin of the best on held-out lights.
    Auto,
}

/// The candidates of `auto`, cheapest first: fewer coefficients per texel first, and at
/// equal count the polynomial (no table to read) before the learned basis.
pub const AUTO_CANDIDATES: [Basis; 4] = [
    Basis::Ptm6,
    Basis::Learned(6),
    Basis::Ptm11,
    Basis::Learned(11),
];

/// Default `--auto-margin`: 2 % of the best held-out error.
pub const AUTO_MARGIN: f64 = 0.02;

/// Parses a basis name or `auto` for clap.
pub fn parse_choice(s: &str) -> Result<BasisChoice, String> {
    if s == "auto" {
        return Ok(BasisChoice::Auto);
    }
    crate::args::parse_basis(s)
        .map(BasisChoice::Fixed)
        .map_err(|e| format!("{e}, or auto"))
}

impl BasisChoice {
    /// The basis whose outputs are checked before the fit: for `auto`, the candidate with the
    /// most files (the renderer layout's parts follow the coefficient count).
    pub fn for_paths(self) -> Basis {
        match self {
            BasisChoice::Fixed(b) => b,
            BasisChoice::Auto => Basis::Learned(11),
        }
    }

    /// The fixed basis, `None` for `auto`.
    pub fn fixed(self) -> Option<Basis> {
        match self {
            BasisChoice::Fixed(b) => Some(b),
            BasisChoice::Auto => None,
        }
    }
}

/// The lights held out by default: an eighth of `lights` when the rest still number at least
/// four per coefficient (the fit stays well determined), else none.
pub fn default_holdout(lights: usize, coefficients: usize) -> usize {
    let n = lights / 8;
    if lights - n >= 4 * coefficients {
        n
    } else {
        0
    }
}

/// What `auto` kept, and the table it chose from.
pub struct Chosen {
    /// The candidate kept.
    pub basis: Basis,
    /// Its options (the shared hold-out included).
    pub opts: FitOptions,
    /// Its fit.
    pub ptm: Ptm,
    /// Its report.
    pub report: FitReport,
    /// Every candidate's error and time, for `--json`.
    pub json: json::Auto,
}

/// The hold-out every candidate shares: `given`, or by default the most any candidate would
/// hold out of `lights` (so all see the same split). Refuses none held out: the choice is by
/// held-out error. `source` names the input in messages.
pub fn shared_holdout(source: &str, lights: usize, given: Option<usize>) -> anyhow::Result<usize> {
    let by_default = |n| {
        AUTO_CANDIDATES
            .iter()
            .map(|b| default_holdout(n, b.len()))
            .max()
            .unwrap_or(0)
    };
    let holdout = given.unwrap_or_else(|| by_default(lights));
    if holdout == 0 {
        let from = (1..10_000).find(|&m| by_default(m) > 0).unwrap_or(0);
        bail!(
            "{source}: auto chooses the basis by the error on held-out lights, and {} none of \
             its {lights} lights: hold some out (--holdout N, N ≥ 1; by default an eighth is \
             held out from {from} lights) or give the basis",
            if given.is_some() {
                "--holdout 0 holds out"
            } else {
                "the default holds out"
            },
        );
    }
    Ok(holdout)
}

/// Fits every candidate with `fit` (the candidate, the shared hold-out → its options, PTM and
/// report), prints their held-out errors and fit times under `tool`'s name, and keeps the
/// first within `margin` of the best. A learned candidate that the link, map or dome does not
/// allow is left out, said why; any other error ends the choice.
pub fn choose(
    tool: &str,
    source: &str,
    holdout: usize,
    margin: f64,
    mut fit: impl FnMut(Basis, usize) -> Result<(FitOptions, Ptm, FitReport), ptm_fit::Error>,
) -> anyhow::Result<Chosen> {
    if !(margin >= 0.0 && margin.is_finite()) {
        bail!("--auto-margin {margin}: give a fraction ≥ 0 of the best held-out error (default {AUTO_MARGIN})");
    }
    let mut tried: Vec<(Basis, FitOptions, Ptm, FitReport)> = Vec::new();
    let mut rows = Vec::new();
    for basis in AUTO_CANDIDATES {
        let t = Instant::now();
        match fit(basis, holdout) {
            Ok((opts, ptm, report)) => {
                rows.push(json::AutoCandidate {
                    basis: basis.name().to_string(),
                    holdout_rms_error: report.holdout.as_ref().map(|h| h.mean),
                    seconds: t.elapsed().as_secs_f64(),
                    skipped: None,
                });
                tried.push((basis, opts, ptm, report));
            }
            // A learned candidate the link, map or dome does not allow is left out, said why.
            Err(ptm_fit::Error::Invalid(why)) if basis.is_learned() => {
                rows.push(json::AutoCandidate {
                    basis: basis.name().to_string(),
                    holdout_rms_error: None,
                    seconds: t.elapsed().as_secs_f64(),
                    skipped: Some(why),
                });
            }
            Err(e) => return Err(e).with_context(|| format!("{source}: auto, {}", basis.name())),
        }
    }
    let errs: Vec<f64> = tried
        .iter()
        .map(|(_, _, _, r)| r.holdout.as_ref().map_or(f64::INFINITY, |h| h.mean))
        .collect();
    let best = errs.iter().copied().fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        bail!("{source}: auto: no candidate measured a finite held-out error");
    }
    let pick = errs
        .iter()
        .position(|&e| e <= best * (1.0 + margin))
        .expect("the best is within any margin ≥ 0");
    eprintln!("{tool}: auto: mean RMS error of K on {holdout} held-out lights, fit time:");
    for r in &rows {
        match (&r.skipped, r.holdout_rms_error) {
            (Some(why), _) => eprintln!("  {:<10} skipped: {why}", r.basis),
            (None, e) => eprintln!(
                "  {:<10} {:.4}  {:>7.2} s{}",
                r.basis,
                e.unwrap_or(f64::NAN),
                r.seconds,
                if r.basis == tried[pick].0.name() {
                    format!(
                        "  <- kept: the first within {:.1} % of the best ({best:.4})",
                        100.0 * margin
                    )
                } else {
                    String::new()
                }
            ),
        }
    }
    let (basis, opts, ptm, report) = tried.swap_remove(pick);
    Ok(Chosen {
        basis,
        opts,
        ptm,
        report,
        json: json::Auto {
            margin,
            chosen: basis.name().to_string(),
            candidates: rows,
        },
    })
}
