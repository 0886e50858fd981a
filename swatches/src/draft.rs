//! Weave drafts: WIF 1.1 files and plain 0/1 interlacement grids, read into a [`Pattern`].
//!
//! WIF (Weaving Information File 1.1, R. Nielsen 1997) is INI-like: `[SECTION]` headers,
//! `key=value` lines, `;` comments, all indices 1-based. We read `[WEAVING]` (Shafts, Treadles,
//! Rising Shed), `[WARP]`/`[WEFT]` Threads, `[THREADING]` (end = shaft\[,shaft\]), `[TIEUP]`
//! (treadle = shafts) with `[TREADLING]` (pick = treadle\[,treadle\]) or `[LIFTPLAN]`
//! (pick = shafts). End e (1-based) becomes warp e − 1 at x = (e − ½)·spacing and pick p weft
//! p − 1 at y = (p − ½)·spacing; warp e is over pick p when one of its shafts is lifted on that
//! pick (inverted for a sinking shed, `Rising Shed=no`). Unthreaded ends and empty picks are
//! allowed (never lifted). Colours and yarn sizes in the file are ignored: the swatch's own
//! parameters set the geometry.
//!
//! A grid is one text line per weft of `0`/`1` per warp (`1`: warp over weft; spaces ignored,
//! `#` starts a comment line). As in images, the first line is the far edge: the top weft
//! (largest y); the first column is warp 0 (x near 0).

use std::collections::BTreeMap;
use std::path::Path;

use crate::weave::Pattern;
use crate::{Error, Result};

/// The most warps or wefts a draft may have (a tile of 1024² crossings is already huge).
pub const MAX_THREADS: usize = 1024;

/// Reads a draft file: WIF when it has `[...]` section headers, else a 0/1 grid.
pub fn read(path: &Path) -> Result<Pattern> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let name = path.display().to_string();
    let is_wif = text.lines().any(|l| l.trim_start().starts_with('['));
    if is_wif {
        parse_wif(&text, &name)
    } else {
        parse_grid(&text, &name)
    }
}

fn draft_err(source: &str, section: &str, line: usize, reason: impl Into<String>) -> Error {
    Error::Draft {
        source_name: source.to_string(),
        section: section.to_string(),
        line,
        reason: reason.into(),
    }
}

/// Parses a 0/1 grid (see the module docs); `source` names it in errors.
pub fn parse_grid(text: &str, source: &str) -> Result<Pattern> {
    let mut rows: Vec<(usize, Vec<bool>)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let mut row = Vec::new();
        for (k, ch) in t.chars().enumerate() {
            match ch {
                '0' => row.push(false),
                '1' => row.push(true),
                c if c.is_whitespace() || c == ',' => {}
                c => {
                    return Err(draft_err(
                        source,
                        "grid",
                        n + 1,
                        format!("character {c:?} at column {} is not 0 or 1", k + 1),
                    ))
                }
            }
        }
        if let Some((first_line, first)) = rows.first() {
            if first.len() != row.len() {
                return Err(draft_err(
                    source,
                    "grid",
                    n + 1,
                    format!(
                        "row has {} cells but line {first_line} has {}; all rows need one cell per warp",
                        row.len(),
                        first.len()
                    ),
                ));
            }
        }
        rows.push((n + 1, row));
    }
    if rows.is_empty() {
        return Err(draft_err(source, "grid", 0, "no rows of 0/1 found"));
    }
    let (warps, wefts) = (rows[0].1.len(), rows.len());
    if warps > MAX_THREADS || wefts > MAX_THREADS {
        return Err(draft_err(
            source,
            "grid",
            0,
            format!("{warps}×{wefts} cells; at most {MAX_THREADS} per side"),
        ));
    }
    // First line = top weft (largest j).
    Ok(Pattern::from_fn(warps, wefts, |i, j| {
        rows[wefts - 1 - j].1[i]
    }))
}

/// One INI section: key (lowercase) → (value, line).
type Section = BTreeMap<String, (String, usize)>;

struct Wif<'a> {
    source: &'a str,
    sections: BTreeMap<String, (Section, usize)>,
}

