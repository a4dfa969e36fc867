//! One module per subcommand: its arguments and its `run`.

pub mod augment;
pub mod bench;
pub mod bench_vae;
pub mod convert;
pub mod correct;
pub mod debias;
pub mod eval;
pub mod inspect;
pub mod interaction;
pub mod metrics;
pub mod predict;
pub mod vae;
pub mod view;
