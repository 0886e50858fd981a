//! Integration tests of `ptm fit`: the command on stored stacks, its JSON, its errors, and the
//! HP PTM export read back by an independent reader written here from the format description.
mod common;

use std::path::Path;

use common::{dome, p, ptm};
use ptm_fit::SampleStack;
use ptm_format::{Basis, LightSet, Ptm};

fn tmpdir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// Smooth occlusion-like K: an exact ptm6 polynomial whose coefficients vary across the tile,
/// plus (when `noise`) a deterministic non-polynomial term.
fn stack(lights: &LightSet, w: usize, h: usize, noise: bool) -> (SampleStack, Vec<[f64; 6]>) {
    let coeffs: Vec<[f64; 6]> = (0..w * h)
        .map(|t| {
            let (x, y) = ((t % w) as f64 / w as f64, (t / w) as f64 / h as f64);
            [
                0.3 * x,
                -0.2 + 0.1 * y,
                0.15 * (x - y),
                0.1,
                0.25 * y,
                0.2 + 0.1 * x * y,
            ]
        })
        .collect();
    let k = lights
        .dirs
        .iter()
        .map(|d| {
            coeffs
                .iter()
                .enumerate()
                .map(|(t, c)| {
                    let mut v = Basis::Ptm6.eval(c, d[0], d[1]);
                    if noise {
                        v += 0.05 * ((t as f64 * 0.37 + d[0] * 9.0).sin() * (d[1] * 7.0).cos());
                    }
                    v as f32
                })
                .collect()
        })
        .collect();
    let s = SampleStack::new(lights.clone(), w, h, [1.0, 1.0], k);
    (s, coeffs)
}

/// The patent's plain PTM (identity link, projected (u, v)): what these tests check; the
/// logistic link has its own tests (tests/logistic.rs, fit/tests/logistic.rs).
const PLAIN: [&str; 4] = ["--link", "identity", "--uv", "projected"];

/// `ptm --json args…` (with [`PLAIN`] after a `fit`): the one JSON object it printed.
fn run_json(args: &[&str]) -> serde_json::Value {
    let mut args = args.to_vec();
    if args.first() == Some(&"fit") {
        args.extend(PLAIN);
    }
    common::json(&args, Path::new("."))
}

#[test]
fn fit_command_recovers_polynomials_and_reports_json() {
    let dir = tmpdir();
    let lights = dome(48);
    let (s, coeffs) = stack(&lights, 12, 9, false);
    let samples = dir.path().join("samples.exr");
    s.write(&samples).unwrap();
    let out = dir.path().join("weave.ptm.exr");
    let j = run_json(&[
        "fit",
        p(&samples),
        "--basis",
        "ptm6",
        "-o",
        p(&out),
        "--holdout",
        "4",
        "--error-map",
    ]);
    assert_eq!(j["rank"], 6);
    assert_eq!(j["lights"], 48);
    assert_eq!(j["lights_fit"], 44);
    assert!(j["condition_number"].as_f64().unwrap() < 20.0);
    assert!(j["rms_error"]["p99"].as_f64().unwrap() < 1e-5);
    assert!(j["holdout_rms_error"]["mean"].as_f64().unwrap() < 1e-5);
    // Timings: `seconds` in all, `seconds_<stage>` per stage, as in every subcommand.
    assert!(j["seconds"].as_f64().unwrap() > 0.0);
    for stage in ["seconds_read", "seconds_write"] {
        assert!(j[stage].as_f64().is_some_and(|s| s >= 0.0), "{stage}: {j}");
    }
    let stages = j.as_object().unwrap().keys();
    assert!(
        stages.filter(|k| k.starts_with("seconds_")).count() >= 3,
        "{j}"
    );
    assert!(j["warnings"].as_array().unwrap().is_empty());
    let (ptm, info) = Ptm::load_with_info(&out).unwrap();
    assert_eq!(ptm.basis, Basis::Ptm6);
    assert!(info.err_rms.is_some() && info.err_max.is_some());
    for (t, c) in coeffs.iter().enumerate() {
        for (plane, want) in ptm.planes.iter().zip(c) {
            assert!((plane[t] as f64 - want).abs() < 1e-5);
        }
    }
    // --half states its added error, and the file honours it.
    let half = dir.path().join("half.ptm.exr");
    let j = run_json(&["fit", p(&samples), "-o", p(&half), "--half"]);
    let bound = j["half_error_bound"].as_f64().unwrap();
    assert!(bound > 0.0 && bound < 2e-3, "{bound}");
    let h = Ptm::load(&half).unwrap();
    for t in 0..ptm.width * ptm.height {
        let (x, y) = (t % ptm.width, t / ptm.width);
        let d = (h.eval_unclamped(x, y, 0.5, -0.5) - ptm.eval_unclamped(x, y, 0.5, -0.5)).abs();
        assert!(d as f64 <= bound + 1e-6);
    }
}

