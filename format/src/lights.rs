//! Light sets: unit directions towards distant lights, and the RTI `.lp` light-position file.
//!
//! `.lp` (HP PTM / RTI convention): first line N, then N lines `name x y z`, the vector pointing
//! from the swatch towards the light, x right (+X of the swatch), y up the image (+Y), z towards
//! the camera (+Z, the macro normal). Names may contain spaces (the last three tokens are the
//! vector, as relight's reader does). Vectors are normalised on read.
use std::path::Path;

use crate::vec3::normalize;
use crate::{Error, Result};

/// An ordered set of distant lights. Order is significant: the bake writes channel `K.0003` for
/// `dirs[3]`, and the fit's design matrix rows follow it.
#[derive(Clone, Debug, PartialEq)]
pub struct LightSet {
    /// One name per light (the `.lp` file-name column; `light0000` … when generated).
    pub names: Vec<String>,
    /// Unit vectors from the swatch towards each light, in the swatch frame (z up).
    pub dirs: Vec<[f64; 3]>,
}

/// A light of a [`LightSet`] at or below the swatch's horizon ([`LightSet::below_horizon`]).
/// Its `Display` is how every diagnostic names it: `light 3 "IMG_0003.png" at -17.46°`.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonLight {
    /// Its index in the light set (channel `K.0003` of a stack for index 3).
    pub index: usize,
    /// Its name (the `.lp` file-name column).
    pub name: String,
    /// Its elevation in degrees (≤ 0).
    pub elevation_deg: f64,
}

impl std::fmt::Display for HorizonLight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "light {} {:?} at {:.2}°",
            self.index, self.name, self.elevation_deg
        )
    }
}

/// The lights `lights` as a list in words: `light 3 "a" at -17.46°, light 5 "b" at 0.00°`, at
/// most `shown` of them, then "and N more".
pub fn horizon_words(lights: &[HorizonLight], shown: usize) -> String {
    let mut s = lights
        .iter()
        .take(shown)
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    if lights.len() > shown {
        s += &format!(" and {} more", lights.len() - shown);
    }
    s
}

impl LightSet {
    /// A light set from directions (normalised here), named `light0000`, `light0001`, ….
    pub fn from_dirs(dirs: impl IntoIterator<Item = [f64; 3]>) -> Self {
        let dirs: Vec<[f64; 3]> = dirs.into_iter().map(normalize).collect();
        let names = (0..dirs.len()).map(|i| format!("light{i:04}")).collect();
        Self { names, dirs }
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    /// Whether the set has no light.
    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }

    /// The lights at or below the horizon (z ≤ 0), in light order: a bake traces none of them
    /// (K = 1), a fit leaves them out, and a photographed stack refuses them.
    pub fn below_horizon(&self) -> Vec<HorizonLight> {
        (0..self.len())
            .filter(|&i| self.dirs[i][2] <= 0.0)
            .map(|i| HorizonLight {
                index: i,
                name: self.names[i].clone(),
                elevation_deg: self.elevation_deg(i),
            })
            .collect()
    }

    /// Elevation of light `i` above the swatch plane, in degrees.
    pub fn elevation_deg(&self, i: usize) -> f64 {
        self.dirs[i][2].clamp(-1.0, 1.0).asin().to_degrees()
    }

