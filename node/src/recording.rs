//! A node's MCAP recording (ROS 2 types, see docs/record.md): `/<device>/points`,
//! `/<device>/imu`, the poses, the detections and the AR frames.
//!
//! The node hands each entry to a writer thread and goes on: converting a scan to PointCloud2,
//! compressing chunks and waiting on a busy disk never hold up its scans, detections or frames.
//! The queue holds about four seconds of data; when the disk falls further behind, entries are
//! dropped and counted ([`RecordingCounts`]), never waited for. A full disk is retried (the
//! recorder keeps one chunk and drops the rest until there is room); any other disk error stops
//! the recording with one warning rather than the node. Chunks close every second of log time
//! and after one second without an entry, so a crash loses at most the open chunk plus what
//! the queue holds (docs/nodes.md gives the bounds). `finish` (on SIGINT/SIGTERM/SIGHUP or the
//! end of a run) writes the index, waiting a bounded time for a stalled disk. Dropping the
//! recorder finishes it too.

use crate::error::{NodeError, Result};
use nalgebra::Isometry3;
use starc_livox::scan::Scan;
use starc_pipeline::lio::ImuSample;
use starc_pipeline::mission::RobotDetection;
use starc_pipeline::record::msgs::{CanFrameMsg, Pose, Quaternion, Vector3};
use starc_pipeline::record::{Frames, PersonBox, Recorder, RecorderOptions, RecorderStats};
use starc_time::{Clock, Stamp};
use starc_view::ViewSnapshot;
use std::path::Path;
use std::sync::mpsc::{channel, sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Entries the writer may fall behind by: at the Avia's 200 Hz IMU and 10 Hz scans, about four
/// seconds (some 40 scans, 30 MB), more than a disk's writeback stalls last.
const QUEUE_ENTRIES: usize = 1024;

/// An open chunk closes after this long without being closed by the recorder itself, so data
/// that arrived before a silence (a LiDAR unplugged) is on disk within a second.
const CHUNK_WALL_S: f64 = 1.0;

/// How long `finish` waits for a stalled disk to take the last writes and the index.
pub const FINISH_WAIT: Duration = Duration::from_secs(10);

/// What the recording did not take, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecordingCounts {
    /// Entries handed to the writer.
    pub queued: u64,
    /// Entries dropped because the writer was `QUEUE_ENTRIES` behind (a slow or stalled disk).
    pub dropped: u64,
    /// Of those, scans.
    pub dropped_scans: u64,
    /// Entries dropped because the recording had stopped (a disk error, logged).
    pub after_stop: u64,
}

/// The base's feedback, recorded in batches (a real base sends thousands of frames a second,
/// which one entry each would push out of the queue).
enum Wheel {
    Frame { t_ns: u64, frame: CanFrameMsg },
    Odometry { t_ns: u64, pose: Pose, linear_m_s: [f64; 3], angular_rad_s: [f64; 3] },
}

/// Feedback items per batch entry.
const WHEEL_BATCH: usize = 128;

/// What the node records, owned, for the writer thread.
enum Entry {
    Wheels(Vec<Wheel>),
    Scan(Box<Scan>),
    Imu(ImuSample),
    Pose { t_ns: u64, pose: Isometry3<f64> },
    Detections { t_ns: u64, people: Vec<PersonBox> },
    ArFrame { t_ns: u64, snapshot: Arc<ViewSnapshot> },
}

pub struct NodeRecorder {
    tx: Option<SyncSender<Entry>>,
    /// The writer thread's end: its result, or a hang-up if it panicked.
    done: Option<Receiver<Finished>>,
    counts: RecordingCounts,
    /// Feedback waiting to go out as one entry (before the next entry of another kind, so the
    /// file keeps the order things arrived in).
    wheels: Vec<Wheel>,
    /// Whether entries have been dropped since the writer last took one (one warning per
    /// episode, not per entry).
    dropping: bool,
}

/// How a node records.
#[derive(Clone, Copy, Debug, Default)]
pub struct RecordOptions {
    /// `fdatasync` after every chunk: the recording survives a power cut, not only a crash.
    pub fsync: bool,
}

pub(crate) fn pose_msg(p: &Isometry3<f64>) -> Pose {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    Pose { position: Vector3::new(t.x, t.y, t.z), orientation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w } }
}

/// A detection's people as boxes in the map frame, numbered in the detector's order.
pub(crate) fn person_boxes(d: &RobotDetection) -> Vec<PersonBox> {
    d.found
        .iter()
        .enumerate()
        .map(|(i, p)| PersonBox {
            id: i as i32,
            center_m: [p.centre_m.x, p.centre_m.y, p.centre_m.z],
            size_m: [p.size_m.x, p.size_m.y, p.size_m.z],
            yaw_rad: p.yaw_rad,
            score: p.score as f32,
            pose: p.pose,
        })
        .collect()
}

impl NodeRecorder {
    /// `device` names the topics (`robot`, `fpv`) and the LiDAR's frame. The file is created
    /// here, so a bad path fails the node at start.
    pub fn create(path: &Path, device: &'static str) -> Result<Self> {
        Self::create_with(path, device, RecordOptions::default())
    }

