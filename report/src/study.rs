//! Error against run time: bake + fit a swatch under many settings and measure the error of the
//! fitted (clamped) K against a dense ground-truth bake on held-out light directions; per
//! swatch, the Pareto front, the four models on the same bakes, and the best setting per
//! time budget.
use std::time::Instant;

use ptm_bake::{dome, BakeConfig, Baker, PreparedMesh};
use ptm_fit::{Accumulator, FitOptions, Weight};
use ptm_format::{Basis, LightSet, Link, Ptm, UvMap};
use rayon::prelude::*;

use crate::{Plan, Result, MODELS};

/// Held-out directions: Fibonacci above 5°, turned 0.7 rad in azimuth so that no test light
/// coincides with a light of any training dome (those are unturned Fibonacci domes).
pub fn test_lights(n: usize) -> Result<LightSet> {
    let f = dome::fibonacci(n, 5.0)?;
    let (s, c) = 0.7f64.sin_cos();
    Ok(LightSet::from_dirs(
        f.dirs
            .iter()
            .map(|d| [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]),
    ))
}

/// A dense bake of the held-out lights: the reference every setting is measured against.
pub struct Truth {
    /// Texels a side.
    pub res: usize,
    /// The held-out lights baked.
    pub lights: LightSet,
    /// `k[light][texel]` at `res`².
    pub k: Vec<Vec<f32>>,
    /// Per-texel coverage at `res`², row-major.
    pub coverage: Vec<f32>,
    /// RMS sampling noise of K in the truth itself: errors below it are not resolved.
    pub noise: f64,
    /// Seconds the truth bakes took.
    pub seconds: f64,
}

/// Deterministic bake settings shared by the study (all cores, packets).
pub fn bake_config(res: usize, spp: u32, seed: u64) -> BakeConfig {
    BakeConfig {
        res: [res, res],
        spp,
        seed,
        light_distance: None,
        packets: true,
        threads: 0,
    }
}

