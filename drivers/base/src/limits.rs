//! Velocity and acceleration limits on the commanded twist, and the wheel-speed limit.

use crate::kinematics::Twist;
use serde::{Deserialize, Serialize};

/// Limits from the config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsConfig {
    pub max_vx_m_s: f64,
    pub max_vy_m_s: f64,
    pub max_wz_rad_s: f64,
    /// Linear acceleration limit (each axis).
    pub max_accel_m_s2: f64,
    pub max_alpha_rad_s2: f64,
    /// No wheel turns faster; the whole wheel vector is scaled down to keep the direction.
    pub max_wheel_rad_s: f64,
}

impl LimitsConfig {
    pub fn validate(&self) -> crate::Result<()> {
        for (field, v) in [
            ("limits.max_vx_m_s", self.max_vx_m_s),
            ("limits.max_vy_m_s", self.max_vy_m_s),
            ("limits.max_wz_rad_s", self.max_wz_rad_s),
            ("limits.max_accel_m_s2", self.max_accel_m_s2),
            ("limits.max_alpha_rad_s2", self.max_alpha_rad_s2),
            ("limits.max_wheel_rad_s", self.max_wheel_rad_s),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(crate::BaseError::config(field, format!("{v} must be finite and >= 0")));
            }
        }
        Ok(())
    }
}

fn step_toward(current: f64, target: f64, max_step: f64) -> f64 {
    current + (target - current).clamp(-max_step, max_step)
}

/// Ramps the setpoint toward the (clamped) target at the acceleration limits.
#[derive(Clone, Debug)]
pub struct TwistLimiter {
    limits: LimitsConfig,
    setpoint: Twist,
}

impl TwistLimiter {
    pub fn new(limits: LimitsConfig) -> Self {
        Self { limits, setpoint: Twist::ZERO }
    }

    /// Clamps a request to the velocity limits (non-finite parts become zero).
    pub fn clamp(&self, t: Twist) -> Twist {
        let c = |v: f64, max: f64| if v.is_finite() { v.clamp(-max, max) } else { 0.0 };
        Twist::new(
            c(t.vx_m_s, self.limits.max_vx_m_s),
            c(t.vy_m_s, self.limits.max_vy_m_s),
            c(t.wz_rad_s, self.limits.max_wz_rad_s),
        )
    }

    /// Moves the setpoint `dt_s` toward `target`; returns the new setpoint.
    pub fn step(&mut self, target: Twist, dt_s: f64) -> Twist {
        let target = self.clamp(target);
        let dt = if dt_s.is_finite() { dt_s.max(0.0) } else { 0.0 };
        let a = self.limits.max_accel_m_s2 * dt;
        let alpha = self.limits.max_alpha_rad_s2 * dt;
        self.setpoint = Twist::new(
            step_toward(self.setpoint.vx_m_s, target.vx_m_s, a),
            step_toward(self.setpoint.vy_m_s, target.vy_m_s, a),
            step_toward(self.setpoint.wz_rad_s, target.wz_rad_s, alpha),
        );
        self.setpoint
    }

    /// Drops the setpoint to zero at once (halt).
    pub fn reset(&mut self) {
        self.setpoint = Twist::ZERO;
    }

    pub fn setpoint(&self) -> Twist {
        self.setpoint
    }

    /// Scales `wheels` down so that none exceeds the wheel-speed limit.
    pub fn limit_wheels(&self, wheels: &mut [f64]) {
        let fastest = wheels.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        if fastest > self.limits.max_wheel_rad_s && fastest > 0.0 {
            let k = self.limits.max_wheel_rad_s / fastest;
            wheels.iter_mut().for_each(|w| *w *= k);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> LimitsConfig {
        LimitsConfig {
            max_vx_m_s: 1.0,
            max_vy_m_s: 0.5,
            max_wz_rad_s: 2.0,
            max_accel_m_s2: 2.0,
            max_alpha_rad_s2: 4.0,
            max_wheel_rad_s: 10.0,
        }
    }

    #[test]
    fn ramps_at_the_acceleration_limit_and_clamps() {
        let mut l = TwistLimiter::new(limits());
        let target = Twist::new(5.0, -5.0, f64::NAN);
        let s = l.step(target, 0.1);
        assert!((s.vx_m_s - 0.2).abs() < 1e-12 && (s.vy_m_s + 0.2).abs() < 1e-12 && s.wz_rad_s == 0.0);
        for _ in 0..20 {
            l.step(target, 0.1);
        }
        assert_eq!(l.setpoint(), Twist::new(1.0, -0.5, 0.0));
        l.reset();
        assert_eq!(l.setpoint(), Twist::ZERO);
    }

    #[test]
    fn wheel_limit_keeps_the_direction() {
        let l = TwistLimiter::new(limits());
        let mut w = vec![20.0, -10.0, 5.0];
        l.limit_wheels(&mut w);
        assert_eq!(w, vec![10.0, -5.0, 2.5]);
        assert!(LimitsConfig { max_vx_m_s: -1.0, ..limits() }.validate().is_err());
    }
}
