//! Stiff and extreme cases, each run and measured: light layouts that cannot determine the
//! basis, precision (f32 against f64 solving, half against float storage), and geometry at
//! extreme scales or broken in the ways real meshes are.
use std::path::Path;

use ptm_bake::{bake_planes, dome, PreparedMesh};
use ptm_fit::solve::LogisticStats;
use ptm_fit::{fit_stack, FitOptions, FitReport, SampleStack};
use ptm_format::{Basis, LightSet, Link, Ptm, SaveOptions, UvMap};
use ptm_swatches::Mesh;

use crate::study::{bake_config, measure, Errors, Truth};
use crate::{Plan, Result};

/// The stability cases, on one swatch at its truth's resolution.
#[derive(Clone, Debug)]
pub struct Stability {
    /// Builtin name of the swatch.
    pub swatch: String,
    /// Texels a side, covered texels, samples per texel of every bake here.
    pub res: usize,
    /// Texels with some coverage.
    pub covered: usize,
    /// Samples per texel.
    pub spp: u32,
    /// Light layouts (rings, near-degenerate rings, too few lights …) fitted per basis and model.
    pub layouts: Vec<LayoutRow>,
    /// Fibonacci lights of the ridge sweep.
    pub ridge_dirs: usize,
    /// One row per fit of the ridge sweep.
    pub ridge: Vec<RidgeRow>,
    /// f32 normal equations and half-float storage against the f64 fit.
    pub precision: Vec<PrecisionRow>,
    /// Scaled, degenerate, non-periodic and under-tessellated versions of the swatch.
    pub geometry: Geometry,
}

impl Stability {
    /// Runs every case on `swatch` (builtin `name`) against `truth`; `scratch` is an existing
    /// folder for the half-float PTMs of the precision study.
    pub fn run(
        name: &str,
        swatch: &PreparedMesh,
        truth: &Truth,
        plan: &Plan,
        scratch: &Path,
    ) -> Result<Stability> {
        Ok(Stability {
            swatch: name.to_owned(),
            res: truth.res,
            covered: truth.coverage.iter().filter(|&&c| c > 0.0).count(),
            spp: plan.spp,
            layouts: layouts(swatch, truth, plan.spp)?,
            ridge_dirs: plan.ridge_dirs,
            ridge: ridge(swatch, truth, plan.spp, plan.ridge_dirs)?,
            precision: precision(swatch, truth, plan.spp, scratch)?,
            geometry: geometry(name, truth.res, plan.spp)?,
        })
    }
}

/// One light layout fitted with one basis and model.
#[derive(Clone, Debug)]
pub struct LayoutRow {
    /// The layout's name as the table prints it.
    pub layout: &'static str,
    /// Basis fitted.
    pub basis: Basis,
    /// Link fitted.
    pub link: Link,
    /// (u, v) map fitted.
    pub uv: UvMap,
    /// The fit, or the error `ptm fit` would stop with, in words.
    pub fit: std::result::Result<LayoutFit, String>,
}

/// What a fit of a light layout reports and how good it is.
#[derive(Clone, Debug)]
pub struct LayoutFit {
    /// Rank and condition number of the (weighted) design matrix.
    pub rank: usize,
    /// Condition number σ_max / σ_min of the same.
    pub cond: f64,
    /// The fit's diagnostics (empty: ok); their words are `Diagnostic`'s `Display`.
    pub warnings: Vec<ptm_fit::Diagnostic>,
    /// Largest |coefficient| over covered texels.
    pub max_abs_coef: f64,
    /// Against the truth on the held-out lights.
    pub errors: Errors,
    /// Logistic link: what Newton did.
    pub logistic: Option<LogisticStats>,
}

