//! What a fit reports beside its result: numeric trouble that is a property of the data (a light
//! set that cannot determine some basis directions, texels that lost samples, texels the
//! logistic Newton solve could not finish), typed. [`Diagnostic`]'s `Display` is the one place
//! their words live; it is what `FitReport` shows and what a PTM file's `ptm:warnings` records.
//! It names no command-line flag: the `ptm` binary adds those.
use std::fmt;

use ptm_format::lights::{horizon_words, HorizonLight};
use ptm_format::Basis;

/// One diagnostic of a fit (`FitReport::warnings`). Each variant's doc names its fields and
/// their units, so the fields carry none of their own.
#[allow(missing_docs)]
#[derive(Clone, Debug, PartialEq)]
pub enum Diagnostic {
    /// Lights at or below the horizon (z ≤ 0): left out of the fit (weight 0), since K = 1
    /// there by definition and, in the projected (u, v), such a light lands on the same (u, v)
    /// as its mirror image above the horizon.
    BelowHorizon { lights: Vec<HorizonLight> },
    /// Fewer lights enter the fit than the basis has coefficients.
    TooFewLights {
        lights: usize,
        coefficients: usize,
        basis: Basis,
    },
    /// Every fitting light has the same elevation (`r2` = u² + v² of all of them).
    Ring { elevation_deg: f64, r2: f64 },
    /// The fitting lights' elevations span less than 0.02 in u² + v².
    NearRing { highest_deg: f64, lowest_deg: f64 },
    /// The lowest fitting light is at `deg` ≥ 45° elevation.
    NoLightBelow { deg: f64 },
    /// The shared design has rank `rank` < `coefficients`; `directions` are the undetermined
    /// basis directions in words, `solution` what the fit returns for them.
    RankDeficient {
        rank: usize,
        coefficients: usize,
        directions: Vec<String>,
        solution: Solution,
    },
    /// The shared design's condition number `cond` exceeds `limit`.
    IllConditioned {
        cond: f64,
        limit: f64,
        directions: Vec<String>,
    },
    /// Per-texel light directions: `texels` texels have rank below `coefficients` (lowest
    /// `lowest_rank`, at texel (`col`, `row`), undetermined there: `directions`).
    TexelsRankDeficient {
        texels: usize,
        coefficients: usize,
        lowest_rank: usize,
        col: usize,
        row: usize,
        directions: Vec<String>,
    },
    /// Per-texel light directions: the worst texel's condition number `cond` exceeds `limit`.
    TexelsIllConditioned {
        cond: f64,
        limit: f64,
        col: usize,
        row: usize,
        directions: Vec<String>,
    },
    /// Non-finite samples dropped (the fit was asked to skip them): `samples` samples in
    /// `texels` texels, of which `lost_rank` fell below full rank (`None`: not counted, as for
    /// the logistic link, which has no per-texel rank).
    SkippedSamples {
        samples: usize,
        texels: usize,
        lost_rank: Option<usize>,
    },
    /// Logistic link: `texels` texels stopped at the iteration cap before the tolerance.
    NotConverged {
        texels: usize,
        max_iterations: u32,
        tolerance: f64,
    },
    /// Logistic link with ridge 0: `texels` texels are separable, so their maximum-likelihood
    /// coefficients are infinite.
    Separable { texels: usize },
    /// RTI images that the pattern matched but the `.lp` file `lp` does not list (file names),
    /// left out of the stack.
    UnusedImages { lp: String, images: Vec<String> },
    /// A diagnostic read back from a file, which records words only (a farm part's
    /// `part:warnings`).
    Recorded(String),
}

/// What a rank-deficient fit returns for the directions its lights cannot determine (each
/// variant's doc names its fields).
#[allow(missing_docs)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solution {
    /// Logistic link: its ridge (λ relative to the mean eigenvalue) holds them near 0.
    LogisticRidge { lambda: f64 },
    /// Identity link with a ridge (λ relative to the mean eigenvalue).
    Ridge { lambda: f64 },
    /// Identity link, truncated SVD: singular values ≤ `cutoff` = `rcond` × σ_max dropped.
    MinimumNorm { cutoff: f64, rcond: f64 },
}

