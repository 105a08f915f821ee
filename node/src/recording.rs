//! A node's MCAP recording (ROS 2 types, see docs/record.md): `/<device>/points`,
//! `/<device>/imu`, the poses, the detections and the AR frames.
//!
//! The node hands each entry to a writer thread and goes on: converting a scan to PointCloud2,
//! compressing chunks and waiting on a busy disk never hold up its scans, detections or frames.
//! The queue holds a few seconds of data; when the disk falls further behind, the node waits
//! rather than drop anything. A failing disk stops the recording with one warning rather than
//! the node; chunks close every second, so a crash leaves a readable file, and `finish` (on
//! SIGINT/SIGTERM or the end of a run) writes the index. Dropping the recorder finishes it too.

use crate::error::{NodeError, Result};
use nalgebra::Isometry3;
use starc_livox::scan::Scan;
use starc_pipeline::lio::ImuSample;
use starc_pipeline::mission::RobotDetection;
use starc_pipeline::record::msgs::{Pose, Quaternion, Vector3};
use starc_pipeline::record::{Frames, PersonBox, Recorder, RecorderOptions, RecorderStats};
use starc_time::{Clock, Stamp};
use starc_view::ViewSnapshot;
use std::path::Path;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

/// Entries the writer may fall behind by: at the Avia's 200 Hz IMU and 10 Hz scans, about four
/// seconds (some 40 scans, 30 MB), more than a disk's writeback stalls last.
const QUEUE_ENTRIES: usize = 1024;

/// What the node records, owned, for the writer thread.
enum Entry {
    Scan(Box<Scan>),
    Imu(ImuSample),
    Pose { t_ns: u64, pose: Isometry3<f64> },
    Detections { t_ns: u64, people: Vec<PersonBox> },
    ArFrame { t_ns: u64, snapshot: Arc<ViewSnapshot> },
}

pub struct NodeRecorder {
    tx: Option<SyncSender<Entry>>,
    writer: Option<JoinHandle<Finished>>,
    /// Whether the node has waited on a full queue since the writer last caught up (one warning
    /// per episode, not per entry).
    waited: bool,
}

fn pose_msg(p: &Isometry3<f64>) -> Pose {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    Pose { position: Vector3::new(t.x, t.y, t.z), orientation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w } }
}

impl NodeRecorder {
    /// `device` names the topics (`robot`, `fpv`) and the LiDAR's frame. The file is created
    /// here, so a bad path fails the node at start.
    pub fn create(path: &Path, device: &'static str) -> Result<Self> {
        let lidar = if device == "robot" { "avia".to_string() } else { format!("{device}_avia") };
        let frames = Frames { lidar, ..Frames::default() };
        let options = RecorderOptions { clock: Clock::Ptp, frames, ..RecorderOptions::default() };
        let rec = Recorder::create(path, options).map_err(|source| NodeError::File { path: path.into(), source })?;
        tracing::info!(path = %path.display(), "recording");
        let (tx, rx) = sync_channel(QUEUE_ENTRIES);
        let writer =
            std::thread::Builder::new().name(format!("{device}-recorder")).spawn(move || write_all(rec, device, rx));
        let writer = writer.map_err(|source| NodeError::Io { what: "starting the recorder thread", source })?;
        Ok(Self { tx: Some(tx), writer: Some(writer), waited: false })
    }

    fn send(&mut self, entry: Entry) {
        let Some(tx) = self.tx.as_ref() else { return };
        let sent = match tx.try_send(entry) {
            Ok(()) => {
                self.waited = false;
                Ok(())
            }
            Err(TrySendError::Full(entry)) => {
                if !self.waited {
                    tracing::warn!("the recording is {QUEUE_ENTRIES} entries behind: the node waits for the disk");
                    self.waited = true;
                }
                tx.send(entry).map_err(|_| ())
            }
            Err(TrySendError::Disconnected(_)) => Err(()),
        };
        // The writer has stopped (it logged why): record nothing more.
        if sent.is_err() {
            self.tx = None;
        }
    }

    /// A scan from the live driver, with every point's firing time.
    pub fn scan(&mut self, scan: Scan) {
        self.send(Entry::Scan(Box::new(scan)));
    }

    pub fn imu(&mut self, s: &ImuSample) {
        self.send(Entry::Imu(*s));
    }

    /// The robot's LiDAR pose from its LIO (`/robot/odom`), or the rig's world pose (`/fpv/odom`).
    pub fn pose(&mut self, t_ns: u64, p: &Isometry3<f64>) {
        self.send(Entry::Pose { t_ns, pose: *p });
    }

    pub fn detections(&mut self, t_ns: u64, d: &RobotDetection) {
        let people: Vec<PersonBox> = d
            .found
            .iter()
            .enumerate()
            .map(|(i, p)| PersonBox {
                id: i as i32,
                center_m: [p.centre_m.x, p.centre_m.y, p.centre_m.z],
                size_m: [p.size_m.x, p.size_m.y, p.size_m.z],
                yaw_rad: p.yaw_rad,
                score: p.score as f32,
            })
            .collect();
        self.send(Entry::Detections { t_ns, people });
    }

