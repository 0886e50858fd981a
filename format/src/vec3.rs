//! The workspace's 3-vector helpers, on plain `[f64; 3]` arrays (the type meshes, light
//! directions and rays already have): written out component by component, in this order, so
//! results are the same bits wherever they are used and a caller never converts.

/// a − b.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a·b, summed x, y, z in that order.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b (right-handed).
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean length |a|.
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// a · s, every component scaled.
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// a / |a|: each component divided by the length (not multiplied by its reciprocal, which
/// rounds differently); non-finite for the zero vector.
pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_handed_and_unit() {
        assert_eq!(cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]);
        assert_eq!(normalize([3.0, 0.0, 4.0]), [0.6, 0.0, 0.8]);
        assert_eq!(norm(sub([4.0, 6.0, 3.0], [1.0, 2.0, 3.0])), 5.0);
        assert_eq!(dot(scale([1.0, 2.0, 3.0], 2.0), [1.0, 1.0, 1.0]), 12.0);
    }
}
