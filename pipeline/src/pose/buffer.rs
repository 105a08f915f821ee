//! A bounded buffer of timed poses, interpolated on SE(3) at any time inside its span.

use crate::PipelineError;
use nalgebra::{Isometry3, UnitQuaternion};
use std::collections::VecDeque;

/// Timed poses in increasing time order (ns, one clock), at most `capacity` (the oldest go).
#[derive(Clone, Debug)]
pub struct PoseBuffer {
    poses: VecDeque<(u64, Isometry3<f64>)>,
    capacity: usize,
}

impl PoseBuffer {
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(2);
        Self { poses: VecDeque::with_capacity(capacity), capacity }
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// First and last time held.
    pub fn span_ns(&self) -> Option<(u64, u64)> {
        Some((self.poses.front()?.0, self.poses.back()?.0))
    }

    pub fn latest(&self) -> Option<(u64, Isometry3<f64>)> {
        self.poses.back().copied()
    }

    /// Appends a pose; times must increase strictly and the pose must be finite.
    pub fn push(&mut self, t_ns: u64, pose: Isometry3<f64>) -> Result<(), PipelineError> {
        let finite =
            pose.translation.vector.iter().all(|v| v.is_finite()) && pose.rotation.coords.iter().all(|v| v.is_finite());
        if !finite {
            return Err(PipelineError::BadPose { t_ns, reason: "not finite".into() });
        }
        // Rotations from a filter's state can drift off unit length (a quaternion built from a
        // not-quite-orthonormal matrix); the composition `applied · now · step · now⁻¹` of the
        // bounded correction then turns that error into metres per frame at a rig far from the
        // odometry origin. Renormalised here, once, for every consumer.
        let norm = pose.rotation.quaternion().norm();
        if !(norm > 0.5 && norm < 2.0) {
            return Err(PipelineError::BadPose { t_ns, reason: format!("rotation quaternion of norm {norm}") });
        }
        let pose = Isometry3::from_parts(pose.translation, UnitQuaternion::new_normalize(*pose.rotation.quaternion()));
        if let Some(&(last, _)) = self.poses.back() {
            if t_ns <= last {
                return Err(PipelineError::BadPose { t_ns, reason: format!("not after the last pose ({last} ns)") });
            }
        }
        if self.poses.len() == self.capacity {
            self.poses.pop_front();
        }
        self.poses.push_back((t_ns, pose));
        Ok(())
    }

    /// The pose at `t_ns`: slerp of the rotation and lerp of the translation between the two
    /// poses around it (exact at a stored time); an error outside the buffer's span.
    pub fn at(&self, t_ns: u64) -> Result<Isometry3<f64>, PipelineError> {
        let out = || {
            let (first_ns, last_ns) = self.span_ns().unwrap_or((0, 0));
            PipelineError::PoseOutOfRange { t_ns, first_ns, last_ns, len: self.poses.len() }
        };
        let (first, last) = self.span_ns().ok_or_else(out)?;
        if t_ns < first || t_ns > last {
            return Err(out());
        }
        // First pose at or after t (exists: t <= last).
        let i = self.poses.partition_point(|(s, _)| *s < t_ns);
        let (tb, b) = *self.poses.get(i).ok_or_else(out)?;
        if tb == t_ns || i == 0 {
            return Ok(b);
        }
        let (ta, a) = *self.poses.get(i - 1).ok_or_else(out)?;
        let f = (t_ns - ta) as f64 / (tb - ta) as f64;
        Ok(interpolate(&a, &b, f))
    }
}

/// `a` at f = 0, `b` at f = 1: slerp on the rotation (the shorter way), lerp on the translation.
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, f: f64) -> Isometry3<f64> {
    let translation = a.translation.vector.lerp(&b.translation.vector, f);
    // slerp refuses (None) only for nearly opposite rotations, which 200 Hz poses never are;
    // fall back to the nearer end rather than fail.
    let rotation = a.rotation.try_slerp(&b.rotation, f, 1e-9).unwrap_or(if f < 0.5 { a.rotation } else { b.rotation });
    Isometry3::from_parts(translation.into(), rotation)
}
