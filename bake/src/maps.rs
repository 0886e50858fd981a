//! Companion maps from the same bake, with no new rays: height and a tangent-space normal from
//! the primary hits, ambient occlusion and a bent normal from every light's K integrated with
//! the dome's quadrature weights (docs/FORMAT.md, "Companion maps").
//!
//! Inputs are plain values, so any tracer can feed them: per footprint sample a
//! [`SurfaceHit`] (hit height, unit normal, triangle), per light its K plane.
//!
//! Frames: the swatch frame is the tangent frame (T = +X, B = +Y, N = +Z). MikkTSpace on a
//! flat, axis-aligned tile with the identity UV map is that identity frame, so the normal map
//! holds the mean normal of the first hits in swatch coordinates; a renderer using it on a mesh
//! builds its own MikkTSpace tangents from that mesh's UVs (as Blender, Substance and glTF do)
//! and applies it there. +Y is up (the OpenGL convention).
use ptm_format::exrio::{self, Attr, Samples};
use ptm_format::LightSet;

use crate::{Error, Result};

/// What one primary (footprint) sample found, in the swatch's own units and frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Height of the hit, z in the swatch frame (mesh units).
    pub z: f64,
    /// Unit geometric normal, face-forwarded towards the camera above (n_z ≥ 0).
    pub n: [f64; 3],
    /// The triangle hit (index into the swatch's triangles).
    pub prim: u32,
}

/// Per-texel sums of the primary hits: what height and normal maps are made of.
#[derive(Clone, Debug, Default)]
pub struct Surface {
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    hits: Vec<u32>,
    z_sum: Vec<f64>,
    z_min: Vec<f64>,
    z_max: Vec<f64>,
    n_sum: Vec<[f64; 3]>,
    /// Footprint samples per texel.
    spp: usize,
    /// Per texel and sample, the material hit ([`NO_HIT`] where the sample saw nothing).
    ids: Vec<u32>,
}

/// A sample that hit nothing, in [`Surface`]'s material ids.
pub const NO_HIT: u32 = u32::MAX;

impl Surface {
    /// No hits yet over `width × height` texels of `spp` footprint samples each.
    pub fn new(width: usize, height: usize, spp: usize) -> Surface {
        let n = width * height;
        Surface {
            spp,
            ids: vec![NO_HIT; n * spp],
            width,
            height,
            hits: vec![0; n],
            z_sum: vec![0.0; n],
            z_min: vec![f64::INFINITY; n],
            z_max: vec![f64::NEG_INFINITY; n],
            n_sum: vec![[0.0; 3]; n],
        }
    }

    /// Bytes a surface of `texels` texels of `spp` samples holds.
    pub fn memory_bytes(texels: f64, spp: f64) -> f64 {
        texels * (4.0 + 3.0 * 8.0 + 3.0 * 8.0 + 4.0 * spp)
    }

    /// Adds footprint sample `sample`'s hit of material `material` to texel `texel`
    /// (row-major). Sums run in the order samples come; callers add each texel's samples in
    /// sample order, so the maps are deterministic.
    pub fn add(&mut self, texel: usize, sample: usize, hit: &SurfaceHit, material: u32) {
        self.ids[texel * self.spp + sample] = material;
        self.hits[texel] += 1;
        self.z_sum[texel] += hit.z;
        self.z_min[texel] = self.z_min[texel].min(hit.z);
        self.z_max[texel] = self.z_max[texel].max(hit.z);
        for a in 0..3 {
            self.n_sum[texel][a] += hit.n[a];
        }
    }

    /// Sets texel `to` to texel `at` of `from` (of the same samples per texel).
    pub fn copy_texel(&mut self, to: usize, from: &Surface, at: usize) {
        self.hits[to] = from.hits[at];
        self.z_sum[to] = from.z_sum[at];
        self.z_min[to] = from.z_min[at];
        self.z_max[to] = from.z_max[at];
        self.n_sum[to] = from.n_sum[at];
        let s = self.spp;
        self.ids[to * s..(to + 1) * s].copy_from_slice(&from.ids[at * s..(at + 1) * s]);
    }

    /// Appends `other`'s rows below this surface's (for assembling row blocks).
    pub fn append_rows(&mut self, other: Surface) {
        self.hits.extend(other.hits);
        self.z_sum.extend(other.z_sum);
        self.z_min.extend(other.z_min);
        self.z_max.extend(other.z_max);
        self.n_sum.extend(other.n_sum);
        self.ids.extend(other.ids);
        self.height += other.height;
    }
}

