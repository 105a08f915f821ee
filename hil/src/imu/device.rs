//! The sans-IO mock IMU: time in, bytes out; host bytes in, replies and settings changes.
//!
//! MIP: fields stream at base rate / decimation per field (the IMU message format), commands in
//! sets 0x01/0x0C get an ACK or NACK (unknown commands: NACK 0x01), a rate change changes the
//! rate, a baud change is ACKed at the old rate and then paces the output. WitMotion: a cycle of
//! frames (register 0x02 chooses which) at the rate of register 0x03; writes are honoured
//! within 10 s of an unlock, as on the device. Output is paced by the baud rate: a sample that
//! would wait more than 50 ms for the line is lost (an overrun), as on a device whose output
//! outgrows its UART.

use crate::imu::faults::{ImuFaultConfig, ImuFaultStats, ImuFaults, SampleFate};
use crate::imu::sensor::SensorModel;
use crate::imu::source::{ImuSource, Motion};
use crate::rng::SplitMix64;
use serde::Serialize;
use starc_imu::mip::command::{
    ack_code_name, FormatEntry, Function, MipCommand, MipReply, ReplyData, NACK_BAD_PARAMETER, NACK_UNKNOWN_COMMAND,
};
use starc_imu::mip::data::{FIELD_ACCEL, FIELD_EULER, FIELD_GPS_TIME, FIELD_GYRO, FIELD_MAG, FIELD_QUATERNION};
use starc_imu::mip::packet::{Packet, CHECKSUM_LEN, HEADER_LEN, MAX_PACKET_LEN, SYNC1, SYNC2};
use starc_imu::mip::{GpsTime, MipData};
use starc_imu::timing::LatencyModel;
use starc_imu::witmotion::config::{self as witcfg, ConfigDecoder, ConfigWrite};
use starc_imu::witmotion::frame::{self as witframe, WitFrame, WitTime};
use starc_imu::{ImuError, Protocol, STANDARD_GRAVITY_M_S2};
use tracing::debug;

const NS_PER_S: u64 = 1_000_000_000;
/// A sample that would wait longer than this for the line is lost.
const MAX_LINE_BACKLOG_NS: u64 = 50_000_000;
/// A WitMotion unlock lasts this long.
const WIT_UNLOCK_NS: u64 = 10 * NS_PER_S;
/// GPS time = Unix time - 315 964 800 s + 18 leap seconds.
const GPS_MINUS_UNIX_S: i64 = 18 - 315_964_800;
/// Bauds a MIP device accepts.
pub const MIP_BAUDS: [u32; 8] = [9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 921_600];
/// 0x80 fields the mock can stream.
pub const MIP_FIELDS: [u8; 6] = [FIELD_ACCEL, FIELD_GYRO, FIELD_MAG, FIELD_QUATERNION, FIELD_EULER, FIELD_GPS_TIME];

/// Settings of the sans-IO device.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceConfig {
    pub protocol: Protocol,
    /// Initial output rate.
    pub rate_hz: f64,
    pub baud: u32,
    /// MIP IMU base rate; decimations divide it.
    pub mip_base_rate_hz: u16,
    /// MIP 0x80 fields streamed (descriptors).
    pub mip_fields: Vec<u8>,
    /// WitMotion frame types output (0x50..=0x5F).
    pub wit_frames: Vec<u8>,
    /// Unix ns at device time 0 (for GPS time and the WitMotion clock).
    pub epoch_ns: u64,
    pub sensor: SensorModel,
    pub faults: ImuFaultConfig,
    pub seed: u64,
}

impl DeviceConfig {
    pub fn new(protocol: Protocol) -> Self {
        Self {
            protocol,
            rate_hz: 100.0,
            baud: 115_200,
            mip_base_rate_hz: 1000,
            mip_fields: vec![FIELD_ACCEL, FIELD_GYRO, FIELD_GPS_TIME],
            wit_frames: vec![witframe::TYPE_ACCEL, witframe::TYPE_GYRO, witframe::TYPE_ANGLE],
            epoch_ns: 1_700_000_000 * NS_PER_S,
            sensor: SensorModel::default(),
            faults: ImuFaultConfig::default(),
            seed: 0,
        }
    }
}

