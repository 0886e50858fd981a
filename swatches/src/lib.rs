//! `ptm-swatches`: procedural, exactly tileable cloth geometry and the triangle mesh every
//! swatch is handed to the baker as.
//!
//! A swatch is named by a spec `NAME[?key=value&key=value...]`, e.g. `plain-weave`,
//! `twill?n=2&m=1&dir=s`, `plain-weave?segments=80`; [`builtin`] builds it and [`NAMES`] lists the
//! generators. Sizes are in the user's units (default: yarn spacing 1); the tile is reported in
//! [`Mesh::tile`].
//!
//! **Periodicity.** One tile spans [0, W]×[0, H] (z up) and the cloth is the union of its copies
//! at (a·W, b·H). Yarns that run across the tile (warps, wefts, knit courses) are cut exactly on
//! the border planes: the ring where a tube leaves through x = W (or y = H) is the ring where it
//! enters through x = 0 (y = 0) translated by W (H), computed that way so both match to float
//! rounding. Those tubes are open at the border and closed on the tile torus: identify border
//! vertices modulo (W, H) and every edge has exactly two triangles. Parts that do not cross a
//! border as a tube (knit loops reaching into the neighbouring course, pile tufts placed near
//! the border) are not cut; they stick out of the tile by less than one tile and their copies
//! fill the neighbours, so a 3×3 block of tiles covers the central tile completely.
//!
//! **Tubes.** Each yarn is a tube of elliptical cross-section swept along a centre curve
//! ([`yarn::Yarn`]); triangle normals point out of the yarn (positive [`Mesh::signed_volume`]).
//! Distinct yarns do not overlap: generators refuse parameters whose [`yarn::Cloth::clearance`]
//! is negative.

pub mod draft;
pub mod knit;
pub mod mesh;
pub mod obj;
pub mod params;
pub mod pile;
pub mod weave;
pub mod yarn;

use std::path::PathBuf;

pub use mesh::Mesh;
pub use params::Params;
pub use weave::{Pattern, WovenParams};
pub use yarn::{Cloth, Yarn};

/// Errors of the swatch crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Arguments that make no swatch (sizes, counts).
    #[error("{0}")]
    Invalid(String),
    /// A generator name that is not builtin.
    #[error("unknown builtin swatch {name:?}; available: {available}")]
    UnknownSwatch {
        /// The name as given.
        name: String,
        /// The builtin names, in words.
        available: String,
    },
    /// A spec that does not parse as `NAME[?k=v&…]`.
    #[error("swatch spec {spec:?}: {reason}")]
    BadSpec {
        /// The spec as given.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A parameter value out of its range.
    #[error("{swatch}: parameter {name} = {value} is out of range; allowed: {allowed}")]
    InvalidParameter {
        /// The generator, e.g. `twill`.
        swatch: String,
        /// The parameter, e.g. `spacing`.
        name: String,
        /// The value as given.
        value: String,
        /// The allowed range or values in words.
        allowed: String,
    },
    /// A parameter the generator does not have.
    #[error("{swatch}: unknown parameter {name:?}; parameters of this swatch: {known}")]
    UnknownParameter {
        /// The generator, e.g. `twill`.
        swatch: String,
        /// The parameter as given.
        name: String,
        /// The parameters the generator has, in words.
        known: String,
    },
    /// A malformed draft; `line` 0 means the section as a whole (e.g. missing).
    #[error("{source_name}: [{section}]{}: {reason}", line_text(.line))]
    Draft {
        /// Where the draft came from (its file), for messages.
        source_name: String,
        /// The section, e.g. `THREADING`.
        section: String,
        /// 1-based line in the section, 0 for the section as a whole.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Parameters whose yarns would pass through each other.
    #[error(
        "{swatch}: yarns overlap (gap {gap:.3e} between yarns {a} and {b} near {at:?}); {hint}"
    )]
    Overlap {
        /// The generator spec.
        swatch: String,
        /// The measured gap, user units (negative: overlap depth).
        gap: f64,
        /// Index of the first yarn.
        a: usize,
        /// Index of the second yarn.
        b: usize,
        /// Where they meet, swatch frame.
        at: [f64; 3],
        /// Which parameter to change, in words.
        hint: String,
    },
    /// An OBJ file that is not a mesh (see [`obj::parse_obj`]).
    #[error("reading {path}: {reason}")]
    InvalidMesh {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line number where there is one.
        reason: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
}

