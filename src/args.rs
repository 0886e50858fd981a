//! The command-line value types that several subcommands share: the library enums, named on
//! the command line by the library's own words through one generic value parser ([`choice`]);
//! the model flags of `ptm fit` and `ptm bake --fit` ([`ModelArgs`]); and `--threads`.
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use ptm_fit::solve::{FitOptions, Weight};
use ptm_format::{Basis, Layout, Link, UvMap};
use ptm_runtime::Blur;

/// A library enum the command line takes by the names the library gives its values (and
/// writes in file headers and `--json`): one parser for all of them, no copy of the enum here.
pub trait Choice: Copy + Send + Sync + 'static {
    /// Every value, in the order `--help` lists them.
    fn all() -> &'static [Self];
    /// The value's name, as the library spells it.
    fn name(self) -> &'static str;
    /// What the value means, for `--help` (none: the flag's own help says it).
    fn help(self) -> Option<&'static str> {
        None
    }
}

/// The value parser of a [`Choice`]: accepts exactly the names of [`Choice::all`], lists them
/// (with their help) in `--help`, and refuses anything else with clap's usual message.
pub fn choice<T: Choice>() -> impl TypedValueParser<Value = T> {
    let values = T::all().iter().map(|&v| {
        let value = PossibleValue::new(v.name());
        match v.help() {
            Some(help) => value.help(help),
            None => value,
        }
    });
    PossibleValuesParser::new(values).map(|name: String| {
        *T::all()
            .iter()
            .find(|v| v.name() == name)
            .expect("clap accepts only the names of `all`")
    })
}

impl Choice for Basis {
    fn all() -> &'static [Self] {
        &Basis::ALL
    }
    fn name(self) -> &'static str {
        Basis::name(self)
    }
}

/// `--basis` / `--fit`: `ptm6`, `ptm11`, or `learnedN` (N terms, 1 ..= 16; the fitter learns
/// 6 or 11 and says so for other N).
pub fn parse_basis(s: &str) -> Result<Basis, String> {
    Basis::from_name(s).ok_or_else(|| {
        format!(
            "`{s}` is not a basis: ptm6, ptm11, learned6, learned11 (or learnedN, N terms in \
             1..={})",
            ptm_format::basis::MAX_LEARNED_TERMS
        )
    })
}

impl Choice for ptm_gpubake::Asked {
    fn all() -> &'static [Self] {
        &ptm_gpubake::Asked::ALL
    }
    fn name(self) -> &'static str {
        ptm_gpubake::Asked::name(self)
    }
    fn help(self) -> Option<&'static str> {
        use ptm_gpubake::Asked;
        Some(match self {
            Asked::Cpu => "Embree on the CPU's cores",
            Asked::Gpu => {
                "wgpu ray queries on a GPU adapter that has them (lavapipe's software ones too)"
            }
            Asked::Auto => "a GPU with hardware ray queries if there is one, else the CPU",
        })
    }
}

impl Choice for Link {
    fn all() -> &'static [Self] {
        &Link::ALL
    }
    fn name(self) -> &'static str {
        Link::name(self)
    }
    fn help(self) -> Option<&'static str> {
        Some(match self {
            Link::Identity => "K = p(u, v): the patent's PTM, least squares",
            Link::Logistic => {
                "K = 1/(1 + e^−p(u, v)), maximum likelihood: follows cloth's step-like shadows"
            }
        })
    }
}

impl Choice for UvMap {
    fn all() -> &'static [Self] {
        &UvMap::ALL
    }
    fn name(self) -> &'static str {
        UvMap::name(self)
    }
    fn help(self) -> Option<&'static str> {
        Some(match self {
            UvMap::Projected => "(u, v) = (l·T, l·B), the patent's and HP's projection",
            UvMap::Hemispherical => {
                "(u, v) = (θ/(π/2))·(cos φ, sin φ): equal steps of elevation are equal steps of \
                 (u, v)"
            }
        })
    }
}

impl Choice for Weight {
    fn all() -> &'static [Self] {
        // ptm-fit lists no `Weight::ALL`: a variant added there fails this match until it is
        // listed here too.
        const _: fn(Weight) = |w| match w {
            Weight::Uniform | Weight::Cosine => {}
        };
        &[Weight::Uniform, Weight::Cosine]
    }
    fn name(self) -> &'static str {
        Weight::name(self)
    }
    fn help(self) -> Option<&'static str> {
        Some(match self {
            Weight::Uniform => "Every light counts the same",
            Weight::Cosine => {
                "Weight sin(elevation): errors at grazing lights, which carry less light, count \
                 less"
            }
        })
    }
}

impl Choice for Layout {
    fn all() -> &'static [Self] {
        &Layout::ALL
    }
    fn name(self) -> &'static str {
        Layout::name(self)
    }
}

