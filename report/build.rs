//! Links the report crate's own tests against libembree4 (see `bake/embree_link.rs`).
include!("../bake/embree_link.rs");

fn main() {
    let manifest = std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    embree_link(manifest.parent().unwrap());
}
