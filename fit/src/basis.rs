//! Polynomial bases of an occlusion PTM, table-driven: a basis is a list of monomials u^a v^b.
//!
//! Orders follow the Pixar patent: ptm6 = A1..A6 (u², u, uv, v, v², 1); ptm11 = the claims' set
//! (u³, v³, u²v², u²v, uv², u², v², uv, u, v, 1). Channel names are the monomials' names.

/// A monomial u^a · v^b with its channel name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Monomial {
    pub name: &'static str,
    pub pu: u8,
    pub pv: u8,
}

const fn m(name: &'static str, pu: u8, pv: u8) -> Monomial {
    Monomial { name, pu, pv }
}

const PTM6: [Monomial; 6] = [
    m("u2", 2, 0),
    m("u", 1, 0),
    m("uv", 1, 1),
    m("v", 0, 1),
    m("v2", 0, 2),
    m("1", 0, 0),
];
const PTM11: [Monomial; 11] = [
    m("u3", 3, 0),
    m("v3", 0, 3),
    m("u2v2", 2, 2),
    m("u2v", 2, 1),
    m("uv2", 1, 2),
    m("u2", 2, 0),
    m("v2", 0, 2),
    m("uv", 1, 1),
    m("u", 1, 0),
    m("v", 0, 1),
    m("1", 0, 0),
];

/// The polynomial basis of a PTM.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Basis {
    /// Biquadratic, 6 terms (patent ¶0030).
    Ptm6,
    /// Cubic set plus u²v², 11 terms (patent claims 18/27).
    Ptm11,
}

impl Basis {
    pub const ALL: [Basis; 2] = [Basis::Ptm6, Basis::Ptm11];

    /// `"ptm6"` or `"ptm11"`: the name on the command line and in the file header.
    pub fn name(self) -> &'static str {
        match self {
            Basis::Ptm6 => "ptm6",
            Basis::Ptm11 => "ptm11",
        }
    }

    pub fn from_name(name: &str) -> Option<Basis> {
        Basis::ALL.into_iter().find(|b| b.name() == name)
    }

    pub fn monomials(self) -> &'static [Monomial] {
        match self {
            Basis::Ptm6 => &PTM6,
            Basis::Ptm11 => &PTM11,
        }
    }

    /// Number of coefficients (a basis is never empty).
    #[allow(clippy::len_without_is_empty)]
    pub fn len(self) -> usize {
        self.monomials().len()
    }

    /// Writes the basis terms at (u, v) into `out[..self.len()]`.
    pub fn terms<T: num_like::Float>(self, u: T, v: T, out: &mut [T]) {
        for (o, mono) in out.iter_mut().zip(self.monomials()) {
            *o = T::powi(u, mono.pu) * T::powi(v, mono.pv);
        }
    }

    /// Unclamped K(u, v) = Σ cᵢ·termᵢ(u, v) for coefficients in basis order.
    pub fn eval<T: num_like::Float>(self, coeffs: &[T], u: T, v: T) -> T {
        let mut k = T::zero();
        for (c, mono) in coeffs.iter().zip(self.monomials()) {
            k = k + *c * T::powi(u, mono.pu) * T::powi(v, mono.pv);
        }
        k
    }
}

/// Minimal float abstraction so the same table serves f32 evaluation and f64 fitting.
pub mod num_like {
    pub trait Float:
        Copy + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self> + PartialOrd
    {
        fn zero() -> Self;
        fn powi(x: Self, n: u8) -> Self;
    }
    macro_rules! float {
        ($t:ty) => {
            impl Float for $t {
                fn zero() -> Self {
                    0.0
                }
                #[inline]
                fn powi(x: Self, n: u8) -> Self {
                    match n {
                        0 => 1.0,
                        1 => x,
                        2 => x * x,
                        3 => x * x * x,
                        _ => x.powi(n as i32),
                    }
                }
            }
        };
    }
    float!(f32);
    float!(f64);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_are_distinct_and_named_uniquely() {
        for b in Basis::ALL {
            let ms = b.monomials();
            for (i, a) in ms.iter().enumerate() {
                for c in &ms[i + 1..] {
                    assert!((a.pu, a.pv) != (c.pu, c.pv), "{b:?} repeats a monomial");
                    assert_ne!(a.name, c.name);
                }
            }
        }
        assert_eq!(Basis::Ptm6.len(), 6);
        assert_eq!(Basis::Ptm11.len(), 11);
    }

    #[test]
    fn eval_matches_hand_written_ptm6() {
        let c = [0.1, -0.2, 0.3, 0.4, -0.5, 0.6];
        let (u, v) = (0.3f64, -0.7f64);
        let want = c[0] * u * u + c[1] * u + c[2] * u * v + c[3] * v + c[4] * v * v + c[5];
        assert!((Basis::Ptm6.eval(&c, u, v) - want).abs() < 1e-15);
    }
}
