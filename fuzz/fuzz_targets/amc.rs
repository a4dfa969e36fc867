//! The AMC reader on any bytes, for the bundled HDM05 skeleton: an error or a
//! clip, never a panic.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

const ASF: &[u8] = include_bytes!("../../examples/data/HDM_bd.asf");

fuzz_target!(|data: &[u8]| {
    static SKELETON: OnceLock<motion::asf::Asf> = OnceLock::new();
    let asf = SKELETON
        .get_or_init(|| motion::io::parse_asf(ASF, "HDM_bd.asf").expect("the bundled ASF"));
    let _ = motion::io::parse_amc(data, "fuzz.amc", asf, 120.0);
});
