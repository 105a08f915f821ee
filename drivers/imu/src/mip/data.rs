//! IMU data (descriptor set 0x80): the fields a 3DM-GX5/CV7 streams.

use crate::error::{ImuError, Result};
use crate::mip::packet::{be_f32, be_f64, be_u16, Packet, PacketWriter};

pub const IMU_DATA_SET: u8 = 0x80;
/// Scaled accelerometer, 3 x f32, g.
pub const FIELD_ACCEL: u8 = 0x04;
/// Scaled gyro, 3 x f32, rad/s.
pub const FIELD_GYRO: u8 = 0x05;
/// Scaled magnetometer, 3 x f32, gauss.
pub const FIELD_MAG: u8 = 0x06;
/// Orientation quaternion, 4 x f32 (w, x, y, z).
pub const FIELD_QUATERNION: u8 = 0x0A;
/// Euler angles, 3 x f32 rad (roll, pitch, yaw).
pub const FIELD_EULER: u8 = 0x0C;
/// GPS correlation time stamp: f64 time of week (s), u16 week, u16 flags.
pub const FIELD_GPS_TIME: u8 = 0x12;

/// GPS time of a sample (MIP 0x80/0x12).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsTime {
    pub tow_s: f64,
    pub week: u16,
    /// Bit 0: PPS valid; bit 1: time refreshed; bit 2: time initialized.
    pub flags: u16,
}

impl GpsTime {
    /// Nanoseconds since the GPS epoch (1980-01-06), or `None` for a nonsensical time of week.
    pub fn gps_ns(&self) -> Option<u64> {
        if !self.tow_s.is_finite() || self.tow_s < 0.0 || self.tow_s >= 604_800.0 {
            return None;
        }
        let week_ns = u64::from(self.week) * 604_800 * 1_000_000_000;
        Some(week_ns + (self.tow_s * 1e9).round() as u64)
    }
}

/// The IMU fields of one 0x80 packet, as sent (device units).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MipData {
    pub accel_g: Option<[f32; 3]>,
    pub gyro_rad_s: Option<[f32; 3]>,
    pub mag_gauss: Option<[f32; 3]>,
    /// w, x, y, z.
    pub quaternion: Option<[f32; 4]>,
    /// Roll, pitch, yaw.
    pub euler_rad: Option<[f32; 3]>,
    pub gps_time: Option<GpsTime>,
    /// Fields of other descriptors (skipped).
    pub unknown_fields: u8,
}

fn floats<const N: usize>(set: u8, descriptor: u8, data: &[u8], expected: &'static str) -> Result<[f32; N]> {
    if data.len() != 4 * N {
        return Err(ImuError::FieldLength { set, descriptor, len: data.len(), expected });
    }
    Ok(std::array::from_fn(|i| be_f32(data, 4 * i)))
}

impl MipData {
    /// Decodes the fields of a 0x80 packet; a known field of the wrong length is an error.
    pub fn decode(packet: &Packet<'_>) -> Result<Self> {
        let set = packet.descriptor_set;
        if set != IMU_DATA_SET {
            return Err(ImuError::BadValue { field: "MIP data descriptor set", value: u64::from(set) });
        }
        let mut d = MipData::default();
        for field in packet.fields() {
            let f = field?;
            match f.descriptor {
                FIELD_ACCEL => d.accel_g = Some(floats(set, f.descriptor, f.data, "12")?),
                FIELD_GYRO => d.gyro_rad_s = Some(floats(set, f.descriptor, f.data, "12")?),
                FIELD_MAG => d.mag_gauss = Some(floats(set, f.descriptor, f.data, "12")?),
                FIELD_QUATERNION => d.quaternion = Some(floats(set, f.descriptor, f.data, "16")?),
                FIELD_EULER => d.euler_rad = Some(floats(set, f.descriptor, f.data, "12")?),
                FIELD_GPS_TIME => {
                    if f.data.len() != 12 {
                        return Err(ImuError::FieldLength {
                            set,
                            descriptor: f.descriptor,
                            len: f.data.len(),
                            expected: "12",
                        });
                    }
                    d.gps_time =
                        Some(GpsTime { tow_s: be_f64(f.data, 0), week: be_u16(f.data, 8), flags: be_u16(f.data, 10) });
                }
                _ => d.unknown_fields = d.unknown_fields.saturating_add(1),
            }
        }
        Ok(d)
    }