impl Truth {
    /// Bakes the truth twice with independent sample positions and keeps their mean; half the
    /// RMS difference of the two is the mean's own sampling noise (returned as `noise`).
    pub fn bake(swatch: &PreparedMesh, res: usize, spp: u32, lights: LightSet) -> Result<Truth> {
        let t = Instant::now();
        // Seeds no setting uses: the truth's sample positions are independent of theirs.
        let (a, coverage, _) =
            ptm_bake::bake_planes(swatch, &lights, &bake_config(res, spp, 0x7e57))?;
        let (b, _, _) = ptm_bake::bake_planes(swatch, &lights, &bake_config(res, spp, 0x7e58))?;
        let (mut d2, mut n) = (0.0f64, 0usize);
        let k =
            a.k.iter()
                .zip(&b.k)
                .map(|(pa, pb)| {
                    pa.iter()
                        .zip(pb)
                        .zip(&coverage)
                        .map(|((&x, &y), &c)| {
                            if c > 0.0 {
                                d2 += ((x - y) as f64).powi(2);
                                n += 1;
                            }
                            0.5 * (x + y)
                        })
                        .collect()
                })
                .collect();
        let noise = 0.5 * (d2 / n.max(1) as f64).sqrt();
        Ok(Truth {
            res,
            lights,
            k,
            coverage,
            noise,
            seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// The truth at a coarser resolution `res` (dividing `self.res`): per coarse texel the
    /// coverage-weighted mean of its children, which is what a bake at `res` estimates (K is
    /// occluded over covered samples). Returns (k planes, coverage).
    pub fn at(&self, res: usize) -> (Vec<Vec<f32>>, Vec<f32>) {
        assert!(
            self.res.is_multiple_of(res),
            "truth resolution {} is not a multiple of {res}",
            self.res
        );
        let f = self.res / res;
        let mut cov = vec![0f32; res * res];
        for (j, row) in cov.chunks_mut(res).enumerate() {
            for (i, c) in row.iter_mut().enumerate() {
                let mut s = 0.0;
                for y in 0..f {
                    for x in 0..f {
                        s += self.coverage[(j * f + y) * self.res + i * f + x];
                    }
                }
                *c = s / (f * f) as f32;
            }
        }
        let k = self
            .k
            .par_iter()
            .map(|plane| {
                let mut out = vec![0f32; res * res];
                for j in 0..res {
                    for i in 0..res {
                        let (mut s, mut w) = (0.0f64, 0.0f64);
                        for y in 0..f {
                            for x in 0..f {
                                let t = (j * f + y) * self.res + i * f + x;
                                s += (plane[t] * self.coverage[t]) as f64;
                                w += self.coverage[t] as f64;
                            }
                        }
                        out[j * res + i] = if w > 0.0 { (s / w) as f32 } else { 0.0 };
                    }
                }
                out
            })
            .collect();
        (k, cov)
    }
}

/// Error of a PTM against reference planes on the test lights, over covered texels.
#[derive(Clone, Copy, Debug, Default)]
pub struct Errors {
    /// RMS, 99th percentile and maximum of |K_fit − K_true| (K_fit clamped to [0, 1], as
    /// rendered).
    pub rms: f64,
    /// 99th percentile of the same.
    pub p99: f64,
    /// Maximum of the same.
    pub max: f64,
    /// Fraction of (texel, light) pairs whose unclamped K leaves [0, 1], and by how much at most.
    pub outside: f64,
    /// Largest distance of an unclamped K outside [0, 1].
    pub outside_max: f64,
}

/// Measures `ptm` against `k_true[light][texel]` on `lights`, over texels with coverage.
pub fn measure(ptm: &Ptm, lights: &LightSet, k_true: &[Vec<f32>], coverage: &[f32]) -> Errors {
    let n = ptm.width * ptm.height;
    let per_light: Vec<(Vec<f32>, usize, f64)> = lights
        .dirs
        .par_iter()
        .zip(k_true)
        .map(|(d, truth)| {
            let (u, v) = (d[0] as f32, d[1] as f32);
            let (mut errs, mut outside, mut out_max) = (Vec::with_capacity(n), 0usize, 0f64);
            for t in (0..n).filter(|&t| coverage[t] > 0.0) {
                let k = ptm.eval_unclamped(t % ptm.width, t / ptm.width, u, v);
                let excess = (k - 1.0).max(-k).max(0.0) as f64;
                if excess > 0.0 {
                    outside += 1;
                    out_max = out_max.max(excess);
                }
                errs.push((k.clamp(0.0, 1.0) - truth[t]).abs());
            }
            (errs, outside, out_max)
        })
        .collect();
    let mut all: Vec<f32> = per_light.iter().flat_map(|p| p.0.iter().copied()).collect();
    if all.is_empty() {
        return Errors::default();
    }
    let count = all.len() as f64;
    let rms = (all.iter().map(|&e| (e as f64).powi(2)).sum::<f64>() / count).sqrt();
    all.sort_by(f32::total_cmp);
    let p99 = all[((count * 0.99).ceil() as usize).clamp(1, all.len()) - 1] as f64;
    Errors {
        rms,
        p99,
        max: *all.last().unwrap() as f64,
        outside: per_light.iter().map(|p| p.1).sum::<usize>() as f64 / count,
        outside_max: per_light.iter().map(|p| p.2).fold(0.0, f64::max),
    }
}

/// One point of the sweep: how the bake samples (lights, samples per texel, texels) and how the
/// fit models K (basis, light weight, link, (u, v) map).
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// Lights of the bake's Fibonacci dome.
    pub dirs: usize,
    /// Samples per texel.
    pub spp: u32,
    /// Texels a side.
    pub res: usize,
    /// Basis fitted.
    pub basis: Basis,
    /// Light weighting of the fit.
    pub weight: Weight,
    /// Link fitted.
    pub link: Link,
    /// (u, v) map fitted.
    pub uv: UvMap,
}

impl Setting {
    /// The setting in words, as the tables and the log name it.
    pub fn label(&self) -> String {
        format!(
            "{} lights, spp {}, {}², {}, {}, {}, {}",
            self.dirs,
            self.spp,
            self.res,
            self.basis.name(),
            self.weight.name(),
            self.link.name(),
            self.uv.name()
        )
    }

    /// The bake this setting needs: settings that share it are fitted from one trace.
    pub fn bake_key(&self) -> (usize, u32, usize) {
        (self.dirs, self.spp, self.res)
    }
}

/// What a setting cost and bought.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The setting measured.
    pub setting: Setting,
    /// Scene build + primary hits + shadow rays (shared by the settings of one bake), and this
    /// setting's streaming fit (accumulate, then solve: SVD apply or Newton per texel).
    pub bake_s: f64,
    /// This setting's fit seconds (beside the bake's `bake_s`).
    pub fit_s: f64,
    /// Against the truth on the held-out lights.
    pub errors: Errors,
    /// Logistic link: what Newton did (iterations, separable and constant texels).
    pub logistic: Option<ptm_fit::solve::LogisticStats>,
}

impl Outcome {
    /// Bake + fit seconds: what the setting costs from a swatch to a PTM.
    pub fn seconds(&self) -> f64 {
        self.bake_s + self.fit_s
    }
}

/// Bakes the Fibonacci dome of `settings[0].dirs` lights once and fits it streaming (the
/// `ptm bake --fit` path) once per setting, all of which share that bake (`bake_key`); times
/// the trace and each fit separately, then measures each PTM against `truth` resampled to the
/// settings' resolution. MIP levels are not fitted: the error is level 0's.
pub fn run_settings(
    swatch: &PreparedMesh,
    truth: &Truth,
    coarse: &(Vec<Vec<f32>>, Vec<f32>),
    settings: &[Setting],
) -> Result<Vec<Outcome>> {
    let s0 = &settings[0];
    assert!(settings.iter().all(|s| s.bake_key() == s0.bake_key()));
    let lights = dome::fibonacci(s0.dirs, 5.0)?;
    let mut fit_s = vec![0.0; settings.len()];
    let mut accs = Vec::with_capacity(settings.len());
    for (s, secs) in settings.iter().zip(&mut fit_s) {
        let opts = FitOptions {
            weight: s.weight,
            link: s.link,
            uv: s.uv,
            mips: false,
            ..FitOptions::new(s.basis)
        };
        let t = Instant::now();
        let mut acc = Accumulator::new(&lights, s.res, s.res, &opts)?;
        acc.set_spp(s.spp)?;
        *secs += t.elapsed().as_secs_f64();
        accs.push(acc);
    }
    let t1 = Instant::now();
    let mut baker = Baker::new(swatch, &bake_config(s0.res, s0.spp, 1))?;
    for acc in &mut accs {
        acc.set_coverage(baker.coverage())?;
    }
    let mut stream_s = 0.0;
    baker.trace(&lights, &mut |i, k, _| {
        for (acc, secs) in accs.iter_mut().zip(fit_s.iter_mut()) {
            let t = Instant::now();
            acc.add_light(i, k).map_err(ptm_bake::Error::sink)?;
            let dt = t.elapsed().as_secs_f64();
            *secs += dt;
            stream_s += dt;
        }
        Ok(())
    })?;
    let bake_s = (t1.elapsed().as_secs_f64() - stream_s).max(0.0);
    let mut out = Vec::with_capacity(settings.len());
    for ((s, acc), secs) in settings.iter().zip(accs).zip(fit_s) {
        let t = Instant::now();
        let (ptm, rep) = acc.finish(swatch.tile)?;
        out.push(Outcome {
            setting: s.clone(),
            bake_s,
            fit_s: secs + t.elapsed().as_secs_f64(),
            errors: measure(&ptm, &truth.lights, &coarse.0, &coarse.1),
            logistic: rep.logistic,
        });
    }
    Ok(out)
}

/// Indices of the Pareto front (no other outcome is both faster and more accurate), by time.
pub fn pareto(outcomes: &[Outcome]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..outcomes.len()).collect();
    idx.sort_by(|&a, &b| outcomes[a].seconds().total_cmp(&outcomes[b].seconds()));
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if outcomes[i].errors.rms < best {
            best = outcomes[i].errors.rms;
            front.push(i);
        }
    }
    front
}

