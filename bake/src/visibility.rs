//! The occlusion sampler: orthographic primary hits over the central tile (once), then per
//! light the occluded fraction K of every texel, traced in coherent packets of the CPU's native
//! width (16, 8 or 4 rays) within 4×4 texel blocks, a few lights per pass over the blocks, and
//! handed light by light to a sink.
//!
//! Determinism: sample positions come from a hash of (texel, sample, seed); each texel's K is
//! an integer count of occluded samples over an integer count of covered samples, so the output
//! is bit-identical for any thread count and for packets versus single rays.
use std::collections::HashMap;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use ptm_format::hash::splitmix64;
use ptm_format::LightSet;
use rayon::prelude::*;

use crate::embree::{self, Device, Packet, Scene, Valid};
use crate::facing::{Compact, Isa, MAX_RUN};
use crate::maps::{Surface, SurfaceHit};
use crate::ring::{self, Ring};
use crate::swatch::PreparedMesh;
use crate::tally;
use crate::tiling;
use crate::{Error, Result};

/// Bake settings. Defaults live in the CLI.
#[derive(Clone, Debug)]
pub struct BakeConfig {
    /// Texels (columns, rows) over the central tile.
    pub res: [usize; 2],
    /// Footprint samples per texel (stratified over an m×⌈spp/m⌉ grid, m = ⌈√spp⌉, jittered).
    pub spp: u32,
    /// Seed of the sample-position hash.
    pub seed: u64,
    /// `Some(R)`: point lights on a hemisphere of radius R (mesh units) centred at
    /// (W/2, H/2, 0) instead of distant lights.
    pub light_distance: Option<f64>,
    /// Trace shadow rays in packets of the native width (true) or one by one (same result).
    pub packets: bool,
    /// Worker threads (0: one per core).
    pub threads: usize,
}

/// The most worker threads a bake may ask for. The output does not depend on the count, and
/// each thread costs a stack and an Embree worker: `--threads 100000` ran for minutes starting
/// them.
pub const MAX_THREADS: usize = 1024;

/// Point lights beyond this many swatch sizes are refused: their directions differ from a
/// distant light's by less than 1e-6 rad across the tile, while the f32 ray directions Embree
/// squares overflow near 1e19 (at `--light-distance 1e38` 73 % of K came out 1).
pub const MAX_LIGHT_DISTANCE: f64 = 1e6;

/// Checks a point-light distance `r` (mesh units) against the swatch: every light of the
/// hemisphere of radius `r` about (W/2, H/2, 0) must lie outside the swatch's bounding box
/// (a light inside the cloth shadows nothing sensible), and `r` must stay within
/// [`MAX_LIGHT_DISTANCE`] swatch sizes.
pub fn check_light_distance(r: f64, swatch: &PreparedMesh) -> Result<()> {
    let b = &swatch.bounds;
    let centre = [swatch.tile[0] / 2.0, swatch.tile[1] / 2.0, 0.0];
    // Farthest corner of the bounds from the centre: the bounding box lies inside that sphere.
    let reach = (0..3)
        .map(|a| {
            let d = (b.min[a] - centre[a])
                .abs()
                .max((b.max[a] - centre[a]).abs());
            d * d
        })
        .sum::<f64>()
        .sqrt();
    let far = MAX_LIGHT_DISTANCE * swatch.scale();
    if !(r.is_finite() && r > reach) {
        return Err(Error::LightsInside { distance: r, reach });
    }
    if r > far {
        return Err(Error::LightsTooFar {
            distance: r,
            times: MAX_LIGHT_DISTANCE,
            scale: swatch.scale(),
        });
    }
    Ok(())
}

/// The frame every tracer of a bake works in (this crate's Embree baker, and the GPU's in
/// `ptm-gpubake`), so that both trace the same numbers: the swatch scaled by a power of two,
/// the shadow-ray offset, the clamp plane and the copies' margin.
pub struct Frame<'s> {
    /// The swatch in the baker's units: scaled by [`Frame::unit`] to a size in [0.5, 1).
    pub swatch: std::borrow::Cow<'s, PreparedMesh>,
    /// Baker units per mesh unit: a power of two (exact in floating point).
    pub unit: f64,
    /// Offset of shadow-ray origins along the face-forwarded normal (baker units).
    pub eps: f64,
    /// The clamp plane of shadow rays and the height of the camera (baker units).
    pub z_cap: f64,
    /// Widening of every copy's bounding box in the tiling rule (baker units).
    pub margin: f64,
}

impl<'s> Frame<'s> {
    /// The frame of `swatch`.
    pub fn new(swatch: &'s PreparedMesh) -> Frame<'s> {
        // Embree works in f32 with denormals flushed: at 1e-12 of a unit its products underflow
        // and primary rays miss; near 1e30 they overflow. K does not depend on scale, so bake a
        // copy scaled by a power of two (exact in floating point) to a size in [0.5, 1).
        let unit = (-(swatch.scale().log2().floor() + 1.0)).exp2();
        let (swatch, unit) = if unit != 1.0 && unit.is_finite() && unit > 0.0 {
            (std::borrow::Cow::Owned(swatch.scaled(unit)), unit)
        } else {
            (std::borrow::Cow::Borrowed(swatch), 1.0)
        };
        let scale = swatch.scale();
        Frame {
            unit,
            // Relative to the scene size: 1e-5 of it is ~100 f32 ulps of the coordinates
            // and 1/100 texel at 1024² (see notes: fixed epsilons fail at other scales).
            eps: 1e-5 * scale,
            z_cap: swatch.bounds.max[2] + 1e-3 * scale,
            margin: 1e-6 * scale,
            swatch,
        }
    }

    /// The primary sample a downward ray from (x, y) on the camera plane ([`Frame::z_cap`] in
    /// f32) makes when it hits at distance `t` a triangle of geometric normal `ng` (any length,
    /// either side): the shadow-ray origin (hit moved [`Frame::eps`] off the surface) and the
    /// unit normal face-forwarded towards the camera, in f32 as tracers take them, and the hit
    /// point in f64. None for a degenerate normal (counted as a miss).
    pub fn primary_sample(&self, xy: [f64; 2], t: f32, ng: [f32; 3]) -> Option<PrimarySample> {
        primary_sample(self.z_cap, self.eps, xy, t, ng)
    }
}

/// [`Frame::primary_sample`] for a frame's `z_cap` and `eps`.
pub fn primary_sample(
    z_cap: f64,
    eps: f64,
    xy: [f64; 2],
    t: f32,
    ng: [f32; 3],
) -> Option<PrimarySample> {
    let len = ng.iter().map(|&c| c as f64 * c as f64).sum::<f64>().sqrt();
    if len <= 0.0 {
        return None;
    }
    let sign = if ng[2] < 0.0 { -1.0 } else { 1.0 } / len;
    let n = ng.map(|c| c as f64 * sign);
    let p = [xy[0], xy[1], z_cap as f32 as f64 - t as f64];
    let mut org = [0.0f32; 3];
    for a in 0..3 {
        org[a] = (p[a] + eps * n[a]) as f32;
    }
    Some(PrimarySample {
        org,
        n32: n.map(|c| c as f32),
        n,
        p,
    })
}

/// One footprint sample's primary hit ([`Frame::primary_sample`]).
#[derive(Clone, Copy, Debug)]
pub struct PrimarySample {
    /// Shadow-ray origin (baker units).
    pub org: [f32; 3],
    /// Unit normal towards the camera, in f32 (what the facing test uses).
    pub n32: [f32; 3],
    /// The same normal in f64 (what the companion maps sum).
    pub n: [f64; 3],
    /// The hit point (baker units).
    pub p: [f64; 3],
}

/// Checks the settings every tracer refuses alike: resolution and samples, the rows of a shard
/// (non-empty, starting at a multiple of 4), the thread count and a point-light distance.
pub fn check_config(swatch: &PreparedMesh, cfg: &BakeConfig, rows: &Range<usize>) -> Result<()> {
    let [nx, ny] = cfg.res;
    if nx == 0 || ny == 0 || cfg.spp == 0 {
        return Err(Error::Config(format!(
            "resolution {nx}×{ny} and spp {} must be positive",
            cfg.spp
        )));
    }
    if !rows.start.is_multiple_of(4) || rows.is_empty() || rows.end > ny {
        return Err(Error::Config(format!(
            "rows {}..{} of {ny}: a shard must be a non-empty range of rows starting at a \
             multiple of 4",
            rows.start, rows.end
        )));
    }
    if cfg.threads > MAX_THREADS {
        return Err(Error::TooManyThreads {
            threads: cfg.threads,
            max: MAX_THREADS,
        });
    }
    if let Some(r) = cfg.light_distance {
        check_light_distance(r, swatch)?;
    }
    Ok(())
}

/// Figures of one bake, for `--json` and the benchmark.
#[derive(Clone, Debug, Default)]
pub struct BakeReport {
    /// Primary (camera) rays traced: texels × samples per texel.
    pub primary_rays: u64,
    /// Shadow rays traced over all lights.
    pub shadow_rays: u64,
    /// Samples counted occluded without tracing: surface facing away from the light, or the
    /// light at or below the horizon.
    pub shadow_rays_skipped: u64,
    /// Seconds building Embree scenes (central tile and shadow copies).
    pub seconds_scene: f64,
    /// Seconds tracing primary rays.
    pub seconds_primary: f64,
    /// Shadow tracing plus the sink's own time (shadow-scene builds count in `seconds_scene`).
    pub seconds_shadow: f64,
    /// Per light: rings of copies k (the block spans up to (2k+1)² copies).
    pub rings: Vec<u32>,
    /// Per light: copies in its shadow scene.
    pub copies: Vec<usize>,
    /// Shadow scenes built with the central copy as triangles ([`centred_pays`]): how many of
    /// the trace's distinct scenes of copies (0 where they were instances only).
    pub centred_scenes: usize,
    /// Texels whose footprint no primary ray hit (coverage 0).
    pub uncovered_texels: usize,
    /// Lights at or below the horizon (K = 1 wherever covered).
    pub below_horizon: Vec<usize>,
    /// Lights so close to the horizon that their shadow run was cut at
    /// `tiling::MAX_RUN_TILES` tiles: K there may be biased towards lit.
    pub capped: Vec<usize>,
}

/// The primary samples of every 4×4 texel block, the covered ones only, packed as shadow rays
/// take them: texel by texel (lane = 4·row + column in the block), each texel's samples in
/// order. Per block, runs of `cap` = 16·spp values: shadow-ray origins (hit points moved off
/// the surface) and unit normals face-forwarded towards the camera, one run per component,
/// then the texel lane of each entry. A block's share (1.6 KB at spp 4) stays in the nearest
/// cache while every light of a pass is traced over it, and a light reads covered samples
/// only, in runs (the layout before kept every sample slot and a hit bit per lane to test).
#[derive(Default)]
struct Blocks {
    /// Entries per block: 16 texels × spp.
    cap: usize,
    /// Per block: origin x, y, z, normal x, y, z, `cap` each.
    data: Vec<f32>,
    /// Per block: the texel lane of each entry.
    lane: Vec<u8>,
    /// Per block: covered samples of each texel (the block's first entries, texel by texel).
    covered: Vec<[u32; 16]>,
    /// Per block: the entries up to each texel's end, the running sums of `covered` (set by
    /// [`Blocks::seal`] once the blocks are filled).
    ends: Vec<[u32; 16]>,
}

impl Blocks {
    fn new(blocks: usize, spp: usize) -> Self {
        let cap = 16 * spp;
        Self {
            cap,
            data: vec![0.0; blocks * 6 * cap],
            lane: vec![0; blocks * cap],
            covered: vec![[0; 16]; blocks],
            ends: Vec::new(),
        }
    }

