//! Data packets (UDP, LiDAR to host): the 18-byte header, points of data types 0-8, and IMU.

use super::status::StatusWord;
use super::timestamp;
use crate::error::{need, LivoxError, Result};
use serde::Serialize;
use starc_time::Stamp;

pub const DATA_VERSION: u8 = 5;
pub const HEADER_LEN: usize = 18;
/// Standard gravity, used to turn the IMU's g into m/s^2.
pub const STANDARD_GRAVITY_M_S2: f32 = 9.806_65;
/// Spacing of firings on 240 kHz devices (Avia, Horizon, Tele-15).
pub const FIRING_INTERVAL_NS: u32 = 4167;
/// Spacing of points on 100 kHz Mid devices (the only users of data types 0 and 1).
pub const MID_FIRING_INTERVAL_NS: u32 = 10_000;
/// Laser lines of the Avia; line of firing k is k % 6.
pub const AVIA_LINES: u8 = 6;

/// The nine data types of SDK1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DataType {
    Cartesian = 0,
    Spherical = 1,
    ExtendedCartesian = 2,
    ExtendedSpherical = 3,
    DualCartesian = 4,
    DualSpherical = 5,
    Imu = 6,
    TripleCartesian = 7,
    TripleSpherical = 8,
}

impl DataType {
    pub const ALL: [DataType; 9] = [
        Self::Cartesian,
        Self::Spherical,
        Self::ExtendedCartesian,
        Self::ExtendedSpherical,
        Self::DualCartesian,
        Self::DualSpherical,
        Self::Imu,
        Self::TripleCartesian,
        Self::TripleSpherical,
    ];

    pub fn from_u8(v: u8) -> Result<Self> {
        Self::ALL.get(usize::from(v)).copied().ok_or(LivoxError::BadDataType(v))
    }

    /// Bytes of one firing (all its returns).
    pub fn firing_size(self) -> usize {
        match self {
            Self::Cartesian => 13,
            Self::Spherical => 9,
            Self::ExtendedCartesian => 14,
            Self::ExtendedSpherical => 10,
            Self::DualCartesian => 28,
            Self::DualSpherical => 16,
            Self::Imu => 24,
            Self::TripleCartesian => 42,
            Self::TripleSpherical => 22,
        }
    }

    /// Firings per packet (the "points/packet" column of the protocol table).
    pub fn firings_per_packet(self) -> usize {
        match self {
            Self::Cartesian | Self::Spherical => 100,
            Self::ExtendedCartesian | Self::ExtendedSpherical => 96,
            Self::DualCartesian | Self::DualSpherical => 48,
            Self::Imu => 1,
            Self::TripleCartesian | Self::TripleSpherical => 30,
        }
    }

    /// Returns per firing.
    pub fn echoes(self) -> usize {
        match self {
            Self::DualCartesian | Self::DualSpherical => 2,
            Self::TripleCartesian | Self::TripleSpherical => 3,
            _ => 1,
        }
    }

    pub fn packet_len(self) -> usize {
        HEADER_LEN + self.firing_size() * self.firings_per_packet()
    }

    pub fn returns_per_packet(self) -> usize {
        if self == Self::Imu {
            0
        } else {
            self.firings_per_packet() * self.echoes()
        }
    }

    pub fn is_spherical(self) -> bool {
        matches!(self, Self::Spherical | Self::ExtendedSpherical | Self::DualSpherical | Self::TripleSpherical)
    }

    pub fn firing_interval_ns(self) -> u32 {
        match self {
            Self::Cartesian | Self::Spherical => MID_FIRING_INTERVAL_NS,
            _ => FIRING_INTERVAL_NS,
        }
    }

    /// Nominal time between consecutive packets of this type.
    pub fn packet_interval_ns(self) -> u64 {
        match self {
            Self::Imu => 5_000_000,
            _ => self.firings_per_packet() as u64 * u64::from(self.firing_interval_ns()),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Cartesian => "cartesian",
            Self::Spherical => "spherical",
            Self::ExtendedCartesian => "extended_cartesian",
            Self::ExtendedSpherical => "extended_spherical",
            Self::DualCartesian => "dual_cartesian",
            Self::DualSpherical => "dual_spherical",
            Self::Imu => "imu",
            Self::TripleCartesian => "triple_cartesian",
            Self::TripleSpherical => "triple_spherical",
        }
    }
}

