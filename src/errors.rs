//! The one place the command turns the libraries' typed errors and diagnostics into words
//! that name its flags. The libraries state facts ("non-finite sample NaN at texel …"); here a
//! variant the command knows gets the flag and the fix ("… or pass --skip-bad …"). Anything
//! else is printed as the library says it.
use std::error::Error as StdError;

use ptm_fit::Diagnostic;

/// The whole chain of `e`, as `{:#}` prints it (causes joined by ": "), with each library error
/// the command knows worded for the command line.
pub fn explain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let s = hinted(cause).unwrap_or_else(|| cause.to_string());
        // A cause its parent already ends with (an OS error a library message quotes) is said
        // once.
        if s.is_empty() || out.ends_with(&s) {
            continue;
        }
        // A library error names its file first ("w.exr: not a readable …"); a context that
        // already ends with that name ("reading w.exr") names it once.
        let s = without_named_file(&out, &s).to_string();
        if !out.is_empty() {
            out += ": ";
        }
        out += &s;
    }
    out
}

/// `cause` without its leading `NAME: ` when the message so far ends with ` NAME` (or is
/// `NAME`): the file a context names and its cause names again.
fn without_named_file<'a>(out: &str, cause: &'a str) -> &'a str {
    for (i, _) in cause.match_indices(": ") {
        let name = &cause[..i];
        let named = out == name
            || out
                .strip_suffix(name)
                .is_some_and(|head| head.ends_with(' '));
        if named {
            return &cause[i + 2..];
        }
    }
    cause
}

/// A fit diagnostic as the command prints it: the library's words, then the flag that changes
/// it where there is one.
pub fn fit_warning(d: &Diagnostic) -> String {
    match d {
        Diagnostic::SkippedSamples { .. } => format!("{d} (--skip-bad)"),
        Diagnostic::NotConverged { .. } => {
            format!("{d}: raise --max-iterations, or the ridge (--regularize)")
        }
        Diagnostic::Separable { .. } => format!("{d}; give --regularize > 0"),
        _ => d.to_string(),
    }
}

/// [`fit_warning`] of each, for `--json`.
pub fn fit_warnings(ds: &[Diagnostic]) -> Vec<String> {
    ds.iter().map(fit_warning).collect()
}

/// A swatch diagnostic of the bake in words, with the flag that replaces a bounding-box tile.
pub fn swatch_warning(w: &ptm_bake::Diagnostic) -> String {
    match w {
        ptm_bake::Diagnostic::NotPeriodic {
            tile_from_bounds: true,
            ..
        } => format!("{w} (--tile W,H)"),
        _ => w.to_string(),
    }
}

