//! The analytic cases of the Embree bake (`bake/tests/common`), on the GPU bake, with the same
//! scenes and tolerances: a flat plane never occluded, the ridge (an infinite wall) casting a
//! band of known width across several tiles, a sphere's elliptic floor shadow and terminator,
//! and point lights' per-texel directions.
#[path = "../../bake/tests/common/mod.rs"]
mod common;
mod gpu;

#[test]
fn flat_plane_is_never_occluded_on_the_gpu() {
    common::flat_plane(&gpu::gpu);
}

#[test]
fn ridge_shadow_band_across_several_tiles_on_the_gpu() {
    common::infinite_wall(&gpu::gpu);
}

#[test]
fn sphere_on_plane_shadow_and_terminator_on_the_gpu() {
    common::sphere_on_plane(&gpu::gpu);
}

#[test]
fn point_lights_record_per_texel_directions_on_the_gpu() {
    common::point_lights(&gpu::gpu);
}