/// Ambient occlusion and bent normal, accumulated light by light from K planes.
///
/// AO = Σₗ wₗ cos θₗ (1 − Kₗ) / Σₗ wₗ cos θₗ, with wₗ the dome's quadrature weight (solid
/// angle, [`crate::dome::Quadrature`]) and cos θₗ = lₗ·N the light's height over the swatch
/// plane: the cosine-weighted visibility over the part of the hemisphere the dome samples,
/// normalised over that part (1 = open, 0 = occluded; a flat plane is 1). The band below the
/// dome's lowest light (`--min-elevation`) is not sampled and so does not enter; the file records
/// the fraction of the cosine-weighted hemisphere that was (`ao:domeFraction` = Σ wₗ cos θₗ / π),
/// by which AO is multiplied where that band is to count as occluded. Bent normal =
/// normalise(Σₗ wₗ cos θₗ (1 − Kₗ) lₗ), the cosine-weighted mean unoccluded direction; the
/// dome's mean direction where every light is occluded.
#[derive(Clone, Debug)]
pub struct Occlusion {
    dirs: Vec<[f64; 3]>,
    /// wₗ cos θₗ per light (0 at or below the horizon).
    weights: Vec<f64>,
    open: Vec<f64>,
    bent: Vec<[f64; 3]>,
}

impl Occlusion {
    /// An accumulator of `texels` texels for `lights` with quadrature `weights` (sr per light).
    pub fn new(lights: &LightSet, weights: &[f64], texels: usize) -> Result<Occlusion> {
        if weights.len() != lights.len() {
            return Err(Error::Config(format!(
                "{} quadrature weights for {} lights",
                weights.len(),
                lights.len()
            )));
        }
        let weights = lights
            .dirs
            .iter()
            .zip(weights)
            .map(|(d, w)| w * d[2].max(0.0))
            .collect();
        Ok(Occlusion {
            dirs: lights.dirs.clone(),
            weights,
            open: vec![0.0; texels],
            bent: vec![[0.0; 3]; texels],
        })
    }

    /// Bytes an accumulator of `texels` texels holds.
    pub fn memory_bytes(texels: f64) -> f64 {
        texels * 4.0 * 8.0
    }

    /// Adds light `index`'s K plane.
    pub fn add_light(&mut self, index: usize, k: &[f32]) -> Result<()> {
        if index >= self.dirs.len() || k.len() != self.open.len() {
            return Err(Error::Config(format!(
                "light {index} with {} texels: the occlusion maps hold {} lights of {} texels",
                k.len(),
                self.dirs.len(),
                self.open.len()
            )));
        }
        let (w, l) = (self.weights[index], self.dirs[index]);
        if w == 0.0 {
            return Ok(());
        }
        for ((o, b), &k) in self.open.iter_mut().zip(&mut self.bent).zip(k) {
            let v = w * (1.0 - k as f64);
            *o += v;
            for a in 0..3 {
                b[a] += v * l[a];
            }
        }
        Ok(())
    }

    /// Σ wₗ cos θₗ / π: the fraction of the cosine-weighted hemisphere the dome samples.
    pub fn dome_fraction(&self) -> f64 {
        self.weights.iter().sum::<f64>() / std::f64::consts::PI
    }
}

