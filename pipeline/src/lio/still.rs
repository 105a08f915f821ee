//! A device that stands still while its LiDAR sees nothing it can match: a responder facing a
//! wall inside the Avia's 1 m blind zone, or a robot parked against one. The IMU alone then
//! integrates its noise and bias twice, and the position runs away by metres within seconds
//! (development office-6: the rig's LIO 9.4 m off by the end of a 10 s stand, APE max).
//! Where the IMU says it has been still, the velocity is held at zero instead (a zero-velocity
//! update, as pedestrian inertial navigation does at each footfall).
//!
//! An IMU cannot tell standing still from gliding at a constant velocity, so the update is used
//! only when the scan cannot correct the state at all (too few matches): nobody walks steadily
//! on into a wall they are within a metre of, a real walker's steps are no glide, and where a
//! scan matches it knows better. (Gating it on the filter's own speed as well was tried: a
//! velocity that had run past the gate was never stopped again, 8.2 m in development flat-5.)

use super::init::spread;
use super::kalman::{update3, Rows3};
use super::propagate::acc_world_jacobian;
use super::state::{Cov, State, VEL};
use super::types::ImuSample;
use nalgebra::{Matrix3, Vector3};
use std::collections::VecDeque;

/// The IMU's last `window_ns`, and whether it was still over all of it.
#[derive(Clone, Debug)]
pub struct StillWindow {
    window_ns: u64,
    max_gyro_std_rad_s: f64,
    max_acc_std_m_s2: f64,
    samples: VecDeque<ImuSample>,
    /// Each sample's acceleration in the world (gravity and bias taken out by the filter's state).
    acc_world: VecDeque<(u64, Vector3<f64>)>,
}

impl StillWindow {
    /// Still means spreads (standard deviations) within these limits, the static start's.
    pub fn new(window_ns: u64, max_gyro_std_rad_s: f64, max_acc_std_m_s2: f64) -> Self {
        Self { window_ns, max_gyro_std_rad_s, max_acc_std_m_s2, samples: VecDeque::new(), acc_world: VecDeque::new() }
    }

    /// Adds one sample (in time order) and forgets those older than the window before it.
    pub fn push(&mut self, s: &ImuSample) {
        self.samples.push_back(*s);
        forget_before(&mut self.samples, s.t_ns.saturating_sub(self.window_ns), |q| q.t_ns);
    }

    /// The world acceleration the filter's state gives for a sample at `t_ns` (for [`Self::quiet`]).
    pub fn push_acc_world(&mut self, t_ns: u64, a: Vector3<f64>) {
        self.acc_world.push_back((t_ns, a));
        forget_before(&mut self.acc_world, t_ns.saturating_sub(self.window_ns), |q| q.0);
    }

    /// Whether the world acceleration over the window stayed under `max_acc_m_s2` (RMS); never
    /// with a limit of 0 or no samples. Its change over the window weighs `change_weight` times
    /// (1: the plain RMS).
    pub fn quiet(&self, max_acc_m_s2: f64, change_weight: f64) -> bool {
        if max_acc_m_s2 <= 0.0 || self.acc_world.is_empty() {
            return false;
        }
        let n = self.acc_world.len() as f64;
        let mean = self.acc_world.iter().map(|(_, a)| a).sum::<Vector3<f64>>() / n;
        let mean_sq = self.acc_world.iter().map(|(_, a)| a.norm_squared()).sum::<f64>() / n;
        let change = (mean_sq - mean.norm_squared()).max(0.0);
        mean.norm_squared() + change_weight * change < max_acc_m_s2 * max_acc_m_s2
    }

    /// Whether the samples span the window up to `t_ns` and their spreads stay within the limits.
    pub fn is_still(&self, t_ns: u64) -> bool {
        let (Some(first), Some(last)) = (self.samples.front(), self.samples.back()) else { return false };
        // Half a window of missing samples at either end is no evidence of anything.
        let covers = last.t_ns.saturating_sub(first.t_ns) >= self.window_ns / 2
            && t_ns.saturating_sub(last.t_ns) <= self.window_ns / 2;
        if !covers || self.samples.len() < 3 {
            return false;
        }
        let s = spread(&self.samples);
        s.gyro_std <= self.max_gyro_std_rad_s && s.acc_std <= self.max_acc_std_m_s2
    }
}

