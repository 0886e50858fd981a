//! A learned basis in the PTM file: both layouts round-trip it losslessly (tables, planes, MIP
//! levels, coverage), `Ptm::eval` and `eval_dir` read the table bilinearly and apply σ, and a
//! file whose table has the wrong size, a non-finite entry, or a term count that does not match
//! its coefficient planes is refused naming the file and the figures. In the renderer layout the
//! table is also images (the basis parts), which a texture system's bilinear lookup reads as
//! `LearnedTable::terms` reads the table, and which are refused as the header is.
use ptm_format::basis::sigmoid64;
use ptm_format::exrio::{self, Attr};
use ptm_format::learned::{GRID_ATTR, TABLE_ATTR};
use ptm_format::ptm::mip_sizes;
use ptm_format::{
    layout, Basis, Layout, LearnedTable, Level, Link, Ptm, PtmFile, SaveOptions, UvMap,
};
use std::collections::HashMap;
use std::path::Path;

fn learned_ptm(k: usize, w: usize, h: usize, mips: bool) -> Ptm {
    let basis = Basis::learned(k).unwrap();
    let plane = |j: usize, n: usize| -> Vec<f32> {
        (0..n)
            .map(|t| ((t * 7 + j * 5) % 13) as f32 / 4.0 - 1.5)
            .collect()
    };
    let g = 5;
    let table = LearnedTable {
        grid: g,
        terms: k,
        values: (0..k * g * g)
            .map(|i| ((i as f32) * 0.37).sin() * 1.7 + 1e-3 * i as f32)
            .collect(),
    };
    let mut p = Ptm::new(
        basis,
        w,
        h,
        [1.0, 2.0],
        (0..k).map(|j| plane(j, w * h)).collect(),
    );
    p.link = Link::Logistic;
    p.uv = UvMap::Hemispherical;
    p.learned = Some(table);
    if mips {
        p.mips = mip_sizes(w, h)
            .into_iter()
            .map(|(lw, lh)| Level {
                width: lw,
                height: lh,
                planes: (0..k).map(|j| plane(j + 1, lw * lh)).collect(),
            })
            .collect();
    }
    let mut cov = vec![1.0f32; w * h];
    cov[2] = 0.0;
    cov[w + 1] = 0.5;
    p.coverage = Some(cov);
    p
}

#[test]
fn both_layouts_round_trip_a_learned_basis_losslessly() {
    let d = tempfile::tempdir().unwrap();
    for (k, mips) in [(6, true), (11, false), (4, true), (1, false), (16, false)] {
        let p = learned_ptm(k, 9, 6, mips);
        let path = d.path().join(format!("l{k}.ptm.exr"));
        p.save(&path, &SaveOptions::default()).unwrap();
        let back = Ptm::load(&path).unwrap();
        assert_eq!(back, p, "channels, {k} terms");
        let rgba = d.path().join(format!("r{k}.ptm.exr"));
        let files =
            ptm_format::layout::save(&p, &rgba, &SaveOptions::default(), Layout::Rgba).unwrap();
        // ⌈(k + 1)/4⌉ coefficient parts and ⌈k/4⌉ basis parts.
        assert_eq!(
            files.len(),
            (k + 1).div_ceil(4) + k.div_ceil(4),
            "{k} terms"
        );
        assert_eq!(files, layout::rgba_paths(&rgba, p.basis), "{k} terms");
        let back = ptm_format::layout::load(&rgba).unwrap();
        assert_eq!(back, p, "rgba, {k} terms");
        // And back to channels through the layout-free file: the same bytes as a direct save.
        let (file, layout) = PtmFile::load(&rgba).unwrap();
        assert_eq!(layout, Layout::Rgba);
        let again = d.path().join(format!("c{k}.ptm.exr"));
        file.save(&again, Layout::Channels).unwrap();
        assert_eq!(Ptm::load(&again).unwrap(), p);
        assert_eq!(
            std::fs::read(&again).unwrap(),
            std::fs::read(&path).unwrap()
        );
        // Channels → rgba again (a conversion, from the file read back): every part, the
        // basis parts among them, byte for byte what the direct save wrote.
        let (from_channels, _) = PtmFile::load(&again).unwrap();
        let conv = d.path().join(format!("v{k}.ptm.exr"));
        let written = from_channels.save(&conv, Layout::Rgba).unwrap();
        assert_eq!(written.len(), files.len());
        for (a, b) in files.iter().zip(&written) {
            assert_eq!(
                std::fs::read(a).unwrap(),
                std::fs::read(b).unwrap(),
                "{k} terms: {} and {}",
                a.display(),
                b.display()
            );
        }
        // Opened by any file of the set, a basis part included.
        let via_basis = layout::basis_part_path(&rgba, 0);
        assert_eq!(ptm_format::layout::load(&via_basis).unwrap(), p);
    }
}

