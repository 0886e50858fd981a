//! The CPU twin of the shaders, one module per WGSL file with the WGSL functions' names
//! (vello's `cpu/` beside `shaders/`): [`shade`] for `shader/shade.wgsl`, [`blit`] for
//! `shader/blit.wgsl`; each blur method's module in [`crate::blur`] is the twin of its own WGSL
//! files. [`twins`] pairs every WGSL function with its twin; a test fails when a WGSL function
//! has none.
//!
//! [`render`] runs the whole pipeline the GPU runs (tables, then one `fs_main` per pixel) on the
//! same [`SceneBuffers`] buffers; tests compare the GPU image with it.

pub mod blit;
pub mod mesh;
pub mod shade;

use rayon::prelude::*;

use crate::output::Image;
use crate::scene::SceneBuffers;
use shade::{pixel_world, ptm_lod, OpacityFn, Twin};

/// Renders the prepared scene on the CPU (row-parallel; each pixel is independent, so the
/// result does not depend on the thread count); a mesh scene through [`mesh::render`].
pub fn render(p: &SceneBuffers) -> Image {
    if p.variant.mesh {
        return mesh::render(p);
    }
    render_with(p, None)
}

/// As [`render`], with the caster opacity of each (cloth point, light) taken from `opacity`
/// instead of the blur method when given (the Monte Carlo reference,
/// [`crate::reference::render_reference`]).
pub fn render_with(p: &SceneBuffers, opacity: Option<&OpacityFn<'_>>) -> Image {
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    // What the method's passes build on the GPU (a table, the separable maps), built here.
    let blur = p.variant.caster.map(|b| {
        let m = crate::blur::method(b);
        (m, m.build_twin(&p.plane, p.prepared.as_ref()))
    });
    let twin = Twin {
        p,
        blur: blur.as_ref().map(|(m, built)| (*m, built.as_ref())),
        opacity,
    };
    let mut pixels = vec![[0f32; 4]; w * h];
    pixels.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            *px = twin.fs_main([i as f32 + 0.5, j as f32 + 0.5]);
        }
    });
    Image {
        width: w,
        height: h,
        pixels,
    }
}

/// The radiance a glossy receiver reflects at every pixel (`glossy_reflection`, before the
/// Fresnel blend), row-major; 0 where a perspective ray misses the cloth. `None` unless the
/// scene has a glossy receiver.
pub fn render_reflection(p: &SceneBuffers) -> Option<Vec<[f32; 3]>> {
    let b = p.variant.caster.filter(|_| p.variant.glossy)?;
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let m = crate::blur::method(b);
    let built = m.build_twin(&p.plane, p.prepared.as_ref());
    let twin = Twin {
        p,
        blur: Some((m, built.as_ref())),
        opacity: None,
    };
    let mut out = vec![[0f32; 3]; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            let frag = [i as f32 + 0.5, j as f32 + 0.5];
            if let Some(q) = pixel_world(&p.frame, frag) {
                *px = twin.glossy_reflection(q, twin.view_direction(frag));
            }
        }
    });
    Some(out)
}

/// How far the unclamped K strays from [0, 1] over the rendered pixels and lights: a property
/// of the fit (overshoot at grazing angles), reported beside the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KExcursion {
    /// Smallest unclamped K evaluated.
    pub min: f32,
    /// Largest unclamped K evaluated.
    pub max: f32,
    /// Fraction of (pixel, light above the horizon) evaluations clamped.
    pub clamped_fraction: f64,
    /// (pixel, light above the horizon) pairs K was evaluated for.
    pub evaluations: u64,
}

/// K before clamping at every pixel for every light, exactly as the shader evaluates it;
/// `None` without a PTM or without a light above the acceptor.
pub fn k_excursion(p: &SceneBuffers) -> Option<KExcursion> {
    if p.variant.basis.is_none() || p.variant.mesh {
        // Reported for the plane path (the mesh path's tangent frames are per pixel).
        return None;
    }
    let twin = Twin {
        p,
        blur: None,
        opacity: None,
    };
    let [w, h] = [p.frame.screen[0] as usize, p.frame.screen[1] as usize];
    let lights = &p.lights[..p.frame.light_count as usize];
    let rows: Vec<(f32, f32, u64, u64)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let (mut lo, mut hi, mut out, mut n) = (f32::INFINITY, f32::NEG_INFINITY, 0u64, 0u64);
            for i in 0..w {
                let frag = [i as f32 + 0.5, j as f32 + 0.5];
                let Some(pos) = pixel_world(&p.frame, frag) else {
                    continue;
                };
                let c = twin.ptm_coeffs(pos, ptm_lod(&p.frame, frag));
                for l in lights {
                    let d = l.to_light(pos);
                    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    if d[2] <= 0.0 || len <= 0.0 {
                        continue;
                    }
                    let l = d.map(|x| x / len);
                    let k = twin.ptm_k_unclamped(&c, l);
                    lo = lo.min(k);
                    hi = hi.max(k);
                    out += u64::from(!(0.0..=1.0).contains(&k));
                    n += 1;
                }
            }
            (lo, hi, out, n)
        })
        .collect();
    let (lo, hi, out, n) = rows
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY, 0, 0), |a, r| {
            (a.0.min(r.0), a.1.max(r.1), a.2 + r.2, a.3 + r.3)
        });
    (n > 0).then(|| KExcursion {
        min: lo,
        max: hi,
        clamped_fraction: out as f64 / n as f64,
        evaluations: n,
    })
}

