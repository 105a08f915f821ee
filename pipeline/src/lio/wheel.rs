//! The base's wheel odometry as a measurement of the filter: the body's velocity in its own
//! frame, which a wheeled robot knows in a bare corridor or past a doorway, where the scan alone
//! leaves a direction unconstrained. FAST-LIO2 has no such input.
//!
//! Measurement, for the base frame `b` mounted in the IMU frame `i` at `(R_ib, p_ib)`:
//! `h(x) = R_ibᵀ (Rᵀ v + ω × p_ib)` with `R` the IMU's attitude, `v` its world velocity and
//! `ω` the bias-corrected gyro rate; measured `z = (vx, vy, 0)`: the wheels give the planar
//! twist and a ground robot does not move along its own z (a pseudo-measurement). The attitude
//! error is a right perturbation (`R = R̂ exp(δθ)`), so `∂(Rᵀv)/∂δθ = [Rᵀv]×`.
//!
//! Slip and a wheel off the ground make the wheels lie: each axis is Huber-weighted by its
//! normalised innovation, and a sample whose whole innovation fails a chi-square gate is not
//! used at all (counted).

use super::kalman::{update3, Rows3};
use super::so3::skew;
use super::state::{Cov, State, BG, ROT, VEL};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// The base's planar twist at one time, on the LiDAR's clock (x forward, y left, z up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WheelSample {
    pub t_ns: u64,
    pub clock: starc_time::Clock,
    pub vx_m_s: f64,
    pub vy_m_s: f64,
    pub wz_rad_s: f64,
}

/// How wheel velocities enter the filter.
#[derive(Clone, Debug, PartialEq)]
pub struct WheelFusion {
    /// The base frame in the IMU frame.
    pub rot_imu_base: Rotation3<f64>,
    pub pos_imu_base: Vector3<f64>,
    /// Planar velocity noise: `sigma_m_s + sigma_rel * |v|` (slip grows with speed).
    pub sigma_m_s: f64,
    pub sigma_rel: f64,
    /// Noise of the "no vertical velocity" pseudo-measurement.
    pub sigma_vz_m_s: f64,
    /// Samples over this long before a scan's end are averaged into its measurement.
    pub window_ns: u64,
    /// Huber threshold on each axis's normalised innovation.
    pub huber_k: f64,
    /// A measurement whose squared Mahalanobis innovation exceeds this is not used.
    pub gate_chi2: f64,
    /// Noise (1 sigma, per axis) of the tilt measured by the accelerometer less the wheels'
    /// acceleration, once per scan ([`super::level`]); 0: not measured. 0.1 m/s² (about 0.6 deg
    /// per scan) chosen on development buildings (docs/lio.md, "The robot's tilt").
    pub level_sigma_m_s2: f64,
    /// While the wheels say the base's centre stands (planar speed at most
    /// `hold_max_speed_m_s`; turning in place allowed), the centre is held where it stood with
    /// this noise per axis ([`super::stand`]); 0: not held. 0.01 m chosen on development
    /// buildings (docs/lio.md, "A standing base holds its place").
    pub hold_sigma_m: f64,
    pub hold_max_speed_m_s: f64,
}

impl Default for WheelFusion {
    fn default() -> Self {
        Self {
            rot_imu_base: Rotation3::identity(),
            pos_imu_base: Vector3::zeros(),
            sigma_m_s: 0.01,
            sigma_rel: 0.03,
            sigma_vz_m_s: 0.02,
            window_ns: 30_000_000,
            huber_k: 2.0,
            gate_chi2: 30.0,
            level_sigma_m_s2: 0.1,
            hold_sigma_m: 0.01,
            hold_max_speed_m_s: 0.01,
        }
    }
}

/// What became of one wheel measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WheelUse {
    /// No wheel sample in the window (no base, or its feedback stopped).
    None,
    Applied,
    /// Its innovation failed the gate: slip, a wheel off the ground, or a filter gone wrong.
    Gated,
}

impl WheelUse {
    pub fn name(self) -> &'static str {
        match self {
            WheelUse::None => "none",
            WheelUse::Applied => "applied",
            WheelUse::Gated => "gated",
        }
    }
}

/// The mean twist of the samples in `(end_ns - window_ns, end_ns]`.
pub fn mean_twist(samples: impl Iterator<Item = WheelSample>, end_ns: u64, window_ns: u64) -> Option<WheelSample> {
    let from = end_ns.saturating_sub(window_ns);
    let (mut sum, mut n, mut clock) = (Vector3::zeros(), 0u32, starc_time::Clock::Ptp);
    for s in samples.filter(|s| s.t_ns > from && s.t_ns <= end_ns) {
        clock = s.clock;
        sum += Vector3::new(s.vx_m_s, s.vy_m_s, s.wz_rad_s);
        n += 1;
    }
    (n > 0).then(|| {
        let m = sum / f64::from(n);
        WheelSample { t_ns: end_ns, clock, vx_m_s: m.x, vy_m_s: m.y, wz_rad_s: m.z }
    })
}

