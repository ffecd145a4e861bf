//! A controller that injects faults into chosen updates ([`Faulty`]),
//! around a real one.

use std::time::Duration;

/// A fault a [`Faulty`] controller injects into one update.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The update fails (a solver error).
    Fail,
    /// The update takes this long first (a deadline overrun).
    Slow(Duration),
}

/// The daemon's own controller with faults injected: before update k
/// (counted from the first), `fault(k)` says what goes wrong, if anything.
/// Everything else is delegated.
pub struct Faulty {
    /// The real controller.
    pub inner: Box<dyn dflat_control::Controller>,
    /// Updates so far.
    pub tick: usize,
    /// The fault of update k.
    pub fault: Box<dyn FnMut(usize) -> Option<Fault> + Send>,
}

impl dflat_control::Controller for Faulty {
    fn name(&self) -> &'static str {
        "faulty df-mpc"
    }
    fn multi_rate(&self) -> bool {
        self.inner.multi_rate()
    }
    fn observe(&mut self, sample: &dflat_control::Measurement) {
        self.inner.observe(sample);
    }
    fn update(
        &mut self,
        measurement: &dflat_control::Measurement,
        reference: &mut dyn dflat_control::ReferenceSource,
    ) -> Result<dflat_control::TickOutput, dflat_control::ControlError> {
        let k = self.tick;
        self.tick += 1;
        match (self.fault)(k) {
            Some(Fault::Fail) => {
                // As a solver that ran out of iterations.
                return Err(
                    dflat_control::optimise::SolverFault::NotConverged { iterations: 0 }.into(),
                );
            }
            Some(Fault::Slow(d)) => std::thread::sleep(d),
            None => {}
        }
        self.inner.update(measurement, reference)
    }
    fn plan_fallback(
        &mut self,
        measurement: &dflat_control::Measurement,
        max_steps: usize,
    ) -> Option<dflat_control::TickOutput> {
        self.inner.plan_fallback(measurement, max_steps)
    }
    fn correct_last_input(&mut self, applied: &nalgebra::Vector3<f64>) {
        self.inner.correct_last_input(applied);
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
    fn disturbance(&self) -> Option<dflat_control::disturbance::DisturbanceReport> {
        self.inner.disturbance()
    }
}
