//! The swatch spec syntax `NAME[?k=v&k=v...]` and typed, range-checked parameter look-ups.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};

use crate::{Error, Result};

/// Parameters of one swatch spec. Every look-up records the key, so [`Params::finish`] can
/// refuse keys no generator asked for (typos would otherwise be silently ignored).
#[derive(Debug)]
pub struct Params {
    swatch: String,
    values: BTreeMap<String, String>,
    asked: RefCell<BTreeSet<String>>,
}

/// Splits `NAME?k=v&...` into the name and its parameters.
pub fn parse_spec(spec: &str) -> Result<(String, Params)> {
    let (name, query) = match spec.split_once('?') {
        Some((n, q)) => (n.trim(), q),
        None => (spec.trim(), ""),
    };
    let mut values = BTreeMap::new();
    for part in query.split('&').filter(|p| !p.trim().is_empty()) {
        let Some((k, v)) = part.split_once('=') else {
            return Err(Error::BadSpec {
                spec: spec.to_string(),
                reason: format!("parameter `{part}` is not of the form key=value"),
            });
        };
        let k = k.trim().to_string();
        if values.insert(k.clone(), v.trim().to_string()).is_some() {
            return Err(Error::BadSpec {
                spec: spec.to_string(),
                reason: format!("parameter `{k}` is given twice"),
            });
        }
    }
    let params = Params {
        swatch: name.to_string(),
        values,
        asked: RefCell::default(),
    };
    Ok((name.to_string(), params))
}

impl Params {
    /// Parameters of `swatch` from `(key, value)` pairs (no spec string).
    pub fn from_pairs<'a>(
        swatch: &str,
        pairs: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Self {
        Params {
            swatch: swatch.to_string(),
            values: pairs
                .into_iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            asked: RefCell::default(),
        }
    }

    fn raw(&self, key: &str) -> Option<&str> {
        self.asked.borrow_mut().insert(key.to_string());
        self.values.get(key).map(String::as_str)
    }

    /// The error for `key = value` outside `allowed` (a human-readable range).
    pub fn invalid(&self, key: &str, value: impl ToString, allowed: impl ToString) -> Error {
        Error::InvalidParameter {
            swatch: self.swatch.clone(),
            name: key.to_string(),
            value: value.to_string(),
            allowed: allowed.to_string(),
        }
    }

    fn parse_real(&self, key: &str, default: f64, allowed: &str) -> Result<f64> {
        match self.raw(key) {
            None => Ok(default),
            Some(s) => s
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| self.invalid(key, s, allowed)),
        }
    }

    /// A real parameter in the closed range [lo, hi] (use ±inf for an open side).
    pub fn real(&self, key: &str, default: f64, lo: f64, hi: f64) -> Result<f64> {
        let allowed = match (lo.is_finite(), hi.is_finite()) {
            (true, true) => format!("a number in [{lo}, {hi}]"),
            (true, false) => format!("a number ≥ {lo}"),
            (false, true) => format!("a number ≤ {hi}"),
            (false, false) => "a number".to_string(),
        };
        let v = self.parse_real(key, default, &allowed)?;
        if v < lo || v > hi {
            return Err(self.invalid(key, v, allowed));
        }
        Ok(v)
    }

    /// A strictly positive real parameter at most `hi`.
    pub fn positive(&self, key: &str, default: f64, hi: f64) -> Result<f64> {
        let allowed = if hi.is_finite() {
            format!("a number in (0, {hi}]")
        } else {
            "a number > 0".to_string()
        };
        let v = self.parse_real(key, default, &allowed)?;
        if v <= 0.0 || v > hi {
            return Err(self.invalid(key, v, allowed));
        }
        Ok(v)
    }

    /// An integer parameter in [lo, hi].
    pub fn int(&self, key: &str, default: i64, lo: i64, hi: i64) -> Result<i64> {
        let allowed = format!("an integer in [{lo}, {hi}]");
        let v = match self.raw(key) {
            None => default,
            Some(s) => s
                .parse::<i64>()
                .map_err(|_| self.invalid(key, s, &allowed))?,
        };
        if v < lo || v > hi {
            return Err(self.invalid(key, v, allowed));
        }
        Ok(v)
    }

    /// A word parameter from a fixed list.
    pub fn choice<'a>(&self, key: &str, default: &'a str, options: &[&'a str]) -> Result<&'a str> {
        match self.raw(key) {
            None => Ok(default),
            Some(s) => options
                .iter()
                .find(|o| o.eq_ignore_ascii_case(s))
                .copied()
                .ok_or_else(|| self.invalid(key, s, format!("one of {}", options.join(", ")))),
        }
    }

    /// A free text parameter (a path, an inline grid).
    pub fn text(&self, key: &str) -> Option<String> {
        self.raw(key).map(str::to_string)
    }

    /// Refuses parameters no look-up asked for, naming the ones that exist.
    pub fn finish(&self) -> Result<()> {
        let asked = self.asked.borrow();
        if let Some(k) = self.values.keys().find(|k| !asked.contains(*k)) {
            return Err(Error::UnknownParameter {
                swatch: self.swatch.clone(),
                name: k.clone(),
                known: asked.iter().cloned().collect::<Vec<_>>().join(", "),
            });
        }
        Ok(())
    }
}