#[test]
fn fit_command_errors_name_the_problem() {
    let dir = tmpdir();
    let foreign = dir.path().join("notes.exr");
    std::fs::write(&foreign, "not an exr").unwrap();
    let out = ptm(
        ["fit", p(&foreign), "-o", p(&dir.path().join("o.exr"))],
        dir.path(),
    );
    assert!(!out.ok);
    let err = out.stderr;
    assert!(
        err.contains("notes.exr") && err.contains("OpenEXR"),
        "{err}"
    );

    // Every texel masked: nothing to fit, not an RMS of 0.
    let (mut s, _) = stack(&dome(12), 4, 4, false);
    s.coverage = vec![0.0; 16];
    let masked = dir.path().join("masked.exr");
    s.write(&masked).unwrap();
    let out = ptm(
        ["fit", p(&masked), "-o", p(&dir.path().join("m.ptm.exr"))],
        dir.path(),
    );
    let err = out.stderr;
    assert!(
        !out.ok && err.contains("every one of its 4×4 texels is masked"),
        "{err}"
    );
    assert!(!dir.path().join("m.ptm.exr").exists());

    // A single elevation ring: warns by default, fails with --strict.
    let ring = LightSet::from_dirs((0..16).map(|i| {
        let a = i as f64 * std::f64::consts::TAU / 16.0;
        [0.8 * a.cos(), 0.8 * a.sin(), 0.6]
    }));
    let (s, _) = stack(&ring, 4, 4, true);
    let samples = dir.path().join("ring.exr");
    s.write(&samples).unwrap();
    let o = dir.path().join("ring.ptm.exr");
    let j = run_json(&["fit", p(&samples), "-o", p(&o)]);
    assert_eq!(j["rank"], 5);
    let w = j["warnings"].to_string();
    assert!(w.contains("ring") && w.contains("u2 + v2"), "{w}");
    let out = ptm(["fit", p(&samples), "-o", p(&o), "--strict"], dir.path());
    assert!(!out.ok);
    assert!(out.stderr.contains("--strict"));
}

/// `ptm fit` checks every output before the work and publishes all or none: an `--export-hp`
/// into a missing directory leaves the main output untouched, and an output that is the input
/// is refused.
#[test]
fn fit_command_outputs_are_one_transaction() {
    let dir = tmpdir();
    let (s, _) = stack(&dome(24), 4, 3, false);
    let samples = dir.path().join("s.exr");
    s.write(&samples).unwrap();
    let o = dir.path().join("w.ptm.exr");
    std::fs::write(&o, "previous output").unwrap();
    let missing = dir.path().join("nodir/w.ptm");
    let out = ptm(
        [
            &["fit", p(&samples), "-o", p(&o), "--export-hp", p(&missing)][..],
            &PLAIN,
        ]
        .concat(),
        dir.path(),
    );
    assert!(!out.ok);
    let err = out.stderr;
    assert!(err.contains("nodir"), "{err}");
    assert_eq!(std::fs::read(&o).unwrap(), b"previous output");
    let mut names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["s.exr", "w.ptm.exr"], "no temporary file left");
    // The same file twice, or the input as output, is refused before any work.
    for (out_path, hp) in [(&samples, None), (&o, Some(&o))] {
        let mut args = [&["fit", p(&samples), "-o", p(out_path)][..], &PLAIN].concat();
        if let Some(hp) = hp {
            args.extend(["--export-hp", p(hp)]);
        }
        let out = ptm(&args, dir.path());
        assert!(!out.ok);
        let err = out.stderr;
        assert!(
            err.contains("same file") || err.contains("is the input"),
            "{err}"
        );
    }
    assert_eq!(SampleStack::read(&samples).unwrap().k, s.k);
    // Both outputs are written when both can be.
    let hp = dir.path().join("w.ptm");
    run_json(&["fit", p(&samples), "-o", p(&o), "--export-hp", p(&hp)]);
    assert!(Ptm::load(&o).is_ok() && std::fs::metadata(&hp).unwrap().len() > 0);
}

/// An independent reader of HP PTM 1.2 LRGB files, written from the format description:
/// whitespace-separated ASCII header (version, format, width, height, 6 scales, 6 biases), then
/// 6 bytes per texel (rows bottom to top), then 3 bytes of RGB per texel.
struct HpFile {
    width: usize,
    height: usize,
    scales: [f64; 6],
    biases: [f64; 6],
    coeff: Vec<u8>,
    rgb: Vec<u8>,
}

