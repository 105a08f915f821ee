//! Serial IMUs end to end over pty pairs: our driver against our mocks (faults on, counts
//! checked), and real peers: PyPI `pymscl` (MicroStrain's MSCL) and PyPI `witmotion` reading our
//! mocks, and pyserial writing frames into our driver.
//!
//! The peers run from `.venv/bin/python` (installed by .ci/run from tests/peers/requirements.txt).
//! Under CI (`CI` set) a missing peer fails the test; elsewhere it is skipped with a message.

use starc_hil::imu::pty::Pty;
use starc_hil::imu::{ImuFaultConfig, MockImu, MockImuConfig, Output, SensorModel};
use starc_imu::config::ImuConfig;
use starc_imu::mip::MipCommand;
use starc_imu::serial::{ImuHandle, ImuPort};
use starc_imu::{GapDetector, ImuEvent, ImuSample, Protocol, RawSample, STANDARD_GRAVITY_M_S2};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc::Receiver;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The venv's python when it can import `module`; `None` (skip) outside CI, a panic in CI.
fn peer_python(module: &str) -> Option<PathBuf> {
    let python = root().join(".venv/bin/python");
    let ok = python.exists()
        && std::process::Command::new(&python)
            .args(["-c", &format!("import {module}")])
            .output()
            .is_ok_and(|o| o.status.success());
    if ok {
        return Some(python);
    }
    if std::env::var_os("CI").is_some() {
        panic!("peer `{module}` is missing from .venv (tests/peers/requirements.txt)");
    }
    println!("skipped: python module {module} not installed in .venv");
    None
}

