#![no_main]
//! The simulator's labels file (`labels_robot.bin`, read by the mission's scorer): never panics
//! on any bytes, and what it accepts is exactly what writing its records back gives.
use libfuzzer_sys::fuzz_target;
use starc_hil::sim::truth::{labels_record, read_labels, LABELS_MAGIC, LABELS_VERSION};

fuzz_target!(|data: &[u8]| {
    if let Some(records) = read_labels(data) {
        let mut again = LABELS_MAGIC.to_vec();
        again.extend_from_slice(&LABELS_VERSION.to_le_bytes());
        for (t_ns, labels) in &records {
            // read_labels takes at most 65535 labels a record: the count is a u16.
            again.extend(labels_record(*t_ns, labels).expect("a record read back fits"));
        }
        assert_eq!(again, data);
    }
});
