//! The offset between the two hosts' clocks from NTP-style exchanges, sans-IO.
//!
//! One exchange gives four stamps: `t1` the probe leaves here, `t2` it reaches the peer, `t3`
//! the reply leaves the peer, `t4` it reaches here (t1, t4 on this clock; t2, t3 on the peer's).
//! Then `offset = ((t2 - t1) + (t3 - t4)) / 2` (peer minus local) and
//! `delay = (t4 - t1) - (t3 - t2)` (the round trip minus the peer's turnaround). Whatever the
//! split of `delay` between the two directions, the true offset lies within `delay / 2` of the
//! estimate, so the exchange with the least delay bounds the offset tightest: over WiFi, where
//! queueing adds tens of milliseconds to some packets, we keep a window of recent exchanges and
//! report the one with the minimum delay (the NTP clock filter's idea).

use std::collections::VecDeque;

use crate::PipelineError;

/// The current estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OffsetEstimate {
    /// Peer clock minus local clock: `local_ns + offset_ns` is the same instant on the peer's clock.
    pub offset_ns: i64,
    /// The true offset lies within `offset_ns ± uncertainty_ns` (half the chosen exchange's delay),
    /// whatever the asymmetry of the path.
    pub uncertainty_ns: u64,
    /// Network round trip of the chosen exchange (turnaround removed).
    pub rtt_ns: u64,
    /// Exchanges in the window.
    pub samples: usize,
}

/// Minimum-delay filter over the last `window` exchanges.
#[derive(Clone, Debug)]
pub struct ClockOffset {
    window: usize,
    /// (offset_ns, delay_ns) of recent exchanges, oldest first.
    samples: VecDeque<(i64, u64)>,
}

impl ClockOffset {
    /// Keeps the last `window` exchanges (at least 1). At one probe a second, 16 to 64 spans long
    /// enough to catch a quiet moment on a busy WiFi and short enough that clock drift (tens of
    /// ppm, i.e. microseconds per minute) stays below the uncertainty.
    pub fn new(window: usize) -> Self {
        let window = window.max(1);
        Self { window, samples: VecDeque::with_capacity(window) }
    }

    /// Adds one exchange. Refuses stamps that cannot come from one exchange (reply before probe,
    /// peer's send before its receive, turnaround longer than the round trip), which change
    /// nothing.
    pub fn add(&mut self, t1_ns: u64, t2_ns: u64, t3_ns: u64, t4_ns: u64) -> Result<OffsetEstimate, PipelineError> {
        let (t1, t2, t3, t4) = (i128::from(t1_ns), i128::from(t2_ns), i128::from(t3_ns), i128::from(t4_ns));
        let round_trip = t4 - t1;
        let turnaround = t3 - t2;
        if round_trip < 0 || turnaround < 0 || turnaround > round_trip {
            return Err(PipelineError::BadFile {
                format: "clock exchange",
                reason: format!("round trip {round_trip} ns, turnaround {turnaround} ns"),
            });
        }
        let offset = ((t2 - t1) + (t3 - t4)) / 2;
        let offset = i64::try_from(offset).map_err(|_| PipelineError::BadFile {
            format: "clock exchange",
            reason: format!("offset {offset} ns does not fit i64"),
        })?;
        let delay = u64::try_from(round_trip - turnaround).unwrap_or(u64::MAX);
        if self.samples.len() == self.window {
            self.samples.pop_front();
        }
        self.samples.push_back((offset, delay));
        self.estimate().ok_or(PipelineError::BadFile { format: "clock exchange", reason: "empty window".into() })
    }

    /// The exchange with the least delay in the window, or None before the first.
    pub fn estimate(&self) -> Option<OffsetEstimate> {
        let &(offset_ns, rtt_ns) = self.samples.iter().min_by_key(|(_, d)| *d)?;
        Some(OffsetEstimate { offset_ns, uncertainty_ns: rtt_ns.div_ceil(2), rtt_ns, samples: self.samples.len() })
    }

    /// A peer stamp on the local clock, if there is an estimate (saturating at the u64 ends).
    pub fn peer_to_local(&self, peer_ns: u64) -> Option<u64> {
        let off = self.estimate()?.offset_ns;
        Some(if off >= 0 {
            peer_ns.saturating_sub(off.unsigned_abs())
        } else {
            peer_ns.saturating_add(off.unsigned_abs())
        })
    }

    /// Forgets every exchange (e.g. when the peer restarted and its clock may have been stepped).
    pub fn reset(&mut self) {
        self.samples.clear();
    }
}
