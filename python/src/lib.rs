//! `ptm`, the Python module for pipelines (pyo3 over `ptm-format`): load an occlusion PTM in
//! either layout, read its coefficients, coverage and header as numpy arrays and Python values,
//! evaluate K for many lights at once (the loop in Rust, without the GIL), build one from
//! arrays and save it. It takes the crate a pipeline takes, `ptm-format`, and nothing of the
//! fitter (no solver, no thread pool).
//!
//! Evaluation is `Ptm::eval` / `Ptm::eval_dir` of `ptm-format` reorganised for many lights:
//! per light the (u, v) map and the powers uᵃ, vᵇ once, then per texel the same f32 sum in the
//! same order (k = k + c·uᵃ·vᵇ, basis order), link and clamp, so the results are those of the
//! Rust functions to the bit.
use std::path::{Path, PathBuf};

use exr::meta::attribute::{AttributeValue, Text};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    AllowTypeChange, IntoPyArray, PyArray2, PyArray3, PyArrayLike2, PyArrayLike3, PyArrayLikeDyn,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};

use ptm_format::basis::num_like::Float;
use ptm_format::exrio::decode_text;
use ptm_format::layout::{self, Layout, PtmFile};
use ptm_format::ptm::mip_sizes;
use ptm_format::{Basis, Level, Link, Ptm, SaveOptions, UvMap};

/// The Python exception of a `ptm-format` error: `OSError` (its errno subclass, e.g.
/// `FileNotFoundError`, with `filename` set) for I/O, `ValueError` for a file that is not a
/// PTM or arguments that make none. The message names the file, as the Rust error does.
fn py_err(e: ptm_format::Error) -> PyErr {
    match e {
        ptm_format::Error::Io { path, source } => {
            let errno = source.raw_os_error().or(match source.kind() {
                std::io::ErrorKind::NotFound => Some(2),
                std::io::ErrorKind::PermissionDenied => Some(13),
                std::io::ErrorKind::AlreadyExists => Some(17),
                _ => None,
            });
            match errno {
                // OSError(errno, strerror, filename) becomes the errno's subclass and prints
                // as "[Errno 2] no such file …: 'w.ptm.exr'".
                Some(n) => {
                    let msg = source.to_string();
                    let msg = msg
                        .strip_suffix(&format!(" (os error {n})"))
                        .unwrap_or(&msg)
                        .to_string();
                    PyOSError::new_err((n, msg, path))
                }
                None => PyOSError::new_err(format!("{path}: {source}")),
            }
        }
        e => PyValueError::new_err(e.to_string()),
    }
}

fn value_err(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

/// The layout a `layout=` argument names, by the CLI's `--layout` names: `"channels"` (one
/// EXR, a channel per coefficient) or `"rgba"`. The old `"single"` is refused naming its new
/// name, so a script that says it learns the name instead of a default.
fn layout_of(name: &str) -> PyResult<Layout> {
    match name {
        "channels" => Ok(Layout::Channels),
        "rgba" => Ok(Layout::Rgba),
        "single" => Err(value_err(
            "layout \"single\" is now called \"channels\", as the CLI's --layout names it \
             (one EXR, a channel per coefficient); pass layout=\"channels\"",
        )),
        _ => Err(value_err(format!(
            "unknown layout {name:?} (this version writes \"channels\" and \"rgba\")"
        ))),
    }
}

fn layout_name(layout: Layout) -> &'static str {
    match layout {
        Layout::Channels => "channels",
        Layout::Rgba => "rgba",
    }
}

