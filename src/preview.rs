//! `ptm preview`: headless render of the swatch plane under spherical area lights, radiance
//! multiplied by (1 − K) from an occlusion PTM and by a penumbra-map shadow of a planar caster.
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_format::atomic::Transaction;
use ptm_format::exrio::{self, Samples};
use ptm_runtime::scene::{Perspective, SceneBuffers};
use ptm_runtime::{compare, cpu, gpu, output, Blur, Caster, Gpu, Image, Light, Scene};

use crate::args::{choice, parse_triple};
use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// Occlusion PTM (`ptm fit` output) in either layout: NAME.ptm.exr, or the renderer layout's
    /// NAME.ptm.c0.exr (NAME.ptm.exr when only its parts exist). Without it, no K.
    #[arg(long)]
    pub ptm: Option<PathBuf>,
    /// Output sRGB PNG (not with --window).
    #[arg(short, long, required_unless_present = "window")]
    pub output: Option<PathBuf>,
    /// Also write the linear radiance as an RGB float EXR.
    #[arg(long)]
    pub exr: Option<PathBuf>,
    /// Output size W,H in pixels. Default: 512 along the longer side of the tiles shown
    /// (--repeat), the other side in proportion, so that the cloth's texels stay square. A
    /// size of another aspect shows more cloth along one side (`--json`'s `tiles` says how much).
    #[arg(long, value_parser = parse_pair::<u32>)]
    pub size: Option<(u32, u32)>,
    /// Light centre x,y,z in swatch units (z above the cloth); repeat for several lights.
    /// Default: one light at 37° elevation, up and to the left, far enough (3.3 view widths) for
    /// the lighting to stay even across the view, low enough for the weave to shadow itself.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub light: Vec<[f32; 3]>,
    /// Sphere radius per light (the last value repeats for further lights). Default: 5% of
    /// the view's longer side.
    #[arg(long)]
    pub light_radius: Vec<f32>,
    /// Make the lights rectangles: sides A,B along X and Y in swatch units, facing straight
    /// down, or with a third value side A turned DEG degrees from X towards Y (the last value
    /// repeats for further lights), instead of spheres of --light-radius. The penumbra is the
    /// rectangle's own kernel, of any aspect ratio: a box (exact with --blur sat and explicit),
    /// turned a parallelogram on the caster averaged as six boxes (not with --blur separable).
    #[arg(long, value_name = "A,B[,DEG]", value_parser = parse_rect)]
    pub light_rect: Vec<(f32, f32, f32)>,
    /// Make the lights Gaussians facing straight down: intensity falling off from the light's
    /// position with standard deviations SX along X and SY along Y in swatch units (the last
    /// value repeats for further lights), instead of spheres of --light-radius. The penumbra is
    /// that Gaussian (sat: three boxes per axis from the table; explicit: exactly; mip: the
    /// ellipse of the same variance; separable: the box of the same variance).
    #[arg(long, value_name = "SX,SY", value_parser = parse_pair::<f32>)]
    pub light_gaussian: Vec<(f32, f32)>,
    /// A distant light (the sun): ELEV degrees above the cloth, AZ degrees from +X towards +Y,
    /// an angular RADIUS in degrees (default 0.27, the sun's; 0 a hard shadow; at most 45);
    /// repeat for several. Its direction is the same at every point, and so is K's footprint:
    /// the PTM's basis (monomials or learned tables) is evaluated once per frame and each
    /// pixel only dots it with its coefficients. Irradiance on a surface facing it: I ·
    /// colour. Numbered after the --light lights for --intensity and --color. On a --mesh its
    /// direction turns with the surface, so K is evaluated per pixel, and the macro shadow's
    /// map is orthographic along it. Not with --window.
    #[arg(long, value_name = "ELEV,AZ[,RADIUS]", value_parser = parse_distant, allow_hyphen_values = true)]
    pub light_distant: Vec<(f32, f32, f32)>,
    /// Intensity per light (last repeats): irradiance = I · colour · cos/d². Default: chosen
    /// so the first light gives irradiance 0.8 at the view's centre (headroom below white).
    #[arg(long)]
    pub intensity: Vec<f32>,
    /// Linear RGB colour per light (last repeats).
    #[arg(long, value_parser = parse_triple)]
    pub color: Vec<[f32; 3]>,
    /// Tiles of the PTM shown: N (N across and N down, whatever the tile's aspect) or X,Y.
    #[arg(long, value_name = "N|X,Y", value_parser = parse_repeat, default_value = "2")]
    pub repeat: (u32, u32),
    /// Constant linear albedo r,g,b.
    #[arg(long, value_parser = parse_triple, default_value = "0.8,0.8,0.8")]
    pub albedo: [f32; 3],
    /// Albedo texture (sRGB PNG), tiled with the PTM.
    #[arg(long)]
    pub albedo_texture: Option<PathBuf>,
    /// Planar RGBA caster image (alpha = opacity), parallel to the cloth, or `builtin:leaves`
    /// (a generated 256² cut-out of leaves). Its default placement scales with the view.
    #[arg(long)]
    pub caster: Option<PathBuf>,
    /// Caster height above the cloth (swatch units). Default: an eighth of the view's longer
    /// side (0.5 over the default 2×2 tiles of a 2×2 swatch).
    #[arg(long)]
    pub caster_height: Option<f32>,
    /// Tilt of the caster in degrees about its centre line parallel to X (positive lifts its far,
    /// +Y edge); the whole caster must stay above the cloth. Not with --blur separable.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub caster_tilt: f32,
    /// Caster size w,h in swatch units. Default: half the view.
    #[arg(long, value_parser = parse_pair::<f32>)]
    pub caster_size: Option<(f32, f32)>,
    /// Caster centre x,y in swatch units. Default: the view's centre.
    #[arg(long, value_parser = parse_pair::<f32>, allow_hyphen_values = true)]
    pub caster_center: Option<(f32, f32)>,
    /// The caster's RGB transmits coloured light (stained glass).
    #[arg(long)]
    pub colored_shadow: bool,
    /// How the caster opacity is averaged over the penumbra kernel.
    #[arg(long, value_parser = choice::<Blur>(), default_value = "sat")]
    pub blur: Blur,
    /// Make the cloth glossy: it also reflects the caster (each texel's colour and opacity)
    /// over --background (or --background-image), blurred by a lobe that is a cone of half-angle
    /// ROUGHNESS × 45° around the mirror direction (0 a mirror, at most 1), so the reflection
    /// blurs with the distance to the caster. The pixel is (1 − F)·diffuse + F·reflection with
    /// Schlick's F of --reflectance. Needs --caster; --blur sat, mip or explicit.
    #[arg(long, value_name = "ROUGHNESS")]
    pub glossy: Option<f32>,
    /// Linear RGB radiance a --glossy cloth reflects where its lobe misses the caster.
    #[arg(long, value_name = "R,G,B", value_parser = parse_triple, default_value = "0.2,0.25,0.35")]
    pub background: [f32; 3],
    /// A sky a --glossy cloth reflects instead of the --background colour: a lat-long
    /// (equirectangular) image, OpenEXR (linear RGB) or PNG/JPEG (sRGB), or `builtin:sky`;
    /// row 0 is the zenith, the centre column looks along +X, and only its upper half (the
    /// sky) is reflected, averaged over the lobe's cone.
    #[arg(long, value_name = "FILE")]
    pub background_image: Option<PathBuf>,
    /// Reflectance F0 of a --glossy cloth at normal incidence (Schlick's Fresnel), 0 to 1.
    #[arg(long, value_name = "F0", default_value_t = 0.3)]
    pub reflectance: f32,
    /// Exposure of the PNG in stops (linear × 2^E before sRGB encoding).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Perspective camera eye x,y,z (default: orthographic top view of the tiles).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub camera: Option<[f32; 3]>,
    /// Point the perspective camera looks at (default: the view's centre on the cloth).
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub look_at: Option<[f32; 3]>,
    /// Vertical field of view of the perspective camera, degrees.
    #[arg(long, default_value_t = 45.0)]
    pub fov: f32,
    /// Render N light azimuths (lights turned about the view's centre by 360°/N each) into a
    /// sheet: frames in a grid that fits N (8: 4×2), each under its azimuth label, with grey
    /// gutters between them.
    #[arg(long, value_name = "N")]
    pub turntable: Option<u32>,
    /// Render with every blur method and the CPU Monte Carlo ground truth; print the error and
    /// GPU time of each method (needs --caster). With --glossy: the reflected radiance of sat,
    /// mip and explicit against a ray-traced lobe (--mc-samples rays per pixel).
    #[arg(long)]
    pub compare_blur: bool,
    /// Monte Carlo samples per pixel and light for --compare-blur.
    #[arg(long, default_value_t = 256)]
    pub mc_samples: u32,
    /// Interactive window instead of a PNG: drag to move the first light, keys 1-4 or B pick
    /// the blur method, P toggles the PTM, `[` and `]` lower and raise the --glossy roughness by
    /// 0.05, Esc quits; on a --mesh, right-drag or the arrow keys
    /// orbit the camera (needs a build with `--features window`).
    #[arg(long, conflicts_with_all = ["output", "exr", "turntable", "compare_blur", "sheet"])]
    pub window: bool,
    /// Smoke test of --window: script N frames (every blur method, PTM off/on, a light move),
    /// then close.
    #[arg(long, value_name = "N", requires = "window", hide = true)]
    pub window_frames: Option<u32>,
    /// The mesh path's flags (`--mesh` and what goes with it).
    #[command(flatten)]
    pub garment: crate::garment::MeshArgs,
}

