//! Benchmark: a farm bake's overhead. Bakes the same job (streaming ptm6 fit) once in one piece
//! and as N = 1, 2, 4, 8 shards run one after another on this machine, each shard as a farm
//! task would run it (load the swatch, build the scenes, trace the primary hits of its rows,
//! trace and fit every light over its rows, write its part), and prints per-stage sums against
//! the one-shot bake (target: total overhead ≤ 5 % at N = 8). The N-shard parts are merged and
//! compared byte for byte with the one-shot PTM. Then the merge's throughput on a stack of
//! `MERGE_LIGHTS` lights (built from the baked K planes, in 8 parts): read, check and
//! concatenate the parts, write the stack (target: 1024² × 256 lights ≤ 2 s).
//!
//! Each configuration runs REPEATS times, interleaved, and the fastest run counts (the CI-class
//! machine is shared: a slow run measures the neighbours, not the bake).
//!
//! `cargo run --release -p ptm-bake --example bench_shards [-- SWATCH RES LIGHTS SPP MERGE_LIGHTS REPEATS]`
use std::path::{Path, PathBuf};
use std::time::Instant;

use ptm_bake::{dome, BakeConfig, Baker, PreparedMesh};
use ptm_fit::shard::{self, PartMeta, PtmPart, Shard};
use ptm_fit::{Accumulator, FitOptions, SampleStack};
use ptm_format::{Basis, LightSet, SaveOptions};

/// Seconds per stage of one bake or shard.
#[derive(Clone, Copy, Default)]
struct Stages {
    load: f64,
    scene: f64,
    primary: f64,
    shadow: f64,
    solve: f64,
    write: f64,
    /// CPU seconds of the whole process over the bake (user + system, all threads): what farm
    /// slots pay, and much less disturbed than wall time by neighbours on a shared machine.
    cpu: f64,
    /// CPU seconds of the stages: swatch load, baker setup (thread pool, Embree device,
    /// scenes, primary hits), tracing + accumulating, solve, part or file write.
    cpu_stage: [f64; 5],
}

impl Stages {
    fn total(&self) -> f64 {
        self.load + self.scene + self.primary + self.shadow + self.solve + self.write
    }

    fn add(&mut self, o: &Stages) {
        self.load += o.load;
        self.scene += o.scene;
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.solve += o.solve;
        self.write += o.write;
        self.cpu += o.cpu;
        for (a, b) in self.cpu_stage.iter_mut().zip(o.cpu_stage) {
            *a += b;
        }
    }
}

/// User + system CPU seconds of this process so far, all threads (`CLOCK_PROCESS_CPUTIME_ID`,
/// nanosecond resolution: per-stage figures of a shard are a few hundredths of a second).
fn cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
    }
    const CLOCK_PROCESS_CPUTIME_ID: i32 = 2;
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: clock_gettime writes one timespec (two i64 on 64-bit Linux) to `ts`.
    if unsafe { clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &mut ts) } != 0 {
        return 0.0;
    }
    ts.sec as f64 + ts.nsec as f64 * 1e-9
}

struct Job<'a> {
    spec: &'a str,
    lights: &'a LightSet,
    cfg: BakeConfig,
}

