//! Spec parsing, parameter refusals (naming the parameter and its allowed range) and weave
//! drafts (WIF 1.1 and 0/1 grids), including malformed ones refused with section and line.

use ptm_swatches::{build, draft, Error, Pattern};

fn err(spec: &str) -> String {
    match build(spec) {
        Ok(_) => panic!("{spec} was accepted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn invalid_parameters_name_the_parameter_and_range() {
    let e = err("plain-weave?width=1.2");
    assert!(e.contains("width = 1.2") && e.contains("(0, 1]"), "{e}");
    let e = err("plain-weave?spacing=-1");
    assert!(e.contains("spacing = -1") && e.contains("> 0"), "{e}");
    let e = err("plain-weave?segments=0");
    assert!(e.contains("segments = 0") && e.contains("[3, 1024]"), "{e}");
    let e = err("plain-weave?crimp=0.01");
    assert!(
        e.contains("crimp = 0.01") && e.contains("a number in ["),
        "{e}"
    );
    let e = err("plain-weave?height=0.95");
    assert!(e.contains("height = 0.95"), "{e}");
    let e = err("plain-weave?flat=0.9");
    assert!(e.contains("flat = 0.9") && e.contains("[0, 0.8]"), "{e}");
    let e = err("plain-weave?width=0.97&height=0.3");
    assert!(
        e.contains("height = 0.3") && e.contains("no crimp separates"),
        "{e}"
    );
    let e = err("satin?n=6&step=2");
    assert!(
        e.contains("step = 2") && e.contains("coprime to n = 6"),
        "{e}"
    );
    let e = err("twill?dir=x");
    assert!(e.contains("dir = x") && e.contains("one of z, s"), "{e}");
    let e = err("rib?k=2&wales=3");
    assert!(
        e.contains("wales = 3") && e.contains("multiple of 2k = 4"),
        "{e}"
    );
    let e = err("velvet?density=100");
    assert!(e.contains("density = 100") && e.contains("only"), "{e}");
    let e = err("velvet?density=200");
    assert!(
        e.contains("density = 200") && e.contains("hexagonal packing"),
        "{e}"
    );
    let e = err("jersey?segments=abc");
    assert!(e.contains("segments = abc") && e.contains("integer"), "{e}");
    let e = err("corduroy?radius=0.6");
    assert!(e.contains("radius = 0.6") && e.contains("(0, 0.5]"), "{e}");
}

#[test]
fn unknown_names_keys_and_malformed_specs_are_refused() {
    let e = err("plain-weave?colour=red");
    assert!(
        e.contains("unknown parameter \"colour\"") && e.contains("segments"),
        "{e}"
    );
    let e = err("chiffon");
    assert!(
        e.contains("unknown builtin swatch \"chiffon\"") && e.contains("plain-weave"),
        "{e}"
    );
    let e = err("plain-weave?segments");
    assert!(e.contains("not of the form key=value"), "{e}");
    let e = err("plain-weave?segments=4&segments=5");
    assert!(e.contains("given twice"), "{e}");
    let e = err("jersey?d=0.3");
    assert!(e.contains("overlap"), "{e}");
}

#[test]
fn named_patterns_have_their_floats() {
    let p = Pattern::twill(2, 1, true);
    // Each warp: over 2 wefts then under 1; each weft: the same float shifted by one warp.
    for i in 0..3 {
        let overs = (0..3).filter(|&j| p.warp_over(i, j)).count();
        assert_eq!(overs, 2);
    }
    assert_ne!(Pattern::twill(2, 1, true), Pattern::twill(2, 1, false));
    // Satin: exactly one binding point per warp and per weft, none adjacent to the next warp's.
    let s = Pattern::satin(5, 2);
    for i in 0..5 {
        let unders: Vec<usize> = (0..5).filter(|&j| !s.warp_over(i, j)).collect();
        assert_eq!(unders.len(), 1);
        let next: Vec<usize> = (0..5).filter(|&j| !s.warp_over(i + 1, j)).collect();
        let d = (unders[0] as i64 - next[0] as i64).rem_euclid(5);
        assert!(
            d == 2 || d == 3,
            "binding points of warps {i}, {} are {d} apart",
            i + 1
        );
    }
    assert_eq!(Pattern::basket(1), Pattern::plain());
    // Weft-faced satin: one warp over per weft.
    let weft = build("satin?n=7&step=3&face=weft&segments=4&along=4").unwrap();
    assert_eq!(weft.cloth.yarns.len(), 14);
    let inv = Pattern::satin(7, 3).inverted();
    for i in 0..7 {
        assert_eq!((0..7).filter(|&j| inv.warp_over(i, j)).count(), 1);
    }
}

const TWILL_WIF: &str = "\
[WIF]
Version=1.1
Date=April 20, 1997
Developers=ptm tests
; a 2/2 twill on four shafts
[CONTENTS]
WEAVING=yes
THREADING=yes
TIEUP=yes
TREADLING=yes

[WEAVING]
Shafts=4
Treadles=4
Rising Shed=yes

[WARP]
Threads=4
Units=centimeters

[WEFT]
Threads=4

[THREADING]
1=1
2=2
3=3
4=4

[TIEUP]
1=1,2
2=2,3
3=3,4
4=4,1

[TREADLING]
1=1
2=2
3=3
4=4
";

#[test]
fn wif_twill_gives_the_expected_interlacement() {
    let p = draft::parse_wif(TWILL_WIF, "twill.wif").unwrap();
    // Pick j (0-based) lifts shafts j+1 and j+2 (1-based, wrapping); end i is on shaft i+1.
    let expect = Pattern::from_fn(4, 4, |i, j| i == j || i == (j + 1) % 4);
    assert_eq!(p, expect);
    // The same cloth as a lift plan, and inverted with a sinking shed.
    let lift = TWILL_WIF.replace("TIEUP]", "X1]").replace(
        "[TREADLING]\n1=1\n2=2\n3=3\n4=4",
        "[LIFTPLAN]\n1=1,2\n2=2,3\n3=3,4\n4=4,1",
    );
    assert_eq!(draft::parse_wif(&lift, "lift.wif").unwrap(), expect);
    let sinking = TWILL_WIF.replace("Rising Shed=yes", "Rising Shed=no");
    let inv = draft::parse_wif(&sinking, "sink.wif").unwrap();
    assert!(inv.over.iter().zip(&expect.over).all(|(a, b)| a != b));
    // Woven through the `draft` generator from a file.
    let dir = std::env::temp_dir().join(format!("ptm-swatches-wif-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("twill.wif");
    std::fs::write(&path, TWILL_WIF).unwrap();
    let s = build(&format!("draft?path={}&segments=4&along=4", path.display())).unwrap();
    assert_eq!(s.mesh.tile, [4.0, 4.0]);
    assert_eq!(s.cloth.yarns.len(), 8);
    std::fs::remove_dir_all(&dir).ok();
}

fn wif_err(text: &str) -> (String, usize, String) {
    match draft::parse_wif(text, "bad.wif") {
        Err(Error::Draft {
            section,
            line,
            reason,
            ..
        }) => (section, line, reason),
        other => panic!("expected a draft error, got {other:?}"),
    }
}

#[test]
fn malformed_wifs_are_refused_with_section_and_line() {
    let line_of = |needle: &str, text: &str| text.lines().position(|l| l == needle).unwrap() + 1;
    let t = TWILL_WIF.replace("3=3,4\n", "3=3,9\n");
    let (sec, line, why) = wif_err(&t);
    assert_eq!(
        (sec.as_str(), line),
        ("TIEUP", line_of("3=3,9", &t)),
        "{why}"
    );
    assert!(why.contains("shaft 9") && why.contains("Shafts=4"), "{why}");

    let t = TWILL_WIF.replace("[TREADLING]\n1=1", "[TREADLING]\n1=7");
    let (sec, line, why) = wif_err(&t);
    assert_eq!(
        (sec.as_str(), line),
        ("TREADLING", line_of("1=7", &t)),
        "{why}"
    );

    let t = TWILL_WIF.replace("[THREADING]\n1=1", "[THREADING]\nfirst=1");
    let (sec, line, why) = wif_err(&t);
    assert_eq!(
        (sec.as_str(), line),
        ("THREADING", line_of("first=1", &t)),
        "{why}"
    );

    let t = TWILL_WIF.replace("[THREADING]\n1=1", "[THREADING]\n0=1");
    let (_, _, why) = wif_err(&t);
    assert!(why.contains("1-based"), "{why}");

    let t = TWILL_WIF.replace("Shafts=4", "Shafts=four");
    let (sec, line, _) = wif_err(&t);
    assert_eq!(
        (sec.as_str(), line),
        ("WEAVING", line_of("Shafts=four", &t))
    );

    let t = TWILL_WIF.replace("[TIEUP]", "[TIEUP");
    let (_, line, why) = wif_err(&t);
    assert_eq!(line, line_of("[TIEUP", &t), "{why}");

    let t = TWILL_WIF.replace("[TIEUP]", "[UNUSED]");
    let (sec, line, why) = wif_err(&t);
    assert_eq!((sec.as_str(), line), ("TIEUP", 0), "{why}");
    let shown = Error::Draft {
        source_name: "bad.wif".into(),
        section: sec,
        line,
        reason: why,
    }
    .to_string();
    assert!(shown.starts_with("bad.wif: [TIEUP]: missing"), "{shown}");

    let t = TWILL_WIF.replace("[THREADING]\n1=1\n2=2", "[THREADING]\n1=1\n1=2");
    let (sec, _, why) = wif_err(&t);
    assert_eq!(sec, "THREADING");
    assert!(why.contains("twice"), "{why}");

    let (sec, line, _) = wif_err("Shafts=4\n[WEAVING]\n");
    assert_eq!((sec.as_str(), line), ("(none)", 1));
}

#[test]
fn grids_read_top_row_first_and_refuse_bad_rows() {
    // First line is the top weft (largest y): weft 1 here, weft 0 below it.
    let p = draft::parse_grid("# a 3×2 grid\n110\n001\n", "g").unwrap();
    assert_eq!((p.warps, p.wefts), (3, 2));
    assert!(!p.warp_over(0, 0) && !p.warp_over(1, 0) && p.warp_over(2, 0));
    assert!(p.warp_over(0, 1) && p.warp_over(1, 1) && !p.warp_over(2, 1));
    match draft::parse_grid("10\n1x\n", "g") {
        Err(Error::Draft {
            section,
            line,
            reason,
            ..
        }) => {
            assert_eq!((section.as_str(), line), ("grid", 2));
            assert!(reason.contains("'x'"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    match draft::parse_grid("10\n101\n", "g") {
        Err(Error::Draft { line, reason, .. }) => {
            assert_eq!(line, 2);
            assert!(
                reason.contains("3 cells") && reason.contains("line 1 has 2"),
                "{reason}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(draft::parse_grid("\n# nothing\n", "g").is_err());
    // Inline through the `grid` generator: `/` separates rows.
    let s = build("grid?rows=10/01&segments=4&along=4").unwrap();
    assert_eq!(s.mesh.tile, [2.0, 2.0]);
}

#[test]
fn huge_wif_counts_are_bounds_not_allocations() {
    // Treadles=1e18 panicked (capacity overflow) and 1e12 aborted: the counts only bound the
    // indices, the cloth is the same twill.
    let expect = draft::parse_wif(TWILL_WIF, "twill.wif").unwrap();
    for n in [
        "1000000000000000000",
        "1000000000000",
        "18446744073709551615",
    ] {
        let t = TWILL_WIF
            .replace("Treadles=4", &format!("Treadles={n}"))
            .replace("Shafts=4", &format!("Shafts={n}"));
        assert_eq!(draft::parse_wif(&t, "huge.wif").unwrap(), expect, "{n}");
    }
    // Repeated shafts in a list are harmless.
    let t = TWILL_WIF.replace("[TIEUP]\n1=1,2", "[TIEUP]\n1=1,2,2,1,1");
    assert_eq!(draft::parse_wif(&t, "dup.wif").unwrap(), expect);
    let t = TWILL_WIF.replace("Treadles=4", "Treadles=99999999999999999999");
    let (sec, _, why) = wif_err(&t);
    assert!(
        sec == "WEAVING" && why.contains("not a non-negative integer"),
        "{why}"
    );
}
