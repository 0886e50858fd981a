//! `ptm preview --mesh`: the mesh scene the flags describe — the mesh (a built-in or an OBJ),
//! the companion maps' normal map and yarn colours, a camera and key light framing the mesh,
//! the sheen and the fill — around the plane scene `preview::build_scene` made (its PTM, albedo
//! and size).
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use ptm_format::exrio;
use ptm_runtime::mesh::{Mesh, MeshScene, UvProjection, BUILTINS};
use ptm_runtime::scene::Perspective;
use ptm_runtime::{Light, Scene};

use crate::args::parse_triple;

/// `ptm preview`'s flags of the mesh path.
#[derive(clap::Args, Debug)]
pub struct MeshArgs {
    /// Render the PTM on a mesh instead of the plane: a built-in `sphere`, `cylinder`, `drape`
    /// (a 2.4 × 2.4 cloth over a sphere, with folds), `plane`, or an OBJ file with UVs. The
    /// PTM tiles --repeat times per UV unit (per unit of cloth for the built-ins, whose UVs are
    /// lengths); the light is brought into each pixel's MikkTSpace tangent frame for K. Default
    /// camera and light frame the mesh.
    #[arg(long, value_name = "NAME|FILE.obj", conflicts_with_all = ["caster", "compare_blur"])]
    pub mesh: Option<String>,
    /// How an OBJ without texture coordinates gets UVs: none (refuse it), planar (uv = xy)
    /// or box (each triangle along its dominant axis).
    #[arg(long, value_parser = ["none", "planar", "box"], default_value = "none", requires = "mesh")]
    pub uv_projection: String,
    /// Companion maps (`ptm bake --maps`) for the mesh: the normal map and the yarn masks.
    /// Default: NAME.maps.exr beside --ptm NAME.ptm.exr when it exists.
    #[arg(long, requires = "mesh")]
    pub maps: Option<PathBuf>,
    /// Leave the companion maps' normal map off.
    #[arg(long, requires = "mesh")]
    pub no_normal_map: bool,
    /// Colour of a yarn of the companion maps (`warp`, `weft`, `loop`, `pile`, … or an OBJ's
    /// usemtl name) as linear r,g,b: the albedo becomes Σ mask · colour per texel (--albedo
    /// for materials not named). Repeat for each yarn.
    #[arg(long, value_name = "NAME=R,G,B", requires = "mesh")]
    pub yarn_color: Vec<String>,
    /// Render without K (the PTM still sets the tile): the comparison image.
    #[arg(long, requires = "mesh")]
    pub no_k: bool,
    /// Sheen colour (glTF KHR_materials_sheen `sheenColorFactor`, linear r,g,b; 0 turns it
    /// off). Mesh path only.
    #[arg(long, value_parser = parse_triple, default_value = "0.25,0.25,0.25")]
    pub sheen: [f32; 3],
    /// Sheen roughness (glTF `sheenRoughnessFactor`, in (0, 1]; the Charlie lobe's α is its
    /// square). Mesh path only.
    #[arg(long, default_value_t = 0.5)]
    pub sheen_roughness: f32,
    /// Fill light (linear r,g,b): albedo · fill · (½ + ½ n_z), the sky over the floor; K does
    /// not darken it (K multiplies the key lights only). Mesh path only.
    #[arg(long, value_parser = parse_triple, default_value = "0.12,0.12,0.12")]
    pub fill: [f32; 3],
    /// Lookdev sheet: three renders side by side, with K, the same without K, and a close-up
    /// with K (the same camera at a fifth of the field of view, where the weave shows).
    #[arg(long, requires = "mesh", conflicts_with_all = ["turntable", "no_k"])]
    pub sheet: bool,
    /// Tessellation of a built-in mesh relative to its default (the drape: 200² quads).
    #[arg(long, default_value_t = 1.0, requires = "mesh")]
    pub mesh_detail: f32,
    /// Side of the macro shadow's depth maps in texels, one map per light framing the mesh from
    /// the light's centre (16 MiB a light at 2048); the shadow's penumbra follows each light's
    /// size (--light-radius). 0 turns the mesh's shadow on itself off.
    #[arg(long, default_value_t = ptm_runtime::mesh::DEFAULT_SHADOW_SIZE, requires = "mesh")]
    pub shadow_size: u32,
    /// No macro shadow (the mesh does not shadow itself; K still darkens the weave).
    #[arg(long, requires = "mesh")]
    pub no_shadow: bool,
}

