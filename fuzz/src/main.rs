//! Mutation fuzzing of ptm's readers on stable Rust (cargo-fuzz needs nightly).
//!
//! Per reader (OBJ, `.lp`, WIF, sample-stack EXR, PTM EXR, renderer-layout parts, caster PNG) a seeded mutator (bit
//! flips, byte inserts and deletes, splices, interesting numbers and tokens) turns the files of
//! `fuzz/corpus/<reader>/` into mutants, and each runs in-process on the reader's
//! parse-and-validate path. A case fails when it panics, aborts (a memory allocation above the
//! bound fails and aborts), or runs past the time bound (a watchdog thread).
//!
//! The cases run in a child process (`ptm-fuzz child …`) so that an abort or a hang costs the
//! child, not the run: the parent reads which case the child had started, records it as a
//! finding under `fuzz/findings/`, and restarts the child after it. Mutant `i` of a reader
//! depends only on (seed, reader, i): a finding replays with `ptm-fuzz replay READER FILE`.
//! Cases 0..corpus are the corpus files unmutated (regression inputs live there).
//!
//! Usage: `ptm-fuzz [--cases N] [--seed S] [READER…]`, `ptm-fuzz replay READER FILE`,
//! `ptm-fuzz mutant READER SEED CASE OUT`, `ptm-fuzz gen-corpus`.
use std::alloc::{GlobalAlloc, Layout, System};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Live heap bytes above which an allocation fails (the case then aborts: a finding).
const MEMORY_LIMIT: usize = 512 << 20;
/// Wall time a case may take (debug-ish builds, two cores shared).
const TIME_LIMIT: Duration = Duration::from_secs(3);
/// Mutants are cut to this length.
const MAX_LEN: usize = 1 << 20;

/// Counts live heap bytes and refuses allocations above [`MEMORY_LIMIT`]. An allocator may not
/// unwind, so a refused allocation aborts the child (`handle_alloc_error`); the parent counts
/// that case as a finding.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size() > MEMORY_LIMIT {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size() > MEMORY_LIMIT {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: `ptr` came from `System` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            let grow = new_size - layout.size();
            if LIVE.fetch_add(grow, Ordering::Relaxed) + grow > MEMORY_LIMIT {
                LIVE.fetch_sub(grow, Ordering::Relaxed);
                return std::ptr::null_mut();
            }
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
        }
        // SAFETY: forwarded; `ptr` came from `System` with `layout`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A reader under test: its corpus folder, whether its inputs are text, and the
/// parse-and-validate path (`Err` is a clean refusal, the expected outcome of most mutants).
struct Reader {
    name: &'static str,
    ext: &'static str,
    text: bool,
    run: fn(&[u8], &Path) -> Result<(), String>,
}

const READERS: &[Reader] = &[
    Reader {
        name: "obj",
        ext: "obj",
        text: true,
        run: run_obj,
    },
    Reader {
        name: "lp",
        ext: "lp",
        text: true,
        run: run_lp,
    },
    Reader {
        name: "wif",
        ext: "wif",
        text: true,
        run: run_wif,
    },
    Reader {
        name: "stack",
        ext: "exr",
        text: false,
        run: run_stack,
    },
    Reader {
        name: "ptm",
        ext: "exr",
        text: false,
        run: run_ptm,
    },
    Reader {
        name: "layout",
        ext: "exr",
        text: false,
        run: run_layout,
    },
    Reader {
        name: "caster",
        ext: "png",
        text: false,
        run: run_caster,
    },
];

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// OBJ: the one reader (ptm_swatches::obj), f64 recentring, the swatch checks, and the tiling plans of a few
/// lights (the copies a mesh much larger than its tile would multiply).
fn run_obj(bytes: &[u8], _: &Path) -> Result<(), String> {
    use ptm_bake::{tiling, PreparedMesh};
    let obj = ptm_swatches::obj::parse_obj(bytes, "fuzz.obj").map_err(err)?;
    let tile = obj.tile;
    let (mesh, _) = obj.recentred(tile);
    let s = PreparedMesh::from_mesh(mesh, tile, "fuzz.obj").map_err(err)?;
    let _ = s.warnings();
    let margin = 1e-6 * s.scale();
    let mut copies = tiling::copies_meeting(s.tile, &s.bounds, &[], margin).len();
    for l in [
        [0.0, 0.0, 1.0],
        [0.6, 0.0, 0.8],
        [1.0, 0.0, 1e-9],
        [0.3, -0.3, 1e-320],
    ] {
        copies += tiling::copies_for_direction(s.tile, &s.bounds, l, margin).len();
    }
    let far = [s.tile[0] / 2.0 + 3.0 * s.scale(), 0.0, 2.0 * s.scale()];
    copies += tiling::copies_for_point(s.tile, &s.bounds, far, margin).len();
    if copies == 0 {
        return Err("no copies".into());
    }
    Ok(())
}

