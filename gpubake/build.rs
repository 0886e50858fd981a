//! Links the GPU bake crate's own tests and benchmark against libembree4 (they run the CPU
//! bake beside the GPU's; see `bake/embree_link.rs`).
include!("../bake/embree_link.rs");

fn main() {
    let manifest = std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    embree_link(manifest.parent().unwrap());
}