/// A header attribute as a Python value: text as `str`, numbers as `int` / `float`, text lists
/// and vectors as tuples; anything else in words (its Rust debug form).
fn attr_value<'py>(py: Python<'py>, v: &AttributeValue) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        AttributeValue::Text(t) => decode_text(t).into_pyobject(py)?.into_any(),
        AttributeValue::TextVector(ts) => PyTuple::new(py, ts.iter().map(decode_text))?.into_any(),
        AttributeValue::I32(x) => x.into_pyobject(py)?.into_any(),
        AttributeValue::F32(x) => (*x as f64).into_pyobject(py)?.into_any(),
        AttributeValue::F64(x) => x.into_pyobject(py)?.into_any(),
        AttributeValue::IntVec2(v) => (v.0, v.1).into_pyobject(py)?.into_any(),
        AttributeValue::FloatVec2(v) => (v.0 as f64, v.1 as f64).into_pyobject(py)?.into_any(),
        AttributeValue::IntVec3(v) => v.into_pyobject(py)?.into_any(),
        AttributeValue::FloatVec3(v) => (v.0 as f64, v.1 as f64, v.2 as f64)
            .into_pyobject(py)?
            .into_any(),
        AttributeValue::Rational(r) => (r.0, r.1).into_pyobject(py)?.into_any(),
        AttributeValue::Bytes { bytes, .. } => PyBytes::new(py, bytes).into_any(),
        other => format!("{other:?}").into_pyobject(py)?.into_any(),
    })
}

fn basis_of(name: &str) -> PyResult<Basis> {
    Basis::from_name(name).ok_or_else(|| {
        value_err(format!(
            "unknown basis {name:?} (this version reads {})",
            Basis::ALL.map(|b| b.name()).join(", ")
        ))
    })
}

fn link_of(name: &str) -> PyResult<Link> {
    Link::from_name(name).ok_or_else(|| {
        value_err(format!(
            "unknown link {name:?} (this version reads {})",
            Link::ALL.map(|l| l.name()).join(", ")
        ))
    })
}

fn uv_of(name: &str) -> PyResult<UvMap> {
    UvMap::from_name(name).ok_or_else(|| {
        value_err(format!(
            "unknown (u, v) map {name:?} (this version reads {})",
            UvMap::ALL.map(|m| m.name()).join(", ")
        ))
    })
}

/// Coefficient planes of a (terms, height, width) array, row-major, in the array's logical order.
fn planes_of(a: &PyArrayLike3<'_, f32, AllowTypeChange>) -> Vec<Vec<f32>> {
    let a = a.as_array();
    a.outer_iter()
        .map(|plane| plane.iter().copied().collect())
        .collect()
}

/// (terms, height, width) float32 array of planes.
fn planes_array<'py>(
    py: Python<'py>,
    planes: &[Vec<f32>],
    width: usize,
    height: usize,
) -> Bound<'py, PyArray3<f32>> {
    let flat: Vec<f32> = planes.iter().flatten().copied().collect();
    Array3::from_shape_vec((planes.len(), height, width), flat)
        .expect("planes of width × height texels")
        .into_pyarray(py)
}

/// Texels per block of the evaluation loop: every plane's block (11 × 2 KB for ptm11) stays in
/// L1 while all lights pass over it.
const BLOCK: usize = 512;

/// One light of an evaluation: its (u, v) after the PTM's map, or below the horizon (K = 1).
#[derive(Clone, Copy)]
enum Light {
    Uv(f32, f32),
    Below,
}

/// The polynomial of one light over a block of texels: k[i] = Σₜ cₜ[i]·aₜ·bₜ (aₜ = uᵖ, bₜ = vᵠ
/// of term t) summed from 0 in basis order, `Basis::eval`'s operations exactly; N terms
/// unrolled so the texels vectorise and the sum stays in registers.
fn poly_block<const N: usize>(planes: &[&[f32]], ab: &[(f32, f32)], k: &mut [f32]) {
    let planes: [&[f32]; N] = std::array::from_fn(|t| &planes[t][..k.len()]);
    let ab: [(f32, f32); N] = std::array::from_fn(|t| ab[t]);
    for (i, k) in k.iter_mut().enumerate() {
        let mut acc = 0f32;
        for t in 0..N {
            acc += planes[t][i] * ab[t].0 * ab[t].1;
        }
        *k = acc;
    }
}

/// [`poly_block`] for any number of terms (a basis this module does not unroll).
fn poly_block_any(planes: &[&[f32]], ab: &[(f32, f32)], k: &mut [f32]) {
    k.fill(0.0);
    for (plane, &(a, b)) in planes.iter().zip(ab) {
        for (k, &c) in k.iter_mut().zip(*plane) {
            *k += c * a * b;
        }
    }
}

