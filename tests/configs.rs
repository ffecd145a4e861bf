//! Every shipped configuration in config/ parses, validates, and is
//! accepted by `dflat check-config`.

use std::path::Path;
use std::process::Command;

use dflat_daemon::config::{Config, ModelKind, ThrustMode};
use dflat_sitl::{SitlPlant, SitlSettings};

fn config_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../config"))
}

#[test]
fn every_file_in_config_parses() {
    let mut n = 0;
    for entry in std::fs::read_dir(config_dir()).expect("config/") {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            Config::load(&path).unwrap_or_else(|e| panic!("{e}"));
            let out = Command::new(env!("CARGO_BIN_EXE_dflat-under-test"))
                .arg("check-config")
                .arg(&path)
                .output()
                .expect("run dflat check-config");
            assert!(
                out.status.success(),
                "check-config {}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            n += 1;
        }
    }
    assert!(n >= 4, "expected default, sitl, px4, ardupilot; found {n}");
}

#[test]
fn shipped_configs_say_what_they_promise() {
    let load = |name: &str| Config::load(&config_dir().join(name)).unwrap();
    let sitl = load("sitl.toml");
    let plant = SitlSettings::load(&config_dir().join("sitl.toml")).unwrap();
    assert_eq!(plant.sitl.plant, SitlPlant::Planar);
    assert_eq!(plant.sitl.start, sitl.mission.path[0]);
    assert!(sitl.link.url.starts_with("udpout:127.0.0.1:"));
    assert_eq!(
        plant.sitl.url.trim_start_matches("udpin:"),
        sitl.link.url.trim_start_matches("udpout:")
    );
    let px4 = load("px4.toml");
    assert_eq!(px4.vehicle.model, ModelKind::Spatial);
    assert_eq!(px4.vehicle.thrust_mode, ThrustMode::Normalized);
    assert_eq!(px4.vehicle.hover_thrust, 0.5);
    let ap = load("ardupilot.toml");
    assert_eq!(ap.vehicle.model, ModelKind::Planar);
    assert_eq!(ap.vehicle.thrust_mode, ThrustMode::Fixed);
    assert_eq!(ap.vehicle.thrust_value, 0.5);
}

/// A file of the flat `[controller]` era: `check-config` refuses it naming
/// each moved key's new place; `check-config --migrate` prints it migrated
/// (comments kept), and that text validates with the same values.
#[test]
fn check_config_refuses_old_keys_and_migrates_them() {
    let dir = std::env::temp_dir().join(format!("dflat-migrate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let old = dir.join("old.toml");
    std::fs::write(
        &old,
        "[controller]\nkind = \"fmpc\"\n# Longer lookahead.\nfmpc_horizon = 90\nq = [2.0, 2.0, 1.0]\n\
         pd_corner_radius = 0.0\ndisturbance = true\n[mission]\nspeed = 4.0\n",
    )
    .unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_dflat-under-test"))
            .args(args)
            .arg(&old)
            .output()
            .expect("run dflat check-config")
    };
    let out = run(&["check-config"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    for moved in [
        "controller.fmpc_horizon has moved to controller.fmpc.horizon",
        "controller.q has moved to controller.dfmpc.q and controller.fmpc.q",
        "controller.pd_corner_radius has moved to controller.pd.corner_radius",
        "controller.disturbance has moved to controller.disturbance.enabled",
        "--migrate",
    ] {
        assert!(stderr.contains(moved), "{moved}: {stderr}");
    }

    let out = run(&["check-config", "--migrate"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("controller.fmpc_horizon has moved"),
        "{stderr}"
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("# Longer lookahead.\nhorizon = 90"), "{text}");
    let cfg = Config::parse(&text, Path::new("migrated.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(cfg.controller.fmpc.horizon, 90);
    assert_eq!(cfg.controller.fmpc.q, [2.0, 2.0, 1.0]);
    assert_eq!(cfg.controller.dfmpc.q, [2.0, 2.0, 1.0]);
    assert_eq!(cfg.controller.pd.corner_radius, 0.0);
    assert!(cfg.controller.disturbance.enabled);
    assert_eq!(cfg.mission.speed, 4.0);
    // The file itself is left as it was.
    assert!(
        std::fs::read_to_string(&old)
            .unwrap()
            .contains("fmpc_horizon = 90")
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `check-config` refuses exactly what a daemon start refuses:
/// each bad file is refused by both, with the field named, and a start
/// refused creates no records.
#[test]
fn check_config_refuses_what_the_daemon_refuses() {
    let dir = std::env::temp_dir().join(format!("dflat-check-vs-start-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let records = dir.join("records");
    let cases = [
        ("url", "[link]\nurl = \"udp-bad\"\n", "link.url"),
        (
            "url-port",
            "[link]\nurl = \"udpout:127.0.0.1:99999\"\n",
            "link.url",
        ),
        (
            "one-waypoint",
            "[mission]\npath = [[1.0, 2.0, -3.0]]\n",
            "mission.path",
        ),
        (
            "below-the-floor",
            "[mission]\npath = [[0.0, 0.0, -3.0], [0.0, 0.0, 150.0]]\n",
            "mission.path[1][2]",
        ),
        (
            "too-fast",
            "[mission]\nspeed = 18.0\n[safety]\nmax_speed_mps = 15.0\n",
            "mission.speed",
        ),
    ];
    for (name, body, field) in cases {
        let file = dir.join(format!("{name}.toml"));
        let text = format!("{body}[logging]\ndir = \"{}\"\n", records.display());
        std::fs::write(&file, text).unwrap();
        let check = Command::new(env!("CARGO_BIN_EXE_dflat-under-test"))
            .arg("check-config")
            .arg(&file)
            .output()
            .unwrap();
        let start = Command::new(env!("CARGO_BIN_EXE_dflat-under-test"))
            .arg("daemon")
            .arg("--config")
            .arg(&file)
            .output()
            .unwrap();
        let (check_err, start_err) = (
            String::from_utf8_lossy(&check.stderr),
            String::from_utf8_lossy(&start.stderr),
        );
        assert!(!check.status.success(), "{name}: check-config accepted it");
        assert!(!start.status.success(), "{name}: the daemon started");
        assert!(
            check_err.contains(field),
            "{name}: check-config: {check_err}"
        );
        assert!(start_err.contains(field), "{name}: daemon: {start_err}");
    }
    assert!(
        !records.exists(),
        "a refused start made its records directory"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
