//! MicroStrain MIP (3DM-GX5, CV7, ...): packets, IMU data, commands and replies, the stream
//! decoder.

pub mod command;
pub mod data;
pub mod packet;
pub mod stream;

pub use command::{FormatEntry, Function, MipCommand, MipReply, ReplyData};
pub use data::{GpsTime, MipData};
pub use packet::{fletcher16, Packet, PacketWriter};
pub use stream::MipDecoder;