fn read_hp(path: &Path) -> HpFile {
    let bytes = std::fs::read(path).unwrap();
    let mut pos = 0;
    let mut token = || {
        while bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        String::from_utf8(bytes[start..pos].to_vec()).unwrap()
    };
    assert_eq!(token(), "PTM_1.2");
    assert_eq!(token(), "PTM_FORMAT_LRGB");
    let width: usize = token().parse().unwrap();
    let height: usize = token().parse().unwrap();
    let scales = [(); 6].map(|_| token().parse::<f64>().unwrap());
    let biases = [(); 6].map(|_| token().parse::<f64>().unwrap());
    pos += 1; // the single whitespace byte ending the header
    let n = width * height;
    assert_eq!(bytes.len() - pos, 9 * n, "payload size");
    HpFile {
        width,
        height,
        scales,
        biases,
        coeff: bytes[pos..pos + 6 * n].to_vec(),
        rgb: bytes[pos + 6 * n..].to_vec(),
    }
}

impl HpFile {
    /// Luminance (255 = unchanged RGB) at image column x, row y counted from the top.
    fn lum(&self, x: usize, y: usize, u: f64, v: f64) -> f64 {
        let row_in_file = self.height - 1 - y;
        let i = (row_in_file * self.width + x) * 6;
        let a: Vec<f64> = (0..6)
            .map(|s| self.scales[s] * (self.coeff[i + s] as f64 - self.biases[s]))
            .collect();
        a[0] * u * u + a[1] * v * v + a[2] * u * v + a[3] * u + a[4] * v + a[5]
    }
}

#[test]
fn hp_export_reads_back_with_an_independent_reader() {
    let dir = tmpdir();
    let (s, _) = stack(&dome(40), 10, 7, true);
    let samples = dir.path().join("samples.exr");
    s.write(&samples).unwrap();
    let out = dir.path().join("w.ptm.exr");
    let hp = dir.path().join("w.ptm");
    let j = run_json(&["fit", p(&samples), "-o", p(&out), "--export-hp", p(&hp)]);
    let qmax = j["hp_export"]["quantisation_error_max"].as_f64().unwrap();
    assert!(
        qmax > 0.0 && qmax < 0.03,
        "stated quantisation error {qmax}"
    );
    let fitted = Ptm::load(&out).unwrap();
    let f = read_hp(&hp);
    assert_eq!((f.width, f.height), (10, 7));
    assert!(f.rgb.iter().all(|&b| b == 255));
    let mut worst: f64 = 0.0;
    for y in 0..7 {
        for x in 0..10 {
            for (u, v) in [(0.0, 0.0), (0.6, 0.3), (-0.5, -0.7), (0.0, 0.99)] {
                let vis = 1.0 - fitted.eval_unclamped(x, y, u as f32, v as f32) as f64;
                let d = (f.lum(x, y, u, v) / 255.0 - vis).abs();
                worst = worst.max(d);
            }
        }
    }
    assert!(
        worst <= qmax + 1e-6,
        "read-back error {worst} > stated {qmax}"
    );
    // A ptm11 fit cannot be exported, and says why.
    let out = ptm(
        [
            "fit",
            p(&samples),
            "-o",
            p(&dir.path().join("c.exr")),
            "--basis",
            "ptm11",
            "--export-hp",
            p(&dir.path().join("c.ptm")),
        ],
        dir.path(),
    );
    assert!(!out.ok);
    assert!(out.stderr.contains("--basis ptm6"));
}

/// Independent f64 least squares for one texel: normal equations solved by Gaussian
/// elimination with partial pivoting (well-conditioned domes only).
fn lstsq_f64(rows: &[[f64; 6]], k: &[f64]) -> [f64; 6] {
    let mut g = [[0.0f64; 7]; 6];
    for (r, &kk) in rows.iter().zip(k) {
        for i in 0..6 {
            for j in 0..6 {
                g[i][j] += r[i] * r[j];
            }
            g[i][6] += r[i] * kk;
        }
    }
    for col in 0..6 {
        let piv = (col..6)
            .max_by(|&a, &b| g[a][col].abs().total_cmp(&g[b][col].abs()))
            .unwrap();
        g.swap(col, piv);
        for r in 0..6 {
            if r != col {
                let f = g[r][col] / g[col][col];
                let pivot_row = g[col];
                for (x, &y) in g[r][col..].iter_mut().zip(&pivot_row[col..]) {
                    *x -= f * y;
                }
            }
        }
    }
    std::array::from_fn(|i| g[i][6] / g[i][i])
}

