//! WGSL source assembly: one source-level variant per scene shape (override constants cannot
//! remove bindings, so what a scene lacks is cut out of the text), and naga validation.
//!
//! Directives are whole lines `//#if NAME`, `//#else`, `//#endif` (nestable); placeholders
//! `{{NC}}`, `{{PTM_EVAL}}`, `{{PTM_JET}}` (its value and derivatives), `{{GRID}}` (a learned basis's grid side), `{{ENV_SIZE}}` (a background image's prefiltered map side), `{{DISTANT_DOTS}}` (a distant light's dot products), `{{LIGHT_TERMS_LEN}}` (their uniform array's length), `{{BLUR}}` (the blur
//! method's file), `{{CHANNELS}}` (its image's channels). The PTM polynomial is generated from
//! the format crate's monomial table, so the shader and `Basis::eval` cannot disagree on the
//! order; a learned basis replaces it by the bilinear read of its table (`learned_eval`).

use ptm_format::{Basis, Link, UvMap};

use crate::scene::Variant;
use crate::{Error, Result};

/// The shading shader, with directives.
pub const SHADE_WGSL: &str = include_str!("shade.wgsl");

/// The defines a variant switches on.
pub fn defines(v: &Variant) -> Vec<&'static str> {
    let mut d = Vec::new();
    if v.basis.is_some() {
        d.push("PTM");
    }
    if v.basis.is_some() && v.ptm_mip {
        d.push("PTM_MIP");
    }
    if v.basis.is_some() && v.coverage {
        d.push("PTM_COVERAGE");
    }
    if v.basis.is_some_and(Basis::is_learned) {
        d.push("PTM_LEARNED");
    }
    if v.basis.is_some() && v.link == Link::Logistic {
        d.push("PTM_LOGISTIC");
    }
    if v.basis.is_some() && v.uv == UvMap::Hemispherical {
        d.push("PTM_HEMISPHERICAL");
    }
    if v.albedo_texture {
        d.push("ALBEDO_TEX");
    }
    if v.caster.is_some() {
        d.push("CASTER");
    }
    if v.mesh {
        d.push("MESH");
    }
    if v.mesh && v.normal_map {
        d.push("NORMAL_MAP");
    }
    if v.mesh && v.shadow {
        d.push("SHADOW");
    }
    if v.gaussian {
        d.push("GAUSSIAN");
    }
    if v.turned_rect && v.caster.is_some() {
        d.push("RECT_TURNED");
    }
    if v.glossy && v.caster.is_some() {
        d.push("GLOSSY");
    }
    if v.glossy && v.caster.is_some() && v.env_size > 0 {
        d.push("GLOSSY_ENV");
    }
    if v.distant && !v.mesh {
        d.push("DISTANT");
    }
    if v.distant && v.distant_only && !v.mesh {
        d.push("DISTANT_ONLY");
    }
    if v.distant && v.mesh {
        d.push("MESH_DISTANT");
    }
    d
}

/// The WGSL expression Σ c\[i\]·u^a·v^b in basis order, e.g. `c[0] * (u * u) + c[1] * (u) + …`;
/// for a learned basis the table's read, `learned_eval(c, uv)` (shade.wgsl, `PTM_LEARNED`).
pub fn ptm_eval_expr(basis: Basis) -> String {
    if basis.is_learned() {
        return "learned_eval(c, uv)".into();
    }
    let terms: Vec<String> = basis
        .monomials()
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let factors: Vec<&str> = std::iter::repeat_n("u", m.pu as usize)
                .chain(std::iter::repeat_n("v", m.pv as usize))
                .collect();
            if factors.is_empty() {
                format!("c[{i}]")
            } else {
                format!("c[{i}] * ({})", factors.join(" * "))
            }
        })
        .collect();
    terms.join(" + ")
}

/// `distant_k`'s three dot products of the coefficients with a distant light's per-frame terms
/// (`{{DISTANT_DOTS}}`), unrolled with constant indices: per vec4 q of the terms (its lanes
/// past the last coefficient 0), `m += dot(ck, m_q)` and the gradient's u and v parts likewise,
/// in the twin's order (`Twin::distant_k`).
pub fn distant_dots(nc: usize) -> String {
    let quads = nc.div_ceil(4);
    let mut out = String::new();
    for q in 0..quads {
        let lane = |l: usize| match 4 * q + l < nc {
            true => format!("c[{}]", 4 * q + l),
            false => "0.0".into(),
        };
        let ck = format!(
            "vec4<f32>({}, {}, {}, {})",
            lane(0),
            lane(1),
            lane(2),
            lane(3)
        );
        out += &format!("    let c{q} = {ck};\n");
        for (var, run) in [("m", 0), ("g.x", 1), ("g.y", 2)] {
            out += &format!(
                "    {var} += dot(c{q}, light_terms[base + {}u]);\n",
                1 + run * quads + q
            );
        }
    }
    out
}

