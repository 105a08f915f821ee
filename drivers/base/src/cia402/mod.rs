//! CANopen CiA 402 drives in profile velocity mode: NMT and heartbeats ([`nmt`]), expedited SDO
//! ([`sdo`]), emergencies ([`emcy`]), the drive state machine ([`drive`]), the PDOs ([`pdo`]),
//! one drive's bring-up and supervision ([`node`]) and the group of a base ([`group`]).

pub mod drive;
pub mod emcy;
pub mod group;
pub mod nmt;
pub mod node;
pub mod pdo;
pub mod sdo;

pub use drive::DriveState;
pub use emcy::Emergency;
pub use group::Cia402Group;
pub use nmt::{NmtCommand, NmtState};
pub use node::{Cia402Config, Cia402Node};
pub use pdo::{VelocityCommand, VelocityStatus};
pub use sdo::{Address, SdoRequest, SdoResponse, Value};
