//! Livox Viewer recordings (.lvx v1.0 and v1.1): a public header, a private header, one device
//! info block per device, then frames of packages (device index, the 18-byte data header, points).
//!
//! | part | v1.1 | v1.0 |
//! |---|---|---|
//! | public header | "livox_tech" padded to 16, version 1,1,0,0, magic 0xAC0EA767 | version 1,0,0,0 |
//! | private header | frame_duration u32 ms, device_count u8 | device_count u8 |
//! | device info | 59 bytes (with extrinsic_enable) | 58 bytes |
//! | frame header | current_offset, next_offset, frame_index (u64 each) | and packet_count u64 |
//!
//! A package's length comes from its data_type ([`packet_len_for`]); packages never cross the
//! frame's `next_offset`. The writer produces v1.1, cutting frames every `frame_duration` of
//! packet time.

use super::{ReadStats, Step};
use crate::data::packet::HEADER_LEN as DATA_HEADER_LEN;
use crate::data::{packet_len_for, timestamp};
use crate::error::{LivoxError, Result};
use serde::Serialize;
use starc_time::{Clock, Stamp};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

pub const SIGNATURE: &[u8] = b"livox_tech";
pub const MAGIC: u32 = 0xac0e_a767;
pub const PUBLIC_HEADER_LEN: usize = 24;
pub const DEVICE_INFO_LEN_V1_1: usize = 59;
pub const DEVICE_INFO_LEN_V1_0: usize = 58;
pub const FRAME_HEADER_LEN_V1_1: usize = 24;
pub const FRAME_HEADER_LEN_V1_0: usize = 32;
/// The writer flushes a frame early once it holds this many bytes.
pub const MAX_WRITER_FRAME_BYTES: usize = 8 * 1024 * 1024;
const FORMAT: &str = "lvx";

/// Which .lvx layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum LvxVersion {
    #[serde(rename = "1.0")]
    V1_0,
    #[serde(rename = "1.1")]
    V1_1,
}

impl LvxVersion {
    fn device_info_len(self) -> usize {
        match self {
            Self::V1_0 => DEVICE_INFO_LEN_V1_0,
            Self::V1_1 => DEVICE_INFO_LEN_V1_1,
        }
    }

    fn frame_header_len(self) -> usize {
        match self {
            Self::V1_0 => FRAME_HEADER_LEN_V1_0,
            Self::V1_1 => FRAME_HEADER_LEN_V1_1,
        }
    }

    fn private_header_len(self) -> usize {
        match self {
            Self::V1_0 => 1,
            Self::V1_1 => 5,
        }
    }
}

/// A device info block.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LvxDevice {
    #[serde(serialize_with = "serialize_code")]
    pub lidar_sn: [u8; 16],
    #[serde(serialize_with = "serialize_code")]
    pub hub_sn: [u8; 16],
    pub device_index: u8,
    /// The SDK's device type (2 Tele-15, 7 Avia...; see `control::DeviceType`).
    pub device_type: u8,
    /// v1.1 only; false in v1.0 files.
    pub extrinsic_enable: bool,
    pub roll_deg: f32,
    pub pitch_deg: f32,
    pub yaw_deg: f32,
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
}

fn serialize_code<S: serde::Serializer>(code: &[u8; 16], s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(&code_text(code))
}

/// The printable part of a NUL-padded serial.
pub fn code_text(code: &[u8; 16]) -> String {
    let end = code.iter().position(|&b| b == 0).unwrap_or(code.len());
    String::from_utf8_lossy(code.get(..end).unwrap_or(&[])).into_owned()
}

impl LvxDevice {
    /// A device with no extrinsics; `lidar_sn` is cut to 16 bytes.
    pub fn new(lidar_sn: &str, device_index: u8, device_type: u8) -> Self {
        let mut sn = [0u8; 16];
        for (d, s) in sn.iter_mut().zip(lidar_sn.bytes()) {
            *d = s;
        }
        Self {
            lidar_sn: sn,
            hub_sn: [0; 16],
            device_index,
            device_type,
            extrinsic_enable: false,
            roll_deg: 0.0,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            x_m: 0.0,
            y_m: 0.0,
            z_m: 0.0,
        }
    }

    pub fn lidar_sn_text(&self) -> String {
        code_text(&self.lidar_sn)
    }