/// What the device did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DeviceStats {
    /// Samples due (sent, dropped by faults, or lost to overruns).
    pub samples: u64,
    /// Samples put on the line (corrupted ones included).
    pub sent: u64,
    /// Samples lost because the line was too slow for them.
    pub overruns: u64,
    pub bytes: u64,
    /// MIP commands decoded.
    pub commands: u64,
    pub acks: u64,
    pub nacks: u64,
    /// WitMotion register writes decoded (unlocks included), and those refused while locked.
    pub config_writes: u64,
    pub locked_writes: u64,
    pub saves: u64,
    pub rate_changes: u64,
    pub baud_changes: u64,
    /// Bytes from the host that were no command.
    pub host_bytes_skipped: u64,
    pub faults: ImuFaultStats,
}

/// The mock device.
pub struct ImuDevice<S: ImuSource> {
    config: DeviceConfig,
    source: S,
    noise: SplitMix64,
    faults: ImuFaults,
    silence_at_ns: Option<u64>,
    baud: u32,
    line_busy_until_ns: u64,
    stats: DeviceStats,
    // MIP
    streaming: bool,
    format: Vec<FormatEntry>,
    tick: u64,
    command_buf: Vec<u8>,
    // WitMotion
    wit_rate_hz: Option<f64>,
    wit_mask: u16,
    wit_next_ns: u64,
    unlocked_until_ns: Option<u64>,
    wit_config: ConfigDecoder,
    writes: Vec<ConfigWrite>,
}

impl<S: ImuSource> std::fmt::Debug for ImuDevice<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImuDevice").field("config", &self.config).field("stats", &self.stats).finish()
    }
}

fn mip_decimation(base: u16, rate_hz: f64) -> u16 {
    (f64::from(base) / rate_hz).round().clamp(1.0, f64::from(u16::MAX)) as u16
}

impl<S: ImuSource> ImuDevice<S> {
    pub fn new(config: DeviceConfig, source: S) -> Self {
        let decimation = mip_decimation(config.mip_base_rate_hz, config.rate_hz);
        let format = config.mip_fields.iter().map(|&descriptor| FormatEntry { descriptor, decimation }).collect();
        let wit_mask = ConfigWrite::output_content(&config.wit_frames).value;
        Self {
            noise: SplitMix64::new(config.seed ^ 0x5E45_0A15_E000_0001),
            faults: ImuFaults::new(&config.faults, config.seed),
            silence_at_ns: config.faults.silence_at_ns(),
            baud: config.baud,
            line_busy_until_ns: 0,
            stats: DeviceStats::default(),
            streaming: true,
            format,
            tick: 0,
            command_buf: Vec::with_capacity(2 * MAX_PACKET_LEN),
            wit_rate_hz: Some(config.rate_hz),
            wit_mask,
            wit_next_ns: 0,
            unlocked_until_ns: None,
            wit_config: ConfigDecoder::new(),
            writes: Vec::new(),
            source,
            config,
        }
    }

    pub fn stats(&self) -> DeviceStats {
        let mut s = self.stats;
        s.faults = self.faults.stats();
        s
    }

    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// The current output rate (samples per second), 0 when idle or silent.
    pub fn rate_hz(&self) -> f64 {
        match self.config.protocol {
            Protocol::Mip if self.streaming => self
                .format
                .iter()
                .map(|e| f64::from(self.config.mip_base_rate_hz) / f64::from(e.decimation.max(1)))
                .fold(0.0, f64::max),
            Protocol::Mip => 0.0,
            Protocol::WitMotion => self.wit_rate_hz.unwrap_or(0.0),
        }
    }

    fn silent(&self, now_ns: u64) -> bool {
        self.silence_at_ns.is_some_and(|s| now_ns >= s)
    }

    /// Appends every sample due at or before `now_ns` (device time) to `out`.
    pub fn poll(&mut self, now_ns: u64, out: &mut Vec<u8>) {
        match self.config.protocol {
            Protocol::Mip => self.poll_mip(now_ns, out),
            Protocol::WitMotion => self.poll_wit(now_ns, out),
        }
    }

