//! Livox SDK1 data packets: points (types 0-8 but 6), IMU (type 6), status and time stamps.

pub mod gaps;
pub mod packet;
pub mod status;
pub mod timestamp;

pub use gaps::{Gap, GapDetector};
pub use packet::{
    encode_imu_packet, encode_point_packet, packet_len_for, DataHeader, DataPacket, DataType, ImuSample, Point, Return,
    ReturnCounts,
};
pub use status::{StatusWord, SyncState, SystemStatus};
