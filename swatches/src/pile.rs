//! Pile and grooves (not implemented yet).

use crate::params::Params;
use crate::yarn::Cloth;
use crate::{Error, Result};

pub fn from_params(name: &str, _p: &Params) -> Result<(Cloth, usize)> {
    Err(Error::Invalid(format!("{name}: not implemented yet")))
}

pub fn corduroy(_p: &Params) -> Result<(Cloth, usize)> {
    Err(Error::Invalid("corduroy: not implemented yet".into()))
}
