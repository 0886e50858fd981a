//! The one place typed results become words: every table of the report as text cells, the
//! columns and cells `ptm report` writes as CSV and into `report.md`.
use ptm_fit::solve::LogisticStats;

use crate::compare::CompareRow;
use crate::runtime::{BlurRow, ExtremeRow, ProfileWidth};
use crate::stability::{Geometry, GeometryCase, LayoutRow, PrecisionRow, RidgeRow, Variant};
use crate::study::SwatchStudy;
use crate::table::{g3, Table};
use crate::Report;

/// Every table of a report, by part.
pub struct Tables {
    /// `study_<swatch>`, one per swatch.
    pub studies: Vec<Table>,
    /// The four models per swatch and basis.
    pub models: Table,
    /// The best setting per time budget.
    pub recommendations: Table,
    /// The PTMs and learned bases against the classic alternatives.
    pub alternatives: Table,
    /// Light layouts of the stability study.
    pub layouts: Table,
    /// The ridge-λ sweep.
    pub ridge: Table,
    /// The precision cases.
    pub precision: Table,
    /// The geometry cases.
    pub geometry: Table,
    /// Blur methods against Monte Carlo.
    pub blur: Table,
    /// Penumbra extremes against analytic profiles.
    pub extremes: Table,
}

impl Tables {
    /// All tables in the order `ptm report` lists their CSVs.
    pub fn all(&self) -> impl Iterator<Item = &Table> {
        self.studies.iter().chain([
            &self.models,
            &self.recommendations,
            &self.alternatives,
            &self.layouts,
            &self.ridge,
            &self.precision,
            &self.geometry,
            &self.blur,
            &self.extremes,
        ])
    }
}

impl Report {
    /// Renders every table.
    pub fn tables(&self) -> Tables {
        let s = &self.stability;
        Tables {
            studies: self.swatches.iter().map(study).collect(),
            models: models(&self.swatches),
            recommendations: recommendations(&self.swatches),
            alternatives: alternatives(&self.alternatives),
            layouts: layouts(&s.layouts),
            ridge: ridge(&s.ridge),
            precision: precision(&s.precision),
            geometry: geometry(&s.geometry),
            blur: blur(&self.runtime.blur),
            extremes: extremes(&self.runtime.extremes),
        }
    }
}

/// `a/b`, or "-" without a logistic fit: Newton's mean/max iterations and the separable and
/// constant texels.
fn newton(l: &Option<LogisticStats>) -> [String; 2] {
    match l {
        Some(l) => [
            format!("{:.1}/{}", l.iterations_mean, l.iterations_max),
            format!("{}/{}", l.separable, l.constant),
        ],
        None => ["-".into(), "-".into()],
    }
}

fn outside(fraction: f64, max: f64) -> String {
    format!("{:.1}% (max {})", 100.0 * fraction, g3(max))
}

fn study(s: &SwatchStudy) -> Table {
    let mut t = Table::new(
        format!("study_{}", s.name),
        &[
            "lights",
            "spp",
            "texels",
            "basis",
            "weight",
            "link",
            "uv",
            "bake s",
            "fit s",
            "RMS err K",
            "p99 err K",
            "max err K",
            "K outside [0,1]",
            "Newton iterations mean/max",
            "separable/constant texels",
            "Pareto",
        ],
    );
    for (i, o) in s.outcomes.iter().enumerate() {
        let x = &o.setting;
        let [iters, sep] = newton(&o.logistic);
        t.push(vec![
            x.dirs.to_string(),
            x.spp.to_string(),
            format!("{}²", x.res),
            x.basis.name().into(),
            x.weight.name().into(),
            x.link.name().into(),
            x.uv.name().into(),
            g3(o.bake_s),
            g3(o.fit_s),
            g3(o.errors.rms),
            g3(o.errors.p99),
            g3(o.errors.max),
            outside(o.errors.outside, o.errors.outside_max),
            iters,
            sep,
            if s.pareto.contains(&i) {
                "★".into()
            } else {
                String::new()
            },
        ]);
    }
    t
}