/// The swatches crate's result type.
pub type Result<T> = std::result::Result<T, Error>;

/// The builtin generators, for help texts and error messages.
pub const NAMES: &[(&str, &str)] = &[
    ("plain-weave", "plain weave; spacing, width, height, crimp, flat, segments, along"),
    ("twill", "n/m twill; n, m, dir=z|s, and the plain-weave parameters"),
    ("satin", "n-end satin; n, step (coprime to n), face=warp|weft, and the plain-weave parameters"),
    ("basket", "basket weave; n, and the plain-weave parameters"),
    ("draft", "a weave draft; path=FILE (WIF 1.1 or 0/1 grid), and the plain-weave parameters"),
    ("grid", "a 0/1 interlacement grid inline; rows=1010/0101 (1 = warp over), and the plain-weave parameters"),
    ("jersey", "stockinette (plain) knit; wale, a, h, d, row, radius, wales, courses, segments, along"),
    ("rib", "k×k rib knit; k, and the jersey parameters"),
    ("velvet", "leaning pile tufts on a plain ground weave; density, pile, radius, tilt, seed, repeat, rings, and the plain-weave parameters for the ground"),
    ("terry", "pile loops on a plain ground weave; density, pile, loop, radius, seed, repeat, rings, and the plain-weave parameters for the ground"),
    ("corduroy", "parallel round wales on a ground slab; spacing, radius, slab, segments, along"),
];

/// A builtin swatch by spec `NAME[?k=v&...]`, e.g. `plain-weave` or `twill?n=2&m=1`.
pub fn builtin(spec: &str) -> Result<Mesh> {
    build(spec).map(|s| s.mesh)
}

/// A generated swatch: its mesh, the yarns it was swept from and their closest approach.
#[derive(Clone, Debug)]
pub struct Swatch {
    /// Canonical generator name (`plain-weave`, `jersey`, ...).
    pub name: String,
    /// The triangle mesh of one tile.
    pub mesh: Mesh,
    /// The yarns it was swept from (and any non-yarn parts).
    pub cloth: Cloth,
    /// The yarns' closest approach (negative gap: overlap).
    pub clearance: yarn::Clearance,
    /// Per triangle of `mesh`, its material: an index into `material_names`.
    pub materials: Vec<u32>,
    /// What the yarns are, for an artist's id map and masks: `warp`, `weft` (weaves and the
    /// ground of pile cloth), `loop` (knits, terry's loops), `pile` (velvet's tufts), `wale`
    /// (corduroy), `ground` (non-yarn geometry), in order of first appearance.
    pub material_names: Vec<String>,
}

/// [`builtin`], keeping the yarns and the clearance (for reports and tests).
pub fn build(spec: &str) -> Result<Swatch> {
    let (name, params) = params::parse_spec(spec)?;
    generate(&name, &params)
}

