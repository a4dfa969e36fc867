//! Moving bytes between a running job and the coordinator: downloads and
//! uploads with retries, and turning the coordinator's "cancelled" / "lease
//! lost" answers into the job's stop reason, so every caller stops the same way.

use std::time::{Duration, Instant};

use crate::client::{Reply, with_retries};
use crate::runner::{JobContext, JobFailure, Stop};

/// Turns a reply into "go on" or "stop"; records why the job must stop.
pub(crate) fn proceed(ctx: &JobContext, reply: Reply<()>) -> bool {
    match reply {
        Reply::Ok(()) => true,
        Reply::Cancelled => {
            ctx.control.set_stop(Stop::Cancelled);
            false
        }
        Reply::LeaseLost => {
            ctx.control.set_stop(Stop::LeaseLost);
            false
        }
    }
}

pub(crate) async fn fetch(
    ctx: &JobContext,
    path: &str,
) -> Result<Option<Option<Vec<u8>>>, JobFailure> {
    let reply = with_retries(path, ctx.patience, || ctx.coordinator.get(path))
        .await
        .map_err(|e| JobFailure::transient(e.to_string()))?;
    Ok(match reply {
        Reply::Ok(bytes) => Some(bytes),
        other => {
            proceed(ctx, other.clone_unit());
            None
        }
    })
}

trait CloneUnit {
    fn clone_unit(&self) -> Reply<()>;
}

impl<T> CloneUnit for Reply<T> {
    fn clone_unit(&self) -> Reply<()> {
        match self {
            Reply::Ok(_) => Reply::Ok(()),
            Reply::LeaseLost => Reply::LeaseLost,
            Reply::Cancelled => Reply::Cancelled,
        }
    }
}

pub(crate) async fn upload(
    ctx: &JobContext,
    path: &str,
    body: Vec<u8>,
) -> Result<bool, JobFailure> {
    let reply = with_retries(path, ctx.patience, || {
        ctx.coordinator.put(path, body.clone())
    })
    .await
    .map_err(|e| JobFailure::transient(e.to_string()))?;
    Ok(proceed(ctx, reply))
}

/// Sleeps for the test-only delay, in small steps so a stop is noticed promptly.
pub(crate) async fn test_pause(ctx: &JobContext) {
    let Some(delay) = ctx.test_delay else { return };
    let until = Instant::now() + delay;
    while Instant::now() < until && ctx.control.stop_reason().is_none() {
        tokio::time::sleep(Duration::from_millis(10).min(until - Instant::now())).await;
    }
}
