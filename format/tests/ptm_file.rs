//! The PTM file layer on its own: coverage travels with the `Ptm` through save and load (float
//! and half, with and without MIP levels), bad coverage is refused, header text is UTF-8 and
//! old Latin-1 headers still read, MIP sizes are OpenEXR's, the storage reported is the
//! channel type on disk.
use ptm_format::exrio::{self, Attr};
use ptm_format::ptm::mip_sizes;
use ptm_format::{Basis, FileFacts, Level, Link, Ptm, SaveOptions, UvMap};

fn ptm(w: usize, h: usize, mips: bool) -> Ptm {
    let basis = Basis::Ptm6;
    let plane = |j: usize, n: usize| -> Vec<f32> {
        (0..n)
            .map(|t| ((t * 7 + j * 3) % 11) as f32 / 8.0 - 0.5)
            .collect()
    };
    let planes = (0..basis.len()).map(|j| plane(j, w * h)).collect();
    let mut p = Ptm::new(basis, w, h, [1.0, 1.0], planes);
    if mips {
        p.link = Link::Logistic;
        p.uv = UvMap::Hemispherical;
        p.mips = mip_sizes(w, h)
            .into_iter()
            .map(|(lw, lh)| Level {
                width: lw,
                height: lh,
                planes: (0..basis.len()).map(|j| plane(j, lw * lh)).collect(),
            })
            .collect();
    }
    // A hole, a quarter-covered texel, the rest covered: all exact in half.
    let mut cov = vec![1.0f32; w * h];
    cov[1] = 0.0;
    cov[w + 2] = 0.25;
    p.coverage = Some(cov);
    p
}

#[test]
fn coverage_survives_save_load_save_load() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a.ptm.exr"), d.path().join("b.ptm.exr"));
    for mips in [false, true] {
        for half in [false, true] {
            let want = ptm(9, 6, mips);
            let opts = SaveOptions {
                half,
                ..SaveOptions::default()
            };
            want.save(&a, &opts).unwrap();
            let (once, info) = Ptm::load_with_info(&a).unwrap();
            assert_eq!(once.coverage, want.coverage, "mips {mips}, half {half}");
            assert_eq!(info.coverage, want.coverage);
            assert_eq!(once.mips.len(), want.mips.len());
            once.save(&b, &opts).unwrap();
            let twice = Ptm::load(&b).unwrap();
            assert_eq!(twice.coverage, want.coverage, "mips {mips}, half {half}");
            if !half {
                assert_eq!(twice, want);
            }
            // With levels, coverage has its box-averaged levels like every channel.
            let c = exrio::read(&b).unwrap();
            assert_eq!(
                c.levels.get("coverage").map_or(0, Vec::len),
                want.mips.len()
            );
        }
    }
    // No coverage: no channel, and None back.
    let mut full = ptm(9, 6, false);
    full.coverage = None;
    full.save(&a, &SaveOptions::default()).unwrap();
    assert!(!exrio::read(&a).unwrap().channels.contains_key("coverage"));
    assert_eq!(Ptm::load(&a).unwrap().coverage, None);
}

#[test]
fn bad_coverage_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("bad.ptm.exr");
    for (cov, what) in [
        (vec![1.0f32; 5], "5 texels"),
        (
            {
                let mut v = vec![1.0f32; 54];
                v[3] = f32::NAN;
                v
            },
            "NaN",
        ),
        (
            {
                let mut v = vec![1.0f32; 54];
                v[4] = 1.5;
                v
            },
            "1.5",
        ),
        (
            {
                let mut v = vec![1.0f32; 54];
                v[4] = -0.25;
                v
            },
            "-0.25",
        ),
    ] {
        let mut bad = ptm(9, 6, false);
        bad.coverage = Some(cov);
        let e = bad.save(&p, &SaveOptions::default()).unwrap_err();
        assert!(e.to_string().contains(what), "{what}: {e}");
        assert!(!p.exists(), "nothing written");
    }
    // A file whose coverage channel is out of range is refused on load.
    let good = ptm(9, 6, false);
    good.save(&p, &SaveOptions::default()).unwrap();
    let mut c = exrio::read(&p).unwrap();
    let mut channels: Vec<(String, exrio::Samples)> = c.channels.drain().collect();
    for (name, s) in &mut channels {
        if name == "coverage" {
            *s = exrio::Samples::F32(vec![2.0; 54]);
        }
    }
    let attrs: Vec<(String, Attr)> = c.attrs.drain().collect();
    let attrs = attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
    exrio::write(&p, 9, 6, channels, attrs).unwrap();
    let e = Ptm::load(&p).unwrap_err();
    assert!(e.to_string().contains("coverage"), "{e}");

    // A resampled file (`oiiotool --resize`) rings a little past [0, 1] at a hole's edge: it
    // reads, clamped. The writer stays strict (above).
    let mut c = exrio::read(&p).unwrap();
    let mut channels: Vec<(String, exrio::Samples)> = c.channels.drain().collect();
    let ringing: Vec<f32> = (0..54).map(|i| [1.0014, -0.03, 0.5, 1.2][i % 4]).collect();
    for (name, s) in &mut channels {
        if name == "coverage" {
            *s = exrio::Samples::F32(ringing.clone());
        }
    }
    let attrs: Vec<(String, Attr)> = c.attrs.drain().collect();
    let attrs = attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
    exrio::write(&p, 9, 6, channels, attrs).unwrap();
    let back = Ptm::load(&p).unwrap();
    let want: Vec<f32> = ringing.iter().map(|c| c.clamp(0.0, 1.0)).collect();
    assert_eq!(back.coverage, Some(want));
}

