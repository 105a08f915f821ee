//! Typed control commands, acknowledgements and messages of Livox SDK1.

use super::frame::{CmdType, RawFrame};
use crate::error::{LivoxError, Result};
use serde::Serialize;
use std::fmt;
use std::net::Ipv4Addr;

/// Every command this crate knows, by its (cmd_set, cmd_id).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandId {
    Broadcast,
    Handshake,
    QueryDeviceInfo,
    Heartbeat,
    Sampling,
    CoordinateSystem,
    Disconnect,
    AbnormalStatus,
    SetMode,
    WriteExtrinsics,
    ReadExtrinsics,
    SetReturnMode,
    GetReturnMode,
    SetImuPush,
    GetImuPush,
    UtcTime,
}

impl CommandId {
    pub const ALL: [CommandId; 16] = [
        Self::Broadcast,
        Self::Handshake,
        Self::QueryDeviceInfo,
        Self::Heartbeat,
        Self::Sampling,
        Self::CoordinateSystem,
        Self::Disconnect,
        Self::AbnormalStatus,
        Self::SetMode,
        Self::WriteExtrinsics,
        Self::ReadExtrinsics,
        Self::SetReturnMode,
        Self::GetReturnMode,
        Self::SetImuPush,
        Self::GetImuPush,
        Self::UtcTime,
    ];

    pub fn set_id(self) -> (u8, u8) {
        match self {
            Self::Broadcast => (0, 0),
            Self::Handshake => (0, 1),
            Self::QueryDeviceInfo => (0, 2),
            Self::Heartbeat => (0, 3),
            Self::Sampling => (0, 4),
            Self::CoordinateSystem => (0, 5),
            Self::Disconnect => (0, 6),
            Self::AbnormalStatus => (0, 7),
            Self::SetMode => (1, 0),
            Self::WriteExtrinsics => (1, 1),
            Self::ReadExtrinsics => (1, 2),
            Self::SetReturnMode => (1, 6),
            Self::GetReturnMode => (1, 7),
            Self::SetImuPush => (1, 8),
            Self::GetImuPush => (1, 9),
            Self::UtcTime => (1, 0x0A),
        }
    }

    pub fn from_set_id(set: u8, id: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.set_id() == (set, id))
    }

    /// Stable snake_case name, used in `starc inspect` output.
    pub fn name(self) -> &'static str {
        match self {
            Self::Broadcast => "broadcast",
            Self::Handshake => "handshake",
            Self::QueryDeviceInfo => "query_device_info",
            Self::Heartbeat => "heartbeat",
            Self::Sampling => "sampling",
            Self::CoordinateSystem => "coordinate_system",
            Self::Disconnect => "disconnect",
            Self::AbnormalStatus => "abnormal_status",
            Self::SetMode => "set_mode",
            Self::WriteExtrinsics => "write_extrinsics",
            Self::ReadExtrinsics => "read_extrinsics",
            Self::SetReturnMode => "set_return_mode",
            Self::GetReturnMode => "get_return_mode",
            Self::SetImuPush => "set_imu_push",
            Self::GetImuPush => "get_imu_push",
            Self::UtcTime => "utc_time",
        }
    }
}

/// The 16-character serial a device broadcasts; devices are told apart by it.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BroadcastCode(pub [u8; 16]);

impl BroadcastCode {
    /// From text: at most 16 bytes, NUL-padded.
    pub fn from_text(text: &str) -> Result<Self> {
        let bytes = text.as_bytes();
        if bytes.len() > 16 {
            return Err(LivoxError::BadValue { field: "broadcast code length", value: bytes.len() as u32 });
        }
        let mut code = [0u8; 16];
        code[..bytes.len()].copy_from_slice(bytes);
        Ok(Self(code))
    }

    /// The printable part (up to the first NUL), lossily decoded.
    pub fn text(&self) -> String {
        let end = self.0.iter().position(|&b| b == 0).unwrap_or(16);
        String::from_utf8_lossy(&self.0[..end]).into_owned()
    }
}

