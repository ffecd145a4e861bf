//! End to end: losing pose while the vehicle accelerates leaves nothing
//! tilted.
//!
//! The real `dflat daemon` against the in-process SITL, whose autopilot
//! holds the last command for 1 s after the stream stops
//! (`sitl.command_timeout_s = 1.0`, PX4's `COM_OF_LOSS_T`) and then holds
//! position on its own. The vehicle flies a straight path from rest; while
//! it accelerates (≥ 10° of true tilt) the pose stream stops. Judged from
//! the SITL's true state and the daemon's records (its commands and their
//! tick times from the newest pose's capture, on the daemon's clock):
//! * the vehicle gains ≤ 0.5 m/s of speed in the 2 s after the loss;
//! * the last command the daemon sent is within 2° of level, and the
//!   stream stops within `safety.level_hover_max_ms` (+ the pose timeout).
//!
//! The same flight with `safety.level_hover_max_ms = 0` (silence at once)
//! is flown too, to show the test tells them apart:
//! there the last command is the tilt and the vehicle gains well over
//! 0.5 m/s.

#[path = "support/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use dflat_daemon::config::Config;
use dflat_sitl::SitlMode;

/// What one pose loss did.
#[derive(Debug)]
struct Loss {
    /// Largest speed in the 2 s after the loss minus the speed at it \[m/s\].
    speed_gain: f64,
    /// |v(t₀ + 2 s) − v(t₀)| \[m/s\].
    velocity_change: f64,
    /// True tilt at the loss \[deg\].
    tilt_at_loss: f64,
    /// Tilt of the last command \[deg\].
    last_command_tilt: f64,
    /// Its time after the newest pose's capture (the daemon's clock) \[s\].
    last_command_after: f64,
    /// Largest tilt commanded after the loss \[deg\].
    max_command_tilt_after: f64,
}

fn fly_and_lose_pose(name: &str, level_hover_ms: f64) -> Loss {
    let dir = scratch(name);
    let path = [[0.0, 0.0, -10.0], [80.0, 0.0, -10.0]];
    let safety = format!("[safety]\nlevel_hover_max_ms = {level_hover_ms:?}");
    let text = path_config(&dir, &path, 8.0, &safety, "command_timeout_s = 1.0");
    let (config, _) = write_daemon_config(&dir, "loss.toml", &text);
    let (sim, _tap) = tapped_sitl(
        &config,
        TapOptions {
            record_trace: true,
            ..TapOptions::default()
        },
    );
    let mut daemon = spawn_daemon(&dir, &config, sim.local_addr());

    // Wait until the vehicle accelerates along the path at ≥ 10° of tilt.
    let until = Instant::now() + Duration::from_secs(30);
    let truth = loop {
        assert!(Instant::now() < until, "never accelerated at 10°");
        let s = sim.truth();
        let tilt = (s.euler[0].cos() * s.euler[1].cos()).acos().to_degrees();
        if sim.mode() == SitlMode::Offboard && tilt >= 10.0 && s.velocity[0] > 0.2 {
            break s;
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    sim.pause_pose();
    let t0 = sim.elapsed();
    std::thread::sleep(Duration::from_millis(2600));
    let _ = daemon.interrupt_and_wait(Duration::from_secs(5));
    let report = sim.stop().expect("sitl stop");
    assert!(!report.diverged);

    let speed = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let window: Vec<_> = report
        .trace
        .iter()
        .filter(|s| s.t >= t0 && s.t <= t0 + 2.0)
        .collect();
    assert!(window.len() > 50, "{} truth samples", window.len());
    let first = window[0];
    let last = window[window.len() - 1];
    let v0 = speed(first.velocity);
    let speed_gain = window
        .iter()
        .map(|s| speed(s.velocity) - v0)
        .fold(f64::NEG_INFINITY, f64::max);
    let dv: Vec<f64> = (0..3)
        .map(|i| last.velocity[i] - first.velocity[i])
        .collect();
    let velocity_change = speed([dv[0], dv[1], dv[2]]);

    // The commands after the loss, on the daemon's clock: its records'
    // tick times from the newest pose's capture.
    let rows = read_flight_csv(&dir);
    let lost = rows
        .iter()
        .filter_map(pose_capture)
        .fold(f64::NEG_INFINITY, f64::max);
    let last = rows
        .iter()
        .rev()
        .find(|r| field(r, "roll").is_some())
        .expect("commands");
    let last_command_after = field(last, "t_wake").expect("t_wake") - lost;
    let tilt_of = |r: &std::collections::HashMap<String, String>| {
        let (roll, pitch) = (field(r, "roll")?, field(r, "pitch")?);
        Some(dflat_control::tilt::tilt(pitch, roll).to_degrees())
    };
    let last_command_tilt = tilt_of(last).expect("the last command's tilt");
    let max_command_tilt_after = rows
        .iter()
        .filter(|r| field(r, "t_wake").is_some_and(|t| t > lost))
        .filter_map(tilt_of)
        .fold(0.0, f64::max);
    let tilt_at_loss = (truth.euler[0].cos() * truth.euler[1].cos())
        .acos()
        .to_degrees();
    let loss = Loss {
        speed_gain,
        velocity_change,
        tilt_at_loss,
        last_command_tilt,
        last_command_after,
        max_command_tilt_after,
    };
    eprintln!("{name}: {loss:?}");
    loss
}

#[test]
fn losing_pose_while_accelerating_leaves_a_level_vehicle() {
    let cfg = Config::default();
    let level_ms = cfg.safety.level_hover_max_ms;
    let loss = fly_and_lose_pose("poseloss-level", level_ms);
    assert!(loss.tilt_at_loss >= 10.0);
    assert!(
        loss.speed_gain <= 0.5,
        "gained {:.2} m/s in the 2 s after the loss",
        loss.speed_gain
    );
    assert!(
        loss.last_command_tilt <= 2.0,
        "last command {:.2}° from level",
        loss.last_command_tilt
    );
    // The stream stops: the last command within the pose timeout plus the
    // level hover (+ 150 ms of scheduling margin) after the loss.
    let limit = (cfg.safety.pose_timeout_ms + level_ms) / 1000.0 + 0.15;
    assert!(
        loss.last_command_after <= limit,
        "still streaming {:.2} s after the loss",
        loss.last_command_after
    );
    assert!(
        loss.last_command_after >= level_ms / 1000.0 - 0.1,
        "the level hover lasted only {:.2} s",
        loss.last_command_after
    );

    // Before: silence at once leaves the tilt in the autopilot for 1 s.
    let before = fly_and_lose_pose("poseloss-silent", 0.0);
    assert!(
        before.last_command_tilt >= 5.0,
        "silence at once left {:.1}° (the test must tell them apart)",
        before.last_command_tilt
    );
    assert!(
        before.speed_gain > loss.speed_gain + 0.3,
        "silent {:.2} m/s vs level {:.2} m/s",
        before.speed_gain,
        loss.speed_gain
    );
    eprintln!(
        "speed gained in the 2 s after the loss: {:.2} m/s (brake, level, stream off) vs {:.2} m/s (silent at once); \
         |Δv| over the 2 s {:.2} vs {:.2} m/s; largest command tilt after the loss {:.1}°",
        loss.speed_gain,
        before.speed_gain,
        loss.velocity_change,
        before.velocity_change,
        loss.max_command_tilt_after
    );
}