    /// The cache lines of a block's samples to prefetch per light of a pass of `lights`
    /// ([`Blocks::prefetch`]).
    fn lines_per_light(&self, lights: usize) -> usize {
        (6 * self.cap).div_ceil(16).div_ceil(lights.max(1))
    }

    /// Asks the CPU to bring cache lines `lines` of block `b`'s samples (if there is such a
    /// block) into the nearest cache ahead of their use: a few lines per light of the block
    /// before it ([`Blocks::lines_per_light`]), since a burst of a whole block's 24 lines waited
    /// on the CPU's fill buffers.
    fn prefetch(&self, b: usize, lines: Range<usize>) {
        #[cfg(target_arch = "x86_64")]
        if b < self.covered.len() {
            use std::arch::x86_64::*;
            let data = &self.data[b * 6 * self.cap..(b + 1) * 6 * self.cap];
            for line in lines.map(|l| l * 16).take_while(|&at| at < data.len()) {
                // SAFETY: a prefetch of memory of `data` (SSE, part of x86-64); it reads
                // nothing into the program.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(data.as_ptr().add(line).cast()) };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (b, lines);
    }

    /// Sums up each block's texel ends, once its samples are in.
    fn seal(&mut self) {
        self.ends = (self.covered.iter())
            .map(|covered| {
                let mut sum = 0;
                covered.map(|c| {
                    sum += c;
                    sum
                })
            })
            .collect();
    }

    /// The blocks' shares, in block order, to fill.
    fn shares_mut(&mut self) -> impl Iterator<Item = BlockMut<'_>> {
        let cap = self.cap;
        self.data
            .chunks_mut(6 * cap)
            .zip(self.lane.chunks_mut(cap))
            .zip(self.covered.iter_mut())
            .map(|((data, lane), covered)| BlockMut {
                data,
                lane,
                covered,
                len: 0,
            })
    }

    /// Block `b`'s samples.
    fn view(&self, b: usize) -> BlockView<'_> {
        let cap = self.cap;
        let covered = &self.covered[b];
        let len = covered.iter().sum::<u32>() as usize;
        let data = &self.data[b * 6 * cap..(b + 1) * 6 * cap];
        let run = |k: usize| &data[k * cap..k * cap + len];
        BlockView {
            org: [run(0), run(1), run(2)],
            n: [run(3), run(4), run(5)],
            lane: &self.lane[b * cap..b * cap + len],
            covered,
            ends: &self.ends[b],
        }
    }
}

/// One block's share of [`Blocks`], filled texel by texel in sample order.
struct BlockMut<'a> {
    data: &'a mut [f32],
    lane: &'a mut [u8],
    covered: &'a mut [u32; 16],
    len: usize,
}

impl BlockMut<'_> {
    fn push(&mut self, lane: usize, org: [f32; 3], n: [f32; 3]) {
        let (cap, i) = (self.lane.len(), self.len);
        for a in 0..3 {
            self.data[a * cap + i] = org[a];
            self.data[(3 + a) * cap + i] = n[a];
        }
        self.lane[i] = lane as u8;
        self.covered[lane] += 1;
        self.len += 1;
    }
}