/// The companion maps of a bake's rows: named planes (row-major, row 0 at y = H) and what the
/// file says of them.
#[derive(Clone, Debug)]
pub struct Maps {
    /// Texels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Channels in file order: `height`, `height.min`, `height.max`, `normal.{X,Y,Z}`, `ao`,
    /// `bent.{X,Y,Z}`, `coverage`, `id`, then `mask.NAME` per material.
    pub channels: Vec<(String, Vec<f32>)>,
    /// Header attributes (`maps:*`), equal for every row block of one bake.
    pub attrs: Vec<(&'static str, Attr)>,
    /// The swatch's height range (mesh units): `maps:heightMin`, `maps:heightMax`.
    pub z_range: [f64; 2],
}

/// Value of `maps:version`.
pub const MAPS_VERSION: &str = "ptm-maps/1";

/// The settings that make the maps what they are, in words (recorded in the file, and in a
/// farm part's identity): the quadrature rule and the height range.
pub fn words(quadrature: crate::dome::Quadrature) -> String {
    format!("ao+bent+height+normal quadrature={}", quadrature.words())
}

impl Maps {
    /// The maps of `surface` and `occlusion` over the same texels, with the texels' `coverage`;
    /// `z_range` is the swatch's height range (mesh units), where uncovered texels' height
    /// lies (at its bottom) and over which 16-bit PNGs spread the height.
    pub fn finish(
        surface: &Surface,
        occlusion: &Occlusion,
        coverage: &[f32],
        z_range: [f64; 2],
        quadrature: crate::dome::Quadrature,
        material_names: &[String],
    ) -> Result<Maps> {
        let n = surface.width * surface.height;
        if occlusion.open.len() != n || coverage.len() != n {
            return Err(Error::Config(format!(
                "maps of {n} texels from {} occlusion and {} coverage texels",
                occlusion.open.len(),
                coverage.len()
            )));
        }
        let norm = occlusion.weights.iter().sum::<f64>();
        let mut dome = [0.0; 3];
        for (w, d) in occlusion.weights.iter().zip(&occlusion.dirs) {
            for a in 0..3 {
                dome[a] += w * d[a];
            }
        }
        let unit = |v: [f64; 3], fallback: [f64; 3]| {
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if len > 0.0 && len.is_finite() {
                v.map(|c| c / len)
            } else {
                fallback
            }
        };
        let dome = unit(dome, [0.0, 0.0, 1.0]);
        let mut h = vec![0.0f32; n];
        let mut h_min = vec![0.0f32; n];
        let mut h_max = vec![0.0f32; n];
        let mut normal = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        let mut ao = vec![0.0f32; n];
        let mut bent = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        for t in 0..n {
            let hits = surface.hits[t];
            let (zm, zlo, zhi, nm) = if hits > 0 {
                (
                    surface.z_sum[t] / hits as f64,
                    surface.z_min[t],
                    surface.z_max[t],
                    unit(surface.n_sum[t], [0.0, 0.0, 1.0]),
                )
            } else {
                (z_range[0], z_range[0], z_range[0], [0.0, 0.0, 1.0])
            };
            h[t] = zm as f32;
            h_min[t] = zlo as f32;
            h_max[t] = zhi as f32;
            ao[t] = if norm > 0.0 {
                (occlusion.open[t] / norm) as f32
            } else {
                0.0
            };
            let b = unit(occlusion.bent[t], dome);
            for a in 0..3 {
                normal[a][t] = nm[a] as f32;
                bent[a][t] = b[a] as f32;
            }
        }
        // Ids: the majority material over each texel's samples (ties to the lower id; −1 where
        // nothing was hit) and per material its share of the footprint.
        let m = material_names.len();
        let mut id = vec![-1.0f32; n];
        let mut masks = vec![vec![0.0f32; n]; m];
        let mut counts = vec![0u32; m];
        for t in 0..n {
            counts.iter_mut().for_each(|c| *c = 0);
            for &s in &surface.ids[t * surface.spp..(t + 1) * surface.spp] {
                if (s as usize) < m {
                    counts[s as usize] += 1;
                }
            }
            let mut best = None;
            for (i, &c) in counts.iter().enumerate() {
                if c > 0 && best.is_none_or(|b: usize| c > counts[b]) {
                    best = Some(i);
                }
                masks[i][t] = c as f32 / surface.spp as f32;
            }
            if let Some(b) = best {
                id[t] = b as f32;
            }
        }
        let [nx, ny, nz] = normal;
        let [bx, by, bz] = bent;
        let channels = vec![
            ("height".to_string(), h),
            ("height.min".to_string(), h_min),
            ("height.max".to_string(), h_max),
            ("normal.X".to_string(), nx),
            ("normal.Y".to_string(), ny),
            ("normal.Z".to_string(), nz),
            ("ao".to_string(), ao),
            ("bent.X".to_string(), bx),
            ("bent.Y".to_string(), by),
            ("bent.Z".to_string(), bz),
            ("coverage".to_string(), coverage.to_vec()),
            ("id".to_string(), id),
        ];
        let mut channels = channels;
        for (name, mask) in material_names.iter().zip(masks) {
            channels.push((format!("mask.{}", channel_word(name)), mask));
        }
        let attrs = vec![
            ("maps:version", Attr::Text(MAPS_VERSION.into())),
            ("maps:settings", Attr::Text(words(quadrature))),
            (
                "maps:normalSpace",
                Attr::Text(
                    "tangent: T = +X, B = +Y, N = +Z of the swatch (MikkTSpace of the flat \
                     tile); +Y up (OpenGL)"
                        .into(),
                ),
            ),
            (
                "maps:heightReference",
                Attr::Text("z = 0 of the swatch frame, mesh units".into()),
            ),
            ("maps:heightMin", Attr::F64(z_range[0])),
            ("maps:heightMax", Attr::F64(z_range[1])),
            (
                "maps:ao",
                Attr::Text(
                    "cosine-weighted visibility over the sampled dome, normalised over it \
                     (1 open)"
                        .into(),
                ),
            ),
            ("maps:domeFraction", Attr::F64(occlusion.dome_fraction())),
            ("maps:materials", Attr::Texts(material_names.to_vec())),
        ];
        Ok(Maps {
            width: surface.width,
            height: surface.height,
            channels,
            attrs,
            z_range,
        })
    }

