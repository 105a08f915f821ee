//! `starc fpv --config fpv.toml`: the responder's rig node. Its Avia through the live driver,
//! the robot's map tiles and detections from the link, all into the rig's side of the mission
//! (`starc_pipeline::mission::RigSide`: LIO, alignment, world pose, overlay, AR frame); the
//! alignment jobs on a low-priority worker thread; each frame, re-rendered on every new rig pose
//! and every new detection, to the configured views (browser, framebuffer, Foxglove, PNG files)
//! and optionally recorded. This file holds sockets, tasks and channels only.

use super::config::{driver_for, lio_config, render_config, FpvNodeConfig};
use super::recording::{NodeRecorder, RecordOptions};
use super::ros2::{Ros2Out, Ros2Summary};
use super::{wait_stop, Fed, LidarFeed, Stop};
use crate::error::{NodeError, Result};
use nalgebra::Isometry3;
use starc_link::{host_now_ns, LinkMessage, LinkNode, Received, Role};
use starc_livox::live::{LivoxDriver, LivoxEvent};
use starc_pipeline::mission::{
    people_to_draw, AlignOutcome, AlignVerdict, DetectionTake, FrameTime, RigCoreConfig, RigSide, RigSideConfig, View,
    HOLD_NS,
};
use starc_pipeline::record::msgs::{CompressedImage, Header, Time};
use starc_pipeline::record::Topic;
use starc_pipeline::PipelineError;
use starc_time::{Clock, Stamp};
use starc_view::{start_views, RunningViews, ViewHub, ViewStatus};
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// How long a scheduled frame waits for the robot's detection of its instant.
const SCHEDULED_WAIT: Duration = Duration::from_millis(100);
/// With no new frame for this long (the rig's LiDAR quiet, no detection), the frame is drawn
/// again as it stands, so the people's ages, the link state and the status keep up with the
/// wall clock instead of freezing on screen.
const REFRESH_AFTER: Duration = Duration::from_millis(250);

/// What the rig node did, for a caller that watches it (the simulated mission).
pub enum FpvEvent {
    Started {
        first_ns: u64,
    },
    Alignment {
        end_ns: u64,
        world_t_lidar: Isometry3<f64>,
        total_ms: f64,
        verdict: AlignVerdict,
    },
    /// A frame at one of the scheduled times.
    Frame {
        index: u64,
        t_ns: u64,
        view: Box<View>,
        render_ms: f64,
    },
    /// A detection with people received: its time on the robot (last packet of its scan to
    /// sent) and on the link.
    Received {
        slam_ns: i64,
        comm_ns: i64,
    },
    /// A detection first drawn: the robot's host times (last packet of its scan, sent), and ours
    /// (received, first frame showing it rendered); `comm_ns` is the link's transport time.
    Shown {
        slam_ns: i64,
        comm_ns: i64,
        viz_ns: i64,
    },
}

#[derive(Debug, Default, serde::Serialize)]
pub struct FpvSummary {
    pub scans: u64,
    pub frames: u64,
    pub alignments: u64,
    pub accepted: u64,
    pub detections_received: u64,
    /// Refused by the rig's clock: before its first scan, or stamped too far ahead of it.
    pub detections_refused_early: u64,
    pub detections_refused_future: u64,
    pub detections_refused_past: u64,
    pub map_tiles: usize,
    /// What the recording queued and dropped (none: not recording, or it could not finish).
    pub recording: Option<crate::recording::RecordingCounts>,
    /// What the ROS 2 bridge published and dropped (none: `[ros2]` off).
    pub ros2: Option<Ros2Summary>,
    /// The Livox driver's devices, sessions and what it refused (spoofed senders, cut scans).
    pub livox: Option<starc_livox::live::DriverStats>,
    pub peak_rss_mib: Option<f64>,
}

