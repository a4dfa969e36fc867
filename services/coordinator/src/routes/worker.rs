//! The internal worker API (`/internal/v1`), authenticated by the worker token.
//!
//! Workers hold no database credentials; everything they do goes through here.
//! Every report carries the job's epoch (lease token): 409 means the lease is no
//! longer the worker's, 410 that the job was cancelled or no longer exists (its
//! dataset was deleted). Either way the worker drops the job.

use std::time::{Duration, Instant};

use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use motionaug_protocol::{
    ClaimRequest, ClaimedJob, CompleteRequest, DepOutput, FailRequest, HeartbeatReply,
    HeartbeatRequest, JobOutput, ReleaseRequest,
};
use serde::Deserialize;
use tokio::sync::broadcast::error::RecvError;
use utoipa::IntoParams;
use uuid::Uuid;

use crate::auth::Worker;
use crate::error::{ApiError, Problem};
use crate::events::Event;
use crate::metrics::{FailureLabel, KindLabel};
use crate::openapi::{Binary, wire};
use crate::queue::{self, Completion, Lease};
use crate::startup::AppState;
use crate::state::JobState;

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct EpochQuery {
    /// The lease epoch of the worker's claim.
    pub epoch: i64,
}

fn refused(state: &AppState, id: Uuid, lease: &Lease) -> ApiError {
    match lease {
        Lease::Cancelled => ApiError::new(
            StatusCode::GONE,
            "Cancelled",
            "the job was cancelled; drop it",
        ),
        Lease::Missing => ApiError::new(
            StatusCode::GONE,
            "Gone",
            format!(
                "there is no job {id}: it was deleted with its dataset, or never existed; drop it"
            ),
        ),
        _ => {
            state.metrics.stale_reports.inc();
            ApiError::conflict("this lease is no longer current; another worker owns the job")
        }
    }
}

fn accept(state: &AppState, id: Uuid, lease: Lease) -> Result<(Uuid, String), ApiError> {
    match lease {
        Lease::Current {
            augmentation_id,
            kind,
            ..
        } => Ok((augmentation_id, kind)),
        other => Err(refused(state, id, &other)),
    }
}

fn valid_worker_id(id: &str) -> Result<(), ApiError> {
    if id.is_empty() || id.len() > 200 || id.chars().any(|c| c.is_control()) {
        return Err(
            ApiError::bad_request("worker_id must be 1 to 200 printable characters")
                .with_field("worker_id"),
        );
    }
    Ok(())
}

/// Worker: claim a job (long poll)
///
/// Holds the request open up to `wait_ms` (capped) until a job of one of `kinds`
/// is runnable. Woken early by `wake` events; polls the database as a fallback.
#[utoipa::path(
    post,
    path = "/internal/v1/jobs/claim",
    operation_id = "claimJob",
    tag = "internal",
    security(("workerToken" = [])),
    request_body = wire::ClaimRequest,
    responses(
        (status = 200, description = "Claimed job with lease epoch", body = wire::ClaimedJob),
        (status = 204, description = "No job became runnable in time"),
        (status = 400, response = Problem),
        (status = 401, response = Problem),
    )
)]
pub async fn claim(
    State(state): State<AppState>,
    _: Worker,
    Json(request): Json<ClaimRequest>,
) -> Result<Response, ApiError> {
    valid_worker_id(&request.worker_id)?;
    let queue_config = &state.config.queue;
    let wait = Duration::from_millis(request.wait_ms).min(queue_config.max_claim_wait);
    let deadline = Instant::now() + wait;
    let mut events = state.events.subscribe();
    queue::touch_worker(&state.db, &request.worker_id).await?;
    loop {
        if let Some(row) = queue::claim(
            &state.db,
            &request.worker_id,
            &request.kinds,
            queue_config.lease,
        )
        .await?
        {
            tracing::info!(job = %row.id, kind = %row.kind, worker = %request.worker_id,
                           attempt = row.attempts, epoch = row.epoch, "job claimed");
            state
                .events
                .publish(Event::Augmentation {
                    id: row.augmentation_id,
                })
                .await;
            let deps = queue::dep_outputs(&state.db, row.id)
                .await?
                .into_iter()
                .map(|(key, kind, output)| DepOutput { key, kind, output })
                .collect();
            let lease_ms = queue_config.lease.as_millis() as u64;
            let job = ClaimedJob {
                id: row.id,
                epoch: row.epoch,
                kind: row.kind,
                attempt: row.attempts,
                input: row.input.0,
                lease_ms,
                heartbeat_ms: (lease_ms / 4).max(50),
                has_checkpoint: row.has_checkpoint,
                deps,
            };
            return Ok(Json(job).into_response());
        }
        let now = Instant::now();
        if now >= deadline {
            return Ok(StatusCode::NO_CONTENT.into_response());
        }
        let nap = (deadline - now).min(queue_config.poll_interval);
        let _ = tokio::time::timeout(nap, async {
            loop {
                match events.recv().await {
                    Ok(Event::Wake { kind }) if request.kinds.contains(&kind) => return,
                    Ok(_) => {}
                    Err(RecvError::Lagged(_)) => return,
                    Err(RecvError::Closed) => std::future::pending::<()>().await,
                }
            }
        })
        .await;
    }
}

