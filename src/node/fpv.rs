//! `starc fpv --config fpv.toml`: the responder's rig node. Its Avia through the live driver
//! into the rig core (LIO, alignment to the robot's map as it arrives over the link, world
//! pose); the robot's detections held and aged; the AR frame re-rendered on every new rig pose
//! and every new detection, published to the configured views (browser, framebuffer, Foxglove,
//! PNG files) and optionally recorded.

use super::config::{lio_config, render_config, FpvNodeConfig};
use super::recording::NodeRecorder;
use super::{wait_stop, Fed, LidarFeed, Stop};
use crate::view::{start_views, ViewHub, ViewStatus};
use anyhow::Context;
use nalgebra::Isometry3;
use starc_link::{host_now_ns, LinkMessage, LinkNode, Role};
use starc_livox::live::LivoxDriver;
use starc_pipeline::align::TileMap;
use starc_pipeline::mission::{render_view, AlignOutcome, AlignVerdict, Overlay, RigCore, RigCoreConfig, View};
use starc_pipeline::record::msgs::{CompressedImage, Header, Time};
use starc_pipeline::record::Topic;
use starc_pipeline::PipelineError;
use std::time::Instant;
use tokio::sync::mpsc;

/// Detections stay on screen this long after the robot last saw them.
pub const HOLD_NS: u64 = 1_000_000_000;
/// How long a scheduled frame waits for the robot's detection of its instant.
const SCHEDULED_WAIT: std::time::Duration = std::time::Duration::from_millis(100);

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
    pub map_tiles: usize,
    pub peak_rss_mib: Option<f64>,
}

struct Waiting {
    stamp_ns: u64,
    slam_ns: i64,
    comm_ns: i64,
    recv_host_ns: u64,
}

type Job = tokio::sync::oneshot::Receiver<Result<AlignOutcome, PipelineError>>;

