//! Top view of a swatch tiled 2×2, z-buffered and Lambert-shaded, as a greyscale PNG: a quick
//! look at a generator (seams between tiles must not show).
//!
//! `cargo run -p ptm-swatches --example top_view -- 'twill?n=3' twill.png [pixels]`

use std::io::Write;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: top_view SPEC OUT.png [pixels]");
        std::process::exit(2);
    }
    let mesh = ptm_swatches::builtin(&args[1]).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1);
    });
    let px: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(512);
    let [w, h] = mesh.tile.map(f64::from);
    // The image shows [0, 2W]×[0, 2H]; row 0 is the far edge y = 2H.
    let (nx, ny) = (px, ((px as f64) * h / w).round() as usize);
    let (sx, sy) = (nx as f64 / (2.0 * w), ny as f64 / (2.0 * h));
    let mut depth = vec![f64::NEG_INFINITY; nx * ny];
    let mut shade = vec![0u8; nx * ny];
    let light = {
        let l = [-0.4f64, 0.5, 0.77];
        let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        l.map(|v| v / n)
    };
    for oy in -1..=2 {
        for ox in -1..=2 {
            for t in &mesh.triangles {
                let p = t.map(|i| {
                    let v = mesh.positions[i as usize].map(f64::from);
                    [
                        (v[0] + ox as f64 * w) * sx,
                        (2.0 * h - v[1] - oy as f64 * h) * sy,
                        v[2],
                    ]
                });
                // Normal in world space (image y is flipped).
                let (a, b, c) = (p[0], p[1], p[2]);
                let e1 = [(b[0] - a[0]) / sx, -(b[1] - a[1]) / sy, b[2] - a[2]];
                let e2 = [(c[0] - a[0]) / sx, -(c[1] - a[1]) / sy, c[2] - a[2]];
                let n = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if len == 0.0 || n[2] <= 0.0 {
                    continue; // facing away from the camera
                }
                let lum = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]) / len;
                let value = (40.0 + 215.0 * lum.max(0.0)) as u8;
                let area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
                let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
                let x1 = (a[0].max(b[0]).max(c[0]).ceil() as usize).min(nx);
                let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
                let y1 = (a[1].max(b[1]).max(c[1]).ceil() as usize).min(ny);
                for y in y0..y1 {
                    for x in x0..x1 {
                        let (qx, qy) = (x as f64 + 0.5, y as f64 + 0.5);
                        let w0 = ((b[0] - qx) * (c[1] - qy) - (c[0] - qx) * (b[1] - qy)) / area;
                        let w1 = ((c[0] - qx) * (a[1] - qy) - (a[0] - qx) * (c[1] - qy)) / area;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                            continue;
                        }
                        let z = w0 * a[2] + w1 * b[2] + w2 * c[2];
                        let k = y * nx + x;
                        if z > depth[k] {
                            depth[k] = z;
                            shade[k] = value;
                        }
                    }
                }
            }
        }
    }
    write_png(&args[2], nx, ny, &shade).expect("writing the PNG");
    eprintln!(
        "{}: {} triangles, tile {w} x {h}, wrote {}",
        args[1],
        mesh.triangles.len(),
        args[2]
    );
}

/// Minimal greyscale PNG: one zlib stream of stored (uncompressed) blocks.
fn write_png(path: &str, w: usize, h: usize, px: &[u8]) -> std::io::Result<()> {
    fn crc(data: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in data {
            c ^= u32::from(b);
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
    let mut raw = Vec::with_capacity((w + 1) * h);
    for row in px.chunks(w) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    let mut z = vec![0x78, 0x01];
    for (i, block) in raw.chunks(65535).enumerate() {
        let last = (i + 1) * 65535 >= raw.len();
        z.push(u8::from(last));
        let n = block.len() as u16;
        z.extend_from_slice(&n.to_le_bytes());
        z.extend_from_slice(&(!n).to_le_bytes());
        z.extend_from_slice(block);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &v in &raw {
        a = (a + u32::from(v)) % 65521;
        b = (b + a) % 65521;
    }
    z.extend_from_slice(&((b << 16) | a).to_be_bytes());
    let mut out = std::fs::File::create(path)?;
    out.write_all(b"\x89PNG\r\n\x1a\n")?;
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&(w as u32).to_be_bytes());
    ihdr.extend_from_slice(&(h as u32).to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    for (kind, data) in [(&b"IHDR"[..], &ihdr[..]), (b"IDAT", &z), (b"IEND", &[])] {
        out.write_all(&(data.len() as u32).to_be_bytes())?;
        let mut chunk = kind.to_vec();
        chunk.extend_from_slice(data);
        out.write_all(&chunk)?;
        out.write_all(&crc(&chunk).to_be_bytes())?;
    }
    Ok(())
}
