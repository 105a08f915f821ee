//! Faults of a mock serial IMU, deterministic from a seed: garbage bytes on the line, samples
//! dropped whole, checksums corrupted, and silence after some time.
//!
//! TOML (the `[faults]` table of a mock IMU config):
//!
//! ```toml
//! seed = 7
//! garbage = 0.01          # fraction of samples preceded by 1-8 garbage bytes (often sync bytes)
//! drop = 0.01             # fraction of samples never sent (MIP packet or WitMotion cycle)
//! corrupt = 0.005         # fraction of samples with one checksum byte flipped
//! silence_after_s = 10.0  # the device goes quiet (no data, no replies)
//! ```

use crate::error::{HilError, Result};
use crate::rng::SplitMix64;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuFaultConfig {
    /// Seed of the fault PRNG; the mock's seed when absent.
    pub seed: Option<u64>,
    pub garbage: f64,
    pub drop: f64,
    pub corrupt: f64,
    pub silence_after_s: Option<f64>,
}

impl ImuFaultConfig {
    pub fn validate(&self) -> Result<()> {
        for (field, v) in
            [("faults.garbage", self.garbage), ("faults.drop", self.drop), ("faults.corrupt", self.corrupt)]
        {
            if !(0.0..=1.0).contains(&v) {
                return Err(HilError::config(field, format!("{v} is not a fraction in [0, 1]")));
            }
        }
        if let Some(s) = self.silence_after_s {
            if !s.is_finite() || s < 0.0 {
                return Err(HilError::config("faults.silence_after_s", format!("{s} is not a time >= 0")));
            }
        }
        Ok(())
    }

    /// Device time from which the mock is silent.
    pub fn silence_at_ns(&self) -> Option<u64> {
        self.silence_after_s.map(|s| (s * 1e9).round() as u64)
    }
}

/// What the faults did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ImuFaultStats {
    pub garbage_bursts: u64,
    pub garbage_bytes: u64,
    pub dropped: u64,
    pub corrupted: u64,
}

/// What to do with one sample.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SampleFate {
    /// Bytes to send before the sample.
    pub garbage: Vec<u8>,
    pub drop: bool,
    /// Flip this many bits into the checksum byte of frame `corrupt_frame` (WitMotion) or the packet.
    pub corrupt: Option<(usize, u8)>,
}

#[derive(Debug)]
pub struct ImuFaults {
    config: ImuFaultConfig,
    rng: SplitMix64,
    stats: ImuFaultStats,
}

impl ImuFaults {
    pub fn new(config: &ImuFaultConfig, seed: u64) -> Self {
        let seed = config.seed.unwrap_or(seed) ^ 0x1A0F_A017_51DE_5EED;
        Self { config: config.clone(), rng: SplitMix64::new(seed), stats: ImuFaultStats::default() }
    }

    pub fn stats(&self) -> ImuFaultStats {
        self.stats
    }

    /// The fate of the next sample, whose encoding has `frames` frames. Every sample draws the
    /// same randomness, so sample k's fate depends only on the seed and k. Garbage bytes favour
    /// the sync bytes of both protocols (0x55, 0x75 0x65) to exercise resynchronisation.
    pub fn next(&mut self, frames: usize) -> SampleFate {
        let (u_garbage, u_drop, u_corrupt) = (self.rng.next_f64(), self.rng.next_f64(), self.rng.next_f64());
        let detail = self.rng.next_u64();
        let mut fate = SampleFate::default();
        let mut r = SplitMix64::new(detail);
        if u_garbage < self.config.garbage {
            let n = 1 + r.below(8) as usize;
            for _ in 0..n {
                let b = match r.below(4) {
                    0 => 0x55,
                    1 => 0x75,
                    2 => 0x65,
                    _ => r.next_u64() as u8,
                };
                fate.garbage.push(b);
            }
            self.stats.garbage_bursts += 1;
            self.stats.garbage_bytes += n as u64;
        }
        if u_drop < self.config.drop {
            fate.drop = true;
            self.stats.dropped += 1;
            return fate;
        }
        if u_corrupt < self.config.corrupt && frames > 0 {
            fate.corrupt = Some((r.below(frames as u64) as usize, 1 + r.below(255) as u8));
            self.stats.corrupted += 1;
        }
        fate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractions_are_met_and_runs_repeat() {
        let config = ImuFaultConfig { garbage: 0.1, drop: 0.05, corrupt: 0.02, ..Default::default() };
        let run = |seed| {
            let mut f = ImuFaults::new(&config, seed);
            let fates: Vec<SampleFate> = (0..20_000).map(|_| f.next(3)).collect();
            (fates, f.stats())
        };
        let (fates, stats) = run(3);
        let near = |count: u64, frac: f64| (count as f64 - frac * 20_000.0).abs() < 0.2 * frac * 20_000.0;
        assert!(near(stats.garbage_bursts, 0.1), "{stats:?}");
        assert!(near(stats.dropped, 0.05), "{stats:?}");
        assert!(near(stats.corrupted, 0.02 * 0.95), "{stats:?}");
        assert!(fates.iter().all(|f| f.corrupt.is_none_or(|(i, m)| i < 3 && m != 0)));
        assert_eq!(run(3).0, fates);
        assert_ne!(run(4).0, fates);
        assert!(ImuFaultConfig { drop: 2.0, ..Default::default() }.validate().is_err());
        assert!(ImuFaultConfig { silence_after_s: Some(-1.0), ..Default::default() }.validate().is_err());
    }
}
