//! The host dies while driving: `starc base drive` (the real program, W held on its terminal)
//! drives a mock CiA 402 base over slcan on a pty (as tests/can_peers.rs: no AF_CAN here),
//! then is killed. With `kill -9` nothing on the host can react, so the drives must stop by
//! themselves: their consumer heartbeat (0x1016, written by the host's bring-up) sees the host's
//! heartbeat stop and they quick-stop (0x6007 = 3). With SIGHUP (the SSH session dropped) the
//! program halts the drives itself, in order, before it exits. Either way every drive must have
//! left Operation Enabled within 200 ms of the last host heartbeat it heard.

#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "support/base_toml.rs"]
mod base_toml;
use base_toml::slcan_base_toml;
use starc_base::cia402::DriveState;
use starc_hil::motors::pty::PtyDevice;
use starc_hil::motors::{MockMotors, MockMotorsConfig, MockProtocol, MotorsStats};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The drive program, killed and reaped however the test ends: no process left behind.
struct Host(Child);

impl Host {
    fn pid(&self) -> i32 {
        i32::try_from(self.0.id()).unwrap()
    }

    fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid, which it keeps until we reap it.
        assert_eq!(unsafe { libc::kill(self.pid(), signal) }, 0, "kill({}, {signal})", self.pid());
    }

    fn wait_for_exit(&mut self, limit: Duration) -> ExitStatus {
        let end = Instant::now() + limit;
        while Instant::now() < end {
            if let Some(status) = self.0.try_wait().unwrap() {
                return status;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("starc base drive did not exit within {limit:?}");
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn write_config(dir: &Path, port: &Path) -> std::path::PathBuf {
    let path = dir.join("base.toml");
    // The RPDO deadline off: the commands stop with the host too, and the deadline (100 ms by
    // default) would stop the drives first; this checks the heartbeat path alone (the deadline
    // has its own test in the mock drive).
    let cia402 = "[motors.cia402]\nhost_node_id = 127\nhost_heartbeat_ms = 50\nconsumer_heartbeat_ms = 150\nabort_connection_option = 3\nrpdo_deadline_ms = 0";
    let text = slcan_base_toml(port, "cia402", "{ id = 1 }, { id = 2 }, { id = 3 }", (4.0, 8.0), cia402);
    std::fs::write(&path, text).unwrap();
    path
}

fn driving(s: &MotorsStats) -> bool {
    s.drives.len() == 3
        && s.drives.iter().all(|(_, d)| d.state == Some(DriveState::OperationEnabled) && d.actual_velocity.abs() > 20)
}

/// Starts the program with W held, waits until every drive turns, holds W a little longer,
/// sends `signal`, and returns the mock's counters 700 ms later, the exit status and the
/// program's output.
async fn drive_then(signal: i32) -> (MotorsStats, ExitStatus, String) {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("can");
    let config = MockMotorsConfig {
        protocol: MockProtocol::Cia402,
        port: port.clone(),
        ids: vec![1, 2, 3],
        ..Default::default()
    };
    let mock = MockMotors::spawn(config).await.unwrap();
    // The program's terminal: raw mode and key reading need a tty on stdin.
    let tty = PtyDevice::open(&dir.path().join("tty")).unwrap();
    let stdin = std::fs::OpenOptions::new().read(true).write(true).open(tty.slave_path()).unwrap();
    let log = dir.path().join("host.log");
    let mut host = Host(
        Command::new(env!("CARGO_BIN_EXE_starc"))
            .args(["base", "drive", "--config"])
            .arg(write_config(dir.path(), &port))
            .args(["--speed", "0.3", "--hold-ms", "300"])
            .env("RUST_LOG", "info")
            .stdin(Stdio::from(stdin))
            .stdout(std::fs::File::create(&log).unwrap())
            .stderr(std::fs::File::create(dir.path().join("host.err")).unwrap())
            .spawn()
            .unwrap(),
    );
    let read_log = || {
        let out = std::fs::read_to_string(&log).unwrap_or_default();
        let err = std::fs::read_to_string(dir.path().join("host.err")).unwrap_or_default();
        format!("{out}\n--- stderr ---\n{err}")
    };

    // Hold W (key repeat: a press every 50 ms) until the base drives, then 300 ms more.
    let start = Instant::now();
    let mut since_driving: Option<Instant> = None;
    while since_driving.is_none_or(|t| t.elapsed() < Duration::from_millis(300)) {
        assert!(start.elapsed() < Duration::from_secs(6), "never drove: {:?}\n{}", mock.stats_now(), read_log());
        assert!(host.0.try_wait().unwrap().is_none(), "starc base drive exited:\n{}", read_log());
        tty.write_now(b"w");
        if since_driving.is_none() && driving(&mock.stats_now()) {
            since_driving = Some(Instant::now());
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(driving(&mock.stats_now()), "{:?}", mock.stats_now());
    host.signal(signal);
    let status = host.wait_for_exit(Duration::from_secs(3));
    // Long enough for a 150 ms consumer time-out and the brake, short of the operator's patience.
    tokio::time::sleep(Duration::from_millis(700)).await;
    let stats = mock.stop().await.unwrap();
    drop(tty);
    (stats, status, read_log())
}

/// Every drive left Operation Enabled at most 200 ms after the last host heartbeat it heard;
/// the (drive, milliseconds) of each.
fn stopped_within_200_ms(stats: &MotorsStats, log: &str) -> Vec<(u8, f64)> {
    assert_eq!(stats.drives.len(), 3);
    let mut out = Vec::new();
    for (node, d) in &stats.drives {
        let last = d.last_host_heartbeat_ns.unwrap_or_else(|| panic!("node {node} heard no host heartbeat: {d:?}"));
        let left = d.left_enabled_ns.unwrap_or_else(|| panic!("node {node} never stopped: {d:?}\n{log}"));
        let after_ms = (left as f64 - last as f64) * 1e-6;
        assert!(after_ms <= 200.0, "node {node} stopped {after_ms:.1} ms after the last heartbeat: {d:?}");
        assert!(d.host_heartbeats >= 10, "node {node}: {d:?}");
        assert!(d.actual_velocity.abs() <= 5, "node {node} still turning: {d:?}");
        out.push((*node, after_ms));
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_of_the_host_the_drives_quick_stop_on_their_own() {
    let (stats, status, log) = drive_then(libc::SIGKILL).await;
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(status.signal(), Some(libc::SIGKILL), "{status:?}");
    let stops = stopped_within_200_ms(&stats, &log);
    for (node, d) in &stats.drives {
        // Nothing from the host stopped it: the consumer heartbeat did, at 150 ms of silence.
        assert_eq!(d.consumer_timeouts, 1, "node {node}: {d:?}");
        assert_eq!(d.heartbeat_lost_ns, d.left_enabled_ns, "node {node}: {d:?}");
        assert_eq!(d.state, Some(DriveState::QuickStopActive), "node {node}: {d:?}");
    }
    println!("kill -9: drives stopped {stops:?} ms after the host's last heartbeat");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sighup_of_the_host_halts_the_drives_in_order() {
    let (stats, status, log) = drive_then(libc::SIGHUP).await;
    assert!(status.success(), "{status:?}\n{log}");
    assert!(log.contains("SIGHUP: halting the motors") && log.contains("stopped; bus:"), "{log}");
    let stops = stopped_within_200_ms(&stats, &log);
    for (node, d) in &stats.drives {
        // The host's quick stop came first; the consumer time-out, when the host had gone, found
        // the drive stopped already.
        let left = d.left_enabled_ns.unwrap_or(u64::MAX);
        assert!(d.heartbeat_lost_ns.is_none_or(|lost| left < lost), "node {node}: {d:?}");
        assert_eq!(d.state, Some(DriveState::QuickStopActive), "node {node}: {d:?}");
    }
    println!("SIGHUP: drives stopped {stops:?} ms after the host's last heartbeat");
}
