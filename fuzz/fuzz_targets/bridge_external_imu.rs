#![no_main]
//! External IMU files (`starc lio --imu`): any bytes give samples or a reason, never a panic;
//! every sample's numbers are what a finite CSV or MIP field can hold.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(samples) = starc_bridge::external_imu::parse(data) {
        assert!(!samples.is_empty());
        for s in samples {
            assert!(s.gyro_rad_s.iter().chain(s.acc_m_s2.iter()).all(|x| x.is_finite()));
        }
    }
});