/// K of every texel for each light into `out` (light-major, `lights.len()` planes of
/// width × height): `Ptm::eval`'s sum, link and clamp, texel block by texel block.
fn eval_into(ptm: &Ptm, lights: &[Light], out: &mut [f32]) {
    let n = ptm.width * ptm.height;
    let monomials = ptm.basis.monomials();
    // Per light, the powers of each term, as `Basis::eval` computes them; a learned basis's
    // terms are its table read at (u, v) (times 1), as `Ptm::eval` reads it.
    let powers: Vec<Option<Vec<(f32, f32)>>> = lights
        .iter()
        .map(|l| match *l {
            Light::Uv(u, v) => Some(match &ptm.learned {
                Some(t) => {
                    let mut b = vec![0f64; t.terms];
                    t.terms(u as f64, v as f64, &mut b);
                    b.into_iter().map(|x| (x as f32, 1.0)).collect()
                }
                None => monomials
                    .iter()
                    .map(|m| (<f32 as Float>::powi(u, m.pu), <f32 as Float>::powi(v, m.pv)))
                    .collect(),
            }),
            Light::Below => None,
        })
        .collect();
    let poly = match monomials.len() {
        6 => poly_block::<6>,
        11 => poly_block::<11>,
        _ => poly_block_any,
    };
    for start in (0..n).step_by(BLOCK) {
        let end = (start + BLOCK).min(n);
        let planes: Vec<&[f32]> = ptm.planes.iter().map(|p| &p[start..end]).collect();
        for (li, pw) in powers.iter().enumerate() {
            let k = &mut out[li * n + start..li * n + end];
            match pw {
                None => k.fill(1.0),
                Some(pw) => {
                    poly(&planes, pw, k);
                    match ptm.link {
                        Link::Identity => k.iter_mut().for_each(|k| *k = k.clamp(0.0, 1.0)),
                        link => k
                            .iter_mut()
                            .for_each(|k| *k = link.apply(*k).clamp(0.0, 1.0)),
                    }
                }
            }
        }
    }
}

/// An array argument as a flat f32/f64 list with its shape.
fn flat<T: numpy::Element + Copy>(
    a: &PyArrayLikeDyn<'_, T, AllowTypeChange>,
) -> (Vec<T>, Vec<usize>) {
    let view = a.as_array();
    (view.iter().copied().collect(), view.shape().to_vec())
}

/// An occlusion PTM: per texel the coefficients of K = link(p(u, v)) in a polynomial basis.
///
/// Load one with `ptm.load(path)`, or build one from arrays:
/// `Ptm(basis, coefficients, tile=(1.0, 1.0), link="identity", uv="projected", coverage=None,
/// mips=None)`, where `coefficients` has shape (terms, height, width) in the order of
/// `monomials`, `coverage` shape (height, width) with values in [0, 1] (0 = a hole), and `mips`
/// a list of (terms, h, w) arrays for MIP levels 1, 2, … down to 1×1 (sides halved, rounded
/// down). Row 0 is the far edge y = H of the tile, column 0 is x = 0 (docs/FORMAT.md).
#[pyclass(name = "Ptm", module = "ptm", frozen)]
struct PyPtm {
    ptm: Ptm,
    /// Every map and header attribute as loaded (saved back verbatim), the coefficient maps
    /// without their levels (they are `ptm`'s planes and MIP levels, held once); `None` for a
    /// PTM built from arrays, whose file is what `Ptm::save` writes.
    file: Option<PtmFile>,
    /// The layout it was loaded from.
    layout: Option<Layout>,
}

