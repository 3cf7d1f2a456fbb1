//! One typed table, four renderings: each report builds its rows once and writes them as
//! Markdown (reports), aligned text (the terminal), CSV and JSON (machines). Human
//! renderings round numbers to the column's digits; CSV and JSON keep every digit.
//! Text from files or arguments (set names) is escaped per format, so no cell can break a
//! row or forge one.

use std::fmt::Write as _;

/// A column: its heading for people, its key for machines (CSV header, JSON field) and the
/// decimals people see.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Column {
    /// Heading in Markdown and text (`AP@0.5`).
    pub header: String,
    /// CSV header and JSON key (`AP50`).
    pub key: String,
    /// Decimals of numbers in Markdown and text.
    pub digits: usize,
    /// Shown in Markdown and text; `false` for a column only machines need (a unit that
    /// people read inside another cell).
    pub for_people: bool,
}

impl Column {
    /// A column headed `header`, keyed `key`, numbers shown with `digits` decimals.
    pub fn new(header: impl Into<String>, key: impl Into<String>, digits: usize) -> Self {
        Column { header: header.into(), key: key.into(), digits, for_people: true }
    }

    /// A column only CSV and JSON carry, keyed `key`.
    pub fn machine(key: impl Into<String>) -> Self {
        Column { header: String::new(), key: key.into(), digits: 0, for_people: false }
    }
}

/// One cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// Text; `note` is shown to people after it in parentheses (`raw (faces found: 98.0%)`)
    /// and left out of CSV and JSON, which carry it in a column or file of their own.
    Text {
        /// The text.
        text: String,
        /// A remark for people.
        note: Option<String>,
    },
    /// A whole number.
    Int(i64),
    /// A number (non-finite: `-` for people, `NaN` in CSV, null in JSON).
    Num(f64),
    /// A number people read as `shown` (with its unit, or in a notation of its own) and
    /// machines as `value` (non-finite: null in JSON, `NaN` in CSV).
    Shown {
        /// The number, in the unit the column's key names.
        value: f64,
        /// What people see.
        shown: String,
    },
    /// A mean and its standard deviation: `m ± s` for people, the mean in CSV,
    /// `{"mean", "std"}` in JSON.
    MeanStd(f64, f64),
    /// No value: `-` for people, empty in CSV, null in JSON.
    Missing,
}

impl Cell {
    /// A text cell without a note.
    pub fn text(text: impl Into<String>) -> Self {
        Cell::Text { text: text.into(), note: None }
    }

    /// `Num(v)`, or `Missing` for `None`.
    pub fn opt(v: Option<f64>) -> Self {
        v.map_or(Cell::Missing, Cell::Num)
    }

    /// The cell as people read it, numbers with `digits` decimals.
    fn readable(&self, digits: usize) -> String {
        let num = |v: f64| if v.is_finite() { format!("{v:.digits$}") } else { "-".into() };
        match self {
            Cell::Text { text, note: None } => campro::file::escape(text),
            Cell::Text { text, note: Some(n) } => {
                format!("{} ({})", campro::file::escape(text), campro::file::escape(n))
            }
            Cell::Int(v) => v.to_string(),
            Cell::Num(v) => num(*v),
            Cell::Shown { shown, .. } => campro::file::escape(shown),
            Cell::MeanStd(m, s) => format!("{} ± {}", num(*m), num(*s)),
            Cell::Missing => "-".into(),
        }
    }

    /// The cell as one CSV field (quoted when it holds a comma, a quote or a line break).
    fn csv(&self) -> String {
        match self {
            Cell::Text { text, .. } => csv_field(text),
            Cell::Int(v) => v.to_string(),
            Cell::Num(v) | Cell::MeanStd(v, _) | Cell::Shown { value: v, .. } => v.to_string(),
            Cell::Missing => String::new(),
        }
    }

    fn json(&self) -> serde_json::Value {
        let num = |v: f64| serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number);
        match self {
            Cell::Text { text, .. } => text.clone().into(),
            Cell::Int(v) => (*v).into(),
            Cell::Num(v) | Cell::Shown { value: v, .. } => num(*v),
            Cell::MeanStd(m, s) => serde_json::json!({ "mean": num(*m), "std": num(*s) }),
            Cell::Missing => serde_json::Value::Null,
        }
    }

    fn is_text(&self) -> bool {
        matches!(self, Cell::Text { .. })
    }
}

impl From<f64> for Cell {
    fn from(v: f64) -> Self {
        Cell::Num(v)
    }
}

impl From<&str> for Cell {
    fn from(v: &str) -> Self {
        Cell::text(v)
    }
}

impl From<String> for Cell {
    fn from(v: String) -> Self {
        Cell::text(v)
    }
}

impl From<usize> for Cell {
    fn from(v: usize) -> Self {
        Cell::Int(i64::try_from(v).unwrap_or(i64::MAX))
    }
}