/// One fit of the ridge sweep: the identity link's least squares (`lambda` None) or the
/// logistic link at ridge λ.
#[derive(Clone, Debug)]
pub struct RidgeRow {
    /// Basis fitted.
    pub basis: Basis,
    /// Link fitted.
    pub link: Link,
    /// (u, v) map fitted.
    pub uv: UvMap,
    /// Relative to the mean eigenvalue of AᵀΩA.
    pub lambda: Option<f64>,
    /// RMS error of K on the held-out lights.
    pub rms: f64,
    /// Largest |coefficient| over covered texels.
    pub max_abs_coef: f64,
    /// Logistic link: what Newton did.
    pub logistic: Option<LogisticStats>,
    /// Seconds of the fit.
    pub fit_s: f64,
}

/// What a precision case compares with our f64 SVD fit.
#[derive(Clone, Debug, PartialEq)]
pub enum Variant {
    /// The same fit by f32 normal equations, texel by texel.
    F32NormalEquations,
    /// The f64 fit stored as half floats and read back; `bound` is the file's stated bound.
    HalfStorage {
        /// The file's stated bound on |ΔK|.
        bound: f64,
    },
}

/// One precision case.
#[derive(Clone, Debug)]
pub struct PrecisionRow {
    /// The light layout, in words.
    pub lights: &'static str,
    /// What is compared with the f64 SVD fit.
    pub variant: Variant,
    /// Basis fitted.
    pub basis: Basis,
    /// Condition number of the design.
    pub cond: f64,
    /// Largest |ΔK| (unclamped) against the f64 SVD fit; infinite where NaN appears.
    pub max_dk: f64,
    /// RMS error of K on the held-out lights, of the f64 SVD fit and of the variant.
    pub rms_f64: f64,
    /// RMS error of the variant (beside `rms_f64`).
    pub rms_variant: f64,
}

/// The geometry cases of one builtin swatch.
#[derive(Clone, Debug)]
pub struct Geometry {
    /// The builtin spec the cases are made from.
    pub spec: String,
    /// The cases, in table order.
    pub cases: Vec<GeometryCase>,
}

/// One geometry case and what the bake made of it.
#[derive(Clone, Debug)]
pub enum GeometryCase {
    /// The swatch scaled by `scale`: K against the unscaled bake.
    Scaled {
        /// Factor every length was multiplied by.
        scale: f32,
        /// Largest |ΔK| against the unscaled bake.
        max_dk: f64,
        /// (texel, light) pairs whose K differs, of `total`.
        differ: usize,
        /// (texel, light) pairs compared.
        total: usize,
    },
    /// `appended` zero-area triangles added; the swatch's warnings.
    Degenerate {
        /// Zero-area triangles added.
        appended: usize,
        /// The swatch's warnings.
        warnings: Vec<ptm_bake::Diagnostic>,
        /// Largest |ΔK| against the bake without them.
        max_dk: f64,
        /// (texel, light) pairs whose K differs.
        differ: usize,
    },
    /// Vertices near the x = W border lifted by 5% of H; the swatch's warnings.
    NonPeriodic {
        /// The swatch's warnings.
        warnings: Vec<ptm_bake::Diagnostic>,
    },
    /// The coarsest tessellation `spec` (`triangles`) baked at `fine_res`² and at `res`²:
    /// uncovered texels of the fine bake, and the coverage-weighted mean K of both.
    FinerThanTriangles {
        /// The coarse spec.
        spec: String,
        /// Its triangle count.
        triangles: usize,
        /// Texels a side of the fine bake.
        fine_res: usize,
        /// Texels a side of the base bake.
        res: usize,
        /// Texels of the fine bake no primary ray reached.
        uncovered: usize,
        /// Coverage-weighted mean K of the fine bake.
        mean_fine: f64,
        /// Coverage-weighted mean K of the base bake.
        mean_base: f64,
    },
}

/// Bakes `lights` over `swatch` at the truth's resolution into a stored stack.
fn bake_stack(
    swatch: &PreparedMesh,
    lights: &LightSet,
    res: usize,
    spp: u32,
) -> Result<SampleStack> {
    let (planes, coverage, _) = bake_planes(swatch, lights, &bake_config(res, spp, 1))?;
    Ok(SampleStack {
        width: res,
        height: res,
        tile: swatch.tile,
        lights: lights.clone(),
        k: planes.k,
        coverage,
        uv: None,
    })
}

