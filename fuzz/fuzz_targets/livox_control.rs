#![no_main]
//! Control frames: decoding never panics, and whatever decodes re-encodes to the same bytes.
use libfuzzer_sys::fuzz_target;
use starc_livox::control::ControlFrame;

fuzz_target!(|data: &[u8]| {
    if let Ok(frame) = ControlFrame::decode(data) {
        let again = frame.encode().ok();
        let reread = again.as_deref().and_then(|b| ControlFrame::decode(b).ok());
        assert_eq!(reread, Some(frame));
    }
});
