//! Hand-written CSV for trial logs (no csv crate): comma-separated, one
//! header line, floats in Rust's shortest round-trip form (so a CSV is
//! bit-exact), NaN for missing values, booleans as 0/1.

use std::fmt::Write as _;
use std::io::{self, Write};

use nalgebra::Vector3;

use super::TrialResult;

/// Header of [`TrialResult::write_ticks_csv`].
pub const TICKS_HEADER: &str = "k,t,x,y,z,vx,vy,vz,roll,pitch,yaw,\
meas_t,meas_x,meas_y,meas_z,meas_yaw,new_samples,ref_x,ref_y,ref_z,\
plan0_x,plan0_y,plan0_z,plan1_x,plan1_y,plan1_z,plan2_x,plan2_y,plan2_z,plan3_x,plan3_y,plan3_z,\
cmd_pitch,cmd_roll,cmd_yaw,cmd_thrust,applied_pitch,applied_roll,applied_yaw,applied_thrust,\
ctrl_saturated,plant_saturated,constrained,status,path_error";

/// Header of [`TrialResult::write_trace_csv`].
pub const TRACE_HEADER: &str = "t,x,y,z,vx,vy,vz,roll,pitch";

/// Header of [`TrialResult::write_samples_csv`].
pub const SAMPLES_HEADER: &str = "t_measured,t_arrival,x,y,z,yaw";

fn push(line: &mut String, values: &[f64]) {
    for v in values {
        // Writing to a String cannot fail.
        let _ = write!(line, ",{v}");
    }
}

/// Position, velocity (local NED) and roll, pitch: the columns
/// `x,y,z,vx,vy,vz,roll,pitch` of the tick log and the trace.
fn motion(position: &Vector3<f64>, velocity: &Vector3<f64>, roll: f64, pitch: f64) -> [f64; 8] {
    [
        position.x, position.y, position.z, velocity.x, velocity.y, velocity.z, roll, pitch,
    ]
}

impl TrialResult {
    /// Writes the per-tick log as CSV (header [`TICKS_HEADER`]). Positions
    /// local NED \[m\], angles \[rad\], thrust [m/s²].
    pub fn write_ticks_csv(&self, mut w: impl Write) -> io::Result<()> {
        writeln!(w, "{TICKS_HEADER}")?;
        let mut line = String::with_capacity(1024);
        for r in &self.ticks {
            line.clear();
            let _ = write!(line, "{}", r.k);
            let s = &r.truth;
            push(&mut line, &[r.t]);
            push(
                &mut line,
                &motion(&s.position, &s.velocity, s.roll, s.pitch),
            );
            push(&mut line, &[s.yaw]);
            let m = r.measurement.map_or([f64::NAN; 5], |m| {
                [m.t, m.position.x, m.position.y, m.position.z, m.yaw]
            });
            push(&mut line, &m);
            let _ = write!(line, ",{}", r.new_samples);
            push(&mut line, r.reference.as_slice());
            for p in &r.plan {
                push(&mut line, p.as_slice());
            }
            let (c, a) = (&r.command, &r.applied);
            push(
                &mut line,
                &[
                    c.pitch, c.roll, c.yaw, c.thrust, a.pitch, a.roll, a.yaw, a.thrust,
                ],
            );
            let _ = write!(
                line,
                ",{},{},{},{}",
                u8::from(r.ctrl_saturated),
                u8::from(r.plant_saturated),
                u8::from(r.constrained),
                r.status.as_str()
            );
            push(&mut line, &[r.path_error]);
            writeln!(w, "{line}")?;
        }
        Ok(())
    }

    /// The per-tick log as a CSV string.
    pub fn ticks_csv(&self) -> String {
        written(|buf| self.write_ticks_csv(buf))
    }

    /// Writes the plant-rate trace as CSV (header [`TRACE_HEADER`]).
    pub fn write_trace_csv(&self, mut w: impl Write) -> io::Result<()> {
        writeln!(w, "{TRACE_HEADER}")?;
        let mut line = String::with_capacity(256);
        for s in &self.trace {
            line.clear();
            let _ = write!(line, "{}", s.t);
            push(
                &mut line,
                &motion(&s.position, &s.velocity, s.roll, s.pitch),
            );
            writeln!(w, "{line}")?;
        }
        Ok(())
    }

    /// The plant-rate trace as a CSV string.
    pub fn trace_csv(&self) -> String {
        written(|buf| self.write_trace_csv(buf))
    }

    /// Writes the delivered sensor samples as CSV (header [`SAMPLES_HEADER`]).
    pub fn write_samples_csv(&self, mut w: impl Write) -> io::Result<()> {
        writeln!(w, "{SAMPLES_HEADER}")?;
        for s in &self.samples {
            writeln!(
                w,
                "{},{},{},{},{},{}",
                s.t_measured, s.t_arrival, s.position.x, s.position.y, s.position.z, s.yaw
            )?;
        }
        Ok(())
    }

    /// The metrics as pretty JSON (serde_json; None → null).
    pub fn metrics_json(&self) -> String {
        serde_json::to_string_pretty(&self.metrics).unwrap_or_default()
    }
}

/// What `write` writes, as a string (writing to a `Vec` cannot fail).
fn written(write: impl FnOnce(&mut Vec<u8>) -> io::Result<()>) -> String {
    let mut buf = Vec::new();
    let _ = write(&mut buf);
    String::from_utf8_lossy(&buf).into_owned()
}
