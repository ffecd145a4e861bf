//! The autopilot's parameters as the tick uses them: the requests due
//! (`crate::autopilot_params`), and the values read back — the hover
//! thrust (flown with `vehicle.hover_thrust_from_autopilot`, else compared)
//! and the tilt limit (which refuses engagement: `tick/standby.rs`).

use dflat_link::ThrustMapping;
use dflat_link::dialect::MavSeverity;
use tracing::{debug, info, warn};

use super::ControlCore;
use crate::autopilot_params::ParamKind;
use crate::config::ThrustMode;

impl ControlCore {
    /// Queues the parameter requests due at `t` (sent with the texts).
    pub(super) fn request_params(&mut self, t: f64) {
        for name in self.engagement.params.due(t) {
            debug!(name, "requesting the autopilot's parameter");
            self.pending_texts
                .push(dflat_link::params::param_request_read(
                    (self.settings.target.system, self.settings.target.component),
                    name,
                ));
        }
    }

    /// A PARAM_VALUE from the autopilot: a value dflat reads is logged next
    /// to the configuration's, and said when they differ.
    pub(super) fn apply_param(&mut self, name: &str, value: f64) {
        let Some(known) = self.engagement.params.on_value(name, value) else {
            return;
        };
        let v = self.settings.vehicle;
        match known.spec.kind {
            ParamKind::HoverThrust if v.hover_thrust_from_autopilot => {
                self.fly_autopilot_hover(name, known.value);
            }
            ParamKind::HoverThrust => {
                info!(
                    param = name,
                    autopilot = known.value,
                    config = v.hover_thrust,
                    "hover thrust: the configuration's vehicle.hover_thrust is flown; \
                     the disturbance estimator takes up a difference"
                );
                if v.thrust_mode == ThrustMode::Normalized
                    && (known.value - v.hover_thrust).abs() > 0.05
                {
                    let text = format!(
                        "dflat: {name} {:.2}, config hover {:.2}",
                        known.value, v.hover_thrust
                    );
                    self.text(MavSeverity::MAV_SEVERITY_WARNING, &text);
                }
            }
            ParamKind::TiltLimitDeg => {
                info!(
                    param = name,
                    autopilot_deg = known.value,
                    config_deg = v.max_tilt.to_degrees(),
                    "tilt limit"
                );
            }
        }
    }

    /// `vehicle.hover_thrust_from_autopilot`: the autopilot's hover thrust
    /// `value` (parameter `name`) becomes the one flown — the thrust
    /// mapping and the level hover's thrust — if it is in 0.05–0.95 and
    /// the daemon has not engaged yet (a change in flight would step the
    /// thrust). Said either way.
    fn fly_autopilot_hover(&mut self, name: &str, value: f64) {
        let v = self.settings.vehicle;
        if v.thrust_mode != ThrustMode::Normalized {
            return;
        }
        let (engagements, _) = self.supervisor.engagement_counts();
        let (lo, hi) = crate::config::HOVER_THRUST_RANGE;
        let text = if !(lo..=hi).contains(&value) {
            warn!(
                param = name,
                value, "autopilot hover thrust outside 0.05–0.95: vehicle.hover_thrust flown"
            );
            format!(
                "dflat: {name} {value:.2} refused, hover {:.2} flown",
                v.hover_thrust
            )
        } else if engagements > 0 {
            warn!(
                param = name,
                value, "autopilot hover thrust arrived after engagement: not flown"
            );
            format!(
                "dflat: {name} {value:.2} late, hover {:.2} flown",
                v.hover_thrust
            )
        } else {
            self.mapping = ThrustMapping::Normalized {
                hover_thrust: value,
                gravity: v.gravity,
            };
            self.failsafe.fallback.hover_thrust = value;
            info!(
                param = name,
                value,
                config = v.hover_thrust,
                "flying the autopilot's hover thrust"
            );
            format!("dflat: flying {name} {value:.2} as hover thrust")
        };
        self.text(MavSeverity::MAV_SEVERITY_INFO, &text);
    }
}
