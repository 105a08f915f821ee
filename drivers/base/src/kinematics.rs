//! Wheel kinematics of holonomic bases: 3- and 4-wheel omni and mecanum.
//!
//! The inverse model is a matrix `J` (one row per wheel) from the body twist (vx, vy, wz) to
//! wheel rates in rad/s. Omni wheel i at angle th_i, distance L from the centre, rolling
//! tangentially: `r w_i = -sin(th_i) vx + cos(th_i) vy + L wz`. Mecanum (FL, FR, RL, RR) with
//! k = lx + ly: `r w = (vx -+ vy -+ k wz)` by the usual sign pattern. The forward model is the
//! least-squares inverse `(J^T J)^-1 J^T`, so odometry from four wheels averages out their
//! disagreement.

use crate::error::{BaseError, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};

/// Planar body velocity: x forward, y left, z up (REP 103).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub vx_m_s: f64,
    pub vy_m_s: f64,
    pub wz_rad_s: f64,
}

impl Twist {
    pub const ZERO: Twist = Twist { vx_m_s: 0.0, vy_m_s: 0.0, wz_rad_s: 0.0 };

    pub fn new(vx_m_s: f64, vy_m_s: f64, wz_rad_s: f64) -> Self {
        Self { vx_m_s, vy_m_s, wz_rad_s }
    }

    fn vector(self) -> Vector3<f64> {
        Vector3::new(self.vx_m_s, self.vy_m_s, self.wz_rad_s)
    }

    pub fn is_finite(self) -> bool {
        self.vx_m_s.is_finite() && self.vy_m_s.is_finite() && self.wz_rad_s.is_finite()
    }
}

/// The wheel layout, from the config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, tag = "model", rename_all = "snake_case")]
pub enum KinematicsConfig {
    /// Three omni wheels; angles (from +x, counter-clockwise) default to 90, 210, 330 deg.
    Omni3 {
        wheel_radius_m: f64,
        center_to_wheel_m: f64,
        #[serde(default)]
        wheel_angles_deg: Option<Vec<f64>>,
    },
    /// Four omni wheels; angles default to 45, 135, 225, 315 deg (an X layout).
    Omni4 {
        wheel_radius_m: f64,
        center_to_wheel_m: f64,
        #[serde(default)]
        wheel_angles_deg: Option<Vec<f64>>,
    },
    /// Four mecanum wheels in the order front-left, front-right, rear-left, rear-right;
    /// `half_length_m` (lx) and `half_width_m` (ly) from the centre to the wheel contact.
    Mecanum { wheel_radius_m: f64, half_length_m: f64, half_width_m: f64 },
}

impl KinematicsConfig {
    pub fn wheel_count(&self) -> usize {
        match self {
            Self::Omni3 { .. } => 3,
            Self::Omni4 { .. } | Self::Mecanum { .. } => 4,
        }
    }
}

/// Inverse and forward kinematics of one base.
#[derive(Clone, Debug)]
pub struct Kinematics {
    inverse: DMatrix<f64>,
    forward: DMatrix<f64>,
}

fn positive(field: &'static str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(BaseError::config(field, format!("{v} must be a positive length")))
    }
}

fn omni_rows(r: f64, l: f64, angles_deg: &[f64]) -> Vec<[f64; 3]> {
    angles_deg
        .iter()
        .map(|deg| {
            let th = deg.to_radians();
            [-th.sin() / r, th.cos() / r, l / r]
        })
        .collect()
}