/// A detection waiting to be first drawn (for its latency).
struct Waiting {
    stamp_ns: u64,
    slam_ns: i64,
    comm_ns: i64,
    recv_host_ns: u64,
}

type Job = tokio::sync::oneshot::Receiver<std::result::Result<AlignOutcome, PipelineError>>;

/// Runs until `stop`. `schedule` lists (index, rig LiDAR time) of extra frames to render and
/// report through `watch` (the simulator's camera frames); live frames need none.
pub async fn run(
    cfg: FpvNodeConfig,
    mut stop: Stop,
    schedule: Vec<(u64, u64)>,
    watch: Option<mpsc::UnboundedSender<FpvEvent>>,
) -> Result<FpvSummary> {
    cfg.validate()?;
    let mut side = RigSide::new(side_config(&cfg)?)?;
    if let Some(start) = cfg.expected_start {
        side.core_mut().set_start_hint(start.isometry());
    }
    if cfg.no_start_gate() {
        tracing::info!("no start gate: the first alignment is taken wherever it lands");
    }
    let record = RecordOptions { fsync: cfg.record_fsync };
    let recorder = cfg.record.as_deref().map(|p| NodeRecorder::create_with(p, "fpv", record)).transpose()?;
    let ros2 = Ros2Out::start(&cfg.ros2, "fpv", None)?;
    let hub = ViewHub::new();
    let (views_stop, views_shutdown) = tokio::sync::watch::channel(false);
    let views = start_views(&cfg.view, hub.clone(), views_shutdown).await?;
    let mut link = LinkNode::open(&cfg.link, Role::Rig).await?;
    let (driver, mut events) = LivoxDriver::start(driver_for(&cfg.livox, cfg.lidar_ip)).await?;
    tracing::info!(host = ?driver.host, "rig node up");

    let mut node = RigNode {
        feed: LidarFeed::new(cfg.lidar_ip, "rig"),
        side,
        recorder,
        ros2,
        hub,
        views,
        watch,
        schedule,
        shared_lidar_clock: cfg.shared_lidar_clock,
        record_frames_every: cfg.record_frames_every.max(1),
        waiting: Vec::new(),
        host_minus_lidar_ns: None,
        next_scheduled: 0,
        passed_at: None,
        drawn_at: None,
        summary: FpvSummary::default(),
        started: false,
    };
    let mut job: Option<Job> = None;
    let mut wait_tick = tokio::time::interval(Duration::from_millis(5));
    let mut refresh_tick = tokio::time::interval(REFRESH_AFTER);
    refresh_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let mut render_live = false;
        let mut refresh = false;
        tokio::select! {
            _ = wait_stop(&mut stop) => break,
            _ = wait_tick.tick(), if node.passed_at.is_some() => {}
            _ = refresh_tick.tick() => refresh = node.drawn_at.is_some_and(|t| t.elapsed() >= REFRESH_AFTER),
            done = async { match job.as_mut() { Some(j) => j.await, None => std::future::pending().await } } => {
                job = None;
                node.aligned(done.unwrap_or_else(|_| Err(PipelineError::BadPose { t_ns: 0, reason: "the alignment thread ended without a result".into() })));
            }
            got = link.recv() => {
                let Some(got) = got else { break };
                render_live = node.on_link(got, &link);
            }
            ev = events.recv() => {
                let Some(ev) = ev else { break };
                render_live = node.on_lidar(ev);
            }
        }
        // A registration when one is due, on a worker thread, against the newest map.
        if job.is_none() {
            if let Some(j) = node.side.next_job() {
                job = Some(super::background::spawn_low_priority("rig-align", move || j.run()));
            }
        }
        let Some((last_ns, _)) = node.side.core().last() else { continue };
        if render_live || refresh {
            node.render_live(last_ns, link_state(&link), !refresh);
        }
        node.render_scheduled(last_ns, link_state(&link));
    }
    if let Some(j) = job.take() {
        let _ = j.await;
    }
    let _ = views_stop.send(true);
    if let Some(r) = node.recorder.take() {
        match r.finish() {
            Ok(counts) => node.summary.recording = Some(counts),
            Err(e) => tracing::warn!("recording: {e}"),
        }
    }
    node.summary.ros2 = node.ros2.take().map(Ros2Out::finish);
    node.summary.livox = Some(driver.stats());
    let _ = driver.stop().await;
    node.summary.map_tiles = node.side.tile_count();
    let refused = node.side.refused();
    (node.summary.detections_refused_early, node.summary.detections_refused_future) =
        (refused.before_first_scan, refused.from_the_future);
    node.summary.detections_refused_past = refused.from_the_past;
    link.close().await?;
    node.summary.peak_rss_mib = starc_pipeline::timing::peak_rss_mib();
    tracing::info!(summary = ?node.summary, "rig node down");
    Ok(node.summary)
}

