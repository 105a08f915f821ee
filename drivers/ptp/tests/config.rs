//! The shipped config/ptp.toml loads, equals the defaults, and unknown keys are refused.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_ptp::PtpConfig;
use std::path::PathBuf;

#[test]
fn shipped_example_loads_and_matches_the_defaults() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/ptp.toml");
    let cfg = PtpConfig::load(&path).unwrap();
    assert_eq!(cfg, PtpConfig::default());
    assert_eq!(cfg.master.utc_offset_s, 37);
    assert!(!cfg.slave.adjust_clock);
}

#[test]
fn unknown_keys_and_bad_values_are_refused() {
    assert!(PtpConfig::from_toml("[master]\nsync_rate = 8\n").is_err());
    assert!(PtpConfig::from_toml("[master]\nlog_sync_interval = 9\n").is_err());
    assert!(PtpConfig::from_toml("[slave]\nannounce_receipt_timeout = 1\n").is_err());
    let c = PtpConfig::from_toml("[master]\nlog_sync_interval = -3\n").unwrap();
    assert_eq!(c.master.log_sync_interval, -3);
}
