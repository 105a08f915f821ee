//! `starc imu monitor`: a serial IMU live, once a second; and `starc mock imu` (wired from
//! `cmd::mock`): a mock MIP or WitMotion IMU on a pty.

use anyhow::Context;
use starc_hil::imu::{MockImu, MockImuConfig, MockImuStats, Output};
use starc_imu::config::ImuConfig;
use starc_imu::serial::{ImuPort, PortStats};
use starc_imu::{GapDetector, ImuEvent, ImuSample, Protocol};
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Live rate, biases (means), noise (std), checksum errors, resyncs and dropped samples.
    Monitor(MonitorArgs),
}

#[derive(clap::Args)]
pub struct MonitorArgs {
    /// Serial port, e.g. /dev/ttyACM0, /dev/ttyUSB0 or a mock's link such as /tmp/starc-imu.
    pub port: Option<String>,
    /// mip or witmotion [default: mip, or the config's].
    #[arg(long)]
    pub protocol: Option<Protocol>,
    /// Line rate the device is at [default: 115200, or the config's].
    #[arg(long)]
    pub baud: Option<u32>,
    /// Settings from a TOML file (see config/imu.toml); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Set the output rate first (MIP: ACKed decimation; WitMotion: verified by the observed rate).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Stop after S seconds [default: until Ctrl-C].
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// One JSON object per second instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Monitor(args) => monitor(args),
    }
}

fn seconds(s: Option<f64>, flag: &str) -> anyhow::Result<Option<Duration>> {
    match s {
        Some(s) if s.is_finite() && s > 0.0 => Ok(Some(Duration::from_secs_f64(s))),
        Some(s) => anyhow::bail!("{flag} {s}: must be a positive number of seconds"),
        None => Ok(None),
    }
}

impl MonitorArgs {
    fn config(&self) -> anyhow::Result<ImuConfig> {
        let mut c = match &self.config {
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                ImuConfig::from_toml(&text).with_context(|| format!("parsing {}", path.display()))?
            }
            None => ImuConfig::default(),
        };
        if let Some(p) = &self.port {
            c.port = p.clone();
        } else if self.config.is_none() {
            anyhow::bail!("give a PORT or a --config");
        }
        if let Some(p) = self.protocol {
            c.protocol = p;
        }
        if let Some(b) = self.baud {
            c.baud = b;
        }
        if self.rate_hz.is_some() {
            c.rate_hz = self.rate_hz;
        }
        c.validate()?;
        Ok(c)
    }
}

/// Running mean and spread of one window.
#[derive(Default)]
struct Window {
    n: u64,
    sum: [f64; 6],
    sq: [f64; 6],
    incomplete: u64,
}

impl Window {
    fn add(&mut self, s: &ImuSample) {
        self.n += 1;
        for (i, v) in s.gyro_rad_s.iter().chain(&s.accel_m_s2).enumerate() {
            self.sum[i] += v;
            self.sq[i] += v * v;
        }
    }

    fn mean(&self) -> [f64; 6] {
        let n = self.n.max(1) as f64;
        self.sum.map(|s| s / n)
    }

    fn std(&self) -> [f64; 6] {
        let n = self.n.max(1) as f64;
        let mean = self.mean();
        std::array::from_fn(|i| (self.sq[i] / n - mean[i] * mean[i]).max(0.0).sqrt())
    }
}

fn v3(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:+.5}")).collect();
    format!("[{}]", parts.join(" "))
}