/// One block's covered samples ([`Blocks::view`]): entry `e` is a sample of texel `lane[e]`.
struct BlockView<'a> {
    org: [&'a [f32]; 3],
    n: [&'a [f32]; 3],
    lane: &'a [u8],
    covered: &'a [u32; 16],
    /// The running sums of `covered`.
    ends: &'a [u32; 16],
}

/// Bytes a [`Baker`] holds for `res` texels at `spp` samples per texel: the primary samples
/// (padded to whole 4×4 blocks), coverage, and the K planes of two passes of lights
/// ([`lights_per_pass`]: one traced while the sink reads the other) with their (u, v) planes,
/// excluding the swatch's own scenes. What the sink keeps comes on top.
/// In f64: absurd requests must be measured, not overflow.
pub fn baker_bytes(res: [usize; 2], spp: u32) -> f64 {
    let blocks = res[0].div_ceil(4) as f64 * res[1].div_ceil(4) as f64;
    let texels = res[0] as f64 * res[1] as f64;
    let planes = (ring::SLOTS * lights_per_pass(res)) as f64;
    blocks * (16.0 * spp as f64 * 25.0 + 64.0) + texels * (4.0 + planes * (4.0 + 8.0))
}

/// Lights traced in one pass over the texel blocks ([`Baker::trace`]): each block's samples
/// are read once per pass, not once per light. Planes of a pass are held together (and those
/// of the pass before, which the sink reads meanwhile), so large images take fewer lights at a
/// time (at most 32 MiB of K planes a pass, at least one light).
pub fn lights_per_pass(res: [usize; 2]) -> usize {
    const MAX: f64 = 8.0;
    let plane = res[0] as f64 * res[1] as f64 * 4.0;
    ((32u64 << 20) as f64 / plane).floor().clamp(1.0, MAX) as usize
}

/// The most triangles, over all centred scenes of a bake, that [`centred_pays`] allows: each
/// holds its own BVH of the tile and a copy of its buffers ([`CENTRED_BYTES_PER_TRIANGLE`]:
/// 189 MB at this cap).
pub const CENTRED_MAX_TRIANGLES: usize = 1 << 21;

/// Bytes a centred scene holds per triangle of the tile: Embree's BVH8 of 4-triangle leaves
/// (70 bytes a triangle in its build statistics, allocation included) and the copied vertex
/// and index buffers (about 18).
pub const CENTRED_BYTES_PER_TRIANGLE: f64 = 90.0;

/// The most bytes the centred scenes of a trace of `lights` lights over `res` texels at `spp`
/// samples can hold ([`centred_pays`] with every sample covered): for the memory check
/// before a bake, beside [`baker_bytes`].
pub fn centred_bytes(res: [usize; 2], spp: u32, lights: usize) -> f64 {
    let rays = res[0] as f64 * res[1] as f64 * spp as f64 * lights as f64;
    (rays / 100.0).min(CENTRED_MAX_TRIANGLES as f64) * CENTRED_BYTES_PER_TRIANGLE
}

/// Whether a trace of `rays` shadow rays (covered samples × lights above the horizon) should
/// build its `sets` scenes of copies centred ([`Device::centred_instance_scene`]) for a tile of
/// `triangles`: when the builds stay within [`CENTRED_MAX_TRIANGLES`] and within one triangle
/// per 100 rays. Measured on a 2-core AVX-512 Xeon at 512² × 256 lights (bench_bake
/// `ours@centred` against `ours@instances`): rays/s +2.4 % on jersey (1,536 triangles, 35 sets),
/// +6.5 % on the plain weave (49,152), +2 % on velvet (47,616), whose 35 builds took 0.16 s:
/// about what the faster rays saved there, so the cut lies near one triangle per 100 rays
/// (a build ran at about 10 M triangles/s, rays at 33–60 M/s). The memory they may take is
/// [`centred_bytes`].
pub fn centred_pays(triangles: usize, sets: usize, rays: u64) -> bool {
    let built = triangles.saturating_mul(sets);
    built <= CENTRED_MAX_TRIANGLES && (built as u64).saturating_mul(100) <= rays
}

/// Receives each light's K plane (row-major, `res[0]` texels × the baker's rows, uncovered
/// texels 0) and,
/// for point lights, each texel's (u, v) of the mean direction to the light.
pub type Sink<'s> = dyn FnMut(usize, &[f32], Option<&[[f32; 2]]>) -> Result<()> + 's;

/// What traces a bake: this crate's [`Baker`] (Embree, on the CPU) or the GPU baker of
/// `ptm-gpubake` (wgpu ray queries). Each is built over the rows it traces, with its primary
/// hits done; [`Tracer::trace`] then hands every light's K plane to a sink, so the products
/// (stack, streaming fit, maps, farm parts) take either alike.
pub trait Tracer {
    /// The image rows traced (a farm shard's block, or all of them).
    fn rows(&self) -> Range<usize>;
    /// Fraction of each traced texel's samples whose primary ray hit the swatch (row-major).
    fn coverage(&self) -> &[f32];
    /// The primary hits' per-texel sums for the companion maps, when built to keep them.
    fn take_surface(&mut self) -> Option<Surface>;
    /// Traces every light of `lights` in order and hands each K plane to `sink`.
    fn trace(&mut self, lights: &LightSet, sink: &mut Sink) -> Result<BakeReport>;
}

impl Tracer for Baker {
    fn rows(&self) -> Range<usize> {
        Baker::rows(self)
    }
    fn coverage(&self) -> &[f32] {
        Baker::coverage(self)
    }
    fn take_surface(&mut self) -> Option<Surface> {
        Baker::take_surface(self)
    }
    fn trace(&mut self, lights: &LightSet, sink: &mut Sink) -> Result<BakeReport> {
        Baker::trace(self, lights, sink)
    }
}

/// A tile's vertex positions and triangles (vertex indices).
type TileMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// A scene built once and its primary hits; [`Baker::trace`] then runs any light set.
pub struct Baker {
    cfg: BakeConfig,
    /// Point-light distance in the baker's units (the swatch is scaled to a size in [0.5, 1)).
    light_distance: Option<f64>,
    tile: [f64; 2],
    bounds: crate::swatch::Bounds,
    /// Offset of shadow-ray origins along the normal, and the top clamp plane (mesh units).
    eps: f64,
    z_cap: f64,
    margin: f64,
    // Fields drop in order: the instance scenes, then the tile scene they instance, then the
    // device (Embree reference-counts all three anyway; this order needs none of it).
    /// Scenes of instances of the tile, one per set of copies.
    shadow_scenes: HashMap<Vec<[i32; 2]>, Scene>,
    /// The same with the central copy as triangles ([`Device::centred_instance_scene`]), for
    /// the traces where their builds pay ([`centred_pays`]).
    centred_scenes: HashMap<Vec<[i32; 2]>, Scene>,
    tile_scene: Scene,
    /// The tile's triangles as the tile scene has them (baker units), kept for centred scenes
    /// while their count is within [`CENTRED_MAX_TRIANGLES`]; none otherwise.
    tile_mesh: Option<TileMesh>,
    /// Centred scenes: `None` where [`centred_pays`] decides, else always or never
    /// ([`Baker::set_centred_scenes`]).
    centred: Option<bool>,
    device: Device,
    pool: rayon::ThreadPool,
    /// Image rows traced (all of them, or a shard's block-aligned share: `crate::shard`); for
    /// [`Baker::new_texels`] the rows of its compact image (4 texels wide).
    rows: Range<usize>,
    /// [`Baker::new_texels`]: the image texels (column, row) traced, in the compact image's
    /// row-major order; empty for a bake of whole rows.
    texels: Vec<[usize; 2]>,
    /// Blocks of 4×4 texels over the traced rows.
    blocks: [usize; 2],
    /// The primary samples, block by block.
    samples: Blocks,
    /// Lanes per `rtcOccluded` call: Embree's native packet width on this CPU
    /// ([`Device::packet_width`]), 1 for single rays.
    width: usize,
    /// The build of the facing test and compaction of distant lights' rays.
    isa: Isa,
    coverage: Vec<f32>,
    /// The primary hits' per-texel sums for the companion maps, when asked for
    /// ([`Baker::with_surface`]).
    surface: Option<Surface>,
    /// Mesh units per baker unit (the inverse of the power of two the swatch was scaled by).
    to_mesh: f64,
    /// Each triangle's material, for the surface's ids (empty without a surface).
    materials: Vec<u32>,
    report: BakeReport,
}

impl Baker {
    /// Builds the Embree scenes and traces the primary hits.
    pub fn new(swatch: &PreparedMesh, cfg: &BakeConfig) -> Result<Self> {
        Self::new_rows(swatch, cfg, 0..cfg.res[1])
    }

    /// As [`Baker::new`] for image rows `rows` only (a shard of a farm bake): planes handed to
    /// the sink and [`Baker::coverage`] then hold `rows.len()` rows. Sample positions hash the
    /// global texel index, so these rows are bit-identical to the same rows of a whole bake.
    /// `rows.start` must be a multiple of 4 (the tracer's texel blocks).
    pub fn new_rows(swatch: &PreparedMesh, cfg: &BakeConfig, rows: Range<usize>) -> Result<Self> {
        Self::build(swatch, cfg, rows, Vec::new(), false)
    }

    /// A baker of the image texels `texels` (column, row) only, in that order: the planes
    /// handed to the sink and [`Baker::coverage`] then hold a compact image 4 texels wide whose
    /// row-major texel `n` is `texels[n]` (rows padded to a multiple of 4 with texels that see
    /// nothing: coverage 0). Sample positions hash the image texel, and the K of a texel does
    /// not depend on which rays share its packets, so each texel's values are bit-identical to
    /// its values in a bake of the whole image. For the few texels a learned basis is learned
    /// on, traced before the rows of a farm shard.
    pub fn new_texels(
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        texels: &[[usize; 2]],
    ) -> Result<Self> {
        let [nx, ny] = cfg.res;
        if let Some(t) = texels.iter().find(|t| t[0] >= nx || t[1] >= ny) {
            return Err(Error::Config(format!(
                "texel ({}, {}) outside the {nx}×{ny} image",
                t[0], t[1]
            )));
        }
        if texels.is_empty() {
            return Err(Error::Config("no texel to trace".into()));
        }
        let rows = 0..texels.len().div_ceil(16) * 4;
        Self::build(swatch, cfg, rows, texels.to_vec(), false)
    }

    /// As [`Baker::new`] on an Embree device also given `embree`, an Embree device config
    /// string (`"isa=avx2"` runs Embree's AVX2 kernels, 8-ray packets, on a CPU with AVX-512):
    /// for benchmarks and checks of the kernels another CPU would run. Embree checks little
    /// (4.4 ignores keys it does not know and ran `isa=foo` as SSE): [`Baker::packet_width`]
    /// says which width it traces.
    pub fn with_embree_config(
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        embree: &str,
    ) -> Result<Self> {
        Self::build_on(swatch, cfg, 0..cfg.res[1], Vec::new(), false, embree)
    }

    /// As [`Baker::new_rows`], also summing the primary hits per texel for the companion maps
    /// (height and normal, [`Baker::take_surface`]). Tracing is the same: no ray is added.
    pub fn with_surface(
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        rows: Range<usize>,
    ) -> Result<Self> {
        Self::build(swatch, cfg, rows, Vec::new(), true)
    }

    /// The per-texel sums of the primary hits ([`Baker::with_surface`]; none otherwise),
    /// in mesh units.
    pub fn take_surface(&mut self) -> Option<Surface> {
        self.surface.take()
    }

    fn build(
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        rows: Range<usize>,
        texels: Vec<[usize; 2]>,
        surface: bool,
    ) -> Result<Self> {
        Self::build_on(swatch, cfg, rows, texels, surface, "")
    }

    fn build_on(
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        rows: Range<usize>,
        texels: Vec<[usize; 2]>,
        surface: bool,
        embree: &str,
    ) -> Result<Self> {
        let nx = if texels.is_empty() { cfg.res[0] } else { 4 };
        // A compact image's rows are its own; the checks of the settings are the same.
        let checked = if texels.is_empty() {
            rows.clone()
        } else {
            0..cfg.res[1].min(4)
        };
        check_config(swatch, cfg, &checked)?;
        let t0 = Instant::now();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(cfg.threads)
            .start_handler(|_| embree::set_ftz_daz())
            .build()
            .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
        let threads = (cfg.threads > 0).then(|| format!("threads={}", cfg.threads));
        let extra = (!embree.is_empty()).then_some(embree);
        let config: Vec<&str> = threads.as_deref().into_iter().chain(extra).collect();
        let device = Device::new(&config.join(","))?;
        let frame = Frame::new(swatch);
        let (unit, swatch) = (frame.unit, &*frame.swatch);
        let tile_scene = device.triangle_scene(&swatch.positions, &swatch.triangles)?;
        let width = if cfg.packets {
            device.packet_width()
        } else {
            1
        };
        let mut baker = Self {
            light_distance: cfg.light_distance.map(|r| r * unit),
            cfg: cfg.clone(),
            tile: swatch.tile,
            bounds: swatch.bounds,
            eps: frame.eps,
            z_cap: frame.z_cap,
            margin: frame.margin,
            device,
            tile_scene,
            shadow_scenes: HashMap::new(),
            centred_scenes: HashMap::new(),
            tile_mesh: (swatch.triangles.len() <= CENTRED_MAX_TRIANGLES)
                .then(|| (swatch.positions.clone(), swatch.triangles.clone())),
            centred: None,
            pool,
            width,
            isa: Isa::detect(),
            blocks: [nx.div_ceil(4), rows.len().div_ceil(4)],
            rows,
            texels,
            samples: Blocks::default(),
            coverage: Vec::new(),
            surface: surface.then(Surface::default),
            to_mesh: 1.0 / unit,
            materials: if surface {
                swatch.materials.clone()
            } else {
                Vec::new()
            },
            report: BakeReport::default(),
        };
        let primary_copies = tiling::copies_meeting(baker.tile, &baker.bounds, &[], baker.margin);
        baker.scene_for(&primary_copies, false)?;
        baker.report.seconds_scene = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        baker.primary(&primary_copies);
        baker.report.seconds_primary = t1.elapsed().as_secs_f64();
        Ok(baker)
    }

    /// Fraction of each texel's samples whose primary ray hit the swatch (row-major).
    pub fn coverage(&self) -> &[f32] {
        &self.coverage
    }

    /// Lanes per Embree shadow-ray call: the CPU's native packet width (16 with AVX-512, 8 with
    /// AVX2, 4 with SSE: [`Device::packet_width`]) when the config asks for packets, else 1.
    pub fn packet_width(&self) -> usize {
        self.width
    }

    /// Which build tests and compacts distant lights' rays from now on (`bake/src/facing.rs`):
    /// "auto" (the widest this CPU runs, the default), "avx512f", "avx2" or "portable". K is
    /// the same with each (tested); this is for tests and benchmarks of the fallbacks. A build
    /// this CPU lacks is refused.
    pub fn set_simd(&mut self, build: &str) -> Result<()> {
        let isa = match build {
            "auto" => Isa::detect(),
            "avx512f" => Isa::Avx512,
            "avx2" => Isa::Avx2,
            "portable" => Isa::Portable,
            _ => {
                return Err(Error::Config(format!(
                    "SIMD build {build:?}: auto, avx512f, avx2 or portable"
                )))
            }
        };
        if !isa.supported() {
            return Err(Error::Config(format!(
                "SIMD build {build:?}: this CPU does not run it (it runs {:?})",
                Isa::detect().name()
            )));
        }
        self.isa = isa;
        Ok(())
    }

    /// The build that tests and compacts distant lights' rays: "avx512f", "avx2" or
    /// "portable".
    pub fn simd(&self) -> &'static str {
        self.isa.name()
    }

    /// Traces shadow rays `width` lanes per Embree call from now on: 16, 8 or 4 (packets,
    /// native or traced one by one inside Embree) or 1 (`rtcOccluded1`). K is the same for
    /// every width (tested); the native width is the fastest.
    pub fn set_packet_width(&mut self, width: usize) -> Result<()> {
        if ![1, 4, 8, 16].contains(&width) {
            return Err(Error::Config(format!(
                "a shadow-ray packet of {width} lanes: Embree traces 1, 4, 8 or 16"
            )));
        }
        self.width = width;
        Ok(())
    }

    /// Whether shadow rays meet the central copy of the tile as triangles of their scene
    /// rather than as an instance ([`Device::centred_instance_scene`]): `None` (the default)
    /// where [`centred_pays`], `Some` always (for a tile of at most
    /// [`CENTRED_MAX_TRIANGLES`]) or never. The output is the same either way
    /// (`tests/widths.rs`).
    pub fn set_centred_scenes(&mut self, centred: Option<bool>) {
        self.centred = centred;
    }

    /// The image rows this baker traces (all rows unless built by [`Baker::new_rows`]; the
    /// compact image's for [`Baker::new_texels`]).
    pub fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }

    /// Texels per row of the planes: the image's, or 4 for [`Baker::new_texels`].
    fn width_traced(&self) -> usize {
        if self.texels.is_empty() {
            self.cfg.res[0]
        } else {
            4
        }
    }

    /// The scene of `copies` of the tile, built if not cached yet: instances only, or with
    /// the central copy as triangles where `centred` (which asks for the tile's triangles to
    /// be kept; without them a centred scene is one of instances, the same hits).
    fn scene_for(&mut self, copies: &[[i32; 2]], centred: bool) -> Result<&Scene> {
        let cache = if centred {
            &mut self.centred_scenes
        } else {
            &mut self.shadow_scenes
        };
        if !cache.contains_key(copies) {
            let offsets: Vec<[f32; 3]> = copies
                .iter()
                .map(|c| {
                    [
                        (c[0] as f64 * self.tile[0]) as f32,
                        (c[1] as f64 * self.tile[1]) as f32,
                        0.0,
                    ]
                })
                .collect();
            let (device, tile) = (&self.device, &self.tile_scene);
            let scene = match &self.tile_mesh {
                Some((positions, triangles)) if centred => {
                    device.centred_instance_scene(tile, positions, triangles, &offsets)?
                }
                _ => device.instance_scene(tile, &offsets)?,
            };
            cache.insert(copies.to_vec(), scene);
        }
        Ok(&cache[copies])
    }

    /// Primary pass: one `rtcIntersect1` straight down per footprint sample.
    fn primary(&mut self, copies: &[[i32; 2]]) {
        let scene = &self.shadow_scenes[copies];
        let nx = self.width_traced();
        let (row0, ny) = (self.rows.start, self.rows.end);
        let texels = &self.texels;
        let [bx, by] = self.blocks;
        let spp = self.cfg.spp as usize;
        let (res, tile, seed, eps) = (self.cfg.res, self.tile, self.cfg.seed, self.eps);
        // The camera sits on the clamp plane, above all geometry.
        let (z_cap, t_far) = (self.z_cap, f32::INFINITY);
        let z_top = z_cap as f32;
        let mut samples = Blocks::new(bx * by, spp);
        // With the companion maps, each block's per-texel sums of its hits too (its 16 lanes
        // as 16 texels, samples in order), gathered into the image's after the pass.
        let keep = self.surface.is_some();
        let mut sums: Vec<Surface> = if keep {
            (0..bx * by).map(|_| Surface::new(16, 1, spp)).collect()
        } else {
            Vec::new()
        };
        let sum_blocks = sums
            .iter_mut()
            .map(Some)
            .chain(std::iter::repeat_with(|| None));
        let blocks: Vec<_> = samples.shares_mut().zip(sum_blocks).collect();
        let (to_mesh, materials) = (self.to_mesh, &self.materials);
        self.pool.install(|| {
            blocks
                .into_par_iter()
                .enumerate()
                .for_each(|(b, (mut out, mut kept))| {
                    let (bi, bj) = (b % bx, b / bx);
                    for lane in 0..16 {
                        let (i, j) = (bi * 4 + lane % 4, row0 + bj * 4 + lane / 4);
                        if i >= nx || j >= ny {
                            continue;
                        }
                        // The image texel: (i, j) itself, or the compact image's entry.
                        let texel = if texels.is_empty() {
                            [i, j]
                        } else {
                            match texels.get(j * 4 + i) {
                                Some(&t) => t,
                                None => continue,
                            }
                        };
                        for s in 0..spp {
                            let [x, y] = sample_xy(res, tile, spp, seed, texel, s);
                            let org = [x as f32, y as f32, z_top];
                            let hit = scene.intersect1(org, [0.0, 0.0, -1.0], 0.0, t_far);
                            let sample = hit.and_then(|h| {
                                Some((h, primary_sample(z_cap, eps, [x, y], h.t, h.ng)?))
                            });
                            if let Some((h, ps)) = sample {
                                out.push(lane, ps.org, ps.n32);
                                if let Some(k) = kept.as_deref_mut() {
                                    let hit = SurfaceHit {
                                        z: ps.p[2] * to_mesh,
                                        n: ps.n,
                                        prim: h.prim,
                                    };
                                    let m = materials.get(h.prim as usize).copied();
                                    k.add(lane, s, &hit, m.unwrap_or(0));
                                }
                            }
                        }
                    }
                });
        });
        // Local rows from here on: row j of the planes is image row row0 + j.
        let ny = ny - row0;
        let mut coverage = vec![0.0f32; nx * ny];
        let mut uncovered = 0;
        for j in 0..ny {
            for i in 0..nx {
                let (b, lane) = ((j / 4) * bx + i / 4, (j % 4) * 4 + i % 4);
                let hits = samples.covered[b][lane] as usize;
                coverage[j * nx + i] = hits as f32 / spp as f32;
                uncovered += (hits == 0) as usize;
            }
        }
        if keep {
            let mut surface = Surface::new(nx, ny, spp);
            for j in 0..ny {
                for i in 0..nx {
                    let (b, lane) = ((j / 4) * bx + i / 4, (j % 4) * 4 + i % 4);
                    surface.copy_texel(j * nx + i, &sums[b], lane);
                }
            }
            self.surface = Some(surface);
        }
        // A compact image's padding is no texel of the image.
        let traced = if self.texels.is_empty() {
            nx * ny
        } else {
            self.texels.len()
        };
        self.report.primary_rays = (traced * spp) as u64;
        self.report.uncovered_texels = uncovered - (nx * ny - traced);
        samples.seal();
        self.samples = samples;
        self.coverage = coverage;
    }

    /// Traces every light of `lights` in order and hands each K plane to `sink`, on the
    /// calling thread, while the pool already traces the next pass of lights.
    pub fn trace(&mut self, lights: &LightSet, sink: &mut Sink) -> Result<BakeReport> {
        let t0 = Instant::now();
        let (nx, ny) = (self.width_traced(), self.rows.len());
        let centre = [self.tile[0] / 2.0, self.tile[1] / 2.0, 0.0];
        let mut rep = BakeReport {
            primary_rays: self.report.primary_rays,
            uncovered_texels: self.report.uncovered_texels,
            seconds_scene: self.report.seconds_scene,
            seconds_primary: self.report.seconds_primary,
            ..Default::default()
        };
        // Plan every light and build the scenes it needs first: scenes are built sequentially
        // and never while tracing.
        let mut plans = Vec::with_capacity(lights.len());
        for (li, &l) in lights.dirs.iter().enumerate() {
            let light = match self.light_distance {
                _ if l[2] <= 0.0 => None,
                // No −0 in a direction: Embree's instance transform turns it into +0, which the
                // central copy of a centred scene must see too (`x + 0.0` is +0 for ±0).
                None => Some(Light::Distant(l.map(|c| c as f32 + 0.0))),
                Some(r) => Some(Light::Point([0, 1, 2].map(|a| centre[a] + r * l[a]))),
            };
            let copies = match light {
                None => Vec::new(),
                Some(Light::Distant(_)) => {
                    tiling::copies_for_direction(self.tile, &self.bounds, l, self.margin)
                }
                Some(Light::Point(p)) => {
                    tiling::copies_for_point(self.tile, &self.bounds, p, self.margin)
                }
            };
            if light.is_some() && tiling::run_is_capped(self.tile, &self.bounds, l) {
                rep.capped.push(li);
            }
            rep.rings.push(tiling::rings(&copies));
            rep.copies.push(copies.len());
            if light.is_none() {
                rep.below_horizon.push(li);
            }
            plans.push((light, copies));
        }
        let mut sets: Vec<&[[i32; 2]]> = plans
            .iter()
            .filter(|(light, _)| light.is_some())
            .map(|(_, copies)| &copies[..])
            .collect();
        sets.sort();
        sets.dedup();
        let covered: u64 = self
            .samples
            .covered
            .iter()
            .flatten()
            .map(|&c| c as u64)
            .sum();
        let rays = covered * (plans.len() - rep.below_horizon.len()) as u64;
        let triangles = self.tile_mesh.as_ref().map_or(usize::MAX, |m| m.1.len());
        let centred = self
            .centred
            .unwrap_or_else(|| centred_pays(triangles, sets.len(), rays));
        let centred = centred && self.tile_mesh.is_some();
        if centred {
            rep.centred_scenes = sets.len();
        }
        for copies in sets {
            self.scene_for(copies, centred)?;
        }
        // Shadow scenes (a few µs each of instances only, milliseconds centred) count as scene
        // time, not tracing.
        let t_scenes = t0.elapsed().as_secs_f64();
        rep.seconds_scene += t_scenes;
        let t0 = Instant::now();
        let scenes = match centred {
            true => &self.centred_scenes,
            false => &self.shadow_scenes,
        };
        let runs: Vec<Run> = plans
            .iter()
            .map(|(light, copies)| Run {
                scene: light.map(|_| &scenes[copies]),
                light: *light,
                z_cap: self.z_cap,
                width: self.width,
                isa: self.isa,
            })
            .collect();
        let point = self.light_distance.is_some();
        let batch = lights_per_pass([nx, ny]);
        let passes: Vec<&[Run]> = runs.chunks(batch).collect();
        // Two passes' planes: the threads trace one while the sink reads the one before, so
        // they never meet between passes ([`ring`]).
        let ring = Ring::new(
            passes.len().min(ring::SLOTS),
            batch.min(runs.len()),
            [nx, ny],
            point,
        );
        let (traced, skipped) = (AtomicU64::new(0), AtomicU64::new(0));
        let (samples, [bx, by]) = (&self.samples, self.blocks);
        self.pool.in_place_scope(|s| -> Result<()> {
            // One task per row of blocks: its samples are contiguous and it owns 4 image rows
            // of every plane of the pass, so results go straight into the planes (no serial
            // scatter). Counts are integer sums, independent of the order tasks finish in.
            let spawn = |p: usize| {
                let (slot, pass) = (p % ring::SLOTS, passes[p]);
                ring.start(slot, by);
                for bj in 0..by {
                    let (ring, traced, skipped) = (&ring, &traced, &skipped);
                    s.spawn(move |_| {
                        let _done = ring.finisher(slot);
                        let mut planes: Vec<RowPlanes> = (0..pass.len())
                            // SAFETY: this task is the only one of the slot's pass with
                            // band `bj`, and it drops the rows before `_done`.
                            .map(|j| unsafe { ring.rows_mut(slot, j, bj) })
                            .collect();
                        let (t, k) = trace_band(samples, pass, &mut planes, bj, bx, nx);
                        traced.fetch_add(t, Ordering::Relaxed);
                        skipped.fetch_add(k, Ordering::Relaxed);
                    });
                }
            };
            for p in 0..passes.len().min(ring::SLOTS) {
                spawn(p);
            }
            for (p, pass) in passes.iter().enumerate() {
                let slot = p % ring::SLOTS;
                if !ring.wait(slot) {
                    // A task panicked: the scope re-raises it.
                    return Ok(());
                }
                for (j, run) in pass.iter().enumerate() {
                    // SAFETY: the slot's pass is done, and its next starts after the sink.
                    let (k, uv) = unsafe { ring.plane(slot, j) };
                    let uv = uv.filter(|_| matches!(run.light, Some(Light::Point(_))));
                    sink(p * batch + j, k, uv)?;
                }
                if p + ring::SLOTS < passes.len() {
                    spawn(p + ring::SLOTS);
                }
            }
            Ok(())
        })?;
        rep.shadow_rays += traced.into_inner();
        rep.shadow_rays_skipped += skipped.into_inner();
        rep.seconds_shadow = t0.elapsed().as_secs_f64();
        Ok(rep)
    }

    /// Builds the shadow scene of distant direction `l` if it is not cached yet (for the
    /// raw-Embree benchmark; [`Baker::trace`] does this itself).
    pub fn prepare_direction(&mut self, l: [f64; 3]) -> Result<()> {
        let copies = tiling::copies_for_direction(self.tile, &self.bounds, l, self.margin);
        self.scene_for(&copies, false).map(|_| ())
    }

    /// The shadow scene of distant direction `l`, once prepared.
    pub fn direction_scene(&self, l: [f64; 3]) -> Option<&Scene> {
        let copies = tiling::copies_for_direction(self.tile, &self.bounds, l, self.margin);
        self.shadow_scenes.get(&copies)
    }

    /// The clamp plane of shadow rays and the height of the camera (mesh units).
    pub fn z_cap(&self) -> f64 {
        self.z_cap
    }

    /// Offset of shadow-ray origins along the surface normal (mesh units).
    pub fn ray_offset(&self) -> f64 {
        self.eps
    }

    /// The scene primary rays are traced against (the copies overlapping the central tile).
    pub fn primary_scene(&self) -> &Scene {
        let copies = tiling::copies_meeting(self.tile, &self.bounds, &[], self.margin);
        &self.shadow_scenes[&copies]
    }

    /// The tile in the baker's units: the swatch's scaled by a power of two to a size in
    /// [0.5, 1) (what [`Baker::primary_scene`] holds).
    pub fn tile(&self) -> [f64; 2] {
        self.tile
    }
}