#[pymethods]
impl PyPtm {
    #[new]
    // Text arguments are `String`s: the stable ABI of CPython 3.9 (abi3-py39) cannot lend a
    // `&str` of a Python string (PyUnicode_AsUTF8AndSize joined it in 3.10).
    #[pyo3(signature = (basis, coefficients, tile = (1.0, 1.0), link = "identity".into(), uv = "projected".into(), coverage = None, mips = None))]
    fn new(
        basis: String,
        coefficients: PyArrayLike3<'_, f32, AllowTypeChange>,
        tile: (f64, f64),
        link: String,
        uv: String,
        coverage: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        mips: Option<Vec<PyArrayLike3<'_, f32, AllowTypeChange>>>,
    ) -> PyResult<PyPtm> {
        let basis = basis_of(&basis)?;
        let shape = coefficients.shape().to_vec();
        let (terms, height, width) = (shape[0], shape[1], shape[2]);
        if terms != basis.len() {
            return Err(value_err(format!(
                "coefficients have shape {shape:?}; {} needs ({}, height, width), one plane per term of {:?}",
                basis.name(),
                basis.len(),
                basis.monomials().iter().map(|m| m.name).collect::<Vec<_>>()
            )));
        }
        let coverage = match coverage {
            None => None,
            Some(c) => {
                if c.shape() != [height, width] {
                    return Err(value_err(format!(
                        "coverage has shape {:?}, not the coefficients' (height, width) = ({height}, {width})",
                        c.shape()
                    )));
                }
                Some(c.as_array().iter().copied().collect())
            }
        };
        let sizes = mip_sizes(width, height);
        let mips = mips.unwrap_or_default();
        let chain: Vec<[usize; 3]> = sizes.iter().map(|&(w, h)| [terms, h, w]).collect();
        if !mips.is_empty()
            && (mips.len() != chain.len() || mips.iter().zip(&chain).any(|(m, c)| m.shape() != c))
        {
            return Err(value_err(format!(
                "MIP levels have shapes {:?}; a {width}×{height} PTM's chain to 1×1 (sides halved, rounded down) is {chain:?}",
                mips.iter().map(|m| m.shape().to_vec()).collect::<Vec<_>>()
            )));
        }
        let mips = mips
            .iter()
            .zip(&sizes)
            .map(|(m, &(w, h))| Level {
                width: w,
                height: h,
                planes: planes_of(m),
            })
            .collect();
        let ptm = Ptm {
            basis,
            link: link_of(&link)?,
            uv: uv_of(&uv)?,
            width,
            height,
            tile: [tile.0, tile.1],
            planes: planes_of(&coefficients),
            mips,
            coverage,
            learned: None,
        };
        ptm.validate().map_err(py_err)?;
        Ok(PyPtm {
            ptm,
            file: None,
            layout: None,
        })
    }

