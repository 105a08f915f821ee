//! `starc lio CAPTURE --out DIR [--device IP|INDEX] [--config FILE] [--imu FILE] [--dump-scans]`:
//! LiDAR-inertial odometry, offline, on every Avia of a capture (pcap, pcapng, .lvx) or of a
//! recording (MCAP: `/<device>/points` with per-point times, `/<device>/imu`).
//!
//! Per device (named as `starc export` names it) it writes into DIR:
//! - `<device>.tum`: the LiDAR's pose at each scan's end, TUM (`t x y z qx qy qz qw`), in the
//!   device's own gravity-aligned odometry frame (its pose at initialization, yaw kept);
//! - `<device>_scans.csv`: per scan, health, the update's figures and the time it took;
//! - `<device>_map.pcd`, `<device>_map.ply`: the local map (voxelized) at the end;
//! - `<device>_scans.bin` with `--dump-scans`: the raw scans for other odometry tools
//!   (`STARCSCN`, u32 version 1, then per scan u64 start ns, u64 end ns, u32 n, n x (f32 x, y, z,
//!   f32 seconds after start), little-endian);
//!
//! and `lio.json`, the summary (timing median and p99, health counts, memory).

use super::export::{DeviceKey, DeviceSelector};
use anyhow::{bail, Context};
use serde::Serialize;
use starc_bridge::external_imu::read_external_imu;
use starc_bridge::is_mcap;
use starc_bridge::livox::{lio_scan, packet_imu};
use starc_bridge::recorded::{recorded, Recorded};
use starc_bridge::wheels::{read_wheel_log, WheelFeedback};
use starc_hil::tum::tum_line;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{Scan, ScanAssembler, ScanConfig, TagFilter};
use starc_pipeline::cloud::{self, CloudFormat, CloudPoint, PointCloud};
use starc_pipeline::lio::{
    Health, ImuSample, ImuSource, InitStatus, Lio, LioConfig, LioFile, LioScan, LioStatus, ScanOutput, WheelSample,
};
use starc_pipeline::timing::peak_rss_mib;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Capture: pcap, pcapng or .lvx (a `starc sim` run's avia.pcap, a Wireshark capture).
    pub file: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Run one device only: its source IPv4 address (pcap, pcapng) or its .lvx device index.
    #[arg(long)]
    pub device: Option<DeviceSelector>,
    /// Settings (TOML, see config/lio.toml); the defaults suit an Avia with its internal IMU.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// External IMU file: a MicroStrain MIP byte stream or a CSV (time_s, gyro xyz rad/s, accel
    /// xyz m/s^2). Needs `[imu] source = "external"` in the config and `--device`.
    #[arg(long)]
    pub imu: Option<PathBuf>,
    /// The base's wheel feedback, a `candump -l` log (C620 or CiA 402 frames, as `starc sim`
    /// writes robot_can.log), fused into the LIO. Needs `--device` and `--base-config`.
    #[arg(long, requires = "base_config")]
    pub wheels: Option<PathBuf>,
    /// The base driver's config (config/base.toml): kinematics, motor protocol, wheel ids.
    #[arg(long)]
    pub base_config: Option<PathBuf>,
    /// Added to the wheel log's stamps to put them on the LiDAR's clock.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    pub wheels_offset_ns: i64,
    /// Also write each device's raw scans to `<device>_scans.bin`.
    #[arg(long)]
    pub dump_scans: bool,
}

/// One device's run.
struct DeviceRun {
    name: String,
    assembler: ScanAssembler,
    lio: Lio,
    done: Vec<Scan>,
    outputs: Vec<ScanOutput>,
    tum: BufWriter<File>,
    table: BufWriter<File>,
    dump: Option<BufWriter<File>>,
    imu_samples: u64,
    scans_in: u64,
    first_ns: Option<u64>,
    last_ns: u64,
    init_reported: Option<InitStatus>,
}

fn create(path: &Path) -> anyhow::Result<BufWriter<File>> {
    Ok(BufWriter::new(File::create(path).with_context(|| format!("creating {}", path.display()))?))
}

