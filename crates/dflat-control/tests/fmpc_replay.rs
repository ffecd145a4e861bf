//! Replays the paper's 1-D simulation trace (`reference/trace_1d.json`)
//! into [`FlatnessMpc`]: the measured positions `ym` tick by tick, and the
//! command `u` (θ_cmd) must match the independently computed one.

use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::reference::Reference;
use dflat_control::{ControlModel, Controller, Frame, Measurement};
use dflat_model::{PlanarModel, PlanarParams};
use nalgebra::Vector3;
use serde_json::Value;

const TRACE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../reference/trace_1d.json");

/// Relative tolerance on θ_cmd at every tick (the trace's smallest |u| is
/// 3e-5 rad, so a pure relative error is well defined).
const RTOL: f64 = 1e-6;
const SCALE_FLOOR: f64 = f64::MIN_POSITIVE;

fn load() -> Value {
    let text = std::fs::read_to_string(TRACE).unwrap_or_else(|e| {
        panic!("reference trace missing: cannot read {TRACE}: {e} (it ships in the repository's reference/)")
    });
    serde_json::from_str(&text).expect("trace_1d.json is not valid JSON")
}

fn num(v: &Value, what: &str) -> f64 {
    v.as_f64()
        .unwrap_or_else(|| panic!("trace field {what} is not a number"))
}

/// Returns the largest relative error of `u` over the run.
fn replay(trace: &Value, run: &str) -> f64 {
    let setup = &trace["setup"];
    let runs = &trace["runs"][run];
    assert!(runs.is_object(), "run {run} missing from the trace");
    let dt = num(&setup["ctrl_dt"], "setup.ctrl_dt");
    let model = PlanarModel::new(PlanarParams {
        dt,
        tau: num(&setup["tau"], "setup.tau"),
        k: num(&setup["k"], "setup.k"),
        g: num(&setup["g"], "setup.g"),
        psi: 0.0,
        frame: Frame::Zup,
        drag_h: 0.0,
    })
    .unwrap();
    let q = num(&runs["weights"]["Q"], "weights.Q");
    let r = num(&runs["weights"]["R"], "weights.R");
    let n = setup["N"].as_u64().expect("setup.N") as usize;
    let settings = FmpcSettings {
        horizon: n,
        q: [q; 3],
        r: [r; 3],
        max_tilt: None,
        ..FmpcSettings::default()
    };
    let mut fmpc = FlatnessMpc::new(ControlModel::Planar(model), settings).unwrap();
    let x_ref = num(&setup["x_ref"], "setup.x_ref");
    let mut reference = Reference::setpoint(Vector3::new(x_ref, 0.0, 0.0)).unwrap();

    let ticks = runs["ticks"].as_array().expect("ticks");
    assert_eq!(ticks.len(), 500);
    let mut worst: f64 = 0.0;
    for (i, tick) in ticks.iter().enumerate() {
        let m = Measurement {
            t: num(&tick["t"], "t"),
            position: Vector3::new(num(&tick["ym"], "ym"), 0.0, 0.0),
            yaw: 0.0,
        };
        let out = fmpc.update(&m, &mut reference).unwrap();
        let expected = num(&tick["u"], "u");
        let err = (out.command.pitch - expected).abs() / expected.abs().max(SCALE_FLOOR);
        assert!(
            err <= RTOL,
            "{run}: tick {i}: θ_cmd = {} but the trace has {expected} (relative error {err:.3e})",
            out.command.pitch
        );
        assert_eq!(
            out.command.roll, 0.0,
            "{run}: tick {i}: no lateral motion, no roll"
        );
        assert_eq!(
            out.plan[0], m.position,
            "{run}: tick {i}: plan starts at the measurement"
        );
        worst = worst.max(err);
    }
    worst
}

#[test]
fn fmpc_replay_sigma0() {
    let worst = replay(&load(), "FMPC_sigma0");
    eprintln!("FMPC_sigma0: max relative error of u = {worst:.3e}");
}

#[test]
fn fmpc_replay_sigma0_001() {
    let worst = replay(&load(), "FMPC_sigma0.001");
    eprintln!("FMPC_sigma0.001: max relative error of u = {worst:.3e}");
}
