//! The DF window stays true when the heading changes: the real DF-MPC in
//! the pure step, fed the same positions and the same world-frame tilts
//! twice — once at a fixed heading, once turning (standby: the vehicle
//! turns under the pilot; engaged: a setpoint's yaw is flown) — plans the
//! same outputs to rounding, and its commands are the same thrust axis
//! expressed at the other heading. Without the conversion the plans part.

use super::tests::step_events;
use super::*;
use crate::config::YawMode;
use crate::control::{build_controller, thrust_mapping};
use crate::yaw::tilt_at_heading;

const DT: f64 = 0.02;

/// One tick's plan and command.
type Tick = (Option<[[f64; 3]; 4]>, Option<AttitudeCommand>);

/// PX4 armed, in POSCTL (standby) or OFFBOARD (engaged).
fn mode(offboard: bool) -> dflat_link::AutopilotMode {
    dflat_link::AutopilotMode {
        family: dflat_link::AutopilotFamily::Px4,
        custom_mode: if offboard { 6 << 16 } else { 3 << 16 },
        armed: true,
    }
}

/// The vehicle's world-frame tilt at tick k (pitch, roll at heading 0)
/// and its position.
fn truth(k: u64) -> ([f64; 2], [f64; 3]) {
    let s = k as f64 * 0.05;
    (
        [0.05 * s.sin(), -0.04 * s.cos()],
        [0.5 * s.sin(), 0.5 * (1.0 - s.cos()), -10.0],
    )
}

/// Steps the pure core of `cfg` through 150 ticks, tick k (time t) fed
/// `events(k, t)`; returns `take` of every tick's output.
fn fly<T>(
    cfg: &Config,
    mut events: impl FnMut(u64, f64) -> Vec<Event>,
    take: impl Fn(StepOutput) -> T,
) -> Vec<T> {
    let controller = build_controller(cfg).unwrap();
    let mut core = ControlCore::new(cfg, controller, thrust_mapping(cfg));
    (0..150)
        .map(|k| take(step_events(&mut core, k, events(k, k as f64 * DT))))
        .collect()
}

/// Flies 150 ticks (50 in standby, then engaged with a setpoint at tick
/// 60 carrying `setpoint_yaw`); the measured heading is `heading(k)`.
/// Returns every tick's (plan, command).
fn run(yaw_mode: YawMode, heading: impl Fn(u64) -> f64, setpoint_yaw: Option<f64>) -> Vec<Tick> {
    let mut cfg = Config::default();
    cfg.vehicle.yaw_mode = yaw_mode;
    fly(
        &cfg,
        |k, t| {
            let ([pitch, roll], position) = truth(k);
            let psi = heading(k);
            // The autopilot reports body angles at its heading.
            let (pitch_b, roll_b) = tilt_at_heading(pitch, roll, 0.0, psi);
            let mut events = vec![
                Event::Heartbeat {
                    arrival: t - 0.002,
                    mode: mode(k >= 50),
                },
                Event::Attitude {
                    arrival: t - 0.002,
                    roll: roll_b,
                    pitch: pitch_b,
                    yaw: psi,
                },
                Event::Pose {
                    arrival: t - 0.001,
                    source_time: None,
                    position,
                    yaw: None,
                    reset_counter: None,
                },
            ];
            if k == 60 {
                events.push(Event::Setpoint {
                    arrival: t - 0.0005,
                    position: [3.0, 1.0, -10.0],
                    yaw: setpoint_yaw,
                    yaw_rate: None,
                    source_time: None,
                    velocity: None,
                    acceleration: None,
                });
            }
            events
        },
        |out| (out.row.plan, out.command.map(|c| c.command)),
    )
}

fn largest_plan_difference(a: &[Tick], b: &[Tick]) -> f64 {
    let mut worst: f64 = 0.0;
    for ((pa, _), (pb, _)) in a.iter().zip(b) {
        let (Some(pa), Some(pb)) = (pa, pb) else {
            assert_eq!(pa.is_some(), pb.is_some(), "one run planned, the other not");
            continue;
        };
        for (x, y) in pa.iter().zip(pb) {
            for (u, v) in x.iter().zip(y) {
                worst = worst.max((u - v).abs());
            }
        }
    }
    worst
}

