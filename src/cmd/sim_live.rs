//! The simulated mission, live: a `starc sim` run's two Avias played back by mock devices over
//! their real protocol (discovery, handshake, heartbeats, point and IMU packets) at their
//! recorded times, the robot node and the rig node each on its own runtime with its own live
//! driver, the link between them over zenoh on tcp/127.0.0.1, and everything the nodes do scored
//! against the simulator's truth into report.json (mode "live").

use anyhow::{bail, Context};
use nalgebra::{Isometry3, UnitQuaternion};
use starc_eval::{summary, LatencyReport, MemoryReport, Scorer, Truth};
use starc_hil::avia::{CaptureSource, MockAvia, MockAviaConfig};
use starc_hil::sim::run::{FPV_AVIA_IP as FPV_AVIA, ROBOT_AVIA_IP as ROBOT_AVIA};
use starc_hil::tum::tum_line;
use starc_link::LinkConfig;
use starc_livox::live::DriverConfig;
use starc_node::config::{CameraMountConfig, FpvNodeConfig, RobotNodeConfig, StartPose};
use starc_node::fpv::{self, FpvEvent};
use starc_node::robot::{self, RobotEvent};
use starc_pipeline::mission::AlignVerdict;
use starc_pipeline::timing::peak_rss_mib;
use std::io::Write as _;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};

/// The mocks' addresses on loopback (the nodes find them by their broadcasts).
const ROBOT_MOCK: Ipv4Addr = Ipv4Addr::new(127, 0, 7, 1);
const FPV_MOCK: Ipv4Addr = Ipv4Addr::new(127, 0, 7, 2);
/// Nice value of the harness (the mock devices and the scorer): on this one machine they share
/// the cores with both nodes, which in the field each have their own computer and real devices.
const HARNESS_NICE: i32 = 5;
/// Time after the recording's end for the nodes to finish their last scans.
const TAIL: Duration = Duration::from_millis(1500);
/// How long the rig keeps listening after the robot has stopped (the link takes well under 1 ms
/// on loopback; this leaves room for a loaded machine).
const RIG_DRAIN: Duration = Duration::from_millis(300);

pub struct LiveOptions {
    pub out: PathBuf,
    pub frames_every: u64,
    /// The rig's expected start from the truth: its true start moved this far (m) and turned
    /// this much (deg), gated at `start_gate_m` (`starc sim`). `None`: nothing from the truth
    /// reaches the rig node; it is seeded at the robot's map origin with no gate.
    pub start_hint: Option<(f64, f64)>,
    /// With a hint: a first alignment farther than this from it is refused.
    pub start_gate_m: f64,
    /// The rig node's `confirm_first_s`.
    pub confirm_first_s: f64,
    /// The rig node's live views (browser, Foxglove) while the mission runs.
    pub view: starc_view::ViewConfig,
    /// The robot node's person detector.
    pub detect: starc_pipeline::detect::DetectConfig,
    /// The robot node takes the base's wheels: the run's robot_can.log replayed in real time
    /// as its bus would carry it.
    pub wheels: bool,
    /// Both nodes' ROS 2 bridge, to the rmw_zenoh router at this endpoint (`--ros2`).
    pub ros2: Option<String>,
}

/// The nodes' `[ros2]` for `--ros2 ENDPOINT`: on, to that router; off without it.
fn ros2_config(endpoint: Option<&str>) -> starc_link::ros2::Ros2Config {
    match endpoint {
        Some(e) => starc_link::ros2::Ros2Config { enabled: true, connect: vec![e.to_string()], ..Default::default() },
        None => Default::default(),
    }
}

/// Free loopback ports for the nodes: each socket is held until every port is chosen, so that
/// the kernel cannot hand out one port twice (a port freed at once can come back on the next
/// bind: the rig's driver once got the robot's command port).
#[derive(Default)]
struct FreePorts {
    udp: Vec<std::net::UdpSocket>,
    tcp: Vec<std::net::TcpListener>,
}