#[test]
fn real_bake_fit_agrees_with_an_independent_f64_solve() {
    let dir = tmpdir();
    let samples = dir.path().join("samples.exr");
    let out = ptm(
        [
            "bake",
            "--swatch",
            "builtin:plain-weave",
            "--res",
            "12",
            "--dirs",
            "24",
            "--spp",
            "2",
            "-o",
            p(&samples),
        ],
        dir.path(),
    );
    assert!(out.ok, "bake failed: {}", out.stderr);
    let fitted = dir.path().join("w.ptm.exr");
    let j = run_json(&["fit", p(&samples), "-o", p(&fitted)]);
    assert_eq!(j["rank"], 6);
    let stack = SampleStack::read(&samples).unwrap();
    let ptm = Ptm::load(&fitted).unwrap();
    let rows: Vec<[f64; 6]> = stack
        .lights
        .dirs
        .iter()
        .map(|d| {
            let mut t = [0.0; 6];
            Basis::Ptm6.terms(d[0], d[1], &mut t);
            t
        })
        .collect();
    let mut worst: f64 = 0.0;
    let mut occluded = 0;
    for t in 0..stack.texels() {
        if stack.coverage[t] <= 0.0 {
            continue;
        }
        let k: Vec<f64> = stack.k.iter().map(|plane| plane[t] as f64).collect();
        occluded += k.iter().filter(|&&x| x > 0.0).count();
        let want = lstsq_f64(&rows, &k);
        for (plane, w) in ptm.planes.iter().zip(want) {
            worst = worst.max((plane[t] as f64 - w).abs());
        }
    }
    assert!(occluded > 0, "the bake should show some occlusion");
    assert!(worst < 1e-5, "fit vs independent f64 solve: {worst}");
}

/// A minimal 8-bit greyscale PNG writer (stored deflate blocks), so this test needs no image
/// crate: PNG signature, IHDR, one IDAT with a zlib stream of uncompressed blocks, IEND.
fn write_grey_png(path: &Path, w: usize, h: usize, pix: &[u8]) {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    }
    let mut raw = Vec::new();
    for row in pix.chunks(w) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    let mut z = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65535).collect();
    for (i, b) in blocks.iter().enumerate() {
        z.push((i + 1 == blocks.len()) as u8);
        z.extend_from_slice(&(b.len() as u16).to_le_bytes());
        z.extend_from_slice(&(!(b.len() as u16)).to_le_bytes());
        z.extend_from_slice(b);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    z.extend_from_slice(&((b << 16) | a).to_be_bytes());
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = (w as u32).to_be_bytes().to_vec();
    ihdr.extend_from_slice(&(h as u32).to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &z);
    chunk(&mut png, b"IEND", &[]);
    std::fs::write(path, png).unwrap();
}

#[test]
fn fit_command_reads_an_rti_image_stack() {
    let dir = tmpdir();
    let lights = dome(20);
    let (w, h) = (9, 5);
    // White = lit: pixel = 255·(1 − K), K = 0.3 + 0.2·u·x/w (exactly ptm6, within [0, 1]).
    let mut lp = format!("{}\n", lights.len());
    for (i, d) in lights.dirs.iter().enumerate() {
        let pix: Vec<u8> = (0..w * h)
            .map(|t| {
                let k = 0.3 + 0.2 * d[0] * (t % w) as f64 / w as f64;
                (255.0 * (1.0 - k)).round() as u8
            })
            .collect();
        let name = format!("img_{i:02}.png");
        write_grey_png(&dir.path().join(&name), w, h, &pix);
        lp += &format!("{name} {} {} {}\n", d[0], d[1], d[2]);
    }
    let lp_path = dir.path().join("dome.lp");
    std::fs::write(&lp_path, lp).unwrap();
    let out = dir.path().join("rti.ptm.exr");
    let pattern = format!("{}/*.png", dir.path().display());
    let j = run_json(&[
        "fit",
        "--images",
        &pattern,
        "--lights",
        p(&lp_path),
        "--tile",
        "2,1",
        "--raw-values",
        "-o",
        p(&out),
    ]);
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(9), Some(5))
    );
    assert_eq!(j["images"]["decoding"], "raw");
    assert_eq!(j["images"]["linear"], 20);
    // 8-bit quantisation of the images bounds the residual.
    assert!(
        j["rms_error"]["max"].as_f64().unwrap() < 3e-3,
        "{}",
        j["rms_error"]
    );
    let fitted = Ptm::load(&out).unwrap();
    assert_eq!(fitted.tile, [2.0, 1.0]);
    // The header says how the images became K.
    let samples = |path: &Path| match ptm_format::exrio::read(path)
        .unwrap()
        .attrs
        .get("ptm:samples")
    {
        Some(ptm_format::exrio::Attr::Text(t)) => t.clone(),
        other => panic!("{}: ptm:samples is {other:?}", path.display()),
    };
    assert!(
        samples(&out).contains("20 images taken as stored (raw values"),
        "{}",
        samples(&out)
    );
    let k = fitted.eval(8, 2, 0.9, 0.1) as f64;
    assert!((k - (0.3 + 0.2 * 0.9 * 8.0 / 9.0)).abs() < 5e-3, "{k}");
    // By default 8-bit values are sRGB: decoded to linear light, a lit fraction 1 − K = 0.7
    // becomes 0.45, so K grows.
    let srgb = dir.path().join("srgb.ptm.exr");
    let j = run_json(&[
        "fit",
        "--images",
        &pattern,
        "--lights",
        p(&lp_path),
        "-o",
        p(&srgb),
    ]);
    assert_eq!(j["images"]["decoding"], "srgb");
    assert_eq!(j["images"]["srgb_decoded"], 20);
    assert!(
        samples(&srgb).contains("20 8-bit images decoded from sRGB to linear"),
        "{}",
        samples(&srgb)
    );
    let k = Ptm::load(&srgb).unwrap().eval(0, 2, 0.0, 0.0) as f64;
    let lin = |v: f64| ((v + 0.055) / 1.055).powf(2.4);
    assert!(
        (k - (1.0 - lin((255.0f64 * 0.7).round() / 255.0))).abs() < 5e-3,
        "{k}"
    );
}

