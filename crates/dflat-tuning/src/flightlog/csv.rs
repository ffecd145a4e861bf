//! The daemon's per-tick CSV, read by column: the columns are
//! `dflat_records`' [`Column`](dflat_records::Column)s, the list the daemon
//! writes by.

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
            .unwrap_or("")
            .split(',')
            .map(|s| s.trim().to_owned())
            .collect();
        dflat_records::check_header(&header).map_err(|e| err(1, e.to_string()))?;
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

    /// Index of a column (a [`Column`](dflat_records::Column), or a name).
    pub fn index(&self, column: impl AsRef<str>) -> Option<usize> {
        let name = column.as_ref();
        self.header.iter().position(|h| h == name)
    }

    /// True when the CSV has the column.
    pub fn has(&self, column: impl AsRef<str>) -> bool {
        self.index(column).is_some()
    }

    /// A numeric column: `None` for empty or non-numeric fields (and for
    /// every row when the column is missing).
    pub fn numbers(&self, column: impl AsRef<str>) -> Vec<Option<f64>> {
        match self.index(column) {
            Some(i) => self
                .rows
                .iter()
                .map(|r| r[i].parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect(),
            None => vec![None; self.rows.len()],
        }
    }

    /// A text column (empty strings for a missing column).
    pub fn texts(&self, column: impl AsRef<str>) -> Vec<&str> {
        match self.index(column) {
            Some(i) => self.rows.iter().map(|r| r[i].as_str()).collect(),
            None => vec![""; self.rows.len()],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_records::Column;

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

    /// The daemon's writer and this reader agree on every column: rows
    /// written by `dflat_daemon::records::write_row` under its header read
    /// back field for field, at the CSV's resolution.
    #[test]
    fn a_written_row_reads_back_field_for_field() {
        use dflat_control::disturbance::EstimatorStatus;
        use dflat_daemon::records::{CSV_HEADER, CsvDisturbance, CsvRow, write_row};
        use dflat_daemon::supervisor::FlightState;

        let full = CsvRow {
            tick: 7,
            t: 0.14,
            state: FlightState::Tracking,
            measured: Some([1.25, -2.5, -10.0]),
            plan: Some([
                [1.0, 2.0, 3.0],
                [1.1, 2.1, 3.1],
                [1.2, 2.2, 3.2],
                [1.3, 2.3, 3.3],
            ]),
            reference: Some([0.5, -0.25, -10.0]),
            command: Some([0.012345, -0.2, 1.5, 0.4821]),
            solve_us: Some(42),
            jitter_us: 120,
            disturbance: Some(CsvDisturbance {
                acceleration: [0.1, -0.2, 0.03],
                thrust_scale: 1.04,
                hover_thrust: Some(0.48),
                status: EstimatorStatus::Tracking,
            }),
            residual: Some(0.0123),
            guard: Some("level"),
            pose_age_ms: Some(4.25),
            wake: 0.140_123_456_789,
            events: 31,
        };
        let empty = CsvRow {
            tick: 8,
            state: FlightState::Failsafe,
            measured: None,
            plan: None,
            reference: None,
            command: None,
            solve_us: None,
            disturbance: None,
            residual: None,
            guard: None,
            pose_age_ms: None,
            ..full
        };
        let mut text = format!("{CSV_HEADER}\n").into_bytes();
        write_row(&mut text, &full).unwrap();
        write_row(&mut text, &empty).unwrap();
        let csv = FlightCsv::parse(&String::from_utf8(text).unwrap(), Path::new("f.csv")).unwrap();
        assert_eq!(csv.rows.len(), 2);
        // Every column of the schema is in the file, in order.
        let names: Vec<&str> = Column::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(csv.header, names);

        // The value each column should read back, per row (None = empty).
        let expected = |row: &CsvRow, c: Column| -> Option<f64> {
            let at = |v: Option<[f64; 3]>, i: usize| v.map(|v| v[i]);
            let d = row.disturbance;
            let axis = |cols: &[Column], c: Column| cols.iter().position(|&x| x == c);
            if let Some(i) = axis(&Column::MEASURED, c) {
                return at(row.measured, i);
            }
            if let Some(i) = axis(&Column::REFERENCE, c) {
                return at(row.reference, i);
            }
            for (k, cols) in Column::PLAN.iter().enumerate() {
                if let Some(i) = axis(cols, c) {
                    return row.plan.map(|p| p[k][i]);
                }
            }
            if let Some(i) = axis(&Column::COMMAND, c) {
                return row.command.map(|v| v[i]);
            }
            if let Some(i) = axis(&Column::DISTURBANCE, c) {
                return d.map(|d| d.acceleration[i]);
            }
            match c {
                Column::Tick => Some(row.tick as f64),
                Column::T => Some(row.t),
                Column::SolveUs => row.solve_us.map(f64::from),
                Column::JitterUs => Some(f64::from(row.jitter_us)),
                Column::ThrustScale => d.map(|d| d.thrust_scale),
                Column::HoverThrust => d.and_then(|d| d.hover_thrust),
                Column::ResidualM => row.residual,
                Column::PoseAgeMs => row.pose_age_ms,
                Column::TWake => Some(row.wake),
                Column::Events => Some(row.events as f64),
                _ => None,
            }
        };
        let texts = [Column::State, Column::EstStatus, Column::Guard];
        for (r, row) in [&full, &empty].into_iter().enumerate() {
            for &c in Column::ALL {
                if texts.contains(&c) {
                    continue;
                }
                let got = csv.numbers(c)[r];
                match (expected(row, c), got) {
                    (Some(want), Some(got)) => assert!(
                        (want - got).abs() <= 5e-7 * want.abs().max(1.0),
                        "row {r} {c}: wrote {want}, read {got}"
                    ),
                    (want, got) => assert_eq!(want, got, "row {r} {c}"),
                }
            }
        }
        assert_eq!(csv.texts(Column::State), ["TRACKING", "FAILSAFE"]);
        assert_eq!(csv.texts(Column::EstStatus), ["tracking", ""]);
        assert_eq!(csv.texts(Column::Guard), ["level", ""]);
        // The exact tick time survives to the last digit.
        assert_eq!(csv.numbers(Column::TWake)[0], Some(0.140_123_456_789));
    }
}
