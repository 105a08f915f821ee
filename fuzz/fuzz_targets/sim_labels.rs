#![no_main]
//! The simulator's labels file (`labels_robot.bin`, read by the mission's scorer): never panics
//! on any bytes, and what it accepts is exactly what writing its records back gives.
use libfuzzer_sys::fuzz_target;
use starc_hil::sim::truth::{read_labels, LABELS_MAGIC, LABELS_VERSION};

fuzz_target!(|data: &[u8]| {
    if let Some(records) = read_labels(data) {
        let mut again = LABELS_MAGIC.to_vec();
        again.extend_from_slice(&LABELS_VERSION.to_le_bytes());
        for (t_ns, labels) in &records {
            again.extend_from_slice(&t_ns.to_le_bytes());
            again.extend_from_slice(&(labels.len() as u16).to_le_bytes());
            for l in labels {
                again.extend_from_slice(&l.to_le_bytes());
            }
        }
        assert_eq!(again, data);
    }
});
