//! Reading a flight's records back: the daemon's `.tlog` (every MAVLink
//! frame sent and received, with its time) and its per-tick CSV.
//!
//! [`FlightLog::read_tlog`] decodes the frames the offline tools need into
//! time series on the tlog's clock (seconds since the first record);
//! [`FlightCsv::read`] reads the CSV by column name. Both refuse malformed
//! input with an error naming the file and what is wrong.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use dflat_link::dialect::{MavAutopilot, MavModeFlag};
use dflat_link::tlog::TlogReader;
use dflat_link::{AutopilotFamily, AutopilotMode, MavMessage, euler_from_quaternion};
use thiserror::Error;

mod csv;
pub use csv::FlightCsv;

/// A flight record that could not be read.
#[derive(Debug, Error)]
pub enum FlightLogError {
    /// The file could not be opened or read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The tlog is malformed (bad marker, truncated record).
    #[error("{file}: not a readable .tlog: {message}")]
    Tlog {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The tlog holds no complete record (0 bytes, or the daemon was
    /// killed before its first record was whole).
    #[error("{file}: no complete .tlog record ({bytes} bytes)")]
    EmptyTlog {
        /// The file.
        file: PathBuf,
        /// Its length \[bytes\].
        bytes: u64,
    },
    /// The CSV is malformed.
    #[error("{file}: line {line}: {message}")]
    Csv {
        /// The file.
        file: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// One SET_ATTITUDE_TARGET the daemon sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandSample {
    /// Send time \[s\] on the log's clock.
    pub t: f64,
    /// The daemon's `time_boot_ms` field (its tick time) \[ms\].
    pub time_boot_ms: u32,
    /// Roll, pitch, yaw \[rad\] (ZYX, from the quaternion).
    pub euler: [f64; 3],
    /// Normalised thrust \[0, 1\].
    pub thrust: f64,
}

/// One ATTITUDE from the autopilot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeSample {
    /// Sample time \[s\] on the log's clock: the autopilot's `time_boot_ms`
    /// mapped with the smallest (arrival − source) offset of the flight.
    pub t: f64,
    /// Arrival \[s\] on the log's clock.
    pub arrival: f64,
    /// Roll, pitch, yaw \[rad\].
    pub euler: [f64; 3],
}

/// One pose (LOCAL_POSITION_NED, ODOMETRY or VISION_POSITION_ESTIMATE).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// Arrival \[s\] on the log's clock.
    pub arrival: f64,
    /// The message's own time \[s\] (its clock), 0 when absent.
    pub source_time: f64,
    /// Position, local NED \[m\].
    pub position: [f64; 3],
}

/// One autopilot HEARTBEAT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeSample {
    /// Arrival \[s\].
    pub t: f64,
    /// The mode it reports.
    pub mode: AutopilotMode,
}

impl ModeSample {
    /// A HEARTBEAT at `t` of an autopilot armed in its offboard mode (PX4
    /// OFFBOARD): the commands are applied. For logs assembled from a
    /// simulation's records (the lab's identify).
    pub fn engaged(t: f64) -> Self {
        Self {
            t,
            mode: AutopilotMode {
                family: AutopilotFamily::Px4,
                custom_mode: dflat_link::modes::px4::custom_mode(
                    dflat_link::modes::px4::OFFBOARD,
                    0,
                ),
                armed: true,
            },
        }
    }
}