fn side_config(cfg: &FpvNodeConfig) -> Result<RigSideConfig> {
    let camera = cfg.camera.model.clone();
    camera.validate().map_err(|e| NodeError::Config(format!("[camera]: {e}")))?;
    Ok(RigSideConfig {
        core: RigCoreConfig {
            // Without a file, the rig's own defaults (config/lio_rig.toml).
            lio: match cfg.lio.as_deref() {
                Some(path) => lio_config(Some(path))?,
                None => RigCoreConfig::rig_lio(),
            },
            start_gate_m: cfg.start_gate_m,
            ..RigCoreConfig::default()
        }
        .with_confirm_first_s(cfg.confirm_first_s),
        camera,
        lidar_t_camera: cfg.camera.lidar_t_camera()?,
        render: render_config(cfg.render.as_deref())?,
        hold_ns: HOLD_NS,
    })
}

/// The rig node's state between its sockets: the mission's rig side and what the node adds
/// (views, recording, latency bookkeeping, the simulator's frame schedule).
struct RigNode {
    feed: LidarFeed,
    side: RigSide,
    recorder: Option<NodeRecorder>,
    ros2: Option<Ros2Out>,
    hub: ViewHub,
    views: RunningViews,
    watch: Option<mpsc::UnboundedSender<FpvEvent>>,
    schedule: Vec<(u64, u64)>,
    shared_lidar_clock: bool,
    record_frames_every: u64,
    waiting: Vec<Waiting>,
    /// The rig host's clock minus its LiDAR's, at the newest scan's last packet.
    host_minus_lidar_ns: Option<i64>,
    next_scheduled: usize,
    passed_at: Option<Instant>,
    /// When the last live frame was drawn.
    drawn_at: Option<Instant>,
    summary: FpvSummary,
    started: bool,
}

impl RigNode {
    fn send(&self, ev: FpvEvent) {
        if let Some(w) = &self.watch {
            let _ = w.send(ev);
        }
    }

    fn aligned(&mut self, outcome: std::result::Result<AlignOutcome, PipelineError>) {
        let report = outcome.as_ref().ok().map(|o| (o.end_ns, o.world_t_lidar, o.report.total_ms));
        let verdict = self.side.apply(outcome);
        self.summary.alignments += 1;
        tracing::info!(%verdict, "rig alignment");
        if matches!(verdict, AlignVerdict::Accepted { .. }) {
            self.summary.accepted += 1;
        }
        if let Some((end_ns, world_t_lidar, total_ms)) = report {
            self.send(FpvEvent::Alignment { end_ns, world_t_lidar, total_ms, verdict });
        }
    }