#[test]
fn the_window_predicts_the_same_with_and_without_a_heading_change() {
    let fixed_heading = run(YawMode::Flown, |_| 0.0, None);
    // The vehicle turns in standby (0.6 rad/s under the pilot); engaged, a
    // setpoint asks for 1.5 rad.
    let turning = |k: u64| (0.012 * k.min(50) as f64).min(0.6);
    let turned = run(YawMode::Flown, turning, Some(1.5));
    let planned = fixed_heading.iter().filter(|(p, _)| p.is_some()).count();
    assert!(planned > 100, "only {planned} ticks planned");
    let diff = largest_plan_difference(&fixed_heading, &turned);
    assert!(
        diff < 1e-9,
        "plans differ by {diff} m with a heading change"
    );

    // The commands: the same thrust axis at another heading, the heading
    // rate-limited on its way to the setpoint's yaw. To the solver's
    // precision: the tilt-rate bound's first row starts from the measured
    // attitude, converted, so the iterative solve sees inputs that differ
    // in the last bits (6e-9 rad seen at tick 18).
    let max_rate = Config::default().vehicle.max_yaw_rate_deg_s.to_radians();
    let mut last_yaw: Option<f64> = None;
    let mut final_yaw = 0.0;
    for (k, ((_, a), (_, b))) in fixed_heading.iter().zip(&turned).enumerate() {
        let (Some(a), Some(b)) = (a, b) else { continue };
        assert!(a.yaw.abs() < 1e-12, "tick {k}: fixed run turned");
        let (pitch, roll) = tilt_at_heading(b.pitch, b.roll, b.yaw, 0.0);
        assert!(
            (pitch - a.pitch).abs() < 1e-7 && (roll - a.roll).abs() < 1e-7,
            "tick {k}: {a:?} vs {b:?}"
        );
        if k > 50
            && let Some(y) = last_yaw
        {
            let step = dflat_link::math::wrap_pi(b.yaw - y).abs();
            assert!(step <= max_rate * DT + 1e-9, "tick {k}: yaw step {step}");
        }
        last_yaw = Some(b.yaw);
        final_yaw = b.yaw;
    }
    // 0.6 rad at the engagement, 0.9 rad more at 45°/s takes 1.15 s of
    // the 1.8 s after the setpoint.
    assert!((final_yaw - 1.5).abs() < 1e-6, "heading {final_yaw}");

    // Without the conversion (fixed yaw mode, the body angles taken as
    // they are) the same turn changes the window: the test can fail.
    let unconverted = run(YawMode::Fixed, turning, Some(1.5));
    let reference = run(YawMode::Fixed, |_| 0.0, None);
    let diff = largest_plan_difference(&reference, &unconverted);
    assert!(
        diff > 1e-6,
        "a heading change left the fixed window: {diff}"
    );
}

/// The heading commanded on a stream turning at 0.5 rad/s (samples at
/// 50 Hz with yaw, creeping along x at 0.1 m/s, engaged from tick 20), with
/// `vehicle.delay_ms` = `delay_ms`: the commanded yaw per tick.
fn stream_headings(delay_ms: f64) -> Vec<Option<f64>> {
    let mut cfg = Config::default();
    cfg.vehicle.yaw_mode = YawMode::Flown;
    cfg.vehicle.delay_ms = delay_ms;
    fly(
        &cfg,
        |k, t| {
            let mut events = vec![
                Event::Heartbeat {
                    arrival: t - 0.002,
                    mode: mode(k >= 20),
                },
                Event::Pose {
                    arrival: t - 0.001,
                    source_time: None,
                    position: [0.0, 0.0, -10.0],
                    yaw: None,
                    reset_counter: None,
                },
            ];
            if k >= 10 {
                events.push(Event::Setpoint {
                    arrival: t - 0.0005,
                    position: [0.1 * t, 0.0, -10.0],
                    yaw: Some(0.5 * t),
                    yaw_rate: Some(0.5),
                    source_time: None,
                    velocity: Some([0.1, 0.0, 0.0]),
                    acceleration: None,
                });
            }
            events
        },
        |out| out.command.map(|c| c.command.yaw),
    )
}

/// With an input delay the controller plans from `delay_ms` ahead, and a
/// stream's heading is commanded that much further ahead too: on a stream
/// turning at 0.5 rad/s, 40 ms (two ticks) of delay lead the commanded
/// heading by 0.02 rad once it follows the stream. Fails with the heading
/// taken `yaw_lead_s` ahead alone (the two runs then agree).
#[test]
fn a_streams_heading_is_led_by_the_input_delay() {
    let (plain, delayed) = (stream_headings(0.0), stream_headings(40.0));
    let mut compared = 0;
    for (k, (a, b)) in plain.iter().zip(&delayed).enumerate().skip(100) {
        let (Some(a), Some(b)) = (a, b) else {
            panic!("tick {k}: no command ({a:?}, {b:?})");
        };
        let lead = dflat_link::math::wrap_pi(b - a);
        assert!((lead - 0.02).abs() < 1e-6, "tick {k}: lead {lead} rad");
        compared += 1;
    }
    assert!(compared >= 40, "{compared} ticks compared");
}