/// Rows of cells under named columns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    columns: Vec<Column>,
    rows: Vec<Vec<Cell>>,
}

impl Table {
    /// An empty table with these columns.
    pub fn new(columns: impl IntoIterator<Item = Column>) -> Self {
        Table { columns: columns.into_iter().collect(), rows: Vec::new() }
    }

    /// Appends a row; missing cells at its end are [`Cell::Missing`], extra ones dropped.
    pub fn push(&mut self, mut row: Vec<Cell>) {
        row.resize(self.columns.len(), Cell::Missing);
        self.rows.push(row);
    }

    /// The rows.
    pub fn rows(&self) -> &[Vec<Cell>] {
        &self.rows
    }

    /// The columns people see, with their indices.
    fn for_people(&self) -> Vec<(usize, &Column)> {
        self.columns.iter().enumerate().filter(|(_, c)| c.for_people).collect()
    }

    /// Each row's cells as people read them, people's columns only.
    fn readable_rows(&self) -> Vec<Vec<String>> {
        let cols = self.for_people();
        self.rows.iter().map(|r| cols.iter().map(|&(i, col)| r[i].readable(col.digits)).collect()).collect()
    }

    /// A Markdown table, every cell through [`md_cell`] (`|`, control characters and HTML
    /// escaped).
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let cols = self.for_people();
        let cells: Vec<String> = cols.iter().map(|(_, c)| md_cell(&c.header)).collect();
        let _ = writeln!(s, "| {} |", cells.join(" | "));
        let _ = writeln!(s, "|{}", "---|".repeat(cols.len()));
        for row in self.readable_rows() {
            let cells: Vec<String> = row.iter().map(|c| md_cell(c)).collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s
    }

    /// Aligned columns for a terminal: text left, numbers right, two spaces between.
    pub fn text(&self) -> String {
        let cols = self.for_people();
        let body = self.readable_rows();
        let width = |k: usize| {
            body.iter().map(|r| r[k].chars().count()).chain([cols[k].1.header.chars().count()]).max().unwrap_or(0)
        };
        let widths: Vec<usize> = (0..cols.len()).map(width).collect();
        // A column is left-aligned when its first row holds text.
        let left: Vec<bool> = cols.iter().map(|&(i, _)| self.rows.first().is_none_or(|r| r[i].is_text())).collect();
        let line = |cells: &[String]| {
            let parts: Vec<String> = cells
                .iter()
                .enumerate()
                .map(
                    |(i, c)| {
                        if left[i] {
                            format!("{c:<w$}", w = widths[i])
                        } else {
                            format!("{c:>w$}", w = widths[i])
                        }
                    },
                )
                .collect();
            parts.join("  ").trim_end().to_string() + "\n"
        };
        let header: Vec<String> = cols.iter().map(|(_, c)| campro::file::escape(&c.header)).collect();
        let mut s = line(&header);
        for r in &body {
            s += &line(r);
        }
        s
    }

    /// CSV: the keys as header, one line per row, every digit of each number.
    pub fn csv(&self) -> String {
        let mut s = self.columns.iter().map(|c| csv_field(&c.key)).collect::<Vec<_>>().join(",") + "\n";
        for row in &self.rows {
            s += &(row.iter().map(Cell::csv).collect::<Vec<_>>().join(",") + "\n");
        }
        s
    }

    /// JSON: an array of objects, one per row, keyed by the columns' keys.
    pub fn json(&self) -> serde_json::Value {
        self.rows
            .iter()
            .map(|row| {
                let o: serde_json::Map<String, serde_json::Value> =
                    self.columns.iter().zip(row).map(|(c, v)| (c.key.clone(), v.json())).collect();
                serde_json::Value::Object(o)
            })
            .collect()
    }
}

/// Text as one Markdown table cell: `|` escaped, line breaks and other control characters
/// written out.
pub fn md_cell(text: &str) -> String {
    md_text(text).replace('|', "\\|")
}