/// Worker: extend the lease, report progress; answer says whether the job was cancelled
#[utoipa::path(
    post,
    path = "/internal/v1/jobs/{id}/heartbeat",
    operation_id = "heartbeatJob",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id")),
    request_body = wire::HeartbeatRequest,
    responses(
        (status = 200, description = "ok", body = wire::HeartbeatReply),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn heartbeat(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Json(request): Json<HeartbeatRequest>,
) -> Result<Json<HeartbeatReply>, ApiError> {
    let lease = queue::heartbeat(
        &state.db,
        id,
        request.epoch,
        request.progress,
        state.config.queue.lease,
    )
    .await?;
    match lease {
        Lease::Current {
            augmentation_id, ..
        } => {
            state
                .events
                .publish(Event::Augmentation {
                    id: augmentation_id,
                })
                .await;
            Ok(Json(HeartbeatReply { cancelled: false }))
        }
        Lease::Cancelled => Ok(Json(HeartbeatReply { cancelled: true })),
        Lease::Stale | Lease::Missing => Err(refused(&state, id, &lease)),
    }
}

/// Artifact names: relative paths of `[A-Za-z0-9._-]` segments, no `..`.
fn valid_artifact_name(name: &str) -> Result<(), ApiError> {
    let ok = !name.is_empty()
        && name.len() <= 255
        && name != "manifest.json"
        && name.split('/').all(|seg| {
            !seg.is_empty()
                && seg != "."
                && seg != ".."
                && seg
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
        });
    if ok {
        Ok(())
    } else {
        Err(ApiError::bad_request(format!(
            "`{name}` is not a valid artifact name"
        )))
    }
}

/// Worker: store one result file
///
/// `name` is a relative path of `[A-Za-z0-9._-]` segments; an earlier attempt's
/// file of the same name is replaced.
#[utoipa::path(
    put,
    path = "/internal/v1/jobs/{id}/artifacts/{*name}",
    operation_id = "putArtifact",
    tag = "internal",
    security(("workerToken" = [])),
    params(
        ("id" = Uuid, Path, description = "The job's id"),
        ("name" = String, Path, description = "The file's name"),
        EpochQuery,
    ),
    request_body(content = inline(Binary), content_type = "application/octet-stream"),
    responses(
        (status = 204, description = "Stored"),
        (status = 400, response = Problem),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn put_artifact(
    State(state): State<AppState>,
    _: Worker,
    Path((id, name)): Path<(Uuid, String)>,
    Query(q): Query<EpochQuery>,
    body: Bytes,
) -> Result<StatusCode, ApiError> {
    valid_artifact_name(&name)?;
    let lease = queue::put_artifact(&state.db, id, q.epoch, &name, &body)
        .await
        .map_err(|e| match e {
            sqlx::Error::Protocol(m) => ApiError::conflict(m),
            other => ApiError::from(other),
        })?;
    accept(&state, id, lease)?;
    Ok(StatusCode::NO_CONTENT)
}

/// Worker: store the job's checkpoint
#[utoipa::path(
    put,
    path = "/internal/v1/jobs/{id}/checkpoint",
    operation_id = "putCheckpoint",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id"), EpochQuery),
    request_body(content = inline(Binary), content_type = "application/octet-stream"),
    responses(
        (status = 204, description = "Stored"),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn put_checkpoint(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Query(q): Query<EpochQuery>,
    body: Bytes,
) -> Result<StatusCode, ApiError> {
    let lease = queue::put_checkpoint(&state.db, id, q.epoch, &body).await?;
    accept(&state, id, lease)?;
    Ok(StatusCode::NO_CONTENT)
}

/// Worker: read the job's checkpoint
#[utoipa::path(
    get,
    path = "/internal/v1/jobs/{id}/checkpoint",
    operation_id = "getCheckpoint",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id"), EpochQuery),
    responses(
        (status = 200, description = "bytes", content_type = "application/octet-stream", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn get_checkpoint(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Query(q): Query<EpochQuery>,
) -> Result<Response, ApiError> {
    let (lease, checkpoint) = queue::get_checkpoint(&state.db, id, q.epoch).await?;
    accept(&state, id, lease)?;
    match checkpoint {
        Some(bytes) => Ok(bytes.into_response()),
        None => Err(ApiError::not_found("checkpoint")),
    }
}

/// Worker: report success (idempotent for the same epoch)
///
/// Every file the output names must have been uploaded by the job.
#[utoipa::path(
    post,
    path = "/internal/v1/jobs/{id}/complete",
    operation_id = "completeJob",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id")),
    request_body = wire::CompleteRequest,
    responses(
        (status = 204, description = "Recorded"),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
        (status = 422, response = Problem),
    )
)]
pub async fn complete(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Json(request): Json<CompleteRequest>,
) -> Result<StatusCode, ApiError> {
    let files = check_output(&state, id, &request.output).await?;
    match queue::complete(&state.db, id, request.epoch, &request.output, &files).await? {
        Completion::Accepted(Lease::Current {
            augmentation_id,
            kind,
            claimed_for_s,
        }) => {
            tracing::info!(job = %id, %kind, seconds = claimed_for_s, "job succeeded");
            let label = KindLabel { kind: kind.clone() };
            state.metrics.jobs_completed.get_or_create(&label).inc();
            state
                .metrics
                .job_duration
                .get_or_create(&label)
                .observe(claimed_for_s);
            state
                .events
                .publish(Event::Augmentation {
                    id: augmentation_id,
                })
                .await;
            // Jobs that depend on this one may have become runnable.
            state.events.publish(Event::Wake { kind }).await;
            Ok(StatusCode::NO_CONTENT)
        }
        Completion::Accepted(_) | Completion::Duplicate => Ok(StatusCode::NO_CONTENT),
        Completion::Refused(lease) => Err(refused(&state, id, &lease)),
        Completion::MissingFiles(missing) => Err(ApiError::unprocessable(format!(
            "the output lists files that were not uploaded: {}",
            missing.join(", ")
        ))),
    }
}

/// Checks the output's structure; returns every file it names.
async fn check_output(
    state: &AppState,
    id: Uuid,
    output: &serde_json::Value,
) -> Result<Vec<String>, ApiError> {
    let kind: Option<String> = sqlx::query_scalar("SELECT kind FROM jobs WHERE id = $1")
        .bind(id)
        .fetch_optional(&state.db)
        .await?;
    let Some(kind) = kind else {
        return Ok(Vec::new());
    };
    let output: JobOutput = serde_json::from_value(output.clone())
        .map_err(|e| ApiError::unprocessable(format!("{kind} output: {e}")))?;
    let entries = output
        .manifest
        .iter()
        .enumerate()
        .map(|(i, e)| (format!("manifest[{i}]"), e))
        .chain(
            output
                .clips
                .iter()
                .map(|c| (format!("clips[{}]", c.name), &c.entry)),
        );
    for (at, entry) in entries {
        serde_json::from_value::<pipeline::ManifestEntry>(entry.clone())
            .map_err(|e| ApiError::unprocessable(format!("{kind} output: {at}: {e}")))?;
    }
    let files = output.all_files();
    for (i, name) in files.iter().enumerate() {
        valid_artifact_name(name)?;
        if files[..i].contains(name) {
            return Err(ApiError::unprocessable(format!(
                "{kind} output: `{name}` is listed twice"
            )));
        }
    }
    Ok(files)
}

/// Worker: report a failed attempt (retried with backoff while attempts remain and retryable)
#[utoipa::path(
    post,
    path = "/internal/v1/jobs/{id}/fail",
    operation_id = "failJob",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id")),
    request_body = wire::FailRequest,
    responses(
        (status = 204, description = "Recorded"),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn fail(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Json(request): Json<FailRequest>,
) -> Result<StatusCode, ApiError> {
    let error: String = request.error.chars().take(4000).collect();
    let (lease, new_state) = queue::fail(
        &state.db,
        id,
        request.epoch,
        &error,
        request.retryable,
        state.config.queue.retry_base,
    )
    .await?;
    let (augmentation_id, kind) = accept(&state, id, lease)?;
    tracing::warn!(job = %id, %kind, error = %error, new_state = ?new_state.map(JobState::as_str), "job attempt failed");
    state
        .metrics
        .job_failures
        .get_or_create(&FailureLabel {
            kind,
            reason: "error".into(),
        })
        .inc();
    state
        .events
        .publish(Event::Augmentation {
            id: augmentation_id,
        })
        .await;
    Ok(StatusCode::NO_CONTENT)
}

/// Worker: hand the job back without using an attempt (shutdown)
#[utoipa::path(
    post,
    path = "/internal/v1/jobs/{id}/release",
    operation_id = "releaseJob",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The job's id")),
    request_body = wire::ReleaseRequest,
    responses(
        (status = 204, description = "Released"),
        (status = 401, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn release(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
    Json(request): Json<ReleaseRequest>,
) -> Result<StatusCode, ApiError> {
    let lease = queue::release(&state.db, id, request.epoch).await?;
    let (augmentation_id, kind) = accept(&state, id, lease)?;
    tracing::info!(job = %id, "job released by its worker");
    state
        .events
        .publish(Event::Augmentation {
            id: augmentation_id,
        })
        .await;
    state.events.publish(Event::Wake { kind }).await;
    Ok(StatusCode::NO_CONTENT)
}

/// Worker: read an artifact of one of the jobs this job depends on
///
/// A clip to correct, a correction's checkpoints, the debiasing model: any file
/// its inputs uploaded, for the holder of the current lease.
#[utoipa::path(
    get,
    path = "/internal/v1/jobs/{id}/inputs/{*name}",
    operation_id = "getInput",
    tag = "internal",
    security(("workerToken" = [])),
    params(
        ("id" = Uuid, Path, description = "The job's id"),
        ("name" = String, Path, description = "The artifact's name"),
        EpochQuery,
    ),
    responses(
        (status = 200, description = "bytes", content_type = "application/octet-stream", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
        (status = 409, response = Problem),
        (status = 410, response = Problem),
    )
)]
pub async fn get_input(
    State(state): State<AppState>,
    _: Worker,
    Path((id, name)): Path<(Uuid, String)>,
    Query(q): Query<EpochQuery>,
) -> Result<Response, ApiError> {
    let (lease, content) = queue::get_input(&state.db, id, q.epoch, &name).await?;
    accept(&state, id, lease)?;
    match content {
        Some(bytes) => Ok(bytes.into_response()),
        None => Err(ApiError::not_found("input")),
    }
}

/// Worker: the clip's original file
#[utoipa::path(
    get,
    path = "/internal/v1/clips/{id}/source",
    operation_id = "getClipSource",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The clip's id")),
    responses(
        (status = 200, description = "bytes", content_type = "application/octet-stream", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn clip_source(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
) -> Result<Response, ApiError> {
    let bytes: Option<Vec<u8>> = sqlx::query_scalar("SELECT source FROM clips WHERE id = $1")
        .bind(id)
        .fetch_optional(&state.db)
        .await?;
    bytes
        .map(IntoResponse::into_response)
        .ok_or_else(|| ApiError::not_found("clip"))
}

/// Worker: the ASF of an AMC clip
#[utoipa::path(
    get,
    path = "/internal/v1/clips/{id}/skeleton",
    operation_id = "getClipSkeleton",
    tag = "internal",
    security(("workerToken" = [])),
    params(("id" = Uuid, Path, description = "The clip's id")),
    responses(
        (status = 200, description = "bytes", content_type = "application/octet-stream", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn clip_skeleton(
    State(state): State<AppState>,
    _: Worker,
    Path(id): Path<Uuid>,
) -> Result<Response, ApiError> {
    let bytes: Option<Option<Vec<u8>>> =
        sqlx::query_scalar("SELECT skeleton FROM clips WHERE id = $1")
            .bind(id)
            .fetch_optional(&state.db)
            .await?;
    bytes
        .flatten()
        .map(IntoResponse::into_response)
        .ok_or_else(|| ApiError::not_found("clip skeleton"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn artifact_names_are_checked() {
        assert!(valid_artifact_name("walk_noise_0.bvh").is_ok());
        assert!(valid_artifact_name("masks/walk_mask_0.json").is_ok());
        assert!(valid_artifact_name("../etc/passwd").is_err());
        assert!(valid_artifact_name("a//b").is_err());
        assert!(valid_artifact_name("manifest.json").is_err());
        assert!(valid_artifact_name("x y").is_err());
    }
}