/// Largest |coefficient| over the covered texels (holes carry a fixed logistic constant that
/// says nothing about the fit).
fn max_abs_coef(ptm: &Ptm, rep: &FitReport) -> f64 {
    let hole = |i: usize| rep.coverage.get(i).is_some_and(|&c| c <= 0.0);
    ptm.planes
        .iter()
        .flat_map(|p| p.iter().enumerate())
        .filter(|&(i, _)| !hole(i))
        .fold(0f64, |m, (_, &c)| m.max(c.abs() as f64))
}

/// The plain PTM and `ptm fit`'s default model.
const FITS: [(Link, UvMap); 2] = [
    (Link::Identity, UvMap::Projected),
    (Link::Logistic, UvMap::Hemispherical),
];

/// The light layouts of the issue, fitted with both bases and both of `FITS` on a real bake.
pub fn layouts(swatch: &PreparedMesh, truth: &Truth, spp: u32) -> Result<Vec<LayoutRow>> {
    let mut near_ring = dome::rings("30x16")?;
    for (i, d) in near_ring.dirs.iter_mut().enumerate() {
        // ±1e-4 in z: numerically a ring, formally full rank.
        let z = d[2] + if i % 2 == 0 { 1e-4 } else { -1e-4 };
        let r = (1.0 - z * z).sqrt() / (d[0] * d[0] + d[1] * d[1]).sqrt();
        *d = [d[0] * r, d[1] * r, z];
    }
    let mut near_ring3 = dome::rings("30x16")?;
    for (i, d) in near_ring3.dirs.iter_mut().enumerate() {
        d[2] += if i % 2 == 0 { 1e-3 } else { -1e-3 };
    }
    let cases: Vec<(&'static str, LightSet)> = vec![
        (
            "Fibonacci 64 above 5° (reference)",
            dome::fibonacci(64, 5.0)?,
        ),
        ("single ring 30°×16", dome::rings("30x16")?),
        ("near-ring 30°×16, z ± 1e-4", near_ring),
        (
            "near-ring 30°×16, z ± 1e-3",
            LightSet::from_dirs(near_ring3.dirs),
        ),
        ("two rings 30°×12 + 60°×8", dome::rings("30x12,60x8")?),
        ("5 lights (fewer than 6 terms)", dome::fibonacci(5, 5.0)?),
        ("10 lights (fewer than 11 terms)", dome::fibonacci(10, 5.0)?),
        ("64 lights all above 60°", dome::fibonacci(64, 60.0)?),
        ("64 lights down to 1°", dome::fibonacci(64, 1.0)?),
    ];
    let (k_true, cov) = truth.at(truth.res);
    let mut rows = Vec::new();
    for (layout, lights) in &cases {
        let stack = bake_stack(swatch, lights, truth.res, spp)?;
        for basis in Basis::ALL {
            for (link, uv) in FITS {
                let opts = FitOptions {
                    link,
                    uv,
                    ..FitOptions::new(basis)
                };
                let fit = match fit_stack(&stack, &opts) {
                    Ok((ptm, rep)) => Ok(LayoutFit {
                        rank: rep.rank,
                        cond: rep.cond,
                        max_abs_coef: max_abs_coef(&ptm, &rep),
                        errors: measure(&ptm, &truth.lights, &k_true, &cov),
                        warnings: rep.warnings,
                        logistic: rep.logistic,
                    }),
                    Err(err) => Err(err.to_string()),
                };
                rows.push(LayoutRow {
                    layout,
                    basis,
                    link,
                    uv,
                    fit,
                });
            }
        }
    }
    Ok(rows)
}

