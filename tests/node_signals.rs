//! `starc robot` finishes its recording (index and all) on SIGINT, SIGTERM and SIGHUP: an
//! operator's Ctrl-C, a service manager's stop, and an SSH session that drops.
//! Loopback only: the link listens on 127.0.0.1, the Livox driver binds 127.0.0.1 and listens
//! for no broadcast (no device comes; the node runs with nothing to do).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_pipeline::record::reader::summarize_file;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Kills the node if the test fails before it exits.
struct Reap(std::process::Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn the_robot_node_finishes_its_recording_on_sigint_sigterm_and_sighup() {
    let dir = tempfile::tempdir().unwrap();
    for (name, signal) in [("SIGINT", libc::SIGINT), ("SIGTERM", libc::SIGTERM), ("SIGHUP", libc::SIGHUP)] {
        let record = dir.path().join(format!("robot_{name}.mcap"));
        let config = dir.path().join(format!("robot_{name}.toml"));
        let data = free_udp_port();
        let text = format!(
            "record = {record:?}\n\n[livox]\nhost_ip = \"127.0.0.1\"\ncmd_port = {}\ndata_port = {data}\nimu_port = {data}\n\n\
             [link]\nlisten = [\"tcp/127.0.0.1:{}\"]\nmulticast_scouting = false\n",
            free_udp_port(),
            free_port()
        );
        std::fs::write(&config, text).unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_starc"))
            .args(["robot", "--config"])
            .arg(&config)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut node = Reap(child);
        let stderr = BufReader::new(node.0.stderr.take().unwrap());
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let mut log = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        while !log.iter().any(|l: &String| l.contains("robot node up")) {
            assert!(Instant::now() < deadline, "{name}: the node never came up:\n{}", log.join("\n"));
            if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
                log.push(line);
            }
        }
        // SAFETY: kill with a pid we spawned and a valid signal number.
        assert_eq!(unsafe { libc::kill(node.0.id() as libc::pid_t, signal) }, 0);
        let deadline = Instant::now() + Duration::from_secs(20);
        let status = loop {
            if let Some(status) = node.0.try_wait().unwrap() {
                break status;
            }
            assert!(Instant::now() < deadline, "{name}: the node did not stop");
            std::thread::sleep(Duration::from_millis(50));
        };
        log.extend(rx.try_iter());
        assert!(status.success(), "{name}: {status:?}\n{}", log.join("\n"));
        let summary = summarize_file(&record).unwrap();
        assert!(summary.finished, "{name}: the recording has no index");
    }
}
