//! Faults the mock motor bus injects, deterministic from a seed.
//!
//! TOML (the `[faults]` table of a mock config):
//!
//! ```toml
//! garbage = 0.01             # fraction of lines to the host preceded by 1-8 junk bytes
//! drop = 0.05                # fraction of frames to the host dropped
//! silence_after_s = 3.0      # the adapter goes quiet (sends nothing) after 3 s
//! bus_error_after_s = 2.0    # F reports bus error + error warning from 2 s on
//! motor_fault_after_s = 1.0  # C620: the ESC stops its feedback; CiA 402: EMCY 0x2310 + Fault
//! motor_fault_id = 2         # which ESC/node (default: the first)
//! ```

use crate::error::{HilError, Result};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotorFaultConfig {
    pub garbage: f64,
    pub drop: f64,
    pub silence_after_s: Option<f64>,
    pub bus_error_after_s: Option<f64>,
    pub motor_fault_after_s: Option<f64>,
    pub motor_fault_id: Option<u8>,
}

impl MotorFaultConfig {
    pub fn validate(&self) -> Result<()> {
        for (field, v) in [("faults.garbage", self.garbage), ("faults.drop", self.drop)] {
            if !(0.0..=1.0).contains(&v) {
                return Err(HilError::config(field, format!("{v} is not a fraction in [0, 1]")));
            }
        }
        for (field, v) in [
            ("faults.silence_after_s", self.silence_after_s),
            ("faults.bus_error_after_s", self.bus_error_after_s),
            ("faults.motor_fault_after_s", self.motor_fault_after_s),
        ] {
            if let Some(s) = v {
                if !s.is_finite() || s < 0.0 {
                    return Err(HilError::config(field, format!("{s} is not a time >= 0")));
                }
            }
        }
        Ok(())
    }
}

/// Converts optional seconds to device nanoseconds.
pub fn at_ns(s: Option<f64>) -> Option<u64> {
    s.map(|s| (s * 1e9).round() as u64)
}

/// What the faults did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MotorFaultStats {
    pub garbage_bursts: u64,
    pub dropped: u64,
    pub silenced_lines: u64,
    pub motor_faults: u64,
}
