//! Faults a mock injects, deterministic from a seed.
//!
//! On outgoing data and IMU packets: drop, duplicate, reorder (hold a packet back and send it
//! after the next one of its kind) and corrupt (flip 1-3 bytes anywhere in the packet). On the
//! control side: stop answering heartbeats some seconds after each handshake, and switch the time
//! stamp source at a given time after power-on. Every packet draws the same amount of randomness,
//! so a fault on packet k depends only on the seed and k.
//!
//! TOML (the `[faults]` table of a mock config):
//!
//! ```toml
//! seed = 7
//! drop = 0.01
//! duplicate = 0.001
//! reorder = 0.001
//! corrupt = 0.0005
//! no_heartbeat_after_s = 10.0
//! switch_time_source = { after_s = 5.0, to = "gps" }
//! ```

use crate::avia::stream::{Packet, PacketKind, TimeSource, NS_PER_S};
use crate::error::{HilError, Result};
use crate::rng::SplitMix64;
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// Which faults to inject.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultConfig {
    /// Seed of the fault PRNG; the mock's seed when absent.
    pub seed: Option<u64>,
    /// Fraction of data/IMU packets dropped.
    pub drop: f64,
    /// Fraction of data/IMU packets sent twice.
    pub duplicate: f64,
    /// Fraction of data/IMU packets swapped with the next packet of their kind.
    pub reorder: f64,
    /// Fraction of data/IMU packets with 1-3 bytes flipped.
    pub corrupt: f64,
    /// Stop answering heartbeats this many seconds after each handshake (0: never answer them).
    pub no_heartbeat_after_s: Option<f64>,
    /// Switch the time stamp source this long after power-on.
    pub switch_time_source: Option<TimeSourceSwitch>,
}

/// A time source switch: `after_s` seconds after power-on, stamps come from `to`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSourceSwitch {
    pub after_s: f64,
    pub to: TimeSource,
}

impl FromStr for TimeSourceSwitch {
    type Err = String;
    /// `S:SRC`, e.g. `5:gps`.
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let (after, to) = s.split_once(':').ok_or_else(|| format!("expected SECONDS:SOURCE, got {s:?}"))?;
        let after_s: f64 = after.trim().parse().map_err(|e| format!("{after:?}: {e}"))?;
        if !after_s.is_finite() || after_s < 0.0 {
            return Err(format!("{after:?}: seconds must be finite and >= 0"));
        }
        Ok(Self { after_s, to: to.trim().parse()? })
    }
}

fn seconds_to_ns(s: f64) -> u64 {
    (s * NS_PER_S as f64).round() as u64
}

impl FaultConfig {
    /// Refuses fractions outside [0, 1] and negative or non-finite times.
    pub fn validate(&self) -> Result<()> {
        for (field, v) in [
            ("faults.drop", self.drop),
            ("faults.duplicate", self.duplicate),
            ("faults.reorder", self.reorder),
            ("faults.corrupt", self.corrupt),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(HilError::config(field, format!("{v} is not a fraction in [0, 1]")));
            }
        }
        if let Some(s) = self.no_heartbeat_after_s {
            if !s.is_finite() || s < 0.0 {
                return Err(HilError::config("faults.no_heartbeat_after_s", format!("{s} is not a time >= 0")));
            }
        }
        if let Some(sw) = self.switch_time_source {
            if !sw.after_s.is_finite() || sw.after_s < 0.0 {
                return Err(HilError::config("faults.switch_time_source.after_s", format!("{} < 0", sw.after_s)));
            }
        }
        Ok(())
    }

    fn touches_packets(&self) -> bool {
        self.drop > 0.0 || self.duplicate > 0.0 || self.reorder > 0.0 || self.corrupt > 0.0
    }

    /// Heartbeats go unanswered this long after a handshake, if at all.
    pub fn heartbeat_silence_ns(&self) -> Option<u64> {
        self.no_heartbeat_after_s.map(seconds_to_ns)
    }

    /// Device time (after power-on) and target of the time source switch, if any.
    pub fn switch_at_ns(&self) -> Option<(u64, TimeSource)> {
        self.switch_time_source.map(|s| (seconds_to_ns(s.after_s), s.to))
    }
}

/// What the faults did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    pub dropped: u64,
    pub duplicated: u64,
    pub reordered: u64,
    pub corrupted: u64,
}

/// The packet fault injector.
#[derive(Debug)]
pub struct Faults {
    config: FaultConfig,
    rng: SplitMix64,
    held: [Option<Packet>; 2],
    stats: FaultStats,
}

fn slot(kind: PacketKind) -> usize {
    match kind {
        PacketKind::Points => 0,
        PacketKind::Imu => 1,
    }
}

impl Faults {
    /// `seed` is used when the config names none.
    pub fn new(config: &FaultConfig, seed: u64) -> Self {
        let seed = config.seed.unwrap_or(seed) ^ 0xFA01_7FA0_17FA_017F;
        Self { config: config.clone(), rng: SplitMix64::new(seed), held: [None, None], stats: FaultStats::default() }
    }

    pub fn config(&self) -> &FaultConfig {
        &self.config
    }

    pub fn stats(&self) -> FaultStats {
        self.stats
    }

