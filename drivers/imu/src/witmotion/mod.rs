//! WitMotion (WT901, HWT905, ...): output frames, configuration writes, the stream decoder.

pub mod config;
pub mod frame;
pub mod stream;

pub use config::{ConfigDecoder, ConfigWrite};
pub use frame::{WitFrame, WitTime};
pub use stream::{WitDecoder, WitGroup};
