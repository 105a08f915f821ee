//! The robot's serial IMU and wheel motors on their real wire protocols, in virtual time.
//!
//! - [`ExternalImu`]: the simulator's external IMU ([`ImuSim`]) feeds the sans-IO MIP mock
//!   ([`ImuDevice`]); the exact byte stream the mock puts on its UART goes to
//!   `robot_imu_external.mip`, and every sample the mock took goes to `robot_imu_external.csv`
//!   (the ground truth), so the two hold the same samples.
//! - [`WheelCan`]: the wheel rates the simulated base measures, as the motor controllers report
//!   them on the CAN bus (C620 feedback or CiA 402 TPDO1), in a `candump -l` log.

use crate::error::Result;
use crate::imu::{DeviceConfig, ImuDevice, ImuSource, Motion, SensorModel};
use crate::sim::imu::{ImuMeasurement, ImuSim};
use crate::sim::scenario::MotorProtocol;
use crate::sim::truth::{out_err, OutFile};
use starc_base::c620::frame::M3508_GEAR_RATIO;
use starc_base::c620::Feedback;
use starc_base::cia402::{Cia402Config, DriveState, VelocityStatus};
use starc_can::CanFrame;
use starc_imu::mip::data::{FIELD_ACCEL, FIELD_GPS_TIME, FIELD_GYRO};
use starc_imu::Protocol;
use std::f64::consts::TAU;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// The mock IMU's UART: the fastest a MIP device offers, so 0x80 packets of accel, gyro and
/// GPS time (48 bytes) fit up to about 1900 Hz.
pub const EXTERNAL_IMU_BAUD: u32 = 921_600;
/// One CAN frame on a 1 Mbit/s bus (8 data bytes, 11-bit id, with typical stuffing): the
/// controllers' feedback frames of one sample follow each other this far apart.
pub const CAN_FRAME_NS: u64 = 130_000;
/// The interface name written in the log.
pub const CAN_INTERFACE: &str = "can0";
/// Temperature the C620s report.
const C620_TEMPERATURE_C: u8 = 30;

/// Samples the mock took from the simulator's IMU: (simulator ns, measurement).
type Taken = Arc<Mutex<Vec<(u64, ImuMeasurement)>>>;

/// The simulator's IMU as what the mock device feels. The [`ImuSim`] already carries the
/// datasheet noise, so the device's own sensor model is ideal.
struct SimImuSource {
    imu: ImuSim,
    start_ns: u64,
    taken: Taken,
}