    fn poll_mip(&mut self, now_ns: u64, out: &mut Vec<u8>) {
        let base = u64::from(self.config.mip_base_rate_hz.max(1));
        loop {
            let t = self.tick * NS_PER_S / base;
            if t > now_ns {
                return;
            }
            let k = self.tick;
            self.tick += 1;
            if !self.streaming || self.silent(t) {
                continue;
            }
            let due: Vec<u8> = self
                .format
                .iter()
                .filter(|e| e.decimation > 0 && k.is_multiple_of(u64::from(e.decimation)))
                .map(|e| e.descriptor)
                .collect();
            if due.is_empty() {
                continue;
            }
            let m = self.measure(t);
            let data = self.mip_data(&due, &m, t);
            let mut bytes = Vec::with_capacity(64);
            if data.encode(&mut bytes).is_err() {
                continue;
            }
            self.send_sample(t, vec![bytes], out);
        }
    }

    fn poll_wit(&mut self, now_ns: u64, out: &mut Vec<u8>) {
        let Some(rate) = self.wit_rate_hz.filter(|r| *r > 0.0) else {
            self.wit_next_ns = now_ns;
            return;
        };
        let period = (1e9 / rate).round() as u64;
        while self.wit_next_ns <= now_ns {
            let t = self.wit_next_ns;
            self.wit_next_ns += period.max(1);
            if self.silent(t) {
                continue;
            }
            let m = self.measure(t);
            let frames = self.wit_frames(&m, t);
            if frames.is_empty() {
                continue;
            }
            self.send_sample(t, frames, out);
        }
    }

    fn measure(&mut self, t: u64) -> Motion {
        let truth = self.source.motion(t);
        self.config.sensor.measure(&truth, &mut self.noise)
    }

    fn mip_data(&self, due: &[u8], m: &Motion, t: u64) -> MipData {
        let mut d = MipData::default();
        for &f in due {
            match f {
                FIELD_ACCEL => d.accel_g = Some(m.accel_m_s2.map(|a| (a / STANDARD_GRAVITY_M_S2) as f32)),
                FIELD_GYRO => d.gyro_rad_s = Some(m.gyro_rad_s.map(|w| w as f32)),
                FIELD_MAG => d.mag_gauss = Some([0.21, 0.0, 0.43]),
                FIELD_QUATERNION => d.quaternion = Some(m.orientation_wxyz.map(|q| q as f32)),
                FIELD_EULER => d.euler_rad = Some(euler_rad(m.orientation_wxyz).map(|e| e as f32)),
                FIELD_GPS_TIME => d.gps_time = Some(self.gps_time(t)),
                _ => {}
            }
        }
        d
    }

    fn gps_time(&self, t: u64) -> GpsTime {
        let unix_ns = self.config.epoch_ns.saturating_add(t);
        let gps_ns = (unix_ns as i128 + i128::from(GPS_MINUS_UNIX_S) * i128::from(NS_PER_S)).max(0) as u64;
        let week_ns = 604_800 * NS_PER_S;
        GpsTime {
            tow_s: (gps_ns % week_ns) as f64 / 1e9,
            week: (gps_ns / week_ns).min(u64::from(u16::MAX)) as u16,
            flags: 0x7,
        }
    }

    fn wit_frames(&self, m: &Motion, t: u64) -> Vec<Vec<u8>> {
        let mut frames = Vec::with_capacity(6);
        for k in 0..16u8 {
            if self.wit_mask & (1 << k) == 0 {
                continue;
            }
            let ty = witframe::TYPE_FIRST + k;
            let frame = match ty {
                witframe::TYPE_TIME => {
                    WitFrame::new(ty, WitTime::from_unix_ns(self.config.epoch_ns.saturating_add(t)).to_data())
                }
                witframe::TYPE_ACCEL => WitFrame::from_values(ty, witframe::accel_raw(m.accel_m_s2, 25.0)),
                witframe::TYPE_GYRO => WitFrame::from_values(ty, witframe::gyro_raw(m.gyro_rad_s, 25.0)),
                witframe::TYPE_ANGLE => {
                    WitFrame::from_values(ty, witframe::angle_raw(euler_rad(m.orientation_wxyz), 1))
                }
                witframe::TYPE_MAG => WitFrame::from_values(ty, [1200, -300, 4100, 2500]),
                witframe::TYPE_QUATERNION => WitFrame::from_values(ty, witframe::quaternion_raw(m.orientation_wxyz)),
                _ => continue,
            };
            frames.push(frame.encode().to_vec());
        }
        frames
    }

