//! What `dflat identify` prints: the values with their intervals and fit
//! quality, the comparison with the configuration flown, and a ready
//! `[vehicle]` snippet.

use std::fmt::Write as _;

use serde::Serialize;

use super::excitation::{self, Excitation, MIN_VERTICAL_ACCEL_STD, Regressor};
use super::{AxisResult, DragResult, Estimate, Identification, VerticalResult};

/// The `[vehicle]` values a flight was flown with (from its configuration).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FlownVehicle {
    /// `vehicle.tau` \[s\].
    pub tau: f64,
    /// `vehicle.k`.
    pub k: f64,
    /// `vehicle.tau_thrust` \[s\].
    pub tau_thrust: f64,
    /// `vehicle.hover_thrust`.
    pub hover_thrust: f64,
    /// The model was the spatial one (thrust values in use).
    pub spatial: bool,
    /// `vehicle.delay_ms` \[ms\].
    pub delay_ms: f64,
    /// `vehicle.drag_h` \[1/s\].
    pub drag_h: f64,
    /// `vehicle.drag_rotor` \[1/s\].
    pub drag_rotor: f64,
}

impl FlownVehicle {
    /// The flown value of a `[vehicle]` field named as in [`Change::field`]
    /// (NaN for a name it does not hold).
    pub fn value_of(&self, field: &str) -> f64 {
        match field {
            "tau" => self.tau,
            "k" => self.k,
            "tau_thrust" => self.tau_thrust,
            "hover_thrust" => self.hover_thrust,
            "delay_ms" => self.delay_ms,
            "drag_h" => self.drag_h,
            "drag_rotor" => self.drag_rotor,
            _ => f64::NAN,
        }
    }
}

/// One field's comparison.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Change {
    /// `[vehicle]` field.
    pub field: &'static str,
    /// Value flown.
    pub flown: f64,
    /// Value identified (as it would be configured).
    pub identified: f64,
    /// 95 % half-width of the identified value.
    pub ci: f64,
    /// Whether the flight excited it ([`excitation`]).
    pub excitation: Excitation,
    /// Whether the flown value should change: the flight excited it, and it
    /// lies outside the interval and more than 5 % away.
    pub change: bool,
}

/// One identified `[vehicle]` field, as it would be configured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Parameter {
    /// `[vehicle]` field.
    pub field: &'static str,
    /// The value and its 95 % half-width (in the field's unit).
    pub estimate: Estimate,
    /// Whether the flight excited it.
    pub excitation: Excitation,
}

/// Absolute half-width below which a field counts as determined whatever
/// its value (in the field's unit): 5 ms of delay, 0.02 /s of drag.
fn floor_of(field: &str) -> f64 {
    match field {
        "delay_ms" => 5.0,
        "drag_h" | "drag_rotor" => 0.02,
        _ => 0.0,
    }
}

/// Least standard deviation of the velocity across the rotor plane's
/// vertical part \[m/s\] for the rotor drag to be recommended: a vehicle
/// tilted into its motion (0.2 m/s: 2 m/s at 6° of tilt). The
/// identification manoeuvre (`dflat identify --manoeuvre`, 4 m/s) gives
/// 0.33 m/s, and there the interval of a 0.3 /s rotor drag is ± 0.006
/// (`e2e_identify`): the interval's rule decides the rest.
pub const MIN_ROTOR_VELOCITY_STD: f64 = 0.2;

/// The excitation check of the rotor drag `e` with the standard deviation
/// `spread` \[m/s\] of its regressor ([`super::Identification::rotor_excitation`]).
pub(super) fn rotor_excitation_check(e: Estimate, spread: f64) -> Excitation {
    excitation::check(
        e.value,
        e.ci,
        floor_of("drag_rotor"),
        Some(Regressor {
            what: "velocity across the rotor plane, vertical part, std",
            value: spread,
            needed: MIN_ROTOR_VELOCITY_STD,
            unit: "m/s",
        }),
    )
}

/// Relative difference below which a value is kept.
const KEEP_FRACTION: f64 = 0.05;

