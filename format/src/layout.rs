//! The two on-disk layouts of a PTM and the lossless conversion between them.
//!
//! - [`Layout::Channels`]: the single-part PTM EXR with one channel per coefficient, named
//!   `ptm.<monomial>` (docs/FORMAT.md, "The PTM EXR"); what [`Ptm::save`] writes.
//! - [`Layout::Rgba`]: the **renderer layout**, one plain RGB(A) EXR per group of coefficients
//!   (`w.ptm.c0.exr`, `w.ptm.c1.exr`, …), so that any texture system, OSL's `texture()`,
//!   MaterialX's `image` node and Blender's Image Texture node reach every coefficient by file
//!   name and colour channel. ptm6: c0 = (u², u, uv), c1 = (v, v², 1, coverage) — the patent's
//!   two images of three channels; ptm11: c0 = (u³, v³, u²v², u²v), c1 = (uv², u², v², uv),
//!   c2 = (u, v, 1, coverage); a learned basis of k terms: RGBA parts of four coefficients
//!   `b0`, `b1`, … with zeros ([`Slot::Unused`]) up to the last part's A. Coverage is always
//!   the A of the last part. Error maps, when present, go to `w.ptm.err.exr` (channels
//!   `err.rms`, `err.max`). A learned basis also writes its table as images, since texture
//!   systems cannot read a header: the **basis parts** `w.ptm.basis0.exr`, … (G × G RGBA,
//!   float, B₄ᵢ … B₄ᵢ₊₃ in part i, zeros past the last term; row 0 is v = +1, so a bilinear
//!   lookup with clamp wrapping reproduces [`crate::LearnedTable::terms`]: [`BASIS_LOOKUP`]).
//!   Every part carries the file's `ptm:*` header plus `ptm:layout`, `ptm:part`, `ptm:parts`,
//!   `ptm:partChannels` and `wrapmodes` = `periodic,periodic`; MIP-mapped files are tiled
//!   64×64 `MIPMAP_LEVELS` `ROUND_DOWN`, as `maketx` writes.
//!
//! This module uses the `exr` crate and this crate's public [`Ptm`] / [`Basis`] types only
//! (no solver, no thread pool): a [`PtmFile`] holds every map with all its levels and stored sample type and
//! every header attribute verbatim, so converting either way and back gives the same samples,
//! types and attributes. Writes are atomic per file and all-or-nothing per set: every part is
//! written to a temporary file first and renamed only when all are complete.
//!
//! It is also the one PTM decoder: every file of either layout is decoded by
//! [`exrio::read_decoded`] into a [`PtmFile`], whose header [`Header::parse`] checks and whose
//! maps [`PtmFile::to_ptm`] turns into a [`Ptm`] (MIP chain, coverage, [`Ptm::validate`]).
//! [`Ptm::load`] is that path for the channel layout, [`PtmFile::load`] for either, so both
//! refuse the same files in the same words.
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use exr::math::RoundingMode;
use exr::meta::attribute::AttributeValue;
use exr::prelude::*;

use crate::exrio::{self, decode_text, encode_text, Decoded};
use crate::header::{self, Attributes, Header};
use crate::ptm::{channel_name, clamp_ringing, mip_sizes, Level};
use crate::{Basis, Error, LearnedTable, Ptm, PtmInfo, Result, SaveOptions};

/// Header attributes every part of the renderer layout (coefficient and basis parts) must
/// share with part c0.
const PART_KEYS: [&str; 6] = [
    "ptm:basis",
    "ptm:link",
    "ptm:uv",
    "ptm:version",
    crate::learned::GRID_ATTR,
    crate::learned::TABLE_ATTR,
];

/// Value of `ptm:layout` in every part of the renderer layout.
pub const RGBA_LAYOUT: &str = "rgba/1";

/// The value of `wrapmodes` (OpenImageIO / `maketx`'s attribute): the maps tile.
pub const WRAPMODES: &str = "periodic,periodic";

/// How a PTM is laid out on disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layout {
    /// One single-part EXR, one channel `ptm.<monomial>` per coefficient.
    Channels,
    /// One RGB(A) EXR per group of coefficients (`<stem>.c0.exr`, …): the renderer layout.
    Rgba,
}

impl Layout {
    /// Every layout, in the order `--layout` lists them.
    pub const ALL: [Layout; 2] = [Layout::Channels, Layout::Rgba];

    /// The layout's name as `--layout` and the `ptm:layout` attribute spell it.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Channels => "channels",
            Layout::Rgba => "rgba",
        }
    }

    /// The layout [`Layout::name`] names, if any.
    pub fn from_name(name: &str) -> Option<Layout> {
        Layout::ALL.into_iter().find(|l| l.name() == name)
    }
}

/// What one slot of a renderer-layout part holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Coefficient of this monomial (its name, e.g. `u2`).
    Coeff(&'static str),
    /// The coverage map (1 where the file has none).
    Coverage,
    /// Nothing: 0 in every texel. A learned basis's last part pads its coefficients with
    /// these so that every part is RGBA and coverage its A (a texture system, OSL's
    /// `texture()`, MaterialX's `image` and Blender's Image Texture read three or four
    /// channels named R, G, B, A; one or two channels they read differently or not at all).
    Unused,
}

impl Slot {
    /// Name of the map in the channel layout (`ptm.u2`, `coverage`).
    pub fn map_name(self) -> String {
        match self {
            Slot::Coeff(m) => format!("ptm.{m}"),
            Slot::Coverage => "coverage".into(),
            Slot::Unused => "unused".into(),
        }
    }

