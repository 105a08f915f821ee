#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::*;
use crate::align::{encode_tiles, TileMap, Vec3};
use crate::ar::OrientedBox;
use crate::detect::{Detection, PersonPose, WindowPoint};
use crate::PipelineError;
use starc_time::{Clock, Stamp};

fn person(n: usize, seed: f32) -> LinkPerson {
    LinkPerson {
        score: 0.87,
        bbox: OrientedBox { centre_m: Vector3::new(3.0, -1.5, 0.9), size_m: Vector3::new(0.6, 0.5, 1.8), yaw_rad: 0.4 },
        pose: Some(PersonPose::Upright),
        points_world: (0..n).map(|i| [seed + i as f32 * 0.01, -1.5, 0.1 + i as f32 * 0.001]).collect(),
    }
}

fn tile_bytes() -> Vec<u8> {
    let pts: Vec<Vec3> = (0..50).map(|i| Vec3::new(0.05 * f64::from(i), 0.5, 1.0)).collect();
    let nrm = vec![Some(Vec3::new(0.0, 0.0, 1.0)); pts.len()];
    encode_tiles(&pts, &nrm, 4.0, 0.01, 3).unwrap().remove(0).1
}

fn every_kind() -> Vec<LinkMessage> {
    vec![
        LinkMessage::Heartbeat { role: Role::Robot, seq: 7, sent_host_ns: 1_700_000_000_123_456_789, map_tiles: 42 },
        LinkMessage::Heartbeat { role: Role::Rig, seq: u32::MAX, sent_host_ns: 0, map_tiles: 0 },
        LinkMessage::ClockProbe { seq: 3, t1_ns: 11 },
        LinkMessage::ClockReply { seq: 3, t1_ns: 11, t2_ns: 22, t3_ns: 33 },
        LinkMessage::RobotPose {
            stamp: Stamp::new(99, Clock::Ptp),
            world_t_lidar: Isometry3::from_parts(
                Translation3::new(1.0, -2.0, 0.5),
                UnitQuaternion::from_euler_angles(0.1, -0.2, 2.5),
            ),
        },
        LinkMessage::Detections {
            seq: 5,
            stamp: Stamp::new(1000, Clock::Ptp),
            scan_last_packet_host_ns: 1010,
            sent_host_ns: 1030,
            people: vec![person(2000, 1.0), person(0, 2.0), person(17, 3.0)],
        },
        LinkMessage::Detections {
            seq: 6,
            stamp: Stamp::new(1, Clock::Device),
            scan_last_packet_host_ns: 2,
            sent_host_ns: 3,
            people: vec![],
        },
        LinkMessage::MapTile { bytes: tile_bytes() },
    ]
}

fn same(a: &LinkMessage, b: &LinkMessage) -> bool {
    match (a, b) {
        (
            LinkMessage::RobotPose { stamp: s1, world_t_lidar: p1 },
            LinkMessage::RobotPose { stamp: s2, world_t_lidar: p2 },
        ) => {
            s1 == s2
                && (p1.translation.vector - p2.translation.vector).norm() == 0.0
                && p1.rotation.angle_to(&p2.rotation) < 1e-12
        }
        _ => a == b,
    }
}

#[test]
fn a_stamp_keeps_its_clock_and_an_unknown_clock_is_refused() {
    let m = LinkMessage::Detections {
        seq: 1,
        stamp: Stamp::new(7, Clock::Device),
        scan_last_packet_host_ns: 8,
        sent_host_ns: 9,
        people: vec![],
    };
    let b = encode(&m).unwrap();
    assert_eq!(decode(&b).unwrap(), m);
    // The clock byte follows seq (4) and the stamp (8) in the payload.
    let mut forged = b.clone();
    forged[HEADER_LEN + 12] = 9;
    let n = forged.len() - 4;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&forged[..n]);
    forged[n..].copy_from_slice(&crc.to_le_bytes());
    let e = decode(&forged).unwrap_err().to_string();
    assert!(e.contains("unknown stamp clock 9"), "{e}");
}

#[test]
fn every_kind_round_trips() {
    for m in every_kind() {
        let b = encode(&m).unwrap();
        let back = decode(&b).unwrap();
        assert!(same(&m, &back), "{m:?} came back as {back:?}");
        // The kind names are distinct key segments.
        assert!(!kind_name(&m).contains('/'));
    }
}

