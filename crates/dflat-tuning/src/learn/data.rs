//! The records `dflat learn` reads: engaged runs of ticks from the daemon's
//! per-tick CSV (the commands sent and the poses measured; nothing else).

use dflat_records::Column;
use nalgebra::Vector3;

use super::LearnError;
use crate::flightlog::FlightCsv;

/// One control tick: the measured position and the command sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Tick time \[s\] (the CSV's `t`).
    pub t: f64,
    /// Measured position, local NED \[m\].
    pub y: Vector3<f64>,
    /// Commanded roll, pitch, yaw \[rad\] (ZYX).
    pub euler: [f64; 3],
    /// Commanded normalised thrust \[0, 1\].
    pub thrust: f64,
}

/// A run of consecutive engaged ticks (`HOLDING` or `TRACKING`: the
/// autopilot applied the commands), evenly spaced.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Run {
    /// The ticks in time order.
    pub ticks: Vec<Tick>,
}

/// True for the states in which the autopilot applies the daemon's commands
/// (the CSV's `state` column).
fn engaged(state: &str) -> bool {
    state.starts_with("TRACKING") || state.starts_with("HOLDING")
}

/// The engaged runs of one flight CSV (`name` for errors), split where a
/// tick is missing (a gap over 1.5 `dt`), a field is empty or the state
/// leaves the engaged ones. Errors name the file and the missing column.
pub fn runs(csv: &FlightCsv, name: &str, dt: f64) -> Result<Vec<Run>, LearnError> {
    let need = [
        Column::T,
        Column::X,
        Column::Y,
        Column::Z,
        Column::Roll,
        Column::Pitch,
        Column::Yaw,
        Column::Thrust,
    ];
    for c in need {
        if !csv.has(c) {
            return Err(LearnError::Record {
                file: name.to_owned(),
                message: format!("no `{c}` column: not a dflat flight CSV"),
            });
        }
    }
    let cols: Vec<Vec<Option<f64>>> = need.iter().map(|c| csv.numbers(c)).collect();
    let states = csv.texts(Column::State);
    let mut out = Vec::new();
    let mut run = Run::default();
    for (i, state) in states.iter().enumerate() {
        let v: Option<Vec<f64>> = cols.iter().map(|c| c[i]).collect();
        let tick = v.filter(|_| engaged(state)).map(|v| Tick {
            t: v[0],
            y: Vector3::new(v[1], v[2], v[3]),
            euler: [v[4], v[5], v[6]],
            thrust: v[7],
        });
        let joins = |t: &Tick| {
            run.ticks
                .last()
                .is_none_or(|last| (t.t - last.t - dt).abs() < 0.5 * dt)
        };
        match tick {
            Some(t) if joins(&t) => run.ticks.push(t),
            Some(t) => {
                out.push(std::mem::take(&mut run));
                run.ticks.push(t);
            }
            None => out.push(std::mem::take(&mut run)),
        }
    }
    out.push(run);
    out.retain(|r| !r.ticks.is_empty());
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const HEADER: &str = "tick,t,state,x,y,z,roll,pitch,yaw,thrust";

    fn csv(rows: &[&str]) -> FlightCsv {
        let text = format!("{HEADER}\n{}\n", rows.join("\n"));
        FlightCsv::parse(&text, Path::new("f.csv")).unwrap()
    }

    /// Only engaged ticks count; a standby tick, an empty field or a missing
    /// tick splits the runs.
    #[test]
    fn engaged_runs_split_at_gaps_and_other_states() {
        let c = csv(&[
            "0,0.00,STANDBY,0,0,-10,0,0,0,0.5",
            "1,0.02,TRACKING,0,0,-10,0,0,0,0.5",
            "2,0.04,TRACKING,0.1,0,-10,0,-0.1,0,0.5",
            "3,0.06,HOLDING,0.2,0,-10,0,-0.1,0,0.5",
            "4,0.08,TRACKING,,0,-10,0,-0.1,0,0.5",
            "5,0.10,TRACKING,0.4,0,-10,0,-0.1,0,0.5",
            "7,0.14,TRACKING,0.6,0,-10,0,-0.1,0,0.5",
            "8,0.16,TRACKING,0.7,0,-10,0.05,-0.1,0.2,0.52",
        ]);
        let runs = runs(&c, "f.csv", 0.02).unwrap();
        let lengths: Vec<usize> = runs.iter().map(|r| r.ticks.len()).collect();
        assert_eq!(lengths, vec![3, 1, 2]);
        let last = runs[2].ticks[1];
        assert_eq!(last.euler, [0.05, -0.1, 0.2]);
        assert_eq!(last.thrust, 0.52);
        assert_eq!(last.y, Vector3::new(0.7, 0.0, -10.0));
    }

    #[test]
    fn a_missing_column_is_named() {
        let c = FlightCsv::parse(
            "tick,t,state,x,y,z\n0,0,TRACKING,0,0,0\n",
            Path::new("f.csv"),
        )
        .unwrap();
        let err = runs(&c, "f.csv", 0.02).unwrap_err().to_string();
        assert!(err.contains("f.csv") && err.contains("`roll`"), "{err}");
    }
}