/// The WGSL expression of the predictor's jet at (u, v) (`{{PTM_JET}}`, a `PtmJet` of p, its
/// gradient and Hessian), each a sum over the basis's monomials differentiated term by term,
/// e.g. ∂/∂u of `c[0]·u³` is `c[0] * (3.0 * u * u)`; for a learned basis `learned_jet(c, uv)`.
pub fn ptm_jet_expr(basis: Basis) -> String {
    if basis.is_learned() {
        return "learned_jet(c, uv)".into();
    }
    // The (i, j)-th derivative of the basis's polynomial in u and v.
    let derivative = |i: u8, j: u8| {
        let fall = |n: u8, k: u8| (0..k).map(|t| u32::from(n - t)).product::<u32>();
        let terms: Vec<String> = basis
            .monomials()
            .iter()
            .enumerate()
            .filter(|(_, m)| m.pu >= i && m.pv >= j)
            .map(|(n, m)| {
                let factor = fall(m.pu, i) * fall(m.pv, j);
                let mut factors: Vec<String> = std::iter::repeat_n("u", (m.pu - i) as usize)
                    .chain(std::iter::repeat_n("v", (m.pv - j) as usize))
                    .map(String::from)
                    .collect();
                if factor != 1 {
                    factors.insert(0, format!("{factor}.0"));
                }
                if factors.is_empty() {
                    format!("c[{n}]")
                } else {
                    format!("c[{n}] * ({})", factors.join(" * "))
                }
            })
            .collect();
        if terms.is_empty() {
            "0.0".to_string()
        } else {
            terms.join(" + ")
        }
    };
    format!(
        "PtmJet({}, vec2<f32>({}, {}), vec3<f32>({}, {}, {}))",
        derivative(0, 0),
        derivative(1, 0),
        derivative(0, 1),
        derivative(2, 0),
        derivative(1, 1),
        derivative(0, 2)
    )
}

/// The mesh path's stages, included into `shade.wgsl` for mesh variants (`{{MESH}}`).
pub const MESH_WGSL: &str = include_str!("mesh.wgsl");

/// The window's blit pass (cargo feature `window`; validated and twinned without it).
pub const BLIT_WGSL: &str = include_str!("blit.wgsl");

/// Keeps the lines whose enclosing `//#if` conditions hold.
pub fn preprocess(src: &str, defined: &[&str]) -> Result<String> {
    let mut out = String::with_capacity(src.len());
    // One entry per open `#if`: whether its current branch is taken.
    let mut stack: Vec<bool> = Vec::new();
    let active = |stack: &[bool]| stack.iter().all(|&a| a);
    for (n, line) in src.lines().enumerate() {
        let t = line.trim();
        if let Some(name) = t.strip_prefix("//#if ") {
            stack.push(defined.contains(&name.trim()));
        } else if t == "//#else" {
            let top = stack
                .last_mut()
                .ok_or_else(|| bad(n, "#else without #if"))?;
            *top = !*top;
        } else if t == "//#endif" {
            stack.pop().ok_or_else(|| bad(n, "#endif without #if"))?;
        } else if active(&stack) {
            out.push_str(line);
            out.push('\n');
        }
    }
    if !stack.is_empty() {
        return Err(bad(src.lines().count(), "unclosed #if"));
    }
    Ok(out)
}

fn bad(line: usize, what: &str) -> Error {
    Error::Shader {
        variant: "(preprocessing)".into(),
        reason: format!("shade.wgsl line {}: {what}", line + 1),
    }
}

/// The complete WGSL source of a variant: `shade.wgsl` with the blur method's file (its
/// bindings and `blur_lookup`, [`crate::blur::Method::wgsl`]) in place of `{{BLUR}}`, and for a
/// mesh variant `mesh.wgsl` in place of `{{MESH}}` (and of the full-screen triangle).
pub fn shade_source(v: &Variant) -> Result<String> {
    let defined = defines(v);
    let blur = match v.caster {
        Some(b) => preprocess(crate::blur::method(b).wgsl(), &defined)?,
        None => String::new(),
    };
    let mesh = if v.mesh {
        preprocess(MESH_WGSL, &defined)?
    } else {
        String::new()
    };
    let src = preprocess(SHADE_WGSL, &defined)?
        .replace("{{BLUR}}", &blur)
        .replace("{{MESH}}", &mesh);
    let nc = v.basis.map_or(0, |b| b.len());
    let eval = v.basis.map(ptm_eval_expr).unwrap_or_default();
    let jet = v.basis.map(ptm_jet_expr).unwrap_or_default();
    Ok(src
        .replace("{{DISTANT_DOTS}}", &distant_dots(nc))
        .replace(
            "{{LIGHT_TERMS_LEN}}",
            &crate::scene::MAX_LIGHT_TERMS.to_string(),
        )
        .replace("{{NC}}", &nc.to_string())
        .replace("{{PTM_EVAL}}", &eval)
        .replace("{{PTM_JET}}", &jet)
        .replace("{{GRID}}", &v.learned_grid.to_string())
        .replace("{{ENV_SIZE}}", &v.env_size.to_string())
        .replace("{{CHANNELS}}", &v.sat_channels().to_string()))
}

