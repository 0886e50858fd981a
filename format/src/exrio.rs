//! Thin layer over the `exr` crate shared by the sample stack, the PTM file and the farm parts:
//! single-part scanline (or tiled MIP-mapped) files, ZIP compression, named flat channels,
//! portable header attributes (text, text vector, f64, i32), encoded in memory with the header
//! attributes sorted (byte-identical files for identical content) and written atomically.
//!
//! Reading: [`read_decoded`] (a file) and [`decode_bytes`] (bytes this crate encoded) are the one
//! decode of an EXR in the workspace: every channel with all its resolution levels and every
//! header attribute as stored ([`Decoded`]). The PTM readers of both layouts build their
//! `PtmFile` from it (`layout.rs`); [`read()`] turns it into the portable [`Contents`] that the
//! sample stack and the farm parts read. This layer knows EXR, not PTMs.
//!
//! Header text is written as UTF-8 (what OpenEXR's Python bindings decode) and read leniently:
//! bytes that are not UTF-8 are taken as Latin-1, as files before this version wrote them
//! ([`decode_text`], the one text decoder of every reader of the workspace).
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use exr::math::RoundingMode;
use exr::meta::attribute::AttributeValue;
use exr::prelude::*;

use crate::{Error, Result};

/// Samples of one channel as stored: f32 or half.
pub enum Samples {
    /// 32-bit float samples.
    F32(Vec<f32>),
    /// Half-float samples.
    F16(Vec<f16>),
}

/// A header attribute of one of the portable types.
#[derive(Clone, Debug, PartialEq)]
pub enum Attr {
    /// UTF-8 text (read back leniently as Latin-1).
    Text(String),
    /// A list of texts (EXR `stringvector`).
    Texts(Vec<String>),
    /// A double.
    F64(f64),
    /// A 32-bit integer.
    I32(i32),
}

/// Header text as we write it: EXR `Text` holds bytes, and ours are UTF-8.
pub fn encode_text(s: &str) -> Text {
    Text::from_bytes_unchecked(s.as_bytes().into())
}

/// Header text as read: UTF-8 when the bytes are, else Latin-1 (files written before headers
/// were UTF-8). The one text decoder of every EXR reader of the workspace.
pub fn decode_text(t: &Text) -> String {
    match std::str::from_utf8(t.bytes()) {
        Ok(s) => s.to_string(),
        Err(_) => t.bytes().iter().map(|&b| b as char).collect(),
    }
}

/// Writes a width×height single-part EXR with ZIP (16 scanlines per block) compression.
/// Row 0 of every channel is the first scanline (the top of the image).
pub fn write(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Samples)>,
    attrs: Vec<(&str, Attr)>,
) -> Result<()> {
    let levels = channels.into_iter().map(|(n, s)| (n, vec![s])).collect();
    write_levels(path, width, height, levels, attrs)
}

/// The bytes of the file [`write()`] writes (`path` names it in errors only).
pub fn encode(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Samples)>,
    attrs: Vec<(&str, Attr)>,
) -> Result<Vec<u8>> {
    let levels = channels.into_iter().map(|(n, s)| (n, vec![s])).collect();
    encode_levels(path, width, height, levels, attrs)
}

/// Tile size of MIP-mapped files (as `maketx` writes them).
pub const TILE: usize = 64;

fn flat(s: Samples) -> FlatSamples {
    match s {
        Samples::F32(v) => FlatSamples::F32(v),
        Samples::F16(v) => FlatSamples::F16(v),
    }
}

/// Writes a single-part EXR whose channels carry one entry per resolution level: one level is
/// a plain scanline file (as [`write()`]); more make a tiled (64×64, ZIP) `MIPMAP_LEVELS` file with
/// `ROUND_DOWN` sizes, levels 0, 1, … down to 1×1 — the form texture systems read.
pub fn write_levels(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Vec<Samples>)>,
    attrs: Vec<(&str, Attr)>,
) -> Result<()> {
    let bytes = encode_levels(path, width, height, channels, attrs)?;
    crate::atomic::write_bytes(path, &bytes)
}