    /// Short name in `ptm:partChannels` (`u2`, `coverage`).
    pub fn short(self) -> &'static str {
        match self {
            Slot::Coeff(m) => m,
            Slot::Coverage => "coverage",
            Slot::Unused => "unused",
        }
    }
}

/// EXR channel names of a part's slots, in slot order.
pub const RGBA: [&str; 4] = ["R", "G", "B", "A"];

/// The parts of the renderer layout of `basis`: slots in R, G, B(, A) order. Coefficients fill
/// them in basis order, three per part for ptm6 and four for ptm11; coverage is the last slot.
///
/// A learned basis of k terms has ⌈(k + 1)/4⌉ RGBA parts: its coefficients four a part in
/// basis order, then [`Slot::Unused`] up to the A of the last part, which is coverage (so
/// `learned11`'s c2 is `b8 b9 b10 coverage`, `learned6`'s c1 `b4 b5 unused coverage`). With
/// the zeros of the basis parts in the same places ([`basis_slots`]), Σₖ cₖ·Bₖ is the sum
/// over parts of the 4-vector dot product of part cᵢ with basis part i.
pub fn parts(basis: Basis) -> Vec<Vec<Slot>> {
    let mut slots: Vec<Slot> = basis
        .monomials()
        .iter()
        .map(|m| Slot::Coeff(m.name))
        .collect();
    if basis.is_learned() {
        let n = (slots.len() + 1).div_ceil(4);
        slots.resize(4 * n - 1, Slot::Unused);
        slots.push(Slot::Coverage);
        return slots.chunks(4).map(<[Slot]>::to_vec).collect();
    }
    let per = if basis == Basis::Ptm6 { 3 } else { 4 };
    slots.push(Slot::Coverage);
    let mut out: Vec<Vec<Slot>> = slots.chunks(per).map(<[Slot]>::to_vec).collect();
    // ptm6: 7 slots in chunks of 3 leave coverage alone; it becomes the A of the last part.
    if out.last().is_some_and(|p| p.len() == 1) && out.len() > 1 {
        let last = out.pop().unwrap();
        out.last_mut().unwrap().extend(last);
    }
    out
}

/// Terms of a learned basis in one basis part (its R, G, B, A).
pub const BASIS_PART_TERMS: usize = 4;

/// Number of basis parts of `basis`: ⌈k/4⌉ for a learned basis of k terms, none for a
/// polynomial one.
pub fn basis_parts(basis: Basis) -> usize {
    if basis.is_learned() {
        basis.len().div_ceil(BASIS_PART_TERMS)
    } else {
        0
    }
}

/// What the R, G, B, A of basis part `i` of a `terms`-term basis hold: `Some(k)`, the table of
/// term k (B₄ᵢ₊꜀ in channel c), or `None`, zeros past the last term.
pub fn basis_slots(terms: usize, i: usize) -> [Option<usize>; 4] {
    std::array::from_fn(|c| Some(BASIS_PART_TERMS * i + c).filter(|&k| k < terms))
}

/// Name of the attribute of a basis part that states how it is read.
pub const BASIS_LOOKUP_ATTR: &str = "ptm:basisLookup";

/// The words of [`BASIS_LOOKUP_ATTR`]: the texel convention of the basis parts. A texel at
/// column i of an image G wide has its centre at s = (i + 0.5)/G, so the grid coordinate
/// x = (u + 1)/2·(G − 1) of [`crate::LearnedTable::terms`] is s = (0.5 + x)/G; clamp wrapping
/// reads the edge texel beyond the centres of the first and last, as the table's read clamps.
pub const BASIS_LOOKUP: &str = "basis part i holds B_(4i+c) in channel c (R, G, B, A = 0..3), 0 past the last term; texel (column x, row r) is ptm:learnedTable's grid column x, row G-1-r (row 0 of the image is v = +1); B_k(u, v) = bilinear lookup, clamp wrap, no MIP, at s = (0.5 + (u+1)/2*(G-1))/G, t = 1 - (0.5 + (v+1)/2*(G-1))/G (t = 0 the first scanline: OSL/OIIO texture()), i.e. uv = (s, (0.5 + (v+1)/2*(G-1))/G) in an image node whose v = 0 is the last row (Blender, MaterialX); then p = sum over parts i of dot(RGBA of part c_i, RGBA of basis part i)";

/// `wrapmodes` of a basis part: lookups clamp to the edge texels.
pub const BASIS_WRAPMODES: &str = "clamp,clamp";

/// The stem shared by a layout's files: `w.ptm.exr`, `w.ptm.c1.exr`, `w.ptm.basis0.exr` and
/// `w.ptm.err.exr` all give `w.ptm`.
pub fn stem(path: &Path) -> PathBuf {
    let s = path.to_string_lossy();
    let mut s: &str = s.strip_suffix(".exr").unwrap_or(&s);
    if let Some((head, tail)) = s.rsplit_once('.') {
        let numbered = |prefix: &str| {
            tail.strip_prefix(prefix)
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        };
        let is_part = numbered("c") || numbered("basis");
        if is_part || tail == "err" {
            s = head;
        }
    }
    PathBuf::from(s)
}

/// File of part `i` of the renderer layout named by `path` (`w.ptm.exr` → `w.ptm.c{i}.exr`).
pub fn part_path(path: &Path, i: usize) -> PathBuf {
    let mut s = stem(path).into_os_string();
    s.push(format!(".c{i}.exr"));
    PathBuf::from(s)
}

/// File of the error maps of the renderer layout named by `path` (`w.ptm.err.exr`).
pub fn err_path(path: &Path) -> PathBuf {
    let mut s = stem(path).into_os_string();
    s.push(".err.exr");
    PathBuf::from(s)
}

