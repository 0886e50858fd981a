//! Every binding of every WGSL file, named once: (WGSL variable name, `@binding` number) of
//! group 0. The GPU code binds buffers by these constants, never by a number, and the tests
//! check each file's declarations against naga's reflection of every variant (the way
//! [`crate::layout`] checks struct offsets), so a binding renumbered or renamed on one side
//! only, or two sharing a number, fails without a GPU.
//!
//! The shading pass's table is shared by `shader/shade.wgsl` and the blur methods' files it
//! includes (`blur/*.wgsl`, [`crate::blur::Method::wgsl`]): a method's bindings are numbered
//! here beside the others so no two can collide.

/// One binding of group 0: the WGSL variable and its `@binding` number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// The WGSL variable's name.
    pub name: &'static str,
    /// Its `@binding(N)`.
    pub index: u32,
}

const fn b(name: &'static str, index: u32) -> Binding {
    Binding { name, index }
}

/// The shading pass (`shader/shade.wgsl` and the blur method included into it).
pub mod shade {
    use super::{b, Binding};
    /// The uniform block (`layout::Frame`).
    pub const FRAME: Binding = b("frame", 0);
    /// The lights (`layout::LightGpu`).
    pub const LIGHTS: Binding = b("lights", 1);
    /// PTM coefficients, texel-major, every MIP level.
    pub const COEFFS: Binding = b("coeffs", 2);
    /// The albedo texture.
    pub const ALBEDO: Binding = b("albedo_tex", 3);
    /// Explicit blur: the image's packed 8-bit texels.
    pub const OPACITY: Binding = b("opacity_tex", 4);
    /// SAT blur: the summed-area table.
    pub const SAT: Binding = b("sat", 5);
    /// MIP blur: the image's MIP chain.
    pub const MIP: Binding = b("mip", 6);
    /// MIP blur: where each level of the chain lies.
    pub const MIP_LEVELS: Binding = b("mip_levels", 7);
    /// Separable blur: the per-light pre-blurred maps.
    pub const SEP_MAP: Binding = b("sep_map", 8);
    /// The PTM's MIP levels.
    pub const PTM_LEVELS: Binding = b("ptm_levels", 9);
    /// The PTM's per-texel coverage.
    pub const COVERAGE: Binding = b("coverage", 10);
    /// The filtered planar image's uniform block (`layout::PlaneGpu`).
    pub const PLANE: Binding = b("plane", 11);
    /// Mesh path: the tangent-space normal map.
    pub const NORMAL_MAP: Binding = b("normal_tex", 12);
    /// A learned basis's tables, node-major (`SceneBuffers::learned`).
    pub const LEARNED: Binding = b("learned", 13);
    /// Mesh path: the macro shadow's depth maps, one layer per light.
    pub const SHADOWS: Binding = b("shadow_maps", 14);
    /// Mesh path: the sampler the macro shadow gathers its depth maps with.
    pub const GATHER: Binding = b("shadow_sampler", 15);
    /// Glossy receiver: the background image's equal-area map and its levels
    /// (`SceneBuffers::environment`).
    pub const ENVIRONMENT: Binding = b("environment", 16);
    /// Distant lights: the basis terms evaluated once per frame (`SceneBuffers::light_terms`).
    pub const LIGHT_TERMS: Binding = b("light_terms", 17);
    /// Every binding of the shading pass.
    pub const ALL: &[Binding] = &[
        FRAME,
        LIGHTS,
        COEFFS,
        ALBEDO,
        OPACITY,
        SAT,
        MIP,
        MIP_LEVELS,
        SEP_MAP,
        PTM_LEVELS,
        COVERAGE,
        PLANE,
        NORMAL_MAP,
        LEARNED,
        SHADOWS,
        GATHER,
        ENVIRONMENT,
        LIGHT_TERMS,
    ];
}

/// The summed-area table passes (`blur/sat_build.wgsl`).
pub mod sat_build {
    use super::{b, Binding};
    /// `layout::SatParams`.
    pub const PARAMS: Binding = b("params", 0);
    /// The image's packed 8-bit texels.
    pub const OPACITY: Binding = b("opacity_tex", 1);
    /// The table written.
    pub const SAT: Binding = b("sat", 2);
    /// Every binding of the file.
    pub const ALL: &[Binding] = &[PARAMS, OPACITY, SAT];
}

/// The separable blur passes (`blur/separable_passes.wgsl`).
pub mod separable_passes {
    use super::{b, Binding};
    /// `layout::SepParams`.
    pub const PARAMS: Binding = b("params", 0);
    /// The image's packed 8-bit texels.
    pub const OPACITY: Binding = b("opacity_tex", 1);
    /// Box half-sides per light.
    pub const RADII: Binding = b("radii", 2);
    /// The horizontal pass's output.
    pub const HMAP: Binding = b("hmap", 3);
    /// The vertical pass's output: the maps the shading pass reads.
    pub const VMAP: Binding = b("vmap", 4);
    /// Every binding of the file.
    pub const ALL: &[Binding] = &[PARAMS, OPACITY, RADII, HMAP, VMAP];
}

