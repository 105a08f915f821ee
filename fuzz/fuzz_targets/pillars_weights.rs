#![no_main]
//! The learned detector's weights file (STPW): never panics on any bytes; what it accepts
//! encodes back to the same bytes, and a network built from it is either refused (a missing
//! tensor or a wrong shape) or runs.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::detect::pillars::weights::{encode, Weights};
use starc_pipeline::detect::pillars::PillarsDetector;
use starc_pipeline::detect::{DetectConfig, DetectWindow, Detector, WindowPoint};

fuzz_target!(|data: &[u8]| {
    let Ok(weights) = Weights::parse(data) else { return };
    assert_eq!(encode(&weights.tensors), data);
    if let Ok(mut detector) = PillarsDetector::from_weights(&weights, &DetectConfig::default()) {
        let points = [WindowPoint { x_m: 2.0, y_m: 0.0, z_m: 0.5, t_ns: 1 }];
        let window = DetectWindow {
            stamp: starc_time::Stamp::new(1, starc_time::Clock::Ptp),
            sensor_pose: nalgebra::Isometry3::identity(),
            points: &points,
        };
        detector.detect(&window, &mut Vec::new());
    }
});