fn models(studies: &[SwatchStudy]) -> Table {
    let mut t = Table::new(
        "models",
        &[
            "swatch",
            "bake",
            "RMS identity·projected",
            "RMS identity·hemispherical",
            "RMS logistic·projected",
            "RMS logistic·hemispherical",
            "fit s identity·projected",
            "fit s identity·hemispherical",
            "fit s logistic·projected",
            "fit s logistic·hemispherical",
            "bake s",
            "logistic·hemispherical vs identity·projected",
        ],
    );
    for s in studies {
        for m in &s.models {
            let x = &m.setting;
            let mut row = vec![
                s.name.clone(),
                format!(
                    "{} lights, spp {}, {}², {}",
                    x.dirs,
                    x.spp,
                    x.res,
                    x.basis.name()
                ),
            ];
            row.extend(m.rms.iter().map(|&e| g3(e)));
            row.extend(m.fit_s.iter().map(|&e| g3(e)));
            row.push(g3(m.bake_s));
            row.push(format!("{:.0}%", 100.0 * m.default_gain()));
            t.push(row);
        }
    }
    t
}

/// One row per swatch: each model's held-out RMS error of K, then its fit seconds, the
/// training bake's seconds and the truth's own noise. The columns come from the first row
/// (every row has the same models, in the same order).
fn alternatives(rows: &[(CompareRow, f64)]) -> Table {
    let names: Vec<String> = rows.first().map_or(Vec::new(), |(r, _)| {
        r.models
            .iter()
            .map(|m| format!("{} ({})", m.name, m.numbers))
            .collect()
    });
    let mut head = vec!["swatch".to_string()];
    head.extend(names.iter().map(|n| format!("RMS {n}")));
    head.extend(names.iter().map(|n| format!("fit s {n}")));
    head.extend(["bake s".to_string(), "truth noise".to_string()]);
    let head: Vec<&str> = head.iter().map(String::as_str).collect();
    let mut t = Table::new("alternatives", &head);
    for (r, noise) in rows {
        let mut row = vec![r.swatch.clone()];
        row.extend(r.models.iter().map(|m| g3(m.rms)));
        row.extend(r.models.iter().map(|m| g3(m.fit_s)));
        row.push(g3(r.bake_s));
        row.push(g3(*noise));
        t.push(row);
    }
    t
}

fn recommendations(studies: &[SwatchStudy]) -> Table {
    let mut t = Table::new(
        "recommendations",
        &[
            "swatch",
            "time budget (s)",
            "best setting within it",
            "seconds",
            "RMS err K",
            "p99 err K",
        ],
    );
    for s in studies {
        for r in &s.recommendations {
            t.push(vec![
                s.name.clone(),
                g3(r.budget_s),
                r.best.setting.label(),
                g3(r.best.seconds()),
                g3(r.best.errors.rms),
                g3(r.best.errors.p99),
            ]);
        }
    }
    t
}

fn layouts(rows: &[LayoutRow]) -> Table {
    let mut t = Table::new(
        "stability_layouts",
        &[
            "light layout",
            "basis",
            "link, uv",
            "rank",
            "cond",
            "what ptm says",
            "max |coef|",
            "RMS err K (held out)",
            "K outside [0,1]",
            "Newton iterations mean/max",
            "separable/constant texels",
        ],
    );
    for r in rows {
        let head = [
            r.layout.to_string(),
            r.basis.name().into(),
            format!("{}, {}", r.link.name(), r.uv.name()),
        ];
        let mut row = head.to_vec();
        match &r.fit {
            Ok(f) => {
                // The iterations cell also counts the texels at the cap here.
                let [_, sep] = newton(&f.logistic);
                let iters = match &f.logistic {
                    Some(l) => format!(
                        "{:.1}/{} ({} at the cap)",
                        l.iterations_mean, l.iterations_max, l.not_converged
                    ),
                    None => "-".into(),
                };
                row.extend([
                    format!("{}/{}", f.rank, r.basis.len()),
                    g3(f.cond),
                    if f.warnings.is_empty() {
                        "ok".into()
                    } else {
                        ptm_fit::diagnostic::words(&f.warnings).join(" ")
                    },
                    g3(f.max_abs_coef),
                    g3(f.errors.rms),
                    outside(f.errors.outside, f.errors.outside_max),
                    iters,
                    sep,
                ]);
            }
            Err(err) => {
                row.extend(["-".into(), "-".into(), format!("error: {err}")]);
                row.extend(std::iter::repeat_n("-".to_string(), 5));
            }
        }
        t.push(row);
    }
    t
}