/// The logistic link's ridge λ (relative to the mean eigenvalue of AᵀΩA) from 1e-6 to 10 on a
/// Fibonacci dome of `dirs` lights, hemispherical (u, v), beside the identity link's fit of the
/// same stack: what λ does to the error, the coefficients, Newton and the separable texels.
pub fn ridge(swatch: &PreparedMesh, truth: &Truth, spp: u32, dirs: usize) -> Result<Vec<RidgeRow>> {
    let (k_true, cov) = truth.at(truth.res);
    let lights = dome::fibonacci(dirs, 5.0)?;
    let stack = bake_stack(swatch, &lights, truth.res, spp)?;
    let mut rows = Vec::new();
    for basis in Basis::ALL {
        let t0 = std::time::Instant::now();
        let (ptm, rep) = fit_stack(
            &stack,
            &FitOptions {
                uv: UvMap::Projected,
                ..FitOptions::new(basis)
            },
        )?;
        let secs = t0.elapsed().as_secs_f64();
        rows.push(RidgeRow {
            basis,
            link: Link::Identity,
            uv: UvMap::Projected,
            lambda: None,
            rms: measure(&ptm, &truth.lights, &k_true, &cov).rms,
            max_abs_coef: max_abs_coef(&ptm, &rep),
            logistic: None,
            fit_s: secs,
        });
        for lambda in [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0] {
            let opts = FitOptions {
                link: Link::Logistic,
                uv: UvMap::Hemispherical,
                regularize: Some(lambda),
                ..FitOptions::new(basis)
            };
            let t0 = std::time::Instant::now();
            let (ptm, rep) = fit_stack(&stack, &opts)?;
            let secs = t0.elapsed().as_secs_f64();
            rows.push(RidgeRow {
                basis,
                link: Link::Logistic,
                uv: UvMap::Hemispherical,
                lambda: Some(lambda),
                rms: measure(&ptm, &truth.lights, &k_true, &cov).rms,
                max_abs_coef: max_abs_coef(&ptm, &rep),
                logistic: rep.logistic,
                fit_s: secs,
            });
        }
    }
    Ok(rows)
}

/// Solves one texel's normal equations AᵀA c = Aᵀk in f32 (Gaussian elimination, partial
/// pivoting): the textbook fitter this project does not use, measured against ours.
fn solve_normal_f32(a: &[Vec<f32>], k: &[f32]) -> Vec<f32> {
    let m = a[0].len();
    let mut n = vec![vec![0f32; m + 1]; m];
    for (row, &kk) in a.iter().zip(k) {
        for i in 0..m {
            for j in 0..m {
                n[i][j] += row[i] * row[j];
            }
            n[i][m] += row[i] * kk;
        }
    }
    for c in 0..m {
        let p = (c..m)
            .max_by(|&x, &y| n[x][c].abs().total_cmp(&n[y][c].abs()))
            .unwrap();
        n.swap(c, p);
        let d = n[c][c];
        let (top, rest) = n.split_at_mut(c + 1);
        let pivot = &top[c];
        for row in rest {
            let f = row[c] / d;
            for (x, &p) in row.iter_mut().zip(pivot).skip(c) {
                *x -= f * p;
            }
        }
    }
    let mut x = vec![0f32; m];
    for c in (0..m).rev() {
        let s: f32 = (c + 1..m).map(|j| n[c][j] * x[j]).sum();
        x[c] = (n[c][m] - s) / n[c][c];
    }
    x
}

