#![no_main]
//! MCAP recording reader: never panics (nor aborts on a huge allocation) on any bytes, in
//! strict and recover mode; a recover read never yields more than a strict one would before
//! its first error, and every message it yields goes through the typed decoder.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::record::reader::{self, ReadMode};

fuzz_target!(|data: &[u8]| {
    let Ok(strict) = reader::messages(data, ReadMode::Strict) else {
        return;
    };
    let good_before_error = strict.take_while(|m| m.is_ok()).count();
    if let Ok(recover) = reader::messages(data, ReadMode::Recover) {
        let mut n = 0;
        for m in recover {
            if let Ok(m) = m {
                let _ = m.decode();
            }
            n += 1;
        }
        assert_eq!(n, good_before_error);
    }
    let _ = reader::summarize(data);
});