    /// Passes `packet` through the faults, appending what goes out to `out`.
    pub fn apply(&mut self, mut packet: Packet, out: &mut Vec<Packet>) {
        if !self.config.touches_packets() {
            out.push(packet);
            return;
        }
        let (u_drop, u_dup, u_reorder, u_corrupt) =
            (self.rng.next_f64(), self.rng.next_f64(), self.rng.next_f64(), self.rng.next_f64());
        let corruption = self.rng.next_u64();
        if u_drop < self.config.drop {
            self.stats.dropped += 1;
            return;
        }
        if u_corrupt < self.config.corrupt && !packet.bytes.is_empty() {
            let mut r = SplitMix64::new(corruption);
            let flips = 1 + r.below(3);
            for _ in 0..flips {
                let at = r.below(packet.bytes.len() as u64) as usize;
                let mask = 1 + r.below(255) as u8;
                if let Some(b) = packet.bytes.get_mut(at) {
                    *b ^= mask;
                }
            }
            self.stats.corrupted += 1;
        }
        let s = slot(packet.kind);
        if u_reorder < self.config.reorder && self.held[s].is_none() {
            self.stats.reordered += 1;
            self.held[s] = Some(packet);
            return;
        }
        if u_dup < self.config.duplicate {
            self.stats.duplicated += 1;
            out.push(packet.clone());
        }
        out.push(packet);
        if let Some(h) = self.held[s].take() {
            out.push(h);
        }
    }

    /// Sends packets held back for reordering (when streaming stops).
    pub fn flush(&mut self, out: &mut Vec<Packet>) {
        for h in &mut self.held {
            if let Some(p) = h.take() {
                out.push(p);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packets(n: u64) -> Vec<Packet> {
        (0..n)
            .map(|i| Packet {
                kind: if i % 10 == 9 { PacketKind::Imu } else { PacketKind::Points },
                device_ns: i,
                bytes: vec![i as u8; 40],
            })
            .collect()
    }

    fn run(config: &FaultConfig, seed: u64, n: u64) -> (Vec<Packet>, FaultStats) {
        let mut f = Faults::new(config, seed);
        let mut out = Vec::new();
        for p in packets(n) {
            f.apply(p, &mut out);
        }
        f.flush(&mut out);
        (out, f.stats())
    }

    #[test]
    fn no_faults_is_a_pass_through() {
        let (out, stats) = run(&FaultConfig::default(), 1, 100);
        assert_eq!(out, packets(100));
        assert_eq!(stats, FaultStats::default());
    }

    #[test]
    fn fractions_are_met_and_runs_repeat() {
        let config = FaultConfig { drop: 0.1, duplicate: 0.05, reorder: 0.05, corrupt: 0.02, ..Default::default() };
        let n = 20_000;
        let (out, stats) = run(&config, 9, n);
        let near = |count: u64, frac: f64| (count as f64 - frac * n as f64).abs() < 0.25 * frac * n as f64 + 10.0;
        assert!(near(stats.dropped, 0.1), "{stats:?}");
        assert!(near(stats.duplicated, 0.05 * 0.9), "{stats:?}");
        assert!(near(stats.reordered, 0.05 * 0.9), "{stats:?}");
        assert!(near(stats.corrupted, 0.02 * 0.9), "{stats:?}");
        assert_eq!(out.len() as u64, n - stats.dropped + stats.duplicated);
        // Reordered: some packet comes after a later one of its kind.
        let late = out
            .windows(2)
            .filter(|w| w[0].kind == PacketKind::Points && w[1].kind == PacketKind::Points)
            .filter(|w| w[1].device_ns < w[0].device_ns)
            .count();
        assert!(late > 0);
        // Corrupted packets differ from their original bytes.
        let changed = out.iter().filter(|p| p.bytes.iter().any(|&b| b != p.device_ns as u8)).count() as u64;
        assert!(changed + 5 >= stats.corrupted && changed > 0, "{changed} {stats:?}");
        assert_eq!(run(&config, 9, n), (out.clone(), stats));
        let seeded = FaultConfig { seed: Some(9), ..config.clone() };
        assert_ne!(run(&config, 10, n).0, out);
        assert_eq!(run(&seeded, 123, n).0, out);
    }

    #[test]
    fn bad_configs_are_refused_and_switches_parse() {
        assert!(FaultConfig { drop: 1.5, ..Default::default() }.validate().is_err());
        assert!(FaultConfig { corrupt: -0.1, ..Default::default() }.validate().is_err());
        assert!(FaultConfig { no_heartbeat_after_s: Some(f64::NAN), ..Default::default() }.validate().is_err());
        assert!(FaultConfig { drop: 1.0, no_heartbeat_after_s: Some(0.0), ..Default::default() }.validate().is_ok());
        assert_eq!("5:gps".parse::<TimeSourceSwitch>(), Ok(TimeSourceSwitch { after_s: 5.0, to: TimeSource::Gps }));
        assert!("5".parse::<TimeSourceSwitch>().is_err());
        assert!("-1:ptp".parse::<TimeSourceSwitch>().is_err());
        assert!("2.5:sun".parse::<TimeSourceSwitch>().is_err());
    }
}