impl FreePorts {
    fn udp(&mut self) -> anyhow::Result<u16> {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0")?;
        let port = socket.local_addr()?.port();
        self.udp.push(socket);
        Ok(port)
    }

    fn tcp(&mut self) -> anyhow::Result<u16> {
        let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
        let port = listener.local_addr()?.port();
        self.tcp.push(listener);
        Ok(port)
    }
}

fn driver(ports: &mut FreePorts, broadcast_port: u16) -> anyhow::Result<DriverConfig> {
    let data_port = ports.udp()?;
    Ok(DriverConfig {
        host_ip: Ipv4Addr::LOCALHOST,
        broadcast_listen: Some(SocketAddrV4::new(Ipv4Addr::LOCALHOST, broadcast_port)),
        cmd_port: ports.udp()?,
        data_port,
        imu_port: data_port,
        accept_unsolicited_data: false,
        ..DriverConfig::default()
    })
}

fn link(listen: Option<u16>, connect: Option<u16>) -> anyhow::Result<LinkConfig> {
    let mut text = String::new();
    if let Some(p) = listen {
        text.push_str(&format!("listen = [\"tcp/127.0.0.1:{p}\"]\n"));
    }
    if let Some(p) = connect {
        text.push_str(&format!("connect = [\"tcp/127.0.0.1:{p}\"]\n"));
    }
    Ok(LinkConfig::from_toml(&text)?)
}

/// The time of a `candump -l` log's first frame.
fn first_log_ns(path: &Path) -> anyhow::Result<u64> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let line = text.lines().find(|l| !l.trim().is_empty()).with_context(|| format!("{} is empty", path.display()))?;
    Ok(starc_can::candump::parse_line(line)?.t_ns)
}

/// Runs the nodes on their own thread and runtime.
fn spawn_node<F, Fut, T>(name: &str, f: F) -> anyhow::Result<std::thread::JoinHandle<starc_node::Result<T>>>
where
    F: FnOnce() -> Fut + Send + 'static,
    Fut: std::future::Future<Output = starc_node::Result<T>>,
    T: Send + 'static,
{
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build()?;
    Ok(std::thread::Builder::new().name(name.into()).spawn(move || rt.block_on(f()))?)
}