impl ImuSource for SimImuSource {
    fn motion(&mut self, t_ns: u64) -> Motion {
        let sim_ns = self.start_ns.saturating_add(t_ns);
        let m = self.imu.sample(sim_ns as f64 * 1e-9);
        self.taken.lock().unwrap_or_else(|e| e.into_inner()).push((sim_ns, m));
        Motion {
            gyro_rad_s: [m.gyro_rad_s.x, m.gyro_rad_s.y, m.gyro_rad_s.z],
            accel_m_s2: [m.accel_m_s2.x, m.accel_m_s2.y, m.accel_m_s2.z],
            orientation_wxyz: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// The robot's external IMU as a MicroStrain MIP device on a serial line.
pub struct ExternalImu {
    device: ImuDevice<SimImuSource>,
    taken: Taken,
    start_ns: u64,
    ptp_offset_ns: i64,
    bytes: Vec<u8>,
    mip: OutFile,
    csv: OutFile,
}

impl ExternalImu {
    /// The IMU powers on at simulator time `start_ns`; its GPS time then reads the PTP time of
    /// that instant (taken as Unix time). The mock streams 0x80 accel, gyro and GPS time with
    /// its base rate at `rate_hz` (decimation 1), so a sample is due every 1/rate_hz.
    pub fn create(out: &Path, imu: ImuSim, rate_hz: f64, start_ns: u64, ptp_offset_ns: i64) -> Result<Self> {
        let taken: Taken = Arc::new(Mutex::new(Vec::new()));
        let base = rate_hz.round().clamp(1.0, f64::from(u16::MAX)) as u16;
        let mut config = DeviceConfig::new(Protocol::Mip);
        config.rate_hz = f64::from(base);
        config.mip_base_rate_hz = base;
        config.mip_fields = vec![FIELD_ACCEL, FIELD_GYRO, FIELD_GPS_TIME];
        config.baud = EXTERNAL_IMU_BAUD;
        config.epoch_ns = start_ns.saturating_add_signed(ptp_offset_ns);
        config.sensor = SensorModel::ideal();
        let source = SimImuSource { imu, start_ns, taken: taken.clone() };
        let mut csv = OutFile::create(&out.join("robot_imu_external.csv"))?;
        csv.line("time_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2")?;
        Ok(Self {
            device: ImuDevice::new(config, source),
            taken,
            start_ns,
            ptp_offset_ns,
            bytes: Vec::with_capacity(256),
            mip: OutFile::create(&out.join("robot_imu_external.mip"))?,
            csv,
        })
    }

    /// Runs the device up to simulator time `t_ns`: its bytes to the .mip file, the samples it
    /// took to the CSV.
    pub fn step(&mut self, t_ns: u64) -> Result<()> {
        let Some(device_ns) = t_ns.checked_sub(self.start_ns) else { return Ok(()) };
        self.device.poll(device_ns, &mut self.bytes);
        let taken = std::mem::take(&mut *self.taken.lock().unwrap_or_else(|e| e.into_inner()));
        for (sim_ns, m) in taken {
            self.csv.line(&format!(
                "{:.6},{:.7},{:.7},{:.7},{:.6},{:.6},{:.6}",
                sim_ns.saturating_add_signed(self.ptp_offset_ns) as f64 * 1e-9,
                m.gyro_rad_s.x,
                m.gyro_rad_s.y,
                m.gyro_rad_s.z,
                m.accel_m_s2.x,
                m.accel_m_s2.y,
                m.accel_m_s2.z
            ))?;
        }
        if !self.bytes.is_empty() {
            self.mip.write(&self.bytes)?;
            self.bytes.clear();
        }
        Ok(())
    }

    /// Flushes both files; warns when the line was too slow for the rate (samples in the CSV
    /// that never reached the .mip file).
    pub fn finish(self) -> Result<()> {
        let stats = self.device.stats();
        if stats.overruns > 0 {
            tracing::warn!(
                overruns = stats.overruns,
                baud = EXTERNAL_IMU_BAUD,
                "external IMU: the serial line could not carry every sample"
            );
        }
        self.mip.finish()?;
        self.csv.finish()
    }
}

/// The base's motor controllers reporting the measured wheel rates on CAN, as a candump log.
pub struct WheelCan {
    protocol: MotorProtocol,
    log: OutFile,
    /// C620 rotor angles in counts (0..8192), integrated from the reported speeds.
    rotor_counts: Vec<f64>,
    last_ns: Option<u64>,
    cia402_units_per_rad_s: f64,
    frames: u64,
}

impl WheelCan {
    pub fn create(out: &Path, protocol: MotorProtocol, wheels: usize) -> Result<Self> {
        Ok(Self {
            protocol,
            log: OutFile::create(&out.join("robot_can.log"))?,
            rotor_counts: vec![0.0; wheels],
            last_ns: None,
            cia402_units_per_rad_s: Cia402Config::default().units_per_rad_s,
            frames: 0,
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// One feedback frame per wheel for the rates measured at PTP time `ptp_ns`; wheel i is
    /// ESC / node i + 1, the frames one frame time apart.
    pub fn write(&mut self, ptp_ns: u64, wheel_rad_s: &[f64]) -> Result<()> {
        let dt_s = self.last_ns.map_or(0.0, |l| ptp_ns.saturating_sub(l) as f64 * 1e-9);
        self.last_ns = Some(ptp_ns);
        for (i, &w) in wheel_rad_s.iter().enumerate() {
            let Ok(id) = u8::try_from(i + 1) else { break };
            let frame = match self.protocol {
                MotorProtocol::C620 => {
                    let rpm = (w * M3508_GEAR_RATIO * 60.0 / TAU).round().clamp(-32768.0, 32767.0) as i16;
                    let counts = self.rotor_counts.get_mut(i).map_or(0.0, |c| {
                        *c = (*c + f64::from(rpm) / 60.0 * dt_s * 8192.0).rem_euclid(8192.0);
                        *c
                    });
                    Feedback {
                        esc: id,
                        angle_raw: (counts.floor() as u16).min(8191),
                        rotor_rpm: rpm,
                        current_raw: 0,
                        temperature_c: C620_TEMPERATURE_C,
                    }
                    .to_frame()
                }
                MotorProtocol::Cia402 => {
                    let v = (w * self.cia402_units_per_rad_s).round().clamp(f64::from(i32::MIN), f64::from(i32::MAX));
                    VelocityStatus { statusword: DriveState::OperationEnabled.statusword(), actual_velocity: v as i32 }
                        .to_frame(id)
                }
            };
            let frame = frame.map_err(|e| out_err(self.log.path(), e))?;
            self.line(ptp_ns + i as u64 * CAN_FRAME_NS, &frame)?;
        }
        Ok(())
    }

    fn line(&mut self, ns: u64, frame: &CanFrame) -> Result<()> {
        self.frames += 1;
        self.log.line(&format!("({}.{:06}) {CAN_INTERFACE} {frame}", ns / 1_000_000_000, ns % 1_000_000_000 / 1000))
    }

    pub fn finish(self) -> Result<()> {
        self.log.finish()
    }
}
