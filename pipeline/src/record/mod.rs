//! Recording to MCAP with ROS 2 message types (CDR), and reading recordings back.
//!
//! - [`writer::Recorder`]: typed methods per message kind onto the topics below; chunked so a
//!   crash keeps every closed chunk; [`writer::Recorder::finish`] writes the index.
//! - [`reader`]: messages back in file order (strict, or recover from a damaged file), a
//!   summary per topic, and `PointCloud2` back into a [`crate::cloud::PointCloud`].
//! - [`msgs`] and [`cdr`]: the ROS 2 messages and their encoding; [`schema`]: their `ros2msg`
//!   definitions, stored in the file so Foxglove, `mcap-ros2-support` and `rosbags` decode it.
//!
//! Stamps are nanoseconds on one clock (PTP by default); each message's MCAP log time and
//! publish time are its header stamp, so a replay can pace by them.
//!
//! ```no_run
//! use starc_pipeline::record::writer::{Recorder, RecorderOptions};
//! use starc_time::{Clock, Stamp};
//! # fn main() -> Result<(), starc_pipeline::PipelineError> {
//! let mut rec = Recorder::create("run.mcap".as_ref(), RecorderOptions::default())?;
//! rec.imu(Stamp::new(1_700_000_000_000_000_000, Clock::Ptp), [0.0, 0.0, 0.1], [0.0, 0.0, 9.81])?;
//! rec.finish()?;
//! # Ok(()) }
//! ```

pub mod attachment;
pub mod build;
pub mod cdr;
pub mod msgs;
pub mod reader;
pub mod scan;
pub mod schema;
pub mod sink;
pub mod vision;
pub mod writer;

pub use build::MessageBuilder;
pub use reader::{messages, summarize, Decoded, ReadMode, RecordedMessage, RecordingSummary};
pub use writer::{ChunkCompression, Frames, PersonBox, Recorder, RecorderOptions, RecorderStats};

/// The topics a recording uses, with the ROS 2 type each carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topic {
    /// `sensor_msgs/msg/PointCloud2`, LiDAR frame, one message per scan.
    Points,
    /// `sensor_msgs/msg/Imu`, IMU frame.
    Imu,
    /// `nav_msgs/msg/Odometry`, base in odom.
    Odom,
    /// `nav_msgs/msg/Odometry`, the base's wheel odometry (base in `wheel_odom`, its twist).
    WheelOdom,
    /// `can_msgs/msg/Frame`, the base's feedback frames as the bus carried them.
    CanRx,
    /// `tf2_msgs/msg/TFMessage`, moving frames.
    Tf,
    /// `tf2_msgs/msg/TFMessage`, extrinsics.
    TfStatic,
    /// `nav_msgs/msg/Odometry`, the viewer's pose in map.
    FpvOdom,
    /// `visualization_msgs/msg/MarkerArray`, detected people in map.
    DetectionMarkers,
    /// `sensor_msgs/msg/CompressedImage`, PNG of the AR view.
    ArImage,
}

impl Topic {
    pub const ALL: [Topic; 10] = [
        Topic::Points,
        Topic::Imu,
        Topic::Odom,
        Topic::WheelOdom,
        Topic::CanRx,
        Topic::Tf,
        Topic::TfStatic,
        Topic::FpvOdom,
        Topic::DetectionMarkers,
        Topic::ArImage,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Topic::Points => "/robot/points",
            Topic::Imu => "/robot/imu",
            Topic::Odom => "/robot/odom",
            Topic::WheelOdom => "/robot/wheel_odom",
            Topic::CanRx => "/robot/can/rx",
            Topic::Tf => "/tf",
            Topic::TfStatic => "/tf_static",
            Topic::FpvOdom => "/fpv/odom",
            Topic::DetectionMarkers => "/detections/markers",
            Topic::ArImage => "/fpv/ar_image/compressed",
        }
    }

    pub fn type_name(self) -> &'static str {
        use msgs::RosMessage;
        match self {
            Topic::Points => msgs::PointCloud2::TYPE_NAME,
            Topic::Imu => msgs::Imu::TYPE_NAME,
            Topic::Odom | Topic::FpvOdom | Topic::WheelOdom => msgs::Odometry::TYPE_NAME,
            Topic::CanRx => msgs::CanFrameMsg::TYPE_NAME,
            Topic::Tf | Topic::TfStatic => msgs::TfMessage::TYPE_NAME,
            Topic::DetectionMarkers => msgs::MarkerArray::TYPE_NAME,
            Topic::ArImage => msgs::CompressedImage::TYPE_NAME,
        }
    }
}
