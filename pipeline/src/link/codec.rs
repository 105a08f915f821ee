//! The link's wire format: one self-contained, length-checked and CRC'd frame per message.
//!
//! Frame, little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 4 | magic `STLK` |
//! | 1 | format version (3; version 2 is still read) |
//! | 1 | kind (1 heartbeat, 2 clock probe, 3 clock reply, 4 robot pose, 5 detections, 6 map tile) |
//! | 2 | reserved (0) |
//! | 4 | payload length n (at most [`MAX_MESSAGE_BYTES`] for the whole frame) |
//! | n | payload (per kind, below) |
//! | 4 | CRC-32 (ISO-HDLC, as zlib) of everything before it |
//!
//! Payloads:
//!
//! | kind | payload |
//! |---|---|
//! | heartbeat | u8 role (1 robot, 2 rig), 3 reserved (0), u32 seq, u64 sent_host_ns, u32 map_tiles |
//! | clock probe | u32 seq, u64 t1_ns |
//! | clock reply | u32 seq, u64 t1_ns, t2_ns, t3_ns |
//! | robot pose | u64 stamp_ns, u8 stamp clock, f64 x, y, z, f64 qi, qj, qk, qw (world_T_lidar) |
//! | detections | u32 seq, u64 stamp_ns, u8 stamp clock, u64 scan_last_packet_host_ns, u64 sent_host_ns, u32 people; per person: f32 score, u8 posture (version 3 only: 0 unknown, 1 upright, 2 sitting or crouching, 3 lying), f64 centre x, y, z, f64 length, width, height, f64 yaw_rad, u32 points, then f32 x, y, z per point (world) |
//! | map tile | one tile of `align::tiles`, byte for byte (it has its own version and CRC) |
//!
//! A stamp clock is 1 device (free-running), 2 PTP, 3 GPS, 4 PPS, 5 host: a robot LiDAR stamp
//! travels with the clock it was read on, so the rig never takes one clock's time for another's.
//!
//! Bounded: a frame is at most [`MAX_MESSAGE_BYTES`], a detections message holds at most
//! [`MAX_PEOPLE`] people and [`MAX_POINTS_PER_MESSAGE`] points; every count is checked against
//! the bytes actually present before anything is allocated. Non-finite numbers are refused both
//! ways, so what decodes can be drawn.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::align::decode_tile;
use crate::ar::{ArPerson, OrientedBox};
use crate::detect::{Detection, PersonPose, WindowPoint};
use crate::PipelineError;
use starc_time::{Clock, Stamp};

const MAGIC: &[u8; 4] = b"STLK";
const VERSION: u8 = 3;
/// The previous version, still read: its people carry no posture.
const VERSION_NO_POSTURE: u8 = 2;
/// Frame header: magic, version, kind, reserved, payload length.
pub const HEADER_LEN: usize = 12;
const CRC_LEN: usize = 4;
/// Largest frame accepted (bytes): room for the largest map tile (about 10.5 MB).
pub const MAX_MESSAGE_BYTES: usize = 16 << 20;
/// Most people in one detections message.
pub const MAX_PEOPLE: usize = 1024;
/// Most points (all people together) in one detections message.
pub const MAX_POINTS_PER_MESSAGE: usize = 1 << 20;
/// A person's fixed part in version 2 (version 3 adds the posture byte).
const PERSON_HEADER_LEN: usize = 4 + 7 * 8 + 4;
const POINT_LEN: usize = 12;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
const FORMAT: &str = "link message";

const KIND_HEARTBEAT: u8 = 1;
const KIND_CLOCK_PROBE: u8 = 2;
const KIND_CLOCK_REPLY: u8 = 3;
const KIND_ROBOT_POSE: u8 = 4;
const KIND_DETECTIONS: u8 = 5;
const KIND_MAP_TILE: u8 = 6;

/// Which end of the link sent a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Role {
    /// The robot: LIO, detection, the map.
    Robot,
    /// The responder's rig: the AR display.
    Rig,
}

impl Role {
    pub fn name(self) -> &'static str {
        match self {
            Role::Robot => "robot",
            Role::Rig => "rig",
        }
    }

    /// The other end.
    pub fn peer(self) -> Role {
        match self {
            Role::Robot => Role::Rig,
            Role::Rig => Role::Robot,
        }
    }
}

