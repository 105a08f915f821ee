//! [`Recorder`]: typed ROS 2 messages into a chunked MCAP file that survives a crash.
//!
//! Each chunk is assembled in memory and reaches the file in one `write_all` when it closes, so
//! an abort, SIGKILL or power cut leaves a file whose every closed chunk is complete and readable
//! (with [`super::reader`] in recover mode, or any MCAP reader that tolerates a missing summary);
//! only the chunk still open is lost. Chunks close by size or by span of log time, whichever
//! comes first, which bounds the loss in both bytes and seconds.

use super::build::MessageBuilder;
use super::msgs::{CanFrameMsg, Header, PointCloud2, PointField, Pose, RosMessage};
use super::sink::{RetrySink, SinkGauge};
use super::{schema, Topic};
use crate::cloud::PointCloud;
use crate::PipelineError;
use mcap::records::MessageHeader;
use starc_time::{Clock, Stamp};
use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

/// Names of the frames the recorder stamps its messages with (REP 105 where it applies).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frames {
    pub map: String,
    pub odom: String,
    /// The frame the wheels' own odometry integrates in (a second `odom`, apart from the LIO's).
    pub wheel_odom: String,
    pub base: String,
    pub lidar: String,
    pub imu: String,
    pub fpv: String,
}

impl Default for Frames {
    fn default() -> Self {
        Self {
            map: "map".into(),
            odom: "odom".into(),
            wheel_odom: "wheel_odom".into(),
            base: "base_link".into(),
            lidar: "avia".into(),
            imu: "imu_link".into(),
            fpv: "fpv_camera".into(),
        }
    }
}

/// Chunk compression. LZ4 costs little CPU; point clouds shrink by about a third.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChunkCompression {
    None,
    Lz4,
}

/// How the recorder writes.
#[derive(Clone, Debug)]
pub struct RecorderOptions {
    /// A chunk closes once it holds this many uncompressed bytes.
    pub chunk_size_bytes: usize,
    /// ... or once its messages span this much log time, so a slow topic alone still commits.
    pub chunk_span_ns: u64,
    pub compression: ChunkCompression,
    /// `fdatasync` after every chunk: survives power loss, costs a disk flush per chunk.
    pub sync_chunks: bool,
    /// The clock every stamp must be on (a recording on mixed clocks cannot be replayed).
    pub clock: Clock,
    pub frames: Frames,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            chunk_size_bytes: 4 << 20,
            chunk_span_ns: 1_000_000_000,
            compression: ChunkCompression::None,
            sync_chunks: false,
            clock: Clock::Ptp,
            frames: Frames::default(),
        }
    }
}

/// One detected person, as a box in the map frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PersonBox {
    /// Track id; stable across frames when the detector tracks.
    pub id: i32,
    pub center_m: [f64; 3],
    /// Length, width, height.
    pub size_m: [f64; 3],
    pub yaw_rad: f64,
    pub score: f32,
    /// Standing, sitting or crouching, lying.
    pub pose: crate::detect::PersonPose,
}

/// What has been written and what is safely in the file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecorderStats {
    pub messages: u64,
    /// Messages in closed chunks: what a crash now would keep.
    pub committed_messages: u64,
    pub chunks: u64,
    pub payload_bytes: u64,
    /// Messages not taken because the disk was full (the file stays readable; the recording
    /// goes on once there is room).
    pub dropped_disk_full: u64,
    /// Writes the disk refused for lack of room; each was retried later.
    pub disk_full_events: u64,
}

struct OpenChunk {
    first_log_ns: u64,
    bytes: usize,
    messages: u64,
}

/// Writes a STARC recording. Call [`Recorder::finish`]; dropping it finishes on a best-effort
/// basis and logs what failed.
pub struct Recorder {
    writer: Option<mcap::Writer<RetrySink<File>>>,
    /// What the file holds back while the disk is full.
    sink: Arc<SinkGauge>,
    /// Messages in closed chunks that a full disk still holds in memory.
    held_messages: u64,
    sync_file: Option<File>,
    options: RecorderOptions,
    /// The messages' builder: `options`' clock and frames.
    build: MessageBuilder,
    channels: BTreeMap<String, u16>,
    sequences: BTreeMap<u16, u32>,
    open: Option<OpenChunk>,
    stats: RecorderStats,
}

