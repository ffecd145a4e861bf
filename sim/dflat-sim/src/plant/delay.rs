//! A pure transport delay in front of a plant: the autopilot applies each
//! command [`PlantOptions::command_delay`] seconds after it was given.

use std::collections::VecDeque;

use dflat_control::AttitudeCommand;
use nalgebra::Vector3;

use super::{Plant, PlantKind, PlantState};

/// Commands waiting at most (a 2 s delay at a 200 Hz apply rate is 400).
const QUEUE_LIMIT: usize = 4096;

/// `inner` with every command held back by `delay` seconds of plant time.
///
/// [`Plant::apply`] queues the command with the plant's current time; while
/// advancing, each queued command reaches `inner` exactly `delay` later (the
/// integration is split at those instants). [`Plant::applied_command`]
/// reports what the inner plant holds now, i.e. the delayed command.
pub struct DelayedPlant {
    inner: Box<dyn Plant>,
    delay: f64,
    queue: VecDeque<(f64, AttitudeCommand)>,
}

impl DelayedPlant {
    /// Wraps `inner` with a delay of `delay` seconds (≥ 0).
    pub fn new(inner: Box<dyn Plant>, delay: f64) -> Self {
        Self {
            inner,
            delay: delay.max(0.0),
            queue: VecDeque::new(),
        }
    }

    fn release_due(&mut self) {
        let now = self.inner.time();
        while let Some(&(at, c)) = self.queue.front() {
            if at + self.delay > now + 1e-9 {
                break;
            }
            self.queue.pop_front();
            self.inner.apply(&c);
        }
    }
}

impl Plant for DelayedPlant {
    fn kind(&self) -> PlantKind {
        self.inner.kind()
    }

    fn reset(&mut self, state: &PlantState) {
        self.queue.clear();
        self.inner.reset(state);
    }

    fn apply(&mut self, command: &AttitudeCommand) {
        if self.queue.len() == QUEUE_LIMIT {
            self.queue.pop_front();
        }
        self.queue.push_back((self.inner.time(), *command));
        self.release_due();
    }

    fn advance(&mut self, dt: f64) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let end = self.inner.time() + dt;
        // Each pass either releases a command or advances to the next
        // release (or the end): bounded by the queue length plus one.
        for _ in 0..=QUEUE_LIMIT + 1 {
            self.release_due();
            let now = self.inner.time();
            let left = end - now;
            if left <= 1e-9 {
                break;
            }
            let next = self
                .queue
                .front()
                .map_or(f64::INFINITY, |&(at, _)| at + self.delay - now);
            self.inner.advance(left.min(next.max(1e-9)));
        }
    }

    fn position(&self) -> Vector3<f64> {
        self.inner.position()
    }

    fn velocity(&self) -> Vector3<f64> {
        self.inner.velocity()
    }

    fn attitude(&self) -> (f64, f64, f64) {
        self.inner.attitude()
    }

    fn true_state(&self) -> PlantState {
        self.inner.true_state()
    }

    fn state_vector(&self) -> Vec<f64> {
        self.inner.state_vector()
    }

    fn time(&self) -> f64 {
        self.inner.time()
    }

    fn applied_command(&self) -> AttitudeCommand {
        self.inner.applied_command()
    }

    fn saturated(&self) -> bool {
        self.inner.saturated()
    }

    fn wind(&self) -> Vector3<f64> {
        self.inner.wind()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{PlantOptions, build_plant};
    use super::*;

    fn step_response(delay: f64) -> Vec<f64> {
        let o = PlantOptions {
            command_delay: delay,
            ..PlantOptions::default()
        };
        let mut p = build_plant(PlantKind::Planar, &o, 1).unwrap();
        p.reset(&PlantState::default());
        let mut out = Vec::new();
        for _ in 0..40 {
            p.apply(&AttitudeCommand {
                pitch: 0.1,
                roll: 0.0,
                yaw: 0.0,
                thrust: 9.81,
            });
            p.advance(0.005);
            out.push(p.attitude().1);
        }
        out
    }

    #[test]
    fn a_delay_shifts_the_response_by_whole_steps() {
        let plain = step_response(0.0);
        let delayed = step_response(0.04);
        // 40 ms = 8 plant steps of 5 ms: nothing moves before, then the
        // same response.
        assert!(delayed[..8].iter().all(|v| *v == 0.0), "{delayed:?}");
        for k in 8..40 {
            assert!((delayed[k] - plain[k - 8]).abs() < 1e-12, "step {k}");
        }
        assert!(plain[0] > 0.0);
    }
}