/// File of basis part `i` of the renderer layout named by `path` (`w.ptm.exr` →
/// `w.ptm.basis{i}.exr`).
pub fn basis_part_path(path: &Path, i: usize) -> PathBuf {
    let mut s = stem(path).into_os_string();
    s.push(format!(".basis{i}.exr"));
    PathBuf::from(s)
}

/// Every file the renderer layout of `basis` named by `path` consists of (without the optional
/// error maps): its parts, then a learned basis's basis parts.
pub fn rgba_paths(path: &Path, basis: Basis) -> Vec<PathBuf> {
    (0..parts(basis).len())
        .map(|i| part_path(path, i))
        .chain((0..basis_parts(basis)).map(|i| basis_part_path(path, i)))
        .collect()
}

/// One map (coefficient, coverage or error) with all its resolution levels as stored.
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    /// Level 0 first, then the coarser MIP levels (sizes as [`mip_sizes`]).
    pub levels: Vec<Vec<f32>>,
    /// Stored as half floats (else float32).
    pub half: bool,
}

/// Everything a PTM file set holds, layout-independent: every map by its channel-layout name
/// (`ptm.u2`, `coverage`, `err.rms`, …) and every header attribute verbatim (without the
/// renderer layout's own `ptm:layout`, `ptm:part*` and `wrapmodes`).
#[derive(Clone, Debug, PartialEq)]
pub struct PtmFile {
    /// Texels per row at level 0.
    pub width: usize,
    /// Rows at level 0.
    pub height: usize,
    /// Every map by its channel-layout name, with its resolution levels.
    pub maps: BTreeMap<String, Map>,
    /// Every header attribute of the PTM, verbatim (UTF-8 text bytes as written).
    pub attrs: BTreeMap<String, AttributeValue>,
}

/// Attributes that belong to a part of the renderer layout, not to the PTM.
const PART_ATTRS: [&str; 5] = [
    "ptm:layout",
    "ptm:part",
    "ptm:parts",
    "ptm:partChannels",
    "wrapmodes",
];

fn format_err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Format {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// The [`PtmFile`] shape of one decoded EXR: its maps by channel name (levels as f32, with
/// their stored type) and its attributes. A MIP chain must be OpenEXR's `ROUND_DOWN` chain to
/// 1×1 ([`mip_sizes`]), the one a PTM's levels follow.
fn file_of(d: Decoded) -> Result<PtmFile> {
    let path = Path::new(&d.path);
    let (width, height) = (d.width, d.height);
    let want = mip_sizes(width, height);
    if !d.level_sizes.is_empty() && d.level_sizes != want {
        return Err(format_err(
            path,
            format!(
                "its MIP levels {:?} are not the {width}×{height} chain {want:?} (halved, rounded \
                 down, to 1×1: OpenEXR's `ROUND_DOWN`)",
                d.level_sizes
            ),
        ));
    }
    let mut maps = BTreeMap::new();
    for (name, list) in d.channels {
        let half = list.iter().any(|s| matches!(s, FlatSamples::F16(_)));
        let levels: Vec<Vec<f32>> = list
            .into_iter()
            .map(|s| match s {
                FlatSamples::F32(v) => v,
                FlatSamples::F16(v) => v.into_iter().map(f16::to_f32).collect(),
                FlatSamples::U32(v) => v.into_iter().map(|x| x as f32).collect(),
            })
            .collect();
        if levels.len() > 1 && levels.len() != want.len() + 1 {
            return Err(format_err(
                path,
                format!(
                    "channel `{name}` has {} resolution levels; a {width}×{height} MIP chain to 1×1 has {}",
                    levels.len(),
                    want.len() + 1
                ),
            ));
        }
        maps.insert(name, Map { levels, half });
    }
    Ok(PtmFile {
        width,
        height,
        maps,
        attrs: d.attrs,
    })
}

/// One file as a [`PtmFile`]: every map and attribute, nothing checked beyond the EXR.
fn read_single(path: &Path) -> Result<PtmFile> {
    file_of(exrio::read_decoded(path)?)
}

/// How an attribute of a part reads in a message: its text, quoted, or its type.
fn shown_attr(v: Option<&AttributeValue>) -> String {
    match v {
        None => "absent".into(),
        Some(AttributeValue::Text(t)) => format!("{:?}", decode_text(t)),
        Some(v) => format!(
            "an EXR `{}` attribute",
            String::from_utf8_lossy(v.kind_name())
        ),
    }
}

/// Encodes one single-part EXR (maps with one level: scanline ZIP; with a MIP chain: tiled
/// 64×64 ZIP `MIPMAP_LEVELS` `ROUND_DOWN`) in memory, attributes sorted so the bytes are
/// deterministic.
fn encode_single(
    shown: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, &Map)>,
    attrs: &BTreeMap<String, AttributeValue>,
) -> Result<Vec<u8>> {
    let mipped = channels.first().is_some_and(|(_, m)| m.levels.len() > 1);
    if channels.iter().any(|(_, m)| (m.levels.len() > 1) != mipped) {
        return Err(format_err(
            shown,
            "maps with and without MIP levels cannot share a file",
        ));
    }
    let flat = |v: &[f32], half: bool| {
        if half {
            FlatSamples::F16(v.iter().map(|&x| f16::from_f32(x)).collect())
        } else {
            FlatSamples::F32(v.to_vec())
        }
    };
    let list: crate::exrio::ChannelList = channels
        .iter()
        .map(|(name, m)| {
            let data = if mipped {
                Levels::Mip {
                    rounding_mode: RoundingMode::Down,
                    level_data: m.levels.iter().map(|l| flat(l, m.half)).collect(),
                }
            } else {
                Levels::Singular(flat(&m.levels[0], m.half))
            };
            AnyChannel::new(encode_text(name), data)
        })
        .collect();
    let mut la = LayerAttributes::default();
    for (name, value) in attrs {
        match (name.as_str(), value) {
            // A standard attribute the `exr` crate keeps in a field of its own.
            ("wrapmodes", AttributeValue::Text(t)) => la.wrap_mode_name = Some(t.clone()),
            _ => {
                la.other.insert(encode_text(name), value.clone());
            }
        }
    }
    crate::exrio::encode_layer(shown, width, height, la, list)
}

