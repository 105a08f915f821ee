#![no_main]
//! Link message parser: never panics on any bytes; what it accepts encodes again, and that
//! encoding decodes to the same message (poses up to quaternion renormalisation).
use libfuzzer_sys::fuzz_target;
use starc_pipeline::link::{decode, encode, LinkMessage};

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = decode(data) {
        let again = encode(&m).expect("a decoded message encodes");
        let back = decode(&again).expect("its encoding decodes");
        match (&m, &back) {
            (LinkMessage::RobotPose { stamp_ns: a, world_t_lidar: p }, LinkMessage::RobotPose { stamp_ns: b, world_t_lidar: q }) => {
                assert_eq!(a, b);
                assert_eq!(p.translation, q.translation);
                assert!(p.rotation.angle_to(&q.rotation) < 1e-9);
            }
            _ => {
                assert_eq!(m, back);
                assert_eq!(again, data, "a canonical frame re-encodes byte for byte");
            }
        }
    }
});
