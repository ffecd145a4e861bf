//! Poses and ticks that stop being one to one, as on a starved companion
//! computer: a tick finds no new pose, the pose arrives a tick late, the
//! shell skips a tick (the autopilot holds the last command), a starved
//! sender's capture times fall between the ticks. Flown on the spatial
//! model's equations (a plant 20 % slower in attitude and thrust than the
//! controller's model) along a line at 4 m/s at 10 m; a flight is judged
//! against the same controller's flight with every pose on time.

use super::{DT, SpatialSim};
use dflat_control::{Controller, Measurement, ReferenceSource};
use dflat_model::SpatialParams;
use nalgebra::Vector3;

/// Speed along the line [m/s].
pub const SPEED: f64 = 4.0;
/// Altitude (NED z) \[m\].
pub const Z: f64 = -10.0;
/// Ticks flown (8 s).
pub const TICKS: usize = 400;
/// Ticks before the judged part (the start from rest onto the moving
/// line, 4 s).
pub const SETTLE: usize = 200;

/// The line's direction (unit, horizontal): both horizontal axes move.
const DIRECTION: [f64; 2] = [0.8, 0.6];

/// A line along [`DIRECTION`] at [`SPEED`] from the origin at t = 0.
pub struct Line {
    /// The tick's time \[s\].
    pub t: f64,
}

impl ReferenceSource for Line {
    fn horizon(&mut self, _measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        for (j, p) in out.iter_mut().enumerate() {
            *p = along(SPEED * (self.t + j as f64 * dt));
        }
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let [cx, cy] = DIRECTION;
        (
            along(SPEED * self.t),
            Vector3::new(SPEED * cx, SPEED * cy, 0.0),
        )
    }
}

/// The point `s` metres along the line.
fn along(s: f64) -> Vector3<f64> {
    Vector3::new(s * DIRECTION[0], s * DIRECTION[1], Z)
}

/// Distance of `p` from the line, horizontally \[m\].
fn cross_track(p: &Vector3<f64>) -> f64 {
    (p.y * DIRECTION[0] - p.x * DIRECTION[1]).abs()
}

/// An autopilot that applies each command `delay` ticks after it is sent
/// and holds the newest it has (over skipped ticks, the last sent).
pub struct DelayedAutopilot {
    delay: usize,
    /// Commands sent and not yet applied, with their tick, oldest first.
    in_flight: std::collections::VecDeque<(usize, (f64, f64, f64))>,
    /// The command applied now (pitch, roll \[rad\], thrust [m/s²]).
    applied: (f64, f64, f64),
}

impl DelayedAutopilot {
    /// `delay` ticks late, applying `initial` until a command takes effect.
    pub fn new(delay: usize, initial: (f64, f64, f64)) -> Self {
        Self {
            delay,
            in_flight: std::collections::VecDeque::new(),
            applied: initial,
        }
    }

    /// The command (pitch, roll, thrust) sent at tick `k`.
    pub fn send(&mut self, k: usize, command: (f64, f64, f64)) {
        self.in_flight.push_back((k, command));
    }

    /// The command applied at tick `k`: the newest sent at least `delay`
    /// ticks before.
    pub fn applied_at(&mut self, k: usize) -> (f64, f64, f64) {
        while let Some(&(sent_at, c)) = self.in_flight.front() {
            if sent_at + self.delay > k {
                break;
            }
            self.applied = c;
            self.in_flight.pop_front();
        }
        self.applied
    }
}

/// What one tick of the loop sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tick {
    /// The pose taken at this tick.
    OnTime,
    /// A pose taken this many hundredths of a step before the tick (a
    /// starved sender's capture times), with its own time.
    Early(u8),
    /// No new pose: the last one again, with its own time.
    NoPose,
    /// The pose of the previous tick (late by one).
    Late,
    /// The shell skipped this tick: no update, the last command held (it
    /// tells the controller, [`dflat_control::Controller::skipped`]).
    Skipped,
}

impl Tick {
    /// Tick `k` of a random mix drawn as `(kind, draw, percent)`: on time
    /// unless `draw < rate`, then by `kind` a tick without a pose, a late
    /// pose, a skipped tick or a pose taken `percent` hundredths early.
    pub fn drawn((kind, draw, percent): (u8, f64, u8), rate: f64) -> Self {
        if draw >= rate {
            return Self::OnTime;
        }
        match kind {
            0 => Self::NoPose,
            1 => Self::Late,
            2 => Self::Skipped,
            _ => Self::Early(percent),
        }
    }
}

/// What a flight measured over the judged part.
#[derive(Debug, Clone, Copy)]
pub struct Flown {
    /// Largest altitude error \[m\].
    pub altitude: f64,
    /// Largest cross-track error \[m\].
    pub cross: f64,
    /// Largest step of the thrust command between two sent commands [m/s²].
    pub thrust_step: f64,
    /// Largest step of the pitch or roll command between two sent
    /// commands \[rad\].
    pub tilt_step: f64,
}

