//! `starc robot --config robot.toml`: the robot node. Its Avia through the live driver into the
//! robot core (LIO, detection, map); every LIO pose and every detection window to the rig over
//! the link, changed map tiles every `map_period_ms` (from a task of their own, newest version
//! per tile: a congested link never holds up a scan); optionally everything recorded.

use super::config::{driver_for, lio_config, RobotNodeConfig};
use super::explore::ExploreDrive;
use super::recording::{NodeRecorder, RecordOptions, RecordingCounts};
use super::ros2::{Ros2Out, Ros2Summary};
use super::tiles::LatestTiles;
use super::wheels::{HostToLidar, WheelOdometry, WheelStep};
use super::{wait_stop, Fed, LidarFeed, Stop};
use crate::error::{NodeError, Result};
use starc_link::{host_now_ns, LinkMessage, LinkNode, Role};
use starc_livox::live::LivoxDriver;
use starc_pipeline::mission::{
    people_to_send, MapScan, RobotCore, RobotCoreConfig, RobotDetection, RobotMap, RobotStep,
};
use starc_time::{Clock, Stamp};
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// What the robot node did, for a caller that watches it (the simulated mission).
#[derive(Debug)]
pub enum RobotEvent {
    Pose { end_ns: u64, lidar_pose: nalgebra::Isometry3<f64> },
    Detection { detection: Box<RobotDetection> },
}

#[derive(Debug, Default, serde::Serialize)]
pub struct RobotSummary {
    pub scans: u64,
    pub imu_samples: u64,
    pub detections_sent: u64,
    pub tiles_sent: u64,
    /// Tiles replaced by a newer version of themselves before the link took them.
    pub tiles_superseded: u64,
    /// What the recording queued and dropped (none: not recording, or it could not finish).
    pub recording: Option<RecordingCounts>,
    /// What the ROS 2 bridge published and dropped (none: `[ros2]` off).
    pub ros2: Option<Ros2Summary>,
    /// The Livox driver's devices, sessions and what it refused (spoofed senders, cut scans).
    pub livox: Option<starc_livox::live::DriverStats>,
    /// Feedback frames heard from the base's bus, twists handed to the LIO, and frames heard
    /// before the first scan gave the clock mapping (not used).
    pub wheel_frames: u64,
    pub wheel_twists: u64,
    pub wheel_frames_early: u64,
    /// Messages the link refused or failed to send (a non-finite pose, a session error): each
    /// counted and logged, none the end of the node.
    pub publish_errors: u64,
    /// What the explorer did (none: `[explore]` off).
    pub explore: Option<super::explore::ExploreSummary>,
    pub peak_rss_mib: Option<f64>,
}

/// Publishes `msg`; a failure is counted in `errors` and logged (the first, then at each power
/// of two), never returned: a robot that stops detecting because one pose could not be sent
/// helps nobody, and the rig sees the gap in what arrives.
async fn publish(link: &LinkNode, msg: &LinkMessage, errors: &mut u64) -> bool {
    match link.publish(msg).await {
        Ok(()) => true,
        Err(e) => {
            *errors += 1;
            if errors.is_power_of_two() {
                tracing::warn!(errors = *errors, "link: a message was not sent: {e}");
            }
            false
        }
    }
}