    /// A published AR frame: its PNG (encoded on the writer thread unless a viewer already did).
    pub fn ar_frame(&mut self, t_ns: u64, snapshot: Arc<ViewSnapshot>) {
        self.send(Entry::ArFrame { t_ns, snapshot });
    }

    /// Waits for the writer to write everything queued and the index; an error if the index
    /// could not be written (a disk error earlier only stopped the recording, with a warning).
    pub fn finish(mut self) -> Result<()> {
        self.close()
    }

    fn close(&mut self) -> Result<()> {
        self.tx = None;
        let Some(writer) = self.writer.take() else { return Ok(()) };
        match writer.join() {
            Ok(Ok(Some(stats))) => tracing::info!(?stats, "recording finished"),
            Ok(Ok(None)) => {}
            Ok(Err(e)) => return Err(NodeError::Pipeline(e)),
            Err(_) => return Err(NodeError::Thread("the recording's writer thread panicked")),
        }
        Ok(())
    }
}

impl Drop for NodeRecorder {
    /// A node that stops on an error still leaves a finished file.
    fn drop(&mut self) {
        if let Err(e) = self.close() {
            tracing::warn!("{e}");
        }
    }
}

/// What the writer thread ends with: the stats of a recording it finished, `None` for one a
/// write error had already stopped (and finished as far as it could), or the error of the last
/// finish.
type Finished = std::result::Result<Option<RecorderStats>, starc_pipeline::PipelineError>;

/// The writer thread: every entry until the node hangs up, then the index.
fn write_all(mut rec: Recorder, device: &'static str, rx: Receiver<Entry>) -> Finished {
    let (points_topic, imu_topic) = (format!("/{device}/points"), format!("/{device}/imu"));
    for entry in rx {
        let (what, result) = match entry {
            Entry::Scan(scan) => {
                ("points", rec.point_cloud_on(&points_topic, &starc_bridge::livox::scan_to_cloud(&scan)))
            }
            Entry::Imu(s) => {
                let (g, a) = (s.gyro_rad_s, s.acc_m_s2);
                ("imu", rec.imu_on(&imu_topic, Stamp::new(s.t_ns, Clock::Ptp), [g.x, g.y, g.z], [a.x, a.y, a.z]))
            }
            Entry::Pose { t_ns, pose } => {
                let (stamp, msg) = (Stamp::new(t_ns, Clock::Ptp), pose_msg(&pose));
                let result = if device == "robot" {
                    rec.odometry(stamp, msg, [0.0; 3], [0.0; 3])
                } else {
                    rec.fpv_odometry(stamp, msg)
                };
                ("odometry", result)
            }
            Entry::Detections { t_ns, people } => ("detections", rec.detections(Stamp::new(t_ns, Clock::Ptp), &people)),
            Entry::ArFrame { t_ns, snapshot } => match snapshot.png() {
                Ok(png) => ("AR frame", rec.ar_image_png(Stamp::new(t_ns, Clock::Ptp), &png)),
                // The encoder failed on this frame alone: the recording goes on without it.
                Err(e) => {
                    tracing::warn!("AR frame at {t_ns} ns not recorded: {e}");
                    continue;
                }
            },
        };
        if let Err(e) = result {
            tracing::warn!("recording stopped: {what}: {e}");
            if let Err(e) = rec.finish() {
                tracing::warn!("recording not finished cleanly: {e}");
            }
            // Dropping the receiver tells the node to stop sending.
            return Ok(None);
        }
    }
    rec.finish().map(Some)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::Vector3 as V3;
    use starc_livox::scan::ScanPoint;
    use starc_pipeline::record::reader::summarize_file;

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
            start: Stamp::new(1_000_000_000 + i * 100_000_000, Clock::Ptp),
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

    /// Everything queued reaches the file, whether the node finishes the recorder or only drops
    /// it (a node that stopped on an error).
    #[test]
    fn every_entry_is_written_on_finish_and_on_drop() {
        let dir = std::env::temp_dir().join(format!("starc_node_rec_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for finish in [true, false] {
            let path = dir.join(format!("robot_{finish}.mcap"));
            let mut rec = NodeRecorder::create(&path, "robot").unwrap();
            for i in 0..30 {
                rec.scan(scan(i));
                for k in 0..20 {
                    let t_ns = 1_000_000_000 + i * 100_000_000 + k * 5_000_000;
                    rec.imu(&ImuSample {
                        t_ns,
                        clock: starc_time::Clock::Ptp,
                        gyro_rad_s: V3::zeros(),
                        acc_m_s2: V3::new(0.0, 0.0, 9.81),
                    });
                }
                rec.pose(1_100_000_000 + i * 100_000_000, &Isometry3::identity());
            }
            if finish {
                rec.finish().unwrap();
            } else {
                drop(rec);
            }
            let s = summarize_file(&path).unwrap();
            assert!(s.finished, "finish = {finish}");
            let count = |t: &str| s.topics.get(t).map_or(0, |t| t.messages);
            assert_eq!((count("/robot/points"), count("/robot/imu")), (30, 600), "finish = {finish}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_bad_path_fails_at_create() {
        assert!(NodeRecorder::create(Path::new("/nonexistent/dir/x.mcap"), "fpv").is_err());
    }
}