/// Reads every channel of one plain EXR with the `exr` crate alone (what any EXR reader sees):
/// (width, height, channels by name).
fn raw(path: &Path) -> (usize, usize, HashMap<String, Vec<f32>>) {
    let img = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = &img.layer_data[0];
    let chans = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    (layer.size.0, layer.size.1, chans)
}

/// What a texture system does with a basis part: a bilinear lookup at (s, t) (t = 0 the first
/// scanline, OSL / OIIO `texture()`), texel centres at (i + ½)/G, clamp wrapping (a texel index
/// outside the image reads the edge texel). Independent of the crate's `bilinear`.
fn texture_lookup(img: &[f32], g: usize, s: f64, t: f64) -> f64 {
    let (x, y) = (s * g as f64 - 0.5, t * g as f64 - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: f64, j: f64| {
        let c = (i as i64).clamp(0, g as i64 - 1) as usize;
        let r = (j as i64).clamp(0, g as i64 - 1) as usize;
        img[r * g + c] as f64
    };
    (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x0 + 1.0, y0))
        + fy * ((1.0 - fx) * at(x0, y0 + 1.0) + fx * at(x0 + 1.0, y0 + 1.0))
}

#[test]
fn a_texture_lookup_of_the_basis_parts_is_the_tables_bilinear_read() {
    let d = tempfile::tempdir().unwrap();
    for k in [11, 6, 1, 16] {
        let mut p = learned_ptm(k, 5, 4, false);
        // The fitter's grid: 17 × 17, values that differ everywhere.
        let g = 17;
        p.learned = Some(LearnedTable {
            grid: g,
            terms: k,
            values: (0..k * g * g)
                .map(|i| ((i as f32) * 0.613).sin() * 3.0 + (i % 7) as f32 * 0.01)
                .collect(),
        });
        let path = d.path().join(format!("t{k}.ptm.exr"));
        layout::save(&p, &path, &SaveOptions::default(), Layout::Rgba).unwrap();
        let table = p.learned.as_ref().unwrap();
        let images: Vec<_> = (0..k.div_ceil(4))
            .map(|i| raw(&layout::basis_part_path(&path, i)))
            .collect();
        for (w, h, chans) in &images {
            assert_eq!((*w, *h), (g, g));
            assert_eq!(chans.len(), 4, "every basis part is RGBA");
        }
        // Zeros past the last term.
        let last = &images[k.div_ceil(4) - 1].2;
        for c in k % 4..4 {
            if k % 4 != 0 {
                assert!(last[["R", "G", "B", "A"][c]].iter().all(|&x| x == 0.0));
            }
        }
        // (u, v) inside, on the grid lines, on the edges and corners, and past them (the
        // table clamps; a texture system's clamp wrap reads the edge texel there).
        let mut uvs = vec![
            (-1.0, -1.0),
            (1.0, 1.0),
            (-1.0, 1.0),
            (1.0, -1.0),
            (0.0, 0.0),
            (1.0, 0.3),
            (-0.2, -1.0),
            (0.125, 0.875),
            (1.0 - 1e-9, -1.0 + 1e-9),
            (1.7, -3.0),
            (-1.2, 0.4),
        ];
        let mut rng = ptm_format::hash::SplitMix(7);
        for _ in 0..400 {
            uvs.push((rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)));
        }
        let mut want = vec![0f64; k];
        let mut worst = 0f64;
        for &(u, v) in &uvs {
            table.terms(u, v, &mut want);
            let x = (u + 1.0) / 2.0 * (g - 1) as f64;
            let y = (v + 1.0) / 2.0 * (g - 1) as f64;
            let s = (0.5 + x) / g as f64;
            let t = 1.0 - (0.5 + y) / g as f64;
            for (term, want) in want.iter().enumerate() {
                let chan = &images[term / 4].2[["R", "G", "B", "A"][term % 4]];
                let got = texture_lookup(chan, g, s, t);
                worst = worst.max((got - want).abs());
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{k} terms, B{term} at ({u}, {v}): lookup {got}, table {want}"
                );
            }
        }
        // At grid points the lookup lands on texel centres: the stored f32 (to the rounding
        // of s·G − ½), with grid row j in image row G − 1 − j.
        for (i, j) in [(0, 0), (g - 1, g - 1), (3, 11), (g - 1, 0)] {
            let s = (0.5 + i as f64) / g as f64;
            let t = 1.0 - (0.5 + j as f64) / g as f64;
            let got = texture_lookup(&images[0].2["R"], g, s, t);
            let stored = table.values[j * g + i] as f64;
            assert!(
                (got - stored).abs() <= 1e-12 * stored.abs().max(1.0),
                "({i}, {j})"
            );
            assert_eq!(images[0].2["R"][(g - 1 - j) * g + i] as f64, stored);
        }
        assert!(worst < 1e-12, "{worst}");
    }
}