    /// Applies the faults and the line's pace to one sample's frames.
    fn send_sample(&mut self, t: u64, mut frames: Vec<Vec<u8>>, out: &mut Vec<u8>) {
        self.stats.samples += 1;
        let SampleFate { garbage, drop, corrupt } = self.faults.next(frames.len());
        let len: usize = garbage.len() + frames.iter().map(Vec::len).sum::<usize>();
        let line = LatencyModel::new(self.baud, 0);
        let start = self.line_busy_until_ns.max(t);
        if start - t > MAX_LINE_BACKLOG_NS {
            self.stats.overruns += 1;
            return;
        }
        if drop {
            // Nothing reaches the line but the garbage.
            out.extend_from_slice(&garbage);
            self.stats.bytes += garbage.len() as u64;
            self.line_busy_until_ns = start + line.transfer_ns(garbage.len());
            return;
        }
        if let Some((i, mask)) = corrupt {
            if let Some(last) = frames.get_mut(i).and_then(|f| f.last_mut()) {
                *last ^= mask;
            }
        }
        out.extend_from_slice(&garbage);
        for f in &frames {
            out.extend_from_slice(f);
        }
        self.line_busy_until_ns = start + line.transfer_ns(len);
        self.stats.sent += 1;
        self.stats.bytes += len as u64;
    }

    /// Takes bytes from the host at `now_ns`; appends any replies to `out`.
    pub fn receive(&mut self, bytes: &[u8], now_ns: u64, out: &mut Vec<u8>) {
        if self.silent(now_ns) {
            return;
        }
        match self.config.protocol {
            Protocol::Mip => self.receive_mip(bytes, out),
            Protocol::WitMotion => self.receive_wit(bytes, now_ns),
        }
    }

    fn receive_mip(&mut self, bytes: &[u8], out: &mut Vec<u8>) {
        for chunk in bytes.chunks(MAX_PACKET_LEN) {
            let mut buf = std::mem::take(&mut self.command_buf);
            buf.extend_from_slice(chunk);
            let used = self.scan_commands(&buf, out);
            buf.drain(..used.min(buf.len()));
            self.command_buf = buf;
        }
    }

    /// Carries out the whole command packets at the front of `buf`; returns the bytes used.
    fn scan_commands(&mut self, buf: &[u8], out: &mut Vec<u8>) -> usize {
        let mut pos = 0;
        while let Some(rest) = buf.get(pos..) {
            let Some(i) = rest.windows(2).position(|w| w == [SYNC1, SYNC2]) else {
                let keep = usize::from(rest.last() == Some(&SYNC1));
                self.stats.host_bytes_skipped += (rest.len() - keep) as u64;
                return pos + rest.len() - keep;
            };
            self.stats.host_bytes_skipped += i as u64;
            pos += i;
            let rest = rest.get(i..).unwrap_or_default();
            let Some(&len) = rest.get(3) else { return pos };
            if rest.len() < HEADER_LEN + usize::from(len) + CHECKSUM_LEN {
                return pos;
            }
            match Packet::parse(rest) {
                Ok((packet, n)) => {
                    if let Some(r) = self.command(&packet) {
                        let before = out.len();
                        if r.encode(out).is_ok() {
                            self.stats.bytes += (out.len() - before) as u64;
                        }
                    }
                    pos += n;
                }
                Err(_) => {
                    self.stats.host_bytes_skipped += 1;
                    pos += 1;
                }
            }
        }
        pos
    }

    /// Carries out one command packet and builds its reply (none for other descriptor sets).
    fn command(&mut self, packet: &Packet<'_>) -> Option<MipReply> {
        let set = packet.descriptor_set;
        if set != 0x01 && set != 0x0C {
            return None;
        }
        let first = packet.fields().next().and_then(|f| f.ok()).map(|f| f.descriptor).unwrap_or(0);
        let reply = match MipCommand::decode(packet) {
            Ok(c) => {
                self.stats.commands += 1;
                self.apply(c)
            }
            Err(ImuError::UnknownCommand { set, descriptor }) => MipReply::nack(set, descriptor, NACK_UNKNOWN_COMMAND),
            Err(_) => MipReply::nack(set, first, NACK_BAD_PARAMETER),
        };
        debug!(set, command = reply.command, code = reply.code, name = ack_code_name(reply.code), "mock MIP reply");
        if reply.is_ack() {
            self.stats.acks += 1;
        } else {
            self.stats.nacks += 1;
        }
        Some(reply)
    }

