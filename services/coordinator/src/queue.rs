//! The job queue: every state change of a job is one short Postgres transaction.
//!
//! * Claiming picks the oldest runnable job with `FOR UPDATE SKIP LOCKED`, so any
//!   number of coordinators and workers can claim at once without blocking each
//!   other, and gives it a lease and a new epoch (the lease token).
//! * Every report from a worker (heartbeat, artifact, checkpoint, completion,
//!   failure, release) locks the job row and is accepted only while the job is
//!   `running` under the same epoch. A late report from an expired lease is refused.
//! * The reaper returns jobs whose lease expired to the queue (or fails them once
//!   they used all their attempts); a re-run resumes from the stored checkpoint.
//! * A job runs once every job it depends on succeeded; when one fails for good,
//!   every job waiting for it fails too, naming it.
//!
//! States are bound as [`JobState`] values, except in the two predicates that the
//! partial indexes `jobs_queued` and `jobs_leases` serve: Postgres uses a partial
//! index only for a query whose text names the index's state, and a bound
//! parameter would let a cached generic plan fall back to scanning every job.

use std::time::Duration;

use serde_json::Value;
use sha2::{Digest, Sha256};
use sqlx::types::Json;
use sqlx::{PgPool, Postgres, Transaction};
use uuid::Uuid;

use crate::state::JobState;

/// States a job can still leave on its own (it has not finished).
const UNFINISHED: &[JobState] = &[JobState::Queued, JobState::Running];

/// A job handed to a worker.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ClaimedRow {
    pub id: Uuid,
    pub augmentation_id: Uuid,
    pub kind: String,
    pub epoch: i64,
    pub attempts: i32,
    pub input: Json<Value>,
    pub has_checkpoint: bool,
}

/// Where a worker's report stands against the job's current lease.
#[derive(Debug, Clone, PartialEq)]
pub enum Lease {
    /// The job is running under this epoch: the report is accepted.
    Current {
        augmentation_id: Uuid,
        kind: String,
        claimed_for_s: f64,
    },
    /// The job was cancelled: stop working on it.
    Cancelled,
    /// There is no such job (its dataset was deleted, or it never existed):
    /// stop working on it.
    Missing,
    /// The lease is no longer this worker's (expired and re-claimed, or finished).
    Stale,
}

/// Backoff before the next attempt after `attempts` failed ones.
pub fn backoff(base: Duration, attempts: i32) -> Duration {
    let exp = attempts.clamp(1, 20) as u32 - 1;
    base.saturating_mul(1u32 << exp.min(16))
        .min(Duration::from_secs(300))
}

/// Claims the oldest runnable job of one of `kinds` for `worker_id`.
pub async fn claim(
    db: &PgPool,
    worker_id: &str,
    kinds: &[String],
    lease: Duration,
) -> Result<Option<ClaimedRow>, sqlx::Error> {
    sqlx::query_as(
        "WITH next AS (
             SELECT j.id FROM jobs j
             -- 'queued' is a literal for the partial index jobs_queued (module docs).
             WHERE j.state = 'queued' AND j.run_after <= now() AND j.kind = ANY($1)
               AND NOT EXISTS (
                   SELECT 1 FROM job_dependencies d JOIN jobs p ON p.id = d.depends_on
                   WHERE d.job_id = j.id AND p.state <> $4)
             ORDER BY j.seq
             LIMIT 1
             FOR UPDATE OF j SKIP LOCKED)
         UPDATE jobs SET state = $5, attempts = jobs.attempts + 1, epoch = jobs.epoch + 1,
                worker_id = $2, claimed_at = now(),
                lease_expires_at = now() + make_interval(secs => $3)
         FROM next WHERE jobs.id = next.id
         RETURNING jobs.id, jobs.augmentation_id, jobs.kind, jobs.epoch, jobs.attempts,
                   jobs.input, jobs.checkpoint IS NOT NULL AS has_checkpoint",
    )
    .bind(kinds)
    .bind(worker_id)
    .bind(lease.as_secs_f64())
    .bind(JobState::Succeeded)
    .bind(JobState::Running)
    .fetch_optional(db)
    .await
}

/// The outputs of the jobs `id` depends on: (key, kind, output).
pub async fn dep_outputs(
    db: &PgPool,
    id: Uuid,
) -> Result<Vec<(String, String, Value)>, sqlx::Error> {
    let rows: Vec<(String, String, Option<Json<Value>>)> = sqlx::query_as(
        "SELECT p.key, p.kind, p.output FROM job_dependencies d JOIN jobs p ON p.id = d.depends_on
         WHERE d.job_id = $1 ORDER BY p.seq",
    )
    .bind(id)
    .fetch_all(db)
    .await?;
    Ok(rows
        .into_iter()
        .map(|(k, kind, o)| (k, kind, o.map_or(Value::Null, |o| o.0)))
        .collect())
}

