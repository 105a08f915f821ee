//! The PI servo that would steer a clock, and the frequency estimate of the measure-only slave.
//!
//! Sign convention (ptp4l's): offset = local - master; `freq_ppb` > 0 means the local clock runs
//! fast by that much, so the correction to apply is `-freq_ppb`.

use crate::config::ServoConfig;
use std::collections::VecDeque;

/// ptp4l's servo states, printed as s0/s1/s2.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ServoState {
    /// s0: not enough samples yet.
    Unlocked,
    /// s1: the offset is past the step threshold (a steering servo steps the clock here).
    Jump,
    /// s2: tracking.
    Locked,
}

impl ServoState {
    pub fn code(self) -> u8 {
        match self {
            Self::Unlocked => 0,
            Self::Jump => 1,
            Self::Locked => 2,
        }
    }
}

/// What a steering servo asks for after a sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoOutput {
    pub state: ServoState,
    /// Estimated frequency error of the local clock (ppb, positive: local fast).
    pub freq_ppb: f64,
    /// Step the local clock by this much (ns) before applying the frequency (s1 only).
    pub step_ns: Option<i64>,
}

/// A proportional-integral servo in the manner of ptp4l's `pi` servo: two samples estimate the
/// frequency, then every sample adds kp*offset (proportional) and ki*offset*interval (integral).
#[derive(Clone, Debug)]
pub struct PiServo {
    cfg: ServoConfig,
    first: Option<(i64, i128)>,
    drift_ppb: f64,
    locked: bool,
}

impl PiServo {
    pub fn new(cfg: ServoConfig) -> Self {
        Self { cfg, first: None, drift_ppb: 0.0, locked: false }
    }

    pub fn reset(&mut self) {
        self.first = None;
        self.drift_ppb = 0.0;
        self.locked = false;
    }

    /// One offset sample (ns) taken at local time `local_ns`; `interval_s` is the sync interval.
    pub fn sample(&mut self, offset_ns: i64, local_ns: i128, interval_s: f64) -> ServoOutput {
        let max = self.cfg.max_freq_ppb;
        if !self.locked {
            let Some((first_offset, first_local)) = self.first else {
                self.first = Some((offset_ns, local_ns));
                return ServoOutput { state: ServoState::Unlocked, freq_ppb: self.drift_ppb, step_ns: None };
            };
            let dt = (local_ns - first_local) as f64;
            if dt <= 0.0 {
                self.first = Some((offset_ns, local_ns));
                return ServoOutput { state: ServoState::Unlocked, freq_ppb: self.drift_ppb, step_ns: None };
            }
            self.drift_ppb = (self.drift_ppb + (offset_ns - first_offset) as f64 / dt * 1e9).clamp(-max, max);
            self.locked = true;
            if offset_ns.abs() > self.cfg.step_threshold_ns {
                return ServoOutput { state: ServoState::Jump, freq_ppb: self.drift_ppb, step_ns: Some(-offset_ns) };
            }
            return ServoOutput { state: ServoState::Locked, freq_ppb: self.drift_ppb, step_ns: None };
        }
        let ki_term = self.cfg.ki * offset_ns as f64 * interval_s;
        let freq = (self.cfg.kp * offset_ns as f64 + self.drift_ppb + ki_term).clamp(-max, max);
        self.drift_ppb = (self.drift_ppb + ki_term).clamp(-max, max);
        ServoOutput { state: ServoState::Locked, freq_ppb: freq, step_ns: None }
    }
}

/// The measure-only slave's view of frequency: the least-squares slope of the raw offset over
/// local time across the last `window` samples, in ppb. Nothing is steered, so the slope is the
/// local clock's frequency error against the master.
#[derive(Clone, Debug)]
pub struct FreqEstimator {
    window: usize,
    samples: VecDeque<(i128, i64)>,
}

impl FreqEstimator {
    pub fn new(window: usize) -> Self {
        Self { window: window.max(2), samples: VecDeque::new() }
    }

    pub fn reset(&mut self) {
        self.samples.clear();
    }

    pub fn push(&mut self, local_ns: i128, offset_ns: i64) {
        if self.samples.len() == self.window {
            self.samples.pop_front();
        }
        self.samples.push_back((local_ns, offset_ns));
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// ppb, once two samples at different times exist.
    pub fn freq_ppb(&self) -> Option<f64> {
        let (t0, y0) = *self.samples.front()?;
        let n = self.samples.len() as f64;
        if n < 2.0 {
            return None;
        }
        let pts = self.samples.iter().map(|&(t, y)| ((t - t0) as f64 * 1e-9, (y - y0) as f64));
        let (sx, sy) = pts.clone().fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let (mx, my) = (sx / n, sy / n);
        let (sxx, sxy) = pts.fold((0.0, 0.0), |(a, b), (x, y)| (a + (x - mx) * (x - mx), b + (x - mx) * (y - my)));
        if sxx <= 0.0 {
            return None;
        }
        Some(sxy / sxx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closes the loop around a simulated clock that runs 50 ppm fast and starts 300 us ahead,
    /// sampled at 8 Hz with +-200 ns of timestamp noise: the servo must step once, then hold
    /// the offset under 1 us and find the 50 ppm.
    #[test]
    fn pi_servo_locks_a_simulated_clock() {
        let mut servo = PiServo::new(ServoConfig::default());
        let interval = 0.125;
        let true_error_ppb = 50_000.0;
        let (mut offset, mut correction_ppb) = (300_000.0f64, 0.0f64);
        let mut steps = 0;
        let mut worst_late = 0.0f64;
        let mut noise = 12345u64;
        for k in 0..800 {
            noise = noise.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let jitter = ((noise >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 400.0;
            let out = servo.sample((offset + jitter) as i64, k as i128 * 125_000_000, interval);
            if let Some(step) = out.step_ns {
                offset += step as f64;
                steps += 1;
            }
            correction_ppb = -out.freq_ppb;
            offset += (true_error_ppb + correction_ppb) * interval;
            if k > 400 {
                worst_late = worst_late.max(offset.abs());
            }
        }
        println!("PI servo: steps {steps}, |offset| after 50 s <= {worst_late:.0} ns, freq {:.0} ppb", -correction_ppb);
        assert_eq!(steps, 1);
        assert!(worst_late < 1000.0, "{worst_late}");
        assert!((-correction_ppb - true_error_ppb).abs() < 100.0, "{correction_ppb}");
    }

    #[test]
    fn freq_estimator_finds_a_drift() {
        let mut f = FreqEstimator::new(16);
        assert_eq!(f.freq_ppb(), None);
        for k in 0..20i64 {
            // 25 ppm fast: 25 us more offset per second.
            f.push(k as i128 * 1_000_000_000 + 1_700_000_000_000_000_000, 1000 + 25_000 * k);
        }
        let ppb = f.freq_ppb().unwrap_or(f64::NAN);
        assert!((ppb - 25_000.0).abs() < 1e-6, "{ppb}");
        assert_eq!(f.len(), 16);
    }
}