/// The command's wording of one cause, when it is a library error that needs one.
fn hinted(e: &(dyn StdError + 'static)) -> Option<String> {
    if let Some(e) = e.downcast_ref::<ptm_format::Error>() {
        return format_error(e);
    }
    if let Some(e) = e.downcast_ref::<ptm_fit::Error>() {
        return fit_error(e);
    }
    if let Some(e) = e.downcast_ref::<ptm_bake::Error>() {
        return bake_error(e);
    }
    if let Some(e) = e.downcast_ref::<ptm_runtime::Error>() {
        return runtime_error(e);
    }
    if let Some(e) = e.downcast_ref::<ptm_gpubake::Error>() {
        return gpubake_error(e);
    }
    if let Some(e) = e.downcast_ref::<ptm_report::Error>() {
        return match e {
            ptm_report::Error::Bake(e) => bake_error(e),
            ptm_report::Error::Fit(e) => fit_error(e),
            ptm_report::Error::Format(e) => format_error(e),
            ptm_report::Error::Runtime(e) => runtime_error(e),
            _ => None,
        };
    }
    None
}

fn format_error(e: &ptm_format::Error) -> Option<String> {
    use ptm_format::Error as E;
    Some(match e {
        E::HpNeedsPtm6 { .. } => format!("{e}: fit with --basis ptm6 to export it"),
        E::HalfOverflow { .. } => format!("{e} (drop --half)"),
        E::Io { .. } | E::Format { .. } | E::LightFile { .. } | E::Invalid(_) => return None,
    })
}

fn fit_error(e: &ptm_fit::Error) -> Option<String> {
    use ptm_fit::Error as E;
    Some(match e {
        E::BadSample { .. } => {
            format!("{e}: fix the input, or pass --skip-bad to drop such samples")
        }
        E::Strict(ds) => format!(
            "--strict: {}",
            ds.iter().map(fit_warning).collect::<Vec<_>>().join("; ")
        ),
        E::HoldoutTooLarge { holdout, .. } => format!("--holdout {holdout}: {e}"),
        E::LogisticNeedsDistantLights => {
            format!("{e}, as a bake with --light-distance makes: fit it with --link identity")
        }
        E::TooManyShards { shard, .. } => format!("--shard {shard}: {e}"),
        E::Images { pattern, reason } => format!("--images {pattern:?}: {reason}"),
        E::NotAPart { .. } => format!("{e}; parts are written by `ptm bake --shard I/N`"),
        E::File(e) => return format_error(e),
        E::Io { .. }
        | E::LightFile { .. }
        | E::Format { .. }
        | E::Invalid(_)
        | E::LightsBelowHorizon { .. } => return None,
    })
}

fn bake_error(e: &ptm_bake::Error) -> Option<String> {
    use ptm_bake::Error as E;
    Some(match e {
        E::Format(e) => return format_error(e),
        E::Sink(e) => return e.downcast_ref::<ptm_fit::Error>().and_then(fit_error),
        E::Tracer(e) => {
            return e
                .downcast_ref::<ptm_gpubake::Error>()
                .and_then(gpubake_error)
        }
        E::Tile {
            path,
            reason,
            stray,
        } => format!(
            "{path}: {reason}: give the tile (--tile W,H or the `# tile` header) in the mesh's \
             units{}",
            if *stray {
                ", or remove stray vertices"
            } else {
                ""
            }
        ),
        E::NoLights => "--dirs must be at least 1".into(),
        E::MinElevation { deg } => format!("--min-elevation {deg}: {e}"),
        E::BadDome { spec, reason } => format!("--dome {spec}: {reason}"),
        E::LightsInside { distance, .. } => format!("--light-distance {distance:e}: {e}"),
        E::LightsTooFar { distance, .. } => {
            format!("--light-distance {distance:e}: {e} (leave --light-distance out)")
        }
        E::TooManyThreads { threads, max } => format!(
            "--threads {threads}: at most {max} (0 uses one per core; the output is the same for \
             any count)"
        ),
        E::Io { .. } | E::InvalidMesh { .. } | E::Dome(_) | E::Config(_) | E::Embree(_) => {
            return None
        }
    })
}

/// The GPU bake's errors with the flags that avoid them (`--device cpu` always does).
fn gpubake_error(e: &ptm_gpubake::Error) -> Option<String> {
    use ptm_gpubake::Error as E;
    Some(match e {
        E::NoRayQueries { .. } => format!(
            "{e}: bake with --device cpu (or auto), or install a driver with ray queries (a \
             GPU's, or Mesa >= 25 for lavapipe)"
        ),
        E::Device { .. } => format!("{e}: bake with --device cpu (or auto)"),
        E::TooBig { .. } => format!("{e}: bake it with --device cpu"),
        E::BandTooBig { .. } => {
            format!("{e}: lower --res or --spp, or bake with --device cpu")
        }
        E::Lost { .. } => format!(
            "{e}; nothing was written: bake again (a farm shard redoes only its own rows), or \
             with --device cpu"
        ),
        E::Bake(e) => return bake_error(e),
    })
}

fn runtime_error(e: &ptm_runtime::Error) -> Option<String> {
    use ptm_runtime::Error as E;
    match e {
        E::SeparableNeedsParallelCaster { tilt_deg } => Some(format!(
            "invalid scene: --blur separable needs a caster parallel to the cloth (its per-light \
             box passes assume one blur radius per light), but the caster is tilted {tilt_deg}°: \
             use --blur sat, mip or explicit"
        )),
        E::Format(e) => format_error(e),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_variants_name_their_flag_and_keep_the_chain() {
        let e = anyhow::Error::from(ptm_fit::Error::BadSample {
            col: 5,
            row: 3,
            light: 12,
            value: f32::NAN,
        })
        .context("fitting samples.exr");
        let s = explain(&e);
        assert_eq!(
            s,
            "fitting samples.exr: non-finite sample NaN at texel (column 5, row 3) for light 12: \
             fix the input, or pass --skip-bad to drop such samples"
        );
        // Through the bake's and the report's wrappers, and the file layer's variant inside fit's.
        let hp = ptm_format::Error::HpNeedsPtm6 {
            path: "w.ptm".into(),
            basis: ptm_format::Basis::Ptm11,
        };
        let e = anyhow::Error::from(ptm_bake::Error::Format(hp));
        assert!(
            explain(&e).ends_with("fit with --basis ptm6 to export it"),
            "{e:#}"
        );
        let e = anyhow::Error::from(ptm_report::Error::Fit(ptm_fit::Error::HoldoutTooLarge {
            holdout: 30,
            lights: 24,
        }));
        assert!(explain(&e).starts_with("--holdout 30: "), "{}", explain(&e));
        // Others print as the library says.
        let e = anyhow::Error::from(ptm_fit::Error::Invalid("no lights to fit".into()));
        assert_eq!(explain(&e), format!("{e:#}"));
    }

    #[test]
    fn bake_errors_name_their_flags() {
        let e = anyhow::Error::from(ptm_bake::Error::TooManyThreads {
            threads: 100_000,
            max: 1024,
        });
        assert!(explain(&e).starts_with("--threads 100000: at most 1024"));
        let e = anyhow::Error::from(ptm_bake::Error::BadDome {
            spec: "rings:10x".into(),
            reason: "count \"\" must be a positive integer".into(),
        });
        assert_eq!(
            explain(&e),
            "--dome rings:10x: count \"\" must be a positive integer"
        );
        let e = anyhow::Error::from(ptm_bake::Error::Tile {
            path: "flat.obj".into(),
            reason: "tile size 0×1 must be positive and finite".into(),
            stray: false,
        });
        assert!(explain(&e).contains("--tile W,H"), "{}", explain(&e));
        let e = anyhow::Error::from(ptm_runtime::Error::SeparableNeedsParallelCaster {
            tilt_deg: 20.0,
        });
        assert!(explain(&e).contains("--blur separable"), "{}", explain(&e));
        assert!(!e.to_string().contains("--"), "{e}");
        let e = anyhow::Error::from(ptm_fit::Error::Images {
            pattern: "x/*.png".into(),
            reason: "matches no file".into(),
        });
        assert_eq!(explain(&e), "--images \"x/*.png\": matches no file");
    }

    #[test]
    fn diagnostics_get_flag_hints_only_where_a_flag_helps() {
        let d = Diagnostic::NotConverged {
            texels: 3,
            max_iterations: 50,
            tolerance: 1e-6,
        };
        assert!(fit_warning(&d).contains("--max-iterations"));
        let d = Diagnostic::NoLightBelow { deg: 60.0 };
        assert_eq!(fit_warning(&d), d.to_string());
    }
}
