//! The NPZ reader (a zip of .npy arrays) on any bytes: an error or arrays,
//! never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = motion::npz::read(data);
});
