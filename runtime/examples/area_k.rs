//! K under an area light against Monte Carlo (#22): one built-in swatch baked once (RES², spp 8,
//! 256 Fibonacci lights above 5°) and fitted as logistic ptm11 and learned11 over the
//! hemispherical map (cached in the temp dir), then for 12 × 12 texels, 4 azimuths, spheres and
//! rectangles of angular radius ρ at elevations from 80° to 2°: the RMS | max of K − the
//! cosine-weighted Monte Carlo mean of `Ptm::eval_dir` over the light (1024 stratified
//! directions), for
//! - `centre`: K at the light's centre (what the renderer did before);
//! - `footprint`: the renderer's `ptm_k_area` (the twin), σ(m/√(1 + π·v/8));
//! - `semi3`: the same mean m and variance v through a 3-point rule (m, m ± √(2v); ½, ¼, ¼);
//! - `no-var`: σ(m), the mean predictor alone;
//! - `ideal-mean`: σ of the exact mean predictor over the light (the best a prefiltered MIP of
//!   the table can do when σ is applied to the filtered predictor);
//! - `ideal+var`: that exact mean with the jet's variance (a bound for a MIP plus the variance).
//!
//! `cargo run -p ptm-runtime --example area_k [-- SWATCH RES SHAPES]` (default jersey 48
//! sphere; SHAPES a comma list of sphere, rect (square) and long (4:1)); run the built binary
//! with `LD_LIBRARY_PATH=.deps/embree/lib` when cargo does not find Embree.

use std::f64::consts::PI;
use std::time::Instant;

use ptm_bake::{dome, BakeConfig, PreparedMesh};
use ptm_fit::{Accumulator, FitOptions};
use ptm_format::hash::{splitmix64 as hash, unit_f64 as unit};
use ptm_format::{Basis, Link, Ptm, UvMap};
use rayon::prelude::*;

fn fit(swatch_name: &str, res: usize) -> Vec<Ptm> {
    let dir = std::env::temp_dir().join(format!("area_k_{swatch_name}_{res}"));
    let names = ["ptm11", "learned11"];
    if names
        .iter()
        .all(|n| dir.join(format!("{n}.ptm.exr")).exists())
    {
        return names
            .iter()
            .map(|n| ptm_format::layout::load(&dir.join(format!("{n}.ptm.exr"))).unwrap())
            .collect();
    }
    std::fs::create_dir_all(&dir).unwrap();
    let swatch = PreparedMesh::load(&format!("builtin:{swatch_name}"), None).unwrap();
    let lights = dome::fibonacci(256, 5.0).unwrap();
    let cfg = BakeConfig {
        res: [res, res],
        spp: 8,
        seed: 1,
        light_distance: None,
        packets: true,
        threads: 0,
    };
    let (planes, coverage, _) = ptm_bake::bake_planes(&swatch, &lights, &cfg).unwrap();
    let mut out = Vec::new();
    for basis in [Basis::Ptm11, Basis::Learned(11)] {
        let opts = FitOptions {
            link: Link::Logistic,
            uv: UvMap::Hemispherical,
            mips: false,
            ..FitOptions::new(basis)
        };
        let mut acc = Accumulator::new(&lights, res, res, &opts).unwrap();
        acc.set_spp(8).unwrap();
        acc.set_coverage(&coverage).unwrap();
        for (i, k) in planes.k.iter().enumerate() {
            acc.add_light(i, k).unwrap();
        }
        let (ptm, _) = acc.finish(swatch.tile).unwrap();
        ptm.save(
            &dir.join(format!("{}.ptm.exr", basis.name())),
            &Default::default(),
        )
        .unwrap();
        out.push(ptm);
    }
    out
}

