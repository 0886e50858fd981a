//! The model-comparison row of issue #22 for one swatch: the PTMs (ptm6/ptm11, identity and
//! logistic, hemispherical (u, v)) and the learned bases (learned6, learned11) beside the horizon-map and AO micro-shadowing baselines of
//! [`crate::baselines`], all fitted from one bake of a Fibonacci training dome and measured
//! as the RMS error of K against the held-out truth (the error [`crate::study::measure`]
//! reports for PTMs: clamped K, covered texels).
use std::time::Instant;

use ptm_bake::{dome, PreparedMesh};
use ptm_fit::Weight;
use ptm_format::{Basis, Link, UvMap};
use rayon::prelude::*;

use crate::baselines::{cosine_visibility, elevation_azimuth, micro_shadow_k, Horizon};
use crate::study::{bake_config, run_settings, Setting, Truth};
use crate::Result;

/// One model of the row: what it is, how many numbers per texel it stores, what it scored.
#[derive(Clone, Debug)]
pub struct ModelScore {
    /// The model in words (`ptm11 logistic`, `horizon 8`, `AO micro-shadowing`).
    pub name: String,
    /// Numbers stored per texel.
    pub numbers: usize,
    /// RMS error of K on the held-out lights.
    pub rms: f64,
    /// Fit seconds (the bake's are shared, in [`CompareRow::bake_s`]).
    pub fit_s: f64,
}

/// Every model of the comparison on one swatch.
#[derive(Clone, Debug)]
pub struct CompareRow {
    /// Builtin name.
    pub swatch: String,
    /// Seconds of the training bake the baselines are fitted from.
    pub bake_s: f64,
    /// In a fixed order: the four PTMs, learned6 and learned11 (where the dome has 4 lights
    /// per term), horizon 8 and 10, AO.
    pub models: Vec<ModelScore>,
}

/// Fits every model to a bake of `dirs` Fibonacci lights above 5° at `res`², `spp` samples
/// per texel, and measures each against `truth` (resampled to `res`).
pub fn compare(
    name: &str,
    swatch: &PreparedMesh,
    truth: &Truth,
    dirs: usize,
    spp: u32,
    res: usize,
) -> Result<CompareRow> {
    let coarse = truth.at(res);
    let setting = |basis, link| Setting {
        dirs,
        spp,
        res,
        basis,
        weight: Weight::Uniform,
        link,
        uv: UvMap::Hemispherical,
    };
    let mut settings: Vec<Setting> = [Basis::Ptm6, Basis::Ptm11]
        .into_iter()
        .flat_map(|basis| [Link::Identity, Link::Logistic].map(|link| setting(basis, link)))
        .collect();
    // The learned bases (logistic, hemispherical by definition) where the dome allows them.
    for k in [6u8, 11] {
        if dirs >= ptm_fit::learned::LIGHTS_PER_TERM * k as usize {
            settings.push(setting(Basis::Learned(k), Link::Logistic));
        }
    }
    let mut models: Vec<ModelScore> = run_settings(swatch, truth, &coarse, &settings)?
        .into_iter()
        .map(|o| ModelScore {
            name: format!("{} {}", o.setting.basis.name(), o.setting.link.name()),
            numbers: o.setting.basis.len(),
            rms: o.errors.rms,
            fit_s: o.fit_s,
        })
        .collect();
    let lights = dome::fibonacci(dirs, 5.0)?;
    let t = Instant::now();
    let (planes, coverage, _) = ptm_bake::bake_planes(swatch, &lights, &bake_config(res, spp, 1))?;
    let bake_s = t.elapsed().as_secs_f64();
    let train: Vec<(f64, f64)> = lights.dirs.iter().map(|&d| elevation_azimuth(d)).collect();
    let test: Vec<(f64, f64)> = truth
        .lights
        .dirs
        .iter()
        .map(|&d| elevation_azimuth(d))
        .collect();
    let texels: Vec<usize> = (0..res * res).filter(|&t| coverage[t] > 0.0).collect();
    let samples = |t: usize| -> Vec<f32> { planes.k.iter().map(|p| p[t]).collect() };
    // RMS over covered texels (covered in the truth as well) of a per-texel predictor.
    let rms = |pred: &(dyn Fn(usize, usize) -> f64 + Sync)| -> f64 {
        let (s, n) = texels
            .par_iter()
            .filter(|&&t| coverage_ok(&coarse.1, t))
            .map(|&t| {
                (0..test.len())
                    .map(|j| (pred(t, j).clamp(0.0, 1.0) - coarse.0[j][t] as f64).powi(2))
                    .sum::<f64>()
            })
            .fold(|| (0.0, 0usize), |(s, n), x| (s + x, n + test.len()))
            .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        (s / n.max(1) as f64).sqrt()
    };
    for azimuths in [8, 10] {
        let t = Instant::now();
        let fits: Vec<Horizon> = texels
            .par_iter()
            .map(|&x| Horizon::fit(azimuths, &train, &samples(x)))
            .collect();
        let fit_s = t.elapsed().as_secs_f64();
        let at = index_of(&texels, res);
        models.push(ModelScore {
            name: format!("horizon {azimuths}"),
            numbers: azimuths + 1,
            rms: rms(&|x, j| fits[at[x]].k(test[j].0, test[j].1)),
            fit_s,
        });
    }
    let t = Instant::now();
    let nol: Vec<f64> = lights.dirs.iter().map(|d| d[2]).collect();
    let vis: Vec<f64> = texels
        .par_iter()
        .map(|&x| cosine_visibility(&nol, &samples(x)))
        .collect();
    let fit_s = t.elapsed().as_secs_f64();
    let at = index_of(&texels, res);
    models.push(ModelScore {
        name: "AO micro-shadowing".into(),
        numbers: 1,
        rms: rms(&|x, j| micro_shadow_k(truth.lights.dirs[j][2], vis[at[x]])),
        fit_s,
    });
    Ok(CompareRow {
        swatch: name.to_owned(),
        bake_s,
        models,
    })
}

fn coverage_ok(cov: &[f32], t: usize) -> bool {
    cov[t] > 0.0
}

/// Texel → position in `texels` (usize::MAX for uncovered texels, never looked up).
fn index_of(texels: &[usize], res: usize) -> Vec<usize> {
    let mut at = vec![usize::MAX; res * res];
    for (i, &t) in texels.iter().enumerate() {
        at[t] = i;
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small bake of the plain weave: every model scores a finite error, the horizon map and
    /// the logistic ptm11 beat the one-number AO, and the ptm11 beats the ptm6 of its link.
    #[test]
    fn comparison_row_orders_the_models_sensibly() {
        let swatch = PreparedMesh::load("builtin:plain-weave", None).unwrap();
        let test = crate::study::test_lights(16).unwrap();
        let truth = Truth::bake(&swatch, 16, 8, test).unwrap();
        let row = compare("plain-weave", &swatch, &truth, 48, 4, 16).unwrap();
        let rms = |name: &str| row.models.iter().find(|m| m.name == name).unwrap().rms;
        assert_eq!(row.models.len(), 9);
        assert!(row.models.iter().all(|m| m.rms.is_finite() && m.rms > 0.0));
        let ao = rms("AO micro-shadowing");
        assert!(rms("horizon 8") < ao && rms("ptm11 logistic") < ao);
        assert!(rms("learned11 logistic") < ao);
        assert!(rms("ptm11 identity") < rms("ptm6 identity"));
    }
}
