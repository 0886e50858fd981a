//! Weft knits: stockinette (jersey) and k×k rib courses on Crane's plain-knit yarn curve.
//!
//! K. Crane, "A Simple Parametric Model of Plain-Knit Yarns" (2023): one course follows
//! γ(t) = (t + a·sin 2t, h·cos t, d·cos 2t), one wale per 2π of t, courses `row` apart in y.
//! t = 0 is the head of a stitch (top of its loop, y = +h), t = π the sinker between two
//! stitches (y = −h), where it passes behind the legs of the course below. The shape parameters
//! are in Crane's loop units (a wale is 2π wide) and the whole swatch is scaled so that one
//! wale is `wale` user units wide.

use crate::params::Params;
use crate::yarn::{Cloth, Ends, Yarn};
use crate::Result;

/// Shape of a knit swatch. `a, h, d, row, radius` are in loop units (wale width 2π).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KnitParams {
    /// Wale width in user units (sets the scale).
    pub wale: f64,
    /// Lateral loop bulge a, loop height h, depth d (Crane: 1.5, 4, 1).
    pub a: f64,
    /// Loop height h (loop units).
    pub h: f64,
    /// Loop depth d (loop units).
    pub d: f64,
    /// Course spacing (Crane: h + ½ = 4.5).
    pub row: f64,
    /// Yarn radius (Crane: ½).
    pub radius: f64,
    /// Rib group width k: k knit wales then k purl wales; 0 for stockinette.
    pub rib: usize,
    /// Wales and courses in the tile (the rib's 2k wales are one repeat).
    pub wales: usize,
    /// Courses in the tile.
    pub courses: usize,
    /// Vertices per ring and rings per wale.
    pub segments: usize,
    /// Rings per wale along the yarn.
    pub along: usize,
}

/// Reads a knit's parameters; `name` is `jersey` or `rib`.
pub fn from_params(name: &str, p: &Params) -> Result<(Cloth, usize)> {
    let rib = if name == "rib" {
        p.int("k", 1, 1, 16)? as usize
    } else {
        0
    };
    let wale = p.positive("wale", 1.0, f64::INFINITY)?;
    let a = p.real("a", 1.5, 0.0, 4.0)?;
    let d = p.real("d", 1.0, 0.0, 4.0)?;
    let row = p.positive("row", 4.5, 20.0)?;
    let radius = p.positive("radius", 0.5, 0.5 * row)?;
    // The loop must stay within one course of its own so a 3×3 block covers the tile.
    let h_max = 1.5 * row - radius;
    let h = p.positive("h", 4.0, h_max)?;
    let period = if rib > 0 { 2 * rib } else { 1 };
    let wales = p.int("wales", period as i64, 1, 64)? as usize;
    if !wales.is_multiple_of(period) {
        return Err(p.invalid("wales", wales, format!("a multiple of 2k = {period}")));
    }
    let courses = p.int("courses", 1, 1, 64)? as usize;
    let segments = p.int("segments", 12, 3, 1024)? as usize;
    let along = p.int("along", 64, 8, 4096)? as usize;
    let kp = KnitParams {
        wale,
        a,
        h,
        d,
        row,
        radius,
        rib,
        wales,
        courses,
        segments,
        along,
    };
    Ok((knit(&kp), segments))
}

/// Side of wale `l`: +1 knit (loops' legs in front), −1 purl (the stitch seen from the back).
fn side(p: &KnitParams, l: i64) -> f64 {
    if p.rib == 0 || (l.rem_euclid(2 * p.rib as i64) as usize) < p.rib {
        1.0
    } else {
        -1.0
    }
}

/// The knit or purl sign along the yarn and its derivative in t: ±1 through each wale, and a
/// half-cosine change of side over the sinker between a knit and a purl wale
/// (t ∈ [2πl + π/2, 2πl + 3π/2]), so the curve stays smooth.
fn side_blend(p: &KnitParams, t: f64) -> (f64, f64) {
    use std::f64::consts::{FRAC_PI_2, PI, TAU};
    let u = t - FRAC_PI_2;
    let l = (u / TAU).floor();
    let local = u - l * TAU;
    let (from, to) = (side(p, l as i64), side(p, l as i64 + 1));
    if local >= PI {
        return (to, 0.0);
    }
    let s = local / PI;
    (
        from + (to - from) * 0.5 * (1.0 - (PI * s).cos()),
        (to - from) * 0.5 * (PI * s).sin(),
    )
}

/// Courses of a knit over `wales` × `courses` stitches.
///
/// The tile is cut through stitch heads (t = 2πl), where the curve's tangent is along +x, so the
/// border rings lie in the planes x = 0 and x = W. Course c is centred on y = (c + ½)·row and
/// reaches h + radius above and below: into the neighbouring courses, which is how loops
/// interlock; those parts are not cut (see the crate docs).
pub fn knit(p: &KnitParams) -> Cloth {
    use std::f64::consts::TAU;
    let sc = p.wale / TAU;
    let tile = [p.wales as f64 * p.wale, p.courses as f64 * p.row * sc];
    let n = p.wales * p.along;
    let t_end = TAU * p.wales as f64;
    let mut yarns = Vec::with_capacity(p.courses);
    for c in 0..p.courses {
        let y0 = (c as f64 + 0.5) * p.row;
        let mut centre = Vec::with_capacity(n + 1);
        let mut tangents = Vec::with_capacity(n + 1);
        for k in 0..=n {
            let t = t_end * k as f64 / n as f64;
            let (s2, c2) = (2.0 * t).sin_cos();
            let (s1, c1) = t.sin_cos();
            let (g, dg) = side_blend(p, t);
            centre.push([sc * (t + p.a * s2), sc * (y0 + p.h * c1), sc * p.d * g * c2]);
            tangents.push([
                1.0 + 2.0 * p.a * c2,
                -p.h * s1,
                p.d * (dg * c2 - 2.0 * g * s2),
            ]);
        }
        yarns.push(Yarn::round(
            centre,
            &tangents,
            sc * p.radius,
            Ends::Periodic {
                shift: [tile[0], 0.0, 0.0],
            },
            [0.0, 0.0, 1.0],
        ));
    }
    Cloth {
        tile,
        yarns,
        ..Cloth::default()
    }
}