    /// Bytes the finished maps hold over `texels` texels of `materials` materials.
    pub fn memory_bytes(texels: f64, materials: f64) -> f64 {
        texels * (12.0 + materials) * 4.0
    }

    /// The plane of channel `name`.
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| &v[..])
    }

    /// The maps as one EXR file (float channels, sorted header attributes), encoded in memory
    /// for `path` (named in errors).
    pub fn encode(&self, path: &std::path::Path) -> Result<Vec<u8>> {
        let channels = self
            .channels
            .iter()
            .map(|(n, v)| (n.clone(), Samples::F32(v.clone())))
            .collect();
        Ok(exrio::encode(
            path,
            self.width,
            self.height,
            channels,
            self.attrs.clone(),
        )?)
    }

    /// 16-bit images for painting tools: (name, channels per pixel, samples row-major from
    /// the top row). `height`: (z − heightMin)/(heightMax − heightMin); `normal` and `bent`:
    /// RGB = n·0.5 + 0.5 (+Y up, the OpenGL convention Blender and Substance read); `ao`:
    /// grey; then `mask.NAME` per material: its share of the footprint, grey.
    pub fn png16(&self) -> Vec<(String, u8, Vec<u16>)> {
        let get = |n: &str| self.channel(n).unwrap_or(&[]);
        let q = |x: f64| (x.clamp(0.0, 1.0) * 65535.0).round() as u16;
        let [lo, hi] = self.z_range;
        let span = if hi > lo { hi - lo } else { 1.0 };
        let height = get("height")
            .iter()
            .map(|&z| q((z as f64 - lo) / span))
            .collect();
        let rgb = |p: &str| {
            let [x, y, z] = [".X", ".Y", ".Z"].map(|c| get(&format!("{p}{c}")));
            (0..x.len())
                .flat_map(|t| [x[t], y[t], z[t]].map(|c| q(c as f64 * 0.5 + 0.5)))
                .collect()
        };
        let grey = |v: &[f32]| v.iter().map(|&a| q(a as f64)).collect::<Vec<u16>>();
        let mut out = vec![
            ("height".to_string(), 1, height),
            ("normal".to_string(), 3, rgb("normal")),
            ("ao".to_string(), 1, grey(get("ao"))),
            ("bent".to_string(), 3, rgb("bent")),
        ];
        for (name, v) in &self.channels {
            if name.starts_with("mask.") {
                out.push((name.clone(), 1, grey(v)));
            }
        }
        out
    }
}

/// A material name as a channel name's last part: characters other than letters, digits, `-`
/// and `_` (a `.` would start a layer) become `_`.
pub fn channel_word(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The maps written as 16-bit PNGs whatever the swatch ([`Maps::png16`], [`png_path`]), in
/// that order; the masks (`mask.NAME`) follow, one per material.
pub const PNG_MAPS: [&str; 4] = ["height", "normal", "ao", "bent"];

/// Where the maps of a bake whose output is `output` go: `NAME.maps.exr` beside it, NAME being
/// the output's file name without `.exr` and `.ptm` (`twill.ptm.exr` → `twill.maps.exr`,
/// `samples.exr` → `samples.maps.exr`).
pub fn maps_path(output: &std::path::Path) -> std::path::PathBuf {
    output.with_file_name(format!("{}.maps.exr", stem(output)))
}

/// The 16-bit PNG of map `name` (`height`, `normal`, `ao`, `bent`) beside `output`:
/// `NAME.height.png`, ….
pub fn png_path(output: &std::path::Path, name: &str) -> std::path::PathBuf {
    output.with_file_name(format!("{}.{name}.png", stem(output)))
}

fn stem(output: &std::path::Path) -> String {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = name.strip_suffix(".exr").unwrap_or(&name);
    name.strip_suffix(".ptm").unwrap_or(name).to_string()
}
