//! Running the `motionaug` binary from the integration tests (one copy shared
//! by every test file of this crate).
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The workspace root (where `examples/` lives).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

pub fn example(name: &str) -> PathBuf {
    root().join("examples/data").join(name)
}

/// Run `motionaug ARGS` in the workspace root.
pub fn motionaug(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_motionaug"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the motionaug binary runs")
}

/// Assert success; the standard output.
pub fn ok(output: Output) -> String {
    assert!(
        output.status.success(),
        "motionaug failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).expect("stdout is UTF-8")
}

/// Assert failure; the standard error.
pub fn failed(output: Output) -> String {
    assert!(!output.status.success(), "motionaug should have failed");
    String::from_utf8_lossy(&output.stderr).into_owned()
}
