//! Shared by the link tests: loopback-only configs with short timings, free ports, bounded waits.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::process::{Child, Command};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use starc_link::{LinkConfig, LinkNode, LinkState, Received, Role};

/// Ports handed out, counted across this test binary's threads.
static NEXT_PORT: AtomicU32 = AtomicU32::new(0);

/// A TCP port free on 127.0.0.1 right now, below the kernel's ephemeral range (32768 and up by
/// default). A port the OS picks for a bind to port 0 comes from that range, where the outgoing
/// connections of the tests running beside this one take their local ports too: one of them
/// took such a port between this check and the node's own bind ("Address already in use").
/// Each call tries the next port of a block chosen by the process id, so parallel tests of one
/// binary never share one.
pub fn free_port() -> u16 {
    const FIRST: u32 = 20_000;
    const SPAN: u32 = 12_000;
    let base = (std::process::id() % 600) * 20;
    for _ in 0..SPAN {
        let n = NEXT_PORT.fetch_add(1, Ordering::Relaxed);
        let port = u16::try_from(FIRST + (base + n) % SPAN).unwrap();
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
    panic!("no free TCP port in {FIRST}..{}", FIRST + SPAN)
}

/// A node listening on a free port (`make` gives its config for a port), and that port. A port
/// found free can still be refused by the time the node binds it (a socket of an earlier test
/// lingering in TIME_WAIT, a neighbour's bind): then it tries the next one, five at most.
pub async fn open_listening(make: impl Fn(u16) -> LinkConfig, role: Role) -> (LinkNode, u16) {
    let mut last = None;
    for _ in 0..5 {
        let port = free_port();
        match LinkNode::open(&make(port), role).await {
            Ok(node) => return (node, port),
            Err(e) => last = Some(e),
        }
    }
    panic!("no listening {role:?} node on five free ports: {last:?}")
}

/// Short timings so loss and recovery take about a second; loopback endpoints only.
pub fn fast(listen: Vec<String>, connect: Vec<String>) -> LinkConfig {
    LinkConfig {
        listen,
        connect,
        heartbeat_ms: 20,
        stale_after_ms: 150,
        lost_after_ms: 500,
        clock_probe_ms: 50,
        reconnect_ms: 100,
        map_fetch_timeout_ms: 2000,
        ..LinkConfig::default()
    }
}

pub fn robot_cfg(port: u16) -> LinkConfig {
    fast(vec![format!("tcp/127.0.0.1:{port}")], vec![])
}

pub fn rig_cfg(port: u16) -> LinkConfig {
    fast(vec![], vec![format!("tcp/127.0.0.1:{port}")])
}

/// Polls `f` every 10 ms until it holds or `limit` passes; returns whether it held.
pub async fn wait_for(limit: Duration, mut f: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if f() {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    f()
}

pub async fn wait_up(node: &LinkNode, limit: Duration) -> bool {
    wait_for(limit, || node.health().state == LinkState::Up).await
}

/// Everything `node` receives within `limit`, stopping early once `done` holds for what came.
pub async fn collect(node: &mut LinkNode, limit: Duration, done: impl Fn(&[Received]) -> bool) -> Vec<Received> {
    let mut got = Vec::new();
    let deadline = tokio::time::Instant::now() + limit;
    while !done(&got) {
        match tokio::time::timeout_at(deadline, node.recv()).await {
            Ok(Some(r)) => got.push(r),
            _ => break,
        }
    }
    got
}

/// The link crate's folder (its tests/peers scripts are under it).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `.venv/bin/python` with eclipse-zenoh, or why not (a failure in CI).
pub fn python() -> Option<PathBuf> {
    let python = root().join("../.venv/bin/python");
    let ok = python.exists()
        && Command::new(&python).args(["-c", "import zenoh"]).output().is_ok_and(|o| o.status.success());
    if ok {
        return Some(python);
    }
    assert!(std::env::var_os("CI").is_none(), "eclipse-zenoh missing from .venv: run .ci/run's install step");
    println!("skipped: .venv has no eclipse-zenoh");
    None
}

/// Kills a peer process if the test fails before it exits.
pub struct Reap(pub Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}
