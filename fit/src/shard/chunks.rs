//! The byte layout of the single-part scanline EXRs `exrio` writes, as far as farm parts need
//! it: header records, the offset table and the compressed chunks. Lets a part be sealed with a
//! checksum of its bytes and lets the merge of a stack copy compressed chunks instead of
//! decoding and re-encoding a gigabyte of samples.
//!
//! Layout (OpenEXR 2): magic and version (8 bytes); header records `name\0 type\0 size:i32
//! value[size]`, sorted by name (`exrio` sorts them), ended by an empty name; the offset table
//! (u64 per chunk, absolute file positions); chunks `y:i32 size:i32 data[size]`, one per 16
//! scanlines under ZIP compression, in increasing y.
use std::ops::Range;

/// One header record: where it lies, and where its value lies.
#[derive(Clone, Debug)]
pub struct Record {
    pub name: String,
    pub span: Range<usize>,
    pub value: Range<usize>,
}

/// A parsed file: header records and the chunks (y of the first scanline, byte range of the
/// whole chunk, 8-byte prefix included).
#[derive(Clone, Debug)]
pub struct Layout {
    pub records: Vec<Record>,
    pub chunks: Vec<(i32, Range<usize>)>,
}

fn i32_at(b: &[u8], at: usize) -> Option<i32> {
    Some(i32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

impl Layout {
    /// Parses `bytes`; None when the file is cut short or its tables point outside it.
    pub fn parse(bytes: &[u8]) -> Option<Layout> {
        if bytes.get(..4)? != [0x76, 0x2f, 0x31, 0x01] {
            return None;
        }
        let mut pos = 8;
        let mut records = Vec::new();
        loop {
            let name_end = pos + bytes.get(pos..)?.iter().position(|&c| c == 0)?;
            if name_end == pos {
                pos += 1;
                break;
            }
            let type_end =
                name_end + 1 + bytes.get(name_end + 1..)?.iter().position(|&c| c == 0)?;
            let size = usize::try_from(i32_at(bytes, type_end + 1)?).ok()?;
            let value = type_end + 5..type_end + 5 + size;
            bytes.get(value.clone())?;
            records.push(Record {
                name: String::from_utf8_lossy(&bytes[pos..name_end]).into_owned(),
                span: pos..value.end,
                value: value.clone(),
            });
            pos = value.end;
        }
        let header_end = pos;
        let mut layout = Layout {
            records,
            chunks: Vec::new(),
        };
        let n = usize::try_from(i32_at(bytes, layout.value("chunkCount")?.start)?).ok()?;
        for i in 0..n {
            let at = header_end + 8 * i;
            let off = u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?) as usize;
            let y = i32_at(bytes, off)?;
            let size = usize::try_from(i32_at(bytes, off + 4)?).ok()?;
            let end = off.checked_add(8 + size)?;
            bytes.get(off..end)?;
            layout.chunks.push((y, off..end));
        }
        Some(layout)
    }

    /// The value bytes of record `name`.
    pub fn value(&self, name: &str) -> Option<Range<usize>> {
        self.records
            .iter()
            .find(|r| r.name == name)
            .map(|r| r.value.clone())
    }
}

/// CRC-32 of every byte of the file except the value of record `skip` (the checksum itself).
pub fn crc_without(bytes: &[u8], layout: &Layout, skip: &str) -> Option<u32> {
    let v = layout.value(skip)?;
    let mut h = crc32fast::Hasher::new();
    h.update(&bytes[..v.start]);
    h.update(&bytes[v.end..]);
    Some(h.finalize())
}

/// A box2i value (xmin, ymin, xmax, ymax) as stored.
pub fn box2i(x1: i32, y1: i32) -> [u8; 16] {
    let mut b = [0u8; 16];
    b[8..12].copy_from_slice(&x1.to_le_bytes());
    b[12..16].copy_from_slice(&y1.to_le_bytes());
    b
}

/// Assembles a scanline EXR from `magic` (8 bytes), header records (raw, in order) and chunks
/// (y, data after the 8-byte prefix), writing the offset table.
pub fn assemble(magic: &[u8], records: &[Vec<u8>], chunks: &[(i32, &[u8])]) -> Vec<u8> {
    let header: usize = 8 + records.iter().map(Vec::len).sum::<usize>() + 1;
    let data: usize = chunks.iter().map(|c| 8 + c.1.len()).sum();
    let mut out = Vec::with_capacity(header + 8 * chunks.len() + data);
    out.extend_from_slice(magic);
    for r in records {
        out.extend_from_slice(r);
    }
    out.push(0);
    let mut at = (header + 8 * chunks.len()) as u64;
    for c in chunks {
        out.extend_from_slice(&at.to_le_bytes());
        at += 8 + c.1.len() as u64;
    }
    for (y, d) in chunks {
        out.extend_from_slice(&y.to_le_bytes());
        out.extend_from_slice(&(d.len() as i32).to_le_bytes());
        out.extend_from_slice(d);
    }
    out
}