    /// A message from the robot; whether the frame should be drawn again.
    fn on_link(&mut self, got: Received, link: &LinkNode) -> bool {
        match got.msg {
            LinkMessage::MapTile { bytes } => {
                if let Err(e) = self.side.push_tile(&bytes) {
                    tracing::warn!("map tile refused: {e}");
                }
                false
            }
            LinkMessage::Detections { stamp, scan_last_packet_host_ns, sent_host_ns, people, .. } => {
                self.summary.detections_received += 1;
                let robot_host_here = link.peer_to_local_ns(scan_last_packet_host_ns);
                let stamp_here = self.on_rig_clock(stamp, robot_host_here);
                let comm_ns = got.latency_ns.or(got.raw_latency_ns).unwrap_or(0);
                let slam_ns = sent_host_ns as i64 - scan_last_packet_host_ns as i64;
                if !people.is_empty() {
                    self.send(FpvEvent::Received { slam_ns, comm_ns });
                }
                // Only what can be drawn now counts: people, and the rig placed in the map.
                if !people.is_empty() && self.side.core().aligned() {
                    self.waiting.push(Waiting {
                        stamp_ns: stamp_here,
                        slam_ns,
                        comm_ns,
                        recv_host_ns: got.recv_host_ns,
                    });
                }
                let take = self.side.push_detections(stamp_here, people_to_draw(&people));
                match take {
                    DetectionTake::RefusedFromTheFuture => {
                        tracing::debug!(stamp_here, "a detection stamped too far ahead of the rig's clock was refused")
                    }
                    DetectionTake::RefusedFromThePast => {
                        tracing::debug!(stamp_here, "a detection stamped too far behind the rig's clock was refused")
                    }
                    _ => {}
                }
                take == DetectionTake::Held
            }
            LinkMessage::RobotPose { world_t_lidar, .. } => {
                self.side.push_robot_pose(&world_t_lidar);
                false
            }
            _ => false,
        }
    }

    /// The robot's LiDAR stamp on our LiDAR's clock: as is when both LiDARs share a PTP clock,
    /// else through both hosts' clocks (the robot's last packet moved onto our host clock, then
    /// onto our LiDAR's; a few ms of jitter).
    fn on_rig_clock(&self, stamp: Stamp, robot_host_here_ns: Option<u64>) -> u64 {
        let shared = self.shared_lidar_clock && stamp.clock == Clock::Ptp;
        match (shared, robot_host_here_ns, self.host_minus_lidar_ns) {
            (false, Some(h), Some(off)) => h.saturating_add_signed(off.saturating_neg()),
            _ => stamp.ns,
        }
    }

    /// Now by this host's clock, on the rig LiDAR's clock (once a scan has tied the two).
    fn now_on_rig_clock(&self) -> Option<u64> {
        self.host_minus_lidar_ns.map(|off| host_now_ns().saturating_add_signed(off.saturating_neg()))
    }

    /// A driver event; whether the frame should be drawn again.
    fn on_lidar(&mut self, ev: LivoxEvent) -> bool {
        let mut outs = Vec::new();
        match self.feed.take(ev, self.recorder.as_mut(), self.ros2.as_mut()) {
            Some(Fed::Scan { scan, last_host_ns, .. }) => {
                if let Some(h) = last_host_ns {
                    self.host_minus_lidar_ns = Some(h as i64 - scan.end_ns as i64);
                }
                self.summary.scans += 1;
                self.side.push_scan(scan, &mut outs);
            }
            Some(Fed::Imu(s)) => self.side.push_imu(s, &mut outs),
            None => {}
        }
        for o in &outs {
            if !self.started {
                self.started = true;
                if let Some(first_ns) = self.side.core().first_ns() {
                    self.send(FpvEvent::Started { first_ns });
                }
            }
            if let Ok(Some(p)) = self.side.core().world().world_pose(o.end_ns) {
                if let Some(r) = self.recorder.as_mut() {
                    r.pose(o.end_ns, &p);
                }
                if let Some(b) = self.ros2.as_mut() {
                    b.pose(o.end_ns, &p);
                }
            }
        }
        !outs.is_empty()
    }

