//! The atomic-write rules of `ptm_format::atomic`: nothing is published by a failed write, no
//! temporary file outlives an error, devices and FIFOs are written through, long names work,
//! a transaction publishes all of its outputs or none, and killed writers' temporaries are swept.
use std::io::Write;
use std::os::unix::fs::FileTypeExt;
use std::path::Path;

use ptm_format::atomic::{
    same_file, tmp_path, write_atomic, write_bytes, write_path, write_with, Transaction,
};
use ptm_format::Error;

/// Names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn failing(_: &mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()> {
    Err(std::io::Error::other("disk on fire"))
}

#[test]
fn writes_and_replaces_a_regular_file() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("out.txt");
    write_bytes(&p, b"one").unwrap();
    write_bytes(&p, b"two").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"two");
    assert_eq!(names(d.path()), ["out.txt"]);
    // The writer's value comes back.
    let n: usize = write_with::<_, Error>(&p, |w| {
        w.write_all(b"three").unwrap();
        Ok(5)
    })
    .unwrap();
    assert_eq!((n, std::fs::read(&p).unwrap()), (5, b"three".to_vec()));
}

#[test]
fn a_failed_write_leaves_the_old_file_and_no_temporary() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("out.txt");
    write_bytes(&p, b"old").unwrap();
    let e = write_atomic(&p, |w| {
        w.write_all(b"half of the new")?;
        failing(w)
    })
    .unwrap_err();
    assert!(e.to_string().contains("disk on fire"), "{e}");
    assert_eq!(std::fs::read(&p).unwrap(), b"old");
    assert_eq!(names(d.path()), ["out.txt"]);
    // A writer that panics removes its temporary file too.
    let caught = std::panic::catch_unwind(|| {
        write_atomic(&p, |w| {
            w.write_all(b"x")?;
            panic!("writer panicked")
        })
    });
    assert!(caught.is_err());
    assert_eq!(std::fs::read(&p).unwrap(), b"old");
    assert_eq!(names(d.path()), ["out.txt"]);
    // A path-only writer that fails leaves nothing either.
    let r: Result<(), Error> = write_path(&p, |tmp| {
        std::fs::write(tmp, b"new").unwrap();
        Err(Error::Invalid("encoder failed".into()))
    });
    assert!(r.is_err());
    assert_eq!(std::fs::read(&p).unwrap(), b"old");
    assert_eq!(names(d.path()), ["out.txt"]);
    write_path::<_, Error>(&p, |tmp| {
        std::fs::write(tmp, b"new").unwrap();
        Ok(())
    })
    .unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"new");
    assert_eq!(names(d.path()), ["out.txt"]);
}

#[test]
fn a_directory_destination_is_an_error_and_leaves_nothing() {
    let d = tempfile::tempdir().unwrap();
    let sub = d.path().join("x");
    std::fs::create_dir(&sub).unwrap();
    let slash = format!("{}/", sub.display());
    let missing_slash = format!("{}/", d.path().join("y").display());
    let dot = d.path().join(".");
    for p in [
        sub.as_path(),
        Path::new(&slash),
        Path::new(&missing_slash),
        dot.as_path(),
    ] {
        let e = write_bytes(p, b"data").unwrap_err();
        assert!(
            matches!(&e, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::IsADirectory),
            "{}: {e}",
            p.display()
        );
    }
    assert_eq!(names(d.path()), ["x"]);
    assert!(names(&sub).is_empty());
    // "." relative to the working directory, without creating anything there.
    let cwd = names(Path::new("."));
    assert!(write_bytes(Path::new("."), b"data").is_err());
    assert_eq!(names(Path::new(".")), cwd);
    // A missing directory is named before any work.
    let e = write_bytes(&d.path().join("nodir/out.txt"), b"data").unwrap_err();
    assert!(e.to_string().contains("nodir"), "{e}");
}

#[test]
fn a_character_device_is_written_through_never_replaced() {
    let dev = Path::new("/dev/null");
    assert!(std::fs::metadata(dev).unwrap().file_type().is_char_device());
    let before = names(Path::new("/dev"));
    write_bytes(dev, b"into the void").unwrap();
    write_path::<_, Error>(dev, |p| {
        assert_eq!(p, dev, "a path-only writer gets the device itself");
        std::fs::write(p, b"more").map_err(|e| Error::Invalid(e.to_string()))
    })
    .unwrap();
    let mut tx = Transaction::new(&[dev]).unwrap();
    tx.stage_bytes(dev, b"staged").unwrap();
    tx.commit().unwrap();
    assert!(std::fs::metadata(dev).unwrap().file_type().is_char_device());
    let after = names(Path::new("/dev"));
    assert!(
        !after
            .iter()
            .any(|n| n.starts_with(".ptm-") && !before.contains(n)),
        "no sibling of /dev/null was created"
    );
}