/// Rewrites basis part `i` of the set at `good` into the set at `bad` (every other file
/// copied) with its channels and size changed by `edit` (width, height, channels by name).
fn bad_basis_part(
    good: &Path,
    bad: &Path,
    k: usize,
    i: usize,
    edit: impl Fn(&mut usize, &mut usize, &mut Vec<(String, exrio::Samples)>),
) {
    for (a, b) in layout::rgba_paths(good, Basis::learned(k).unwrap())
        .iter()
        .zip(layout::rgba_paths(bad, Basis::learned(k).unwrap()))
    {
        std::fs::copy(a, b).unwrap();
    }
    let src = layout::basis_part_path(good, i);
    let mut c = exrio::read(&src).unwrap();
    let mut channels: Vec<(String, exrio::Samples)> = c.channels.drain().collect();
    channels.sort_by(|a, b| a.0.cmp(&b.0));
    let (mut w, mut h) = (c.width, c.height);
    edit(&mut w, &mut h, &mut channels);
    let attrs: Vec<(String, Attr)> = c.attrs.drain().collect();
    let attrs = attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
    exrio::write(&layout::basis_part_path(bad, i), w, h, channels, attrs).unwrap();
}

fn f32s(s: &mut exrio::Samples) -> &mut Vec<f32> {
    match s {
        exrio::Samples::F32(v) => v,
        exrio::Samples::F16(_) => panic!("basis parts are float"),
    }
}