    pub fn create_with(path: &Path, device: &'static str, opts: RecordOptions) -> Result<Self> {
        let lidar = if device == "robot" { "avia".to_string() } else { format!("{device}_avia") };
        let frames = Frames { lidar, ..Frames::default() };
        let options =
            RecorderOptions { clock: Clock::Ptp, frames, sync_chunks: opts.fsync, ..RecorderOptions::default() };
        let rec = Recorder::create(path, options).map_err(|source| NodeError::File { path: path.into(), source })?;
        tracing::info!(path = %path.display(), fsync = opts.fsync, "recording");
        let (tx, rx) = sync_channel(QUEUE_ENTRIES);
        let (done_tx, done) = channel();
        let writer = std::thread::Builder::new()
            .name(format!("{device}-recorder"))
            .spawn(move || drop(done_tx.send(write_all(rec, device, rx))));
        writer.map_err(|source| NodeError::Io { what: "starting the recorder thread", source })?;
        Ok(Self {
            tx: Some(tx),
            done: Some(done),
            counts: RecordingCounts::default(),
            wheels: Vec::new(),
            dropping: false,
        })
    }

    /// What has been queued and dropped so far.
    pub fn counts(&self) -> RecordingCounts {
        self.counts
    }

    /// Queues `entry` after any feedback batched before it.
    fn send(&mut self, entry: Entry) {
        self.flush_wheels();
        self.queue(entry);
    }

    fn batch(&mut self, item: Wheel) {
        self.wheels.push(item);
        if self.wheels.len() >= WHEEL_BATCH {
            self.flush_wheels();
        }
    }

    /// The batched feedback as one entry, if any.
    fn flush_wheels(&mut self) {
        if !self.wheels.is_empty() {
            let batch = std::mem::take(&mut self.wheels);
            self.queue(Entry::Wheels(batch));
        }
    }

    /// A feedback frame from the base's bus (`/robot/can/rx`), at `t_ns` on the LiDAR's clock.
    pub fn can_frame(&mut self, t_ns: u64, frame: &starc_can::CanFrame) {
        let id = frame.id();
        let mut data = [0u8; 8];
        let bytes = frame.data();
        if let Some(d) = data.get_mut(..bytes.len()) {
            d.copy_from_slice(bytes);
        }
        let msg = CanFrameMsg {
            id: id.raw(),
            is_extended: id.is_extended(),
            dlc: bytes.len() as u8,
            data,
            ..CanFrameMsg::default()
        };
        self.batch(Wheel::Frame { t_ns, frame: msg });
    }

    /// The base's wheel odometry (`/robot/wheel_odom`): planar pose (x, y, yaw) and twist.
    pub fn wheel_odometry(&mut self, t_ns: u64, pose_xy_yaw: (f64, f64, f64), twist: [f64; 3]) {
        let (x, y, yaw) = pose_xy_yaw;
        let (s, c) = (yaw / 2.0).sin_cos();
        let pose = Pose { position: Vector3::new(x, y, 0.0), orientation: Quaternion { x: 0.0, y: 0.0, z: s, w: c } };
        let [vx, vy, wz] = twist;
        self.batch(Wheel::Odometry { t_ns, pose, linear_m_s: [vx, vy, 0.0], angular_rad_s: [0.0, 0.0, wz] });
    }

