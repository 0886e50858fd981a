//! Atomic file output: write to a temporary file beside the target, fsync, then rename, so a
//! crash never leaves a half-written file where a good one was.
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use crate::{Error, Result};

/// Writes `path` through `write` into `path.<pid>.tmp`, then renames it over `path`.
/// On any error the temporary file is removed and `path` is untouched.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let io_err = |e: std::io::Error| Error::Io {
        path: path.display().to_string(),
        source: e,
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| io_err(std::io::Error::other("output path has no file name")))?;
    let mut tmp_name = file_name.to_os_string();
    tmp_name.push(format!(".{}.tmp", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let result = (|| {
        let mut w = BufWriter::new(File::create(&tmp)?);
        write(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io_err)
}

/// Temporary path beside `path` for writers that need a path rather than a stream (the `exr`
/// crate); pair with [`commit_tmp`].
pub fn tmp_path(path: &Path) -> std::path::PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".{}.tmp", std::process::id()));
    path.with_file_name(name)
}

/// Renames a finished temporary file over `path` (or removes it when `ok` is an error).
pub fn commit_tmp<T>(tmp: &Path, path: &Path, ok: Result<T>) -> Result<T> {
    match ok {
        Ok(v) => {
            std::fs::rename(tmp, path).map_err(|e| Error::Io {
                path: path.display().to_string(),
                source: e,
            })?;
            Ok(v)
        }
        Err(e) => {
            let _ = std::fs::remove_file(tmp);
            Err(e)
        }
    }
}
