//! The records `dflat learn` reads: engaged runs of ticks from the daemon's
//! per-tick CSV (the commands sent and the poses measured; nothing else).

use dflat_daemon::csv_schema::Column;
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
