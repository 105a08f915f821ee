//! DJI C620 ESC frames (M3508 motors), 1 Mbit/s, 11-bit ids, big-endian.
//!
//! Commands: `0x200` carries four i16 currents for ESC 1-4, `0x1FF` for ESC 5-8;
//! -16384..16384 = -20..20 A. Feedback from ESC k on `0x200 + k` at 1 kHz: rotor angle u16
//! (0..8191 = 360 deg), rotor speed i16 rpm, actual current i16 (same scale), temperature u8 C.

use crate::error::{bytes, need, BaseError, Result};
use starc_can::{CanFrame, CanId};

/// Id of the current command for ESC 1-4.
pub const COMMAND_LOW_ID: u16 = 0x200;
/// Id of the current command for ESC 5-8.
pub const COMMAND_HIGH_ID: u16 = 0x1FF;
/// Feedback of ESC k (1-8) is `FEEDBACK_BASE_ID + k`.
pub const FEEDBACK_BASE_ID: u16 = 0x200;
/// Full-scale raw current.
pub const CURRENT_RAW_MAX: i16 = 16384;
/// Full-scale current in amperes.
pub const CURRENT_MAX_A: f64 = 20.0;
/// The M3508's planetary gearbox: rotor turns per output turn.
pub const M3508_GEAR_RATIO: f64 = 3591.0 / 187.0;
/// Rotor angle counts per turn.
pub const ANGLE_COUNTS: u16 = 8192;

/// Amperes to the raw command value, clamped to +-20 A.
pub fn current_to_raw(current_a: f64) -> i16 {
    if !current_a.is_finite() {
        return 0;
    }
    let raw = (current_a / CURRENT_MAX_A * f64::from(CURRENT_RAW_MAX)).round();
    raw.clamp(-f64::from(CURRENT_RAW_MAX), f64::from(CURRENT_RAW_MAX)) as i16
}

/// The raw current value in amperes.
pub fn raw_to_current(raw: i16) -> f64 {
    f64::from(raw) * CURRENT_MAX_A / f64::from(CURRENT_RAW_MAX)
}

/// Which of the two command frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandGroup {
    /// ESC 1-4 on 0x200.
    Low,
    /// ESC 5-8 on 0x1FF.
    High,
}

impl CommandGroup {
    pub fn id(self) -> u16 {
        match self {
            Self::Low => COMMAND_LOW_ID,
            Self::High => COMMAND_HIGH_ID,
        }
    }

    /// The group and slot (0-3) of ESC `esc` (1-8).
    pub fn of(esc: u8) -> Option<(Self, usize)> {
        match esc {
            1..=4 => Some((Self::Low, usize::from(esc - 1))),
            5..=8 => Some((Self::High, usize::from(esc - 5))),
            _ => None,
        }
    }
}

/// One current command frame: raw currents for four ESCs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CurrentCommand {
    pub group: CommandGroup,
    pub raw: [i16; 4],
}

impl CurrentCommand {
    pub fn to_frame(&self) -> Result<CanFrame> {
        let mut data = [0u8; 8];
        for (chunk, value) in data.chunks_exact_mut(2).zip(self.raw) {
            chunk.copy_from_slice(&value.to_be_bytes());
        }
        Ok(CanFrame::standard(self.group.id(), &data)?)
    }

    /// Parses a command frame (the mock ESCs read these).
    pub fn parse(frame: &CanFrame) -> Result<Self> {
        let group = match frame.id() {
            CanId::Standard(COMMAND_LOW_ID) => CommandGroup::Low,
            CanId::Standard(COMMAND_HIGH_ID) => CommandGroup::High,
            id => return Err(BaseError::WrongId { what: "C620 command", id: id.raw() }),
        };
        if frame.is_remote() {
            return Err(BaseError::malformed("C620 command", "remote frame"));
        }
        let data = frame.data();
        need("C620 command", data, 8)?;
        let mut raw = [0i16; 4];
        for (k, slot) in raw.iter_mut().enumerate() {
            *slot = i16::from_be_bytes(bytes(data, 2 * k));
        }
        Ok(Self { group, raw })
    }
}

/// One feedback frame of one ESC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Feedback {
    /// 1-8.
    pub esc: u8,
    /// Rotor angle, 0..8191 = 0..360 deg.
    pub angle_raw: u16,
    /// Rotor speed (before the gearbox) in rpm.
    pub rotor_rpm: i16,
    /// Actual current, raw (-16384..16384 = -20..20 A).
    pub current_raw: i16,
    pub temperature_c: u8,
}