/// `A,B` or `A,B,DEG` (DEG 0 when left out).
fn parse_rect(s: &str) -> Result<(f32, f32, f32), String> {
    parse_two_or_three(
        s,
        0.0,
        "A,B or A,B,DEG (sides, and the turn of side A from X in degrees)",
    )
}

/// `ELEV,AZ` or `ELEV,AZ,RADIUS` (the sun's radius when left out).
fn parse_distant(s: &str) -> Result<(f32, f32, f32), String> {
    parse_two_or_three(
        s,
        SUN_RADIUS_DEG,
        "ELEV,AZ or ELEV,AZ,RADIUS (degrees: elevation above the cloth, azimuth from +X \
         towards +Y, angular radius)",
    )
}

/// Two or three comma-separated numbers, the third `third` when left out; an error names a
/// part that is not a number, or says `expected` for another count.
fn parse_two_or_three(s: &str, third: f32, expected: &str) -> Result<(f32, f32, f32), String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f32>()
                .map_err(|_| format!("`{x}` is not a number"))
        })
        .collect::<Result<_, _>>()?;
    match parts[..] {
        [a, b] => Ok((a, b, third)),
        [a, b, c] => Ok((a, b, c)),
        _ => Err(format!("expected {expected}, got `{s}`")),
    }
}