/// The bytes of the file [`write_levels`] writes (`path` names it in errors only).
pub fn encode_levels(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Vec<Samples>)>,
    attrs: Vec<(&str, Attr)>,
) -> Result<Vec<u8>> {
    let mipped = channels.first().is_some_and(|(_, l)| l.len() > 1);
    let list: ChannelList = channels
        .into_iter()
        .map(|(name, levels)| {
            let data = if mipped {
                Levels::Mip {
                    rounding_mode: RoundingMode::Down,
                    level_data: levels.into_iter().map(flat).collect(),
                }
            } else {
                Levels::Singular(flat(levels.into_iter().next().expect("one level")))
            };
            AnyChannel::new(encode_text(&name), data)
        })
        .collect();
    let mut la = LayerAttributes::default();
    for (name, a) in attrs {
        la.other.insert(encode_text(name), attribute_value(a));
    }
    encode_layer(path, width, height, la, list)
}

/// The `exr` crate's value of a portable attribute (text as UTF-8).
pub fn attribute_value(a: Attr) -> AttributeValue {
    match a {
        Attr::Text(s) => AttributeValue::Text(encode_text(&s)),
        Attr::Texts(v) => AttributeValue::TextVector(v.iter().map(|s| encode_text(s)).collect()),
        Attr::F64(x) => AttributeValue::F64(x),
        Attr::I32(x) => AttributeValue::I32(x),
    }
}

/// Channels of one layer with all their resolution levels, as the `exr` crate takes them.
pub type ChannelList = SmallVec<[AnyChannel<Levels<FlatSamples>>; 4]>;

/// The bytes of a single-part EXR of `channels` (channels with a MIP chain: tiled 64×64 ZIP
/// `MIPMAP_LEVELS` `ROUND_DOWN`, the form texture systems read; else scanline ZIP, 16 lines a
/// block), header attributes sorted so the same image always gives the same bytes (`path`
/// names it in errors only). Every EXR the workspace writes is encoded here.
pub fn encode_layer(
    path: &Path,
    width: usize,
    height: usize,
    attributes: LayerAttributes,
    channels: ChannelList,
) -> Result<Vec<u8>> {
    let mipped = channels
        .first()
        .is_some_and(|c| matches!(c.sample_data, Levels::Mip { .. }));
    let encoding = if mipped {
        Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::Tiles(Vec2(TILE, TILE)),
            line_order: LineOrder::Increasing,
        }
    } else {
        Encoding::SMALL_LOSSLESS
    };
    let layer = Layer::new(
        (width, height),
        attributes,
        encoding,
        AnyChannels::sort(channels),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| Error::Format {
            path: path.display().to_string(),
            reason: format!("writing EXR: {e}"),
        })?;
    let mut bytes = bytes.into_inner();
    sort_header_attributes(&mut bytes, path)?;
    Ok(bytes)
}

/// Rewrites the header of the single-part EXR in `bytes` with its attributes sorted by name.
///
/// The `exr` crate keeps custom attributes in a `HashMap` and writes them in its (random,
/// per-process) iteration order, so the same image would give different bytes on every run.
/// Sorting the attribute records in place keeps the header's length, so the offset table after
/// it stays valid, and makes files byte-identical for identical content.
pub fn sort_header_attributes(bytes: &mut [u8], path: &Path) -> Result<()> {
    let bad = || Error::Format {
        path: path.display().to_string(),
        reason: "writing EXR: unexpected header layout".into(),
    };
    // Magic number and version field, then records `name\0 type\0 size:i32 value[size]`,
    // ended by an empty name.
    let mut pos = 8;
    let mut records: Vec<(usize, usize)> = Vec::new();
    loop {
        let name_end = pos
            + bytes
                .get(pos..)
                .and_then(|b| b.iter().position(|&c| c == 0))
                .ok_or_else(bad)?;
        if name_end == pos {
            break;
        }
        let type_end = name_end
            + 1
            + bytes
                .get(name_end + 1..)
                .and_then(|b| b.iter().position(|&c| c == 0))
                .ok_or_else(bad)?;
        let size_at = type_end + 1;
        let size = i32::from_le_bytes(
            bytes
                .get(size_at..size_at + 4)
                .ok_or_else(bad)?
                .try_into()
                .unwrap(),
        );
        let end = size_at + 4 + usize::try_from(size).map_err(|_| bad())?;
        if end > bytes.len() {
            return Err(bad());
        }
        records.push((pos, end));
        pos = end;
    }
    let name = |r: &(usize, usize)| {
        let b = &bytes[r.0..r.1];
        b[..b.iter().position(|&c| c == 0).unwrap()].to_vec()
    };
    let mut sorted = records.clone();
    sorted.sort_by_key(|r| name(r));
    if sorted == records {
        return Ok(());
    }
    let header: Vec<u8> = sorted
        .iter()
        .flat_map(|&(a, b)| bytes[a..b].to_vec())
        .collect();
    bytes[8..8 + header.len()].copy_from_slice(&header);
    Ok(())
}

