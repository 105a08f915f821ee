//! Port settings (TOML via serde; see config/ptp.toml).

use crate::error::{PtpError, Result};
use serde::{Deserialize, Serialize};

/// Which timescale the local timestamps are on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LocalTimescale {
    /// CLOCK_REALTIME (UTC): what software timestamps are on.
    Utc,
    /// A clock that already counts TAI (a PHC a grandmaster disciplines to PTP time).
    Tai,
}

/// A grandmaster port.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MasterConfig {
    pub domain: u8,
    /// log2 of the Announce interval in seconds (0: 1 s).
    pub log_announce_interval: i8,
    /// log2 of the Sync interval in seconds (0: 1 s; a Livox LiDAR is happy with 1 s).
    pub log_sync_interval: i8,
    /// log2 of the Delay_Req interval we ask slaves to keep (sent in Delay_Resp).
    pub log_min_delay_req_interval: i8,
    pub priority1: u8,
    pub priority2: u8,
    /// 248: "default" (a clock that is not traceable); 6 for a GPS-locked grandmaster.
    pub clock_class: u8,
    /// 0xFE: unknown.
    pub clock_accuracy: u8,
    pub offset_scaled_log_variance: u16,
    /// TAI - UTC in seconds: 37 since 2017-01-01.
    pub utc_offset_s: i16,
    /// Send PTP (TAI) time with ptpTimescale set; false sends the local clock as-is (ARB).
    pub ptp_timescale: bool,
    /// 1588 timeSource (0xA0 internal oscillator, 0x20 GPS, 0x50 NTP).
    pub time_source: u8,
    pub local_timescale: LocalTimescale,
}

impl Default for MasterConfig {
    fn default() -> Self {
        Self {
            domain: 0,
            log_announce_interval: 0,
            log_sync_interval: 0,
            log_min_delay_req_interval: 0,
            priority1: 128,
            priority2: 128,
            clock_class: 248,
            clock_accuracy: 0xfe,
            offset_scaled_log_variance: 0xffff,
            utc_offset_s: 37,
            ptp_timescale: true,
            time_source: crate::message::time_source::INTERNAL_OSCILLATOR,
            local_timescale: LocalTimescale::Utc,
        }
    }
}

/// The PI servo's gains (ptp4l's defaults for software timestamps).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoConfig {
    pub kp: f64,
    pub ki: f64,
    /// Offsets beyond this make the servo step (or report s1 in measure-only mode).
    pub step_threshold_ns: i64,
    /// The largest frequency correction the servo asks for.
    pub max_freq_ppb: f64,
}

impl Default for ServoConfig {
    fn default() -> Self {
        Self { kp: 0.7, ki: 0.3, step_threshold_ns: 20_000, max_freq_ppb: 500_000.0 }
    }
}

/// A slave port.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SlaveConfig {
    pub domain: u8,
    /// log2 of the Delay_Req interval until a master's Delay_Resp names its own.
    pub log_min_delay_req_interval: i8,
    /// Announce intervals without an Announce before the master counts as gone.
    pub announce_receipt_timeout: u8,
    /// Delay samples in the moving median.
    pub delay_filter_length: usize,
    /// Samples in the measure-only frequency estimate.
    pub freq_window: usize,
    /// TAI - UTC used when a master sets ptpTimescale without currentUtcOffsetValid.
    pub default_utc_offset_s: i16,
    pub local_timescale: LocalTimescale,
    /// Steer the local clock with the servo. Off by default: the slave measures only. Turning
    /// it on makes the slave emit adjust actions; the transport applies them only when it was
    /// also given a clock to adjust.
    pub adjust_clock: bool,
    pub servo: ServoConfig,
    /// Seed of the Delay_Req interval jitter.
    pub seed: u64,
}

impl Default for SlaveConfig {
    fn default() -> Self {
        Self {
            domain: 0,
            log_min_delay_req_interval: 0,
            announce_receipt_timeout: 3,
            delay_filter_length: 10,
            freq_window: 16,
            default_utc_offset_s: 37,
            local_timescale: LocalTimescale::Utc,
            adjust_clock: false,
            servo: ServoConfig::default(),
            seed: 1,
        }
    }
}

/// config/ptp.toml: `[master]` and `[slave]` tables, each optional.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PtpConfig {
    pub master: MasterConfig,
    pub slave: SlaveConfig,
}

impl PtpConfig {
    pub fn from_toml(text: &str) -> Result<Self> {
        let c: Self = toml::from_str(text).map_err(|e| PtpError::BadConfig(e.to_string()))?;
        c.validate()?;
        Ok(c)
    }

    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| PtpError::io(format!("read {}", path.display()), e))?;
        Self::from_toml(&text)
    }

    pub fn validate(&self) -> Result<()> {
        let m = &self.master;
        for (name, v) in [
            ("master.log_announce_interval", m.log_announce_interval),
            ("master.log_sync_interval", m.log_sync_interval),
            ("master.log_min_delay_req_interval", m.log_min_delay_req_interval),
            ("slave.log_min_delay_req_interval", self.slave.log_min_delay_req_interval),
        ] {
            if !(-7..=4).contains(&v) {
                return Err(PtpError::BadConfig(format!("{name} = {v}: keep it within -7..=4")));
            }
        }
        let s = &self.slave;
        if s.announce_receipt_timeout < 2 {
            return Err(PtpError::BadConfig("slave.announce_receipt_timeout must be at least 2".into()));
        }
        if !(1..=128).contains(&s.delay_filter_length) || !(2..=1024).contains(&s.freq_window) {
            return Err(PtpError::BadConfig("slave.delay_filter_length 1..=128, slave.freq_window 2..=1024".into()));
        }
        if !(s.servo.kp.is_finite() && s.servo.ki.is_finite() && s.servo.kp >= 0.0 && s.servo.ki >= 0.0) {
            return Err(PtpError::BadConfig("servo gains must be finite and non-negative".into()));
        }
        Ok(())
    }
}