/// The four models of [`MODELS`] fitted from one bake and basis: one row of the model table.
#[derive(Clone, Debug)]
pub struct ModelRow {
    /// The plain PTM's setting (identity link, projected (u, v), uniform weight).
    pub setting: Setting,
    /// RMS error of K and fit seconds per model, in the order of [`MODELS`].
    pub rms: [f64; 4],
    /// Fit seconds per model, in the order of [`MODELS`].
    pub fit_s: [f64; 4],
    /// The shared bake's seconds.
    pub bake_s: f64,
}

impl ModelRow {
    /// The fraction by which `ptm fit`'s default model (logistic, hemispherical) reduces the
    /// RMS error of the plain PTM on the same bake.
    pub fn default_gain(&self) -> f64 {
        1.0 - self.rms[3] / self.rms[0]
    }
}

/// The most accurate measured setting within a time budget.
#[derive(Clone, Debug)]
pub struct Recommendation {
    /// Bake + fit seconds allowed.
    pub budget_s: f64,
    /// The outcome chosen.
    pub best: Outcome,
}

/// One swatch's sweep: every setting of the plan measured against its ground truth.
#[derive(Clone, Debug)]
pub struct SwatchStudy {
    /// Builtin name (`plain-weave`).
    pub name: String,
    /// Triangles of the swatch's mesh.
    pub triangles: usize,
    /// The periodic tile's width and height, in mesh units.
    pub tile: [f64; 2],
    /// Seconds of the two truth bakes, and the truth's own RMS sampling noise of K.
    pub truth_seconds: f64,
    /// RMS sampling noise of K in the truth itself.
    pub truth_noise: f64,
    /// In the order the settings were baked (grouped by bake).
    pub outcomes: Vec<Outcome>,
    /// Indices into `outcomes` of the Pareto front, by time ([`pareto`]).
    pub pareto: Vec<usize>,
    /// The four models on one bake per basis.
    pub models: Vec<ModelRow>,
    /// One per half decade of seconds spanning the measured range.
    pub recommendations: Vec<Recommendation>,
}

