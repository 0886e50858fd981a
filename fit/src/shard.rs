//! Farm bakes: the partition of a bake into shards of texel rows (`shard/partition.rs`), the
//! part file one shard writes (here), and the merge of all parts into exactly the file one
//! machine would have written (`shard/merge.rs`). Their public items are all named from here,
//! `ptm_fit::shard::…`.
//!
//! A shard is a block of whole image rows, starting at a multiple of [`ROW_BLOCK`] (the
//! tracer's 4×4 texel blocks). Sample positions hash the global texel index and the streaming
//! fit is per texel, so a shard's rows are bit-identical to the same rows of a whole bake; the
//! merge concatenates them and recomputes what is file-level (error statistics, coverage
//! channel presence) from the per-texel maps the parts carry.
//!
//! Part layout (docs/FORMAT.md, "Part files"): a single-part EXR of width × (rows of the
//! shard), the channels of the final file for those rows (plus `err.rms` and `coverage` for a
//! PTM part), and `part:*` attributes: version, kind, shard index and count, rows, full size,
//! the bake's settings, the swatch's content hash, the writing software and a CRC-32 of the
//! decoded content. Parts are written atomically, so a killed task leaves no part at all.
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use exr::meta::attribute::AttributeValue;

use crate::solve::LogisticStats;
use crate::{Error, FitReport, Result, SampleStack, Weight};
use partition::local_levels;
use ptm_format::exrio::{self, Attr};
use ptm_format::ptm::channel_name;
use ptm_format::{Basis, LightSet, Link, Ptm, UvMap};

mod chunks;
mod identity;
mod merge;
pub(crate) mod partition;
mod write;

pub use identity::BakeIdentity;
pub use merge::{check_set, merge_encode, merge_into, parts_in, Merged};
pub use partition::{PartLevels, Shard, ROW_BLOCK};
pub use write::{write_ptm_part, write_rows_part, write_stack_part};

/// How the parts of one product of a bake (its `part:kind`) join into the file one machine
/// writes. A new product chooses one here; the merge dispatches on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MergeRule {
    /// The sample stack: the parts' compressed chunks copied under the whole image's header.
    CopyChunks,
    /// The PTM: rows decoded and concatenated, the file-level facts (error statistics,
    /// coverage, MIP levels) recomputed from the per-texel maps the parts carry.
    Refit,
    /// Per-texel maps with no file-level figure (the companion maps): rows concatenated and
    /// the product's own attributes, equal in every part, kept.
    ConcatRows,
}

impl MergeRule {
    /// The rule of the parts of kind `kind` (`stack`, `ptm`, `maps`), or none for a kind this
    /// version does not know.
    pub fn of(kind: &str) -> Option<MergeRule> {
        match kind {
            "stack" => Some(MergeRule::CopyChunks),
            "ptm" => Some(MergeRule::Refit),
            "maps" => Some(MergeRule::ConcatRows),
            _ => None,
        }
    }
}

/// Value of `part:version`.
pub const PART_VERSION: &str = "ptm-part/1";