/// One file of a set: its path and the encoder of its bytes.
type WriteJob<'a> = (PathBuf, Box<dyn FnOnce() -> Result<Vec<u8>> + 'a>);

/// Encodes every job; nothing is written.
fn encode_set(jobs: Vec<WriteJob<'_>>) -> Result<Vec<(PathBuf, Vec<u8>)>> {
    jobs.into_iter()
        .map(|(path, encode)| Ok((path, encode()?)))
        .collect()
}

/// Publishes encoded files all together (one [`crate::atomic::Transaction`]: every destination
/// checked first, none replaced unless all were written); returns their paths.
pub fn publish(files: &[(PathBuf, Vec<u8>)]) -> Result<Vec<PathBuf>> {
    let paths: Vec<&PathBuf> = files.iter().map(|(p, _)| p).collect();
    let mut tx = crate::atomic::Transaction::new(&paths)?;
    for (p, bytes) in files {
        tx.stage_bytes(p, bytes)?;
    }
    tx.commit()?;
    Ok(files.iter().map(|(p, _)| p.clone()).collect())
}

impl PtmFile {
    /// Basis named by `ptm:basis`, once the whole header reads ([`Header::parse`]).
    pub fn basis(&self, path: &Path) -> Result<Basis> {
        Ok(Header::parse(&self.attrs, path)?.basis)
    }

    /// The maps and header attributes [`Ptm::save`] with `opts` writes for `ptm`, in memory
    /// (`path` names the file in errors only).
    pub fn from_ptm(ptm: &Ptm, path: &Path, opts: &SaveOptions) -> Result<PtmFile> {
        file_of(exrio::decode_bytes(path, &ptm.encode(path, opts)?)?)
    }

    /// Reads a PTM in either layout. `path` names the channel-layout file, or any file of the
    /// renderer layout (`w.ptm.c0.exr`, or `w.ptm.exr` when only the `.c*` files exist). The
    /// file set is checked as [`PtmFile::to_ptm`] checks it.
    pub fn load(path: &Path) -> Result<(PtmFile, Layout)> {
        let layout = detect(path)?;
        let file = match layout {
            Layout::Channels => read_single(path)?,
            Layout::Rgba => read_rgba(path)?,
        };
        file.to_ptm(path)?;
        Ok((file, layout))
    }

    /// The PTM these maps hold: the header as [`Header::parse`] reads it, every coefficient
    /// map with the same MIP chain, coverage clamped and checked, and [`Ptm::validate`]; a
    /// refusal names `path`. The one place a PTM is made from a file.
    pub fn to_ptm(&self, path: &Path) -> Result<Ptm> {
        let take = |name: &str| self.maps.get(name).map(Cow::Borrowed);
        Ok(ptm_of(self.width, self.height, &self.attrs, path, take)?.0)
    }

    /// [`PtmFile::to_ptm`] moving the maps out of `self`, with the header's facts and the error
    /// maps ([`Ptm::load_with_info`]).
    fn into_ptm_with_info(self, path: &Path) -> Result<(Ptm, PtmInfo)> {
        let PtmFile {
            width,
            height,
            mut maps,
            attrs,
        } = self;
        let take = |name: &str| maps.remove(name).map(Cow::Owned);
        let (ptm, storage) = ptm_of(width, height, &attrs, path, take)?;
        let mut level0 = |name: &str| maps.remove(name).and_then(|m| m.levels.into_iter().next());
        // Facts beside the coefficients: informative, so one of an unexpected type reads as
        // not recorded rather than refusing the file.
        let fact = |name: &str| header::number(&attrs, name, path).ok().flatten();
        let info = PtmInfo {
            storage: storage.into(),
            lights: fact("ptm:nLights").map(|x| x as usize),
            solver: header::text(&attrs, "ptm:solver", path).ok().flatten(),
            rank: fact("ptm:rank").map(|x| x as usize),
            cond: fact("ptm:cond"),
            rms_mean: fact("ptm:rmsMean"),
            err_rms: level0("err.rms"),
            err_max: level0("err.max"),
            coverage: ptm.coverage.clone(),
        };
        Ok((ptm, info))
    }

    /// Per-texel coverage when the file has it (level 0).
    pub fn coverage(&self) -> Option<&[f32]> {
        self.maps.get("coverage").map(|m| m.levels[0].as_slice())
    }

    /// Writes the maps in `layout` to the file(s) named by `path` (for [`Layout::Rgba`], its
    /// parts `<stem>.c0.exr`, …, and `<stem>.err.exr` when there are error maps; a stale
    /// `<stem>.err.exr` of an earlier write is removed). All or nothing. Returns the files.
    pub fn save(&self, path: &Path, layout: Layout) -> Result<Vec<PathBuf>> {
        let out = publish(&self.encode(path, layout)?)?;
        remove_stale_errors(path, layout, &out);
        Ok(out)
    }

