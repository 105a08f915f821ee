//! A base that stands: its wheels say its centre is not moving (it may turn in place), yet a
//! scan that sees its surroundings weakly along one direction (a corridor, a turn through new
//! geometry) can slide the position a few millimetres a scan, all one way, by centimetres over
//! a few seconds. The wheels' velocity cannot stop that: a scan moves the position, not the
//! velocity. So while the base stands, its centre is held where it stood at the first standing
//! scan, with `hold_sigma_m` per axis: the scans still move it where they pin it down firmly
//! (the hold is one metre-scale measurement beside hundreds of matches), not along their weak
//! directions.

use super::kalman::{update3, Rows3};
use super::so3::skew;
use super::state::{Cov, State, POS, ROT};
use super::wheel::{WheelFusion, WheelSample};
use nalgebra::{Matrix3, Vector3};

/// Whether the wheels' twist says the base's centre stands (turning in place allowed).
pub fn stands(twist: &WheelSample, cfg: &WheelFusion) -> bool {
    cfg.hold_sigma_m > 0.0 && twist.vx_m_s.hypot(twist.vy_m_s) <= cfg.hold_max_speed_m_s
}

/// The base's centre in the world.
pub fn base_position(state: &State, cfg: &WheelFusion) -> Vector3<f64> {
    state.pos + state.rot * cfg.pos_imu_base
}

/// One Kalman update of `state`/`cov` holding the base's centre at `anchor` (world), through
/// the wheels' chi-square gate. Returns false (nothing changed) when gated.
pub fn hold_update(state: &mut State, cov: &mut Cov, anchor: &Vector3<f64>, cfg: &WheelFusion) -> bool {
    let innovation = anchor - base_position(state, cfg);
    let mut h = Rows3::zeros();
    h.fixed_view_mut::<3, 3>(0, POS).copy_from(&Matrix3::identity());
    // R exp(δθ) p ≈ R p - R [p]× δθ (the attitude error is a right perturbation).
    h.fixed_view_mut::<3, 3>(0, ROT).copy_from(&(-(state.rot.matrix() * skew(&cfg.pos_imu_base))));
    let r = Matrix3::identity() * (cfg.hold_sigma_m * cfg.hold_sigma_m);
    update3(state, cov, &h, &innovation, &r, cfg.gate_chi2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn state_at(pos: Vector3<f64>, yaw_rad: f64) -> State {
        State { rot: Rotation3::from_euler_angles(0.0, 0.0, yaw_rad), pos, ..State::at_rest() }
    }

    fn twist(vx_m_s: f64, wz_rad_s: f64) -> WheelSample {
        WheelSample { t_ns: 0, clock: starc_time::Clock::Ptp, vx_m_s, vy_m_s: 0.0, wz_rad_s }
    }

    #[test]
    fn a_base_turning_in_place_stands_and_one_driving_does_not() {
        let cfg = WheelFusion { hold_sigma_m: 0.01, ..WheelFusion::default() };
        assert!(stands(&twist(0.0, 0.8), &cfg));
        assert!(!stands(&twist(0.2, 0.0), &cfg));
        assert!(!stands(&twist(0.0, 0.0), &WheelFusion { hold_sigma_m: 0.0, ..cfg }), "off");
    }

    #[test]
    fn the_hold_pulls_a_slid_position_back_to_where_the_base_stood() {
        // The base's centre 0.1 m ahead of the IMU; the filter has slid 3 cm along x since.
        let cfg =
            WheelFusion { hold_sigma_m: 0.01, pos_imu_base: Vector3::new(0.1, 0.0, 0.0), ..WheelFusion::default() };
        let anchor = base_position(&state_at(Vector3::zeros(), 0.0), &cfg);
        let mut s = state_at(Vector3::new(0.03, 0.0, 0.0), 0.0);
        let mut cov = Cov::identity() * 1e-3;
        assert!(hold_update(&mut s, &mut cov, &anchor, &cfg));
        assert!(s.pos.x.abs() < 0.005, "{:?}", s.pos);
        // Turned in place by 90 deg about the base's centre: the IMU has moved, the centre not,
        // and the hold leaves it there.
        let turned = Rotation3::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let pos = anchor - turned * cfg.pos_imu_base;
        let mut t = state_at(pos, std::f64::consts::FRAC_PI_2);
        let before = t.pos;
        assert!(hold_update(&mut t, &mut cov, &anchor, &cfg));
        assert!((t.pos - before).norm() < 1e-9, "{:?} -> {:?}", before, t.pos);
    }
}
