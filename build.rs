//! Links the `ptm` binary and its integration tests against libembree4 (see `bake/embree_link.rs`).
include!("bake/embree_link.rs");

fn main() {
    embree_link(std::path::Path::new(env!("CARGO_MANIFEST_DIR")));
}
