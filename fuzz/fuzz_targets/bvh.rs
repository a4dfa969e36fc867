//! The BVH reader on any bytes: an error or a clip, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = motion::io::parse_bvh(data, "fuzz.bvh", motion::Unit::Metres);
});
