//! API tests against the real application, a real Postgres (a fresh database per
//! test, dropped afterwards) and the machine's Redis, one module per resource.
//! One test binary (zero2prod's `tests/api/main.rs` layout), so the service's
//! dependencies are linked once.
//!
//! Jobs are driven through the internal worker API by the test itself, which lets
//! it check the lease rules precisely (stale epochs, duplicate completions,
//! cancellation, retries). Real worker processes are exercised by the worker
//! crate's end-to-end test.

mod augmentations;
mod cli;
mod datasets;
mod errors;
mod health;
mod helpers;
mod jobs;
mod limits;
mod load;
mod memory;
mod openapi;
mod viewer;
