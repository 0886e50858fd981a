//! A learned basis in the PTM file: both layouts round-trip it losslessly (tables, planes, MIP
//! levels, coverage), `Ptm::eval` and `eval_dir` read the table bilinearly and apply σ, and a
//! file whose table has the wrong size, a non-finite entry, or a term count that does not match
//! its coefficient planes is refused naming the file and the figures.
use ptm_format::basis::sigmoid64;
use ptm_format::exrio::{self, Attr};
use ptm_format::learned::{GRID_ATTR, TABLE_ATTR};
use ptm_format::ptm::mip_sizes;
use ptm_format::{Basis, Layout, LearnedTable, Level, Link, Ptm, PtmFile, SaveOptions, UvMap};
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
        assert_eq!(files.len(), (k + 1).div_ceil(4), "{k} terms");
        let back = ptm_format::layout::load(&rgba).unwrap();
        assert_eq!(back, p, "rgba, {k} terms");
        // And back to channels through the layout-free file: the same bytes as a direct save.
        let (file, layout) = PtmFile::load(&rgba).unwrap();
        assert_eq!(layout, Layout::Rgba);
        let again = d.path().join(format!("c{k}.ptm.exr"));
        file.save(&again, Layout::Channels).unwrap();
        assert_eq!(Ptm::load(&again).unwrap(), p);
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
