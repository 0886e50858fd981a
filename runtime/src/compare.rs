//! `--compare-blur`: every blur method on the GPU against the CPU Monte Carlo ground truth, as
//! one table of errors (linear radiance) and GPU times.

use crate::scene::{Blur, Scene, SceneBuffers};
use crate::{gpu, reference, Gpu, Image, Result};

/// `scene` with `blur`, prepared and rendered on the GPU after a warm-up frame (first-use costs,
/// lavapipe's shader JIT among them, are not the method's): the renderer, the prepared scene,
/// and the seconds of one shading frame and of the setup passes (SAT, MIP chain, separable:
/// neither compiling nor uploading).
fn timed(g: &Gpu, scene: &Scene, blur: Blur) -> Result<(gpu::Renderer, SceneBuffers, f64, f64)> {
    let mut s = scene.clone();
    s.blur = blur;
    let p = s.prepare()?;
    let r = gpu::Renderer::new(g, &p)?;
    r.frame()?;
    let shade_s = r.frame()?;
    let setup_s = r
        .setup
        .passes
        .iter()
        .filter(|(n, _)| !matches!(*n, "compile" | "upload"))
        .fold(0.0, |a, (_, s)| a + s);
    Ok((r, p, shade_s, setup_s))
}

/// One method's row of the comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct BlurRow {
    /// The blur method's name (`explicit`, `sat`, `mip`, `separable`).
    pub method: &'static str,
    /// Largest |method − ground truth| over pixels and channels (linear radiance).
    pub max_abs_error: f32,
    /// Mean |method − ground truth| over pixels and channels.
    pub mean_abs_error: f32,
    /// Seconds of the shading pass (wall clock around submit + wait).
    pub shade_s: f64,
    /// Seconds of per-caster setup passes (SAT build, MIP chain, separable passes).
    pub setup_s: f64,
}

/// Mean |a − b| over pixels and rgb channels (linear radiance); the images must be the same size.
pub fn mean_abs_diff(a: &Image, b: &Image) -> f32 {
    let mut sum = 0f64;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            sum += (p[c] - q[c]).abs() as f64;
        }
    }
    (sum / (3 * a.pixels.len().max(1)) as f64) as f32
}

/// Renders `scene` with each blur method and compares with the Monte Carlo reference.
pub fn compare_blur(g: &Gpu, scene: &Scene, mc_samples: u32) -> Result<Vec<BlurRow>> {
    let reference = reference::render_reference(&scene.prepare()?, mc_samples);
    let mut rows = Vec::new();
    // Separable has no kernel for a turned rectangle: left out of the rows then.
    for blur in Blur::ALL
        .into_iter()
        .filter(|&b| b != Blur::Separable || !scene.turned_rect())
    {
        let (r, _, shade_s, setup_s) = timed(g, scene, blur)?;
        let img = r.readback()?;
        rows.push(BlurRow {
            method: blur.name(),
            max_abs_error: img.max_abs_diff(&reference).unwrap_or(f32::NAN),
            mean_abs_error: mean_abs_diff(&img, &reference),
            shade_s,
            setup_s,
        });
    }
    Ok(rows)
}

/// Renders glossy `scene` (it must have a caster and [`Scene::glossy`]) with each method that
/// has a kernel per pixel (explicit, sat, mip) and compares its reflected radiance (the CPU
/// twin's `cpu::render_reflection`, which the GPU matches to 6e-5 in `tests/gpu_twin.rs`; the
/// GPU image mixes it with the diffuse shade) with the ray-traced lobe
/// (`reference::render_reflection_reference`, `mc_samples` rays per pixel); the times are the
/// GPU frame's. The caster must not be downsampled (the reference reads its texels as given).
pub fn compare_reflection(g: &Gpu, scene: &Scene, mc_samples: u32) -> Result<Vec<BlurRow>> {
    let Some(c) = scene.caster.as_ref().filter(|_| scene.glossy.is_some()) else {
        return Err(crate::Error::Scene(
            "comparing reflections needs a glossy receiver and a caster".into(),
        ));
    };
    let p = scene.prepare()?;
    if p.caster_downsample != 1 {
        return Err(crate::Error::Scene(format!(
            "comparing reflections reads the caster's texels as given: use a caster of at most \
             the scene's texels (this one is downsampled {}×)",
            p.caster_downsample
        )));
    }
    let env = scene.glossy.as_ref().and_then(|g| g.environment.as_deref());
    let reference = reference::render_reflection_reference(&p, &c.rgba, env, mc_samples);
    let mut rows = Vec::new();
    for blur in [Blur::Explicit, Blur::Sat, Blur::Mip] {
        let (_, p, shade_s, setup_s) = timed(g, scene, blur)?;
        let got = crate::cpu::render_reflection(&p).expect("a glossy scene reflects");
        let (mut max, mut sum) = (0f32, 0f64);
        for (x, y) in got.iter().zip(&reference) {
            for k in 0..3 {
                let e = (x[k] - y[k]).abs();
                max = max.max(e);
                sum += e as f64;
            }
        }
        rows.push(BlurRow {
            method: blur.name(),
            max_abs_error: max,
            mean_abs_error: (sum / (3 * got.len().max(1)) as f64) as f32,
            shade_s,
            setup_s,
        });
    }
    Ok(rows)
}

/// A plain-text table of the rows.
pub fn table(rows: &[BlurRow]) -> String {
    let mut s = String::from("method      max |err|   mean |err|   shade ms   setup ms\n");
    for r in rows {
        s.push_str(&format!(
            "{:<10} {:>10.2e} {:>12.2e} {:>10.2} {:>10.2}\n",
            r.method,
            r.max_abs_error,
            r.mean_abs_error,
            1e3 * r.shade_s,
            1e3 * r.setup_s
        ));
    }
    s
}