#[test]
fn a_fifo_is_written_through() {
    let d = tempfile::tempdir().unwrap();
    let fifo = d.path().join("pipe");
    let ok = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(ok.success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(&fifo).unwrap())
    };
    write_bytes(&fifo, b"through the pipe").unwrap();
    assert_eq!(reader.join().unwrap(), b"through the pipe");
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    assert_eq!(names(d.path()), ["pipe"]);
}

#[test]
fn a_255_byte_name_works_and_temporary_names_are_short_and_unique() {
    let d = tempfile::tempdir().unwrap();
    let name = format!("{}.exr", "n".repeat(251));
    assert_eq!(name.len(), 255);
    let p = d.path().join(&name);
    write_bytes(&p, b"long").unwrap();
    write_bytes(&p, b"longer").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"longer");
    assert_eq!(names(d.path()), [name]);
    let (a, b) = (tmp_path(&p), tmp_path(&p));
    assert_ne!(a, b);
    assert_eq!(a.parent(), Some(d.path()));
    assert!(a.file_name().unwrap().len() < 48, "{}", a.display());
}

#[test]
fn a_transaction_publishes_all_or_none() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a.exr"), d.path().join("b.ptm"));
    write_bytes(&a, b"old a").unwrap();
    write_bytes(&b, b"old b").unwrap();

    // One output fails: neither is replaced, no temporary is left.
    let mut tx = Transaction::new(&[&a, &b]).unwrap();
    tx.stage_bytes(&a, b"new a").unwrap();
    assert!(tx
        .stage(&b, |w| failing(w)
            .map_err(|e| Error::Invalid(e.to_string())))
        .is_err());
    drop(tx);
    assert_eq!(std::fs::read(&a).unwrap(), b"old a");
    assert_eq!(std::fs::read(&b).unwrap(), b"old b");
    assert_eq!(names(d.path()), ["a.exr", "b.ptm"]);

    // An output never staged: commit publishes none.
    let mut tx = Transaction::new(&[&a, &b]).unwrap();
    tx.stage_bytes(&a, b"new a").unwrap();
    assert!(tx.commit().is_err());
    assert_eq!(std::fs::read(&a).unwrap(), b"old a");
    assert_eq!(names(d.path()), ["a.exr", "b.ptm"]);

    // All staged: all published.
    let mut tx = Transaction::new(&[&a, &b]).unwrap();
    tx.stage_bytes(&b, b"new b").unwrap();
    tx.stage_bytes(&a, b"new a").unwrap();
    tx.commit().unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), b"new a");
    assert_eq!(std::fs::read(&b).unwrap(), b"new b");
    assert_eq!(names(d.path()), ["a.exr", "b.ptm"]);

    // Destinations are checked before the work: a missing directory, a directory, the same
    // file twice (also through a link), a path that is not an output.
    let missing = d.path().join("nodir/x.ptm");
    assert!(Transaction::new(&[&a, &missing]).is_err());
    assert!(Transaction::new(&[a.as_path(), d.path()]).is_err());
    assert!(Transaction::new(&[&a, &a]).is_err());
    let link = d.path().join("link.exr");
    std::os::unix::fs::symlink(&a, &link).unwrap();
    assert!(Transaction::new(&[&a, &link]).is_err());
    std::fs::remove_file(&link).unwrap();
    let mut tx = Transaction::new(&[&a]).unwrap();
    assert!(tx.stage_bytes(&b, b"not mine").is_err());
    drop(tx);

    // A rename that fails at commit (the destination became a directory after the check)
    // leaves no temporary file.
    let c = d.path().join("c.exr");
    let mut tx = Transaction::new(&[&c]).unwrap();
    tx.stage_bytes(&c, b"c").unwrap();
    std::fs::create_dir(&c).unwrap();
    std::fs::write(c.join("keep"), b"k").unwrap();
    assert!(tx.commit().is_err());
    assert_eq!(names(d.path()), ["a.exr", "b.ptm", "c.exr"]);
    assert_eq!(names(&c), ["keep"]);
}