impl DeviceRun {
    fn new(out: &Path, name: String, cfg: &LioConfig, scan_cfg: &ScanConfig, dump: bool) -> anyhow::Result<Self> {
        let mut table = create(&out.join(format!("{name}_scans.csv")))?;
        writeln!(
            table,
            "end_s,health,refused,matched,rms_m,degeneracy_index,weak_directions,iterations,points_in,\
             points_used,map_points,pos_sigma_m,yaw_sigma_deg,elapsed_us,wheel,weak_axes,voxel_m"
        )?;
        let dump = if dump {
            let mut w = create(&out.join(format!("{name}_scans.bin")))?;
            w.write_all(b"STARCSCN")?;
            w.write_all(&1u32.to_le_bytes())?;
            Some(w)
        } else {
            None
        };
        Ok(Self {
            tum: create(&out.join(format!("{name}.tum")))?,
            table,
            dump,
            assembler: ScanAssembler::new(scan_cfg.clone()).map_err(|e| anyhow::anyhow!("{e}"))?,
            lio: Lio::new(cfg.clone()),
            done: Vec::new(),
            outputs: Vec::new(),
            imu_samples: 0,
            scans_in: 0,
            first_ns: None,
            last_ns: 0,
            init_reported: None,
            name,
        })
    }

    fn push_imu(&mut self, s: ImuSample, out: &mut Vec<ScanOutput>) {
        self.imu_samples += 1;
        self.lio.push_imu(s, out);
        if let LioStatus::Initializing(st) = self.lio.status() {
            if let InitStatus::MotionDetected { restarts } = st {
                if self.init_reported != Some(st) && restarts % 10 == 1 {
                    tracing::warn!(device = %self.name, restarts, "LIO: the device moved during initialization; waiting for it to stand still");
                }
            }
            self.init_reported = Some(st);
        }
    }

    /// Hands finished scans to the filter (and the dump).
    fn flush_scans(&mut self, out: &mut Vec<ScanOutput>) -> anyhow::Result<()> {
        for scan in std::mem::take(&mut self.done) {
            self.push_scan(lio_scan(&scan), out)?;
        }
        Ok(())
    }

    fn push_scan(&mut self, scan: LioScan, out: &mut Vec<ScanOutput>) -> anyhow::Result<()> {
        self.first_ns.get_or_insert(scan.start_ns);
        self.last_ns = self.last_ns.max(scan.end_ns);
        self.scans_in += 1;
        if let Some(w) = &mut self.dump {
            w.write_all(&scan.start_ns.to_le_bytes())?;
            w.write_all(&scan.end_ns.to_le_bytes())?;
            w.write_all(&(scan.points.len() as u32).to_le_bytes())?;
            for p in &scan.points {
                let dt_s = (p.t_ns.saturating_sub(scan.start_ns)) as f32 * 1e-9;
                for v in [p.x_m, p.y_m, p.z_m, dt_s] {
                    w.write_all(&v.to_le_bytes())?;
                }
            }
        }
        self.lio.push_scan(scan, out);
        Ok(())
    }

    fn record(&mut self, outs: &mut Vec<ScanOutput>) -> anyhow::Result<()> {
        for o in outs.drain(..) {
            writeln!(self.tum, "{}", tum_line(o.end_ns, &o.lidar_pose))?;
            writeln!(
                self.table,
                "{}.{:09},{},{},{},{:.4},{:.4},{},{},{},{},{},{:.4},{:.3},{},{},{},{}",
                o.end_ns / 1_000_000_000,
                o.end_ns % 1_000_000_000,
                o.health.name(),
                o.refused.map_or("", |r| r.name()),
                o.update.matched,
                o.update.rms_m,
                o.update.degeneracy_index,
                o.update.weak_directions,
                o.update.iterations,
                o.points_in,
                o.points_used,
                o.map_points,
                o.pos_sigma_m,
                o.yaw_sigma_deg,
                o.elapsed_us,
                o.wheel.name(),
                starc_pipeline::lio::weak_axes_names(o.update.weak_axes),
                o.voxel_m
            )?;
            self.outputs.push(o);
        }
        Ok(())
    }
}

#[derive(Serialize)]
struct DeviceSummary {
    device: String,
    imu_samples: u64,
    scans_in: u64,
    scans_out: usize,
    capture_s: f64,
    status: String,
    health: BTreeMap<&'static str, u64>,
    scans_refused: u64,
    times_lost: u64,
    /// Scans whose tilt was measured from the accelerometer less the wheels, and those gated.
    level_updates: u64,
    level_gated: u64,
    time_per_scan_ms_median: f64,
    time_per_scan_ms_p99: f64,
    time_per_scan_ms_max: f64,
    points_per_scan_median: usize,
    map_points: usize,
    files: Vec<String>,
}

#[derive(Serialize)]
struct Summary {
    capture: String,
    config: LioFile,
    wall_s: f64,
    /// The process's peak resident memory (VmHWM), MiB.
    peak_rss_mib: Option<f64>,
    devices: Vec<DeviceSummary>,
}