fn monitor(args: MonitorArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let duration = seconds(args.duration, "--duration")?;
    let runtime = super::runtime()?;
    runtime.block_on(async move {
        let (imu, mut events) = ImuPort::open(&config)?;
        eprintln!("{}: {} at {} baud", config.port, config.protocol, config.baud);
        if let Some(rate) = imu.configure(&config).await? {
            eprintln!("output rate set to {rate:.1} Hz");
        }
        let started = tokio::time::Instant::now();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.tick().await;
        let mut window = Window::default();
        // Gaps on the device's clock when it sends one, else on host stamps; a switch restarts.
        let mut gaps = GapDetector::new(None);
        let mut on_device_clock = None;
        let mut dropped_before = 0;
        let mut last = (tokio::time::Instant::now(), PortStats::default());
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        loop {
            tokio::select! {
                e = events.recv() => match e {
                    Some(ImuEvent::Sample(s)) => {
                        if on_device_clock != Some(s.device_ns.is_some()) {
                            dropped_before += gaps.dropped();
                            gaps = GapDetector::new(None);
                            on_device_clock = Some(s.device_ns.is_some());
                        }
                        gaps.observe(s.device_ns.unwrap_or(s.stamp.ns));
                        window.add(&s);
                    }
                    Some(ImuEvent::Incomplete(_)) => window.incomplete += 1,
                    Some(ImuEvent::MipReply(_)) => {}
                    None => anyhow::bail!("{}: the port closed", config.port),
                },
                _ = tick.tick() => {
                    let (now, stats) = (tokio::time::Instant::now(), imu.stats());
                    let dt = (now - last.0).as_secs_f64();
                    print_window(&args, started.elapsed().as_secs_f64(), dt, &window, &stats, dropped_before + gaps.dropped());
                    window = Window::default();
                    last = (now, stats);
                    if duration.is_some_and(|d| started.elapsed() >= d) {
                        break;
                    }
                }
                r = &mut ctrl_c => { r.context("waiting for Ctrl-C")?; break; }
            }
        }
        imu.stop().await?;
        anyhow::Ok(())
    })
}

fn print_window(args: &MonitorArgs, t: f64, dt: f64, w: &Window, s: &PortStats, dropped: u64) {
    let rate = if dt > 0.0 { w.n as f64 / dt } else { 0.0 };
    let (mean, std) = (w.mean(), w.std());
    let d = &s.decoder;
    if args.json {
        let v = serde_json::json!({
            "t_s": t, "rate_hz": rate, "samples": w.n, "incomplete": w.incomplete,
            "gyro_mean_rad_s": &mean[..3], "gyro_std_rad_s": &std[..3],
            "accel_mean_m_s2": &mean[3..], "accel_std_m_s2": &std[3..],
            "dropped": dropped, "stats": s,
        });
        println!("{v}");
        return;
    }
    println!("{t:6.1} s  {rate:7.1} Hz  gyro mean {} std {} rad/s", v3(&mean[..3]), v3(&std[..3]),);
    println!("           accel mean {} std {} m/s^2", v3(&mean[3..]), v3(&std[3..]),);
    println!(
        "           bad checksums {}  resyncs {}  skipped {} B  dropped {}  incomplete {}  samples {}",
        d.bad_checksums, d.resyncs, d.skipped_bytes, dropped, d.incomplete, d.samples
    );
}

// ---------------------------------------------------------------------------------------------
// starc mock imu

#[derive(clap::Args)]
pub struct MockArgs {
    /// A TOML mock config (the fields of `MockImuConfig`); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// mip or witmotion [default: mip].
    #[arg(long)]
    pub protocol: Option<Protocol>,
    /// Create a symlink here to the pty slave, e.g. /tmp/starc-imu [default: print /dev/pts/N only].
    #[arg(long)]
    pub port: Option<PathBuf>,
    /// Output rate at power-on [default: 100].
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Baud rate at power-on; paces the output [default: 115200].
    #[arg(long)]
    pub baud: Option<u32>,
    /// What streams, comma-separated: accel,gyro,mag,quaternion,euler,time.
    #[arg(long, value_delimiter = ',')]
    pub outputs: Option<Vec<String>>,
    /// Fraction of samples preceded by 1-8 garbage bytes.
    #[arg(long, value_name = "P")]
    pub garbage: Option<f64>,
    /// Fraction of samples never sent.
    #[arg(long, value_name = "P")]
    pub drop: Option<f64>,
    /// Fraction of samples with a corrupted checksum.
    #[arg(long, value_name = "P")]
    pub corrupt: Option<f64>,
    /// Go quiet (no data, no replies) S seconds after start.
    #[arg(long, value_name = "S")]
    pub silence_after: Option<f64>,
    /// Seed of the noise and the faults [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Stop after S seconds [default: until Ctrl-C].
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// Print the final counters as JSON.
    #[arg(long)]
    pub json: bool,
}

