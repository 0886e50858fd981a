//! `ptm batch manifest.toml`: many bakes (swatch × settings × output), each split into shards;
//! run here one after another, or (`--slurm DIR`) written as a Slurm array job with one task
//! per shard of every bake plus a merge job that runs after them. Slurm does the scheduling.
//!
//! Manifest: an optional `[defaults]` table and one `[[bake]]` table per bake. Every key but
//! `shards` is a `ptm bake` flag: `res = 256` → `--res 256`, `tile = [2, 1]` → `--tile 2,1`,
//! `single_rays = true` → `--single-rays`; `output` is required. Relative paths are relative
//! to the manifest's directory (tasks run there).
//! ```toml
//! [defaults]
//! res = 1024
//! dirs = 64
//! shards = 8
//!
//! [[bake]]
//! swatch = "builtin:plain-weave"
//! fit = "ptm6"
//! output = "out/weave.ptm.exr"
//! ```
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Parser;
use ptm_fit::shard::Shard;

use crate::json;

#[derive(clap::Args)]
pub struct Args {
    /// The manifest (TOML): `[defaults]` and `[[bake]]` tables of `ptm bake` flags.
    pub manifest: PathBuf,
    /// Write a Slurm array job into DIR (tasks.txt, bake.sbatch, merge.sbatch, submit.sh) and
    /// print the sbatch command instead of baking here.
    #[arg(long, value_name = "DIR")]
    pub slurm: Option<PathBuf>,
    /// With --slurm: at most N array tasks run at once (`--array=0-M%N`).
    #[arg(long, value_name = "N")]
    pub throttle: Option<usize>,
    /// With --slurm: extra `#SBATCH` option for both jobs (repeatable), e.g. --sbatch=--partition=ci.
    #[arg(long = "sbatch", value_name = "OPT", allow_hyphen_values = true)]
    pub sbatch: Vec<String>,
}

/// `ptm bake`'s flags alone, to check a manifest's bakes before anything runs.
#[derive(Parser)]
#[command(name = "ptm bake", no_binary_name = false)]
struct BakeLine {
    #[command(flatten)]
    args: crate::bake::Args,
}

/// One bake of the manifest: its `ptm bake` arguments (without `--shard`) and shard count.
#[derive(Clone, Debug)]
pub struct Job {
    pub args: Vec<String>,
    pub output: PathBuf,
    pub shards: usize,
}

fn flag_value(key: &str, v: &toml::Value) -> anyhow::Result<Option<String>> {
    Ok(Some(match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(x) => x.to_string(),
        toml::Value::Boolean(true) => return Ok(None),
        toml::Value::Array(a) => {
            let parts: anyhow::Result<Vec<String>> = a
                .iter()
                .map(|x| match flag_value(key, x)? {
                    Some(s) => Ok(s),
                    None => bail!("`{key}`: arrays hold numbers or strings"),
                })
                .collect();
            parts?.join(",")
        }
        _ => bail!("`{key}`: unsupported value {v}"),
    }))
}

