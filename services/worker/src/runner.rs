//! The claim loop: `concurrency` slots, each claiming one job at a time, with a
//! heartbeat task per job that extends the lease, reports progress and learns of
//! cancellation. On shutdown every slot stops claiming; running jobs stop at their
//! next checkpoint and are released to the queue for another worker.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::Duration;

use motionaug_protocol::{ClaimedJob, CompleteRequest, FailRequest, ReleaseRequest, kinds};
use tokio::sync::watch;
use tokio::task::JoinSet;
use tracing::Instrument;

use crate::client::{Coordinator, Reply, with_retries};
use crate::config::WorkerConfig;
use crate::jobs;

/// Job kinds this worker runs.
pub const KINDS: &[&str] = kinds::ALL;

/// How long a claim request may wait for work on the coordinator.
const CLAIM_WAIT: Duration = Duration::from_secs(20);

/// Why a job must stop early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    Cancelled = 1,
    LeaseLost = 2,
    Shutdown = 3,
}

/// Shared between a running job, its heartbeat task and the shutdown watcher.
#[derive(Debug, Default)]
pub struct JobControl {
    stop: AtomicU8,
    progress: AtomicU64,
}

impl JobControl {
    pub fn stop_reason(&self) -> Option<Stop> {
        match self.stop.load(Ordering::SeqCst) {
            1 => Some(Stop::Cancelled),
            2 => Some(Stop::LeaseLost),
            3 => Some(Stop::Shutdown),
            _ => None,
        }
    }

    /// The first reason wins.
    pub fn set_stop(&self, reason: Stop) {
        let _ = self
            .stop
            .compare_exchange(0, reason as u8, Ordering::SeqCst, Ordering::SeqCst);
    }

    pub fn progress(&self) -> f64 {
        f64::from_bits(self.progress.load(Ordering::SeqCst))
    }

    pub fn set_progress(&self, fraction: f64) {
        self.progress
            .store(fraction.clamp(0.0, 1.0).to_bits(), Ordering::SeqCst);
    }
}

/// What a job needs while it runs.
pub struct JobContext {
    pub coordinator: Coordinator,
    pub job: ClaimedJob,
    pub control: Arc<JobControl>,
    pub test_delay: Option<Duration>,
    /// How long to keep retrying a report while the coordinator is unreachable.
    pub patience: Duration,
    /// Local scratch space of jobs (corrections, models).
    pub work_dir: std::path::PathBuf,
    /// How often a correction stores a checkpoint (and uploads it).
    pub checkpoint_every: Duration,
}

/// The result of running a job.
#[derive(Debug)]
pub enum Outcome {
    /// Finished: the output to report.
    Done(serde_json::Value),
    /// Stopped early (see [`JobControl::stop_reason`]).
    Stopped,
}

/// A failed attempt.
#[derive(Debug)]
pub struct JobFailure {
    pub message: String,
    /// `false` when another attempt cannot help (bad input).
    pub retryable: bool,
}

impl JobFailure {
    pub fn permanent(message: impl Into<String>) -> Self {
        JobFailure {
            message: message.into(),
            retryable: false,
        }
    }

    pub fn transient(message: impl Into<String>) -> Self {
        JobFailure {
            message: message.into(),
            retryable: true,
        }
    }
}

/// Runs the worker until `shutdown` resolves and running jobs are handed back.
pub async fn run(
    config: WorkerConfig,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let coordinator = Coordinator::new(&config.coordinator_url, &config.token)?;
    let (stop_tx, stop_rx) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        let _ = stop_tx.send(true);
    });
    tracing::info!(worker = %config.worker_id, coordinator = %config.coordinator_url,
                   concurrency = config.concurrency, "worker started");
    if config.test_delay.is_some() {
        tracing::warn!(
            "MOTIONAUG_WORKER_TEST_DELAY_MS is set: outputs are deliberately slowed (test only)"
        );
    }
    let mut slots = JoinSet::new();
    for slot in 0..config.concurrency {
        slots.spawn(slot_loop(
            coordinator.clone(),
            config.clone(),
            stop_rx.clone(),
            slot,
        ));
    }
    let mut stop_wait = stop_rx.clone();
    let _ = stop_wait.wait_for(|s| *s).await;
    tracing::info!("shutting down: no new jobs; handing running jobs back");
    let drained = tokio::time::timeout(config.shutdown_grace, async {
        while slots.join_next().await.is_some() {}
    })
    .await;
    if drained.is_err() {
        tracing::warn!("shutdown grace period over; leases of unfinished jobs will expire");
    }
    tracing::info!("worker stopped");
    Ok(())
}

