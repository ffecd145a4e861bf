//! The trial set-up the path studies share (paths, vision rate, phase, and
//! through [`PathsConfig`](super::paths::PathsConfig) the airframe and
//! tilt-cone studies): where the L path flies, when a trial ends, when it
//! counts as diverged, and the plant's saturation. One struct, one check,
//! one stop rule and one trial builder, instead of a copy per study.

use std::sync::Arc;

use dflat_control::reference::{Reference, paths};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{ExperimentError, invalid};
use crate::harness::{
    ControllerFactory, ReferenceFactory, StopCondition, TrialSpec, polyline_path_distance,
};
use dflat_sim::plant::{PlantOptions, PlantState};
use dflat_sim::sensing::SensorSpec;

/// A path trial's set-up, shared by the path studies. Serialised flat into
/// each study's configuration (the JSON keys are the field names).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialSetup {
    /// Altitude of the L path, NED z \[m\] (−10 = 10 m up).
    pub altitude: f64,
    /// Time flown after arrival \[s\].
    pub settle: f64,
    /// Arrival radius around the path end \[m\].
    pub arrival_radius: f64,
    /// A trial also ends at length/speed + this \[s\].
    pub timeout_margin: f64,
    /// Hard cap on a trial's length \[s\] (None: no cap; tests shorten runs).
    pub max_duration: Option<f64>,
    /// Path error beyond which a trial counts as diverged and stops \[m\].
    pub divergence_bound: f64,
    /// Attitude saturation of the plant (autopilot) \[deg\].
    pub tilt_limit_deg: f64,
}

impl Default for TrialSetup {
    /// 10 m up, 2 s settle within 1 m, 20 s margin, no cap, diverged beyond
    /// 15 m, ±35° saturation.
    fn default() -> Self {
        Self {
            altitude: -10.0,
            settle: 2.0,
            arrival_radius: 1.0,
            timeout_margin: 20.0,
            max_duration: None,
            divergence_bound: 15.0,
            tilt_limit_deg: 35.0,
        }
    }
}

impl TrialSetup {
    /// Checks the fields; errors name the field.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        if !self.altitude.is_finite() {
            return Err(invalid("altitude", "finite m"));
        }
        for (field, v) in [
            ("settle", self.settle),
            ("timeout_margin", self.timeout_margin),
        ] {
            if !(v.is_finite() && (0.0..=3600.0).contains(&v)) {
                return Err(invalid(field, "0 ..= 3600 s"));
            }
        }
        if !(self.arrival_radius.is_finite() && self.arrival_radius > 0.0) {
            return Err(invalid("arrival_radius", "finite and > 0 m"));
        }
        if self
            .max_duration
            .is_some_and(|d| !(d.is_finite() && d > 0.0))
        {
            return Err(invalid("max_duration", "finite and > 0 s"));
        }
        if !(self.divergence_bound.is_finite() && self.divergence_bound > 0.0) {
            return Err(invalid("divergence_bound", "finite and > 0 m"));
        }
        if !(self.tilt_limit_deg > 0.0 && self.tilt_limit_deg <= 80.0) {
            return Err(invalid("tilt_limit_deg", "(0, 80] deg"));
        }
        Ok(())
    }

    /// The L path's waypoints at [`altitude`](Self::altitude) (local NED \[m\]).
    pub fn l_path(&self) -> Vec<Vector3<f64>> {
        paths::waypoints(&paths::L_XY, self.altitude)
    }

    /// The plant options: lab defaults with the configured tilt limit.
    pub fn plant_options(&self) -> PlantOptions {
        PlantOptions {
            tilt_limit: self.tilt_limit_deg.to_radians(),
            ..PlantOptions::default()
        }
    }

    /// The stop at the end of `waypoints` flown at `speed` \[m/s\]: within
    /// the arrival radius, then the settle time; at the latest after the
    /// path's time plus the margin (capped by `max_duration`).
    pub fn end_stop(&self, waypoints: &[Vector3<f64>], speed: f64) -> StopCondition {
        let mut max_duration = path_length(waypoints) / speed + self.timeout_margin;
        if let Some(cap) = self.max_duration {
            max_duration = max_duration.min(cap);
        }
        StopCondition::PathEnd {
            end: waypoints[waypoints.len() - 1],
            radius: self.arrival_radius,
            settle: self.settle,
            max_duration,
        }
    }

    /// A trial of `controller` on `waypoints` at `speed` \[m/s\] on `plant`
    /// seeing `sensor`: from hover at the first waypoint, the path error to
    /// the polyline, stopped by `stop` or on divergence.
    #[allow(clippy::too_many_arguments)]
    pub fn trial(
        &self,
        name: String,
        controller: ControllerFactory,
        plant: PlantOptions,
        sensor: SensorSpec,
        waypoints: &[Vector3<f64>],
        speed: f64,
        stop: StopCondition,
    ) -> Result<TrialSpec, ExperimentError> {
        let reference = Reference::path(waypoints, speed).map_err(ExperimentError::Reference)?;
        let factory: ReferenceFactory = Arc::new(move || Box::new(reference.clone()));
        let mut t = TrialSpec::new(name, controller, factory);
        t.initial = PlantState::hover(waypoints[0], plant.g);
        t.plant_options = plant;
        t.sensor = sensor;
        t.stop = stop;
        t.path_distance = Some(polyline_path_distance(waypoints.to_vec(), true));
        t.divergence_bound = self.divergence_bound;
        t.stop_on_divergence = true;
        t.validate()?;
        Ok(t)
    }

    /// [`trial`](Self::trial) on the L path at `speed`, ending at arrival
    /// and settle ([`end_stop`](Self::end_stop)), on
    /// [`plant_options`](Self::plant_options).
    pub fn l_trial(
        &self,
        name: String,
        controller: ControllerFactory,
        sensor: SensorSpec,
        speed: f64,
    ) -> Result<TrialSpec, ExperimentError> {
        let w = self.l_path();
        let stop = self.end_stop(&w, speed);
        self.trial(
            name,
            controller,
            self.plant_options(),
            sensor,
            &w,
            speed,
            stop,
        )
    }
}

/// Length of a polyline \[m\].
pub(crate) fn path_length(w: &[Vector3<f64>]) -> f64 {
    w.windows(2).map(|p| (p[1] - p[0]).norm()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_end_stop_is_capped_and_the_checks_name_the_field() {
        let s = TrialSetup::default();
        let w = s.l_path();
        // The L path: 20 m then 30 m.
        assert!((path_length(&w) - 50.0).abs() < 1e-12);
        match s.end_stop(&w, 5.0) {
            StopCondition::PathEnd {
                radius,
                settle,
                max_duration,
                ..
            } => assert_eq!((radius, settle, max_duration), (1.0, 2.0, 30.0)),
            other => panic!("{other:?}"),
        }
        let capped = TrialSetup {
            max_duration: Some(6.0),
            ..s.clone()
        };
        match capped.end_stop(&w, 5.0) {
            StopCondition::PathEnd { max_duration, .. } => assert_eq!(max_duration, 6.0),
            other => panic!("{other:?}"),
        }
        s.validate().unwrap();
        let bad = TrialSetup {
            arrival_radius: 0.0,
            ..s
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("arrival_radius")
        );
    }
}