impl fmt::Display for Solution {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match *self {
            Solution::LogisticRidge { lambda } => write!(
                f,
                "logistic fit whose ridge (lambda = {lambda:e} x mean eigenvalue) holds them near 0"
            ),
            Solution::Ridge { lambda } => {
                write!(f, "ridge solution (lambda = {lambda:e} x mean eigenvalue)")
            }
            Solution::MinimumNorm { cutoff, rcond } => write!(
                f,
                "minimum-norm solution (truncated SVD: singular values <= {cutoff:.3e} = {rcond:e} x sigma_max dropped)"
            ),
        }
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match self {
            Diagnostic::BelowHorizon { lights } => write!(
                f,
                "{} {} at or below the horizon left out of the fit (K = 1 there by definition): {}",
                lights.len(),
                if lights.len() == 1 { "light" } else { "lights" },
                horizon_words(lights, HORIZON_SHOWN)
            ),
            Diagnostic::TooFewLights {
                lights,
                coefficients,
                basis,
            } => write!(
                f,
                "only {lights} lights enter the fit for {coefficients} coefficients of {}: at least {} directions of the basis are undetermined",
                basis.name(),
                coefficients - lights
            ),
            Diagnostic::Ring { elevation_deg, r2 } => write!(
                f,
                "all lights lie on one elevation ring ({elevation_deg:.2}°, u²+v² = {r2:.4}): u2+v2 cannot be told from the constant, and K inside the ring is not determined by the data"
            ),
            Diagnostic::NearRing {
                highest_deg,
                lowest_deg,
            } => write!(
                f,
                "lights lie near one elevation ring (elevations {highest_deg:.2}°–{lowest_deg:.2}°): terms that differ only by u²+v² are nearly indistinguishable"
            ),
            Diagnostic::NoLightBelow { deg } => write!(
                f,
                "no light below {deg:.1}° elevation: K at grazing lights, where most occlusion lives, is extrapolated"
            ),
            Diagnostic::RankDeficient {
                rank,
                coefficients,
                directions,
                solution,
            } => write!(
                f,
                "rank {rank} of {coefficients}: the light set cannot determine these basis directions: {}; returning the {solution}",
                directions.join("; ")
            ),
            Diagnostic::IllConditioned {
                cond,
                limit,
                directions,
            } => write!(
                f,
                "ill-conditioned (condition number {cond:.1} > {limit}): poorly determined directions: {}",
                directions.join("; ")
            ),
            Diagnostic::TexelsRankDeficient {
                texels,
                coefficients,
                lowest_rank,
                col,
                row,
                directions,
            } => write!(
                f,
                "{texels} texels have rank below {coefficients} with their per-texel light directions (lowest rank {lowest_rank}); they get the minimum-norm solution; undetermined at texel (column {col}, row {row}): {}",
                directions.join("; ")
            ),
            Diagnostic::TexelsIllConditioned {
                cond,
                limit,
                col,
                row,
                directions,
            } => write!(
                f,
                "ill-conditioned texels: worst condition number {cond:.1} > {limit} at texel (column {col}, row {row}); poorly determined: {}",
                directions.join("; ")
            ),
            Diagnostic::SkippedSamples {
                samples,
                texels,
                lost_rank,
            } => {
                write!(
                    f,
                    "{samples} non-finite samples in {texels} texels were dropped"
                )?;
                match lost_rank {
                    Some(n) => write!(f, "; {n} of those texels lost rank"),
                    None => Ok(()),
                }
            }
            Diagnostic::NotConverged {
                texels,
                max_iterations,
                tolerance,
            } => write!(
                f,
                "{texels} texels stopped at the logistic iteration cap ({max_iterations}) before the tolerance {tolerance:e}"
            ),
            Diagnostic::Separable { texels } => write!(
                f,
                "{texels} texels are separable (K is 0 or 1 and a polynomial boundary splits them exactly) and the ridge is 0: their maximum-likelihood coefficients are infinite, so they stopped where the iteration cap left them"
            ),
            Diagnostic::UnusedImages { lp, images } => {
                let (n, shown) = (images.len(), images.len().min(UNUSED_SHOWN));
                let (is, was) = if n == 1 { ("image is", "was") } else { ("images are", "were") };
                write!(f, "{n} {is} not listed in {lp} and {was} ignored: ")?;
                write!(f, "{}", images[..shown].join(", "))?;
                if n > shown {
                    write!(f, " and {} more", n - shown)?;
                }
                Ok(())
            }
            Diagnostic::Recorded(words) => f.write_str(words),
        }
    }
}

