//! `motionaug-coordinator`: see the library crate.

fn main() -> anyhow::Result<()> {
    motionaug_coordinator::cli::main()
}
