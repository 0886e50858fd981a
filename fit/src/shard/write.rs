//! Writing a part file: its channels (a stack's K planes, coverage and (u, v); a PTM's
//! coefficients, RMS and coverage maps, and for the logistic link its max map, MIP levels and
//! pooled counts) and `part:*` attributes, encoded in memory, sealed with a CRC-32 of the
//! content and written atomically (see `shard.rs` for the layout and its reader).
use std::path::Path;

use super::partition::local_levels;
use super::{chunks, err, PartMeta, PtmPart, PART_VERSION};
use crate::logistic::image::data_warnings;
use crate::solve::{LearnedStats, LogisticStats};
use crate::stack::k_channel;
use crate::{Error, Result, SampleStack};
use ptm_format::exrio::{self, Attr, Samples};
use ptm_format::ptm::channel_name;
use ptm_format::{LightSet, Link};

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
    attrs: Vec<(&'static str, Attr)>,
) -> Result<()> {
    write_sealed_any(path, width, rows, channels, attrs)
}

/// [`write_sealed`] with attribute names of any lifetime.
fn write_sealed_any(
    path: &Path,
    width: usize,
    rows: usize,
    channels: Vec<(String, Samples)>,
    mut attrs: Vec<(&str, Attr)>,
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
        let data = data_warnings(stats);
        warnings = warnings.strip_suffix(&data[..]).unwrap_or(warnings);
        logistic_channels(meta, part, stats, &mut channels, &mut attrs)?;
    }
    if !warnings.is_empty() {
        let words = crate::diagnostic::words(warnings);
        attrs.push(("part:warnings", Attr::Texts(words)));
    }
    if let Some(table) = &ptm.learned {
        // The tables every part was fitted against (the merge checks they agree), in the PTM
        // file's own attributes, and what their learning did.
        let Some(st) = &fit.learned else {
            return Err(Error::Invalid(format!(
                "part {}: a learned basis without the statistics of its learning",
                meta.shard
            )));
        };
        attrs.extend(table.attrs());
        attrs.extend(learned_attrs(st));
    }
    write_sealed(path, ptm.width, ptm.height, channels, attrs)
}

/// What the learning of a part's basis did, as `part:learned*` numbers ([`super::read_part`]
/// reads them back).
fn learned_attrs(st: &LearnedStats) -> Vec<(&'static str, Attr)> {
    vec![
        ("part:learnedRoughness", Attr::F64(st.roughness)),
        ("part:learnedTexels", Attr::F64(st.texels as f64)),
        (
            "part:learnedAlternations",
            Attr::F64(st.alternations as f64),
        ),
        ("part:learnedKept", Attr::F64(st.kept as f64)),
        ("part:learnedDevianceStart", Attr::F64(st.deviance_start)),
        ("part:learnedDeviance", Attr::F64(st.deviance)),
        ("part:learnedRmsStart", Attr::F64(st.rms_start)),
        ("part:learnedRms", Attr::F64(st.rms)),
        ("part:learnedSeconds", Attr::F64(st.seconds)),
    ]
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

/// Writes the rows of a per-texel product that merges by concatenating rows (`part:kind`
/// `kind`, e.g. the companion maps: [`super::MergeRule::ConcatRows`]) as part `path`,
/// atomically: its channels for the shard's rows and its own header attributes, kept as given
/// (equal in every part of one bake), beside the `part:*` identity.
pub fn write_rows_part(
    path: &Path,
    meta: &PartMeta,
    kind: &str,
    width: usize,
    channels: Vec<(String, Vec<f32>)>,
    attrs: &[(&str, Attr)],
) -> Result<()> {
    check_rows(meta, width, meta.rows.len())?;
    let n = width * meta.rows.len();
    if let Some((name, _)) = channels.iter().find(|(_, v)| v.len() != n) {
        return Err(Error::Invalid(format!(
            "part {}: channel {name} does not hold {n} texels",
            meta.shard
        )));
    }
    if attrs.iter().any(|(k, _)| k.starts_with("part:")) {
        return Err(Error::Invalid(format!(
            "part {}: a product's own attributes may not be named part:*",
            meta.shard
        )));
    }
    let channels = channels
        .into_iter()
        .map(|(n, v)| (n, Samples::F32(v)))
        .collect();
    let mut attrs: Vec<(&str, Attr)> = attrs.to_vec();
    attrs.extend(meta_attrs(meta, kind));
    write_sealed_any(path, width, meta.rows.len(), channels, attrs)
}