    /// `b` holds the version's device info length (checked by the caller).
    fn decode(b: &[u8], version: LvxVersion) -> Self {
        let mut lidar_sn = [0u8; 16];
        lidar_sn.copy_from_slice(&b[..16]);
        let mut hub_sn = [0u8; 16];
        hub_sn.copy_from_slice(&b[16..32]);
        let (extrinsic_enable, f) = match version {
            LvxVersion::V1_1 => (b[34] != 0, 35),
            LvxVersion::V1_0 => (false, 34),
        };
        let fl = |i: usize| f32::from_le_bytes([b[f + i], b[f + i + 1], b[f + i + 2], b[f + i + 3]]);
        Self {
            lidar_sn,
            hub_sn,
            device_index: b[32],
            device_type: b[33],
            extrinsic_enable,
            roll_deg: fl(0),
            pitch_deg: fl(4),
            yaw_deg: fl(8),
            x_m: fl(12),
            y_m: fl(16),
            z_m: fl(20),
        }
    }

    fn encode_v1_1(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.lidar_sn);
        out.extend_from_slice(&self.hub_sn);
        out.extend_from_slice(&[self.device_index, self.device_type, u8::from(self.extrinsic_enable)]);
        for v in [self.roll_deg, self.pitch_deg, self.yaw_deg, self.x_m, self.y_m, self.z_m] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// The headers of an .lvx file.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LvxHeader {
    pub version: LvxVersion,
    /// The version bytes as stored.
    pub version_bytes: [u8; 4],
    /// v1.1 only.
    pub frame_duration_ms: Option<u32>,
    pub devices: Vec<LvxDevice>,
}

impl LvxHeader {
    pub fn device(&self, index: u8) -> Option<&LvxDevice> {
        self.devices.iter().find(|d| d.device_index == index)
    }
}

/// The time stamp of a package's data header; an undecodable stamp is kept raw on the device clock.
pub fn package_stamp(packet: &[u8]) -> Stamp {
    let (Some(&ts_type), Some(raw)) = (packet.get(8), packet.get(10..18)) else {
        return Stamp::new(0, Clock::Device);
    };
    let mut bytes = [0u8; 8];
    bytes.copy_from_slice(raw);
    timestamp::decode(ts_type, bytes).unwrap_or(Stamp::new(u64::from_le_bytes(bytes), Clock::Device))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    PublicHeader,
    PrivateHeader,
    Devices { count: u8 },
    FrameHeader,
    Packages { frame_end: u64 },
}

/// Sans-IO .lvx decoder.
#[derive(Clone, Debug)]
pub struct LvxDecoder {
    state: State,
    offset: u64,
    version: LvxVersion,
    version_bytes: [u8; 4],
    frame_duration_ms: Option<u32>,
    header: Option<LvxHeader>,
}

impl Default for LvxDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl LvxDecoder {
    pub fn new() -> Self {
        Self {
            state: State::PublicHeader,
            offset: 0,
            version: LvxVersion::V1_1,
            version_bytes: [0; 4],
            frame_duration_ms: None,
            header: None,
        }
    }

    /// File offset of the next byte to decode.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Set once the device list has been read.
    pub fn header(&self) -> Option<&LvxHeader> {
        self.header.as_ref()
    }

    pub fn header_done(&self) -> bool {
        self.header.is_some()
    }

    /// Whether the input may end here (between frames).
    pub fn at_frame_boundary(&self) -> bool {
        self.state == State::FrameHeader
    }

    fn malformed(&self, reason: &'static str) -> LivoxError {
        LivoxError::MalformedCapture { format: FORMAT, offset: self.offset, reason }
    }

    fn skip(&mut self, n: usize, next: State) -> Step {
        self.offset += n as u64;
        self.state = next;
        Step::Skip(n)
    }

