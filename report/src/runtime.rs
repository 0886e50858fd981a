//! The runtime side of the report: each `--blur` method's soft shadow against the Monte Carlo
//! ground truth beside its frame time, and the extreme cases of the penumbra map (R → 0,
//! d_ca → 0, d_lc → 0, a huge light, an 8192² caster through the summed-area table), each
//! measured against its analytic answer and against the CPU twin.
use ptm_runtime::penumbra::{caster_radius, half_plane_fraction};
use ptm_runtime::synthetic::{self, cloth, half_plane, leaves, STRIP_PIXELS};
use ptm_runtime::{compare, cpu, gpu, Blur, Gpu, Light, Scene};

use crate::{Error, Result};

/// The runtime part of the study, on one adapter.
#[derive(Clone, Debug)]
pub struct Runtime {
    /// The adapter, in words (`Gpu::describe`).
    pub adapter: String,
    /// One row per blur method against the Monte Carlo ground truth.
    pub blur: Vec<BlurRow>,
    /// One row per extreme case of the penumbra map.
    pub extremes: Vec<ExtremeRow>,
}

impl Runtime {
    /// Opens whatever adapter wgpu finds and measures the blur methods (a smaller image and
    /// fewer Monte Carlo samples when `quick`) and the extreme cases.
    pub fn run(quick: bool) -> Result<Runtime> {
        let gpu = Gpu::new().map_err(Error::NoAdapter)?;
        Ok(Runtime {
            adapter: gpu.describe(),
            blur: blur_methods(&gpu, quick)?,
            extremes: extremes(&gpu)?,
        })
    }
}

/// One blur method's soft shadow against the Monte Carlo ground truth.
#[derive(Clone, Debug)]
pub struct BlurRow {
    /// The spherical light's radius (a rectangle's longer half-side, a Gaussian's larger σ).
    pub light_radius: f32,
    /// A rectangular light's sides (None: a sphere); it asks the methods for the box kernel,
    /// a sphere for the disc.
    pub light_rect: Option<[f32; 2]>,
    /// A Gaussian light's standard deviations (None: a sphere or a rectangle); it asks for the
    /// Gaussian kernel.
    pub light_gaussian: Option<[f32; 2]>,
    /// The penumbra radius on the caster, texels (a rectangle's longer half-side, a
    /// Gaussian's larger σ).
    pub penumbra_texels: f64,
    /// A glossy receiver's reflection row (roughness, and the mean reflected radiance of the
    /// ray-traced reference): `measured` is then the reflected radiance's error against the
    /// ray-traced lobe (`compare::compare_reflection`), the light and penumbra fields unused
    /// (0).
    pub glossy: Option<(f32, f64)>,
    /// A reflection row whose background is a sky image (`synthetic::sky`, prefiltered for the
    /// lobe) rather than a colour.
    pub sky: bool,
    /// The method's errors against the ground truth and its pass times.
    pub measured: compare::BlurRow,
}

/// The 10–90 % width of an opacity profile on the cloth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProfileWidth {
    /// The case's analytic opacity is a constant: no width to speak of.
    Constant,
    /// No edge of the profile lies in view.
    NoEdgeInView,
    /// In cloth units.
    Width(f64),
}

/// One extreme case of the penumbra map, measured.
#[derive(Clone, Debug)]
pub struct ExtremeRow {
    /// The case in words.
    pub name: &'static str,
    /// What ptm does about it, in words.
    pub does: &'static str,
    /// The blur method rendered.
    pub blur: Blur,
    /// The caster was box-downsampled by this factor (1: not) to `caster_texels`.
    pub caster_downsample: usize,
    /// Caster texels (w, h) after downsampling.
    pub caster_texels: [u32; 2],
    /// Analytic and measured 10–90 % widths of the opacity profile along the strip.
    pub analytic_width: ProfileWidth,
    /// Measured 10–90 % width (beside `analytic_width`).
    pub measured_width: ProfileWidth,
    /// One caster texel's footprint on the cloth; None where the light lies on the caster
    /// plane.
    pub caster_texel_on_cloth: Option<f64>,
    /// Largest |opacity − analytic| along the strip (edge texels skipped).
    pub max_deviation: f64,
    /// Largest |GPU − CPU twin| over the image; None where the images do not compare.
    pub gpu_vs_twin: Option<f64>,
    /// Whether every pixel of the render is finite.
    pub all_finite: bool,
    /// Setup + shade passes, milliseconds.
    pub ms: f64,
}

