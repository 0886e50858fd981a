//! What a PTM's numbers mean, table-driven: the polynomial basis (a list of monomials u^a v^b),
//! the link from polynomial to K, and the map from a light direction to (u, v).
//!
//! Orders follow the Pixar patent: ptm6 = A1..A6 (u², u, uv, v, v², 1); ptm11 = the claims' set
//! (u³, v³, u²v², u²v, uv², u², v², uv, u, v, 1). Channel names are the monomials' names.
//!
//! K = link(p(u, v)), p = Σ cᵢ·mᵢ(u, v): [`Link::Identity`] (the patent's PTM, K = p) or
//! [`Link::Logistic`] (K = σ(p) = 1/(1 + e^−p), which follows a texel's step-like shadow).
//! (u, v) = [`UvMap::Projected`] (l·T, l·B), the patent's and HP's, or [`UvMap::Hemispherical`]
//! (θ/(π/2))·(cos φ, sin φ), azimuthal equidistant, which spreads grazing lights apart.

/// A monomial u^a · v^b with its channel name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Monomial {
    /// EXR channel name of the coefficient (`c0`, `c1`, …).
    pub name: &'static str,
    /// Power of u.
    pub pu: u8,
    /// Power of v.
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

/// Most terms of a learned basis ([`Basis::Learned`]).
pub const MAX_LEARNED_TERMS: usize = 16;

/// Channel names of a learned basis's terms: `b0`, `b1`, … (the powers are unused: a learned
/// term is a table, [`crate::learned::LearnedTable`], not a monomial).
const LEARNED: [Monomial; MAX_LEARNED_TERMS] = [
    m("b0", 0, 0),
    m("b1", 0, 0),
    m("b2", 0, 0),
    m("b3", 0, 0),
    m("b4", 0, 0),
    m("b5", 0, 0),
    m("b6", 0, 0),
    m("b7", 0, 0),
    m("b8", 0, 0),
    m("b9", 0, 0),
    m("b10", 0, 0),
    m("b11", 0, 0),
    m("b12", 0, 0),
    m("b13", 0, 0),
    m("b14", 0, 0),
    m("b15", 0, 0),
];

const LEARNED_NAMES: [&str; MAX_LEARNED_TERMS] = [
    "learned1",
    "learned2",
    "learned3",
    "learned4",
    "learned5",
    "learned6",
    "learned7",
    "learned8",
    "learned9",
    "learned10",
    "learned11",
    "learned12",
    "learned13",
    "learned14",
    "learned15",
    "learned16",
];

/// The basis of a PTM: a fixed polynomial one, or k functions learned from the swatch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Basis {
    /// Biquadratic, 6 terms (patent ¶0030).
    Ptm6,
    /// Cubic set plus u²v², 11 terms (patent claims 18/27).
    Ptm11,
    /// k terms (1 ..= [`MAX_LEARNED_TERMS`]) learned from the swatch's bake, each a table over
    /// the hemispherical (u, v) square that the PTM file carries
    /// ([`crate::learned::LearnedTable`]); channels `b0` … `b{k−1}`. Constructed through
    /// [`Basis::learned`], which checks k.
    Learned(u8),
}

impl Basis {
    /// Every polynomial basis, in the order help texts list them (learned bases are
    /// [`Basis::learned`]).
    pub const ALL: [Basis; 2] = [Basis::Ptm6, Basis::Ptm11];

    /// The learned basis of `terms` terms, when 1 ≤ terms ≤ [`MAX_LEARNED_TERMS`].
    pub fn learned(terms: usize) -> Option<Basis> {
        (1..=MAX_LEARNED_TERMS)
            .contains(&terms)
            .then_some(Basis::Learned(terms as u8))
    }

    /// Whether the terms are learned tables rather than monomials.
    pub fn is_learned(self) -> bool {
        matches!(self, Basis::Learned(_))
    }