    /// Looks at the bytes at the current offset.
    pub fn step(&mut self, input: &[u8], stats: &mut ReadStats) -> Result<Step> {
        match self.state {
            State::PublicHeader => {
                if input.len() < PUBLIC_HEADER_LEN {
                    return Ok(Step::Need(PUBLIC_HEADER_LEN));
                }
                if !input.starts_with(SIGNATURE) {
                    return Err(self.malformed("signature is not \"livox_tech\""));
                }
                let magic = u32::from_le_bytes([input[20], input[21], input[22], input[23]]);
                if magic != MAGIC {
                    return Err(self.malformed("magic code is not 0xac0ea767"));
                }
                self.version_bytes = [input[16], input[17], input[18], input[19]];
                self.version = match (input[16], input[17]) {
                    (1, 1) => LvxVersion::V1_1,
                    (1, 0) => LvxVersion::V1_0,
                    (major, minor) => {
                        return Err(LivoxError::UnsupportedCaptureVersion {
                            format: FORMAT,
                            major: major.into(),
                            minor: minor.into(),
                        })
                    }
                };
                Ok(self.skip(PUBLIC_HEADER_LEN, State::PrivateHeader))
            }
            State::PrivateHeader => {
                let len = self.version.private_header_len();
                if input.len() < len {
                    return Ok(Step::Need(len));
                }
                let count = match self.version {
                    LvxVersion::V1_1 => {
                        self.frame_duration_ms = Some(u32::from_le_bytes([input[0], input[1], input[2], input[3]]));
                        input[4]
                    }
                    LvxVersion::V1_0 => input[0],
                };
                Ok(self.skip(len, State::Devices { count }))
            }
            State::Devices { count } => {
                let each = self.version.device_info_len();
                let len = each * usize::from(count);
                if input.len() < len {
                    return Ok(Step::Need(len));
                }
                let devices = input
                    .get(..len)
                    .unwrap_or(&[])
                    .chunks_exact(each)
                    .map(|b| LvxDevice::decode(b, self.version))
                    .collect();
                self.header = Some(LvxHeader {
                    version: self.version,
                    version_bytes: self.version_bytes,
                    frame_duration_ms: self.frame_duration_ms,
                    devices,
                });
                // With no devices the header is complete without consuming anything.
                self.offset += len as u64;
                self.state = State::FrameHeader;
                Ok(Step::Skip(len))
            }
            State::FrameHeader => {
                let len = self.version.frame_header_len();
                if input.len() < len {
                    return Ok(Step::Need(len));
                }
                let u64_at = |i: usize| {
                    u64::from_le_bytes([
                        input[i],
                        input[i + 1],
                        input[i + 2],
                        input[i + 3],
                        input[i + 4],
                        input[i + 5],
                        input[i + 6],
                        input[i + 7],
                    ])
                };
                let (current, next) = (u64_at(0), u64_at(8));
                let frame_error = |reason| LivoxError::LvxFrame { offset: self.offset, current, next, reason };
                if current != self.offset {
                    return Err(frame_error("current_offset is not where the frame is"));
                }
                if next < self.offset + len as u64 {
                    return Err(frame_error("next_offset points inside the frame header"));
                }
                stats.lvx_frames += 1;
                let frame_end = next;
                Ok(self.skip(len, State::Packages { frame_end }))
            }
            State::Packages { frame_end } => {
                if self.offset == frame_end {
                    self.state = State::FrameHeader;
                    return Ok(Step::Skip(0));
                }
                let head = 1 + DATA_HEADER_LEN;
                if input.len() < head {
                    return Ok(Step::Need(head));
                }
                let data_type = input[10];
                let Some(packet_len) = packet_len_for(data_type) else {
                    return Err(LivoxError::LvxDataType { offset: self.offset, data_type });
                };
                let len = 1 + packet_len;
                if self.offset + len as u64 > frame_end {
                    return Err(self.malformed("package runs past the frame's next_offset"));
                }
                if input.len() < len {
                    return Ok(Step::Need(len));
                }
                self.offset += len as u64;
                Ok(Step::Package { consumed: len, device_index: input[0], data: 1..len })
            }
        }
    }
}

/// Writes .lvx v1.1 files from data packets (the bytes a device sends over UDP).
pub struct LvxWriter<W: Write> {
    out: W,
    offset: u64,
    frame_duration_ns: u64,
    devices: Vec<u8>,
    frame: Vec<u8>,
    frame_start: Option<Stamp>,
    frame_index: u64,
    packets: u64,
}