/// The sun's angular radius, degrees: `--light-distant`'s default.
const SUN_RADIUS_DEG: f32 = 0.27;

fn parse_pair<T: std::str::FromStr>(s: &str) -> Result<(T, T), String> {
    let parts: Vec<&str> = s.split(',').collect();
    match parts[..] {
        [a, b] => Ok((
            a.trim()
                .parse()
                .map_err(|_| format!("`{a}` is not a number"))?,
            b.trim()
                .parse()
                .map_err(|_| format!("`{b}` is not a number"))?,
        )),
        _ => Err(format!("expected two comma-separated numbers, got `{s}`")),
    }
}

fn parse_repeat(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = match s.split_once(',') {
        None => {
            let n = s
                .trim()
                .parse()
                .map_err(|_| format!("`{s}` is not a whole number"))?;
            (n, n)
        }
        Some(_) => parse_pair::<u32>(s)?,
    };
    if x == 0 || y == 0 {
        return Err(format!("`{s}`: at least 1 tile each way"));
    }
    Ok((x, y))
}

/// The output size: `--size`, or 512 pixels along the longer side of `view` (x0, y0, x1, y1)
/// and the other side in proportion (at least 1).
fn output_size(args: &Args, view: [f32; 4]) -> [u32; 2] {
    if let Some((w, h)) = args.size {
        return [w, h];
    }
    let (vw, vh) = (view[2] - view[0], view[3] - view[1]);
    let side = |a: f32, b: f32| ((512.0 * a / b).round() as u32).clamp(1, 512);
    if vw >= vh {
        [512, side(vh, vw)]
    } else {
        [side(vw, vh), 512]
    }
}

/// The flags the mesh path shares with the plane's.
fn view_of(args: &Args) -> crate::garment::View<'_> {
    crate::garment::View {
        ptm: args.ptm.as_deref(),
        repeat: args.repeat,
        albedo: args.albedo,
        size: args.size,
        fov: args.fov,
        camera: args.camera,
        look_at: args.look_at,
        light: &args.light,
        light_radius: &args.light_radius,
        light_distant: &args.light_distant,
        intensity: &args.intensity,
        color: &args.color,
    }
}

/// The value for light `i` from a repeatable option (the last one repeats).
fn nth<T: Copy>(v: &[T], i: usize, default: T) -> T {
    v.get(i).or(v.last()).copied().unwrap_or(default)
}