/// Flies `ctrl` along the line with tick k seeing `ticks(k)`, on a plant
/// 20 % slower in attitude and thrust than the default spatial model and
/// with `heavier` × its gravity (a hover-thrust error the model does not
/// know).
pub fn fly(ctrl: &mut dyn Controller, heavier: f64, ticks: &dyn Fn(usize) -> Tick) -> Flown {
    fly_delayed(ctrl, heavier, 0, ticks)
}

/// [`fly`] through an autopilot that applies each command `delay` ticks
/// after it is sent (and holds the newest it has: over skipped ticks, the
/// last sent).
pub fn fly_delayed(
    ctrl: &mut dyn Controller,
    heavier: f64,
    delay: usize,
    ticks: &dyn Fn(usize) -> Tick,
) -> Flown {
    let plant = SpatialParams {
        tau: 1.2 * SpatialParams::default().tau,
        tau_thrust: 1.2 * SpatialParams::default().tau_thrust,
        g: heavier * SpatialParams::default().g,
        ..SpatialParams::default()
    };
    let mut sim = SpatialSim::at_rest(plant, Vector3::new(0.0, 0.0, Z));
    let mut reference = Line { t: 0.0 };
    let hover = SpatialParams::default().g;
    let mut command = (0.0, 0.0, hover);
    let mut autopilot = DelayedAutopilot::new(delay, command);
    let mut sent: Option<(f64, f64, f64)> = None;
    let mut last = Measurement {
        t: 0.0,
        position: sim.pos,
        yaw: 0.0,
    };
    let mut previous = sim.pos;
    let mut observed = f64::NEG_INFINITY;
    let mut flown = Flown {
        altitude: 0.0,
        cross: 0.0,
        thrust_step: 0.0,
        tilt_step: 0.0,
    };
    for k in 0..TICKS {
        let t = k as f64 * DT;
        let tick = if k < 3 { Tick::OnTime } else { ticks(k) };
        let judged = k >= SETTLE;
        if tick == Tick::Skipped {
            // The shell knows it skipped the tick (its clock).
            ctrl.skipped(1);
        } else {
            match tick {
                Tick::OnTime => {
                    last = Measurement {
                        t,
                        position: sim.pos,
                        yaw: 0.0,
                    }
                }
                Tick::Early(percent) => {
                    let f = f64::from(percent) / 100.0;
                    last = Measurement {
                        t: t - f * DT,
                        position: sim.pos + (previous - sim.pos) * f,
                        yaw: 0.0,
                    }
                }
                Tick::Late if last.t < t - DT => {
                    last = Measurement {
                        t: t - DT,
                        position: previous,
                        yaw: 0.0,
                    }
                }
                _ => {}
            }
            if last.t > observed {
                // Every pose reaches a multi-rate window or an estimator.
                ctrl.observe(&last);
                observed = last.t;
            }
            reference.t = t;
            // A multi-rate controller is handed the tick time (its samples
            // came through `observe`), as the daemon does; the others the
            // newest pose at its capture time.
            let measurement = if ctrl.multi_rate() {
                Measurement { t, ..last }
            } else {
                last
            };
            let out = ctrl
                .update(&measurement, &mut reference)
                .unwrap_or_else(|e| panic!("tick {k} ({tick:?}): {e}"));
            let c = out.command;
            assert!(c.is_finite(), "tick {k}: {c:?}");
            command = (c.pitch, c.roll, c.thrust);
            if let (Some(s), true) = (sent, judged) {
                flown.thrust_step = flown.thrust_step.max((command.2 - s.2).abs());
                let step = (command.0 - s.0).abs().max((command.1 - s.1).abs());
                flown.tilt_step = flown.tilt_step.max(step);
            }
            sent = Some(command);
        }
        previous = sim.pos;
        if tick != Tick::Skipped {
            autopilot.send(k, command);
        }
        let (theta, phi, thrust) = autopilot.applied_at(k);
        sim.step(theta, phi, thrust);
        if judged {
            flown.altitude = flown.altitude.max((sim.pos.z - Z).abs());
            flown.cross = flown.cross.max(cross_track(&sim.pos));
        }
    }
    flown
}

/// The perturbed flight holds the altitude and the line as the clean one
/// does, and its command is as smooth; a tilt step after skipped ticks may
/// reach `catch_up` \[rad\] (what the controller lets one tick move it).
pub fn judge(clean: &Flown, perturbed: &Flown, catch_up: f64, what: &str) {
    assert!(
        perturbed.altitude <= 2.0 * clean.altitude + 0.02,
        "{what}: altitude error {:.4} m against {:.4} m with every pose on time",
        perturbed.altitude,
        clean.altitude
    );
    assert!(
        perturbed.cross <= 2.0 * clean.cross + 0.02,
        "{what}: cross-track error {:.4} m against {:.4} m",
        perturbed.cross,
        clean.cross
    );
    assert!(
        perturbed.thrust_step <= 2.0 * clean.thrust_step + 0.3,
        "{what}: thrust step {:.3} m/s² against {:.3} m/s²",
        perturbed.thrust_step,
        clean.thrust_step
    );
    assert!(
        perturbed.tilt_step <= (2.0 * clean.tilt_step + 0.02).max(catch_up),
        "{what}: tilt step {:.4} rad against {:.4} rad",
        perturbed.tilt_step,
        clean.tilt_step
    );
}
