//! Shared by the link tests: loopback-only configs with short timings, free ports, bounded waits.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, Instant};

use starc_link::{LinkConfig, LinkNode, LinkState, Received};

/// A port free on 127.0.0.1 right now (the OS picks it; the small race is acceptable in tests).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
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