#[test]
fn bad_basis_parts_are_refused_with_the_file_and_the_figures() {
    let d = tempfile::tempdir().unwrap();
    let good = d.path().join("good.ptm.exr");
    let p = learned_ptm(6, 9, 6, false);
    layout::save(&p, &good, &SaveOptions::default(), Layout::Rgba).unwrap();
    assert_eq!(layout::load(&good).unwrap(), p);
    let bad = d.path().join("bad.ptm.exr");
    type Edit = Box<dyn Fn(&mut usize, &mut usize, &mut Vec<(String, exrio::Samples)>)>;
    let cases: Vec<(usize, Edit, &[&str])> = vec![
        // A 5 × 4 image for a 5 × 5 table (a row dropped).
        (
            0,
            Box::new(|_, h, ch| {
                *h = 4;
                ch.iter_mut().for_each(|(_, s)| f32s(s).truncate(20));
            }),
            &[
                "bad.ptm.basis0.exr",
                "basis part basis0 is 5×4",
                "`ptm:learnedGrid` is 5",
            ],
        ),
        // A non-finite entry: B5 is the G of basis part 1, at column 2, row 3.
        (
            1,
            Box::new(|_, _, ch| {
                let g = ch.iter_mut().find(|(n, _)| n == "G").unwrap();
                f32s(&mut g.1)[3 * 5 + 2] = f32::INFINITY;
            }),
            &[
                "bad.ptm.basis1.exr",
                "channel G (B5) is inf at column 2, row 3",
            ],
        ),
        // A seventh term where learned6 has none: the B of basis part 1.
        (
            1,
            Box::new(|_, _, ch| {
                let b = ch.iter_mut().find(|(n, _)| n == "B").unwrap();
                f32s(&mut b.1)[7] = 0.25;
            }),
            &[
                "channel B holds 0.25 at column 2, row 1",
                "learned6 has 6 terms (B0..B5)",
            ],
        ),
        // A value that is not the header's.
        (
            0,
            Box::new(|_, _, ch| {
                let r = ch.iter_mut().find(|(n, _)| n == "R").unwrap();
                f32s(&mut r.1)[0] += 1.0;
            }),
            &[
                "B0 is",
                "at column 0, row 0 (grid column 0, row 4)",
                "the part and the header disagree",
            ],
        ),
        // A channel missing.
        (
            0,
            Box::new(|_, _, ch| ch.retain(|(n, _)| n != "A")),
            &["basis part basis0 lacks channel A (B3)"],
        ),
    ];
    for (i, edit, want) in cases {
        bad_basis_part(&good, &bad, 6, i, edit);
        for e in [
            PtmFile::load(&bad).unwrap_err().to_string(),
            layout::load(&layout::part_path(&bad, 0))
                .unwrap_err()
                .to_string(),
        ] {
            for w in want {
                assert!(e.contains(w), "want {w:?} in: {e}");
            }
        }
    }
    // A missing basis part.
    bad_basis_part(&good, &bad, 6, 0, |_, _, _| {});
    std::fs::remove_file(layout::basis_part_path(&bad, 1)).unwrap();
    let e = PtmFile::load(&bad).unwrap_err().to_string();
    assert!(
        e.contains("bad.ptm.basis1.exr")
            && e.contains("missing basis part basis1")
            && e.contains("basis0..basis1"),
        "{e}"
    );
    // An unused slot of a coefficient part that is not 0 (learned6's c1 is b4 b5 unused coverage).
    bad_basis_part(&good, &bad, 6, 0, |_, _, _| {});
    let c1 = layout::part_path(&bad, 1);
    let mut c = exrio::read(&c1).unwrap();
    let mut channels: Vec<(String, exrio::Samples)> = c.channels.drain().collect();
    f32s(&mut channels.iter_mut().find(|(n, _)| n == "B").unwrap().1)[4] = f32::NAN;
    let attrs: Vec<(String, Attr)> = c.attrs.drain().collect();
    let attrs = attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
    exrio::write(&c1, c.width, c.height, channels, attrs).unwrap();
    let e = PtmFile::load(&bad).unwrap_err().to_string();
    assert!(
        e.contains("bad.ptm.c1.exr")
            && e.contains("channel B is unused in learned6 and must hold 0, but holds NaN"),
        "{e}"
    );
    // Written again as a basis of fewer terms, the stale basis part goes.
    let mut q = learned_ptm(3, 9, 6, false);
    q.coverage = None;
    let files = layout::save(&q, &good, &SaveOptions::default(), Layout::Rgba).unwrap();
    assert_eq!(files.len(), 2);
    assert!(!layout::basis_part_path(&good, 1).exists());
    assert_eq!(layout::load(&good).unwrap(), q);
}

