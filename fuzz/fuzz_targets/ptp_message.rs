#![no_main]
//! PTP messages: parsing arbitrary bytes never panics; whatever parses and is encodable encodes
//! to its canonical length, parses back to the same message, and is byte-identical to the input
//! when the input was canonical.
use libfuzzer_sys::fuzz_target;
use starc_ptp::message::Message;

fuzz_target!(|data: &[u8]| {
    let Ok(m) = Message::parse(data) else { return };
    let Ok(bytes) = m.encode() else { return };
    assert_eq!(Some(bytes.len()), m.wire_len().ok());
    let again = Message::parse(&bytes).unwrap_or_else(|e| panic!("re-parse failed: {e}"));
    assert_eq!(again, m);
    let declared = u16::from_be_bytes([data[2], data[3]]) as usize;
    if declared == bytes.len() {
        assert_eq!(&data[..declared], &bytes[..]);
    }
});
