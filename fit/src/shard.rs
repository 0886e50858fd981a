//! Farm bakes: the partition of a bake into shards of texel rows, the part file one shard
//! writes, and the merge of all parts into exactly the file one machine would have written.
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
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use exr::meta::attribute::AttributeValue;

use crate::solve::LogisticStats;
use crate::stack::k_channel;
use crate::{Error, ErrorStats, FitReport, Result, SampleStack, Weight};
use ptm_format::exrio::{self, Attr, Samples};
use ptm_format::ptm::channel_name;
use ptm_format::{Basis, LightSet, Link, Ptm, UvMap};

mod chunks;

/// Value of `part:version`.
pub const PART_VERSION: &str = "ptm-part/1";

/// Shards start at multiples of this many rows: the 16 scanlines of an OpenEXR ZIP chunk (so
/// a stack merges by copying compressed chunks), a multiple of the tracer's 4×4 texel blocks.
pub const ROW_BLOCK: usize = 16;

/// Shard `index` of `count` (0-based), as `--shard I/N` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, 0-based, below `count`.
    pub index: usize,
    /// How many shards the bake is split into.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// Parses `I/N` with 0 ≤ I < N.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = |why: &str| format!("{s:?}: {why} (expected I/N with 0 <= I < N, e.g. 0/4)");
        let (i, n) = s.split_once('/').ok_or_else(|| bad("no `/`"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| bad(&format!("shard index {i:?} is not a whole number >= 0")))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| bad(&format!("shard count {n:?} is not a whole number >= 1")))?;
        if count == 0 {
            return Err(bad("the shard count must be at least 1"));
        }
        if index >= count {
            return Err(bad(&format!(
                "shard index {index} is out of range: shards of {count} are numbered 0 to {}",
                count - 1
            )));
        }
        Ok(Shard { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// Image rows of this shard in a bake of `height` rows: blocks of [`ROW_BLOCK`] rows split
    /// as evenly as whole blocks allow (shard i gets blocks ⌊i·B/N⌋ … ⌊(i+1)·B/N⌋). An error
    /// when there are fewer blocks than shards (a shard would be empty).
    pub fn rows(&self, height: usize) -> Result<Range<usize>> {
        let blocks = height.div_ceil(ROW_BLOCK);
        if self.count > blocks {
            return Err(Error::TooManyShards {
                shard: *self,
                rows: height,
                blocks,
            });
        }
        let at = |i: usize| (i * blocks / self.count * ROW_BLOCK).min(height);
        Ok(at(self.index)..at(self.index + 1))
    }

    /// The part file of this shard for final output `out`: `samples.exr` →
    /// `samples.part-0002-of-0004.exr`, `weave.ptm.exr` → `weave.ptm.part-0002-of-0004.exr`.
    pub fn part_path(&self, out: &Path) -> PathBuf {
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem = name.strip_suffix(".exr").unwrap_or(&name);
        out.with_file_name(format!(
            "{stem}.part-{:04}-of-{:04}.exr",
            self.index, self.count
        ))
    }
}

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

/// A logistic part's share of the MIP chain. A coarse texel is fitted to the pooled counts of
/// its footprint; the levels whose footprints span at most [`ROW_BLOCK`] rows lie inside one
/// shard, so the part fits them for its rows exactly as a whole bake does. The deeper levels'
/// footprints cross shard borders: the part carries the pooled counts of its last level
/// (1/256 of level 0's texels, exact), and the merge joins them and fits the rest.
#[derive(Clone, Debug, PartialEq)]
pub struct PartLevels {
    /// Levels 1 … S for the part's rows (sizes from `local_levels`).
    pub levels: Vec<ptm_format::Level>,
    /// Pooled counts of level S for the part's rows, when the chain goes deeper:
    /// (covered samples per texel, occluded samples `[light][texel]`).
    pub counts: Option<(Vec<u32>, Vec<Vec<u32>>)>,
    /// The fit's light weighting (the merge rebuilds the fit's tables with it).
    pub weight: crate::Weight,
}

impl Default for PartLevels {
    fn default() -> Self {
        PartLevels {
            levels: Vec::new(),
            counts: None,
            weight: Weight::Uniform,
        }
    }
}

/// The MIP levels below level 0 whose every texel pools rows of one [`ROW_BLOCK`] only, for
/// rows `rows` (a shard's: starting at a multiple of [`ROW_BLOCK`]) of an image
/// `width × height`: per level, its footprint restricted to those rows (the whole level's
/// width, the rows of the level that pool them, the pooling factors); and whether the chain
/// goes deeper (levels whose footprints cross shard borders, left to the merge).
pub(crate) fn local_levels(
    width: usize,
    height: usize,
    rows: Range<usize>,
) -> (Vec<crate::logistic::Footprint>, bool) {
    let chain = crate::logistic::Footprint::chain(width, height);
    let mut span = 1;
    let mut out = Vec::new();
    for fp in &chain[1..] {
        span *= fp.fy;
        if !ROW_BLOCK.is_multiple_of(span) {
            return (out, true);
        }
        // rows.start is a multiple of the span: level rows [start/span, end/span).
        let local = (rows.end / span)
            .min(fp.height)
            .saturating_sub(rows.start / span);
        out.push(crate::logistic::Footprint {
            height: local,
            ..*fp
        });
    }
    (out, false)
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

/// What [`merge_into`] wrote (or [`merge_encode`] encoded).
#[derive(Clone, Debug)]
pub struct Merged {
    /// `"stack"` or `"ptm"`.
    pub kind: String,
    /// Texels per row of the merged file.
    pub width: usize,
    /// Rows of the merged file.
    pub height: usize,
    /// Its light set.
    pub lights: LightSet,
}

fn light_attrs(lights: &LightSet) -> [(&'static str, Attr); 2] {
    let dirs = lights
        .dirs
        .iter()
        .map(|d| format!("{:e} {:e} {:e}", d[0], d[1], d[2]))
        .collect();
    [
        ("part:lightDirs", Attr::Texts(dirs)),
        ("part:lightNames", Attr::Texts(lights.names.clone())),
    ]
}

/// Stands in for the checksum while the part is encoded (the same length as the real one).
const UNSEALED: &str = "crc32:00000000";

/// Writes a part atomically: encodes it in memory with a placeholder checksum, then writes
/// the bytes with the CRC-32 of everything but the checksum's own value filled in.
fn write_sealed(
    path: &Path,
    width: usize,
    rows: usize,
    channels: Vec<(String, Samples)>,
    mut attrs: Vec<(&'static str, Attr)>,
) -> Result<()> {
    attrs.push(("part:checksum", Attr::Text(UNSEALED.into())));
    let mut bytes = exrio::encode(path, width, rows, channels, attrs)?;
    let unexpected = || err(path, "writing part: unexpected EXR layout");
    let layout = chunks::Layout::parse(&bytes).ok_or_else(unexpected)?;
    let crc = chunks::crc_without(&bytes, &layout, "part:checksum").ok_or_else(unexpected)?;
    let at = layout.value("part:checksum").ok_or_else(unexpected)?;
    bytes[at].copy_from_slice(format!("crc32:{crc:08x}").as_bytes());
    Ok(ptm_format::atomic::write_bytes(path, &bytes)?)
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

fn meta_attrs(m: &PartMeta, kind: &str) -> Vec<(&'static str, Attr)> {
    vec![
        ("part:version", Attr::Text(PART_VERSION.into())),
        ("part:kind", Attr::Text(kind.into())),
        ("part:index", Attr::I32(m.shard.index as i32)),
        ("part:count", Attr::I32(m.shard.count as i32)),
        ("part:rowStart", Attr::I32(m.rows.start as i32)),
        ("part:rowEnd", Attr::I32(m.rows.end as i32)),
        ("part:width", Attr::I32(m.width as i32)),
        ("part:height", Attr::I32(m.height as i32)),
        ("part:settings", Attr::Text(m.settings.clone())),
        ("part:swatch", Attr::Text(m.swatch.clone())),
        ("part:software", Attr::Text(m.software.clone())),
    ]
}

fn check_rows(meta: &PartMeta, width: usize, rows: usize) -> Result<()> {
    if width != meta.width || rows != meta.rows.len() {
        return Err(Error::Invalid(format!(
            "part {}: data of {width}×{rows} texels for rows {}..{} of a {}-wide image",
            meta.shard, meta.rows.start, meta.rows.end, meta.width
        )));
    }
    Ok(())
}

/// Writes the rows of a sample stack as part `path`, atomically.
pub fn write_stack_part(path: &Path, meta: &PartMeta, mut stack: SampleStack) -> Result<()> {
    stack.validate()?;
    check_rows(meta, stack.width, stack.height)?;
    // The stack's own attributes too: the merge copies them into the whole stack's header.
    let mut attrs = stack.header_attrs();
    attrs.extend(meta_attrs(meta, "stack"));
    attrs.extend(light_attrs(&stack.lights));
    let mut channels = Vec::with_capacity(stack.k.len() * 3 + 1);
    for (i, plane) in std::mem::take(&mut stack.k).into_iter().enumerate() {
        channels.push((k_channel(i), Samples::F32(plane)));
    }
    let coverage = std::mem::take(&mut stack.coverage);
    channels.push(("coverage".to_string(), Samples::F32(coverage)));
    if let Some(uv) = &stack.uv {
        for (i, plane) in uv.iter().enumerate() {
            channels.push((
                format!("u.{i:04}"),
                Samples::F32(plane.iter().map(|p| p[0]).collect()),
            ));
            channels.push((
                format!("v.{i:04}"),
                Samples::F32(plane.iter().map(|p| p[1]).collect()),
            ));
        }
    }
    attrs.push(("part:tileW", Attr::F64(stack.tile[0])));
    attrs.push(("part:tileH", Attr::F64(stack.tile[1])));
    attrs.push((
        "part:uv",
        Attr::Text(
            if stack.uv.is_some() {
                "per-texel"
            } else {
                "distant"
            }
            .into(),
        ),
    ));
    write_sealed(path, stack.width, stack.height, channels, attrs)
}

/// Writes the rows of a fitted PTM as part `path`, atomically: coefficients, the per-texel RMS
/// residual and coverage of its rows, and the fit's texel-independent facts.
pub fn write_ptm_part(path: &Path, meta: &PartMeta, part: &PtmPart) -> Result<()> {
    let (ptm, fit) = (&part.ptm, &part.fit);
    ptm.validate()?;
    check_rows(meta, ptm.width, ptm.height)?;
    let n = ptm.width * ptm.height;
    if fit.rms_map.len() != n || part.coverage.len() != n {
        return Err(Error::Invalid(format!(
            "part {}: the RMS and coverage maps must have {n} texels",
            meta.shard
        )));
    }
    if !fit.holdout_lights.is_empty() {
        return Err(Error::Invalid(format!(
            "part {}: a fit with held-out lights cannot be sharded (its held-out error is not              kept per texel)",
            meta.shard
        )));
    }
    let mut channels: Vec<(String, Samples)> = ptm
        .basis
        .monomials()
        .iter()
        .zip(&ptm.planes)
        .map(|(m, p)| (channel_name(m.name), Samples::F32(p.clone())))
        .collect();
    channels.push(("err.rms".into(), Samples::F32(fit.rms_map.clone())));
    channels.push(("coverage".into(), Samples::F32(part.coverage.clone())));
    let mut attrs = meta_attrs(meta, "ptm");
    attrs.extend(light_attrs(&part.lights));
    attrs.extend([
        ("part:tileW", Attr::F64(ptm.tile[0])),
        ("part:tileH", Attr::F64(ptm.tile[1])),
        ("part:basis", Attr::Text(ptm.basis.name().into())),
        ("part:link", Attr::Text(ptm.link.name().into())),
        ("part:uv", Attr::Text(ptm.uv.name().into())),
        ("part:mips", Attr::I32(part.mips as i32)),
        ("part:nLights", Attr::I32(fit.lights as i32)),
        ("part:nLightsFit", Attr::I32(fit.lights_fit as i32)),
        ("part:solver", Attr::Text(fit.solver.clone())),
        ("part:rank", Attr::I32(fit.rank as i32)),
    ]);
    if fit.cond.is_finite() {
        attrs.push(("part:cond", Attr::F64(fit.cond)));
    }
    let mut warnings = &fit.warnings[..];
    if ptm.link == Link::Logistic {
        let Some(stats) = &fit.logistic else {
            return Err(Error::Invalid(format!(
                "part {}: a logistic fit without its statistics",
                meta.shard
            )));
        };
        // The part keeps the light set's warnings; the merge words the data's from the sums.
        let data = crate::solve::logistic_warnings(stats);
        warnings = warnings.strip_suffix(&data[..]).unwrap_or(warnings);
        logistic_channels(meta, part, stats, &mut channels, &mut attrs)?;
    }
    if !warnings.is_empty() {
        let words = crate::diagnostic::words(warnings);
        attrs.push(("part:warnings", Attr::Texts(words)));
    }
    write_sealed(path, ptm.width, ptm.height, channels, attrs)
}

/// Flat values laid out in channels of `n` texels each (the last one padded with zeros): how a
/// part stores data of other sizes than its rows (MIP levels, pooled counts).
fn packed(name: &str, values: &[f32], n: usize) -> Vec<(String, Samples)> {
    values
        .chunks(n)
        .enumerate()
        .map(|(i, c)| {
            let mut v = c.to_vec();
            v.resize(n, 0.0);
            (format!("{name}.{i:04}"), Samples::F32(v))
        })
        .collect()
}

/// The logistic part's extra channels and attributes: the max-residual map, its MIP levels
/// and pooled counts ([`PartLevels`]), the fit's options and iteration sums.
fn logistic_channels(
    meta: &PartMeta,
    part: &PtmPart,
    stats: &LogisticStats,
    channels: &mut Vec<(String, Samples)>,
    attrs: &mut Vec<(&'static str, Attr)>,
) -> Result<()> {
    let (ptm, fit, lv) = (&part.ptm, &part.fit, &part.levels);
    let n = ptm.width * ptm.height;
    let (local, deeper) = local_levels(meta.width, meta.height, meta.rows.clone());
    let want = if part.mips { local.len() } else { 0 };
    let sizes_ok = lv.levels.len() == want
        && lv.levels.iter().zip(&local).all(|(l, f)| {
            (l.width, l.height) == (f.width, f.height)
                && l.planes.len() == ptm.planes.len()
                && l.planes.iter().all(|p| p.len() == f.width * f.height)
        });
    let counts_ok = match (&lv.counts, part.mips && deeper) {
        (None, false) => true,
        (Some((cov, occ)), true) => {
            let s = local.last().map_or(0, |f| f.width * f.height);
            cov.len() == s && occ.len() == part.lights.len() && occ.iter().all(|o| o.len() == s)
        }
        _ => false,
    };
    if fit.max_map.len() != n || !sizes_ok || !counts_ok {
        return Err(Error::Invalid(format!(
            "part {}: the logistic fit's max map, MIP levels or pooled counts do not fit rows              {}..{} of {}×{}",
            meta.shard, meta.rows.start, meta.rows.end, meta.width, meta.height
        )));
    }
    channels.push(("err.max".into(), Samples::F32(fit.max_map.clone())));
    for (j, m) in ptm.basis.monomials().iter().enumerate() {
        let flat: Vec<f32> = lv
            .levels
            .iter()
            .flat_map(|l| l.planes[j].iter().copied())
            .collect();
        channels.extend(packed(&format!("mip.{}", m.name), &flat, n));
    }
    if let Some((cov, occ)) = &lv.counts {
        // Counts of at most 256 texels × 65535 samples: exact in f32 (< 2²⁴).
        let flat: Vec<f32> = cov
            .iter()
            .chain(occ.iter().flatten())
            .map(|&c| c as f32)
            .collect();
        channels.extend(packed("pool", &flat, n));
    }
    attrs.extend([
        ("part:weight", Attr::Text(lv.weight.name().into())),
        ("part:rcond", Attr::F64(fit.rcond)),
        ("part:lambda", Attr::F64(stats.lambda)),
        ("part:ridge", Attr::F64(stats.ridge)),
        ("part:tolerance", Attr::F64(stats.tolerance)),
        ("part:maxIterations", Attr::I32(stats.max_iterations as i32)),
        ("part:kernel", Attr::Text(stats.kernel.into())),
        ("part:iterations", Attr::F64(stats.iterations_total as f64)),
        ("part:iterationsMax", Attr::I32(stats.iterations_max as i32)),
        ("part:notConverged", Attr::I32(stats.not_converged as i32)),
        ("part:separable", Attr::I32(stats.separable as i32)),
        ("part:constant", Attr::I32(stats.constant as i32)),
    ]);
    Ok(())
}

fn err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Format {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// EXR text is Latin-1 bytes (as `exrio` reads it).
fn latin1(t: &exr::meta::attribute::Text) -> String {
    t.bytes().iter().map(|&b| b as char).collect()
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
                AttributeValue::Text(t) => Attr::Text(latin1(t)),
                AttributeValue::TextVector(v) => Attr::Texts(v.iter().map(latin1).collect()),
                AttributeValue::F64(x) => Attr::F64(*x),
                AttributeValue::I32(x) => Attr::I32(*x),
                _ => continue,
            };
            out.insert(latin1(name), a);
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
    let kernel = crate::logistic::Kernel::from_name(&kernel)
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

/// Part files in `dir` (names containing `.part-` and ending in `.exr`), sorted.
pub fn parts_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let io = |e| Error::Io {
        path: dir.display().to_string(),
        source: e,
    };
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).map_err(io)? {
        let p = e.map_err(io)?.path();
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.contains(".part-") && name.ends_with(".exr") {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// Checks that `paths` are exactly the shards 0 … N−1 of one bake (same settings, swatch,
/// software, size, kind; none missing or twice; rows as the partition gives them), reading
/// headers only. Returns the metas in shard order. Errors name the files and both values.
pub fn check_set(paths: &[PathBuf]) -> Result<Vec<(PathBuf, PartMeta)>> {
    if paths.is_empty() {
        return Err(Error::Invalid("no part files to merge".into()));
    }
    let absent: Vec<String> = paths
        .iter()
        .filter(|p| !p.exists())
        .map(|p| p.display().to_string())
        .collect();
    if !absent.is_empty() {
        return Err(Error::Invalid(format!(
            "missing part(s) {} (rerun their shards, then merge again)",
            absent.join(", ")
        )));
    }
    let mut metas = Vec::with_capacity(paths.len());
    for p in paths {
        let (m, kind) = read_meta(p)?;
        metas.push((p.clone(), m, kind));
    }
    let (p0, m0, k0) = metas[0].clone();
    let (m0, k0) = (&m0, &k0);
    for (p, m, k) in &metas[1..] {
        let differ = |what: &str, a: &dyn fmt::Display, b: &dyn fmt::Display| {
            Error::Invalid(format!(
                "{} and {} are parts of different bakes: {what} {a:?} against {b:?}",
                p0.display(),
                p.display(),
                a = a.to_string(),
                b = b.to_string()
            ))
        };
        if m.software != m0.software {
            return Err(differ("software version", &m0.software, &m.software));
        }
        if k != k0 {
            return Err(differ("kind", k0, k));
        }
        if m.settings != m0.settings {
            return Err(differ("settings", &m0.settings, &m.settings));
        }
        if m.swatch != m0.swatch {
            return Err(differ("swatch content hash", &m0.swatch, &m.swatch));
        }
        if (m.width, m.height) != (m0.width, m0.height) {
            return Err(differ(
                "image size",
                &format!("{}x{}", m0.width, m0.height),
                &format!("{}x{}", m.width, m.height),
            ));
        }
        if m.shard.count != m0.shard.count {
            return Err(differ("shard count", &m0.shard.count, &m.shard.count));
        }
    }
    let count = m0.shard.count;
    let mut slots: Vec<Option<(PathBuf, PartMeta)>> = vec![None; count];
    for (p, m, _) in metas {
        let i = m.shard.index;
        if i >= count {
            return Err(err(
                &p,
                format!("shard index {i} of {count} is out of range"),
            ));
        }
        let want = m.shard.rows(m.height)?;
        if m.rows != want {
            return Err(err(
                &p,
                format!(
                    "shard {} holds rows {}..{}, the partition gives {}..{}",
                    m.shard, m.rows.start, m.rows.end, want.start, want.end
                ),
            ));
        }
        if let Some((q, _)) = &slots[i] {
            return Err(Error::Invalid(format!(
                "shard {i}/{count} given twice: {} and {}",
                q.display(),
                p.display()
            )));
        }
        slots[i] = Some((p, m));
    }
    let missing: Vec<String> = (0..count)
        .filter(|&i| slots[i].is_none())
        .map(|i| format!("{i}/{count}"))
        .collect();
    if !missing.is_empty() {
        return Err(Error::Invalid(format!(
            "missing shard(s) {} of the bake of {} (rerun them, then merge again)",
            missing.join(", "),
            p0.display()
        )));
    }
    Ok(slots.into_iter().flatten().collect())
}

/// Merges a complete set of parts (see [`check_set`]) into the whole stack or PTM at `out`,
/// written atomically, byte for byte what one machine writes. See [`merge_encode`].
pub fn merge_into(paths: &[PathBuf], out: &Path) -> Result<Merged> {
    let (merged, bytes) = merge_encode(paths, out)?;
    ptm_format::atomic::write_bytes(out, &bytes)?;
    Ok(merged)
}

/// Merges a complete set of parts (see [`check_set`]) into the bytes of the whole stack or PTM
/// that one machine writes, for a caller that publishes it with other outputs (`out` names the
/// file in errors; nothing is written). A stack merges by copying the parts' compressed chunks
/// under the whole image's header; a PTM is decoded, concatenated, its file-level facts
/// recomputed (`finish_fit`) and encoded.
pub fn merge_encode(paths: &[PathBuf], out: &Path) -> Result<(Merged, Vec<u8>)> {
    let set = check_set(paths)?;
    let (_, kind) = read_meta(&set[0].0)?;
    let (width, height) = (set[0].1.width, set[0].1.height);
    let (lights, bytes) = match kind.as_str() {
        "stack" => merge_stack(&set)?,
        "ptm" => {
            let (ptm, fit, lights) = merge_ptm(&set)?;
            let save = ptm_format::SaveOptions {
                half: false,
                report: Some(&fit),
                error_map: false,
            };
            let bytes = ptm.encode(out, &save)?;
            (lights, bytes)
        }
        other => return Err(err(&set[0].0, format!("unknown part kind {other:?}"))),
    };
    let merged = Merged {
        kind,
        width,
        height,
        lights,
    };
    Ok((merged, bytes))
}

/// The light set recorded in a part's header.
fn lights_of(path: &Path, attrs: &BTreeMap<String, Attr>) -> Result<LightSet> {
    let (Some(Attr::Texts(dirs)), Some(Attr::Texts(names))) =
        (attrs.get("part:lightDirs"), attrs.get("part:lightNames"))
    else {
        return Err(err(
            path,
            "part lacks `part:lightDirs` or `part:lightNames`",
        ));
    };
    let mut out = Vec::with_capacity(dirs.len());
    for s in dirs {
        let v: Vec<f64> = s
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect();
        if v.len() != 3 || names.len() != dirs.len() {
            return Err(err(path, format!("light direction {s:?} is not `x y z`")));
        }
        out.push([v[0], v[1], v[2]]);
    }
    Ok(LightSet {
        names: names.clone(),
        dirs: out,
    })
}

/// Whether a header record depends on the part rather than on the whole stack.
fn per_part(name: &str) -> bool {
    name.starts_with("part:") || matches!(name, "dataWindow" | "displayWindow" | "chunkCount")
}

/// The stack merge: every part checked (layout, checksum, chunks of its rows, the same
/// channels and stack attributes), then the first part's header records without `part:*`,
/// sized for the whole image, and every part's chunks at their rows' y.
fn merge_stack(set: &[(PathBuf, PartMeta)]) -> Result<(LightSet, Vec<u8>)> {
    let (width, height) = (set[0].1.width, set[0].1.height);
    let mut parts = Vec::with_capacity(set.len());
    for (path, meta) in set {
        let (bytes, layout) = verify(path)?;
        if meta.rows.start % ROW_BLOCK != 0 || layout.chunks.len() != meta.rows.len().div_ceil(16) {
            return Err(err(
                path,
                format!(
                    "{} chunks for rows {}..{}: not a part of 16-row ZIP chunks",
                    layout.chunks.len(),
                    meta.rows.start,
                    meta.rows.end
                ),
            ));
        }
        parts.push((path, meta, bytes, layout));
    }
    let shared = |bytes: &[u8], layout: &chunks::Layout| -> Vec<Vec<u8>> {
        layout
            .records
            .iter()
            .filter(|r| !per_part(&r.name))
            .map(|r| bytes[r.span.clone()].to_vec())
            .collect()
    };
    let (_, _, bytes0, layout0) = &parts[0];
    let want = shared(bytes0, layout0);
    for (path, _, bytes, layout) in &parts[1..] {
        if shared(bytes, layout) != want || bytes[..8] != bytes0[..8] {
            return Err(err(
                path,
                "its channels or stack attributes differ from the first part's",
            ));
        }
    }
    let (w1, h1) = (width as i32 - 1, height as i32 - 1);
    let n_chunks = height.div_ceil(16) as i32;
    let records: Vec<Vec<u8>> = layout0
        .records
        .iter()
        .filter(|r| !r.name.starts_with("part:"))
        .map(|r| {
            let mut raw = bytes0[r.span.clone()].to_vec();
            let at = r.value.start - r.span.start;
            match r.name.as_str() {
                "dataWindow" | "displayWindow" => {
                    raw[at..at + 16].copy_from_slice(&chunks::box2i(w1, h1))
                }
                "chunkCount" => raw[at..at + 4].copy_from_slice(&n_chunks.to_le_bytes()),
                _ => {}
            }
            raw
        })
        .collect();
    let mut list = Vec::with_capacity(n_chunks as usize);
    for (_, meta, bytes, layout) in &parts {
        for (y, span) in &layout.chunks {
            list.push((y + meta.rows.start as i32, &bytes[span.start + 8..span.end]));
        }
    }
    let file = chunks::assemble(&bytes0[..8], &records, &list);
    Ok((lights_of(&set[0].0, &read_header(&set[0].0)?)?, file))
}

/// The PTM merge: decodes every part, concatenates the rows, recomputes the file-level facts.
fn merge_ptm(set: &[(PathBuf, PartMeta)]) -> Result<(Ptm, FitReport, LightSet)> {
    // Texels of the whole image: the first part's planes are grown to it once, not by doubling.
    let full = set[0].1.width * set[0].1.height;
    let grow = |v: &mut Vec<f32>| v.reserve_exact(full.saturating_sub(v.len()));
    let mut out: Option<(Ptm, FitReport, LightSet)> = None;
    let mut coverage: Vec<f32> = Vec::new();
    let mut mips = false;
    let mut levels = PartLevels::default();
    for (path, _) in set {
        let part = read_part(path)?;
        let PartData::Ptm(p) = part.data else {
            return Err(err(path, "part kinds differ"));
        };
        let mut p = *p;
        match &mut out {
            None => {
                p.ptm.planes.iter_mut().for_each(grow);
                grow(&mut p.fit.rms_map);
                if p.ptm.link == Link::Logistic {
                    grow(&mut p.fit.max_map);
                }
                grow(&mut p.coverage);
                coverage = p.coverage;
                mips = p.mips;
                levels = p.levels;
                out = Some((p.ptm, p.fit, p.lights));
            }
            Some((ptm, fit, lights)) => {
                let same = p.ptm.basis == ptm.basis
                    && (p.ptm.link, p.ptm.uv, p.mips) == (ptm.link, ptm.uv, mips)
                    && p.ptm.tile == ptm.tile
                    && p.lights == *lights
                    && p.fit.solver == fit.solver
                    && (p.fit.lights, p.fit.lights_fit, p.fit.rank)
                        == (fit.lights, fit.lights_fit, fit.rank)
                    && p.fit.cond.to_bits() == fit.cond.to_bits()
                    && p.fit.warnings == fit.warnings
                    && p.levels.weight == levels.weight
                    && p.levels.levels.len() == levels.levels.len()
                    && p.levels.counts.is_some() == levels.counts.is_some();
                if !same {
                    return Err(err(
                        path,
                        "its fit (basis, link, lights, solver, rank, warnings) differs from the first part's",
                    ));
                }
                for (a, b) in ptm.planes.iter_mut().zip(p.ptm.planes) {
                    a.extend(b);
                }
                ptm.height += p.ptm.height;
                fit.rms_map.extend(p.fit.rms_map);
                fit.max_map.extend(p.fit.max_map);
                coverage.extend(p.coverage);
                if let (Some(a), Some(b)) = (&mut fit.logistic, &p.fit.logistic) {
                    a.iterations_total += b.iterations_total;
                    a.iterations_max = a.iterations_max.max(b.iterations_max);
                    a.not_converged += b.not_converged;
                    a.separable += b.separable;
                    a.constant += b.constant;
                }
                // Rows of a level lie in shard order, like level 0's.
                for (a, b) in levels.levels.iter_mut().zip(p.levels.levels) {
                    for (x, y) in a.planes.iter_mut().zip(b.planes) {
                        x.extend(y);
                    }
                    a.height += b.height;
                }
                if let (Some((cov, occ)), Some((c2, o2))) = (&mut levels.counts, p.levels.counts) {
                    cov.extend(c2);
                    for (a, b) in occ.iter_mut().zip(o2) {
                        a.extend(b);
                    }
                }
            }
        }
    }
    let (mut ptm, mut fit, lights) = out.expect("check_set refuses an empty set");
    finish_fit(&mut ptm, &mut fit, coverage, mips, levels, &lights)?;
    Ok((ptm, fit, lights))
}

/// Recomputes the file-level facts of a merged fit from its per-texel maps, as
/// `Accumulator::finish` computes them for a whole bake: statistics, the coverage channel and
/// the MIP levels. The one place a new per-file figure is to be added. Logistic link: the
/// parts' levels joined, the deeper levels fitted from the joined pooled counts, and the
/// iteration statistics (and the warnings they raise) from the parts' sums.
fn finish_fit(
    ptm: &mut Ptm,
    fit: &mut FitReport,
    coverage: Vec<f32>,
    mips: bool,
    levels: PartLevels,
    lights: &LightSet,
) -> Result<()> {
    let masked: Vec<bool> = coverage.iter().map(|&c| c <= 0.0).collect();
    fit.texels = ptm.width * ptm.height;
    fit.masked = masked.iter().filter(|&&m| m).count();
    if ptm.link == Link::Logistic {
        let Some(stats) = fit.logistic.as_mut() else {
            return Err(Error::Invalid(
                "logistic parts without their statistics".into(),
            ));
        };
        stats.iterations_mean =
            stats.iterations_total as f64 / (fit.texels - fit.masked).max(1) as f64;
        let kernel = crate::logistic::Kernel::from_name(stats.kernel)
            .filter(|k| k.supported())
            .unwrap_or_else(crate::logistic::Kernel::detect);
        let opts = crate::FitOptions {
            link: Link::Logistic,
            uv: ptm.uv,
            weight: levels.weight,
            regularize: Some(stats.lambda),
            tolerance: stats.tolerance,
            max_iterations: stats.max_iterations,
            mips,
            kernel: Some(kernel),
            rcond: fit.rcond,
            ..crate::FitOptions::new(ptm.basis)
        };
        let stats = stats.clone();
        fit.warnings.extend(crate::solve::logistic_warnings(&stats));
        fit.max = Some(ErrorStats::of(&fit.max_map, &masked));
        if mips {
            let chain = crate::logistic::Footprint::chain(ptm.width, ptm.height);
            let s = levels.levels.len();
            if levels
                .levels
                .iter()
                .zip(&chain[1..])
                .any(|(l, f)| l.height != f.height)
            {
                return Err(Error::Invalid(
                    "the parts' MIP levels do not join into the whole image's".into(),
                ));
            }
            ptm.mips = levels.levels;
            if let Some((cov, occ)) = &levels.counts {
                let above_w = chain[s].width;
                let deeper = crate::solve::logistic_coarse_levels(
                    lights,
                    &opts,
                    cov,
                    occ,
                    above_w,
                    &chain[s + 1..],
                )?;
                ptm.mips.extend(deeper);
            }
            if ptm.mips.len() + 1 != chain.len() {
                return Err(Error::Invalid(
                    "the parts' MIP levels do not join into the whole image's".into(),
                ));
            }
            fit.mip_levels = ptm.mips.len();
        }
    } else if mips {
        ptm.mips = crate::solve::identity_mips(ptm, &coverage);
        fit.mip_levels = ptm.mips.len();
    }
    fit.rms = ErrorStats::of(&fit.rms_map, &masked);
    ptm.coverage = crate::solve::ptm_coverage(&coverage);
    fit.coverage = if coverage.iter().any(|&c| c < 1.0) {
        coverage
    } else {
        Vec::new()
    };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_refuse() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { index: 2, count: 4 }));
        for bad in ["0/0", "5/4", "4/4", "-1/3", "x/3", "1", "1/y", ""] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains("expected I/N"), "{bad}: {e}");
        }
    }

    #[test]
    fn partition_covers_every_row_once_block_aligned() {
        for h in [4usize, 5, 63, 64, 1000, 1024] {
            for n in 1..=h.div_ceil(ROW_BLOCK).min(9) {
                let mut next = 0;
                for i in 0..n {
                    let r = Shard { index: i, count: n }.rows(h).unwrap();
                    assert_eq!(r.start, next);
                    assert_eq!(r.start % ROW_BLOCK, 0);
                    assert!(!r.is_empty());
                    next = r.end;
                }
                assert_eq!(next, h);
            }
        }
        assert!(Shard { index: 0, count: 3 }.rows(8).is_err());
    }

    fn stack_part(dir: &Path, s: Shard, software: &str) -> PathBuf {
        let (w, h) = (5, 40);
        let rows = s.rows(h).unwrap();
        let n = w * rows.len();
        let stack = SampleStack {
            width: w,
            height: rows.len(),
            tile: [1.0, 1.0],
            lights: LightSet::from_dirs([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]),
            k: (0..2)
                .map(|l| {
                    (0..n)
                        .map(|t| ((t + rows.start * w + l) % 5) as f32 / 4.0)
                        .collect()
                })
                .collect(),
            coverage: vec![1.0; n],
            uv: None,
        };
        let meta = PartMeta {
            shard: s,
            rows,
            width: w,
            height: h,
            settings: "res=5x8".into(),
            swatch: "0123".into(),
            software: software.into(),
        };
        let p = s.part_path(&dir.join("s.exr"));
        write_stack_part(&p, &meta, stack).unwrap();
        p
    }

    #[test]
    fn parts_of_another_version_are_refused_with_both_versions() {
        let dir = std::env::temp_dir().join(format!("ptm-shard-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = stack_part(&dir, Shard { index: 0, count: 2 }, "ptm 0.1.0");
        let b = stack_part(&dir, Shard { index: 1, count: 2 }, "ptm 0.2.0");
        let out = dir.join("m.exr");
        let e = merge_into(&[a.clone(), b.clone()], &out)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("software version") && e.contains("ptm 0.1.0") && e.contains("ptm 0.2.0"),
            "{e}"
        );
        let b = stack_part(&dir, Shard { index: 1, count: 2 }, "ptm 0.1.0");
        assert_eq!(merge_into(&[b, a], &out).unwrap().kind, "stack");
        let s = SampleStack::read(&out).unwrap();
        assert_eq!(s.height, 40);
        assert!(s.k[1]
            .iter()
            .enumerate()
            .all(|(t, &k)| k == ((t + 1) % 5) as f32 / 4.0));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn part_names() {
        let s = Shard { index: 2, count: 4 };
        assert_eq!(
            s.part_path(Path::new("d/w.ptm.exr")),
            Path::new("d/w.ptm.part-0002-of-0004.exr")
        );
        assert_eq!(
            s.part_path(Path::new("samples.exr")),
            Path::new("samples.part-0002-of-0004.exr")
        );
    }
}