/// `(WGSL file, full path of the twin)` for every pair, e.g. `("blur/sat_build.wgsl",
/// "ptm_runtime::blur::sat::sat_rows")`: the twin of a function has its name and lives in the
/// module that owns its file ([`twin_module`]). Taking the function's path makes the compiler
/// check that the twin exists.
pub fn twins() -> Vec<(&'static str, &'static str)> {
    use crate::blur::{explicit, mip, sat, separable, Method};
    macro_rules! twins {
        ($($file:literal => $($f:expr),+;)+) => {
            vec![$($(($file, std::any::type_name_of_val(&$f))),+),+]
        };
    }
    twins! {
        "shade.wgsl" => shade::vs_main, shade::view_dir, shade::pixel_world,
            shade::tile_bilinear, shade::ptm_lod, shade::level_axis, shade::level_bilinear,
            shade::Twin::ptm_level, shade::Twin::ptm_coeffs, shade::ptm_hemispherical,
            shade::ptm_sigmoid, shade::learned_bilinear, shade::Twin::learned_node,
            shade::Twin::learned_eval,
            shade::Twin::learned_jet, shade::Twin::ptm_k, shade::Twin::ptm_jet,
            shade::cap_moments, shade::Twin::ptm_footprint,
            shade::Twin::ptm_k_area, shade::Twin::distant_k, shade::Twin::coverage_level,
            shade::Twin::ptm_coverage, shade::Twin::albedo_at,
            shade::caster_texel_coords, shade::rect_chord, shade::rect_slabs, shade::Twin::light_blur, shade::Twin::light_opacity, shade::sphere_ellipse,
            shade::env_texel, shade::env_bilinear, shade::env_lookup,
            shade::Twin::glossy_reflection, shade::Twin::glossy_ring_weights, shade::Twin::glossy_fresnel,
            shade::Twin::shade,
            shade::Twin::fs_main;
        "blur/explicit.wgsl" => explicit::opacity_raw, explicit::blur_explicit,
            explicit::blur_explicit_gauss, <explicit::Explicit as Method>::blur_lookup;
        "blur/sat.wgsl" => sat::sat_load, sat::sat_spans, sat::blur_sat, sat::blur_sat_ellipse,
            sat::blur_sat_gauss, <sat::Sat as Method>::blur_lookup;
        "blur/sat_build.wgsl" => sat::sat_rows, sat::sat_columns;
        "blur/mip.wgsl" => mip::mip_texel, mip::mip_bilinear, mip::mip_trilinear, mip::blur_mip,
            mip::ewa_area, mip::blur_mip_ellipse,
            <mip::Mip as Method>::blur_lookup;
        "blur/separable.wgsl" => separable::sep_tap, separable::blur_separable,
            <separable::Separable as Method>::blur_lookup;
        "blur/separable_passes.wgsl" => separable::texel, separable::sep_h, separable::hval,
            separable::sep_v;
        "blit.wgsl" => blit::vs_main, blit::srgb_encode, blit::fs_main;
        "mesh.wgsl" => mesh::mesh_clip, mesh::vs_mesh, mesh::mesh_lod, mesh::tangent_frame,
            mesh::normal_at, mesh::sheen_d, mesh::sheen_l, mesh::sheen_lambda,
            mesh::sheen_visibility, mesh::sheen_brdf, mesh::shade_mesh, mesh::fs_mesh,
            mesh::shadow_view, mesh::shadow_clip, mesh::vs_shadow, mesh::shadow_distance,
            mesh::shadow_depth,
            mesh::shadow_taps, mesh::shadow_light_radius, mesh::shadow_source, mesh::shadow_view_ortho,
            mesh::light_shadow_view, mesh::shadow_axes,
            mesh::shadow_visibility;
    }
}

