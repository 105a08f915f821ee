//! Unwraps the 16-bit millisecond stamps of slcan `Z1` (0..59999, then 0 again) into one
//! monotonic device time.

use starc_time::{Clock, Stamp};

/// Where the adapter's millisecond counter wraps.
pub const WRAP_MS: u64 = 60_000;

/// Turns successive wrapped stamps into nanoseconds on the adapter's clock.
#[derive(Debug, Default, Clone)]
pub struct StampUnwrapper {
    last_ms: Option<u64>,
    wraps: u64,
}

impl StampUnwrapper {
    pub fn new() -> Self {
        Self::default()
    }

    /// The device time of a stamp. A stamp smaller than the previous one means one wrap (a gap
    /// of more than a minute without frames cannot be seen and is not corrected).
    pub fn unwrap(&mut self, stamp_ms: u16) -> Stamp {
        let ms = u64::from(stamp_ms) % WRAP_MS;
        if let Some(last) = self.last_ms {
            if ms < last {
                self.wraps += 1;
            }
        }
        self.last_ms = Some(ms);
        Stamp::new((self.wraps * WRAP_MS + ms) * 1_000_000, Clock::Device)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_at_sixty_seconds() {
        let mut u = StampUnwrapper::new();
        assert_eq!(u.unwrap(59_990).ns, 59_990_000_000);
        assert_eq!(u.unwrap(59_999).ns, 59_999_000_000);
        assert_eq!(u.unwrap(3).ns, 60_003_000_000);
        assert_eq!(u.unwrap(3).ns, 60_003_000_000);
        assert_eq!(u.unwrap(10).clock, Clock::Device);
    }
}