impl Choice for Blur {
    fn all() -> &'static [Self] {
        &Blur::ALL
    }
    fn name(self) -> &'static str {
        Blur::name(self)
    }
    fn help(self) -> Option<&'static str> {
        Some(match self {
            Blur::Explicit => {
                "Reference: a grid of samples over the penumbra disk (cost grows with the radius²)"
            }
            Blur::Sat => {
                "Summed-area table of u32 opacity counts, built on the GPU (constant cost)"
            }
            Blur::Mip => {
                "Trilinear lookup in the caster's MIP chain (constant cost, coarser kernel)"
            }
            Blur::Separable => {
                "Per-light horizontal then vertical running-sum box passes over the caster"
            }
        })
    }
}

/// The model and solver flags shared by `ptm fit` and `ptm bake --fit`.
#[derive(clap::Args, Clone, Debug)]
pub struct ModelArgs {
    /// Link from polynomial to K. The default measured best on every built-in swatch
    /// (docs/model.md, "What accuracy costs"); `--link identity --uv projected` is the patent's
    /// PTM, fitted by least squares.
    #[arg(long, value_parser = choice::<Link>(), default_value = "logistic")]
    pub link: Link,
    /// Map from light direction to (u, v).
    #[arg(long, value_parser = choice::<UvMap>(), default_value = "hemispherical")]
    pub uv: UvMap,
    /// Logistic link: Newton stops when the decrement falls below TOL per unit light weight.
    #[arg(long, value_name = "TOL", default_value_t = ptm_fit::logistic::DEFAULT_TOLERANCE)]
    pub tolerance: f64,
    /// Logistic link: at most N Newton iterations per texel (texels that hit it are counted).
    #[arg(long, value_name = "N", default_value_t = ptm_fit::logistic::DEFAULT_MAX_ITERATIONS)]
    pub max_iterations: u32,
    /// Write no MIP levels (a plain scanline file; renderers then average coefficients, which
    /// is exact only for the identity link).
    #[arg(long)]
    pub no_mips: bool,
}

impl ModelArgs {
    /// Fills the model fields of `opts`.
    pub fn apply(&self, opts: &mut FitOptions) {
        opts.link = self.link;
        opts.uv = self.uv;
        opts.tolerance = self.tolerance;
        opts.max_iterations = self.max_iterations;
        opts.mips = !self.no_mips;
    }
}

/// The most `--threads` a bake starts: more only costs thread start-up and memory (each
/// thread holds Embree and rayon state), never speed.
pub const MAX_THREADS: usize = 1024;

/// `--threads N`: 0 (one per core) up to [`MAX_THREADS`].
pub fn parse_threads(s: &str) -> Result<usize, String> {
    let n: usize = s
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number of threads"))?;
    if n > MAX_THREADS {
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        return Err(format!(
            "at most {MAX_THREADS} threads (this machine has {cores} cores; 0 uses one per core)"
        ));
    }
    Ok(n)
}

/// Parses `R,G,B` (or any three comma-separated numbers) for clap.
pub fn parse_triple(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse()
                .map_err(|_| format!("`{p}` is not a number"))
        })
        .collect::<Result<_, _>>()?;
    v.try_into()
        .map_err(|_| format!("expected three comma-separated numbers, got `{s}`"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Line {
        #[arg(long, value_parser = choice::<Link>())]
        link: Link,
        #[arg(long, value_parser = choice::<Blur>())]
        blur: Option<Blur>,
    }

    #[test]
    fn a_choice_takes_the_library_names_and_refuses_others() {
        for link in Link::ALL {
            let l = Line::try_parse_from(["t", "--link", link.name()]).unwrap();
            assert_eq!(l.link, link);
        }
        for blur in Blur::ALL {
            let l = Line::try_parse_from(["t", "--link", "identity", "--blur", blur.name()]);
            assert_eq!(l.unwrap().blur, Some(blur));
        }
        let e = Line::try_parse_from(["t", "--link", "Identity"])
            .err()
            .unwrap();
        let text = e.to_string();
        assert!(
            text.contains("invalid value 'Identity'")
                && text.contains("[possible values: identity, logistic]"),
            "{text}"
        );
    }

    #[test]
    fn every_choice_lists_each_variant_once() {
        fn distinct<T: Choice>() {
            let names: Vec<_> = T::all().iter().map(|v| v.name()).collect();
            let mut sorted = names.clone();
            sorted.sort();
            sorted.dedup();
            assert_eq!(sorted.len(), names.len(), "{names:?}");
        }
        distinct::<Basis>();
        distinct::<Link>();
        distinct::<UvMap>();
        distinct::<Weight>();
        distinct::<Layout>();
        distinct::<Blur>();
    }
}