impl Wif<'_> {
    fn section(&self, name: &str) -> Option<&Section> {
        self.sections.get(name).map(|s| &s.0)
    }

    fn int(&self, section: &str, key: &str) -> Result<Option<usize>> {
        let Some((v, line)) = self.section(section).and_then(|s| s.get(key)) else {
            return Ok(None);
        };
        v.parse::<usize>().map(Some).map_err(|_| {
            draft_err(
                self.source,
                section,
                *line,
                format!("{key}={v} is not a non-negative integer"),
            )
        })
    }

    /// Entries `index=list` of a section as (index, list, line), indices and list items checked
    /// against `1..=index_max` and `1..=item_max`.
    fn lists(
        &self,
        section: &str,
        index_name: &str,
        index_max: usize,
        item_name: &str,
        item_max: usize,
        item_limit: &str,
    ) -> Result<Vec<(usize, Vec<usize>, usize)>> {
        let Some(sec) = self.section(section) else {
            return Ok(Vec::new());
        };
        let mut out = Vec::with_capacity(sec.len());
        for (key, (value, line)) in sec {
            let err = |reason: String| draft_err(self.source, section, *line, reason);
            let idx: usize = key
                .parse()
                .map_err(|_| err(format!("key {key:?} is not a {index_name} number")))?;
            if idx == 0 || idx > index_max {
                return Err(err(format!(
                    "{index_name} {idx} is outside 1..={index_max} (indices are 1-based)"
                )));
            }
            let mut items = Vec::new();
            for part in value.split(',').map(str::trim).filter(|p| !p.is_empty()) {
                let item: usize = part.parse().map_err(|_| {
                    err(format!(
                        "{index_name} {idx}: {part:?} is not a {item_name} number"
                    ))
                })?;
                if item == 0 || item > item_max {
                    return Err(err(format!(
                        "{index_name} {idx}: {item_name} {item} is outside 1..={item_max} ({item_limit})"
                    )));
                }
                items.push(item);
            }
            out.push((idx, items, *line));
        }
        Ok(out)
    }
}