#[derive(Clone, Copy)]
enum Light {
    /// Unit direction towards a distant light.
    Distant([f32; 3]),
    /// Position of a point light (mesh units).
    Point([f64; 3]),
}

struct BlockResult {
    k: [f32; 16],
    /// Point lights only: each texel's (u, v).
    uv: Option<[[f32; 2]; 16]>,
    traced: u64,
    skipped: u64,
}

/// One task's share of one light's planes: its 4 rows of K and (point lights only) of (u, v).
type RowPlanes<'p> = (&'p mut [f32], &'p mut [[f32; 2]]);

/// One light's tracing state, shared by all blocks.
struct Run<'a> {
    scene: Option<&'a Scene>,
    light: Option<Light>,
    z_cap: f64,
    /// Lanes per `rtcOccluded` call: 16, 8 or 4 (packets), or 1 (`rtcOccluded1`).
    width: usize,
    /// The build of the facing test and compaction ([`crate::facing`]).
    isa: Isa,
}

impl Run<'_> {
    /// Shadow ray of entry `e` of `block`: direction (unit for distant lights, to the light for
    /// point lights), tfar (to the top clamp plane, where nothing lies above, and for a point
    /// light no further than the light, t = 1), and whether the surface faces the light at all
    /// (never for a light below the horizon).
    fn ray(&self, block: &BlockView, e: usize) -> ([f32; 3], f32, bool) {
        let org = [block.org[0][e], block.org[1][e], block.org[2][e]];
        let dir = match self.light {
            Some(Light::Distant(l)) => l,
            // +0.0: no −0 (see `Baker::trace`).
            Some(Light::Point(p)) => [0, 1, 2].map(|a| (p[a] - org[a] as f64) as f32 + 0.0),
            None => return ([0.0; 3], 0.0, false),
        };
        let n = [block.n[0][e], block.n[1][e], block.n[2][e]];
        let facing = dir[0] * n[0] + dir[1] * n[1] + dir[2] * n[2] > 0.0;
        let z_room = self.z_cap as f32 - org[2];
        let mut tfar = if dir[2] > 0.0 {
            (z_room / dir[2]).max(0.0)
        } else {
            f32::INFINITY
        };
        if matches!(self.light, Some(Light::Point(_))) {
            tfar = tfar.min(1.0);
        }
        (dir, tfar, facing)
    }

    fn block(&self, block: &BlockView, q: &mut Queues) -> BlockResult {
        match (self.light, self.scene, self.width) {
            (Some(Light::Distant(l)), Some(scene), 16) => {
                self.distant_w(block, l, scene, &mut q.w16, &mut q.marks)
            }
            (Some(Light::Distant(l)), Some(scene), 8) => {
                self.distant_w(block, l, scene, &mut q.w8, &mut q.marks)
            }
            (Some(Light::Distant(l)), Some(scene), 4) => {
                self.distant_w(block, l, scene, &mut q.w4, &mut q.marks)
            }
            (_, _, 16) => self.block_w(block, &mut q.w16),
            (_, _, 8) => self.block_w(block, &mut q.w8),
            (_, _, 4) => self.block_w(block, &mut q.w4),
            _ => self.block_w(block, &mut q.w1),
        }
    }

    /// [`Run::block_w`] for a distant light above the horizon, the common case, with what
    /// every ray of the block shares hoisted out of the loop: the direction is written into
    /// the packet once per block (Embree writes back only `tfar`); the facing test and the
    /// compaction of the facing samples run over up to 64 entries at a time, in AVX-512F,
    /// AVX2 or branch-free portable code ([`crate::facing`]); `tfar` is computed a packet at a
    /// time; nothing of a point light (per-ray direction, its (u, v) sums) is looked at; and
    /// the lit rays are counted per texel once per block from two bit masks, which entries
    /// faced the light and which rays came back lit ([`tally::block_k`], in AVX-512, AVX2 or
    /// portable code; [`tally::block_lit`] above spp 4), instead of an add into the ray's texel
    /// per ray, so no texel lane travels with the rays.
    /// The same rays in the same packets with the same `tfar` as [`Run::block_w`], so the same
    /// K to the bit (`tests/widths.rs`). Timed with the Embree calls left out (a local build),
    /// a jersey bake at 512² × 256 lights runs its shadow pass in 0.25–0.28 s, where the loop
    /// before this one (a sample at a time, per-lane hit bits) took 0.54–0.57 s (bench_bake,
    /// AVX-512 Xeon).
    fn distant_w<const W: usize>(
        &self,
        block: &BlockView,
        l: [f32; 3],
        scene: &Scene,
        queue: &mut Queue<W>,
        marks: &mut Marks,
    ) -> BlockResult {
        queue.toward(l);
        let z_cap = self.z_cap as f32;
        let len = block.lane.len();
        let Marks {
            compact,
            facing,
            lit,
        } = marks;
        facing.clear(len);
        lit.clear(len);
        // The rays to trace, compacted 64 entries at a time, then handed over a packet at a
        // time; fewer than a packet's wait for the next entries. `done`: the block's rays
        // traced so far, the bit of `lit` where the next packet's lanes go.
        let mut done = 0;
        compact.len = 0;
        for (word, start) in (0..len).step_by(MAX_RUN).enumerate() {
            let r = start..(start + MAX_RUN).min(len);
            let ([ox, oy, oz], [nx, ny, nz]) = (block.org, block.n);
            facing.words[word] = compact.push_facing(
                [&ox[r.clone()], &oy[r.clone()], &oz[r.clone()]],
                [&nx[r.clone()], &ny[r.clone()], &nz[r.clone()]],
                l,
                self.isa,
            );
            let mut at = 0;
            while compact.len - at >= W {
                queue.load(compact, at, W, z_cap, l[2]);
                lit.put(done, queue.trace_lit(scene));
                (at, done) = (at + W, done + W);
            }
            compact.shift(at);
        }
        if compact.len > 0 {
            queue.load(compact, 0, compact.len, z_cap, l[2]);
            lit.put(done, queue.trace_lit(scene));
            done += compact.len;
        }
        let traced = done as u64;
        if let ([f], [l]) = (&facing.words[..], &lit.words[..]) {
            return BlockResult {
                k: tally::block_k(*f, *l, block.covered, block.ends, self.isa),
                uv: None,
                traced,
                skipped: len as u64 - traced,
            };
        }
        let lit = tally::block_lit(&facing.words, &lit.words, block.ends);
        finish(&lit, block.covered, None, traced, len as u64 - traced)
    }

    /// K of one block's 16 texels, tracing `W` lanes per call. Texel by texel, each texel's
    /// samples in order ([`Blocks`]), so that a packet holds the samples of one or a few
    /// neighbouring texels (8 lanes at spp 4: two texels), the most coherent packets a block
    /// has: 26 % fewer Embree instructions per ray on the weave than packets of one sample of 8
    /// texels. Each texel's counts and direction sums run over its samples in their order.
    fn block_w<const W: usize>(&self, block: &BlockView, queue: &mut Queue<W>) -> BlockResult {
        let mut lit = [0u32; 16];
        let mut dir_sum = [[0.0f64; 3]; 16];
        let (mut traced, mut skipped) = (0u64, 0u64);
        let point = matches!(self.light, Some(Light::Point(_)));
        for (e, &lane) in block.lane.iter().enumerate() {
            let (dir, tfar, facing) = self.ray(block, e);
            if point {
                let len = dir.iter().map(|&c| c as f64 * c as f64).sum::<f64>().sqrt();
                for a in 0..3 {
                    dir_sum[lane as usize][a] += dir[a] as f64 / len;
                }
            }
            // Samples facing away from the light (all, for a light below the horizon) are
            // occluded without a ray.
            let Some(scene) = self.scene.filter(|_| facing) else {
                skipped += 1;
                continue;
            };
            traced += 1;
            let org = [block.org[0][e], block.org[1][e], block.org[2][e]];
            if W == 1 {
                lit[lane as usize] += !scene.occluded1(org, dir, 0.0, tfar) as u32;
            } else if queue.push(org, dir, tfar, lane) {
                queue.trace(scene, &mut lit);
            }
        }
        if let Some(scene) = self.scene {
            queue.trace(scene, &mut lit);
        }
        finish(
            &lit,
            block.covered,
            point.then_some(&dir_sum),
            traced,
            skipped,
        )
    }
}