impl LvxWriter<BufWriter<File>> {
    /// Creates `path` and writes the headers. `frame_duration_ms` is usually 50.
    pub fn create(path: &Path, frame_duration_ms: u32, devices: &[LvxDevice]) -> Result<Self> {
        let file = File::create(path).map_err(|e| LivoxError::io(format!("creating {}", path.display()), e))?;
        Self::new(BufWriter::new(file), frame_duration_ms, devices)
    }
}

impl<W: Write> LvxWriter<W> {
    pub fn new(mut out: W, frame_duration_ms: u32, devices: &[LvxDevice]) -> Result<Self> {
        if frame_duration_ms == 0 {
            return Err(LivoxError::BadValue { field: "lvx frame duration", value: 0 });
        }
        let count = u8::try_from(devices.len())
            .map_err(|_| LivoxError::BadValue { field: "lvx device count", value: devices.len() as u32 })?;
        let mut head = Vec::with_capacity(PUBLIC_HEADER_LEN + 5 + devices.len() * DEVICE_INFO_LEN_V1_1);
        head.extend_from_slice(SIGNATURE);
        head.resize(16, 0);
        head.extend_from_slice(&[1, 1, 0, 0]);
        head.extend_from_slice(&MAGIC.to_le_bytes());
        head.extend_from_slice(&frame_duration_ms.to_le_bytes());
        head.push(count);
        for d in devices {
            d.encode_v1_1(&mut head);
        }
        out.write_all(&head).map_err(|e| LivoxError::io("writing lvx header", e))?;
        Ok(Self {
            out,
            offset: head.len() as u64,
            frame_duration_ns: u64::from(frame_duration_ms) * 1_000_000,
            devices: devices.iter().map(|d| d.device_index).collect(),
            frame: Vec::new(),
            frame_start: None,
            frame_index: 0,
            packets: 0,
        })
    }

    /// Adds one data packet (18-byte header and points, exactly as long as its data_type says)
    /// from the device with `device_index`. A packet stamped `frame_duration` or more away from the
    /// first packet of the current frame (or on another clock) starts a new frame.
    pub fn write_packet(&mut self, device_index: u8, packet: &[u8]) -> Result<()> {
        if !self.devices.contains(&device_index) {
            return Err(LivoxError::LvxUnknownDevice(device_index));
        }
        let header = crate::data::DataHeader::decode(packet)?;
        let need = header.data_type.packet_len();
        if packet.len() != need {
            return Err(LivoxError::PacketLength { data_type: header.data_type as u8, need, have: packet.len() });
        }
        let stamp = header.timestamp;
        let cut = match self.frame_start {
            None => false,
            Some(start) => {
                start.clock != stamp.clock
                    || start.ns.abs_diff(stamp.ns) >= self.frame_duration_ns
                    || self.frame.len() + 1 + packet.len() > MAX_WRITER_FRAME_BYTES
            }
        };
        if cut {
            self.flush_frame()?;
        }
        if self.frame_start.is_none() {
            self.frame_start = Some(stamp);
        }
        self.frame.push(device_index);
        self.frame.extend_from_slice(packet);
        self.packets += 1;
        Ok(())
    }

    fn flush_frame(&mut self) -> Result<()> {
        if self.frame_start.is_none() {
            return Ok(());
        }
        let current = self.offset;
        let next = current + (FRAME_HEADER_LEN_V1_1 + self.frame.len()) as u64;
        let mut header = [0u8; FRAME_HEADER_LEN_V1_1];
        header[..8].copy_from_slice(&current.to_le_bytes());
        header[8..16].copy_from_slice(&next.to_le_bytes());
        header[16..].copy_from_slice(&self.frame_index.to_le_bytes());
        self.out.write_all(&header).map_err(|e| LivoxError::io("writing lvx frame", e))?;
        self.out.write_all(&self.frame).map_err(|e| LivoxError::io("writing lvx frame", e))?;
        self.offset = next;
        self.frame_index += 1;
        self.frame.clear();
        self.frame_start = None;
        Ok(())
    }

    /// Frames written so far (the one being filled not included).
    pub fn frames(&self) -> u64 {
        self.frame_index
    }

    pub fn packets(&self) -> u64 {
        self.packets
    }

    /// Writes the last frame, flushes, and hands back the writer.
    pub fn finish(mut self) -> Result<W> {
        self.flush_frame()?;
        self.out.flush().map_err(|e| LivoxError::io("flushing lvx", e))?;
        Ok(self.out)
    }
}
