//! The UDP ports of Livox SDK1.

/// The device listens for commands on this port and broadcasts from it.
pub const DEVICE_CMD_PORT: u16 = 65000;
/// The host listens for broadcasts here.
pub const HOST_BROADCAST_PORT: u16 = 55000;

/// Host command port for host slot `n` (the SDK uses 55000 + 500 + n).
pub fn host_cmd_port(n: u16) -> u16 {
    55_500 + n
}

/// Host data (and IMU) port for host slot `n` (55000 + 1000 + n).
pub fn host_data_port(n: u16) -> u16 {
    56_000 + n
}
