#![no_main]
//! Data packets: parsing and point decoding never panic, counts are consistent, and the scan
//! assembler accepts whatever parses.
use libfuzzer_sys::fuzz_target;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};

fuzz_target!(|data: &[u8]| {
    if let Ok(packet) = DataPacket::parse(data) {
        let mut points = Vec::new();
        let counts = packet.decode_points(&mut points);
        assert_eq!(counts, packet.count_returns());
        assert_eq!(points.len() as u32, counts.returns - counts.empty);
        let _ = packet.imu();
        if let Ok(mut assembler) = ScanAssembler::new(ScanConfig::default()) {
            let mut done = Vec::new();
            assembler.push(&packet, None, &mut done);
            assembler.push(&packet, None, &mut done);
            let _ = assembler.finish();
        }
    }
});
