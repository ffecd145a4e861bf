//! Files written for the flat `[controller]` table (before the sub-tables
//! `[controller.dfmpc]`, `.disturbance`, `.fmpc` and `.pd`): which keys
//! moved where ([`MOVES`]), the refusal that names them
//! ([`ConfigError::Moved`](super::ConfigError::Moved)), and the rewrite
//! behind `dflat check-config --migrate` ([`migrate`]), which keeps the
//! file's comments and layout.

use std::fmt;

use toml_edit::{DocumentMut, Item, Key, Table};

/// Each key that left `[controller]`: its old name there and its new
/// places, as `sub-table.key` under `controller` (`q` went to both MPCs).
/// `disturbance` moved only when it is a boolean (the new
/// `[controller.disturbance]` is a table).
pub const MOVES: &[(&str, &[&str])] = &[
    ("horizon", &["dfmpc.horizon"]),
    ("q", &["dfmpc.q", "fmpc.q"]),
    ("r_jerk", &["dfmpc.r_jerk"]),
    ("smoothness_weight", &["dfmpc.smoothness_weight"]),
    ("multi_rate", &["dfmpc.multi_rate"]),
    ("multi_rate_window", &["dfmpc.multi_rate_window"]),
    ("constraint_speed", &["dfmpc.constraint_speed"]),
    ("max_tilt_rate_deg_s", &["dfmpc.max_tilt_rate_deg_s"]),
    ("qp_solver", &["dfmpc.qp_solver"]),
    ("plan_tilt_bound", &["dfmpc.plan_tilt_bound"]),
    ("disturbance", &["disturbance.enabled"]),
    ("disturbance_bandwidth_hz", &["disturbance.bandwidth_hz"]),
    ("disturbance_window", &["disturbance.window"]),
    (
        "disturbance_max_acceleration",
        &["disturbance.max_acceleration"],
    ),
    (
        "disturbance_thrust_scale_range",
        &["disturbance.thrust_scale_range"],
    ),
    ("disturbance_max_step", &["disturbance.max_step"]),
    ("fmpc_horizon", &["fmpc.horizon"]),
    ("fmpc_r_jerk", &["fmpc.r_jerk"]),
    ("pd_kp", &["pd.kp"]),
    ("pd_kd", &["pd.kd"]),
    ("pd_corner_radius", &["pd.corner_radius"]),
    ("pd_corner_acceleration", &["pd.corner_acceleration"]),
];

/// One old key found in a file, with its new places (full TOML paths).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MovedKey {
    /// The old path, e.g. `controller.fmpc_horizon`.
    pub old: String,
    /// The new paths, e.g. `controller.fmpc.horizon`.
    pub new: Vec<String>,
}

impl fmt::Display for MovedKey {
    /// "controller.fmpc_horizon has moved to controller.fmpc.horizon".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} has moved to {}", self.old, self.new.join(" and "))
    }
}

/// True when `[controller]`'s `key` holding `value` is an old key.
fn is_old(key: &str, is_table: bool) -> bool {
    // `disturbance` is the new sub-table's name too.
    !(key == "disturbance" && is_table)
}

fn moved(key: &str, new: &[&str]) -> MovedKey {
    MovedKey {
        old: format!("controller.{key}"),
        new: new.iter().map(|n| format!("controller.{n}")).collect(),
    }
}

/// The old keys `doc` (a parsed file) still uses, in [`MOVES`] order.
pub fn moved_keys(doc: &toml::Table) -> Vec<MovedKey> {
    let Some(controller) = doc.get("controller").and_then(|c| c.as_table()) else {
        return Vec::new();
    };
    MOVES
        .iter()
        .filter(|(key, _)| {
            controller
                .get(*key)
                .is_some_and(|v| is_old(key, v.is_table()))
        })
        .map(|(key, new)| moved(key, new))
        .collect()
}