/// Packet length for a data_type byte, if known (used by the .lvx reader to frame packages).
pub fn packet_len_for(data_type: u8) -> Option<usize> {
    DataType::from_u8(data_type).ok().map(DataType::packet_len)
}

/// The decoded 18-byte header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct DataHeader {
    pub version: u8,
    pub slot: u8,
    pub lidar_id: u8,
    pub status: StatusWord,
    pub data_type: DataType,
    /// The first firing's time on the clock named by `timestamp_type`.
    pub timestamp: Stamp,
}

impl DataHeader {
    /// The wire's timestamp_type (0 none, 1 PTP, 3 GPS/UTC, 4 PPS), from the stamp's clock.
    pub fn timestamp_type(&self) -> u8 {
        match self.timestamp.clock {
            starc_time::Clock::Ptp => 1,
            starc_time::Clock::Gps => 3,
            starc_time::Clock::Pps => 4,
            starc_time::Clock::Device | starc_time::Clock::Host => 0,
        }
    }

    pub fn decode(bytes: &[u8]) -> Result<Self> {
        need("data packet header", bytes, HEADER_LEN)?;
        if bytes[0] != DATA_VERSION {
            return Err(LivoxError::BadDataVersion(bytes[0]));
        }
        let mut raw_ts = [0u8; 8];
        raw_ts.copy_from_slice(&bytes[10..18]);
        Ok(Self {
            version: bytes[0],
            slot: bytes[1],
            lidar_id: bytes[2],
            status: StatusWord::from_raw(u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]])),
            data_type: DataType::from_u8(bytes[9])?,
            timestamp: timestamp::decode(bytes[8], raw_ts)?,
        })
    }

    pub fn encode_into(&self, out: &mut Vec<u8>) -> Result<()> {
        let (ts_type, raw_ts) = timestamp::encode(self.timestamp)?;
        out.extend_from_slice(&[self.version, self.slot, self.lidar_id, 0]);
        out.extend_from_slice(&self.status.raw.to_le_bytes());
        out.push(ts_type);
        out.push(self.data_type as u8);
        out.extend_from_slice(&raw_ts);
        Ok(())
    }
}

/// One return, decoded. Coordinates in metres in the sensor frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Point {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    pub reflectivity: u8,
    /// Livox tag: bits 5-4 return number, 3-2 intensity noise, 1-0 spatial noise confidence.
    pub tag: u8,
    /// Laser line (0-5 on the Avia).
    pub line: u8,
    /// Which return of its firing (0 first).
    pub echo: u8,
    /// Firing time after the packet time stamp.
    pub offset_ns: u32,
}

/// How many returns a packet carried and how many of them were empty (no target).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ReturnCounts {
    pub returns: u32,
    pub empty: u32,
}

/// A length-checked data packet borrowing its body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DataPacket<'a> {
    pub header: DataHeader,
    body: &'a [u8],
}

/// An IMU sample from a data_type 6 packet.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImuSample {
    pub gyro_rad_s: [f32; 3],
    /// Acceleration as the device sends it, in g.
    pub acc_g: [f32; 3],
}

impl ImuSample {
    /// Whether every rate and acceleration is a finite number.
    pub fn is_finite(&self) -> bool {
        self.gyro_rad_s.iter().chain(self.acc_g.iter()).all(|v| v.is_finite())
    }

    pub fn acc_m_s2(&self) -> [f32; 3] {
        self.acc_g.map(|a| a * STANDARD_GRAVITY_M_S2)
    }
}

