//! Helpers shared by the end-to-end tests of the `ptm` command: the one way they run the
//! binary ([`ptm`], and [`ok`], [`refused`], [`json`] over it) and the fixtures several test
//! files build (the fit crate's Fibonacci dome and stacks, a box on a floor as OBJ).
#![allow(dead_code)] // each test file uses a part

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

// The fit crate's Fibonacci dome, shared by path.
#[path = "../../fit/tests/common/mod.rs"]
mod fit_common;
pub use fit_common::fibonacci;

/// What a run of `ptm` did.
#[derive(Debug)]
pub struct Run {
    /// It exited with status 0.
    pub ok: bool,
    /// Its exit code (none when a signal ended it).
    pub code: Option<i32>,
    /// Its stdout, as text (lossily; `--json` paths are lossy text anyway).
    pub stdout: String,
    /// Its stderr, as text.
    pub stderr: String,
}

/// The `ptm` binary under test, for a run that needs more than [`ptm`] gives (a child to kill).
pub fn command() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ptm"))
}

/// Runs `ptm args…` in the folder `dir` and waits for it.
pub fn ptm<I, S>(args: I, dir: &Path) -> Run
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let out = command()
        .args(args)
        .current_dir(dir)
        .output()
        .expect("running ptm");
    Run {
        ok: out.status.success(),
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Runs `ptm args…` in `dir`, asserts that it succeeded, and returns its stdout.
pub fn ok<I, S>(args: I, dir: &Path) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let args: Vec<S> = args.into_iter().collect();
    let run = ptm(&args, dir);
    assert!(run.ok, "ptm {:?} failed: {}", shown(&args), run.stderr);
    run.stdout
}

/// Runs `ptm args…` in `dir`, asserts that it failed, and returns its stderr.
pub fn refused<I, S>(args: I, dir: &Path) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let args: Vec<S> = args.into_iter().collect();
    let run = ptm(&args, dir);
    assert!(!run.ok, "ptm {:?} should fail", shown(&args));
    run.stderr
}

/// Runs `ptm --json args…` in `dir`, asserts that it succeeded, and returns the one JSON object
/// it printed.
pub fn json<I, S>(args: I, dir: &Path) -> serde_json::Value
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let args: Vec<S> = args.into_iter().collect();
    let run = ptm(
        std::iter::once(OsStr::new("--json")).chain(args.iter().map(|a| a.as_ref())),
        dir,
    );
    assert!(run.ok, "ptm {:?} failed:\n{}", shown(&args), run.stderr);
    serde_json::from_str(&run.stdout)
        .unwrap_or_else(|e| panic!("ptm {:?}: stdout is not one JSON object: {e}", shown(&args)))
}

fn shown<S: AsRef<OsStr>>(args: &[S]) -> Vec<String> {
    args.iter()
        .map(|a| a.as_ref().to_string_lossy().into_owned())
        .collect()
}

/// A path as the `&str` argument tests pass (their paths are UTF-8).
pub fn p(path: &Path) -> &str {
    path.to_str().expect("a UTF-8 test path")
}

/// A floor with a box on it, as an OBJ with quads (triangulated on load), 1×1 tile.
pub const BOX_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
v 0.3 0.3 0.2\nv 0.7 0.3 0.2\nv 0.7 0.7 0.2\nv 0.3 0.7 0.2\n\
v 0.3 0.3 0\nv 0.7 0.3 0\nv 0.7 0.7 0\nv 0.3 0.7 0\n\
f 1 2 3 4\nf 5 6 7 8\nf 9 10 6 5\nf 10 11 7 6\nf 11 12 8 7\nf 12 9 5 8\n";

/// Fibonacci hemisphere above 5° elevation.
pub fn dome(n: usize) -> ptm_format::LightSet {
    fibonacci(n, 5.0)
}
