//! The two CRCs of the Livox SDK1 control protocol.
//!
//! The SDK seeds standard reflected tables with odd constants; expressed as Rocksoft models they
//! are plain CRC-16/CCITT and CRC-32 with non-standard initial values. Each model's `check` is its
//! CRC of `123456789`, the Rocksoft convention; the test below verifies both.

use crc::{Algorithm, Crc};

const LIVOX_CRC16: Algorithm<u16> = Algorithm {
    width: 16,
    poly: 0x1021,
    init: 0x9232,
    refin: true,
    refout: true,
    xorout: 0x0000,
    check: 0xAB4E,
    residue: 0x0000,
};

const LIVOX_CRC32: Algorithm<u32> = Algorithm {
    width: 32,
    poly: 0x04C1_1DB7,
    init: 0xAFE5_0D95,
    refin: true,
    refout: true,
    xorout: 0xFFFF_FFFF,
    check: 0xB08D_B5B1,
    residue: 0x0000_0000,
};

static CRC16: Crc<u16> = Crc::<u16>::new(&LIVOX_CRC16);
static CRC32: Crc<u32> = Crc::<u32>::new(&LIVOX_CRC32);

/// CRC16 of a control frame's first 7 bytes.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// CRC32 of a control frame up to (not including) the CRC32 itself.
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_values_are_the_crcs_of_123456789() {
        assert_eq!(crc16(b"123456789"), 0xAB4E);
        assert_eq!(crc32(b"123456789"), 0xB08D_B5B1);
    }
}