/// Issue #25.4: by default an eighth of the lights are held out where the dome leaves 4 lights
/// per coefficient, and both figures are printed, labelled, with what they mean; `--holdout 0`
/// fits every light; a dome too small for ptm11 holds none out and says why; `--png-k` and
/// `--png-error` write K under the first held-out light and the residual map.
#[test]
fn the_fit_holds_out_lights_by_default_and_labels_both_errors() {
    let dir = tmpdir();
    let d = dir.path();
    let lights = dome(32);
    let (s, _) = stack(&lights, 6, 5, true);
    s.write(&d.join("s.exr")).unwrap();
    let run = ptm(
        [
            "--json",
            "fit",
            "s.exr",
            "-o",
            "a.ptm.exr",
            "--png-k",
            "k.png",
            "--png-error",
            "e.png",
        ],
        d,
    );
    assert!(run.ok, "{}", run.stderr);
    let j: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(j["holdout_lights"].as_array().unwrap().len(), 4, "{j}");
    assert_eq!(
        (j["lights_fit"].as_u64(), j["holdout_default"].as_bool()),
        (Some(28), Some(true))
    );
    assert!(j["holdout_rms_error"]["mean"].as_f64().unwrap() > 0.0);
    for says in [
        "training residual",
        "4 held-out lights",
        "reading it",
        "docs/model.md",
    ] {
        assert!(run.stderr.contains(says), "no {says:?} in {}", run.stderr);
    }
    // K under the first held-out light, as the PTM evaluates it, and the error map.
    let first = j["holdout_lights"][0].as_u64().unwrap() as usize;
    assert_eq!(j["png_light"].as_u64(), Some(first as u64));
    let fitted = Ptm::load(&d.join("a.ptm.exr")).unwrap();
    let (w, h, k) = ptm_runtime::output::read_rgba8(&d.join("k.png")).unwrap();
    assert_eq!((w, h), (6, 5));
    for (t, px) in k.iter().enumerate() {
        let want = fitted.eval_dir(t % w, t / w, lights.dirs[first]);
        assert!(
            (px[0] as f32 - 255.0 * want).abs() <= 0.5 + 1e-3,
            "texel {t}"
        );
    }
    let (w, h, _) = ptm_runtime::output::read_rgba8(&d.join("e.png")).unwrap();
    assert_eq!((w, h), (6, 5));
    // --holdout 0 fits every light.
    let j = common::json(["fit", "s.exr", "-o", "b.ptm.exr", "--holdout", "0"], d);
    assert_eq!(
        (j["lights_fit"].as_u64(), j["holdout_default"].as_bool()),
        (Some(32), Some(false))
    );
    assert!(j["holdout_rms_error"].is_null());
    // ptm11 on 32 lights: 28 would be under 4 × 11.
    let run = ptm(["fit", "s.exr", "-o", "c.ptm.exr", "--basis", "ptm11"], d);
    assert!(
        run.ok && run.stderr.contains("too few to spare"),
        "{}",
        run.stderr
    );
}

