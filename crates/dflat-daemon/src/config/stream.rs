//! `[stream]`: streamed trajectories (SET_POSITION_TARGET_LOCAL_NED with
//! velocity and/or acceleration) and how position-only setpoints become
//! routes. See `docs/controllers.md`, "Goals as references".

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// `[stream]`: how streamed trajectory samples are extrapolated, when a
/// stream counts as lost, and which samples are refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StreamConfig {
    /// No sample for this long \[s\] (arrival time): the stream is lost,
    /// the reference stops smoothly where its extrapolation stops and the
    /// daemon holds there (0.1–10).
    pub timeout_s: f64,
    /// A sample further than this \[m\] from where the stream's reference
    /// predicts it (or, for a stream's first sample, from the vehicle) is
    /// refused with the current goal kept (0.1–100).
    pub max_jump_m: f64,
    /// Time after a sample the extrapolation runs at full rate \[s\] (0–5).
    pub extrapolation_s: f64,
    /// Time over which the extrapolation then slows to a stop \[s\] (0.1–5).
    pub decay_s: f64,
    /// Position-only setpoints arriving within `implied_max_gap_s` of the
    /// previous one are stream samples whose velocity and acceleration
    /// are implied by the last three (default off: each is a route).
    pub implied_velocity: bool,
    /// Largest spacing \[s\] of position-only setpoints that counts as a
    /// stream with `implied_velocity` (0.02–1; 0.25 s = 4 Hz).
    pub implied_max_gap_s: f64,
    /// How long \[s\] the stream's own jerk (the change of acceleration
    /// between consecutive p/v/a samples) is extrapolated before the
    /// prediction continues as a turn at the curvature reached (0–2; 0 =
    /// constant curvature from each sample).
    pub jerk_horizon_s: f64,
    /// Whose clock a sample's `time_boot_ms` is on (module docs of
    /// `tick/goals.rs`): `"sender"` (the sender's own; each sample is
    /// the planner's present) or `"autopilot"` (the autopilot's boot time,
    /// as MAVROS stamps it: samples may lie ahead, the trajectory sent
    /// ahead).
    pub time_base: TimeBase,
    /// How far ahead \[s\] of its arrival a sample may lie with
    /// `time_base = "autopilot"` (0.1–30); further is refused.
    pub max_ahead_s: f64,
    /// Peak acceleration \[m/s²\] of a setpoint's route (start and stop
    /// ramps) and of a lost stream's stop (its decay is lengthened to keep
    /// within it; 0.2–10).
    pub route_acceleration: f64,
}

/// `stream.time_base`: whose clock a sample's `time_boot_ms` is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TimeBase {
    /// The sender's own clock, its offset estimated from the samples'
    /// arrivals: every sample is the sender's present (none lies ahead).
    #[default]
    Sender,
    /// The autopilot's boot time (as MAVROS stamps setpoints), mapped by
    /// the pose clock: a sample may lie up to `max_ahead_s` ahead.
    Autopilot,
}

impl Default for StreamConfig {
    fn default() -> Self {
        Self {
            timeout_s: 0.5,
            max_jump_m: 3.0,
            extrapolation_s: 1.0,
            decay_s: 1.0,
            implied_velocity: false,
            implied_max_gap_s: 0.25,
            jerk_horizon_s: 0.25,
            time_base: TimeBase::Sender,
            max_ahead_s: 10.0,
            route_acceleration: 2.0,
        }
    }
}

impl StreamConfig {
    /// Checks the ranges; the error names the field (`stream.…`).
    pub fn validate(&self, file: &std::path::Path) -> Result<(), ConfigError> {
        for (field, x, lo, hi) in [
            ("stream.timeout_s", self.timeout_s, 0.1, 10.0),
            ("stream.max_jump_m", self.max_jump_m, 0.1, 100.0),
            ("stream.extrapolation_s", self.extrapolation_s, 0.0, 5.0),
            ("stream.decay_s", self.decay_s, 0.1, 5.0),
            ("stream.jerk_horizon_s", self.jerk_horizon_s, 0.0, 2.0),
            ("stream.max_ahead_s", self.max_ahead_s, 0.1, 30.0),
            (
                "stream.implied_max_gap_s",
                self.implied_max_gap_s,
                0.02,
                1.0,
            ),
            (
                "stream.route_acceleration",
                self.route_acceleration,
                0.2,
                10.0,
            ),
        ] {
            if !(x.is_finite() && x >= lo && x <= hi) {
                return Err(ConfigError::Range {
                    file: file.to_owned(),
                    field: field.to_owned(),
                    value: x.to_string(),
                    allowed: format!("{lo} to {hi}"),
                });
            }
        }
        Ok(())
    }

    /// The core's stream settings.
    pub fn settings(&self) -> dflat_control::reference::StreamSettings {
        dflat_control::reference::StreamSettings {
            extrapolation_s: self.extrapolation_s,
            decay_s: self.decay_s,
            implied_velocity: self.implied_velocity,
            implied_max_gap_s: self.implied_max_gap_s,
            jerk_horizon_s: self.jerk_horizon_s,
            max_ahead_s: self.max_ahead_s,
            stop_acceleration: self.route_acceleration,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_values_name_the_field() {
        let p = std::path::Path::new("x.toml");
        assert!(StreamConfig::default().validate(p).is_ok());
        let c = StreamConfig {
            decay_s: 0.0,
            ..StreamConfig::default()
        };
        let e = c.validate(p).unwrap_err().to_string();
        assert!(e.contains("stream.decay_s"), "{e}");
        let c = StreamConfig {
            max_jump_m: f64::NAN,
            ..StreamConfig::default()
        };
        assert!(
            c.validate(p)
                .unwrap_err()
                .to_string()
                .contains("stream.max_jump_m")
        );
    }
}
