//! A node's MCAP recording (ROS 2 types, see docs/record.md): `/<device>/points`,
//! `/<device>/imu`, the poses, the detections and the AR frames. A failing disk stops the
//! recording with one warning rather than the node; chunks close every second, so a crash leaves
//! a readable file, and `finish` (on SIGINT/SIGTERM or the end of a run) writes the index.

use nalgebra::Isometry3;
use starc_pipeline::cloud::PointCloud;
use starc_pipeline::lio::ImuSample;
use starc_pipeline::mission::RobotDetection;
use starc_pipeline::record::msgs::{Pose, Quaternion, Vector3};
use starc_pipeline::record::{Frames, PersonBox, Recorder, RecorderOptions};
use starc_time::{Clock, Stamp};
use std::path::Path;

pub struct NodeRecorder {
    rec: Option<Recorder>,
    device: &'static str,
}

fn pose_msg(p: &Isometry3<f64>) -> Pose {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    Pose { position: Vector3::new(t.x, t.y, t.z), orientation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w } }
}

impl NodeRecorder {
    /// `device` names the topics (`robot`, `fpv`) and the LiDAR's frame.
    pub fn create(path: &Path, device: &'static str) -> anyhow::Result<Self> {
        let lidar = if device == "robot" { "avia".to_string() } else { format!("{device}_avia") };
        let frames = Frames { lidar, ..Frames::default() };
        let options = RecorderOptions { clock: Clock::Ptp, frames, ..RecorderOptions::default() };
        let rec = Recorder::create(path, options)?;
        tracing::info!(path = %path.display(), "recording");
        Ok(Self { rec: Some(rec), device })
    }

    fn put(&mut self, what: &str, f: impl FnOnce(&mut Recorder) -> Result<(), starc_pipeline::PipelineError>) {
        let Some(rec) = self.rec.as_mut() else { return };
        if let Err(e) = f(rec) {
            tracing::warn!("recording stopped: {what}: {e}");
            if let Some(mut rec) = self.rec.take() {
                let _ = rec.finish();
            }
        }
    }

    /// A scan from the live driver, with every point's firing time.
    pub fn scan(&mut self, scan: &starc_livox::scan::Scan) {
        self.points(&crate::cmd::export::scan_to_cloud(scan));
    }

    pub fn points(&mut self, cloud: &PointCloud) {
        let topic = format!("/{}/points", self.device);
        self.put("points", |r| r.point_cloud_on(&topic, cloud));
    }

    pub fn imu(&mut self, s: &ImuSample) {
        let topic = format!("/{}/imu", self.device);
        let (g, a) = (s.gyro_rad_s, s.acc_m_s2);
        self.put("imu", |r| r.imu_on(&topic, Stamp::new(s.t_ns, Clock::Ptp), [g.x, g.y, g.z], [a.x, a.y, a.z]));
    }

    /// The robot's LiDAR pose from its LIO (`/robot/odom`), or the rig's world pose (`/fpv/odom`).
    pub fn pose(&mut self, t_ns: u64, p: &Isometry3<f64>) {
        let stamp = Stamp::new(t_ns, Clock::Ptp);
        let msg = pose_msg(p);
        if self.device == "robot" {
            self.put("odometry", |r| r.odometry(stamp, msg, [0.0; 3], [0.0; 3]));
        } else {
            self.put("odometry", |r| r.fpv_odometry(stamp, msg));
        }
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
        self.put("detections", |r| r.detections(Stamp::new(t_ns, Clock::Ptp), &people));
    }

    pub fn ar_frame(&mut self, t_ns: u64, png: &[u8]) {
        self.put("AR frame", |r| r.ar_image_png(Stamp::new(t_ns, Clock::Ptp), png));
    }

    pub fn finish(mut self) -> anyhow::Result<()> {
        if let Some(mut rec) = self.rec.take() {
            let stats = rec.finish()?;
            tracing::info!(?stats, "recording finished");
        }
        Ok(())
    }
}
