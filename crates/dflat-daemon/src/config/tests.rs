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
    let e = parse("[controller]\nq = [1.0, -1.0, 1.0]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.q[1]"), "{e}");
}

#[test]
fn spatial_needs_normalized_thrust() {
    let e = parse("[vehicle]\nmodel = \"spatial\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("vehicle.thrust_mode"), "{e}");
    assert!(parse("[vehicle]\nmodel = \"spatial\"\nthrust_mode = \"normalized\"\n").is_ok());
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