    /// Queues `entry`, or drops and counts it: the node never waits for the disk.
    fn queue(&mut self, entry: Entry) {
        let Some(tx) = self.tx.as_ref() else {
            self.counts.after_stop += 1;
            return;
        };
        let is_scan = matches!(entry, Entry::Scan(_));
        match tx.try_send(entry) {
            Ok(()) => {
                self.counts.queued += 1;
                self.dropping = false;
            }
            Err(TrySendError::Full(_)) => {
                self.counts.dropped += 1;
                self.counts.dropped_scans += u64::from(is_scan);
                if !self.dropping {
                    tracing::warn!(
                        dropped = self.counts.dropped,
                        "the recording is {QUEUE_ENTRIES} entries behind the node: dropping until the disk catches up"
                    );
                    self.dropping = true;
                }
            }
            // The writer has stopped (it logged why): record nothing more.
            Err(TrySendError::Disconnected(_)) => {
                self.counts.after_stop += 1;
                self.tx = None;
            }
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
        self.send(Entry::Detections { t_ns, people: person_boxes(d) });
    }

    /// A published AR frame: its PNG (encoded on the writer thread unless a viewer already did).
    pub fn ar_frame(&mut self, t_ns: u64, snapshot: Arc<ViewSnapshot>) {
        self.send(Entry::ArFrame { t_ns, snapshot });
    }

    /// Waits for the writer to write everything queued and the index; an error if the index
    /// could not be written (a disk error earlier only stopped the recording, with a warning).
    /// A disk that takes nothing for [`FINISH_WAIT`] is left to the writer thread, which goes on
    /// finishing the file if the disk comes back before the process ends.
    pub fn finish(mut self) -> Result<RecordingCounts> {
        self.close(FINISH_WAIT)?;
        Ok(self.counts)
    }

    /// As [`finish`](Self::finish), waiting at most `wait`.
    pub fn finish_within(mut self, wait: Duration) -> Result<RecordingCounts> {
        self.close(wait)?;
        Ok(self.counts)
    }

    fn close(&mut self, wait: Duration) -> Result<()> {
        self.flush_wheels();
        self.tx = None;
        let Some(done) = self.done.take() else { return Ok(()) };
        match done.recv_timeout(wait) {
            Ok(Ok(Some(stats))) => tracing::info!(?stats, counts = ?self.counts, "recording finished"),
            Ok(Ok(None)) => {}
            Ok(Err(e)) => return Err(NodeError::Pipeline(e)),
            Err(RecvTimeoutError::Timeout) => return Err(NodeError::RecordingStalled { waited_s: wait.as_secs_f64() }),
            Err(RecvTimeoutError::Disconnected) => {
                return Err(NodeError::Thread("the recording's writer thread panicked"))
            }
        }
        Ok(())
    }
}

impl Drop for NodeRecorder {
    /// A node that stops on an error still leaves a finished file.
    fn drop(&mut self) {
        if let Err(e) = self.close(FINISH_WAIT) {
            tracing::warn!("{e}");
        }
    }
}

/// What the writer thread ends with: the stats of a recording it finished, `None` for one a
/// write error had already stopped (and finished as far as it could), or the error of the last
/// finish.
type Finished = std::result::Result<Option<RecorderStats>, starc_pipeline::PipelineError>;

/// The next entry; `Ok(None)` when the open chunk has waited [`CHUNK_WALL_S`] and should close
/// first; `Err` once the node has hung up.
fn next_entry(rx: &Receiver<Entry>, open_since: Option<Instant>) -> std::result::Result<Option<Entry>, ()> {
    let Some(since) = open_since else { return rx.recv().map(Some).map_err(|_| ()) };
    let left = Duration::from_secs_f64(CHUNK_WALL_S).saturating_sub(since.elapsed());
    match rx.recv_timeout(left) {
        Ok(entry) => Ok(Some(entry)),
        Err(RecvTimeoutError::Timeout) => Ok(None),
        Err(RecvTimeoutError::Disconnected) => Err(()),
    }
}

/// The writer thread: every entry until the node hangs up, then the index.
fn write_all(mut rec: Recorder, device: &'static str, rx: Receiver<Entry>) -> Finished {
    let (points_topic, imu_topic) = (format!("/{device}/points"), format!("/{device}/imu"));
    let mut open_since: Option<Instant> = None;
    let mut skipped = 0u64;
    while let Ok(next) = next_entry(&rx, open_since) {
        let Some(entry) = next else {
            open_since = None;
            if let Err(e) = rec.close_chunk() {
                return stop(rec, "closing a chunk", &e);
            }
            continue;
        };
        let (what, result) = match entry {
            Entry::Wheels(batch) => ("wheels", write_wheels(&mut rec, &batch)),
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
        match result {
            Ok(()) => {}
            // The entry itself was bad (a stamp past 2038 or on another clock, a cloud that
            // does not fit a message): it is skipped, the recording goes on.
            Err(e) if !is_disk_error(&e) => {
                skipped += 1;
                if skipped.is_power_of_two() {
                    tracing::warn!(skipped, "recording: a {what} entry was not recorded: {e}");
                }
            }
            Err(e) => return stop(rec, what, &e),
        }
        open_since = if rec.has_open_chunk() { open_since.or_else(|| Some(Instant::now())) } else { None };
    }
    if skipped > 0 {
        tracing::warn!(skipped, "recording: entries not recorded (bad stamps or contents)");
    }
    rec.finish().map(Some)
}

fn write_wheels(rec: &mut Recorder, batch: &[Wheel]) -> std::result::Result<(), starc_pipeline::PipelineError> {
    for item in batch {
        match item {
            Wheel::Frame { t_ns, frame } => rec.can_frame(Stamp::new(*t_ns, Clock::Ptp), frame)?,
            Wheel::Odometry { t_ns, pose, linear_m_s, angular_rad_s } => {
                rec.wheel_odometry(Stamp::new(*t_ns, Clock::Ptp), *pose, *linear_m_s, *angular_rad_s)?
            }
        }
    }
    Ok(())
}

/// Whether a write error is the file's (the disk, the container), not the entry's.
fn is_disk_error(e: &starc_pipeline::PipelineError) -> bool {
    matches!(e, starc_pipeline::PipelineError::Io { .. } | starc_pipeline::PipelineError::Mcap { .. })
}

/// A write failed (not for lack of room: that is retried): the recording ends here, finished as
/// far as the disk allows. Dropping the receiver tells the node to stop sending.
fn stop(mut rec: Recorder, what: &str, e: &starc_pipeline::PipelineError) -> Finished {
    tracing::warn!("recording stopped: {what}: {e}");
    if let Err(e) = rec.finish() {
        tracing::warn!("recording not finished cleanly: {e}");
    }
    Ok(None)
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