fn fmt_ci(e: &Estimate, unit_scale: f64, digits: usize) -> String {
    if e.ci.is_finite() {
        format!(
            "{:.digits$} ± {:.digits$}",
            e.value * unit_scale,
            e.ci * unit_scale
        )
    } else {
        format!("{:.digits$} (not determined)", e.value * unit_scale)
    }
}

impl Identification {
    /// The hover thrust and τ_T, when the vertical fit ran.
    pub fn vertical_estimates(&self) -> Option<(Estimate, Estimate)> {
        match &self.vertical {
            VerticalResult::Fitted(v) => Some((
                Estimate {
                    value: v.hover_thrust,
                    ci: v.hover_thrust_ci,
                },
                Estimate {
                    value: v.tau_thrust,
                    ci: v.tau_thrust_ci,
                },
            )),
            VerticalResult::Skipped(_) => None,
        }
    }

    /// The identified fields with their excitation, in snippet order
    /// (`tau`, `k`, `delay_ms`, then `drag_h`, `hover_thrust`, `tau_thrust`
    /// where fitted).
    pub fn parameters(&self) -> Vec<Parameter> {
        let param = |field: &'static str, e: Estimate, regressor: Option<Regressor>| Parameter {
            field,
            estimate: e,
            excitation: excitation::check(e.value, e.ci, floor_of(field), regressor),
        };
        let delay_ms = Estimate {
            value: self.delay.value * 1e3,
            ci: self.delay.ci * 1e3,
        };
        let mut out = vec![
            param("tau", self.tau, None),
            param("k", self.gain, None),
            param("delay_ms", delay_ms, None),
        ];
        if let Some(d) = self.drag_estimate() {
            out.push(param("drag_h", d, None));
        }
        if let VerticalResult::Fitted(v) = &self.vertical
            && let Some(e) = v.drag_rotor
        {
            out.push(Parameter {
                field: "drag_rotor",
                estimate: e,
                excitation: rotor_excitation_check(e, self.rotor_excitation),
            });
        }
        if let Some((hover, tau_t)) = self.vertical_estimates() {
            out.push(param("hover_thrust", hover, None));
            let climbs = Regressor {
                what: "commanded vertical specific thrust std",
                value: self.vertical_excitation,
                needed: MIN_VERTICAL_ACCEL_STD,
                unit: "m/s²",
            };
            out.push(param("tau_thrust", tau_t, Some(climbs)));
        }
        out
    }

    /// The comparison with the configuration flown, one row per field: a
    /// field changes only when the flight excited it, the flown value lies
    /// outside its interval and more than 5 % away.
    pub fn compare(&self, flown: &FlownVehicle) -> Vec<Change> {
        self.parameters()
            .into_iter()
            .map(|p| {
                let flown = flown.value_of(p.field);
                let e = p.estimate;
                let off = (e.value - flown).abs();
                Change {
                    field: p.field,
                    flown,
                    identified: e.value,
                    ci: e.ci,
                    change: p.excitation.is_excited()
                        && off > e.ci
                        && off > KEEP_FRACTION * flown.abs(),
                    excitation: p.excitation,
                }
            })
            .collect()
    }

    /// The human-readable report (`source` names the log).
    pub fn report(&self, source: &str, flown: Option<&FlownVehicle>) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "dflat identify {source}: {:.1} s engaged in {} segment(s)",
            self.engaged_s,
            self.segments.len()
        );
        let _ = writeln!(
            s,
            "\nattitude (first order with pure delay, per axis; 95 % intervals):"
        );
        for (name, axis) in [("roll", &self.roll), ("pitch", &self.pitch)] {
            match axis {
                AxisResult::Fitted(f) => {
                    let _ = writeln!(
                        s,
                        "  {name:<5} τ {:.3} ± {:.3} s   k̃ {:.3} ± {:.3}   delay {:.1} ± {:.1} ms   \
                         variance explained {:.1} %   residual rms {:.2}°   whiteness: ρ₁ {:.2}, Ljung–Box Q {:.0} ({})   {} samples",
                        f.tau,
                        f.tau_ci,
                        f.gain,
                        f.gain_ci,
                        f.delay * 1e3,
                        f.delay_ci * 1e3,
                        f.variance_explained * 100.0,
                        f.rms.to_degrees(),
                        f.whiteness.lag1,
                        f.whiteness.ljung_box,
                        if f.whiteness.white {
                            "white"
                        } else {
                            "not white: unmodelled dynamics"
                        },
                        f.samples
                    );
                }
                AxisResult::Skipped(why) => {
                    let _ = writeln!(s, "  {name:<5} not identified: {why}");
                }
            }
        }
        let _ = writeln!(
            s,
            "  both  τ {} s   k̃ {}   delay {} ms",
            fmt_ci(&self.tau, 1.0, 3),
            fmt_ci(&self.gain, 1.0, 3),
            fmt_ci(&self.delay, 1e3, 1)
        );
        let _ = writeln!(s, "\nvertical (spatial model):");
        match &self.vertical {
            VerticalResult::Fitted(v) => {
                let tau_t = Estimate {
                    value: v.tau_thrust,
                    ci: v.tau_thrust_ci,
                };
                let _ = writeln!(
                    s,
                    "  hover thrust {:.3} ± {:.3}   τ_T {} s   variance explained {:.1} %   residual rms {:.3} m   \
                     whiteness: ρ₁ {:.2}, Ljung–Box Q {:.0} ({})   {} samples",
                    v.hover_thrust,
                    v.hover_thrust_ci,
                    fmt_ci(&tau_t, 1.0, 3),
                    v.variance_explained * 100.0,
                    v.rms,
                    v.whiteness.lag1,
                    v.whiteness.ljung_box,
                    if v.whiteness.white {
                        "white"
                    } else {
                        "not white"
                    },
                    v.samples
                );
                if let Some(rotor) = v.drag_rotor {
                    let _ = writeln!(
                        s,
                        "  rotor drag {} /s (against the velocity across the rotor plane, std {:.2} m/s)",
                        fmt_ci(&rotor, 1.0, 3),
                        self.rotor_excitation
                    );
                }
            }
            VerticalResult::Skipped(why) => {
                let _ = writeln!(s, "  not identified: {why}");
            }
        }
        let _ = writeln!(
            s,
            "\nhorizontal drag (tilt's acceleration vs the measured motion):"
        );
        match &self.drag {
            DragResult::Fitted(d) => {
                let _ = writeln!(
                    s,
                    "  drag_h {:.3} ± {:.3} /s   offset [{:.2}, {:.2}] m/s²   variance explained {:.1} %   \
                     residual rms {:.3} m   whiteness: ρ₁ {:.2}, Ljung–Box Q {:.0} ({})   {} samples",
                    d.drag,
                    d.drag_ci,
                    d.offset[0],
                    d.offset[1],
                    d.variance_explained * 100.0,
                    d.rms,
                    d.whiteness.lag1,
                    d.whiteness.ljung_box,
                    if d.whiteness.white {
                        "white"
                    } else {
                        "not white"
                    },
                    d.samples
                );
            }
            DragResult::Skipped(why) => {
                let _ = writeln!(s, "  not identified: {why}");
            }
        }
        if let Some(flown) = flown {
            let _ = writeln!(s, "\ncompared with the configuration flown:");
            for c in self.compare(flown) {
                let verdict = if let Excitation::Unexcited(why) = &c.excitation {
                    format!("keep: unexcited ({why})")
                } else if c.change {
                    format!(
                        "change to {:.3} ({:+.0} %)",
                        c.identified,
                        (c.identified / c.flown - 1.0) * 100.0
                    )
                } else {
                    "keep (within the interval or 5 %)".to_owned()
                };
                let _ = writeln!(
                    s,
                    "  {:<13} flown {:.3}   identified {:.3}   → {verdict}",
                    c.field, c.flown, c.identified
                );
            }
        }
        s
    }

    /// A ready `[vehicle]` snippet (comments say where each value comes
    /// from). Values the flight did not determine are left out, or taken
    /// from `flown` when given.
    pub fn vehicle_snippet(&self, source: &str, flown: Option<&FlownVehicle>) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# From `dflat identify {source}`: {:.1} s engaged.",
            self.engaged_s
        );
        let _ = writeln!(
            s,
            "# Attitude lag τ {} s, pure delay {} ms (its own term, rounded to\n\
             # control ticks by the daemon).",
            fmt_ci(&self.tau, 1.0, 3),
            fmt_ci(&self.delay, 1e3, 1)
        );
        let _ = writeln!(s, "[vehicle]");
        let params = self.parameters();
        for p in &params {
            if p.field == "drag_h" && p.excitation.is_excited() {
                let _ = writeln!(
                    s,
                    "# Horizontal drag {} /s (acceleration the tilt does not explain,\n\
                     # against velocity).",
                    fmt_ci(&p.estimate, 1.0, 3)
                );
            }
            if p.field == "drag_rotor" && p.excitation.is_excited() {
                let _ = writeln!(
                    s,
                    "# Rotor drag {} /s (altitude the thrust does not explain, against\n\
                     # the velocity across the rotor plane).",
                    fmt_ci(&p.estimate, 1.0, 3)
                );
            }
            write_field(&mut s, p, flown);
        }
        if !params.iter().any(|p| p.field == "drag_h") {
            let _ = writeln!(s, "# drag_h: not determined by this flight.");
        }
        if !params.iter().any(|p| p.field == "hover_thrust") {
            let _ = writeln!(
                s,
                "# hover_thrust, tau_thrust: not identified (no thrust variation: planar model?)."
            );
        }
        s
    }
}