/// A file rewritten for the sub-tables.
#[derive(Debug, Clone, PartialEq)]
pub struct Migrated {
    /// The new TOML text (comments and order kept; moved keys take their
    /// comments along into their sub-table).
    pub text: String,
    /// What moved, in [`MOVES`] order (empty: nothing to do, `text` is the
    /// input).
    pub moved: Vec<MovedKey>,
}

/// Why a file could not be migrated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MigrateError {
    /// Not TOML.
    #[error("not TOML: {0}")]
    Parse(String),
    /// `controller` or one of its sub-tables is not a table (a value, or
    /// an inline `controller = { ... }`).
    #[error("`{0}` is not a [table]; write it as one")]
    NotATable(String),
    /// A key is set both in the old place and the new one.
    #[error("{old} and {new} are both set; keep one (the new one)")]
    Both {
        /// The old path.
        old: String,
        /// The new path.
        new: String,
    },
}

/// Moves every old key of `[controller]` into its sub-table.
pub fn migrate(text: &str) -> Result<Migrated, MigrateError> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| MigrateError::Parse(e.to_string().trim().to_owned()))?;
    let Some(item) = doc.get_mut("controller") else {
        return Ok(unchanged(text));
    };
    let Some(controller) = item.as_table_mut() else {
        return Err(MigrateError::NotATable("controller".into()));
    };
    let position = controller.position();
    let mut done = Vec::new();
    for (key, new) in MOVES {
        let is_table = controller.get(key).is_some_and(|i| i.is_table_like());
        if !controller.contains_key(key) || !is_old(key, is_table) {
            continue;
        }
        let Some((old_key, value)) = controller.remove_entry(key) else {
            continue;
        };
        for target in *new {
            let (sub, leaf) = target.split_once('.').unwrap_or(("", target));
            let table = sub_table(controller, sub, position)
                .ok_or_else(|| MigrateError::NotATable(format!("controller.{sub}")))?;
            if table.contains_key(leaf) {
                return Err(MigrateError::Both {
                    old: format!("controller.{key}"),
                    new: format!("controller.{target}"),
                });
            }
            let mut new_key = Key::new(leaf);
            *new_key.leaf_decor_mut() = old_key.leaf_decor().clone();
            table.insert_formatted(&new_key, value.clone());
        }
        done.push(moved(key, new));
    }
    Ok(Migrated {
        text: doc.to_string(),
        moved: done,
    })
}

fn unchanged(text: &str) -> Migrated {
    Migrated {
        text: text.to_owned(),
        moved: Vec::new(),
    }
}

/// `[controller.<name>]`, created right after `[controller]` when absent
/// (an inline one is made a standard one); `None` if it is a value.
fn sub_table<'a>(
    controller: &'a mut Table,
    name: &str,
    position: Option<isize>,
) -> Option<&'a mut Table> {
    let item = controller.entry(name).or_insert_with(|| {
        let mut t = Table::new();
        if let Some(p) = position {
            t.set_position(Some(p));
        }
        Item::Table(t)
    });
    if !item.is_table() {
        // An inline sub-table: made a standard one to take the keys.
        let taken = std::mem::take(item);
        *item = match taken.into_table() {
            Ok(t) => Item::Table(t),
            Err(other) => other,
        };
    }
    item.as_table_mut()
}

#[cfg(test)]
mod tests {
    use super::*;

    const OLD: &str = r#"# A file of the flat era.
[vehicle]
tau = 0.25

[controller]
kind = "pd"
# The PD gains.
pd_kp = 3.0
pd_kd = 2.0
q = [2.0, 2.0, 1.0]
fmpc_horizon = 80
disturbance = true
disturbance_window = 60
constraint_tilt_deg = 25.0

[mission]
speed = 4.0
"#;

    #[test]
    fn finds_every_old_key_with_its_new_place() {
        let doc: toml::Table = toml::from_str(OLD).unwrap();
        let moved: Vec<String> = moved_keys(&doc).iter().map(|m| m.to_string()).collect();
        assert_eq!(
            moved,
            [
                "controller.q has moved to controller.dfmpc.q and controller.fmpc.q",
                "controller.disturbance has moved to controller.disturbance.enabled",
                "controller.disturbance_window has moved to controller.disturbance.window",
                "controller.fmpc_horizon has moved to controller.fmpc.horizon",
                "controller.pd_kp has moved to controller.pd.kp",
                "controller.pd_kd has moved to controller.pd.kd",
            ]
        );
        let new: toml::Table =
            toml::from_str("[controller.disturbance]\nenabled = true\n").unwrap();
        assert!(moved_keys(&new).is_empty());
    }

