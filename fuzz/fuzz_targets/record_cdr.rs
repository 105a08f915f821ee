#![no_main]
//! CDR decoders of the recorded ROS 2 messages: never panic on any payload, and whatever
//! decodes re-encodes to bytes that decode and re-encode to the same bytes. The first input
//! byte picks the message type.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::record::msgs::{
    CanFrameMsg, CompressedImage, Imu, MarkerArray, Odometry, PointCloud2, RosMessage, TfMessage, Twist,
};
use starc_pipeline::record::vision::Detection3DArray;

fn check<T: RosMessage>(payload: &[u8]) {
    if let Ok(m) = T::from_cdr(payload) {
        let once = m.to_cdr();
        let again = T::from_cdr(&once).map(|m| m.to_cdr());
        assert!(again.as_ref().is_ok_and(|b| *b == once), "{}: {again:?}", T::TYPE_NAME);
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&kind, payload)) = data.split_first() else {
        return;
    };
    match kind % 9 {
        0 => check::<PointCloud2>(payload),
        1 => check::<Imu>(payload),
        2 => check::<Odometry>(payload),
        3 => check::<TfMessage>(payload),
        4 => check::<MarkerArray>(payload),
        5 => check::<CanFrameMsg>(payload),
        6 => check::<Twist>(payload),
        7 => check::<Detection3DArray>(payload),
        _ => check::<CompressedImage>(payload),
    }
});