    /// Encodes the present fields, in descriptor order, as one 0x80 packet appended to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        let mut w = PacketWriter::new(IMU_DATA_SET);
        let mut buf = [0u8; 16];
        let mut put = |w: &mut PacketWriter, descriptor: u8, values: &[f32]| -> Result<()> {
            for (chunk, v) in buf.chunks_exact_mut(4).zip(values) {
                chunk.copy_from_slice(&v.to_be_bytes());
            }
            w.field(descriptor, buf.get(..4 * values.len()).unwrap_or_default()).map(|_| ())
        };
        if let Some(v) = self.accel_g {
            put(&mut w, FIELD_ACCEL, &v)?;
        }
        if let Some(v) = self.gyro_rad_s {
            put(&mut w, FIELD_GYRO, &v)?;
        }
        if let Some(v) = self.mag_gauss {
            put(&mut w, FIELD_MAG, &v)?;
        }
        if let Some(v) = self.quaternion {
            put(&mut w, FIELD_QUATERNION, &v)?;
        }
        if let Some(v) = self.euler_rad {
            put(&mut w, FIELD_EULER, &v)?;
        }
        if let Some(t) = self.gps_time {
            let mut b = [0u8; 12];
            b[..8].copy_from_slice(&t.tow_s.to_be_bytes());
            b[8..10].copy_from_slice(&t.week.to_be_bytes());
            b[10..].copy_from_slice(&t.flags.to_be_bytes());
            w.field(FIELD_GPS_TIME, &b)?;
        }
        w.finish(out);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full() -> MipData {
        MipData {
            accel_g: Some([0.01, -0.02, -1.0]),
            gyro_rad_s: Some([0.001, 0.002, -0.003]),
            mag_gauss: Some([0.2, 0.0, 0.45]),
            quaternion: Some([1.0, 0.0, 0.0, 0.0]),
            euler_rad: Some([0.1, -0.2, 3.0]),
            gps_time: Some(GpsTime { tow_s: 345_600.125, week: 2345, flags: 0x7 }),
            unknown_fields: 0,
        }
    }

    #[test]
    fn every_field_round_trips() {
        let mut bytes = Vec::new();
        full().encode(&mut bytes).unwrap_or_else(|e| panic!("{e}"));
        // 4 header + 3x14 + 18 + 14 + 14 (gps) + 2 checksum.
        assert_eq!(bytes.len(), 4 + 14 * 4 + 18 + 14 + 2);
        let (p, n) = Packet::parse(&bytes).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(n, bytes.len());
        assert_eq!(MipData::decode(&p).unwrap_or_else(|e| panic!("{e}")), full());
        // Each field alone.
        let one = [
            MipData { accel_g: full().accel_g, ..Default::default() },
            MipData { gyro_rad_s: full().gyro_rad_s, ..Default::default() },
            MipData { mag_gauss: full().mag_gauss, ..Default::default() },
            MipData { quaternion: full().quaternion, ..Default::default() },
            MipData { euler_rad: full().euler_rad, ..Default::default() },
            MipData { gps_time: full().gps_time, ..Default::default() },
        ];
        for d in one {
            let mut b = Vec::new();
            d.encode(&mut b).unwrap_or_else(|e| panic!("{e}"));
            let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(MipData::decode(&p).unwrap_or_else(|e| panic!("{e}")), d);
        }
    }

    #[test]
    fn accel_field_bytes_are_big_endian() {
        let d = MipData { accel_g: Some([1.0, 0.0, -1.0]), ..Default::default() };
        let mut b = Vec::new();
        d.encode(&mut b).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(&b[..6], &[0x75, 0x65, 0x80, 0x0E, 0x0E, 0x04]);
        assert_eq!(&b[6..10], &[0x3F, 0x80, 0x00, 0x00]);
        assert_eq!(&b[14..18], &[0xBF, 0x80, 0x00, 0x00]);
    }

    #[test]
    fn wrong_lengths_wrong_sets_and_unknown_fields() {
        let mut w = PacketWriter::new(IMU_DATA_SET);
        w.field(FIELD_GYRO, &[0; 8]).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
        let b = w.to_bytes();
        let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
        assert!(matches!(MipData::decode(&p), Err(ImuError::FieldLength { descriptor: 0x05, len: 8, .. })));

        let mut w = PacketWriter::new(IMU_DATA_SET);
        w.field(FIELD_GPS_TIME, &[0; 10]).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
        let b = w.to_bytes();
        let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
        assert!(matches!(MipData::decode(&p), Err(ImuError::FieldLength { descriptor: 0x12, len: 10, .. })));

        let mut w = PacketWriter::new(IMU_DATA_SET);
        w.field(0x17, &[1, 2, 3]).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
        let b = w.to_bytes();
        let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(MipData::decode(&p).map(|d| d.unknown_fields).ok(), Some(1));

        let b = PacketWriter::new(0x82).to_bytes();
        let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
        assert!(matches!(MipData::decode(&p), Err(ImuError::BadValue { .. })));
    }

    #[test]
    fn gps_time_in_ns() {
        let t = GpsTime { tow_s: 1.5, week: 1, flags: 0 };
        assert_eq!(t.gps_ns(), Some(604_801_500_000_000));
        assert_eq!(GpsTime { tow_s: -1.0, week: 1, flags: 0 }.gps_ns(), None);
        assert_eq!(GpsTime { tow_s: f64::NAN, week: 1, flags: 0 }.gps_ns(), None);
    }
}
