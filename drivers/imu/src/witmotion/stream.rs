//! The WitMotion stream decoder: bytes in any chunking, samples out.
//!
//! Resynchronisation: a candidate frame is any `0x55` followed by an output type; when its
//! checksum fails, only the `0x55` is skipped, so after a stray `0x55` (or a lost byte) the real
//! frame that follows is still found (PyPI `witmotion` drops it: it reads the real frame's
//! `0x55` as the type and gives up). An 8-bit sum lets about 1 in 256 misaligned windows pass,
//! so while hunting (after skipped bytes, or at start) a candidate is accepted only when the
//! byte after it is `0x55`: the next frame confirms it. In sync, frames are taken at once unless
//! the byte after is not `0x55` and a good frame starts inside the candidate (a frame that lost a
//! byte and passed the checksum by chance would eat that frame's start). Waiting for those
//! bytes delays a frame only while they have not arrived: always while hunting, and in sync for
//! the rare frame with an inner `0x55` followed by a frame type (under 1%).
//!
//! Frames of one output cycle come in ascending type order (0x50 time, 0x51 acc, 0x52 gyro,
//! 0x53 angle, 0x54 mag, ... 0x59 quaternion) and make one sample. A cycle ends at the type that
//! ended the previous cycle, when a type not above the last one starts the next cycle, or at a
//! run of 10 or more skipped bytes, which may hide a lost frame (frames across such a gap are
//! never merged; shorter garbage inside a cycle does not split it). Whole frames that vanish without a
//! trace across a cycle boundary (the end of one cycle and the start of the next) can still
//! merge two cycles into one sample; serial loss leaves bytes behind, so this needs a source
//! that drops whole frames.

use crate::sample::{ImuEvent, ImuSample, Incomplete, RawSample};
use crate::stats::DecoderStats;
use crate::stream::StreamCore;
use crate::timing::Timestamper;
use crate::witmotion::frame::{
    accel_m_s2, angle_rad, gyro_rad_s, is_output_type, quaternion_wxyz, WitFrame, WitTime, FRAME_LEN, HEADER,
    TYPE_ACCEL, TYPE_ANGLE, TYPE_GYRO, TYPE_MAG, TYPE_QUATERNION, TYPE_TIME,
};
use crate::ImuError;
use starc_time::Stamp;

/// Skipped bytes that may hide a lost frame (one that lost a byte is 10 bytes long).
const MIN_LOST_FRAME_LEN: u64 = FRAME_LEN as u64 - 1;

/// The raw frames of one output cycle.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WitGroup {
    pub time: Option<WitTime>,
    /// x, y, z, temperature (0.01 C).
    pub accel: Option<[i16; 4]>,
    /// x, y, z, temperature (0.01 C) or voltage, by model.
    pub gyro: Option<[i16; 4]>,
    /// roll, pitch, yaw, firmware version.
    pub angle: Option<[i16; 4]>,
    /// x, y, z (raw counts), temperature.
    pub mag: Option<[i16; 4]>,
    /// w, x, y, z.
    pub quaternion: Option<[i16; 4]>,
    /// Frames of other types in the cycle.
    pub other: u8,
}

impl WitGroup {
    fn add(&mut self, f: &WitFrame) {
        let v = f.values();
        match f.frame_type {
            TYPE_TIME => self.time = Some(WitTime::from_data(f.data)),
            TYPE_ACCEL => self.accel = Some(v),
            TYPE_GYRO => self.gyro = Some(v),
            TYPE_ANGLE => self.angle = Some(v),
            TYPE_MAG => self.mag = Some(v),
            TYPE_QUATERNION => self.quaternion = Some(v),
            _ => self.other = self.other.saturating_add(1),
        }
    }
}

/// The cycle being assembled.
#[derive(Debug, Default)]
struct Cycle {
    group: WitGroup,
    frames: usize,
    /// Measurement stamp and arrival of its first frame.
    first: Option<(Stamp, Stamp)>,
    last_type: Option<u8>,
    /// The type that ended the previous cycle.
    end_type: Option<u8>,
}

#[derive(Debug)]
pub struct WitDecoder {
    core: StreamCore,
    cycle: Cycle,
}

impl WitDecoder {
    pub fn new(timestamper: Timestamper) -> Self {
        Self { core: StreamCore::new(timestamper), cycle: Cycle::default() }
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
        let cycle = &mut self.cycle;
        self.core.push(bytes, host_receive, |core, buf| scan(core, buf, cycle, out));
    }
}