/// The flags the mesh path shares with the plane preview.
pub struct View<'a> {
    /// The PTM (`--ptm`), whose NAME.maps.exr is looked for beside it.
    pub ptm: Option<&'a Path>,
    /// `--repeat`: tiles per UV unit.
    pub repeat: (u32, u32),
    /// `--albedo`.
    pub albedo: [f32; 3],
    /// `--size`.
    pub size: Option<(u32, u32)>,
    /// `--fov`, degrees.
    pub fov: f32,
    /// `--camera`.
    pub camera: Option<[f32; 3]>,
    /// `--look-at`.
    pub look_at: Option<[f32; 3]>,
    /// `--light` positions.
    pub light: &'a [[f32; 3]],
    /// `--light-radius`, per light (the last repeats).
    pub light_radius: &'a [f32],
    /// `--light-distant` (elevation, azimuth, angular radius; degrees).
    pub light_distant: &'a [(f32, f32, f32)],
    /// `--intensity`, per light.
    pub intensity: &'a [f32],
    /// `--color`, per light.
    pub color: &'a [[f32; 3]],
}

/// `--color` of light `i` (the last repeats; white without one).
fn nth_color(view: &View, i: usize) -> [f32; 3] {
    view.color
        .get(i)
        .or(view.color.last())
        .copied()
        .unwrap_or([1.0; 3])
}

/// The `--light-distant` lights, numbered from `first` for `--intensity` and `--color` (the
/// last value repeats): each a unit direction from its elevation and azimuth, its angular
/// radius in radians, and where no intensity is given `default(sin elevation)`.
pub fn distant_lights(view: &View, first: usize, default: impl Fn(f32) -> f32) -> Vec<Light> {
    let nth = |v: &[f32], i: usize| v.get(i).or(v.last()).copied();
    view.light_distant
        .iter()
        .enumerate()
        .map(|(j, &(elev, az, r))| {
            let i = first + j;
            let (e, a) = (elev.to_radians(), az.to_radians());
            Light {
                position: [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()],
                radius: r.to_radians(),
                distant: true,
                intensity: nth(view.intensity, i).unwrap_or_else(|| default(e.sin())),
                color: nth_color(view, i),
                ..Light::default()
            }
        })
        .collect()
}

/// The mesh scene and what it was made of.
pub struct Garment {
    /// The scene to prepare.
    pub scene: MeshScene,
    /// The built-in's name or the OBJ's path.
    pub name: String,
    /// The companion maps read, if any.
    pub maps: Option<PathBuf>,
    /// Whether the albedo comes from the yarn masks.
    pub yarn_colors: bool,
}

/// The default output size of a mesh render.
pub const DEFAULT_SIZE: [u32; 2] = [640, 480];

