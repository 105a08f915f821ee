//! [`MessageBuilder`]: our data as ROS 2 messages, stamped on one clock and named in one set of
//! frames. The recorder writes what it builds into MCAP; the ROS 2 bridge (starc-link) puts the
//! same messages on rmw_zenoh keys, so a recording and a live topic never differ.

use super::msgs::{
    check_cloud, ColorRgba, CompressedImage, Header, Imu, Marker, MarkerArray, Odometry, PointCloud2, Pose, Quaternion,
    RosMessage, TfMessage, Time, TransformStamped, Vector3,
};
use super::vision::{BoundingBox3D, Detection3D, Detection3DArray, ObjectHypothesisWithPose};
use super::writer::{cloud_to_msg, Frames, PersonBox};
use crate::cloud::PointCloud;
use crate::detect::PersonPose;
use crate::PipelineError;
use starc_time::{Clock, Stamp};

/// Builds messages whose stamps must be on `clock`, in `frames`.
#[derive(Clone, Debug)]
pub struct MessageBuilder {
    pub clock: Clock,
    pub frames: Frames,
}

impl MessageBuilder {
    pub fn new(clock: Clock, frames: Frames) -> Self {
        Self { clock, frames }
    }

    fn stamp(&self, stamp: Stamp) -> Result<Time, PipelineError> {
        if stamp.clock != self.clock {
            return Err(PipelineError::Recording {
                reason: format!("stamp on the {} clock where messages are on the {} clock", stamp.clock, self.clock),
            });
        }
        Time::from_ns(stamp.ns)
            .ok_or_else(|| PipelineError::Recording { reason: format!("{} ns does not fit a ROS 2 time", stamp.ns) })
    }

    pub fn header(&self, stamp: Stamp, frame_id: &str) -> Result<Header, PipelineError> {
        Ok(Header { stamp: self.stamp(stamp)?, frame_id: frame_id.into() })
    }

    /// A scan in the LiDAR frame, stamped at its start (our point layout, `cloud_to_msg`).
    pub fn cloud(&self, cloud: &PointCloud) -> Result<(Stamp, PointCloud2), PipelineError> {
        let start = cloud
            .start
            .ok_or_else(|| PipelineError::Recording { reason: "a point cloud without a start time".into() })?;
        let msg = cloud_to_msg(cloud, self.header(start, &self.frames.lidar)?);
        check_cloud(&msg)?;
        Ok((start, msg))
    }

