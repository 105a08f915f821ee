//! What the view tests share: the workspace root and the peers' Python.

use std::path::PathBuf;
use std::process::Command;

pub fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The venv's python with the peers; a missing peer is a failure, not a skip.
pub fn peer_python() -> PathBuf {
    let python = root().join(".venv/bin/python");
    let ok = Command::new(&python)
        .args(["-c", "import websockets, mcap_ros2._dynamic, rosbags.typesys"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(ok, "peers websockets / mcap-ros2-support / rosbags missing from .venv: .venv/bin/pip install -r tests/peers/requirements.txt");
    python
}