/// Drops the front of `q` (in time order) from before `from_ns`.
fn forget_before<T>(q: &mut VecDeque<T>, from_ns: u64, t_ns: impl Fn(&T) -> u64) {
    while q.front().is_some_and(|x| t_ns(x) < from_ns) {
        q.pop_front();
    }
}

/// The variance (trace of the covariance) of the world acceleration the filter derives from an
/// accelerometer reading `acc_m_s2`: its attitude, accelerometer bias and gravity errors, through
/// the propagation's own Jacobian ([`acc_world_jacobian`]).
pub fn acc_world_var(state: &State, cov: &Cov, acc_m_s2: &Vector3<f64>) -> f64 {
    let j = acc_world_jacobian(&state.rot, &(acc_m_s2 - state.bias_acc));
    (j * cov * j.transpose()).trace()
}

/// One Kalman update of `state`/`cov` with a world velocity of zero, `sigma_m_s` on each axis.
/// Returns false (nothing changed) when the innovation covariance cannot be inverted.
pub fn zero_velocity_update(state: &mut State, cov: &mut Cov, sigma_m_s: f64) -> bool {
    let mut h = Rows3::zeros();
    h.fixed_view_mut::<3, 3>(0, VEL).copy_from(&Matrix3::identity());
    let r = Matrix3::identity() * (sigma_m_s * sigma_m_s);
    update3(state, cov, &h, &-state.vel, &r, f64::INFINITY)
}

#[cfg(test)]
mod tests {
    use super::super::init::InitResult;
    use super::super::start::start_covariance;
    use super::super::state::ROT;
    use super::*;
    use nalgebra::Rotation3;
    use std::f64::consts::PI;

    const MS: u64 = 1_000_000;

    fn sample(t_ns: u64, gyro_z: f64, acc_x: f64) -> ImuSample {
        ImuSample {
            t_ns,
            clock: starc_time::Clock::Ptp,
            gyro_rad_s: Vector3::new(0.0, 0.0, gyro_z),
            acc_m_s2: Vector3::new(acc_x, 0.0, 9.81),
        }
    }

    #[test]
    fn still_only_over_a_whole_quiet_window() {
        let mut w = StillWindow::new(500 * MS, 0.06, 0.2);
        assert!(!w.is_still(0), "nothing seen");
        for k in 0..100u64 {
            // Hand sway: 0.03 rad/s and 0.1 m/s^2 either way.
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            w.push(&sample(k * 5 * MS, 0.03 * sign, 0.1 * sign));
        }
        assert!(w.is_still(500 * MS));
        // The IMU went quiet for a second: not known to be still now.
        assert!(!w.is_still(1500 * MS));
        // A step (walking): not still until it has left the window.
        w.push(&sample(505 * MS, 0.0, 3.0));
        assert!(!w.is_still(505 * MS));
        for k in 102..300u64 {
            w.push(&sample(k * 5 * MS, 0.0, 0.0));
        }
        assert!(w.is_still(299 * 5 * MS));
    }