/// An artifact named `name` of one of the jobs `id` depends on, for the current lease.
pub async fn get_input(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    name: &str,
) -> Result<(Lease, Option<Vec<u8>>), sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    let mut content = None;
    if matches!(status, Lease::Current { .. }) {
        content = sqlx::query_scalar(
            "SELECT a.content FROM artifacts a
             JOIN job_dependencies d ON d.depends_on = a.job_id
             WHERE d.job_id = $1 AND a.name = $2",
        )
        .bind(id)
        .bind(name)
        .fetch_optional(&mut *tx)
        .await?;
    }
    tx.commit().await?;
    Ok((status, content))
}

/// Fails every job that (transitively) waits for `failed`, which failed for
/// good: they can never run. Returns how many.
async fn fail_dependents(
    tx: &mut Transaction<'_, Postgres>,
    failed: Uuid,
) -> Result<u64, sqlx::Error> {
    Ok(sqlx::query(
        "WITH RECURSIVE down(id) AS (
             SELECT job_id FROM job_dependencies WHERE depends_on = $1
             UNION
             SELECT d.job_id FROM job_dependencies d JOIN down ON d.depends_on = down.id)
         UPDATE jobs SET state = $2, finished_at = now(), lease_expires_at = NULL,
                error = 'not run: its input ' || (SELECT key FROM jobs WHERE id = $1) || ' failed'
         WHERE id IN (SELECT id FROM down) AND state = ANY($3)",
    )
    .bind(failed)
    .bind(JobState::Failed)
    .bind(UNFINISHED)
    .execute(&mut **tx)
    .await?
    .rows_affected())
}

/// Records that a worker is alive (for the worker-count metric).
pub async fn touch_worker(db: &PgPool, worker_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO workers (id) VALUES ($1)
         ON CONFLICT (id) DO UPDATE SET last_seen = now()",
    )
    .bind(worker_id)
    .execute(db)
    .await?;
    Ok(())
}

/// Locks the job row and compares its lease with `epoch`.
async fn check_lease(
    tx: &mut Transaction<'_, Postgres>,
    id: Uuid,
    epoch: i64,
) -> Result<Lease, sqlx::Error> {
    let row: Option<(JobState, i64, Uuid, String, f64)> = sqlx::query_as(
        "SELECT state, epoch, augmentation_id, kind,
                COALESCE(EXTRACT(EPOCH FROM now() - claimed_at)::float8, 0)
         FROM jobs WHERE id = $1 FOR UPDATE",
    )
    .bind(id)
    .fetch_optional(&mut **tx)
    .await?;
    Ok(match row {
        None => Lease::Missing,
        Some((JobState::Cancelled, ..)) => Lease::Cancelled,
        Some((JobState::Running, current, augmentation_id, kind, claimed_for_s))
            if current == epoch =>
        {
            Lease::Current {
                augmentation_id,
                kind,
                claimed_for_s,
            }
        }
        Some(_) => Lease::Stale,
    })
}

/// Extends the lease and stores progress.
pub async fn heartbeat(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    progress: f64,
    lease: Duration,
) -> Result<Lease, sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    if matches!(status, Lease::Current { .. }) {
        sqlx::query(
            "UPDATE jobs SET lease_expires_at = now() + make_interval(secs => $2),
                    progress = GREATEST(0, LEAST(1, $3))
             WHERE id = $1",
        )
        .bind(id)
        .bind(lease.as_secs_f64())
        .bind(if progress.is_finite() { progress } else { 0.0 })
        .execute(&mut *tx)
        .await?;
        sqlx::query(
            "UPDATE workers SET last_seen = now()
             WHERE id = (SELECT worker_id FROM jobs WHERE id = $1)",
        )
        .bind(id)
        .execute(&mut *tx)
        .await?;
    }
    tx.commit().await?;
    Ok(status)
}

