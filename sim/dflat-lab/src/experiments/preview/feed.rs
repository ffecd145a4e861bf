//! A planner's stream as the controller receives it: samples of a
//! [`Trajectory`] at the planner's rate, with the fields it sends, alone or
//! each with the next seconds of the trajectory sent ahead, fed into the
//! daemon's own stream reference ([`Reference::stream`]) at the tick's
//! time. The lab's stand-in for SET_POSITION_TARGET_LOCAL_NED over MAVLink.

use dflat_control::ReferenceSource;
use dflat_control::reference::{Reference, StreamSample, StreamSettings};
use dflat_sim::trajectory::Trajectory;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Which fields each sample carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fields {
    /// Position only.
    P,
    /// Position and velocity.
    Pv,
    /// Position, velocity and acceleration.
    Pva,
}

impl Fields {
    /// Short label: "p", "p/v", "p/v/a".
    pub fn label(self) -> &'static str {
        match self {
            Self::P => "p",
            Self::Pv => "p/v",
            Self::Pva => "p/v/a",
        }
    }
}

/// How the planner sends its trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StreamForm {
    /// Samples per second \[Hz\] (> 0).
    pub rate_hz: f64,
    /// Fields of each sample.
    pub fields: Fields,
    /// How far ahead \[s\] each send carries the trajectory (0: the present
    /// sample only). With `ahead_s > 0` each send is the present sample
    /// and the samples every `1/rate_hz` after it up to `ahead_s`.
    pub ahead_s: f64,
    /// Heading along the velocity, and its rate, sent.
    pub yaw: bool,
}

/// The stream as a [`ReferenceSource`]: at each tick (one `horizon` or
/// `closest` call, `δt` apart, from t = 0) the sends due by then are pushed
/// into the stream reference, whose clock is then set to the tick.
pub struct StreamFeed {
    trajectory: Trajectory,
    form: StreamForm,
    settings: StreamSettings,
    reference: Option<Reference>,
    /// The tick's time \[s\].
    t: f64,
    /// The next send's time \[s\].
    next_send: f64,
}

impl StreamFeed {
    /// A feed of `trajectory` in `form`, predicted with `settings`.
    pub fn new(trajectory: Trajectory, form: StreamForm, settings: StreamSettings) -> Self {
        Self {
            trajectory,
            form,
            settings,
            reference: None,
            t: 0.0,
            next_send: 0.0,
        }
    }

    fn sample(&self, t: f64) -> StreamSample {
        let p = self.trajectory.at(t);
        let (v, a) = match self.form.fields {
            Fields::P => (None, None),
            Fields::Pv => (Some(p.velocity), None),
            Fields::Pva => (Some(p.velocity), Some(p.acceleration)),
        };
        StreamSample {
            t,
            position: p.position,
            velocity: v,
            acceleration: a,
            yaw: self.form.yaw.then_some(p.yaw),
            yaw_rate: self.form.yaw.then_some(p.yaw_rate),
        }
    }

    /// Adds a sample. A planner's own trajectory is never refused (finite,
    /// in time order, within `max_ahead_s`: `tests/reference_ahead.rs`), so
    /// an error here would be the lab's bug: it is debug-asserted.
    fn push(&mut self, s: StreamSample) {
        let pushed = match &mut self.reference {
            None => Reference::stream(self.settings, &s).map(|r| self.reference = Some(r)),
            Some(r) => r.push_sample(&s),
        };
        debug_assert!(pushed.is_ok(), "{pushed:?}");
    }

    /// Sends what is due by the tick's time and sets the reference's clock.
    fn advance(&mut self, dt: f64) {
        let period = 1.0 / self.form.rate_hz;
        while self.next_send <= self.t + 1e-9 {
            let t0 = self.next_send;
            let n = (self.form.ahead_s * self.form.rate_hz).round() as usize;
            for k in 0..=n {
                let s = self.sample(t0 + k as f64 * period);
                self.push(s);
            }
            self.next_send += period;
        }
        if let Some(r) = &mut self.reference {
            r.set_time(self.t);
        }
        self.t += dt;
    }

    /// The stream's reference (after the first tick).
    pub fn reference(&self) -> Option<&Reference> {
        self.reference.as_ref()
    }
}

impl ReferenceSource for StreamFeed {
    fn horizon(&mut self, measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        self.advance(dt);
        match &mut self.reference {
            Some(r) => r.horizon(measured, dt, out),
            None => out.fill(self.trajectory.start),
        }
    }

    fn closest(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        match &mut self.reference {
            Some(r) => r.closest(measured),
            None => (self.trajectory.start, Vector3::zeros()),
        }
    }

    fn flyable(&self) -> bool {
        self.reference.as_ref().is_some_and(|r| r.flyable())
    }
}
