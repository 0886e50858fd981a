//! `ptm_eval FILE X,Y,Z …`: K of every texel of a PTM (either layout) for each light direction
//! (towards the light, swatch frame), as JSON `[[row0…], …]` per direction: the reference the
//! client tests (Blender, MaterialX) compare renders with.
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((file, dirs)) = args.split_first() else {
        eprintln!("usage: ptm_eval FILE X,Y,Z ...");
        std::process::exit(2);
    };
    let ptm = match ptm_fit::layout::load(Path::new(file)) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("ptm_eval: {e}");
            std::process::exit(1);
        }
    };
    let mut out = Vec::new();
    for d in dirs {
        let v: Vec<f64> = d.split(',').map(|x| x.parse().expect("X,Y,Z")).collect();
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let l = [v[0] / n, v[1] / n, v[2] / n];
        let rows: Vec<String> = (0..ptm.height)
            .map(|y| {
                let r: Vec<String> = (0..ptm.width)
                    .map(|x| format!("{:e}", ptm.eval_dir(x, y, l)))
                    .collect();
                format!("[{}]", r.join(","))
            })
            .collect();
        out.push(format!("[{}]", rows.join(",")));
    }
    println!("[{}]", out.join(","));
}