/// Text that came from outside (a set's name, a file name, a manifest's model name) as
/// Markdown prose: control characters escaped ([`campro::file::escape`]) and `&`, `<`, `>`
/// as HTML entities, so that a `<script>` in a name is shown, never run, wherever the
/// report is rendered.
pub fn md_text(text: &str) -> String {
    campro::file::escape(text).replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Text as one CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line
/// break. Text that a spreadsheet would run as a formula (starting with `=`, `+`, `-`, `@`, a
/// tab or a carriage return: a person-folder name such as `=HYPERLINK(...)`) is written with
/// a leading `'`, which spreadsheets show as text (OWASP's CSV-injection rule). Numbers are
/// never text cells, so no figure changes.
pub fn csv_field(text: &str) -> String {
    let text = if text.starts_with(['=', '+', '-', '@', '\t', '\r']) {
        std::borrow::Cow::Owned(format!("'{text}"))
    } else {
        std::borrow::Cow::Borrowed(text)
    };
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.into_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Table {
        let mut t = Table::new([Column::new("image type", "image_type", 0), Column::new("AP", "AP", 3)]);
        t.push(vec!["raw".into(), 0.51234.into()]);
        t.push(vec![Cell::Text { text: "a|b,\"c\"\nd".into(), note: Some("x".into()) }, Cell::Missing]);
        t.push(vec![Cell::text("m"), Cell::MeanStd(12.345, 0.5)]);
        t
    }

    #[test]
    fn csv_never_hands_a_spreadsheet_a_formula() {
        assert_eq!(csv_field("=HYPERLINK(\"http://x\",\"a\")"), "\"'=HYPERLINK(\"\"http://x\"\",\"\"a\"\")\"");
        assert_eq!(csv_field("+1"), "'+1");
        assert_eq!(csv_field("-cmd"), "'-cmd");
        assert_eq!(csv_field("@SUM(A1)"), "'@SUM(A1)");
        assert_eq!(csv_field("\tx"), "'\tx");
        assert_eq!(csv_field("Ann_Person"), "Ann_Person");
        let mut t = Table::new([Column::new("person", "person", 0), Column::new("n", "n", 0)]);
        t.push(vec![Cell::text("=1+1"), Cell::Num(-0.5)]);
        assert_eq!(t.csv(), "person,n\n'=1+1,-0.5\n");
    }

    #[test]
    fn markdown_by_hand() {
        assert_eq!(
            sample().markdown(),
            "| image type | AP |\n|---|---|\n| raw | 0.512 |\n| a\\|b,\"c\"\\nd (x) | - |\n| m | 12.345 ± 0.500 |\n"
        );
    }

    #[test]
    fn markdown_shows_html_in_names_and_never_runs_it() {
        let mut t = Table::new([Column::new("set <b>", "set", 0)]);
        t.push(vec![Cell::text("<script>alert(1)</script> & co")]);
        assert_eq!(t.markdown(), "| set &lt;b&gt; |\n|---|\n| &lt;script&gt;alert(1)&lt;/script&gt; &amp; co |\n");
    }

    #[test]
    fn csv_keeps_every_digit_and_quotes_text() {
        assert_eq!(sample().csv(), "image_type,AP\nraw,0.51234\n\"a|b,\"\"c\"\"\nd\",\nm,12.345\n");
    }

    #[test]
    fn json_is_one_object_a_row() {
        let j = sample().json();
        assert_eq!(j[0], serde_json::json!({"image_type": "raw", "AP": 0.51234}));
        assert_eq!(j[1]["AP"], serde_json::Value::Null);
        assert_eq!(j[1]["image_type"], "a|b,\"c\"\nd");
        assert_eq!(j[2]["AP"], serde_json::json!({"mean": 12.345, "std": 0.5}));
    }

    #[test]
    fn text_aligns_text_left_and_numbers_right() {
        let mut t = Table::new([Column::new("set", "set", 0), Column::new("max LSB", "max", 2)]);
        t.push(vec!["grey".into(), 1.0.into()]);
        t.push(vec!["random pixels".into(), f64::INFINITY.into()]);
        assert_eq!(t.text(), "set            max LSB\ngrey              1.00\nrandom pixels        -\n");
    }

    #[test]
    fn shown_numbers_and_machine_columns() {
        let mut t =
            Table::new([Column::new("time", "seconds", 0), Column::machine("per"), Column::new("err", "err", 3)]);
        t.push(vec![Cell::Shown { value: 0.002, shown: "2.00 ms/frame".into() }, "frame".into(), 0.5.into()]);
        t.push(vec![Cell::Shown { value: f64::NAN, shown: "-".into() }, Cell::Missing, Cell::Missing]);
        assert_eq!(t.markdown(), "| time | err |\n|---|---|\n| 2.00 ms/frame | 0.500 |\n| - | - |\n");
        assert_eq!(t.text(), "         time    err\n2.00 ms/frame  0.500\n            -      -\n");
        assert_eq!(t.csv(), "seconds,per,err\n0.002,frame,0.5\nNaN,,\n");
        assert_eq!(t.json()[0], serde_json::json!({"seconds": 0.002, "per": "frame", "err": 0.5}));
        assert_eq!(t.json()[1], serde_json::json!({"seconds": null, "per": null, "err": null}));
    }

    #[test]
    fn short_rows_are_padded() {
        let mut t = Table::new([Column::new("a", "a", 0), Column::new("b", "b", 0)]);
        t.push(vec!["x".into()]);
        assert_eq!(t.rows()[0][1], Cell::Missing);
        assert_eq!(t.csv(), "a,b\nx,\n");
    }
}