/// The contents of a single-part flat EXR: channels by name, header attributes by name.
pub struct Contents {
    /// The file, for messages.
    pub path: String,
    /// Width of the full-resolution level, pixels.
    pub width: usize,
    /// Height of the full-resolution level, pixels.
    pub height: usize,
    /// Full-resolution samples of each channel, row-major.
    pub channels: HashMap<String, Samples>,
    /// Coarser resolution levels 1, 2, … of each channel of a MIP-mapped file (else empty).
    pub levels: HashMap<String, Vec<Samples>>,
    /// Sizes of those levels.
    pub level_sizes: Vec<(usize, usize)>,
    /// Header attributes of the portable types, by name (others are skipped).
    pub attrs: HashMap<String, Attr>,
}

/// What every reader says of a file the exr crate cannot read, with the likely causes: cut
/// short (a copy or a write that did not finish) or not an OpenEXR file at all.
pub fn unreadable(e: impl std::fmt::Display) -> String {
    format!("not a readable OpenEXR file (truncated or foreign?): {e}")
}

/// The most uncompressed pixel bytes per byte of file a header may claim. Deflate cannot
/// exceed about 1032:1; RLE, PIZ and B44 stay far below. A header is read before its pixels
/// and the exr crate allocates whatever it claims: a mutated data window asked for 500 PB.
const MAX_COMPRESSION_RATIO: f64 = 4096.0;

/// Refuses a file whose headers claim more pixel data than `file_len` bytes can hold; every
/// reader of EXR files calls it before the exr crate allocates what a header claims.
pub fn check_claimed_size(path: &Path, file_len: u64) -> Result<()> {
    use exr::meta::attribute::LevelMode;
    use exr::meta::BlockDescription;
    let bad = |reason: String| Error::Format {
        path: path.display().to_string(),
        reason,
    };
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| bad(unreadable(e)))?;
    for h in meta.headers.iter() {
        // In f64: a corrupt size must be measured, not overflow.
        let (w, ht) = (h.layer_size.0 as f64, h.layer_size.1 as f64);
        let per_pixel: f64 = h
            .channels
            .list
            .iter()
            .map(|c| {
                let sub = (c.sampling.0.max(1) * c.sampling.1.max(1)) as f64;
                c.sample_type.bytes_per_sample() as f64 / sub
            })
            .sum();
        let levels = match h.blocks {
            BlockDescription::Tiles(t) => match t.level_mode {
                LevelMode::Singular => 1.0,
                LevelMode::MipMap => 4.0 / 3.0 + 1e-9,
                LevelMode::RipMap => 4.0,
            },
            BlockDescription::ScanLines => 1.0,
        };
        let claimed = w * ht * per_pixel * levels + 8.0 * h.chunk_count as f64;
        if claimed > MAX_COMPRESSION_RATIO * file_len as f64 + (64u64 << 20) as f64 {
            return Err(bad(format!(
                "its header claims {}×{} pixels of {} channels ({:.3e} bytes) but the file has \
                 {file_len} bytes: it is truncated or corrupt",
                h.layer_size.0,
                h.layer_size.1,
                h.channels.list.len(),
                claimed
            )));
        }
    }
    Ok(())
}

