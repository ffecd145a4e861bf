//! System identification from a flight log: the numbers the `[vehicle]`
//! model needs (`dflat identify`).
//!
//! * per attitude axis (roll, pitch), from SET_ATTITUDE_TARGET against
//!   ATTITUDE: the first-order time constant τ, the gain k̃ and a pure
//!   delay d ([`attitude`]);
//! * for the spatial model, from the commanded thrust, the measured tilt
//!   and the altitude: the hover thrust and the thrust time constant τ_T
//!   ([`vertical`]);
//! * the rotor drag d_r (spatial model), from the altitude the thrust does
//!   not explain against the velocity across the rotor plane, jointly with
//!   the hover thrust ([`vertical`]);
//! * the horizontal linear drag D, from the acceleration that the measured
//!   tilt (and, when determined, the rotor drag) does not explain against
//!   the velocity ([`drag`]).
//!
//! Each value is recommended only when the flight excited it
//! ([`excitation`]): its regressor moved and its interval is small against
//! it; otherwise it is kept and said to be unexcited.
//!
//! The pure delay is its own term (`vehicle.delay_ms`): the model has one.
//!
//! Only *engaged* data are used (the autopilot armed in its offboard mode
//! and commands streaming, [`FlightLog::engaged_segments`]). Each value
//! comes with a 95 % confidence interval (least squares, inflated for
//! correlated residuals) and the fit quality: the share of variance
//! explained and the residuals' whiteness (Ljung–Box). The maths is pure:
//! [`identify`] takes the decoded log and returns values or a refusal.

pub mod attitude;
pub mod drag;
pub mod excitation;
pub mod stats;
pub mod vertical;

mod report;
pub use report::{Change, FlownVehicle};

use serde::Serialize;
use thiserror::Error;

use crate::flightlog::FlightLog;
use attitude::{AxisData, AxisFit, fit_axis};
use drag::{DragData, DragFit, DragSegment, ThrustModel, fit_drag};
use vertical::{VerticalData, VerticalFit, VerticalSegment, fit_vertical};

/// Least engaged time \[s\] to identify anything.
pub const MIN_ENGAGED_S: f64 = 3.0;
/// Least standard deviation of an axis' attitude command \[deg\] for it to
/// be identified.
pub const MIN_ANGLE_STD_DEG: f64 = 1.0;
/// Least standard deviation of the thrust command (normalised) for τ_T.
pub const MIN_THRUST_STD: f64 = 0.002;
/// Length of the attitude chunks \[s\] (each from its own first sample).
const ATTITUDE_CHUNK_S: f64 = 5.0;
/// Length of the altitude chunks \[s\] (each with its own z₀, ż₀).
const VERTICAL_CHUNK_S: f64 = 3.0;
/// Length of the horizontal chunks for the drag fit \[s\] (each with its
/// own initial position and velocity).
const DRAG_CHUNK_S: f64 = 4.0;
/// Gravity assumed \[m/s²\].
pub const GRAVITY: f64 = 9.81;
/// Half-width of the window the velocity across the rotor plane is
/// fitted on \[s\] (a straight line through the poses of ±0.1 s).
const ROTOR_VELOCITY_HALF_S: f64 = 0.1;

/// Why a log cannot be identified.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum IdentifyError {
    /// Nothing was flown under the daemon's commands.
    #[error(
        "no engaged segment: {commands} attitude commands and {heartbeats} autopilot heartbeats in the log, \
         but never armed in the offboard mode while commands streamed (is this the daemon's .tlog of a flight?)"
    )]
    NoEngagedSegment {
        /// SET_ATTITUDE_TARGET in the log.
        commands: usize,
        /// Autopilot HEARTBEATs in the log.
        heartbeats: usize,
    },
    /// Too short engaged.
    #[error("only {seconds:.1} s engaged (need at least {MIN_ENGAGED_S} s): fly longer")]
    TooShort {
        /// Engaged time \[s\].
        seconds: f64,
    },
    /// The commands did not move enough to see the response.
    #[error(
        "too little excitation: attitude command standard deviation roll {roll_deg:.2}°, pitch {pitch_deg:.2}° \
         (need ≥ {MIN_ANGLE_STD_DEG}° on an axis) — a hover says nothing about τ and k̃; \
         fly a path with corners (`dflat identify --manoeuvre` prints one)"
    )]
    TooLittleExcitation {
        /// Roll command σ \[deg\].
        roll_deg: f64,
        /// Pitch command σ \[deg\].
        pitch_deg: f64,
    },
    /// The log has no ATTITUDE messages in the engaged segments.
    #[error("no ATTITUDE from the autopilot during the engaged segments: cannot see the response")]
    NoAttitude,
}

