//! What every subcommand checks about its outputs before any work — none may be one of its
//! inputs (the same file after resolving links), a light file is written beside an output only
//! where that makes a file of its own — and how paths appear in messages (`--json` gives them
//! as `crate::json::path` does).
use std::path::{Path, PathBuf};

use anyhow::bail;
use ptm_format::atomic::same_file;

/// Refuses an output that is one of the inputs: `inputs` are (what it is, its path), e.g.
/// `("swatch", "pw.obj")`.
pub fn refuse_inputs(outputs: &[&Path], inputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    for out in outputs {
        if let Some((what, input)) = inputs.iter().find(|(_, i)| same_file(out, i)) {
            bail!(
                "the output {} is the {what} {}: give the output another name (the input would \
                 be overwritten)",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Whether `path` exists and is neither a regular file nor a directory (`/dev/null`, a FIFO):
/// written through, so nothing may be created beside it.
pub fn is_special(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// The light file written beside `out` (`samples.exr` → `samples.lp`, `weave.ptm.exr` →
/// `weave.lp`), or none when `out` is a device or FIFO (`-o /dev/null` creates no
/// `/dev/null.lp`).
pub fn lp_beside(out: &Path) -> Option<PathBuf> {
    (!is_special(out)).then(|| lp_path(out))
}

/// `samples.exr` → `samples.lp`, `weave.ptm.exr` → `weave.lp`.
/// Works on the name as an `OsStr`: a name that is not UTF-8 keeps its bytes.
pub fn lp_path(out: &Path) -> PathBuf {
    let name = Path::new(out.file_name().unwrap_or_default());
    let strip = |p: &Path, ext: &str| match p.extension() {
        Some(e) if e == ext => PathBuf::from(p.file_stem().unwrap_or_default()),
        _ => p.to_path_buf(),
    };
    let stem = strip(&strip(name, "exr"), "ptm");
    let mut lp = stem.into_os_string();
    lp.push(".lp");
    out.with_file_name(lp)
}

/// An error context naming the file an error is about, which `--json` reports as the error's
/// `input`: shown as "`action` `path`" (e.g. "reading cap.lp").
#[derive(Debug)]
pub struct Named {
    pub action: &'static str,
    pub path: String,
}

impl Named {
    pub fn new(action: &'static str, path: &Path) -> Named {
        Named {
            action,
            path: path.display().to_string(),
        }
    }
}

impl std::fmt::Display for Named {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.action, self.path)
    }
}

/// Paths for a message: `a`, `a and b`, `a, b and c`.
pub fn list<P: AsRef<Path>>(paths: &[P]) -> String {
    let names: Vec<String> = paths
        .iter()
        .map(|p| p.as_ref().display().to_string())
        .collect();
    match names.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    }
}
