//! `starc base`: the omni-wheel base over CAN.
//!
//! `starc base status --config config/base.toml` brings the motors up and prints their states,
//! the odometry and any faults (`--watch` keeps printing). `starc base drive --config ...` is a
//! keyboard teleop in the terminal: W/S forward/back, A/D left/right, Q/E turn, space stops,
//! c clears faults, x or Esc quits. `starc mock motors` (the [`MockArgs`] here) plays C620 ESCs
//! or CiA 402 drives behind an slcan adapter on a pty.
//!
//! SIGINT, SIGTERM and SIGHUP (the terminal or the SSH session gone) end either command in
//! order: the motors are halted first. A `kill -9` cannot be caught; for that the CiA 402
//! drives watch the host's heartbeat and stop by themselves (docs/safety.md).

use anyhow::Context;
use starc_base::runner::{open_bus, spawn, BaseHandle};
use starc_base::{Base, BaseConfig, BaseEvent, BaseStatus, Twist};
use starc_hil::motors::{MockMotors, MockMotorsConfig, MockProtocol, MotorFaultConfig};
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Bring the motors up and print motor states, odometry and faults.
    Status(StatusArgs),
    /// Keyboard teleop: W/S, A/D, Q/E; space stops; c clears faults; x or Esc quits.
    Drive(DriveArgs),
}

#[derive(clap::Args)]
pub struct StatusArgs {
    /// The base config (see config/base.toml).
    #[arg(long)]
    pub config: PathBuf,
    /// How long to listen before printing.
    #[arg(long, default_value_t = 1.5, value_name = "S")]
    pub seconds: f64,
    /// Keep printing every half second until Ctrl-C.
    #[arg(long)]
    pub watch: bool,
    /// Print the status as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct DriveArgs {
    #[arg(long)]
    pub config: PathBuf,
    /// Linear speed of W/S/A/D in m/s.
    #[arg(long, default_value_t = 0.3)]
    pub speed: f64,
    /// Turn rate of Q/E in rad/s.
    #[arg(long, default_value_t = 1.0)]
    pub turn: f64,
    /// Without a key press for this long the base stops (dead man; key repeat keeps it going).
    #[arg(long, default_value_t = 600, value_name = "MS")]
    pub hold_ms: u64,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    let runtime = super::runtime()?;
    match command {
        Command::Status(a) => runtime.block_on(status(a)),
        Command::Drive(a) => runtime.block_on(drive(a)),
    }
}

/// SIGINT, SIGTERM and SIGHUP, caught for as long as this lives. Installed before the base
/// starts: from then on none of them ends the process the default way, halt frames unsent.
struct Signals {
    interrupt: tokio::signal::unix::Signal,
    terminate: tokio::signal::unix::Signal,
    hangup: tokio::signal::unix::Signal,
}

impl Signals {
    fn install() -> anyhow::Result<Self> {
        use tokio::signal::unix::{signal, SignalKind};
        Ok(Self {
            interrupt: signal(SignalKind::interrupt()).context("catching SIGINT")?,
            terminate: signal(SignalKind::terminate()).context("catching SIGTERM")?,
            hangup: signal(SignalKind::hangup()).context("catching SIGHUP")?,
        })
    }

    /// The name of the next signal.
    async fn recv(&mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "SIGINT",
            _ = self.terminate.recv() => "SIGTERM",
            _ = self.hangup.recv() => "SIGHUP",
        }
    }
}

async fn start(config: &std::path::Path) -> anyhow::Result<(BaseHandle, tokio::sync::mpsc::Receiver<BaseEvent>)> {
    let config = BaseConfig::load(config).with_context(|| format!("loading {}", config.display()))?;
    let (bus, options) = open_bus(&config.can).await.context("opening the CAN transport")?;
    Ok(spawn(bus, Base::new(config)?, options))
}