    #[test]
    fn every_old_key_has_a_new_place_in_the_schema() {
        // Each target is a field of the new [controller] sub-tables: the
        // default configuration's TOML has it.
        let cfg: toml::Table = toml::from_str(&super::super::Config::default().to_toml()).unwrap();
        let controller = cfg["controller"].as_table().unwrap();
        for (old, new) in MOVES {
            assert!(
                *old == "disturbance" || !controller.contains_key(*old),
                "{old} is still in [controller]"
            );
            for target in *new {
                let (sub, leaf) = target.split_once('.').unwrap();
                assert!(
                    controller[sub].as_table().unwrap().contains_key(leaf),
                    "controller.{target}"
                );
            }
        }
    }

    #[test]
    fn migrates_keeping_comments_and_values() {
        let m = migrate(OLD).unwrap();
        assert_eq!(m.moved.len(), 6);
        assert!(m.text.contains("# The PD gains.\nkp = 3.0"), "{}", m.text);
        assert!(m.text.contains("# A file of the flat era."));
        let doc: toml::Table = toml::from_str(&m.text).unwrap();
        assert!(moved_keys(&doc).is_empty());
        let c = &doc["controller"];
        assert_eq!(c["kind"].as_str(), Some("pd"));
        assert_eq!(c["constraint_tilt_deg"].as_float(), Some(25.0));
        assert_eq!(c["pd"]["kp"].as_float(), Some(3.0));
        assert_eq!(c["pd"]["kd"].as_float(), Some(2.0));
        assert_eq!(c["fmpc"]["horizon"].as_integer(), Some(80));
        assert_eq!(c["fmpc"]["q"], c["dfmpc"]["q"]);
        assert_eq!(c["disturbance"]["enabled"].as_bool(), Some(true));
        assert_eq!(c["disturbance"]["window"].as_integer(), Some(60));
        assert_eq!(doc["mission"]["speed"].as_float(), Some(4.0));
        // The result is a valid configuration with the same values.
        let cfg = super::super::Config::parse(&m.text, std::path::Path::new("m.toml")).unwrap();
        assert_eq!(cfg.controller.pd.kp, 3.0);
        assert_eq!(cfg.controller.dfmpc.q, [2.0, 2.0, 1.0]);
        assert_eq!(cfg.controller.fmpc.q, [2.0, 2.0, 1.0]);
        assert!(cfg.controller.disturbance.enabled);
        assert_eq!(cfg.vehicle.tau, 0.25);
        // Migrating again changes nothing.
        let again = migrate(&m.text).unwrap();
        assert!(again.moved.is_empty());
        assert_eq!(again.text, m.text);
    }

    #[test]
    fn a_key_in_both_places_is_refused() {
        let e = migrate("[controller]\nhorizon = 50\n[controller.dfmpc]\nhorizon = 60\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("controller.horizon") && e.contains("controller.dfmpc.horizon"),
            "{e}"
        );
    }

    #[test]
    fn a_sub_table_that_is_a_value_is_refused() {
        let e = migrate("[controller]\ndfmpc = 3\nhorizon = 50\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("controller.dfmpc"), "{e}");
        let e = migrate("controller = 3\n").unwrap_err().to_string();
        assert!(e.contains("`controller`"), "{e}");
    }

    #[test]
    fn files_without_old_keys_are_unchanged() {
        for text in [
            "",
            "[vehicle]\ntau = 0.3\n",
            "[controller]\nrate_hz = 40.0\n",
        ] {
            let m = migrate(text).unwrap();
            assert!(m.moved.is_empty());
            assert_eq!(m.text, text);
        }
    }
}
