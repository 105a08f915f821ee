//! Gravity from the accelerometer, less what the wheels say the base did: the filter's tilt
//! measured once per scan on a wheeled robot.
//!
//! The IMU's mean specific force over a scan is `f = Rᵀ (a - g) + b_a`, with `a` the IMU's world
//! acceleration, `g` the state's gravity and `b_a` its bias. On a wheeled base the wheels give
//! `a` in the body: the change of their twist over the scan plus the turn's `ω × v`. What is left
//! is gravity seen from the IMU, which fixes roll and pitch (never yaw). Without it the tilt is
//! held only by the map, and sparse scans (a wall's edge after a turn in place) tip the pose
//! a degree or two that the map then keeps (docs/lio.md, "The robot's tilt").
//!
//! Measurement `h(x) = a_imu - Rᵀ g + b_a` against `z = f̄`; with the right perturbation
//! `R = R̂ exp(δθ)`, `∂(-Rᵀg)/∂δθ = -[Rᵀg]×`, `∂h/∂b_a = I`, `∂h/∂g = -Rᵀ`. The lever arm from the
//! base's centre to the IMU (`ω × (ω × p)`, 0.04 m/s² at 1 rad/s and 4 cm) is left out.

use super::kalman::{update3, Rows3};
use super::so3::skew;
use super::state::{Cov, State, BA, GRAV, ROT};
use super::wheel::WheelSample;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// The accelerometer's samples since the last scan and the wheels' twist at the last scan: what
/// one level measurement needs.
#[derive(Clone, Debug, Default)]
pub struct LevelWindow {
    acc_sum_m_s2: Vector3<f64>,
    acc_n: u32,
    last_twist: Option<WheelSample>,
}

impl LevelWindow {
    /// One IMU sample propagated.
    pub fn push_acc(&mut self, acc_m_s2: &Vector3<f64>) {
        self.acc_sum_m_s2 += acc_m_s2;
        self.acc_n += 1;
    }

    /// The accelerometer's mean since the last call and the base's acceleration from the last
    /// call's twist to `twist`; both windows start again here. None without samples or twists.
    pub fn take(&mut self, twist: Option<WheelSample>) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let (sum, n) = (std::mem::take(&mut self.acc_sum_m_s2), std::mem::take(&mut self.acc_n));
        let prev = std::mem::replace(&mut self.last_twist, twist)?;
        let acc_base = base_acceleration(&prev, &twist?)?;
        (n > 0).then(|| (sum / f64::from(n), acc_base))
    }
}

/// The base's acceleration in its own frame between two wheel twists (`prev` before `now`):
/// the change of its velocity plus the turn's `ω × v`; None when they are not 1 ms to 1 s apart.
pub fn base_acceleration(prev: &WheelSample, now: &WheelSample) -> Option<Vector3<f64>> {
    let dt_s = now.t_ns.checked_sub(prev.t_ns)? as f64 * 1e-9;
    if !(1e-3..=1.0).contains(&dt_s) {
        return None;
    }
    let v = Vector3::new(now.vx_m_s, now.vy_m_s, 0.0);
    let dv = v - Vector3::new(prev.vx_m_s, prev.vy_m_s, 0.0);
    let omega = Vector3::new(0.0, 0.0, 0.5 * (now.wz_rad_s + prev.wz_rad_s));
    Some(dv / dt_s + omega.cross(&v))
}

/// One Kalman update of the tilt from the accelerometer's mean over a scan (`mean_acc_m_s2`,
/// IMU frame) and the base's acceleration (`acc_base_m_s2`, base frame, mounted by
/// `rot_imu_base`); noise `sigma_m_s2` per axis. Returns false (nothing changed) when the
/// innovation's squared Mahalanobis length passes `gate_chi2` (a bump, a wheel slipping) or the
/// innovation covariance is singular.
pub fn level_update(
    state: &mut State,
    cov: &mut Cov,
    mean_acc_m_s2: &Vector3<f64>,
    acc_base_m_s2: &Vector3<f64>,
    rot_imu_base: &Rotation3<f64>,
    sigma_m_s2: f64,
    gate_chi2: f64,
) -> bool {
    let rot_t = state.rot.inverse();
    let g_imu = rot_t * state.gravity;
    let predicted_f = rot_imu_base * acc_base_m_s2 - g_imu + state.bias_acc;
    let innovation = mean_acc_m_s2 - predicted_f;
    let mut h = Rows3::zeros();
    h.fixed_view_mut::<3, 3>(0, ROT).copy_from(&(-skew(&g_imu)));
    h.fixed_view_mut::<3, 3>(0, BA).copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, GRAV).copy_from(&(-rot_t.matrix()));
    let r = Matrix3::identity() * (sigma_m_s2 * sigma_m_s2);
    update3(state, cov, &h, &innovation, &r, gate_chi2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn twist(t_ns: u64, vx_m_s: f64, vy_m_s: f64, wz_rad_s: f64) -> WheelSample {
        WheelSample { t_ns, clock: starc_time::Clock::Ptp, vx_m_s, vy_m_s, wz_rad_s }
    }

    #[test]
    fn the_base_accelerates_by_its_change_of_speed_and_its_turn() {
        let a = base_acceleration(&twist(0, 0.0, 0.0, 0.0), &twist(100_000_000, 0.1, 0.0, 0.0));
        assert!(a.is_some_and(|a| (a - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-9), "{a:?}");
        // Driving at 0.5 m/s while turning left at 1 rad/s: 0.5 m/s² towards the turn's centre.
        let a = base_acceleration(&twist(0, 0.5, 0.0, 1.0), &twist(100_000_000, 0.5, 0.0, 1.0));
        assert!(a.is_some_and(|a| (a - Vector3::new(0.0, 0.5, 0.0)).norm() < 1e-9), "{a:?}");
        assert!(base_acceleration(&twist(5, 0.0, 0.0, 0.0), &twist(5, 1.0, 0.0, 0.0)).is_none());
        assert!(base_acceleration(&twist(9, 0.0, 0.0, 0.0), &twist(5, 1.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn a_tilted_estimate_is_levelled_and_yaw_is_left_alone() {
        // The base stands level and still; the filter thinks it is rolled 2 deg and turned 30 deg.
        let truth = Rotation3::from_euler_angles(0.0, 0.0, 0.5);
        let mut s =
            State { rot: truth * Rotation3::from_euler_angles(2f64.to_radians(), 0.0, 0.0), ..State::at_rest() };
        let mut cov = Cov::identity() * 1e-6;
        for i in ROT..ROT + 3 {
            cov[(i, i)] = 1e-3;
        }
        let f = -(truth.inverse() * s.gravity);
        let level = Rotation3::identity();
        for _ in 0..20 {
            assert!(level_update(&mut s, &mut cov, &f, &Vector3::zeros(), &level, 0.05, 1e9));
        }
        let (roll, pitch, yaw) = s.rot.euler_angles();
        assert!(roll.abs().to_degrees() < 0.05 && pitch.abs().to_degrees() < 0.05, "{roll} {pitch}");
        assert!((yaw - 0.5).abs() < 1e-6, "yaw moved: {yaw}");
    }

    #[test]
    fn a_bump_fails_the_gate() {
        let mut s = State::at_rest();
        let mut cov = Cov::identity() * 1e-6;
        let before = s.clone();
        let jolt = Vector3::new(3.0, 0.0, 9.81);
        assert!(!level_update(&mut s, &mut cov, &jolt, &Vector3::zeros(), &Rotation3::identity(), 0.05, 16.0));
        assert_eq!(s, before);
    }
}