    /// One IMU sample; orientation unknown (`orientation_covariance[0] = -1`, REP 145).
    pub fn imu(&self, stamp: Stamp, gyro_rad_s: [f64; 3], acc_m_s2: [f64; 3]) -> Result<Imu, PipelineError> {
        let mut not_given = [0.0; 9];
        not_given[0] = -1.0;
        Ok(Imu {
            header: self.header(stamp, &self.frames.imu)?,
            orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 0.0 },
            orientation_covariance: not_given,
            angular_velocity: Vector3::new(gyro_rad_s[0], gyro_rad_s[1], gyro_rad_s[2]),
            angular_velocity_covariance: [0.0; 9],
            linear_acceleration: Vector3::new(acc_m_s2[0], acc_m_s2[1], acc_m_s2[2]),
            linear_acceleration_covariance: [0.0; 9],
        })
    }

    /// `child` in `frame`, with its twist (linear m/s, angular rad/s) in `child`; covariances
    /// zero (unknown).
    pub fn odometry(
        &self,
        stamp: Stamp,
        frame: &str,
        child: &str,
        pose: Pose,
        twist: [[f64; 3]; 2],
    ) -> Result<Odometry, PipelineError> {
        let [l, a] = twist;
        Ok(Odometry {
            header: self.header(stamp, frame)?,
            child_frame_id: child.into(),
            pose,
            pose_covariance: [0.0; 36],
            twist: (Vector3::new(l[0], l[1], l[2]), Vector3::new(a[0], a[1], a[2])),
            twist_covariance: [0.0; 36],
        })
    }

    /// Each `(parent, child, translation + rotation)` at `stamp`.
    pub fn tf(&self, stamp: Stamp, transforms: &[(&str, &str, Pose)]) -> Result<TfMessage, PipelineError> {
        let time = self.stamp(stamp)?;
        let transforms = transforms
            .iter()
            .map(|(parent, child, pose)| TransformStamped {
                header: Header { stamp: time, frame_id: (*parent).into() },
                child_frame_id: (*child).into(),
                translation: pose.position,
                rotation: pose.orientation,
            })
            .collect();
        Ok(TfMessage { transforms })
    }

    /// People in the map frame as RViz markers: a DELETEALL marker (boxes of people no longer
    /// seen disappear), then one translucent cube and one score label each.
    pub fn markers(&self, stamp: Stamp, people: &[PersonBox]) -> Result<MarkerArray, PipelineError> {
        let header = self.header(stamp, &self.frames.map)?;
        let mut markers = Vec::with_capacity(1 + 2 * people.len());
        // Empty namespace: every ROS 2 version reads that as "all markers on this topic".
        markers.push(Marker { header: header.clone(), action: Marker::DELETE_ALL, ..Marker::default() });
        for p in people {
            let pose = box_pose(p);
            markers.push(Marker {
                header: header.clone(),
                ns: "people".into(),
                id: p.id,
                kind: Marker::CUBE,
                action: Marker::ADD,
                pose,
                scale: Vector3::new(p.size_m[0], p.size_m[1], p.size_m[2]),
                color: ColorRgba { r: 1.0, g: 0.35, b: 0.1, a: 0.5 },
                ..Marker::default()
            });
            let mut label_pose = pose;
            label_pose.position.z += p.size_m[2] / 2.0 + 0.2;
            markers.push(Marker {
                header: header.clone(),
                ns: "people_labels".into(),
                id: p.id,
                kind: Marker::TEXT_VIEW_FACING,
                action: Marker::ADD,
                pose: label_pose,
                scale: Vector3::new(0.0, 0.0, 0.25),
                color: ColorRgba { r: 1.0, g: 1.0, b: 1.0, a: 1.0 },
                text: format!("person {} {} ({:.2})", p.id, posture(p.pose), p.score),
                ..Marker::default()
            });
        }
        Ok(MarkerArray { markers })
    }

    /// People in the map frame as `vision_msgs/Detection3DArray`: each box, its track id, and two
    /// hypotheses with the detector's score: class `person`, and the posture (`upright`, `low`:
    /// sitting or crouching, `lying`), for which vision_msgs has no field of its own.
    pub fn people(&self, stamp: Stamp, people: &[PersonBox]) -> Result<Detection3DArray, PipelineError> {
        let header = self.header(stamp, &self.frames.map)?;
        let detections = people
            .iter()
            .map(|p| {
                let pose = box_pose(p);
                Detection3D {
                    header: header.clone(),
                    results: vec![
                        ObjectHypothesisWithPose::scored("person", f64::from(p.score), pose),
                        ObjectHypothesisWithPose::scored(posture(p.pose), f64::from(p.score), pose),
                    ],
                    bbox: BoundingBox3D { center: pose, size: Vector3::new(p.size_m[0], p.size_m[1], p.size_m[2]) },
                    id: p.id.to_string(),
                }
            })
            .collect();
        Ok(Detection3DArray { header, detections })
    }

    /// A rendered frame, PNG-encoded, in the viewer's frame.
    pub fn png_image(&self, stamp: Stamp, png: &[u8]) -> Result<CompressedImage, PipelineError> {
        super::cdr::check_len(CompressedImage::TYPE_NAME, "data", png.len())?;
        Ok(CompressedImage { header: self.header(stamp, &self.frames.fpv)?, format: "png".into(), data: png.to_vec() })
    }
}

/// A posture as the markers and the detections name it.
pub fn posture(pose: PersonPose) -> &'static str {
    match pose {
        PersonPose::Upright => "upright",
        PersonPose::Low => "low",
        PersonPose::Lying => "lying",
    }
}

/// A box's centre and yaw as a pose.
fn box_pose(p: &PersonBox) -> Pose {
    let (s, c) = (p.yaw_rad / 2.0).sin_cos();
    Pose {
        position: Vector3::new(p.center_m[0], p.center_m[1], p.center_m[2]),
        orientation: Quaternion { x: 0.0, y: 0.0, z: s, w: c },
    }
}