/// A flat RTI capture of `lights`: one 4×3 grey PNG per light, named `img_NN.png`, and its
/// `.lp` file `dome.lp` in `dir`.
fn rti_capture(dir: &Path, lights: &LightSet) -> std::path::PathBuf {
    let mut lp = format!("{}\n", lights.len());
    for (i, d) in lights.dirs.iter().enumerate() {
        let name = format!("img_{i:02}.png");
        write_grey_png(&dir.join(&name), 4, 3, &[200; 12]);
        lp += &format!("{name} {} {} {}\n", d[0], d[1], d[2]);
    }
    let path = dir.join("dome.lp");
    std::fs::write(&path, lp).unwrap();
    path
}

#[test]
fn images_the_lp_does_not_list_are_named() {
    let dir = tmpdir();
    let lp = rti_capture(dir.path(), &dome(12));
    write_grey_png(&dir.path().join("stray.png"), 4, 3, &[0; 12]);
    let pattern = format!("{}/*.png", dir.path().display());
    let out = dir.path().join("rti.ptm.exr");
    let args = [
        "fit",
        "--images",
        &pattern,
        "--lights",
        p(&lp),
        "-o",
        p(&out),
    ];
    let run = ptm(args, dir.path());
    assert!(run.ok, "{}", run.stderr);
    assert!(
        run.stderr.contains(&format!(
            "warning: 1 image is not listed in {} and was ignored: stray.png",
            lp.display()
        )),
        "{}",
        run.stderr
    );
    write_grey_png(&dir.path().join("stray2.png"), 4, 3, &[0; 12]);
    let run = ptm(args, dir.path());
    assert!(
        run.stderr.contains("2 images are not listed in")
            && run
                .stderr
                .contains("and were ignored: stray.png, stray2.png"),
        "{}",
        run.stderr
    );
}

/// A stack with a light below the horizon: the fit names it in `warnings` and leaves it out,
/// so the coefficients are those of the stack without it (its K = 1 would otherwise land on
/// the (u, v) of its mirror image above the horizon).
#[test]
fn a_stack_light_below_the_horizon_is_named_and_left_out() {
    let dir = tmpdir();
    let lights = dome(20);
    let (s, _) = stack(&lights, 5, 4, true);
    s.write(&dir.path().join("above.exr")).unwrap();
    let mut low = s.clone();
    low.lights
        .dirs
        .push(ptm_format::vec3::normalize([0.954, 0.0, -0.3]));
    low.lights.names.push("low".into());
    low.k.push(vec![1.0; 20]);
    low.write(&dir.path().join("low.exr")).unwrap();
    let fit = |name: &str| {
        let out = dir.path().join(format!("{name}.ptm.exr"));
        let j = run_json(&[
            "fit",
            p(&dir.path().join(format!("{name}.exr"))),
            "-o",
            p(&out),
        ]);
        (j, Ptm::load(&out).unwrap())
    };
    let (ja, a) = fit("above");
    let (jl, l) = fit("low");
    assert_eq!(jl["lights"], 21);
    assert_eq!(jl["lights_fit"], 20);
    let w = jl["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w
            .as_str()
            .unwrap()
            .starts_with("1 light at or below the horizon left out of the fit (K = 1 there by definition): light 20 \"low\" at -17.")),
        "{w:?}"
    );
    assert_eq!(ja["warnings"].as_array().map(Vec::len), Some(0), "{ja}");
    for (pa, pl) in a.planes.iter().zip(&l.planes) {
        for (x, y) in pa.iter().zip(pl) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }
}

/// A photographed stack whose `.lp` puts a light below the horizon (z < 0: a sign error in
/// the capture) is refused, naming the light and the likely cause; every light below says the
/// z axis is flipped.
#[test]
fn a_photographed_light_below_the_horizon_is_refused() {
    let dir = tmpdir();
    let mut lights = dome(12);
    lights.dirs[5] = ptm_format::vec3::normalize([0.954, 0.0, -0.3]);
    let lp = rti_capture(dir.path(), &lights);
    let pattern = format!("{}/*.png", dir.path().display());
    let out = dir.path().join("rti.ptm.exr");
    let args = [
        "fit",
        "--images",
        &pattern,
        "--lights",
        p(&lp),
        "-o",
        p(&out),
    ];
    let err = common::refused(args, dir.path());
    assert!(
        err.contains(&format!(
            "{}: 1 of its 12 lights is below the horizon (z < 0): light 5 \"img_05.png\" at -17.",
            lp.display()
        )) && err.contains("the sign of z is likely wrong"),
        "{err}"
    );
    assert!(!out.exists());
    for d in &mut lights.dirs {
        d[2] = -d[2].abs();
    }
    rti_capture(dir.path(), &lights);
    let err = common::refused(args, dir.path());
    assert!(
        err.contains("12 of its 12 lights are below") && err.contains("z axis is likely flipped"),
        "{err}"
    );
}