/// f32 normal equations against our f64 SVD, and half against float storage.
pub fn precision(
    swatch: &PreparedMesh,
    truth: &Truth,
    spp: u32,
    scratch: &Path,
) -> Result<Vec<PrecisionRow>> {
    let (k_true, cov) = truth.at(truth.res);
    let mut rows = Vec::new();
    let mut near_ring = dome::rings("30x16")?;
    for (i, d) in near_ring.dirs.iter_mut().enumerate() {
        d[2] += if i % 2 == 0 { 1e-3 } else { -1e-3 };
    }
    let near_ring = LightSet::from_dirs(near_ring.dirs);
    for (name, lights) in [
        ("Fibonacci 64", dome::fibonacci(64, 5.0)?),
        ("near-ring 30°×16, z ± 1e-3", near_ring),
        ("64 lights above 60°", dome::fibonacci(64, 60.0)?),
    ] {
        let stack = bake_stack(swatch, &lights, truth.res, spp)?;
        for basis in Basis::ALL {
            let (ptm, rep) = fit_stack(&stack, &FitOptions::new(basis))?;
            let ours = measure(&ptm, &truth.lights, &k_true, &cov);
            // The same fit by f32 normal equations, texel by texel.
            let a: Vec<Vec<f32>> = lights
                .dirs
                .iter()
                .map(|d| {
                    let mut row = vec![0f32; basis.len()];
                    basis.terms(d[0] as f32, d[1] as f32, &mut row);
                    row
                })
                .collect();
            let mut f32_ptm = ptm.clone();
            let n = ptm.width * ptm.height;
            for texel in 0..n {
                let k: Vec<f32> = stack.k.iter().map(|p| p[texel]).collect();
                for (c, v) in solve_normal_f32(&a, &k).into_iter().enumerate() {
                    f32_ptm.planes[c][texel] = if v.is_finite() { v } else { f32::NAN };
                }
            }
            let dk = max_dk(&ptm, &f32_ptm, &truth.lights);
            let theirs = measure(&f32_ptm, &truth.lights, &k_true, &cov);
            rows.push(PrecisionRow {
                lights: name,
                variant: Variant::F32NormalEquations,
                basis,
                cond: rep.cond,
                max_dk: dk,
                rms_f64: ours.rms,
                rms_variant: theirs.rms,
            });
            if name == "Fibonacci 64" {
                let path = scratch.join(format!("half-{}.ptm.exr", basis.name()));
                ptm.save(
                    &path,
                    &SaveOptions {
                        half: true,
                        ..Default::default()
                    },
                )?;
                let back = ptm_format::layout::load(&path)?;
                let _ = std::fs::remove_file(&path);
                let half = measure(&back, &truth.lights, &k_true, &cov);
                rows.push(PrecisionRow {
                    lights: name,
                    variant: Variant::HalfStorage {
                        bound: ptm.half_error_bound(),
                    },
                    basis,
                    cond: rep.cond,
                    max_dk: max_dk(&ptm, &back, &truth.lights),
                    rms_f64: ours.rms,
                    rms_variant: half.rms,
                });
            }
        }
    }
    Ok(rows)
}

/// Largest |K_a − K_b| (unclamped) over texels and lights; NaN anywhere counts as infinite.
fn max_dk(a: &Ptm, b: &Ptm, lights: &LightSet) -> f64 {
    let mut m = 0f64;
    for d in &lights.dirs {
        for y in 0..a.height {
            for x in 0..a.width {
                let (ka, kb) = (
                    a.eval_unclamped(x, y, d[0] as f32, d[1] as f32),
                    b.eval_unclamped(x, y, d[0] as f32, d[1] as f32),
                );
                let dk = (ka - kb).abs() as f64;
                m = if dk.is_nan() {
                    f64::INFINITY
                } else {
                    m.max(dk)
                };
            }
        }
    }
    m
}

fn scaled(mesh: &Mesh, s: f32) -> Mesh {
    Mesh {
        positions: mesh.positions.iter().map(|p| p.map(|c| c * s)).collect(),
        triangles: mesh.triangles.clone(),
        tile: mesh.tile.map(|c| c * s),
    }
}

