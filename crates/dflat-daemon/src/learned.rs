//! The learned residual the daemon flies (`controller.dfmpc.learned_model`):
//! the model file read, validated and checked against `[vehicle]`.

use std::path::Path;

use dflat_control::ControlError;
use dflat_control::learned::LearnedResidual;

use crate::config::{Config, ModelKind, VehicleConfig};

/// The config field that names the model file.
pub const FIELD: &str = "controller.dfmpc.learned_model";

/// `vehicle.model` as a model file names it, and the numeric `[vehicle]`
/// fields a residual is learned over (name, value): the parametric model.
pub fn vehicle_fields(v: &VehicleConfig) -> (&'static str, Vec<(&'static str, f64)>) {
    let model = match v.model {
        ModelKind::Spatial => "spatial",
        ModelKind::Planar => "planar",
    };
    (
        model,
        vec![
            ("tau", v.tau),
            ("k", v.k),
            ("tau_thrust", v.tau_thrust),
            ("gravity", v.gravity),
            ("hover_thrust", v.hover_thrust),
            ("drag_h", v.drag_h),
            ("drag_v", v.drag_v),
            ("drag_rotor", v.drag_rotor),
            ("delay_ms", v.delay_ms),
        ],
    )
}

/// Reads a model file (TOML) and validates it; the error names the file and
/// the field.
pub fn read(path: &Path) -> Result<LearnedResidual, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let model: LearnedResidual = toml::from_str(&text)
        .map_err(|e| format!("{}: not a learned model: {e}", path.display()))?;
    model
        .validate()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(model)
}

/// The residual of `controller.dfmpc.learned_model` (`None` when empty):
/// read, validated and refused unless it was learned with this `[vehicle]`
/// table, the error naming the field, the file and what differs.
pub fn configured(cfg: &Config) -> Result<Option<LearnedResidual>, ControlError> {
    let file = cfg.controller.dfmpc.learned_model.trim();
    if file.is_empty() {
        return Ok(None);
    }
    let invalid = |reason: String| ControlError::InvalidSetting {
        field: FIELD,
        reason,
    };
    let model = read(Path::new(file)).map_err(invalid)?;
    let (kind, fields) = vehicle_fields(&cfg.vehicle);
    model
        .check_vehicle(kind, &fields)
        .map_err(|e| invalid(format!("{file}: {e}")))?;
    Ok(Some(model))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_control::learned::{FORMAT, Feature, Support, VERSION, Validation};

    fn model_for(cfg: &Config) -> LearnedResidual {
        let (kind, fields) = vehicle_fields(&cfg.vehicle);
        LearnedResidual {
            format: FORMAT.into(),
            version: VERSION,
            vehicle_model: kind.into(),
            vehicle: fields.iter().map(|(k, v)| ((*k).to_owned(), *v)).collect(),
            dt: 0.02,
            window: 3,
            features: vec![Feature::Bias],
            lambda: 1e-6,
            weights: [vec![0.1], vec![0.0], vec![0.0]],
            support: Support {
                speed_max: 5.0,
                tilt_max: 0.5,
                thrust_min: 5.0,
                thrust_max: 15.0,
            },
            validation: Validation {
                one_step_parametric_m: 1e-3,
                one_step_learned_m: 1e-4,
                horizon_s: 0.5,
                horizon_parametric_m: 0.1,
                horizon_learned_m: 0.01,
                samples: 10,
                start_parametric_s: 0.4,
                start_learned_s: 1.2,
                acceleration_parametric: 1.0,
                acceleration_learned: 0.1,
            },
            seconds: 60.0,
        }
    }

    /// The model learned with this `[vehicle]` loads; against another
    /// airframe's table it is refused, naming the config field, the file
    /// and the vehicle field that differs.
    #[test]
    fn a_model_loads_only_against_its_vehicle_table() {
        let dir = std::env::temp_dir().join(format!("dflat-learned-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.learned.toml");
        let mut cfg = Config::default();
        std::fs::write(&path, toml::to_string(&model_for(&cfg)).unwrap()).unwrap();
        cfg.controller.dfmpc.learned_model = path.display().to_string();
        assert!(configured(&cfg).unwrap().is_some());
        cfg.vehicle.tau *= 1.5;
        let err = configured(&cfg).unwrap_err().to_string();
        assert!(err.contains(FIELD) && err.contains("vehicle.tau"), "{err}");
        cfg.controller.dfmpc.learned_model = dir.join("missing.toml").display().to_string();
        let err = configured(&cfg).unwrap_err().to_string();
        assert!(err.contains("cannot read"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
        cfg.controller.dfmpc.learned_model.clear();
        assert!(configured(&cfg).unwrap().is_none());
    }

    /// A version-2 file (before the held-out predictions' start windows
    /// were written) still loads, its windows the 0.4 s it was judged
    /// with; a version this build does not know is refused in words.
    #[test]
    fn a_version_2_file_loads_and_a_newer_one_is_refused() {
        let dir = std::env::temp_dir().join(format!("dflat-learned-v2-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.learned.toml");
        let cfg = Config::default();
        let text = toml::to_string(&model_for(&cfg)).unwrap();
        let v2: String = text
            .lines()
            .filter(|l| !l.starts_with("start_"))
            .map(|l| {
                if l.starts_with("version") {
                    "version = 2\n".to_owned()
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        assert!(v2.contains("version = 2") && !v2.contains("start_learned_s"));
        std::fs::write(&path, &v2).unwrap();
        let model = read(&path).unwrap();
        assert_eq!(model.validation.start_parametric_s, 0.4);
        assert_eq!(model.validation.start_learned_s, 0.4);
        std::fs::write(&path, v2.replace("version = 2", "version = 99")).unwrap();
        let err = read(&path).unwrap_err();
        assert!(
            err.contains("version = 99") && err.contains("learn it again"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