/// A flight's MAVLink traffic as time series (seconds since the first
/// record; `start_unix_us` is that record's timestamp).
#[derive(Debug, Clone, Default)]
pub struct FlightLog {
    /// The file read.
    pub file: PathBuf,
    /// Timestamp of the first record \[µs since the UNIX epoch\].
    pub start_unix_us: u64,
    /// Records read.
    pub records: u64,
    /// Records whose frame did not decode (bad CRC, unknown id).
    pub undecoded: u64,
    /// The file ended inside a record (the daemon was killed mid-write, or
    /// the disk filled up): that partial record was dropped.
    pub torn_tail: bool,
    /// SET_ATTITUDE_TARGET sent by the daemon.
    pub commands: Vec<CommandSample>,
    /// ATTITUDE from the autopilot.
    pub attitude: Vec<AttitudeSample>,
    /// LOCAL_POSITION_NED.
    pub local_position: Vec<PoseSample>,
    /// VISION_POSITION_ESTIMATE.
    pub vision: Vec<PoseSample>,
    /// ODOMETRY.
    pub odometry: Vec<PoseSample>,
    /// Autopilot HEARTBEATs.
    pub modes: Vec<ModeSample>,
    /// STATUSTEXTs (time, text), both directions.
    pub texts: Vec<(f64, String)>,
    /// Offset \[s\] from the autopilot's clock (ATTITUDE `time_boot_ms`) to
    /// the log's: the smallest arrival − source time.
    pub autopilot_clock_offset: Option<f64>,
}

/// Gap in the command stream that ends an engaged segment \[s\].
pub const COMMAND_GAP: f64 = 0.1;
/// A HEARTBEAT older than this no longer vouches for the mode \[s\].
pub const HEARTBEAT_STALE: f64 = 3.0;

impl FlightLog {
    /// Reads and decodes a `.tlog`. A truncated last record (the daemon
    /// killed mid-write) ends the log without error and sets
    /// [`torn_tail`](Self::torn_tail); a file without any complete record
    /// is [`FlightLogError::EmptyTlog`]; any other damage is an error
    /// naming the byte offset.
    pub fn read_tlog(path: &Path) -> Result<Self, FlightLogError> {
        let file = std::fs::File::open(path).map_err(|source| FlightLogError::Io {
            file: path.to_owned(),
            source,
        })?;
        let mut log = FlightLog {
            file: path.to_owned(),
            ..FlightLog::default()
        };
        let mut attitude_raw: Vec<(f64, f64, [f64; 3])> = Vec::new();
        for record in TlogReader::new(BufReader::new(file)) {
            let record = match record {
                Ok(r) => r,
                Err(dflat_link::tlog::TlogError::Truncated { .. }) => {
                    log.torn_tail = true;
                    break;
                }
                Err(e) => {
                    return Err(FlightLogError::Tlog {
                        file: path.to_owned(),
                        message: e.to_string(),
                    });
                }
            };
            if log.records == 0 {
                log.start_unix_us = record.timestamp_us;
            }
            log.records += 1;
            let t = record.timestamp_us.saturating_sub(log.start_unix_us) as f64 * 1e-6;
            let Ok(frame) = record.parse() else {
                log.undecoded += 1;
                continue;
            };
            log.push(t, &frame.message, &mut attitude_raw);
        }
        if log.records == 0 {
            return Err(FlightLogError::EmptyTlog {
                file: path.to_owned(),
                bytes: std::fs::metadata(path).map_or(0, |m| m.len()),
            });
        }
        // ATTITUDE sample times: the source clock mapped by the smallest
        // arrival − source offset (the fastest message's transport).
        let offset = attitude_raw
            .iter()
            .map(|(arrival, source, _)| arrival - source)
            .fold(f64::INFINITY, f64::min);
        log.autopilot_clock_offset = offset.is_finite().then_some(offset);
        log.attitude = attitude_raw
            .into_iter()
            .map(|(arrival, source, euler)| AttitudeSample {
                t: source + offset,
                arrival,
                euler,
            })
            .collect();
        Ok(log)
    }

