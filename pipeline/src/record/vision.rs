//! `vision_msgs` (ROS 2, 4.x: Humble and later): the people the robot detected as 3D boxes, the
//! type ROS 2 perception tools read. Field order follows the `.msg` definitions in
//! [`super::schema`].

use super::cdr::{CdrReader, CdrWriter};
use super::msgs::{read_seq, seq, Cdr, Header, Pose, RosMessage, Vector3};
use crate::PipelineError;

/// `vision_msgs/ObjectHypothesisWithPose`: a class with its score, and the pose with covariance.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectHypothesisWithPose {
    pub class_id: String,
    pub score: f64,
    pub pose: Pose,
    pub covariance: [f64; 36],
}

impl ObjectHypothesisWithPose {
    /// `class_id` with `score` at `pose`, covariance unknown (zero).
    pub fn scored(class_id: &str, score: f64, pose: Pose) -> Self {
        Self { class_id: class_id.into(), score, pose, covariance: [0.0; 36] }
    }
}

impl Cdr for ObjectHypothesisWithPose {
    fn encode(&self, w: &mut CdrWriter) {
        w.string(&self.class_id);
        w.f64(self.score);
        self.pose.encode(w);
        w.f64_array(&self.covariance);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            class_id: r.string("hypothesis.class_id")?,
            score: r.f64("hypothesis.score")?,
            pose: Pose::decode(r)?,
            covariance: r.f64_array("pose.covariance")?,
        })
    }
}

/// `vision_msgs/BoundingBox3D`: centre pose and size (x, y, z extents).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BoundingBox3D {
    pub center: Pose,
    pub size: Vector3,
}

impl Cdr for BoundingBox3D {
    fn encode(&self, w: &mut CdrWriter) {
        self.center.encode(w);
        self.size.encode(w);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { center: Pose::decode(r)?, size: Vector3::decode(r)? })
    }
}

/// `vision_msgs/Detection3D`.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection3D {
    pub header: Header,
    pub results: Vec<ObjectHypothesisWithPose>,
    pub bbox: BoundingBox3D,
    /// Track id, as text.
    pub id: String,
}

impl Cdr for Detection3D {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        seq(w, &self.results);
        self.bbox.encode(w);
        w.string(&self.id);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            header: Header::decode(r)?,
            // a class id (4-byte length), score, pose and covariance: 4 + 8 + 56 + 288
            results: read_seq(r, "results", 356)?,
            bbox: BoundingBox3D::decode(r)?,
            id: r.string("id")?,
        })
    }
}

/// `vision_msgs/Detection3DArray`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Detection3DArray {
    pub header: Header,
    pub detections: Vec<Detection3D>,
}

impl Cdr for Detection3DArray {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        seq(w, &self.detections);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        // a header (8 + 4), an empty result list (4), a box (80) and an id (4)
        Ok(Self { header: Header::decode(r)?, detections: read_seq(r, "detections", 100)? })
    }
}

impl RosMessage for Detection3DArray {
    const TYPE_NAME: &'static str = "vision_msgs/msg/Detection3DArray";
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::record::msgs::{Quaternion, Time};

    #[test]
    fn detections_round_trip_and_every_prefix_is_refused() {
        let header = Header { stamp: Time { sec: 3, nanosec: 4 }, frame_id: "map".into() };
        let pose = Pose { position: Vector3::new(1.0, 2.0, 0.9), orientation: Quaternion::IDENTITY };
        let msg = Detection3DArray {
            header: header.clone(),
            detections: vec![Detection3D {
                header,
                results: vec![ObjectHypothesisWithPose::scored("person", 0.9, pose)],
                bbox: BoundingBox3D { center: pose, size: Vector3::new(0.5, 0.4, 1.8) },
                id: "7".into(),
            }],
        };
        let bytes = msg.to_cdr();
        assert_eq!(Detection3DArray::from_cdr(&bytes).unwrap(), msg);
        for cut in 0..bytes.len() {
            assert!(Detection3DArray::from_cdr(&bytes[..cut]).is_err(), "cut at {cut}");
        }
    }
}