/// The module a WGSL file's twins live in: `cpu::shade` for `shade.wgsl`, the method's module
/// for a blur method's files (`blur/sat.wgsl` and `blur/sat_build.wgsl`: `blur::sat`).
pub fn twin_module(file: &str) -> String {
    match file.strip_prefix("blur/") {
        Some(f) => {
            let stem = f.trim_end_matches(".wgsl");
            let method = stem.split('_').next().unwrap_or(stem);
            format!("::blur::{method}::")
        }
        None => format!("::cpu::{}::", file.trim_end_matches(".wgsl")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Variant;
    use crate::shader;
    use std::collections::BTreeSet;

    /// Function and entry point names of WGSL sources (every variant of a file together).
    fn wgsl_functions(sources: &[String]) -> BTreeSet<String> {
        let mut names = BTreeSet::new();
        for src in sources {
            let m = naga::front::wgsl::parse_str(src).expect("WGSL parses");
            names.extend(m.functions.iter().filter_map(|(_, f)| f.name.clone()));
            names.extend(m.entry_points.iter().map(|e| e.name.clone()));
        }
        names
    }

    /// Names of the functions a WGSL file declares, read from its text (`fn name(` at the start
    /// of a line: a blur method's lookup file does not parse alone, it uses shade.wgsl's
    /// globals).
    fn declared(src: &str) -> BTreeSet<String> {
        src.lines()
            .filter_map(|l| l.strip_prefix("fn "))
            .filter_map(|l| l.split('(').next())
            .map(|n| n.trim().to_string())
            .collect()
    }

    #[test]
    fn every_wgsl_function_has_its_listed_twin_in_the_module_named_after_its_file() {
        let variants = Variant::all();
        let assembled: Vec<String> = variants
            .iter()
            .map(|v| shader::shade_source(v).unwrap())
            .collect();
        // Each file with its functions: a method's lookup file from its text (and each of them
        // must be in the variants that include it), its passes and shade.wgsl's own from naga.
        let mut files: Vec<(String, BTreeSet<String>)> = Vec::new();
        let mut method_fns = BTreeSet::new();
        for b in crate::scene::Blur::ALL {
            let m = crate::blur::method(b);
            let own = declared(m.wgsl());
            for (v, src) in variants.iter().zip(&assembled) {
                if v.caster == Some(b) {
                    // What the variant keeps of the file (the Gaussian's code only with one).
                    let kept =
                        declared(&shader::preprocess(m.wgsl(), &shader::defines(v)).unwrap());
                    let in_variant = wgsl_functions(std::slice::from_ref(src));
                    assert!(kept.is_subset(&in_variant), "{}: {kept:?}", v.name());
                }
            }
            method_fns.extend(own.iter().cloned());
            files.push((format!("blur/{}.wgsl", b.name()), own));
            for (file, pass) in m.pass_wgsl() {
                files.push((format!("blur/{file}"), wgsl_functions(&[pass.to_string()])));
            }
        }
        let mesh_fns = declared(shader::MESH_WGSL);
        method_fns.extend(mesh_fns.iter().cloned());
        let shade: BTreeSet<String> = wgsl_functions(&assembled)
            .difference(&method_fns)
            .cloned()
            .collect();
        files.insert(0, ("shade.wgsl".into(), shade));
        files.push(("mesh.wgsl".into(), mesh_fns));
        files.push((
            "blit.wgsl".into(),
            wgsl_functions(&[shader::BLIT_WGSL.to_string()]),
        ));
        let table = twins();
        for (file, wgsl) in &files {
            let module = twin_module(file);
            let mut listed = BTreeSet::new();
            for &(_, path) in table.iter().filter(|(f, _)| f == file) {
                assert!(
                    path.contains(&module),
                    "{file}: twin {path} is not in {module}"
                );
                let name = path.rsplit("::").next().unwrap().to_string();
                assert!(listed.insert(name), "{file}: {path} listed twice");
            }
            let missing: Vec<_> = wgsl.difference(&listed).collect();
            let stale: Vec<_> = listed.difference(wgsl).collect();
            assert!(
                missing.is_empty() && stale.is_empty(),
                "{file}: WGSL functions without a twin in cpu::twins(): {missing:?}; listed \
                 twins of no WGSL function: {stale:?}"
            );
        }
        assert!(table.iter().all(|(f, _)| files.iter().any(|(g, _)| f == g)));
    }
}