/// The scene the flags describe: the PTM (or plain cloth) tiled `--repeat` times (X across, Y
/// down), the output size (`--size`, or square pixels on those tiles), the view at the
/// output's aspect, albedo, lights (one default light when none is given), the caster and the
/// camera.
fn build_scene(args: &Args) -> anyhow::Result<Scene> {
    let (rx, ry) = args.repeat;
    let mut scene = match &args.ptm {
        Some(path) => {
            // Either layout (`ptm fit --layout rgba`'s parts, named by any part or the stem).
            // Its errors name the file.
            let ptm = ptm_format::layout::load(path)?;
            // What the renderer requires of it beyond the format (a learned basis's table
            // among it), said of the file here rather than of the scene later.
            ptm_runtime::scene::check_ptm(&ptm)
                .with_context(|| crate::outputs::Named::new("reading", path))?;
            Scene::over_ptm(ptm, 1, [1, 1])
        }
        None => Scene::without_ptm(),
    };
    // As `Scene::over_ptm` lays out its view, in f64 then rounded once.
    let tile = scene.ptm.as_ref().map_or([1.0, 1.0], |p| p.tile);
    scene.view[2] = (tile[0] * rx as f64) as f32;
    scene.view[3] = (tile[1] * ry as f64) as f32;
    let size = output_size(args, scene.view);
    scene.size = size;
    // A non-square output shows a non-square patch with square pixels, widened (never cropped)
    // along one side from the tiles asked for.
    let aspect = size[0] as f32 / size[1] as f32;
    let view_aspect = (scene.view[2] - scene.view[0]) / (scene.view[3] - scene.view[1]);
    if aspect > view_aspect {
        scene.view[2] = scene.view[0] + (scene.view[3] - scene.view[1]) * aspect;
    } else {
        scene.view[3] = scene.view[1] + (scene.view[2] - scene.view[0]) / aspect;
    }
    if args.albedo.iter().any(|c| !(c.is_finite() && *c >= 0.0)) {
        bail!(
            "--albedo {:?}: each of r,g,b must be a finite number ≥ 0 (linear reflectance)",
            args.albedo
        );
    }
    scene.albedo = args.albedo;
    if let Some(path) = &args.albedo_texture {
        check_image_size(path, "--albedo-texture")?;
        let (w, h, texels) = output::read_rgba8(path)?;
        let lin = texels
            .iter()
            .map(|p| [0, 1, 2].map(|c| output::srgb_decode(p[c] as f32 / 255.0)))
            .collect();
        scene.albedo_texture = Some((w, h, lin));
    }

    let extent = (scene.view[2] - scene.view[0]).max(scene.view[3] - scene.view[1]);
    let centre = [
        0.5 * (scene.view[0] + scene.view[2]),
        0.5 * (scene.view[1] + scene.view[3]),
    ];
    let positions = if args.light.is_empty() && !args.light_distant.is_empty() {
        Vec::new()
    } else if args.light.is_empty() {
        vec![[
            centre[0] - 2.4 * extent,
            centre[1] + 1.2 * extent,
            2.0 * extent,
        ]]
    } else {
        args.light.clone()
    };
    scene.lights = positions
        .iter()
        .enumerate()
        .map(|(i, &position)| {
            let d = [
                position[0] - centre[0],
                position[1] - centre[1],
                position[2],
            ];
            let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            let cos = (d[2] / d2.sqrt()).max(0.05);
            Light {
                position,
                radius: nth(&args.light_radius, i, 0.05 * extent),
                rect: (!args.light_rect.is_empty())
                    .then(|| nth(&args.light_rect, i, (0.0, 0.0, 0.0)))
                    .map(|(a, b, _)| [a, b]),
                square_box: false,
                rect_angle_deg: nth(&args.light_rect, i, (0.0, 0.0, 0.0)).2,
                gaussian: (!args.light_gaussian.is_empty())
                    .then(|| nth(&args.light_gaussian, i, (0.0, 0.0)))
                    .map(|(a, b)| [a, b]),
                distant: false,
                intensity: nth(&args.intensity, i, 0.8 * d2 / cos),
                color: nth(&args.color, i, [1.0, 1.0, 1.0]),
            }
        })
        .collect();
    let local = scene.lights.len();
    scene.lights.extend(crate::garment::distant_lights(
        &view_of(args),
        local,
        |sin_e| {
            // Irradiance 0.8 on the cloth (headroom below white), as the default light's.
            0.8 / sin_e.max(0.05)
        },
    ));

    if let Some(path) = &args.caster {
        let (w, h, rgba) = match builtin_caster(path)? {
            Some(c) => c,
            None => {
                check_image_size(path, "--caster")?;
                output::read_rgba8(path)?
            }
        };
        let (cw, ch) = args.caster_size.unwrap_or((
            0.5 * (scene.view[2] - scene.view[0]),
            0.5 * (scene.view[3] - scene.view[1]),
        ));
        let (cx, cy) = args.caster_center.unwrap_or((centre[0], centre[1]));
        scene.caster = Some(Caster {
            width: w,
            height: h,
            rgba,
            rect: [cx - 0.5 * cw, cy - 0.5 * ch, cx + 0.5 * cw, cy + 0.5 * ch],
            elevation: args.caster_height.unwrap_or(0.125 * extent),
            tilt_deg: args.caster_tilt,
        });
    }
    scene.colored_shadow = args.colored_shadow;
    scene.blur = args.blur;
    let environment = match (&args.background_image, args.glossy) {
        (Some(path), Some(_)) => Some(std::sync::Arc::new(background_image(path)?)),
        _ => None,
    };
    scene.glossy = args.glossy.map(|roughness| ptm_runtime::Glossy {
        roughness,
        background: args.background,
        f0: args.reflectance,
        environment,
    });
    if let Some(eye) = args.camera.filter(|_| args.garment.mesh.is_none()) {
        if !(eye.iter().all(|c| c.is_finite()) && eye[2] > 0.0) {
            bail!(
                "--camera {eye:?}: the eye must be finite and above the cloth (z > 0; the cloth \
                 is the plane z = 0, seen from above)"
            );
        }
        scene.perspective = Some(Perspective {
            eye,
            target: args.look_at.unwrap_or([centre[0], centre[1], 0.0]),
            fov_y_deg: args.fov,
        });
    }
    Ok(scene)
}

/// An 8-bit RGBA image: width, height, texels.
type Rgba8 = (usize, usize, Vec<[u8; 4]>);

/// The casters `--caster builtin:NAME` names: `leaves` (256², 60 translucent green discs).
/// `None` for a file.
fn builtin_caster(path: &Path) -> anyhow::Result<Option<Rgba8>> {
    let Some(name) = path.to_str().and_then(|s| s.strip_prefix("builtin:")) else {
        return Ok(None);
    };
    match name {
        "leaves" => {
            let c = ptm_runtime::synthetic::leaves(256, [0.0; 4], 0.0);
            Ok(Some((c.width, c.height, c.rgba)))
        }
        _ => bail!("--caster builtin:{name}: unknown builtin caster; there is builtin:leaves"),
    }
}

/// `--background-image`: a lat-long file, or `builtin:sky` (`synthetic::sky_latlong` at
/// 512 × 256: a blue gradient, cloud banks, a sun 35° up at azimuth 40°).
fn background_image(path: &Path) -> anyhow::Result<ptm_runtime::environment::Environment> {
    use ptm_runtime::environment::Environment;
    let flag = || format!("--background-image {}", path.display());
    match path.to_str().and_then(|s| s.strip_prefix("builtin:")) {
        Some("sky") => {
            let (w, h) = (512, 256);
            let sky = ptm_runtime::synthetic::sky_latlong(w, h);
            Ok(Environment::from_latlong("builtin:sky", w, h, &sky)?)
        }
        Some(name) => bail!("--background-image builtin:{name}: unknown; there is builtin:sky"),
        None => Environment::load(path).with_context(flag),
    }
}