/// The file names the lights it held out (`ptm:holdoutLights`), as `--json` does, for both
/// links and both layouts, so a reader can measure the held-out error itself; a fit holding
/// none out records an empty list.
#[test]
fn the_file_records_its_held_out_lights() {
    let dir = tmpdir();
    let (s, _) = stack(&dome(30), 5, 4, true);
    let samples = dir.path().join("s.exr");
    s.write(&samples).unwrap();
    let text = |path: &Path| match ptm_format::exrio::read(path)
        .unwrap()
        .attrs
        .get("ptm:holdoutLights")
    {
        Some(ptm_format::exrio::Attr::Text(t)) => t.clone(),
        other => panic!("{}: ptm:holdoutLights is {other:?}", path.display()),
    };
    for (link, layout, file) in [
        ("identity", "channels", "i.ptm.exr"),
        ("logistic", "rgba", "l.ptm.c1.exr"),
    ] {
        let out = dir.path().join("i.ptm.exr".replace('i', &link[..1]));
        let args = [
            "fit",
            p(&samples),
            "-o",
            p(&out),
            "--link",
            link,
            "--layout",
            layout,
        ];
        let j = common::json([&args[..], &["--holdout", "5"]].concat(), dir.path());
        let held: Vec<String> = j["holdout_lights"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i.to_string())
            .collect();
        assert_eq!(held.len(), 5, "{j}");
        assert_eq!(
            text(&dir.path().join(file)),
            held.join(" "),
            "{link} {layout}"
        );
        // `--holdout 0` (30 lights would otherwise hold an eighth out by default) records none.
        common::json([&args[..], &["--holdout", "0"]].concat(), dir.path());
        assert_eq!(text(&dir.path().join(file)), "", "{link} {layout}");
    }
}

