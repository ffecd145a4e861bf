//! What `dflat identify` prints: the values with their intervals and fit
//! quality, the comparison with the configuration flown, and a ready
//! `[vehicle]` snippet.

use std::fmt::Write as _;

use serde::Serialize;

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
    /// Whether the flown value should change: it lies outside the
    /// interval and more than 5 % away.
    pub change: bool,
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

    /// The comparison with the configuration flown, one row per field.
    pub fn compare(&self, flown: &FlownVehicle) -> Vec<Change> {
        let row = |field, flown: f64, e: Estimate| {
            let off = (e.value - flown).abs();
            Change {
                field,
                flown,
                identified: e.value,
                ci: e.ci,
                change: e.ci.is_finite() && off > e.ci && off > KEEP_FRACTION * flown.abs(),
            }
        };
        let delay_ms = Estimate {
            value: self.delay.value * 1e3,
            ci: self.delay.ci * 1e3,
        };
        let mut out = vec![
            row("tau", flown.tau, self.tau),
            row("k", flown.k, self.gain),
            row("delay_ms", flown.delay_ms, delay_ms),
        ];
        if let Some(d) = self.drag_estimate() {
            out.push(row("drag_h", flown.drag_h, d));
        }
        if let Some((hover, tau_t)) = self.vertical_estimates() {
            out.push(row("hover_thrust", flown.hover_thrust, hover));
            out.push(row("tau_thrust", flown.tau_thrust, tau_t));
        }
        out
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
                let verdict = if !c.ci.is_finite() {
                    "keep (not determined by this flight)".to_owned()
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
        let _ = writeln!(s, "tau = {:.3}", self.vehicle_tau());
        let _ = writeln!(s, "k = {:.3}", self.gain.value);
        let _ = writeln!(s, "delay_ms = {:.1}", (self.delay.value * 1e3).max(0.0));
        match self.drag_estimate() {
            Some(d) if d.ci.is_finite() => {
                let _ = writeln!(
                    s,
                    "# Horizontal drag {} /s (acceleration the tilt does not explain,\n\
                     # against velocity).\ndrag_h = {:.3}",
                    fmt_ci(&d, 1.0, 3),
                    d.value.clamp(0.0, 2.0)
                );
            }
            _ => {
                let _ = writeln!(s, "# drag_h: not determined by this flight.");
            }
        }
        match self.vertical_estimates() {
            Some((hover, tau_t)) => {
                let _ = writeln!(s, "hover_thrust = {:.3}", hover.value);
                if tau_t.ci.is_finite() && tau_t.ci < tau_t.value {
                    let _ = writeln!(s, "tau_thrust = {:.3}", tau_t.value);
                } else if let Some(f) = flown {
                    let _ = writeln!(
                        s,
                        "# τ_T not determined by this flight: the value flown.\ntau_thrust = {:.3}",
                        f.tau_thrust
                    );
                } else {
                    let _ = writeln!(
                        s,
                        "# tau_thrust: not determined by this flight (thrust barely varied)."
                    );
                }
            }
            None => {
                let _ = writeln!(
                    s,
                    "# hover_thrust, tau_thrust: not identified (no thrust variation: planar model?)."
                );
            }
        }
        s
    }
}