fn print_status(s: &BaseStatus) {
    println!(
        "base: mode {:?}, ready {}, e-stop {}, watchdog {}",
        s.mode,
        s.ready,
        if s.estop_pressed { "PRESSED" } else { "released" },
        if s.watchdog_tripped { "tripped (no command)" } else { "fed" }
    );
    if s.faults.is_empty() {
        println!("faults: none");
    }
    for f in &s.faults {
        println!("fault: {f}");
    }
    for w in &s.wheels {
        let opt = |v: Option<f64>, unit: &str| v.map(|x| format!("{x:7.2} {unit}")).unwrap_or_else(|| "      -".into());
        let age = match (s.stamp, w.last_feedback) {
            (Some(now), Some(t)) => now.since(t).map(|ns| format!("{} ms ago", ns / 1_000_000)).unwrap_or_default(),
            _ => "never".into(),
        };
        println!(
            "wheel {} (motor {:3}): {:8} target {:7.2} rad/s  measured {}  current {}  temp {}  sw {}  feedback {}",
            w.wheel,
            w.motor,
            format!("{:?}", w.phase).to_lowercase(),
            w.target_rad_s,
            opt(w.measured_rad_s, "rad/s"),
            opt(w.current_a, "A"),
            opt(w.temperature_c, "C"),
            w.statusword.map(|x| format!("{x:#06x}")).unwrap_or_else(|| "-".into()),
            age
        );
    }
    match &s.odometry {
        Some(o) => println!(
            "odometry: x {:.3} m  y {:.3} m  theta {:.1} deg  vx {:.3} m/s  vy {:.3} m/s  wz {:.3} rad/s  (at {})",
            o.x_m,
            o.y_m,
            o.theta_rad.to_degrees(),
            o.twist.vx_m_s,
            o.twist.vy_m_s,
            o.twist.wz_rad_s,
            o.stamp
        ),
        None => println!("odometry: none (not every wheel reports)"),
    }
}

async fn status(args: StatusArgs) -> anyhow::Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive");
    }
    let mut signals = Signals::install()?;
    let (base, mut events) = start(&args.config).await?;
    let mut wait = Duration::from_secs_f64(args.seconds);
    loop {
        tokio::select! {
            _ = tokio::time::sleep(wait) => {}
            name = signals.recv() => {
                eprintln!("{name}: halting the motors");
                break;
            }
        }
        while let Ok(e) = events.try_recv() {
            if !args.json {
                println!("event: {}", serde_json::to_string(&e)?);
            }
        }
        let s = base.status();
        if args.json {
            println!("{}", serde_json::to_string_pretty(&s)?);
        } else {
            print_status(&s);
        }
        if !args.watch || base.is_finished() {
            break;
        }
        wait = Duration::from_millis(500);
        println!();
    }
    let summary = base.stop().await?;
    if !args.json {
        let b = summary.bus;
        println!(
            "bus: {} sent, {} received, {} malformed, {} faults, {} tx acks",
            b.frames_sent, b.frames_received, b.malformed, b.faults, b.tx_acks
        );
    }
    Ok(())
}

/// Raw terminal mode for as long as it lives, restored on drop and on panic.
struct RawTerminal;

impl RawTerminal {
    fn enter() -> anyhow::Result<Self> {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let _ = crossterm::terminal::disable_raw_mode();
            previous(info);
        }));
        crossterm::terminal::enable_raw_mode().context("raw terminal mode (is stdin a terminal?)")?;
        Ok(Self)
    }
}

impl Drop for RawTerminal {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
    }
}

enum Key {
    Twist(fn(&mut Twist, f64, f64)),
    Stop,
    Clear,
    Quit,
}

