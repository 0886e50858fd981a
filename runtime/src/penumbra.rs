//! Penumbra-map geometry (blur radius by similar triangles) and the analytic half-plane
//! penumbra the blur methods are judged against (the Monte Carlo reference is
//! [`crate::reference`]).
//!
//! Distances: d_lc = light centre → caster plane, d_ca = caster plane → acceptor, measured
//! along the normal (the planes are parallel, so ratios along any ray are the same).

use std::f64::consts::PI;

use ptm_format::vec3::{cross, normalize};

/// Blur radius on the caster plane: the cone from an acceptor point to a light of radius R cuts
/// the caster plane in a circle of radius w = R·d_ca/(d_lc + d_ca).
pub fn caster_radius(r: f64, d_lc: f64, d_ca: f64) -> f64 {
    r * d_ca / (d_lc + d_ca)
}

/// The same footprint projected from the light centre onto the acceptor: R·d_ca/d_lc (the
/// half-width of the penumbra of a straight caster edge on the acceptor).
pub fn acceptor_radius(r: f64, d_lc: f64, d_ca: f64) -> f64 {
    r * d_ca / d_lc
}

/// Fraction of a disk of radius w lying on the occluded side of a straight edge at signed
/// distance `d` from its centre (d > 0: the centre is inside the occluder by d).
pub fn half_plane_fraction(d: f64, w: f64) -> f64 {
    if w <= 0.0 {
        return if d > 0.0 {
            1.0
        } else if d < 0.0 {
            0.0
        } else {
            0.5
        };
    }
    let t = (d / w).clamp(-1.0, 1.0);
    // Area of the segment beyond a chord at distance t·w from the centre, over π w².
    let segment = (t.acos() - t * (1.0 - t * t).sqrt()) / PI;
    1.0 - segment
}

/// A cone around a unit `axis`: an orthonormal frame (e1, e2) about it and the cosine of its
/// half-angle.
pub struct Cone {
    /// The cone's axis.
    pub axis: [f64; 3],
    e1: [f64; 3],
    e2: [f64; 3],
    /// The cosine of its half-angle.
    pub cos_max: f64,
}

impl Cone {
    /// The direction at (u1, u2) ∈ [0, 1)², uniform in solid angle within the cone.
    pub fn dir(&self, u1: f64, u2: f64) -> [f64; 3] {
        let cos_t = 1.0 - u1 * (1.0 - self.cos_max);
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * PI * u2;
        std::array::from_fn(|k| {
            self.axis[k] * cos_t + (self.e1[k] * phi.cos() + self.e2[k] * phi.sin()) * sin_t
        })
    }
}

/// The cone that a sphere of radius `r` at distance `d` along the unit `axis` subtends (the
/// whole sphere of directions, cos −1, from inside it).
pub fn cone_frame(axis: [f64; 3], r: f64, d: f64) -> Cone {
    let helper = if axis[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let e1 = normalize(cross(helper, axis));
    let e2 = cross(axis, e1);
    let cos_max = if r >= d {
        -1.0
    } else {
        (1.0 - (r / d) * (r / d)).sqrt()
    };
    Cone {
        axis,
        e1,
        e2,
        cos_max,
    }
}