impl Kinematics {
    pub fn new(config: &KinematicsConfig) -> Result<Self> {
        let rows = match config {
            KinematicsConfig::Omni3 { wheel_radius_m, center_to_wheel_m, wheel_angles_deg }
            | KinematicsConfig::Omni4 { wheel_radius_m, center_to_wheel_m, wheel_angles_deg } => {
                let r = positive("kinematics.wheel_radius_m", *wheel_radius_m)?;
                let l = positive("kinematics.center_to_wheel_m", *center_to_wheel_m)?;
                let n = config.wheel_count();
                let default: Vec<f64> = if n == 3 { vec![90.0, 210.0, 330.0] } else { vec![45.0, 135.0, 225.0, 315.0] };
                let angles = wheel_angles_deg.clone().unwrap_or(default);
                if angles.len() != n || angles.iter().any(|a| !a.is_finite()) {
                    return Err(BaseError::config(
                        "kinematics.wheel_angles_deg",
                        format!("need {n} finite angles, got {angles:?}"),
                    ));
                }
                omni_rows(r, l, &angles)
            }
            KinematicsConfig::Mecanum { wheel_radius_m, half_length_m, half_width_m } => {
                let r = positive("kinematics.wheel_radius_m", *wheel_radius_m)?;
                let k = positive("kinematics.half_length_m", *half_length_m)?
                    + positive("kinematics.half_width_m", *half_width_m)?;
                vec![
                    [1.0 / r, -1.0 / r, -k / r],
                    [1.0 / r, 1.0 / r, k / r],
                    [1.0 / r, 1.0 / r, -k / r],
                    [1.0 / r, -1.0 / r, k / r],
                ]
            }
        };
        let n = rows.len();
        let inverse = DMatrix::from_fn(n, 3, |i, j| rows.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0));
        let normal = inverse.transpose() * &inverse;
        let normal_inv = normal.try_inverse().ok_or_else(|| {
            BaseError::config("kinematics", "the wheel layout cannot observe every body velocity (singular)")
        })?;
        let forward = normal_inv * inverse.transpose();
        Ok(Self { inverse, forward })
    }

    pub fn wheel_count(&self) -> usize {
        self.inverse.nrows()
    }

    /// Wheel rates (rad/s) for a body twist.
    pub fn wheel_rates(&self, twist: Twist) -> Vec<f64> {
        (&self.inverse * twist.vector()).iter().copied().collect()
    }

    /// The body twist that best explains measured wheel rates (least squares). `None` when the
    /// slice has the wrong length.
    pub fn body_twist(&self, wheel_rad_s: &[f64]) -> Option<Twist> {
        if wheel_rad_s.len() != self.wheel_count() {
            return None;
        }
        let v = &self.forward * DVector::from_column_slice(wheel_rad_s);
        Some(Twist::new(*v.get(0)?, *v.get(1)?, *v.get(2)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Twist, b: Twist) -> bool {
        (a.vx_m_s - b.vx_m_s).abs() < 1e-9
            && (a.vy_m_s - b.vy_m_s).abs() < 1e-9
            && (a.wz_rad_s - b.wz_rad_s).abs() < 1e-9
    }

    #[test]
    fn omni3_matches_the_formula_and_inverts() -> Result<()> {
        let k = Kinematics::new(&KinematicsConfig::Omni3 {
            wheel_radius_m: 0.05,
            center_to_wheel_m: 0.2,
            wheel_angles_deg: None,
        })?;
        // Pure rotation: every wheel turns at L w / r.
        let w = k.wheel_rates(Twist::new(0.0, 0.0, 1.0));
        assert!(w.iter().all(|x| (x - 4.0).abs() < 1e-12), "{w:?}");
        // Forward x: the wheel at 90 deg rolls backwards at v/r, the others at +v/(2r).
        let w = k.wheel_rates(Twist::new(0.5, 0.0, 0.0));
        assert!((w[0] + 10.0).abs() < 1e-9 && (w[1] - 5.0).abs() < 1e-9 && (w[2] - 5.0).abs() < 1e-9, "{w:?}");
        let t = Twist::new(0.3, -0.2, 0.7);
        assert!(close(k.body_twist(&k.wheel_rates(t)).unwrap_or_default(), t));
        Ok(())
    }

    #[test]
    fn mecanum_matches_the_textbook_and_least_squares_averages() -> Result<()> {
        let k = Kinematics::new(&KinematicsConfig::Mecanum {
            wheel_radius_m: 0.1,
            half_length_m: 0.2,
            half_width_m: 0.15,
        })?;
        let w = k.wheel_rates(Twist::new(1.0, 0.5, 2.0));
        // w_FL = (vx - vy - k w)/r with k = 0.35.
        let expected =
            [(1.0 - 0.5 - 0.7) / 0.1, (1.0 + 0.5 + 0.7) / 0.1, (1.0 + 0.5 - 0.7) / 0.1, (1.0 - 0.5 + 0.7) / 0.1];
        for (a, b) in w.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9, "{w:?}");
        }
        // One wheel slipping by +1 rad/s shifts the estimate by a quarter of its projection.
        let mut slipped = k.wheel_rates(Twist::new(1.0, 0.0, 0.0));
        slipped[0] += 1.0;
        let est = k.body_twist(&slipped).unwrap_or_default();
        assert!((est.vx_m_s - 1.025).abs() < 1e-9, "{est:?}");
        assert!(k.body_twist(&[1.0, 2.0]).is_none());
        Ok(())
    }

    #[test]
    fn omni4_and_bad_layouts() -> Result<()> {
        let k = Kinematics::new(&KinematicsConfig::Omni4 {
            wheel_radius_m: 0.06,
            center_to_wheel_m: 0.25,
            wheel_angles_deg: None,
        })?;
        let t = Twist::new(-0.4, 0.9, -1.1);
        assert!(close(k.body_twist(&k.wheel_rates(t)).unwrap_or_default(), t));
        let collinear = KinematicsConfig::Omni3 {
            wheel_radius_m: 0.05,
            center_to_wheel_m: 0.2,
            wheel_angles_deg: Some(vec![0.0, 0.0, 180.0]),
        };
        assert!(Kinematics::new(&collinear).is_err());
        let negative = KinematicsConfig::Mecanum { wheel_radius_m: -0.1, half_length_m: 0.2, half_width_m: 0.2 };
        assert!(Kinematics::new(&negative).is_err());
        let wrong_count =
            KinematicsConfig::Omni4 { wheel_radius_m: 0.1, center_to_wheel_m: 0.2, wheel_angles_deg: Some(vec![0.0]) };
        assert!(Kinematics::new(&wrong_count).is_err());
        Ok(())
    }
}