/// Parses WIF 1.1 text (see the module docs); `source` names it in errors, which give the
/// section and line.
pub fn parse_wif(text: &str, source: &str) -> Result<Pattern> {
    let mut sections: BTreeMap<String, (Section, usize)> = BTreeMap::new();
    let mut current: Option<String> = None;
    for (n, raw) in text.lines().enumerate() {
        let n = n + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with(';') {
            continue;
        }
        if let Some(rest) = line.strip_prefix('[') {
            let Some(name) = rest.strip_suffix(']') else {
                return Err(draft_err(
                    source,
                    line,
                    n,
                    "section header without a closing ]",
                ));
            };
            let name = name.trim().to_ascii_uppercase();
            // WIF writers spell the tie-up section both ways.
            let name = if name == "TIE-UP" {
                "TIEUP".to_string()
            } else {
                name
            };
            if sections.contains_key(&name) {
                return Err(draft_err(source, &name, n, "section appears twice"));
            }
            sections.insert(name.clone(), (Section::new(), n));
            current = Some(name);
            continue;
        }
        let Some(sec) = current.as_ref() else {
            return Err(draft_err(
                source,
                "(none)",
                n,
                "a key=value line before any [SECTION] header",
            ));
        };
        let Some((k, v)) = line.split_once('=') else {
            return Err(draft_err(
                source,
                sec,
                n,
                format!("{line:?} is not key=value"),
            ));
        };
        let k = k.trim().to_ascii_lowercase();
        let entry = sections.get_mut(sec).expect("current section exists");
        if entry
            .0
            .insert(k.clone(), (v.trim().to_string(), n))
            .is_some()
        {
            return Err(draft_err(
                source,
                sec,
                n,
                format!("key {k:?} appears twice"),
            ));
        }
    }
    let wif = Wif { source, sections };
    let missing =
        |section: &str, what: &str| draft_err(source, section, 0, format!("missing; {what}"));
    if wif.section("THREADING").is_none() {
        return Err(missing(
            "THREADING",
            "a draft needs the shaft of each warp end",
        ));
    }
    let weaving_line = wif.sections.get("WEAVING").map_or(0, |s| s.1);
    let shafts = wif.int("WEAVING", "shafts")?.ok_or_else(|| {
        draft_err(
            source,
            "WEAVING",
            weaving_line,
            "Shafts= is missing (the number of shafts)",
        )
    })?;
    if shafts == 0 {
        return Err(draft_err(
            source,
            "WEAVING",
            weaving_line,
            "Shafts=0: a loom needs at least one shaft",
        ));
    }
    let treadles = wif.int("WEAVING", "treadles")?.unwrap_or(0);
    let rising = match wif.section("WEAVING").and_then(|s| s.get("rising shed")) {
        None => true,
        Some((v, line)) => match v.to_ascii_lowercase().as_str() {
            "yes" | "true" | "on" | "1" => true,
            "no" | "false" | "off" | "0" => false,
            _ => {
                return Err(draft_err(
                    source,
                    "WEAVING",
                    *line,
                    format!("Rising Shed={v} is not yes or no"),
                ))
            }
        },
    };
    let max_key = |section: &str| {
        wif.section(section)
            .map(|s| {
                s.keys()
                    .filter_map(|k| k.parse::<usize>().ok())
                    .max()
                    .unwrap_or(0)
            })
            .unwrap_or(0)
    };
    let liftplan = wif.section("LIFTPLAN").is_some();
    let pick_section = if liftplan { "LIFTPLAN" } else { "TREADLING" };
    let warps = wif
        .int("WARP", "threads")?
        .unwrap_or_else(|| max_key("THREADING"));
    let wefts = wif
        .int("WEFT", "threads")?
        .unwrap_or_else(|| max_key(pick_section));
    for (sec, count, what) in [("WARP", warps, "warp ends"), ("WEFT", wefts, "picks")] {
        if count == 0 || count > MAX_THREADS {
            let line = wif
                .section(sec)
                .and_then(|s| s.get("threads"))
                .map_or(0, |v| v.1);
            return Err(draft_err(
                source,
                sec,
                line,
                format!("{count} {what}; need 1..={MAX_THREADS}"),
            ));
        }
    }
    let limit = format!("[WEAVING] Shafts={shafts}");
    let threading = wif.lists("THREADING", "end", warps, "shaft", shafts, &limit)?;
    let mut shafts_of = vec![Vec::new(); warps];
    for (end, s, _) in threading {
        shafts_of[end - 1] = s;
    }
    let mut lifted = vec![Vec::new(); wefts];
    if liftplan {
        for (pick, s, _) in wif.lists("LIFTPLAN", "pick", wefts, "shaft", shafts, &limit)? {
            lifted[pick - 1] = s;
        }
    } else {
        if wif.section("TREADLING").is_none() {
            return Err(missing(
                "TREADLING",
                "give [TREADLING] with [TIEUP], or [LIFTPLAN]",
            ));
        }
        if wif.section("TIEUP").is_none() {
            return Err(missing(
                "TIEUP",
                "[TREADLING] needs the tie-up of each treadle",
            ));
        }
        if treadles == 0 {
            return Err(draft_err(
                source,
                "WEAVING",
                weaving_line,
                "Treadles= is missing or 0 but the draft has a [TREADLING]",
            ));
        }
        let tlimit = format!("[WEAVING] Treadles={treadles}");
        // Keyed by treadle, not a vector of `Treadles=` entries: the header's count is only a
        // bound (Treadles=1000000000000 must not allocate a terabyte).
        let mut tieup = BTreeMap::new();
        for (t, s, _) in wif.lists("TIEUP", "treadle", treadles, "shaft", shafts, &limit)? {
            tieup.insert(t, s);
        }
        for (pick, ts, _) in wif.lists("TREADLING", "pick", wefts, "treadle", treadles, &tlimit)? {
            lifted[pick - 1] = ts
                .iter()
                .flat_map(|t| tieup.get(t).into_iter().flatten().copied())
                .collect();
        }
    }
    // Sorted and deduplicated, so each crossing is a merge of two short lists.
    for l in lifted.iter_mut().chain(shafts_of.iter_mut()) {
        l.sort_unstable();
        l.dedup();
    }
    Ok(Pattern::from_fn(warps, wefts, |i, j| {
        let up = shafts_of[i]
            .iter()
            .any(|s| lifted[j].binary_search(s).is_ok());
        up == rising
    }))
}
