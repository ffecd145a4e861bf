//! The daemon's per-tick CSV, read by column name.

use std::path::Path;

use super::FlightLogError;

/// A flight CSV: the header and every row's fields (as text).
#[derive(Debug, Clone, Default)]
pub struct FlightCsv {
    /// Column names.
    pub header: Vec<String>,
    /// Rows of fields, each as long as the header.
    pub rows: Vec<Vec<String>>,
    /// The file ended in a torn row (the daemon was killed mid-write, or
    /// the disk filled up): what was dropped, for a warning. The rows
    /// before it are complete.
    pub torn_tail: Option<String>,
}

impl FlightCsv {
    /// Reads a CSV file; every row must have as many fields as the header.
    pub fn read(path: &Path) -> Result<Self, FlightLogError> {
        let text = std::fs::read_to_string(path).map_err(|source| FlightLogError::Io {
            file: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses CSV text; `file` names it in errors. A torn tail — a last
    /// row without its newline (a crash mid-write) or a tail of NUL bytes
    /// (a crash before the data reached the disk) — is dropped and reported
    /// in [`torn_tail`](Self::torn_tail); damage anywhere else (a complete
    /// row with the wrong number of fields) is an error.
    pub fn parse(text: &str, file: &Path) -> Result<Self, FlightLogError> {
        // A tail of NULs: the file's length reached the disk, its data not.
        let clean = text.trim_end_matches('\0');
        let mut torn_tail = (clean.len() < text.len())
            .then(|| format!("{} NUL bytes at the end", text.len() - clean.len()));
        let text = clean;
        // No final newline: the last line was cut mid-write. (A file
        // without any newline is a header alone: kept, checked below.)
        let text = match text.rfind('\n') {
            Some(i) if i + 1 < text.len() => {
                let cut = &text[i + 1..];
                torn_tail = Some(format!("a torn last row ({} bytes, no newline)", cut.len()));
                &text[..=i]
            }
            _ => text,
        };
        let err = |line: usize, message: String| FlightLogError::Csv {
            file: file.to_owned(),
            line,
            message,
        };
        let mut lines = text.lines();
        let header: Vec<String> = lines
            .next()
            .filter(|h| !h.trim().is_empty())
            .ok_or_else(|| err(1, "empty: no header line".into()))?
            .split(',')
            .map(|s| s.trim().to_owned())
            .collect();
        for needed in ["tick", "t", "state"] {
            if !header.iter().any(|h| h == needed) {
                return Err(err(
                    1,
                    format!("no `{needed}` column: not a dflat flight CSV"),
                ));
            }
        }
        let mut rows = Vec::new();
        for (i, line) in lines.enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let fields: Vec<String> = line.split(',').map(|s| s.trim().to_owned()).collect();
            if fields.len() != header.len() {
                return Err(err(
                    i + 2,
                    format!(
                        "{} fields, the header has {} columns",
                        fields.len(),
                        header.len()
                    ),
                ));
            }
            rows.push(fields);
        }
        Ok(Self {
            header,
            rows,
            torn_tail,
        })
    }

    /// Index of a column.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// True when the CSV has the column.
    pub fn has(&self, name: &str) -> bool {
        self.index(name).is_some()
    }

    /// A numeric column: `None` for empty or non-numeric fields (and for
    /// every row when the column is missing).
    pub fn numbers(&self, name: &str) -> Vec<Option<f64>> {
        match self.index(name) {
            Some(i) => self
                .rows
                .iter()
                .map(|r| r[i].parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect(),
            None => vec![None; self.rows.len()],
        }
    }

    /// A text column (empty strings for a missing column).
    pub fn texts(&self, name: &str) -> Vec<&str> {
        match self.index(name) {
            Some(i) => self.rows.iter().map(|r| r[i].as_str()).collect(),
            None => vec![""; self.rows.len()],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_by_name_and_errors_name_the_line() {
        let csv = FlightCsv::parse(
            "tick,t,state,x\n0,0.0,WAITING,\n1,0.02,TRACKING,1.5\n",
            Path::new("f.csv"),
        )
        .unwrap();
        assert_eq!(csv.numbers("x"), vec![None, Some(1.5)]);
        assert_eq!(csv.texts("state"), vec!["WAITING", "TRACKING"]);
        assert_eq!(csv.numbers("nope"), vec![None, None]);
        let e = FlightCsv::parse("tick,t,state\n0,1\n", Path::new("f.csv"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("f.csv") && e.contains("line 2") && e.contains("2 fields"),
            "{e}"
        );
        let e = FlightCsv::parse("a,b\n", Path::new("g.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`tick`"), "{e}");
    }

    #[test]
    fn a_torn_tail_is_dropped_and_reported() {
        let f = Path::new("f.csv");
        let whole = "tick,t,state,x\n0,0.0,WAITING,\n1,0.02,TRACKING,1.5\n";
        let csv = FlightCsv::parse(whole, f).unwrap();
        assert_eq!((csv.rows.len(), csv.torn_tail.is_none()), (2, true));
        // Cut mid-row, at every byte of the last row.
        for cut in whole.len() - 17..whole.len() - 1 {
            let csv = FlightCsv::parse(&whole[..cut], f).unwrap();
            assert_eq!(csv.rows.len(), 1, "cut at {cut}");
            assert!(csv.torn_tail.as_deref().unwrap().contains("torn last row"));
        }
        // A NUL tail (data not on disk yet).
        let nul = format!("{whole}{}", "\0".repeat(40));
        let csv = FlightCsv::parse(&nul, f).unwrap();
        assert_eq!(csv.rows.len(), 2);
        assert!(csv.torn_tail.as_deref().unwrap().contains("NUL"));
        // Only the header.
        let csv = FlightCsv::parse("tick,t,state,x\n", f).unwrap();
        assert!(csv.rows.is_empty() && csv.torn_tail.is_none());
        // A complete bad row in the middle is still an error.
        assert!(FlightCsv::parse("tick,t,state\n0,1\n2,0.1,X\n", f).is_err());
    }
}