/// 64-bit FNV-1a of byte chunks, as 16 hex digits: a content fingerprint (of a swatch, a light
/// set), not a security hash.
pub fn fingerprint<'a>(chunks: impl IntoIterator<Item = &'a [u8]>) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for c in chunks {
        for &b in c {
            h = (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    format!("{h:016x}")
}

/// What identifies a part: which shard, and of which bake.
#[derive(Clone, Debug, PartialEq)]
pub struct PartMeta {
    /// Which shard of how many this part is.
    pub shard: Shard,
    /// Rows of the full image this part holds.
    pub rows: Range<usize>,
    /// Size of the full image (texels per row, rows).
    pub width: usize,
    /// Rows of the full image.
    pub height: usize,
    /// Every setting of the full bake that changes its output, in words (equal for all parts).
    pub settings: String,
    /// Content hash of the swatch (see [`fingerprint`]).
    pub swatch: String,
    /// Writing software and version, e.g. `ptm 0.1.0`.
    pub software: String,
}

/// The fit's file-level facts that do not depend on texels (the same in every part) and the
/// per-texel maps the merge recomputes statistics from.
#[derive(Clone, Debug)]
pub struct PtmPart {
    /// The part's rows of the fitted PTM (no MIP levels).
    pub ptm: Ptm,
    /// Light count, lights in the fit, solver, rank, condition, light-set warnings; `rms_map`
    /// holds the part's rows.
    pub fit: FitReport,
    /// Coverage of the part's rows (always stored, also where it is all 1).
    pub coverage: Vec<f32>,
    /// The light set of the bake, equal in every part.
    pub lights: LightSet,
    /// The whole bake's PTM carries MIP levels. Identity link: the merge computes them all
    /// from the merged coefficients (coverage-weighted box averages, as `Accumulator::finish`).
    /// Logistic link: see `levels`.
    pub mips: bool,
    /// Logistic link: the MIP levels of the part's rows fitted by the part, and the pooled
    /// counts the merge fits the deeper levels from (`local_levels`). Empty otherwise.
    pub levels: PartLevels,
}

/// A part's content: rows of a sample stack, or rows of a PTM with its fit facts.
#[derive(Clone, Debug)]
pub enum PartData {
    /// Rows of a sample stack.
    Stack(SampleStack),
    /// Rows of a PTM with the fit's facts.
    Ptm(Box<PtmPart>),
}

/// A part read and checked.
#[derive(Clone, Debug)]
pub struct Part {
    /// The part file, for messages.
    pub path: PathBuf,
    /// Which shard of which bake it holds.
    pub meta: PartMeta,
    /// Its rows.
    pub data: PartData,
}

/// Reads a part's bytes and checks them: its header and chunk table lie inside the file and
/// the checksum matches. Errors name the file and say what to do.
fn verify(path: &Path) -> Result<(Vec<u8>, chunks::Layout)> {
    let bytes = std::fs::read(path).map_err(|e| Error::Io {
        path: path.display().to_string(),
        source: e,
    })?;
    let layout = chunks::Layout::parse(&bytes).ok_or_else(|| {
        err(path, "truncated or damaged (its header or chunk table is cut short): delete it and rerun its shard")
    })?;
    let stored = layout
        .value("part:checksum")
        .map(|v| String::from_utf8_lossy(&bytes[v]).into_owned())
        .ok_or_else(|| err(path, "not a sealed ptm part (no `part:checksum`)"))?;
    let found = chunks::crc_without(&bytes, &layout, "part:checksum")
        .map(|c| format!("crc32:{c:08x}"))
        .unwrap_or_default();
    if found != stored {
        return Err(err(
            path,
            format!(
                "checksum mismatch (stored {stored}, content {found}): the part is damaged or \
                 incomplete; delete it and rerun its shard"
            ),
        ));
    }
    Ok((bytes, layout))
}

/// Checks a part without decoding its pixels (layout and checksum) and returns its identity.
pub fn check_part(path: &Path) -> Result<PartMeta> {
    verify(path)?;
    Ok(read_meta(path)?.0)
}

fn err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Format {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// Header attributes of a part, without decoding its pixels.
fn read_header(path: &Path) -> Result<BTreeMap<String, Attr>> {
    if let Err(e) = std::fs::metadata(path) {
        return Err(Error::Io {
            path: path.display().to_string(),
            source: e,
        });
    }
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| {
        err(
            path,
            format!("not a readable OpenEXR file (truncated?): {e}"),
        )
    })?;
    let mut out = BTreeMap::new();
    for h in &meta.headers {
        for (name, value) in h
            .own_attributes
            .other
            .iter()
            .chain(&h.shared_attributes.other)
        {
            let a = match value {
                AttributeValue::Text(t) => Attr::Text(exrio::decode_text(t)),
                AttributeValue::TextVector(v) => {
                    Attr::Texts(v.iter().map(exrio::decode_text).collect())
                }
                AttributeValue::F64(x) => Attr::F64(*x),
                AttributeValue::I32(x) => Attr::I32(*x),
                _ => continue,
            };
            out.insert(exrio::decode_text(name), a);
        }
    }
    Ok(out)
}

fn meta_from(path: &Path, attrs: &BTreeMap<String, Attr>) -> Result<(PartMeta, String)> {
    let text = |k: &str| match attrs.get(k) {
        Some(Attr::Text(s)) => Ok(s.clone()),
        _ => Err(err(path, format!("part lacks the text attribute `{k}`"))),
    };
    let int = |k: &str| match attrs.get(k) {
        Some(Attr::I32(x)) if *x >= 0 => Ok(*x as usize),
        _ => Err(err(path, format!("part lacks the integer attribute `{k}`"))),
    };
    match attrs.get("part:version") {
        Some(Attr::Text(v)) if v == PART_VERSION => {}
        Some(Attr::Text(v)) => {
            return Err(err(
                path,
                format!("part version {v:?} is not supported (expected {PART_VERSION:?})"),
            ))
        }
        _ => {
            return Err(Error::NotAPart {
                path: path.display().to_string(),
            })
        }
    }
    let meta = PartMeta {
        shard: Shard {
            index: int("part:index")?,
            count: int("part:count")?,
        },
        rows: int("part:rowStart")?..int("part:rowEnd")?,
        width: int("part:width")?,
        height: int("part:height")?,
        settings: text("part:settings")?,
        swatch: text("part:swatch")?,
        software: text("part:software")?,
    };
    let kind = text("part:kind")?;
    Ok((meta, kind))
}

/// Reads a part's identity (header only; cheap).
pub fn read_meta(path: &Path) -> Result<(PartMeta, String)> {
    meta_from(path, &read_header(path)?)
}

/// Reads and checks a whole part: every channel decodes and the checksum matches.
pub fn read_part(path: &Path) -> Result<Part> {
    verify(path)?;
    let mut c = exrio::read(path)?;
    let attrs: BTreeMap<String, Attr> = c.attrs.clone().into_iter().collect();
    let (meta, kind) = meta_from(path, &attrs)?;
    const WHAT: &str = "part";
    if c.width != meta.width || c.height != meta.rows.len() {
        return Err(c.error(format!(
            "holds {}×{} texels but names rows {}..{} of a {}-wide image",
            c.width, c.height, meta.rows.start, meta.rows.end, meta.width
        )));
    }
    let dir_text = c.texts("part:lightDirs", WHAT)?;
    let mut dirs = Vec::with_capacity(dir_text.len());
    for s in &dir_text {
        let v: Vec<f64> = s
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect();
        if v.len() != 3 {
            return Err(c.error(format!("light direction {s:?} is not `x y z`")));
        }
        dirs.push([v[0], v[1], v[2]]);
    }
    let lights = LightSet {
        names: c.texts("part:lightNames", WHAT)?,
        dirs,
    };
    let tile = [c.f64("part:tileW", WHAT)?, c.f64("part:tileH", WHAT)?];
    let data = match kind.as_str() {
        "stack" => {
            let per_texel = c.text("part:uv", WHAT)? == "per-texel";
            let (k, coverage, uv) =
                crate::stack::take_planes(&mut c, lights.len(), per_texel, WHAT)?;
            PartData::Stack(SampleStack {
                width: c.width,
                height: c.height,
                tile,
                lights,
                k,
                coverage,
                uv,
            })
        }
        "ptm" => {
            let name = c.text("part:basis", WHAT)?;
            let basis = Basis::from_name(&name)
                .ok_or_else(|| c.error::<Error>(format!("unknown basis {name:?}")))?;
            let mut planes = Vec::with_capacity(basis.len());
            for m in basis.monomials() {
                planes.push(c.take_f32(&channel_name(m.name), WHAT)?);
            }
            let fit = FitReport {
                basis: Some(basis),
                lights: c.f64("part:nLights", WHAT)? as usize,
                lights_fit: c.f64("part:nLightsFit", WHAT)? as usize,
                solver: c.text("part:solver", WHAT)?,
                rank: c.f64("part:rank", WHAT)? as usize,
                cond: c.f64("part:cond", WHAT).unwrap_or(f64::INFINITY),
                warnings: (c.texts("part:warnings", WHAT).unwrap_or_default())
                    .into_iter()
                    .map(crate::Diagnostic::Recorded)
                    .collect(),
                rms_map: c.take_f32("err.rms", WHAT)?,
                ..FitReport::default()
            };
            let mut fit = fit;
            let coverage = c.take_f32("coverage", WHAT)?;
            let link = c.text("part:link", WHAT)?;
            let link = Link::from_name(&link)
                .ok_or_else(|| c.error::<Error>(format!("unknown link {link:?}")))?;
            let uv = c.text("part:uv", WHAT)?;
            let uv = UvMap::from_name(&uv)
                .ok_or_else(|| c.error::<Error>(format!("unknown uv map {uv:?}")))?;
            let mips = c.f64("part:mips", WHAT)? != 0.0;
            let levels = if link == Link::Logistic {
                read_logistic(&mut c, &meta, basis, mips, lights.len(), &mut fit)?
            } else {
                PartLevels::default()
            };
            let learned = if basis.is_learned() {
                let (table, stats) = read_learned(&c, basis.len())?;
                fit.learned = Some(stats);
                Some(table)
            } else {
                None
            };
            let ptm = Ptm {
                basis,
                link,
                uv,
                width: c.width,
                height: c.height,
                tile,
                planes,
                mips: Vec::new(),
                coverage: None, // the merge's `finish_fit` sets the whole image's
                learned,
            };
            PartData::Ptm(Box::new(PtmPart {
                ptm,
                fit,
                coverage,
                lights,
                mips,
                levels,
            }))
        }
        other => return Err(c.error(format!("unknown part kind {other:?}"))),
    };
    Ok(Part {
        path: path.to_path_buf(),
        meta,
        data,
    })
}

/// A learned part's tables (the PTM file's `ptm:learnedGrid` and `ptm:learnedTable`) and the
/// statistics of their learning (`part:learned*`), checked for `terms` terms.
fn read_learned(
    c: &exrio::Contents,
    terms: usize,
) -> Result<(ptm_format::LearnedTable, crate::solve::LearnedStats)> {
    const WHAT: &str = "part";
    use ptm_format::learned::{GRID_ATTR, TABLE_ATTR};
    let grid = c.f64(GRID_ATTR, WHAT)?;
    let mut values = Vec::new();
    for text in c.texts(TABLE_ATTR, WHAT)? {
        for v in text.split_whitespace() {
            values.push(v.parse::<f32>().map_err(|_| {
                c.error::<Error>(format!("`{TABLE_ATTR}` holds {v:?}, not a number"))
            })?);
        }
    }
    let table = ptm_format::LearnedTable {
        grid: grid.max(0.0) as usize,
        terms,
        values,
    };
    table
        .check(terms, &format!("{}: `{TABLE_ATTR}`", c.path))
        .map_err(Error::Invalid)?;
    let num = |k: &str| c.f64(k, WHAT);
    let stats = crate::solve::LearnedStats {
        terms,
        grid: table.grid,
        roughness: num("part:learnedRoughness")?,
        texels: num("part:learnedTexels")? as usize,
        alternations: num("part:learnedAlternations")? as u32,
        kept: num("part:learnedKept")? as u32,
        deviance_start: num("part:learnedDevianceStart")?,
        deviance: num("part:learnedDeviance")?,
        rms_start: num("part:learnedRmsStart")?,
        rms: num("part:learnedRms")?,
        seconds: num("part:learnedSeconds")?,
    };
    Ok((table, stats))
}

/// Takes `len` flat values from the channels `name.0000`, `name.0001`, … (see [`packed`]).
fn unpacked(c: &mut exrio::Contents, name: &str, len: usize, what: &str) -> Result<Vec<f32>> {
    let n = c.width * c.height;
    let mut out = Vec::with_capacity(len);
    for i in 0..len.div_ceil(n.max(1)) {
        out.extend(c.take_f32(&format!("{name}.{i:04}"), what)?);
    }
    out.truncate(len);
    Ok(out)
}

/// The logistic part's max-residual map, statistics, options, MIP levels and pooled counts
/// (what [`logistic_channels`] wrote).
fn read_logistic(
    c: &mut exrio::Contents,
    meta: &PartMeta,
    basis: Basis,
    mips: bool,
    lights: usize,
    fit: &mut FitReport,
) -> Result<PartLevels> {
    const WHAT: &str = "part";
    let int =
        |c: &exrio::Contents, k: &str| -> Result<usize> { Ok(c.f64(k, WHAT)?.max(0.0) as usize) };
    fit.max_map = c.take_f32("err.max", WHAT)?;
    fit.rcond = c.f64("part:rcond", WHAT)?;
    let kernel = c.text("part:kernel", WHAT)?;
    let kernel = crate::simd::Isa::from_name(&kernel)
        .ok_or_else(|| c.error::<Error>(format!("unknown logistic kernel {kernel:?}")))?;
    fit.logistic = Some(LogisticStats {
        iterations_mean: 0.0, // the merge divides the summed iterations
        iterations_total: c.f64("part:iterations", WHAT)? as u64,
        iterations_max: int(c, "part:iterationsMax")? as u32,
        not_converged: int(c, "part:notConverged")?,
        separable: int(c, "part:separable")?,
        constant: int(c, "part:constant")?,
        lambda: c.f64("part:lambda", WHAT)?,
        ridge: c.f64("part:ridge", WHAT)?,
        tolerance: c.f64("part:tolerance", WHAT)?,
        max_iterations: int(c, "part:maxIterations")? as u32,
        kernel: kernel.name(),
    });
    let weight = match c.text("part:weight", WHAT)?.as_str() {
        "uniform" => Weight::Uniform,
        "cosine" => Weight::Cosine,
        w => return Err(c.error(format!("unknown light weighting {w:?}"))),
    };
    let mut out = PartLevels {
        weight,
        ..PartLevels::default()
    };
    if !mips {
        return Ok(out);
    }
    let (local, deeper) = local_levels(meta.width, meta.height, meta.rows.clone());
    let texels: usize = local.iter().map(|f| f.width * f.height).sum();
    let mut planes = Vec::with_capacity(basis.len());
    for m in basis.monomials() {
        planes.push(unpacked(c, &format!("mip.{}", m.name), texels, WHAT)?);
    }
    let mut at = 0;
    for f in &local {
        let n = f.width * f.height;
        out.levels.push(ptm_format::Level {
            width: f.width,
            height: f.height,
            planes: planes.iter().map(|p| p[at..at + n].to_vec()).collect(),
        });
        at += n;
    }
    if deeper {
        let s = local.last().map_or(0, |f| f.width * f.height);
        let flat = unpacked(c, "pool", s * (lights + 1), WHAT)?;
        let mut it = flat
            .chunks(s.max(1))
            .map(|v| v.iter().map(|&x| x as u32).collect());
        let cov: Vec<u32> = if s == 0 {
            Vec::new()
        } else {
            it.next().unwrap_or_default()
        };
        let occ: Vec<Vec<u32>> = if s == 0 {
            vec![Vec::new(); lights]
        } else {
            it.collect()
        };
        out.counts = Some((cov, occ));
    }
    Ok(out)
}