    /// The basis: "ptm6" (u², u, uv, v, v², 1) or "ptm11".
    #[getter]
    fn basis(&self) -> &'static str {
        self.ptm.basis.name()
    }

    /// The link: "identity" (K = p(u, v)) or "logistic" (K = 1 / (1 + exp(−p))).
    #[getter]
    fn link(&self) -> &'static str {
        self.ptm.link.name()
    }

    /// The (u, v) map: "projected" ((l·X, l·Y)) or "hemispherical" (θ/(π/2)·(cos φ, sin φ)).
    #[getter]
    fn uv(&self) -> &'static str {
        self.ptm.uv.name()
    }

    /// Texels per row.
    #[getter]
    fn width(&self) -> usize {
        self.ptm.width
    }

    /// Rows (row 0 is the far edge y = H of the tile).
    #[getter]
    fn height(&self) -> usize {
        self.ptm.height
    }

    /// Tile size (W, H) in swatch units.
    #[getter]
    fn tile(&self) -> (f64, f64) {
        (self.ptm.tile[0], self.ptm.tile[1])
    }

    /// Names of the basis terms in coefficient order, e.g. ("u2", "u", "uv", "v", "v2", "1").
    #[getter]
    fn monomials(&self) -> Vec<&'static str> {
        self.ptm.basis.monomials().iter().map(|m| m.name).collect()
    }

    /// The coefficients, float32 of shape (terms, height, width) in `monomials` order (a copy).
    #[getter]
    fn coefficients<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        planes_array(py, &self.ptm.planes, self.ptm.width, self.ptm.height)
    }

    /// Per-texel coverage, float32 (height, width) (0 = a hole: no cloth, K means nothing), or
    /// None when every texel is fully covered.
    #[getter]
    fn coverage<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f32>>> {
        self.ptm.coverage.as_ref().map(|c| {
            Array2::from_shape_vec((self.ptm.height, self.ptm.width), c.clone())
                .expect("coverage of width × height texels")
                .into_pyarray(py)
        })
    }

    /// The fitted MIP levels 1, 2, … down to 1×1 as (terms, h, w) float32 arrays; empty when the
    /// file has none.
    #[getter]
    fn mips<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray3<f32>>> {
        self.ptm
            .mips
            .iter()
            .map(|l| planes_array(py, &l.planes, l.width, l.height))
            .collect()
    }

    /// Every header attribute of the file (`ptm:basis`, `ptm:nLights`, `ptm:rmsMean`, …) as
    /// str, int, float or tuple; for a PTM built from arrays, those `save` writes. The renderer
    /// layout's own part attributes (`ptm:layout`, `ptm:part`, …) are not the PTM's and are left
    /// out, so both layouts of one PTM have the same metadata.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let built;
        let attrs = match &self.file {
            Some(f) => &f.attrs,
            None => {
                built = PtmFile::from_ptm(&self.ptm, Path::new("<Ptm>"), &SaveOptions::default())
                    .map_err(py_err)?;
                &built.attrs
            }
        };
        let d = PyDict::new(py);
        for (k, v) in attrs {
            d.set_item(k, attr_value(py, v)?)?;
        }
        Ok(d)
    }

    /// The layout the PTM was loaded from, "channels" or "rgba"; None when built from arrays.
    #[getter]
    fn layout(&self) -> Option<&'static str> {
        self.layout.map(layout_name)
    }

    /// K, the occluded fraction (0 = lit, 1 = occluded), of every texel for lights whose
    /// projected direction is (lx, ly) = (l·T, l·B), l the unit vector towards the light in the
    /// upper hemisphere (T = +X, B = +Y of the swatch). These are not the polynomial's (u, v):
    /// the file's (u, v) map (`uv`, e.g. hemispherical) and link are applied here, and K is
    /// clamped to [0, 1], as `Ptm::eval` does.
    ///
    /// lx, ly: numbers → float32 array (height, width); 1-D arrays of N lights (or one of them a
    /// number) → (N, height, width). One thread, without the GIL: Python threads evaluate in
    /// parallel.
    fn eval_xy<'py>(
        &self,
        py: Python<'py>,
        lx: PyArrayLikeDyn<'py, f32, AllowTypeChange>,
        ly: PyArrayLikeDyn<'py, f32, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let ((us, ushape), (vs, vshape)) = (flat(&lx), flat(&ly));
        if ushape.len() > 1 || vshape.len() > 1 {
            return Err(value_err(format!(
                "lx and ly are numbers or 1-D arrays of lights, not arrays of shape {ushape:?} and {vshape:?}"
            )));
        }
        let scalar = ushape.is_empty() && vshape.is_empty();
        // A number stands for every light of the other argument.
        let count = match (ushape.is_empty(), vshape.is_empty()) {
            (true, _) => vs.len(),
            (_, true) => us.len(),
            _ if us.len() == vs.len() => us.len(),
            _ => {
                return Err(value_err(format!(
                    "lx has {} lights but ly has {}",
                    us.len(),
                    vs.len()
                )))
            }
        };
        let at = |xs: &[f32], number: bool, i: usize| if number { xs[0] } else { xs[i] };
        let uvmap = self.ptm.uv;
        let lights: Vec<Light> = (0..count)
            .map(|i| {
                let (mu, mv) = uvmap
                    .of_projected(at(&us, ushape.is_empty(), i), at(&vs, vshape.is_empty(), i));
                Light::Uv(mu, mv)
            })
            .collect();
        self.evaluate(py, &lights, scalar)
    }

    /// Deprecated: `eval_xy(lx, ly)`, under its old name, whose arguments read like the file's
    /// (u, v) but are the projected direction (l·T, l·B). Warns (FutureWarning, shown by
    /// default) on every call site, then evaluates as `eval_xy`.
    fn eval<'py>(
        &self,
        py: Python<'py>,
        u: PyArrayLikeDyn<'py, f32, AllowTypeChange>,
        v: PyArrayLikeDyn<'py, f32, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let category = py.get_type::<pyo3::exceptions::PyFutureWarning>();
        PyErr::warn(
            py,
            category.as_any(),
            c"Ptm.eval(u, v) is deprecated and will be removed: its arguments are the projected \
              light direction (lx, ly) = (l.T, l.B), not the file's (u, v) map of it; call \
              Ptm.eval_xy(lx, ly) (or eval_dir(l))",
            1,
        )?;
        self.eval_xy(py, u, v)
    }

    /// K of every texel for unit directions l towards the light (swatch frame: x along the
    /// tangent, y the bitangent, z the normal), clamped to [0, 1], as `Ptm::eval_dir` does:
    /// lights at or below the horizon (l_z ≤ 0) are fully occluded, K = 1. l is not normalised.
    ///
    /// l: shape (3,) → float32 array (height, width); (N, 3) → (N, height, width). One thread,
    /// without the GIL.
    fn eval_dir<'py>(
        &self,
        py: Python<'py>,
        l: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (ls, shape) = flat(&l);
        let scalar = match shape.as_slice() {
            [3] => true,
            [_, 3] => false,
            _ => {
                return Err(value_err(format!(
                "l has shape {shape:?}; eval_dir takes one direction (3,) or N directions (N, 3)"
            )))
            }
        };
        let uvmap = self.ptm.uv;
        let lights: Vec<Light> = ls
            .chunks_exact(3)
            .map(|d| {
                if d[2] <= 0.0 {
                    Light::Below
                } else {
                    let (u, v) = uvmap.of_dir([d[0], d[1], d[2]]);
                    Light::Uv(u as f32, v as f32)
                }
            })
            .collect();
        self.evaluate(py, &lights, scalar)
    }

    /// Writes the PTM to `path` and returns the files written: layout "channels" (one EXR, one
    /// channel per coefficient; the CLI's name, "single" before) or "rgba" (the renderer layout: `path`
    /// `w.ptm.exr` writes `w.ptm.c0.exr`, `w.ptm.c1.exr`, …). half=True stores half floats
    /// (ValueError if a coefficient does not fit). A loaded PTM keeps every map (MIP levels,
    /// coverage, error maps) and header attribute of its file; all files are written or none.
    #[pyo3(signature = (path, half = false, layout = "channels".into()))]
    fn save(
        &self,
        py: Python<'_>,
        path: PathBuf,
        half: bool,
        layout: String,
    ) -> PyResult<Vec<String>> {
        let layout = layout_of(&layout)?;
        let written = py
            .detach(|| match &self.file {
                None => {
                    let opts = SaveOptions {
                        half,
                        ..SaveOptions::default()
                    };
                    layout::save(&self.ptm, &path, &opts, layout)
                }
                Some(file) => with_storage(file, &self.ptm, &path, half)?.save(&path, layout),
            })
            .map_err(py_err)?;
        Ok(written
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect())
    }

    fn __repr__(&self) -> String {
        let p = &self.ptm;
        format!(
            "<ptm.Ptm {} {} {} {}×{}, {} MIP levels{}>",
            p.basis.name(),
            p.link.name(),
            p.uv.name(),
            p.width,
            p.height,
            p.mips.len(),
            if p.coverage.is_some() {
                ", coverage"
            } else {
                ""
            }
        )
    }
}

