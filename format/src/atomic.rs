//! Atomic file output, the one helper every writer of the workspace uses: the bytes go to a new
//! temporary file in the destination's directory, which is fsynced, renamed over the
//! destination, and the directory fsynced, so a crash or a failed write never leaves a
//! half-written file where a good one was.
//!
//! Rules (tested in `tests/atomic.rs`):
//! - The temporary file has a short name of its own (`.ptm-<pid>-<counter>-<host><random>.tmp`),
//!   never the destination's name with a suffix, so a legal 255-byte destination name still
//!   works and two writers (threads or processes) never share a temporary file.
//! - Temporary files a killed writer left behind (`kill -9`, a power cut) are swept: the first
//!   time a process writes into a directory, it removes the temporaries there whose writer is
//!   gone — same host (by the name's host tag) and no such process — and any older than a day
//!   (a writer on another host of a shared filesystem, or a system where liveness is unknown).
//! - A failed write never publishes: the temporary file is removed on every error path (a
//!   failed writer, a failed fsync, a failed rename) and when a panic unwinds through it.
//! - A destination that exists and is not a regular file (a character device such as
//!   `/dev/null`, a FIFO) is written through directly: never renamed over, no sibling created.
//! - A destination that is a directory, or names one (`.`, `x/`), is an error before any work.
//! - [`Transaction`] stages several outputs and publishes them only when all were written, after
//!   checking every destination before the work starts.
use std::collections::HashSet;
use std::fs::{File, OpenOptions};
use std::hash::{BuildHasher, Hasher};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};

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
/// another process's (16 hashed bits of a per-process random seed, the time and the counter);
/// files are created with `create_new`, so a collision is retried, never shared. The name also
/// carries a 16-bit tag of the host name, so a sweep on one host of a shared filesystem never
/// takes another host's live process for a dead one.
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
        "{TEMP_PREFIX}{}-{n}-{:04x}{:04x}{TEMP_SUFFIX}",
        std::process::id(),
        host_tag(),
        h.finish() & 0xffff
    )
}

const TEMP_PREFIX: &str = ".ptm-";
const TEMP_SUFFIX: &str = ".tmp";

/// A temporary file older than this is stale whoever wrote it: a live writer keeps writing its
/// temporary or publishes it within seconds of the last byte.
const STALE_AGE: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// 16 bits of a hash of this machine's host name (0 when it has none to read).
fn host_tag() -> u16 {
    static TAG: OnceLock<u16> = OnceLock::new();
    *TAG.get_or_init(|| {
        let name = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .or_else(|_| std::fs::read_to_string("/etc/hostname"))
            .or_else(|_| std::env::var("HOSTNAME"))
            .unwrap_or_default();
        let h = name
            .trim()
            .bytes()
            .fold(0u64, |h, b| crate::hash::splitmix64(h ^ u64::from(b)));
        (h >> 48) as u16
    })
}

/// What a temporary file's name says of its writer.
#[derive(Debug, PartialEq, Eq)]
struct TempOwner {
    pid: u32,
    /// The host tag, `None` in names written before it existed (6 random hex digits).
    host: Option<u16>,
}

/// Parses `.ptm-<pid>-<counter>-<hex>.tmp`; `None` for any other name.
fn temp_owner(name: &str) -> Option<TempOwner> {
    let mid = name.strip_prefix(TEMP_PREFIX)?.strip_suffix(TEMP_SUFFIX)?;
    let mut parts = mid.split('-');
    let (pid, counter, hex) = (parts.next()?, parts.next()?, parts.next()?);
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let is_hex = hex
        .bytes()
        .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase());
    if parts.next().is_some() || !digits(pid) || !digits(counter) || !is_hex {
        return None;
    }
    let host = match hex.len() {
        8 => Some(u16::from_str_radix(&hex[..4], 16).ok()?),
        6 => None,
        _ => return None,
    };
    Some(TempOwner {
        pid: pid.parse().ok()?,
        host,
    })
}

/// Whether process `pid` of this host is alive; `None` when this system cannot tell.
fn process_alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(proc.join(pid.to_string()).exists())
}

/// Removes the stale temporary files in `dir` (see the module rules) and returns their paths.
/// Best effort: an unreadable directory or a file that cannot be removed is left as it is.
/// [`write_with`] and the other writers call it once per directory and process; a tool that
/// cleans up a directory without writing to it can call it directly.
pub fn sweep_stale_temps(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let (me, host) = (std::process::id(), host_tag());
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(owner) = name.to_str().and_then(temp_owner) else {
            continue;
        };
        // symlink_metadata: a link with a temporary's name is not ours to follow.
        let Ok(meta) = std::fs::symlink_metadata(entry.path()) else {
            continue;
        };
        if !meta.is_file() || owner.pid == me {
            continue;
        }
        let dead_here = owner.host == Some(host) && process_alive(owner.pid) == Some(false);
        let old = meta
            .modified()
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age > STALE_AGE);
        if (dead_here || old) && std::fs::remove_file(entry.path()).is_ok() {
            removed.push(entry.path());
        }
    }
    removed
}

/// Sweeps `dir` the first time this process writes into it.
fn sweep_once(dir: &Path) {
    static SWEPT: OnceLock<Mutex<HashSet<PathBuf>>> = OnceLock::new();
    let swept = SWEPT.get_or_init(Default::default);
    let first = swept
        .lock()
        .map(|mut s| s.insert(dir.to_path_buf()))
        .unwrap_or(false);
    if first {
        sweep_stale_temps(dir);
    }
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
    sweep_once(dir);
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
    let dir = dir_of(path);
    sweep_once(&dir);
    dir.join(temp_name())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_parse_back_to_their_writer() {
        let name = temp_name();
        let owner = temp_owner(&name).unwrap_or_else(|| panic!("{name} does not parse"));
        assert_eq!(owner.pid, std::process::id());
        assert_eq!(owner.host, Some(host_tag()));
        // Names of the earlier 6-digit form carry no host.
        assert_eq!(
            temp_owner(".ptm-12-0-0a1b2c.tmp"),
            Some(TempOwner {
                pid: 12,
                host: None
            })
        );
        for other in [
            ".ptm-12-0-0a1b2c3.tmp",
            ".ptm-12-0-0A1B2C3D.tmp",
            ".ptm--0-0a1b2c3d.tmp",
            ".ptm-12-x-0a1b2c3d.tmp",
            ".ptm-12-0-0a1b2c3d-1.tmp",
            ".ptm-99999999999-0-0a1b2c3d.tmp",
            "ptm-12-0-0a1b2c3d.tmp",
            ".ptm-12-0-0a1b2c3d.tmp~",
            "weave.ptm.exr",
        ] {
            assert_eq!(temp_owner(other), None, "{other}");
        }
    }
}
