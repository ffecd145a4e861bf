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
