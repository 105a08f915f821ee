//! The Lawicel `Sn` bitrate codes.

use crate::error::{CanError, Result};

/// `S0`..`S8` in bit/s, as the Lawicel manual defines them. python-can maps `S7` to 750 kbit/s
/// instead of 800 kbit/s: asking python-can for 750k on one of our mocks gets 800k.
pub const BITRATES: [u32; 9] = [10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000];

/// The digit of `Sn` for a bitrate in bit/s.
pub fn code_for(bitrate: u32) -> Result<u8> {
    BITRATES.iter().position(|&b| b == bitrate).map(|i| i as u8).ok_or(CanError::UnsupportedBitrate(bitrate))
}

/// The bitrate of `Sn`, or `None` for codes outside 0..=8.
pub fn bitrate_of(code: u8) -> Option<u32> {
    BITRATES.get(usize::from(code)).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip() {
        assert_eq!(code_for(1_000_000).ok(), Some(8));
        assert_eq!(code_for(800_000).ok(), Some(7));
        assert!(code_for(750_000).is_err());
        assert_eq!(bitrate_of(6), Some(500_000));
        assert_eq!(bitrate_of(9), None);
    }
}