    /// The files [`PtmFile::save`] writes, encoded: `(path, bytes)` for each, nothing written.
    pub fn encode(&self, path: &Path, layout: Layout) -> Result<Vec<(PathBuf, Vec<u8>)>> {
        let basis = self.basis(path)?;
        self.to_ptm(path)?;
        match layout {
            Layout::Channels => {
                let out = path.to_path_buf();
                let channels: Vec<(String, &Map)> =
                    self.maps.iter().map(|(k, m)| (k.clone(), m)).collect();
                encode_set(vec![(
                    out,
                    Box::new(|| {
                        encode_single(path, self.width, self.height, channels, &self.attrs)
                    }),
                )])
            }
            Layout::Rgba => {
                let parts = parts(basis);
                let mipped = self
                    .maps
                    .values()
                    .next()
                    .is_some_and(|m| m.levels.len() > 1);
                let ones = self.filled(1.0, mipped);
                let zeros = self.filled(0.0, mipped);
                let mut jobs: Vec<WriteJob<'_>> = Vec::new();
                for (i, slots) in parts.iter().enumerate() {
                    let p = part_path(path, i);
                    let mut attrs = self.attrs.clone();
                    attrs.insert(
                        "ptm:layout".into(),
                        AttributeValue::Text(encode_text(RGBA_LAYOUT)),
                    );
                    attrs.insert("ptm:part".into(), AttributeValue::I32(i as i32));
                    attrs.insert("ptm:parts".into(), AttributeValue::I32(parts.len() as i32));
                    attrs.insert(
                        "ptm:partChannels".into(),
                        AttributeValue::TextVector(
                            slots.iter().map(|s| encode_text(s.short())).collect(),
                        ),
                    );
                    attrs.insert(
                        "wrapmodes".into(),
                        AttributeValue::Text(encode_text(WRAPMODES)),
                    );
                    let mut channels = Vec::new();
                    for (k, slot) in slots.iter().enumerate() {
                        let map = match slot {
                            Slot::Coverage => self.maps.get("coverage").unwrap_or(&ones),
                            Slot::Unused => &zeros,
                            s => self.maps.get(&s.map_name()).ok_or_else(|| {
                                format_err(path, format!("PTM lacks `{}`", s.map_name()))
                            })?,
                        };
                        channels.push((RGBA[k].to_string(), map));
                    }
                    let shown = p.clone();
                    let (w, h) = (self.width, self.height);
                    jobs.push((
                        p.clone(),
                        Box::new(move || encode_single(&shown, w, h, channels, &attrs)),
                    ));
                }
                if basis.is_learned() {
                    let table = LearnedTable::from_attrs(&self.attrs, basis.len(), path)?;
                    for i in 0..basis_parts(basis) {
                        let p = basis_part_path(path, i);
                        let attrs = self.basis_part_attrs(&table, i);
                        let shown = p.clone();
                        let table = table.clone();
                        jobs.push((
                            p.clone(),
                            Box::new(move || {
                                let g = table.grid;
                                let maps = basis_part_maps(&table, i);
                                let channels = RGBA
                                    .iter()
                                    .zip(&maps)
                                    .map(|(c, m)| (c.to_string(), m))
                                    .collect();
                                encode_single(&shown, g, g, channels, &attrs)
                            }),
                        ));
                    }
                }
                let errs: Vec<(String, &Map)> = self
                    .maps
                    .iter()
                    .filter(|(k, _)| k.starts_with("err."))
                    .map(|(k, m)| (k.clone(), m))
                    .collect();
                let ep = err_path(path);
                if !errs.is_empty() {
                    let mut attrs = self.attrs.clone();
                    attrs.insert(
                        "ptm:layout".into(),
                        AttributeValue::Text(encode_text(RGBA_LAYOUT)),
                    );
                    attrs.insert("ptm:part".into(), AttributeValue::Text(encode_text("err")));
                    let shown = ep.clone();
                    let (w, h) = (self.width, self.height);
                    jobs.push((
                        ep.clone(),
                        Box::new(move || encode_single(&shown, w, h, errs, &attrs)),
                    ));
                }
                let unknown: Vec<&String> = self
                    .maps
                    .keys()
                    .filter(|k| {
                        !k.starts_with("err.")
                            && *k != "coverage"
                            && !parts.iter().flatten().any(|s| s.map_name() == **k)
                    })
                    .collect();
                if !unknown.is_empty() {
                    return Err(format_err(
                        path,
                        format!("channels {unknown:?} have no place in the rgba layout"),
                    ));
                }
                encode_set(jobs)
            }
        }
    }

    /// A map holding `value` everywhere, with levels when `mipped`: ones for the coverage of a
    /// file without holes, zeros for [`Slot::Unused`].
    fn filled(&self, value: f32, mipped: bool) -> Map {
        let mut levels = vec![vec![value; self.width * self.height]];
        if mipped {
            for (w, h) in mip_sizes(self.width, self.height) {
                levels.push(vec![value; w * h]);
            }
        }
        let half = self.maps.values().next().is_some_and(|m| m.half);
        Map { levels, half }
    }

    /// The header of basis part `i`: the PTM's attributes (the table among them) plus what
    /// the part is and how a texture system reads it.
    fn basis_part_attrs(&self, table: &LearnedTable, i: usize) -> Attributes {
        let mut attrs = self.attrs.clone();
        let text = |t: &str| AttributeValue::Text(encode_text(t));
        attrs.insert("ptm:layout".into(), text(RGBA_LAYOUT));
        attrs.insert("ptm:part".into(), text(&format!("basis{i}")));
        attrs.insert(
            "ptm:partChannels".into(),
            AttributeValue::TextVector(
                basis_slots(table.terms, i)
                    .iter()
                    .map(|t| encode_text(&t.map_or("unused".into(), |k| format!("B{k}"))))
                    .collect(),
            ),
        );
        attrs.insert(BASIS_LOOKUP_ATTR.into(), text(BASIS_LOOKUP));
        attrs.insert("wrapmodes".into(), text(BASIS_WRAPMODES));
        attrs
    }
}

