//! One module per subcommand: its arguments and its `run`.

pub mod augment;
pub mod convert;
pub mod inspect;
pub mod interaction;
pub mod metrics;