/// A single-part EXR as decoded, before any reader interprets it: every channel with all its
/// resolution levels as stored, and every header attribute (the part's and the file's shared
/// ones) verbatim, by name.
pub struct Decoded {
    /// The file, for messages.
    pub path: String,
    /// Width of the full-resolution level, pixels.
    pub width: usize,
    /// Height of the full-resolution level, pixels.
    pub height: usize,
    /// Every channel by name with its resolution levels, finest first: one for a plain image,
    /// the chain for a MIP map (a rip map's full-resolution level only: its diagonal is no MIP
    /// chain).
    pub channels: Vec<(String, Vec<FlatSamples>)>,
    /// Sizes of levels 1, 2, … of a MIP-mapped file, as its rounding mode gives them (empty
    /// without levels).
    pub level_sizes: Vec<(usize, usize)>,
    /// Every header attribute by name, verbatim (names decoded by [`decode_text`]).
    pub attrs: BTreeMap<String, AttributeValue>,
}

/// Decodes the single-part EXR at `path`: refuses a header that claims more pixels than the
/// file holds ([`check_claimed_size`]) before anything is allocated, then decodes every level
/// of every channel of the first layer, strictly (the exr crate's pedantic mode).
pub fn read_decoded(path: &Path) -> Result<Decoded> {
    let io = |e: std::io::Error| Error::Io {
        path: path.display().to_string(),
        source: e,
    };
    let file_len = std::fs::metadata(path).map_err(io)?.len();
    check_claimed_size(path, file_len)?;
    let file = std::fs::File::open(path).map_err(io)?;
    decode(path, std::io::BufReader::new(file))
}

/// Decodes an EXR held in memory, as [`read_decoded`] decodes a file (`shown` names it in
/// errors); for bytes this crate encoded, whose size is known to be sound.
pub fn decode_bytes(shown: &Path, bytes: &[u8]) -> Result<Decoded> {
    decode(shown, std::io::Cursor::new(bytes))
}

/// The one call of the exr crate's reader in the workspace.
fn decode(path: &Path, source: impl std::io::Read + std::io::Seek + Send) -> Result<Decoded> {
    let image = exr::prelude::read()
        .no_deep_data()
        .all_resolution_levels()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .pedantic()
        .from_buffered(source)
        .map_err(|e| Error::Format {
            path: path.display().to_string(),
            reason: unreadable(e),
        })?;
    let layer = image.layer_data;
    let size = layer.size;
    let mut level_sizes = Vec::new();
    let mut channels = Vec::with_capacity(layer.channel_data.list.len());
    for ch in layer.channel_data.list {
        let levels = match ch.sample_data {
            Levels::Singular(s) => vec![s],
            Levels::Mip {
                rounding_mode,
                level_data,
            } => {
                if level_sizes.is_empty() {
                    level_sizes = exr::meta::mip_map_levels(rounding_mode, size)
                        .skip(1)
                        .map(|(_, s)| (s.0, s.1))
                        .collect();
                }
                level_data
            }
            Levels::Rip { level_data, .. } => level_data.map_data.into_iter().take(1).collect(),
        };
        channels.push((decode_text(&ch.name), levels));
    }
    let attrs = layer
        .attributes
        .other
        .iter()
        .chain(&image.attributes.other)
        .map(|(k, v)| (decode_text(k), v.clone()))
        .collect();
    Ok(Decoded {
        path: path.display().to_string(),
        width: size.0,
        height: size.1,
        channels,
        level_sizes,
        attrs,
    })
}

/// Reads every channel and the portable attributes of the first layer ([`read_decoded`], then
/// [`Contents`]). Attributes of other types are skipped.
pub fn read(path: &Path) -> Result<Contents> {
    Ok(Contents::from(read_decoded(path)?))
}

