#![no_main]
//! slcan: splitting and decoding never panic, in either direction, and whatever decodes
//! re-encodes to something that decodes to the same value.
use libfuzzer_sys::fuzz_target;
use starc_can::slcan::{Command, Line, LineSplitter, Reply, SlcanHost};
use starc_time::{Clock, Stamp};

fuzz_target!(|data: &[u8]| {
    let mut lines = Vec::new();
    LineSplitter::new().push(data, &mut lines);
    for line in &lines {
        if let Ok(reply) = Reply::decode(line) {
            let bytes = reply.to_bytes();
            let mut again = Vec::new();
            LineSplitter::new().push(&bytes, &mut again);
            assert_eq!(again.len(), 1);
            assert_eq!(again.first().map(Reply::decode).and_then(Result::ok), Some(reply));
        }
        if let Line::Text(text) = line {
            if let Ok(cmd) = Command::decode(text) {
                let bytes = cmd.to_bytes();
                let back = bytes.strip_suffix(b"\r").map(Command::decode).and_then(Result::ok);
                assert_eq!(back, Some(cmd));
            }
        }
    }
    let mut host = SlcanHost::new();
    host.set_open(data.first().is_some_and(|b| b & 1 == 1));
    let mut out = std::collections::VecDeque::new();
    for chunk in data.chunks(7) {
        host.receive(chunk, Stamp::new(0, Clock::Host), &mut out);
    }
});
