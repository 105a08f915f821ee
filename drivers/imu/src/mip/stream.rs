//! The MIP stream decoder: bytes in any chunking, events out.
//!
//! Resynchronisation: a candidate packet starts at `0x75 0x65`; when its checksum fails only its
//! first byte is skipped and the search goes on from the next byte, so a good packet that starts
//! inside a bad candidate (garbage with a sync pair in it, or a packet cut short by a lost byte)
//! is still found. A candidate whose length runs past the bytes received so far is dropped as
//! soon as a whole good packet is seen inside it, so a false header with a long length does not
//! hold good packets back. Fletcher-16 lets about 1 in 65536 damaged candidates pass.

use crate::mip::command::{MipReply, BASE_SET, DM3_SET};
use crate::mip::data::{MipData, IMU_DATA_SET};
use crate::mip::packet::{Packet, CHECKSUM_LEN, HEADER_LEN, SYNC1, SYNC2};
use crate::sample::{ImuEvent, ImuSample, Incomplete, RawSample, STANDARD_GRAVITY_M_S2};
use crate::stats::DecoderStats;
use crate::stream::StreamCore;
use crate::timing::Timestamper;
use crate::ImuError;
use starc_time::Stamp;

#[derive(Debug)]
pub struct MipDecoder {
    core: StreamCore,
    replies: Vec<MipReply>,
}

impl MipDecoder {
    pub fn new(timestamper: Timestamper) -> Self {
        Self { core: StreamCore::new(timestamper), replies: Vec::new() }
    }

    pub fn stats(&self) -> DecoderStats {
        self.core.stats
    }

    pub fn timestamper_mut(&mut self) -> &mut Timestamper {
        &mut self.core.timestamper
    }

    /// Bytes held back (an incomplete frame), never more than a few maximum frames.
    pub fn buffered(&self) -> usize {
        self.core.buffered()
    }

    /// Decodes `bytes` read at `host_receive`, appending events to `out`.
    pub fn push(&mut self, bytes: &[u8], host_receive: Stamp, out: &mut Vec<ImuEvent>) {
        let replies = &mut self.replies;
        self.core.push(bytes, host_receive, |core, buf| scan(core, buf, replies, out));
    }
}

/// Consumes whole packets and garbage from the front of the buffer; stops at an incomplete
/// candidate. Returns the bytes consumed.
fn scan(core: &mut StreamCore, buf: &[u8], replies: &mut Vec<MipReply>, out: &mut Vec<ImuEvent>) -> usize {
    let mut pos = 0;
    loop {
        let rest = buf.get(pos..).unwrap_or_default();
        let Some(i) = rest.iter().position(|&b| b == SYNC1) else {
            core.skip(rest.len());
            return buf.len();
        };
        core.skip(i);
        pos += i;
        let rest = buf.get(pos..).unwrap_or_default();
        match rest.get(1) {
            None => return pos,
            Some(&b) if b != SYNC2 => {
                core.skip(1);
                pos += 1;
                continue;
            }
            Some(_) => {}
        }
        let Some(&len) = rest.get(3) else { return pos };
        let total = HEADER_LEN + usize::from(len) + CHECKSUM_LEN;
        if rest.len() < total {
            if holds_good_packet(rest) {
                // A false header with a long length: a whole good packet inside it proves it
                // false now, rather than after up to 261 bytes.
                core.skip(1);
                pos += 1;
                continue;
            }
            return pos;
        }
        match Packet::parse(rest) {
            Ok((packet, n)) => {
                let _ = core.frame();
                let arrival = core.arrival(pos + n - 1);
                handle(core, &packet, n, arrival, replies, out);
                pos += n;
            }
            Err(ImuError::BadChecksum { .. }) => {
                core.stats.bad_checksums += 1;
                core.skip(1);
                pos += 1;
            }
            Err(_) => {
                core.skip(1);
                pos += 1;
            }
        }
    }
}

/// Whether a complete packet with a good checksum starts after the first byte of `rest`.
fn holds_good_packet(rest: &[u8]) -> bool {
    let mut from = 1;
    while let Some(i) = rest.get(from..).and_then(|r| r.windows(2).position(|w| w == [SYNC1, SYNC2])) {
        if rest.get(from + i..).is_some_and(|p| Packet::parse(p).is_ok()) {
            return true;
        }
        from += i + 1;
    }
    false
}

fn handle(
    core: &mut StreamCore,
    packet: &Packet<'_>,
    len: usize,
    arrival: Stamp,
    replies: &mut Vec<MipReply>,
    out: &mut Vec<ImuEvent>,
) {
    match packet.descriptor_set {
        IMU_DATA_SET => match MipData::decode(packet) {
            Ok(data) => {
                core.stats.unknown += u64::from(data.unknown_fields);
                match sample(&data, core.timestamper.measured(arrival, len), arrival) {
                    Some(s) => core.deliver(s, out),
                    None => {
                        core.stats.incomplete += 1;
                        out.push(ImuEvent::Incomplete(Incomplete { host_receive: arrival, raw: RawSample::Mip(data) }));
                    }
                }
            }
            Err(_) => core.stats.malformed += 1,
        },
        BASE_SET | DM3_SET => {
            replies.clear();
            match MipReply::decode_all(packet, replies) {
                Ok(()) => {
                    core.stats.replies += replies.len() as u64;
                    out.extend(replies.drain(..).map(ImuEvent::MipReply));
                }
                Err(_) => core.stats.malformed += 1,
            }
        }
        _ => core.stats.unknown += 1,
    }
}

/// A sample from a packet with both accel and gyro.
pub fn sample(data: &MipData, stamp: Stamp, host_receive: Stamp) -> Option<ImuSample> {
    let (accel, gyro) = (data.accel_g?, data.gyro_rad_s?);
    Some(ImuSample {
        stamp,
        host_receive,
        device_ns: data.gps_time.and_then(|t| t.gps_ns()),
        gyro_rad_s: gyro.map(f64::from),
        accel_m_s2: accel.map(|g| f64::from(g) * STANDARD_GRAVITY_M_S2),
        orientation_wxyz: data.quaternion.map(|q| q.map(f64::from)),
        euler_rad: data.euler_rad.map(|e| e.map(f64::from)),
        raw: RawSample::Mip(data.clone()),
    })
}
