//! The `motionaug-coordinator` binary's command line.

use std::process::Command;

/// `--help` and `--version` print and exit at once, even without any
/// configuration (no DATABASE_URL, no worker token).
#[test]
fn help_and_version_print_and_exit() {
    let binary = env!("CARGO_BIN_EXE_motionaug-coordinator");
    for (arg, expected) in [
        ("--help", "Usage: motionaug-coordinator"),
        ("-h", "Usage: motionaug-coordinator"),
        (
            "--version",
            concat!("motionaug-coordinator ", env!("CARGO_PKG_VERSION")),
        ),
        ("-V", "motionaug-coordinator "),
    ] {
        let out = Command::new(binary)
            .arg(arg)
            .env_clear()
            .output()
            .expect("the coordinator binary runs");
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{arg}: {out:?}");
        assert!(stdout.contains(expected), "{arg}: {stdout}");
    }
    let out = Command::new(binary)
        .arg("--no-such-flag")
        .env_clear()
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
}