/// How many lights a [`Diagnostic::BelowHorizon`] names before "and N more".
const HORIZON_SHOWN: usize = 8;

/// How many of the images an [`Diagnostic::UnusedImages`] names before "and N more".
const UNUSED_SHOWN: usize = 8;

/// The words of each diagnostic, as a PTM file's `ptm:warnings` records them.
pub fn words(diagnostics: &[Diagnostic]) -> Vec<String> {
    diagnostics.iter().map(ToString::to_string).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The words are today's (files keep their `ptm:warnings`), less any command-line flag.
    #[test]
    fn words_name_no_flag() {
        let all = [
            Diagnostic::TooFewLights {
                lights: 4,
                coefficients: 6,
                basis: Basis::Ptm6,
            },
            Diagnostic::Ring {
                elevation_deg: 30.0,
                r2: 0.75,
            },
            Diagnostic::NearRing {
                highest_deg: 31.0,
                lowest_deg: 29.0,
            },
            Diagnostic::NoLightBelow { deg: 60.0 },
            Diagnostic::RankDeficient {
                rank: 5,
                coefficients: 6,
                directions: vec!["u2 + v2 - 0.671*1".into()],
                solution: Solution::MinimumNorm {
                    cutoff: 1e-6,
                    rcond: 1e-6,
                },
            },
            Diagnostic::SkippedSamples {
                samples: 2,
                texels: 1,
                lost_rank: Some(0),
            },
            Diagnostic::NotConverged {
                texels: 3,
                max_iterations: 50,
                tolerance: 1e-6,
            },
            Diagnostic::Separable { texels: 3 },
        ];
        for d in &all {
            let s = d.to_string();
            assert!(!s.contains("--"), "{s}");
        }
        assert_eq!(
            all[1].to_string(),
            "all lights lie on one elevation ring (30.00°, u²+v² = 0.7500): u2+v2 cannot be told \
             from the constant, and K inside the ring is not determined by the data"
        );
        assert_eq!(
            all[4].to_string(),
            "rank 5 of 6: the light set cannot determine these basis directions: u2 + v2 - \
             0.671*1; returning the minimum-norm solution (truncated SVD: singular values <= \
             1.000e-6 = 1e-6 x sigma_max dropped)"
        );
        assert_eq!(
            all[5].to_string(),
            "2 non-finite samples in 1 texels were dropped; 0 of those texels lost rank"
        );
        assert_eq!(
            Diagnostic::Recorded("as read".into()).to_string(),
            "as read"
        );
        let unused = |n: usize| Diagnostic::UnusedImages {
            lp: "cap.lp".into(),
            images: (0..n).map(|i| format!("IMG_{i}.png")).collect(),
        };
        assert_eq!(
            unused(1).to_string(),
            "1 image is not listed in cap.lp and was ignored: IMG_0.png"
        );
        assert_eq!(
            unused(2).to_string(),
            "2 images are not listed in cap.lp and were ignored: IMG_0.png, IMG_1.png"
        );
        assert!(unused(10)
            .to_string()
            .ends_with("IMG_6.png, IMG_7.png and 2 more"));
    }
}