/// Reads and checks a manifest: every bake's flags parse as `ptm bake` would parse them.
pub fn read_manifest(path: &Path) -> anyhow::Result<Vec<Job>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("{}: not valid TOML", path.display()))?;
    let empty = toml::Table::new();
    let defaults = match doc.get("defaults") {
        None => &empty,
        Some(toml::Value::Table(t)) => t,
        Some(_) => bail!("{}: `defaults` must be a table", path.display()),
    };
    if let Some(k) = doc.keys().find(|k| *k != "defaults" && *k != "bake") {
        bail!(
            "{}: unknown top-level key `{k}` (expected [defaults] and [[bake]])",
            path.display()
        );
    }
    let bakes = match doc.get("bake") {
        Some(toml::Value::Array(a)) if !a.is_empty() => a,
        _ => bail!("{}: no [[bake]] tables", path.display()),
    };
    let mut jobs = Vec::new();
    for (n, b) in bakes.iter().enumerate() {
        let what = format!("{}: bake {n}", path.display());
        let toml::Value::Table(b) = b else {
            bail!("{what}: not a table");
        };
        let mut merged = defaults.clone();
        merged.extend(b.clone());
        let shards = match merged.remove("shards") {
            None => 1,
            Some(toml::Value::Integer(i)) if i >= 1 => i as usize,
            Some(v) => bail!("{what}: shards = {v} must be a whole number >= 1"),
        };
        if merged.contains_key("shard") {
            bail!("{what}: `shard` is set by ptm batch; give `shards = N` instead");
        }
        let mut args = Vec::new();
        for (k, v) in &merged {
            let flag = format!("--{}", k.replace('_', "-"));
            if matches!(v, toml::Value::Boolean(false)) {
                continue;
            }
            args.push(flag);
            if let Some(s) = flag_value(k, v).with_context(|| what.clone())? {
                args.push(s);
            }
        }
        let line =
            BakeLine::try_parse_from(std::iter::once("bake".to_string()).chain(args.clone()))
                .map_err(|e| anyhow::anyhow!("{what}: {}", e.render().to_string().trim()))?;
        Shard {
            index: 0,
            count: shards,
        }
        .rows(line.args.res.last().copied().unwrap_or(0))
        .with_context(|| what.clone())?;
        jobs.push(Job {
            args,
            output: line.args.output.clone(),
            shards,
        });
    }
    Ok(jobs)
}

/// Single-quotes `s` for a POSIX shell.
fn quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=,@%+".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

fn part_paths(job: &Job) -> Vec<PathBuf> {
    (0..job.shards)
        .map(|index| {
            Shard {
                index,
                count: job.shards,
            }
            .part_path(&job.output)
        })
        .collect()
}

/// `ptm batch`: reads and checks the manifest, then bakes it here or writes the Slurm job;
/// returns what `--json` prints.
pub fn run(args: &Args) -> anyhow::Result<json::Batch> {
    let jobs = read_manifest(&args.manifest)?;
    let dir = args
        .manifest
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let dir = std::fs::canonicalize(dir).with_context(|| format!("{}", dir.display()))?;
    match &args.slurm {
        Some(out) => write_slurm(args, &jobs, &dir, out).map(json::Batch::Slurm),
        None => run_here(&jobs, &dir).map(json::Batch::Here),
    }
}