    /// `"ptm6"`, `"ptm11"` or `"learnedN"`: the name on the command line and in the file
    /// header.
    pub fn name(self) -> &'static str {
        match self {
            Basis::Ptm6 => "ptm6",
            Basis::Ptm11 => "ptm11",
            Basis::Learned(k) => LEARNED_NAMES[(k as usize).clamp(1, MAX_LEARNED_TERMS) - 1],
        }
    }

    /// The basis whose [`Basis::name`] is `name` (as the file's `ptm:basis` and the CLI spell
    /// it): `ptm6`, `ptm11`, or `learnedN` with N in 1 ..= 16 (`learned6`, `learned11`, …).
    pub fn from_name(name: &str) -> Option<Basis> {
        if let Some(n) = name.strip_prefix("learned") {
            // Decimal without a sign or leading zero, so each basis has one name.
            if n.starts_with('0') || !n.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            return n.parse().ok().and_then(Basis::learned);
        }
        Basis::ALL.into_iter().find(|b| b.name() == name)
    }

    /// The basis's terms in coefficient order (channel i holds the coefficient of the i-th):
    /// the monomials of a polynomial basis; for a learned one the names `b0` … only (its
    /// values come from its table, never from the powers).
    pub fn monomials(self) -> &'static [Monomial] {
        match self {
            Basis::Ptm6 => &PTM6,
            Basis::Ptm11 => &PTM11,
            Basis::Learned(k) => &LEARNED[..(k as usize).clamp(1, MAX_LEARNED_TERMS)],
        }
    }

    /// Number of coefficients (a basis is never empty).
    #[allow(clippy::len_without_is_empty)]
    pub fn len(self) -> usize {
        self.monomials().len()
    }

    /// Writes the basis terms at (u, v) into `out[..self.len()]`.
    ///
    /// # Panics
    /// For a learned basis, whose terms are the file's table
    /// ([`crate::learned::LearnedTable::terms`]).
    pub fn terms<T: num_like::Float>(self, u: T, v: T, out: &mut [T]) {
        assert!(
            !self.is_learned(),
            "{}: a learned basis is evaluated from its table (LearnedTable::terms)",
            self.name()
        );
        for (o, mono) in out.iter_mut().zip(self.monomials()) {
            *o = T::powi(u, mono.pu) * T::powi(v, mono.pv);
        }
    }

    /// Unclamped K(u, v) = Σ cᵢ·termᵢ(u, v) for coefficients in basis order.
    ///
    /// # Panics
    /// For a learned basis (see [`Basis::terms`]; [`crate::Ptm::eval`] evaluates either).
    pub fn eval<T: num_like::Float>(self, coeffs: &[T], u: T, v: T) -> T {
        assert!(
            !self.is_learned(),
            "{}: a learned basis is evaluated from its table (Ptm::eval)",
            self.name()
        );
        let mut k = T::zero();
        for (c, mono) in coeffs.iter().zip(self.monomials()) {
            k = k + *c * T::powi(u, mono.pu) * T::powi(v, mono.pv);
        }
        k
    }
}

/// How K follows from the polynomial p(u, v).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Link {
    /// K = p(u, v): the patent's PTM, linear in the coefficients (filtering coefficients filters K).
    Identity,
    /// K = σ(p(u, v)) = 1 / (1 + e^−p): fitted by maximum likelihood; a sharp edge along p = 0.
    Logistic,
}

impl Link {
    /// Every link, in the order help texts list them.
    pub const ALL: [Link; 2] = [Link::Identity, Link::Logistic];

    /// `"identity"` or `"logistic"`: the name on the command line and in `ptm:link`.
    pub fn name(self) -> &'static str {
        match self {
            Link::Identity => "identity",
            Link::Logistic => "logistic",
        }
    }

    /// The link whose name is `name` (as `ptm:link` and the CLI spell it).
    pub fn from_name(name: &str) -> Option<Link> {
        Link::ALL.into_iter().find(|l| l.name() == name)
    }

    /// K from the polynomial's value p (unclamped for the identity link).
    #[inline]
    pub fn apply(self, p: f32) -> f32 {
        match self {
            Link::Identity => p,
            Link::Logistic => sigmoid(p),
        }
    }
}

/// σ(z) = 1 / (1 + e^−z), accurate in both tails.
#[inline]
pub fn sigmoid(z: f32) -> f32 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// σ in f64.
#[inline]
pub fn sigmoid64(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// Where a unit light direction l lands in the (u, v) plane of the polynomial.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UvMap {
    /// (u, v) = (l·T, l·B): orthographic projection on the tangent plane (patent, HP PTM).
    Projected,
    /// (u, v) = (θ / (π/2))·(cos φ, sin φ), θ = angle of l from the normal, φ its azimuth:
    /// azimuthal equidistant, so equal steps of elevation are equal steps of (u, v).
    Hemispherical,
}

impl UvMap {
    /// Every (u, v) map, in the order help texts list them.
    pub const ALL: [UvMap; 2] = [UvMap::Projected, UvMap::Hemispherical];

    /// `"projected"` or `"hemispherical"`: the name on the command line and in `ptm:uv`.
    pub fn name(self) -> &'static str {
        match self {
            UvMap::Projected => "projected",
            UvMap::Hemispherical => "hemispherical",
        }
    }

    /// The map whose name is `name` (as `ptm:uv` and the CLI spell it).
    pub fn from_name(name: &str) -> Option<UvMap> {
        UvMap::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The formula in words (the `ptm:uvFormula` attribute).
    pub fn formula(self) -> &'static str {
        match self {
            UvMap::Projected => "u = dot(l, T), v = dot(l, B), l = unit vector towards the light",
            UvMap::Hemispherical => {
                "u = (theta / (pi/2)) * cos(phi), v = (theta / (pi/2)) * sin(phi); theta = acos(dot(l, N)), phi = atan2(dot(l, B), dot(l, T)), l = unit vector towards the light"
            }
        }
    }

    /// (u, v) of a unit direction l in the tangent frame (T, B, N) = (+X, +Y, +Z).
    pub fn of_dir(self, l: [f64; 3]) -> (f64, f64) {
        match self {
            UvMap::Projected => (l[0], l[1]),
            UvMap::Hemispherical => {
                let r = (l[0] * l[0] + l[1] * l[1]).sqrt();
                let theta = r.atan2(l[2]);
                let s = if r > 1e-12 {
                    theta / (std::f64::consts::FRAC_PI_2 * r)
                } else {
                    // θ ≈ r near the zenith: the factor tends to 1/(π/2).
                    1.0 / std::f64::consts::FRAC_PI_2
                };
                (l[0] * s, l[1] * s)
            }
        }
    }

    /// (u, v) of the light whose projected coordinates are (pu, pv) = (l·T, l·B), taking l in the
    /// upper hemisphere (l·N = √(1 − pu² − pv²) ≥ 0, the only lights a PTM describes).
    #[inline]
    pub fn of_projected(self, pu: f32, pv: f32) -> (f32, f32) {
        match self {
            UvMap::Projected => (pu, pv),
            UvMap::Hemispherical => {
                let r2 = pu * pu + pv * pv;
                let r = r2.sqrt().min(1.0);
                // θ = asin(r) on the upper hemisphere; factor θ / ((π/2)·r), → 2/π at r = 0.
                let s = if r > 1e-4 {
                    r.asin() / (std::f32::consts::FRAC_PI_2 * r)
                } else {
                    (1.0 + r2 / 6.0) / std::f32::consts::FRAC_PI_2
                };
                (pu * s, pv * s)
            }
        }
    }
}

