//! The CiA 402 drive state machine as the statusword shows it, and the controlword commands.

use serde::Serialize;

/// Objects of the drive profile this driver uses.
pub mod object {
    pub const CONTROLWORD: u16 = 0x6040;
    pub const STATUSWORD: u16 = 0x6041;
    pub const MODES_OF_OPERATION: u16 = 0x6060;
    pub const MODES_DISPLAY: u16 = 0x6061;
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    pub const SUPPORTED_MODES: u16 = 0x6502;
    pub const DEVICE_TYPE: u16 = 0x1000;
    pub const ERROR_REGISTER: u16 = 0x1001;
    pub const HEARTBEAT_PRODUCER: u16 = 0x1017;
    /// Consumer heartbeat time (CiA 301): sub 1.. = node id << 16 | time in ms.
    pub const CONSUMER_HEARTBEAT: u16 = 0x1016;
    /// Abort connection option code (CiA 402, INTEGER16): what the drive does when the
    /// connection to the host is lost (heartbeat consumer time-out, bus-off, NMT stop...).
    pub const ABORT_CONNECTION_OPTION: u16 = 0x6007;
    pub const RPDO1_COMM: u16 = 0x1400;
    pub const RPDO1_MAP: u16 = 0x1600;
    pub const TPDO1_COMM: u16 = 0x1800;
    pub const TPDO1_MAP: u16 = 0x1A00;
}

/// Values of 0x6007, the abort connection option code (CiA 402; negative values are
/// manufacturer-specific).
pub mod abort_connection {
    pub const NO_ACTION: i16 = 0;
    /// Fault signal: the drive goes through Fault Reaction Active to Fault.
    pub const FAULT: i16 = 1;
    /// Disable voltage command: the power stage is switched off and the motor coasts.
    pub const DISABLE_VOLTAGE: i16 = 2;
    /// Quick stop command: the drive brakes on its quick-stop ramp.
    pub const QUICK_STOP: i16 = 3;
}

/// Profile velocity mode (0x6060 = 3).
pub const PROFILE_VELOCITY_MODE: i8 = 3;

/// Controlword commands.
pub mod controlword {
    pub const SHUTDOWN: u16 = 0x0006;
    pub const SWITCH_ON: u16 = 0x0007;
    pub const ENABLE_OPERATION: u16 = 0x000F;
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    pub const QUICK_STOP: u16 = 0x0002;
    pub const FAULT_RESET: u16 = 0x0080;
}

/// The states of the CiA 402 power state machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriveState {
    NotReadyToSwitchOn,
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
    QuickStopActive,
    FaultReactionActive,
    Fault,
}

impl DriveState {
    /// Decodes the statusword (CiA 402 table: masks 0x4F / 0x6F).
    pub fn from_statusword(sw: u16) -> Option<Self> {
        Some(match (sw & 0x4F, sw & 0x6F) {
            (0x00, _) => Self::NotReadyToSwitchOn,
            (0x40, _) => Self::SwitchOnDisabled,
            (_, 0x21) => Self::ReadyToSwitchOn,
            (_, 0x23) => Self::SwitchedOn,
            (_, 0x27) => Self::OperationEnabled,
            (_, 0x07) => Self::QuickStopActive,
            (0x0F, _) => Self::FaultReactionActive,
            (0x08, _) => Self::Fault,
            _ => return None,
        })
    }

    /// A statusword showing this state (what a drive would send; bit 4 "voltage enabled" and
    /// bit 9 "remote" set where a real drive sets them).
    pub fn statusword(self) -> u16 {
        let remote = 0x0200;
        match self {
            Self::NotReadyToSwitchOn => remote,
            Self::SwitchOnDisabled => 0x0040 | remote,
            Self::ReadyToSwitchOn => 0x0021 | 0x0010 | remote,
            Self::SwitchedOn => 0x0023 | 0x0010 | remote,
            Self::OperationEnabled => 0x0027 | 0x0010 | remote,
            Self::QuickStopActive => 0x0007 | 0x0010 | remote,
            Self::FaultReactionActive => 0x000F | 0x0010 | remote,
            Self::Fault => 0x0008 | remote,
        }
    }

    /// Enabled as the protocol sheet defines it: `sw & 0x6F == 0x27`.
    pub fn is_enabled(sw: u16) -> bool {
        sw & 0x6F == 0x27
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statuswords_decode_to_their_states() {
        for s in [
            DriveState::NotReadyToSwitchOn,
            DriveState::SwitchOnDisabled,
            DriveState::ReadyToSwitchOn,
            DriveState::SwitchedOn,
            DriveState::OperationEnabled,
            DriveState::QuickStopActive,
            DriveState::FaultReactionActive,
            DriveState::Fault,
        ] {
            assert_eq!(DriveState::from_statusword(s.statusword()), Some(s), "{s:?}");
        }
        assert_eq!(DriveState::from_statusword(0x0637), Some(DriveState::OperationEnabled));
        assert!(DriveState::is_enabled(0x1237));
        assert!(!DriveState::is_enabled(0x0233));
        assert_eq!(DriveState::from_statusword(0x0001), None);
    }
}