fn light(position: [f32; 3], radius: f32) -> Light {
    Light {
        position,
        radius,
        rect: None,
        square_box: false,
        rect_angle_deg: 0.0,
        gaussian: None,
        distant: false,
        intensity: 4.0,
        color: [1.0; 3],
    }
}

/// Every blur method against the Monte Carlo soft shadow, for a small and a large sphere
/// (the disc kernel), two rectangles (the box kernel, aspects 4:1 and 1000:1) and two
/// Gaussians (the Gaussian kernel, round and 4:1).
pub fn blur_methods(g: &Gpu, quick: bool) -> Result<Vec<BlurRow>> {
    let (side, mc) = if quick { (96, 96) } else { (384, 512) };
    let mut rows = Vec::new();
    let caster_texels = 512;
    let spheres = [0.1f32, 0.5].map(|r| (r, None));
    let spheres = spheres.map(|(r, rect)| (r, rect, None));
    let rects = [[0.8f32, 0.2], [1.0, 0.001]].map(|r| (0.5 * r[0].max(r[1]), Some(r), None));
    let gaussians = [[0.2f32, 0.2], [0.4, 0.1]].map(|g| (g[0].max(g[1]), None, Some(g)));
    for (reach, rect, gaussian) in spheres.into_iter().chain(rects).chain(gaussians) {
        let mut s = Scene::over_ptm(cloth(32), 4, [side, side]);
        s.view = [-1.0, -1.0, 1.0, 1.0];
        let mut l = light([0.3, 0.2, 2.0], reach);
        l.rect = rect;
        l.gaussian = gaussian;
        s.lights = vec![l];
        s.caster = Some(leaves(caster_texels, [-1.5, -1.5, 1.5, 1.5], 0.6));
        let w = caster_radius(reach as f64, 2.0 - 0.6, 0.6) * caster_texels as f64 / 3.0;
        for measured in compare::compare_blur(g, &s, mc)? {
            rows.push(BlurRow {
                light_radius: reach,
                light_rect: rect,
                light_gaussian: gaussian,
                penumbra_texels: w,
                glossy: None,
                sky: false,
                measured,
            });
        }
    }
    rows.extend(reflections(g, quick)?);
    Ok(rows)
}

/// A glossy cloth's reflection of a leafy caster 0.4 above it, seen in perspective from the
/// front and above, at roughness 0.1, 0.25 and 0.5, over a background colour and over the
/// synthetic sky: each per-pixel method's reflected radiance against the ray-traced lobe (48²
/// and 1024 rays per pixel when `quick`, else 96² and 4096).
pub fn reflections(g: &Gpu, quick: bool) -> Result<Vec<BlurRow>> {
    let (side, mc) = if quick { (48, 1024) } else { (96, 4096) };
    let sky = std::sync::Arc::new(synthetic::sky());
    let mut rows = Vec::new();
    for with_sky in [false, true] {
        for roughness in [0.1f32, 0.25, 0.5] {
            let mut s = Scene::over_ptm(cloth(32), 4, [side, side]);
            s.view = [-1.0, -1.0, 1.0, 1.0];
            s.lights = vec![light([0.3, -0.2, 3.0], 0.2)];
            s.caster = Some(leaves(96, [-0.8, -0.8, 0.8, 0.8], 0.4));
            s.perspective = Some(ptm_runtime::scene::Perspective {
                eye: [0.0, -2.5, 2.0],
                target: [0.0, 0.0, 0.0],
                fov_y_deg: 50.0,
            });
            let env = with_sky.then(|| sky.clone());
            s.glossy = Some(ptm_runtime::Glossy {
                roughness,
                background: [0.2, 0.3, 0.5],
                f0: 0.3,
                environment: env.clone(),
            });
            let p = s.prepare()?;
            let c = s.caster.as_ref().expect("set above");
            let fine = ptm_runtime::reference::render_reflection_reference(
                &p,
                &c.rgba,
                env.as_deref(),
                mc,
            );
            let level =
                fine.iter().flatten().map(|&x| x as f64).sum::<f64>() / (3 * fine.len()) as f64;
            for measured in compare::compare_reflection(g, &s, mc)? {
                rows.push(BlurRow {
                    light_radius: 0.0,
                    light_rect: None,
                    light_gaussian: None,
                    penumbra_texels: 0.0,
                    glossy: Some((roughness, level)),
                    sky: with_sky,
                    measured,
                });
            }
        }
    }
    Ok(rows)
}