fn key_of(event: crossterm::event::Event) -> Option<Key> {
    use crossterm::event::{Event, KeyCode, KeyEventKind, KeyModifiers};
    let Event::Key(k) = event else { return None };
    if k.kind == KeyEventKind::Release {
        return None;
    }
    Some(match (k.code, k.modifiers.contains(KeyModifiers::CONTROL)) {
        (KeyCode::Char('c'), true) | (KeyCode::Esc, _) | (KeyCode::Char('x'), _) => Key::Quit,
        (KeyCode::Char('w'), _) => Key::Twist(|t, v, _| t.vx_m_s = v),
        (KeyCode::Char('s'), _) => Key::Twist(|t, v, _| t.vx_m_s = -v),
        (KeyCode::Char('a'), _) => Key::Twist(|t, v, _| t.vy_m_s = v),
        (KeyCode::Char('d'), _) => Key::Twist(|t, v, _| t.vy_m_s = -v),
        (KeyCode::Char('q'), _) => Key::Twist(|t, _, w| t.wz_rad_s = w),
        (KeyCode::Char('e'), _) => Key::Twist(|t, _, w| t.wz_rad_s = -w),
        (KeyCode::Char(' '), _) => Key::Stop,
        (KeyCode::Char('c'), false) => Key::Clear,
        _ => return None,
    })
}

async fn drive(args: DriveArgs) -> anyhow::Result<()> {
    let mut signals = Signals::install()?;
    let (base, mut events) = start(&args.config).await?;
    let raw = RawTerminal::enter()?;
    let (key_tx, mut keys) = tokio::sync::mpsc::channel(64);
    let (quit_tx, quit_rx) = std::sync::mpsc::channel::<()>();
    // crossterm's blocking reader on its own thread; it checks for quit between polls.
    let reader = std::thread::spawn(move || {
        while quit_rx.try_recv().is_err() {
            if crossterm::event::poll(Duration::from_millis(50)).unwrap_or(false) {
                if let Ok(e) = crossterm::event::read() {
                    if key_tx.blocking_send(e).is_err() {
                        break;
                    }
                }
            }
        }
    });
    let mut out = std::io::stdout();
    write!(out, "W/S forward/back, A/D left/right, Q/E turn, space stop, c clear faults, x quit\r\n")?;
    let mut twist = Twist::ZERO;
    let mut last_key = tokio::time::Instant::now();
    let hold = Duration::from_millis(args.hold_ms);
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    let mut shown = 0u32;
    let result: anyhow::Result<()> = loop {
        tokio::select! {
            // In raw mode Ctrl-C is a key; SIGINT still comes from `kill`, SIGTERM from a
            // service manager, SIGHUP from a terminal or SSH session that went away.
            name = signals.recv() => {
                let _ = write!(out, "\r\n{name}: halting the motors\r\n");
                break Ok(());
            }
            Some(event) = keys.recv() => match key_of(event) {
                Some(Key::Quit) => break Ok(()),
                Some(Key::Stop) => twist = Twist::ZERO,
                Some(Key::Clear) => {
                    let answer = match base.clear().await? {
                        Ok(cleared) => format!("cleared {} fault(s)", cleared.len()),
                        Err(why) => format!("clear refused: {why:?}"),
                    };
                    write!(out, "\r\n{answer}\r\n")?;
                }
                Some(Key::Twist(set)) => {
                    set(&mut twist, args.speed, args.turn);
                    last_key = tokio::time::Instant::now();
                }
                None => {}
            },
            _ = tick.tick() => {
                if last_key.elapsed() > hold {
                    twist = Twist::ZERO;
                }
                if let Err(e) = base.command(twist).await {
                    break Err(e.into());
                }
                while let Ok(e) = events.try_recv() {
                    write!(out, "\r\nevent: {}\r\n", serde_json::to_string(&e)?)?;
                }
                shown += 1;
                if shown.is_multiple_of(4) {
                    let s = base.status();
                    let measured: Vec<String> = s.wheels.iter()
                        .map(|w| w.measured_rad_s.map(|r| format!("{r:6.2}")).unwrap_or_else(|| "     -".into()))
                        .collect();
                    let odo = s.odometry.map(|o| format!("x {:6.2} y {:6.2} th {:6.1}", o.x_m, o.y_m, o.theta_rad.to_degrees())).unwrap_or_default();
                    write!(out, "\r{:?} cmd ({:5.2} {:5.2} {:5.2}) wheels [{}] {} faults {}   ",
                        s.mode, twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s, measured.join(" "), odo, s.faults.len())?;
                    out.flush()?;
                }
                if base.is_finished() {
                    break Err(anyhow::anyhow!("the base loop ended (CAN transport closed?)"));
                }
            }
        }
    };
    // Halt first: the terminal may be gone (SIGHUP), and nothing below may hold up the stop.
    let summary = base.stop().await;
    let _ = quit_tx.send(());
    let _ = reader.join();
    drop(raw);
    // Writes that fail (no terminal any more) are ignored: `println!` would panic.
    let mut out = std::io::stdout();
    let _ = writeln!(out);
    let summary = summary?;
    let _ = writeln!(
        out,
        "stopped; bus: {} sent, {} received, {} malformed",
        summary.bus.frames_sent, summary.bus.frames_received, summary.bus.malformed
    );
    result
}