    /// The live frame at the newest rig scan or detection, to the views and the recording;
    /// `new_data` false for a frame drawn again only to keep its ages and status current.
    fn render_live(&mut self, last_ns: u64, link: &'static str, new_data: bool) {
        let t_ns = last_ns.max(self.side.newest_detection_ns());
        let time = FrameTime { scene_ns: t_ns, now_ns: self.now_on_rig_clock().unwrap_or(t_ns).max(t_ns) };
        let view = self.side.render(time, link, new_data && self.schedule.is_empty());
        self.drawn_at = Some(Instant::now());
        let rendered = host_now_ns();
        self.summary.frames += 1;
        if view.aligned {
            self.shown_by(t_ns, rendered);
        }
        self.waiting.retain(|d| d.stamp_ns + HOLD_NS > t_ns);
        let status = ViewStatus {
            aligned: view.aligned,
            detection_age_ms: view.detection_age_ms,
            link: link.to_string(),
            people: view.people.len(),
            frame_seq: self.summary.frames,
            stamp_ns: t_ns,
        };
        let snapshot = match self.hub.publish(&view.frame, status) {
            Ok(s) => s,
            Err(e) => return tracing::warn!("frame not published: {e}"),
        };
        // Foxglove's image panel gets the same PNG the browser does, encoded only while a panel
        // is subscribed.
        let foxglove = self.views.foxglove.as_ref().filter(|f| f.subscribed(Topic::ArImage.name()));
        if let (Some(fox), Some(stamp), Ok(png)) = (foxglove, Time::from_ns(t_ns), snapshot.png()) {
            let msg = CompressedImage {
                header: Header { stamp, frame_id: "fpv_camera".into() },
                format: "png".into(),
                data: png.to_vec(),
            };
            let _ = fox.publish_msg(Topic::ArImage.name(), t_ns, &msg);
        }
        // A redraw repeats the last frame's stamp: the live views take it, the recording and
        // ROS 2 (which would get two frames at one time) do not.
        if !new_data {
            return;
        }
        if let Some(b) = self.ros2.as_mut() {
            b.ar_frame(t_ns, snapshot.clone());
        }
        if let Some(r) = self.recorder.as_mut().filter(|_| self.summary.frames.is_multiple_of(self.record_frames_every))
        {
            r.ar_frame(t_ns, snapshot);
        }
    }

    /// The detections up to `t_ns` are on screen now: their latencies are complete.
    fn shown_by(&mut self, t_ns: u64, rendered_host_ns: u64) {
        let (shown, still): (Vec<Waiting>, Vec<Waiting>) =
            std::mem::take(&mut self.waiting).into_iter().partition(|d| d.stamp_ns <= t_ns);
        self.waiting = still;
        for d in shown {
            let viz_ns = rendered_host_ns as i64 - d.recv_host_ns as i64;
            self.send(FpvEvent::Shown { slam_ns: d.slam_ns, comm_ns: d.comm_ns, viz_ns });
        }
    }

    /// A scheduled frame renders once the rig has passed its time and the robot's detection of
    /// that instant has arrived (or SCHEDULED_WAIT after), as the live view would show it then:
    /// a frame is re-rendered whenever a detection arrives.
    fn render_scheduled(&mut self, last_ns: u64, link: &'static str) {
        while let Some(&(index, t_ns)) = self.schedule.get(self.next_scheduled).filter(|(_, t)| *t <= last_ns) {
            let since = *self.passed_at.get_or_insert_with(Instant::now);
            if self.side.newest_detection_ns() < t_ns && since.elapsed() < SCHEDULED_WAIT {
                break;
            }
            self.passed_at = None;
            self.next_scheduled += 1;
            let t0 = Instant::now();
            let view = self.side.render(FrameTime::at(t_ns), link, true);
            let render_ms = t0.elapsed().as_secs_f64() * 1e3;
            self.send(FpvEvent::Frame { index, t_ns, view: Box::new(view), render_ms });
        }
    }
}

fn link_state(link: &LinkNode) -> &'static str {
    link.health().state.name()
}
