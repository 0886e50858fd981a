//! Penumbra-map geometry (blur radius by similar triangles) and the analytic half-plane
//! penumbra the blur methods are judged against (the Monte Carlo reference is
//! [`crate::reference`]).
//!
//! Distances: d_lc = light centre → caster plane, d_ca = caster plane → acceptor, measured
//! along the normal (the planes are parallel, so ratios along any ray are the same).

use std::f64::consts::PI;

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