#[test]
fn basis_auto_keeps_the_cheapest_candidate_within_the_margin() {
    let dir = tmpdir();
    let d = dir.path();
    let (s, _) = stack(&dome(64), 8, 6, true);
    s.write(&d.join("s.exr")).unwrap();
    let chosen_of = |j: &serde_json::Value, margin: f64| {
        let errs: Vec<f64> = j["auto"]["candidates"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["holdout_rms_error"].as_f64().unwrap())
            .collect();
        let best = errs.iter().copied().fold(f64::INFINITY, f64::min);
        let i = errs
            .iter()
            .position(|&e| e <= best * (1.0 + margin))
            .unwrap();
        j["auto"]["candidates"][i]["basis"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let j = common::json(["fit", "s.exr", "-o", "a.ptm.exr", "--basis", "auto"], d);
    let names: Vec<&str> = j["auto"]["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["basis"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["ptm6", "learned6", "ptm11", "learned11"], "{j}");
    // Every candidate saw the same 8 held-out lights (an eighth of 64, the largest's default).
    assert_eq!(j["holdout_lights"].as_array().unwrap().len(), 8, "{j}");
    let want = chosen_of(&j, 0.02);
    assert_eq!(j["auto"]["chosen"].as_str(), Some(want.as_str()));
    assert_eq!(j["basis"].as_str(), Some(want.as_str()));
    assert_eq!(Ptm::load(&d.join("a.ptm.exr")).unwrap().basis.name(), want);
    // The written file is the kept candidate's fit: its held-out error is the one listed.
    let listed = j["auto"]["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["basis"] == want.as_str())
        .unwrap()["holdout_rms_error"]
        .as_f64();
    assert_eq!(j["holdout_rms_error"]["mean"].as_f64(), listed);
    // Margin 0 keeps the best; a huge margin the cheapest.
    let j = common::json(
        [
            "fit",
            "s.exr",
            "-o",
            "b.ptm.exr",
            "--basis",
            "auto",
            "--auto-margin",
            "0",
        ],
        d,
    );
    assert_eq!(j["auto"]["chosen"].as_str().unwrap(), chosen_of(&j, 0.0));
    let j = common::json(
        [
            "fit",
            "s.exr",
            "-o",
            "c.ptm.exr",
            "--basis",
            "auto",
            "--auto-margin",
            "1e9",
        ],
        d,
    );
    assert_eq!(j["auto"]["chosen"].as_str(), Some("ptm6"));
    // No held-out lights: nothing to choose by.
    let run = ptm(
        [
            "fit",
            "s.exr",
            "-o",
            "d.ptm.exr",
            "--basis",
            "auto",
            "--holdout",
            "0",
        ],
        d,
    );
    assert!(
        !run.ok && run.stderr.contains("held-out") && run.stderr.contains("--holdout N"),
        "{}",
        run.stderr
    );
    // 32 lights, 4 held out: 28 fitting lights are too few for learned11 (44), which is
    // skipped with the reason; learned6 (24) is fitted.
    let (s, _) = stack(&dome(32), 8, 6, true);
    s.write(&d.join("t.exr")).unwrap();
    let j = common::json(["fit", "t.exr", "-o", "e.ptm.exr", "--basis", "auto"], d);
    let c = &j["auto"]["candidates"];
    assert!(
        c[1]["skipped"].is_null() && c[1]["holdout_rms_error"].is_f64(),
        "{j}"
    );
    assert!(
        c[3]["skipped"].as_str().unwrap().contains("at least 44"),
        "{j}"
    );
    assert!(c[3]["holdout_rms_error"].is_null());
}

/// `ptm bake --fit auto` fits each candidate from the counts it streamed and keeps what `ptm
/// fit --basis auto` keeps from the same bake's stored stack: the same held-out lights, the
/// same errors, the same choice and coefficients. What cannot be chosen that way is refused.
#[test]
fn bake_fit_auto_chooses_as_fit_basis_auto_on_the_stored_stack() {
    let dir = tmpdir();
    let d = dir.path();
    let bake = [
        "bake",
        "--swatch",
        "builtin:jersey",
        "--res",
        "24",
        "--dirs",
        "64",
        "--spp",
        "4",
    ];
    common::ok([&bake[..], &["-o", "s.exr"]].concat(), d);
    let fit = common::json(["fit", "s.exr", "--basis", "auto", "-o", "f.ptm.exr"], d);
    let baked = common::json(
        [&bake[..], &["--fit", "auto", "-o", "b.ptm.exr"]].concat(),
        d,
    );
    let b = &baked["fit"];
    assert_eq!(b["auto"]["chosen"], fit["auto"]["chosen"], "{b}\n{fit}");
    assert_eq!(b["basis"], fit["basis"]);
    assert_eq!(b["holdout_lights"], fit["holdout_lights"]);
    assert_eq!(b["holdout_lights"].as_array().unwrap().len(), 8, "{b}");
    let (cb, cf) = (&b["auto"]["candidates"], &fit["auto"]["candidates"]);
    for i in 0..4 {
        assert_eq!(cb[i]["basis"], cf[i]["basis"]);
        let (eb, ef) = (
            cb[i]["holdout_rms_error"].as_f64().unwrap(),
            cf[i]["holdout_rms_error"].as_f64().unwrap(),
        );
        assert!((eb - ef).abs() < 1e-6, "{}: {eb} vs {ef}", cb[i]["basis"]);
    }
    let kept = b["auto"]["chosen"].as_str().unwrap();
    let listed = cb
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["basis"] == kept)
        .unwrap()["holdout_rms_error"]
        .as_f64()
        .unwrap();
    assert_eq!(b["holdout_rms_error"]["mean"].as_f64(), Some(listed));
    let (pb, pf) = (
        Ptm::load(&d.join("b.ptm.exr")).unwrap(),
        Ptm::load(&d.join("f.ptm.exr")).unwrap(),
    );
    assert_eq!(pb.basis.name(), kept);
    for (x, y) in pb.planes.iter().flatten().zip(pf.planes.iter().flatten()) {
        assert!((x - y).abs() < 1e-4, "{x} vs {y}");
    }
    // A given hold-out is every candidate's; none held out cannot choose.
    let h3 = common::json(
        [
            &bake[..],
            &["--fit", "auto", "--holdout", "3", "-o", "h.ptm.exr"],
        ]
        .concat(),
        d,
    );
    assert_eq!(h3["fit"]["holdout_lights"].as_array().unwrap().len(), 3);
    for (extra, says) in [
        (&["--holdout", "0"][..], "--holdout N"),
        (&["--link", "identity"][..], "logistic"),
        (&["--shard", "1/2"][..], "--shard with --fit auto"),
    ] {
        let err = common::refused(
            [&bake[..], &["--fit", "auto", "-o", "x.ptm.exr"], extra].concat(),
            d,
        );
        assert!(err.contains(says), "{extra:?}: {err}");
    }
    assert!(!d.join("x.ptm.exr").exists());
}