#[test]
fn learned_parts_are_rgba_with_coverage_in_the_last_a() {
    let names = |k: usize| -> Vec<Vec<&str>> {
        layout::parts(Basis::learned(k).unwrap())
            .iter()
            .map(|p| p.iter().map(|s| s.short()).collect())
            .collect()
    };
    assert_eq!(
        names(11),
        [
            ["b0", "b1", "b2", "b3"],
            ["b4", "b5", "b6", "b7"],
            ["b8", "b9", "b10", "coverage"]
        ]
    );
    assert_eq!(
        names(6),
        [["b0", "b1", "b2", "b3"], ["b4", "b5", "unused", "coverage"]]
    );
    assert_eq!(names(1), [["b0", "unused", "unused", "coverage"]]);
    assert_eq!(
        names(4),
        [
            ["b0", "b1", "b2", "b3"],
            ["unused", "unused", "unused", "coverage"]
        ]
    );
    for k in 1..=16 {
        let parts = layout::parts(Basis::learned(k).unwrap());
        assert!(parts.iter().all(|p| p.len() == 4), "{k}");
        assert_eq!(
            *parts.last().unwrap().last().unwrap(),
            layout::Slot::Coverage
        );
        // Slot j of the coefficient parts and slot j of the basis parts hold the same term.
        for (i, part) in parts
            .iter()
            .enumerate()
            .take(layout::basis_parts(Basis::learned(k).unwrap()))
        {
            for (c, (slot, term)) in part.iter().zip(layout::basis_slots(k, i)).enumerate() {
                match term {
                    Some(t) => {
                        assert_eq!(slot.short(), format!("b{t}"), "{k} terms, part {i}, {c}")
                    }
                    None => assert!(matches!(
                        slot,
                        layout::Slot::Unused | layout::Slot::Coverage
                    )),
                }
            }
        }
    }
}

#[test]
fn eval_reads_the_table_bilinearly_and_applies_the_logistic_link() {
    let p = learned_ptm(6, 4, 3, false);
    let t = p.learned.as_ref().unwrap();
    let g = t.grid;
    // An independent bilinear read: (u, v) → grid coordinates, four corners by hand.
    let read = |k: usize, u: f64, v: f64| -> f64 {
        let x = (u + 1.0) / 2.0 * (g - 1) as f64;
        let y = (v + 1.0) / 2.0 * (g - 1) as f64;
        let (i, j) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - i as f64, y - j as f64);
        let at = |i: usize, j: usize| t.values[k * g * g + j * g + i] as f64;
        at(i, j) * (1.0 - fx) * (1.0 - fy)
            + at(i + 1, j) * fx * (1.0 - fy)
            + at(i, j + 1) * (1.0 - fx) * fy
            + at(i + 1, j + 1) * fx * fy
    };
    for (el, az) in [(60f64, 0.3f64), (20.0, 2.0), (8.0, -2.5), (85.0, 1.0)] {
        let (e, a) = (el.to_radians(), az.to_radians());
        let l = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
        let (u, v) = UvMap::Hemispherical.of_dir(l);
        for (x, y) in [(0, 0), (3, 2), (1, 1)] {
            let c = p.coeffs(x, y);
            let z: f64 = (0..6).map(|k| c[k] as f64 * read(k, u, v)).sum();
            let want = sigmoid64(z);
            let got = p.eval_dir(x, y, l) as f64;
            assert!(
                (got - want).abs() < 2e-6,
                "eval_dir ({el}, {az}) texel ({x}, {y}): {got} vs {want}"
            );
            let got = p.eval(x, y, l[0] as f32, l[1] as f32) as f64;
            assert!(
                (got - want).abs() < 2e-4,
                "eval ({el}, {az}): {got} vs {want}"
            );
        }
    }
    assert_eq!(p.eval_dir(0, 0, [1.0, 0.0, -0.1]), 1.0, "below the horizon");
}

/// Rewrites `src` with its attributes changed by `edit` (and a channel added when `extra`).
fn rewritten(src: &Path, dst: &Path, edit: impl Fn(&mut Vec<(String, Attr)>), extra: bool) {
    let mut c = exrio::read(src).unwrap();
    let mut channels: Vec<(String, exrio::Samples)> = c.channels.drain().collect();
    if extra {
        channels.push((
            "ptm.b6".into(),
            exrio::Samples::F32(vec![0.0; c.width * c.height]),
        ));
    }
    let mut attrs: Vec<(String, Attr)> = c.attrs.drain().collect();
    edit(&mut attrs);
    let attrs = attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
    exrio::write(dst, c.width, c.height, channels, attrs).unwrap();
}

fn set(attrs: &mut Vec<(String, Attr)>, name: &str, a: Attr) {
    attrs.retain(|(n, _)| n != name);
    attrs.push((name.into(), a));
}