/// One detected person as sent: box, score and the person's points in the world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkPerson {
    /// Confidence in [0, 1].
    pub score: f32,
    pub bbox: OrientedBox,
    /// The posture the robot's detector judged (`None` from a version 2 sender).
    pub pose: Option<PersonPose>,
    /// The person's points, world frame (the robot's map frame), metres.
    pub points_world: Vec<[f32; 3]>,
}

impl LinkPerson {
    /// From a detector output and the window it was found in (its `point_indices` index
    /// `window_points`; indices past the end are skipped).
    pub fn from_detection(d: &Detection, window_points: &[WindowPoint]) -> Self {
        let points_world = d
            .point_indices
            .iter()
            .filter_map(|&i| window_points.get(i as usize))
            .map(|p| [p.x_m, p.y_m, p.z_m])
            .collect();
        Self {
            score: d.score as f32,
            bbox: OrientedBox { centre_m: d.centre_m, size_m: d.size_m, yaw_rad: d.yaw_rad },
            pose: Some(d.pose),
            points_world,
        }
    }

    /// What the AR renderer draws, `age_ns` old at render time.
    pub fn to_ar_person(&self, age_ns: u64) -> ArPerson {
        ArPerson {
            points_world: self
                .points_world
                .iter()
                .map(|p| Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
                .collect(),
            bbox: Some(self.bbox),
            age_ns,
            pose: self.pose,
        }
    }
}

/// Everything the robot and the rig say to each other. All `*_ns` are the sender's host
/// realtime clock unless named otherwise.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkMessage {
    /// Sent by both ends every heartbeat period; `map_tiles` is how many map tiles the sender
    /// holds (the robot: tiles published; the rig: 0 or what it has applied), so a rig that
    /// holds fewer than the robot knows to fetch the map again.
    Heartbeat { role: Role, seq: u32, sent_host_ns: u64, map_tiles: u32 },
    /// NTP-style probe: `t1_ns` is the prober's clock at sending.
    ClockProbe { seq: u32, t1_ns: u64 },
    /// The answer: the probe's `t1_ns`, the answerer's clock at receiving it (`t2_ns`) and at
    /// sending this reply (`t3_ns`). The prober adds `t4` on receipt.
    ClockReply { seq: u32, t1_ns: u64, t2_ns: u64, t3_ns: u64 },
    /// The robot's LiDAR pose in the map (world) frame at `stamp` (the robot LiDAR's clock).
    RobotPose { stamp: Stamp, world_t_lidar: Isometry3<f64> },
    /// People found in one scan window: `stamp` is the scan's end on the robot LiDAR's clock,
    /// `scan_last_packet_host_ns` when its last packet arrived and `sent_host_ns` when this
    /// message left (both robot host clock), so the rig can split the end-to-end latency into
    /// detection and transport.
    Detections { seq: u32, stamp: Stamp, scan_last_packet_host_ns: u64, sent_host_ns: u64, people: Vec<LinkPerson> },
    /// One tile of the map in the `align::tiles` format (apply it with `align::TileMap::apply`).
    MapTile { bytes: Vec<u8> },
}

/// The kind's short name, as used in link keys (`<prefix>/<role>/<kind>`).
pub fn kind_name(m: &LinkMessage) -> &'static str {
    match m {
        LinkMessage::Heartbeat { .. } => "heartbeat",
        LinkMessage::ClockProbe { .. } => "clock_probe",
        LinkMessage::ClockReply { .. } => "clock_reply",
        LinkMessage::RobotPose { .. } => "pose",
        LinkMessage::Detections { .. } => "detections",
        LinkMessage::MapTile { .. } => "map_tile",
    }
}

/// The key and version of a map tile's bytes (from its header, unchecked: call it on tiles that
/// [`decode`] or `align::decode_tile` accepted), for a sender that keeps the newest of each.
pub fn map_tile_id(tile: &[u8]) -> Option<((i32, i32, i32), u32)> {
    let word = |at: usize| tile.get(at..at + 4).and_then(|s| s.try_into().ok()).map(u32::from_le_bytes);
    Some(((word(12)? as i32, word(16)? as i32, word(20)? as i32), word(24)?))
}

fn bad(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: FORMAT, reason: reason.into() }
}

fn finite(values: &[f64], what: &str) -> Result<(), PipelineError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(bad(format!("{what} is not finite")))
    }
}

fn posture_byte(pose: Option<PersonPose>) -> u8 {
    match pose {
        None => 0,
        Some(PersonPose::Upright) => 1,
        Some(PersonPose::Low) => 2,
        Some(PersonPose::Lying) => 3,
    }
}