fn quantile_ms(sorted_us: &[u64], q: f64) -> f64 {
    if sorted_us.is_empty() {
        return 0.0;
    }
    let i = ((sorted_us.len() - 1) as f64 * q).round() as usize;
    sorted_us.get(i).map_or(0.0, |&v| v as f64 * 1e-3)
}

/// The rig's LIO settings for `starc mission` and `starc eval`: `path`'s (a LIO config, as
/// config/lio.toml; every key optional), else the rig's defaults (config/lio_rig.toml).
pub fn rig_lio_config(path: Option<&Path>) -> anyhow::Result<LioConfig> {
    let Some(path) = path else { return Ok(starc_pipeline::mission::RigCoreConfig::rig_lio()) };
    load_config(Some(path))?.to_config().with_context(|| format!("{}", path.display()))
}

fn load_config(path: Option<&Path>) -> anyhow::Result<LioFile> {
    let Some(path) = path else { return Ok(LioFile::default()) };
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    LioFile::from_toml(&text).with_context(|| format!("{}", path.display()))
}

/// The wheel log's twists (none without `--wheels`).
fn wheel_samples(args: &Args) -> anyhow::Result<Vec<WheelSample>> {
    let (Some(log), Some(base)) = (&args.wheels, &args.base_config) else { return Ok(Vec::new()) };
    if args.device.is_none() {
        bail!("--wheels belongs to one device (the robot's LiDAR): name it with --device");
    }
    let base = starc_base::BaseConfig::load(base).with_context(|| format!("{}", base.display()))?;
    let samples = read_wheel_log(log, &WheelFeedback::from_base(&base), args.wheels_offset_ns)?;
    tracing::info!(samples = samples.len(), "wheel odometry from {}", log.display());
    Ok(samples)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let file = load_config(args.config.as_deref())?;
    let cfg = file.to_config()?;
    let external = match (file.imu.source, &args.imu) {
        (ImuSource::External, Some(path)) => {
            if args.device.is_none() {
                bail!("--imu belongs to one device: name it with --device");
            }
            Some(read_external_imu(path, file.imu.time_offset_ns)?)
        }
        (ImuSource::External, None) => {
            bail!("the config says [imu] source = \"external\": give the IMU file with --imu")
        }
        (ImuSource::Internal, Some(_)) => {
            bail!("--imu given, but the config's [imu] source is \"internal\" (see config/lio_external_imu.toml)")
        }
        (ImuSource::Internal, None) => None,
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let scan_cfg =
        ScanConfig { period_ms: file.scan.period_ms, tags: TagFilter::FastLio, blind_m: 0.0, ..ScanConfig::default() };
    scan_cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    if is_mcap(&args.file) {
        return run_recording(&args, file, &cfg, &scan_cfg);
    }

    let started = Instant::now();
    let show = std::io::stderr().is_terminal();
    let mut last_shown = Instant::now();
    let mut devices: BTreeMap<DeviceKey, DeviceRun> = BTreeMap::new();
    let mut ext_next = 0usize;
    let wheels = wheel_samples(&args)?;
    let mut wheel_next = 0usize;
    let mut outs = Vec::new();
    let mut read_error = None;
    let cap = capture::open(&args.file).with_context(|| format!("opening {}", args.file.display()))?;
    for item in cap {
        let datagram = match item {
            Ok(d) => d,
            Err(e) => {
                read_error = Some(e);
                break;
            }
        };
        let key = DeviceKey::of(&datagram);
        if args.device.is_some_and(|sel| !sel.matches(key)) {
            continue;
        }
        let Ok(packet) = DataPacket::parse(&datagram.payload) else { continue };
        let dev = match devices.entry(key) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(DeviceRun::new(&args.out, key.to_string(), &cfg, &scan_cfg, args.dump_scans)?)
            }
        };
        let t_ns = packet.header.timestamp.ns;
        dev.first_ns.get_or_insert(t_ns);
        dev.last_ns = dev.last_ns.max(t_ns);
        if let Some(ext) = &external {
            while let Some(s) = ext.get(ext_next).filter(|s| s.t_ns <= t_ns) {
                dev.push_imu(*s, &mut outs);
                ext_next += 1;
            }
        }
        while let Some(w) = wheels.get(wheel_next).filter(|w| w.t_ns <= t_ns) {
            dev.lio.push_wheel(*w);
            wheel_next += 1;
        }
        if let Some(s) = packet_imu(&packet) {
            if external.is_none() {
                dev.push_imu(s, &mut outs);
            }
        } else if !packet.is_imu() {
            dev.assembler.push(&packet, None, &mut dev.done);
            dev.flush_scans(&mut outs)?;
        }
        dev.record(&mut outs)?;
        if show && last_shown.elapsed() >= Duration::from_millis(200) {
            last_shown = Instant::now();
            let line: Vec<String> = devices
                .values()
                .map(|d| {
                    let span = d.last_ns.saturating_sub(d.first_ns.unwrap_or(d.last_ns)) as f64 * 1e-9;
                    let health = d.outputs.last().map_or("initializing", |o| o.health.name());
                    format!("{}: {span:.1} s, {} scans, {health}", d.name, d.outputs.len())
                })
                .collect();
            eprint!("\r{}   ", line.join(" | "));
            let _ = std::io::stderr().flush();
        }
    }
    if show {
        eprint!("\r{:100}\r", "");
    }
    if let Some(ext) = &external {
        for dev in devices.values_mut() {
            for s in &ext[ext_next..] {
                dev.push_imu(*s, &mut outs);
            }
        }
    }
    let outputs = conclude(&args, file, started, devices.values_mut(), &mut outs)?;
    if outputs == 0 {
        match args.device {
            Some(sel) => bail!("no data packets from {sel} in {}", args.file.display()),
            None => bail!("no Livox data packets in {}", args.file.display()),
        }
    }
    if let Some(e) = read_error {
        bail!("{}: reading stopped early (everything before was processed): {e}", args.file.display());
    }
    Ok(())
}