fn ridge(rows: &[RidgeRow]) -> Table {
    let mut t = Table::new(
        "stability_ridge",
        &[
            "basis",
            "link, uv",
            "λ",
            "RMS err K (held out)",
            "max |coef|",
            "Newton iterations mean/max",
            "texels at the iteration cap",
            "separable texels",
            "constant texels",
            "fit s",
        ],
    );
    for r in rows {
        let mut row = vec![
            r.basis.name().into(),
            format!("{}, {}", r.link.name(), r.uv.name()),
        ];
        match r.lambda {
            None => row.extend([
                "-".into(),
                g3(r.rms),
                g3(r.max_abs_coef),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
            ]),
            Some(lambda) => {
                let l = r.logistic.clone().unwrap_or_default();
                row.extend([
                    format!("{lambda:e}"),
                    g3(r.rms),
                    g3(r.max_abs_coef),
                    format!("{:.1}/{}", l.iterations_mean, l.iterations_max),
                    l.not_converged.to_string(),
                    l.separable.to_string(),
                    l.constant.to_string(),
                ]);
            }
        }
        row.push(g3(r.fit_s));
        t.push(row);
    }
    t
}

fn precision(rows: &[PrecisionRow]) -> Table {
    let mut t = Table::new(
        "stability_precision",
        &[
            "case",
            "basis",
            "cond",
            "max |ΔK| vs f64 SVD",
            "RMS err K, f64 SVD",
            "RMS err K, this variant",
        ],
    );
    for r in rows {
        let case = match r.variant {
            Variant::F32NormalEquations => format!("{}: f32 normal equations", r.lights),
            Variant::HalfStorage { bound } => format!(
                "{}: half-float storage (stated bound {})",
                r.lights,
                g3(bound)
            ),
        };
        t.push(vec![
            case,
            r.basis.name().into(),
            g3(r.cond),
            g3(r.max_dk),
            g3(r.rms_f64),
            g3(r.rms_variant),
        ]);
    }
    t
}

fn geometry(g: &Geometry) -> Table {
    let mut t = Table::new(
        "stability_geometry",
        &[
            "case",
            "what ptm does",
            "max |ΔK| vs reference bake",
            "texel·lights that differ",
        ],
    );
    let spec = &g.spec;
    for c in &g.cases {
        t.push(match c {
            GeometryCase::Scaled {
                scale,
                max_dk,
                differ,
                total,
            } => vec![
                format!("{spec} scaled by {scale:e}"),
                "bakes a copy scaled by a power of two (exact) to unit size: Embree alone loses hits from 1e-12".into(),
                g3(*max_dk),
                format!("{differ} of {total}"),
            ],
            GeometryCase::Degenerate {
                appended,
                warnings,
                max_dk,
                differ,
            } => vec![
                format!("{appended} zero-area triangles appended"),
                words(warnings),
                g3(*max_dk),
                format!("{differ}"),
            ],
            GeometryCase::NonPeriodic { warnings } => vec![
                "vertices near x = W lifted by 5% of H".into(),
                words(warnings),
                "-".into(),
                "-".into(),
            ],
            GeometryCase::FinerThanTriangles {
                spec,
                triangles,
                fine_res,
                res,
                uncovered,
                mean_fine,
                mean_base,
            } => vec![
                format!("{spec} ({triangles} triangles) at {fine_res}² texels"),
                format!("{uncovered} uncovered texels; facets resolved, K stays in [0, 1]"),
                format!("mean K {} vs {} at {res}²", g3(*mean_fine), g3(*mean_base)),
                "-".into(),
            ],
        });
    }
    t
}