/// Traces every light of `pass` over row `bj` of texel blocks (`bx` blocks, `nx` texels
/// wide) into that row's bands of the pass's planes; returns the rays traced and skipped.
fn trace_band(
    samples: &Blocks,
    pass: &[Run],
    planes: &mut [RowPlanes],
    bj: usize,
    bx: usize,
    nx: usize,
) -> (u64, u64) {
    let (mut traced, mut skipped) = (0u64, 0u64);
    let mut queues = Queues::default();
    let per = samples.lines_per_light(pass.len());
    // The task's image rows: 4, or fewer at the bottom.
    let rows_in = planes.first().map_or(0, |p| (p.0.len() / nx).min(4));
    for bi in 0..bx {
        let block = samples.view(bj * bx + bi);
        // Every light of the pass over this block while its samples are in the nearest cache.
        let lights = pass.iter().zip(planes.iter_mut()).enumerate();
        for (li, (run, (k_rows, uv_rows))) in lights {
            samples.prefetch(bj * bx + bi + 1, li * per..(li + 1) * per);
            let r = run.block(&block, &mut queues);
            traced += r.traced;
            skipped += r.skipped;
            // The block's texels in the task's rows: 4 or fewer of each row.
            let (i, w) = (bi * 4, 4.min(nx - bi * 4));
            for j in 0..rows_in {
                let at = j * nx + i;
                // A whole row of the block in one 16-byte move (a copy of `w` floats is a
                // `memcpy` call). Read out as an array: two `copy_from_slice`s, of 4 and of
                // `w`, were merged by LLVM into that one call of a run-time length.
                if w == 4 {
                    let row: [f32; 4] = std::array::from_fn(|c| r.k[j * 4 + c]);
                    k_rows[at..at + 4].copy_from_slice(&row);
                } else {
                    k_rows[at..at + w].copy_from_slice(&r.k[j * 4..j * 4 + w]);
                }
                if let Some(uv) = &r.uv {
                    uv_rows[at..at + w].copy_from_slice(&uv[j * 4..j * 4 + w]);
                }
            }
        }
    }
    (traced, skipped)
}

