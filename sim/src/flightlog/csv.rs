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

    /// Parses CSV text; `file` names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Self, FlightLogError> {
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
        Ok(Self { header, rows })
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
}