/// `.lp`: the parser, then the tiling plan of every light over a unit swatch (subnormal or
/// grazing directions).
fn run_lp(bytes: &[u8], _: &Path) -> Result<(), String> {
    let text = std::str::from_utf8(bytes).map_err(err)?;
    let set = ptm_format::LightSet::parse_lp(text, "fuzz.lp").map_err(err)?;
    let b = ptm_bake::swatch::Bounds {
        min: [0.0; 3],
        max: [1.0, 1.0, 0.4],
    };
    for d in set.dirs.iter().take(64) {
        assert!(
            d.iter().all(|c| c.is_finite()),
            "non-finite direction {d:?} accepted"
        );
        if d[2] > 0.0 {
            let _ = ptm_bake::tiling::copies_for_direction([1.0, 1.0], &b, *d, 1e-9);
        }
    }
    Ok(())
}

/// WIF (and the 0/1 grid the same files may hold).
fn run_wif(bytes: &[u8], _: &Path) -> Result<(), String> {
    let text = String::from_utf8_lossy(bytes);
    let _ = ptm_swatches::draft::parse_grid(&text, "fuzz.txt");
    let p = ptm_swatches::draft::parse_wif(&text, "fuzz.wif").map_err(err)?;
    if p.over.is_empty() {
        return Err("empty pattern".into());
    }
    Ok(())
}

/// Sample-stack EXR: read and validated.
fn run_stack(bytes: &[u8], tmp: &Path) -> Result<(), String> {
    let path = tmp.join("case.exr");
    std::fs::write(&path, bytes).map_err(err)?;
    let s = ptm_fit::SampleStack::read(&path).map_err(err)?;
    s.validate().map_err(err)?;
    Ok(())
}

/// PTM EXR: loaded and evaluated at its corners.
fn run_ptm(bytes: &[u8], tmp: &Path) -> Result<(), String> {
    let path = tmp.join("case.ptm.exr");
    std::fs::write(&path, bytes).map_err(err)?;
    let p = ptm_format::Ptm::load(&path).map_err(err)?;
    if p.width > 0 && p.height > 0 {
        let _ = p.eval(0, 0, 0.3, -0.2) + p.eval(p.width - 1, p.height - 1, 0.0, 0.9);
    }
    Ok(())
}

/// Part c1 of the renderer-layout ptm6 whose part c0 seeds the `layout` corpus (written by
/// `gen_corpus`): the partner every mutated c0 is read with.
const LAYOUT_C1: &[u8] = include_bytes!("../pair/ptm6.ptm.c1.exr");

/// Renderer layout (`ptm convert`'s and `Ptm` loading's reader of RGB(A) parts): the mutant is
/// part c0 beside a valid part c1, loaded, turned into a `Ptm` and evaluated at its corners.
fn run_layout(bytes: &[u8], tmp: &Path) -> Result<(), String> {
    let path = tmp.join("case.ptm.exr");
    std::fs::write(ptm_format::layout::part_path(&path, 0), bytes).map_err(err)?;
    std::fs::write(ptm_format::layout::part_path(&path, 1), LAYOUT_C1).map_err(err)?;
    let (file, _) = ptm_format::PtmFile::load(&path).map_err(err)?;
    let p = file.to_ptm(&path).map_err(err)?;
    if p.width > 0 && p.height > 0 {
        let _ = p.eval(0, 0, 0.3, -0.2) + p.eval(p.width - 1, p.height - 1, 0.0, 0.9);
    }
    Ok(())
}

