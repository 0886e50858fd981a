//! The renderer layout (one RGB(A) EXR per group of coefficients): lossless both ways, every
//! coefficient where docs/FORMAT.md puts it, bad input refused naming the file and part, with
//! nothing half-written, and the same malformed header refused in the same words by the
//! readers of both layouts (one decoder).
use std::path::{Path, PathBuf};

use exr::prelude::*;
use ptm_format::layout::{self, part_path, parts, Layout, PtmFile, Slot};
use ptm_format::ptm::{mip_sizes, Level};
use ptm_format::{Basis, FileFacts, Link, Ptm, SaveOptions, ToFileFacts, UvMap};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ptm-layout-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn plane(n: usize, j: usize, scale: f32) -> Vec<f32> {
    (0..n)
        .map(|t| (((t * 31 + j * 17) % 101) as f32 / 37.0 - 1.3 + 1e-7 * t as f32) * scale)
        .collect()
}

/// What a fit would record beside the coefficients: error maps and a warning with non-ASCII text.
struct Report {
    rank: usize,
    coverage: Vec<f32>,
    rms_map: Vec<f32>,
    max_map: Vec<f32>,
}

impl ToFileFacts for Report {
    fn file_facts(&self) -> FileFacts<'_> {
        FileFacts {
            lights: 40,
            lights_fit: 38,
            solver: "test solver",
            rank: self.rank,
            cond: 12.5,
            warnings: vec!["no light below 45° – grazing K is extrapolated".into()],
            rms_map: &self.rms_map,
            max_map: &self.max_map,
            ..FileFacts::default()
        }
    }
}

/// A PTM with every feature on: `mips` levels, holes (coverage), error maps, a warning with
/// non-ASCII text.
fn sample(basis: Basis, link: Link, uv: UvMap, mips: bool) -> (Ptm, Report) {
    let (w, h) = (13, 7);
    let n = w * h;
    let planes = (0..basis.len()).map(|j| plane(n, j, 1.0)).collect();
    let mips = if mips {
        mip_sizes(w, h)
            .into_iter()
            .enumerate()
            .map(|(k, (lw, lh))| Level {
                width: lw,
                height: lh,
                planes: (0..basis.len())
                    .map(|j| plane(lw * lh, j + k, 0.5))
                    .collect(),
            })
            .collect()
    } else {
        Vec::new()
    };
    let coverage: Vec<f32> = (0..n)
        .map(|t| {
            if t % 9 == 0 {
                0.0
            } else {
                1.0 - (t % 4) as f32 / 8.0
            }
        })
        .collect();
    let ptm = Ptm {
        basis,
        link,
        uv,
        width: w,
        height: h,
        tile: [1.5, 0.75],
        planes,
        mips,
        coverage: Some(coverage.clone()),
        learned: None,
    };
    let report = Report {
        rank: basis.len(),
        coverage,
        rms_map: (0..n).map(|t| t as f32 / 1000.0).collect(),
        max_map: (0..n).map(|t| t as f32 / 500.0).collect(),
    };
    (ptm, report)
}

fn opts(report: &Report, half: bool) -> SaveOptions<'_> {
    SaveOptions {
        half,
        report: Some(report),
        error_map: true,
    }
}

/// Reads one channel of a plain EXR with the `exr` crate alone (what any EXR reader sees).
fn raw_channel(path: &Path, name: &str) -> Vec<f32> {
    let img = read_all_flat_layers_from_file(path).unwrap();
    let layer = &img.layer_data[0];
    let ch = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == name)
        .unwrap_or_else(|| panic!("{} lacks {name}", path.display()));
    ch.sample_data.values_as_f32().collect()
}