fn blur(rows: &[BlurRow]) -> Table {
    let mut t = Table::new(
        "runtime_blur",
        &[
            "light",
            "kernel",
            "penumbra radius on the caster (texels)",
            "method",
            "max |err| (radiance)",
            "mean |err| (radiance)",
            "shade ms",
            "setup ms",
        ],
    );
    for r in rows {
        let m = &r.measured;
        if let Some((roughness, level)) = r.glossy {
            t.push(vec![
                format!(
                    "glossy reflection{}, roughness {} (mean reflected {})",
                    if r.sky { " over a sky image" } else { "" },
                    g3(roughness as f64),
                    g3(level)
                ),
                if r.sky {
                    "glossy lobe (imaginary light) + prefiltered sky".into()
                } else {
                    "glossy lobe (imaginary light)".into()
                },
                "-".into(),
                m.method.into(),
                g3(m.max_abs_error as f64),
                g3(m.mean_abs_error as f64),
                g3(1e3 * m.shade_s),
                g3(1e3 * m.setup_s),
            ]);
            continue;
        }
        t.push(vec![
            match (r.light_rect, r.light_gaussian) {
                (Some([a, b]), _) => format!("rect {}×{}", g3(a as f64), g3(b as f64)),
                (None, Some([a, b])) => format!("gaussian σ {}×{}", g3(a as f64), g3(b as f64)),
                (None, None) => format!("sphere R {}", g3(r.light_radius as f64)),
            },
            match (r.light_rect, r.light_gaussian) {
                (Some(_), _) => "box",
                (None, Some(_)) => "gaussian",
                (None, None) => "disc",
            }
            .into(),
            g3(r.penumbra_texels),
            m.method.into(),
            g3(m.max_abs_error as f64),
            g3(m.mean_abs_error as f64),
            g3(1e3 * m.shade_s),
            g3(1e3 * m.setup_s),
        ]);
    }
    t
}

fn width(w: ProfileWidth) -> String {
    match w {
        ProfileWidth::Constant => "-".into(),
        ProfileWidth::NoEdgeInView => "no edge in view".into(),
        ProfileWidth::Width(w) => g3(w),
    }
}

fn extremes(rows: &[ExtremeRow]) -> Table {
    let mut t = Table::new(
        "runtime_extremes",
        &[
            "case",
            "what ptm does",
            "blur",
            "analytic penumbra width on the cloth",
            "measured 10–90 % width",
            "caster texel on the cloth",
            "max |opacity − analytic|",
            "GPU vs CPU twin",
            "all finite",
            "setup + shade ms",
        ],
    );
    for r in rows {
        let mut does = r.does.to_string();
        if r.caster_downsample > 1 {
            does += &format!(
                " (downsampled ×{} to {}×{})",
                r.caster_downsample, r.caster_texels[0], r.caster_texels[1]
            );
        }
        t.push(vec![
            r.name.into(),
            does,
            r.blur.name().into(),
            width(r.analytic_width),
            width(r.measured_width),
            r.caster_texel_on_cloth.map_or_else(|| "-".into(), g3),
            g3(r.max_deviation),
            g3(r.gpu_vs_twin.unwrap_or(f64::NAN)),
            if r.all_finite { "yes" } else { "NO" }.into(),
            g3(r.ms),
        ]);
    }
    t
}

/// A swatch's diagnostics in words, one cell.
fn words(warnings: &[ptm_bake::Diagnostic]) -> String {
    warnings
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(" ")
}
