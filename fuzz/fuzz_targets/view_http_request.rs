#![no_main]
//! The live view's HTTP request-head parser (`starc_view::request`): never panics on any bytes
//! a browser or attacker sends, and whatever parses is a GET or HEAD of an absolute, printable
//! path within the caps.
use libfuzzer_sys::fuzz_target;
use starc_view::request;

fuzz_target!(|data: &[u8]| {
    let end = request::head_end(data);
    if let Ok(Some(n)) = end {
        assert!(n <= data.len() && n <= request::MAX_HEAD_BYTES + 4);
    }
    if let Ok(r) = request::parse_head(data) {
        assert!(r.path.starts_with('/') && r.path.len() <= request::MAX_PATH_BYTES);
        assert!(!r.path.contains('?') && r.path.bytes().all(|b| b.is_ascii_graphic()));
    }
});
