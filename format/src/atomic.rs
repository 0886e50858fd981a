//! Atomic file output, the one helper every writer of the workspace uses: the bytes go to a new
//! temporary file in the destination's directory, which is fsynced, renamed over the
//! destination, and the directory fsynced, so a crash or a failed write never leaves a
//! half-written file where a good one was.
//!
//! Rules (tested in `tests/atomic.rs`):
//! - The temporary file has a short name of its own (`.ptm-<pid>-<counter>-<hash>.tmp`), never
//!   the destination's name with a suffix, so a legal 255-byte destination name still works
//!   and two writers (threads or processes) never share a temporary file.
//! - A failed write never publishes: the temporary file is removed on every error path (a
//!   failed writer, a failed fsync, a failed rename) and when a panic unwinds through it.
//! - A destination that exists and is not a regular file (a character device such as
//!   `/dev/null`, a FIFO) is written through directly: never renamed over, no sibling created.
//! - A destination that is a directory, or names one (`.`, `x/`), is an error before any work.
//! - [`Transaction`] stages several outputs and publishes them only when all were written, after
//!   checking every destination before the work starts.
use std::fs::{File, OpenOptions};
use std::hash::{BuildHasher, Hasher};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{Error, Result};

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        source,
    }
}

fn refuse(path: &Path, kind: std::io::ErrorKind, reason: &str) -> Error {
    io_error(path, std::io::Error::new(kind, reason.to_string()))
}

/// How a destination receives its bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Absent or a regular file: temporary file, then rename.
    Replace,
    /// Exists and is neither a regular file nor a directory (a device, a FIFO, a socket):
    /// written through directly.
    Through,
}

/// Checks a destination before any work: it must name a file (not `.`, `x/`, an existing
/// directory) in a directory that exists.
fn classify(path: &Path) -> Result<Kind> {
    let names_dir = path.as_os_str().is_empty()
        || path.file_name().is_none()
        || path.to_string_lossy().ends_with('/')
        || path.to_string_lossy().ends_with(std::path::MAIN_SEPARATOR);
    if names_dir {
        return Err(refuse(
            path,
            std::io::ErrorKind::IsADirectory,
            "names a directory, not a file: give an output file name",
        ));
    }
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(refuse(
            path,
            std::io::ErrorKind::IsADirectory,
            "is a directory, not a file: give an output file name",
        )),
        Ok(m) if !m.is_file() => Ok(Kind::Through),
        Ok(_) => Ok(Kind::Replace),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let dir = dir_of(path);
            match std::fs::metadata(&dir) {
                Ok(m) if m.is_dir() => Ok(Kind::Replace),
                Ok(_) => Err(refuse(
                    path,
                    std::io::ErrorKind::NotADirectory,
                    &format!("{} is not a directory", dir.display()),
                )),
                Err(e) => Err(io_error(
                    path,
                    std::io::Error::new(
                        e.kind(),
                        format!("directory {}: {e} (create it first)", dir.display()),
                    ),
                )),
            }
        }
        Err(e) => Err(io_error(path, e)),
    }
}

/// The directory a destination's temporary file goes in.
fn dir_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A short temporary name unique in this process (pid + counter) and unlikely to collide with
/// another process's (a few hashed characters of a per-process random seed, the time and the
/// counter); files are created with `create_new`, so a collision is retried, never shared.
fn temp_name() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(n);
    h.write_u32(std::process::id());
    if let Ok(t) = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
        h.write_u128(t.as_nanos());
    }
    format!(
        ".ptm-{}-{n}-{:06x}.tmp",
        std::process::id(),
        h.finish() & 0xff_ffff
    )
}

/// A temporary file that is removed when dropped unless it was published.
struct Temp {
    path: PathBuf,
    armed: bool,
}

