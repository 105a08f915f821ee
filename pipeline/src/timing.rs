//! Compute time, measured on a clock the caller chooses, and peak memory. The cores report how long their steps
//! took (for latency figures); no result depends on it. A rerun that must give the same bytes
//! twice turns the clock off and every measured time reads 0.

use std::time::Instant;

/// Which clock measures compute time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Stopwatch {
    /// The monotonic wall clock.
    #[default]
    Wall,
    /// No clock: every lap is 0.
    Off,
}

impl Stopwatch {
    pub fn start(self) -> Lap {
        Lap(match self {
            Stopwatch::Wall => Some(Instant::now()),
            Stopwatch::Off => None,
        })
    }

    /// The wall clock when `on`, else none.
    pub fn wall_if(on: bool) -> Self {
        if on {
            Stopwatch::Wall
        } else {
            Stopwatch::Off
        }
    }
}

/// A started measurement.
#[derive(Clone, Copy, Debug)]
pub struct Lap(Option<Instant>);

impl Lap {
    pub fn ms(&self) -> f64 {
        self.0.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3)
    }

    pub fn us(&self) -> u64 {
        self.0.map_or(0, |t| u64::try_from(t.elapsed().as_micros()).unwrap_or(u64::MAX))
    }
}

/// The process's peak resident memory (VmHWM), in MiB; `None` where /proc is not Linux's.
pub fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_reads_zero() {
        let lap = Stopwatch::Off.start();
        std::thread::sleep(std::time::Duration::from_millis(2));
        assert_eq!((lap.ms(), lap.us()), (0.0, 0));
        assert!(Stopwatch::Wall.start().ms() >= 0.0);
    }
}