fn mcap_err(context: &str) -> impl FnOnce(mcap::McapError) -> PipelineError + '_ {
    move |source| PipelineError::Mcap { context: context.into(), source }
}

impl Recorder {
    /// Creates (truncates) `path` and writes the MCAP header.
    pub fn create(path: &Path, options: RecorderOptions) -> Result<Self, PipelineError> {
        let file = File::create(path).map_err(|e| PipelineError::io(format!("creating {}", path.display()), e))?;
        let sync_file = if options.sync_chunks {
            Some(file.try_clone().map_err(|e| PipelineError::io("cloning the recording's handle", e))?)
        } else {
            None
        };
        let compression = match options.compression {
            ChunkCompression::None => None,
            ChunkCompression::Lz4 => Some(mcap::Compression::Lz4),
        };
        let file = RetrySink::new(file, 0);
        let sink = file.gauge();
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("starc-", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            // Chunks close where the recorder says (see `after_write`), never in between.
            .chunk_size(None)
            // Buffered chunks: nothing of an unfinished chunk ever reaches the file.
            .disable_seeking(true)
            .create(file)
            .map_err(mcap_err("writing the header"))?;
        Ok(Self {
            writer: Some(writer),
            sink,
            held_messages: 0,
            sync_file,
            build: MessageBuilder::new(options.clock, options.frames.clone()),
            options,
            channels: BTreeMap::new(),
            sequences: BTreeMap::new(),
            open: None,
            stats: RecorderStats::default(),
        })
    }

    pub fn options(&self) -> &RecorderOptions {
        &self.options
    }

    pub fn stats(&self) -> RecorderStats {
        RecorderStats { disk_full_events: self.sink.full_events(), ..self.stats }
    }

    /// Whether messages wait in a chunk that has not closed yet (lost if the process dies now).
    pub fn has_open_chunk(&self) -> bool {
        self.open.is_some()
    }

    /// Whether the disk has taken everything so far; if not, tries again now.
    fn disk_has_room(&mut self) -> Result<bool, PipelineError> {
        if self.sink.held_bytes() > 0 {
            let writer = self.writer.as_mut().ok_or_else(finished)?;
            writer.flush().map_err(mcap_err("writing what a full disk held back"))?;
        }
        let room = self.sink.held_bytes() == 0;
        if room && self.held_messages > 0 {
            self.stats.committed_messages += std::mem::take(&mut self.held_messages);
        }
        Ok(room)
    }

    /// The messages' builder: this recording's clock and frames.
    pub fn builder(&self) -> &MessageBuilder {
        &self.build
    }

    fn header(&self, stamp: Stamp, frame_id: &str) -> Result<Header, PipelineError> {
        self.builder().header(stamp, frame_id)
    }

    fn channel(&mut self, topic: &str, type_name: &str) -> Result<u16, PipelineError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let text = schema::definition(type_name)
            .ok_or_else(|| PipelineError::Recording { reason: format!("no ros2msg definition for {type_name}") })?;
        let writer = self.writer.as_mut().ok_or_else(finished)?;
        let schema_id =
            writer.add_schema(type_name, "ros2msg", text.as_bytes()).map_err(mcap_err("adding a schema"))?;
        let metadata = BTreeMap::from([("offered_qos_profiles".to_string(), offered_qos(topic))]);
        let id = writer.add_channel(schema_id, topic, "cdr", &metadata).map_err(mcap_err("adding a channel"))?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Writes any message on any topic; `log_ns` is its time on the recording's clock. The typed
    /// methods below are this plus the topic, frame and conversion.
    pub fn write<T: RosMessage>(&mut self, topic: &str, log_ns: u64, msg: &T) -> Result<(), PipelineError> {
        let payload = msg.to_cdr();
        self.write_cdr(topic, T::TYPE_NAME, log_ns, &payload)
    }

    /// Writes an already encoded CDR payload (as read back from another recording).
    pub fn write_cdr(
        &mut self,
        topic: &str,
        type_name: &str,
        log_ns: u64,
        payload: &[u8],
    ) -> Result<(), PipelineError> {
        // A full disk: the chunk it refused stays in memory and this message is not taken,
        // which bounds the memory held to that chunk until the disk has room again.
        if self.open.is_none() && !self.disk_has_room()? {
            self.stats.dropped_disk_full += 1;
            return Ok(());
        }
        let channel_id = self.channel(topic, type_name)?;
        let sequence = self.sequences.entry(channel_id).or_insert(0);
        *sequence = sequence.wrapping_add(1);
        let header = MessageHeader { channel_id, sequence: *sequence, log_time: log_ns, publish_time: log_ns };
        let writer = self.writer.as_mut().ok_or_else(finished)?;
        writer.write_to_known_channel(&header, payload).map_err(mcap_err("writing a message"))?;
        self.stats.messages += 1;
        self.stats.payload_bytes += payload.len() as u64;
        let open = self.open.get_or_insert(OpenChunk { first_log_ns: log_ns, bytes: 0, messages: 0 });
        open.bytes = open.bytes.saturating_add(payload.len() + 31);
        open.messages += 1;
        open.first_log_ns = open.first_log_ns.min(log_ns);
        let span_ns = log_ns.saturating_sub(open.first_log_ns);
        if open.bytes >= self.options.chunk_size_bytes || span_ns >= self.options.chunk_span_ns {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Closes the open chunk now: everything written so far will survive a crash.
    pub fn close_chunk(&mut self) -> Result<(), PipelineError> {
        let Some(open) = self.open.take() else {
            return Ok(());
        };
        let writer = self.writer.as_mut().ok_or_else(finished)?;
        writer.flush().map_err(mcap_err("closing a chunk"))?;
        self.stats.chunks += 1;
        if self.sink.held_bytes() > 0 {
            self.held_messages += open.messages;
            return Ok(());
        }
        if let Some(f) = &self.sync_file {
            f.sync_data().map_err(|e| PipelineError::io("syncing the recording", e))?;
        }
        self.stats.committed_messages += open.messages + std::mem::take(&mut self.held_messages);
        Ok(())
    }

    /// One LiDAR scan on `/robot/points` in the LiDAR frame: fields x, y, z, intensity (f32),
    /// t (u32, ns after the header stamp), line and tag (u8). The stamp is the scan's start.
    pub fn point_cloud(&mut self, cloud: &PointCloud) -> Result<(), PipelineError> {
        self.point_cloud_on(Topic::Points.name(), cloud)
    }

    /// As [`point_cloud`](Self::point_cloud) on another topic (a second device: `/fpv/points`).
    pub fn point_cloud_on(&mut self, topic: &str, cloud: &PointCloud) -> Result<(), PipelineError> {
        let (start, msg) = self.builder().cloud(cloud)?;
        self.write(topic, start.ns, &msg)
    }

    /// One IMU sample on `/robot/imu` (orientation unknown: `orientation_covariance[0] = -1`, per REP 145).
    pub fn imu(&mut self, stamp: Stamp, gyro_rad_s: [f64; 3], acc_m_s2: [f64; 3]) -> Result<(), PipelineError> {
        self.imu_on(Topic::Imu.name(), stamp, gyro_rad_s, acc_m_s2)
    }

    /// As [`imu`](Self::imu) on another topic (a second device: `/fpv/imu`).
    pub fn imu_on(
        &mut self,
        topic: &str,
        stamp: Stamp,
        gyro_rad_s: [f64; 3],
        acc_m_s2: [f64; 3],
    ) -> Result<(), PipelineError> {
        let msg = self.builder().imu(stamp, gyro_rad_s, acc_m_s2)?;
        self.write(topic, stamp.ns, &msg)
    }

    /// The robot's odometry on `/robot/odom`: base frame in the odom frame, twist in the base
    /// frame (linear m/s, angular rad/s). Covariances stay zero (unknown).
    pub fn odometry(
        &mut self,
        stamp: Stamp,
        pose: Pose,
        linear_m_s: [f64; 3],
        angular_rad_s: [f64; 3],
    ) -> Result<(), PipelineError> {
        let odom = self.options.frames.odom.clone();
        self.base_odometry(Topic::Odom, &odom, stamp, pose, [linear_m_s, angular_rad_s])
    }

    /// The base's wheel odometry on `/robot/wheel_odom`: the base in the `wheel_odom` frame
    /// (the wheels' own integration), twist in the base frame (linear m/s, angular rad/s).
    pub fn wheel_odometry(
        &mut self,
        stamp: Stamp,
        pose: Pose,
        linear_m_s: [f64; 3],
        angular_rad_s: [f64; 3],
    ) -> Result<(), PipelineError> {
        let wheel_odom = self.options.frames.wheel_odom.clone();
        self.base_odometry(Topic::WheelOdom, &wheel_odom, stamp, pose, [linear_m_s, angular_rad_s])
    }

    /// The base frame's odometry in `frame` on `topic`; `twist` is (linear m/s, angular rad/s).
    fn base_odometry(
        &mut self,
        topic: Topic,
        frame: &str,
        stamp: Stamp,
        pose: Pose,
        twist: [[f64; 3]; 2],
    ) -> Result<(), PipelineError> {
        let msg = self.builder().odometry(stamp, frame, &self.options.frames.base, pose, twist)?;
        self.write(topic.name(), stamp.ns, &msg)
    }

    /// One CAN frame the base's bus carried (its feedback), on `/robot/can/rx` as
    /// `can_msgs/Frame`; `frame_id` empty, as ros2_socketcan leaves it.
    pub fn can_frame(&mut self, stamp: Stamp, frame: &CanFrameMsg) -> Result<(), PipelineError> {
        let msg = CanFrameMsg { header: self.header(stamp, "")?, ..frame.clone() };
        self.write(Topic::CanRx.name(), stamp.ns, &msg)
    }

    /// The viewer's (FPV headset or camera) pose on `/fpv/odom`, in the map frame.
    pub fn fpv_odometry(&mut self, stamp: Stamp, pose: Pose) -> Result<(), PipelineError> {
        let frames = &self.options.frames;
        let msg = self.builder().odometry(stamp, &frames.map, &frames.fpv, pose, [[0.0; 3]; 2])?;
        self.write(Topic::FpvOdom.name(), stamp.ns, &msg)
    }

    /// Transforms on `/tf`: each `(parent, child, translation + rotation)` at `stamp`.
    pub fn tf(&mut self, stamp: Stamp, transforms: &[(&str, &str, Pose)]) -> Result<(), PipelineError> {
        let msg = self.builder().tf(stamp, transforms)?;
        self.write(Topic::Tf.name(), stamp.ns, &msg)
    }

    /// Fixed transforms (extrinsics) on `/tf_static`; write them once, at the start.
    pub fn tf_static(&mut self, stamp: Stamp, transforms: &[(&str, &str, Pose)]) -> Result<(), PipelineError> {
        let msg = self.builder().tf(stamp, transforms)?;
        self.write(Topic::TfStatic.name(), stamp.ns, &msg)
    }

    /// Detected people on `/detections/markers`, in the map frame: a DELETEALL marker (so boxes
    /// of people no longer seen disappear), then one translucent cube and one score label each.
    pub fn detections(&mut self, stamp: Stamp, people: &[PersonBox]) -> Result<(), PipelineError> {
        let msg = self.builder().markers(stamp, people)?;
        self.write(Topic::DetectionMarkers.name(), stamp.ns, &msg)
    }

    /// The AR view as shown to the user, PNG-encoded, on `/fpv/ar_image/compressed`.
    pub fn ar_image_png(&mut self, stamp: Stamp, png: &[u8]) -> Result<(), PipelineError> {
        let msg = self.builder().png_image(stamp, png)?;
        self.write(Topic::ArImage.name(), stamp.ns, &msg)
    }

    /// Closes the last chunk and writes the summary (index, statistics) and footer. Further
    /// writes return an error.
    pub fn finish(&mut self) -> Result<RecorderStats, PipelineError> {
        self.close_chunk()?;
        let Some(mut writer) = self.writer.take() else {
            return Ok(self.stats);
        };
        writer.finish().map_err(mcap_err("writing the summary"))?;
        let mut file = writer.into_inner();
        file.retry().map_err(|e| PipelineError::io("writing the end of the recording", e))?;
        if file.held_bytes() > 0 {
            return Err(PipelineError::Recording {
                reason: format!(
                    "the disk is full: the last {} bytes (the index) were not written; every chunk before \
                     them reads in recover mode",
                    file.held_bytes()
                ),
            });
        }
        self.stats.committed_messages += std::mem::take(&mut self.held_messages);
        if self.options.sync_chunks {
            file.get_ref().sync_all().map_err(|e| PipelineError::io("syncing the recording", e))?;
        }
        Ok(self.stats())
    }
}

/// The QoS `ros2 bag play` republishes a topic with (rosbag2's channel metadata, Humble's
/// integer form): reliable, volatile, keep last 10; `/tf_static` transient local, keep last 1,
/// so late subscribers still get the extrinsics.
fn offered_qos(topic: &str) -> String {
    const INFINITE: &str = "\n    sec: 2147483647\n    nsec: 4294967295";
    let (durability, depth) = if topic == super::Topic::TfStatic.name() { (1, 1) } else { (2, 10) };
    format!(
        "- history: 1\n  depth: {depth}\n  reliability: 1\n  durability: {durability}\n  deadline:{INFINITE}\n  \
         lifespan:{INFINITE}\n  liveliness: 1\n  liveliness_lease_duration:{INFINITE}\n  \
         avoid_ros_namespace_conventions: false\n"
    )
}

fn finished() -> PipelineError {
    PipelineError::Recording { reason: "the recording is already finished".into() }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.writer.is_some() {
            if let Err(e) = self.finish() {
                tracing::warn!("recording not finished cleanly: {e}");
            }
        }
    }
}

/// Bytes per point in our PointCloud2 layout (x, y, z, intensity, t, line, tag, 2 pad).
pub const POINT_STEP: u32 = 24;

/// Our point layout as `sensor_msgs/PointField`s.
pub fn point_fields() -> Vec<PointField> {
    let f = |name: &str, offset, datatype| PointField { name: name.into(), offset, datatype, count: 1 };
    vec![
        f("x", 0, PointField::FLOAT32),
        f("y", 4, PointField::FLOAT32),
        f("z", 8, PointField::FLOAT32),
        f("intensity", 12, PointField::FLOAT32),
        f("t", 16, PointField::UINT32),
        f("line", 20, PointField::UINT8),
        f("tag", 21, PointField::UINT8),
    ]
}

/// An unordered cloud (height 1) in our layout.
pub fn cloud_to_msg(cloud: &PointCloud, header: Header) -> PointCloud2 {
    let mut data = Vec::with_capacity(cloud.points.len() * POINT_STEP as usize);
    for p in &cloud.points {
        data.extend_from_slice(&p.x_m.to_le_bytes());
        data.extend_from_slice(&p.y_m.to_le_bytes());
        data.extend_from_slice(&p.z_m.to_le_bytes());
        data.extend_from_slice(&p.intensity.to_le_bytes());
        data.extend_from_slice(&p.offset_ns.to_le_bytes());
        data.extend_from_slice(&[p.line, p.tag, 0, 0]);
    }
    let width = u32::try_from(cloud.points.len()).unwrap_or(u32::MAX);
    PointCloud2 {
        header,
        height: 1,
        width,
        fields: point_fields(),
        is_bigendian: false,
        point_step: POINT_STEP,
        row_step: width.saturating_mul(POINT_STEP),
        data,
        is_dense: cloud.points.iter().all(|p| p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite()),
    }
}