/// Runs until `stop`; `watch` (if any) hears every pose and detection.
pub async fn run(
    cfg: RobotNodeConfig,
    mut stop: Stop,
    watch: Option<mpsc::UnboundedSender<RobotEvent>>,
) -> Result<RobotSummary> {
    let lio = match cfg.lio.as_deref() {
        Some(path) => lio_config(Some(path))?,
        None => RobotCoreConfig::robot_lio(),
    };
    let core_cfg = RobotCoreConfig { lio, detect: cfg.detect.clone(), ..RobotCoreConfig::default() };
    // The map thread walks a sample of the rays for the coverage, which the tiles carry to the
    // rig (format 2): it judges its registrations by their overlap with what the robot saw.
    let map = RobotMap::new(core_cfg.map_config())?;
    let mut core = RobotCore::new(core_cfg)?;
    let period = Duration::from_millis(cfg.map_period_ms.max(10));
    let tiles = Arc::new(LatestTiles::default());
    let (map_tx, map_thread) = spawn_map(map, period, tiles.clone())?;
    let record = RecordOptions { fsync: cfg.record_fsync };
    let mut recorder = cfg.record.as_deref().map(|p| NodeRecorder::create_with(p, "robot", record)).transpose()?;
    let explore_cfg = cfg.explore.clone().filter(|e| e.enabled);
    let (cmd_vel_tx, teleop, mut cmd_vel_rx) = teleop_route(&cfg, explore_cfg.is_some());
    let mut ros2 = Ros2Out::start(&cfg.ros2, "robot", cmd_vel_tx)?;
    let mut explore = match &explore_cfg {
        Some(e) => Some(ExploreDrive::open(e, cfg.ros2.cmd_vel_timeout_ms).await?),
        None => None,
    };
    let mut control = tokio::time::interval(explore_cfg.as_ref().map_or(Duration::from_secs(3600), |e| e.period()));
    control.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let link = Arc::new(LinkNode::open(&cfg.link, Role::Robot).await?);
    let tile_task = tokio::spawn(send_tiles(link.clone(), tiles.clone()));
    let (mut wheel_rx, wheel_task, mut wheels) = match &cfg.wheels {
        Some(w) => {
            let odometry = WheelOdometry::new(&w.feedback()?)?;
            let (rx, task) = super::wheels::start(w).await?;
            (Some(rx), Some(task), Some(odometry))
        }
        None => (None, None, None),
    };
    let mut host_to_lidar = HostToLidar::default();
    let (driver, mut events) = LivoxDriver::start(driver_for(&cfg.livox, cfg.lidar_ip)).await?;
    tracing::info!(host = ?driver.host, wheels = wheels.is_some(), "robot node up");
    let mut feed = LidarFeed::new(cfg.lidar_ip, "robot");
    // Each recent scan's end, its LiDAR's clock, and when its last packet arrived (host clock).
    let mut scan_hosts: VecDeque<(u64, Clock, u64)> = VecDeque::new();
    let mut steps: Vec<RobotStep> = Vec::new();
    let mut summary = RobotSummary::default();
    let mut seq = 0u32;
    loop {
        tokio::select! {
            _ = wait_stop(&mut stop) => break,
            _ = control.tick(), if explore.is_some() => {
                let now = host_now_ns();
                if let Some(x) = explore.as_mut() {
                    if let Err(e) = x.control(now, host_to_lidar.to_lidar(now)).await {
                        tracing::error!("exploring stopped: {e}");
                        explore = None;
                    }
                }
            }
            tw = async { match cmd_vel_rx.as_mut() { Some(r) => r.recv().await, None => std::future::pending().await } } => {
                match (tw, explore.as_mut()) {
                    (Some(tw), Some(x)) => {
                        if let Err(e) = x.teleop(super::teleop::base_twist(&tw), host_now_ns()).await {
                            tracing::error!("/cmd_vel: {e}");
                        }
                    }
                    _ => cmd_vel_rx = None,
                }
            }
            rx = async { match wheel_rx.as_mut() { Some(r) => r.recv().await, None => std::future::pending().await } } => {
                let (Some((host_ns, frame)), Some(odometry)) = (rx, wheels.as_mut()) else {
                    // The bus failed (logged where it did) or a replay came to its end.
                    tracing::info!("the wheels' feed ended: the LIO goes on without them");
                    wheel_rx = None;
                    continue;
                };
                summary.wheel_frames += 1;
                // Before the first scan there is no LiDAR time to put the frame at.
                let Some(t_ns) = host_to_lidar.to_lidar(host_ns) else {
                    summary.wheel_frames_early += 1;
                    continue;
                };
                if let Some(r) = recorder.as_mut() {
                    r.can_frame(t_ns, &frame);
                }
                if let Some(step) = odometry.frame(t_ns, &frame) {
                    push_wheel(&mut core, &step, lidar_clock(&scan_hosts), recorder.as_mut());
                    if let Some(x) = explore.as_mut() {
                        let tw = step.twist;
                        x.on_wheels(tw.t_ns, tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s);
                    }
                }
            }
            ev = events.recv() => {
                let Some(ev) = ev else { break };
                match feed.take(ev, recorder.as_mut(), ros2.as_mut()) {
                    Some(Fed::Scan { scan, clock, last_host_ns }) => {
                        let last_host_ns = last_host_ns.unwrap_or_else(host_now_ns);
                        host_to_lidar.scan(scan.end_ns, last_host_ns);
                        scan_hosts.push_back((scan.end_ns, clock, last_host_ns));
                        if scan_hosts.len() > 64 {
                            scan_hosts.pop_front();
                        }
                        summary.scans += 1;
                        core.push_scan(scan, &mut steps);
                    }
                    Some(Fed::Imu(s)) => {
                        summary.imu_samples += 1;
                        core.push_imu(s, &mut steps);
                    }
                    None => {}
                }
                let placed = core.take_unmapped();
                let placed_at: Vec<(u64, nalgebra::Isometry3<f64>)> =
                    steps.iter().map(|s| (s.output.end_ns, s.output.lidar_pose)).collect();
                for step in steps.drain(..) {
                    // The detection leaves first: it is what the latency is measured on.
                    if let Some(det) = step.detection {
                        let (clock, last_packet_host_ns) = scan_of(&scan_hosts, det.stamp_ns);
                        seq = seq.wrapping_add(1);
                        let people = people_to_send(&det);
                        let sent_host_ns = host_now_ns();
                        let stamp = Stamp::new(det.stamp_ns, clock);
                        let msg = LinkMessage::Detections { seq, stamp, scan_last_packet_host_ns: last_packet_host_ns, sent_host_ns, people };
                        if publish(&link, &msg, &mut summary.publish_errors).await {
                            summary.detections_sent += 1;
                        }
                        if let Some(r) = recorder.as_mut() {
                            r.detections(det.stamp_ns, &det);
                        }
                        if let Some(b) = ros2.as_mut() {
                            b.detections(det.stamp_ns, &det);
                        }
                        if let Some(w) = &watch {
                            let _ = w.send(RobotEvent::Detection { detection: Box::new(det) });
                        }
                    }
                    let o = &step.output;
                    let stamp = Stamp::new(o.end_ns, scan_of(&scan_hosts, o.end_ns).0);
                    let pose = LinkMessage::RobotPose { stamp, world_t_lidar: o.lidar_pose };
                    publish(&link, &pose, &mut summary.publish_errors).await;
                    if let Some(r) = recorder.as_mut() {
                        r.pose(o.end_ns, &o.lidar_pose);
                    }
                    if let Some(b) = ros2.as_mut() {
                        b.pose(o.end_ns, &o.lidar_pose);
                    }
                    if let Some(w) = &watch {
                        let _ = w.send(RobotEvent::Pose { end_ns: o.end_ns, lidar_pose: o.lidar_pose });
                    }
                }
                // After the poses and detections are out: the explorer's grid takes a few ms.
                if let Some(x) = explore.as_mut() {
                    for ((end_ns, pose), scan) in placed_at.iter().zip(&placed) {
                        x.on_scan(*end_ns, pose, scan.points.iter().map(|p| p.xyz()));
                    }
                }
                for scan in placed {
                    let _ = map_tx.send(scan);
                }
            }
        }
    }
    if let Some(task) = wheel_task {
        task.abort();
    }
    summary.wheel_twists = wheels.as_ref().map_or(0, |w| w.twists);
    // The base halts before anything else is closed.
    if let Some(x) = explore.take() {
        summary.explore = Some(x.finish().await);
    }
    // The last tiles, so a rig that joins after the run still gets the whole map: the map
    // thread hands them over once it has everything.
    for placed in core.take_unmapped() {
        let _ = map_tx.send(placed);
    }
    drop(map_tx);
    if let Err(e) = map_thread.join().map_err(|_| NodeError::Thread("the map thread panicked")).and_then(|r| r) {
        tracing::warn!("the map: {e}");
    }
    summary.tiles_superseded = tiles.superseded();
    match finish_tiles(tile_task).await {
        Some((sent, errors)) => {
            summary.tiles_sent = sent;
            summary.publish_errors += errors;
        }
        None => tracing::warn!("map tiles still waiting after {} s: not sent", TILES_WAIT.as_secs()),
    }
    if let Some(r) = recorder.take() {
        match r.finish() {
            Ok(counts) => summary.recording = Some(counts),
            Err(e) => tracing::warn!("recording: {e}"),
        }
    }
    summary.ros2 = ros2.take().map(Ros2Out::finish);
    // The bridge's end closed /cmd_vel: the base is halted and its bus closed. A bridge whose
    // router never answered still holds /cmd_vel's sender: then the task is dropped, which
    // stops the base's loop, and its halt frames go out.
    if let Some(mut t) = teleop {
        match tokio::time::timeout(TELEOP_WAIT, &mut t).await {
            Ok(Ok(Err(_))) => {} // logged when it failed
            Ok(Err(e)) => tracing::warn!("/cmd_vel task: {e}"),
            Ok(Ok(Ok(()))) => {}
            Err(_) => {
                t.abort();
                tracing::warn!("/cmd_vel still open at the end: the base's task dropped, which halts it");
            }
        }
    }
    summary.livox = Some(driver.stats());
    let _ = driver.stop().await;
    match Arc::try_unwrap(link) {
        Ok(link) => link.close().await?,
        Err(_) => tracing::warn!("the link is still in use: not closed cleanly"),
    }
    summary.peak_rss_mib = starc_pipeline::timing::peak_rss_mib();
    tracing::info!(?summary, "robot node down");
    Ok(summary)
}