/// The four G × G float maps (R, G, B, A) of basis part `i` of `table`: image row r is the
/// table's grid row G − 1 − r (row 0 at v = +1, as row 0 of a coefficient part is the far
/// edge y = H), zeros past the last term.
fn basis_part_maps(table: &LearnedTable, i: usize) -> Vec<Map> {
    let g = table.grid;
    basis_slots(table.terms, i)
        .iter()
        .map(|term| {
            let mut level = vec![0f32; g * g];
            if let Some(k) = *term {
                let t = &table.values[k * g * g..(k + 1) * g * g];
                for (r, row) in level.chunks_exact_mut(g).enumerate() {
                    row.copy_from_slice(&t[(g - 1 - r) * g..(g - r) * g]);
                }
            }
            Map {
                levels: vec![level],
                half: false,
            }
        })
        .collect()
}

/// The [`Ptm`] of a file's header and maps (`take` hands out the map of a name), and how its
/// coefficients are stored (`"float32"`, `"half"` or `"mixed"`, from the maps' types, whatever
/// `ptm:storage` says: a tool that rewrote the file keeps our attributes but not necessarily
/// their truth). See [`PtmFile::to_ptm`].
fn ptm_of<'a>(
    width: usize,
    height: usize,
    attrs: &Attributes,
    path: &Path,
    mut take: impl FnMut(&str) -> Option<Cow<'a, Map>>,
) -> Result<(Ptm, &'static str)> {
    let Header {
        basis,
        link,
        uv,
        tile,
    } = Header::parse(attrs, path)?;
    let sizes = mip_sizes(width, height);
    let mut planes = Vec::with_capacity(basis.len());
    let mut levels: Vec<std::vec::IntoIter<Vec<f32>>> = Vec::with_capacity(basis.len());
    let mut halves = Vec::with_capacity(basis.len());
    for m in basis.monomials() {
        let name = channel_name(m.name);
        let Some(map) = take(&name).filter(|m| !m.levels.is_empty()) else {
            let why = if attrs.contains_key("ptm:layout") {
                "it is a part of the renderer layout, which `layout::load` and `PtmFile::load` read"
            } else {
                "the file is truncated in content or was written by another tool"
            };
            return Err(format_err(
                path,
                format!("PTM lacks channel `{name}` ({why})"),
            ));
        };
        halves.push(map.half);
        let mut chain = map.into_owned().levels.into_iter();
        planes.push(chain.next().expect("a level"));
        levels.push(chain);
    }
    let n = levels[0].len();
    if levels.iter().any(|l| l.len() != n) {
        return Err(format_err(
            path,
            "coefficient channels have different numbers of MIP levels",
        ));
    }
    if n > 0 && n != sizes.len() {
        return Err(format_err(
            path,
            format!(
                "coefficient channels have {} resolution levels; a {width}×{height} MIP chain to 1×1 has {}",
                n + 1,
                sizes.len() + 1
            ),
        ));
    }
    let mips = sizes[..n]
        .iter()
        .map(|&(width, height)| Level {
            width,
            height,
            planes: levels
                .iter_mut()
                .map(|l| l.next().expect("a level"))
                .collect(),
        })
        .collect();
    let learned = if basis.is_learned() {
        let k = basis.len();
        // Coefficient planes beyond the table's terms: a file that disagrees with itself.
        for i in k..crate::basis::MAX_LEARNED_TERMS {
            let extra = format!("ptm.b{i}");
            if take(&extra).is_some() {
                return Err(format_err(
                    path,
                    format!(
                        "basis {} has {k} coefficient planes but the file also holds `{extra}`",
                        basis.name()
                    ),
                ));
            }
        }
        Some(crate::LearnedTable::from_attrs(attrs, k, path)?)
    } else {
        None
    };
    let storage = match (halves.iter().all(|&h| h), halves.iter().any(|&h| h)) {
        (true, _) => "half",
        (false, true) => "mixed",
        (false, false) => "float32",
    };
    // A resampled file's ringing past [0, 1] is clamped; then a coverage of ones is none, as a
    // fit leaves it (the renderer layout stores ones then). Anything else is for `validate`.
    let coverage = take("coverage")
        .and_then(|m| match m {
            Cow::Borrowed(m) => m.levels.first().cloned(),
            Cow::Owned(m) => m.levels.into_iter().next(),
        })
        .map(|mut c| {
            clamp_ringing(&mut c);
            c
        })
        .filter(|c| !c.iter().all(|&x| x == 1.0));
    let ptm = Ptm {
        basis,
        link,
        uv,
        width,
        height,
        tile,
        planes,
        mips,
        coverage,
        learned,
    };
    ptm.validate()
        .map_err(|e| format_err(path, e.to_string()))?;
    Ok((ptm, storage))
}

impl Ptm {
    /// Loads a PTM EXR (the channel layout; [`load`] reads either layout). A file that is not
    /// a PTM, lacks a coefficient channel, or whose header this version does not understand
    /// ([`Header::parse`]) is an error saying which, as [`PtmFile::load`] says it.
    pub fn load(path: &Path) -> Result<Ptm> {
        Ok(Self::load_with_info(path)?.0)
    }

    /// Loads a PTM EXR and its header facts and error maps.
    pub fn load_with_info(path: &Path) -> Result<(Ptm, PtmInfo)> {
        read_single(path)?.into_ptm_with_info(path)
    }
}