async fn slot_loop(
    coordinator: Coordinator,
    config: WorkerConfig,
    mut shutdown: watch::Receiver<bool>,
    slot: usize,
) {
    let mut pause = Duration::from_millis(100);
    loop {
        if *shutdown.borrow() {
            return;
        }
        let claimed = tokio::select! {
            r = coordinator.claim(&config.worker_id, KINDS, CLAIM_WAIT) => r,
            _ = shutdown.changed() => return,
        };
        match claimed {
            Ok(Some(job)) => {
                pause = Duration::from_millis(100);
                run_claimed(&coordinator, &config, job, shutdown.clone()).await;
            }
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(slot, error = %e, "claim failed; retrying");
                tokio::select! {
                    _ = tokio::time::sleep(pause) => {},
                    _ = shutdown.changed() => return,
                }
                pause = (pause * 2).min(Duration::from_secs(5));
            }
        }
    }
}

async fn heartbeat_loop(coordinator: Coordinator, job: ClaimedJob, control: Arc<JobControl>) {
    let mut tick = tokio::time::interval(Duration::from_millis(job.heartbeat_ms.max(20)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.tick().await;
    loop {
        tick.tick().await;
        match coordinator
            .heartbeat(job.id, job.epoch, control.progress())
            .await
        {
            Ok(Reply::Ok(())) => {}
            Ok(Reply::Cancelled) => {
                tracing::info!("job cancelled");
                control.set_stop(Stop::Cancelled);
                return;
            }
            Ok(Reply::LeaseLost) => {
                tracing::warn!("lease lost; abandoning the job");
                control.set_stop(Stop::LeaseLost);
                return;
            }
            Err(e) => tracing::warn!(error = %e, "heartbeat failed; will retry"),
        }
    }
}

async fn run_claimed(
    coordinator: &Coordinator,
    config: &WorkerConfig,
    job: ClaimedJob,
    mut shutdown: watch::Receiver<bool>,
) {
    let span = tracing::info_span!("job", id = %job.id, kind = %job.kind, attempt = job.attempt, epoch = job.epoch);
    async move {
        tracing::info!(resume = job.has_checkpoint, "job started");
        let control = Arc::new(JobControl::default());
        let heartbeats = tokio::spawn(
            heartbeat_loop(coordinator.clone(), job.clone(), control.clone()).in_current_span(),
        );
        let watcher_control = control.clone();
        let watcher = tokio::spawn(async move {
            let _ = shutdown.wait_for(|s| *s).await;
            watcher_control.set_stop(Stop::Shutdown);
        });
        let patience = Duration::from_millis(job.lease_ms.saturating_mul(2)).max(Duration::from_secs(10));
        let ctx = Arc::new(JobContext {
            coordinator: coordinator.clone(),
            job: job.clone(),
            control: control.clone(),
            test_delay: config.test_delay,
            patience,
            work_dir: config.work_dir.clone(),
            checkpoint_every: config.checkpoint_every,
        });
        let result = match job.kind.as_str() {
            other if KINDS.contains(&other) => jobs::run(ctx.clone()).await,
            other => Err(JobFailure::permanent(format!("this worker cannot run jobs of kind `{other}`"))),
        };
        watcher.abort();
        let id = job.id;
        let epoch = job.epoch;
        let reply = match (result, control.stop_reason()) {
            (_, Some(Stop::Cancelled)) | (_, Some(Stop::LeaseLost)) => {
                heartbeats.abort();
                tracing::info!(reason = ?control.stop_reason(), "job dropped");
                return;
            }
            (Ok(Outcome::Done(output)), _) => {
                let body = CompleteRequest { epoch, output };
                let path = format!("/jobs/{id}/complete");
                let r = with_retries("complete", patience, || ctx.coordinator.post(&path, &body))
                .await;
                if r.is_ok() {
                    tracing::info!("job succeeded");
                }
                r
            }
            (Ok(Outcome::Stopped), _) => {
                let body = ReleaseRequest { epoch };
                let path = format!("/jobs/{id}/release");
                let r = with_retries("release", patience, || ctx.coordinator.post(&path, &body))
                .await;
                tracing::info!("job released for another worker");
                r
            }
            (Err(failure), _) => {
                tracing::warn!(error = %failure.message, retryable = failure.retryable, "job failed");
                let body = FailRequest {
                    epoch,
                    error: failure.message,
                    retryable: failure.retryable,
                };
                let path = format!("/jobs/{id}/fail");
                with_retries("fail", patience, || ctx.coordinator.post(&path, &body))
                .await
            }
        };
        heartbeats.abort();
        match reply {
            Ok(Reply::Ok(())) => {}
            Ok(other) => tracing::warn!(answer = ?other, "coordinator refused the report"),
            Err(e) => tracing::warn!(error = %e, "could not report; the lease will expire"),
        }
    }
    .instrument(span)
    .await
}
