//! PTM EXR round trips (exact for f32, within the stated bound for half) and load errors.
use std::path::PathBuf;

use ptm_fit::solve::{fit_stack, FitOptions};
use ptm_fit::SampleStack;
use ptm_format::{Basis, LightSet, Ptm, SaveOptions};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ptm-fit-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn sample_ptm(basis: Basis) -> Ptm {
    let (w, h) = (13, 7);
    let planes = (0..basis.len())
        .map(|j| {
            (0..w * h)
                .map(|t| ((t * 31 + j * 17) % 101) as f32 / 37.0 - 1.3 + 1e-7 * t as f32)
                .collect()
        })
        .collect();
    Ptm {
        basis,
        width: w,
        height: h,
        link: ptm_format::Link::Identity,
        uv: ptm_format::UvMap::Projected,
        mips: Vec::new(),
        coverage: None,
        tile: [1.5, 0.75],
        planes,
        learned: None,
    }
}

#[test]
fn f32_round_trip_is_exact_and_half_within_bound() {
    let dir = tmpdir("rt");
    for basis in Basis::ALL {
        let ptm = sample_ptm(basis);
        let p = dir.join(format!("{}.ptm.exr", basis.name()));
        ptm.save(&p, &SaveOptions::default()).unwrap();
        assert_eq!(Ptm::load(&p).unwrap(), ptm);
        let half = SaveOptions {
            half: true,
            ..SaveOptions::default()
        };
        ptm.save(&p, &half).unwrap();
        let (back, info) = Ptm::load_with_info(&p).unwrap();
        assert_eq!(info.storage, "half");
        let bound = ptm.half_error_bound();
        assert!(bound > 0.0 && bound < 5e-3, "bound {bound}");
        let mut worst = 0f64;
        for y in 0..ptm.height {
            for x in 0..ptm.width {
                for (u, v) in [(0.0, 0.0), (0.7, -0.7), (-1.0, 0.0), (0.3, 0.9)] {
                    let d = (ptm.eval_unclamped(x, y, u, v) - back.eval_unclamped(x, y, u, v)).abs()
                        as f64;
                    worst = worst.max(d);
                }
            }
        }
        assert!(
            worst <= bound * 1.0001 + 1e-7,
            "half error {worst} > bound {bound}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn channels_are_named_by_monomial_and_header_is_complete() {
    let dir = tmpdir("hdr");
    let lights = LightSet::from_dirs((0..20).map(|i| {
        let a = i as f64 * 2.4;
        let z = 0.1 + 0.9 * i as f64 / 20.0;
        let r = (1.0 - z * z).sqrt();
        [r * a.cos(), r * a.sin(), z]
    }));
    let k = (0..20)
        .map(|l| (0..12).map(|t| ((l * 5 + t) % 7) as f32 / 7.0).collect())
        .collect();
    let stack = SampleStack::new(lights.clone(), 4, 3, [1.0, 2.0], k);
    let (ptm, report) = fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap();
    let p = dir.join("w.ptm.exr");
    let opts = SaveOptions {
        half: false,
        report: Some(&report),
        error_map: true,
    };
    ptm.save(&p, &opts).unwrap();
    // Read with the exr crate directly, as a pipeline without our code would.
    let img = exr::prelude::read_all_flat_layers_from_file(&p).unwrap();
    let layer = &img.layer_data[0];
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for want in [
        "ptm.u2", "ptm.u", "ptm.uv", "ptm.v", "ptm.v2", "ptm.1", "err.rms", "err.max",
    ] {
        assert!(
            names.iter().any(|n| n == want),
            "{want} missing from {names:?}"
        );
    }
    let attrs: Vec<String> = layer
        .attributes
        .other
        .keys()
        .map(|k| k.to_string())
        .collect();
    for want in [
        "ptm:version",
        "ptm:basis",
        "ptm:monomials",
        "ptm:value",
        "ptm:uv",
        "ptm:frame",
        "ptm:tileW",
        "ptm:nLights",
        "ptm:solver",
        "ptm:rank",
        "ptm:cond",
        "ptm:rmsMean",
    ] {
        assert!(
            attrs.iter().any(|n| n == want),
            "{want} missing from {attrs:?}"
        );
    }
    let (back, info) = Ptm::load_with_info(&p).unwrap();
    assert_eq!(back, ptm);
    assert_eq!(info.lights, Some(20));
    assert_eq!(info.rank, Some(6));
    assert_eq!(info.err_rms.unwrap(), report.rms_map);
    assert!(
        !names.iter().any(|n| n == "coverage") && info.coverage.is_none(),
        "fully covered: no coverage channel"
    );

    // A hole (coverage 0) and a partly covered texel: both fitting paths record the coverage,
    // and the file carries it, so a pipeline can tell a hole from lit cloth.
    let mut holed = stack.clone();
    holed.coverage[5] = 0.0;
    holed.coverage[7] = 0.25;
    let (ptm, report) = fit_stack(&holed, &FitOptions::new(Basis::Ptm6)).unwrap();
    assert_eq!(report.coverage, holed.coverage);
    assert_eq!(ptm.coverage.as_ref(), Some(&holed.coverage), "stored stack");
    let mut acc = ptm_fit::Accumulator::new(&lights, 4, 3, &FitOptions::new(Basis::Ptm6)).unwrap();
    acc.set_coverage(&holed.coverage).unwrap();
    for (i, plane) in holed.k.iter().enumerate() {
        acc.add_light(i, plane).unwrap();
    }
    let (streamed_ptm, streamed) = acc.finish([1.0, 2.0]).unwrap();
    assert_eq!(streamed.coverage, holed.coverage);
    assert_eq!(
        streamed_ptm.coverage.as_ref(),
        Some(&holed.coverage),
        "identity stream"
    );
    // The logistic link, stored and streamed, with MIP levels.
    let mut logistic = FitOptions::new(Basis::Ptm6);
    logistic.link = ptm_format::Link::Logistic;
    logistic.mips = true;
    let mut binary = holed.clone();
    for k in &mut binary.k {
        for x in k.iter_mut() {
            *x = if *x > 0.5 { 1.0 } else { 0.0 };
        }
    }
    let (lptm, _) = fit_stack(&binary, &logistic).unwrap();
    assert_eq!(
        lptm.coverage.as_ref(),
        Some(&holed.coverage),
        "logistic stack"
    );
    let mut lacc = ptm_fit::Accumulator::new(&lights, 4, 3, &logistic).unwrap();
    lacc.set_coverage(&holed.coverage).unwrap();
    lacc.set_spp(4).unwrap();
    for (i, plane) in binary.k.iter().enumerate() {
        lacc.add_light(i, plane).unwrap();
    }
    let (lstreamed, _) = lacc.finish([1.0, 2.0]).unwrap();
    assert_eq!(
        lstreamed.coverage.as_ref(),
        Some(&holed.coverage),
        "logistic stream"
    );
    // A fully covered fit carries none.
    let (full, _) = fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap();
    assert_eq!(full.coverage, None);
    let opts = SaveOptions {
        half: true,
        report: Some(&report),
        error_map: false,
    };
    ptm.save(&p, &opts).unwrap();
    let (back, info) = Ptm::load_with_info(&p).unwrap();
    assert_eq!(
        info.coverage.unwrap(),
        holed.coverage,
        "0, 0.25 and 1 are exact in half"
    );
    assert_eq!(back.coverage.as_ref(), Some(&holed.coverage));
    // load → save → load keeps it (the file's own facts are not needed for that), and the
    // logistic PTM's MIP-mapped file too.
    let p2 = dir.join("again.ptm.exr");
    back.save(&p2, &SaveOptions::default()).unwrap();
    assert_eq!(Ptm::load(&p2).unwrap().coverage, back.coverage);
    lptm.save(&p2, &SaveOptions::default()).unwrap();
    let lback = Ptm::load(&p2).unwrap();
    assert!(!lback.mips.is_empty());
    assert_eq!(lback, lptm);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn foreign_truncated_and_unknown_files_are_named_errors() {
    let dir = tmpdir("bad");
    let ptm = sample_ptm(Basis::Ptm6);
    let good = dir.join("good.ptm.exr");
    ptm.save(&good, &SaveOptions::default()).unwrap();
    let bytes = std::fs::read(&good).unwrap();

    let p = dir.join("trunc.ptm.exr");
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(e.contains("trunc.ptm.exr") && e.contains("OpenEXR"), "{e}");

    let p = dir.join("missing.exr");
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(e.contains("missing.exr"), "{e}");

    // A sample stack is not a PTM, and says so.
    let lights = LightSet::from_dirs([[0.0, 0.0, 1.0]]);
    let stack = SampleStack::new(lights, 2, 2, [1.0, 1.0], vec![vec![0.0; 4]]);
    let p = dir.join("samples.exr");
    stack.write(&p).unwrap();
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("not an occlusion PTM") && e.contains("sample stack"),
        "{e}"
    );

    // A foreign EXR (plain RGBA).
    let p = dir.join("rgba.exr");
    exr::prelude::write_rgba_file(&p, 4, 4, |_, _| (0.5f32, 0.5f32, 0.5f32, 1.0f32)).unwrap();
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(e.contains("not an occlusion PTM"), "{e}");

    // Unknown basis and a missing channel: edit the header / channels with the exr crate.
    use exr::meta::attribute::AttributeValue;
    use exr::prelude::*;
    let img = read_all_flat_layers_from_file(&good).unwrap();
    let mut unknown = img.clone();
    unknown.layer_data[0].attributes.other.insert(
        Text::from("ptm:basis"),
        AttributeValue::Text(Text::from("hsh9")),
    );
    let p = dir.join("unknown.ptm.exr");
    unknown.write().to_file(&p).unwrap();
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(e.contains("unknown basis") && e.contains("hsh9"), "{e}");

    let mut lacking = img;
    lacking.layer_data[0]
        .channel_data
        .list
        .retain(|c| c.name.to_string() != "ptm.uv");
    let p = dir.join("lacking.ptm.exr");
    lacking.write().to_file(&p).unwrap();
    let e = Ptm::load(&p).unwrap_err().to_string();
    assert!(e.contains("ptm.uv"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A logistic, hemispherical PTM with a MIP chain round-trips exactly through the tiled,
/// MIP-mapped file, which announces itself as version 2 with its link and map.
#[test]
fn logistic_hemispherical_mip_chain_round_trips() {
    let dir = tmpdir("mip");
    for basis in Basis::ALL {
        let mut ptm = sample_ptm(basis);
        ptm.link = ptm_format::Link::Logistic;
        ptm.uv = ptm_format::UvMap::Hemispherical;
        ptm.mips = ptm_format::ptm::mip_sizes(ptm.width, ptm.height)
            .into_iter()
            .enumerate()
            .map(|(l, (width, height))| ptm_format::Level {
                width,
                height,
                planes: (0..basis.len())
                    .map(|j| {
                        (0..width * height)
                            .map(|t| (t + j + l) as f32 * 0.01)
                            .collect()
                    })
                    .collect(),
            })
            .collect();
        assert_eq!(ptm.mips.len(), 3); // 13×7 → 6×3 → 3×1 → 1×1
        let p = dir.join(format!("{}.ptm.exr", basis.name()));
        ptm.save(&p, &SaveOptions::default()).unwrap();
        let back = Ptm::load(&p).unwrap();
        assert_eq!(back, ptm);
        assert_eq!(back.version(), ptm_format::ptm::PTM_VERSION_2);
        // σ of the polynomial at the hemispherical coordinates.
        let c = ptm.coeffs(3, 2);
        let (pu, pv) = (0.4f32, -0.3f32);
        let (u, v) = ptm_format::UvMap::Hemispherical.of_projected(pu, pv);
        let want = ptm_format::basis::sigmoid(basis.eval(&c, u, v));
        assert!((back.eval(3, 2, pu, pv) - want).abs() < 1e-6);
    }
}

/// A file whose `ptm:link` or `ptm:uv` this version does not know is refused, naming the value
/// (never evaluated as a plain polynomial).
#[test]
fn unknown_link_or_uv_map_is_an_error_naming_it() {
    let dir = tmpdir("unknown");
    let mut ptm = sample_ptm(Basis::Ptm6);
    ptm.link = ptm_format::Link::Logistic;
    ptm.uv = ptm_format::UvMap::Hemispherical;
    let p = dir.join("u.ptm.exr");
    ptm.save(&p, &SaveOptions::default()).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let patch = |from: &[u8], to: &[u8]| {
        let mut b = bytes.clone();
        let i = b.windows(from.len()).position(|w| w == from).unwrap();
        b[i..i + to.len()].copy_from_slice(to);
        let q = dir.join("patched.ptm.exr");
        std::fs::write(&q, b).unwrap();
        Ptm::load(&q).unwrap_err().to_string()
    };
    let e = patch(b"logistic", b"sigmoidz");
    assert!(e.contains("sigmoidz") && e.contains("ptm:link"), "{e}");
    let e = patch(b"hemispherical", b"hemispherixal");
    assert!(e.contains("hemispherixal") && e.contains("ptm:uv"), "{e}");
}