/// A builtin swatch by name and parameters. Refuses unknown names, unknown parameters, values
/// out of range and parameter sets whose yarns would overlap.
pub fn generate(name: &str, p: &Params) -> Result<Swatch> {
    let canonical = match name {
        "plain" | "plain-weave" => "plain-weave",
        "stockinette" | "jersey" => "jersey",
        other => other,
    };
    let (cloth, segments) = match canonical {
        "plain-weave" | "twill" | "satin" | "basket" | "draft" | "grid" => {
            let pattern = match canonical {
                "plain-weave" => Pattern::plain(),
                "twill" => {
                    let n = p.int("n", 2, 1, 32)? as usize;
                    let m = p.int("m", 1, 1, 32)? as usize;
                    let z = p.choice("dir", "z", &["z", "s"])? == "z";
                    Pattern::twill(n, m, z)
                }
                "satin" => {
                    let n = p.int("n", 5, 5, 64)? as usize;
                    let step = p.int("step", 2, 2, n as i64 - 2)? as usize;
                    if gcd(n, step) != 1 {
                        return Err(p.invalid(
                            "step",
                            step,
                            format!("an integer in [2, {}] coprime to n = {n}", n - 2),
                        ));
                    }
                    let satin = Pattern::satin(n, step);
                    match p.choice("face", "warp", &["warp", "weft"])? {
                        "warp" => satin,
                        _ => satin.inverted(),
                    }
                }
                "basket" => Pattern::basket(p.int("n", 2, 1, 32)? as usize),
                "draft" => {
                    let path = p.text("path").ok_or_else(|| {
                        p.invalid("path", "(missing)", "the path of a WIF or 0/1 grid file")
                    })?;
                    draft::read(std::path::Path::new(&path))?
                }
                _ => {
                    let rows = p.text("rows").ok_or_else(|| {
                        p.invalid(
                            "rows",
                            "(missing)",
                            "rows of 0/1 separated by '/', e.g. 10/01",
                        )
                    })?;
                    draft::parse_grid(&rows.replace('/', "\n"), "rows")?
                }
            };
            let wp = WovenParams::from_params(p)?;
            (weave::woven(&weave::checked(pattern)?, &wp), wp.segments)
        }
        "jersey" | "rib" => knit::from_params(canonical, p)?,
        "velvet" | "terry" => pile::from_params(canonical, p)?,
        "corduroy" => pile::corduroy(p)?,
        _ => {
            return Err(Error::UnknownSwatch {
                name: name.to_string(),
                available: NAMES.iter().map(|n| n.0).collect::<Vec<_>>().join(", "),
            })
        }
    };
    p.finish()?;
    let clearance = check_clearance(canonical, &cloth)?;
    let (mesh, parts) = cloth.mesh_parts(segments);
    let (materials, material_names) = materials(canonical, &cloth, &parts);
    Ok(Swatch {
        name: canonical.to_string(),
        mesh,
        cloth,
        clearance,
        materials,
        material_names,
    })
}

/// What each part of a generated cloth is, by generator and how its yarn runs: a yarn that
/// crosses the tile along y is a warp, along x a weft (a knit's course: `loop`), a capped one
/// a pile tuft (`pile`, or terry's `loop`); the non-yarn geometry is the `ground`. Returns the
/// material of each triangle (`parts`: its yarn, or `yarns.len()` for the ground) and the names.
fn materials(generator: &str, cloth: &Cloth, parts: &[u32]) -> (Vec<u32>, Vec<String>) {
    let kind = |part: u32| -> &'static str {
        let Some(y) = cloth.yarns.get(part as usize) else {
            return "ground";
        };
        match (generator, &y.ends) {
            ("corduroy", _) => "wale",
            ("jersey" | "rib", _) => "loop",
            ("terry", yarn::Ends::Capped) => "loop",
            (_, yarn::Ends::Capped) => "pile",
            (_, yarn::Ends::Periodic { shift }) if shift[1] != 0.0 => "warp",
            (_, yarn::Ends::Periodic { .. }) => "weft",
        }
    };
    let mut present = vec![false; cloth.yarns.len() + 1];
    for &p in parts {
        present[p as usize] = true;
    }
    let mut names: Vec<String> = Vec::new();
    let mut of_part: Vec<u32> = Vec::new();
    for part in 0..=cloth.yarns.len() as u32 {
        let k = kind(part);
        let i = match names.iter().position(|n| n == k) {
            Some(i) => i,
            None if present[part as usize] => {
                names.push(k.to_string());
                names.len() - 1
            }
            None => 0,
        };
        of_part.push(i as u32);
    }
    (parts.iter().map(|&p| of_part[p as usize]).collect(), names)
}

/// The cloth's clearance, or an error when its yarns overlap (beyond rounding: 1e-9 of the
/// tile).
pub fn check_clearance(swatch: &str, cloth: &Cloth) -> Result<yarn::Clearance> {
    let c = cloth.clearance();
    if c.gap < -1e-9 * cloth.tile[0].max(cloth.tile[1]) {
        return Err(Error::Overlap {
            swatch: swatch.to_string(),
            gap: c.gap,
            a: c.yarns.0,
            b: c.yarns.1,
            at: c.at,
            hint: match swatch {
                "jersey" | "rib" => {
                    "use a thinner yarn (radius), deeper loops (d) or a larger course spacing (row)"
                }
                "velvet" | "terry" => "make the ground yarns thinner or raise the crimp",
                _ => "make the yarns thinner or further apart, or raise the crimp",
            }
            .to_string(),
        });
    }
    Ok(c)
}

fn line_text(line: &usize) -> String {
    if *line == 0 {
        String::new()
    } else {
        format!(" line {line}")
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}