/// Stores one result file of the job (replacing the same name from an earlier
/// attempt of the same job).
pub async fn put_artifact(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    name: &str,
    content: &[u8],
) -> Result<Lease, sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    if let Lease::Current {
        augmentation_id, ..
    } = &status
    {
        let hash = Sha256::digest(content).to_vec();
        let inserted = sqlx::query(
            "INSERT INTO artifacts (id, job_id, augmentation_id, name, content, sha256, epoch)
             VALUES ($1, $2, $3, $4, $5, $6, $7)
             ON CONFLICT (augmentation_id, name) DO UPDATE
                SET content = EXCLUDED.content, sha256 = EXCLUDED.sha256, epoch = EXCLUDED.epoch
                WHERE artifacts.job_id = EXCLUDED.job_id",
        )
        .bind(Uuid::new_v4())
        .bind(id)
        .bind(augmentation_id)
        .bind(name)
        .bind(content)
        .bind(hash)
        .bind(epoch)
        .execute(&mut *tx)
        .await?;
        if inserted.rows_affected() == 0 {
            // Another job of the augmentation already owns this file name.
            tx.rollback().await?;
            return Err(sqlx::Error::Protocol(format!(
                "artifact name `{name}` is already used by another job of this augmentation"
            )));
        }
    }
    tx.commit().await?;
    Ok(status)
}

pub async fn put_checkpoint(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    content: &[u8],
) -> Result<Lease, sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    if matches!(status, Lease::Current { .. }) {
        sqlx::query("UPDATE jobs SET checkpoint = $2 WHERE id = $1")
            .bind(id)
            .bind(content)
            .execute(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    Ok(status)
}

/// The checkpoint, for the worker holding the current lease.
pub async fn get_checkpoint(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
) -> Result<(Lease, Option<Vec<u8>>), sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    let mut checkpoint = None;
    if matches!(status, Lease::Current { .. }) {
        checkpoint = sqlx::query_scalar("SELECT checkpoint FROM jobs WHERE id = $1")
            .bind(id)
            .fetch_one(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    Ok((status, checkpoint))
}

/// What became of a completion report.
#[derive(Debug, Clone, PartialEq)]
pub enum Completion {
    /// The job is now succeeded (this report did it).
    Accepted(Lease),
    /// The same lease already completed the job: nothing changed.
    Duplicate,
    /// The report was refused (lease stale or job cancelled).
    Refused(Lease),
    /// The output names files the job never uploaded.
    MissingFiles(Vec<String>),
}

/// Marks the job succeeded with its output. A repeated report of the same epoch
/// after success is answered as success without changing anything.
pub async fn complete(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    output: &Value,
    files: &[String],
) -> Result<Completion, sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    let outcome = match status {
        Lease::Current { .. } => {
            let stored: Vec<String> = sqlx::query_scalar(
                "SELECT name FROM artifacts WHERE job_id = $1 AND name = ANY($2)",
            )
            .bind(id)
            .bind(files)
            .fetch_all(&mut *tx)
            .await?;
            let missing: Vec<String> = files
                .iter()
                .filter(|f| !stored.contains(f))
                .cloned()
                .collect();
            if !missing.is_empty() {
                tx.rollback().await?;
                return Ok(Completion::MissingFiles(missing));
            }
            sqlx::query(
                "UPDATE jobs SET state = $3, output = $2, progress = 1, error = NULL,
                        lease_expires_at = NULL, finished_at = now(),
                        completions = completions + 1
                 WHERE id = $1",
            )
            .bind(id)
            .bind(Json(output))
            .bind(JobState::Succeeded)
            .execute(&mut *tx)
            .await?;
            Completion::Accepted(status)
        }
        Lease::Stale => {
            let row: Option<(JobState, i64)> =
                sqlx::query_as("SELECT state, epoch FROM jobs WHERE id = $1")
                    .bind(id)
                    .fetch_optional(&mut *tx)
                    .await?;
            if row == Some((JobState::Succeeded, epoch)) {
                Completion::Duplicate
            } else {
                Completion::Refused(Lease::Stale)
            }
        }
        Lease::Cancelled | Lease::Missing => Completion::Refused(status),
    };
    tx.commit().await?;
    Ok(outcome)
}

/// Records a failed attempt: back to the queue with backoff while attempts remain
/// and the error is retryable, else failed for good. Returns the new state.
pub async fn fail(
    db: &PgPool,
    id: Uuid,
    epoch: i64,
    error: &str,
    retryable: bool,
    retry_base: Duration,
) -> Result<(Lease, Option<JobState>), sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    let mut new_state = None;
    if matches!(status, Lease::Current { .. }) {
        let (attempts, max_attempts): (i32, i32) =
            sqlx::query_as("SELECT attempts, max_attempts FROM jobs WHERE id = $1")
                .bind(id)
                .fetch_one(&mut *tx)
                .await?;
        let retry = retryable && attempts < max_attempts;
        let state = if retry {
            JobState::Queued
        } else {
            JobState::Failed
        };
        sqlx::query(
            "UPDATE jobs SET state = $2, error = $3, worker_id = NULL, lease_expires_at = NULL,
                    run_after = now() + make_interval(secs => $4),
                    finished_at = CASE WHEN $5 THEN now() END
             WHERE id = $1",
        )
        .bind(id)
        .bind(state)
        .bind(error)
        .bind(backoff(retry_base, attempts).as_secs_f64())
        .bind(state == JobState::Failed)
        .execute(&mut *tx)
        .await?;
        if state == JobState::Failed {
            fail_dependents(&mut tx, id).await?;
        }
        new_state = Some(state);
    }
    tx.commit().await?;
    Ok((status, new_state))
}

