//! A node's ROS 2 bridge (`[ros2]`, docs/ros2.md): what the node records, also put live on
//! rmw_zenoh keys for a ROS 2 system. The robot publishes `robot/points`, `robot/imu`,
//! `robot/odom`, `tf`, `detections/markers` and `detections/people`; the rig `fpv/odom`, `tf`
//! and `fpv/ar_image/compressed` (all under the configured namespace).
//!
//! As with the recording, the node hands each entry to a thread of the bridge's own and goes
//! on: building a PointCloud2 and a router that falls behind never hold up a scan. When the
//! thread is `queue` entries behind, entries are dropped and counted.

use crate::error::{NodeError, Result};
use crate::recording::{person_boxes, pose_msg};
use nalgebra::Isometry3;
use starc_link::ros2::{Qos, Ros2Bridge, Ros2Config, Ros2Counts, TopicId};
use starc_livox::scan::Scan;
use starc_pipeline::lio::ImuSample;
use starc_pipeline::mission::RobotDetection;
use starc_pipeline::record::msgs::{RosMessage, Twist};
use starc_pipeline::record::{Frames, MessageBuilder, PersonBox};
use starc_time::{Clock, Stamp};
use starc_view::ViewSnapshot;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::Duration;

enum Entry {
    Scan(Box<Scan>),
    Imu(ImuSample),
    Pose { t_ns: u64, pose: Isometry3<f64> },
    Detections { t_ns: u64, people: Vec<PersonBox> },
    ArFrame { t_ns: u64, snapshot: Arc<ViewSnapshot> },
}

impl Entry {
    /// A scan or a frame: counted against `MAX_PENDING_BIG`.
    fn is_big(&self) -> bool {
        matches!(self, Entry::Scan(_) | Entry::ArFrame { .. })
    }
}

/// What the bridge did over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Ros2Summary {
    pub queued: u64,
    /// Entries dropped because the bridge was `queue` entries (or four scans) behind.
    pub dropped: u64,
    pub published: u64,
    pub put_errors: u64,
    /// Entries that made no message (a stamp past 2038, a frame that did not encode).
    pub skipped: u64,
    /// CPU time of the bridge's thread: building the messages and handing them to zenoh
    /// (zenoh's own network threads not included).
    pub thread_cpu_s: f64,
}

/// What the bridge's thread ends with.
struct Done {
    counts: Ros2Counts,
    skipped: u64,
    cpu_s: f64,
}

/// CPU time of the calling thread.
fn thread_cpu_s() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0;
    if ok {
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    } else {
        0.0
    }
}

/// How long the node waits, when stopping, for the bridge to put what is queued and close.
pub const CLOSE_WAIT: Duration = Duration::from_secs(3);

/// Scans and AR frames waiting for the bridge at most (each 0.5-1 MB): a router that falls
/// behind costs scans and frames, counted, not memory.
const MAX_PENDING_BIG: usize = 4;

pub struct Ros2Out {
    tx: Option<SyncSender<Entry>>,
    /// Scans and frames queued and not yet put (the thread counts them down).
    pending_big: Arc<AtomicUsize>,
    /// The robot publishes its scans and IMU; the rig does not.
    robot: bool,
    /// The thread's result, once it ends.
    done: Option<Receiver<Done>>,
    summary: Ros2Summary,
    image_every: u64,
    frames_seen: u64,
}

impl Ros2Out {
    /// The bridge of `device` (`robot` or `fpv`), or `None` when `[ros2]` is off. A config that
    /// cannot work fails here; the session itself opens on the bridge's thread (a router that is
    /// not up yet only delays the topics).
    ///
    /// With `cmd_vel`, the twists the ROS 2 system sends on `/cmd_vel` go there (a full channel
    /// drops the newest: the base's watchdog makes a late command worthless anyway).
    pub fn start(
        cfg: &Ros2Config,
        device: &'static str,
        cmd_vel: Option<tokio::sync::mpsc::Sender<Twist>>,
    ) -> Result<Option<Self>> {
        if !cfg.enabled {
            return Ok(None);
        }
        cfg.validate()?;
        let (tx, rx) = sync_channel(cfg.queue);
        let cfg_thread = cfg.clone();
        let pending_big = Arc::new(AtomicUsize::new(0));
        let pending = pending_big.clone();
        let (done_tx, done) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name(format!("{device}-ros2"))
            .spawn(move || drop(done_tx.send(run(&cfg_thread, device, rx, cmd_vel, &pending))))
            .map_err(|source| NodeError::Io { what: "starting the ROS 2 bridge's thread", source })?;
        tracing::info!(connect = ?cfg.connect, domain = cfg.domain_id, namespace = %cfg.namespace, "ROS 2 bridge");
        Ok(Some(Self {
            tx: Some(tx),
            pending_big,
            robot: device == "robot",
            done: Some(done),
            summary: Ros2Summary::default(),
            image_every: cfg.image_every,
            frames_seen: 0,
        }))
    }

