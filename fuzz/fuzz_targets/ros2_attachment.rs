#![no_main]
//! rmw_zenoh's per-sample attachment (what the ROS 2 bridge takes with each /cmd_vel sample):
//! never panics on any bytes, and what decodes encodes back to the same 33 bytes.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::record::attachment::Attachment;

fuzz_target!(|data: &[u8]| {
    if let Ok(a) = Attachment::decode(data) {
        assert_eq!(a.encode().as_slice(), data);
    }
});