/// Gives the job back to the queue without using up an attempt (graceful shutdown).
pub async fn release(db: &PgPool, id: Uuid, epoch: i64) -> Result<Lease, sqlx::Error> {
    let mut tx = db.begin().await?;
    let status = check_lease(&mut tx, id, epoch).await?;
    if matches!(status, Lease::Current { .. }) {
        sqlx::query(
            "UPDATE jobs SET state = $2, attempts = GREATEST(attempts - 1, 0),
                    worker_id = NULL, lease_expires_at = NULL, run_after = now()
             WHERE id = $1",
        )
        .bind(id)
        .bind(JobState::Queued)
        .execute(&mut *tx)
        .await?;
    }
    tx.commit().await?;
    Ok(status)
}

/// A job whose lease expired, after the reaper dealt with it.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct Reaped {
    pub id: Uuid,
    pub augmentation_id: Uuid,
    pub kind: String,
    pub state: JobState,
}

/// Returns jobs with an expired lease to the queue (or fails them when they have
/// used all their attempts). Safe to run from every coordinator at once.
pub async fn reap(db: &PgPool, retry_base: Duration) -> Result<Vec<Reaped>, sqlx::Error> {
    let mut tx = db.begin().await?;
    let reaped: Vec<Reaped> = sqlx::query_as(
        "WITH expired AS (
             SELECT id FROM jobs
             -- 'running' is a literal for the partial index jobs_leases (module docs).
             WHERE state = 'running' AND lease_expires_at < now()
             FOR UPDATE SKIP LOCKED)
         UPDATE jobs SET
             state = CASE WHEN attempts >= max_attempts THEN $2 ELSE $3 END,
             error = 'lease expired: worker ' || COALESCE(worker_id, '?')
                     || ' stopped sending heartbeats (attempt ' || attempts || ')',
             worker_id = NULL, lease_expires_at = NULL,
             run_after = now() + make_interval(secs => $1 * power(2, LEAST(attempts, 17) - 1)),
             finished_at = CASE WHEN attempts >= max_attempts THEN now() END
         FROM expired WHERE jobs.id = expired.id
         RETURNING jobs.id, jobs.augmentation_id, jobs.kind, jobs.state",
    )
    .bind(retry_base.as_secs_f64())
    .bind(JobState::Failed)
    .bind(JobState::Queued)
    .fetch_all(&mut *tx)
    .await?;
    for job in reaped.iter().filter(|j| j.state == JobState::Failed) {
        fail_dependents(&mut tx, job.id).await?;
    }
    tx.commit().await?;
    Ok(reaped)
}

/// Cancels every unfinished job of the augmentation; returns how many changed.
pub async fn cancel_augmentation(db: &PgPool, augmentation_id: Uuid) -> Result<u64, sqlx::Error> {
    let mut tx = db.begin().await?;
    sqlx::query(
        "UPDATE augmentations SET cancelled_at = COALESCE(cancelled_at, now()) WHERE id = $1",
    )
    .bind(augmentation_id)
    .execute(&mut *tx)
    .await?;
    let changed = sqlx::query(
        "UPDATE jobs SET state = $2, lease_expires_at = NULL, finished_at = now()
         WHERE augmentation_id = $1 AND state = ANY($3)",
    )
    .bind(augmentation_id)
    .bind(JobState::Cancelled)
    .bind(UNFINISHED)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    tx.commit().await?;
    Ok(changed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_and_is_capped() {
        let base = Duration::from_millis(100);
        assert_eq!(backoff(base, 1), Duration::from_millis(100));
        assert_eq!(backoff(base, 2), Duration::from_millis(200));
        assert_eq!(backoff(base, 4), Duration::from_millis(800));
        assert_eq!(backoff(base, 100), Duration::from_secs(300));
        assert_eq!(backoff(base, 0), Duration::from_millis(100));
    }
}
