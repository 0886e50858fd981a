//! Generation and OBJ-writing speed of the builtin swatches at benchmark sizes.
//!
//! `cargo run --release -p ptm-swatches --example bench_generate`
//!
//! Prints per spec: triangles, generation time (including the clearance check), and the OBJ
//! write rate next to a plain write of the same number of bytes (the I/O limit).

use std::io::Write;
use std::time::Instant;

fn main() {
    let specs = [
        "plain-weave?segments=80",
        "twill?n=3&m=1&segments=40",
        "satin?n=8&step=3&segments=24",
        "jersey?wales=4&courses=4&segments=24&along=128",
        "rib?k=2&courses=4&segments=24&along=128",
        "velvet?segments=16",
        "terry?segments=16",
    ];
    let dir = std::env::temp_dir().join(format!("ptm-bench-swatches-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    println!(
        "| spec | triangles | generate ms | M tri/s | OBJ MB | OBJ write MB/s | raw write MB/s |"
    );
    println!("|---|---|---|---|---|---|---|");
    for spec in specs {
        let t0 = Instant::now();
        let s = ptm_swatches::build(spec).expect(spec);
        let gen = t0.elapsed().as_secs_f64();
        let path = dir.join("bench.obj");
        let t1 = Instant::now();
        s.mesh.write_obj(&path).expect("write");
        let write = t1.elapsed().as_secs_f64();
        let bytes = std::fs::metadata(&path).expect("metadata").len() as usize;
        let raw = vec![b'x'; bytes];
        let t2 = Instant::now();
        let mut f = std::fs::File::create(dir.join("raw.bin")).expect("raw");
        f.write_all(&raw).expect("raw write");
        f.sync_all().expect("sync");
        let raw_t = t2.elapsed().as_secs_f64();
        let mb = bytes as f64 / 1e6;
        let tris = s.mesh.triangles.len();
        println!(
            "| `{spec}` | {tris} | {:.1} | {:.2} | {mb:.1} | {:.0} | {:.0} |",
            gen * 1e3,
            tris as f64 / gen / 1e6,
            mb / write,
            mb / raw_t
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
