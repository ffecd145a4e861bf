//! What the SITL answers on either link (the shell around the pure
//! [`super::commands`] and [`super::params`]): COMMAND_LONG / COMMAND_INT,
//! the parameter protocol, MAVLink FTP, SETUP_SIGNING. Answers go back on
//! the link the request came from, addressed to its sender; refusals say
//! why in a STATUSTEXT and are counted.

use std::sync::atomic::Ordering;
use std::time::Duration;

use dflat_link::command::{Addressing, CommandRequest};
use dflat_link::dialect::{
    AUTOPILOT_VERSION_DATA, FILE_TRANSFER_PROTOCOL_DATA, MavProtocolCapability, MavResult,
    MavSeverity, MavSysStatusSensor, SYS_STATUS_DATA,
};
use dflat_link::params::{AutopilotParam, param_name};
use dflat_link::{MavHeader, MavMessage, statustext};

use super::commands::{CommandContext, SitlMessage, answer, ftp_reply};
use super::counters::{Kind, bump};
use super::params::ParamError;
use super::routing::{Dest, Link};
use super::{Shared, lock};

/// The latest of the SITL's periodic messages, for MAV_CMD_REQUEST_MESSAGE.
#[derive(Debug, Default)]
pub(super) struct Latest {
    pub(super) heartbeat: Option<MavMessage>,
    pub(super) sys_status: Option<MavMessage>,
    pub(super) attitude: Option<MavMessage>,
    pub(super) position: Option<MavMessage>,
}

/// SYS_STATUS of the stand-in: gyro, accelerometer, attitude, altitude and
/// position control present, enabled and healthy; no battery model
/// (voltage and current unknown).
pub(super) fn sys_status() -> MavMessage {
    let sensors = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
    MavMessage::SYS_STATUS(SYS_STATUS_DATA {
        onboard_control_sensors_present: sensors,
        onboard_control_sensors_enabled: sensors,
        onboard_control_sensors_health: sensors,
        load: 0,
        voltage_battery: u16::MAX,
        current_battery: -1,
        battery_remaining: -1,
        ..SYS_STATUS_DATA::default()
    })
}

/// AUTOPILOT_VERSION: MAVLink 2, COMMAND_INT, attitude targets, and the
/// flavour's parameter encoding (PX4 bytewise, ArduPilot cast).
fn autopilot_version(shared: &Shared) -> MavMessage {
    let encoding = match shared.params_family() {
        dflat_link::AutopilotFamily::Px4 => {
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        }
        _ => MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    };
    MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
        capabilities: MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
            | encoding,
        ..AUTOPILOT_VERSION_DATA::default()
    })
}

impl Shared {
    fn params_family(&self) -> dflat_link::AutopilotFamily {
        lock(&self.params).family()
    }

    /// The offboard-loss timeout in force (`COM_OF_LOSS_T` / `GUID_TIMEOUT`).
    pub(super) fn command_timeout(&self) -> Duration {
        Duration::from_micros(self.command_timeout_us.load(Ordering::Relaxed))
    }

    fn reply(&self, link: Link, msg: &MavMessage) {
        self.send_own(msg, Dest::Only(link), Kind::Reply);
    }

    fn refuse(&self, link: Link, text: &str) {
        tracing::info!(text, "sitl: refused");
        self.reply(link, &statustext(MavSeverity::MAV_SEVERITY_WARNING, text));
    }
}

