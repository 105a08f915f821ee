//! What each role may send, and the key each message must arrive on. The link's own access
//! control, on top of TLS: a peer holding a valid certificate (or a bug) still cannot make the
//! robot queue what only the robot produces, or pass one kind off under another's key.

use starc_pipeline::link::{map_tile_id, LinkMessage, Role};

use crate::certs::{RIG_CN, ROBOT_CN};
use crate::keys::{map_key, message_key};

/// What a role's zenoh session sends on the wire: (zenoh `access_control` message names, key
/// expression). The robot puts on its own keys, subscribes to the rig's and serves the map; the
/// rig puts on its own keys, subscribes to the robot's and queries the map (node.rs declares
/// nothing else: no liveliness tokens, no deletes).
fn wire_actions(prefix: &str, sender: Role) -> [(&'static [&'static str], String); 3] {
    let map = format!("{}/**", map_key(prefix));
    match sender {
        Role::Robot => [
            (&["put"], format!("{prefix}/robot/**")),
            (&["declare_subscriber"], format!("{prefix}/rig/**")),
            (&["declare_queryable", "reply"], map),
        ],
        Role::Rig => [
            (&["put"], format!("{prefix}/rig/**")),
            (&["declare_subscriber"], format!("{prefix}/robot/**")),
            (&["query"], map),
        ],
    }
}

/// zenoh's `access_control` section tying each role's keys to its certificate's common name
/// (`starc link certs`: `starc-robot`, `starc-rig`), as JSON5. `LinkConfig::zenoh` writes it
/// whenever mutual TLS is on, on both nodes: every subject is the *other* end of a transport (the
/// name in the certificate it showed), ingress is what we take from it and egress what we send
/// it, so one policy serves robot and rig. A peer holding the rig's certificate may put only on
/// `<prefix>/rig/**`, subscribe to `<prefix>/robot/**` and query the map, and is sent only the
/// robot's messages; the robot's certificate the converse. Everything else, and every transport
/// whose certificate names neither (or that has none: plain tcp), is denied by default, so zenoh
/// drops it on arrival before routing it anywhere: a stolen rig key cannot pass off robot
/// detections or tiles to another rig, nor serve a forged map. zenoh allows a message when an
/// allow rule's key expression includes the message's whole key expression.
pub fn zenoh_access_control(prefix: &str) -> String {
    let q = crate::config::json;
    let (mut rules, mut subjects, mut policies) = (Vec::new(), Vec::new(), Vec::new());
    for (peer, cn) in [(Role::Robot, ROBOT_CN), (Role::Rig, RIG_CN)] {
        let subject = peer.name();
        let mut ids = Vec::new();
        // Ingress: what this subject sends us; egress: what we, its counterpart, send it.
        for (flow, sender) in [("ingress", peer), ("egress", peer.peer())] {
            for (messages, key) in wire_actions(prefix, sender) {
                let id = q(&format!("{}_{}_{flow}", sender.name(), messages.join("_")));
                let messages = messages.iter().map(|m| q(m)).collect::<Vec<_>>().join(", ");
                rules.push(format!(
                    "{{ id: {id}, messages: [{messages}], flows: [\"{flow}\"], permission: \"allow\", key_exprs: [{}] }}",
                    q(&key)
                ));
                ids.push(id);
            }
        }
        subjects.push(format!("{{ id: {}, cert_common_names: [{}] }}", q(subject), q(cn)));
        policies.push(format!("{{ id: {}, subjects: [{}], rules: [{}] }}", q(subject), q(subject), ids.join(", ")));
    }
    let list = |items: Vec<String>| format!("[\n    {}\n  ]", items.join(",\n    "));
    format!(
        "{{\n  enabled: true,\n  default_permission: \"deny\",\n  rules: {},\n  subjects: {},\n  policies: {}\n}}",
        list(rules),
        list(subjects),
        list(policies)
    )
}

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
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use starc_time::{Clock, Stamp};

    #[test]
    fn the_policy_by_certificate_name_is_a_zenoh_access_control_section() {
        let policy = zenoh_access_control("starc");
        let mut z = zenoh::Config::default();
        z.insert_json5("access_control", &policy).unwrap();
        // Each role's sending rights, once as what we take from it and once as what we send it.
        assert_eq!(policy.matches("permission: \"allow\"").count(), 12, "{policy}");
        assert!(policy.contains(
            r#"{ id: "rig_put_ingress", messages: ["put"], flows: ["ingress"], permission: "allow", key_exprs: ["starc/rig/**"] }"#
        ));
        assert!(policy.contains(r#"{ id: "rig", cert_common_names: ["starc-rig"] }"#), "{policy}");
    }

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
