//! Stiff and extreme cases, each run and measured: light layouts that cannot determine the
//! basis, precision (f32 against f64 solving, half against float storage), and geometry at
//! extreme scales or broken in the ways real meshes are.
use anyhow::Result;
use ptm_bake::{bake_planes, dome, Swatch};
use ptm_fit::{
    fit_stack, Basis, FitOptions, FitReport, LightSet, Link, Ptm, SampleStack, SaveOptions, UvMap,
};
use ptm_swatches::Mesh;

use super::study::{bake_config, measure, Truth};
use super::table::{g3, Table};

/// Bakes `lights` over `swatch` at the truth's resolution into a stored stack.
fn bake_stack(swatch: &Swatch, lights: &LightSet, res: usize, spp: u32) -> Result<SampleStack> {
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

/// Newton's iterations (mean/max) and separable/constant texels of a logistic fit, or "-".
fn newton_cells(rep: &FitReport) -> [String; 2] {
    match &rep.logistic {
        Some(l) => [
            format!(
                "{:.1}/{} ({} at the cap)",
                l.iterations_mean, l.iterations_max, l.not_converged
            ),
            format!("{}/{}", l.separable, l.constant),
        ],
        None => ["-".into(), "-".into()],
    }
}

/// The plain PTM and `ptm fit`'s default model.
const FITS: [(Link, UvMap); 2] = [
    (Link::Identity, UvMap::Projected),
    (Link::Logistic, UvMap::Hemispherical),
];

/// The light layouts of the issue, fitted with both bases and both of [`FITS`] on a real bake.
pub fn layouts(swatch: &Swatch, truth: &Truth, spp: u32) -> Result<Table> {
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
    let cases: Vec<(&str, LightSet)> = vec![
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
    for (name, lights) in &cases {
        let stack = bake_stack(swatch, lights, truth.res, spp)?;
        for basis in Basis::ALL {
            for (link, uv) in FITS {
                let fit = format!("{}, {}", link.name(), uv.name());
                let opts = FitOptions {
                    link,
                    uv,
                    ..FitOptions::new(basis)
                };
                let row = match fit_stack(&stack, &opts) {
                    Ok((ptm, rep)) => {
                        let e = measure(&ptm, &truth.lights, &k_true, &cov);
                        let [iters, sep] = newton_cells(&rep);
                        vec![
                            name.to_string(),
                            basis.name().into(),
                            fit,
                            format!("{}/{}", rep.rank, basis.len()),
                            g3(rep.cond),
                            if rep.warnings.is_empty() {
                                "ok".into()
                            } else {
                                rep.warnings.join(" ")
                            },
                            g3(max_abs_coef(&ptm, &rep)),
                            g3(e.rms),
                            format!("{:.1}% (max {})", 100.0 * e.outside, g3(e.outside_max)),
                            iters,
                            sep,
                        ]
                    }
                    Err(err) => {
                        let mut r = vec![
                            name.to_string(),
                            basis.name().into(),
                            fit,
                            "-".into(),
                            "-".into(),
                            format!("error: {err}"),
                        ];
                        r.extend(std::iter::repeat_n("-".to_string(), 5));
                        r
                    }
                };
                t.push(row);
            }
        }
    }
    Ok(t)
}

/// The logistic link's ridge λ (relative to the mean eigenvalue of AᵀΩA) from 1e-6 to 10 on a
/// Fibonacci dome of `dirs` lights, hemispherical (u, v), beside the identity link's fit of the
/// same stack: what λ does to the error, the coefficients, Newton and the separable texels.
pub fn ridge(swatch: &Swatch, truth: &Truth, spp: u32, dirs: usize) -> Result<Table> {
    let (k_true, cov) = truth.at(truth.res);
    let lights = dome::fibonacci(dirs, 5.0)?;
    let stack = bake_stack(swatch, &lights, truth.res, spp)?;
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
        t.push(vec![
            basis.name().into(),
            "identity, projected".into(),
            "-".into(),
            g3(measure(&ptm, &truth.lights, &k_true, &cov).rms),
            g3(max_abs_coef(&ptm, &rep)),
            "-".into(),
            "-".into(),
            "-".into(),
            "-".into(),
            g3(secs),
        ]);
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
            let l = rep.logistic.clone().unwrap_or_default();
            t.push(vec![
                basis.name().into(),
                "logistic, hemispherical".into(),
                format!("{lambda:e}"),
                g3(measure(&ptm, &truth.lights, &k_true, &cov).rms),
                g3(max_abs_coef(&ptm, &rep)),
                format!("{:.1}/{}", l.iterations_mean, l.iterations_max),
                l.not_converged.to_string(),
                l.separable.to_string(),
                l.constant.to_string(),
                g3(secs),
            ]);
        }
    }
    Ok(t)
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
    swatch: &Swatch,
    truth: &Truth,
    spp: u32,
    scratch: &std::path::Path,
) -> Result<Table> {
    let (k_true, cov) = truth.at(truth.res);
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
            t.push(vec![
                format!("{name}: f32 normal equations"),
                basis.name().into(),
                g3(rep.cond),
                g3(dk),
                g3(ours.rms),
                g3(theirs.rms),
            ]);
            if name == "Fibonacci 64" {
                let path = scratch.join(format!("half-{}.ptm.exr", basis.name()));
                ptm.save(
                    &path,
                    &SaveOptions {
                        half: true,
                        ..Default::default()
                    },
                )?;
                let back = Ptm::load(&path)?;
                let _ = std::fs::remove_file(&path);
                let half = measure(&back, &truth.lights, &k_true, &cov);
                t.push(vec![
                    format!(
                        "{name}: half-float storage (stated bound {})",
                        g3(ptm.half_error_bound())
                    ),
                    basis.name().into(),
                    g3(rep.cond),
                    g3(max_dk(&ptm, &back, &truth.lights)),
                    g3(ours.rms),
                    g3(half.rms),
                ]);
            }
        }
    }
    Ok(t)
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
pub fn geometry(spec: &str, res: usize, spp: u32) -> Result<Table> {
    let mesh = ptm_swatches::builtin(spec)?;
    let lights = dome::fibonacci(16, 5.0)?;
    /// A bake of one mesh: the checked swatch, K planes, coverage, uncovered texels.
    type Baked = (Swatch, Vec<Vec<f32>>, Vec<f32>, usize);
    let bake = |m: Mesh, name: &str, res: usize| -> Result<Baked> {
        let sw = Swatch::from_mesh(m, None, name)?;
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
    let mut t = Table::new(
        "stability_geometry",
        &[
            "case",
            "what ptm does",
            "max |ΔK| vs reference bake",
            "texel·lights that differ",
        ],
    );
    for s in [1e-12f32, 1e-4, 1e4, 1e12] {
        let (_, k, _, _) = bake(scaled(&mesh, s), &format!("{spec} ×{s:e}"), res)?;
        let (m, n) = diff(&k);
        t.push(vec![
            format!("{spec} scaled by {s:e}"),
            "bakes a copy scaled by a power of two (exact) to unit size: Embree alone loses hits from 1e-12".into(),
            g3(m),
            format!("{n} of {}", k_ref.len() * k_ref[0].len()),
        ]);
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
    t.push(vec![
        "51 zero-area triangles appended".into(),
        sw.warnings().join(" "),
        g3(m),
        format!("{n}"),
    ]);
    // Non-periodic: lift every vertex within 2% of the x = W border by 5% of the tile height.
    let mut broken = mesh.clone();
    let (w, h) = (mesh.tile[0], mesh.tile[1]);
    for p in &mut broken.positions {
        if p[0] > 0.98 * w {
            p[2] += 0.05 * h;
        }
    }
    let sw = Swatch::from_mesh(broken, None, &format!("{spec} (x = W border lifted)"))?;
    t.push(vec![
        "vertices near x = W lifted by 5% of H".into(),
        sw.warnings().join(" "),
        "-".into(),
        "-".into(),
    ]);
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
    t.push(vec![
        format!("{coarse} ({ntri} triangles) at {}² texels", res * 4),
        format!("{unc} uncovered texels; facets resolved, K stays in [0, 1]"),
        format!(
            "mean K {} vs {} at {res}²",
            g3(mean(&k_fine, Some(&cov_fine))),
            g3(mean(&k_base, Some(&cov_base)))
        ),
        "-".into(),
    ]);
    Ok(t)
}
