//! Links the bake crate's own tests and benchmarks against libembree4 (see `embree_link.rs`).
include!("embree_link.rs");

fn main() {
    let manifest = std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    embree_link(manifest.parent().unwrap());
}