/// A block's K (occluded over covered samples per texel: the covered ones not found lit) and,
/// for a point light, the mean direction to it per texel as (u, v).
fn finish(
    lit: &[u32; 16],
    covered: &[u32; 16],
    dir_sum: Option<&[[f64; 3]; 16]>,
    traced: u64,
    skipped: u64,
) -> BlockResult {
    let mut out = BlockResult {
        k: [0.0; 16],
        uv: None,
        traced,
        skipped,
    };
    // Uncovered texels: 0 / 1.
    for ((k, &lit), &covered) in out.k.iter_mut().zip(lit).zip(covered) {
        *k = tally::k_of(covered, lit);
    }
    if let Some(dir_sum) = dir_sum {
        let mut uv = [[0.0; 2]; 16];
        for ((uv, d), &covered) in uv.iter_mut().zip(dir_sum).zip(covered) {
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if covered > 0 && len > 0.0 {
                *uv = [(d[0] / len) as f32, (d[1] / len) as f32];
            }
        }
        out.uv = Some(uv);
    }
    out
}

/// One queue of each packet width and one buffer of compacted rays, kept by a task across its
/// blocks and lights: a packet is 1.5 KB, and building one per block and light cost 1 % of a
/// bake in `memmove` alone.
#[derive(Default)]
struct Queues {
    w16: Queue<16>,
    w8: Queue<8>,
    w4: Queue<4>,
    /// Holds nothing: single rays go straight to `rtcOccluded1`.
    w1: Queue<1>,
    marks: Marks,
}