type Teleop = tokio::task::JoinHandle<Result<()>>;
type CmdVel = tokio::sync::mpsc::Receiver<starc_pipeline::record::msgs::Twist>;

/// Where `/cmd_vel` goes (`[ros2] cmd_vel`): with the explorer on, to the node's loop, which
/// hands it to the explorer's base (one driver per base); without it, to a base task of its own
/// (`[ros2] base_config`). The sender for the bridge, that task, the loop's receiver.
fn teleop_route(
    cfg: &RobotNodeConfig,
    exploring: bool,
) -> (Option<tokio::sync::mpsc::Sender<starc_pipeline::record::msgs::Twist>>, Option<Teleop>, Option<CmdVel>) {
    if !(cfg.ros2.enabled && cfg.ros2.cmd_vel) {
        return (None, None, None);
    }
    let (tx, rx) = tokio::sync::mpsc::channel(16);
    if exploring {
        return (Some(tx), None, Some(rx));
    }
    let Some(base) = cfg.ros2.base_config.clone() else { return (None, None, None) };
    let silent = Duration::from_millis(cfg.ros2.cmd_vel_timeout_ms);
    let teleop = async move {
        let result = super::teleop::drive(&base, rx, silent).await;
        if let Err(e) = &result {
            tracing::error!("/cmd_vel cannot drive the base: {e}");
        }
        result
    };
    (Some(tx), Some(tokio::spawn(teleop)), None)
}