/// The half-plane profiles' strip under light `l`, blurred with `blur`, at albedo 0.8 (what its
/// tables have always been rendered at; opacity is a ratio of two renders, so albedo cancels).
fn strip(l: Light, blur: Blur) -> Scene {
    let mut s = synthetic::strip(l);
    s.albedo = [0.8; 3];
    s.blur = blur;
    s
}

/// 10 %–90 % width of a rising or falling profile sampled at `xs`, by linear interpolation.
fn width_10_90(xs: &[f64], o: &[f64]) -> f64 {
    let cross = |level: f64| {
        (1..o.len()).find_map(|i| {
            let (a, b) = (o[i - 1] - level, o[i] - level);
            (a.signum() != b.signum() || b == 0.0)
                .then(|| xs[i - 1] + (xs[i] - xs[i - 1]) * a / (a - b))
        })
    };
    match (cross(0.1), cross(0.9)) {
        (Some(a), Some(b)) => (b - a).abs(),
        _ => f64::NAN,
    }
}

struct Case {
    name: &'static str,
    does: &'static str,
    light: Light,
    blur: Blur,
    /// The half-plane caster: texels a side and height above the cloth (built per case, so
    /// the 8192² one is held only while it is measured).
    caster: (usize, f32),
    /// Analytic opacity at acceptor x (None: use the infinite half-plane formula).
    analytic: Option<f64>,
}

