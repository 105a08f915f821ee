#![no_main]
//! The Foxglove server's parser of client messages (`starc_view::foxglove_proto`): never panics
//! on any text, and a subscribe it accepts stays within the cap.
use libfuzzer_sys::fuzz_target;
use starc_view::foxglove_proto;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(foxglove_proto::ClientOp::Subscribe(subs)) = foxglove_proto::parse_client(text) {
        assert!(subs.len() <= foxglove_proto::MAX_SUBSCRIPTIONS_PER_MESSAGE);
    }
});
