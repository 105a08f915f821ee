//! slcan (Lawicel) adapters: the ASCII protocol ([`codec`]), line splitting ([`lines`]), the
//! host-side decoder ([`host`]) and the transport on a serial port or any byte stream
//! ([`serial`]).

pub mod bitrate;
pub mod codec;
pub mod host;
pub mod lines;
pub mod serial;
pub mod timestamp;

pub use codec::{decode_frame, Command, Reply, StatusFlags};
pub use host::{HostItem, SlcanHost};
pub use lines::{Line, LineSplitter};
pub use serial::{SlcanBus, SlcanOptions, SlcanSerial};
pub use timestamp::StampUnwrapper;