/// One robust Kalman update of `state`/`cov` with the wheels' twist; `gyro_rad_s` is the IMU's
/// rate (bias not yet removed).
pub fn wheel_update(
    state: &mut State,
    cov: &mut Cov,
    gyro_rad_s: &Vector3<f64>,
    twist: &WheelSample,
    cfg: &WheelFusion,
) -> WheelUse {
    let omega = gyro_rad_s - state.bias_gyro;
    let rot_t = state.rot.inverse();
    let base_from_imu = cfg.rot_imu_base.inverse();
    let v_imu = rot_t * state.vel;
    let z = Vector3::new(twist.vx_m_s, twist.vy_m_s, 0.0);
    let innovation = z - base_from_imu * (v_imu + omega.cross(&cfg.pos_imu_base));
    let mut h = Rows3::zeros();
    h.fixed_view_mut::<3, 3>(0, ROT).copy_from(&(base_from_imu.matrix() * skew(&v_imu)));
    h.fixed_view_mut::<3, 3>(0, VEL).copy_from((base_from_imu * rot_t).matrix());
    h.fixed_view_mut::<3, 3>(0, BG).copy_from(&(base_from_imu.matrix() * skew(&cfg.pos_imu_base)));
    let planar = cfg.sigma_m_s + cfg.sigma_rel * z.xy().norm();
    let mut noise = Vector3::new(planar * planar, planar * planar, cfg.sigma_vz_m_s * cfg.sigma_vz_m_s);
    let predicted = h * *cov * h.transpose();
    for i in 0..3 {
        let e = innovation[i].abs() / (predicted[(i, i)] + noise[i]).sqrt();
        if e > cfg.huber_k {
            noise[i] *= e / cfg.huber_k;
        }
    }
    if update3(state, cov, &h, &innovation, &Matrix3::from_diagonal(&noise), cfg.gate_chi2) {
        WheelUse::Applied
    } else {
        WheelUse::Gated
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state_moving(vel: Vector3<f64>, yaw_rad: f64) -> State {
        State {
            rot: Rotation3::from_euler_angles(0.0, 0.0, yaw_rad),
            pos: Vector3::zeros(),
            vel,
            bias_gyro: Vector3::zeros(),
            bias_acc: Vector3::zeros(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            rot_imu_lidar: Rotation3::identity(),
            pos_imu_lidar: Vector3::zeros(),
        }
    }

    fn uncertain() -> Cov {
        Cov::identity() * 0.01
    }

    #[test]
    fn the_wheels_pull_the_velocity_towards_theirs() {
        // Facing +y in the world, the filter thinks it stands still; the wheels say 1 m/s ahead.
        let mut s = state_moving(Vector3::zeros(), std::f64::consts::FRAC_PI_2);
        let mut cov = uncertain();
        let twist = WheelSample { t_ns: 0, clock: starc_time::Clock::Ptp, vx_m_s: 1.0, vy_m_s: 0.0, wz_rad_s: 0.0 };
        let cfg = WheelFusion { gate_chi2: 1e9, ..WheelFusion::default() };
        assert_eq!(wheel_update(&mut s, &mut cov, &Vector3::zeros(), &twist, &cfg), WheelUse::Applied);
        assert!(s.vel.y > 0.5 && s.vel.x.abs() < 0.05, "{:?}", s.vel);
        assert!(cov[(VEL + 1, VEL + 1)] < 0.01, "the velocity is better known after");
    }

    #[test]
    fn agreeing_wheels_change_nothing_and_a_lever_arm_counts_the_turn() {
        // Turning at 1 rad/s in place, with the base 0.5 m ahead of the IMU: the base moves 0.5 m/s
        // sideways (left) while the IMU stands still.
        let mut s = state_moving(Vector3::zeros(), 0.0);
        let mut cov = uncertain();
        let cfg = WheelFusion { pos_imu_base: Vector3::new(0.5, 0.0, 0.0), ..WheelFusion::default() };
        let twist = WheelSample { t_ns: 0, clock: starc_time::Clock::Ptp, vx_m_s: 0.0, vy_m_s: 0.5, wz_rad_s: 1.0 };
        let gyro = Vector3::new(0.0, 0.0, 1.0);
        assert_eq!(wheel_update(&mut s, &mut cov, &gyro, &twist, &cfg), WheelUse::Applied);
        assert!(s.vel.norm() < 1e-9, "{:?}", s.vel);
    }

    #[test]
    fn a_slipping_wheel_is_gated() {
        // A confident filter moving at 1 m/s; the wheels claim 4 m/s (spinning on ice).
        let mut s = state_moving(Vector3::new(1.0, 0.0, 0.0), 0.0);
        let mut cov = Cov::identity() * 1e-6;
        let twist = WheelSample { t_ns: 0, clock: starc_time::Clock::Ptp, vx_m_s: 4.0, vy_m_s: 0.0, wz_rad_s: 0.0 };
        let before = s.clone();
        assert_eq!(wheel_update(&mut s, &mut cov, &Vector3::zeros(), &twist, &WheelFusion::default()), WheelUse::Gated);
        assert_eq!(s, before);
    }

    #[test]
    fn the_mean_takes_only_the_window() {
        let at = |t_ns, vx_m_s| WheelSample { t_ns, clock: starc_time::Clock::Ptp, vx_m_s, vy_m_s: 0.0, wz_rad_s: 0.0 };
        let samples = [at(0, 9.0), at(80, 1.0), at(90, 2.0), at(100, 3.0), at(110, 9.0)];
        let m = mean_twist(samples.into_iter(), 100, 30).unwrap_or(at(0, f64::NAN));
        assert!((m.vx_m_s - 2.0).abs() < 1e-12 && m.t_ns == 100);
        assert!(mean_twist(samples.into_iter(), 50, 10).is_none());
    }
}
