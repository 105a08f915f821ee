//! One decoder type for either protocol.

use crate::mip::MipDecoder;
use crate::sample::{ImuEvent, Protocol};
use crate::stats::DecoderStats;
use crate::timing::Timestamper;
use crate::witmotion::WitDecoder;
use starc_time::Stamp;

/// A stream decoder for the protocol a port speaks (sans-IO: bytes and receive times in, events
/// out).
#[derive(Debug)]
pub enum ImuDecoder {
    Mip(MipDecoder),
    WitMotion(WitDecoder),
}

impl ImuDecoder {
    pub fn new(protocol: Protocol, timestamper: Timestamper) -> Self {
        match protocol {
            Protocol::Mip => ImuDecoder::Mip(MipDecoder::new(timestamper)),
            Protocol::WitMotion => ImuDecoder::WitMotion(WitDecoder::new(timestamper)),
        }
    }

    pub fn protocol(&self) -> Protocol {
        match self {
            ImuDecoder::Mip(_) => Protocol::Mip,
            ImuDecoder::WitMotion(_) => Protocol::WitMotion,
        }
    }

    /// Decodes `bytes` that a read returned at `host_receive`, appending events to `out`.
    pub fn push(&mut self, bytes: &[u8], host_receive: Stamp, out: &mut Vec<ImuEvent>) {
        match self {
            ImuDecoder::Mip(d) => d.push(bytes, host_receive, out),
            ImuDecoder::WitMotion(d) => d.push(bytes, host_receive, out),
        }
    }

    pub fn stats(&self) -> DecoderStats {
        match self {
            ImuDecoder::Mip(d) => d.stats(),
            ImuDecoder::WitMotion(d) => d.stats(),
        }
    }

    pub fn timestamper_mut(&mut self) -> &mut Timestamper {
        match self {
            ImuDecoder::Mip(d) => d.timestamper_mut(),
            ImuDecoder::WitMotion(d) => d.timestamper_mut(),
        }
    }
}