#[test]
fn header_text_is_utf8_and_old_latin1_reads() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("w.ptm.exr");
    let warnings = vec![
        "horizon below 20° on 3 texels".to_string(),
        "residual 1.5e-2 K² – above the target".to_string(),
    ];
    let facts = FileFacts {
        lights: 12,
        lights_fit: 12,
        solver: "svd-pinv f64 – rcond 1e-6",
        rank: 6,
        cond: 3.5,
        warnings: warnings.clone(),
        ..FileFacts::default()
    };
    let opts = SaveOptions {
        report: Some(&facts),
        ..SaveOptions::default()
    };
    ptm(9, 6, false).save(&p, &opts).unwrap();
    let c = exrio::read(&p).unwrap();
    assert_eq!(
        c.attrs.get("ptm:warnings"),
        Some(&Attr::Texts(warnings.clone()))
    );
    assert_eq!(
        c.attrs.get("ptm:solver"),
        Some(&Attr::Text("svd-pinv f64 – rcond 1e-6".into()))
    );
    let (_, info) = Ptm::load_with_info(&p).unwrap();
    assert_eq!(info.solver.as_deref(), Some("svd-pinv f64 – rcond 1e-6"));
    // The raw attribute bytes are UTF-8 (° = C2 B0, ² = C2 B2, – = E2 80 93), no Latin-1 byte.
    let raw = std::fs::read(&p).unwrap();
    let find = |needle: &[u8]| raw.windows(needle.len()).position(|w| w == needle);
    for s in &warnings {
        let at = find(s.as_bytes()).unwrap_or_else(|| panic!("{s:?} not stored as UTF-8"));
        assert!(std::str::from_utf8(&raw[at..at + s.len()]).is_ok());
    }
    assert!(find(b"20\xb0 ").is_none(), "no Latin-1 degree sign");
    assert!(find("\u{2013}".as_bytes()).is_some());

    // An old file wrote ° as the Latin-1 byte 0xB0: it still reads, as °.
    let at = find("20°".as_bytes()).unwrap();
    let mut old = raw.clone();
    // Same length: "20\xC2\xB0" becomes "20\xB0\xB0" (Latin-1 "20°°").
    old[at + 2] = 0xB0;
    let q = d.path().join("old.ptm.exr");
    std::fs::write(&q, &old).unwrap();
    let c = exrio::read(&q).unwrap();
    match c.attrs.get("ptm:warnings") {
        Some(Attr::Texts(v)) => assert!(v[0].starts_with("horizon below 20°°"), "{v:?}"),
        other => panic!("{other:?}"),
    }
    assert!(Ptm::load(&q).is_ok());
}

#[test]
fn mip_sizes_are_openexr_round_down_levels() {
    for (w, h) in [(13, 7), (64, 64), (4, 16), (1, 5), (1, 1), (255, 2)] {
        let want: Vec<(usize, usize)> =
            exr::meta::mip_map_levels(exr::math::RoundingMode::Down, exr::math::Vec2(w, h))
                .skip(1)
                .map(|(_, s)| (s.0, s.1))
                .collect();
        assert_eq!(mip_sizes(w, h), want, "{w}×{h}");
    }
}

