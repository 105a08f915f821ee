#![no_main]
//! Data packets: parsing and point decoding never panic, counts are consistent, points and IMU
//! samples handed out are finite, and the scan assembler accepts whatever parses and never holds
//! more than its cap (the same packet pushed over and over: a repeated time stamp).
use libfuzzer_sys::fuzz_target;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};

fuzz_target!(|data: &[u8]| {
    if let Ok(packet) = DataPacket::parse(data) {
        let mut points = Vec::new();
        let counts = packet.decode_points(&mut points);
        assert_eq!(counts, packet.count_returns());
        assert_eq!(points.len() as u32, counts.returns - counts.empty);
        assert!(points.iter().all(|p| p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite()));
        if let Some(s) = packet.imu() {
            assert!(s.is_finite());
        }
        assert_eq!(packet.imu().is_some(), packet.imu_raw().is_some_and(|s| s.is_finite()));
        // A small cap (1000 points/s: 100 per scan) so that a few pushes reach it.
        let config = ScanConfig { max_points_per_s: 1000, ..ScanConfig::default() };
        let cap = config.max_points();
        if let Ok(mut assembler) = ScanAssembler::new(config) {
            let mut done = Vec::new();
            for _ in 0..4 {
                assembler.push(&packet, None, &mut done);
                assert!(assembler.pending_points() <= cap);
            }
            done.extend(assembler.finish());
            assert!(done.iter().all(|s| s.points.len() <= cap));
        }
    }
});