/// The same swatch at extreme scales, with degenerate triangles, made non-periodic, and
/// sampled finer than its triangles.
pub fn geometry(spec: &str, res: usize, spp: u32) -> Result<Geometry> {
    let mesh = ptm_swatches::builtin(spec)?;
    let lights = dome::fibonacci(16, 5.0)?;
    /// A bake of one mesh: the checked swatch, K planes, coverage, uncovered texels.
    type Baked = (PreparedMesh, Vec<Vec<f32>>, Vec<f32>, usize);
    let bake = |m: Mesh, name: &str, res: usize| -> Result<Baked> {
        let sw = PreparedMesh::from_mesh(m, None, name)?;
        let (planes, cov, rep) = bake_planes(&sw, &lights, &bake_config(res, spp, 1))?;
        Ok((sw, planes.k, cov, rep.uncovered_texels))
    };
    let (_, k_ref, _, _) = bake(mesh.clone(), spec, res)?;
    let diff = |k: &[Vec<f32>]| -> (f64, usize) {
        let mut m = 0f64;
        let mut n = 0;
        for (a, b) in k_ref.iter().flatten().zip(k.iter().flatten()) {
            let d = (a - b).abs() as f64;
            m = m.max(d);
            n += (d > 0.0) as usize;
        }
        (m, n)
    };
    let mut cases = Vec::new();
    for s in [1e-12f32, 1e-4, 1e4, 1e12] {
        let (_, k, _, _) = bake(scaled(&mesh, s), &format!("{spec} ×{s:e}"), res)?;
        let (m, n) = diff(&k);
        cases.push(GeometryCase::Scaled {
            scale: s,
            max_dk: m,
            differ: n,
            total: k_ref.len() * k_ref[0].len(),
        });
    }
    // Degenerate triangles: repeated vertices and collinear triples, appended.
    let mut degen = mesh.clone();
    let nv = degen.positions.len() as u32;
    let (p0, p1) = (degen.positions[0], degen.positions[1]);
    degen.positions.push([
        2.0 * p1[0] - p0[0],
        2.0 * p1[1] - p0[1],
        2.0 * p1[2] - p0[2],
    ]);
    for i in 0..50u32 {
        degen.triangles.push([i % nv, i % nv, (i + 1) % nv]);
    }
    degen.triangles.push([0, 1, nv]);
    let (sw, k, _, _) = bake(degen, &format!("{spec} + 51 degenerate"), res)?;
    let (m, n) = diff(&k);
    cases.push(GeometryCase::Degenerate {
        appended: 51,
        warnings: sw.warnings(),
        max_dk: m,
        differ: n,
    });
    // Non-periodic: lift every vertex within 2% of the x = W border by 5% of the tile height.
    let mut broken = mesh.clone();
    let (w, h) = (mesh.tile[0], mesh.tile[1]);
    for p in &mut broken.positions {
        if p[0] > 0.98 * w {
            p[2] += 0.05 * h;
        }
    }
    let sw = PreparedMesh::from_mesh(broken, None, &format!("{spec} (x = W border lifted)"))?;
    cases.push(GeometryCase::NonPeriodic {
        warnings: sw.warnings(),
    });
    // Texels finer than triangles: the coarsest tessellation at 4× the resolution; the mean
    // of K over 4×4 fine texels must match a bake at the base resolution within sampling error.
    let coarse = format!(
        "{}?segments=3&along=2",
        spec.split('?').next().unwrap_or(spec)
    );
    let cmesh = ptm_swatches::builtin(&coarse)?;
    let ntri = cmesh.triangles.len();
    let (_, k_fine, cov_fine, unc) = bake(cmesh.clone(), &coarse, res * 4)?;
    let (_, k_base, cov_base, _) = bake(cmesh, &coarse, res)?;
    let mean = |k: &[Vec<f32>], cov: Option<&[f32]>| -> f64 {
        let mut s = 0.0;
        let mut w = 0.0;
        for p in k {
            for (i, &x) in p.iter().enumerate() {
                let c = cov.map_or(1.0, |c| c[i] as f64);
                s += x as f64 * c;
                w += c;
            }
        }
        s / w
    };
    cases.push(GeometryCase::FinerThanTriangles {
        spec: coarse,
        triangles: ntri,
        fine_res: res * 4,
        res,
        uncovered: unc,
        mean_fine: mean(&k_fine, Some(&cov_fine)),
        mean_base: mean(&k_base, Some(&cov_base)),
    });
    Ok(Geometry {
        spec: spec.to_owned(),
        cases,
    })
}