#[test]
fn layout_table_matches_the_spec() {
    let names = |b| -> Vec<Vec<&str>> {
        parts(b)
            .iter()
            .map(|p| p.iter().map(|s| s.short()).collect())
            .collect()
    };
    assert_eq!(
        names(Basis::Ptm6),
        vec![vec!["u2", "u", "uv"], vec!["v", "v2", "1", "coverage"]]
    );
    assert_eq!(
        names(Basis::Ptm11),
        vec![
            vec!["u3", "v3", "u2v2", "u2v"],
            vec!["uv2", "u2", "v2", "uv"],
            vec!["u", "v", "1", "coverage"]
        ]
    );
    assert_eq!(
        part_path(Path::new("a/w.ptm.exr"), 2),
        PathBuf::from("a/w.ptm.c2.exr")
    );
    assert_eq!(
        part_path(Path::new("a/w.ptm.c0.exr"), 1),
        PathBuf::from("a/w.ptm.c1.exr")
    );
    assert_eq!(Layout::from_name("rgba"), Some(Layout::Rgba));
    assert_eq!(Layout::from_name("xyz"), None);
}

#[test]
fn conversion_is_lossless_both_ways() {
    let dir = tmpdir("rt");
    let cases = [
        (Basis::Ptm6, Link::Identity, UvMap::Projected, false, false),
        (
            Basis::Ptm6,
            Link::Logistic,
            UvMap::Hemispherical,
            true,
            true,
        ),
        (
            Basis::Ptm11,
            Link::Identity,
            UvMap::Hemispherical,
            true,
            false,
        ),
        (Basis::Ptm11, Link::Logistic, UvMap::Projected, false, true),
    ];
    for (i, &(basis, link, uv, mips, half)) in cases.iter().enumerate() {
        let (ptm, report) = sample(basis, link, uv, mips);
        let a = dir.join(format!("{i}.ptm.exr"));
        ptm.save(&a, &opts(&report, half)).unwrap();
        let (fa, la) = PtmFile::load(&a).unwrap();
        assert_eq!(la, Layout::Channels);
        assert!(fa.maps.contains_key("coverage"));
        assert!(fa.maps.values().all(|m| m.half == half));
        // channels → rgba: what fit --layout rgba writes equals the converted file.
        let b = dir.join(format!("{i}.rgba.ptm.exr"));
        let written = fa.save(&b, Layout::Rgba).unwrap();
        assert_eq!(written.len(), parts(basis).len() + 1, "parts + error maps");
        let (fb, lb) = PtmFile::load(&part_path(&b, 0)).unwrap();
        assert_eq!(lb, Layout::Rgba);
        assert_eq!(fb, fa, "case {i}: rgba holds every map, type and attribute");
        let direct = dir.join(format!("{i}.direct.ptm.exr"));
        layout::save(&ptm, &direct, &opts(&report, half), Layout::Rgba).unwrap();
        for k in 0..parts(basis).len() {
            assert_eq!(
                std::fs::read(part_path(&direct, k)).unwrap(),
                std::fs::read(part_path(&b, k)).unwrap(),
                "case {i}: layout::save = convert, byte for byte (deterministic)"
            );
        }
        // rgba → channels → the same maps and attributes; the Ptm itself is unchanged.
        let c = dir.join(format!("{i}.back.ptm.exr"));
        fb.save(&c, Layout::Channels).unwrap();
        let (fc, _) = PtmFile::load(&c).unwrap();
        assert_eq!(fc, fa, "case {i}: back to channels");
        let (back, info) = Ptm::load_with_info(&c).unwrap();
        let (orig, info0) = Ptm::load_with_info(&a).unwrap();
        assert_eq!(back, orig);
        assert_eq!(info, info0);
        assert_eq!(layout::load(&b).unwrap(), orig);
        if !half {
            assert_eq!(orig, ptm);
        }
        // Any EXR reader finds coefficient `uv` as a colour channel of the part the table names.
        let (k, slot) = parts(basis)
            .iter()
            .enumerate()
            .find_map(|(k, p)| {
                p.iter()
                    .position(|s| *s == Slot::Coeff("uv"))
                    .map(|s| (k, s))
            })
            .unwrap();
        let j = basis
            .monomials()
            .iter()
            .position(|m| m.name == "uv")
            .unwrap();
        assert_eq!(
            raw_channel(&part_path(&b, k), ["R", "G", "B", "A"][slot]),
            orig.planes[j]
        );
        assert_eq!(
            raw_channel(&part_path(&b, parts(basis).len() - 1), "A"),
            report.coverage
        );
    }
}