/// One axis: fitted, or why not.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AxisResult {
    /// Fitted.
    Fitted(AxisFit),
    /// Not identified, and why.
    Skipped(String),
}

/// The vertical fit, or why not.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VerticalResult {
    /// Fitted.
    Fitted(VerticalFit),
    /// Not identified, and why.
    Skipped(String),
}

/// The drag fit, or why not.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DragResult {
    /// Fitted.
    Fitted(DragFit),
    /// Not identified, and why.
    Skipped(String),
}

/// A value with its 95 % half-width.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// The value.
    pub value: f64,
    /// 95 % half-width (infinite: not determined).
    pub ci: f64,
}

impl Estimate {
    /// Inverse-variance mean of estimates (finite intervals only; the plain
    /// mean when none has one).
    pub fn combine(items: &[Estimate]) -> Option<Estimate> {
        let finite: Vec<&Estimate> = items
            .iter()
            .filter(|e| e.ci.is_finite() && e.ci > 0.0)
            .collect();
        if finite.is_empty() {
            let n = items.len();
            return (n > 0).then(|| Estimate {
                value: items.iter().map(|e| e.value).sum::<f64>() / n as f64,
                ci: items.iter().map(|e| e.ci).fold(0.0, f64::max),
            });
        }
        let w: f64 = finite.iter().map(|e| e.ci.powi(-2)).sum();
        let v = finite.iter().map(|e| e.value * e.ci.powi(-2)).sum::<f64>() / w;
        Some(Estimate {
            value: v,
            ci: w.powf(-0.5),
        })
    }
}

/// What [`identify`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identification {
    /// Engaged segments used \[s, s\] (log time).
    pub segments: Vec<(f64, f64)>,
    /// Engaged time \[s\].
    pub engaged_s: f64,
    /// Roll axis.
    pub roll: AxisResult,
    /// Pitch axis.
    pub pitch: AxisResult,
    /// τ over the fitted axes \[s\].
    pub tau: Estimate,
    /// k̃ over the fitted axes.
    pub gain: Estimate,
    /// Pure delay over the fitted axes \[s\].
    pub delay: Estimate,
    /// Vertical (spatial model).
    pub vertical: VerticalResult,
    /// Horizontal linear drag.
    pub drag: DragResult,
    /// Standard deviation of the commanded vertical specific thrust over
    /// the engaged time \[m/s²\] (the regressor of τ_T; 0 without the
    /// vertical fit): [`excitation::vertical_accel_std`].
    pub vertical_excitation: f64,
    /// Standard deviation of the velocity across the rotor plane's
    /// vertical part `(v − n·(n·v))_z` over the engaged poses \[m/s\] (the
    /// regressor of the rotor drag; 0 without the vertical fit).
    pub rotor_excitation: f64,
}

impl Identification {
    /// The τ to configure \[s\]: the lag alone (the model has its own
    /// delay term, `vehicle.delay_ms`).
    pub fn vehicle_tau(&self) -> f64 {
        self.tau.value
    }

    /// The drag estimate \[1/s\], when fitted.
    pub fn drag_estimate(&self) -> Option<Estimate> {
        match &self.drag {
            DragResult::Fitted(f) => Some(Estimate {
                value: f.drag,
                ci: f.drag_ci,
            }),
            DragResult::Skipped(_) => None,
        }
    }
}