/// Runs a peer script to completion off the runtime's workers; returns its JSON output.
async fn run_peer(python: PathBuf, args: Vec<String>) -> serde_json::Value {
    let out = tokio::task::spawn_blocking(move || std::process::Command::new(python).args(&args).output())
        .await
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_else(|e| panic!("starting the peer: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {}\n{stdout}", String::from_utf8_lossy(&out.stderr));
    let line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(line).unwrap_or_else(|e| panic!("peer output {stdout:?}: {e}"))
}

fn mock_config(protocol: Protocol, rate_hz: f64, baud: u32) -> MockImuConfig {
    let mut c = MockImuConfig::new(protocol);
    c.rate_hz = rate_hz;
    c.baud = baud;
    c.seed = 11;
    c
}

async fn open(mock: &MockImu, protocol: Protocol, baud: u32) -> (ImuHandle, Receiver<ImuEvent>) {
    let config = ImuConfig::on(mock.port().display().to_string(), protocol, baud);
    ImuPort::open(&config).unwrap_or_else(|e| panic!("{e}"))
}

/// Samples arriving within `seconds`.
async fn collect(events: &mut Receiver<ImuEvent>, seconds: f64) -> Vec<ImuSample> {
    let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(seconds);
    let mut out = Vec::new();
    while let Ok(Some(e)) = tokio::time::timeout_at(deadline, events.recv()).await {
        if let ImuEvent::Sample(s) = e {
            out.push(s);
        }
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn our_driver_reads_our_mip_mock_with_faults_and_counts_them() {
    let mut c = mock_config(Protocol::Mip, 200.0, 921_600);
    c.outputs = Some(vec![Output::Accel, Output::Gyro, Output::Time]);
    c.faults = ImuFaultConfig { garbage: 0.05, drop: 0.02, corrupt: 0.02, ..Default::default() };
    let mock = MockImu::spawn_still(c).unwrap_or_else(|e| panic!("{e}"));
    let (imu, mut events) = open(&mock, Protocol::Mip, 921_600).await;
    imu.mip_ping().await.unwrap_or_else(|e| panic!("{e}"));
    // Idle, let the line go quiet, and count from there.
    imu.mip_idle().await.unwrap_or_else(|e| panic!("{e}"));
    collect(&mut events, 0.2).await;
    let (m0, d0) = (mock.stats().device, imu.stats().decoder);
    imu.mip_resume().await.unwrap_or_else(|e| panic!("{e}"));
    let rate = imu.set_mip_rate(100.0).await.unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rate, 100.0);
    let samples = collect(&mut events, 2.5).await;
    imu.mip_idle().await.unwrap_or_else(|e| panic!("{e}"));
    let tail = collect(&mut events, 0.3).await;
    let (m1, d1) = (mock.stats().device, imu.stats().decoder);
    let (sent, corrupted, dropped) =
        (m1.sent - m0.sent, m1.faults.corrupted - m0.faults.corrupted, m1.faults.dropped - m0.faults.dropped);
    let decoded = d1.samples - d0.samples;
    println!("mock: {sent} sent, {dropped} dropped, {corrupted} corrupted; driver: {decoded} samples; {d1:?}");
    assert!(sent > 200, "{sent}");
    assert!(corrupted > 0 && dropped > 0 && d1.resyncs > d0.resyncs, "faults must have happened");
    // Garbage never costs a MIP packet; a corrupted one is lost, and counted.
    assert_eq!(decoded, sent - corrupted);
    assert_eq!(samples.len() + tail.len(), decoded as usize);
    assert!(d1.bad_checksums - d0.bad_checksums >= corrupted);
    // Losses show as gaps in the device's GPS time (edges of the window are invisible).
    let mut gaps = GapDetector::new(Some(100.0));
    let mut stream: Vec<&ImuSample> = samples.iter().chain(&tail).collect();
    stream.retain(|s| matches!(&s.raw, RawSample::Mip(d) if d.gps_time.is_some()));
    for s in &stream {
        gaps.observe(s.device_ns.unwrap_or(0));
    }
    let lost = dropped + corrupted;
    assert!(gaps.dropped() <= lost && gaps.dropped() + 4 >= lost, "gaps {} lost {lost}", gaps.dropped());
    let g: f64 = stream.iter().map(|s| s.accel_m_s2[2]).sum::<f64>() / stream.len() as f64;
    assert!((g + STANDARD_GRAVITY_M_S2).abs() < 0.1, "a GX5 at rest reads -1 g on z: {g}");
    let ms = mock.stats().device;
    assert_eq!(ms.nacks, 0);
    assert!(ms.acks >= 6 && ms.rate_changes == 1);
    imu.stop().await.unwrap_or_else(|e| panic!("{e}"));
    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mip_baud_change_is_acked_and_the_stream_goes_on() {
    let mock = MockImu::spawn_still(mock_config(Protocol::Mip, 100.0, 115_200)).unwrap_or_else(|e| panic!("{e}"));
    let (imu, mut events) = open(&mock, Protocol::Mip, 115_200).await;
    imu.set_mip_baud(921_600).await.unwrap_or_else(|e| panic!("{e}"));
    let n = collect(&mut events, 1.0).await.len();
    assert!((90..=110).contains(&n), "{n} samples in 1 s after the baud change");
    let s = mock.stats().device;
    assert_eq!((s.baud_changes, s.nacks), (1, 0));
    // A baud the device does not offer is refused with a NACK.
    let e = imu.mip_command(MipCommand::UartBaudRate(starc_imu::mip::Function::Apply(1234))).await;
    assert!(matches!(e, Err(starc_imu::ImuError::Nack { code: 3, .. })), "{e:?}");
    imu.stop().await.unwrap_or_else(|e| panic!("{e}"));
    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn our_driver_sets_a_witmotion_rate_verified_by_what_arrives() {
    let mut c = mock_config(Protocol::WitMotion, 100.0, 115_200);
    c.faults = ImuFaultConfig { garbage: 0.05, drop: 0.02, ..Default::default() };
    c.sensor = SensorModel::default();
    let mock = MockImu::spawn_still(c).unwrap_or_else(|e| panic!("{e}"));
    let (imu, mut events) = open(&mock, Protocol::WitMotion, 115_200).await;
    let drain = tokio::spawn(async move { collect(&mut events, 3.5).await });
    let observed = imu.set_witmotion_rate(50.0, 2).await.unwrap_or_else(|e| panic!("{e}"));
    assert!((observed - 50.0).abs() < 5.0, "{observed}");
    let s = mock.stats().device;
    assert_eq!((s.config_writes, s.locked_writes, s.rate_changes), (2, 0, 1));
    let samples = drain.await.unwrap_or_else(|e| panic!("{e}"));
    let d = imu.stats().decoder;
    assert!(d.resyncs > 0 && d.skipped_bytes > 0, "{d:?}");
    let n = samples.len() as f64;
    let az = samples.iter().map(|s| s.accel_m_s2[2]).sum::<f64>() / n;
    let gx = samples.iter().map(|s| s.gyro_rad_s[0]).sum::<f64>() / n;
    assert!((az - STANDARD_GRAVITY_M_S2 - 0.03).abs() < 0.02, "a flat WT901 reads +1 g on z (+0.03 bias): {az}");
    assert!((gx - 0.002).abs() < 0.002, "gyro x bias 0.002 rad/s: {gx}");
    // A rate the device cannot do never reaches it.
    assert!(imu.set_witmotion_rate(300.0, 1).await.is_err());
    imu.stop().await.unwrap_or_else(|e| panic!("{e}"));
    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pymscl_reads_our_mip_mock_and_gets_acks() {
    let Some(python) = peer_python("mscl") else { return };
    let mut c = mock_config(Protocol::Mip, 100.0, 115_200);
    c.outputs = Some(vec![Output::Accel, Output::Gyro, Output::Time]);
    let mock = MockImu::spawn_still(c).unwrap_or_else(|e| panic!("{e}"));
    let script = root().join("tests/peers/mscl_read.py").display().to_string();
    let v = run_peer(python, vec![script, mock.port().display().to_string(), "115200".into(), "2".into()]).await;
    println!("pymscl: {v}");
    assert!(v.get("error").is_none(), "{v}");
    assert_eq!((v["ping"].as_bool(), v["idle"].as_bool(), v["resume"].as_bool()), (Some(true), Some(true), Some(true)));
    assert_eq!(v["packets_while_idle"], 0);
    let packets = v["packets"].as_u64().unwrap_or(0);
    assert!((180..=215).contains(&packets), "{packets} packets in 2 s at 100 Hz");
    for ch in ["scaledAccelZ", "scaledGyroX", "gpsCorrelTimestampTow", "gpsCorrelTimestampWeekNum"] {
        assert_eq!(v["channels"][ch].as_u64(), Some(packets), "{ch}");
    }
    let az = v["means"]["scaledAccelZ"].as_f64().unwrap_or(0.0);
    assert!((az + 1.0 - 0.03 / STANDARD_GRAVITY_M_S2).abs() < 0.002, "MSCL reads -1 g (+bias) on z: {az}");
    let gx = v["means"]["scaledGyroX"].as_f64().unwrap_or(0.0);
    assert!((gx - 0.002).abs() < 0.002, "{gx}");
    let tows = v["tow_first_last"].as_array().cloned().unwrap_or_default();
    let span =
        tows.get(1).and_then(|t| t.as_f64()).unwrap_or(0.0) - tows.first().and_then(|t| t.as_f64()).unwrap_or(0.0);
    assert!((span - (packets - 1) as f64 * 0.01).abs() < 0.05, "GPS time of week spans the packets: {span}");
    let s = mock.stop().await.unwrap_or_else(|e| panic!("{e}")).device;
    assert_eq!((s.commands, s.acks, s.nacks), (3, 3, 0), "MSCL's ping, set idle and resume");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pypi_witmotion_reads_our_witmotion_mock_and_changes_its_rate() {
    let Some(python) = peer_python("witmotion") else { return };
    let mock = MockImu::spawn_still(mock_config(Protocol::WitMotion, 100.0, 115_200)).unwrap_or_else(|e| panic!("{e}"));
    let script = root().join("tests/peers/witmotion_read.py").display().to_string();
    let v = run_peer(python, vec![script, mock.port().display().to_string(), "115200".into(), "1".into(), "50".into()])
        .await;
    println!("witmotion: {v}");
    for kind in ["AccelerationMessage", "AngularVelocityMessage", "AngleMessage"] {
        let before = v["counts"][kind].as_u64().unwrap_or(0);
        let after = v["counts_after_rate"][kind].as_u64().unwrap_or(0);
        assert!((95..=105).contains(&before), "{kind}: {before} at 100 Hz");
        assert!((45..=55).contains(&after), "{kind}: {after} at 50 Hz");
    }
    // witmotion scales by g = 9.8; 1 g + 0.03 m/s^2 of bias comes out as 9.8 * 1.003.
    let az = v["last"]["a"][2].as_f64().unwrap_or(0.0);
    assert!((az - 9.8 * (1.0 + 0.03 / STANDARD_GRAVITY_M_S2)).abs() < 0.08, "{az}");
    assert_eq!(v["last"]["temp_c"].as_f64(), Some(25.0));
    let s = mock.stop().await.unwrap_or_else(|e| panic!("{e}")).device;
    assert_eq!((s.config_writes, s.locked_writes, s.rate_changes), (2, 0, 1), "unlock + rate write from witmotion");
}

/// pyserial writes frames built in Python (stray sync bytes and false headers between them)
/// into a pty; our driver reads the other end and must decode every one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pyserial_writes_frames_our_driver_decodes_every_one() {
    let Some(python) = peer_python("serial") else { return };
    for protocol in [Protocol::Mip, Protocol::WitMotion] {
        let (pty, master) = Pty::open(None).unwrap_or_else(|e| panic!("{e}"));
        let config = ImuConfig::on(pty.tty().display().to_string(), protocol, 115_200);
        let (imu, mut events) = ImuPort::from_stream(master, &config).unwrap_or_else(|e| panic!("{e}"));
        let script = root().join("tests/peers/serial_write.py").display().to_string();
        let n = 400u32;
        let args = vec![script, pty.tty().display().to_string(), protocol.name().into(), n.to_string(), "3".into()];
        let v = run_peer(python.clone(), args).await;
        println!("pyserial {protocol}: {v}");
        let samples = collect(&mut events, 0.5).await;
        let idx: Vec<u32> = samples
            .iter()
            .map(|s| match &s.raw {
                RawSample::Mip(d) => (d.gps_time.map(|t| t.tow_s).unwrap_or(-1.0) * 100.0).round() as u32,
                RawSample::WitMotion(g) => g.accel.map(|a| a[0] as u16 as u32).unwrap_or(u32::MAX),
            })
            .collect();
        assert_eq!(idx, (0..n).collect::<Vec<_>>(), "{protocol}: every sample, in order");
        for (k, s) in samples.iter().enumerate() {
            let k = k as f64;
            match protocol {
                Protocol::Mip => {
                    assert!((s.accel_m_s2[0] - k / 1000.0 * STANDARD_GRAVITY_M_S2).abs() < 1e-4);
                    assert!((s.gyro_rad_s[0] - k / 10000.0).abs() < 1e-6);
                }
                Protocol::WitMotion => {
                    assert!((s.gyro_rad_s[0] - (3.0 * k * 2000.0 / 32768.0).to_radians()).abs() < 1e-9);
                    assert!((s.accel_m_s2[2] - STANDARD_GRAVITY_M_S2).abs() < 1e-9);
                }
            }
        }
        let d = imu.stats().decoder;
        let garbage = v["garbage_bytes"].as_u64().unwrap_or(0);
        assert_eq!(d.skipped_bytes, garbage, "{protocol}: exactly the garbage is skipped");
        assert_eq!(d.resyncs, v["garbage_bursts"].as_u64().unwrap_or(0));
        if protocol == Protocol::WitMotion {
            let pypi = v["pypi_witmotion_frames"].as_u64().unwrap_or(0);
            println!("same bytes: STARC decoded {} frames of {}, PyPI witmotion {pypi}", d.frames, 3 * n);
            assert_eq!(d.frames, u64::from(3 * n));
        }
        imu.stop().await.unwrap_or_else(|e| panic!("{e}"));
        drop(pty);
    }
}