#[test]
fn parts_are_tiled_mipmapped_and_periodic() {
    let dir = tmpdir("meta");
    let (ptm, report) = sample(Basis::Ptm11, Link::Logistic, UvMap::Hemispherical, true);
    let p = dir.join("w.ptm.exr");
    layout::save(&ptm, &p, &opts(&report, false), Layout::Rgba).unwrap();
    for k in 0..3 {
        let meta = exr::meta::MetaData::read_from_file(part_path(&p, k), false).unwrap();
        let h = &meta.headers[0];
        assert!(
            matches!(h.blocks, exr::meta::BlockDescription::Tiles(t) if t.tile_size == Vec2(64, 64))
        );
        let other = &h.own_attributes.other;
        assert_eq!(
            h.own_attributes
                .wrap_mode_name
                .as_ref()
                .map(|t| t.to_string()),
            Some("periodic,periodic".into())
        );
        let text = |n: &str| match other.get(&Text::from(n)) {
            Some(exr::meta::attribute::AttributeValue::Text(t)) => t.to_string(),
            v => panic!("{n}: {v:?}"),
        };
        assert_eq!(text("ptm:layout"), "rgba/1");
        assert_eq!(text("ptm:link"), "logistic");
        assert_eq!(text("ptm:uv"), "hemispherical");
        let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["A", "B", "G", "R"]);
    }
    assert!(layout::err_path(&p).exists());
    // Written again without error maps, the stale error file goes.
    let no_err = SaveOptions {
        error_map: false,
        ..opts(&report, false)
    };
    layout::save(&ptm, &p, &no_err, Layout::Rgba).unwrap();
    assert!(!layout::err_path(&p).exists());
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

fn err_of(path: &Path) -> String {
    PtmFile::load(path).unwrap_err().to_string()
}