/// What [`Run::distant_w`] keeps of a block, whatever the width: its rays compacted, which
/// entries faced the light, and which rays came back lit.
#[derive(Default)]
struct Marks {
    compact: Box<Compact>,
    facing: Bits,
    lit: Bits,
}

/// A bit set of a block's entries or rays (16·spp at most).
#[derive(Default)]
struct Bits {
    words: Vec<u64>,
}

impl Bits {
    /// Room for `n` bits, all clear.
    fn clear(&mut self, n: usize) {
        self.words.clear();
        self.words.resize(n.div_ceil(64).max(1), 0);
    }

    /// Sets the bits from `at` on to those of `m` (a packet's lanes: `at` is a multiple of the
    /// packet width, which divides 64, so they all fall in one word).
    fn put(&mut self, at: usize, m: u32) {
        self.words[at / 64] |= (m as u64) << (at % 64);
    }
}

/// Shadow rays of one block waiting for a full packet of `W` lanes. The block's rays to be
/// traced (covered, facing the light) go into packets as they come, whatever texel or sample
/// they came from: all lie within the block's 4×4 texels and share the light, so the packets
/// stay coherent, and every call but the block's last is full.
struct Queue<const W: usize> {
    /// One packet, reused: Embree writes only `tfar` (its one-by-one fallback writes back every
    /// other field as it read it), so only origins, directions, tfar and the mask change.
    packet: Packet<W>,
    valid: Valid<W>,
    /// The block lane (texel) of each packet lane.
    lane: [u8; W],
    len: usize,
    /// The lanes `valid` marks active (the first `active`).
    active: usize,
}

impl<const W: usize> Default for Queue<W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const W: usize> Queue<W> {
    fn new() -> Self {
        Self {
            packet: Packet::default(),
            valid: Valid::default(),
            active: 0,
            lane: [0; W],
            len: 0,
        }
    }

    /// Points every lane in direction `dir` (Embree writes back only `tfar`, so it stays for
    /// every [`Queue::load`] of the block).
    fn toward(&mut self, dir: [f32; 3]) {
        self.packet.dir_x = [dir[0]; W];
        self.packet.dir_y = [dir[1]; W];
        self.packet.dir_z = [dir[2]; W];
    }

    /// Fills the packet with `n` rays of `c` from `at`, each ending at the clamp plane `z_cap`
    /// (`lz`: the light's z). All `W` lanes are copied, in straight lines (a copy of `n`, known
    /// only at run time, was a `memmove` call per component): lanes from `n` on hold whatever
    /// `c` holds there and stay inactive.
    fn load(&mut self, c: &Compact, at: usize, n: usize, z_cap: f32, lz: f32) {
        let p = &mut self.packet;
        p.org_x.copy_from_slice(&c.org[0][at..at + W]);
        p.org_y.copy_from_slice(&c.org[1][at..at + W]);
        p.org_z.copy_from_slice(&c.org[2][at..at + W]);
        for (t, &z) in p.tfar.iter_mut().zip(&p.org_z) {
            *t = ((z_cap - z) / lz).max(0.0);
        }
        self.len = n;
    }

    /// Appends a ray of the block's lane (texel) `lane`; true when the packet is full.
    fn push(&mut self, org: [f32; 3], dir: [f32; 3], tfar: f32, lane: u8) -> bool {
        let (p, i) = (&mut self.packet, self.len);
        p.dir_x[i] = dir[0];
        p.dir_y[i] = dir[1];
        p.dir_z[i] = dir[2];
        p.org_x[i] = org[0];
        p.org_y[i] = org[1];
        p.org_z[i] = org[2];
        p.tfar[i] = tfar;
        self.lane[i] = lane;
        self.len += 1;
        self.len == W
    }

    /// Traces the queued rays (if any) and counts the unoccluded ones into their texels.
    fn trace(&mut self, scene: &Scene, lit: &mut [u32; 16]) {
        let (n, m) = (self.len, self.trace_lit(scene));
        for (i, &lane) in self.lane[..n].iter().enumerate() {
            lit[lane as usize] += (m >> i) & 1;
        }
    }