    fn send(&mut self, entry: Entry) {
        let Some(tx) = &self.tx else { return };
        match tx.try_send(entry) {
            Ok(()) => self.summary.queued += 1,
            Err(TrySendError::Full(entry)) => {
                self.summary.dropped += 1;
                if entry.is_big() {
                    self.pending_big.fetch_sub(1, Ordering::Relaxed);
                }
            }
            Err(TrySendError::Disconnected(_)) => self.tx = None,
        }
    }

    /// A scan from the live driver (robot only).
    pub fn scan(&mut self, scan: &Scan) {
        if !self.robot {
            return;
        }
        if self.take_big_slot() {
            self.send(Entry::Scan(Box::new(scan.clone())));
        }
    }

    /// Whether one more scan or frame may wait (counted as dropped if not).
    fn take_big_slot(&mut self) -> bool {
        if self.pending_big.load(Ordering::Relaxed) >= MAX_PENDING_BIG {
            self.summary.dropped += 1;
            return false;
        }
        self.pending_big.fetch_add(1, Ordering::Relaxed);
        true
    }

    /// An IMU sample (robot only).
    pub fn imu(&mut self, s: &ImuSample) {
        if self.robot {
            self.send(Entry::Imu(*s));
        }
    }

    /// The robot's LiDAR pose from its LIO, or the rig's world pose.
    pub fn pose(&mut self, t_ns: u64, pose: &Isometry3<f64>) {
        self.send(Entry::Pose { t_ns, pose: *pose });
    }

    pub fn detections(&mut self, t_ns: u64, d: &RobotDetection) {
        self.send(Entry::Detections { t_ns, people: person_boxes(d) });
    }

    /// A rendered AR frame (every `image_every`-th goes out).
    pub fn ar_frame(&mut self, t_ns: u64, snapshot: Arc<ViewSnapshot>) {
        self.frames_seen += 1;
        if self.image_every > 0 && self.frames_seen.is_multiple_of(self.image_every) && self.take_big_slot() {
            self.send(Entry::ArFrame { t_ns, snapshot });
        }
    }

    /// Lets the thread put what is queued, withdraw the node's tokens and close the session,
    /// waiting at most [`CLOSE_WAIT`]: a router that never answered does not keep the node up.
    pub fn finish(mut self) -> Ros2Summary {
        self.close()
    }

    fn close(&mut self) -> Ros2Summary {
        self.tx = None;
        if let Some(done) = self.done.take() {
            match done.recv_timeout(CLOSE_WAIT) {
                Ok(done) => {
                    self.summary.published = done.counts.published;
                    self.summary.put_errors = done.counts.put_errors;
                    self.summary.skipped = done.skipped;
                    self.summary.thread_cpu_s = done.cpu_s;
                }
                Err(RecvTimeoutError::Timeout) => {
                    tracing::warn!("the ROS 2 router did not answer within {} s: bridge left", CLOSE_WAIT.as_secs())
                }
                Err(RecvTimeoutError::Disconnected) => tracing::warn!("the ROS 2 bridge's thread panicked"),
            }
        }
        tracing::info!(summary = ?self.summary, "ROS 2 bridge closed");
        self.summary
    }
}

impl Drop for Ros2Out {
    fn drop(&mut self) {
        if self.done.is_some() {
            self.close();
        }
    }
}

/// The topics of one device.
struct Topics {
    points: Option<TopicId>,
    imu: Option<TopicId>,
    odom: TopicId,
    tf: TopicId,
    markers: Option<TopicId>,
    people: Option<TopicId>,
    image: Option<TopicId>,
}

fn advertise<T: RosMessage>(
    bridge: &mut Ros2Bridge,
    topic: &str,
) -> std::result::Result<TopicId, starc_link::LinkError> {
    bridge.advertise(topic, T::TYPE_NAME, Qos::DEFAULT)
}

fn topics(bridge: &mut Ros2Bridge, device: &str) -> std::result::Result<Topics, starc_link::LinkError> {
    use starc_pipeline::record::msgs::{CompressedImage, Imu, MarkerArray, Odometry, PointCloud2, TfMessage};
    use starc_pipeline::record::vision::Detection3DArray;
    let robot = device == "robot";
    Ok(Topics {
        points: robot.then(|| advertise::<PointCloud2>(bridge, "robot/points")).transpose()?,
        imu: robot.then(|| advertise::<Imu>(bridge, "robot/imu")).transpose()?,
        odom: advertise::<Odometry>(bridge, &format!("{device}/odom"))?,
        tf: advertise::<TfMessage>(bridge, "tf")?,
        markers: robot.then(|| advertise::<MarkerArray>(bridge, "detections/markers")).transpose()?,
        people: robot.then(|| advertise::<Detection3DArray>(bridge, "detections/people")).transpose()?,
        image: (!robot).then(|| advertise::<CompressedImage>(bridge, "fpv/ar_image/compressed")).transpose()?,
    })
}