/// The extreme cases, each measured: analytic penumbra width on the acceptor against the
/// measured 10–90 % width, the largest deviation from the analytic opacity profile, the GPU
/// against its CPU twin, and whether every pixel is finite.
pub fn extremes(g: &Gpu) -> Result<Vec<ExtremeRow>> {
    let h = 0.5f32;
    let big = 8192;
    let cases = vec![
        Case {
            name: "reference: R = 0.5, d_lc = 1.5, d_ca = 0.5",
            does: "w = R·d_ca/(d_lc + d_ca) on the caster",
            light: light([0.0, 0.0, 2.0], 0.5),
            blur: Blur::Sat,
            caster: (512, h),
            analytic: None,
        },
        Case {
            name: "R = 0 (point light)",
            does: "w = 0: one caster lookup, a hard shadow",
            light: light([0.0, 0.0, 2.0], 0.0),
            blur: Blur::Sat,
            caster: (512, h),
            analytic: None,
        },
        Case {
            name: "R = 1e-6",
            does: "w far below a texel: every kernel sample falls in one texel, a hard shadow",
            light: light([0.0, 0.0, 2.0], 1e-6),
            blur: Blur::Explicit,
            caster: (512, h),
            analytic: None,
        },
        Case {
            name: "d_ca → 0 (caster 1e-6 above the cloth)",
            does: "w → 0: the shadow is the caster's own texels",
            light: light([0.0, 0.0, 2.0], 0.5),
            blur: Blur::Sat,
            caster: (512, 1e-6),
            analytic: None,
        },
        Case {
            name: "d_lc → 0 (light 1e-4 above the caster)",
            does: "every cloth point looks at the caster near the light's foot: w → R",
            light: light([0.02, 0.0, h + 1e-4], 0.05),
            blur: Blur::Sat,
            caster: (512, h),
            analytic: None,
        },
        Case {
            name: "d_lc = 0 (light on the caster plane)",
            does: "the caster cannot shadow the cloth: opacity 0",
            light: light([0.02, 0.0, h], 0.05),
            blur: Blur::Sat,
            caster: (512, h),
            analytic: Some(0.0),
        },
        Case {
            name: "huge light R = 1000",
            does: "the box holds the whole 8 × 8 caster: opacity = opaque area / box area",
            light: light([0.0, 0.0, 2.0], 1000.0),
            blur: Blur::Sat,
            caster: (512, h),
            analytic: Some(32.0 / (500.0f64 * 500.0)),
        },
        Case {
            name: "8192² caster through the SAT",
            does: "box-downsampled by 2 to ≤ 4096² (reported), u32 SAT sums exact",
            light: light([0.0, 0.0, 2.0], 0.5),
            blur: Blur::Sat,
            caster: (big, h),
            analytic: None,
        },
    ];
    let mut rows = Vec::new();
    for mut c in cases {
        // The SAT's cases keep the square box of half-side w (`Light::square_box`), whose
        // profile across the half-plane is the analytic ramp below; a sphere's own kernel, the
        // ellipse its cone cuts from the caster plane, is held to Monte Carlo instead
        // (`blur_methods`, runtime/tests/kernels.rs).
        c.light.square_box = c.blur != Blur::Explicit;
        let mut s = strip(c.light, c.blur);
        let free = gpu::render(g, &s.prepare()?)?.0;
        s.caster = Some(half_plane(c.caster.0, c.caster.0, c.caster.1));
        let p = s.prepare()?;
        let (lit, timings) = gpu::render(g, &p)?;
        let twin = cpu::render(&p);
        let finite = lit.pixels.iter().flatten().all(|v| v.is_finite());
        let [lx, _, lz] = c.light.position.map(f64::from);
        let (r, d_ca) = (c.light.radius as f64, p.frame.caster_height as f64);
        let d_lc = lz - d_ca;
        let w = caster_radius(r, d_lc, d_ca);
        // Where the ray from cloth point x to the light centre meets the caster plane.
        let caster_x = |x: f64| lx + (x - lx) * d_lc / lz;
        let xs: Vec<f64> = (0..STRIP_PIXELS)
            .map(|i| -1.0 + 2.0 * (i as f64 + 0.5) / STRIP_PIXELS as f64)
            .collect();
        let measured: Vec<f64> = (0..STRIP_PIXELS as usize)
            .map(|i| {
                let k = STRIP_PIXELS as usize + i;
                1.0 - (lit.pixels[k][0] / free.pixels[k][0]) as f64
            })
            .collect();
        let analytic: Vec<f64> = xs
            .iter()
            .map(|&x| {
                if let Some(a) = c.analytic {
                    return a;
                }
                // Signed distance of the caster-plane point into the occluder (x < 0).
                let cx = caster_x(x);
                match c.blur {
                    Blur::Explicit => half_plane_fraction(-cx, w),
                    _ if w <= 0.0 => half_plane_fraction(-cx, 0.0),
                    _ => ((-cx + w) / (2.0 * w)).clamp(0.0, 1.0),
                }
            })
            .collect();
        // Texels straddling the edge are averaged by the caster's resolution: skip the two
        // pixels whose footprint (on the caster) holds the edge texel.
        let texel = 8.0 / (p.plane.size[0] as f64);
        let max_dev = xs
            .iter()
            .zip(measured.iter().zip(&analytic))
            .filter(|(&x, _)| c.analytic.is_some() || caster_x(x).abs() > texel)
            .map(|(_, (m, a))| (m - a).abs())
            .fold(0f64, f64::max);
        // A profile without an edge in view (constant) has no width.
        let width = |w: f64| {
            if c.analytic.is_some() {
                ProfileWidth::Constant
            } else if w.is_nan() {
                ProfileWidth::NoEdgeInView
            } else {
                ProfileWidth::Width(w)
            }
        };
        let ms = timings
            .passes
            .iter()
            .filter(|(n, _)| !matches!(*n, "compile" | "readback"))
            .fold(0.0, |a, (_, s)| a + s)
            * 1e3;
        rows.push(ExtremeRow {
            name: c.name,
            does: c.does,
            blur: c.blur,
            caster_downsample: p.caster_downsample,
            caster_texels: p.plane.size,
            analytic_width: width(width_10_90(&xs, &analytic)),
            measured_width: width(width_10_90(&xs, &measured)),
            caster_texel_on_cloth: (d_lc > 0.0).then(|| texel * lz / d_lc),
            max_deviation: max_dev,
            gpu_vs_twin: lit.max_abs_diff(&twin).map(f64::from),
            all_finite: finite,
            ms,
        });
    }
    Ok(rows)
}