/// Flushes every device, writes their files and lio.json, prints the report; returns how many
/// devices there were.
fn conclude<'a>(
    args: &Args,
    file: LioFile,
    started: Instant,
    devices: impl Iterator<Item = &'a mut DeviceRun>,
    outs: &mut Vec<ScanOutput>,
) -> anyhow::Result<usize> {
    let mut summaries = Vec::new();
    for dev in devices {
        dev.done.extend(dev.assembler.finish());
        dev.flush_scans(outs)?;
        dev.record(outs)?;
        summaries.push(finish(dev, &args.out)?);
    }
    let n = summaries.len();
    let summary = Summary {
        capture: args.file.display().to_string(),
        config: file,
        wall_s: started.elapsed().as_secs_f64(),
        peak_rss_mib: peak_rss_mib(),
        devices: summaries,
    };
    let json = serde_json::to_string_pretty(&summary)?;
    std::fs::write(args.out.join("lio.json"), json + "\n")
        .with_context(|| format!("writing {}", args.out.join("lio.json").display()))?;
    print!("{}", report(&summary));
    Ok(n)
}

/// A recording (MCAP): scans from every `/<device>/points` and IMU samples from `/<device>/imu`,
/// in file order.
fn run_recording(args: &Args, file: LioFile, cfg: &LioConfig, scan_cfg: &ScanConfig) -> anyhow::Result<()> {
    if args.device.is_some() || args.imu.is_some() || args.wheels.is_some() {
        bail!(
            "--device, --imu and --wheels are for captures; a recording's devices are its topics (/robot/points, /robot/imu)"
        );
    }
    let started = Instant::now();
    let period_ns = scan_cfg.period_ns();
    let mut devices: BTreeMap<String, DeviceRun> = BTreeMap::new();
    let mut outs = Vec::new();
    let messages = starc_pipeline::record::reader::open(&args.file, starc_pipeline::record::ReadMode::Recover)
        .with_context(|| format!("opening {}", args.file.display()))?;
    for m in messages {
        let m = m.with_context(|| format!("reading {}", args.file.display()))?;
        let Some(input) = recorded(&m, period_ns)? else { continue };
        let name = match &input {
            Recorded::Imu(d, _) | Recorded::Scan(d, _) | Recorded::Wheel(d, _) => d.clone(),
        };
        let dev = match devices.entry(name.clone()) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(DeviceRun::new(&args.out, name, cfg, scan_cfg, args.dump_scans)?)
            }
        };
        match input {
            Recorded::Imu(_, s) => dev.push_imu(s, &mut outs),
            Recorded::Scan(_, scan) => dev.push_scan(scan, &mut outs)?,
            // The robot node's wheel odometry: used when the LIO config has `[wheels]`.
            Recorded::Wheel(_, w) => dev.lio.push_wheel(w),
        }
        dev.record(&mut outs)?;
    }
    if conclude(args, file, started, devices.values_mut(), &mut outs)? == 0 {
        bail!("{}: no /<device>/points or /<device>/imu messages", args.file.display());
    }
    Ok(())
}

