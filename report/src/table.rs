//! A small table type: every table of the report is written as Markdown into `report.md` and as
//! the CSV behind it.

/// A titled table of preformatted cells.
pub struct Table {
    /// File stem of the CSV (`<name>.csv`).
    pub name: String,
    /// Column headers.
    pub columns: Vec<String>,
    /// Rows of cells, as many as `columns` each.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// An empty table with these column headers.
    pub fn new(name: impl Into<String>, columns: &[&str]) -> Self {
        Table {
            name: name.into(),
            columns: columns.iter().map(|c| c.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row (one cell per column).
    pub fn push(&mut self, row: Vec<String>) {
        debug_assert_eq!(row.len(), self.columns.len());
        self.rows.push(row);
    }

    /// A Markdown table (`|` in cells escaped, newlines as spaces).
    pub fn markdown(&self) -> String {
        let mut s = format!("| {} |\n", self.columns.join(" | "));
        s += &format!("|{}\n", "---|".repeat(self.columns.len()));
        for r in &self.rows {
            let cells: Vec<String> = r
                .iter()
                .map(|c| c.replace('|', "\\|").replace('\n', " "))
                .collect();
            s += &format!("| {} |\n", cells.join(" | "));
        }
        s
    }

    /// RFC 4180 CSV: header line, then one line per row; cells with commas, quotes or
    /// newlines quoted.
    pub fn csv(&self) -> String {
        let quote = |c: &str| {
            if c.contains([',', '"', '\n']) {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.to_string()
            }
        };
        let mut s = self
            .columns
            .iter()
            .map(|c| quote(c))
            .collect::<Vec<_>>()
            .join(",")
            + "\n";
        for r in &self.rows {
            s += &(r.iter().map(|c| quote(c)).collect::<Vec<_>>().join(",") + "\n");
        }
        s
    }
}

/// A number with 3 significant digits, in scientific notation outside [1e-3, 1e4).
pub fn g3(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    if a != 0.0 && !(1e-3..1e4).contains(&a) {
        format!("{x:.2e}")
    } else {
        let digits = if a == 0.0 {
            0
        } else {
            (2 - a.log10().floor() as i32).max(0) as usize
        };
        format!("{x:.digits$}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_and_markdown_escapes() {
        let mut t = Table::new("t", &["a", "b"]);
        t.push(vec!["x,y".into(), "p|q".into()]);
        assert_eq!(t.csv(), "a,b\n\"x,y\",p|q\n");
        assert!(t.markdown().contains("p\\|q"));
        assert_eq!(g3(0.012345), "0.0123");
        assert_eq!(g3(123.456), "123");
        assert_eq!(g3(1.5e-5), "1.50e-5");
    }
}