impl SwatchStudy {
    /// Bakes the truth of `swatch` on the `test` lights and measures every setting of `plan`
    /// (one bake per (lights, spp, texels), every setting that shares it fitted from it).
    /// Returns the truth too: the stability cases measure against it.
    pub fn run(
        name: &str,
        swatch: &PreparedMesh,
        plan: &Plan,
        test: &LightSet,
        progress: &mut dyn FnMut(&str),
    ) -> Result<(SwatchStudy, Truth)> {
        progress(&format!(
            "{name}: {} triangles, baking the truth",
            swatch.triangles.len()
        ));
        let truth = Truth::bake(swatch, plan.truth_res, plan.truth_spp, test.clone())?;
        let mut coarse = std::collections::HashMap::new();
        let mut outcomes = Vec::new();
        let mut keys = Vec::new();
        for s in &plan.settings {
            if !keys.contains(&s.bake_key()) {
                keys.push(s.bake_key());
            }
        }
        for key in keys {
            let group: Vec<Setting> = plan
                .settings
                .iter()
                .filter(|s| s.bake_key() == key)
                .cloned()
                .collect();
            let c = coarse.entry(key.2).or_insert_with(|| truth.at(key.2));
            for o in run_settings(swatch, &truth, c, &group)? {
                progress(&format!(
                    "{name}: {:<70} bake {:>7.3} s  fit {:>7.3} s  rms {:.4}",
                    o.setting.label(),
                    o.bake_s,
                    o.fit_s,
                    o.errors.rms
                ));
                outcomes.push(o);
            }
        }
        let study = SwatchStudy {
            name: name.to_owned(),
            triangles: swatch.triangles.len(),
            tile: swatch.tile,
            truth_seconds: truth.seconds,
            truth_noise: truth.noise,
            pareto: pareto(&outcomes),
            models: model_rows(&outcomes),
            recommendations: recommendations(&outcomes),
            outcomes,
        };
        Ok((study, truth))
    }

