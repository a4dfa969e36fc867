//! The ASF reader on any bytes: an error or a skeleton, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = motion::io::parse_asf(data, "fuzz.asf");
});