fn table_texts(attrs: &[(String, Attr)]) -> Vec<String> {
    match attrs.iter().find(|(n, _)| n == TABLE_ATTR) {
        Some((_, Attr::Texts(v))) => v.clone(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn bad_tables_are_refused_with_the_file_and_the_figures() {
    let d = tempfile::tempdir().unwrap();
    let good = d.path().join("good.ptm.exr");
    learned_ptm(6, 9, 6, false)
        .save(&good, &SaveOptions::default())
        .unwrap();
    let bad = d.path().join("bad.ptm.exr");
    type Edit = Box<dyn Fn(&mut Vec<(String, Attr)>)>;
    let cases: Vec<(Edit, bool, &[&str])> = vec![
        // A grid of 4 stated for tables of 5 × 5 values.
        (
            Box::new(|a| set(a, GRID_ATTR, Attr::I32(4))),
            false,
            &["term 0 holds 25 values", "4×4 grid", "has 16"],
        ),
        // One table dropped: 5 tables for 6 coefficient planes.
        (
            Box::new(|a| {
                let mut t = table_texts(a);
                t.pop();
                set(a, TABLE_ATTR, Attr::Texts(t));
            }),
            false,
            &["holds 5 tables", "learned6 has 6 coefficient planes"],
        ),
        // A non-finite entry.
        (
            Box::new(|a| {
                let mut t = table_texts(a);
                let mut w: Vec<&str> = t[3].split(' ').collect();
                w[7] = "inf";
                t[3] = w.join(" ");
                set(a, TABLE_ATTR, Attr::Texts(t));
            }),
            false,
            &["term 3 is inf at grid column 2, row 1"],
        ),
        // Text that is not a number.
        (
            Box::new(|a| {
                let mut t = table_texts(a);
                t[0] = t[0].replacen(' ', " x ", 1);
                set(a, TABLE_ATTR, Attr::Texts(t));
            }),
            false,
            &["term 0, value 1: \"x\" is not a number"],
        ),
        // No table at all.
        (
            Box::new(|a| a.retain(|(n, _)| n != TABLE_ATTR)),
            false,
            &["needs the string-vector attribute `ptm:learnedTable`"],
        ),
        // A grid side out of range.
        (
            Box::new(|a| set(a, GRID_ATTR, Attr::I32(1))),
            false,
            &["`ptm:learnedGrid` is 1"],
        ),
        // A seventh coefficient plane beside six tables.
        (
            Box::new(|_| {}),
            true,
            &["learned6 has 6 coefficient planes but the file also holds `ptm.b6`"],
        ),
    ];
    for (edit, extra, want) in cases {
        rewritten(&good, &bad, edit, extra);
        let e = Ptm::load(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.ptm.exr"), "{e}");
        for w in want {
            assert!(e.contains(w), "want {w:?} in: {e}");
        }
        let e2 = PtmFile::load(&bad).unwrap_err().to_string();
        assert_eq!(e, e2, "both decoders refuse in the same words");
    }
    // The writer refuses what the reader would.
    let mut p = learned_ptm(6, 9, 6, false);
    p.learned.as_mut().unwrap().values[40] = f32::NAN;
    let e = p
        .save(&bad, &SaveOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("term 1 is NaN at grid column 0, row 3"), "{e}");
    let mut p = learned_ptm(6, 9, 6, false);
    p.learned = None;
    let e = p
        .save(&bad, &SaveOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("needs its table"), "{e}");
    let mut p = learned_ptm(6, 9, 6, false);
    p.uv = UvMap::Projected;
    let e = p
        .save(&bad, &SaveOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("hemispherical"), "{e}");
}

#[test]
fn learned_basis_names_parse_one_way() {
    for k in 1..=16 {
        let b = Basis::learned(k).unwrap();
        assert_eq!(b.len(), k);
        assert_eq!(Basis::from_name(b.name()), Some(b));
        assert_eq!(b.name(), format!("learned{k}"));
    }
    for bad in [
        "learned0",
        "learned17",
        "learned06",
        "learned",
        "learned+6",
        "Learned6",
    ] {
        assert_eq!(Basis::from_name(bad), None, "{bad}");
    }
    assert_eq!(Basis::from_name("ptm11"), Some(Basis::Ptm11));
}
