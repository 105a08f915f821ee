//! The 32-bit status word carried in every data packet and heartbeat ACK.

use serde::Serialize;

/// Time synchronisation state (bits 14-16).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SyncState {
    None,
    Ptp,
    Gps,
    Pps,
    Abnormal,
    Reserved(u8),
}

/// Overall state (bits 30-31).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SystemStatus {
    Normal,
    Warning,
    Error,
    Reserved,
}

/// The status word, field by field. Two-bit fields are 0 normal, 1 warning, 2 error.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct StatusWord {
    pub raw: u32,
    pub temperature: u8,
    pub voltage: u8,
    pub motor: u8,
    pub dirty: u8,
    pub firmware_error: bool,
    pub pps_ok: bool,
    pub end_of_service_life: bool,
    pub fan_warning: bool,
    pub self_heating: bool,
    pub ptp_ok: bool,
    pub sync: SyncState,
    pub system: SystemStatus,
}

impl StatusWord {
    pub fn from_raw(raw: u32) -> Self {
        let two = |shift: u32| ((raw >> shift) & 0b11) as u8;
        let bit = |n: u32| raw & (1 << n) != 0;
        let sync = match (raw >> 14) & 0b111 {
            0 => SyncState::None,
            1 => SyncState::Ptp,
            2 => SyncState::Gps,
            3 => SyncState::Pps,
            4 => SyncState::Abnormal,
            other => SyncState::Reserved(other as u8),
        };
        let system = match two(30) {
            0 => SystemStatus::Normal,
            1 => SystemStatus::Warning,
            2 => SystemStatus::Error,
            _ => SystemStatus::Reserved,
        };
        Self {
            raw,
            temperature: two(0),
            voltage: two(2),
            motor: two(4),
            dirty: two(6),
            firmware_error: bit(8),
            pps_ok: bit(9),
            end_of_service_life: bit(10),
            fan_warning: bit(11),
            self_heating: bit(12),
            ptp_ok: bit(13),
            sync,
            system,
        }
    }

    /// Builds a raw word from the fields a mock device sets.
    pub fn compose(sync: SyncState, system: SystemStatus, ptp_ok: bool, pps_ok: bool) -> u32 {
        let sync_bits = match sync {
            SyncState::None => 0,
            SyncState::Ptp => 1,
            SyncState::Gps => 2,
            SyncState::Pps => 3,
            SyncState::Abnormal => 4,
            SyncState::Reserved(v) => u32::from(v & 0b111),
        };
        let system_bits = match system {
            SystemStatus::Normal => 0,
            SystemStatus::Warning => 1,
            SystemStatus::Error => 2,
            SystemStatus::Reserved => 3,
        };
        (sync_bits << 14) | (system_bits << 30) | (u32::from(ptp_ok) << 13) | (u32::from(pps_ok) << 9)
    }

    /// The status in words, for operators: "normal, sync ptp" or "warning: temperature high, ...".
    pub fn describe(&self) -> String {
        let mut problems = Vec::new();
        let level = |v: u8| match v {
            1 => "warning",
            2 => "error",
            _ => "abnormal",
        };
        for (name, v) in [
            ("temperature", self.temperature),
            ("voltage", self.voltage),
            ("motor", self.motor),
            ("window dirty", self.dirty),
        ] {
            if v != 0 {
                problems.push(format!("{name} {}", level(v)));
            }
        }
        if self.firmware_error {
            problems.push("firmware error".into());
        }
        if self.end_of_service_life {
            problems.push("end of service life".into());
        }
        if self.fan_warning {
            problems.push("fan warning".into());
        }
        if self.self_heating {
            problems.push("self-heating".into());
        }
        let system = match self.system {
            SystemStatus::Normal => "normal",
            SystemStatus::Warning => "warning",
            SystemStatus::Error => "error",
            SystemStatus::Reserved => "unknown",
        };
        let sync = match self.sync {
            SyncState::None => "none".to_string(),
            SyncState::Ptp => "ptp".to_string(),
            SyncState::Gps => "gps".to_string(),
            SyncState::Pps => "pps".to_string(),
            SyncState::Abnormal => "abnormal".to_string(),
            SyncState::Reserved(v) => format!("reserved {v}"),
        };
        let mut text = format!("{system}, sync {sync}");
        if self.ptp_ok {
            text.push_str(", ptp signal ok");
        }
        if self.pps_ok {
            text.push_str(", pps ok");
        }
        if !problems.is_empty() {
            text.push_str(": ");
            text.push_str(&problems.join(", "));
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_decode_from_their_bits() {
        let s = StatusWord::from_raw((1 << 14) | (1 << 13) | (2 << 4) | (1 << 30) | (1 << 11));
        assert_eq!(s.sync, SyncState::Ptp);
        assert!(s.ptp_ok && s.fan_warning && !s.pps_ok);
        assert_eq!(s.motor, 2);
        assert_eq!(s.system, SystemStatus::Warning);
        assert_eq!(s.describe(), "warning, sync ptp, ptp signal ok: motor error, fan warning");
    }

    #[test]
    fn compose_is_read_back() {
        let raw = StatusWord::compose(SyncState::Gps, SystemStatus::Normal, false, true);
        let s = StatusWord::from_raw(raw);
        assert_eq!((s.sync, s.system, s.ptp_ok, s.pps_ok), (SyncState::Gps, SystemStatus::Normal, false, true));
    }
}