/// The bridge's thread: opens the session, declares the device's topics, puts every entry.
fn run(
    cfg: &Ros2Config,
    device: &'static str,
    rx: Receiver<Entry>,
    cmd_vel: Option<tokio::sync::mpsc::Sender<Twist>>,
    pending_big: &AtomicUsize,
) -> Done {
    let mut bridge = match Ros2Bridge::open(cfg, &format!("starc_{device}")) {
        Ok(b) => b,
        Err(e) => {
            tracing::warn!("ROS 2 bridge not opened: {e}");
            return Done { counts: Ros2Counts::default(), skipped: 0, cpu_s: thread_cpu_s() };
        }
    };
    let topics = match topics(&mut bridge, device) {
        Ok(t) => t,
        Err(e) => {
            tracing::warn!("ROS 2 topics not declared: {e}");
            return Done { counts: bridge.counts(), skipped: 0, cpu_s: thread_cpu_s() };
        }
    };
    if let Some(tx) = cmd_vel {
        let forward = move |payload: Vec<u8>| match Twist::from_cdr(&payload) {
            Ok(t) if [t.linear.x, t.linear.y, t.angular.z].iter().all(|v| v.is_finite()) => {
                let _ = tx.try_send(t);
            }
            _ => tracing::debug!("a /cmd_vel sample that is not a finite Twist"),
        };
        if let Err(e) = bridge.subscribe("cmd_vel", Twist::TYPE_NAME, Qos::DEFAULT, forward) {
            tracing::warn!("/cmd_vel not subscribed: {e}");
        }
    }
    let lidar = if device == "robot" { "avia".to_string() } else { format!("{device}_avia") };
    let build = MessageBuilder::new(Clock::Ptp, Frames { lidar, ..Frames::default() });
    let mut skipped = 0u64;
    while let Ok(entry) = rx.recv() {
        if entry.is_big() {
            pending_big.fetch_sub(1, Ordering::Relaxed);
        }
        match put(&mut bridge, &build, &topics, device, entry) {
            Ok(()) => {}
            Err(e) => {
                skipped += 1;
                if skipped.is_power_of_two() {
                    tracing::warn!(skipped, "ROS 2: a message was not published: {e}");
                }
            }
        }
    }
    let counts = bridge.counts();
    if let Err(e) = bridge.close() {
        tracing::warn!("{e}");
    }
    Done { counts, skipped, cpu_s: thread_cpu_s() }
}

fn put(
    bridge: &mut Ros2Bridge,
    build: &MessageBuilder,
    topics: &Topics,
    device: &str,
    entry: Entry,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let now_ns = i64::try_from(starc_link::host_now_ns()).unwrap_or(i64::MAX);
    let mut out = |id: Option<TopicId>, payload: Vec<u8>| match id {
        Some(id) => bridge.put(id, payload, now_ns),
        None => Ok(()),
    };
    let stamp = |t_ns| Stamp::new(t_ns, Clock::Ptp);
    match entry {
        Entry::Scan(scan) => out(topics.points, build.cloud(&starc_bridge::livox::scan_to_cloud(&scan))?.1.to_cdr())?,
        Entry::Imu(s) => {
            let (g, a) = (s.gyro_rad_s, s.acc_m_s2);
            out(topics.imu, build.imu(stamp(s.t_ns), [g.x, g.y, g.z], [a.x, a.y, a.z])?.to_cdr())?
        }
        Entry::Pose { t_ns, pose } => {
            let f = &build.frames;
            let (frame, child) = if device == "robot" { (&f.odom, &f.base) } else { (&f.map, &f.fpv) };
            let msg = pose_msg(&pose);
            out(Some(topics.odom), build.odometry(stamp(t_ns), frame, child, msg, [[0.0; 3]; 2])?.to_cdr())?;
            out(Some(topics.tf), build.tf(stamp(t_ns), &[(frame, child, msg)])?.to_cdr())?
        }
        Entry::Detections { t_ns, people } => {
            out(topics.markers, build.markers(stamp(t_ns), &people)?.to_cdr())?;
            out(topics.people, build.people(stamp(t_ns), &people)?.to_cdr())?
        }
        Entry::ArFrame { t_ns, snapshot } => {
            out(topics.image, build.png_image(stamp(t_ns), &snapshot.png()?)?.to_cdr())?
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn off_by_default_and_a_config_that_cannot_work_fails_at_start() {
        assert!(Ros2Out::start(&Ros2Config::default(), "robot", None).unwrap().is_none());
        let off_host =
            Ros2Config { enabled: true, connect: vec!["tcp/192.168.1.9:7447".into()], ..Ros2Config::default() };
        assert!(Ros2Out::start(&off_host, "robot", None).is_err());
    }

    /// With no router to connect to, the node's calls never block and the bridge ends cleanly.
    #[test]
    fn no_router_never_holds_up_the_node() {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let cfg = Ros2Config {
            enabled: true,
            connect: vec![format!("tcp/127.0.0.1:{port}")],
            queue: 8,
            ..Ros2Config::default()
        };
        let mut out = Ros2Out::start(&cfg, "robot", None).unwrap().unwrap();
        let started = std::time::Instant::now();
        for i in 0..1000u64 {
            out.pose(i, &Isometry3::identity());
        }
        assert!(started.elapsed() < std::time::Duration::from_secs(1));
        let summary = out.finish();
        assert_eq!(summary.queued + summary.dropped, 1000);
    }
}