    /// The first steps of a walk: the IMU's spreads still read as still, the world acceleration
    /// does not.
    #[test]
    fn quiet_only_while_the_world_acceleration_stays_small() {
        let mut w = StillWindow::new(500 * MS, 0.06, 0.2);
        assert!(!w.quiet(0.1, 1.0), "nothing seen");
        for k in 0..100u64 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            w.push_acc_world(k * 5 * MS, Vector3::new(0.05 * sign, 0.0, 0.02));
        }
        assert!(w.quiet(0.1, 1.0));
        assert!(!w.quiet(0.0, 1.0), "a limit of 0 is off");
        // Setting off: 0.3 m/s^2 forward over the last 0.2 s of the window.
        for k in 100..140u64 {
            w.push_acc_world(k * 5 * MS, Vector3::new(0.3, 0.0, 0.0));
        }
        assert!(!w.quiet(0.1, 1.0));
        assert!(w.quiet(0.3, 1.0), "0.19 m/s^2 RMS over the window");
    }

    #[test]
    fn a_steady_acceleration_passes_where_a_ramp_of_the_same_rms_does_not() {
        let (mut steady, mut ramp) = (StillWindow::new(500 * MS, 0.06, 0.2), StillWindow::new(500 * MS, 0.06, 0.2));
        for k in 0..100u64 {
            // A bias leaking into the world: 0.12 m/s^2, steady. Setting off: 0 to 0.21 m/s^2.
            steady.push_acc_world(k * 5 * MS, Vector3::new(0.12, 0.0, 0.0));
            ramp.push_acc_world(k * 5 * MS, Vector3::new(0.21 * k as f64 / 99.0, 0.0, 0.0));
        }
        // Both are about 0.12 m/s^2 RMS: the plain RMS cannot tell them apart.
        assert!(steady.quiet(0.13, 1.0) && ramp.quiet(0.13, 1.0));
        assert!(!steady.quiet(0.11, 1.0) && !ramp.quiet(0.11, 1.0));
        // With the change weighing three times, the ramp is motion; the steady leak is not.
        assert!(steady.quiet(0.13, 3.0));
        assert!(!ramp.quiet(0.13, 3.0));
    }

    #[test]
    fn a_bias_taken_for_gravity_is_sure_at_the_start_and_unsure_after_a_half_turn() {
        let start = InitResult {
            rot_world_imu: Rotation3::identity(),
            gravity_m_s2: 9.81,
            bias_gyro: Vector3::zeros(),
            gyro_std_rad_s: 0.002,
            end_ns: 0,
        };
        let mut cov = start_covariance(&start, 0.05);
        let still = Vector3::new(0.0, 0.0, 9.81);
        // An attitude 0.01 rad unsure about x and y (the start's) leaks g * 0.01 on each.
        let mut attitude = Cov::zeros();
        attitude.fixed_view_mut::<3, 3>(ROT, ROT).copy_from(&cov.fixed_view::<3, 3>(ROT, ROT));
        let tilt_only = acc_world_var(&State::at_rest(), &attitude, &still);
        assert!((tilt_only.sqrt() - 9.81 * 0.01 * 2f64.sqrt()).abs() < 1e-3, "{}", tilt_only.sqrt());
        // With the attitude known exactly:
        cov.fixed_view_mut::<3, 3>(ROT, ROT).fill(0.0);
        let at_start = acc_world_var(&State::at_rest(), &cov, &still);
        // The bias and the gravity's lean are one unknown: where the device looks as it did at the
        // start, they cancel; half a turn later a horizontal bias counts twice.
        let turned = State { rot: Rotation3::from_axis_angle(&Vector3::z_axis(), PI), ..State::at_rest() };
        let after_turn = acc_world_var(&turned, &cov, &still);
        assert!(at_start.sqrt() < 0.01, "{}", at_start.sqrt());
        assert!((after_turn.sqrt() - (2.0 * 4.0 * 0.05f64.powi(2)).sqrt()).abs() < 0.01, "{}", after_turn.sqrt());
    }

    #[test]
    fn the_update_stops_a_drifting_velocity_and_leaves_the_rest() {
        let mut state =
            State { pos: Vector3::new(1.0, 2.0, 0.0), vel: Vector3::new(0.8, -0.3, 0.1), ..State::at_rest() };
        // Only the velocity is uncertain (and uncorrelated with the rest).
        let mut cov = Cov::identity() * 1e-6;
        for i in VEL..VEL + 3 {
            cov[(i, i)] = 1.0;
        }
        assert!(zero_velocity_update(&mut state, &mut cov, 0.02));
        assert!(state.vel.norm() < 0.01, "{:?}", state.vel);
        assert!((state.pos - Vector3::new(1.0, 2.0, 0.0)).norm() < 1e-9);
        assert!(cov[(VEL, VEL)] < 1e-3);
    }
}