/// Bakes `shard` (None: the whole image) and writes the PTM or its part; keeps the K planes
/// when `keep` is given.
fn bake(
    job: &Job,
    shard: Option<Shard>,
    out: &Path,
    keep: Option<&mut Vec<Vec<f32>>>,
) -> Result<(Stages, PathBuf), Box<dyn std::error::Error>> {
    let mut st = Stages::default();
    let cpu0 = cpu_seconds();
    let t = Instant::now();
    let swatch = PreparedMesh::load(job.spec, None)?;
    st.load = t.elapsed().as_secs_f64();
    let mut mark = cpu0;
    let mut stage = |st: &mut Stages, i: usize| {
        let now = cpu_seconds();
        st.cpu_stage[i] = now - mark;
        mark = now;
    };
    stage(&mut st, 0);
    let [w, h] = job.cfg.res;
    let rows = match shard {
        Some(s) => s.rows(h)?,
        None => 0..h,
    };
    let mut acc = Accumulator::new(job.lights, w, rows.len(), &FitOptions::new(Basis::Ptm6))?;
    let mut baker = Baker::new_rows(&swatch, &job.cfg, rows.clone())?;
    stage(&mut st, 1);
    let coverage = baker.coverage().to_vec();
    acc.set_coverage(&coverage)?;
    let mut keep = keep;
    let rep = baker.trace(job.lights, &mut |i, k, _| {
        if let Some(planes) = keep.as_deref_mut() {
            planes.push(k.to_vec());
        }
        acc.add_light(i, k).map_err(ptm_bake::Error::sink)
    })?;
    st.scene = rep.seconds_scene;
    st.primary = rep.seconds_primary;
    st.shadow = rep.seconds_shadow;
    drop(baker);
    stage(&mut st, 2);
    let t = Instant::now();
    let (ptm, fit) = acc.finish(swatch.tile)?;
    st.solve = t.elapsed().as_secs_f64();
    stage(&mut st, 3);
    let t = Instant::now();
    let path = match shard {
        None => {
            let save = SaveOptions {
                half: false,
                report: Some(&fit),
                error_map: false,
            };
            ptm.save(out, &save)?;
            out.to_path_buf()
        }
        Some(s) => {
            let meta = PartMeta {
                shard: s,
                rows,
                width: w,
                height: h,
                settings: "bench".into(),
                swatch: "bench".into(),
                software: "bench".into(),
            };
            let path = s.part_path(out);
            let part = PtmPart {
                ptm,
                fit,
                coverage,
                lights: job.lights.clone(),
                mips: false,
                levels: Default::default(),
            };
            shard::write_ptm_part(&path, &meta, &part)?;
            path
        }
    };
    st.write = t.elapsed().as_secs_f64();
    stage(&mut st, 4);
    st.cpu = cpu_seconds() - cpu0;
    Ok((st, path))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    let spec = arg(0, "builtin:plain-weave?segments=48&along=144");
    let res: usize = arg(1, "1024").parse()?;
    let n_lights: usize = arg(2, "64").parse()?;
    let spp: u32 = arg(3, "4").parse()?;
    let merge_lights: usize = arg(4, "256").parse()?;
    let repeats: usize = arg(5, "3").parse()?;
    let dir = tempdir()?;
    let lights = dome::fibonacci(n_lights, 5.0)?;
    let job = Job {
        spec: &spec,
        lights: &lights,
        cfg: BakeConfig {
            res: [res, res],
            spp,
            seed: 0,
            light_distance: None,
            packets: true,
            threads: 0,
        },
    };
    println!(
        "job: {spec}, {res}² texels, {n_lights} lights, spp {spp}, --fit ptm6, {} threads",
        rayon::current_num_threads()
    );
    let mut planes = Vec::new();
    let whole = dir.join("whole.ptm.exr");
    // The first bake warms caches and the allocator and keeps the K planes for the merge test.
    bake(&job, None, &whole, Some(&mut planes))?;
    let counts = [1usize, 2, 4, 8];
    let mut best: Vec<Option<Stages>> = vec![None; 1 + counts.len()];
    let keep = |b: &mut Option<Stages>, s: Stages| {
        if b.is_none_or(|b| s.cpu < b.cpu) {
            *b = Some(s);
        }
    };
    for _ in 0..repeats {
        keep(&mut best[0], bake(&job, None, &whole, None)?.0);
        for (c, &n) in counts.iter().enumerate() {
            let out = dir.join(format!("n{n}.ptm.exr"));
            let mut sum = Stages::default();
            for index in 0..n {
                sum.add(&bake(&job, Some(Shard { index, count: n }), &out, None)?.0);
            }
            keep(&mut best[c + 1], sum);
        }
    }
    let one = best[0].unwrap();
    let row = |name: &str, s: &Stages, base: Option<&Stages>| {
        let pct = |a: f64, b: f64| {
            format!(
                "{:+.1}%",
                100.0 * (a - b) / base.map_or(1.0, |_| b.max(1e-12))
            )
        };
        match base {
            None => println!(
                "{name:>9} | load {:.3} | scene {:.3} | primary {:.3} | shadow+fit {:.3} | solve {:.3} | write {:.3} | wall {:.3} s | cpu {:.2} s",
                s.load, s.scene, s.primary, s.shadow, s.solve, s.write, s.total(), s.cpu
            ),
            Some(b) => println!(
                "{name:>9} | load {:.3} | scene {:.3} | primary {:.3} | shadow+fit {:.3} | solve {:.3} | write {:.3} | wall {:.3} s ({}) | cpu {:.2} s ({}, per shard {:+.3} s)",
                s.load, s.scene, s.primary, s.shadow, s.solve, s.write, s.total(),
                pct(s.total(), b.total()),
                s.cpu,
                pct(s.cpu, b.cpu),
                (s.cpu - b.cpu) / name.trim_start_matches("N = ").parse::<f64>().unwrap_or(1.0)
            ),
        }
    };
    println!(
        "least CPU time of {repeats} interleaved runs each (overhead against the one-shot bake):"
    );
    let cpu_row = |name: &str, s: &Stages| {
        let c = s.cpu_stage;
        println!(
            "{name:>9} | CPU s: load {:.3} | setup (pool, device, scenes, primary) {:.3} | trace+accumulate {:.3} | solve {:.3} | write {:.3}",
            c[0], c[1], c[2], c[3], c[4]
        );
    };
    row("one-shot", &one, None);
    cpu_row("one-shot", &one);
    for (c, &n) in counts.iter().enumerate() {
        let out = dir.join(format!("n{n}.ptm.exr"));
        row(&format!("N = {n}"), &best[c + 1].unwrap(), Some(&one));
        cpu_row(&format!("N = {n}"), &best[c + 1].unwrap());
        let parts: Vec<PathBuf> = (0..n)
            .map(|index| Shard { index, count: n }.part_path(&out))
            .collect();
        let t = Instant::now();
        shard::merge_into(&parts, &out)?;
        let t_merge = t.elapsed().as_secs_f64();
        let bytes: u64 = parts
            .iter()
            .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
            .sum();
        println!(
            "          merge of the {n} PTM parts: {t_merge:.3} s ({:.0} MB of parts, {:.0} MB/s of f32 channels)",
            bytes as f64 / 1e6,
            (res * res * 8 * 4) as f64 / 1e6 / t_merge
        );
        assert!(
            std::fs::read(&out)? == std::fs::read(&whole)?,
            "merged N = {n} differs from the one-shot PTM"
        );
        for p in parts {
            std::fs::remove_file(p)?;
        }
    }
    println!("merged PTMs are byte-identical to the one-shot bake for N = 1, 2, 4, 8");

    // Merge throughput: a stack of `merge_lights` lights (the baked planes, cycled) in 8 parts.
    let mlights = dome::fibonacci(merge_lights, 5.0)?;
    let count = 8;
    let t = Instant::now();
    let mut paths = Vec::new();
    for index in 0..count {
        let s = Shard { index, count };
        let rows = s.rows(res)?;
        let cut = |p: &Vec<f32>| p[rows.start * res..rows.end * res].to_vec();
        let stack = SampleStack {
            width: res,
            height: rows.len(),
            tile: [1.0, 1.0],
            lights: mlights.clone(),
            k: (0..merge_lights)
                .map(|l| cut(&planes[l % planes.len()]))
                .collect(),
            coverage: vec![1.0; rows.len() * res],
            uv: None,
        };
        let meta = PartMeta {
            shard: s,
            rows,
            width: res,
            height: res,
            settings: "bench".into(),
            swatch: "bench".into(),
            software: "bench".into(),
        };
        let p = s.part_path(&dir.join("stack.exr"));
        shard::write_stack_part(&p, &meta, stack)?;
        paths.push(p);
    }
    let t_parts = t.elapsed().as_secs_f64();
    drop(planes);
    let bytes: u64 = paths
        .iter()
        .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
        .sum();
    let t = Instant::now();
    shard::merge_into(&paths, &dir.join("stack.exr"))?;
    let total = t.elapsed().as_secs_f64();
    // The whole stack written directly, for comparison (what a one-machine bake pays).
    let t = Instant::now();
    let whole_stack = SampleStack::read(&dir.join("stack.exr"))?;
    let t_decode = t.elapsed().as_secs_f64();
    let t = Instant::now();
    whole_stack.write_into(&dir.join("direct.exr"))?;
    let t_encode = t.elapsed().as_secs_f64();
    assert!(
        std::fs::read(dir.join("direct.exr"))? == std::fs::read(dir.join("stack.exr"))?,
        "the merged stack differs from the same stack written directly"
    );
    let raw = (res * res * merge_lights * 4) as f64;
    println!(
        "merge: {res}² × {merge_lights} lights in {count} parts ({:.0} MB of EXR, {:.0} MB of f32; \
         writing the parts took {t_parts:.2} s): {total:.3} s = {:.0} MB/s of part files, \
         {:.0} MB/s of samples (target ≤ 2 s); for comparison, decoding that stack takes \
         {t_decode:.2} s and encoding it {t_encode:.2} s (byte-identical)",
        bytes as f64 / 1e6,
        raw / 1e6,
        bytes as f64 / 1e6 / total,
        raw / 1e6 / total
    );
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}

/// A fresh directory under the system temporary directory.
fn tempdir() -> std::io::Result<PathBuf> {
    let d = std::env::temp_dir().join(format!("ptm-bench-shards-{}", std::process::id()));
    std::fs::create_dir_all(&d)?;
    Ok(d)
}