    /// Parses `.lp` text; `origin` names the source in errors.
    pub fn parse_lp(text: &str, origin: &str) -> Result<Self> {
        let bad = |line: usize, reason: String| Error::LightFile {
            path: origin.to_string(),
            line,
            reason,
        };
        // RTIBuilder and text editors on Windows write a UTF-8 byte-order mark; `#` lines are
        // comments (relight's exports carry a header comment).
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text.lines().enumerate().filter(|(_, l)| {
            let l = l.trim();
            !l.is_empty() && !l.starts_with('#')
        });
        let (l0, first) = lines
            .next()
            .ok_or_else(|| bad(1, "empty file: expected the light count N on line 1".into()))?;
        let n: usize = first.trim().parse().map_err(|_| {
            bad(
                l0 + 1,
                format!("expected the light count N, found {:?}", first.trim()),
            )
        })?;
        if n == 0 {
            return Err(bad(l0 + 1, "light count is 0".into()));
        }
        // The count is checked against the lines that follow before anything is allocated for
        // it: a header of 10¹⁸ must not reserve memory for 10¹⁸ lights.
        let listed = lines.clone().count();
        if n != listed {
            return Err(bad(
                l0 + 1,
                format!("header says {n} lights but the file lists {listed}"),
            ));
        }
        let mut set = LightSet {
            names: Vec::with_capacity(n),
            dirs: Vec::with_capacity(n),
        };
        for (ln, line) in lines {
            let toks: Vec<&str> = line.split_whitespace().collect();
            if toks.len() < 4 {
                return Err(bad(
                    ln + 1,
                    format!("expected `name x y z`, found {:?}", line.trim()),
                ));
            }
            let mut v = [0.0; 3];
            for (k, t) in toks[toks.len() - 3..].iter().enumerate() {
                v[k] = t
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(ln + 1, format!("{t:?} is not a finite number")))?;
            }
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if len < 1e-4 {
                return Err(bad(
                    ln + 1,
                    format!("light vector {v:?} has length {len:.2e} < 1e-4"),
                ));
            }
            set.names.push(toks[..toks.len() - 3].join(" "));
            set.dirs.push(normalize(v));
        }
        Ok(set)
    }

    /// Reads an `.lp` file.
    pub fn read_lp(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.display().to_string(),
            source: e,
        })?;
        Self::parse_lp(&text, &path.display().to_string())
    }

    /// `.lp` text with 17 significant digits: a write/read round trip is exact.
    pub fn to_lp(&self) -> String {
        let mut s = format!("{}\n", self.len());
        for (name, d) in self.names.iter().zip(&self.dirs) {
            s += &format!("{name} {:e} {:e} {:e}\n", d[0], d[1], d[2]);
        }
        s
    }

    /// Writes an `.lp` file atomically.
    pub fn write_lp(&self, path: &Path) -> Result<()> {
        crate::atomic::write_bytes(path, self.to_lp().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lp_round_trip_is_exact() {
        let set = LightSet::from_dirs([[0.3, -0.2, 0.9], [0.0, 0.0, 1.0], [-1.0, 1e-3, 0.05]]);
        let back = LightSet::parse_lp(&set.to_lp(), "mem").unwrap();
        assert_eq!(set, back);
    }

    #[test]
    fn lp_with_bom_and_comments() {
        let text = "\u{feff}# written by RTIBuilder\n2\n# first ring\na.jpg 0 0 1\n  # indented\nb.jpg 1 0 0\n";
        let s = LightSet::parse_lp(text, "t.lp").unwrap();
        assert_eq!(s.names, ["a.jpg", "b.jpg"]);
        assert_eq!(s.dirs, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]);
    }

    #[test]
    fn lp_names_with_spaces_and_errors() {
        let s = LightSet::parse_lp("2\nmy img 1.png 0 0 2\nb.png 1 0 0\n", "t.lp").unwrap();
        assert_eq!(s.names[0], "my img 1.png");
        assert_eq!(s.dirs[0], [0.0, 0.0, 1.0]);
        let e = LightSet::parse_lp("3\na 0 0 1\n", "t.lp")
            .unwrap_err()
            .to_string();
        assert!(e.contains("t.lp") && e.contains("3 lights"), "{e}");
        // Huge counts are refused before anything is reserved for them.
        for n in [
            "1000000000000000000",
            "1000000000000",
            "18446744073709551615",
        ] {
            let e = LightSet::parse_lp(&format!("{n}\na 0 0 1\n"), "t.lp")
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!("header says {n} lights but the file lists 1")),
                "{e}"
            );
        }
        let e = LightSet::parse_lp("1\na 0 0 nan\n", "t.lp")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
        let e = LightSet::parse_lp("1\na 0 0 0\n", "t.lp")
            .unwrap_err()
            .to_string();
        assert!(e.contains("length"), "{e}");
    }
}
