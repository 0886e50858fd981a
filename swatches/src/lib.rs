//! `ptm-swatches`: procedural, exactly tileable cloth geometry and the triangle mesh type every
//! swatch is handed to the baker as.

pub mod mesh;

pub use mesh::Mesh;

/// Errors of the swatch crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{0}")]
    Invalid(String),
    #[error("unknown builtin swatch {name:?}; available: {available}")]
    UnknownSwatch { name: String, available: String },
}

pub type Result<T> = std::result::Result<T, Error>;

/// A builtin swatch by spec `NAME[?k=v&...]`, e.g. `plain-weave` or `twill?n=2&m=1`.
pub fn builtin(spec: &str) -> Result<Mesh> {
    let name = spec.split('?').next().unwrap_or("");
    Err(Error::UnknownSwatch {
        name: name.to_string(),
        available: String::new(),
    })
}