/// Tiles of the PTM (or of the unit tile without one) across and down the view.
fn tiles_shown(scene: &Scene) -> [f32; 2] {
    let tile = scene.ptm.as_ref().map_or([1.0, 1.0], |p| p.tile);
    [
        ((scene.view[2] - scene.view[0]) as f64 / tile[0]) as f32,
        ((scene.view[3] - scene.view[1]) as f64 / tile[1]) as f32,
    ]
}

/// Refuses an image the decoder would refuse for its size with what the limit is and what to
/// do, instead of the decoder's bare "Memory limit exceeded".
fn check_image_size(path: &Path, flag: &str) -> anyhow::Result<()> {
    use image::ImageDecoder;
    let named = || crate::outputs::Named::new("reading", path);
    let decoder = image::ImageReader::open(path)
        .with_context(named)?
        .with_guessed_format()
        .with_context(named)?
        .into_decoder();
    // Not decodable at all: read_rgba8 says why.
    let Ok(decoder) = decoder else {
        return Ok(());
    };
    let (w, h) = decoder.dimensions();
    let bytes = decoder.total_bytes();
    let Some(limit) = image::Limits::default().max_alloc else {
        return Ok(());
    };
    if bytes > limit {
        let side = ptm_runtime::scene::MAX_CASTER_SIDE;
        bail!(
            "{}: {flag} image is {w}×{h} ({:.1} GiB decoded), over the image decoder's limit of              {} MiB: downscale it (the renderer box-downsamples anything larger than {side}×{side}              anyway, so {side}×{side} as an 8-bit PNG loses nothing)",
            path.display(),
            bytes as f64 / (1u64 << 30) as f64,
            limit >> 20
        );
    }
    Ok(())
}

#[cfg(feature = "window")]
fn run_window(args: &Args) -> anyhow::Result<json::Preview> {
    use ptm_runtime::window::{self, WindowOptions};
    let mut scene = build_scene(args)?;
    let options = WindowOptions {
        exposure: args.exposure,
        exit_after_frames: args.window_frames,
    };
    let report = match &args.garment.mesh {
        Some(name) => {
            let m = crate::garment::build(&args.garment, &view_of(args), name, &mut scene)?;
            // Refused here, before the window opens, if the mesh scene cannot be prepared.
            for w in &m.scene.prepare_frame()?.warnings {
                eprintln!("ptm preview: {w}");
            }
            window::run_mesh(m.scene, options)?
        }
        None => {
            // The window prepares every frame; the opening view's warnings are told once, here.
            for w in &scene.prepare()?.warnings {
                eprintln!("ptm preview: {w}");
            }
            window::run(scene, options)?
        }
    };
    Ok(json::Preview::Window(json::Window {
        adapter: report.adapter,
        surface_format: report.surface_format,
        frames: report.frames,
        renders: report.renders,
        seconds_last_render: report.last_render_s,
        blur: report.blur,
        ptm_on: report.ptm_on,
        light: report.light,
        camera: report.camera,
        mean_rgb: report.mean_rgb,
    }))
}

#[cfg(not(feature = "window"))]
fn run_window(_: &Args) -> anyhow::Result<json::Preview> {
    bail!(
        "this ptm was built without the preview window: rebuild with --features window \
         (cargo build --features window), or leave out --window and give -o out.png"
    )
}

/// `ptm preview`: builds and prepares the scene, opens the GPU, says what preparing found,
/// renders (and compares the blur methods), writes the images; returns what `--json` prints.
/// With `--window`, shows the scene interactively instead.
pub fn run(args: &Args) -> anyhow::Result<json::Preview> {
    check_exposure(args)?;
    if args.window {
        return run_window(args);
    }
    let start = Instant::now();
    // clap requires -o unless --window.
    let output = args.output.as_deref().context("--output is required")?;
    let tx = check_outputs(args, output)?;
    let mut scene = build_scene(args)?;
    let mesh = match &args.garment.mesh {
        Some(name) => Some(crate::garment::build(
            &args.garment,
            &view_of(args),
            name,
            &mut scene,
        )?),
        None => None,
    };
    let (prepared, mesh_report) = match &mesh {
        Some(m) => {
            let (p, t) = m.scene.prepare()?;
            (p, Some((m, t)))
        }
        None => (scene.prepare()?, None),
    };
    let (gpu, device_s) = open_gpu(&prepared)?;
    let mut report = json::Render {
        adapter: gpu.describe(),
        variant: prepared.variant.name(),
        size: scene.size,
        view: scene.view,
        tiles: tiles_shown(&scene),
        lights: scene.lights.len(),
        blur: scene.caster.as_ref().map(|_| scene.blur.name()),
        seconds_device: device_s,
        mesh: mesh_report.map(|(m, t)| json::MeshReport {
            mesh: m.name.clone(),
            triangles: t.triangles,
            tangent_fallback_triangles: t.fallback_triangles,
            vertex_buffer_bytes: ptm_runtime::mesh::vertex_bytes(t.triangles),
            maps: m.maps.as_deref().map(json::path),
            normal_map: m.scene.normal_map.is_some(),
            yarn_colors: m.yarn_colors,
            k: m.scene.scene.ptm.is_some(),
            shadow_map_size: prepared.frame.shadow_size,
            shadow_map_bytes: if prepared.variant.shadow {
                ptm_runtime::mesh::shadow_bytes(prepared.frame.shadow_size, scene.lights.len())
            } else {
                0
            },
        }),
        ..Default::default()
    };
    if let Some(m) = &report.mesh {
        if m.tangent_fallback_triangles > 0 {
            eprintln!(
                "ptm preview: {} of the mesh's {} triangles have degenerate UVs or no area; \
                 their tangents fell back to one perpendicular to the normal",
                m.tangent_fallback_triangles, m.triangles
            );
        }
    }
    diagnose(&scene, &prepared, &mut report);
    let prep = |s: &Scene| -> anyhow::Result<SceneBuffers> {
        Ok(match &mesh {
            Some(m) => {
                let mut ms = m.scene.clone();
                ms.scene = s.clone();
                ms.prepare()?.0
            }
            None => s.prepare()?,
        })
    };
    let scene = mesh.as_ref().map_or(&scene, |m| &m.scene.scene);
    let image = match &mesh {
        Some(m) if args.garment.sheet => lookdev_sheet(&gpu, m, &prepared, &mut report)?,
        _ => render(args, &gpu, scene, &prepared, &prep, &mut report)?,
    };
    if args.compare_blur {
        compare_blur(args, &gpu, scene, &mut report)?;
    }
    write_outputs(args, output, tx, &image, &mut report)?;
    report.seconds = start.elapsed().as_secs_f64();
    Ok(json::Preview::Render(Box::new(report)))
}

