//! The robot-to-rig link, sans-IO: the wire format of its messages ([`codec`]), the clock offset
//! between the two hosts from NTP-style probes ([`clock`]) and the link's health from heartbeats
//! ([`health`]). The transport (zenoh) lives in the `starc-link` crate; nothing here opens a socket.
//!
//! Every time stamp on the wire is nanoseconds of the sender's host realtime clock
//! (`starc_time::Clock::Host`); the receiver maps it into its own with [`ClockOffset`].

pub mod clock;
pub mod codec;
pub mod health;

pub use clock::{ClockOffset, OffsetEstimate};
pub use codec::{
    decode, encode, kind_name, map_tile_id, LinkMessage, LinkPerson, Role, HEADER_LEN, MAX_MESSAGE_BYTES, MAX_PEOPLE,
    MAX_POINTS_PER_MESSAGE,
};
pub use health::{HealthConfig, LinkHealth, LinkState};

#[cfg(test)]
mod tests;
