//! The motionaug coordinator: REST API for tenants, the job queue in Postgres, the
//! internal worker API and live events over Redis.
//!
//! Layout (zero2prod style): [`configuration`] reads the environment, [`telemetry`]
//! sets up JSON logs, [`startup`] wires the database, Redis, metrics and the router
//! into an [`startup::Application`]; [`cli`] is the binary's entry point.

pub mod auth;
pub mod cli;
pub mod configuration;
pub mod error;
pub mod events;
pub mod metrics;
pub mod openapi;
pub mod queue;
pub mod quota;
pub mod routes;
pub mod startup;
pub mod state;
pub mod telemetry;
pub mod upload;
pub mod upload_memory;