impl PyPtm {
    /// K for `lights`, computed without the GIL: (height, width) when `scalar`, else
    /// (lights, height, width).
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        lights: &[Light],
        scalar: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (w, h) = (self.ptm.width, self.ptm.height);
        let out = py.detach(|| {
            let mut out = vec![0f32; lights.len() * w * h];
            eval_into(&self.ptm, lights, &mut out);
            out
        });
        Ok(if scalar {
            Array2::from_shape_vec((h, w), out)
                .expect("one plane")
                .into_pyarray(py)
                .into_any()
        } else {
            Array3::from_shape_vec((lights.len(), h, w), out)
                .expect("one plane per light")
                .into_pyarray(py)
                .into_any()
        })
    }
}

/// The name of coefficient `j`'s map in a [`PtmFile`] (`ptm.u2`, …).
fn coefficient_map(ptm: &Ptm, j: usize) -> String {
    format!("ptm.{}", ptm.basis.monomials()[j].name)
}

/// `file` with its coefficient maps' levels moved out: `ptm` (made from it) holds them.
fn without_coefficients(mut file: PtmFile, ptm: &Ptm) -> PtmFile {
    for j in 0..ptm.basis.len() {
        if let Some(m) = file.maps.get_mut(&coefficient_map(ptm, j)) {
            m.levels = Vec::new();
        }
    }
    file
}

