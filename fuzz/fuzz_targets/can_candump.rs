#![no_main]
//! `candump -l` lines: any text gives a frame or a typed error, never a panic, and a frame that
//! parses prints back (candump's compact form) to the text it came from, case aside.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(line) = std::str::from_utf8(data) else { return };
    if let Ok(f) = starc_can::candump::parse_line(line) {
        let (_, frame_text) = line.trim_end().rsplit_once(' ').unwrap_or_default();
        let printed = f.frame.to_string();
        // A remote frame without its DLC ("601#R") prints as "601#R0".
        assert!(printed.eq_ignore_ascii_case(frame_text) || printed.eq_ignore_ascii_case(&format!("{frame_text}0")));
    }
});