/// How long the node waits, when stopping, for /cmd_vel's base task to halt the base.
const TELEOP_WAIT: Duration = Duration::from_secs(2);

/// How long the node waits, when stopping, for the link to take the last map tiles.
const TILES_WAIT: Duration = Duration::from_secs(5);

/// Sends every tile handed over until the map thread is done: (sent, errors).
async fn send_tiles(link: Arc<LinkNode>, tiles: Arc<LatestTiles>) -> (u64, u64) {
    let (mut sent, mut errors) = (0, 0);
    while let Some(bytes) = tiles.next().await {
        if publish(&link, &LinkMessage::MapTile { bytes }, &mut errors).await {
            sent += 1;
        }
    }
    (sent, errors)
}

/// The tile task's counts, or `None` (and the task aborted) if the link did not take the last
/// tiles within [`TILES_WAIT`].
async fn finish_tiles(mut task: tokio::task::JoinHandle<(u64, u64)>) -> Option<(u64, u64)> {
    match tokio::time::timeout(TILES_WAIT, &mut task).await {
        Ok(done) => done.ok(),
        Err(_) => {
            task.abort();
            let _ = task.await;
            None
        }
    }
}

/// The clock the newest scan is on (PTP until one has come).
fn lidar_clock(scans: &VecDeque<(u64, Clock, u64)>) -> Clock {
    scans.back().map_or(Clock::Ptp, |(_, c, _)| *c)
}

