//! What a node's recording loses, and that it never holds up the node: a chunk reaches the disk
//! after a second of silence; a stalled disk drops and counts entries instead of blocking, and
//! `finish` gives up after its wait; `kill -9` loses at most the open chunk (about a second).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_livox::scan::{Scan, ScanPoint};
use starc_node::recording::{NodeRecorder, RecordingCounts};
use starc_node::NodeError;
use starc_pipeline::lio::ImuSample;
use starc_pipeline::record::{messages, ReadMode};
use starc_time::{Clock, Stamp};
use std::io::{BufRead, BufReader, Read};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const T0_NS: u64 = 1_700_000_000_000_000_000;

fn scan(i: u64) -> Scan {
    let points = (0..100u32)
        .map(|k| ScanPoint {
            x_m: 1.0 + k as f32 * 0.01,
            y_m: 0.5,
            z_m: 0.2,
            reflectivity: 10,
            tag: 0,
            line: (k % 6) as u8,
            offset_ns: k * 1000,
        })
        .collect();
    Scan {
        start: Stamp::new(T0_NS + i * 100_000_000, Clock::Ptp),
        period_ns: 100_000_000,
        points,
        packets: 1,
        returns: 100,
        empty: 0,
        filtered: 0,
        lost_packets: 0,
        last_host_receive: None,
    }
}

fn imu(t_ns: u64) -> ImuSample {
    ImuSample {
        t_ns,
        clock: Clock::Ptp,
        gyro_rad_s: nalgebra::Vector3::zeros(),
        acc_m_s2: nalgebra::Vector3::new(0.0, 0.0, 9.81),
    }
}

/// Log times of the messages a reader in recover mode gets from `bytes`.
fn recovered(bytes: &[u8]) -> Vec<u64> {
    messages(bytes, ReadMode::Recover).unwrap().map(|m| m.unwrap().log_ns).collect()
}

#[test]
fn an_open_chunk_reaches_the_disk_after_a_second_of_silence() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("robot.mcap");
    let mut rec = NodeRecorder::create(&path, "robot").unwrap();
    // 0.1 s of log time: far from the 1 s span that closes a chunk by itself.
    for k in 0..20 {
        rec.imu(&imu(T0_NS + k * 5_000_000));
    }
    // Then the LiDAR goes quiet. Within a second (plus the writer's own time) the chunk is on
    // disk although no entry came to close it.
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut found = 0;
    while Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        found = recovered(&std::fs::read(&path).unwrap()).len();
        if found == 20 {
            break;
        }
    }
    assert_eq!(found, 20, "the silent chunk never reached the disk");
    rec.finish().unwrap();
}

/// A disk that takes nothing: a FIFO whose reader does not read (64 KiB of pipe buffer, then
/// every write blocks, as on a stalled disk).
#[test]
fn a_stalled_disk_drops_and_counts_and_never_holds_up_the_node() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stalled.mcap");
    let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: a valid C string and mode; mkfifo touches nothing else.
    assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
    let reader = std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(&path).unwrap();
    let rec = NodeRecorder::create(&path, "robot").unwrap();

    // The node's side on its own thread: if any call blocked, it would not be back in time.
    const SCANS: u64 = 3000;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut rec = rec;
        for i in 0..SCANS {
            rec.scan(scan(i));
        }
        let _ = tx.send(rec);
    });
    let rec = rx.recv_timeout(Duration::from_secs(30)).expect("the node was held up by the disk");
    let counts: RecordingCounts = rec.counts();
    println!("a stalled disk: {SCANS} scans handed over, {counts:?}");
    assert_eq!(counts.queued + counts.dropped, SCANS, "{counts:?}");
    assert!(counts.dropped > 0 && counts.dropped == counts.dropped_scans, "{counts:?}");
    assert!(counts.queued <= 1024 + 64, "more queued than the queue and the writer can hold: {counts:?}");

    // Stopping gives up after its wait instead of hanging on the disk.
    let started = Instant::now();
    let e = rec.finish_within(Duration::from_millis(500)).unwrap_err();
    assert!(matches!(e, NodeError::RecordingStalled { .. }), "{e}");
    assert!(started.elapsed() < Duration::from_secs(5));

    // The disk comes back: the writer thread still writes everything it took, and the index.
    let mut reader = reader;
    // SAFETY: plain fcntl on a descriptor we own, clearing O_NONBLOCK.
    unsafe { libc::fcntl(std::os::fd::AsRawFd::as_raw_fd(&reader), libc::F_SETFL, 0) };
    let mut bytes = Vec::new();
    reader.read_to_end(&mut bytes).unwrap();
    let all: Vec<_> = messages(&bytes, ReadMode::Strict).unwrap().map(|m| m.unwrap()).collect();
    assert_eq!(all.len() as u64, counts.queued, "every entry taken is in the file");
}