    /// The outcome with the least RMS error.
    pub fn best(&self) -> &Outcome {
        self.outcomes
            .iter()
            .min_by(|a, b| a.errors.rms.total_cmp(&b.errors.rms))
            .expect("a study measures at least one setting")
    }
}

/// Every bake and basis measured under all four models (uniform weight): one row each.
fn model_rows(outcomes: &[Outcome]) -> Vec<ModelRow> {
    let mut rows = Vec::new();
    for o in outcomes.iter().filter(|o| {
        (o.setting.link, o.setting.uv) == MODELS[0] && o.setting.weight == Weight::Uniform
    }) {
        let same = |m: (Link, UvMap)| {
            outcomes.iter().find(|x| {
                x.setting
                    == Setting {
                        link: m.0,
                        uv: m.1,
                        ..o.setting.clone()
                    }
            })
        };
        let four: Vec<&Outcome> = MODELS.iter().filter_map(|&m| same(m)).collect();
        if four.len() < MODELS.len() {
            continue;
        }
        rows.push(ModelRow {
            setting: o.setting.clone(),
            rms: std::array::from_fn(|i| four[i].errors.rms),
            fit_s: std::array::from_fn(|i| four[i].fit_s),
            bake_s: o.bake_s,
        });
    }
    rows
}

/// Budgets spanning the measured range, one per half decade, each with the most accurate
/// setting within it.
fn recommendations(outcomes: &[Outcome]) -> Vec<Recommendation> {
    let (lo, hi) = outcomes.iter().fold((f64::MAX, 0f64), |(a, b), o| {
        (a.min(o.seconds()), b.max(o.seconds()))
    });
    let mut out = Vec::new();
    let mut budget = 10f64.powf((lo.log10() * 2.0).ceil() / 2.0);
    while budget <= hi * 1.5 {
        if let Some(best) = outcomes
            .iter()
            .filter(|o| o.seconds() <= budget)
            .min_by(|a, b| a.errors.rms.total_cmp(&b.errors.rms))
        {
            out.push(Recommendation {
                budget_s: budget,
                best: best.clone(),
            });
        }
        budget *= 10f64.sqrt();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(secs: f64, rms: f64) -> Outcome {
        Outcome {
            setting: Setting {
                dirs: 1,
                spp: 1,
                res: 1,
                basis: Basis::Ptm6,
                weight: Weight::Uniform,
                link: Link::Identity,
                uv: UvMap::Projected,
            },
            bake_s: secs,
            fit_s: 0.0,
            logistic: None,
            errors: Errors {
                rms,
                ..Default::default()
            },
        }
    }

    #[test]
    fn pareto_keeps_only_undominated_points() {
        let o = [
            outcome(1.0, 0.5),
            outcome(2.0, 0.6),
            outcome(3.0, 0.2),
            outcome(0.5, 0.9),
        ];
        assert_eq!(pareto(&o), vec![3, 0, 2]);
    }

    #[test]
    fn test_lights_are_unit_and_above_five_degrees() {
        let t = test_lights(40).unwrap();
        let train = dome::fibonacci(40, 5.0).unwrap();
        for (d, e) in t.dirs.iter().zip(&train.dirs) {
            assert!(((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 1.0).abs() < 1e-12);
            assert!(d[2] >= 5f64.to_radians().sin());
            assert!(
                (d[0] - e[0]).abs() + (d[1] - e[1]).abs() > 1e-3,
                "a test light is a training light"
            );
        }
    }
}