    fn apply(&mut self, c: MipCommand) -> MipReply {
        let (set, d) = (c.descriptor_set(), c.descriptor());
        let ack = |data| MipReply::ack(set, d, data);
        match c {
            MipCommand::Ping => ack(None),
            MipCommand::SetIdle => {
                self.streaming = false;
                ack(None)
            }
            MipCommand::Resume => {
                self.streaming = true;
                ack(None)
            }
            MipCommand::GetImuBaseRate => ack(Some(ReplyData::ImuBaseRate(self.config.mip_base_rate_hz))),
            MipCommand::ImuMessageFormat(f) => match f {
                Function::Apply(entries) => {
                    if entries.iter().any(|e| e.decimation == 0 || !MIP_FIELDS.contains(&e.descriptor)) {
                        return MipReply::nack(set, d, NACK_BAD_PARAMETER);
                    }
                    self.format = entries;
                    self.stats.rate_changes += 1;
                    ack(None)
                }
                Function::Read => ack(Some(ReplyData::ImuMessageFormat(self.format.clone()))),
                Function::Default => {
                    let dec = mip_decimation(self.config.mip_base_rate_hz, self.config.rate_hz);
                    self.format = self
                        .config
                        .mip_fields
                        .iter()
                        .map(|&descriptor| FormatEntry { descriptor, decimation: dec })
                        .collect();
                    ack(None)
                }
                Function::Save | Function::Load => ack(None),
            },
            MipCommand::UartBaudRate(f) => match f {
                Function::Apply(baud) if MIP_BAUDS.contains(&baud) => {
                    // The ACK leaves at the old rate; the output after it goes at the new one.
                    self.baud = baud;
                    self.stats.baud_changes += 1;
                    ack(None)
                }
                Function::Apply(_) => MipReply::nack(set, d, NACK_BAD_PARAMETER),
                Function::Read => ack(Some(ReplyData::UartBaudRate(self.baud))),
                Function::Default => {
                    self.baud = 115_200;
                    ack(None)
                }
                Function::Save | Function::Load => ack(None),
            },
        }
    }

    fn receive_wit(&mut self, bytes: &[u8], now_ns: u64) {
        let skipped = self.wit_config.skipped_bytes;
        self.wit_config.push(bytes, &mut self.writes);
        self.stats.host_bytes_skipped += self.wit_config.skipped_bytes - skipped;
        let writes = std::mem::take(&mut self.writes);
        for w in &writes {
            self.stats.config_writes += 1;
            if w.register == witcfg::REG_UNLOCK {
                if w.value == witcfg::UNLOCK_KEY {
                    self.unlocked_until_ns = Some(now_ns + WIT_UNLOCK_NS);
                }
                continue;
            }
            if self.unlocked_until_ns.is_none_or(|u| now_ns > u) {
                self.stats.locked_writes += 1;
                continue;
            }
            match w.register {
                witcfg::REG_SAVE => self.stats.saves += 1,
                witcfg::REG_OUTPUT_CONTENT => self.wit_mask = w.value,
                witcfg::REG_RATE => {
                    if let Some(hz) = witcfg::rate_hz(w.value) {
                        self.wit_rate_hz = Some(hz);
                        self.wit_next_ns = now_ns;
                        self.stats.rate_changes += 1;
                    } else if w.value == witcfg::RATE_NO_OUTPUT {
                        self.wit_rate_hz = None;
                        self.stats.rate_changes += 1;
                    }
                }
                witcfg::REG_BAUD => {
                    if let Some(b) = witcfg::baud(w.value) {
                        self.baud = b;
                        self.stats.baud_changes += 1;
                    }
                }
                _ => {}
            }
        }
        self.writes = writes;
        self.writes.clear();
    }
}

/// Roll, pitch, yaw (rad) of a unit quaternion (w, x, y, z), aerospace sequence.
pub fn euler_rad(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    [roll, pitch, yaw]
}