pub fn run(dir: &Path, opts: &LiveOptions) -> anyhow::Result<()> {
    let started = Instant::now();
    std::fs::create_dir_all(opts.out.join("ar")).with_context(|| format!("creating {}", opts.out.display()))?;
    let mut score = Scorer::new(Truth::load(dir)?);
    let pcap = dir.join("avia.pcap");
    let s0 = super::mock::capture_start_ns(&pcap, None)?;
    let end_ns =
        [&score.truth.gt_robot, &score.truth.gt_fpv].iter().filter_map(|t| t.last().map(|l| l.0)).max().unwrap_or(s0);
    let camera = score.truth.mount.camera.clone();
    let lidar_t_camera = score.truth.mount.lidar_t_camera;

    let (expected_start, start_gate_m) = rig_start(&score.truth, s0, opts);

    let mut ports = FreePorts::default();
    let (robot_bcast, fpv_bcast, link_port) = (ports.udp()?, ports.udp()?, ports.tcp()?);
    let wheels = match opts.wheels {
        true => Some(starc_node::wheels::WheelsConfig {
            replay: Some(dir.join("robot_can.log")),
            feedback: Some(starc_eval::wheels::run_wheel_feedback(dir)?),
            ..Default::default()
        }),
        false => None,
    };
    let mut robot_cfg = RobotNodeConfig {
        livox: driver(&mut ports, robot_bcast)?,
        lidar_ip: Some(ROBOT_MOCK),
        lio: None,
        detect: opts.detect.clone(),
        map_period_ms: 1000,
        wheels,
        record: Some(opts.out.join("robot.mcap")),
        record_fsync: false,
        link: link(Some(link_port), None)?,
        ros2: ros2_config(opts.ros2.as_deref()),
        // The replayed run's robot moved as recorded: nothing here drives a base.
        explore: None,
    };
    let q = lidar_t_camera.rotation.quaternion();
    let c = lidar_t_camera.translation.vector;
    let fpv_cfg = FpvNodeConfig {
        livox: driver(&mut ports, fpv_bcast)?,
        lidar_ip: Some(FPV_MOCK),
        lio: None,
        render: None,
        camera: CameraMountConfig {
            model: camera,
            translation_m: [c.x, c.y, c.z],
            quaternion_xyzw: [q.i, q.j, q.k, q.w],
        },
        expected_start,
        start_gate_m,
        confirm_first_s: opts.confirm_first_s,
        shared_lidar_clock: true,
        view: opts.view.clone(),
        record: Some(opts.out.join("fpv.mcap")),
        record_fsync: false,
        record_frames_every: 5,
        link: link(None, Some(link_port))?,
        ros2: ros2_config(opts.ros2.as_deref()),
    };
    let schedule: Vec<(u64, u64)> = score.truth.frames.iter().map(|f| (f.index, f.t_ns)).collect();

    // Released for the nodes to bind.
    drop(ports);

    // The mocks, on their own runtime: playback starts PLAYBACK_LEAD_NS after now, at the first stamp.
    // They stand in for devices that cost a real host no CPU: below the nodes when the cores are busy.
    let mocks_rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .on_thread_start(|| starc_node::lower_this_thread(HARNESS_NICE))
        .enable_all()
        .build()?;
    let w0 = Instant::now() + Duration::from_nanos(super::mock::PLAYBACK_LEAD_NS);
    if let Some(w) = robot_cfg.wheels.as_mut() {
        // The log is on the Avias' clock: its frames play on the same timeline as their packets.
        let first_ns = first_log_ns(&dir.join("robot_can.log"))?;
        let w0_unix_ns = starc_link::host_now_ns() + super::mock::PLAYBACK_LEAD_NS;
        w.replay_start_at_unix_ns = Some(w0_unix_ns.saturating_add_signed(first_ns as i64 - s0 as i64));
    }
    let mut mocks = Vec::new();
    for (sim_ip, mock_ip, bcast) in [(ROBOT_AVIA, ROBOT_MOCK, robot_bcast), (FPV_AVIA, FPV_MOCK, fpv_bcast)] {
        let lead_left = w0.saturating_duration_since(Instant::now()).as_nanos() as u64;
        let epoch = s0.saturating_sub(lead_left);
        let source = CaptureSource::open(&pcap)?.for_device(sim_ip).at_recorded_time(epoch);
        let cfg = MockAviaConfig {
            broadcast_to: SocketAddrV4::new(Ipv4Addr::LOCALHOST, bcast),
            epoch_ns: Some(epoch),
            ..MockAviaConfig::on(mock_ip)
        };
        mocks.push(mocks_rt.block_on(MockAvia::spawn_with_source(cfg, Box::new(source)))?);
    }

    // The robot stops first and the rig a moment later, so that what the robot sent last still
    // arrives (with one signal for both, its last detection sometimes met a rig already gone).
    let (robot_stop_tx, robot_stop) = watch::channel(false);
    let (fpv_stop_tx, fpv_stop) = watch::channel(false);
    let (robot_tx, mut robot_rx) = mpsc::unbounded_channel();
    let (fpv_tx, mut fpv_rx) = mpsc::unbounded_channel();
    let robot = spawn_node("robot-node", move || robot::run(robot_cfg, robot_stop, Some(robot_tx)))?;
    let fpv = spawn_node("fpv-node", move || fpv::run(fpv_cfg, fpv_stop, schedule, Some(fpv_tx)))?;
    // The scoring below is the harness too (the nodes' threads, started above, keep their priority).
    starc_node::lower_this_thread(HARNESS_NICE);

    let deadline = w0 + Duration::from_nanos(end_ns.saturating_sub(s0)) + TAIL;
    let total_s = deadline.saturating_duration_since(Instant::now()).as_secs_f64();
    let mut tally = Tally::new(opts, lidar_t_camera);
    let mut last_progress = Instant::now();
    loop {
        let now = Instant::now();
        let finished = now >= deadline || robot.is_finished() || fpv.is_finished();
        tally.drain(&mut score, &mut robot_rx, &mut fpv_rx);
        if finished {
            break;
        }
        if now.duration_since(last_progress) >= Duration::from_secs(5) {
            last_progress = now;
            let left = deadline.saturating_duration_since(now).as_secs_f64();
            eprintln!(
                "live mission: {:.0} / {total_s:.0} s, {} detection windows, {} frames scored",
                total_s - left,
                tally.detections,
                tally.frames
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let _ = robot_stop_tx.send(true);
    let robot_summary = robot.join().map_err(|_| anyhow::anyhow!("the robot node panicked"))?;
    std::thread::sleep(RIG_DRAIN);
    let _ = fpv_stop_tx.send(true);
    let fpv_summary = fpv.join().map_err(|_| anyhow::anyhow!("the rig node panicked"))?;
    // What the nodes did between the last look and their stop is scored too: the replay of
    // their recordings sees all of it.
    tally.drain(&mut score, &mut robot_rx, &mut fpv_rx);
    for m in mocks.drain(..) {
        let _ = mocks_rt.block_on(m.stop());
    }
    let robot_summary = robot_summary.context("robot node")?;
    let fpv_summary = fpv_summary.context("rig node")?;
    let Tally { robot_tum, rig_tum, slam, comm, viz, total, detect_ms, scoring_error, .. } = tally;
    if let Some(e) = scoring_error {
        return Err(e);
    }
    if robot_tum.is_empty() || fpv_summary.scans == 0 {
        bail!(
            "the live mission got no {}: did the nodes connect to the mocks?",
            if robot_tum.is_empty() { "robot poses" } else { "rig scans" }
        );
    }
    let dq = starc_eval::quantiles(&detect_ms);
    tracing::info!(p50_ms = dq.p50, p99_ms = dq.p99, "robot node: person detection compute per window");
    let latency = LatencyReport::from_parts(&slam, &comm, &viz, &total);
    let memory = MemoryReport {
        peak_rss_mib: peak_rss_mib(),
        note: Some("one process: both nodes, both mocks and the scorer".into()),
    };
    let report = score.finish("live", latency, &total, memory, started.elapsed().as_secs_f64(), &opts.out)?;
    std::fs::write(opts.out.join("robot.tum"), robot_tum.join("\n") + "\n")?;
    std::fs::write(opts.out.join("rig_world.tum"), rig_tum.join("\n") + "\n")?;
    std::fs::write(
        opts.out.join("nodes.json"),
        serde_json::to_string_pretty(&serde_json::json!({ "robot": robot_summary, "fpv": fpv_summary }))? + "\n",
    )?;
    let mut stdout = std::io::stdout().lock();
    write!(stdout, "{}", summary(&report))?;
    writeln!(
        stdout,
        "  nodes: robot {} scans, {} detection windows and {} map tiles sent; rig {} scans, {} frames, {} detections received",
        robot_summary.scans,
        robot_summary.detections_sent,
        robot_summary.tiles_sent,
        fpv_summary.scans,
        fpv_summary.frames,
        fpv_summary.detections_received
    )?;
    writeln!(
        stdout,
        "  wrote {} (report.json, frames.csv, ar/, plots/, robot.mcap, fpv.mcap, robot.tum, rig_world.tum, nodes.json)",
        opts.out.display()
    )?;
    Ok(())
}

/// The rig node's `expected_start` and `start_gate_m`: with a hint, the truth's start of the
/// rig moved by it, gated; without one, none and no gate (the node seeds at the map's origin).
fn rig_start(truth: &Truth, s0: u64, opts: &LiveOptions) -> (Option<StartPose>, f64) {
    let Some((hint_m, hint_deg)) = opts.start_hint else { return (None, f64::INFINITY) };
    // The robot's LIO world is gravity-aligned at its start with yaw zero: the expected start
    // of the responder in it, from the truth (then moved by the hint).
    let gt0 = truth.gt_robot.first().map(|g| g.1).unwrap_or_else(Isometry3::identity);
    let (roll, pitch, _) = gt0.rotation.euler_angles();
    let lio_t_world_guess =
        Isometry3::from_parts(Default::default(), UnitQuaternion::from_euler_angles(roll, pitch, 0.0)) * gt0.inverse();
    let fpv_t0 = truth.gt_fpv.first().map_or(s0, |g| g.0);
    let hint = truth.start_hint(&lio_t_world_guess, fpv_t0, hint_m, hint_deg);
    let (_, _, hint_yaw) = hint.rotation.euler_angles();
    let t = hint.translation.vector;
    (Some(StartPose { position_m: [t.x, t.y, t.z], yaw_deg: hint_yaw.to_degrees() }), opts.start_gate_m)
}

/// What the harness hears from the nodes while they run, scored as it comes.
struct Tally {
    robot_tum: Vec<String>,
    rig_tum: Vec<String>,
    slam: Vec<f64>,
    comm: Vec<f64>,
    viz: Vec<f64>,
    total: Vec<f64>,
    detect_ms: Vec<f64>,
    detections: u64,
    frames: u64,
    scoring_error: Option<anyhow::Error>,
    png_dir: PathBuf,
    frames_every: u64,
    lidar_t_camera: Isometry3<f64>,
}

impl Tally {
    fn new(opts: &LiveOptions, lidar_t_camera: Isometry3<f64>) -> Self {
        Self {
            robot_tum: Vec::new(),
            rig_tum: Vec::new(),
            slam: Vec::new(),
            comm: Vec::new(),
            viz: Vec::new(),
            total: Vec::new(),
            detect_ms: Vec::new(),
            detections: 0,
            frames: 0,
            scoring_error: None,
            png_dir: opts.out.join("ar"),
            frames_every: opts.frames_every,
            lidar_t_camera,
        }
    }

    /// Scores everything the nodes have sent so far.
    fn drain(
        &mut self,
        score: &mut Scorer,
        robot_rx: &mut mpsc::UnboundedReceiver<RobotEvent>,
        fpv_rx: &mut mpsc::UnboundedReceiver<FpvEvent>,
    ) {
        while let Ok(ev) = robot_rx.try_recv() {
            match ev {
                RobotEvent::Pose { end_ns, lidar_pose, .. } => {
                    score.robot_pose(end_ns, &lidar_pose, None);
                    self.robot_tum.push(tum_line(end_ns, &lidar_pose));
                }
                RobotEvent::Detection { detection } => {
                    self.detections += 1;
                    self.detect_ms.push(detection.detect_ms);
                    score.detection(&detection);
                }
            }
        }
        while let Ok(ev) = fpv_rx.try_recv() {
            match ev {
                FpvEvent::Started { first_ns } => score.rig_started(first_ns),
                FpvEvent::Alignment { end_ns, world_t_lidar, total_ms, verdict } => {
                    score.alignment(end_ns, &world_t_lidar, total_ms, matches!(verdict, AlignVerdict::Accepted { .. }));
                }
                FpvEvent::Frame { index, t_ns, view, render_ms } => {
                    self.frames += 1;
                    self.rig_tum.push(tum_line(t_ns, &(view.world_t_camera * self.lidar_t_camera.inverse())));
                    if let Some(f) = score.truth.frames.iter().find(|f| f.index == index).cloned() {
                        let keep = (self.frames_every > 0 && index.is_multiple_of(self.frames_every))
                            .then_some(self.png_dir.as_path());
                        if let Err(e) = score.frame(&f, &view, render_ms, keep) {
                            self.scoring_error.get_or_insert(e.into());
                        }
                    }
                }
                // L_SLAM and L_comm of every detection with people; L_viz and the total of those
                // drawn (the rig aligned).
                FpvEvent::Received { slam_ns, comm_ns } => {
                    self.slam.push(slam_ns as f64 * 1e-6);
                    self.comm.push(comm_ns as f64 * 1e-6);
                }
                FpvEvent::Shown { slam_ns, comm_ns, viz_ns } => {
                    self.viz.push(viz_ns as f64 * 1e-6);
                    self.total.push((slam_ns + comm_ns + viz_ns) as f64 * 1e-6);
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::{rig_start, FreePorts, LiveOptions};
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};
    use starc_eval::{CameraMount, Truth};

    fn truth() -> Truth {
        let pose = |x: f64, y: f64, yaw_deg: f64| {
            Isometry3::from_parts(
                Translation3::new(x, y, 1.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
            )
        };
        Truth {
            dir: Default::default(),
            scenario: "synthetic".into(),
            // The robot faces +y; the rig starts 1 m behind it.
            gt_robot: vec![(0, pose(0.0, 2.0, 90.0)), (1_000_000_000, pose(0.0, 3.0, 90.0))],
            gt_fpv: vec![(0, pose(0.0, 1.0, 90.0)), (1_000_000_000, pose(0.0, 1.0, 90.0))],
            people: Vec::new(),
            frames: Vec::new(),
            mount: CameraMount { camera: Default::default(), lidar_t_camera: Isometry3::identity() },
            robot_returns: None,
            explored: None,
        }
    }

    fn options(start_hint: Option<(f64, f64)>) -> LiveOptions {
        LiveOptions {
            out: Default::default(),
            frames_every: 0,
            start_hint,
            start_gate_m: 2.0,
            confirm_first_s: starc_pipeline::mission::CONFIRM_FIRST_S,
            view: Default::default(),
            detect: Default::default(),
            wheels: false,
            ros2: None,
        }
    }

    #[test]
    fn without_a_hint_nothing_from_the_truth_reaches_the_rig() {
        let (start, gate_m) = rig_start(&truth(), 0, &options(None));
        assert!(start.is_none());
        assert_eq!(gate_m, f64::INFINITY);
        // With one, the rig's true start in the robot's LIO world (x forward from the robot's
        // start: 1 m behind it is x = -1), moved 0.8 m x, -0.6 m y and turned 20 deg, gated.
        let (start, gate_m) = rig_start(&truth(), 0, &options(Some((1.0, 20.0))));
        let start = start.unwrap();
        assert_eq!(gate_m, 2.0);
        let [x, y, z] = start.position_m;
        assert!((x + 0.2).abs() < 1e-9 && (y + 0.6).abs() < 1e-9 && z.abs() < 1e-9, "{:?}", start.position_m);
        assert!((start.yaw_deg - 20.0).abs() < 1e-9, "{}", start.yaw_deg);
    }

    #[test]
    fn free_ports_are_never_handed_out_twice() {
        let mut ports = FreePorts::default();
        let mut seen: Vec<u16> = (0..200).map(|_| ports.udp().unwrap()).collect();
        seen.extend((0..50).map(|_| ports.tcp().unwrap()));
        let udp: std::collections::HashSet<u16> = seen[..200].iter().copied().collect();
        let tcp: std::collections::HashSet<u16> = seen[200..].iter().copied().collect();
        assert_eq!((udp.len(), tcp.len()), (200, 50));
    }
}
