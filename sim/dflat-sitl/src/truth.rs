//! The truth CSV ([`SitlOptions::truth_csv`]): the plant's state and the
//! command applied, at the telemetry rate.

use super::*;

pub(super) fn create_truth_csv(path: &Path) -> Result<BufWriter<File>, SitlError> {
    let err = |source| SitlError::Truth {
        file: path.to_owned(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(err)?;
    }
    let mut w = BufWriter::new(File::create(path).map_err(err)?);
    writeln!(
        w,
        "t,x,y,z,vx,vy,vz,roll,pitch,yaw,cmd_roll,cmd_pitch,cmd_yaw,cmd_thrust,mode"
    )
    .map_err(err)?;
    Ok(w)
}

pub(super) fn write_truth_row(w: &mut impl std::io::Write, s: &TruthSample) -> std::io::Result<()> {
    let [x, y, z] = s.position;
    let [vx, vy, vz] = s.velocity;
    let [r, p, yw] = s.euler;
    write!(
        w,
        "{:.4},{x:.5},{y:.5},{z:.5},{vx:.5},{vy:.5},{vz:.5},{r:.6},{p:.6},{yw:.6},",
        s.t
    )?;
    match s.command {
        Some(c) => write!(
            w,
            "{:.6},{:.6},{:.6},{:.5},",
            c.roll, c.pitch, c.yaw, c.thrust
        )?,
        None => write!(w, ",,,,")?,
    }
    writeln!(w, "{}", s.mode.as_str())
}

/// One row of a truth CSV written by the SITL.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthRow {
    /// SITL time \[s\].
    pub t: f64,
    /// True position, NED \[m\].
    pub position: [f64; 3],
    /// True velocity, NED \[m/s\].
    pub velocity: [f64; 3],
    /// Whether a command was in force.
    pub commanded: bool,
}

/// Reads the truth CSV written with [`SitlOptions::truth_csv`] (rows that do
/// not parse, e.g. a partly written last line, are skipped).
pub fn read_truth_csv(path: &Path) -> std::io::Result<Vec<TruthRow>> {
    let text = std::fs::read_to_string(path)?;
    Ok(text
        .lines()
        .skip(1)
        .filter_map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            if f.len() != 15 {
                return None;
            }
            let n = |i: usize| f[i].parse::<f64>().ok();
            Some(TruthRow {
                t: n(0)?,
                position: [n(1)?, n(2)?, n(3)?],
                velocity: [n(4)?, n(5)?, n(6)?],
                commanded: f[14] == "offboard",
            })
        })
        .collect())
}