fn scan(core: &mut StreamCore, buf: &[u8], cycle: &mut Cycle, out: &mut Vec<ImuEvent>) -> usize {
    let mut pos = 0;
    loop {
        let rest = buf.get(pos..).unwrap_or_default();
        let Some(i) = rest.iter().position(|&b| b == HEADER) else {
            core.skip(rest.len());
            return buf.len();
        };
        core.skip(i);
        pos += i;
        let rest = buf.get(pos..).unwrap_or_default();
        match rest.get(1) {
            None => return pos,
            Some(&t) if !is_output_type(t) => {
                core.skip(1);
                pos += 1;
                continue;
            }
            Some(_) => {}
        }
        if rest.len() < FRAME_LEN {
            return pos;
        }
        let frame = match WitFrame::parse(rest) {
            Ok(frame) => frame,
            Err(e) => {
                if matches!(e, ImuError::WitChecksum { .. }) {
                    core.stats.bad_checksums += 1;
                }
                core.skip(1);
                pos += 1;
                continue;
            }
        };
        match decide(buf.get(pos..).unwrap_or_default(), core.synced()) {
            Decision::Wait => return pos,
            Decision::Reject => {
                core.skip(1);
                pos += 1;
                continue;
            }
            Decision::Accept => {}
        }
        let gap_bytes = core.frame();
        let arrival = core.arrival(pos + FRAME_LEN - 1);
        let stamp = core.timestamper.measured(arrival, FRAME_LEN);
        on_frame(core, cycle, &frame, gap_bytes, stamp, arrival, out);
        pos += FRAME_LEN;
    }
}

enum Decision {
    Accept,
    Reject,
    /// Not enough bytes to tell yet.
    Wait,
}

/// Whether the frame at the start of `rest` (its checksum passed) is taken.
///
/// Hunting, the next frame must confirm it (its `0x55` right after). In sync, it is taken unless
/// the byte after it is not `0x55` and a good frame starts inside it: then it is most likely a
/// frame that lost a byte, which passed the 8-bit checksum by chance, and taking it would eat
/// the start of the good frame.
fn decide(rest: &[u8], synced: bool) -> Decision {
    let next = rest.get(FRAME_LEN).copied();
    if next == Some(HEADER) {
        return Decision::Accept;
    }
    if !synced {
        return if next.is_none() { Decision::Wait } else { Decision::Reject };
    }
    for j in 1..FRAME_LEN {
        if rest.get(j) != Some(&HEADER) {
            continue;
        }
        match rest.get(j + 1) {
            None => return Decision::Wait,
            Some(&t) if !is_output_type(t) => continue,
            Some(_) => {}
        }
        match rest.get(j..j + FRAME_LEN) {
            None => return Decision::Wait,
            Some(inner) if WitFrame::parse(inner).is_ok() => return Decision::Reject,
            Some(_) => {}
        }
    }
    Decision::Accept
}

fn on_frame(
    core: &mut StreamCore,
    cycle: &mut Cycle,
    frame: &WitFrame,
    gap_bytes: u64,
    stamp: Stamp,
    arrival: Stamp,
    out: &mut Vec<ImuEvent>,
) {
    let t = frame.frame_type;
    if !matches!(t, TYPE_TIME | TYPE_ACCEL | TYPE_GYRO | TYPE_ANGLE | TYPE_MAG | TYPE_QUATERNION) {
        core.stats.unknown += 1;
    }
    if let Some(last) = cycle.last_type {
        if t <= last {
            // The next cycle starts: the last one ended at `last`.
            cycle.end_type = Some(last);
            emit(core, cycle, arrival, out);
        } else if gap_bytes >= MIN_LOST_FRAME_LEN {
            // A whole frame may have been lost since the last one (perhaps the end of this
            // cycle and the start of the next): never merge across such a gap.
            emit(core, cycle, arrival, out);
        }
    }
    if cycle.first.is_none() {
        cycle.first = Some((stamp, arrival));
    }
    cycle.group.add(frame);
    cycle.frames += 1;
    cycle.last_type = Some(t);
    if cycle.end_type == Some(t) {
        emit(core, cycle, arrival, out);
    }
}

fn emit(core: &mut StreamCore, cycle: &mut Cycle, last_arrival: Stamp, out: &mut Vec<ImuEvent>) {
    let group = std::mem::take(&mut cycle.group);
    let first = cycle.first.take();
    cycle.frames = 0;
    cycle.last_type = None;
    let (stamp, _) = first.unwrap_or((last_arrival, last_arrival));
    match sample(&group, stamp, last_arrival) {
        // WitMotion values are scaled i16s, always finite; checked all the same.
        Some(s) => core.deliver(s, out),
        None => {
            core.stats.incomplete += 1;
            out.push(ImuEvent::Incomplete(Incomplete { host_receive: last_arrival, raw: RawSample::WitMotion(group) }));
        }
    }
}

/// A sample from a cycle with both acceleration and angular rate.
pub fn sample(group: &WitGroup, stamp: Stamp, host_receive: Stamp) -> Option<ImuSample> {
    let (accel, gyro) = (group.accel?, group.gyro?);
    Some(ImuSample {
        stamp,
        host_receive,
        device_ns: group.time.and_then(WitTime::unix_ns),
        gyro_rad_s: gyro_rad_s(&gyro),
        accel_m_s2: accel_m_s2(&accel),
        orientation_wxyz: group.quaternion.as_ref().map(quaternion_wxyz),
        euler_rad: group.angle.as_ref().map(angle_rad),
        raw: RawSample::WitMotion(group.clone()),
    })
}