#[test]
fn detections_of_2000_points_stay_small() {
    let m = &every_kind()[5];
    let b = encode(m).unwrap();
    // 12 bytes per point plus fixed parts: no hidden blow-up.
    assert_eq!(b.len(), HEADER_LEN + 33 + 3 * 65 + 2017 * 12 + 4);
}

#[test]
fn every_flipped_bit_is_refused() {
    for m in every_kind() {
        let b = encode(&m).unwrap();
        // Every byte of small messages; a stride through the big ones.
        let stride = (b.len() / 512).max(1);
        for i in (0..b.len()).step_by(stride) {
            let mut c = b.clone();
            c[i] ^= 0x10;
            assert!(decode(&c).is_err(), "{} with byte {i} flipped decoded", kind_name(&m));
        }
    }
}

#[test]
fn corrupt_crc_is_a_typed_error() {
    let mut b = encode(&every_kind()[0]).unwrap();
    let n = b.len();
    b[n - 1] ^= 1;
    match decode(&b) {
        Err(PipelineError::BadFile { reason, .. }) => assert!(reason.contains("CRC"), "{reason}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_truncation_is_refused() {
    for m in every_kind() {
        let b = encode(&m).unwrap();
        let stride = (b.len() / 256).max(1);
        for n in (0..b.len()).step_by(stride) {
            assert!(decode(&b[..n]).is_err(), "{} truncated to {n} decoded", kind_name(&m));
        }
        let mut longer = b.clone();
        longer.push(0);
        assert!(decode(&longer).is_err());
    }
    assert!(matches!(decode(&[]), Err(PipelineError::Truncated { .. })));
}

/// Rewrites a frame's payload and fixes up length and CRC, so only the payload check can refuse.
fn reframe(kind: u8, payload: &[u8]) -> Vec<u8> {
    reframe_as(2, kind, payload)
}

fn reframe_as(version: u8, kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut b = b"STLK".to_vec();
    b.push(version);
    b.push(kind);
    b.extend_from_slice(&[0, 0]);
    b.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    b.extend_from_slice(payload);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn oversize_counts_are_refused_before_allocating() {
    // A detections payload that claims u32::MAX people, then one claiming 2^30 points.
    let detections_head = || {
        let mut p = Vec::new();
        p.extend_from_slice(&1u32.to_le_bytes());
        p.extend_from_slice(&[0; 8]);
        p.push(2); // PTP
        p.extend_from_slice(&[0; 16]);
        p
    };
    let mut p = detections_head();
    p.extend_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(decode(&reframe(5, &p)), Err(PipelineError::BadFile { .. })));

    let mut p = detections_head();
    p.extend_from_slice(&1u32.to_le_bytes());
    p.extend_from_slice(&0.5f32.to_le_bytes());
    p.extend_from_slice(&[0; 56]);
    p.extend_from_slice(&(1u32 << 30).to_le_bytes());
    assert!(matches!(decode(&reframe(5, &p)), Err(PipelineError::BadFile { .. })));

    // A header promising a 4 GiB payload.
    let mut b = encode(&every_kind()[2]).unwrap();
    b[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(decode(&b).is_err());

    // Frames over the limit are refused by length alone, and not produced.
    assert!(decode(&vec![0u8; MAX_MESSAGE_BYTES + 1]).is_err());
    let too_many = LinkMessage::Detections {
        seq: 0,
        stamp: Stamp::new(0, Clock::Ptp),
        scan_last_packet_host_ns: 0,
        sent_host_ns: 0,
        people: vec![person(0, 0.0); MAX_PEOPLE + 1],
    };
    assert!(encode(&too_many).is_err());
}

#[test]
fn unknown_kind_version_role_and_bad_values_are_refused() {
    assert!(matches!(decode(&reframe(9, &[])), Err(PipelineError::Unsupported { .. })));
    // Format 1 (before stamps carried their clock) and a future 4.
    for version in [1, 4] {
        let mut b = encode(&every_kind()[2]).unwrap();
        b[4] = version;
        assert!(decode(&b).is_err());
    }
    // Heartbeat with role 3.
    let mut p = vec![3, 0, 0, 0];
    p.extend_from_slice(&[0; 16]);
    assert!(decode(&reframe(1, &p)).is_err());
    // A pose whose quaternion is not unit.
    let mut p = 5u64.to_le_bytes().to_vec();
    p.push(2);
    for v in [0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    assert!(decode(&reframe(4, &p)).is_err());
    // NaN in a pose is refused on both sides.
    let nan_pose = LinkMessage::RobotPose {
        stamp: Stamp::new(0, Clock::Ptp),
        world_t_lidar: Isometry3::from_parts(Translation3::new(f64::NAN, 0.0, 0.0), UnitQuaternion::identity()),
    };
    assert!(encode(&nan_pose).is_err());
    // A damaged map tile inside an intact frame.
    let mut t = tile_bytes();
    t[40] ^= 1;
    assert!(decode(&reframe(6, &t)).is_err());
    assert!(encode(&LinkMessage::MapTile { bytes: t }).is_err());
}

/// A detections payload (either version) with one person of `points` points.
fn one_person_payload(posture: Option<u8>, points: u32) -> Vec<u8> {
    let mut p = 1u32.to_le_bytes().to_vec();
    p.extend_from_slice(&10u64.to_le_bytes());
    p.push(2); // PTP
    p.extend_from_slice(&[0; 16]);
    p.extend_from_slice(&1u32.to_le_bytes());
    p.extend_from_slice(&0.5f32.to_le_bytes());
    p.extend(posture);
    for v in [1.0f64, 2.0, 0.9, 0.5, 0.4, 1.7, 0.0] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    p.extend_from_slice(&points.to_le_bytes());
    for i in 0..points {
        for v in [1.0f32, 2.0, i as f32 * 0.1] {
            p.extend_from_slice(&v.to_le_bytes());
        }
    }
    p
}

#[test]
fn posture_travels_and_a_version_2_sender_is_still_read() {
    let people_of = |m: LinkMessage| match m {
        LinkMessage::Detections { people, .. } => people,
        other => panic!("{other:?}"),
    };
    // Ours: version 3, each posture and none.
    let poses = [Some(PersonPose::Upright), Some(PersonPose::Low), Some(PersonPose::Lying), None];
    let people: Vec<LinkPerson> = poses.iter().map(|&pose| LinkPerson { pose, ..person(3, 1.0) }).collect();
    let m = LinkMessage::Detections {
        seq: 1,
        stamp: Stamp::new(1, Clock::Ptp),
        scan_last_packet_host_ns: 2,
        sent_host_ns: 3,
        people,
    };
    let b = encode(&m).unwrap();
    assert_eq!(b[4], 3, "written as version 3");
    let back = people_of(decode(&b).unwrap());
    assert_eq!(back.iter().map(|p| p.pose).collect::<Vec<_>>(), poses);
    assert_eq!(back[2].to_ar_person(0).pose, Some(PersonPose::Lying));

    // A version 2 sender (no posture byte): read, posture unknown, points intact.
    let v2 = people_of(decode(&reframe_as(2, 5, &one_person_payload(None, 4))).unwrap());
    assert_eq!((v2.len(), v2[0].pose, v2[0].points_world.len()), (1, None, 4));
    // The same bytes as version 3 are 1 byte short (the posture byte shifts every field).
    assert!(decode(&reframe_as(3, 5, &one_person_payload(None, 4))).is_err());
    // Version 3: a known posture is read, an unknown one refused.
    let v3 = people_of(decode(&reframe_as(3, 5, &one_person_payload(Some(2), 4))).unwrap());
    assert_eq!(v3[0].pose, Some(PersonPose::Low));
    assert!(matches!(decode(&reframe_as(3, 5, &one_person_payload(Some(7), 4))), Err(PipelineError::BadFile { .. })));
}

#[test]
fn map_tiles_apply_to_the_rig_map() {
    let LinkMessage::MapTile { bytes } = decode(&encode(&every_kind()[7]).unwrap()).unwrap() else { panic!() };
    let tile = crate::align::decode_tile(&bytes).unwrap();
    assert_eq!(map_tile_id(&bytes), Some((tile.key, 3)));
    assert_eq!(map_tile_id(&bytes[..20]), None);
    let mut map = TileMap::default();
    assert!(map.apply(&bytes).unwrap());
    assert_eq!(map.points().0.len(), 50);
}

#[test]
fn person_converts_from_detection_and_to_ar() {
    let window: Vec<WindowPoint> =
        (0..10).map(|i| WindowPoint { x_m: i as f32, y_m: 1.0, z_m: 2.0, t_ns: 0 }).collect();
    let d = Detection {
        stamp: Stamp::new(5, Clock::Host),
        centre_m: Vector3::new(1.0, 2.0, 0.9),
        size_m: Vector3::new(0.5, 0.4, 1.7),
        yaw_rad: 0.2,
        score: 0.75,
        pose: PersonPose::Upright,
        point_indices: vec![1, 3, 99],
    };
    let p = LinkPerson::from_detection(&d, &window);
    assert_eq!(p.points_world, vec![[1.0, 1.0, 2.0], [3.0, 1.0, 2.0]]);
    assert_eq!(p.score, 0.75);
    assert_eq!(p.pose, Some(PersonPose::Upright));
    let ar = p.to_ar_person(7);
    assert_eq!(ar.age_ns, 7);
    assert_eq!(ar.pose, Some(PersonPose::Upright));
    assert_eq!(ar.bbox.unwrap().centre_m, d.centre_m);
    assert_eq!(ar.points_world[1], Vector3::new(3.0, 1.0, 2.0));
}

/// One exchange over a path with the given one-way delays, the peer `offset_ns` ahead and
/// `turnaround_ns` spent answering.
fn exchange(t1: u64, offset_ns: i64, fwd_ns: u64, back_ns: u64, turnaround_ns: u64) -> (u64, u64, u64, u64) {
    let t2 = (t1 + fwd_ns).checked_add_signed(offset_ns).unwrap();
    let t3 = t2 + turnaround_ns;
    let t4 = t1 + fwd_ns + turnaround_ns + back_ns;
    (t1, t2, t3, t4)
}

#[test]
fn clock_offset_symmetric_path_is_exact() {
    let mut c = ClockOffset::new(8);
    assert!(c.estimate().is_none());
    let (a, b, d, e) = exchange(5_000_000_000, -3_000_000_000, 2_000_000, 2_000_000, 50_000);
    let est = c.add(a, b, d, e).unwrap();
    assert_eq!(est.offset_ns, -3_000_000_000);
    assert_eq!(est.rtt_ns, 4_000_000);
    assert_eq!(est.uncertainty_ns, 2_000_000);
    assert_eq!(c.peer_to_local(10_000_000_000), Some(13_000_000_000));
}

#[test]
fn clock_offset_asymmetric_path_stays_within_its_uncertainty() {
    let mut c = ClockOffset::new(8);
    // 9 ms out, 1 ms back: the estimate is off by (9 - 1) / 2 = 4 ms, inside the 5 ms bound.
    let (a, b, d, e) = exchange(5_000_000_000, 123_456_789, 9_000_000, 1_000_000, 100_000);
    let est = c.add(a, b, d, e).unwrap();
    let err = (est.offset_ns - 123_456_789).unsigned_abs();
    assert_eq!(err, 4_000_000);
    assert!(err <= est.uncertainty_ns, "{err} > {}", est.uncertainty_ns);
}

#[test]
fn clock_offset_min_delay_filter_beats_jitter() {
    // WiFi-like: 1.5 ms base each way plus exponential-ish queueing up to 40 ms per direction.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let truth = 987_654_321i64;
    let mut c = ClockOffset::new(32);
    let mut naive = Vec::new();
    let mut t = 1_000_000_000u64;
    for _ in 0..32 {
        let jitter = |u: f64| (-(1.0 - u).ln() * 8_000_000.0).min(40_000_000.0) as u64;
        let fwd = 1_500_000 + jitter(rnd());
        let back = 1_500_000 + jitter(rnd());
        let (a, b, d, e) = exchange(t, truth, fwd, back, 20_000);
        let est = c.add(a, b, d, e).unwrap();
        naive.push((((b as i128 - a as i128) + (d as i128 - e as i128)) / 2) as i64);
        let err = (est.offset_ns - truth).unsigned_abs();
        assert!(err <= est.uncertainty_ns, "error {err} ns beyond the bound {} ns", est.uncertainty_ns);
        t += 1_000_000_000;
    }
    let est = c.estimate().unwrap();
    let err = (est.offset_ns - truth).unsigned_abs();
    let worst_naive = naive.iter().map(|o| (o - truth).unsigned_abs()).max().unwrap();
    // The filtered estimate is far better than the worst single exchange and within a few ms.
    assert!(err < 3_000_000, "filtered error {err} ns");
    assert!(worst_naive > 4 * err.max(1), "naive worst {worst_naive} ns vs filtered {err} ns");
    assert_eq!(est.samples, 32);
}

#[test]
fn clock_offset_window_forgets_old_exchanges() {
    let mut c = ClockOffset::new(2);
    let s = exchange(1_000, 0, 100, 100, 0);
    c.add(s.0, s.1, s.2, s.3).unwrap(); // best delay, soon out of the window
    for i in 0..2 {
        let s = exchange(10_000 + i * 1_000, 500, 400, 400, 0);
        c.add(s.0, s.1, s.2, s.3).unwrap();
    }
    let est = c.estimate().unwrap();
    assert_eq!((est.offset_ns, est.rtt_ns, est.samples), (500, 800, 2));
    c.reset();
    assert!(c.estimate().is_none());
}

#[test]
fn clock_offset_refuses_impossible_exchanges() {
    let mut c = ClockOffset::new(4);
    assert!(c.add(100, 0, 0, 50).is_err()); // reply before the probe
    assert!(c.add(0, 100, 50, 200).is_err()); // peer sent before it received
    assert!(c.add(0, 0, 500, 100).is_err()); // turnaround longer than the round trip
                                             // Offsets beyond i64 (clocks ~292 years apart) are refused, not wrapped.
    assert!(c.add(0, u64::MAX, u64::MAX, 0).is_err());
    assert!(c.add(u64::MAX, 0, 0, u64::MAX).is_err());
    assert!(c.estimate().is_none());
}

const MS: u64 = 1_000_000;

#[test]
fn health_goes_stale_then_lost_and_resumes() {
    let mut h = LinkHealth::new(HealthConfig { stale_after_ms: 300, lost_after_ms: 1500 }).unwrap();
    assert_eq!(h.state(), LinkState::Lost);
    assert_eq!(h.tick(10 * MS), None);
    assert_eq!(h.on_heartbeat(100 * MS), Some(LinkState::Up));
    assert_eq!(h.resumptions(), 0);
    for t in (200..=390).step_by(10) {
        assert_eq!(h.tick(t * MS), None, "at {t} ms");
    }
    assert_eq!(h.tick(400 * MS), Some(LinkState::Stale));
    assert_eq!(h.tick(500 * MS), None);
    assert_eq!(h.tick(1600 * MS), Some(LinkState::Lost));
    assert_eq!(h.tick(5000 * MS), None);
    assert_eq!(h.silent_ms(5000 * MS), Some(4900));
    assert_eq!(h.on_heartbeat(5000 * MS), Some(LinkState::Up));
    assert_eq!((h.stalls(), h.drops(), h.resumptions(), h.heartbeats()), (1, 1, 1, 2));
    // A short gap: Stale and back without a loss.
    assert_eq!(h.tick(5350 * MS), Some(LinkState::Stale));
    assert_eq!(h.on_heartbeat(5360 * MS), Some(LinkState::Up));
    assert_eq!((h.stalls(), h.drops(), h.resumptions()), (2, 1, 2));
}

#[test]
fn health_counts_a_gap_nobody_ticked_through() {
    let mut h = LinkHealth::new(HealthConfig { stale_after_ms: 300, lost_after_ms: 1500 }).unwrap();
    h.on_heartbeat(0);
    assert_eq!(h.on_heartbeat(2000 * MS), Some(LinkState::Up));
    assert_eq!((h.drops(), h.resumptions()), (1, 1));
    // A clock stepped back does not panic or un-stall anything.
    assert_eq!(h.tick(0), None);
    assert_eq!(h.state(), LinkState::Up);
}

#[test]
fn health_config_is_checked() {
    assert!(LinkHealth::new(HealthConfig { stale_after_ms: 0, lost_after_ms: 10 }).is_err());
    assert!(LinkHealth::new(HealthConfig { stale_after_ms: 10, lost_after_ms: 10 }).is_err());
}