/// Distinct monomials of the products mᵢ·mⱼ of a basis (the terms of its normal matrix), and for
/// each packed upper-triangle entry (i ≤ j, row-major) the index of its product among them.
/// ptm6 has 21 entries over 15 products, ptm11 66 over 33: a Hessian Σₙ wₙ·aₙaₙᵀ costs only
/// the distinct products per light.
///
/// # Panics
/// For a learned basis (its products are not monomials).
pub fn products(basis: Basis) -> (Vec<(u8, u8)>, Vec<usize>) {
    assert!(!basis.is_learned(), "products of a learned basis");
    let ms = basis.monomials();
    let mut distinct: Vec<(u8, u8)> = Vec::new();
    let mut index = Vec::new();
    for i in 0..ms.len() {
        for j in i..ms.len() {
            let p = (ms[i].pu + ms[j].pu, ms[i].pv + ms[j].pv);
            let k = match distinct.iter().position(|&d| d == p) {
                Some(k) => k,
                None => {
                    distinct.push(p);
                    distinct.len() - 1
                }
            };
            index.push(k);
        }
    }
    (distinct, index)
}

/// Minimal float abstraction so the same table serves f32 evaluation and f64 fitting.
pub mod num_like {
    /// f32 or f64, as far as evaluating a monomial needs.
    pub trait Float:
        Copy + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self> + PartialOrd
    {
        /// Additive identity.
        fn zero() -> Self;
        /// x to the small non-negative power n (x⁰ = 1).
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
    fn product_tables_are_complete() {
        let (d6, i6) = products(Basis::Ptm6);
        let (d11, i11) = products(Basis::Ptm11);
        assert_eq!((d6.len(), i6.len()), (15, 21));
        assert_eq!((d11.len(), i11.len()), (33, 66));
        // Every packed entry's product monomial is the sum of its two exponents.
        let ms = Basis::Ptm11.monomials();
        let mut q = 0;
        for i in 0..ms.len() {
            for j in i..ms.len() {
                assert_eq!(d11[i11[q]], (ms[i].pu + ms[j].pu, ms[i].pv + ms[j].pv));
                q += 1;
            }
        }
    }

    #[test]
    fn hemispherical_map_is_equidistant_and_agrees_with_directions() {
        for (el, az) in [
            (90.0f64, 0.0f64),
            (60.0, 0.3),
            (30.0, 2.0),
            (5.0, -1.0),
            (0.0, 0.7),
        ] {
            let (e, a) = (el.to_radians(), az.to_radians());
            let l = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
            let (u, v) = UvMap::Hemispherical.of_dir(l);
            let r = (u * u + v * v).sqrt();
            assert!((r - (90.0 - el) / 90.0).abs() < 1e-12, "el {el}: r {r}");
            let (fu, fv) = UvMap::Hemispherical.of_projected(l[0] as f32, l[1] as f32);
            assert!((fu as f64 - u).abs() < 2e-4 && (fv as f64 - v).abs() < 2e-4);
            assert_eq!(UvMap::Projected.of_dir(l), (l[0], l[1]));
        }
        assert_eq!(Link::from_name("logistic"), Some(Link::Logistic));
        assert_eq!(
            UvMap::from_name("hemispherical"),
            Some(UvMap::Hemispherical)
        );
        assert!(
            (sigmoid(0.0) - 0.5).abs() < 1e-7 && sigmoid(-200.0) == 0.0 && sigmoid(200.0) == 1.0
        );
    }

    #[test]
    fn eval_matches_hand_written_ptm6() {
        let c = [0.1, -0.2, 0.3, 0.4, -0.5, 0.6];
        let (u, v) = (0.3f64, -0.7f64);
        let want = c[0] * u * u + c[1] * u + c[2] * u * v + c[3] * v + c[4] * v * v + c[5];
        assert!((Basis::Ptm6.eval(&c, u, v) - want).abs() < 1e-15);
    }
}