/// The file layer's refusals are typed and name no command-line flag: an HP export of another
/// basis than ptm6, a coefficient a half float cannot hold (nothing is written).
#[test]
fn hp_of_another_basis_and_half_overflow_are_typed() {
    let d = tempfile::tempdir().unwrap();
    let mut p = ptm(4, 3, false);
    p.basis = Basis::Ptm11;
    p.planes.resize(Basis::Ptm11.len(), vec![0.0; 12]);
    let path = d.path().join("w.ptm");
    match ptm_format::hp::encode_hp_lrgb(&p, &path, None) {
        Err(e @ ptm_format::Error::HpNeedsPtm6 { .. }) => {
            assert!(
                matches!(&e, ptm_format::Error::HpNeedsPtm6 { basis: Basis::Ptm11, path }
                if path.ends_with("w.ptm"))
            );
            assert!(!e.to_string().contains("--"), "{e}");
        }
        r => panic!("{:?}", r.map(|_| ())),
    }
    let mut p = ptm(4, 3, false);
    p.planes[2][5] = 7.0e4;
    let out = d.path().join("big.ptm.exr");
    let half = SaveOptions {
        half: true,
        ..SaveOptions::default()
    };
    match p.save(&out, &half) {
        Err(e @ ptm_format::Error::HalfOverflow { magnitude, .. }) => {
            assert_eq!(magnitude, 7.0e4);
            assert!(!e.to_string().contains("--"), "{e}");
        }
        r => panic!("{r:?}"),
    }
    assert!(!out.exists());
    p.save(&out, &SaveOptions::default()).unwrap();
}

/// A file another tool rewrote (`oiiotool -d half`) keeps our `ptm:storage` attribute but not
/// its truth: the channels' type on disk is what the reader reports.
#[test]
fn storage_is_the_channel_type_on_disk() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("w.ptm.exr");
    let orig = ptm(9, 6, false);
    orig.save(&p, &SaveOptions::default()).unwrap();
    let c = exrio::read(&p).unwrap();
    assert_eq!(
        c.attrs.get("ptm:storage"),
        Some(&Attr::Text("float32".into()))
    );
    assert_eq!(Ptm::load_with_info(&p).unwrap().1.storage, "float32");
    // Rewrite: every channel (or only the first) as half, the attributes as they were.
    for (all, want) in [(true, "half"), (false, "mixed")] {
        let mut channels: Vec<(String, exrio::Samples)> = c
            .channels
            .iter()
            .map(|(name, s)| {
                let v = match s {
                    exrio::Samples::F32(v) => v.clone(),
                    exrio::Samples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
                };
                let to_half = all || name == "ptm.u2";
                let s = if to_half {
                    exrio::Samples::F16(v.iter().map(|&x| half::f16::from_f32(x)).collect())
                } else {
                    exrio::Samples::F32(v)
                };
                (name.clone(), s)
            })
            .collect();
        channels.sort_by(|a, b| a.0.cmp(&b.0));
        let attrs = c
            .attrs
            .iter()
            .map(|(k, v)| (k.as_str(), v.clone()))
            .collect();
        let q = d.path().join(format!("{want}.ptm.exr"));
        exrio::write(&q, c.width, c.height, channels, attrs).unwrap();
        let (back, info) = Ptm::load_with_info(&q).unwrap();
        assert_eq!(info.storage, want);
        // Our test planes are multiples of 1/8 in [-0.5, 0.75]: exact in half.
        assert_eq!(back.planes, orig.planes);
    }
}

/// A coefficient that is not a number, or a tile that is not a size, is refused on save (and so
/// on load: the reader validates the same way), naming the value and where it is.
#[test]
fn non_finite_coefficients_and_tiles_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("w.ptm.exr");
    let mut bad = ptm(9, 6, false);
    bad.planes[2][9 + 4] = f32::NAN;
    let e = bad
        .save(&p, &SaveOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("coefficient uv is NaN at texel (column 4, row 1)"),
        "{e}"
    );
    let mut bad = ptm(9, 6, true);
    bad.mips[1].planes[0][0] = f32::INFINITY;
    let e = bad
        .save(&p, &SaveOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("inf") && e.contains("MIP level 2"), "{e}");
    for tile in [
        [f64::INFINITY, 1.0],
        [1.0, 0.0],
        [-1.0, 1.0],
        [f64::NAN, 1.0],
    ] {
        let mut bad = ptm(9, 6, false);
        bad.tile = tile;
        let e = bad
            .save(&p, &SaveOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("tile"), "{tile:?}: {e}");
    }
    assert!(!p.exists(), "nothing written");
}