/// Builds the mesh scene of `--mesh NAME` on `scene` (from `build_scene`): replaces its size,
/// view (the mesh's footprint, about whose centre --turntable turns the lights), lights and
/// camera with the mesh's, and its albedo with the yarn colours when asked.
pub fn build(
    args: &MeshArgs,
    view: &View,
    name: &str,
    scene: &mut Scene,
) -> anyhow::Result<Garment> {
    let mesh = if let Some(m) = Mesh::builtin(name, args.mesh_detail) {
        if !(args.mesh_detail > 0.0 && args.mesh_detail <= 16.0) {
            bail!("--mesh-detail {} must be in (0, 16]", args.mesh_detail);
        }
        m
    } else if name.to_ascii_lowercase().ends_with(".obj") || Path::new(name).exists() {
        let projection = match args.uv_projection.as_str() {
            "planar" => UvProjection::Planar,
            "box" => UvProjection::Box,
            _ => UvProjection::None,
        };
        Mesh::from_obj(Path::new(name), projection)?
    } else {
        bail!(
            "--mesh {name}: not a built-in mesh ({}) nor an OBJ file",
            BUILTINS.join(", ")
        );
    };
    let tile = scene
        .ptm
        .as_ref()
        .map_or([1.0, 1.0], |p| p.tile.map(|t| t as f32));
    let (rx, ry) = view.repeat;
    let uv_to_ptm = [rx as f32 * tile[0], ry as f32 * tile[1]];

    // Companion maps: the flag, or NAME.maps.exr beside NAME.ptm.exr.
    let maps_path = args.maps.clone().or_else(|| {
        let ptm = view.ptm.as_ref()?.to_str()?;
        let stem = ptm.strip_suffix(".ptm.exr")?;
        let p = PathBuf::from(format!("{stem}.maps.exr"));
        p.exists().then_some(p)
    });
    let mut normal_map = None;
    let mut yarn_colors = false;
    if let Some(path) = &maps_path {
        let mut maps = exrio::read(path)?;
        let what = "a companion maps file (`ptm bake --maps`)";
        maps.text("maps:version", what)?;
        let (w, h) = (maps.width, maps.height);
        if !args.no_normal_map {
            let x = maps.take_f32("normal.X", what)?;
            let y = maps.take_f32("normal.Y", what)?;
            let z = maps.take_f32("normal.Z", what)?;
            normal_map = Some((w, h, (0..w * h).map(|i| [x[i], y[i], z[i]]).collect()));
        }
        if !args.yarn_color.is_empty() {
            let materials = maps.texts("maps:materials", what)?;
            let coverage = maps.take_f32("coverage", what)?;
            let mut albedo: Vec<[f32; 3]> = vec![[0.0; 3]; w * h];
            let mut named = vec![0f32; w * h];
            for spec in &args.yarn_color {
                let (m, rgb) = parse_yarn_color(spec)?;
                if !materials.contains(&m) {
                    bail!(
                        "--yarn-color {spec}: {} has no material `{m}` (it has {})",
                        path.display(),
                        materials.join(", ")
                    );
                }
                let channel: String = m
                    .chars()
                    .map(|c| {
                        if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                            c
                        } else {
                            '_'
                        }
                    })
                    .collect();
                let mask = maps.take_f32(&format!("mask.{channel}"), what)?;
                for i in 0..w * h {
                    for c in 0..3 {
                        albedo[i][c] += mask[i] * rgb[c];
                    }
                    named[i] += mask[i];
                }
            }
            // Σ mask · colour over the covered fraction, the rest (materials not named) at
            // --albedo; uncovered texels (holes, shown black by the coverage) at --albedo too.
            for i in 0..w * h {
                let cov = coverage[i];
                for (a, &base) in albedo[i].iter_mut().zip(&view.albedo) {
                    *a = if cov > 0.0 {
                        (*a + (cov - named[i]).max(0.0) * base) / cov
                    } else {
                        base
                    };
                }
            }
            scene.albedo_texture = Some((w, h, albedo));
            yarn_colors = true;
        }
    } else if !args.yarn_color.is_empty() {
        bail!(
            "--yarn-color needs the companion maps' masks: bake with --maps, or name the file \
             with --maps NAME.maps.exr"
        );
    }
    if args.no_k {
        scene.ptm = None;
    }

    // Framing: the bounding sphere, seen from the front and above.
    let (lo, hi) = mesh.bounds();
    let c: [f32; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let r = 0.5 * (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f32>().sqrt();
    scene.view = [
        lo[0],
        lo[1],
        hi[0].max(lo[0] + 1e-6),
        hi[1].max(lo[1] + 1e-6),
    ];
    scene.size = view.size.map_or(DEFAULT_SIZE, |(w, h)| [w, h]);
    let dist = r / (0.5 * view.fov.to_radians()).sin() * 0.62;
    let eye = view
        .camera
        .unwrap_or([c[0], c[1] - 0.87 * dist, c[2] + 0.5 * dist]);
    if !eye.iter().all(|x| x.is_finite()) {
        bail!("--camera {eye:?} must be finite");
    }
    scene.perspective = Some(Perspective {
        eye,
        target: view.look_at.unwrap_or(c),
        fov_y_deg: view.fov,
    });
    let positions = if view.light.is_empty() && !view.light_distant.is_empty() {
        Vec::new()
    } else if view.light.is_empty() {
        vec![[c[0] - 1.6 * r, c[1] - 1.9 * r, c[2] + 2.4 * r]]
    } else {
        view.light.to_vec()
    };
    let nth = |v: &[f32], i: usize| v.get(i).or(v.last()).copied();
    scene.lights = positions
        .iter()
        .enumerate()
        .map(|(i, &position)| {
            let d2: f32 = (0..3).map(|a| (position[a] - c[a]).powi(2)).sum();
            Light {
                position,
                radius: nth(view.light_radius, i).unwrap_or(0.25 * r),
                rect: None,
                square_box: false,
                rect_angle_deg: 0.0,
                gaussian: None,
                distant: false,
                // Irradiance 1 at the mesh's centre, facing the light.
                intensity: nth(view.intensity, i).unwrap_or(d2),
                color: nth_color(view, i),
            }
        })
        .collect();
    let local = scene.lights.len();
    // Irradiance 1 on a surface facing the sun, as the local lights' at the mesh's centre.
    scene.lights.extend(distant_lights(view, local, |_| 1.0));
    Ok(Garment {
        scene: MeshScene {
            scene: scene.clone(),
            mesh,
            uv_to_ptm,
            sheen_color: args.sheen,
            sheen_roughness: args.sheen_roughness,
            fill: args.fill,
            normal_map,
            tile,
            shadow_size: if args.no_shadow { 0 } else { args.shadow_size },
        },
        name: name.to_string(),
        maps: maps_path,
        yarn_colors,
    })
}

/// `NAME=R,G,B`.
fn parse_yarn_color(s: &str) -> anyhow::Result<(String, [f32; 3])> {
    let (name, rgb) = s.split_once('=').with_context(|| {
        format!("--yarn-color {s}: expected NAME=R,G,B (e.g. warp=0.5,0.1,0.1)")
    })?;
    let v: Vec<f32> = rgb
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--yarn-color {s}: R,G,B must be numbers"))?;
    match v[..] {
        [r, g, b] if v.iter().all(|x| x.is_finite() && *x >= 0.0) => {
            Ok((name.to_string(), [r, g, b]))
        }
        _ => bail!("--yarn-color {s}: expected three numbers ≥ 0 after `=`"),
    }
}
