//! `ptm_eval FILE X,Y,Z|U,V …`: K of every texel of a PTM (either layout) for each light, as
//! JSON `[[row0…], …]` per light: `Ptm::eval_dir` of the direction X,Y,Z towards the light
//! (swatch frame, normalised here), or `Ptm::eval` of the projection (u, v) = (l·X, l·Y), read
//! as f64 and rounded to f32. The reference the client tests (Blender, MaterialX, the Python
//! module) compare with.
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((file, dirs)) = args.split_first() else {
        eprintln!("usage: ptm_eval FILE X,Y,Z|U,V ...");
        std::process::exit(2);
    };
    let ptm = match ptm_format::layout::load(Path::new(file)) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("ptm_eval: {e}");
            std::process::exit(1);
        }
    };
    let mut out = Vec::new();
    for d in dirs {
        let v: Vec<f64> = d
            .split(',')
            .map(|x| x.parse().expect("X,Y,Z or U,V"))
            .collect();
        let k = |x: usize, y: usize| match v[..] {
            [u, v] => ptm.eval(x, y, u as f32, v as f32),
            [lx, ly, lz] => {
                let n = (lx * lx + ly * ly + lz * lz).sqrt();
                ptm.eval_dir(x, y, [lx / n, ly / n, lz / n])
            }
            _ => panic!("a light is X,Y,Z or U,V, not {d}"),
        };
        let rows: Vec<String> = (0..ptm.height)
            .map(|y| {
                let r: Vec<String> = (0..ptm.width).map(|x| format!("{:e}", k(x, y))).collect();
                format!("[{}]", r.join(","))
            })
            .collect();
        out.push(format!("[{}]", rows.join(",")));
    }
    println!("[{}]", out.join(","));
}