/// The child side of the crash test: records the Avia's rates in real time and prints the log
/// time of every entry it has handed over, until killed.
#[test]
fn crash_child() {
    let Some(path) = std::env::var_os("STARC_RECORDING_CRASH_CHILD") else { return };
    let mut rec = NodeRecorder::create(Path::new(&path), "robot").unwrap();
    let started = Instant::now();
    for k in 0..2000u64 {
        let t_ns = T0_NS + k * 5_000_000;
        rec.imu(&imu(t_ns));
        if k % 20 == 0 {
            rec.scan(scan(k / 20));
        }
        println!("{t_ns}");
        let due = Duration::from_millis(5 * (k + 1));
        std::thread::sleep(due.saturating_sub(started.elapsed()));
    }
    rec.finish().unwrap();
}

#[test]
fn kill_9_loses_at_most_the_open_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("crash.mcap");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "crash_child", "--nocapture", "--test-threads", "1"])
        .env("STARC_RECORDING_CRASH_CHILD", &path)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = BufReader::new(child.stdout.take().unwrap());
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in stdout.lines().map_while(Result::ok) {
            if let Ok(t) = line.trim().parse::<u64>() {
                let _ = tx.send(t);
            }
        }
    });
    // 3.9 s of recording (just short of a chunk closing by span), then SIGKILL: no flush, no index.
    let until = Instant::now() + Duration::from_millis(3900);
    let mut handed_over = 0;
    while Instant::now() < until {
        if let Ok(t) = rx.recv_timeout(Duration::from_millis(50)) {
            handed_over = t;
        }
    }
    child.kill().unwrap();
    child.wait().unwrap();
    while let Ok(t) = rx.try_recv() {
        handed_over = handed_over.max(t);
    }
    let kept = recovered(&std::fs::read(&path).unwrap());
    let newest_kept = kept.iter().copied().max().unwrap_or(T0_NS);
    let lost_s = handed_over.saturating_sub(newest_kept) as f64 * 1e-9;
    println!(
        "kill -9 after {:.2} s of log time: {} messages kept, the last {lost_s:.3} s lost",
        (handed_over - T0_NS) as f64 * 1e-9,
        kept.len()
    );
    assert!(handed_over > T0_NS + 2_000_000_000, "the child recorded too little: {handed_over}");
    // The open chunk (at most 1 s of log time) and the few entries in flight to the writer.
    assert!(lost_s <= 1.1, "lost {lost_s:.3} s");
}

/// A bad entry (a stamp past 2038, which ROS 2 time cannot hold) is skipped; the recording
/// goes on and finishes with everything else.
#[test]
fn an_entry_stamped_past_2038_is_skipped_and_the_recording_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("robot.mcap");
    let mut rec = NodeRecorder::create(&path, "robot").unwrap();
    rec.imu(&imu(T0_NS));
    rec.imu(&imu(u64::MAX - 1));
    rec.imu(&imu(T0_NS + 5_000_000));
    rec.finish().unwrap();
    let all: Vec<u64> =
        messages(&std::fs::read(&path).unwrap(), ReadMode::Strict).unwrap().map(|m| m.unwrap().log_ns).collect();
    assert_eq!(all, vec![T0_NS, T0_NS + 5_000_000]);
}