impl Feedback {
    /// Parses a feedback frame (`0x201`..`0x208`, 8 data bytes, angle within 0..8191).
    pub fn parse(frame: &CanFrame) -> Result<Self> {
        let id = frame.id();
        let esc = match id {
            CanId::Standard(raw @ 0x201..=0x208) => (raw - FEEDBACK_BASE_ID) as u8,
            other => return Err(BaseError::WrongId { what: "C620 feedback", id: other.raw() }),
        };
        if frame.is_remote() {
            return Err(BaseError::malformed("C620 feedback", "remote frame"));
        }
        let data = frame.data();
        need("C620 feedback", data, 7)?;
        let angle_raw = u16::from_be_bytes(bytes(data, 0));
        if angle_raw >= ANGLE_COUNTS {
            return Err(BaseError::malformed("C620 feedback", format!("angle {angle_raw} is not below 8192")));
        }
        Ok(Self {
            esc,
            angle_raw,
            rotor_rpm: i16::from_be_bytes(bytes(data, 2)),
            current_raw: i16::from_be_bytes(bytes(data, 4)),
            temperature_c: data.get(6).copied().unwrap_or(0),
        })
    }

    pub fn to_frame(&self) -> Result<CanFrame> {
        let mut data = [0u8; 8];
        data[..2].copy_from_slice(&self.angle_raw.to_be_bytes());
        data[2..4].copy_from_slice(&self.rotor_rpm.to_be_bytes());
        data[4..6].copy_from_slice(&self.current_raw.to_be_bytes());
        data[6] = self.temperature_c;
        Ok(CanFrame::standard(FEEDBACK_BASE_ID + u16::from(self.esc), &data)?)
    }

    /// Output-shaft speed in rad/s for a gearbox of `gear_ratio` rotor turns per output turn.
    pub fn output_rad_s(&self, gear_ratio: f64) -> f64 {
        f64::from(self.rotor_rpm) * std::f64::consts::TAU / 60.0 / gear_ratio
    }

    pub fn current_a(&self) -> f64 {
        raw_to_current(self.current_raw)
    }

    pub fn angle_rad(&self) -> f64 {
        f64::from(self.angle_raw) * std::f64::consts::TAU / f64::from(ANGLE_COUNTS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_layout_is_big_endian() -> Result<()> {
        let cmd = CurrentCommand { group: CommandGroup::Low, raw: [500, -500, 16384, -16384] };
        let f = cmd.to_frame()?;
        assert_eq!(f.to_string(), "200#01F4FE0C4000C000");
        assert_eq!(CurrentCommand::parse(&f)?, cmd);
        assert_eq!(current_to_raw(10.0), 8192);
        assert_eq!(current_to_raw(-99.0), -16384);
        assert_eq!(current_to_raw(f64::NAN), 0);
        assert!((raw_to_current(-8192) + 10.0).abs() < 1e-12);
        Ok(())
    }

    #[test]
    fn feedback_parses_and_converts() -> Result<()> {
        let f = CanFrame::standard(0x203, &[0x1F, 0xFF, 0x0E, 0x10, 0x02, 0x00, 0x24, 0x00])?;
        let fb = Feedback::parse(&f)?;
        assert_eq!((fb.esc, fb.angle_raw, fb.rotor_rpm, fb.current_raw, fb.temperature_c), (3, 8191, 3600, 512, 36));
        // 3600 rpm at the rotor is 187.47 rpm at the output.
        let out_rpm = fb.output_rad_s(M3508_GEAR_RATIO) * 60.0 / std::f64::consts::TAU;
        assert!((out_rpm - 3600.0 * 187.0 / 3591.0).abs() < 1e-9);
        assert_eq!(Feedback::parse(&fb.to_frame()?)?, fb);
        Ok(())
    }

    #[test]
    fn bad_feedback_is_refused() -> Result<()> {
        assert!(Feedback::parse(&CanFrame::standard(0x209, &[0; 8])?).is_err());
        assert!(Feedback::parse(&CanFrame::standard(0x201, &[0; 6])?).is_err());
        assert!(Feedback::parse(&CanFrame::standard(0x201, &[0x20, 0, 0, 0, 0, 0, 0, 0])?).is_err());
        assert!(Feedback::parse(&CanFrame::remote(CanId::Standard(0x201), 8)?).is_err());
        assert!(CurrentCommand::parse(&CanFrame::standard(0x200, &[0; 7])?).is_err());
        Ok(())
    }
}
