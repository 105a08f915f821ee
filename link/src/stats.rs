//! Latency figures over the last messages of one kind.

use std::collections::VecDeque;

/// Summary of the last [`LatencyWindow::CAPACITY`] latencies (nanoseconds; negative values are
/// possible when the clock offset estimate is off by more than the latency).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LatencySummary {
    /// Samples ever recorded.
    pub count: u64,
    /// Over the window.
    pub p50_ns: i64,
    pub p99_ns: i64,
    pub max_ns: i64,
}

/// A ring of recent latencies.
#[derive(Clone, Debug, Default)]
pub struct LatencyWindow {
    recent: VecDeque<i64>,
    count: u64,
}

impl LatencyWindow {
    pub const CAPACITY: usize = 1024;

    pub fn record(&mut self, latency_ns: i64) {
        if self.recent.len() == Self::CAPACITY {
            self.recent.pop_front();
        }
        self.recent.push_back(latency_ns);
        self.count += 1;
    }

    /// None before the first sample.
    pub fn summary(&self) -> Option<LatencySummary> {
        let mut v: Vec<i64> = self.recent.iter().copied().collect();
        v.sort_unstable();
        let last = v.len().checked_sub(1)?;
        let at = |q: f64| v.get((last as f64 * q).round() as usize).copied();
        Some(LatencySummary { count: self.count, p50_ns: at(0.5)?, p99_ns: at(0.99)?, max_ns: *v.last()? })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_over_the_window() {
        let mut w = LatencyWindow::default();
        assert_eq!(w.summary(), None);
        for i in 1..=100 {
            w.record(i * 1000);
        }
        let s = w.summary().unwrap_or_default();
        assert_eq!((s.count, s.p50_ns, s.p99_ns, s.max_ns), (100, 51_000, 99_000, 100_000));
        for _ in 0..LatencyWindow::CAPACITY {
            w.record(7);
        }
        let s = w.summary().unwrap_or_default();
        assert_eq!((s.count, s.p50_ns, s.max_ns), (100 + LatencyWindow::CAPACITY as u64, 7, 7));
    }
}