#[test]
fn bad_rgba_sets_are_refused_naming_file_and_part() {
    let dir = tmpdir("bad");
    let (ptm, report) = sample(Basis::Ptm11, Link::Identity, UvMap::Projected, false);
    let good = dir.join("g.ptm.exr");
    layout::save(&ptm, &good, &opts(&report, false), Layout::Rgba).unwrap();
    let copy = |name: &str| -> PathBuf {
        for k in 0..3 {
            std::fs::copy(part_path(&good, k), part_path(&dir.join(name), k)).unwrap();
        }
        dir.join(name)
    };

    // A missing part.
    let m = copy("missing.ptm.exr");
    std::fs::remove_file(part_path(&m, 1)).unwrap();
    let e = err_of(&part_path(&m, 0));
    assert!(
        e.contains("missing.ptm.c1.exr") && e.contains("missing part c1"),
        "{e}"
    );

    // A part lacking a channel: c2 written with R, G, B only.
    let c = copy("chan.ptm.exr");
    let (f, _) = PtmFile::load(&good).unwrap();
    // Rewrite part c2 by hand with three channels and the part's header.
    let img = read_all_flat_layers_from_file(part_path(&good, 2)).unwrap();
    let mut layer = img.layer_data[0].clone();
    layer
        .channel_data
        .list
        .retain(|ch| ch.name.to_string() != "A");
    Image::from_layer(layer)
        .write()
        .to_file(part_path(&c, 2))
        .unwrap();
    let e = err_of(&c);
    assert!(
        e.contains("chan.ptm.c2.exr") && e.contains("part c2 lacks channel A (coverage)"),
        "{e}"
    );

    // Parts of different sizes.
    let s = copy("size.ptm.exr");
    let (small, small_report) = {
        let (mut p, r) = sample(Basis::Ptm11, Link::Identity, UvMap::Projected, false);
        p.width = 7;
        p.height = 13;
        (p, r)
    };
    let other = dir.join("small.ptm.exr");
    layout::save(&small, &other, &opts(&small_report, false), Layout::Rgba).unwrap();
    std::fs::copy(part_path(&other, 1), part_path(&s, 1)).unwrap();
    let e = err_of(&s);
    assert!(
        e.contains("size.ptm.c1.exr") && e.contains("part c1 is 7×13 but part c0 is 13×7"),
        "{e}"
    );

    // Unknown link, (u, v) map and version: refused by name, in either layout, and never
    // written (the version as `Ptm::load` refuses it).
    for (key, value) in [
        ("ptm:link", "softmax"),
        ("ptm:uv", "octahedral"),
        ("ptm:version", "occlusion-ptm/9"),
    ] {
        let mut bad = f.clone();
        bad.attrs.insert(
            key.into(),
            exr::meta::attribute::AttributeValue::Text(Text::from(value)),
        );
        let name = value.replace('/', "-");
        let out = dir.join(format!("{name}.ptm.exr"));
        let e = bad.save(&out, Layout::Rgba).unwrap_err().to_string();
        assert!(e.contains(value) && e.contains(key), "{e}");
        assert!(!part_path(&out, 0).exists());
        let e = bad.save(&out, Layout::Channels).unwrap_err().to_string();
        assert!(e.contains(value), "{e}");
        assert!(!out.exists());
        // A set whose parts say so is refused on read, naming part c0.
        let u = copy(&format!("u-{name}.ptm.exr"));
        let img = read_all_flat_layers_from_file(part_path(&good, 0)).unwrap();
        let mut layer = img.layer_data[0].clone();
        layer.attributes.other.insert(
            Text::from(key),
            exr::meta::attribute::AttributeValue::Text(Text::from(value)),
        );
        Image::from_layer(layer)
            .write()
            .to_file(part_path(&u, 0))
            .unwrap();
        let e = err_of(&u);
        assert!(e.contains(&format!("u-{name}.ptm.c0.exr")), "{e}");
        assert!(e.contains(value), "{e}");
    }

    // A failing write leaves nothing behind: when part c1 cannot be written (a directory
    // stands where it goes), part c0 is not published either, and no temporary file is left.
    let blocked = dir.join("blocked.ptm.exr");
    std::fs::create_dir_all(part_path(&blocked, 1)).unwrap();
    let e = f.save(&blocked, Layout::Rgba);
    assert!(e.is_err());
    assert!(
        !part_path(&blocked, 0).exists(),
        "c0 must not be published when c1 failed"
    );
    let tmps: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp"))
        .collect();
    assert!(tmps.is_empty(), "temporary files left: {tmps:?}");
}

/// A copy of the EXR `from` at `to` with header attribute `key` set to `value`, written with the
/// exr crate alone (our writers refuse such headers).
fn with_attr(from: &Path, to: &Path, key: &str, value: &exr::meta::attribute::AttributeValue) {
    let img = read_all_flat_layers_from_file(from).unwrap();
    let mut layer = img.layer_data[0].clone();
    layer
        .attributes
        .other
        .insert(Text::from(key), value.clone());
    Image::from_layer(layer).write().to_file(to).unwrap();
}