#[test]
fn same_file_resolves_links() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a"), d.path().join("b"));
    std::fs::write(&a, b"a").unwrap();
    std::fs::write(&b, b"b").unwrap();
    let (hard, soft) = (d.path().join("hard"), d.path().join("soft"));
    std::fs::hard_link(&a, &hard).unwrap();
    std::os::unix::fs::symlink(&a, &soft).unwrap();
    assert!(same_file(&a, &a));
    assert!(same_file(&a, &hard));
    assert!(same_file(&soft, &a));
    assert!(same_file(&d.path().join("./a"), &a));
    assert!(!same_file(&a, &b));
    assert!(!same_file(&a, &d.path().join("missing")));
    assert!(!same_file(
        &d.path().join("missing"),
        &d.path().join("missing")
    ));
}

/// A pid that no process of this host has: a child that has exited and been reaped.
fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    assert!(!Path::new(&format!("/proc/{pid}")).exists());
    pid
}

#[test]
fn temporaries_of_killed_writers_are_swept_and_live_ones_kept() {
    let d = tempfile::tempdir().unwrap();
    // This host's tag, as the writer puts it in its names: the first 4 of the 8 hex digits.
    let mine = tmp_path(&d.path().join("probe"));
    let name = mine.file_name().unwrap().to_str().unwrap();
    let hex = name.rsplit('-').next().unwrap().trim_end_matches(".tmp");
    let (tag, other_tag) = (&hex[..4], if &hex[..4] == "0000" { "ffff" } else { "0000" });
    let (dead, live) = (dead_pid(), std::os::unix::process::parent_id());
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(25 * 3600);
    let make = |name: &str, mtime: Option<std::time::SystemTime>| {
        let f = std::fs::File::create(d.path().join(name)).unwrap();
        f.set_len(1 << 20).unwrap(); // a killed bake leaves tens of MB
        if let Some(t) = mtime {
            f.set_modified(t).unwrap();
        }
    };
    make(&format!(".ptm-{dead}-3-{tag}beef.tmp"), None); // killed here: swept
    make(&format!(".ptm-{live}-3-{tag}beef.tmp"), None); // live writer here: kept
    make(&format!(".ptm-{dead}-3-{other_tag}beef.tmp"), None); // another host's: kept
    make(&format!(".ptm-{dead}-4-{other_tag}beef.tmp"), Some(old)); // a day old: swept
    make(&format!(".ptm-{dead}-5-c0ffee.tmp"), None); // old name form, recent: kept
    make(&format!(".ptm-{dead}-6-c0ffee.tmp"), Some(old)); // old name form, a day old: swept
    make(&format!("{dead}.tmp"), Some(old)); // not ours: kept
    std::os::unix::fs::symlink(
        "/nonexistent",
        d.path().join(format!(".ptm-{dead}-7-{tag}beef.tmp")),
    )
    .unwrap(); // a link with our name: kept

    // tmp_path above was this process's first write here and swept the empty directory; the
    // next test shows that sweep happening on a write. Here, the sweep itself:
    let mut removed: Vec<String> = ptm_format::atomic::sweep_stale_temps(d.path())
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    removed.sort();
    let mut expect = vec![
        format!(".ptm-{dead}-3-{tag}beef.tmp"),
        format!(".ptm-{dead}-4-{other_tag}beef.tmp"),
        format!(".ptm-{dead}-6-c0ffee.tmp"),
    ];
    expect.sort();
    assert_eq!(removed, expect);
    let mut left = vec![
        format!(".ptm-{live}-3-{tag}beef.tmp"),
        format!(".ptm-{dead}-3-{other_tag}beef.tmp"),
        format!(".ptm-{dead}-5-c0ffee.tmp"),
        format!(".ptm-{dead}-7-{tag}beef.tmp"),
        format!("{dead}.tmp"),
    ];
    left.sort();
    assert_eq!(names(d.path()), left);
}

#[test]
fn the_first_write_into_a_directory_sweeps_it() {
    let d = tempfile::tempdir().unwrap();
    let probe = tmp_path(&d.path().join("probe")); // sweeps d (empty) and names this host
    let hex = probe
        .to_str()
        .unwrap()
        .rsplit('-')
        .next()
        .unwrap()
        .to_string();
    let sub = d.path().join("out");
    std::fs::create_dir(&sub).unwrap();
    let stale = sub.join(format!(".ptm-{}-0-{}beef.tmp", dead_pid(), &hex[..4]));
    std::fs::write(&stale, vec![0u8; 1 << 16]).unwrap();
    write_bytes(&sub.join("a.exr"), b"a").unwrap();
    assert_eq!(names(&sub), ["a.exr"]);
}