/// Caster PNG: `ptm preview --caster`'s reader.
fn run_caster(bytes: &[u8], tmp: &Path) -> Result<(), String> {
    let path = tmp.join("case.png");
    std::fs::write(&path, bytes).map_err(err)?;
    let (w, h, px) = ptm_runtime::output::read_rgba8(&path).map_err(err)?;
    if px.len() != w * h {
        panic!("{w}×{h} caster with {} texels", px.len());
    }
    Ok(())
}

// splitmix64: mutants are a function of (seed, reader, case) alone.
use ptm_format::hash::SplitMix as Rng;

/// Numbers and tokens that break readers: zero, negative, huge counts, non-finite values,
/// subnormals, integer limits.
const TOKENS: &[&str] = &[
    "0",
    "-1",
    "1e18",
    "1000000000000",
    "1000000000000000000",
    "18446744073709551616",
    "4294967296",
    "2147483648",
    "nan",
    "inf",
    "-inf",
    "1e-320",
    "1e308",
    "-0",
    "1e11",
    "1e-30",
    "16384",
    "65536",
];

/// Whole lines that reach the readers' corner cases.
const LINES: &[&str] = &[
    "# tile 1e-30 1e-30\n",
    "# tile 1e30 1e30\n",
    "v 1e11 0 0\n",
    "f 0 1 2\n",
    "f -99 1 2\n",
    "f 1 2 3 4 5 6 7 8\n",
    "1000000000000\n",
    "a 1 0 1e-320\n",
    "\u{feff}",
    "# comment\n",
    "[WEAVING]\nShafts=1000000000000\nTreadles=1000000000000\n",
    "[LIFTPLAN]\n1=1,2,3,4\n",
    "[WARP]\nThreads=1024\n",
    "\r\n",
    "\u{fffd}\u{e9}\n",
];

/// Binary values written over 4 or 8 bytes: sizes, counts and offsets of binary formats.
const WORDS: &[u64] = &[
    0,
    1,
    0x7f,
    0xff,
    0x7fff,
    0xffff,
    0x1_0000,
    16384,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    u64::MAX,
    0x7ff8_0000_0000_0000, // f64 NaN
    0x7ff0_0000_0000_0000, // f64 inf
    0x0000_0000_0000_0001, // f64 smallest subnormal
    0x43ab_c16d_674e_c800, // f64 1e18
    0x7fc0_0000,           // f32 NaN
    0x7f80_0000,           // f32 inf
];

/// Mutant `case` of a reader: cases below the corpus size are the corpus files as they are.
fn mutant(seed: u64, reader: usize, case: u64, corpus: &[Vec<u8>], text: bool) -> Vec<u8> {
    if (case as usize) < corpus.len() {
        return corpus[case as usize].clone();
    }
    let mut r = Rng(seed ^ (reader as u64).wrapping_mul(0x5851_f42d_4c95_7f2d) ^ case << 20);
    r.next_u64();
    let mut d = corpus[r.below(corpus.len())].clone();
    for _ in 0..1 + r.below(4) {
        let n = d.len();
        match r.below(9) {
            0 if n > 0 => {
                let i = r.below(n);
                d[i] ^= 1 << r.below(8);
            }
            1 if n > 0 => {
                let i = r.below(n);
                d[i] = [
                    0,
                    0xff,
                    0x7f,
                    0x80,
                    b'\n',
                    b'-',
                    b'9',
                    0xe9,
                    r.next_u64() as u8,
                ][r.below(9)];
            }
            2 => {
                let i = r.below(n + 1);
                let bytes: Vec<u8> = (0..1 + r.below(8)).map(|_| r.next_u64() as u8).collect();
                d.splice(i..i, bytes);
            }
            3 if n > 0 => {
                let i = r.below(n);
                let len = (1 + r.below(16)).min(n - i);
                d.drain(i..i + len);
            }
            4 if n > 0 => {
                // Duplicate a range elsewhere (repeated lines, chunks, attributes).
                let i = r.below(n);
                let len = (1 + r.below(64)).min(n - i);
                let piece = d[i..i + len].to_vec();
                let at = r.below(n + 1);
                d.splice(at..at, piece);
            }
            5 => {
                // Splice: a prefix of this input, a suffix of another.
                let other = &corpus[r.below(corpus.len())];
                let (a, b) = (r.below(n + 1), r.below(other.len() + 1));
                d.truncate(a);
                d.extend_from_slice(&other[b..]);
            }
            6 if text => {
                // Replace a number with an interesting one.
                let starts: Vec<usize> = (0..n)
                    .filter(|&i| d[i].is_ascii_digit() && (i == 0 || !d[i - 1].is_ascii_digit()))
                    .collect();
                if !starts.is_empty() {
                    let i = starts[r.below(starts.len())];
                    let end = (i..n).find(|&k| !d[k].is_ascii_digit()).unwrap_or(n);
                    let tok = TOKENS[r.below(TOKENS.len())].as_bytes().to_vec();
                    d.splice(i..end, tok);
                }
            }
            6 if n >= 8 => {
                let w = WORDS[r.below(WORDS.len())];
                let i = r.below(n - 7);
                if r.below(2) == 0 {
                    d[i..i + 4].copy_from_slice(&(w as u32).to_le_bytes());
                } else {
                    d[i..i + 8].copy_from_slice(&w.to_le_bytes());
                }
            }
            7 if text => {
                // An interesting line at a line start.
                let starts: Vec<usize> = std::iter::once(0)
                    .chain((0..n).filter(|&i| d[i] == b'\n').map(|i| i + 1))
                    .collect();
                let i = starts[r.below(starts.len())];
                let line = LINES[r.below(LINES.len())].as_bytes().to_vec();
                d.splice(i..i, line);
            }
            7 => d.truncate(r.below(n + 1)),
            _ if n > 0 => {
                // A run of one byte (long lines, long names, zero fills).
                let i = r.below(n);
                let len = (1 + r.below(256)).min(n - i);
                let b = d[r.below(n)];
                d[i..i + len].fill(b);
            }
            _ => {}
        }
    }
    d.truncate(MAX_LEN);
    d
}

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus")
}