impl fmt::Debug for BroadcastCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BroadcastCode({:?})", self.text())
    }
}

impl fmt::Display for BroadcastCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text())
    }
}

impl Serialize for BroadcastCode {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.text())
    }
}

/// Device type byte of the broadcast.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceType {
    Hub,
    Mid40,
    Tele15,
    Horizon,
    Mid70,
    Avia,
    Other(u8),
}

impl DeviceType {
    pub fn from_u8(v: u8) -> Self {
        match v {
            0 => Self::Hub,
            1 => Self::Mid40,
            2 => Self::Tele15,
            3 => Self::Horizon,
            6 => Self::Mid70,
            7 => Self::Avia,
            other => Self::Other(other),
        }
    }

    pub fn to_u8(self) -> u8 {
        match self {
            Self::Hub => 0,
            Self::Mid40 => 1,
            Self::Tele15 => 2,
            Self::Horizon => 3,
            Self::Mid70 => 6,
            Self::Avia => 7,
            Self::Other(v) => v,
        }
    }

    pub fn name(self) -> String {
        match self {
            Self::Hub => "Hub".into(),
            Self::Mid40 => "Mid-40".into(),
            Self::Tele15 => "Tele-15".into(),
            Self::Horizon => "Horizon".into(),
            Self::Mid70 => "Mid-70".into(),
            Self::Avia => "Avia".into(),
            Self::Other(v) => format!("type {v}"),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CoordinateSystem {
    Cartesian = 0,
    Spherical = 1,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LidarMode {
    Normal = 1,
    PowerSave = 2,
    Standby = 3,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReturnMode {
    First = 0,
    Strongest = 1,
    Dual = 2,
    Triple = 3,
}

impl ReturnMode {
    pub fn echoes(self) -> usize {
        match self {
            Self::First | Self::Strongest => 1,
            Self::Dual => 2,
            Self::Triple => 3,
        }
    }
}

/// Mounting of the LiDAR as the device stores it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Extrinsics {
    pub roll_deg: f32,
    pub pitch_deg: f32,
    pub yaw_deg: f32,
    pub x_mm: i32,
    pub y_mm: i32,
    pub z_mm: i32,
}

/// The UTC time a host pushes for GPS-less synchronisation (set 1, id 0x0A).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct UtcTime {
    pub year_since_2000: u8,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub microseconds_in_hour: u32,
}

/// A host-to-device command.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "command", rename_all = "snake_case")]
pub enum Request {
    Handshake { host_ip: Ipv4Addr, data_port: u16, cmd_port: u16, imu_port: u16 },
    QueryDeviceInfo,
    Heartbeat,
    Sampling { start: bool },
    CoordinateSystem { system: CoordinateSystem },
    Disconnect,
    SetMode { mode: LidarMode },
    WriteExtrinsics { extrinsics: Extrinsics },
    ReadExtrinsics,
    SetReturnMode { mode: ReturnMode },
    GetReturnMode,
    SetImuPush { enabled: bool },
    GetImuPush,
    UtcTime { time: UtcTime },
}

/// A device's acknowledgement. `ret` 0 means success.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "command", rename_all = "snake_case")]
pub enum Response {
    QueryDeviceInfo {
        ret: u8,
        firmware: [u8; 4],
    },
    Heartbeat {
        ret: u8,
        work_state: u8,
        feature: u8,
        status: u32,
    },
    ReadExtrinsics {
        ret: u8,
        extrinsics: Extrinsics,
    },
    GetReturnMode {
        ret: u8,
        mode: ReturnMode,
    },
    GetImuPush {
        ret: u8,
        enabled: bool,
    },
    /// Commands whose ACK is a bare return code.
    Ret {
        id: CommandId,
        ret: u8,
    },
}

impl Response {
    pub fn ret(&self) -> u8 {
        match *self {
            Self::QueryDeviceInfo { ret, .. }
            | Self::Heartbeat { ret, .. }
            | Self::ReadExtrinsics { ret, .. }
            | Self::GetReturnMode { ret, .. }
            | Self::GetImuPush { ret, .. }
            | Self::Ret { ret, .. } => ret,
        }
    }
}

/// A device-initiated message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "message", rename_all = "snake_case")]
pub enum Message {
    Broadcast { code: BroadcastCode, device_type: DeviceType },
    AbnormalStatus { status: u32 },
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Body {
    Request(Request),
    Response(Response),
    Message(Message),
}

/// A decoded, verified control frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ControlFrame {
    pub cmd_type: CmdType,
    pub seq: u16,
    pub body: Body,
}

impl Request {
    pub fn id(&self) -> CommandId {
        match self {
            Self::Handshake { .. } => CommandId::Handshake,
            Self::QueryDeviceInfo => CommandId::QueryDeviceInfo,
            Self::Heartbeat => CommandId::Heartbeat,
            Self::Sampling { .. } => CommandId::Sampling,
            Self::CoordinateSystem { .. } => CommandId::CoordinateSystem,
            Self::Disconnect => CommandId::Disconnect,
            Self::SetMode { .. } => CommandId::SetMode,
            Self::WriteExtrinsics { .. } => CommandId::WriteExtrinsics,
            Self::ReadExtrinsics => CommandId::ReadExtrinsics,
            Self::SetReturnMode { .. } => CommandId::SetReturnMode,
            Self::GetReturnMode => CommandId::GetReturnMode,
            Self::SetImuPush { .. } => CommandId::SetImuPush,
            Self::GetImuPush => CommandId::GetImuPush,
            Self::UtcTime { .. } => CommandId::UtcTime,
        }
    }

    fn payload(&self) -> Vec<u8> {
        match *self {
            Self::Handshake { host_ip, data_port, cmd_port, imu_port } => {
                let mut p = host_ip.octets().to_vec();
                p.extend_from_slice(&data_port.to_le_bytes());
                p.extend_from_slice(&cmd_port.to_le_bytes());
                p.extend_from_slice(&imu_port.to_le_bytes());
                p
            }
            Self::QueryDeviceInfo
            | Self::Heartbeat
            | Self::Disconnect
            | Self::ReadExtrinsics
            | Self::GetReturnMode
            | Self::GetImuPush => Vec::new(),
            Self::Sampling { start } => vec![u8::from(start)],
            Self::CoordinateSystem { system } => vec![system as u8],
            Self::SetMode { mode } => vec![mode as u8],
            Self::WriteExtrinsics { extrinsics } => extrinsics_bytes(&extrinsics),
            Self::SetReturnMode { mode } => vec![mode as u8],
            Self::SetImuPush { enabled } => vec![u8::from(enabled)],
            Self::UtcTime { time } => {
                let mut p = vec![time.year_since_2000, time.month, time.day, time.hour];
                p.extend_from_slice(&time.microseconds_in_hour.to_le_bytes());
                p
            }
        }
    }

    fn decode(id: CommandId, p: &[u8]) -> Result<Self> {
        let (set, cid) = id.set_id();
        let bad = || LivoxError::BadPayload { set, id: cid, len: p.len() };
        let exact = |n: usize| if p.len() == n { Ok(()) } else { Err(bad()) };
        Ok(match id {
            CommandId::Handshake => {
                exact(10)?;
                Self::Handshake {
                    host_ip: Ipv4Addr::new(p[0], p[1], p[2], p[3]),
                    data_port: u16::from_le_bytes([p[4], p[5]]),
                    cmd_port: u16::from_le_bytes([p[6], p[7]]),
                    imu_port: u16::from_le_bytes([p[8], p[9]]),
                }
            }
            CommandId::QueryDeviceInfo => exact(0).map(|_| Self::QueryDeviceInfo)?,
            CommandId::Heartbeat => exact(0).map(|_| Self::Heartbeat)?,
            CommandId::Disconnect => exact(0).map(|_| Self::Disconnect)?,
            CommandId::ReadExtrinsics => exact(0).map(|_| Self::ReadExtrinsics)?,
            CommandId::GetReturnMode => exact(0).map(|_| Self::GetReturnMode)?,
            CommandId::GetImuPush => exact(0).map(|_| Self::GetImuPush)?,
            CommandId::Sampling => {
                exact(1)?;
                Self::Sampling { start: flag(p[0], "sampling")? }
            }
            CommandId::CoordinateSystem => {
                exact(1)?;
                let system = match p[0] {
                    0 => CoordinateSystem::Cartesian,
                    1 => CoordinateSystem::Spherical,
                    v => return Err(LivoxError::BadValue { field: "coordinate system", value: v.into() }),
                };
                Self::CoordinateSystem { system }
            }
            CommandId::SetMode => {
                exact(1)?;
                let mode = match p[0] {
                    1 => LidarMode::Normal,
                    2 => LidarMode::PowerSave,
                    3 => LidarMode::Standby,
                    v => return Err(LivoxError::BadValue { field: "lidar mode", value: v.into() }),
                };
                Self::SetMode { mode }
            }
            CommandId::WriteExtrinsics => {
                exact(24)?;
                Self::WriteExtrinsics { extrinsics: extrinsics_from(p) }
            }
            CommandId::SetReturnMode => {
                exact(1)?;
                Self::SetReturnMode { mode: return_mode(p[0])? }
            }
            CommandId::SetImuPush => {
                exact(1)?;
                Self::SetImuPush { enabled: flag(p[0], "imu push")? }
            }
            CommandId::UtcTime => {
                exact(8)?;
                Self::UtcTime {
                    time: UtcTime {
                        year_since_2000: p[0],
                        month: p[1],
                        day: p[2],
                        hour: p[3],
                        microseconds_in_hour: u32::from_le_bytes([p[4], p[5], p[6], p[7]]),
                    },
                }
            }
            CommandId::Broadcast | CommandId::AbnormalStatus => return Err(bad()),
        })
    }
}

impl Response {
    pub fn id(&self) -> CommandId {
        match self {
            Self::QueryDeviceInfo { .. } => CommandId::QueryDeviceInfo,
            Self::Heartbeat { .. } => CommandId::Heartbeat,
            Self::ReadExtrinsics { .. } => CommandId::ReadExtrinsics,
            Self::GetReturnMode { .. } => CommandId::GetReturnMode,
            Self::GetImuPush { .. } => CommandId::GetImuPush,
            Self::Ret { id, .. } => *id,
        }
    }

    fn payload(&self) -> Vec<u8> {
        match *self {
            Self::QueryDeviceInfo { ret, firmware } => {
                let mut p = vec![ret];
                p.extend_from_slice(&firmware);
                p
            }
            Self::Heartbeat { ret, work_state, feature, status } => {
                let mut p = vec![ret, work_state, feature];
                p.extend_from_slice(&status.to_le_bytes());
                p
            }
            Self::ReadExtrinsics { ret, extrinsics } => {
                let mut p = vec![ret];
                p.extend_from_slice(&extrinsics_bytes(&extrinsics));
                p
            }
            Self::GetReturnMode { ret, mode } => vec![ret, mode as u8],
            Self::GetImuPush { ret, enabled } => vec![ret, u8::from(enabled)],
            Self::Ret { ret, .. } => vec![ret],
        }
    }

    fn decode(id: CommandId, p: &[u8]) -> Result<Self> {
        let (set, cid) = id.set_id();
        let bad = || LivoxError::BadPayload { set, id: cid, len: p.len() };
        let Some(&ret) = p.first() else {
            return Err(bad());
        };
        // A refusal may carry only the return code, whatever the command.
        let full = |n: usize| -> Result<bool> {
            if p.len() == n {
                Ok(true)
            } else if p.len() == 1 && ret != 0 {
                Ok(false)
            } else {
                Err(bad())
            }
        };
        Ok(match id {
            CommandId::QueryDeviceInfo => {
                if !full(5)? {
                    return Ok(Self::Ret { id, ret });
                }
                Self::QueryDeviceInfo { ret, firmware: [p[1], p[2], p[3], p[4]] }
            }
            CommandId::Heartbeat => {
                if !full(7)? {
                    return Ok(Self::Ret { id, ret });
                }
                Self::Heartbeat {
                    ret,
                    work_state: p[1],
                    feature: p[2],
                    status: u32::from_le_bytes([p[3], p[4], p[5], p[6]]),
                }
            }
            CommandId::ReadExtrinsics => {
                if !full(25)? {
                    return Ok(Self::Ret { id, ret });
                }
                Self::ReadExtrinsics { ret, extrinsics: extrinsics_from(&p[1..]) }
            }
            CommandId::GetReturnMode => {
                if !full(2)? {
                    return Ok(Self::Ret { id, ret });
                }
                Self::GetReturnMode { ret, mode: return_mode(p[1])? }
            }
            CommandId::GetImuPush => {
                if !full(2)? {
                    return Ok(Self::Ret { id, ret });
                }
                Self::GetImuPush { ret, enabled: flag(p[1], "imu push")? }
            }
            CommandId::Broadcast | CommandId::AbnormalStatus => return Err(bad()),
            _ => {
                if p.len() != 1 {
                    return Err(bad());
                }
                Self::Ret { id, ret }
            }
        })
    }
}

impl Message {
    pub fn id(&self) -> CommandId {
        match self {
            Self::Broadcast { .. } => CommandId::Broadcast,
            Self::AbnormalStatus { .. } => CommandId::AbnormalStatus,
        }
    }

    fn payload(&self) -> Vec<u8> {
        match *self {
            Self::Broadcast { code, device_type } => {
                let mut p = code.0.to_vec();
                p.push(device_type.to_u8());
                p.extend_from_slice(&[0, 0]);
                p
            }
            Self::AbnormalStatus { status } => status.to_le_bytes().to_vec(),
        }
    }

    fn decode(id: CommandId, p: &[u8]) -> Result<Self> {
        let (set, cid) = id.set_id();
        let bad = || LivoxError::BadPayload { set, id: cid, len: p.len() };
        match id {
            CommandId::Broadcast if p.len() == 19 => {
                let mut code = [0u8; 16];
                code.copy_from_slice(&p[..16]);
                Ok(Self::Broadcast { code: BroadcastCode(code), device_type: DeviceType::from_u8(p[16]) })
            }
            CommandId::AbnormalStatus if p.len() == 4 => {
                Ok(Self::AbnormalStatus { status: u32::from_le_bytes([p[0], p[1], p[2], p[3]]) })
            }
            _ => Err(bad()),
        }
    }
}

impl Body {
    pub fn id(&self) -> CommandId {
        match self {
            Self::Request(r) => r.id(),
            Self::Response(r) => r.id(),
            Self::Message(m) => m.id(),
        }
    }
}

impl ControlFrame {
    pub fn request(seq: u16, request: Request) -> Self {
        Self { cmd_type: CmdType::Cmd, seq, body: Body::Request(request) }
    }

    pub fn response(seq: u16, response: Response) -> Self {
        Self { cmd_type: CmdType::Ack, seq, body: Body::Response(response) }
    }

    pub fn message(seq: u16, message: Message) -> Self {
        Self { cmd_type: CmdType::Msg, seq, body: Body::Message(message) }
    }

    pub fn id(&self) -> CommandId {
        self.body.id()
    }

    /// Decodes and verifies a datagram. The official SDK sends its handshake with cmd_type 1
    /// (ACK); a handshake-shaped payload is therefore read as a request whatever its type.
    pub fn decode(bytes: &[u8]) -> Result<Self> {
        let raw = RawFrame::decode(bytes)?;
        Self::from_raw(&raw)
    }

    pub fn from_raw(raw: &RawFrame<'_>) -> Result<Self> {
        let id = CommandId::from_set_id(raw.cmd_set, raw.cmd_id)
            .ok_or(LivoxError::UnknownCommand { set: raw.cmd_set, id: raw.cmd_id })?;
        let body = match raw.cmd_type {
            CmdType::Msg => Body::Message(Message::decode(id, raw.payload)?),
            CmdType::Cmd => Body::Request(Request::decode(id, raw.payload)?),
            CmdType::Ack if id == CommandId::Handshake && raw.payload.len() == 10 => {
                Body::Request(Request::decode(id, raw.payload)?)
            }
            CmdType::Ack => Body::Response(Response::decode(id, raw.payload)?),
        };
        Ok(Self { cmd_type: raw.cmd_type, seq: raw.seq, body })
    }

    pub fn encode(&self) -> Result<Vec<u8>> {
        let payload = match &self.body {
            Body::Request(r) => r.payload(),
            Body::Response(r) => r.payload(),
            Body::Message(m) => m.payload(),
        };
        let (cmd_set, cmd_id) = self.id().set_id();
        RawFrame { cmd_type: self.cmd_type, seq: self.seq, cmd_set, cmd_id, payload: &payload }.encode()
    }
}

fn flag(v: u8, field: &'static str) -> Result<bool> {
    match v {
        0 => Ok(false),
        1 => Ok(true),
        v => Err(LivoxError::BadValue { field, value: v.into() }),
    }
}

fn return_mode(v: u8) -> Result<ReturnMode> {
    match v {
        0 => Ok(ReturnMode::First),
        1 => Ok(ReturnMode::Strongest),
        2 => Ok(ReturnMode::Dual),
        3 => Ok(ReturnMode::Triple),
        v => Err(LivoxError::BadValue { field: "return mode", value: v.into() }),
    }
}

fn extrinsics_bytes(e: &Extrinsics) -> Vec<u8> {
    let mut p = Vec::with_capacity(24);
    for v in [e.roll_deg, e.pitch_deg, e.yaw_deg] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    for v in [e.x_mm, e.y_mm, e.z_mm] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    p
}

/// `p` holds at least 24 bytes (checked by the callers).
fn extrinsics_from(p: &[u8]) -> Extrinsics {
    let f = |i: usize| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
    let n = |i: usize| i32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
    Extrinsics { roll_deg: f(0), pitch_deg: f(4), yaw_deg: f(8), x_mm: n(12), y_mm: n(16), z_mm: n(20) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn every_request() -> Vec<Request> {
        vec![
            Request::Handshake {
                host_ip: Ipv4Addr::new(192, 168, 1, 50),
                data_port: 56001,
                cmd_port: 55501,
                imu_port: 56001,
            },
            Request::QueryDeviceInfo,
            Request::Heartbeat,
            Request::Sampling { start: true },
            Request::Sampling { start: false },
            Request::CoordinateSystem { system: CoordinateSystem::Spherical },
            Request::Disconnect,
            Request::SetMode { mode: LidarMode::PowerSave },
            Request::WriteExtrinsics {
                extrinsics: Extrinsics {
                    roll_deg: 1.5,
                    pitch_deg: -2.0,
                    yaw_deg: 90.0,
                    x_mm: 10,
                    y_mm: -20,
                    z_mm: 300,
                },
            },
            Request::ReadExtrinsics,
            Request::SetReturnMode { mode: ReturnMode::Triple },
            Request::GetReturnMode,
            Request::SetImuPush { enabled: true },
            Request::GetImuPush,
            Request::UtcTime {
                time: UtcTime { year_since_2000: 26, month: 11, day: 21, hour: 8, microseconds_in_hour: 1_234_567 },
            },
        ]
    }

    fn every_response() -> Vec<Response> {
        let mut v = vec![
            Response::QueryDeviceInfo { ret: 0, firmware: [3, 8, 0, 0] },
            Response::Heartbeat { ret: 0, work_state: 1, feature: 0, status: 0x0000_2200 },
            Response::ReadExtrinsics {
                ret: 0,
                extrinsics: Extrinsics { roll_deg: 0.0, pitch_deg: 0.5, yaw_deg: 0.0, x_mm: 1, y_mm: 2, z_mm: 3 },
            },
            Response::GetReturnMode { ret: 0, mode: ReturnMode::Dual },
            Response::GetImuPush { ret: 0, enabled: true },
        ];
        for id in [
            CommandId::Handshake,
            CommandId::Sampling,
            CommandId::CoordinateSystem,
            CommandId::Disconnect,
            CommandId::SetMode,
            CommandId::WriteExtrinsics,
            CommandId::SetReturnMode,
            CommandId::SetImuPush,
            CommandId::UtcTime,
        ] {
            v.push(Response::Ret { id, ret: 0 });
            v.push(Response::Ret { id, ret: 1 });
        }
        v
    }

    #[test]
    fn every_request_round_trips() {
        for (i, r) in every_request().into_iter().enumerate() {
            let frame = ControlFrame::request(i as u16, r);
            let bytes = frame.encode().unwrap_or_default();
            assert_eq!(ControlFrame::decode(&bytes).ok(), Some(frame), "{r:?}");
        }
    }

    #[test]
    fn every_response_round_trips() {
        for (i, r) in every_response().into_iter().enumerate() {
            let frame = ControlFrame::response(i as u16, r);
            let bytes = frame.encode().unwrap_or_default();
            assert_eq!(ControlFrame::decode(&bytes).ok(), Some(frame), "{r:?}");
        }
    }

    #[test]
    fn messages_round_trip_and_broadcast_is_34_bytes() {
        let code = BroadcastCode::from_text("3WEDH7600101621").unwrap_or(BroadcastCode([0; 16]));
        let b = ControlFrame::message(0, Message::Broadcast { code, device_type: DeviceType::Avia });
        let bytes = b.encode().unwrap_or_default();
        assert_eq!(bytes.len(), 34);
        assert_eq!(ControlFrame::decode(&bytes).ok(), Some(b));
        let a = ControlFrame::message(9, Message::AbnormalStatus { status: 0x4000_0001 });
        assert_eq!(ControlFrame::decode(&a.encode().unwrap_or_default()).ok(), Some(a));
    }

    #[test]
    fn handshake_sent_as_ack_is_read_as_a_request() {
        let req = Request::Handshake { host_ip: Ipv4Addr::LOCALHOST, data_port: 1, cmd_port: 2, imu_port: 3 };
        let payload = req.payload();
        let bytes = RawFrame { cmd_type: CmdType::Ack, seq: 5, cmd_set: 0, cmd_id: 1, payload: &payload }
            .encode()
            .unwrap_or_default();
        let frame = ControlFrame::decode(&bytes).ok();
        assert_eq!(frame.map(|f| f.body), Some(Body::Request(req)));
    }

    #[test]
    fn refusals_may_carry_only_a_return_code() {
        let bytes = RawFrame { cmd_type: CmdType::Ack, seq: 1, cmd_set: 0, cmd_id: 2, payload: &[1] }
            .encode()
            .unwrap_or_default();
        let frame = ControlFrame::decode(&bytes).ok();
        assert_eq!(
            frame.map(|f| f.body),
            Some(Body::Response(Response::Ret { id: CommandId::QueryDeviceInfo, ret: 1 }))
        );
    }

    #[test]
    fn bad_values_and_unknown_commands_are_typed_errors() {
        let bytes = RawFrame { cmd_type: CmdType::Cmd, seq: 1, cmd_set: 1, cmd_id: 6, payload: &[7] }
            .encode()
            .unwrap_or_default();
        assert!(matches!(ControlFrame::decode(&bytes), Err(LivoxError::BadValue { .. })));
        let bytes = RawFrame { cmd_type: CmdType::Cmd, seq: 1, cmd_set: 9, cmd_id: 9, payload: &[] }
            .encode()
            .unwrap_or_default();
        assert!(matches!(ControlFrame::decode(&bytes), Err(LivoxError::UnknownCommand { set: 9, id: 9 })));
        let bytes = RawFrame { cmd_type: CmdType::Cmd, seq: 1, cmd_set: 0, cmd_id: 1, payload: &[1, 2] }
            .encode()
            .unwrap_or_default();
        assert!(matches!(ControlFrame::decode(&bytes), Err(LivoxError::BadPayload { .. })));
    }
}