/// One `[vehicle]` line of the snippet: the identified value when the
/// flight excited it; else the value flown (when known) under a comment
/// that says why, or only the comment.
fn write_field(s: &mut String, p: &Parameter, flown: Option<&FlownVehicle>) {
    let digits = if p.field == "delay_ms" { 1 } else { 3 };
    let configured = |v: f64| match p.field {
        "delay_ms" => v.max(0.0),
        "drag_h" | "drag_rotor" => v.clamp(0.0, 2.0),
        _ => v,
    };
    match (&p.excitation, flown) {
        (Excitation::Excited, _) => {
            let _ = writeln!(s, "{} = {:.digits$}", p.field, configured(p.estimate.value));
        }
        (Excitation::Unexcited(why), Some(f)) => {
            let _ = writeln!(
                s,
                "# {}: unexcited by this flight ({why}): the value flown.\n{} = {:.digits$}",
                p.field,
                p.field,
                f.value_of(p.field)
            );
        }
        (Excitation::Unexcited(why), None) => {
            let _ = writeln!(
                s,
                "# {}: unexcited by this flight ({why}): keep yours (identified {:.digits$}).",
                p.field, p.estimate.value
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::stats::Whiteness;
    use crate::identify::vertical::VerticalFit;

    /// What identify found on an independent vehicle's level flight: τ_T
    /// 0.456 ± 0.136 s from thrust that only compensated the tilt.
    fn level_flight(tau_thrust_ci: f64, vertical_excitation: f64) -> Identification {
        let e = |value, ci| Estimate { value, ci };
        Identification {
            segments: vec![(0.0, 30.0)],
            engaged_s: 30.0,
            roll: AxisResult::Skipped("test".into()),
            pitch: AxisResult::Skipped("test".into()),
            tau: e(0.1, 0.005),
            gain: e(1.0, 0.02),
            delay: e(0.03, 0.002),
            vertical: VerticalResult::Fitted(VerticalFit {
                hover_thrust: 0.45,
                hover_thrust_ci: 0.004,
                tau_thrust: 0.456,
                tau_thrust_ci,
                drag_rotor: None,
                samples: 1500,
                variance_explained: 0.9,
                rms: 0.02,
                whiteness: Whiteness {
                    lag1: 0.1,
                    ljung_box: 10.0,
                    white: true,
                },
            }),
            drag: DragResult::Skipped("test".into()),
            vertical_excitation,
            rotor_excitation: 0.0,
        }
    }

    fn flown() -> FlownVehicle {
        FlownVehicle {
            tau: 0.2,
            k: 1.0,
            tau_thrust: 0.04,
            hover_thrust: 0.5,
            spatial: true,
            delay_ms: 0.0,
            drag_h: 0.0,
            drag_rotor: 0.0,
        }
    }

    /// The comparison's row of `field` against [`flown`].
    fn change_of(found: &Identification, field: &str) -> Change {
        found
            .compare(&flown())
            .into_iter()
            .find(|c| c.field == field)
            .unwrap()
    }

    fn tau_thrust(found: &Identification) -> Change {
        change_of(found, "tau_thrust")
    }

    /// `field` not changed and said unexcited: the snippet keeps the
    /// value flown (`kept`, its line as written) and says why.
    fn assert_kept_unexcited(found: &Identification, field: &str, kept: &str) {
        let c = change_of(found, field);
        assert!(!c.change && !c.excitation.is_excited(), "{c:?}");
        let snippet = found.vehicle_snippet("flight.tlog", Some(&flown()));
        assert!(snippet.contains(&format!("\n{kept}\n")), "{snippet}");
        assert!(
            snippet.contains(&format!("{field}: unexcited")),
            "{snippet}"
        );
    }

    /// The rotor drag changes only when its regressor moved and its
    /// interval is tight: a slow flight (spread 0.1 m/s) keeps the value
    /// flown, in words, whatever the interval; a fast one changes it.
    #[test]
    fn the_rotor_drag_changes_only_when_the_flight_excited_it() {
        let with_rotor = |spread: f64, ci: f64| {
            let mut found = level_flight(0.01, 0.5);
            if let VerticalResult::Fitted(v) = &mut found.vertical {
                v.drag_rotor = Some(Estimate { value: 0.25, ci });
            }
            found.rotor_excitation = spread;
            found
        };
        for found in [with_rotor(0.1, 0.01), with_rotor(0.5, 0.1)] {
            assert_kept_unexcited(&found, "drag_rotor", "drag_rotor = 0.000");
        }
        let fast = with_rotor(0.5, 0.01);
        let c = change_of(&fast, "drag_rotor");
        assert!(c.change && c.excitation.is_excited(), "{c:?}");
        let snippet = fast.vehicle_snippet("fast.tlog", Some(&flown()));
        assert!(snippet.contains("\ndrag_rotor = 0.250\n"), "{snippet}");
        assert!(
            fast.report("fast.tlog", None)
                .contains("rotor drag 0.250 ± 0.010 /s")
        );
    }

    /// A level flight must not change `tau_thrust`: neither with its 30 %
    /// interval, nor with a tight one when the vertical was never excited;
    /// the snippet keeps the value flown and says why.
    #[test]
    fn a_level_flight_does_not_change_tau_thrust() {
        for found in [level_flight(0.136, 0.05), level_flight(0.01, 0.05)] {
            assert_kept_unexcited(&found, "tau_thrust", "tau_thrust = 0.040");
            let report = found.report("level.tlog", Some(&flown()));
            assert!(report.contains("keep: unexcited"), "{report}");
            // The parameters it did excite still change.
            assert!(
                found
                    .compare(&flown())
                    .iter()
                    .any(|c| c.field == "tau" && c.change)
            );
        }
    }

    /// Climbs with a tight interval: τ_T is recommended.
    #[test]
    fn climbs_change_tau_thrust() {
        let found = level_flight(0.03, 1.2);
        let c = tau_thrust(&found);
        assert!(c.change && c.excitation.is_excited(), "{c:?}");
        let snippet = found.vehicle_snippet("climbs.tlog", Some(&flown()));
        assert!(snippet.contains("\ntau_thrust = 0.456\n"), "{snippet}");
    }
}