/// The predictor p(u, v) of texel coefficients `c` (before the link).
fn predictor(ptm: &Ptm, c: &[f64], u: f64, v: f64) -> f64 {
    if let Some(t) = &ptm.learned {
        let mut b = [0f64; 16];
        t.terms(u, v, &mut b[..t.terms]);
        return (0..t.terms).map(|k| c[k] * b[k]).sum();
    }
    let cf: Vec<f32> = c.iter().map(|&x| x as f32).collect();
    ptm.basis.eval(&cf, u as f32, v as f32) as f64
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The mean of σ(X) for X of mean m and variance v: the 3-point rule exact for the semicircle
/// law (`semi3`) or MacKay's probit approximation (`probit`, the renderer's).
fn rule(name: &str, m: f64, v: f64) -> f64 {
    let sd = v.max(0.0).sqrt();
    match name {
        "semi3" => {
            let a = 2f64.sqrt() * sd;
            0.5 * sigmoid(m) + 0.25 * (sigmoid(m + a) + sigmoid(m - a))
        }
        "probit" => sigmoid(m / (1.0 + PI * v / 8.0).sqrt()),
        _ => unreachable!(),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let swatch = args.first().map_or("jersey", String::as_str);
    let res: usize = args.get(1).map_or(48, |s| s.parse().unwrap());
    let t = Instant::now();
    let ptms = fit(swatch, res);
    println!("fit/load {:.1} s", t.elapsed().as_secs_f64());
    let step = (res / 12).max(1);
    let texels: Vec<(usize, usize)> = (0..res)
        .step_by(step)
        .flat_map(|y| (0..res).step_by(step).map(move |x| (x, y)))
        .collect();
    let methods = [
        "centre",
        "footprint",
        "semi3",
        "no-var",
        "ideal-mean",
        "ideal+var",
    ];
    let shapes: Vec<&str> = args
        .get(2)
        .map_or(vec!["sphere"], |s| s.split(',').collect());
    for ptm in &ptms {
        let bufs = ptm_runtime::Scene::over_ptm(ptm.clone(), 1, [res as u32, res as u32])
            .prepare()
            .unwrap();
        let twin = ptm_runtime::cpu::shade::Twin {
            p: &bufs,
            blur: None,
            opacity: None,
        };
        let twin = &twin;
        for &shape in &shapes {
            println!(
                "\n== {} {shape} ({} texels, 4 azimuths) RMS | max of K̄ − MC",
                ptm.basis.name(),
                texels.len()
            );
            print!("{:>6} {:>5}", "rho", "elev");
            for m in methods {
                print!(" {m:>15}");
            }
            println!(" {:>8}", "mc spread");
            for rho in [0.02f64, 0.08, 0.25, 0.6] {
                for elev in [80.0f64, 45.0, 20.0, 10.0, 5.0, 2.0] {
                    let rows: Vec<(Vec<f64>, f64)> = texels
                        .par_iter()
                        .flat_map_iter(|&(x, y)| {
                            (0..4).map(move |a| {
                                let az = 0.4 + 1.57 * a as f64;
                                let e = elev.to_radians();
                                let l0 = [e.cos() * az.cos(), e.cos() * az.sin(), e.sin()];
                                let c: Vec<f64> =
                                    ptm.coeffs(x, y).iter().map(|&v| v as f64).collect();
                                let helper = [0.0, 0.0, 1.0];
                                let e1 = ptm_format::vec3::normalize(ptm_format::vec3::cross(
                                    helper, l0,
                                ));
                                let e2 = ptm_format::vec3::cross(l0, e1);
                                let cos_max = rho.cos();
                                let half = match shape {
                                    "rect" => [rho.tan(), rho.tan()],
                                    _ => [2.0 * rho.tan(), 0.5 * rho.tan()],
                                };
                                let strata = 32;
                                let (mut sw, mut sk, mut sp) = (0.0, 0.0, 0.0);
                                let key = (x * 1000 + y) as u64 * 7 + a;
                                for s in 0..strata * strata {
                                    let hs = hash(key.wrapping_mul(0x1000_0001).wrapping_add(s));
                                    let u1 = ((s % strata) as f64 + unit(hs)) / strata as f64;
                                    let u2 = ((s / strata) as f64 + unit(hash(hs))) / strata as f64;
                                    let (d, wgt) = if shape == "sphere" {
                                        let ct = 1.0 - u1 * (1.0 - cos_max);
                                        let st = (1.0 - ct * ct).max(0.0).sqrt();
                                        let ph = 2.0 * PI * u2;
                                        let d: [f64; 3] = std::array::from_fn(|k| {
                                            l0[k] * ct + (e1[k] * ph.cos() + e2[k] * ph.sin()) * st
                                        });
                                        (d, d[2])
                                    } else {
                                        let q = [
                                            l0[0] + (2.0 * u1 - 1.0) * half[0],
                                            l0[1] + (2.0 * u2 - 1.0) * half[1],
                                            l0[2],
                                        ];
                                        let r2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
                                        let r = r2.sqrt();
                                        (q.map(|x| x / r), q[2] * q[2] / (r2 * r2))
                                    };
                                    if d[2] <= 0.0 {
                                        continue;
                                    }
                                    let (u, v) = ptm.uv.of_dir(d);
                                    sw += wgt;
                                    sk += wgt * ptm.eval_dir(x, y, d) as f64;
                                    sp += wgt * predictor(ptm, &c, u, v);
                                }
                                let mc = sk / sw;
                                let pbar = sp / sw;
                                // The twin, as the shader: a light at distance 2 from the texel centre.
                                let pos = [
                                    ((x as f64 + 0.5) / res as f64 * ptm.tile[0]) as f32,
                                    ((1.0 - (y as f64 + 0.5) / res as f64) * ptm.tile[1]) as f32,
                                ];
                                let dist = 2.0;
                                let light = ptm_runtime::layout::LightGpu {
                                    position: [
                                        pos[0] + (dist * l0[0]) as f32,
                                        pos[1] + (dist * l0[1]) as f32,
                                        (dist * l0[2]) as f32,
                                    ],
                                    radius: if shape == "sphere" {
                                        (dist * rho.sin()) as f32
                                    } else {
                                        0.0
                                    },
                                    color: [1.0; 3],
                                    shape: u32::from(shape != "sphere"),
                                    half: if shape == "sphere" {
                                        [0.0; 2]
                                    } else {
                                        half.map(|h| (h * dist) as f32)
                                    },
                                    axis: [1.0, 0.0],
                                };
                                let cf = twin.ptm_coeffs(pos, 0.0);
                                let to_light = [
                                    light.position[0] - pos[0],
                                    light.position[1] - pos[1],
                                    light.position[2],
                                ];
                                let dd = (to_light.iter().map(|v| v * v).sum::<f32>()).sqrt();
                                let lf = to_light.map(|v| v / dd);
                                let f = twin.ptm_footprint(lf, to_light, dd, &light);
                                let j = twin.ptm_jet(&cf, f.centre);
                                let cv = f.cov.map(|v| v as f64);
                                let (p, g, h) =
                                    (j.p as f64, j.g.map(|v| v as f64), j.h.map(|v| v as f64));
                                let var = g[0] * g[0] * cv[0]
                                    + 2.0 * g[0] * g[1] * cv[1]
                                    + g[1] * g[1] * cv[2];
                                let m =
                                    p + 0.5 * (h[0] * cv[0] + 2.0 * h[1] * cv[1] + h[2] * cv[2]);
                                let centre = twin.ptm_k(&cf, lf) as f64;
                                let area = twin.ptm_k_area(&cf, lf, &f) as f64;
                                let out: Vec<f64> = methods
                                    .iter()
                                    .map(|&name| match name {
                                        "centre" => centre,
                                        "footprint" => area,
                                        "semi3" => rule("semi3", m, var),
                                        "no-var" => sigmoid(m),
                                        "ideal-mean" => sigmoid(pbar),
                                        "ideal+var" => rule("probit", pbar, var),
                                        _ => unreachable!(),
                                    })
                                    .map(|k| k - mc)
                                    .collect();
                                (out, mc)
                            })
                        })
                        .collect();
                    print!("{rho:>6} {elev:>5}");
                    for (i, _) in methods.iter().enumerate() {
                        let n = rows.len() as f64;
                        let rms = (rows.iter().map(|r| r.0[i] * r.0[i]).sum::<f64>() / n).sqrt();
                        let max = rows.iter().map(|r| r.0[i].abs()).fold(0.0, f64::max);
                        print!(" {:>7.4}|{:<7.4}", rms, max);
                    }
                    let lo = rows.iter().map(|r| r.1).fold(1.0, f64::min);
                    let hi = rows.iter().map(|r| r.1).fold(0.0, f64::max);
                    println!(" {:>4.2}-{:<4.2}", lo, hi);
                }
            }
        }
    }
}