/// Bakes every shard of every job here, then merges each job (complete parts are kept).
fn run_here(jobs: &[Job], dir: &Path) -> anyhow::Result<json::BatchHere> {
    let t0 = Instant::now();
    std::env::set_current_dir(dir).with_context(|| format!("entering {}", dir.display()))?;
    let mut done = Vec::new();
    for (n, job) in jobs.iter().enumerate() {
        if let Some(parent) = job.output.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)?;
        }
        for i in 0..job.shards {
            let shard = format!("{i}/{}", job.shards);
            eprintln!(
                "ptm batch: bake {n}, shard {shard}: {}",
                job.output.display()
            );
            let line = BakeLine::try_parse_from(
                ["bake".to_string()]
                    .into_iter()
                    .chain(job.args.clone())
                    .chain(["--shard".into(), shard]),
            )?;
            crate::bake::run(&line.args)
                .with_context(|| format!("bake {n} ({})", job.output.display()))?;
        }
        let merge = crate::merge::Args {
            parts: part_paths(job),
            output: job.output.clone(),
        };
        crate::merge::run(&merge).with_context(|| format!("merging bake {n}"))?;
        done.push(dir.join(&job.output));
    }
    Ok(json::BatchHere {
        outputs: json::paths(&done),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Writes the Slurm job files and prints the command that submits them.
fn write_slurm(
    args: &Args,
    jobs: &[Job],
    dir: &Path,
    out: &Path,
) -> anyhow::Result<json::BatchSlurm> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let out = std::fs::canonicalize(out)?;
    let exe = std::env::current_exe().context("locating the ptm binary")?;
    let mut tasks = String::new();
    let mut merges = String::new();
    for job in jobs {
        for i in 0..job.shards {
            let mut line: Vec<String> = job.args.iter().map(|a| quote(a)).collect();
            line.push("--shard".into());
            line.push(format!("{i}/{}", job.shards));
            writeln!(tasks, "{}", line.join(" "))?;
        }
        let parts: Vec<String> = part_paths(job)
            .iter()
            .map(|p| quote(&p.to_string_lossy()))
            .collect();
        writeln!(
            merges,
            "{} -o {}",
            parts.join(" "),
            quote(&job.output.to_string_lossy())
        )?;
    }
    let n_tasks = tasks.lines().count();
    let extra: String = args
        .sbatch
        .iter()
        .map(|o| format!("#SBATCH {o}\n"))
        .collect();
    let head = |name: &str| {
        format!(
            "#!/bin/bash\n# Written by `ptm batch {}`.\n#SBATCH --job-name={name}\n{extra}set -euo pipefail\n\
             PTM=\"${{PTM:-{}}}\"\ncd {}\n",
            args.manifest.display(),
            quote(&exe.to_string_lossy()),
            quote(&dir.to_string_lossy())
        )
    };
    let bake = format!(
        "{}# One array task per shard: line SLURM_ARRAY_TASK_ID + 1 of tasks.txt. A task whose \
         part is already complete and valid skips it, so resubmitting retries only what failed.\n\
         line=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" {})\n\
         [ -n \"$line\" ] || {{ echo \"no task $SLURM_ARRAY_TASK_ID\" >&2; exit 2; }}\n\
         eval \"set -- $line\"\nexec \"$PTM\" bake \"$@\"\n",
        head("ptm-bake"),
        quote(&out.join("tasks.txt").to_string_lossy())
    );
    let merge = format!(
        "{}# After every bake task (afterany): merge each bake; a bake with a missing or damaged \
         part is refused by name and the job fails.\nstatus=0\n\
         while IFS= read -r line; do\n  eval \"set -- $line\"\n  \"$PTM\" merge \"$@\" || status=1\n\
         done < {}\nexit $status\n",
        head("ptm-merge"),
        quote(&out.join("merges.txt").to_string_lossy())
    );
    let throttle = args.throttle.map(|t| format!("%{t}")).unwrap_or_default();
    let submit = format!(
        "#!/bin/bash\nset -euo pipefail\ncd {}\n\
         jid=$(sbatch --parsable --array=0-{}{throttle} -o 'bake_%A_%a.log' bake.sbatch)\n\
         mid=$(sbatch --parsable --dependency=afterany:$jid -o 'merge_%j.log' merge.sbatch)\n\
         echo \"bake array $jid, merge $mid\"\n",
        quote(&out.to_string_lossy()),
        n_tasks - 1
    );
    // The job's five files are published together, none of them the manifest.
    let files = [
        ("tasks.txt", &tasks),
        ("merges.txt", &merges),
        ("bake.sbatch", &bake),
        ("merge.sbatch", &merge),
        ("submit.sh", &submit),
    ]
    .map(|(name, text)| (out.join(name), text));
    let paths: Vec<&Path> = files.iter().map(|(p, _)| p.as_path()).collect();
    crate::outputs::refuse_inputs(&paths, &[("manifest", args.manifest.as_path())])?;
    let mut tx = ptm_format::atomic::Transaction::new(&paths)?;
    for (path, text) in &files {
        tx.stage_bytes(path, text.as_bytes())?;
    }
    tx.commit()?;
    // The output directories must exist before the tasks write parts into them.
    for job in jobs {
        if let Some(parent) = job.output.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir.join(parent))?;
        }
    }
    let cmd = format!("bash {}", quote(&out.join("submit.sh").to_string_lossy()));
    eprintln!(
        "ptm batch: {} bakes, {n_tasks} shard tasks; submit with:\n  {cmd}",
        jobs.len()
    );
    Ok(json::BatchSlurm {
        bakes: jobs.len(),
        tasks: n_tasks,
        dir: json::path(&out),
        submit: cmd,
    })
}
