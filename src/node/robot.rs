//! `starc robot --config robot.toml`: the robot node. Its Avia through the live driver into the
//! robot core (LIO, detection, map); every LIO pose and every detection window to the rig over
//! the link, changed map tiles every `map_period_ms`; optionally everything recorded.

use super::config::{lio_config, RobotNodeConfig};
use super::recording::NodeRecorder;
use super::{wait_stop, Fed, LidarFeed, Stop};
use anyhow::Context;
use starc_link::{host_now_ns, LinkMessage, LinkNode, LinkPerson, Role};
use starc_livox::live::LivoxDriver;
use starc_pipeline::mission::{RobotCore, RobotCoreConfig, RobotDetection, RobotStep};
use std::collections::VecDeque;
use std::time::Duration;
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
    pub peak_rss_mib: Option<f64>,
}

/// Runs until `stop`; `watch` (if any) hears every pose and detection.
pub async fn run(
    cfg: RobotNodeConfig,
    mut stop: Stop,
    watch: Option<mpsc::UnboundedSender<RobotEvent>>,
) -> anyhow::Result<RobotSummary> {
    let core_cfg = RobotCoreConfig { lio: lio_config(cfg.lio.as_deref())?, ..RobotCoreConfig::default() };
    let mut core = RobotCore::new(core_cfg)?;
    let mut recorder = cfg.record.as_deref().map(|p| NodeRecorder::create(p, "robot")).transpose()?;
    let link = LinkNode::open(&cfg.link, Role::Robot).await.context("opening the link")?;
    let (driver, mut events) = LivoxDriver::start(cfg.livox.clone()).await.context("starting the Livox driver")?;
    tracing::info!(host = ?driver.host, "robot node up");
    let mut feed = LidarFeed::new(cfg.lidar_ip, "robot");
    let mut map_tick = tokio::time::interval(Duration::from_millis(cfg.map_period_ms.max(10)));
    let mut scan_hosts: VecDeque<(u64, u64)> = VecDeque::new();
    let mut steps: Vec<RobotStep> = Vec::new();
    let mut summary = RobotSummary::default();
    let mut seq = 0u32;
    loop {
        tokio::select! {
            _ = wait_stop(&mut stop) => break,
            _ = map_tick.tick() => {
                for bytes in core.take_changed_tiles()? {
                    link.publish(&LinkMessage::MapTile { bytes }).await?;
                    summary.tiles_sent += 1;
                }
            }
            ev = events.recv() => {
                let Some(ev) = ev else { break };
                match feed.take(ev, recorder.as_mut()) {
                    Some(Fed::Scan { scan, last_host_ns }) => {
                        scan_hosts.push_back((scan.end_ns, last_host_ns.unwrap_or_else(host_now_ns)));
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
                for step in steps.drain(..) {
                    // The detection leaves first: it is what the latency is measured on.
                    if let Some(det) = step.detection {
                        let last_packet_host_ns = scan_hosts.iter().find(|(end, _)| *end == det.stamp_ns).map_or_else(host_now_ns, |(_, h)| *h);
                        seq = seq.wrapping_add(1);
                        let people = det
                            .people
                            .iter()
                            .zip(&det.scores)
                            .filter_map(|(p, score)| {
                                Some(LinkPerson {
                                    score: *score as f32,
                                    bbox: p.bbox?,
                                    points_world: p.points_world.iter().map(|v| [v.x as f32, v.y as f32, v.z as f32]).collect(),
                                })
                            })
                            .collect();
                        let sent_host_ns = host_now_ns();
                        let msg = LinkMessage::Detections { seq, stamp_ns: det.stamp_ns, scan_last_packet_host_ns: last_packet_host_ns, sent_host_ns, people };
                        link.publish(&msg).await?;
                        summary.detections_sent += 1;
                        if let Some(r) = recorder.as_mut() {
                            r.detections(det.stamp_ns, &det);
                        }
                        if let Some(w) = &watch {
                            let _ = w.send(RobotEvent::Detection { detection: Box::new(det) });
                        }
                    }
                    let o = &step.output;
                    link.publish(&LinkMessage::RobotPose { stamp_ns: o.end_ns, world_t_lidar: o.lidar_pose }).await?;
                    if let Some(r) = recorder.as_mut() {
                        r.pose(o.end_ns, &o.lidar_pose);
                    }
                    if let Some(w) = &watch {
                        let _ = w.send(RobotEvent::Pose { end_ns: o.end_ns, lidar_pose: o.lidar_pose });
                    }
                }
            }
        }
    }
    // The last tiles, so a rig that joins after the run still gets the whole map.
    for bytes in core.take_changed_tiles()? {
        link.publish(&LinkMessage::MapTile { bytes }).await?;
        summary.tiles_sent += 1;
    }
    if let Some(r) = recorder.take() {
        r.finish()?;
    }
    let _ = driver.stop().await;
    link.close().await?;
    summary.peak_rss_mib = crate::cmd::lio::peak_rss_mib();
    tracing::info!(?summary, "robot node down");
    Ok(summary)
}