/// `file` (as [`without_coefficients`] left it) with `ptm`'s planes and MIP levels back in its
/// coefficient maps, stored as half floats or float32 (every map, and `ptm:storage`, as
/// `Ptm::save` does); a coefficient a half float cannot hold is an error naming `path`.
fn with_storage(file: &PtmFile, ptm: &Ptm, path: &Path, half: bool) -> ptm_format::Result<PtmFile> {
    let mut file = file.clone();
    for j in 0..ptm.basis.len() {
        if let Some(m) = file.maps.get_mut(&coefficient_map(ptm, j)) {
            m.levels = std::iter::once(&ptm.planes[j])
                .chain(ptm.mips.iter().map(|l| &l.planes[j]))
                .cloned()
                .collect();
        }
    }
    if half {
        let big = file
            .maps
            .iter()
            .filter(|(k, _)| k.starts_with("ptm."))
            .flat_map(|(_, m)| m.levels.iter().flatten())
            .fold(0f32, |a, &x| a.max(x.abs()));
        if big.is_nan() || big >= 65504.0 {
            return Err(ptm_format::Error::HalfOverflow {
                path: path.display().to_string(),
                magnitude: big,
            });
        }
    }
    for m in file.maps.values_mut() {
        m.half = half;
    }
    let storage = if half { "half" } else { "float32" };
    file.attrs.insert(
        "ptm:storage".into(),
        AttributeValue::Text(Text::from(storage)),
    );
    Ok(file)
}

/// Loads an occlusion PTM from `path`: the single-file PTM EXR, or the renderer layout named by
/// any of its parts (`w.ptm.c0.exr`) or by its stem (`w.ptm.exr` when only the parts exist).
/// Raises FileNotFoundError / OSError when it cannot be read, ValueError when it is not a PTM
/// (or a part of the renderer layout is missing or disagrees); the message names the file.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<PyPtm> {
    let (file, layout) = py
        .detach(|| -> ptm_format::Result<_> {
            let (file, layout) = PtmFile::load(&path)?;
            let ptm = file.to_ptm(&path)?;
            Ok(((file, ptm), layout))
        })
        .map_err(py_err)?;
    let (file, ptm) = file;
    Ok(PyPtm {
        file: Some(without_coefficients(file, &ptm)),
        ptm,
        layout: Some(layout),
    })
}

/// Occlusion polynomial texture maps (occlusion PTMs) for pipelines.
///
/// `ptm.load(path)` reads a PTM (the single-file PTM EXR or the renderer layout's RGB(A)
/// parts) into a `ptm.Ptm`: `basis`, `link`, `uv`, `width`, `height`, `tile`, `monomials`,
/// `coefficients` (numpy float32, (terms, height, width)), `coverage`, `mips`, `metadata`.
/// `Ptm.eval_xy(lx, ly)` (the projected light direction (l·T, l·B), whatever the file's (u, v)
/// map) and `Ptm.eval_dir(l)` give K, the occluded fraction of each texel, for one light or N at
/// once; `Ptm.save(path, half=False, layout="channels"|"rgba")` writes it, and
/// `ptm.Ptm(basis, coefficients, ...)` builds one from arrays. File format: docs/FORMAT.md.
#[pymodule(name = "ptm")]
fn ptm_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_class::<PyPtm>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