/// Parses and validates WGSL with naga (no GPU needed).
pub fn validate(name: &str, src: &str) -> Result<naga::Module> {
    let module = naga::front::wgsl::parse_str(src).map_err(|e| Error::Shader {
        variant: name.into(),
        reason: e.emit_to_string(src),
    })?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| Error::Shader {
        variant: name.into(),
        reason: format!("{e:?}"),
    })?;
    Ok(module)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shade_variant_validates_with_naga() {
        let all = Variant::all();
        // No PTM, or ptm6 or ptm11 × link × (u, v) map × with and without a MIP chain × with
        // and without coverage, or learned6 or learned11 (logistic, hemispherical) × MIP chain
        // × coverage; × albedo × (caster, or a mesh with or without a normal map and a macro
        // shadow); and with a Gaussian light, without albedo, MIP chain or coverage; and with a
        // turned rectangle, likewise, with a per-pixel method (3) and either channel count; and
        // with a glossy receiver, likewise, over a grey caster blurred by a per-pixel method (3),
        // with a background colour or image; and with a distant light, without albedo, MIP
        // chain or coverage, with no caster or any method (4) and either channel count or a
        // glossy receiver over a per-pixel method (3), and with every light distant; and on
        // the mesh path (4).
        assert_eq!(
            all.len(),
            (1 + 2 * 2 * 2 * 2 * 2 + 2 * 2 * 2) * 2 * (9 + 4)
                + (1 + 2 * 2 * 2 + 2) * (9 + 4)
                + (1 + 2 * 2 * 2 + 2) * 3 * 2
                + (1 + 2 * 2 * 2 + 2) * 3 * 2
                + (1 + 2 * 2 * 2 + 2) * (1 + 4 * 2 + 3) * 2
                + (1 + 2 * 2 * 2 + 2) * 4
        );
        for v in all {
            let src = shade_source(&v).unwrap();
            assert!(!src.contains("{{"), "{}: unfilled placeholder", v.name());
            assert!(
                !src.lines().any(|l| l.trim_start().starts_with("//#")),
                "{}: directive left",
                v.name()
            );
            if let Err(e) = validate(&v.name(), &src) {
                panic!("{e}");
            }
        }
    }

    #[test]
    fn compute_shaders_validate_with_naga() {
        for b in crate::scene::Blur::ALL {
            for (file, src) in crate::blur::method(b).pass_wgsl() {
                validate(file, src).unwrap();
            }
        }
    }

    #[test]
    fn variants_without_a_feature_have_no_binding_for_it() {
        let v = Variant {
            basis: None,
            learned_grid: 0,
            albedo_texture: false,
            caster: None,
            colored: false,
            ptm_mip: false,
            coverage: false,
            link: Link::Identity,
            uv: UvMap::Projected,
            mesh: false,
            normal_map: false,
            shadow: false,
            gaussian: false,
            turned_rect: false,
            glossy: false,
            env_size: 0,
            distant: false,
            distant_only: false,
        };
        let src = shade_source(&v).unwrap();
        for name in [
            "coeffs",
            "albedo_tex",
            "opacity_tex",
            "var<storage, read> sat",
        ] {
            assert!(!src.contains(name), "plain variant still mentions {name}");
        }
        let module = validate("plain", &src).unwrap();
        for name in [
            "mip",
            "sep_map",
            "ptm_levels",
            "ptm_lod",
            "ptm_coverage",
            "normal_tex",
            "vs_mesh",
            "shadow_maps",
            "shadow_sampler",
        ] {
            assert!(!src.contains(name), "plain variant still mentions {name}");
        }
        assert_eq!(module.global_variables.len(), 2, "only frame and lights");
    }

    #[test]
    fn only_turned_rectangle_glossy_and_distant_variants_have_their_code() {
        let all = Variant::all();
        assert!(all.iter().any(|v| v.turned_rect));
        assert!(all.iter().any(|v| v.glossy));
        assert!(all.iter().any(|v| v.distant && v.basis.is_some()));
        for v in all {
            let src = shade_source(&v).unwrap();
            // A distant light's direction only with one; its per-frame terms (binding and
            // dot products) only with one over a PTM.
            assert_eq!(
                src.contains("to_light = light.position;"),
                v.distant,
                "{}",
                v.name()
            );
            // A distant light's orthographic shadow view only on a mesh with one and a shadow.
            assert_eq!(
                src.contains("fn shadow_view_ortho"),
                v.distant && v.mesh && v.shadow,
                "{}",
                v.name()
            );
            let terms = v.distant && v.basis.is_some() && !v.mesh;
            for name in ["fn distant_k", "var<uniform> light_terms"] {
                assert_eq!(src.contains(name), terms, "{}: {name}", v.name());
            }
            assert_eq!(src.contains("fn rect_slabs"), v.turned_rect, "{}", v.name());
            for name in ["glossy_reflection", "glossy_fresnel"] {
                assert_eq!(src.contains(name), v.glossy, "{}: {name}", v.name());
            }
            // The background image's binding and lookup only with one.
            for name in ["env_lookup", "var<storage, read> environment"] {
                assert_eq!(src.contains(name), v.env_size > 0, "{}: {name}", v.name());
            }
            if v.env_size > 0 {
                assert!(src.contains("const ENV_SIZE: u32 = 8u;"), "{}", v.name());
            }
        }
    }

    #[test]
    fn only_the_files_link_and_uv_map_are_compiled() {
        // Names and intrinsics that exist only for the logistic link or the hemispherical map.
        let logistic = ["ptm_sigmoid", "exp("];
        let hemispherical = ["ptm_hemispherical", "atan2"];
        let all = Variant::all();
        assert!(all.iter().any(|v| v.link == Link::Logistic));
        assert!(all.iter().any(|v| v.uv == UvMap::Hemispherical));
        for v in all {
            let src = shade_source(&v).unwrap();
            let ptm = v.basis.is_some();
            for name in logistic {
                // The mesh path's sheen visibility and the explicit grid's Gaussian weights have
                // their own exp().
                let gauss_grid = v.gaussian && v.caster == Some(crate::scene::Blur::Explicit);
                if (v.mesh || gauss_grid) && name == "exp(" {
                    continue;
                }
                let want = ptm && v.link == Link::Logistic;
                assert_eq!(src.contains(name), want, "{}: {name}", v.name());
            }
            for name in hemispherical {
                let want = ptm && v.uv == UvMap::Hemispherical;
                assert_eq!(src.contains(name), want, "{}: {name}", v.name());
            }
        }
    }

    #[test]
    fn only_learned_variants_have_the_table_its_binding_and_its_lookup() {
        // A polynomial scene's WGSL never mentions the learned basis: no binding, no grid
        // constant, no lookup, not even a comment; a learned scene's has all three and no
        // polynomial.
        let all = Variant::all();
        assert!(all.iter().any(|v| v.basis.is_some_and(Basis::is_learned)));
        for v in all {
            let src = shade_source(&v).unwrap();
            let learned = v.basis.is_some_and(Basis::is_learned);
            assert_eq!(
                src.to_lowercase().contains("learned"),
                learned,
                "{}",
                v.name()
            );
            let module = validate(&v.name(), &src).unwrap();
            let bound = crate::bindings::reflect(&module)
                .contains(&("learned".to_string(), crate::bindings::shade::LEARNED.index));
            assert_eq!(bound, learned, "{}: the table's binding", v.name());
            if learned {
                assert!(
                    src.contains("const LEARNED_GRID: u32 = 17u;"),
                    "{}",
                    v.name()
                );
                assert!(src.contains("let k = ptm_sigmoid(learned_eval(c, uv));"));
                assert!(!src.contains("c[0] * (u"), "{}: a polynomial", v.name());
            }
        }
    }

    #[test]
    fn generated_polynomial_matches_the_basis_order() {
        assert_eq!(
            ptm_eval_expr(Basis::Ptm6),
            "c[0] * (u * u) + c[1] * (u) + c[2] * (u * v) + c[3] * (v) + c[4] * (v * v) + c[5]"
        );
        assert!(ptm_eval_expr(Basis::Ptm11).starts_with("c[0] * (u * u * u) + c[1] * (v * v * v)"));
    }

    #[test]
    fn preprocess_nests_and_rejects_unbalanced() {
        let src = "a\n//#if X\nb\n//#if Y\nc\n//#else\nd\n//#endif\n//#else\ne\n//#endif\nf\n";
        assert_eq!(preprocess(src, &["X"]).unwrap(), "a\nb\nd\nf\n");
        assert_eq!(preprocess(src, &["X", "Y"]).unwrap(), "a\nb\nc\nf\n");
        assert_eq!(preprocess(src, &["Y"]).unwrap(), "a\ne\nf\n");
        assert!(preprocess("//#if X\n", &[]).is_err());
        assert!(preprocess("//#endif\n", &[]).is_err());
    }
}
