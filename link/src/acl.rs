//! What each role may send, and the key each message must arrive on. The link's own access
//! control, on top of TLS: a peer holding a valid certificate (or a bug) still cannot make the
//! robot queue what only the robot produces, or pass one kind off under another's key.

use starc_pipeline::link::{map_tile_id, LinkMessage, Role};

use crate::keys::{map_key, message_key};

/// Why a decoded message was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// A kind the sender's role never sends (a rig sends heartbeats and clock probes and
    /// replies only), or a heartbeat naming the wrong role.
    Kind,
    /// The key it came on is not the one for its kind (or, for a fetched tile, not that tile's).
    Key,
}

/// Whether `sender` ever sends this kind: the robot sends everything; the rig only its
/// heartbeats, clock probes and clock replies (node/src/fpv.rs publishes nothing else).
pub fn may_send(sender: Role, msg: &LinkMessage) -> bool {
    match sender {
        Role::Robot => true,
        Role::Rig => matches!(
            msg,
            LinkMessage::Heartbeat { .. } | LinkMessage::ClockProbe { .. } | LinkMessage::ClockReply { .. }
        ),
    }
}

/// Checks a message from `sender` that arrived on `key`: published (`<prefix>/<sender>/<kind>`)
/// or, `fetched`, as a reply to the rig's map query (`<prefix>/robot/map/<x>/<y>/<z>`, a map tile
/// with that key).
pub fn check(prefix: &str, sender: Role, key: &str, msg: &LinkMessage, fetched: bool) -> Result<(), Refusal> {
    if !may_send(sender, msg) {
        return Err(Refusal::Kind);
    }
    if let LinkMessage::Heartbeat { role, .. } = msg {
        if *role != sender {
            return Err(Refusal::Kind);
        }
    }
    if !fetched {
        return if key == message_key(prefix, sender, msg) { Ok(()) } else { Err(Refusal::Key) };
    }
    let LinkMessage::MapTile { bytes } = msg else { return Err(Refusal::Key) };
    let Some(((x, y, z), _)) = map_tile_id(bytes) else { return Err(Refusal::Key) };
    if sender == Role::Robot && key == format!("{}/{x}/{y}/{z}", map_key(prefix)) {
        Ok(())
    } else {
        Err(Refusal::Key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::{Clock, Stamp};

    fn heartbeat(role: Role) -> LinkMessage {
        LinkMessage::Heartbeat { role, seq: 1, sent_host_ns: 2, map_tiles: 0 }
    }

    fn detections() -> LinkMessage {
        LinkMessage::Detections {
            seq: 1,
            stamp: Stamp::new(1, Clock::Ptp),
            scan_last_packet_host_ns: 2,
            sent_host_ns: 3,
            people: vec![],
        }
    }

    #[test]
    fn the_rig_sends_only_heartbeats_and_clock_messages_each_on_its_own_key() {
        let probe = LinkMessage::ClockProbe { seq: 1, t1_ns: 2 };
        assert_eq!(check("starc", Role::Rig, "starc/rig/heartbeat", &heartbeat(Role::Rig), false), Ok(()));
        assert_eq!(check("starc", Role::Rig, "starc/rig/clock_probe", &probe, false), Ok(()));
        // A rig never sends people, poses or tiles: whatever key they come on.
        assert_eq!(check("starc", Role::Rig, "starc/rig/detections", &detections(), false), Err(Refusal::Kind));
        // A probe on the heartbeat key, a heartbeat naming the robot on the rig's key.
        assert_eq!(check("starc", Role::Rig, "starc/rig/heartbeat", &probe, false), Err(Refusal::Key));
        assert_eq!(
            check("starc", Role::Rig, "starc/rig/heartbeat", &heartbeat(Role::Robot), false),
            Err(Refusal::Kind)
        );
        // The robot's kinds on their keys only.
        assert_eq!(check("starc", Role::Robot, "starc/robot/detections", &detections(), false), Ok(()));
        assert_eq!(check("starc", Role::Robot, "starc/robot/pose", &detections(), false), Err(Refusal::Key));
        assert_eq!(check("other", Role::Robot, "starc/robot/detections", &detections(), false), Err(Refusal::Key));
    }

    #[test]
    fn a_fetched_tile_must_come_on_its_own_key() {
        let mut tile = vec![0u8; 32];
        tile[12..16].copy_from_slice(&3i32.to_le_bytes());
        tile[16..20].copy_from_slice(&(-1i32).to_le_bytes());
        tile[20..24].copy_from_slice(&0i32.to_le_bytes());
        let msg = LinkMessage::MapTile { bytes: tile };
        assert_eq!(check("starc", Role::Robot, "starc/robot/map/3/-1/0", &msg, true), Ok(()));
        assert_eq!(check("starc", Role::Robot, "starc/robot/map/3/-1/1", &msg, true), Err(Refusal::Key));
        assert_eq!(check("starc", Role::Robot, "starc/robot/map/3/-1/0", &detections(), true), Err(Refusal::Key));
    }
}
