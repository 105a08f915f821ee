//! config/link.toml loads, is safe by default, and becomes the zenoh config we mean.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use starc_link::{LinkConfig, Mode};

fn shipped() -> LinkConfig {
    LinkConfig::from_file(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/link.toml")).unwrap()
}

#[test]
fn the_shipped_example_loads() {
    let cfg = shipped();
    assert_eq!(cfg.mode, Mode::Peer);
    assert_eq!(cfg.listen, vec!["tcp/127.0.0.1:7447".to_string()]);
    assert!(!cfg.multicast_scouting);
    assert_eq!(cfg.key_prefix, "starc");
    assert_eq!((cfg.heartbeat_ms, cfg.stale_after_ms, cfg.lost_after_ms), (100, 500, 2000));
    assert!(cfg.tls.is_none() && cfg.zenoh_config.is_none());
}

#[test]
fn defaults_never_scout_or_listen_everywhere() {
    let z = LinkConfig::default().zenoh().unwrap();
    assert_eq!(z.get_json("scouting/multicast/enabled").unwrap(), "false");
    assert_eq!(z.get_json("scouting/gossip/enabled").unwrap(), "false");
    // zenoh's own default would be tcp/[::]:0 (every interface).
    assert_eq!(z.get_json("listen/endpoints").unwrap(), "[]");
    let z = shipped().zenoh().unwrap();
    assert_eq!(z.get_json("listen/endpoints").unwrap(), r#"["tcp/127.0.0.1:7447"]"#);
}

#[test]
fn bad_configs_are_refused() {
    assert!(LinkConfig::from_toml("no_such_field = 1").is_err());
    assert!(LinkConfig::from_toml("listen = [\"not an endpoint\"]").is_err());
    assert!(LinkConfig::from_toml("heartbeat_ms = 600").is_err()); // above stale_after_ms
    assert!(LinkConfig::from_toml("stale_after_ms = 3000").is_err()); // above lost_after_ms
    assert!(LinkConfig::from_toml("key_prefix = \"starc/*\"").is_err());
    assert!(LinkConfig::from_toml("[tls]\nroot_ca = \"ca.pem\"\ncert = \"a.pem\"").is_err());
    assert!(LinkConfig::from_toml("mode = \"client\"\nconnect = [\"tcp/127.0.0.1:7447\"]").is_ok());
}

#[test]
fn relative_paths_follow_the_file_and_tls_lands_in_zenoh() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("link.toml");
    std::fs::write(&path, "listen = [\"tls/127.0.0.1:7448\"]\n[tls]\nroot_ca = \"ca.pem\"\ncert = \"r.pem\"\nkey = \"r.key\"\nmutual = true\n").unwrap();
    let cfg = LinkConfig::from_file(&path).unwrap();
    let tls = cfg.tls.clone().unwrap();
    assert_eq!(tls.root_ca, dir.path().join("ca.pem"));
    let z = cfg.zenoh().unwrap();
    assert_eq!(z.get_json("transport/link/tls/enable_mtls").unwrap(), "true");
    assert!(z.get_json("transport/link/tls/listen_certificate").unwrap().contains("r.pem"));
}

#[test]
fn plain_tcp_beyond_loopback_needs_insecure_and_the_error_names_the_key_and_file() {
    let e = LinkConfig::from_toml("listen = [\"tcp/192.168.50.2:7447\"]").unwrap_err().to_string();
    assert!(e.contains("listen") && e.contains("insecure = true"), "{e}");
    let e = LinkConfig::from_toml("connect = [\"tcp/robot.local:7447\"]").unwrap_err().to_string();
    assert!(e.contains("connect"), "{e}");
    assert!(LinkConfig::from_toml("listen = [\"tcp/192.168.50.2:7447\"]\ninsecure = true").is_ok());
    // Loopback, v4, v6 and by name, is always allowed.
    for ep in ["tcp/127.0.0.1:7447", "tcp/127.0.7.1:7447", "tcp/[::1]:7447", "tcp/localhost:7447"] {
        assert!(LinkConfig::from_toml(&format!("connect = [\"{ep}\"]")).is_ok(), "{ep}");
    }
    // tls/ needs a [tls] table; listening beyond loopback needs mutual TLS.
    assert!(LinkConfig::from_toml("connect = [\"tls/192.168.50.2:7447\"]").is_err());
    let tls = "[tls]\nroot_ca = \"ca.pem\"\ncert = \"r.pem\"\nkey = \"r.key\"\n";
    let e = LinkConfig::from_toml(&format!("listen = [\"tls/192.168.50.2:7447\"]\n{tls}")).unwrap_err().to_string();
    assert!(e.contains("tls.mutual"), "{e}");
    assert!(LinkConfig::from_toml(&format!("listen = [\"tls/192.168.50.2:7447\"]\n{tls}mutual = true\n")).is_ok());
    // From a file, the error names the file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("robot_link.toml");
    std::fs::write(&path, "listen = [\"tcp/10.0.0.2:7447\"]\n").unwrap();
    let e = LinkConfig::from_file(&path).unwrap_err().to_string();
    assert!(e.contains("robot_link.toml") && e.contains("listen"), "{e}");
}

#[test]
fn zenoh_never_reassembles_more_than_our_largest_frame() {
    let z = LinkConfig::default().zenoh().unwrap();
    let max: usize = z.get_json("transport/link/rx/max_message_size").unwrap().parse().unwrap();
    let frame = starc_pipeline::link::MAX_MESSAGE_BYTES;
    assert!((frame..2 * frame).contains(&max), "{max}");
    assert!(LinkConfig::from_toml("queue_bytes = 0").is_err());
    assert!(LinkConfig::from_toml("max_tile_version_lead = 0").is_err());
}

#[test]
fn mutual_tls_ties_each_role_to_its_certificate_name_unless_the_file_brings_its_own_policy() {
    let tls = "[tls]\nroot_ca = \"ca.pem\"\ncert = \"r.pem\"\nkey = \"r.key\"\n";
    let z = LinkConfig::from_toml(&format!("key_prefix = \"fleet/a\"\n{tls}mutual = true\n")).unwrap().zenoh().unwrap();
    assert_eq!(z.get_json("access_control/enabled").unwrap(), "true");
    assert_eq!(z.get_json("access_control/default_permission").unwrap(), "\"deny\"");
    let subjects = z.get_json("access_control/subjects").unwrap();
    assert!(subjects.contains("\"starc-robot\"") && subjects.contains("\"starc-rig\""), "{subjects}");
    let rules = z.get_json("access_control/rules").unwrap();
    assert!(rules.contains("\"fleet/a/rig/**\"") && rules.contains("\"fleet/a/robot/map/**\""), "{rules}");
    // No certificate names to go by: nothing written (zenoh's default, disabled).
    for no_names in [String::new(), format!("{tls}mutual = false\n")] {
        let z = LinkConfig::from_toml(&no_names).unwrap().zenoh().unwrap();
        assert_eq!(z.get_json("access_control/enabled").unwrap(), "false", "{no_names}");
    }
    // A zenoh_config file enabling its own access_control keeps it.
    let dir = tempfile::tempdir().unwrap();
    let own = r#"{ access_control: { enabled: true, default_permission: "allow",
        rules: [{ id: "mine", messages: ["put"], flows: ["ingress"], permission: "deny", key_exprs: ["x"] }],
        subjects: [{ id: "everyone" }], policies: [{ rules: ["mine"], subjects: ["everyone"] }] } }"#;
    std::fs::write(dir.path().join("z.json5"), own).unwrap();
    std::fs::write(dir.path().join("link.toml"), format!("zenoh_config = \"z.json5\"\n{tls}mutual = true\n")).unwrap();
    let z = LinkConfig::from_file(&dir.path().join("link.toml")).unwrap().zenoh().unwrap();
    assert_eq!(z.get_json("access_control/default_permission").unwrap(), "\"allow\"");
    assert!(z.get_json("access_control/rules").unwrap().contains("\"mine\""));
}
