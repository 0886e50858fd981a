//! RTI image stacks: PNGs + `.lp` → sample stack (K = 1 − luminance) → fit.
use ptm_fit::images::{read_image_stack, Decoding};
use ptm_fit::solve::{fit_stack, FitOptions};
use ptm_format::{Basis, LightSet};

#[test]
fn png_stack_with_lp_fits_the_visibility_polynomial() {
    let dir = std::env::temp_dir().join(format!("ptm-fit-images-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lights = LightSet::from_dirs((0..24).map(|i| {
        let z = 0.15 + 0.8 * i as f64 / 24.0;
        let a = i as f64 * 2.4;
        let r = (1.0f64 - z * z).sqrt();
        [r * a.cos(), r * a.sin(), z]
    }));
    let (w, h) = (6u32, 4u32);
    // Texel (x, y): K = 0.3 + 0.2·x/w·u − 0.1·v² (row y only shifts the constant slightly).
    let k_at = |x: u32, y: u32, u: f64, v: f64| {
        0.3 + 0.2 * x as f64 / w as f64 * u - 0.1 * v * v + 0.02 * y as f64
    };
    let mut names = Vec::new();
    for (i, d) in lights.dirs.iter().enumerate() {
        let name = format!("img {i:02}.png");
        let img = image::ImageBuffer::from_fn(w, h, |x, y| {
            let vis = 1.0 - k_at(x, y, d[0], d[1]);
            image::Luma([(vis * 65535.0).round() as u16])
        });
        img.save(dir.join(&name)).unwrap();
        names.push(name);
    }
    std::fs::write(
        dir.join("unlisted.png"),
        std::fs::read(dir.join(&names[0])).unwrap(),
    )
    .unwrap();
    let mut lp = lights.clone();
    lp.names = names;
    lp.write_lp(&dir.join("dome.lp")).unwrap();
    let pattern = format!("{}/*.png", dir.display());
    // 16-bit images are linear: no sRGB decoding even by default.
    let (stack, info) =
        read_image_stack(&pattern, &dir.join("dome.lp"), [2.0, 1.0], Decoding::Srgb).unwrap();
    assert_eq!(
        (info.unused.len(), info.linear, info.srgb_decoded),
        (1, 24, 0)
    );
    assert_eq!((stack.width, stack.height, stack.lights.len()), (6, 4, 24));
    let (ptm, rep) = fit_stack(&stack, &FitOptions::new(Basis::Ptm6)).unwrap();
    assert!(rep.rms.max < 1e-4, "{:?}", rep.rms);
    // Row 0 of the image is row 0 of the PTM: compare at (x = 5, y = 3).
    let (u, v) = (0.4, -0.5);
    let want = k_at(5, 3, u, v) as f32;
    assert!((ptm.eval(5, 3, u as f32, v as f32) - want).abs() < 1e-4);
    // An .lp entry without an image is named.
    std::fs::remove_file(dir.join("img 03.png")).unwrap();
    let e =
        read_image_stack(&pattern, &dir.join("dome.lp"), [1.0, 1.0], Decoding::Srgb).unwrap_err();
    assert!(
        matches!(&e, ptm_fit::Error::Images { pattern: p, .. } if *p == pattern),
        "{e}"
    );
    let e = e.to_string();
    assert!(e.contains("img 03.png") && e.contains("light 3"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
