//! The merge of a farm bake's parts into exactly the file one machine writes: a stack by
//! copying the parts' compressed chunks under the whole image's header (`chunks.rs` knows the
//! scanline EXR byte layout), a PTM by concatenating the parts' rows and recomputing the
//! file-level facts ([`finish_fit`], the one place a new per-file figure goes); a logistic PTM's
//! deeper MIP levels are fitted here from the parts' pooled counts.
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use super::partition::{PartLevels, ROW_BLOCK};
use super::{chunks, err, read_header, read_meta, read_part, verify, PartData, PartMeta};
use crate::logistic::image::{coarse_levels, data_warnings};
use crate::mip::{identity_mips, Footprint};
use crate::simd::Isa;
use crate::solve::options::{ptm_coverage, ErrorStats, FitOptions, FitReport};
use crate::{Error, Result};
use ptm_format::exrio::Attr;
use ptm_format::{LightSet, Link, Ptm};

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
    let (lights, bytes) = match super::MergeRule::of(&kind) {
        Some(super::MergeRule::CopyChunks) => merge_stack(&set)?,
        Some(super::MergeRule::ConcatRows) => {
            (LightSet::from_dirs(Vec::new()), merge_rows(&set, out)?)
        }
        Some(super::MergeRule::Refit) => {
            let (ptm, fit, lights) = merge_ptm(&set)?;
            let save = ptm_format::SaveOptions {
                half: false,
                report: Some(&fit),
                error_map: false,
            };
            let bytes = ptm.encode(out, &save)?;
            (lights, bytes)
        }
        None => return Err(err(&set[0].0, format!("unknown part kind {kind:?}"))),
    };
    let merged = Merged {
        kind,
        width,
        height,
        lights,
    };
    Ok((merged, bytes))
}

/// Joins parts that merge by concatenating rows ([`super::MergeRule::ConcatRows`]): every
/// channel's rows in shard order under the product's own attributes (all but `part:*`, which
/// must be equal in every part), encoded by the writer a one-machine bake uses.
fn merge_rows(set: &[(PathBuf, PartMeta)], out: &Path) -> Result<Vec<u8>> {
    let mut channels: BTreeMap<String, Vec<f32>> = BTreeMap::new();
    let mut own: Option<BTreeMap<String, Attr>> = None;
    let (width, height) = (set[0].1.width, set[0].1.height);
    for (path, meta) in set {
        verify(path)?;
        let mut c = ptm_format::exrio::read(path)?;
        if c.width != width || c.height != meta.rows.len() {
            return Err(err(
                path,
                format!(
                    "holds {}×{} texels but names rows {}..{} of a {width}-wide image",
                    c.width, c.height, meta.rows.start, meta.rows.end
                ),
            ));
        }
        let attrs: BTreeMap<String, Attr> = c
            .attrs
            .drain()
            .filter(|(k, _)| !k.starts_with("part:"))
            .collect();
        match &own {
            None => own = Some(attrs),
            Some(a) if *a != attrs => {
                return Err(err(
                    path,
                    format!(
                        "its header differs from {}'s outside part:* (parts of one bake agree)",
                        set[0].0.display()
                    ),
                ))
            }
            Some(_) => {}
        }
        let names: Vec<String> = {
            let mut n: Vec<String> = c.channels.keys().cloned().collect();
            n.sort();
            n
        };
        if !channels.is_empty() && !names.iter().eq(channels.keys()) {
            return Err(err(
                path,
                format!(
                    "its channels differ from {}'s (parts of one bake agree)",
                    set[0].0.display()
                ),
            ));
        }
        for n in names {
            let v = c.take_f32(&n, "part")?;
            channels.entry(n).or_default().extend(v);
        }
    }
    let own = own.unwrap_or_default();
    let attrs: Vec<(&str, Attr)> = own.iter().map(|(k, v)| (k.as_str(), v.clone())).collect();
    let channels = channels
        .into_iter()
        .map(|(n, v)| (n, ptm_format::exrio::Samples::F32(v)))
        .collect();
    Ok(ptm_format::exrio::encode(
        out, width, height, channels, attrs,
    )?)
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
                    && p.ptm.learned == ptm.learned
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
                        "its fit (basis and its learned tables, link, lights, solver, rank, warnings) \
                         differs from the first part's",
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
        let isa = Isa::from_name(stats.kernel)
            .filter(|k| k.supported())
            .unwrap_or_else(Isa::detect);
        let opts = FitOptions {
            link: Link::Logistic,
            uv: ptm.uv,
            weight: levels.weight,
            regularize: Some(stats.lambda),
            tolerance: stats.tolerance,
            max_iterations: stats.max_iterations,
            mips,
            isa: Some(isa),
            rcond: fit.rcond,
            // A learned basis: the parts' tables (all equal, checked above) fit the deeper levels.
            given_basis: ptm
                .learned
                .clone()
                .map(|t| Box::new((t, fit.learned.clone().unwrap_or_default()))),
            ..FitOptions::new(ptm.basis)
        };
        let stats = stats.clone();
        fit.warnings.extend(data_warnings(&stats));
        fit.max = Some(ErrorStats::of(&fit.max_map, &masked));
        if mips {
            let chain = Footprint::chain(ptm.width, ptm.height);
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
                let deeper = coarse_levels(lights, &opts, cov, occ, above_w, &chain[s + 1..])?;
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
        ptm.mips = identity_mips(ptm, &coverage);
        fit.mip_levels = ptm.mips.len();
    }
    fit.rms = ErrorStats::of(&fit.rms_map, &masked);
    ptm.coverage = ptm_coverage(&coverage);
    fit.coverage = if coverage.iter().any(|&c| c < 1.0) {
        coverage
    } else {
        Vec::new()
    };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{write_stack_part, Shard};
    use super::*;
    use crate::SampleStack;

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
}
