// Shared by `bake/build.rs` and the root `build.rs` (included textually): find libembree4 and
// tell the linker where it is. Rust passes `rustc-link-arg` only to the package's own final
// artifacts, so every package that links an executable against Embree runs this.
//
// Order of search: `EMBREE_DIR` (a system Embree 4 install with `lib/libembree4.so`), then the
// project's `.deps/embree/lib`, filled by `scripts/setup.sh` from the pinned `embreex` wheel.

fn embree_link(workspace_root: &std::path::Path) {
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    let dir = match std::env::var_os("EMBREE_DIR") {
        Some(d) => {
            let d = std::path::PathBuf::from(d);
            ["lib", "lib64"]
                .iter()
                .map(|l| d.join(l))
                .find(|l| l.join("libembree4.so").exists())
                .unwrap_or_else(|| {
                    panic!(
                        "EMBREE_DIR={} has no lib/libembree4.so; point it at an Embree 4 install \
                         or unset it and run scripts/setup.sh",
                        d.display()
                    )
                })
        }
        None => {
            let d = workspace_root.join(".deps/embree/lib");
            if !d.join("libembree4.so").exists() {
                panic!(
                    "Embree 4 not found in {}: run `bash scripts/setup.sh` (fetches Embree 4.4 \
                     from the embreex wheel) or set EMBREE_DIR to an Embree 4 install",
                    d.display()
                );
            }
            d
        }
    };
    println!("cargo:rerun-if-changed={}", dir.join("libembree4.so").display());
    println!("cargo:rustc-link-search=native={}", dir.display());
    // The wheel's libembree4 needs its TBB at link time (rpath-link) and at run time (rpath).
    println!("cargo:rustc-link-arg=-Wl,-rpath-link,{}", dir.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
}