fn finish(dev: &mut DeviceRun, out: &Path) -> anyhow::Result<DeviceSummary> {
    dev.tum.flush()?;
    dev.table.flush()?;
    if let Some(w) = &mut dev.dump {
        w.flush()?;
    }
    let points: Vec<CloudPoint> = dev
        .lio
        .map()
        .points()
        .map(|p| CloudPoint { x_m: p.x as f32, y_m: p.y as f32, z_m: p.z as f32, ..CloudPoint::default() })
        .collect();
    let map = PointCloud::new(None, points);
    let mut files = vec![format!("{}.tum", dev.name), format!("{}_scans.csv", dev.name)];
    for format in [CloudFormat::PcdBinary, CloudFormat::PlyBinary] {
        let name = format!("{}_map.{}", dev.name, format.extension());
        cloud::write(&out.join(&name), &map, format)?;
        files.push(name);
    }
    if dev.dump.is_some() {
        files.push(format!("{}_scans.bin", dev.name));
    }
    let mut times: Vec<u64> = dev.outputs.iter().map(|o| o.elapsed_us).collect();
    times.sort_unstable();
    let mut sizes: Vec<usize> = dev.outputs.iter().map(|o| o.points_in).collect();
    sizes.sort_unstable();
    let mut health = BTreeMap::new();
    for h in Health::ALL {
        health.insert(h.name(), dev.outputs.iter().filter(|o| o.health == h).count() as u64);
    }
    let (scans_refused, times_lost) = dev.lio.health_counts();
    let (level_updates, level_gated) = dev.lio.level_counts();
    let status = match dev.lio.status() {
        LioStatus::Running => "running".to_string(),
        LioStatus::Initializing(InitStatus::MotionDetected { restarts }) => {
            format!("never initialized: the device moved during each of {restarts} windows (it needs to stand still)")
        }
        LioStatus::Initializing(_) => "never initialized: too little IMU data".to_string(),
    };
    Ok(DeviceSummary {
        device: dev.name.clone(),
        imu_samples: dev.imu_samples,
        scans_in: dev.scans_in,
        scans_out: dev.outputs.len(),
        capture_s: dev.last_ns.saturating_sub(dev.first_ns.unwrap_or(0)) as f64 * 1e-9,
        status,
        health,
        scans_refused,
        times_lost,
        level_updates,
        level_gated,
        time_per_scan_ms_median: quantile_ms(&times, 0.5),
        time_per_scan_ms_p99: quantile_ms(&times, 0.99),
        time_per_scan_ms_max: quantile_ms(&times, 1.0),
        points_per_scan_median: sizes.get(sizes.len() / 2).copied().unwrap_or(0),
        map_points: map.len(),
        files,
    })
}

fn report(s: &Summary) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "starc lio {}: {:.2} s wall, peak memory {:.0} MiB",
        s.capture,
        s.wall_s,
        s.peak_rss_mib.unwrap_or(0.0)
    );
    for d in &s.devices {
        let _ = writeln!(
            o,
            "  {}: {} ({:.1} s, {} scans of ~{} points); per scan median {:.2} ms, p99 {:.2} ms, max {:.2} ms; \
             map {} points",
            d.device,
            d.status,
            d.capture_s,
            d.scans_out,
            d.points_per_scan_median,
            d.time_per_scan_ms_median,
            d.time_per_scan_ms_p99,
            d.time_per_scan_ms_max,
            d.map_points
        );
        let h: Vec<String> = d.health.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let _ = writeln!(o, "    health: {}; refused {}, lost {} times", h.join(", "), d.scans_refused, d.times_lost);
        if d.level_updates + d.level_gated > 0 {
            let _ = writeln!(
                o,
                "    tilt from the accelerometer less the wheels: {} scans, {} gated",
                d.level_updates, d.level_gated
            );
        }
    }
    o
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_rig_lio_config_is_the_default_without_a_file_and_the_files_with_one() {
        assert_eq!(rig_lio_config(None).unwrap(), starc_pipeline::mission::RigCoreConfig::default().lio);
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("rig.toml");
        std::fs::write(&good, "[imu]\ngyro_noise_rad_s = 0.01\n").unwrap();
        assert_eq!(rig_lio_config(Some(&good)).unwrap().noise.gyro_rad_s, 0.01);
        // An unknown key is refused, and the error names the file.
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, "[imu]\ngyro_noise = 0.01\n").unwrap();
        let err = format!("{:#}", rig_lio_config(Some(&bad)).unwrap_err());
        assert!(err.contains("bad.toml"), "{err}");
    }
}
