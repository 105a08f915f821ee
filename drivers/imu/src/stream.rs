//! What both stream decoders share: a bounded buffer over the byte stream, the skip and resync
//! counters, and the time stamps of the reads.

use crate::sample::{ImuEvent, ImuSample};
use crate::stats::DecoderStats;
use crate::timing::Timestamper;
use starc_time::Stamp;

/// Bytes held at most: a few of the longest MIP packets. Input is taken in pieces that fit, so
/// nothing is ever allocated from a length on the wire.
pub(crate) const BUFFER_LEN: usize = 1024;

#[derive(Debug)]
pub(crate) struct StreamCore {
    pub buf: Vec<u8>,
    /// Stream offset of `buf[0]`.
    pub start: u64,
    /// Bytes pushed so far (the stream offset one past the last byte).
    pub received: u64,
    /// Inside a run of skipped bytes (counted as one resync).
    in_gap: bool,
    /// Bytes skipped since the last good frame.
    gap_bytes: u64,
    pub stats: DecoderStats,
    pub timestamper: Timestamper,
}

impl StreamCore {
    pub fn new(timestamper: Timestamper) -> Self {
        Self {
            buf: Vec::with_capacity(BUFFER_LEN),
            start: 0,
            received: 0,
            in_gap: false,
            gap_bytes: 0,
            stats: DecoderStats::default(),
            timestamper,
        }
    }

    /// Feeds `bytes` read at `host_receive` in pieces that fit the buffer; `scan` gets the
    /// buffered bytes, consumes what it can from their front and returns how many it consumed.
    pub fn push(&mut self, bytes: &[u8], host_receive: Stamp, mut scan: impl FnMut(&mut Self, &[u8]) -> usize) {
        self.stats.bytes += bytes.len() as u64;
        self.received += bytes.len() as u64;
        self.timestamper.chunk(self.received, host_receive.ns);
        let mut rest = bytes;
        while !rest.is_empty() {
            let room = BUFFER_LEN.saturating_sub(self.buf.len()).max(1);
            let (now, later) = rest.split_at(room.min(rest.len()));
            self.buf.extend_from_slice(now);
            rest = later;
            let buf = std::mem::take(&mut self.buf);
            let used = scan(self, &buf).min(buf.len());
            self.buf = buf;
            self.buf.drain(..used);
            self.start += used as u64;
            self.timestamper.consumed(self.start);
        }
    }

    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// Counts `n` bytes that belong to no frame.
    pub fn skip(&mut self, n: usize) {
        if n == 0 {
            return;
        }
        if !self.in_gap {
            self.stats.resyncs += 1;
            self.in_gap = true;
        }
        self.stats.skipped_bytes += n as u64;
        self.gap_bytes += n as u64;
    }

    /// A good frame: sync is back. Returns the bytes skipped since the last good frame.
    pub fn frame(&mut self) -> u64 {
        let gap = std::mem::take(&mut self.gap_bytes);
        self.in_gap = false;
        self.stats.frames += 1;
        gap
    }

    /// Whether the last bytes consumed were a good frame (no skip since).
    pub fn synced(&self) -> bool {
        !self.in_gap && self.stats.frames > 0
    }

    /// Hands `sample` out and counts it, unless a rate or an acceleration is NaN or infinite:
    /// then it is dropped and counted (`non_finite`). A non-finite orientation only loses the
    /// orientation (`non_finite_orientation`): the LIO needs the rates, not the device's filter.
    /// The raw values stay as the device sent them.
    pub fn deliver(&mut self, mut sample: ImuSample, out: &mut Vec<ImuEvent>) {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(finite(&sample.gyro_rad_s) && finite(&sample.accel_m_s2)) {
            self.stats.non_finite += 1;
            return;
        }
        let mut trimmed = false;
        if sample.orientation_wxyz.is_some_and(|q| !finite(&q)) {
            sample.orientation_wxyz = None;
            trimmed = true;
        }
        if sample.euler_rad.is_some_and(|e| !finite(&e)) {
            sample.euler_rad = None;
            trimmed = true;
        }
        self.stats.non_finite_orientation += u64::from(trimmed);
        self.stats.samples += 1;
        out.push(ImuEvent::Sample(sample));
    }

    /// Host arrival of the byte at buffer position `pos`.
    pub fn arrival(&self, pos: usize) -> Stamp {
        self.timestamper.arrival(self.start + pos as u64)
    }
}