fn posture_from_byte(b: u8) -> Result<Option<PersonPose>, PipelineError> {
    Ok(match b {
        0 => None,
        1 => Some(PersonPose::Upright),
        2 => Some(PersonPose::Low),
        3 => Some(PersonPose::Lying),
        other => return Err(bad(format!("unknown posture {other}"))),
    })
}

fn put_stamp(p: &mut Vec<u8>, stamp: &Stamp) {
    p.extend_from_slice(&stamp.ns.to_le_bytes());
    p.push(match stamp.clock {
        Clock::Device => 1,
        Clock::Ptp => 2,
        Clock::Gps => 3,
        Clock::Pps => 4,
        Clock::Host => 5,
    });
}

/// Encodes one message into a frame. Refuses (typed error) what the decoder would refuse:
/// non-finite numbers, more than [`MAX_PEOPLE`] people or [`MAX_POINTS_PER_MESSAGE`] points,
/// a damaged map tile, a frame over [`MAX_MESSAGE_BYTES`].
pub fn encode(m: &LinkMessage) -> Result<Vec<u8>, PipelineError> {
    let mut p = Vec::new();
    let kind = match m {
        LinkMessage::Heartbeat { role, seq, sent_host_ns, map_tiles } => {
            p.push(match role {
                Role::Robot => 1,
                Role::Rig => 2,
            });
            p.extend_from_slice(&[0; 3]);
            p.extend_from_slice(&seq.to_le_bytes());
            p.extend_from_slice(&sent_host_ns.to_le_bytes());
            p.extend_from_slice(&map_tiles.to_le_bytes());
            KIND_HEARTBEAT
        }
        LinkMessage::ClockProbe { seq, t1_ns } => {
            p.extend_from_slice(&seq.to_le_bytes());
            p.extend_from_slice(&t1_ns.to_le_bytes());
            KIND_CLOCK_PROBE
        }
        LinkMessage::ClockReply { seq, t1_ns, t2_ns, t3_ns } => {
            p.extend_from_slice(&seq.to_le_bytes());
            for t in [t1_ns, t2_ns, t3_ns] {
                p.extend_from_slice(&t.to_le_bytes());
            }
            KIND_CLOCK_REPLY
        }
        LinkMessage::RobotPose { stamp, world_t_lidar } => {
            let t = world_t_lidar.translation.vector;
            let q = world_t_lidar.rotation.quaternion().coords; // i, j, k, w
            let values = [t.x, t.y, t.z, q.x, q.y, q.z, q.w];
            finite(&values, "robot pose")?;
            put_stamp(&mut p, stamp);
            for v in values {
                p.extend_from_slice(&v.to_le_bytes());
            }
            KIND_ROBOT_POSE
        }
        LinkMessage::Detections { seq, stamp, scan_last_packet_host_ns, sent_host_ns, people } => {
            if people.len() > MAX_PEOPLE {
                return Err(bad(format!("{} people (at most {MAX_PEOPLE})", people.len())));
            }
            let points: usize = people.iter().map(|q| q.points_world.len()).sum();
            if points > MAX_POINTS_PER_MESSAGE {
                return Err(bad(format!("{points} points (at most {MAX_POINTS_PER_MESSAGE})")));
            }
            p.reserve(32 + people.len() * (PERSON_HEADER_LEN + 1) + points * POINT_LEN);
            p.extend_from_slice(&seq.to_le_bytes());
            put_stamp(&mut p, stamp);
            for t in [scan_last_packet_host_ns, sent_host_ns] {
                p.extend_from_slice(&t.to_le_bytes());
            }
            p.extend_from_slice(&(people.len() as u32).to_le_bytes());
            for person in people {
                let b = &person.bbox;
                let values = [b.centre_m.x, b.centre_m.y, b.centre_m.z, b.size_m.x, b.size_m.y, b.size_m.z, b.yaw_rad];
                finite(&values, "person box")?;
                finite(&[f64::from(person.score)], "person score")?;
                p.extend_from_slice(&person.score.to_le_bytes());
                p.push(posture_byte(person.pose));
                for v in values {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                p.extend_from_slice(&(person.points_world.len() as u32).to_le_bytes());
                for pt in &person.points_world {
                    if !pt.iter().all(|v| v.is_finite()) {
                        return Err(bad("person point is not finite"));
                    }
                    for v in pt {
                        p.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
            KIND_DETECTIONS
        }
        LinkMessage::MapTile { bytes } => {
            decode_tile(bytes)?;
            p.extend_from_slice(bytes);
            KIND_MAP_TILE
        }
    };
    let total = HEADER_LEN + p.len() + CRC_LEN;
    if total > MAX_MESSAGE_BYTES {
        return Err(bad(format!("{total} bytes (at most {MAX_MESSAGE_BYTES})")));
    }
    let mut b = Vec::with_capacity(total);
    b.extend_from_slice(MAGIC);
    b.push(VERSION);
    b.push(kind);
    b.extend_from_slice(&0u16.to_le_bytes());
    b.extend_from_slice(&(p.len() as u32).to_le_bytes());
    b.extend_from_slice(&p);
    let crc = CRC32.checksum(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    Ok(b)
}

/// A cursor over a payload whose reads fail (typed) past its end.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], PipelineError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let s = end.and_then(|e| self.b.get(self.at..e)).ok_or(PipelineError::Truncated {
            format: FORMAT,
            what,
            need: n as u64,
            have: self.b.len().saturating_sub(self.at) as u64,
        })?;
        self.at += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], PipelineError> {
        self.take(N, what)?.try_into().map_err(|_| bad(what))
    }

    fn u8(&mut self, what: &'static str) -> Result<u8, PipelineError> {
        Ok(self.array::<1>(what)?[0])
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, PipelineError> {
        self.array(what).map(u32::from_le_bytes)
    }

    fn stamp(&mut self) -> Result<Stamp, PipelineError> {
        let ns = self.u64("stamp_ns")?;
        let clock = match self.u8("stamp clock")? {
            1 => Clock::Device,
            2 => Clock::Ptp,
            3 => Clock::Gps,
            4 => Clock::Pps,
            5 => Clock::Host,
            other => return Err(bad(format!("unknown stamp clock {other}"))),
        };
        Ok(Stamp::new(ns, clock))
    }

    fn u64(&mut self, what: &'static str) -> Result<u64, PipelineError> {
        self.array(what).map(u64::from_le_bytes)
    }

    fn f32(&mut self, what: &'static str) -> Result<f32, PipelineError> {
        let v = f32::from_le_bytes(self.array(what)?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(bad(format!("{what} is not finite")))
        }
    }

    fn f64(&mut self, what: &'static str) -> Result<f64, PipelineError> {
        let v = f64::from_le_bytes(self.array(what)?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(bad(format!("{what} is not finite")))
        }
    }

    fn remaining(&self) -> usize {
        self.b.len().saturating_sub(self.at)
    }

    fn finish(&self) -> Result<(), PipelineError> {
        match self.remaining() {
            0 => Ok(()),
            n => Err(bad(format!("{n} bytes after the payload"))),
        }
    }
}

/// Decodes one frame: magic, version, kind, exact length, CRC and every field are checked; any
/// failure is a typed error, never a panic, and nothing is allocated beyond the bytes present.
pub fn decode(b: &[u8]) -> Result<LinkMessage, PipelineError> {
    if b.len() < HEADER_LEN + CRC_LEN {
        return Err(PipelineError::Truncated {
            format: FORMAT,
            what: "header and CRC",
            need: (HEADER_LEN + CRC_LEN) as u64,
            have: b.len() as u64,
        });
    }
    if b.len() > MAX_MESSAGE_BYTES {
        return Err(bad(format!("{} bytes (at most {MAX_MESSAGE_BYTES})", b.len())));
    }
    let mut h = Reader { b, at: 0 };
    if h.take(4, "magic")? != MAGIC {
        return Err(bad("bad magic (not a STARC link message)"));
    }
    let version = h.u8("version")?;
    if version != VERSION && version != VERSION_NO_POSTURE {
        return Err(PipelineError::Unsupported { format: FORMAT, what: format!("version {version}") });
    }
    let kind = h.u8("kind")?;
    let reserved = u16::from_le_bytes(h.array("reserved")?);
    if reserved != 0 {
        return Err(bad(format!("reserved field {reserved}")));
    }
    let len = h.u32("payload length")? as usize;
    let need = HEADER_LEN.saturating_add(len).saturating_add(CRC_LEN);
    if b.len() != need {
        return Err(PipelineError::Truncated {
            format: FORMAT,
            what: "payload and CRC (length must match the header exactly)",
            need: need as u64,
            have: b.len() as u64,
        });
    }
    let body = b.get(..HEADER_LEN + len).ok_or_else(|| bad("short"))?;
    let saved =
        u32::from_le_bytes(b.get(HEADER_LEN + len..).and_then(|s| s.try_into().ok()).ok_or_else(|| bad("short CRC"))?);
    let calculated = CRC32.checksum(body);
    if saved != calculated {
        return Err(bad(format!("CRC mismatch (saved {saved:#010x}, calculated {calculated:#010x})")));
    }
    let payload = body.get(HEADER_LEN..).ok_or_else(|| bad("short"))?;
    let mut r = Reader { b: payload, at: 0 };
    let m = match kind {
        KIND_HEARTBEAT => {
            let role = match r.u8("role")? {
                1 => Role::Robot,
                2 => Role::Rig,
                other => return Err(bad(format!("unknown role {other}"))),
            };
            if r.take(3, "reserved")? != [0; 3] {
                return Err(bad("heartbeat reserved bytes are not 0"));
            }
            let seq = r.u32("seq")?;
            let sent_host_ns = r.u64("sent_host_ns")?;
            let map_tiles = r.u32("map_tiles")?;
            LinkMessage::Heartbeat { role, seq, sent_host_ns, map_tiles }
        }
        KIND_CLOCK_PROBE => LinkMessage::ClockProbe { seq: r.u32("seq")?, t1_ns: r.u64("t1_ns")? },
        KIND_CLOCK_REPLY => LinkMessage::ClockReply {
            seq: r.u32("seq")?,
            t1_ns: r.u64("t1_ns")?,
            t2_ns: r.u64("t2_ns")?,
            t3_ns: r.u64("t3_ns")?,
        },
        KIND_ROBOT_POSE => {
            let stamp = r.stamp()?;
            let mut v = [0.0; 7];
            for x in v.iter_mut() {
                *x = r.f64("pose")?;
            }
            let [x, y, z, qi, qj, qk, qw] = v;
            let q = Quaternion::new(qw, qi, qj, qk);
            if (q.norm() - 1.0).abs() > 1e-6 {
                return Err(bad(format!("pose rotation is not a unit quaternion (norm {})", q.norm())));
            }
            let world_t_lidar = Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::new_normalize(q));
            LinkMessage::RobotPose { stamp, world_t_lidar }
        }
        KIND_DETECTIONS => {
            let seq = r.u32("seq")?;
            let stamp = r.stamp()?;
            let scan_last_packet_host_ns = r.u64("scan_last_packet_host_ns")?;
            let sent_host_ns = r.u64("sent_host_ns")?;
            let count = r.u32("people")? as usize;
            // Each person needs its fixed part: a forged count cannot ask for more than the
            // bytes present.
            let with_posture = version >= VERSION;
            let person_len = PERSON_HEADER_LEN + usize::from(with_posture);
            if count > MAX_PEOPLE || count.saturating_mul(person_len) > r.remaining() {
                return Err(bad(format!("{count} people do not fit {} bytes (at most {MAX_PEOPLE})", r.remaining())));
            }
            let mut people = Vec::with_capacity(count);
            let mut total_points = 0usize;
            for _ in 0..count {
                let score = r.f32("person score")?;
                let pose = if with_posture { posture_from_byte(r.u8("person posture")?)? } else { None };
                let mut v = [0.0; 7];
                for x in v.iter_mut() {
                    *x = r.f64("person box")?;
                }
                let [cx, cy, cz, l, w, h, yaw_rad] = v;
                let n = r.u32("person points")? as usize;
                total_points = total_points.saturating_add(n);
                if total_points > MAX_POINTS_PER_MESSAGE || n.saturating_mul(POINT_LEN) > r.remaining() {
                    return Err(bad(format!(
                        "{n} person points do not fit {} bytes (at most {MAX_POINTS_PER_MESSAGE} in all)",
                        r.remaining()
                    )));
                }
                let mut points_world = Vec::with_capacity(n);
                for _ in 0..n {
                    points_world.push([r.f32("point x")?, r.f32("point y")?, r.f32("point z")?]);
                }
                let bbox = OrientedBox { centre_m: Vector3::new(cx, cy, cz), size_m: Vector3::new(l, w, h), yaw_rad };
                people.push(LinkPerson { score, bbox, pose, points_world });
            }
            LinkMessage::Detections { seq, stamp, scan_last_packet_host_ns, sent_host_ns, people }
        }
        KIND_MAP_TILE => {
            let bytes = r.take(r.remaining(), "map tile")?;
            decode_tile(bytes)?;
            LinkMessage::MapTile { bytes: bytes.to_vec() }
        }
        other => return Err(PipelineError::Unsupported { format: FORMAT, what: format!("kind {other}") }),
    };
    r.finish()?;
    Ok(m)
}