/// The largest side of `--size` (wgpu's guaranteed texture limit on desktop GPUs).
pub const MAX_SIDE: u32 = 16384;
/// The most pixels a run holds as linear RGBA f32 (`--size` × `--turntable` frames): 4 GiB.
pub const MAX_PIXELS: u64 = 1 << 28;
/// The most `--mc-samples` per pixel and light.
pub const MAX_MC_SAMPLES: u32 = 1 << 16;

/// Refuses an `--exposure` that is not a finite number of stops, and counts that would allocate
/// more than any run needs (`--size`, `--turntable` frames) or run for hours (`--mc-samples`),
/// before anything is allocated.
fn check_exposure(args: &Args) -> anyhow::Result<()> {
    if !args.exposure.is_finite() {
        bail!(
            "--exposure {} must be a finite number of stops",
            args.exposure
        );
    }
    // The default size is at most 512×512.
    let (w, h) = args.size.unwrap_or((512, 512));
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        bail!("--size {w},{h}: each side must be 1 to {MAX_SIDE} pixels");
    }
    let frames = args.turntable.unwrap_or(1) as u64;
    let pixels = w as u64 * h as u64 * frames;
    if pixels > MAX_PIXELS {
        bail!(
            "--size {w},{h} × {frames} turntable frames is {pixels} pixels, more than the {MAX_PIXELS}              (4 GiB of linear RGBA) one run holds: lower --size or --turntable"
        );
    }
    for &(a, b, deg) in &args.light_rect {
        if !(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0) {
            bail!("--light-rect {a},{b}: both sides must be finite and > 0 (swatch units)");
        }
        if !deg.is_finite() {
            bail!("--light-rect {a},{b},{deg}: the turn must be a finite number of degrees");
        }
        if args.blur == Blur::Separable && deg.to_radians().sin() != 0.0 && args.caster.is_some() {
            bail!(
                "--light-rect {a},{b},{deg}: --blur separable filters along X and Y only: use \
                 sat, mip or explicit for a turned rectangle"
            );
        }
    }
    for &(a, b) in &args.light_gaussian {
        if !(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0) {
            bail!(
                "--light-gaussian {a},{b}: both standard deviations must be finite and > 0 \
                 (swatch units; a point light is --light-radius 0)"
            );
        }
    }
    for &(elev, az, r) in &args.light_distant {
        if !(elev.is_finite() && elev > 0.0 && elev <= 90.0) {
            bail!("--light-distant {elev},{az}: the elevation must be above 0° and at most 90°");
        }
        if !az.is_finite() {
            bail!("--light-distant {elev},{az}: the azimuth must be a finite number of degrees");
        }
        if !(r.is_finite() && (0.0..=45.0).contains(&r)) {
            bail!(
                "--light-distant {elev},{az},{r}: the angular radius must be 0 to 45 degrees (the \
                 sun's is {SUN_RADIUS_DEG}; a wider source is a sky)"
            );
        }
        if !args.light_rect.is_empty() || !args.light_gaussian.is_empty() {
            bail!(
                "--light-distant: a distant light is a disc of an angular radius; not with \
                 --light-rect or --light-gaussian"
            );
        }
        if args.window {
            bail!(
                "--light-distant: not with --window, whose drags place a light under the cursor \
                 (render offscreen, or place a --light far away)"
            );
        }
    }
    if !args.light_gaussian.is_empty() && !args.light_rect.is_empty() {
        bail!("--light-gaussian and --light-rect both give the lights' shape: choose one");
    }
    if let Some(r) = args.glossy {
        if !(0.0..=1.0).contains(&r) {
            bail!("--glossy {r}: the roughness must lie in [0, 1] (0 a mirror, 1 a 45° cone)");
        }
        let b = args.background;
        if !b.iter().all(|x| x.is_finite() && *x >= 0.0) {
            bail!(
                "--background {},{},{}: must be finite and ≥ 0 (linear RGB radiance)",
                b[0],
                b[1],
                b[2]
            );
        }
        if !(0.0..=1.0).contains(&args.reflectance) {
            bail!("--reflectance {}: F0 must lie in [0, 1]", args.reflectance);
        }
        if args.caster.is_none() {
            bail!("--glossy reflects the caster: give it a --caster");
        }
        if args.blur == Blur::Separable {
            bail!(
                "--glossy needs a kernel per pixel; --blur separable has one per light: use \
                 sat, mip or explicit"
            );
        }
        if args.colored_shadow {
            bail!("--glossy reflects a grey-opacity caster: not with --colored-shadow");
        }
        if args.garment.mesh.is_some() {
            bail!("--glossy reflects the caster in the plane of the cloth: not with --mesh");
        }
    }
    if let (Some(path), None) = (&args.background_image, args.glossy) {
        bail!(
            "--background-image {}: only a --glossy cloth reflects a background: add --glossy",
            path.display()
        );
    }
    if args.mc_samples == 0 || args.mc_samples > MAX_MC_SAMPLES {
        bail!(
            "--mc-samples {} must be 1 to {MAX_MC_SAMPLES}",
            args.mc_samples
        );
    }
    Ok(())
}

