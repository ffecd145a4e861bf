//! A lab flight as the tuning tools read a real one: the commands sent and
//! the poses measured at their capture times (for `learn`), and the
//! log `identify` reads (commands, the autopilot's attitude, the poses,
//! the autopilot engaged throughout).

use dflat_sim::sensing::PoseSample as SimPose;
use dflat_tuning::flightlog::{AttitudeSample, CommandSample, FlightLog, ModeSample, PoseSample};
use dflat_tuning::learn::data::{Pose, Run, Tick};

use super::Vehicle;
use crate::harness::{TickRecord, TickStatus, TrialResult};
use nalgebra::Vector3;

/// Normalised thrust the lab's records carry for a specific thrust `t`
/// \[m/s²\]: hover (g) is [`Vehicle::HOVER_THRUST`].
fn normalised(t: f64, g: f64) -> f64 {
    t * Vehicle::HOVER_THRUST / g
}

/// The flight's engaged run (from the first good tick to the last, split
/// where an update failed) with every pose at its capture time.
pub fn runs(result: &TrialResult, g: f64) -> Vec<Run> {
    let mut out = Vec::new();
    let mut run = Run::default();
    let mut samples = result.samples.iter().peekable();
    for tick in &result.ticks {
        if tick.status != TickStatus::Ok {
            if !run.ticks.is_empty() {
                out.push(std::mem::take(&mut run));
            }
            continue;
        }
        let c = tick.command;
        run.ticks.push(Tick {
            t: tick.t,
            euler: [c.roll, c.pitch, c.yaw],
            thrust: normalised(c.thrust, g),
        });
        // The poses that had arrived by this tick, each with the plant's
        // true position at its capture time (to judge `learn`'s held-out
        // prediction without the noise; nothing is fitted to it).
        while let Some(s) = samples.next_if(|s: &&SimPose| s.t_arrival <= tick.t + 1e-9) {
            let truth = truth_at(&result.ticks, s.t_measured);
            run.push_pose_with_truth(s.t_measured, s.position, truth);
        }
    }
    if !run.ticks.is_empty() {
        out.push(run);
    }
    for r in &mut out {
        let (first, last) = (r.ticks[0].t, r.ticks[r.ticks.len() - 1].t);
        r.poses.retain(|p: &Pose| p.t >= first && p.t <= last);
    }
    out
}

/// The plant's true position at `t` \[s\] (NED \[m\]): the cubic Hermite
/// of the ticks' true positions and velocities around `t` (error of order
/// jerk·δt³/384: ~0.1 mm at 50 Hz and 500 m/s³). `None` outside the
/// ticks.
pub fn truth_at(ticks: &[TickRecord], t: f64) -> Option<Vector3<f64>> {
    let j = ticks.partition_point(|k| k.t <= t);
    if j == 0 {
        return None;
    }
    let a = &ticks[j - 1];
    if (t - a.t).abs() <= 1e-12 {
        return Some(a.truth.position);
    }
    let b = ticks.get(j)?;
    let h = b.t - a.t;
    let s = (t - a.t) / h;
    let (s2, s3) = (s * s, s * s * s);
    Some(
        a.truth.position * (2.0 * s3 - 3.0 * s2 + 1.0)
            + a.truth.velocity * (h * (s3 - 2.0 * s2 + s))
            + b.truth.position * (-2.0 * s3 + 3.0 * s2)
            + b.truth.velocity * (h * (s3 - s2)),
    )
}

/// Several flights as one log, each `gap` \[s\] after the previous one's
/// end (separate engaged segments): the commands, the true attitude at each
/// tick (the SITL's ATTITUDE), the poses at their capture times (source
/// time on the autopilot's clock, which is the log's), the autopilot in
/// offboard and armed while each flight streams.
pub fn flight_log(results: &[&TrialResult], g: f64) -> FlightLog {
    let mut log = FlightLog {
        autopilot_clock_offset: Some(0.0),
        ..FlightLog::default()
    };
    let mut offset = 0.0;
    for r in results {
        let mut end = offset;
        for tick in r.ticks.iter().filter(|t| t.status == TickStatus::Ok) {
            let t = offset + tick.t;
            let c = tick.command;
            log.commands.push(CommandSample {
                t,
                time_boot_ms: (t * 1e3) as u32,
                euler: [c.roll, c.pitch, c.yaw],
                thrust: normalised(c.thrust, g),
            });
            let s = &tick.truth;
            log.attitude.push(AttitudeSample {
                t,
                arrival: t,
                euler: [s.roll, s.pitch, s.yaw],
            });
            end = t;
        }
        for s in &r.samples {
            log.local_position.push(PoseSample {
                arrival: offset + s.t_arrival,
                source_time: offset + s.t_measured,
                position: s.position.into(),
            });
        }
        let mut t = offset;
        while t <= end {
            log.modes.push(ModeSample::engaged(t));
            t += 1.0;
        }
        offset = end + 10.0;
    }
    log.records = (log.commands.len() + log.attitude.len() + log.local_position.len()) as u64;
    log
}
