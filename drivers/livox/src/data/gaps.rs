//! Lost-packet detection from time-stamp gaps.

use serde::Serialize;
use starc_time::Stamp;

/// A hole in a packet stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Gap {
    /// Time stamp of the packet before the hole.
    pub after_ns: u64,
    pub gap_ns: u64,
    /// Packets that should have arrived in between.
    pub lost_packets: u64,
}

/// Watches one stream (points or IMU of one device). A gap longer than 1.8 expected intervals
/// means lost packets; a stamp that goes backwards is counted as reordered, not as a gap. A jump
/// of more than [`CLOCK_JUMP_NS`] either way (a resynchronised clock, a corrupted stamp) is
/// counted as a clock jump and restarts the watch, so one bad stamp cannot poison the rest.
pub const CLOCK_JUMP_NS: u64 = 1_000_000_000;

#[derive(Clone, Debug, Default)]
pub struct GapDetector {
    last: Option<Stamp>,
    pub packets: u64,
    pub lost_packets: u64,
    pub gaps: u64,
    pub reordered: u64,
    pub clock_changes: u64,
    pub clock_jumps: u64,
}

impl GapDetector {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn observe(&mut self, stamp: Stamp, expected_interval_ns: u64) -> Option<Gap> {
        self.packets += 1;
        let Some(last) = self.last else {
            self.last = Some(stamp);
            return None;
        };
        if last.clock != stamp.clock {
            self.clock_changes += 1;
            self.last = Some(stamp);
            return None;
        }
        if stamp.ns.abs_diff(last.ns) > CLOCK_JUMP_NS {
            self.clock_jumps += 1;
            self.last = Some(stamp);
            return None;
        }
        if stamp.ns < last.ns {
            self.reordered += 1;
            return None;
        }
        self.last = Some(stamp);
        let gap_ns = stamp.ns - last.ns;
        // gap_ns <= CLOCK_JUMP_NS, so the products below cannot overflow for any sane interval.
        if expected_interval_ns == 0 || u128::from(gap_ns) * 10 <= u128::from(expected_interval_ns) * 18 {
            return None;
        }
        let lost = (gap_ns + expected_interval_ns / 2) / expected_interval_ns - 1;
        self.gaps += 1;
        self.lost_packets += lost;
        Some(Gap { after_ns: last.ns, gap_ns, lost_packets: lost })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::Clock;

    #[test]
    fn finds_missing_packets() {
        let mut d = GapDetector::new();
        let ts = |n: u64| Stamp::new(n * 400_000, Clock::Ptp);
        for n in [0, 1, 2, 5, 6, 8] {
            d.observe(ts(n), 400_000);
        }
        assert_eq!((d.gaps, d.lost_packets, d.packets), (2, 3, 6));
    }

    #[test]
    fn a_wild_stamp_is_a_clock_jump_and_the_watch_recovers() {
        let mut d = GapDetector::new();
        let ts = |n: u64| Stamp::new(n * 400_000, Clock::Ptp);
        d.observe(ts(0), 400_000);
        d.observe(ts(1), 400_000);
        d.observe(Stamp::new(u64::MAX - 5, Clock::Ptp), 400_000);
        for n in 2..10 {
            d.observe(ts(n), 400_000);
        }
        assert_eq!((d.gaps, d.lost_packets, d.reordered, d.clock_jumps), (0, 0, 0, 2));
        d.observe(ts(12), u64::MAX);
        d.observe(ts(13), 0);
    }

    #[test]
    fn jitter_and_reordering_are_not_loss() {
        let mut d = GapDetector::new();
        for ns in [0, 400_000, 1_100_000, 900_000, 1_500_000] {
            d.observe(Stamp::new(ns, Clock::Device), 400_000);
        }
        assert_eq!((d.gaps, d.lost_packets, d.reordered), (0, 0, 1));
    }
}