/// Opens whatever adapter wgpu finds and says which shader variant runs on it. Returns the
/// GPU and the seconds opening it took.
fn open_gpu(prepared: &SceneBuffers) -> anyhow::Result<(Gpu, f64)> {
    let t = Instant::now();
    let gpu = Gpu::new()?;
    let device_s = t.elapsed().as_secs_f64();
    eprintln!(
        "ptm preview: {} on {}",
        prepared.variant.name(),
        gpu.describe()
    );
    Ok((gpu, device_s))
}

/// Tells (stderr) and records (`report`) what preparing the scene found: a downsampled caster,
/// non-finite coefficients, the runtime's warnings, lights that add nothing or are not
/// shadowed, and K leaving [0, 1] before clamping.
fn diagnose(scene: &Scene, prepared: &SceneBuffers, report: &mut json::Render) {
    if prepared.caster_downsample > 1 {
        eprintln!(
            "ptm preview: the caster is larger than {0}²; box-downsampled by {1} (u32 box sums are \
             exact only up to {0}² texels)",
            ptm_runtime::scene::MAX_CASTER_SIDE,
            prepared.caster_downsample
        );
    }
    report.caster_downsample = prepared.caster_downsample;
    if prepared.nonfinite_coeffs > 0 {
        eprintln!(
            "ptm preview: {} PTM coefficients are NaN or infinite; rendered as 0 (K = 0 there)",
            prepared.nonfinite_coeffs
        );
    }
    report.nonfinite_coeffs = prepared.nonfinite_coeffs;
    for w in &prepared.warnings {
        eprintln!("ptm preview: {w}");
    }
    report.warnings = prepared.warnings.iter().map(|w| w.to_string()).collect();
    for (i, l) in scene.lights.iter().enumerate() {
        if l.position[2] <= 0.0 {
            eprintln!(
                "ptm preview: light {i} is not above the cloth (z = {}); it adds nothing",
                l.position[2]
            );
        } else if let (Some(c), false) = (&scene.caster, l.distant) {
            // (A distant light's z is its direction's: it is always beyond the caster.)
            if l.position[2] <= c.elevation {
                eprintln!(
                    "ptm preview: light {i} is on or below the caster plane; the caster does not \
                     shadow it"
                );
            }
        }
    }
    if let Some(k) = cpu::k_excursion(prepared) {
        if k.clamped_fraction > 0.0 {
            eprintln!(
                "ptm preview: K left [0, 1] before clamping in {:.2}% of evaluations (min {:.3}, \
                 max {:.3})",
                100.0 * k.clamped_fraction,
                k.min,
                k.max
            );
        }
        report.k_unclamped = Some((&k).into());
    }
}

/// Renders the scene on the GPU: one frame, or with `--turntable N` N frames with the lights
/// turned about the vertical axis, tiled into a contact sheet. Records the pass timings.
fn render(
    args: &Args,
    gpu: &Gpu,
    scene: &Scene,
    prepared: &SceneBuffers,
    prep: &dyn Fn(&Scene) -> anyhow::Result<SceneBuffers>,
    report: &mut json::Render,
) -> anyhow::Result<Image> {
    let Some(n) = args.turntable else {
        let (img, t) = gpu::render(gpu, prepared)?;
        report.seconds_passes = Some(json::Passes(t.passes));
        return Ok(img);
    };
    if n == 0 {
        bail!("--turntable needs at least 1 frame");
    }
    let mut frames = Vec::new();
    let mut per_frame = Vec::new();
    for k in 0..n {
        let turned = scene.with_lights_turned(std::f32::consts::TAU * k as f32 / n as f32);
        let (img, t) = gpu::render(gpu, &prep(&turned)?)?;
        per_frame.push(json::Passes(t.passes));
        frames.push(img);
    }
    // Frame k turns the lights by 360°·k/n: its label is that azimuth.
    let azimuths: Vec<f32> = (0..n).map(|k| 360.0 * k as f32 / n as f32).collect();
    let labels: Vec<String> = azimuths.iter().map(|a| format!("{}°", a.round())).collect();
    let layout = output::sheet_layout(frames.len(), frames[0].width, frames[0].height);
    report.turntable = Some(json::Turntable {
        frames: n,
        columns: layout.columns,
        rows: layout.rows,
        gutter: layout.gutter,
        azimuths_deg: azimuths,
        seconds_passes: per_frame,
    });
    Ok(Image::labelled_sheet(&frames, &labels).expect("frames share one size"))
}

