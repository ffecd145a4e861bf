//! The records `dflat learn` reads: engaged runs of ticks from the daemon's
//! per-tick CSV (the commands sent and the poses measured, each pose at its
//! capture time; nothing else).

use dflat_records::Column;
use nalgebra::Vector3;

use super::LearnError;
use crate::flightlog::FlightCsv;

/// One control tick: the command sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Tick time \[s\] (the CSV's `t`).
    pub t: f64,
    /// Commanded roll, pitch, yaw \[rad\] (ZYX).
    pub euler: [f64; 3],
    /// Commanded normalised thrust \[0, 1\].
    pub thrust: f64,
}

/// One measured pose at its capture time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Capture time \[s\] (the ticks' clock).
    pub t: f64,
    /// Measured position, local NED \[m\].
    pub y: Vector3<f64>,
    /// The true position at `t`, local NED \[m\], where a simulator knows
    /// it (the lab's records); `None` in a flight's record. Used only to
    /// judge the held-out prediction without the poses' noise
    /// ([`super::Learned::horizon_truth_m`]); nothing is fitted to it.
    pub truth: Option<Vector3<f64>>,
}

/// A run of consecutive engaged ticks (`HOLDING` or `TRACKING`: the
/// autopilot applied the commands), evenly spaced, and the poses captured
/// over it (in time order, each once).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Run {
    /// The ticks in time order.
    pub ticks: Vec<Tick>,
    /// The poses in capture order.
    pub poses: Vec<Pose>,
}

impl Run {
    /// Adds a pose captured at `t`, unless it is not newer than the last
    /// one (a pose seen by several ticks is one pose).
    pub fn push_pose(&mut self, t: f64, y: Vector3<f64>) {
        self.push_pose_with_truth(t, y, None);
    }

    /// As [`Run::push_pose`], with the true position at `t` (a
    /// simulator's records: [`Pose::truth`]).
    pub fn push_pose_with_truth(&mut self, t: f64, y: Vector3<f64>, truth: Option<Vector3<f64>>) {
        if self.poses.last().is_none_or(|p| t > p.t + 1e-9) && t.is_finite() {
            self.poses.push(Pose { t, y, truth });
        }
    }
}

/// True for the states in which the autopilot applies the daemon's commands
/// (the CSV's `state` column).
fn engaged(state: &str) -> bool {
    state.starts_with("TRACKING") || state.starts_with("HOLDING")
}

/// The engaged runs of one flight CSV (`name` for errors), split where a
/// tick is missing (a gap over 1.5 `dt`), a field is empty or the state
/// leaves the engaged ones. Each tick's pose is taken at its capture time,
/// the tick's `t` less its `pose_age_ms` (the tick's `t` without that
/// column), once however many ticks saw it. Errors name the file and the
/// missing column.
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
    let ages = csv
        .has(Column::PoseAgeMs)
        .then(|| csv.numbers(Column::PoseAgeMs));
    let states = csv.texts(Column::State);
    let mut out = Vec::new();
    let mut run = Run::default();
    for (i, state) in states.iter().enumerate() {
        let v: Option<Vec<f64>> = cols.iter().map(|c| c[i]).collect();
        let age = ages.as_ref().map_or(Some(0.0), |a| a[i]);
        let tick = v.filter(|_| engaged(state)).map(|v| {
            (
                Tick {
                    t: v[0],
                    euler: [v[4], v[5], v[6]],
                    thrust: v[7],
                },
                Vector3::new(v[1], v[2], v[3]),
            )
        });
        let joins = |t: &Tick| {
            run.ticks
                .last()
                .is_none_or(|last| (t.t - last.t - dt).abs() < 0.5 * dt)
        };
        match tick {
            Some((t, y)) => {
                if !joins(&t) {
                    out.push(std::mem::take(&mut run));
                }
                run.ticks.push(t);
                if let Some(age) = age {
                    run.push_pose(t.t - age * 1e-3, y);
                }
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
        assert_eq!(runs[2].poses[1].y, Vector3::new(0.7, 0.0, -10.0));
    }

    /// A pose seen by several ticks (vision slower than the loop) is one
    /// pose at its capture time.
    #[test]
    fn poses_are_taken_at_their_capture_time_once() {
        let text = "tick,t,state,x,y,z,roll,pitch,yaw,thrust,pose_age_ms\n\
            0,0.00,TRACKING,0,0,-10,0,0,0,0.5,10\n\
            1,0.02,TRACKING,0,0,-10,0,0,0,0.5,30\n\
            2,0.04,TRACKING,0.1,0,-10,0,0,0,0.5,5\n";
        let c = FlightCsv::parse(text, Path::new("f.csv")).unwrap();
        let runs = runs(&c, "f.csv", 0.02).unwrap();
        let t: Vec<f64> = runs[0].poses.iter().map(|p| p.t).collect();
        assert_eq!(runs[0].ticks.len(), 3);
        assert_eq!(t.len(), 2);
        assert!(
            (t[0] + 0.01).abs() < 1e-12 && (t[1] - 0.035).abs() < 1e-12,
            "{t:?}"
        );
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