impl From<Decoded> for Contents {
    fn from(d: Decoded) -> Contents {
        let samples = |s: FlatSamples| match s {
            FlatSamples::F32(v) => Samples::F32(v),
            FlatSamples::F16(v) => Samples::F16(v),
            FlatSamples::U32(v) => Samples::F32(v.into_iter().map(|x| x as f32).collect()),
        };
        let mut channels = HashMap::new();
        let mut levels = HashMap::new();
        for (name, list) in d.channels {
            let mut it = list.into_iter();
            let Some(first) = it.next() else { continue };
            channels.insert(name.clone(), samples(first));
            let rest: Vec<Samples> = it.map(samples).collect();
            if !rest.is_empty() {
                levels.insert(name, rest);
            }
        }
        let mut attrs = HashMap::new();
        for (name, value) in d.attrs {
            let a = match value {
                AttributeValue::Text(t) => Attr::Text(decode_text(&t)),
                AttributeValue::TextVector(v) => Attr::Texts(v.iter().map(decode_text).collect()),
                AttributeValue::F64(x) => Attr::F64(x),
                AttributeValue::F32(x) => Attr::F64(x as f64),
                AttributeValue::I32(x) => Attr::I32(x),
                _ => continue,
            };
            attrs.insert(name, a);
        }
        Contents {
            path: d.path,
            width: d.width,
            height: d.height,
            channels,
            level_sizes: if levels.is_empty() {
                Vec::new()
            } else {
                d.level_sizes
            },
            levels,
            attrs,
        }
    }
}

impl Contents {
    fn bad(&self, reason: String) -> Error {
        Error::Format {
            path: self.path.clone(),
            reason,
        }
    }

    /// Removes and returns channel `name` as f32, or an error naming it and what the file is.
    pub fn take_f32(&mut self, name: &str, what: &str) -> Result<Vec<f32>> {
        match self.channels.remove(name) {
            Some(Samples::F32(v)) => Ok(v),
            Some(Samples::F16(v)) => Ok(v.into_iter().map(f16::to_f32).collect()),
            None => Err(self.bad(format!(
                "{what} lacks channel `{name}` (the file is truncated in content or was written by another tool)"
            ))),
        }
    }

    /// Removes and returns the coarser levels of channel `name` as f32 (empty when the file has
    /// no MIP levels).
    pub fn take_levels_f32(&mut self, name: &str) -> Vec<Vec<f32>> {
        self.levels
            .remove(name)
            .unwrap_or_default()
            .into_iter()
            .map(|s| match s {
                Samples::F32(v) => v,
                Samples::F16(v) => v.into_iter().map(f16::to_f32).collect(),
            })
            .collect()
    }

    /// The text attribute `name`, or an error saying the `what` lacks it.
    pub fn text(&self, name: &str, what: &str) -> Result<String> {
        match self.attrs.get(name) {
            Some(Attr::Text(s)) => Ok(s.clone()),
            _ => Err(self.bad(format!("{what} lacks the text attribute `{name}`"))),
        }
    }

    /// The text-vector attribute `name`, or an error saying the `what` lacks it.
    pub fn texts(&self, name: &str, what: &str) -> Result<Vec<String>> {
        match self.attrs.get(name) {
            Some(Attr::Texts(v)) => Ok(v.clone()),
            _ => Err(self.bad(format!("{what} lacks the text-vector attribute `{name}`"))),
        }
    }

    /// The number attribute `name` (a double or an integer), or an error saying the `what` lacks it.
    pub fn f64(&self, name: &str, what: &str) -> Result<f64> {
        match self.attrs.get(name) {
            Some(Attr::F64(x)) => Ok(*x),
            Some(Attr::I32(x)) => Ok(*x as f64),
            _ => Err(self.bad(format!("{what} lacks the number attribute `{name}`"))),
        }
    }

    /// A format error naming this file, as the caller's error type (`ptm_fit::Error` converts).
    pub fn error<E: From<Error>>(&self, reason: impl Into<String>) -> E {
        self.bad(reason.into()).into()
    }
}