fn load_corpus(reader: &Reader) -> Vec<Vec<u8>> {
    let dir = corpus_dir().join(reader.name);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let corpus: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    assert!(!corpus.is_empty(), "{}: empty corpus", dir.display());
    corpus
}

fn reader(name: &str) -> usize {
    READERS
        .iter()
        .position(|r| r.name == name)
        .unwrap_or_else(|| panic!("unknown reader {name:?}"))
}

/// Runs one input; `Err(message)` for a panic.
fn run_case(r: &Reader, bytes: &[u8], tmp: &Path) -> Result<bool, String> {
    match std::panic::catch_unwind(|| (r.run)(bytes, tmp)) {
        Ok(res) => Ok(res.is_ok()),
        Err(p) => Err(p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "panic".into())),
    }
}

/// Child: cases `start..end` of one reader, one line on stdout per case.
fn child(name: &str, seed: u64, start: u64, end: u64) {
    let idx = reader(name);
    let r = &READERS[idx];
    let corpus = load_corpus(r);
    let tmp = std::env::temp_dir().join(format!("ptm-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    std::panic::set_hook(Box::new(|_| {}));
    // Watchdog: the case that has run past the time bound ends the child.
    static STARTED_MS: AtomicU64 = AtomicU64::new(0);
    static CASE: AtomicU64 = AtomicU64::new(0);
    let t0 = Instant::now();
    std::thread::spawn(move || loop {
        std::thread::sleep(Duration::from_millis(50));
        let s = STARTED_MS.load(Ordering::SeqCst);
        if s > 0 && t0.elapsed().as_millis() as u64 > s + TIME_LIMIT.as_millis() as u64 {
            println!("hang {}", CASE.load(Ordering::SeqCst));
            std::process::exit(124);
        }
    });
    let mut out = std::io::stdout().lock();
    for case in start..end {
        let bytes = mutant(seed, idx, case, &corpus, r.text);
        writeln!(out, "start {case}").unwrap();
        out.flush().unwrap();
        CASE.store(case, Ordering::SeqCst);
        STARTED_MS.store(t0.elapsed().as_millis() as u64 + 1, Ordering::SeqCst);
        let res = run_case(r, &bytes, &tmp);
        STARTED_MS.store(0, Ordering::SeqCst);
        match res {
            Ok(true) => writeln!(out, "ok {case}"),
            Ok(false) => writeln!(out, "refused {case}"),
            Err(msg) => writeln!(out, "panic {case} {}", msg.replace('\n', " ")),
        }
        .unwrap();
    }
    writeln!(out, "done").unwrap();
    out.flush().unwrap();
    std::fs::remove_dir_all(&tmp).ok();
}

#[derive(Default)]
struct Tally {
    ok: u64,
    refused: u64,
    findings: Vec<String>,
}

/// Parent: runs `cases` cases of a reader in children, restarting after each abort or hang.
fn fuzz(name: &str, seed: u64, cases: u64, findings_dir: &Path) -> Tally {
    let idx = reader(name);
    let r = &READERS[idx];
    let corpus = load_corpus(r);
    let cases = cases.max(corpus.len() as u64);
    let exe = std::env::current_exe().unwrap();
    let mut tally = Tally::default();
    let mut start = 0;
    while start < cases {
        let mut ch = Command::new(&exe)
            .args(["child", name, &seed.to_string(), &start.to_string()])
            .arg(cases.to_string())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = ch.stdout.take().unwrap();
        let (mut last, mut done, mut hang) = (None, false, false);
        for line in BufReader::new(stdout).lines() {
            let line = line.unwrap();
            let mut it = line.splitn(3, ' ');
            let (kind, case) = (
                it.next().unwrap_or(""),
                it.next().and_then(|c| c.parse().ok()),
            );
            match (kind, case) {
                ("start", Some(c)) => last = Some(c),
                ("ok", Some(_)) => tally.ok += 1,
                ("refused", Some(_)) => tally.refused += 1,
                ("panic", Some(c)) => {
                    let msg = it.next().unwrap_or("");
                    tally.findings.push(save(
                        r,
                        idx,
                        seed,
                        c,
                        &corpus,
                        findings_dir,
                        &format!("panic: {msg}"),
                    ));
                }
                ("hang", Some(_)) => hang = true,
                ("done", _) => done = true,
                _ => {}
            }
        }
        let mut stderr = String::new();
        use std::io::Read;
        ch.stderr.take().unwrap().read_to_string(&mut stderr).ok();
        let status = ch.wait().unwrap();
        if done {
            break;
        }
        let Some(c) = last else {
            panic!("fuzz child for {name} died before its first case: {status}: {stderr}");
        };
        let why = if hang {
            format!("hang: over {TIME_LIMIT:?}")
        } else if stderr.contains("memory allocation") {
            format!("memory: over {} MB ({})", MEMORY_LIMIT >> 20, stderr.trim())
        } else {
            format!("abort: {status}: {}", stderr.trim())
        };
        tally
            .findings
            .push(save(r, idx, seed, c, &corpus, findings_dir, &why));
        start = c + 1;
    }
    tally
}

fn save(
    r: &Reader,
    idx: usize,
    seed: u64,
    case: u64,
    corpus: &[Vec<u8>],
    dir: &Path,
    why: &str,
) -> String {
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join(format!("{}-{seed}-{case}.{}", r.name, r.ext));
    std::fs::write(&path, mutant(seed, idx, case, corpus, r.text)).unwrap();
    format!(
        "{}: case {case}: {why} (saved as {})",
        r.name,
        path.display()
    )
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("child") => {
            let n = |i: usize| args[i].parse::<u64>().unwrap();
            child(&args[1], n(2), n(3), n(4));
            return ExitCode::SUCCESS;
        }
        Some("gen-corpus") => {
            gen_corpus();
            return ExitCode::SUCCESS;
        }
        Some("mutant") => {
            // `mutant READER SEED CASE OUT`: writes one mutant (to keep a finding).
            let idx = reader(&args[1]);
            let corpus = load_corpus(&READERS[idx]);
            let n = |i: usize| args[i].parse::<u64>().unwrap();
            let bytes = mutant(n(2), idx, n(3), &corpus, READERS[idx].text);
            std::fs::write(&args[4], bytes).unwrap();
            return ExitCode::SUCCESS;
        }
        Some("replay") => {
            let r = &READERS[reader(&args[1])];
            let bytes = std::fs::read(&args[2]).unwrap();
            let tmp = std::env::temp_dir().join(format!("ptm-fuzz-{}", std::process::id()));
            std::fs::create_dir_all(&tmp).unwrap();
            let res = (r.run)(&bytes, &tmp);
            std::fs::remove_dir_all(&tmp).ok();
            println!("{res:?}");
            return ExitCode::SUCCESS;
        }
        _ => {}
    }
    let (mut cases, mut seed, mut names) = (1000u64, 1u64, Vec::new());
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--cases" => cases = it.next().and_then(|v| v.parse().ok()).expect("--cases N"),
            "--seed" => seed = it.next().and_then(|v| v.parse().ok()).expect("--seed S"),
            name => names.push(name.to_string()),
        }
    }
    if names.is_empty() {
        names = READERS.iter().map(|r| r.name.to_string()).collect();
    }
    let findings_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("findings");
    let mut total = 0;
    for name in &names {
        let t0 = Instant::now();
        let t = fuzz(name, seed, cases, &findings_dir);
        let n = t.ok + t.refused + t.findings.len() as u64;
        eprintln!(
            "ptm-fuzz: {name}: {n} cases (seed {seed}) in {:.1} s: {} accepted, {} refused, {} findings",
            t0.elapsed().as_secs_f64(),
            t.ok,
            t.refused,
            t.findings.len()
        );
        for f in &t.findings {
            eprintln!("ptm-fuzz:   {f}");
        }
        total += t.findings.len();
    }
    if total > 0 {
        eprintln!("ptm-fuzz: {total} findings: each must become a regression input in fuzz/corpus or a unit test");
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// Writes the binary corpus files (sample stacks, PTMs, casters) from the crates' own writers.
fn gen_corpus() {
    use ptm_fit::SampleStack;
    use ptm_format::{Basis, LightSet, Ptm, SaveOptions};
    let dir = corpus_dir();
    let lights = LightSet::from_dirs([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.6, 0.8]]);
    let (w, h) = (4, 3);
    let k: Vec<Vec<f32>> = (0..3)
        .map(|l| (0..w * h).map(|t| (t + l) as f32 / 20.0).collect())
        .collect();
    let mut stack = SampleStack {
        width: w,
        height: h,
        tile: [1.0, 0.75],
        lights,
        k,
        coverage: (0..w * h).map(|t| (t % 3) as f32 / 2.0).collect(),
        uv: None,
    };
    std::fs::create_dir_all(dir.join("stack")).unwrap();
    stack.write(&dir.join("stack/distant.exr")).unwrap();
    stack.uv = Some(vec![vec![[0.1, -0.2]; w * h]; 3]);
    stack.write(&dir.join("stack/point.exr")).unwrap();
    std::fs::create_dir_all(dir.join("ptm")).unwrap();
    let planes = (0..6)
        .map(|c| (0..w * h).map(|t| (c * t) as f32 / 50.0).collect())
        .collect();
    let p = Ptm {
        basis: Basis::Ptm6,
        width: w,
        height: h,
        link: ptm_format::Link::Identity,
        uv: ptm_format::UvMap::Projected,
        mips: Vec::new(),
        tile: [1.0, 0.75],
        planes,
        // A hole in every seventh texel, so the corpus carries a coverage channel.
        coverage: Some(
            (0..w * h)
                .map(|t| if t % 7 == 0 { 0.0 } else { 1.0 })
                .collect(),
        ),
        learned: None,
    };
    p.save(&dir.join("ptm/ptm6.exr"), &SaveOptions::default())
        .unwrap();
    let half = SaveOptions {
        half: true,
        ..SaveOptions::default()
    };
    p.save(&dir.join("ptm/ptm6-half.exr"), &half).unwrap();
    // The renderer layout of the same PTM: part c0 seeds the corpus, part c1 is its partner.
    std::fs::create_dir_all(dir.join("layout")).unwrap();
    let pair = dir.join("../pair");
    std::fs::create_dir_all(&pair).unwrap();
    let files = ptm_format::layout::save(
        &p,
        &pair.join("ptm6.ptm.exr"),
        &SaveOptions::default(),
        ptm_format::Layout::Rgba,
    )
    .unwrap();
    std::fs::rename(&files[0], dir.join("layout/ptm6.ptm.c0.exr")).unwrap();
    std::fs::create_dir_all(dir.join("caster")).unwrap();
    image::RgbaImage::from_fn(6, 5, |x, y| {
        image::Rgba([x as u8 * 40, y as u8 * 50, 90, 200])
    })
    .save(dir.join("caster/rgba8.png"))
    .unwrap();
    image::ImageBuffer::from_fn(3, 2, |x, y| image::Luma([(x * 20000 + y * 300) as u16]))
        .save(dir.join("caster/grey16.png"))
        .unwrap();
}