#[inline(always)]
fn le_i32(b: &[u8], i: usize) -> i32 {
    i32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

#[inline(always)]
fn le_u32(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

#[inline(always)]
fn le_u16(b: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([b[i], b[i + 1]])
}

#[inline(always)]
fn le_f32(b: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Spherical (depth mm, theta from zenith and phi in 0.01 deg) to metres.
#[inline]
fn spherical_to_xyz(depth_mm: u32, theta_cdeg: u16, phi_cdeg: u16) -> (f32, f32, f32) {
    let d = depth_mm as f32 * 1e-3;
    let theta = (f32::from(theta_cdeg) * 0.01).to_radians();
    let phi = (f32::from(phi_cdeg) * 0.01).to_radians();
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    (d * st * cp, d * st * sp, d * ct)
}

impl<'a> DataPacket<'a> {
    /// Checks the header and that the datagram is exactly as long as its data type says.
    pub fn parse(bytes: &'a [u8]) -> Result<Self> {
        let header = DataHeader::decode(bytes)?;
        let need_len = header.data_type.packet_len();
        if bytes.len() != need_len {
            return Err(LivoxError::PacketLength {
                data_type: header.data_type as u8,
                need: need_len,
                have: bytes.len(),
            });
        }
        Ok(Self { header, body: &bytes[HEADER_LEN..] })
    }

    pub fn is_imu(&self) -> bool {
        self.header.data_type == DataType::Imu
    }

    /// The IMU sample of an IMU packet; `None` for point packets and for samples holding a NaN
    /// or an infinity (the wire carries raw f32s, and one NaN poisons the LIO's state): see
    /// [`DataPacket::imu_raw`] for the values as sent.
    pub fn imu(&self) -> Option<ImuSample> {
        self.imu_raw().filter(ImuSample::is_finite)
    }

    /// The IMU sample as sent, non-finite values included.
    pub fn imu_raw(&self) -> Option<ImuSample> {
        if !self.is_imu() {
            return None;
        }
        let b = self.body;
        Some(ImuSample {
            gyro_rad_s: [le_f32(b, 0), le_f32(b, 4), le_f32(b, 8)],
            acc_g: [le_f32(b, 12), le_f32(b, 16), le_f32(b, 20)],
        })
    }

    /// Appends every non-empty return to `out` with its firing time and line; empty returns are
    /// counted, never stored.
    pub fn decode_points(&self, out: &mut Vec<Point>) -> ReturnCounts {
        let dt = self.header.data_type;
        if dt == DataType::Imu {
            return ReturnCounts::default();
        }
        let before = out.len();
        out.reserve(dt.returns_per_packet());
        let interval = dt.firing_interval_ns();
        let body = self.body;
        // One loop per data type, with the firing layout known at compile time.
        let empty = match dt {
            DataType::Cartesian => decode_cartesian::<13, 1, false>(body, interval, out),
            DataType::ExtendedCartesian => decode_cartesian::<14, 1, true>(body, interval, out),
            DataType::DualCartesian => decode_cartesian::<28, 2, true>(body, interval, out),
            DataType::TripleCartesian => decode_cartesian::<42, 3, true>(body, interval, out),
            DataType::Spherical => decode_spherical::<9, false>(body, interval, out),
            DataType::ExtendedSpherical => decode_spherical::<10, true>(body, interval, out),
            DataType::DualSpherical => decode_multi_spherical::<16, 2>(body, interval, out),
            DataType::TripleSpherical => decode_multi_spherical::<22, 3>(body, interval, out),
            DataType::Imu => 0,
        };
        ReturnCounts { returns: (out.len() - before) as u32 + empty, empty }
    }

    /// Counts returns without decoding coordinates (fast path for `starc inspect`).
    pub fn count_returns(&self) -> ReturnCounts {
        let dt = self.header.data_type;
        if dt == DataType::Imu {
            return ReturnCounts::default();
        }
        let mut empty = 0u32;
        for f in self.body.chunks_exact(dt.firing_size()) {
            for e in 0..dt.echoes() {
                let is_empty = match dt {
                    DataType::Cartesian | DataType::ExtendedCartesian => f[..12].iter().all(|&b| b == 0),
                    DataType::DualCartesian | DataType::TripleCartesian => {
                        f[e * 14..e * 14 + 12].iter().all(|&b| b == 0)
                    }
                    DataType::Spherical | DataType::ExtendedSpherical => le_u32(f, 0) == 0,
                    _ => le_u32(f, 4 + e * 6) == 0,
                };
                empty += u32::from(is_empty);
            }
        }
        ReturnCounts { returns: dt.returns_per_packet() as u32, empty }
    }
}

/// The line after `line` on the Avia's six.
#[inline(always)]
fn next_line(line: u8) -> u8 {
    if line + 1 == AVIA_LINES {
        0
    } else {
        line + 1
    }
}

/// Cartesian firings of `SIZE` bytes holding `ECHOES` returns of 14 bytes (13 without a tag);
/// `EXTENDED` types carry a tag and cycle through the Avia's lines, Mid types (type 0) do not.
/// Returns the number of empty returns.
#[inline(always)]
fn decode_cartesian<const SIZE: usize, const ECHOES: usize, const EXTENDED: bool>(
    body: &[u8],
    interval: u32,
    out: &mut Vec<Point>,
) -> u32 {
    let mut empty = 0u32;
    let mut line = 0u8;
    for (k, f) in body.chunks_exact(SIZE).enumerate() {
        let Ok(f) = <&[u8; SIZE]>::try_from(f) else { continue };
        let offset_ns = k as u32 * interval;
        for e in 0..ECHOES {
            let o = e * 14;
            // Mid type 0 has no tag byte; `get` keeps the untaken branch free of a panic path.
            let tag = if EXTENDED { f.get(o + 13).copied().unwrap_or(0) } else { 0 };
            push_cartesian(out, &mut empty, f, o, tag, line, e as u8, offset_ns);
        }
        if EXTENDED {
            line = next_line(line);
        }
    }
    empty
}

/// Single-return spherical firings (types 1 and 3): depth u32, theta u16, phi u16, reflectivity,
/// and a tag when `EXTENDED` (type 3, which also cycles through the Avia's lines).
#[inline(always)]
fn decode_spherical<const SIZE: usize, const EXTENDED: bool>(body: &[u8], interval: u32, out: &mut Vec<Point>) -> u32 {
    let table = trig_table();
    let mut empty = 0u32;
    let mut line = 0u8;
    for (k, f) in body.chunks_exact(SIZE).enumerate() {
        let Ok(f) = <&[u8; SIZE]>::try_from(f) else { continue };
        let offset_ns = k as u32 * interval;
        let tag = if EXTENDED { f.get(9).copied().unwrap_or(0) } else { 0 };
        let depth = le_u32(f, 0);
        push_spherical(out, &mut empty, table, depth, le_u16(f, 4), le_u16(f, 6), f[8], tag, line, 0, offset_ns);
        if EXTENDED {
            line = next_line(line);
        }
    }
    empty
}

/// Multi-return spherical firings (types 5 and 8): theta u16, phi u16, then per return depth u32,
/// reflectivity, tag.
#[inline(always)]
fn decode_multi_spherical<const SIZE: usize, const ECHOES: usize>(
    body: &[u8],
    interval: u32,
    out: &mut Vec<Point>,
) -> u32 {
    let table = trig_table();
    let mut empty = 0u32;
    let mut line = 0u8;
    for (k, f) in body.chunks_exact(SIZE).enumerate() {
        let Ok(f) = <&[u8; SIZE]>::try_from(f) else { continue };
        let offset_ns = k as u32 * interval;
        let (theta, phi) = (le_u16(f, 0), le_u16(f, 2));
        for e in 0..ECHOES {
            let o = 4 + e * 6;
            let depth = le_u32(f, o);
            push_spherical(out, &mut empty, table, depth, theta, phi, f[o + 4], f[o + 5], line, e as u8, offset_ns);
        }
        line = next_line(line);
    }
    empty
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn push_cartesian(
    out: &mut Vec<Point>,
    empty: &mut u32,
    f: &[u8],
    o: usize,
    tag: u8,
    line: u8,
    echo: u8,
    offset_ns: u32,
) {
    let (x, y, z) = (le_i32(f, o), le_i32(f, o + 4), le_i32(f, o + 8));
    if x == 0 && y == 0 && z == 0 {
        *empty += 1;
        return;
    }
    out.push(Point {
        x_m: x as f32 * 1e-3,
        y_m: y as f32 * 1e-3,
        z_m: z as f32 * 1e-3,
        reflectivity: f[o + 12],
        tag,
        line,
        echo,
        offset_ns,
    });
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn push_spherical(
    out: &mut Vec<Point>,
    empty: &mut u32,
    table: Option<&TrigTable>,
    depth_mm: u32,
    theta: u16,
    phi: u16,
    reflectivity: u8,
    tag: u8,
    line: u8,
    echo: u8,
    offset_ns: u32,
) {
    if depth_mm == 0 {
        *empty += 1;
        return;
    }
    let (x_m, y_m, z_m) = match table {
        Some(t) => t.to_xyz(depth_mm, theta, phi),
        None => spherical_to_xyz(depth_mm, theta, phi),
    };
    out.push(Point { x_m, y_m, z_m, reflectivity, tag, line, echo, offset_ns });
}

/// Entries of the sine table: every u16 angle in 0.01 degrees, plus 90 degrees for cosines.
const TRIG_LEN: usize = 65_536 + 9_000;

/// `sin(i * 0.01 deg)` for every u16 angle `i` (and `cos(i) = sin(i + 9000)`), each correctly
/// rounded from f64: exact to the last bit where the f32 `sin_cos` is not, and several times faster.
struct TrigTable(Box<[f32; TRIG_LEN]>);

impl TrigTable {
    #[inline(always)]
    fn to_xyz(&self, depth_mm: u32, theta_cdeg: u16, phi_cdeg: u16) -> (f32, f32, f32) {
        let (t, p) = (usize::from(theta_cdeg), usize::from(phi_cdeg));
        let (st, ct) = (self.0[t], self.0[t + 9_000]);
        let (sp, cp) = (self.0[p], self.0[p + 9_000]);
        let d = depth_mm as f32 * 1e-3;
        (d * st * cp, d * st * sp, d * ct)
    }
}

/// The table, built on first use (about 300 KB, well under a millisecond); `None` only if it
/// could not be built, in which case points are converted with `sin_cos`.
fn trig_table() -> Option<&'static TrigTable> {
    static TABLE: std::sync::OnceLock<Option<TrigTable>> = std::sync::OnceLock::new();
    TABLE
        .get_or_init(|| {
            let sines: Vec<f32> = (0..TRIG_LEN).map(|i| (i as f64 * 0.01).to_radians().sin() as f32).collect();
            sines.into_boxed_slice().try_into().ok().map(TrigTable)
        })
        .as_ref()
}

/// One return to encode; all-zero coordinates encode an empty return.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Return {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    pub reflectivity: u8,
    pub tag: u8,
}

impl Return {
    pub const EMPTY: Return = Return { x_m: 0.0, y_m: 0.0, z_m: 0.0, reflectivity: 0, tag: 0 };

    fn mm(v: f32) -> i32 {
        (v * 1000.0).round().clamp(i32::MIN as f32, i32::MAX as f32) as i32
    }

    fn is_empty(&self) -> bool {
        Self::mm(self.x_m) == 0 && Self::mm(self.y_m) == 0 && Self::mm(self.z_m) == 0
    }

    /// (depth mm, theta 0.01 deg from zenith, phi 0.01 deg in 0..360).
    fn spherical(&self) -> (u32, u16, u16) {
        if self.is_empty() {
            return (0, 0, 0);
        }
        let (x, y, z) = (f64::from(self.x_m), f64::from(self.y_m), f64::from(self.z_m));
        let d = (x * x + y * y + z * z).sqrt();
        let theta = (z / d).clamp(-1.0, 1.0).acos().to_degrees();
        let phi = y.atan2(x).to_degrees().rem_euclid(360.0);
        ((d * 1000.0).round() as u32, (theta * 100.0).round() as u16, ((phi * 100.0).round() as u16) % 36_000)
    }
}

/// Encodes a point packet: `returns` holds `firings_per_packet * echoes` returns, firing-major.
pub fn encode_point_packet(header: &DataHeader, returns: &[Return], out: &mut Vec<u8>) -> Result<()> {
    let dt = header.data_type;
    if dt == DataType::Imu || returns.len() != dt.returns_per_packet() {
        return Err(LivoxError::PacketLength {
            data_type: dt as u8,
            need: dt.returns_per_packet(),
            have: returns.len(),
        });
    }
    header.encode_into(out)?;
    for firing in returns.chunks_exact(dt.echoes()) {
        match dt {
            DataType::Cartesian | DataType::ExtendedCartesian | DataType::DualCartesian | DataType::TripleCartesian => {
                for r in firing {
                    for v in [r.x_m, r.y_m, r.z_m] {
                        out.extend_from_slice(&Return::mm(v).to_le_bytes());
                    }
                    out.push(r.reflectivity);
                    if dt != DataType::Cartesian {
                        out.push(r.tag);
                    }
                }
            }
            DataType::Spherical | DataType::ExtendedSpherical => {
                let r = firing[0];
                let (d, theta, phi) = r.spherical();
                out.extend_from_slice(&d.to_le_bytes());
                out.extend_from_slice(&theta.to_le_bytes());
                out.extend_from_slice(&phi.to_le_bytes());
                out.push(r.reflectivity);
                if dt == DataType::ExtendedSpherical {
                    out.push(r.tag);
                }
            }
            DataType::DualSpherical | DataType::TripleSpherical => {
                // Returns of one firing share a direction; take it from the first non-empty one.
                let dir = firing.iter().find(|r| !r.is_empty()).map(|r| r.spherical()).unwrap_or((0, 0, 0));
                out.extend_from_slice(&dir.1.to_le_bytes());
                out.extend_from_slice(&dir.2.to_le_bytes());
                for r in firing {
                    let (d, _, _) = r.spherical();
                    out.extend_from_slice(&d.to_le_bytes());
                    out.push(r.reflectivity);
                    out.push(r.tag);
                }
            }
            DataType::Imu => {}
        }
    }
    Ok(())
}

/// Encodes an IMU packet (data_type 6).
pub fn encode_imu_packet(header: &DataHeader, sample: &ImuSample, out: &mut Vec<u8>) -> Result<()> {
    if header.data_type != DataType::Imu {
        return Err(LivoxError::BadDataType(header.data_type as u8));
    }
    header.encode_into(out)?;
    for v in sample.gyro_rad_s.iter().chain(sample.acc_g.iter()) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::Clock;

    fn header(data_type: DataType, clock: Clock) -> DataHeader {
        DataHeader {
            version: DATA_VERSION,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(0x2000 | (1 << 14)),
            data_type,
            timestamp: Stamp::new(1_000_000_000, clock),
        }
    }

    fn returns_for(dt: DataType) -> Vec<Return> {
        (0..dt.returns_per_packet())
            .map(|i| {
                if i % 7 == 3 {
                    Return::EMPTY
                } else {
                    // Directions shared within a firing for the spherical multi-return types.
                    let k = (i / dt.echoes()) as f32;
                    let e = (i % dt.echoes()) as f32;
                    let s = 1.0 + e;
                    Return { x_m: 5.0 * s, y_m: (0.01 * k - 0.3) * s, z_m: 0.2 * s, reflectivity: i as u8, tag: 0x10 }
                }
            })
            .collect()
    }

    #[test]
    fn the_packet_table_holds() {
        let table = [(0, 1318), (1, 918), (2, 1362), (3, 978), (4, 1362), (5, 786), (6, 42), (7, 1278), (8, 678)];
        for (t, len) in table {
            assert_eq!(packet_len_for(t), Some(len), "data_type {t}");
        }
        assert_eq!(packet_len_for(9), None);
    }

    #[test]
    fn every_point_type_round_trips_with_firing_times_and_lines() {
        for dt in DataType::ALL.into_iter().filter(|&d| d != DataType::Imu) {
            let h = header(dt, Clock::Ptp);
            let input = returns_for(dt);
            let mut bytes = Vec::new();
            assert!(encode_point_packet(&h, &input, &mut bytes).is_ok());
            assert_eq!(bytes.len(), dt.packet_len(), "{dt:?}");
            let packet = DataPacket::parse(&bytes);
            assert!(packet.is_ok(), "{dt:?}: {packet:?}");
            let Ok(packet) = packet else { continue };
            assert_eq!(packet.header, h);
            let mut points = Vec::new();
            let counts = packet.decode_points(&mut points);
            let expect_empty = input.iter().filter(|r| **r == Return::EMPTY).count() as u32;
            assert_eq!(counts, ReturnCounts { returns: input.len() as u32, empty: expect_empty }, "{dt:?}");
            assert_eq!(packet.count_returns(), counts, "{dt:?}");
            let kept: Vec<(usize, &Return)> = input.iter().enumerate().filter(|(_, r)| **r != Return::EMPTY).collect();
            assert_eq!(points.len(), kept.len());
            let tol = if dt.is_spherical() { 0.02 } else { 0.0006 };
            for (p, (i, r)) in points.iter().zip(kept) {
                let firing = i / dt.echoes();
                assert!(
                    (p.x_m - r.x_m).abs() < tol && (p.y_m - r.y_m).abs() < tol && (p.z_m - r.z_m).abs() < tol,
                    "{dt:?} return {i}: {p:?} vs {r:?}"
                );
                assert_eq!(p.offset_ns, firing as u32 * dt.firing_interval_ns());
                assert_eq!(p.echo as usize, i % dt.echoes());
                let mid = matches!(dt, DataType::Cartesian | DataType::Spherical);
                assert_eq!(p.line, if mid { 0 } else { (firing % 6) as u8 });
                assert!(p.x_m != 0.0 || p.y_m != 0.0 || p.z_m != 0.0);
            }
        }
    }

    #[test]
    fn imu_converts_g_and_keeps_raw() {
        let h = header(DataType::Imu, Clock::Device);
        let s = ImuSample { gyro_rad_s: [0.1, -0.2, 0.3], acc_g: [0.0, 0.0, 1.0] };
        let mut bytes = Vec::new();
        assert!(encode_imu_packet(&h, &s, &mut bytes).is_ok());
        assert_eq!(bytes.len(), 42);
        let p = DataPacket::parse(&bytes).ok();
        let imu = p.and_then(|p| p.imu());
        assert_eq!(imu, Some(s));
        assert_eq!(imu.map(|i| i.acc_m_s2()[2]), Some(STANDARD_GRAVITY_M_S2));
    }

    #[test]
    fn imu_samples_with_nan_or_infinity_are_not_handed_out() {
        let h = header(DataType::Imu, Clock::Device);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for k in 0..6 {
                let mut s = ImuSample { gyro_rad_s: [0.1, -0.2, 0.3], acc_g: [0.0, 0.0, 1.0] };
                if k < 3 {
                    s.gyro_rad_s[k] = bad;
                } else {
                    s.acc_g[k - 3] = bad;
                }
                let mut bytes = Vec::new();
                assert!(encode_imu_packet(&h, &s, &mut bytes).is_ok());
                let Ok(p) = DataPacket::parse(&bytes) else { panic!("an IMU packet with {bad} parses") };
                assert!(p.is_imu());
                assert_eq!(p.imu(), None, "value {k} = {bad}");
                assert!(p.imu_raw().is_some_and(|r| !r.is_finite()));
            }
        }
    }

    #[test]
    fn wrong_lengths_and_fields_are_typed_errors() {
        let h = header(DataType::ExtendedCartesian, Clock::Ptp);
        let mut bytes = Vec::new();
        assert!(encode_point_packet(&h, &returns_for(DataType::ExtendedCartesian), &mut bytes).is_ok());
        for len in [0, 1, 17, 18, 100, bytes.len() - 1] {
            assert!(DataPacket::parse(&bytes[..len]).is_err(), "len {len}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(DataPacket::parse(&longer), Err(LivoxError::PacketLength { .. })));
        let mut bad = bytes.clone();
        bad[9] = 9;
        assert!(matches!(DataPacket::parse(&bad), Err(LivoxError::BadDataType(9))));
        bad = bytes.clone();
        bad[0] = 4;
        assert!(matches!(DataPacket::parse(&bad), Err(LivoxError::BadDataVersion(4))));
        bad = bytes;
        bad[8] = 2;
        assert!(matches!(DataPacket::parse(&bad), Err(LivoxError::BadTimestampType(2))));
    }
}