/// The window's blit (`shader/blit.wgsl`, cargo feature `window`).
pub mod blit {
    use super::{b, Binding};
    /// The rendered frame.
    pub const FRAME: Binding = b("frame_tex", 0);
    /// The letterbox parameters.
    pub const PARAMS: Binding = b("params", 1);
    /// Every binding of the file.
    pub const ALL: &[Binding] = &[FRAME, PARAMS];
}

/// (name, binding) of every global of group 0 that `module` declares, in declaration order.
pub fn reflect(module: &naga::Module) -> Vec<(String, u32)> {
    module
        .global_variables
        .iter()
        .filter_map(|(_, g)| {
            let rb = g.binding.as_ref()?;
            (rb.group == 0).then(|| (g.name.clone().unwrap_or_default(), rb.binding))
        })
        .collect()
}

/// Checks `module`'s bindings against `table`: every binding it declares is in the table
/// under its name and number, and no two share a number. Returns the names it declares.
pub fn check(file: &str, module: &naga::Module, table: &[Binding]) -> Result<Vec<String>, String> {
    let mut seen: Vec<(String, u32)> = Vec::new();
    for (name, index) in reflect(module) {
        let Some(want) = table.iter().find(|b| b.name == name) else {
            return Err(format!(
                "{file}: binding {index} `{name}` is not in bindings.rs"
            ));
        };
        if want.index != index {
            return Err(format!(
                "{file}: `{name}` is @binding({index}) in the WGSL, {} in bindings.rs",
                want.index
            ));
        }
        if let Some((other, _)) = seen.iter().find(|(_, i)| *i == index) {
            return Err(format!(
                "{file}: `{name}` and `{other}` share @binding({index})"
            ));
        }
        seen.push((name, index));
    }
    Ok(seen.into_iter().map(|(n, _)| n).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Variant;
    use crate::shader;
    use std::collections::BTreeSet;

    fn distinct(table: &[Binding]) {
        let names: BTreeSet<_> = table.iter().map(|b| b.name).collect();
        let numbers: BTreeSet<_> = table.iter().map(|b| b.index).collect();
        assert_eq!(names.len(), table.len(), "a name twice in {table:?}");
        assert_eq!(numbers.len(), table.len(), "a number twice in {table:?}");
    }

    #[test]
    fn every_shade_variant_declares_the_bindings_of_the_table_and_uses_them_all() {
        distinct(shade::ALL);
        let mut used = BTreeSet::new();
        for v in Variant::all() {
            let src = shader::shade_source(&v).unwrap();
            let module = shader::validate(&v.name(), &src).unwrap();
            let names = check(&v.name(), &module, shade::ALL).unwrap_or_else(|e| panic!("{e}"));
            used.extend(names);
        }
        let unused: Vec<_> = shade::ALL
            .iter()
            .filter(|b| !used.contains(b.name))
            .collect();
        assert!(
            unused.is_empty(),
            "bindings no variant declares: {unused:?}"
        );
    }

    #[test]
    fn the_compute_passes_declare_the_bindings_of_their_tables() {
        for (file, src, table) in [
            ("blit.wgsl", shader::BLIT_WGSL, blit::ALL),
            (
                "sat_build.wgsl",
                crate::blur::sat::BUILD_WGSL,
                sat_build::ALL,
            ),
            (
                "separable_passes.wgsl",
                crate::blur::separable::PASSES_WGSL,
                separable_passes::ALL,
            ),
        ] {
            distinct(table);
            let module = shader::validate(file, src).unwrap();
            let names = check(file, &module, table).unwrap();
            assert_eq!(names.len(), table.len(), "{file}: {names:?} vs {table:?}");
        }
    }

    #[test]
    fn a_renumbered_or_unlisted_binding_is_named() {
        let src = "@group(0) @binding(3) var<uniform> frame: vec4<f32>;\n\
                   @group(0) @binding(1) var<storage, read> stray: array<u32>;\n\
                   @fragment fn f() -> @location(0) vec4<f32> { return frame + f32(stray[0]); }";
        let module = shader::validate("t", src).unwrap();
        let e = check("t.wgsl", &module, shade::ALL).unwrap_err();
        assert!(e.contains("`frame` is @binding(3)"), "{e}");
        let e = check("t.wgsl", &module, &[b("frame", 3)]).unwrap_err();
        assert!(e.contains("`stray` is not in bindings.rs"), "{e}");
    }
}