#[derive(clap::Args)]
pub struct MockArgs {
    /// c620 (DJI ESCs, 1 kHz feedback) or cia402 (CANopen drives).
    #[arg(long)]
    pub protocol: MockProtocol,
    /// Where to link the pty's slave: the "serial port" to open as an slcan adapter.
    #[arg(long)]
    pub port: PathBuf,
    /// ESC ids (1-8) or node ids, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    pub ids: Vec<u8>,
    /// C620 feedback rate per ESC.
    #[arg(long, default_value_t = 1000.0)]
    pub feedback_hz: f64,
    /// Motor time constant in seconds.
    #[arg(long, default_value_t = 0.05)]
    pub tau_s: f64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fraction of lines to the host preceded by junk bytes.
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// Fraction of frames to the host dropped.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// The adapter goes silent after S seconds.
    #[arg(long, value_name = "S")]
    pub silence_after: Option<f64>,
    /// F reports bus error + error warning after S seconds.
    #[arg(long, value_name = "S")]
    pub bus_error_after: Option<f64>,
    /// A motor faults after S seconds (C620: feedback stops; CiA 402: EMCY 0x2310 and Fault).
    #[arg(long, value_name = "S")]
    pub motor_fault_after: Option<f64>,
    /// Which motor faults [default: the first id].
    #[arg(long)]
    pub motor_fault_id: Option<u8>,
    /// Stop after S seconds [default: until Ctrl-C].
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// Print the final counters as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn mock(args: MockArgs) -> anyhow::Result<()> {
    let config = MockMotorsConfig {
        protocol: args.protocol,
        port: args.port.clone(),
        ids: args.ids.clone(),
        feedback_hz: args.feedback_hz,
        tau_s: args.tau_s,
        seed: args.seed,
        faults: MotorFaultConfig {
            garbage: args.garbage,
            drop: args.drop,
            silence_after_s: args.silence_after,
            bus_error_after_s: args.bus_error_after,
            motor_fault_after_s: args.motor_fault_after,
            motor_fault_id: args.motor_fault_id,
        },
    };
    let duration = match args.duration {
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration {s}: must be a positive number of seconds"),
        None => None,
    };
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let stats = runtime.block_on(async move {
        let mock = MockMotors::spawn(config).await?;
        eprintln!("mock {:?} motors {:?} on {} (slcan; Ctrl-C stops)", args.protocol, args.ids, args.port.display());
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
        anyhow::Ok(mock.stop().await?)
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    } else {
        let a = &stats.adapter;
        println!(
            "adapter: {} commands ({} refused), {} frames from the host, {} to the host, {} bytes lost (nobody reading)",
            a.commands, a.refused, a.frames_from_host, a.frames_to_host, stats.overflow_bytes
        );
        let f = &stats.faults;
        println!(
            "faults: {} garbage bursts, {} dropped, {} silenced, {} motor faults",
            f.garbage_bursts, f.dropped, f.silenced_lines, f.motor_faults
        );
        for (node, d) in &stats.drives {
            println!(
                "node {node}: {} SDO ({} aborted), {} RPDO, {} TPDO, {} heartbeats, {} EMCY, {} NMT",
                d.sdo_requests, d.sdo_aborts, d.rpdos, d.tpdos, d.heartbeats, d.emcys, d.nmt
            );
        }
        if stats.c620_commands > 0 {
            println!("c620: {} current commands", stats.c620_commands);
        }
    }
    Ok(())
}