/// The readers of both layouts are one decoder: fed the same malformed header, `Ptm::load` and
/// `PtmFile::load` of the channel layout, and `PtmFile::load` and `layout::load` of the renderer
/// layout, refuse it in the same words, each naming its file and the attribute. (Before, a
/// `ptm:link` that is not text read as "identity" in the renderer layout and was refused in the
/// channel layout.)
#[test]
fn both_layouts_refuse_the_same_malformed_headers_alike() {
    use exr::meta::attribute::AttributeValue as V;
    use ptm_format::Error;
    let dir = tmpdir("malformed");
    let (ptm, report) = sample(Basis::Ptm11, Link::Logistic, UvMap::Hemispherical, false);
    let opts = SaveOptions {
        error_map: false,
        ..opts(&report, false)
    };
    let channels = dir.join("good.ptm.exr");
    ptm.save(&channels, &opts).unwrap();
    let rgba = dir.join("good-rgba.ptm.exr");
    layout::save(&ptm, &rgba, &opts, Layout::Rgba).unwrap();
    let n_parts = parts(Basis::Ptm11).len();
    let texts = |v: &[&str]| V::TextVector(v.iter().map(|s| Text::from(*s)).collect());
    let cases: [(&str, &str, V, &str); 5] = [
        (
            "link",
            "ptm:link",
            V::I32(1),
            "`ptm:link` is not text (it is an EXR `int` attribute)",
        ),
        (
            "uv",
            "ptm:uv",
            V::Text(Text::from("octahedral")),
            "unknown (u, v) map \"octahedral\" in `ptm:uv` (this version reads projected, hemispherical)",
        ),
        (
            "monomials",
            "ptm:monomials",
            texts(&["u", "v"]),
            "monomial list [\"u\", \"v\"] in `ptm:monomials` does not match basis ptm11",
        ),
        (
            "version",
            "ptm:version",
            V::Text(Text::from("occlusion-ptm/9")),
            "PTM version \"occlusion-ptm/9\" in `ptm:version` is not supported (this version reads \"occlusion-ptm/1\" and \"occlusion-ptm/2\")",
        ),
        (
            "tile",
            "ptm:tileW",
            V::F64(-1.5),
            "`ptm:tileW` is -1.5: a tile side is a positive finite size",
        ),
    ];
    for (name, key, value, want) in cases {
        let single = dir.join(format!("{name}.ptm.exr"));
        with_attr(&channels, &single, key, &value);
        let set = dir.join(format!("{name}-rgba.ptm.exr"));
        for k in 0..n_parts {
            with_attr(&part_path(&rgba, k), &part_path(&set, k), key, &value);
        }
        let c0 = part_path(&set, 0);
        let refusals = [
            ("Ptm::load", &single, Ptm::load(&single).map(|_| ())),
            ("PtmFile::load", &single, PtmFile::load(&single).map(|_| ())),
            ("PtmFile::load rgba", &c0, PtmFile::load(&c0).map(|_| ())),
            ("layout::load rgba", &c0, layout::load(&set).map(|_| ())),
        ];
        for (reader, file, r) in refusals {
            match r {
                Err(Error::Format { path, reason }) => {
                    assert_eq!(
                        Path::new(&path),
                        file.as_path(),
                        "{name}: {reader} names its file"
                    );
                    assert!(reason.starts_with(want), "{name}: {reader}: {reason}");
                    assert!(reason.contains(key), "{name}: {reader}: {reason}");
                }
                other => panic!("{name}: {reader}: {other:?}"),
            }
        }
    }
    // The malformed files differ from the good ones in that attribute only: unchanged, each
    // reads (so the refusals above are the attribute's).
    for k in 0..n_parts {
        with_attr(
            &part_path(&rgba, k),
            &part_path(&dir.join("same-rgba.ptm.exr"), k),
            "ptm:uv",
            &V::Text(Text::from("hemispherical")),
        );
    }
    with_attr(
        &channels,
        &dir.join("same.ptm.exr"),
        "ptm:uv",
        &V::Text(Text::from("hemispherical")),
    );
    assert_eq!(Ptm::load(&dir.join("same.ptm.exr")).unwrap(), ptm);
    assert_eq!(layout::load(&dir.join("same-rgba.ptm.exr")).unwrap(), ptm);
}