/// Runs until `stop`. `schedule` lists (index, rig LiDAR time) of extra frames to render and
/// report through `watch` (the simulator's camera frames); live frames need none.
pub async fn run(
    cfg: FpvNodeConfig,
    mut stop: Stop,
    schedule: Vec<(u64, u64)>,
    watch: Option<mpsc::UnboundedSender<FpvEvent>>,
) -> anyhow::Result<FpvSummary> {
    cfg.validate()?;
    let camera = cfg.camera.model.clone();
    camera.validate().map_err(|e| anyhow::anyhow!("[camera]: {e}"))?;
    let lidar_t_camera = cfg.camera.lidar_t_camera()?;
    let render_cfg = render_config(cfg.render.as_deref())?;
    let core_cfg = RigCoreConfig {
        lio: lio_config(cfg.lio.as_deref())?,
        start_gate_m: cfg.start_gate_m,
        ..RigCoreConfig::default()
    };
    let mut core = RigCore::new(core_cfg)?;
    core.set_start_hint(cfg.expected_start.map_or_else(Isometry3::identity, |s| s.isometry()));
    if cfg.no_start_gate() {
        tracing::info!("no start gate: the first alignment is taken wherever it lands");
    }
    let mut overlay = Overlay::new(HOLD_NS);
    let mut tiles = TileMap::default();
    let mut tiles_changed = false;
    let mut recorder = cfg.record.as_deref().map(|p| NodeRecorder::create(p, "fpv")).transpose()?;
    let hub = ViewHub::new();
    let (views_stop, views_shutdown) = tokio::sync::watch::channel(false);
    let views = start_views(&cfg.view, hub.clone(), views_shutdown).await.context("starting the views")?;
    let mut link = LinkNode::open(&cfg.link, Role::Rig).await.context("opening the link")?;
    let (driver, mut events) = LivoxDriver::start(cfg.livox.clone()).await.context("starting the Livox driver")?;
    tracing::info!(host = ?driver.host, "rig node up");

    let mut feed = LidarFeed::new(cfg.lidar_ip, "rig");
    let mut job: Option<Job> = None;
    let mut outs = Vec::new();
    let mut waiting: Vec<Waiting> = Vec::new();
    let mut host_minus_lidar_ns: Option<i64> = None;
    let mut newest_detection_ns = 0u64;
    let mut next_scheduled = 0usize;
    let mut passed_at: Option<Instant> = None;
    let mut wait_tick = tokio::time::interval(std::time::Duration::from_millis(5));
    let mut summary = FpvSummary::default();
    let mut started = false;
    loop {
        let mut render_live = false;
        tokio::select! {
            _ = wait_stop(&mut stop) => break,
            _ = wait_tick.tick(), if passed_at.is_some() => {}
            done = async { match job.as_mut() { Some(j) => j.await, None => std::future::pending().await } } => {
                job = None;
                let outcome = done.unwrap_or_else(|_| Err(PipelineError::BadPose { t_ns: 0, reason: "the alignment thread ended without a result".into() }));
                let report = outcome.as_ref().ok().map(|o| (o.end_ns, o.world_t_lidar, o.report.total_ms));
                let verdict = core.apply(outcome);
                summary.alignments += 1;
                tracing::info!(?verdict, "rig alignment");
                if matches!(verdict, AlignVerdict::Accepted { .. }) {
                    summary.accepted += 1;
                }
                if let (Some(w), Some((end_ns, world_t_lidar, total_ms))) = (&watch, report) {
                    let _ = w.send(FpvEvent::Alignment { end_ns, world_t_lidar, total_ms, verdict });
                }
            }
            got = link.recv() => {
                let Some(got) = got else { break };
                match got.msg {
                    LinkMessage::MapTile { bytes } => match tiles.apply(&bytes) {
                        Ok(changed) => tiles_changed |= changed,
                        Err(e) => tracing::warn!("map tile refused: {e}"),
                    },
                    LinkMessage::Detections { stamp_ns, scan_last_packet_host_ns, sent_host_ns, people, .. } => {
                        summary.detections_received += 1;
                        // The robot's LiDAR stamp onto ours: as is when both LiDARs share a PTP
                        // clock, else through both hosts' clocks (a few ms of jitter).
                        let stamp_here = match (cfg.shared_lidar_clock, link.peer_to_local_ns(scan_last_packet_host_ns), host_minus_lidar_ns) {
                            (false, Some(h), Some(off)) => h.saturating_add_signed(off.saturating_neg()),
                            _ => stamp_ns,
                        };
                        let comm_ns = got.latency_ns.or(got.raw_latency_ns).unwrap_or(0);
                        let slam_ns = sent_host_ns as i64 - scan_last_packet_host_ns as i64;
                        if let (Some(w), false) = (&watch, people.is_empty()) {
                            let _ = w.send(FpvEvent::Received { slam_ns, comm_ns });
                        }
                        // Only what can be drawn now counts: people, and the rig placed in the map.
                        if !people.is_empty() && core.aligned() {
                            waiting.push(Waiting { stamp_ns: stamp_here, slam_ns, comm_ns, recv_host_ns: got.recv_host_ns });
                        }
                        newest_detection_ns = newest_detection_ns.max(stamp_here);
                        overlay.push(stamp_here, people.iter().map(|p| p.to_ar_person(0)).collect());
                        render_live = true;
                    }
                    _ => {}
                }
            }
            ev = events.recv() => {
                let Some(ev) = ev else { break };
                match feed.take(ev, recorder.as_mut()) {
                    Some(Fed::Scan { scan, last_host_ns }) => {
                        if let Some(h) = last_host_ns {
                            host_minus_lidar_ns = Some(h as i64 - scan.end_ns as i64);
                        }
                        summary.scans += 1;
                        core.push_scan(scan, &mut outs);
                    }
                    Some(Fed::Imu(s)) => core.push_imu(s, &mut outs),
                    None => {}
                }
                for o in outs.drain(..) {
                    render_live = true;
                    if !started {
                        started = true;
                        if let (Some(w), Some(first_ns)) = (&watch, core.first_ns()) {
                            let _ = w.send(FpvEvent::Started { first_ns });
                        }
                    }
                    if let (Some(r), Ok(Some(p))) = (recorder.as_mut(), core.world().world_pose(o.end_ns)) {
                        r.pose(o.end_ns, &p);
                    }
                }
            }
        }
        // A registration when one is due, on a worker thread, against the newest map.
        if job.is_none() && core.wants_map() && tiles_changed {
            core.set_map(tiles.points().0);
            tiles_changed = false;
        }
        if job.is_none() {
            let now_ns = core.last().map_or(0, |(t, _)| t);
            if let Some(j) = core.next_job(|| overlay.boxes_at(now_ns)) {
                job = Some(super::background::spawn_low_priority("rig-align", move || j.run()));
            }
        }
        let Some((last_ns, _)) = core.last() else { continue };
        if render_live {
            let t_ns = last_ns.max(newest_detection_ns);
            if schedule.is_empty() {
                core.world_mut().step_frame();
            }
            let link_now = link_state(&link);
            let view = render_view(&camera, &lidar_t_camera, &core, &overlay, t_ns, link_now, &render_cfg);
            let rendered = host_now_ns();
            summary.frames += 1;
            if view.aligned {
                waiting.retain(|d| {
                    if d.stamp_ns > t_ns {
                        return true;
                    }
                    if let Some(w) = &watch {
                        let viz_ns = rendered as i64 - d.recv_host_ns as i64;
                        let _ = w.send(FpvEvent::Shown { slam_ns: d.slam_ns, comm_ns: d.comm_ns, viz_ns });
                    }
                    false
                });
            }
            waiting.retain(|d| d.stamp_ns + HOLD_NS > t_ns);
            let status = ViewStatus {
                aligned: view.aligned,
                detection_age_ms: view.detection_age_ms,
                link: link_now.to_string(),
                people: view.people.len(),
                frame_seq: summary.frames,
                stamp_ns: t_ns,
            };
            match hub.publish(&view.frame, status) {
                Ok(snapshot) => {
                    // Foxglove's image panel gets the same PNG the browser does, encoded only
                    // while a panel is subscribed.
                    let foxglove = views.foxglove.as_ref().filter(|f| f.subscribed(Topic::ArImage.name()));
                    if let (Some(fox), Some(stamp), Ok(png)) = (foxglove, Time::from_ns(t_ns), snapshot.png()) {
                        let msg = CompressedImage {
                            header: Header { stamp, frame_id: "fpv_camera".into() },
                            format: "png".into(),
                            data: png.to_vec(),
                        };
                        let _ = fox.publish_msg(Topic::ArImage.name(), t_ns, &msg);
                    }
                    if let Some(r) = recorder.as_mut().filter(|_| summary.frames % cfg.record_frames_every.max(1) == 0)
                    {
                        r.ar_frame(t_ns, snapshot);
                    }
                }
                Err(e) => tracing::warn!("frame not published: {e}"),
            }
        }
        // A scheduled frame renders once the rig has passed its time and the robot's detection
        // of that instant has arrived (or SCHEDULED_WAIT after), as the live view would show it
        // then: a frame is re-rendered whenever a detection arrives.
        while let Some(&(index, t_ns)) = schedule.get(next_scheduled).filter(|(_, t)| *t <= last_ns) {
            let since = *passed_at.get_or_insert_with(Instant::now);
            if newest_detection_ns < t_ns && since.elapsed() < SCHEDULED_WAIT {
                break;
            }
            passed_at = None;
            next_scheduled += 1;
            core.world_mut().step_frame();
            let t0 = Instant::now();
            let view = render_view(&camera, &lidar_t_camera, &core, &overlay, t_ns, link_state(&link), &render_cfg);
            let render_ms = t0.elapsed().as_secs_f64() * 1e3;
            if let Some(w) = &watch {
                let _ = w.send(FpvEvent::Frame { index, t_ns, view: Box::new(view), render_ms });
            }
        }
    }
    if let Some(j) = job.take() {
        let _ = j.await;
    }
    let _ = views_stop.send(true);
    if let Some(r) = recorder.take() {
        r.finish()?;
    }
    let _ = driver.stop().await;
    summary.map_tiles = tiles.tile_count();
    link.close().await?;
    summary.peak_rss_mib = crate::cmd::lio::peak_rss_mib();
    tracing::info!(?summary, "rig node down");
    Ok(summary)
}

fn link_state(link: &LinkNode) -> &'static str {
    link.health().state.name()
}
