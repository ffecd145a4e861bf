//! Tests of the configuration schema and its validation.

use super::*;

fn parse(text: &str) -> Result<Config, ConfigError> {
    Config::parse(text, Path::new("test.toml"))
}

#[test]
fn empty_file_gives_defaults() {
    assert_eq!(parse("").unwrap(), Config::default());
}

#[test]
fn unknown_field_is_refused_with_its_name() {
    let e = parse("[vehicle]\ntaux = 0.3\n").unwrap_err().to_string();
    assert!(e.contains("test.toml") && e.contains("taux"), "{e}");
}

#[test]
fn out_of_range_names_field_and_range() {
    let e = parse("[vehicle]\ntau = 5.0\n").unwrap_err().to_string();
    assert!(e.contains("vehicle.tau") && e.contains("0.02 to 2"), "{e}");
    let e = parse("[controller.dfmpc]\nq = [1.0, -1.0, 1.0]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.dfmpc.q[1]"), "{e}");
}

#[test]
fn spatial_needs_normalized_thrust() {
    let e = parse("[vehicle]\nmodel = \"spatial\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("vehicle.thrust_mode"), "{e}");
    assert!(parse("[vehicle]\nmodel = \"spatial\"\nthrust_mode = \"normalized\"\n").is_ok());
}

/// The rotor drag is the spatial model's (its lift acts on the thrust the
/// planar model does not fly): refused on the planar model, out of range
/// refused, and flown by the spatial model's maps.
#[test]
fn rotor_drag_needs_the_spatial_model() {
    let e = parse("[vehicle]\ndrag_rotor = 0.2\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("vehicle.drag_rotor") && e.contains("spatial"),
        "{e}"
    );
    let spatial = "[vehicle]\nmodel = \"spatial\"\nthrust_mode = \"normalized\"\n";
    let e = parse(&format!("{spatial}drag_rotor = 2.5\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("vehicle.drag_rotor"), "{e}");
    let cfg = parse(&format!("{spatial}drag_rotor = 0.2\n")).unwrap();
    assert_eq!(cfg.vehicle.drag_rotor, 0.2);
    match crate::control::control_model(&cfg).unwrap() {
        dflat_control::ControlModel::Spatial(m) => assert_eq!(m.params().drag_rotor, 0.2),
        other => panic!("{other:?}"),
    }
}

#[test]
fn path_mission_needs_two_distinct_waypoints() {
    let e = parse("[mission]\nstart = \"path\"\npath = [[0.0, 0.0, -5.0]]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("mission.path"), "{e}");
    let e = parse("[mission]\npath = [[0.0, 0.0, -5.0], [0.0, 0.0, -5.0]]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("mission.path[1]"), "{e}");
}

#[test]
fn safety_fields_are_validated() {
    for (text, field) in [
        ("max_speed_mps = 0.0", "safety.max_speed_mps"),
        ("pose_jump_margin_m = -1.0", "safety.pose_jump_margin_m"),
        ("hold_last_ticks = 51", "safety.hold_last_ticks"),
        ("residual_failsafe_m = 0.01", "safety.residual_failsafe_m"),
        ("residual_failsafe_m = nan", "safety.residual_failsafe_m"),
    ] {
        let e = parse(&format!("[safety]\n{text}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{text}: {e}");
    }
    let e = parse("[mission]\nrepeat = true\n").unwrap_err().to_string();
    assert!(e.contains("mission.repeat"), "{e}");
    assert!(
        parse("[mission]\nrepeat = true\npath = [[0.0, 0.0, -5.0], [5.0, 0.0, -5.0], [0.0, 0.0, -5.0]]\n")
            .is_ok()
    );
    assert!(parse("[safety]\nresidual_failsafe_m = 2.0\nhold_last_ticks = 0\n").is_ok());
}

#[test]
fn signing_fields_are_validated() {
    let cfg = parse("").unwrap();
    assert!(cfg.link.signing_key_file.is_empty());
    let err = parse("[link]\nsigning_key_file = \"/etc/dflat/key\"\nsigning_timestamp_file = \"\"")
        .unwrap_err()
        .to_string();
    assert!(err.contains("link.signing_timestamp_file"), "{err}");
    let cfg = parse("[link]\nsigning_key_file = \"/etc/dflat/key\"\nsigning_link_id = 3").unwrap();
    assert_eq!(cfg.link.signing_link_id, 3);
    assert!(parse("[link]\nsigning_link_id = 256").is_err());
    // The SITL's table is the SITL's: kept as written, not validated here.
    assert!(Config::default().sitl.is_none());
    let cfg = parse("[sitl]\nsigning_key_file = \"/etc/dflat/sitl.key\"").unwrap();
    let sitl = cfg.sitl.as_ref().unwrap();
    assert_eq!(
        sitl["signing_key_file"].as_str(),
        Some("/etc/dflat/sitl.key")
    );
    assert_eq!(parse(&cfg.to_toml()).unwrap(), cfg);
}

#[test]
fn effective_config_round_trips() {
    let c = Config::default();
    assert_eq!(parse(&c.to_toml()).unwrap(), c);
}

#[test]
fn controller_fields_are_named_by_their_full_path() {
    for (text, field, allowed) in [
        (
            "[controller.dfmpc]\nhorizon = 5",
            "controller.dfmpc.horizon",
            "10 to 2000 ticks",
        ),
        (
            "[controller.dfmpc]\nhorizon = 2001",
            "controller.dfmpc.horizon",
            "10 to 2000 ticks",
        ),
        (
            "[controller.fmpc]\nhorizon = 9",
            "controller.fmpc.horizon",
            "10 to 2000 ticks",
        ),
        (
            "[controller.dfmpc]\nq = [1.0, 0.0, 1.0]",
            "controller.dfmpc.q[1]",
            "> 0",
        ),
        (
            "[controller.fmpc]\nr_jerk = [1.0, 1.0, -1.0]",
            "controller.fmpc.r_jerk[2]",
            "> 0",
        ),
        ("[controller.pd]\nkd = 0.0", "controller.pd.kd", "> 0"),
        (
            "[controller.pd]\ncorner_radius = 51.0",
            "controller.pd.corner_radius",
            "0 (off) or > 0 to 50 m",
        ),
        (
            "[controller.pd]\ncorner_acceleration = 0.05",
            "controller.pd.corner_acceleration",
            "0.1 to 20",
        ),
        (
            "[controller.disturbance]\nwindow = 5",
            "controller.disturbance.window",
            "10 to 2000",
        ),
        (
            "[controller.disturbance]\nbandwidth_hz = 6.0",
            "controller.disturbance.bandwidth_hz",
            "0.001 to 5",
        ),
        (
            "[controller.disturbance]\nmax_step = 0.0",
            "controller.disturbance.max_step",
            "0.01 to 100",
        ),
        (
            "[controller.dfmpc]\nmax_tilt_rate_deg_s = 5.0",
            "controller.dfmpc.max_tilt_rate_deg_s",
            "10 to 1000",
        ),
        (
            "[controller.dfmpc]\nconstraint_speed = 60.0",
            "controller.dfmpc.constraint_speed",
            "50",
        ),
        (
            "[controller.dfmpc]\nmulti_rate_window = 1",
            "controller.dfmpc.multi_rate_window",
            "2 to 250",
        ),
        (
            "[controller]\nconstraint_tilt_deg = 61.0",
            "controller.constraint_tilt_deg",
            "1 to 60 deg",
        ),
        (
            "[controller]\nsample_sigma = 2.0",
            "controller.sample_sigma",
            "0.0001 to 1 m",
        ),
        (
            "[controller.estimator]\njerk_psd = 1e7",
            "controller.estimator.jerk_psd",
            "1000000 m²/s⁵",
        ),
    ] {
        let e = parse(text).unwrap_err().to_string();
        assert!(
            e.contains(&format!("field `{field}`")) && e.contains(allowed),
            "{text}: {e}"
        );
    }
    // 0 is "off" where documented.
    assert!(
        parse("[controller]\nconstraint_tilt_deg = 0.0\n[controller.dfmpc]\nconstraint_speed = 0.0\nmax_tilt_rate_deg_s = 0.0\n[controller.pd]\ncorner_radius = 0.0")
            .is_ok()
    );
}

/// The daemon's limit is the core's: a value the file accepts builds the
/// controller, one it refuses the core refuses too.
#[test]
fn the_file_and_the_core_share_one_range() {
    use dflat_control::dfmpc::DfMpcSettings;
    use dflat_control::fmpc::FmpcSettings;
    for n in [9usize, 10, 2000, 2001] {
        let file = parse(&format!("[controller.dfmpc]\nhorizon = {n}")).is_ok();
        let core = DfMpcSettings {
            horizon: n,
            ..DfMpcSettings::default()
        }
        .validate()
        .is_ok();
        assert_eq!(file, core, "df-mpc horizon {n}");
        assert_eq!(file, (10..=2000).contains(&n));
        let file = parse(&format!("[controller.fmpc]\nhorizon = {n}")).is_ok();
        let core = FmpcSettings {
            horizon: n,
            ..FmpcSettings::default()
        }
        .validate()
        .is_ok();
        assert_eq!(file, core, "fmpc horizon {n}");
    }
}

#[test]
fn old_flat_keys_are_refused_with_their_new_place() {
    let e = parse("[controller]\nfmpc_horizon = 80\npd_corner_radius = 0.0\ndisturbance = true\n")
        .unwrap_err();
    let ConfigError::Moved { moved, .. } = &e else {
        panic!("{e}");
    };
    assert_eq!(moved.len(), 3);
    let e = e.to_string();
    for part in [
        "test.toml",
        "controller.fmpc_horizon has moved to controller.fmpc.horizon",
        "controller.pd_corner_radius has moved to controller.pd.corner_radius",
        "controller.disturbance has moved to controller.disturbance.enabled",
        "dflat check-config --migrate test.toml",
    ] {
        assert!(e.contains(part), "{part}: {e}");
    }
    // Every old key, one at a time.
    for (old, new) in super::migrate::MOVES {
        let value = if *old == "disturbance" { "false" } else { "1" };
        let e = parse(&format!("[controller]\n{old} = {value}\n"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!(
                "controller.{old} has moved to controller.{}",
                new[0]
            )),
            "{old}: {e}"
        );
    }
}

#[test]
fn defaults_are_the_cores_where_the_core_has_the_daemons() {
    let c = ControllerConfig::default();
    let d = dflat_control::disturbance::DisturbanceSettings::default();
    assert_eq!(
        DisturbanceConfig {
            enabled: true,
            ..c.disturbance.clone()
        }
        .settings(),
        Some(d)
    );
    assert_eq!(
        c.fmpc.horizon,
        dflat_control::fmpc::FmpcSettings::default().horizon
    );
    assert_eq!(
        c.fmpc.r_jerk,
        dflat_control::fmpc::FmpcSettings::default().r
    );
    assert_eq!(
        c.dfmpc.horizon,
        dflat_control::dfmpc::DfMpcSettings::default().horizon
    );
    let mr = c.multi_rate().unwrap();
    assert_eq!(mr, dflat_control::window::MultiRateSettings::default());
}
