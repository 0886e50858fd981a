//! Weave drafts: WIF 1.1 files and plain 0/1 interlacement grids, to a [`Pattern`].

use std::path::Path;

use crate::weave::Pattern;
use crate::{Error, Result};

/// Reads a draft file (not implemented yet).
pub fn read(path: &Path) -> Result<Pattern> {
    Err(Error::Invalid(format!(
        "{}: drafts are not implemented yet",
        path.display()
    )))
}

/// Parses a 0/1 grid (not implemented yet).
pub fn parse_grid(_text: &str, name: &str) -> Result<Pattern> {
    Err(Error::Invalid(format!(
        "{name}: grids are not implemented yet"
    )))
}
