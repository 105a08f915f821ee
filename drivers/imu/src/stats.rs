//! Counters of a decoder, and dropped samples found from gaps in time.

use serde::Serialize;
use std::collections::VecDeque;

/// What a stream decoder has seen since it started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DecoderStats {
    /// Bytes pushed in.
    pub bytes: u64,
    /// Frames (WitMotion) or packets (MIP) that passed their checksum.
    pub frames: u64,
    /// Samples handed out (every rate and acceleration finite).
    pub samples: u64,
    /// Samples dropped because a rate or an acceleration was NaN or infinite (a MIP device
    /// sends raw f32s; one NaN would poison the LIO's state).
    pub non_finite: u64,
    /// Samples handed out without their orientation (quaternion or Euler angles), which held a
    /// NaN or an infinity; their rates and accelerations were finite.
    pub non_finite_orientation: u64,
    /// Data without both gyro and accel.
    pub incomplete: u64,
    /// MIP replies (ACK/NACK) decoded.
    pub replies: u64,
    /// Candidate frames whose checksum failed.
    pub bad_checksums: u64,
    /// Runs of skipped bytes between good frames: each is one loss of sync.
    pub resyncs: u64,
    /// Bytes that belonged to no good frame.
    pub skipped_bytes: u64,
    /// Frames with a good checksum but a bad layout (MIP fields, lengths).
    pub malformed: u64,
    /// Good frames or fields of a type we do not decode.
    pub unknown: u64,
}

/// Counts samples missing from a stream from the gaps between their times.
///
/// The period is the mean interval over a sliding window of recent samples, or a fixed nominal
/// period when the rate is known. An interval over 1.5 periods counts
/// `round(interval / period) - 1` missing samples. Exact on a device clock (MIP GPS time, the WitMotion time frame); on
/// host receive times it is only as good as their spacing: a USB adapter that delivers several
/// samples per read makes long intervals that look like losses.
#[derive(Clone, Debug)]
pub struct GapDetector {
    nominal_period_ns: Option<f64>,
    /// Recent sample times and how many samples were missing just before each.
    window: VecDeque<(u64, u64)>,
    dropped: u64,
}

const GAP_WINDOW: usize = 200;
/// Intervals needed before an estimated period is trusted.
const MIN_INTERVALS: usize = 8;

impl Default for GapDetector {
    fn default() -> Self {
        Self::new(None)
    }
}

impl GapDetector {
    /// `rate_hz`: the known output rate, or `None` to estimate it.
    pub fn new(rate_hz: Option<f64>) -> Self {
        let nominal_period_ns = rate_hz.filter(|r| r.is_finite() && *r > 0.0).map(|r| 1e9 / r);
        Self { nominal_period_ns, window: VecDeque::with_capacity(GAP_WINDOW + 1), dropped: 0 }
    }

    /// The period in use, if known yet: the mean interval over the window. Lost samples inflate
    /// it a little (5% lost: 5% longer), which still flags every single loss (2 periods > 1.5);
    /// correcting for them would feed back into the estimate.
    pub fn period_ns(&self) -> Option<f64> {
        if let Some(p) = self.nominal_period_ns {
            return Some(p);
        }
        let n = self.window.len();
        if n <= MIN_INTERVALS {
            return None;
        }
        let (first, last) = (self.window.front()?.0, self.window.back()?.0);
        let span = last.saturating_sub(first) as f64;
        (span > 0.0).then(|| span / (n - 1) as f64)
    }

    /// Observes the next sample's time; returns how many samples went missing before it.
    pub fn observe(&mut self, t_ns: u64) -> u64 {
        let mut missing = 0;
        match (self.period_ns(), self.window.back()) {
            (_, Some(&(prev, _))) if t_ns < prev => {
                // Time went backwards (a device clock reset): start over.
                self.window.clear();
            }
            (Some(period), Some(&(prev, _))) => {
                let interval = t_ns.saturating_sub(prev) as f64;
                if interval > 1.5 * period {
                    missing = ((interval / period).round() as u64).saturating_sub(1);
                }
            }
            _ => {}
        }
        self.window.push_back((t_ns, missing));
        if self.window.len() > GAP_WINDOW {
            self.window.pop_front();
        }
        self.dropped += missing;
        missing
    }

    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_missing_samples_with_a_known_rate() {
        let mut g = GapDetector::new(Some(100.0));
        let times = [0u64, 10, 20, 40, 50, 90, 100].map(|ms| ms * 1_000_000);
        let missing: Vec<u64> = times.iter().map(|&t| g.observe(t)).collect();
        assert_eq!(missing, vec![0, 0, 0, 1, 0, 3, 0]);
        assert_eq!(g.dropped(), 4);
    }

    #[test]
    fn estimates_the_rate_and_ignores_jitter() {
        let mut g = GapDetector::new(None);
        let mut t = 0u64;
        for k in 0..200u64 {
            // 5 ms period with +-1 ms jitter, and one sample in 50 missing.
            let jitter = (k * 7919 % 3) * 1_000_000;
            if k % 50 == 49 {
                t += 5_000_000;
                continue;
            }
            g.observe(t + jitter);
            t += 5_000_000;
        }
        // The last drop (k = 199) has no sample after it to show the gap.
        assert_eq!(g.dropped(), 3);
        assert!(g.period_ns().is_some_and(|p| (p - 5e6).abs() < 0.2e6));
    }
}
