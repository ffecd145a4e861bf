//! The tilt-cone study, reduced to one speed and one trial:
//! what the cone in the plan changes in flight, and bad options refused.

use dflat_lab::experiments::tilt_cone::{TiltConeConfig, TiltConeRow, run_tilt_cone};

fn cell<'a>(rows: &'a [TiltConeRow], path: &str, bound: &str) -> &'a TiltConeRow {
    rows.iter()
        .find(|r| r.path == path && r.bound == bound)
        .unwrap_or_else(|| panic!("no row {path} / {bound}"))
}

#[test]
fn cone_plans_within_its_bound_and_the_box_does_not() {
    let config = TiltConeConfig {
        speeds: vec![8.0],
        trials: 1,
        ..TiltConeConfig::default()
    };
    let result = run_tilt_cone(&config, false).unwrap();
    // Four paths × three bounds.
    assert_eq!(result.rows.len(), 12);
    for r in &result.rows {
        assert_eq!(r.controller_errors, 0, "{} {}", r.path, r.bound);
        assert!(r.path_error_mean.is_finite() && r.command_rate_rms_dps.is_finite());
        // The cone plans within its bound (a planned tilt is the first
        // free planned acceleration, which the cone bounds exactly).
        for (bound, deg) in [("cone 30°", 30.0), ("cone 35°", 35.0)] {
            if r.bound == bound {
                assert!(
                    r.planned_tilt_max_deg <= deg + 0.05,
                    "{} {}: {}",
                    r.path,
                    r.bound,
                    r.planned_tilt_max_deg
                );
            }
        }
    }
    // On the L path the box's per-axis bound lets the combined planned
    // tilt exceed 30° (the command limit then cuts it), and the command is
    // saturated more often than with the cone at the same bound.
    let (boxed, cone) = (
        cell(&result.rows, "L", "box 30°"),
        cell(&result.rows, "L", "cone 30°"),
    );
    assert!(
        boxed.planned_tilt_max_deg > 33.0,
        "{}",
        boxed.planned_tilt_max_deg
    );
    assert!(cone.saturated_share < boxed.saturated_share);
    assert!(result.table().lines().count() == 2 + 12);
}

#[test]
fn bad_options_are_refused_with_the_field_named() {
    let err = |c: TiltConeConfig| run_tilt_cone(&c, false).unwrap_err().to_string();
    let no_speed = TiltConeConfig {
        speeds: vec![],
        ..TiltConeConfig::default()
    };
    assert!(err(no_speed).contains("speeds"));
    let flat = TiltConeConfig {
        plan_tilt_deg: 0.0,
        ..TiltConeConfig::default()
    };
    assert!(err(flat).contains("plan_tilt_deg"));
    let none = TiltConeConfig {
        trials: 0,
        ..TiltConeConfig::default()
    };
    assert!(err(none).contains("trials"));
}
