//! The coordinator's upload path on a zip of any bytes: `upload::parse_upload`
//! unpacks it under the upload memory budget and reads every entry with the
//! mocap readers. Whatever the bytes, it answers clips or a client error
//! (4xx: never a 500, never a panic), holds no more memory than the budget,
//! and what it accepts stays within the unpacked-size and file limits.
//!
//! The limits are the defaults scaled down (8 MiB unpacked instead of 128), so
//! a bomb costs milliseconds and libFuzzer keeps its pace; the checks that
//! enforce them are the same code.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use motionaug_coordinator::configuration::Limits;
use motionaug_coordinator::upload::{UploadFile, parse_upload};
use motionaug_coordinator::upload_memory::UploadMemory;

fn limits() -> Limits {
    Limits {
        max_files: 50,
        max_unzipped_bytes: 8 << 20,
        upload_memory_bytes: 12 << 20,
        ..Limits::default()
    }
}

fuzz_target!(|data: &[u8]| {
    static RUNTIME: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    let runtime = RUNTIME.get_or_init(|| {
        tokio::runtime::Builder::new_current_thread()
            .build()
            .expect("a tokio runtime")
    });
    let limits = limits();
    let memory = UploadMemory::new(1, limits.upload_memory_bytes);
    let mut reservation = runtime.block_on(memory.start());
    let files = vec![UploadFile {
        label: "fuzz.zip".into(),
        name: "fuzz.zip".into(),
        bytes: data.to_vec(),
    }];
    match parse_upload(files, &limits, &mut reservation) {
        Ok(clips) => {
            assert!(clips.len() <= limits.max_files);
            // Every clip is an entry of the one zip (skeletons, shared by
            // several clips, are left out of the sum).
            let unpacked: u64 = clips.iter().map(|c| c.source.len() as u64).sum();
            assert!(unpacked <= limits.max_unzipped_bytes);
        }
        Err(e) => assert!(
            e.status().is_client_error() || e.status().as_u16() == 503,
            "upload answered {}: {:?}",
            e.status(),
            e.0.detail
        ),
    }
    assert!(reservation.bytes() <= limits.upload_memory_bytes);
});