    /// Traces the queued rays (if any) and empties the queue; returns which came back lit
    /// (unoccluded), bit `i` for lane `i`.
    fn trace_lit(&mut self, scene: &Scene) -> u32 {
        if self.len == 0 {
            return 0;
        }
        // Every packet of a block but its last is full: the mask changes only for that one.
        if self.active != self.len {
            for (i, v) in self.valid.0.iter_mut().enumerate() {
                *v = -((i < self.len) as i32);
            }
            self.active = self.len;
        }
        scene.occluded_packet(&self.valid, &mut self.packet);
        let n = std::mem::take(&mut self.len);
        self.packet.lit_mask() & (u32::MAX >> (32 - n))
    }
}

/// Position (x, y) in mesh units of footprint sample `s` of texel `[i, j]` (column, row): cell
/// (s mod m, s div m) of an m×⌈spp/m⌉ grid over the texel, m = ⌈√spp⌉, jittered by the hash.
pub fn sample_xy(
    res: [usize; 2],
    tile: [f64; 2],
    spp: usize,
    seed: u64,
    texel: [usize; 2],
    s: usize,
) -> [f64; 2] {
    let m = (spp as f64).sqrt().ceil() as usize;
    let rows = spp.div_ceil(m);
    let [i, j] = texel;
    let (jx, jy) = jitter((j * res[0] + i) as u64, s as u64, seed);
    let fx = ((s % m) as f64 + jx) / m as f64;
    let fy = ((s / m) as f64 + jy) / rows as f64;
    // Row 0 is the far edge y = H.
    [
        (i as f64 + fx) * tile[0] / res[0] as f64,
        tile[1] - (j as f64 + fy) * tile[1] / res[1] as f64,
    ]
}

/// Two uniform numbers in [0, 1) from (texel, sample, seed): SplitMix64 finalisers over a
/// combined key, 24 bits each (exact in f32 and f64).
fn jitter(texel: u64, sample: u64, seed: u64) -> (f64, f64) {
    let h = splitmix64(
        splitmix64(seed ^ 0x9e37_79b9_7f4a_7c15).wrapping_add(texel)
            ^ splitmix64(sample.wrapping_add(0x632b_e59b_d9b4_e019)),
    );
    let u = (h >> 40) as f64 / (1u64 << 24) as f64;
    let v = ((h >> 16) & 0xff_ffff) as f64 / (1u64 << 24) as f64;
    (u, v)
}

/// A plane collector: every light's K plane (and uv planes for point lights) in memory, for
/// `-o samples.exr` and tests.
#[derive(Clone, Debug, Default)]
pub struct Planes {
    /// Per light in order, the K plane (row-major, row 0 at y = H).
    pub k: Vec<Vec<f32>>,
    /// Per light, the (u, v) of the light seen from each texel (point lights only).
    pub uv: Option<Vec<Vec<[f32; 2]>>>,
}

impl Planes {
    /// Appends light `index`'s planes; a [`Sink`] for [`Baker::trace`] (lights arrive in order).
    pub fn push(&mut self, index: usize, k: &[f32], uv: Option<&[[f32; 2]]>) -> Result<()> {
        debug_assert_eq!(index, self.k.len());
        self.k.push(k.to_vec());
        if let Some(uv) = uv {
            self.uv.get_or_insert_with(Vec::new).push(uv.to_vec());
        }
        Ok(())
    }
}

/// Bakes `lights` over `swatch` into memory: (planes, coverage, report).
pub fn bake_planes(
    swatch: &PreparedMesh,
    lights: &LightSet,
    cfg: &BakeConfig,
) -> Result<(Planes, Vec<f32>, BakeReport)> {
    let mut baker = Baker::new(swatch, cfg)?;
    let mut planes = Planes::default();
    let report = baker.trace(lights, &mut |i, k, uv| planes.push(i, k, uv))?;
    Ok((planes, baker.coverage().to_vec(), report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centred_scenes_pay_within_the_cap_and_one_triangle_per_100_rays() {
        // Jersey at 512² × 256 lights: 1,536 triangles, 35 scenes, 178 M rays.
        assert!(centred_pays(1536, 35, 178_000_000));
        // The same tile at 64² × 16: 1,536 × 10 triangles for 170 k rays.
        assert!(!centred_pays(1536, 10, 170_000));
        // Within the ratio but over the memory cap.
        assert!(!centred_pays(CENTRED_MAX_TRIANGLES, 2, u64::MAX));
        assert!(centred_pays(CENTRED_MAX_TRIANGLES, 1, u64::MAX));
        // No overflow on absurd counts.
        assert!(!centred_pays(usize::MAX, usize::MAX, u64::MAX));
        // What the memory check counts: a triangle per 100 possible rays, up to the cap.
        let small = centred_bytes([64, 64], 4, 16);
        assert_eq!(
            small,
            64.0 * 64.0 * 4.0 * 16.0 / 100.0 * CENTRED_BYTES_PER_TRIANGLE
        );
        let cap = CENTRED_MAX_TRIANGLES as f64 * CENTRED_BYTES_PER_TRIANGLE;
        assert_eq!(centred_bytes([512, 512], 4, 256), cap);
        assert_eq!(
            centred_bytes([usize::MAX, usize::MAX], u32::MAX, usize::MAX),
            cap
        );
    }

    #[test]
    fn sample_jitter_is_pinned() {
        // Values of the bake's own splitmix64 before it moved to ptm_format::hash: sample
        // positions, and so every baked file, must not change.
        let q = |n: u32| n as f64 / (1u64 << 24) as f64;
        assert_eq!(jitter(0, 0, 0), (q(3_220_021), q(14_766_942)));
        assert_eq!(jitter(12_345, 7, 42), (q(9_344_779), q(6_093_084)));
    }

    #[test]
    fn every_tracing_thread_flushes_denormals() {
        let mesh = ptm_swatches::Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            tile: [1.0, 1.0],
        };
        let swatch = PreparedMesh::from_mesh(mesh, None, "quad").unwrap();
        let cfg = BakeConfig {
            res: [4, 4],
            spp: 1,
            seed: 0,
            light_distance: None,
            packets: true,
            threads: 2,
        };
        let baker = Baker::new(&swatch, &cfg).unwrap();
        let flags = baker.pool.broadcast(|_| embree::ftz_daz_enabled());
        assert_eq!(flags, vec![true, true]);
        assert_eq!(baker.coverage(), &[1.0; 16]);
    }

    #[test]
    fn light_distance_and_threads_are_bounded() {
        // A unit square at z ∈ [0, 0.5]: its bounds reach √(0.5² + 0.5² + 0.5²) ≈ 0.866 from
        // the tile centre.
        let mesh = ptm_swatches::Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.5],
                [0.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            tile: [1.0, 1.0],
        };
        let swatch = PreparedMesh::from_mesh(mesh, None, "quad").unwrap();
        assert!(check_light_distance(0.9, &swatch).is_ok());
        assert!(check_light_distance(1e6, &swatch).is_ok());
        for r in [0.5, 1e-30, 0.0, -3.0, f64::NAN] {
            let e = check_light_distance(r, &swatch).unwrap_err().to_string();
            assert!(
                e.contains("inside the swatch") && e.contains("8.6603e-1"),
                "{r}: {e}"
            );
        }
        for r in [1e38, 1e300, f64::INFINITY] {
            let e = check_light_distance(r, &swatch).unwrap_err().to_string();
            assert!(
                e.contains("distant to f32 precision") || e.contains("inside"),
                "{r}: {e}"
            );
        }
        let cfg = |threads, light_distance| BakeConfig {
            res: [4, 4],
            spp: 1,
            seed: 0,
            light_distance,
            packets: true,
            threads,
        };
        let e = Baker::new(&swatch, &cfg(100_000, None)).err().unwrap();
        assert!(
            matches!(
                e,
                Error::TooManyThreads {
                    threads: 100_000,
                    max: 1024
                }
            ),
            "{e}"
        );
        let e = Baker::new(&swatch, &cfg(1, Some(1e38)))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("distant to f32 precision"), "{e}");
    }

    #[test]
    fn jitter_is_uniform_and_decorrelated() {
        let mut mean = [0.0; 2];
        let n = 10_000;
        for t in 0..n {
            let (u, v) = jitter(t, 3, 7);
            assert!((0.0..1.0).contains(&u) && (0.0..1.0).contains(&v));
            mean[0] += u / n as f64;
            mean[1] += v / n as f64;
        }
        assert!(
            (mean[0] - 0.5).abs() < 0.01 && (mean[1] - 0.5).abs() < 0.01,
            "{mean:?}"
        );
        assert_ne!(jitter(1, 0, 0), jitter(0, 1, 0));
        assert_ne!(jitter(0, 0, 1), jitter(0, 0, 0));
    }
}