    fn push(&mut self, t: f64, msg: &MavMessage, attitude: &mut Vec<(f64, f64, [f64; 3])>) {
        match msg {
            MavMessage::SET_ATTITUDE_TARGET(d) => {
                let q = d.q.map(f64::from);
                self.commands.push(CommandSample {
                    t,
                    time_boot_ms: d.time_boot_ms,
                    euler: euler_from_quaternion(q),
                    thrust: f64::from(d.thrust),
                });
            }
            MavMessage::ATTITUDE(d) => attitude.push((
                t,
                f64::from(d.time_boot_ms) * 1e-3,
                [d.roll, d.pitch, d.yaw].map(f64::from),
            )),
            MavMessage::LOCAL_POSITION_NED(d) => self.local_position.push(PoseSample {
                arrival: t,
                source_time: f64::from(d.time_boot_ms) * 1e-3,
                position: [d.x, d.y, d.z].map(f64::from),
            }),
            MavMessage::VISION_POSITION_ESTIMATE(d) => self.vision.push(PoseSample {
                arrival: t,
                source_time: d.usec as f64 * 1e-6,
                position: [d.x, d.y, d.z].map(f64::from),
            }),
            MavMessage::ODOMETRY(d) => self.odometry.push(PoseSample {
                arrival: t,
                source_time: d.time_usec as f64 * 1e-6,
                position: [d.x, d.y, d.z].map(f64::from),
            }),
            MavMessage::HEARTBEAT(d) if d.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID => {
                self.modes.push(ModeSample {
                    t,
                    mode: AutopilotMode {
                        family: AutopilotFamily::from_mav_autopilot(d.autopilot),
                        custom_mode: d.custom_mode,
                        armed: d
                            .base_mode
                            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
                    },
                });
            }
            MavMessage::STATUSTEXT(d) => {
                let bytes: Vec<u8> = d.text.iter().copied().take_while(|b| *b != 0).collect();
                self.texts
                    .push((t, String::from_utf8_lossy(&bytes).into_owned()));
            }
            _ => {}
        }
    }

    /// The pose stream the vertical motion is read from: LOCAL_POSITION_NED
    /// if the log has it, else ODOMETRY, else VISION_POSITION_ESTIMATE.
    pub fn positions(&self) -> &[PoseSample] {
        [&self.local_position, &self.odometry, &self.vision]
            .into_iter()
            .find(|v| !v.is_empty())
            .map_or(&[], |v| v.as_slice())
    }

    /// The sample time \[s, log clock\] of a pose: its own timestamp on the
    /// autopilot's clock when it is one (mapped like ATTITUDE, at most 0.5 s
    /// before its arrival), else its arrival.
    pub fn pose_time(&self, p: &PoseSample) -> f64 {
        match self.autopilot_clock_offset {
            Some(offset) if p.source_time > 0.0 => {
                let t = p.source_time + offset;
                let age = p.arrival - t;
                if (-1e-3..=0.5).contains(&age) {
                    t
                } else {
                    p.arrival
                }
            }
            _ => p.arrival,
        }
    }

    /// The engaged segments \[start, end\] (log seconds): the autopilot's
    /// latest HEARTBEAT (at most [`HEARTBEAT_STALE`] old) says armed and in
    /// its offboard mode, and commands stream without a gap longer than
    /// [`COMMAND_GAP`].
    pub fn engaged_segments(&self) -> Vec<(f64, f64)> {
        let engaged_at = |t: f64| {
            let i = self.modes.partition_point(|m| m.t <= t);
            i > 0 && {
                let m = self.modes[i - 1];
                t - m.t <= HEARTBEAT_STALE && m.mode.applies_commands()
            }
        };
        let mut out: Vec<(f64, f64)> = Vec::new();
        let mut open: Option<(f64, f64)> = None;
        for c in &self.commands {
            let ok = engaged_at(c.t);
            match (&mut open, ok) {
                (Some((_, end)), true) if c.t - *end <= COMMAND_GAP => *end = c.t,
                (slot, true) => {
                    if let Some(seg) = slot.take() {
                        out.push(seg);
                    }
                    *slot = Some((c.t, c.t));
                }
                (slot, false) => {
                    if let Some(seg) = slot.take() {
                        out.push(seg);
                    }
                }
            }
        }
        out.extend(open);
        out.retain(|(a, b)| b > a);
        out
    }
}