fn output(name: &str) -> anyhow::Result<Output> {
    Ok(match name.trim() {
        "accel" => Output::Accel,
        "gyro" => Output::Gyro,
        "mag" => Output::Mag,
        "quaternion" => Output::Quaternion,
        "euler" | "angle" => Output::Euler,
        "time" => Output::Time,
        other => anyhow::bail!("unknown output {other:?} (accel, gyro, mag, quaternion, euler, time)"),
    })
}

impl MockArgs {
    fn config(&self) -> anyhow::Result<MockImuConfig> {
        let mut c = match &self.config {
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?
            }
            None => MockImuConfig::new(self.protocol.unwrap_or(Protocol::Mip)),
        };
        if let Some(p) = self.protocol {
            c.protocol = p;
        }
        if let Some(p) = &self.port {
            c.port = Some(p.clone());
        }
        if let Some(r) = self.rate_hz {
            c.rate_hz = r;
        }
        if let Some(b) = self.baud {
            c.baud = b;
        }
        if let Some(o) = &self.outputs {
            c.outputs = Some(o.iter().map(|n| output(n)).collect::<anyhow::Result<_>>()?);
        }
        if let Some(s) = self.seed {
            c.seed = s;
        }
        for (flag, field) in [
            (self.garbage, &mut c.faults.garbage),
            (self.drop, &mut c.faults.drop),
            (self.corrupt, &mut c.faults.corrupt),
        ] {
            if let Some(v) = flag {
                *field = v;
            }
        }
        if self.silence_after.is_some() {
            c.faults.silence_after_s = self.silence_after;
        }
        c.validate()?;
        Ok(c)
    }
}

pub fn mock(args: MockArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let duration = seconds(args.duration, "--duration")?;
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let (stats, elapsed) = runtime.block_on(async move {
        let started = tokio::time::Instant::now();
        let mock = MockImu::spawn_still(config.clone())?;
        // The path goes to stdout so that scripts can read it.
        println!("{}", mock.port().display());
        eprintln!(
            "mock {} IMU on {} (pty {}), {} Hz at {} baud; Ctrl-C stops",
            config.protocol,
            mock.port().display(),
            mock.tty().display(),
            config.rate_hz,
            config.baud
        );
        let stopped = async {
            match duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            signal = tokio::signal::ctrl_c() => signal.context("waiting for Ctrl-C")?,
            _ = stopped => {}
        }
        let stats = mock.stop().await?;
        anyhow::Ok((stats, started.elapsed()))
    })?;
    if args.json {
        let v = serde_json::json!({ "seconds": elapsed.as_secs_f64(), "stats": stats });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_mock_stats(elapsed, &stats);
    }
    Ok(())
}

fn print_mock_stats(elapsed: Duration, s: &MockImuStats) {
    let d = &s.device;
    let f = &d.faults;
    eprintln!("ran {:.1} s", elapsed.as_secs_f64());
    eprintln!(
        "  samples   {} due, {} sent, {} lost to overruns; {} bytes written, {} dropped (not read)",
        d.samples, d.sent, d.overruns, s.bytes_written, s.bytes_dropped
    );
    eprintln!(
        "  host      {} bytes; MIP {} commands, {} ACK, {} NACK; WitMotion {} writes ({} while locked), {} saves",
        s.host_bytes, d.commands, d.acks, d.nacks, d.config_writes, d.locked_writes, d.saves
    );
    eprintln!("  settings  {} rate changes, {} baud changes", d.rate_changes, d.baud_changes);
    eprintln!(
        "  faults    {} garbage bursts ({} bytes), {} dropped, {} corrupted",
        f.garbage_bursts, f.garbage_bytes, f.dropped, f.corrupted
    );
}