/// Serves `msg` from `header` received on `link` if it is a request to the
/// SITL; returns whom it addresses (`None`: no target), which decides the
/// routing.
pub(super) fn serve(
    shared: &Shared,
    link: Link,
    header: &MavHeader,
    msg: &MavMessage,
) -> Option<Addressing> {
    let addressing = shared.addressing(msg)?;
    let own = (shared.system_id, shared.component_id);
    let from_self = header.system_id == u32::from(own.0) && header.component_id == own.1;
    if addressing == Addressing::Elsewhere || from_self {
        return Some(addressing);
    }
    match msg {
        MavMessage::COMMAND_LONG(_) | MavMessage::COMMAND_INT(_) => {
            if let Some(req) =
                CommandRequest::from_message(msg, header.system_id as u8, header.component_id)
            {
                command(shared, link, &req);
            }
        }
        MavMessage::PARAM_REQUEST_LIST(_) => {
            let params = lock(&shared.params).clone();
            for i in 0..params.len() {
                if let Some(m) = params.value_message(i) {
                    shared.reply(link, &m);
                }
            }
        }
        MavMessage::PARAM_REQUEST_READ(d) => {
            let params = lock(&shared.params).clone();
            let name = param_name(&d.param_id).unwrap_or("?");
            match params.lookup(d.param_index, name) {
                Ok(i) => {
                    if let Some(m) = params.value_message(i) {
                        shared.reply(link, &m);
                    }
                }
                Err(e) => {
                    bump(&shared.counters.params_refused);
                    shared.refuse(link, &e.to_string());
                }
            }
        }
        MavMessage::PARAM_SET(d) => {
            let name = param_name(&d.param_id).unwrap_or("?");
            let mut params = lock(&shared.params);
            let result = params.set(name, d.param_value);
            if result.is_ok()
                && let Some(t) = params.si(AutopilotParam::OffboardLossTimeout)
            {
                shared
                    .command_timeout_us
                    .store((t * 1e6).round() as u64, Ordering::Relaxed);
            }
            let params = params.clone();
            match result {
                Ok(i) => {
                    bump(&shared.counters.params_set);
                    tracing::info!(name, value = d.param_value, "sitl: parameter set");
                    if let Some(m) = params.value_message(i) {
                        shared.reply(link, &m);
                    }
                }
                Err(e) => {
                    bump(&shared.counters.params_refused);
                    shared.refuse(link, &e.to_string());
                    // The unchanged value, so a ground station sees it stayed.
                    if matches!(e, ParamError::ReadOnly(_))
                        && let Some((i, _)) = params.find(name)
                        && let Some(m) = params.value_message(i)
                    {
                        shared.reply(link, &m);
                    }
                }
            }
        }
        MavMessage::FILE_TRANSFER_PROTOCOL(d) => {
            if let Some(payload) = ftp_reply(&d.payload) {
                bump(&shared.counters.ftp_answered);
                shared.reply(
                    link,
                    &MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                        target_network: 0,
                        target_system: header.system_id as u8,
                        target_component: header.component_id,
                        payload,
                    }),
                );
            }
        }
        // The stand-in flies attitude targets only; say where position
        // setpoints go (once), rather than dropping them silently.
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)
            if addressing == Addressing::ToUs
                && !shared.told_setpoints.swap(true, Ordering::Relaxed) =>
        {
            let text = format!(
                "SITL: setpoints go to the companion, not {}/{}",
                own.0, own.1
            );
            shared.refuse(link, &text);
        }
        MavMessage::SETUP_SIGNING(_) => {
            bump(&shared.counters.signing_setups_refused);
            shared.refuse(link, "SITL: SETUP_SIGNING refused, key from config");
        }
        _ => {}
    }
    Some(addressing)
}

fn command(shared: &Shared, link: Link, req: &CommandRequest) {
    let stream_alive =
        lock(&shared.command).is_some_and(|(at, _)| at.elapsed() < shared.command_timeout());
    let pose_available =
        !shared.pose_paused.load(Ordering::Relaxed) && lock(&shared.latest).attitude.is_some();
    let ctx = CommandContext {
        own: (shared.system_id, shared.component_id),
        autopilot: shared.autopilot,
        stream_alive,
        pose_available,
    };
    let Some(a) = answer(req, &ctx) else {
        return;
    };
    bump(&shared.counters.commands_acked);
    match a.result {
        MavResult::MAV_RESULT_UNSUPPORTED => bump(&shared.counters.commands_unsupported),
        MavResult::MAV_RESULT_DENIED => bump(&shared.counters.commands_denied),
        _ => {}
    }
    tracing::debug!(command = ?req.command, result = ?a.result, "sitl: command answered");
    shared.reply(link, &a.ack);
    if let Some(reason) = &a.reason {
        shared.refuse(link, reason);
    }
    if let Some(mode) = a.mode {
        *lock(&shared.mode_request) = Some(mode);
    }
    let then = match a.then {
        Some(SitlMessage::AutopilotVersion) => Some(autopilot_version(shared)),
        Some(m) => {
            let latest = lock(&shared.latest);
            match m {
                SitlMessage::Heartbeat => latest.heartbeat.clone(),
                SitlMessage::SysStatus => latest.sys_status.clone().or_else(|| Some(sys_status())),
                SitlMessage::Attitude => latest.attitude.clone(),
                SitlMessage::LocalPosition => latest.position.clone(),
                SitlMessage::AutopilotVersion => None,
            }
        }
        None => None,
    };
    if let Some(m) = then {
        let kind = match a.then {
            Some(SitlMessage::Heartbeat) => Kind::Heartbeat,
            Some(SitlMessage::SysStatus) => Kind::SysStatus,
            Some(SitlMessage::Attitude) => Kind::Attitude,
            Some(SitlMessage::LocalPosition) => Kind::Position,
            _ => Kind::Reply,
        };
        shared.send_own(&m, Dest::Only(link), kind);
    }
}