impl Drop for Temp {
    fn drop(&mut self) {
        if self.armed {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Creates a new temporary file in `dir`.
fn create_temp(dir: &Path, dest: &Path) -> Result<(Temp, File)> {
    let mut last = None;
    for _ in 0..16 {
        let path = dir.join(temp_name());
        match OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(f) => return Ok((Temp { path, armed: true }, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => {
                return Err(io_error(
                    dest,
                    std::io::Error::new(
                        e.kind(),
                        format!("creating a temporary file in {}: {e}", dir.display()),
                    ),
                ))
            }
        }
    }
    Err(io_error(dest, last.expect("16 collisions")))
}

/// Fsyncs a directory so a rename in it is durable. Filesystems that cannot sync a directory
/// (`EINVAL`) are not an error.
fn sync_dir(dir: &Path, dest: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        let d = File::open(dir).map_err(|e| io_error(dest, e))?;
        match d.sync_all() {
            Err(e) if e.kind() != std::io::ErrorKind::InvalidInput => {
                return Err(io_error(dest, e))
            }
            _ => {}
        }
    }
    #[cfg(not(unix))]
    let _ = (dir, dest);
    Ok(())
}

/// Runs `write` on a buffered stream into a fresh temporary file (in `dir`), flushes and fsyncs
/// it. On any error the temporary file is gone when this returns.
fn stage_in<T, E: From<Error>>(
    dir: &Path,
    dest: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::result::Result<T, E>,
) -> std::result::Result<(Temp, T), E> {
    let (temp, file) = create_temp(dir, dest)?;
    let mut w = BufWriter::new(file);
    let value = write(&mut w)?;
    let file = w.into_inner().map_err(|e| io_error(dest, e.into_error()))?;
    file.sync_all().map_err(|e| io_error(dest, e))?;
    Ok((temp, value))
}

/// Renames a finished temporary file over `dest` and fsyncs the directory. A failed rename
/// removes the temporary file (the `Temp` guard).
fn publish(mut temp: Temp, dest: &Path) -> Result<()> {
    std::fs::rename(&temp.path, dest).map_err(|e| io_error(dest, e))?;
    temp.armed = false;
    sync_dir(&dir_of(dest), dest)
}

/// Opens a non-regular destination (device, FIFO) for writing through.
fn open_through(dest: &Path) -> Result<BufWriter<File>> {
    let f = OpenOptions::new()
        .write(true)
        .open(dest)
        .map_err(|e| io_error(dest, e))?;
    Ok(BufWriter::new(f))
}

/// Writes `path` atomically through `write`, which gets a buffered stream (seekable: encoders
/// that need `Seek` work). Returns what `write` returns; on any error nothing is published and
/// no temporary file is left. A non-regular destination (`/dev/null`, a FIFO) is written
/// through directly.
pub fn write_with<T, E: From<Error>>(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    match classify(path)? {
        Kind::Through => {
            let mut w = open_through(path)?;
            let value = write(&mut w)?;
            w.flush().map_err(|e| io_error(path, e))?;
            Ok(value)
        }
        Kind::Replace => {
            let (temp, value) = stage_in(&dir_of(path), path, write)?;
            publish(temp, path)?;
            Ok(value)
        }
    }
}

/// [`write_with`] for writers that fail with an `std::io::Error` (the error names `path`).
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    write_with(path, |w| write(w).map_err(|e| io_error(path, e)))
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Atomic output for encoders that can only write to a path: `write` gets the path of a fresh
/// temporary file beside `path` (or `path` itself when that is a device or FIFO), which is then
/// fsynced and renamed over `path`. On any error the temporary file is removed.
pub fn write_path<T, E: From<Error>>(
    path: &Path,
    write: impl FnOnce(&Path) -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    match classify(path)? {
        Kind::Through => write(path),
        Kind::Replace => {
            let (temp, file) = create_temp(&dir_of(path), path)?;
            drop(file);
            let value = write(&temp.path)?;
            File::open(&temp.path)
                .and_then(|f| f.sync_all())
                .map_err(|e| io_error(path, e))?;
            publish(temp, path)?;
            Ok(value)
        }
    }
}

/// A fresh, unique temporary path in `path`'s directory for writers that manage the file
/// themselves; pair with [`commit_tmp`] (or use [`write_path`], which does both).
pub fn tmp_path(path: &Path) -> PathBuf {
    dir_of(path).join(temp_name())
}

/// Publishes a temporary file written by the caller: when `ok` is `Ok`, fsyncs `tmp` and renames
/// it over `path`; otherwise, or when that fails, removes `tmp`.
pub fn commit_tmp<T>(tmp: &Path, path: &Path, ok: Result<T>) -> Result<T> {
    let temp = Temp {
        path: tmp.to_path_buf(),
        armed: true,
    };
    let value = ok?;
    File::open(tmp)
        .and_then(|f| f.sync_all())
        .map_err(|e| io_error(path, e))?;
    publish(temp, path)?;
    Ok(value)
}

/// Whether `a` and `b` are the same file after resolving links (device and inode on unix, the
/// canonical path elsewhere). A path that does not exist is the same file as nothing.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// One output of a [`Transaction`].
struct Output {
    path: PathBuf,
    kind: Kind,
    staged: Option<Temp>,
}

/// Several outputs published together: every destination is checked when the transaction is
/// made (before the work), each output is staged in a temporary file as it is produced, and
/// [`Transaction::commit`] publishes them all only when all were staged. Dropping a transaction
/// without committing removes every staged file and publishes nothing.
///
/// Outputs that are devices or FIFOs are staged in the system temporary directory and copied
/// into the destination at commit. Renames are atomic one by one; a failure in the middle of
/// [`Transaction::commit`] (rare: everything was written and synced before) can leave the
/// outputs renamed before it published.
pub struct Transaction {
    outputs: Vec<Output>,
}

impl Transaction {
    /// Checks every destination: each names a file in an existing directory, and no two are the
    /// same file.
    pub fn new<P: AsRef<Path>>(paths: &[P]) -> Result<Transaction> {
        let mut outputs: Vec<Output> = Vec::with_capacity(paths.len());
        for p in paths {
            let path = p.as_ref();
            let kind = classify(path)?;
            if let Some(o) = outputs
                .iter()
                .find(|o| o.path == path || same_file(&o.path, path))
            {
                return Err(Error::Invalid(format!(
                    "{} and {} are the same file: give each output its own name",
                    o.path.display(),
                    path.display()
                )));
            }
            outputs.push(Output {
                path: path.to_path_buf(),
                kind,
                staged: None,
            });
        }
        Ok(Transaction { outputs })
    }

    /// Adds an output known only after the work (an optional file), checked as
    /// [`Transaction::new`] checks its paths; a path already in the transaction is left as is.
    pub fn add(&mut self, path: &Path) -> Result<()> {
        if self.outputs.iter().any(|o| o.path == path) {
            return Ok(());
        }
        let kind = classify(path)?;
        if let Some(o) = self.outputs.iter().find(|o| same_file(&o.path, path)) {
            return Err(Error::Invalid(format!(
                "{} and {} are the same file: give each output its own name",
                o.path.display(),
                path.display()
            )));
        }
        self.outputs.push(Output {
            path: path.to_path_buf(),
            kind,
            staged: None,
        });
        Ok(())
    }

    fn output(&mut self, path: &Path) -> Result<&mut Output> {
        self.outputs
            .iter_mut()
            .find(|o| o.path == path)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "{}: not an output of this transaction",
                    path.display()
                ))
            })
    }

    /// Writes output `path` (one given to [`Transaction::new`]) into its temporary file.
    pub fn stage<T, E: From<Error>>(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut BufWriter<File>) -> std::result::Result<T, E>,
    ) -> std::result::Result<T, E> {
        let out = self.output(path)?;
        out.staged = None;
        let dir = match out.kind {
            Kind::Replace => dir_of(path),
            Kind::Through => std::env::temp_dir(),
        };
        let (temp, value) = stage_in(&dir, path, write)?;
        out.staged = Some(temp);
        Ok(value)
    }

    /// [`Transaction::stage`] of bytes.
    pub fn stage_bytes(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        self.stage(path, |w| w.write_all(bytes).map_err(|e| io_error(path, e)))
    }

    /// Publishes every output, or none when one was not staged.
    pub fn commit(mut self) -> Result<()> {
        if let Some(o) = self.outputs.iter().find(|o| o.staged.is_none()) {
            return Err(Error::Invalid(format!(
                "{}: output was not written, so none was published",
                o.path.display()
            )));
        }
        for o in &mut self.outputs {
            let temp = o.staged.take().expect("staged");
            match o.kind {
                Kind::Replace => publish(temp, &o.path)?,
                Kind::Through => {
                    let mut from = File::open(&temp.path).map_err(|e| io_error(&o.path, e))?;
                    let mut to = open_through(&o.path)?;
                    std::io::copy(&mut from, &mut to)
                        .and_then(|_| to.flush())
                        .map_err(|e| io_error(&o.path, e))?;
                }
            }
        }
        Ok(())
    }
}