/// Which layout `path` names: a file with `ptm:layout` is a part of the renderer layout; a
/// missing file whose `<stem>.c0.exr` exists names that layout too.
pub fn detect(path: &Path) -> Result<Layout> {
    if path.exists() {
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| format_err(path, exrio::unreadable(e)))?;
        let rgba = meta.headers.iter().any(|h| {
            h.own_attributes
                .other
                .contains_key(&encode_text("ptm:layout"))
        });
        Ok(if rgba { Layout::Rgba } else { Layout::Channels })
    } else if part_path(path, 0).exists() {
        Ok(Layout::Rgba)
    } else {
        Err(Error::Io {
            path: path.display().to_string(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such file (nor a renderer-layout part .c0.exr beside it)",
            ),
        })
    }
}

fn read_rgba(path: &Path) -> Result<PtmFile> {
    let p0 = part_path(path, 0);
    let first = read_single(&p0)?;
    let shown = |i: usize| format!("part c{i}");
    let layout = header::text(&first.attrs, "ptm:layout", &p0)?;
    if layout.as_deref() != Some(RGBA_LAYOUT) {
        return Err(format_err(
            &p0,
            format!(
                "{}: `ptm:layout` is {layout:?}; this version reads {RGBA_LAYOUT:?}",
                shown(0)
            ),
        ));
    }
    let mut file = PtmFile {
        width: first.width,
        height: first.height,
        maps: BTreeMap::new(),
        attrs: first
            .attrs
            .iter()
            .filter(|(k, _)| !PART_ATTRS.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
    };
    let basis = Header::parse(&file.attrs, &p0)?.basis;
    let parts = parts(basis);
    let mut singles = vec![first];
    for i in 1..parts.len() {
        let p = part_path(path, i);
        if !p.exists() {
            return Err(format_err(
                &p,
                format!(
                    "missing {} of the rgba layout of {} ({} has parts c0..c{})",
                    shown(i),
                    stem(path).display(),
                    basis.name(),
                    parts.len() - 1
                ),
            ));
        }
        singles.push(read_single(&p)?);
    }
    for (i, (slots, s)) in parts.iter().zip(singles.iter_mut()).enumerate() {
        let p = part_path(path, i);
        if (s.width, s.height) != (file.width, file.height) {
            return Err(format_err(
                &p,
                format!(
                    "{} is {}×{} but part c0 is {}×{}",
                    shown(i),
                    s.width,
                    s.height,
                    file.width,
                    file.height
                ),
            ));
        }
        for key in PART_KEYS {
            if s.attrs.get(key) != file.attrs.get(key) {
                return Err(format_err(
                    &p,
                    format!(
                        "{}: `{key}` is {} but part c0 says {}",
                        shown(i),
                        shown_attr(s.attrs.get(key)),
                        shown_attr(file.attrs.get(key))
                    ),
                ));
            }
        }
        match s.attrs.get("ptm:part") {
            Some(AttributeValue::I32(k)) if *k as usize == i => {}
            other => {
                return Err(format_err(
                    &p,
                    format!("{}: `ptm:part` is {other:?}, expected {i}", shown(i)),
                ))
            }
        }
        for (k, slot) in slots.iter().enumerate() {
            let map = s.maps.remove(RGBA[k]).ok_or_else(|| {
                format_err(
                    &p,
                    format!(
                        "{} lacks channel {} ({})",
                        shown(i),
                        RGBA[k],
                        slot.map_name()
                    ),
                )
            })?;
            if *slot == Slot::Unused {
                // A renderer adds this slot times 0 (the basis part's zero there): it must be a
                // number, and the writer's zero keeps the set's bytes what a conversion writes.
                if let Some((level, t, x)) = first_nonzero(&map.levels) {
                    return Err(format_err(
                        &p,
                        format!(
                            "{}: channel {} is unused in {} and must hold 0, but holds {x} at \
                             level {level}, texel {t}",
                            shown(i),
                            RGBA[k],
                            basis.name()
                        ),
                    ));
                }
                continue;
            }
            file.maps.insert(slot.map_name(), map);
        }
    }
    let levels: Vec<usize> = file.maps.values().map(|m| m.levels.len()).collect();
    if levels.iter().any(|&n| n != levels[0]) {
        return Err(format_err(
            &p0,
            "parts have different numbers of MIP levels",
        ));
    }
    // Coverage all ones is "no coverage map" (the channel layout leaves it out).
    if file
        .maps
        .get("coverage")
        .is_some_and(|m| m.levels.iter().flatten().all(|&c| c == 1.0))
    {
        file.maps.remove("coverage");
    }
    if basis.is_learned() {
        // A header table this version refuses is `to_ptm`'s to refuse, in the words both
        // layouts share; the basis parts are checked against a table that reads.
        if let Ok(table) = LearnedTable::from_attrs(&file.attrs, basis.len(), path) {
            for i in 0..basis_parts(basis) {
                check_basis_part(path, &file.attrs, &table, i)?;
            }
        }
    }
    let ep = err_path(path);
    if ep.exists() {
        let e = read_single(&ep)?;
        if (e.width, e.height) != (file.width, file.height) {
            return Err(format_err(
                &ep,
                format!(
                    "error maps are {}×{} but part c0 is {}×{}",
                    e.width, e.height, file.width, file.height
                ),
            ));
        }
        for (k, m) in e.maps {
            if k.starts_with("err.") {
                file.maps.insert(k, m);
            }
        }
    }
    Ok(file)
}

/// The first value of `levels` that is not 0: (level, texel, value).
fn first_nonzero(levels: &[Vec<f32>]) -> Option<(usize, usize, f32)> {
    levels
        .iter()
        .enumerate()
        .find_map(|(l, v)| v.iter().position(|&x| x != 0.0).map(|t| (l, t, v[t])))
}

/// Checks basis part `i` of the renderer layout named by `path` against the header's `table`
/// (`attrs`, part c0's): present, the same basis, link, map, version and table attributes,
/// G × G with one level, R, G, B, A all there, every value finite, its terms' values those of
/// the table bit for bit and zeros past the last term. What a renderer reads is then what
/// [`LearnedTable::terms`] reads.
fn check_basis_part(path: &Path, attrs: &Attributes, table: &LearnedTable, i: usize) -> Result<()> {
    let p = basis_part_path(path, i);
    let (g, k) = (table.grid, table.terms);
    let name = format!("basis part basis{i}");
    let basis = Basis::learned(k).expect("a learned basis's table");
    if !p.exists() {
        return Err(format_err(
            &p,
            format!(
                "missing {name} of the rgba layout of {} ({} has basis parts basis0..basis{}: \
                 its table as images, for texture systems)",
                stem(path).display(),
                basis.name(),
                basis_parts(basis) - 1
            ),
        ));
    }
    let s = read_single(&p)?;
    for key in PART_KEYS {
        if s.attrs.get(key) != attrs.get(key) {
            return Err(format_err(
                &p,
                format!(
                    "{name}: `{key}` is {} but part c0 says {}",
                    shown_attr(s.attrs.get(key)),
                    shown_attr(attrs.get(key))
                ),
            ));
        }
    }
    let want_part = format!("basis{i}");
    match s.attrs.get("ptm:part") {
        Some(AttributeValue::Text(t)) if decode_text(t) == want_part => {}
        other => {
            return Err(format_err(
                &p,
                format!(
                    "{name}: `ptm:part` is {}, expected {want_part:?}",
                    shown_attr(other)
                ),
            ))
        }
    }
    if (s.width, s.height) != (g, g) {
        return Err(format_err(
            &p,
            format!(
                "{name} is {}×{} but `{}` is {g}: a basis part is the {g}×{g} table",
                s.width,
                s.height,
                crate::learned::GRID_ATTR
            ),
        ));
    }
    for (c, term) in basis_slots(k, i).into_iter().enumerate() {
        let what = term.map_or("unused".into(), |t| format!("B{t}"));
        let map = s
            .maps
            .get(RGBA[c])
            .ok_or_else(|| format_err(&p, format!("{name} lacks channel {} ({what})", RGBA[c])))?;
        if map.levels.len() != 1 {
            return Err(format_err(
                &p,
                format!(
                    "{name} has {} resolution levels; a basis part has one (a lookup must read \
                     the table itself, not a filtered copy)",
                    map.levels.len()
                ),
            ));
        }
        for (t, &x) in map.levels[0].iter().enumerate() {
            let (col, row) = (t % g, t / g);
            if !x.is_finite() {
                return Err(format_err(
                    &p,
                    format!(
                        "{name}: channel {} ({what}) is {x} at column {col}, row {row}: not a \
                         number a renderer can use",
                        RGBA[c]
                    ),
                ));
            }
            let want = term.map_or(0.0, |term| {
                table.values[term * g * g + (g - 1 - row) * g + col]
            });
            if x.to_bits() == want.to_bits() {
                continue;
            }
            return Err(format_err(
                &p,
                match term {
                    None => format!(
                        "{name}: channel {} holds {x} at column {col}, row {row}, but {} has {k} \
                         terms (B0..B{}), so this channel is unused and must hold 0: a table of \
                         more terms than the coefficient planes?",
                        RGBA[c],
                        basis.name(),
                        k - 1
                    ),
                    Some(_) => format!(
                        "{name}: {what} is {x} at column {col}, row {row} (grid column {col}, row \
                         {}) but `{}` holds {want} there: the part and the header disagree \
                         (a texture system reads the part)",
                        g - 1 - row,
                        crate::learned::TABLE_ATTR
                    ),
                },
            ));
        }
    }
    Ok(())
}

/// Loads a PTM in either layout (see [`PtmFile::load`]).
pub fn load(path: &Path) -> Result<Ptm> {
    let (file, _) = PtmFile::load(path)?;
    file.to_ptm(path)
}

/// Saves a PTM as [`Ptm::save`] does, in `layout`, all files or none; returns the files
/// written.
pub fn save(ptm: &Ptm, path: &Path, opts: &SaveOptions, layout: Layout) -> Result<Vec<PathBuf>> {
    let files = publish(&encode(ptm, path, opts, layout)?)?;
    remove_stale_errors(path, layout, &files);
    Ok(files)
}

/// After a renderer-layout write, removes the error file and the basis parts an earlier write
/// left that this one did not write (they would describe other coefficients or another basis).
pub fn remove_stale_errors(path: &Path, layout: Layout, written: &[PathBuf]) {
    if layout != Layout::Rgba {
        return;
    }
    let most = crate::basis::MAX_LEARNED_TERMS.div_ceil(BASIS_PART_TERMS);
    let stale = std::iter::once(err_path(path)).chain((0..most).map(|i| basis_part_path(path, i)));
    for p in stale {
        if !written.contains(&p) && p.exists() {
            let _ = std::fs::remove_file(&p);
        }
    }
}

/// The files [`save`] writes, encoded (nothing written): the channel layout's single file, or
/// the renderer layout's parts, made from the channel layout's encoding (decoded in memory,
/// [`PtmFile::from_ptm`]) so both carry the same header and maps.
pub fn encode(
    ptm: &Ptm,
    path: &Path,
    opts: &SaveOptions,
    layout: Layout,
) -> Result<Vec<(PathBuf, Vec<u8>)>> {
    match layout {
        Layout::Channels => Ok(vec![(path.to_path_buf(), ptm.encode(path, opts)?)]),
        Layout::Rgba => PtmFile::from_ptm(ptm, path, opts)?.encode(path, Layout::Rgba),
    }
}
