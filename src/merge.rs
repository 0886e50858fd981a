//! `ptm merge`: assemble the parts of a farm bake (`ptm bake --shard I/N`) into exactly the
//! sample stack or PTM one machine would have written, with the `.lp` beside it.
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use ptm_fit::shard;
use ptm_format::atomic::Transaction;

use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// Part files, or directories holding them (every `*.part-*.exr` inside).
    #[arg(required = true, value_name = "PARTS")]
    pub parts: Vec<PathBuf>,
    /// Output: the stack (samples.exr) or PTM (NAME.ptm.exr) the parts are shards of.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
}

/// The part files `args.parts` names, directories expanded.
pub fn part_files(args: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in args {
        if p.is_dir() {
            let found = shard::parts_in(p)?;
            if found.is_empty() {
                bail!(
                    "{}: no part files (*.part-*.exr) in this directory",
                    p.display()
                );
            }
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// `ptm merge`: checks the parts and both destinations, merges, and publishes the output and
/// its `.lp` together; returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Merge> {
    let t0 = Instant::now();
    let all = part_files(&args.parts)?;
    // Each product's parts merge into its own file: the companion maps' (kind `maps`) beside
    // the output, K's (the stack or the PTM) into it.
    let (maps_parts, files) = split_maps(&all)?;
    // With the maps parts found beside K's.
    let all: Vec<PathBuf> = files.iter().chain(&maps_parts).cloned().collect();
    let maps_out = (!maps_parts.is_empty()).then(|| ptm_bake::maps::maps_path(&args.output));
    // No .lp beside a device (-o /dev/null).
    let lp = crate::outputs::lp_beside(&args.output);
    let mut outputs = vec![args.output.as_path()];
    outputs.extend(lp.as_deref());
    outputs.extend(maps_out.as_deref());
    let parts: Vec<(&str, &std::path::Path)> = all.iter().map(|p| ("part", p.as_path())).collect();
    crate::outputs::refuse_inputs(&outputs, &parts).context("give the merged file another name")?;
    // Both destinations are checked before the merge and published together after it.
    let mut tx = Transaction::new(&outputs)?;
    let bytes: u64 = all
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    let (merged, encoded) = shard::merge_encode(&files, &args.output)
        .with_context(|| format!("merging into {}", args.output.display()))?;
    let (lights, width, height, kind) = (&merged.lights, merged.width, merged.height, &merged.kind);
    let maps = match &maps_out {
        Some(out) => {
            let (_, maps) = shard::merge_encode(&maps_parts, out)
                .with_context(|| format!("merging into {}", out.display()))?;
            Some(maps)
        }
        None => None,
    };
    let t1 = Instant::now();
    tx.stage_bytes(&args.output, &encoded)?;
    if let (Some(out), Some(maps)) = (&maps_out, &maps) {
        tx.stage_bytes(out, maps)?;
    }
    if let Some(lp) = &lp {
        tx.stage_bytes(lp, lights.to_lp().as_bytes())?;
    }
    tx.commit()?;
    let t_write = t1.elapsed().as_secs_f64();
    let total = t0.elapsed().as_secs_f64();
    let out_bytes = encoded.len();
    eprintln!(
        "ptm merge: {} parts ({:.1} MB) → {} ({width}×{height}, {} lights){} in {total:.2} s",
        files.len(),
        bytes as f64 / 1e6,
        args.output.display(),
        lights.len(),
        lp.iter()
            .chain(&maps_out)
            .map(|p| format!(" and {}", p.display()))
            .collect::<String>()
    );
    Ok(json::Merge {
        output: json::path(&args.output),
        lights_file: lp.as_deref().map(json::path),
        kind: kind.clone(),
        parts: json::paths(&all),
        maps: maps_out.as_deref().map(json::path),
        width,
        height,
        lights: lights.len(),
        bytes_in: bytes,
        bytes_out: out_bytes,
        mb_per_s: bytes as f64 / 1e6 / total.max(1e-9),
        seconds: total,
        seconds_merge: total - t_write,
        seconds_write: t_write,
    })
}

/// Splits the parts into the companion maps' (kind `maps`) and the rest (K's), and checks that
/// both are parts of one bake: the same settings, swatch, software and size. Reads headers
/// only.
fn split_maps(parts: &[PathBuf]) -> anyhow::Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let (mut maps, mut k) = (Vec::new(), Vec::new());
    let mut first: [Option<(PathBuf, shard::PartMeta)>; 2] = [None, None];
    for p in parts {
        // A missing or unreadable part is the merge's to report, in its words.
        let Ok((meta, kind)) = shard::read_meta(p) else {
            k.push(p.clone());
            continue;
        };
        let slot = usize::from(kind == "maps");
        if slot == 1 {
            maps.push(p.clone());
        } else {
            k.push(p.clone());
        }
        first[slot].get_or_insert((p.clone(), meta));
    }
    if let [Some((pk, mk)), Some((pm, mm))] = &first {
        let same = |a: &shard::PartMeta, b: &shard::PartMeta| {
            (
                &a.settings,
                &a.swatch,
                &a.software,
                a.width,
                a.height,
                a.shard.count,
            ) == (
                &b.settings,
                &b.swatch,
                &b.software,
                b.width,
                b.height,
                b.shard.count,
            )
        };
        if !same(mk, mm) {
            bail!(
                "{} and {} are parts of different bakes (settings {:?} against {:?})",
                pk.display(),
                pm.display(),
                mk.settings,
                mm.settings
            );
        }
    }
    // Maps parts not given are found beside K's (`w.ptm.part-0000-of-0004.exr` →
    // `w.maps.part-0000-of-0004.exr`), so the K parts' glob or a batch merges them too; where
    // some of them exist, the set's check names those missing.
    if maps.is_empty() {
        if let Some((pk, mk)) = &first[0] {
            let beside: Vec<PathBuf> = k
                .iter()
                .filter_map(|p| maps_part_beside(p))
                .filter(|m| m.exists())
                .collect();
            if !beside.is_empty() {
                let want = (0..mk.shard.count).map(|index| {
                    shard::Shard {
                        index,
                        count: mk.shard.count,
                    }
                    .part_path(&ptm_bake::maps::maps_path(&output_of(pk)))
                });
                maps = want.collect();
            }
        }
    }
    if k.is_empty() && !maps.is_empty() {
        bail!(
            "only companion-map parts given ({}): give the stack or PTM parts of the same bake \
             too",
            maps[0].display()
        );
    }
    Ok((maps, k))
}

/// The output a part `NAME.part-IIII-of-NNNN.exr` is a shard of: `NAME.exr`.
fn output_of(part: &std::path::Path) -> PathBuf {
    let name = part
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = match name.rfind(".part-") {
        Some(i) => &name[..i],
        None => name.strip_suffix(".exr").unwrap_or(&name),
    };
    part.with_file_name(format!("{stem}.exr"))
}

/// The companion maps' part of the same shard as K's part `part`.
fn maps_part_beside(part: &std::path::Path) -> Option<PathBuf> {
    let name = part.file_name()?.to_string_lossy().into_owned();
    let suffix = &name[name.rfind(".part-")?..];
    let maps = ptm_bake::maps::maps_path(&output_of(part));
    let stem = maps.file_name()?.to_string_lossy().into_owned();
    let stem = stem.strip_suffix(".exr")?;
    Some(part.with_file_name(format!("{stem}{suffix}")))
}