fn std_dev(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = v.clone().count().max(1) as f64;
    let m = v.clone().sum::<f64>() / n;
    (v.map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

fn inside(segments: &[(f64, f64)], t: f64) -> Option<usize> {
    segments.iter().position(|(a, b)| t >= *a && t <= *b)
}

/// Splits the samples of each segment into chunks of at most `len` seconds.
fn chunked<T: Copy>(
    segments: &[(f64, f64)],
    samples: impl Iterator<Item = (f64, T)>,
    len: f64,
) -> Vec<Vec<Vec<(f64, T)>>> {
    let mut out: Vec<Vec<Vec<(f64, T)>>> = vec![Vec::new(); segments.len()];
    for (t, v) in samples {
        let Some(s) = inside(segments, t) else {
            continue;
        };
        let chunks = &mut out[s];
        match chunks.last_mut() {
            Some(c) if c.first().is_some_and(|(t0, _)| t - t0 < len) => c.push((t, v)),
            _ => chunks.push(vec![(t, v)]),
        }
    }
    out
}

/// Identifies the vehicle from a decoded flight log.
pub fn identify(log: &FlightLog) -> Result<Identification, IdentifyError> {
    let segments = log.engaged_segments();
    if segments.is_empty() {
        return Err(IdentifyError::NoEngagedSegment {
            commands: log.commands.len(),
            heartbeats: log.modes.len(),
        });
    }
    let engaged_s: f64 = segments.iter().map(|(a, b)| b - a).sum();
    if engaged_s < MIN_ENGAGED_S {
        return Err(IdentifyError::TooShort { seconds: engaged_s });
    }
    let engaged_cmds: Vec<_> = log
        .commands
        .iter()
        .filter(|c| inside(&segments, c.t).is_some())
        .collect();
    let roll_std = std_dev(engaged_cmds.iter().map(|c| c.euler[0])).to_degrees();
    let pitch_std = std_dev(engaged_cmds.iter().map(|c| c.euler[1])).to_degrees();
    if roll_std < MIN_ANGLE_STD_DEG && pitch_std < MIN_ANGLE_STD_DEG {
        return Err(IdentifyError::TooLittleExcitation {
            roll_deg: roll_std,
            pitch_deg: pitch_std,
        });
    }
    if !log
        .attitude
        .iter()
        .any(|a| inside(&segments, a.t).is_some())
    {
        return Err(IdentifyError::NoAttitude);
    }
    let axis = |i: usize, std_deg: f64| -> AxisResult {
        if std_deg < MIN_ANGLE_STD_DEG {
            return AxisResult::Skipped(format!(
                "command standard deviation {std_deg:.2}° < {MIN_ANGLE_STD_DEG}°: too little excitation"
            ));
        }
        let data = AxisData {
            commands: log.commands.iter().map(|c| (c.t, c.euler[i])).collect(),
            chunks: chunked(
                &segments,
                log.attitude.iter().map(|a| (a.t, a.euler[i])),
                ATTITUDE_CHUNK_S,
            )
            .into_iter()
            .flatten()
            .collect(),
        };
        match fit_axis(&data) {
            Some(fit) => AxisResult::Fitted(fit),
            None => AxisResult::Skipped("fewer than 20 attitude samples engaged".into()),
        }
    };
    let roll = axis(0, roll_std);
    let pitch = axis(1, pitch_std);
    let fits: Vec<&AxisFit> = [&roll, &pitch]
        .into_iter()
        .filter_map(|a| match a {
            AxisResult::Fitted(f) => Some(f),
            AxisResult::Skipped(_) => None,
        })
        .collect();
    let pick = |f: fn(&AxisFit) -> Estimate| {
        Estimate::combine(&fits.iter().map(|a| f(a)).collect::<Vec<_>>())
    };
    let (Some(tau), Some(gain), Some(delay)) = (
        pick(|a| Estimate {
            value: a.tau,
            ci: a.tau_ci,
        }),
        pick(|a| Estimate {
            value: a.gain,
            ci: a.gain_ci,
        }),
        pick(|a| Estimate {
            value: a.delay,
            ci: a.delay_ci,
        }),
    ) else {
        return Err(IdentifyError::NoAttitude);
    };
    let rotor = rotor_velocity(log, &segments);
    let vertical = vertical_fit(log, &segments, &engaged_cmds, delay.value, &rotor);
    let rotor_excitation = match &vertical {
        VerticalResult::Fitted(_) => std_dev(rotor.iter().map(|(_, q)| q[2])),
        VerticalResult::Skipped(_) => 0.0,
    };
    // The horizontal fit counts the rotor drag in only when identify
    // recommends it: else drag_h carries all of it.
    let rotor_drag = match &vertical {
        VerticalResult::Fitted(v) => v
            .drag_rotor
            .filter(|e| report::rotor_excitation_check(*e, rotor_excitation).is_excited()),
        VerticalResult::Skipped(_) => None,
    };
    let drag = drag_fit(
        log,
        &segments,
        &vertical,
        delay.value,
        rotor_drag.map(|e| (e.value, &rotor[..])),
    );
    let vertical_excitation = match &vertical {
        VerticalResult::Fitted(v) => excitation::vertical_accel_std(
            &engaged_cmds
                .iter()
                .map(|c| (c.t, c.thrust))
                .collect::<Vec<_>>(),
            &log.attitude
                .iter()
                .map(|a| (a.t, a.euler[0].cos() * a.euler[1].cos()))
                .collect::<Vec<_>>(),
            v.hover_thrust,
            GRAVITY,
        ),
        VerticalResult::Skipped(_) => 0.0,
    };
    Ok(Identification {
        segments,
        engaged_s,
        roll,
        pitch,
        tau,
        gain,
        delay,
        vertical,
        drag,
        vertical_excitation,
        rotor_excitation,
    })
}

/// (time \[s\], `v − n·(n·v)` NED \[m/s\]) per engaged pose.
type RotorSeries = [(f64, [f64; 3])];

/// The velocity across the rotor plane, `q = v − n·(n·v)` (NED \[m/s\]),
/// at each engaged pose: v the slope of a straight line through the poses
/// within [`ROTOR_VELOCITY_HALF_S`], n = R·e3 the measured attitude's thrust
/// axis at the pose's time.
fn rotor_velocity(log: &FlightLog, segments: &[(f64, f64)]) -> Vec<(f64, [f64; 3])> {
    let poses: Vec<(f64, [f64; 3])> = log
        .positions()
        .iter()
        .map(|p| (log.pose_time(p), p.position))
        .filter(|(t, _)| inside(segments, *t).is_some())
        .collect();
    let attitude: Vec<(f64, [f64; 3])> = log.attitude.iter().map(|a| (a.t, a.euler)).collect();
    let h = ROTOR_VELOCITY_HALF_S;
    let mut out = Vec::with_capacity(poses.len());
    let (mut lo, mut hi) = (0, 0);
    for (i, &(t, _)) in poses.iter().enumerate() {
        while poses[lo].0 < t - h {
            lo += 1;
        }
        hi = hi.max(i);
        while hi + 1 < poses.len() && poses[hi + 1].0 <= t + h {
            hi += 1;
        }
        let w = &poses[lo..=hi];
        if w.len() < 3 || inside(segments, w[0].0) != inside(segments, w[w.len() - 1].0) {
            continue;
        }
        let mt = w.iter().map(|(s, _)| s).sum::<f64>() / w.len() as f64;
        let stt: f64 = w.iter().map(|(s, _)| (s - mt).powi(2)).sum();
        if stt <= 0.0 {
            continue;
        }
        let v = nalgebra::Vector3::from_fn(|ax, _| {
            let mp = w.iter().map(|(_, p)| p[ax]).sum::<f64>() / w.len() as f64;
            w.iter().map(|(s, p)| (s - mt) * (p[ax] - mp)).sum::<f64>() / stt
        });
        let [roll, pitch, yaw] = drag::attitude_at(&attitude, t);
        let n = crate::learn::parametric::thrust_axis(roll, pitch, yaw);
        let q = v - n * n.dot(&v);
        out.push((t, [q.x, q.y, q.z]));
    }
    out
}

fn drag_fit(
    log: &FlightLog,
    segments: &[(f64, f64)],
    vertical: &VerticalResult,
    delay: f64,
    rotor: Option<(f64, &RotorSeries)>,
) -> DragResult {
    let positions = log.positions();
    let chunks = chunked(
        segments,
        positions
            .iter()
            .map(|p| (log.pose_time(p), [p.position[0], p.position[1]])),
        DRAG_CHUNK_S,
    );
    let data = DragData {
        attitude: log.attitude.iter().map(|a| (a.t, a.euler)).collect(),
        // The thrust the vertical fit found (spatial flights); else the
        // altitude is taken as held.
        thrust: match vertical {
            VerticalResult::Fitted(v) => Some(ThrustModel {
                commands: log.commands.iter().map(|c| (c.t, c.thrust)).collect(),
                hover_thrust: v.hover_thrust,
                tau_thrust: v.tau_thrust,
                delay,
            }),
            VerticalResult::Skipped(_) => None,
        },
        rotor: rotor.map(|(d, q)| (d, q.iter().map(|(t, q)| (*t, [q[0], q[1]])).collect())),
        segments: segments
            .iter()
            .zip(chunks)
            .map(|(&span, chunks)| DragSegment { span, chunks })
            .collect(),
        gravity: GRAVITY,
    };
    match fit_drag(&data) {
        Some(fit) => DragResult::Fitted(fit),
        None => DragResult::Skipped(
            "fewer than 50 position samples engaged, or too little speed variation".into(),
        ),
    }
}

fn vertical_fit(
    log: &FlightLog,
    segments: &[(f64, f64)],
    engaged_cmds: &[&crate::flightlog::CommandSample],
    delay: f64,
    rotor: &RotorSeries,
) -> VerticalResult {
    let thrust_std = std_dev(engaged_cmds.iter().map(|c| c.thrust));
    if thrust_std < 1e-4 {
        return VerticalResult::Skipped(
            "thrust command constant (fixed thrust: the autopilot holds altitude, planar model)"
                .into(),
        );
    }
    let positions = log.positions();
    let chunks = chunked(
        segments,
        positions.iter().map(|p| (log.pose_time(p), p.position[2])),
        VERTICAL_CHUNK_S,
    );
    let data = VerticalData {
        thrust: log.commands.iter().map(|c| (c.t, c.thrust)).collect(),
        tilt_cos: log
            .attitude
            .iter()
            .map(|a| (a.t, a.euler[0].cos() * a.euler[1].cos()))
            .collect(),
        segments: segments
            .iter()
            .zip(chunks)
            .map(|(&span, chunks)| VerticalSegment { span, chunks })
            .collect(),
        rotor: rotor.iter().map(|(t, q)| (*t, q[2])).collect(),
        delay,
        gravity: GRAVITY,
    };
    match fit_vertical(&data) {
        Some(mut fit) => {
            if thrust_std < MIN_THRUST_STD {
                fit.tau_thrust_ci = f64::INFINITY;
            }
            VerticalResult::Fitted(fit)
        }
        None => VerticalResult::Skipped(
            "fewer than 50 position samples engaged, or the thrust does not explain the altitude"
                .into(),
        ),
    }
}

/// Speed of the identification manoeuvre \[m/s\].
pub const MANOEUVRE_SPEED: f64 = 4.0;

/// A short, safe identification flight from `start` (NED): a closed
/// 8 m × 6 m loop with altitude steps of ±1.5 m, so that both attitude
/// axes and the thrust are excited (corners and climbs), flown at
/// [`MANOEUVRE_SPEED`] in about 15 s.
pub fn manoeuvre_path(start: [f64; 3]) -> Vec<[f64; 3]> {
    let [x, y, z] = start;
    vec![
        [x, y, z],
        [x + 8.0, y, z],
        [x + 8.0, y + 6.0, z - 1.5],
        [x, y + 6.0, z + 1.0],
        [x, y, z],
    ]
}

/// The manoeuvre as a `[mission]` table for the daemon's configuration.
pub fn manoeuvre_mission(start: [f64; 3]) -> String {
    let points: Vec<String> = manoeuvre_path(start)
        .iter()
        .map(|p| format!("[{:.1}, {:.1}, {:.1}]", p[0], p[1], p[2]))
        .collect();
    format!(
        "# Identification manoeuvre (`dflat identify --manoeuvre`): a closed loop\n\
         # with corners and ±1.5 m altitude steps, about 15 s at {MANOEUVRE_SPEED} m/s.\n\
         # Fly it once engaged (start = \"path\"), then `dflat identify` the .tlog.\n\
         [mission]\nstart = \"path\"\npath = [{}]\nspeed = {MANOEUVRE_SPEED:.1}\n",
        points.join(", ")
    )
}
