//! Motion compensation: every point moved to the LiDAR frame at the scan's end, by the IMU pose
//! propagated to its own firing time.

use super::propagate::Knot;
use super::state::State;
use super::types::TimedPoint;
use nalgebra::{Rotation3, Vector3};

/// Points fired within this of each other are moved with one pose.
const SHARE_POSE_NS: u64 = 50_000;

/// De-skews `points` with `knots` (sorted by time, covering the scan) into the LiDAR frame of
/// `end` (the state at the scan's end). Points before the first knot use the first knot.
pub fn deskew(points: &[TimedPoint], knots: &[Knot], end: &State, out: &mut Vec<Vector3<f64>>) {
    out.clear();
    let (r_il, t_il) = (end.rot_imu_lidar, end.pos_imu_lidar);
    let end_inv = end.rot.inverse();
    // Points a few tens of microseconds apart share one pose (at 1 rad/s that is 50 urad):
    // one pose per firing block instead of per point.
    let mut cached: Option<(u64, Rotation3<f64>, Vector3<f64>)> = None;
    let r_li = r_il.inverse();
    for p in points {
        let (rot, pos) = match cached {
            Some((t, rot, pos)) if p.t_ns.abs_diff(t) <= SHARE_POSE_NS => (rot, pos),
            _ => {
                let i = knots.partition_point(|k| k.t_ns <= p.t_ns).saturating_sub(1);
                let Some(k) = knots.get(i) else {
                    out.push(p.xyz());
                    continue;
                };
                let dt_s = p.t_ns.saturating_sub(k.t_ns) as f64 * 1e-9;
                let (rot, pos) = k.pose_after(dt_s);
                // Straight to the end frame: IMU(t) -> world -> IMU(end).
                let rel = end_inv * rot;
                let rel_pos = end_inv * (pos - end.pos);
                cached = Some((p.t_ns, rel, rel_pos));
                (rel, rel_pos)
            }
        };
        let imu_end = rot * (r_il * p.xyz() + t_il) + pos;
        out.push(r_li * (imu_end - t_il));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_fired_before_a_forward_move_is_moved_back() {
        let end = State {
            rot: Rotation3::identity(),
            pos: Vector3::new(1.0, 0.0, 0.0),
            vel: Vector3::new(10.0, 0.0, 0.0),
            bias_gyro: Vector3::zeros(),
            bias_acc: Vector3::zeros(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            rot_imu_lidar: Rotation3::identity(),
            pos_imu_lidar: Vector3::new(0.1, 0.0, 0.0),
        };
        let knot = Knot {
            t_ns: 0,
            rot: Rotation3::identity(),
            pos: Vector3::zeros(),
            vel: Vector3::new(10.0, 0.0, 0.0),
            omega: Vector3::zeros(),
            acc_world: Vector3::zeros(),
        };
        let p = TimedPoint { x_m: 5.0, y_m: 0.0, z_m: 0.0, t_ns: 50_000_000 };
        let mut out = Vec::new();
        deskew(&[p], &[knot], &end, &mut out);
        // Fired 0.5 m behind the end pose, so 0.5 m closer in the end frame.
        assert!((out[0] - Vector3::new(4.5, 0.0, 0.0)).norm() < 1e-9, "{:?}", out[0]);
    }
}