/// `--sheet`: with K, without K, and a close-up with K (a fifth of the field of view), side by
/// side in one image (grey gutters between them).
fn lookdev_sheet(
    gpu: &Gpu,
    m: &crate::garment::Garment,
    prepared: &SceneBuffers,
    report: &mut json::Render,
) -> anyhow::Result<Image> {
    let (with_k, t) = gpu::render(gpu, prepared)?;
    report.seconds_passes = Some(json::Passes(t.passes));
    let mut no_k = m.scene.clone();
    no_k.scene.ptm = None;
    let (without_k, _) = gpu::render(gpu, &no_k.prepare()?.0)?;
    let mut close = m.scene.clone();
    if let Some(cam) = &mut close.scene.perspective {
        cam.fov_y_deg /= 5.0;
    }
    let (close_up, _) = gpu::render(gpu, &close.prepare()?.0)?;
    Ok(Image::contact_sheet(&[with_k, without_k, close_up], 3).expect("frames share one size"))
}

/// `--compare-blur`: every blur method against the Monte Carlo soft shadow (with `--glossy`,
/// every per-pixel method's reflected radiance against the ray-traced lobe), as a table on
/// stderr and rows in `report`.
fn compare_blur(
    args: &Args,
    gpu: &Gpu,
    scene: &Scene,
    report: &mut json::Render,
) -> anyhow::Result<()> {
    if scene.caster.is_none() {
        bail!("--compare-blur needs a caster (--caster image.png)");
    }
    let rows = if scene.glossy.is_some() {
        eprintln!("reflected radiance against the ray-traced glossy lobe:");
        compare::compare_reflection(gpu, scene, args.mc_samples)?
    } else {
        compare::compare_blur(gpu, scene, args.mc_samples)?
    };
    eprintln!("{}", compare::table(&rows));
    report.compare_blur = Some(rows.iter().map(Into::into).collect());
    Ok(())
}

/// Refuses an output that is an input (`--ptm`, `--caster`, `--albedo-texture`) or the other
/// output, and checks both destinations before any work; the PNG and the EXR are then
/// published together.
fn check_outputs(args: &Args, output: &Path) -> anyhow::Result<Transaction> {
    let mut outputs = vec![output];
    outputs.extend(args.exr.as_deref());
    let mut inputs = Vec::new();
    inputs.extend(args.ptm.as_deref().map(|p| ("PTM", p)));
    inputs.extend(args.garment.maps.as_deref().map(|p| ("companion maps", p)));
    inputs.extend(
        args.garment
            .mesh
            .as_deref()
            .filter(|m| m.ends_with(".obj"))
            .map(|p| ("mesh", Path::new(p))),
    );
    inputs.extend(args.caster.as_deref().map(|p| ("caster", p)));
    inputs.extend(
        args.albedo_texture
            .as_deref()
            .map(|p| ("albedo texture", p)),
    );
    crate::outputs::refuse_inputs(&outputs, &inputs)?;
    Ok(Transaction::new(&outputs)?)
}

/// Writes the PNG (at `--exposure`) and, with `--exr`, the linear EXR, both or neither;
/// records their paths.
fn write_outputs(
    args: &Args,
    output: &Path,
    mut tx: Transaction,
    image: &Image,
    report: &mut json::Render,
) -> anyhow::Result<()> {
    let png = png_bytes(image.width, image.height, image.to_srgb8(args.exposure))
        .with_context(|| crate::outputs::Named::new("writing", output))?;
    tx.stage_bytes(output, &png)?;
    if let Some(exr) = &args.exr {
        // R, G, B as f32, row 0 the top of the image.
        let channel = |c: usize| {
            let plane = image.pixels.iter().map(|p| p[c]).collect();
            (["R", "G", "B"][c].to_string(), Samples::F32(plane))
        };
        let bytes = exrio::encode(
            exr,
            image.width,
            image.height,
            (0..3).map(channel).collect(),
            Vec::new(),
        )?;
        tx.stage_bytes(exr, &bytes)?;
    }
    tx.commit()?;
    eprintln!("ptm preview: wrote {}", output.display());
    report.png = json::path(output);
    if let Some(exr) = &args.exr {
        eprintln!("ptm preview: wrote {}", exr.display());
        report.exr = Some(json::path(exr));
    }
    Ok(())
}

/// The bytes of an 8-bit RGBA PNG.
pub fn png_bytes(width: usize, height: usize, rgba: Vec<u8>) -> anyhow::Result<Vec<u8>> {
    let img = image::RgbaImage::from_raw(width as u32, height as u32, rgba)
        .context("the pixels do not make an RGBA image of this size")?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}