/// Hands a decoded twist to the LIO and the recording.
fn push_wheel(core: &mut RobotCore, step: &WheelStep, clock: Clock, recorder: Option<&mut NodeRecorder>) {
    let tw = step.twist;
    core.push_wheel(starc_pipeline::lio::WheelSample {
        t_ns: tw.t_ns,
        clock,
        vx_m_s: tw.vx_m_s,
        vy_m_s: tw.vy_m_s,
        wz_rad_s: tw.wz_rad_s,
    });
    if let Some(r) = recorder {
        r.wheel_odometry(tw.t_ns, step.pose, [tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s]);
    }
}

/// The clock and last-packet host time of the scan ending at `end_ns` (an unknown scan: PTP, as
/// the Avia's points are once a grandmaster runs, and now).
fn scan_of(scans: &VecDeque<(u64, Clock, u64)>, end_ns: u64) -> (Clock, u64) {
    scans.iter().find(|(end, ..)| *end == end_ns).map_or_else(|| (Clock::Ptp, host_now_ns()), |(_, c, h)| (*c, *h))
}

type MapThread = std::thread::JoinHandle<Result<()>>;
type PlacedScans = std::sync::mpsc::Sender<MapScan>;

/// The map grown on its own thread from the placed scans the node hands it: growing it and
/// encoding tiles (several milliseconds a second) never hold up a scan or a detection. Every
/// `period` it hands the changed tiles to `tiles`, and the last ones once the node hangs up;
/// then (or when it fails) it closes `tiles`.
fn spawn_map(mut map: RobotMap, period: Duration, tiles: Arc<LatestTiles>) -> Result<(PlacedScans, MapThread)> {
    let (scans_tx, scans_rx) = std::sync::mpsc::channel::<MapScan>();
    let thread = std::thread::Builder::new()
        .name("robot-map".into())
        .spawn(move || {
            let grown = grow_map(&mut map, period, &scans_rx, &tiles);
            tiles.close();
            grown
        })
        .map_err(|source| NodeError::Io { what: "starting the map thread", source })?;
    Ok((scans_tx, thread))
}

fn grow_map(
    map: &mut RobotMap,
    period: Duration,
    scans: &std::sync::mpsc::Receiver<MapScan>,
    tiles: &LatestTiles,
) -> Result<()> {
    let mut next = Instant::now() + period;
    loop {
        match scans.recv_timeout(next.saturating_duration_since(Instant::now())) {
            Ok(placed) => map.add_scan(&placed),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
        }
        if Instant::now() >= next {
            next = (next + period).max(Instant::now());
            // Everything the node has handed over by now goes into these tiles.
            while let Ok(placed) = scans.try_recv() {
                map.add_scan(&placed);
            }
            tiles.put(map.take_changed_tiles()?);
        }
    }
    tiles.put(map.take_changed_tiles()?);
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::publish;
    use nalgebra::{Isometry3, Translation3};
    use starc_link::{LinkConfig, LinkMessage, LinkNode, Role};
    use starc_time::{Clock, Stamp};

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_message_the_link_refuses_is_counted_and_the_next_one_goes_out() {
        // A free loopback port for the robot's listener (no peer needed to publish).
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let cfg = LinkConfig { listen: vec![format!("tcp/127.0.0.1:{port}")], ..LinkConfig::default() };
        let link = LinkNode::open(&cfg, Role::Robot).await.unwrap();
        let stamp = Stamp::new(1_000, Clock::Ptp);
        let nan = Isometry3::from_parts(Translation3::new(f64::NAN, 0.0, 0.0), Default::default());
        let mut errors = 0;
        assert!(!publish(&link, &LinkMessage::RobotPose { stamp, world_t_lidar: nan }, &mut errors).await);
        assert_eq!(errors, 1);
        let good = LinkMessage::RobotPose { stamp, world_t_lidar: Isometry3::identity() };
        assert!(publish(&link, &good, &mut errors).await);
        assert_eq!(errors, 1);
        link.close().await.unwrap();
    }
}
