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
