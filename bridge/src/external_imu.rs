//! An external IMU's samples from a file, for `starc lio --imu`: the byte stream of a
//! MicroStrain device (MIP), or the simulator's CSV.

use crate::BridgeError;
use nalgebra::Vector3;
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::{ImuDecoder, ImuEvent, Protocol};
use starc_pipeline::lio::ImuSample;
use starc_time::{Clock, Stamp};
use std::path::Path;

/// Unix time minus GPS time: the epochs 1970-01-01 and 1980-01-06 apart, less the 18 leap
/// seconds GPS has gained since.
const UNIX_MINUS_GPS_NS: i64 = (315_964_800 - 18) * 1_000_000_000;

/// The MIP sync bytes a MicroStrain stream starts with.
const MIP_SYNC: [u8; 2] = [0x75, 0x65];

/// An external IMU's samples, in time order, with `offset_ns` added to their stamps. They are
/// taken as on the LiDAR's PTP clock: a MIP device's GPS time from a PTP-disciplined receiver, or
/// the simulator's CSV (whose times are the Avias' PTP times).
///
/// A file starting with the MIP sync bytes is decoded as a MicroStrain MIP stream; its GPS time
/// field (Unix time + 18 s leap seconds, as a PTP-disciplined device reports it) gives the stamp.
/// Otherwise it is read as the simulator's CSV: `time_s,gyro_x_rad_s,..,accel_z_m_s2`.
pub fn read_external_imu(path: &Path, offset_ns: i64) -> Result<Vec<ImuSample>, BridgeError> {
    let bytes = std::fs::read(path).map_err(|source| BridgeError::Io { path: path.into(), source })?;
    let mut samples = parse(&bytes).map_err(|reason| BridgeError::ExternalImu { path: path.into(), reason })?;
    for s in &mut samples {
        s.t_ns = s.t_ns.saturating_add_signed(offset_ns);
    }
    samples.sort_by_key(|s| s.t_ns);
    Ok(samples)
}

/// An external IMU file's samples in file order: a MIP stream or the CSV (see
/// [`read_external_imu`]); the reason when it holds none.
pub fn parse(bytes: &[u8]) -> Result<Vec<ImuSample>, String> {
    let samples = if bytes.starts_with(&MIP_SYNC) { mip(bytes) } else { csv(bytes)? };
    if samples.is_empty() {
        return Err("no IMU samples".into());
    }
    Ok(samples)
}

fn mip(bytes: &[u8]) -> Vec<ImuSample> {
    let mut decoder = ImuDecoder::new(Protocol::Mip, Timestamper::new(LatencyModel::new(0, 0)));
    let mut events = Vec::new();
    decoder.push(bytes, Stamp::new(0, Clock::Host), &mut events);
    let mut out = Vec::with_capacity(events.len());
    let mut untimed = 0u64;
    for e in events {
        let ImuEvent::Sample(s) = e else { continue };
        let t_ns = s.device_ns.and_then(|gps_ns| u64::try_from(gps_ns as i64 + UNIX_MINUS_GPS_NS).ok());
        let Some(t_ns) = t_ns else {
            untimed += 1;
            continue;
        };
        let sample = ImuSample {
            t_ns,
            clock: Clock::Ptp,
            gyro_rad_s: Vector3::from(s.gyro_rad_s),
            acc_m_s2: Vector3::from(s.accel_m_s2),
        };
        // A NaN or infinity would poison the filter's state for good: such a sample is dropped.
        if sample.gyro_rad_s.iter().chain(sample.acc_m_s2.iter()).all(|x| x.is_finite()) {
            out.push(sample);
        } else {
            untimed += 1;
        }
    }
    let stats = decoder.stats();
    if stats.bad_checksums > 0 || untimed > 0 {
        tracing::warn!(
            bad_checksums = stats.bad_checksums,
            untimed_or_not_finite = untimed,
            "external IMU: samples dropped"
        );
    }
    out
}

fn csv(bytes: &[u8]) -> Result<Vec<ImuSample>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "neither a MIP stream nor UTF-8 CSV".to_string())?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if n == 0 && line.starts_with("time_s") || line.trim().is_empty() {
            continue;
        }
        out.push(csv_line(line).map_err(|e| format!("CSV line {}: {e}", n + 1))?);
    }
    Ok(out)
}

fn csv_line(line: &str) -> Result<ImuSample, String> {
    let v: Vec<f64> = line
        .split(',')
        .map(|f| f.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| "expected 7 numbers (time_s, gyro xyz, accel xyz)".to_string())?;
    let [t, gx, gy, gz, ax, ay, az] = v[..] else {
        return Err(format!("{} fields, expected 7", v.len()));
    };
    if !(t.is_finite() && t >= 0.0) {
        return Err(format!("bad time {t}"));
    }
    if !v.iter().all(|x| x.is_finite()) {
        return Err("a value is not finite".into());
    }
    // Seconds with 6 decimals: round to the microsecond they were written with.
    let t_ns = ((t * 1e6).round() as u64).saturating_mul(1000);
    Ok(ImuSample { t_ns, clock: Clock::Ptp, gyro_rad_s: Vector3::new(gx, gy, gz), acc_m_s2: Vector3::new(ax, ay, az) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_reads_and_sorts_and_offsets() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("imu.csv");
        let text = "time_s,gx,gy,gz,ax,ay,az\n0.002000,0,0,1,0,0,9.8\n0.001000,0,0,0,0,0,9.8\n";
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("{e}"));
        let s = read_external_imu(&path, 500).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.iter().map(|s| s.t_ns).collect::<Vec<_>>(), vec![1_000_500, 2_000_500]);
        assert_eq!(s[1].gyro_rad_s.z, 1.0);
    }

    #[test]
    fn non_finite_values_are_refused() {
        let e = parse(b"0.1,inf,0,0,0,0,9.8\n").err().unwrap_or_default();
        assert!(e.contains("line 1") && e.contains("not finite"), "{e}");
    }

    #[test]
    fn csv_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("imu.csv");
        std::fs::write(&path, "time_s\n0.1,1,2\n").unwrap_or_else(|e| panic!("{e}"));
        let e = read_external_imu(&path, 0).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("line 2") && e.contains("3 fields"), "{e}");
    }
}
