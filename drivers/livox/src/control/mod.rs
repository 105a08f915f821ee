//! Livox SDK1 control protocol (UDP port 65000 on the device): framing and typed commands.

pub mod command;
pub mod frame;

pub use command::{
    Body, BroadcastCode, CommandId, ControlFrame, CoordinateSystem, DeviceType, Extrinsics, LidarMode, Message,
    Request, Response, ReturnMode, UtcTime,
};
pub use frame::{CmdType, RawFrame};
