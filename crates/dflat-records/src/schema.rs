//! The per-tick flight CSV's columns: one list, used by the daemon's
//! writer (`dflat_daemon::records::write_row`, whose header is
//! [`CSV_HEADER`]) and by the offline reader (`dflat_tuning::flightlog`,
//! which looks columns up by [`Column`]). A column added, renamed or moved
//! here moves for both.

/// Declares [`Column`] (one variant per column, in file order), its names
/// and [`CSV_HEADER`] from one list.
macro_rules! columns {
    ($(#[doc = $fdoc:literal])* $first:ident = $first_name:literal,
     $($(#[doc = $doc:literal])* $variant:ident = $name:literal,)*) => {
        /// One column of the per-tick flight CSV, in file order. Positions
        /// local NED \[m\], angles ZYX \[rad\].
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Column {
            $(#[doc = $fdoc])*
            $first,
            $($(#[doc = $doc])* $variant,)*
        }

        impl Column {
            /// Every column, in file order.
            pub const ALL: &'static [Column] = &[Column::$first, $(Column::$variant,)*];

            /// The column's name in the header.
            pub const fn name(self) -> &'static str {
                match self {
                    Column::$first => $first_name,
                    $(Column::$variant => $name,)*
                }
            }
        }

        /// The CSV header line (no newline): [`Column::ALL`]'s names joined
        /// by commas.
        pub const CSV_HEADER: &str = concat!($first_name $(, ",", $name)*);
    };
}

columns! {
    /// Tick index k (deadline start + k·δt).
    Tick = "tick",
    /// Tick deadline since the daemon started \[s\], 0.1 ms.
    T = "t",
    /// Flight state at the end of the tick (`WAITING`, `STANDBY`, …).
    State = "state",
    /// Measured position x \[m\].
    X = "x",
    /// Measured position y \[m\].
    Y = "y",
    /// Measured position z \[m\].
    Z = "z",
    /// Planned output y*_k, x \[m\].
    Plan0X = "plan0_x",
    /// Planned output y*_k, y \[m\].
    Plan0Y = "plan0_y",
    /// Planned output y*_k, z \[m\].
    Plan0Z = "plan0_z",
    /// Planned output y*_{k+1}, x \[m\].
    Plan1X = "plan1_x",
    /// Planned output y*_{k+1}, y \[m\].
    Plan1Y = "plan1_y",
    /// Planned output y*_{k+1}, z \[m\].
    Plan1Z = "plan1_z",
    /// Planned output y*_{k+2}, x \[m\].
    Plan2X = "plan2_x",
    /// Planned output y*_{k+2}, y \[m\].
    Plan2Y = "plan2_y",
    /// Planned output y*_{k+2}, z \[m\].
    Plan2Z = "plan2_z",
    /// Planned output y*_{k+3}, x \[m\].
    Plan3X = "plan3_x",
    /// Planned output y*_{k+3}, y \[m\].
    Plan3Y = "plan3_y",
    /// Planned output y*_{k+3}, z \[m\].
    Plan3Z = "plan3_z",
    /// Reference y_ref,k, x \[m\].
    RefX = "ref_x",
    /// Reference y_ref,k, y \[m\].
    RefY = "ref_y",
    /// Reference y_ref,k, z \[m\].
    RefZ = "ref_z",
    /// Commanded roll \[rad\].
    Roll = "roll",
    /// Commanded pitch \[rad\].
    Pitch = "pitch",
    /// Commanded yaw \[rad\].
    Yaw = "yaw",
    /// Commanded normalised thrust \[0, 1\].
    Thrust = "thrust",
    /// Controller update time \[µs\].
    SolveUs = "solve_us",
    /// Wake time − deadline \[µs\].
    JitterUs = "jitter_us",
    /// Disturbance estimate d̂ x \[m/s²\].
    DistX = "dist_x",
    /// Disturbance estimate d̂ y \[m/s²\].
    DistY = "dist_y",
    /// Disturbance estimate d̂ z \[m/s²\].
    DistZ = "dist_z",
    /// Thrust scale κ̂ \[-\].
    ThrustScale = "thrust_scale",
    /// Hover thrust as sent to the autopilot \[0, 1\].
    HoverThrust = "hover_thrust",
    /// Estimator status (`settling`, `filling`, `tracking`, `frozen`).
    EstStatus = "est_status",
    /// Model-consistency residual \[m\].
    ResidualM = "residual_m",
    /// What the guards did (`plan`, `held`, `level`, `jump`, `residual`).
    Guard = "guard",
    /// Age of the newest pose at the tick \[ms\].
    PoseAgeMs = "pose_age_ms",
    /// The tick's exact time since the daemon started \[s\].
    TWake = "t_wake",
    /// Link events the tick had applied so far.
    Events = "events",
}

impl Column {
    /// The measured position's columns (x, y, z).
    pub const MEASURED: [Column; 3] = [Column::X, Column::Y, Column::Z];
    /// The reference's columns (x, y, z).
    pub const REFERENCE: [Column; 3] = [Column::RefX, Column::RefY, Column::RefZ];
    /// The planned outputs' columns, y*_k … y*_{k+3} (x, y, z each).
    pub const PLAN: [[Column; 3]; 4] = [
        [Column::Plan0X, Column::Plan0Y, Column::Plan0Z],
        [Column::Plan1X, Column::Plan1Y, Column::Plan1Z],
        [Column::Plan2X, Column::Plan2Y, Column::Plan2Z],
        [Column::Plan3X, Column::Plan3Y, Column::Plan3Z],
    ];
    /// The command's columns (roll, pitch, yaw, thrust).
    pub const COMMAND: [Column; 4] = [Column::Roll, Column::Pitch, Column::Yaw, Column::Thrust];
    /// The disturbance estimate's acceleration columns (x, y, z).
    pub const DISTURBANCE: [Column; 3] = [Column::DistX, Column::DistY, Column::DistZ];

    /// The column of a header name, if it is one of ours.
    pub fn from_name(name: &str) -> Option<Column> {
        Column::ALL.iter().copied().find(|c| c.name() == name)
    }
}

/// What makes a header line not a dflat flight CSV's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SchemaError {
    /// The header has no fields.
    #[error("empty: no header line")]
    Empty,
    /// A column every flight CSV has is missing.
    #[error("no `{0}` column: not a dflat flight CSV")]
    Missing(Column),
}

/// The columns every flight CSV has, whatever its version: a reader needs
/// them to place a row in the flight.
pub const REQUIRED: [Column; 3] = [Column::Tick, Column::T, Column::State];

/// Checks a header's column names (as read, in file order): not empty, and
/// with every [`REQUIRED`] column. Columns this version does not know are
/// allowed (a newer daemon's file), and so are missing optional ones (an
/// older daemon's).
pub fn check_header<S: AsRef<str>>(header: &[S]) -> Result<(), SchemaError> {
    if header.iter().all(|h| h.as_ref().trim().is_empty()) {
        return Err(SchemaError::Empty);
    }
    match REQUIRED
        .iter()
        .find(|c| !header.iter().any(|h| h.as_ref() == c.name()))
    {
        Some(missing) => Err(SchemaError::Missing(*missing)),
        None => Ok(()),
    }
}

impl AsRef<str> for Column {
    fn as_ref(&self) -> &str {
        self.name()
    }
}

impl std::fmt::Display for Column {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_is_the_columns_in_order_and_names_are_unique() {
        let names: Vec<&str> = Column::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(CSV_HEADER, names.join(","));
        assert_eq!(Column::ALL.len(), 38);
        for (i, c) in Column::ALL.iter().enumerate() {
            assert_eq!(Column::from_name(c.name()), Some(*c));
            assert_eq!(names.iter().filter(|n| **n == c.name()).count(), 1, "{c}");
            assert_eq!(Column::ALL.iter().position(|d| d == c), Some(i));
        }
        assert_eq!(Column::from_name("nope"), None);
        let grouped: Vec<Column> = Column::PLAN.iter().flatten().copied().collect();
        assert_eq!(&Column::ALL[6..18], &grouped[..]);
    }

    #[test]
    fn a_header_needs_tick_t_and_state() {
        let ours: Vec<&str> = CSV_HEADER.split(',').collect();
        assert_eq!(check_header(&ours), Ok(()));
        assert_eq!(check_header(&["tick", "t", "state", "new_column"]), Ok(()));
        assert_eq!(check_header(&[""]), Err(SchemaError::Empty));
        assert_eq!(
            check_header(&["tick", "state"]),
            Err(SchemaError::Missing(Column::T))
        );
        assert_eq!(
            SchemaError::Missing(Column::State).to_string(),
            "no `state` column: not a dflat flight CSV"
        );
    }
}
