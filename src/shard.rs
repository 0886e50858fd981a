//! `ptm bake --shard I/N`: what identifies a farm bake (its settings in words, which `ptm bake`
//! states, the swatch's content hash, the tool version) and the part file a shard writes
//! instead of the output. The partition, the part format and the merge live in `ptm_fit::shard`.
use std::path::Path;

use ptm_bake::PreparedMesh;
use ptm_fit::shard::{self, PartLevels, PartMeta, PtmPart, Shard};
use ptm_fit::{FitReport, SampleStack};
use ptm_format::{LightSet, Ptm};

/// Writer and version recorded in every part; parts of different versions never merge.
pub fn software() -> String {
    format!("ptm {}", env!("CARGO_PKG_VERSION"))
}

/// Content hash of the swatch as baked: positions, triangles and tile.
pub fn swatch_hash(swatch: &PreparedMesh) -> String {
    let pos: Vec<u8> = swatch
        .positions
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    let tri: Vec<u8> = swatch
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    let tile: Vec<u8> = swatch.tile.iter().flat_map(|c| c.to_le_bytes()).collect();
    shard::fingerprint([&pos[..], &tri[..], &tile[..]])
}

/// The identity of shard `s` of a bake of `res` texels with `settings` (in words: what
/// changes the output) of `swatch`.
pub fn meta(
    s: Shard,
    res: [usize; 2],
    settings: String,
    swatch: &PreparedMesh,
) -> anyhow::Result<PartMeta> {
    Ok(PartMeta {
        shard: s,
        rows: s.rows(res[1])?,
        width: res[0],
        height: res[1],
        settings,
        swatch: swatch_hash(swatch),
        software: software(),
    })
}

/// True when the part at `path` exists, is whole, passes its checksum and belongs to this very
/// bake: a resubmitted farm job then skips it. A damaged or foreign part is reported and baked
/// again.
pub fn is_complete(path: &Path, want: &PartMeta) -> bool {
    if !path.exists() {
        return false;
    }
    match shard::check_part(path) {
        Ok(meta) if meta == *want => true,
        Ok(p) => {
            eprintln!(
                "ptm bake: {} is a part of another bake (settings {:?}, software {:?}); baking \
                 it again",
                path.display(),
                p.settings,
                p.software
            );
            false
        }
        Err(e) => {
            eprintln!("ptm bake: {e}; baking it again");
            false
        }
    }
}

/// Writes the stack rows of a shard as its part.
pub fn write_stack(path: &Path, meta: &PartMeta, stack: SampleStack) -> anyhow::Result<()> {
    Ok(shard::write_stack_part(path, meta, stack)?)
}

/// Writes the fitted rows of a shard as its part (the coverage of its rows included, and a
/// logistic fit's MIP levels and pooled counts of its rows).
#[allow(clippy::too_many_arguments)]
pub fn write_ptm(
    path: &Path,
    meta: &PartMeta,
    ptm: Ptm,
    fit: FitReport,
    coverage: Vec<f32>,
    lights: &LightSet,
    mips: bool,
    levels: PartLevels,
) -> anyhow::Result<()> {
    let part = PtmPart {
        ptm,
        fit,
        coverage,
        lights: lights.clone(),
        mips,
        levels,
    };
    Ok(shard::write_ptm_part(path, meta, &part)?)
}

/// The learned basis of a farm shard's fit, learned as a bake of the whole image learns it:
/// the texels are tested for coverage in the learning's subsample order (a few thousand at a
/// time, by [`ptm_bake::Baker::new_texels`]) until [`ptm_fit::learned::MAX_SUBSAMPLE`] covered
/// ones are found (or the image runs out); those, in image order, are traced under every light
/// and the basis is learned from them alone ([`ptm_fit::Accumulator::learn_basis`]). Each shard
/// does this itself (deterministic, so every shard and the whole bake find the same tables),
/// so shards need no first pass and no order on the farm: a few thousand texels' rays and the
/// learning (seconds) per shard. `opts` are the fit's (a learned basis). Returns the tables,
/// the statistics of their learning and the seconds it all took.
pub fn learned_basis(
    swatch: &PreparedMesh,
    cfg: &ptm_bake::BakeConfig,
    lights: &LightSet,
    opts: &ptm_fit::FitOptions,
) -> anyhow::Result<(ptm_format::LearnedTable, ptm_fit::solve::LearnedStats, f64)> {
    use ptm_fit::learned::{subsample_order, MAX_SUBSAMPLE};
    let t0 = std::time::Instant::now();
    let [w, h] = cfg.res;
    let total = w * h;
    let at = |t: usize| [t % w, t / w];
    let mut n = (2 * MAX_SUBSAMPLE).min(total);
    let sub = loop {
        let order = subsample_order(total, n);
        let texels: Vec<[usize; 2]> = order.iter().map(|&t| at(t)).collect();
        let baker = ptm_bake::Baker::new_texels(swatch, cfg, &texels)?;
        let mut covered: Vec<usize> = order
            .iter()
            .zip(baker.coverage())
            .filter(|(_, &c)| c > 0.0)
            .map(|(&t, _)| t)
            .take(MAX_SUBSAMPLE)
            .collect();
        if covered.len() == MAX_SUBSAMPLE || n == total {
            covered.sort_unstable();
            break covered;
        }
        n = (4 * n).min(total);
    };
    if sub.is_empty() {
        anyhow::bail!(
            "no texel of the {w}×{h} image sees the swatch: there is no basis to learn (was the \
             swatch missed by the camera?)"
        );
    }
    let texels: Vec<[usize; 2]> = sub.iter().map(|&t| at(t)).collect();
    let mut baker = ptm_bake::Baker::new_texels(swatch, cfg, &texels)?;
    let mut acc = ptm_fit::Accumulator::new(lights, 4, baker.rows().len(), opts)?;
    acc.set_spp(cfg.spp)?;
    acc.set_coverage(baker.coverage())?;
    baker.trace(lights, &mut |i, k, _| {
        acc.add_light(i, k).map_err(ptm_bake::Error::sink)
    })?;
    let (table, stats) = acc.learn_basis()?;
    Ok((table, stats, t0.elapsed().as_secs_f64()))
}
