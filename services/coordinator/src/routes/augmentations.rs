//! `/v1/augmentations`: start one over a dataset (the job graph of
//! `pipeline::plan`), follow it
//! (status, server-sent events), download its results, cancel it.

use std::collections::{BTreeMap, HashMap};
use std::convert::Infallible;
use std::io::Write;
use std::time::Duration;

use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use futures_util::Stream;
use motionaug_protocol::{ClipFormat, ClipRef, JobOutput, PipelineInput};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use tokio::sync::broadcast::error::RecvError;
use utoipa::{IntoParams, ToSchema};
use uuid::Uuid;

use crate::auth::Tenant;
use crate::error::{ApiError, Problem};
use crate::events::Event;
use crate::openapi::{Binary, Recipe};
use crate::routes::datasets;
use crate::startup::AppState;
use crate::state::{AugmentationState, JobCounts, JobState};
use crate::{queue, quota};

/// A job that failed for good.
#[derive(Debug, Serialize, Clone, PartialEq, ToSchema)]
pub struct JobError {
    pub job: Uuid,
    /// The job's key in the graph, e.g. `correct:walk__00_noise_000`.
    pub key: String,
    /// The clip the job was about, when there is one.
    pub clip: Option<String>,
    pub error: String,
}

/// An augmentation's state, progress and job counts.
#[derive(Debug, Serialize, Clone, PartialEq, ToSchema)]
#[schema(as = Augmentation)]
pub struct AugmentationStatus {
    pub id: Uuid,
    pub dataset_id: Uuid,
    pub status: AugmentationState,
    /// Fraction done: succeeded jobs count whole, running ones by their progress.
    #[schema(minimum = 0, maximum = 1)]
    pub progress: f64,
    pub jobs: JobCounts,
    /// Jobs of each kind: synthesize, vae, interaction, tracker,
    /// variant_tracker, correct_original, correct, debias_train, debias_apply.
    pub kinds: BTreeMap<String, i64>,
    pub errors: Vec<JobError>,
    pub created_at: DateTime<Utc>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct AugmentationList {
    pub augmentations: Vec<AugmentationStatus>,
}

/// The augmentation a request started or cancelled.
#[derive(Debug, Serialize, ToSchema)]
pub struct AugmentationRef {
    pub id: Uuid,
    /// Its state right after the request.
    pub status: AugmentationState,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CreateQuery {
    /// Overrides the recipe's seed (like the CLI's `--seed`).
    pub seed: Option<u64>,
}

/// The JSON recipe, checked with the same parser the CLI uses.
fn check_recipe(body: &Bytes) -> Result<(Value, pipeline::Recipe), ApiError> {
    let value: Value = serde_json::from_slice(body).map_err(|e| {
        ApiError::unprocessable(format!(
            "recipe: not valid JSON at line {}, column {}: {e}",
            e.line(),
            e.column()
        ))
        .with_file("recipe")
        .with_line(Some(e.line()))
    })?;
    let recipe = motionaug_protocol::recipe::parse(&value).map_err(|e| {
        let mut err = ApiError::unprocessable(format!("recipe: {}", e.message)).with_file("recipe");
        if let Some(field) = e.field {
            err = err.with_field(field);
        }
        err
    })?;
    Ok((value, recipe))
}

/// A stored clip as the graph needs it.
type ClipRow = (Uuid, String, String, String, Option<String>);

fn clip_ref((clip_id, clip_name, format, source_name, skeleton_name): &ClipRow) -> ClipRef {
    ClipRef {
        clip_id: *clip_id,
        clip_name: clip_name.clone(),
        source_name: source_name.clone(),
        skeleton_name: skeleton_name.clone(),
        format: match format.as_str() {
            "amc" => ClipFormat::Amc,
            "npz" => ClipFormat::Npz,
            _ => ClipFormat::Bvh,
        },
    }
}

/// One job to insert: key, kind, input, keys of the jobs it waits for.
struct NewJob {
    key: String,
    kind: &'static str,
    input: Value,
    deps: Vec<String>,
}

/// The augmentation's jobs: `pipeline::plan` as planned (each job carries its
/// settings), with the stored clips each job reads.
fn graph(recipe: &pipeline::Recipe, clips: &[ClipRow], seed: u64) -> Result<Vec<NewJob>, ApiError> {
    let names: Vec<String> = clips.iter().map(|c| c.1.clone()).collect();
    let plan = pipeline::plan(recipe, &names, seed);
    let by_name: HashMap<&str, &ClipRow> = clips.iter().map(|c| (c.1.as_str(), c)).collect();
    plan.jobs
        .into_iter()
        .map(|planned| {
            let clips = planned
                .kind
                .sources()
                .into_iter()
                .map(|n| {
                    by_name
                        .get(n)
                        .map(|row| clip_ref(row))
                        .ok_or_else(|| ApiError::internal(format!("the plan names no clip `{n}`")))
                })
                .collect::<Result<Vec<_>, _>>()?;
            let input = PipelineInput {
                clip_name: planned.kind.clip().map(str::to_string),
                clips,
                job: planned.clone(),
            };
            Ok(NewJob {
                key: planned.key,
                kind: planned.kind.name(),
                input: to_json(&input)?,
                deps: planned.deps,
            })
        })
        .collect()
}

fn to_json<T: Serialize>(value: &T) -> Result<Value, ApiError> {
    serde_json::to_value(value).map_err(|e| ApiError::internal(e.to_string()))
}

/// Start an augmentation: the job graph of the recipe over the dataset's clips
///
/// Synthesis, VAE sampling, interaction variants, physical correction and
/// debiasing, as `motionaug augment` runs them.
#[utoipa::path(
    post,
    path = "/v1/datasets/{id}/augmentations",
    operation_id = "createAugmentation",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The dataset's id"), CreateQuery),
    request_body(content = Recipe),
    responses(
        (status = 202, description = "Queued", body = AugmentationRef,
            headers(("Location" = String, description = "The augmentation's URL"))),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
        (status = 413, response = Problem),
        (status = 422, response = Problem),
        (status = 429, response = Problem),
    )
)]
pub async fn create(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(dataset_id): Path<Uuid>,
    Query(query): Query<CreateQuery>,
    body: Bytes,
) -> Result<Response, ApiError> {
    datasets::find(&state, &tenant, dataset_id).await?;
    let (recipe_value, recipe) = check_recipe(&body)?;
    let seed = recipe.effective_seed(query.seed);
    let clips: Vec<ClipRow> = sqlx::query_as(
        "SELECT id, name, format, source_name, skeleton_name FROM clips
         WHERE dataset_id = $1 ORDER BY position",
    )
    .bind(dataset_id)
    .fetch_all(&state.db)
    .await?;
    // Sized before it is planned: a recipe over the quota is never planned.
    let names: Vec<String> = clips.iter().map(|c| c.1.clone()).collect();
    let size = pipeline::plan::size(&recipe, &names);
    let correction_seconds = recipe.correct.as_ref().map_or(0.0, |c| {
        size.corrections as f64 * c.time_budget_s + size.trackers as f64 * c.tracker_budget_s
    });
    let quotas = &state.config.quotas;
    quota::check_augmentation_size(quotas, size.outputs, correction_seconds)?;
    let jobs = graph(&recipe, &clips, seed)?;
    if jobs.is_empty() {
        return Err(ApiError::unprocessable(
            "recipe: makes nothing from this dataset (no clip class has `[vae] min_clips` clips, \
             or no `<stem>_A` / `<stem>_B` pair for `[interaction]`)",
        )
        .with_file("recipe"));
    }
    let mut kinds: BTreeMap<&'static str, i64> = BTreeMap::new();
    for job in &jobs {
        *kinds.entry(job.kind).or_default() += 1;
    }
    let id = Uuid::new_v4();
    let mut tx = state.db.begin().await?;
    quota::lock_tenant(&mut tx, tenant.id).await?;
    let usage = quota::usage(&mut *tx, tenant.id).await?;
    quota::check_new_augmentation(quotas, &usage, correction_seconds)?;
    sqlx::query(
        "INSERT INTO augmentations (id, tenant_id, dataset_id, recipe, seed, kinds, outputs,
                                    correction_seconds)
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(id)
    .bind(tenant.id)
    .bind(dataset_id)
    .bind(sqlx::types::Json(&recipe_value))
    .bind(seed as i64)
    .bind(sqlx::types::Json(&kinds))
    .bind(size.outputs as i64)
    .bind(correction_seconds)
    .execute(&mut *tx)
    .await?;
    let job_count = jobs.len();
    insert_jobs(&mut tx, id, jobs, state.config.queue.max_attempts).await?;
    tx.commit().await?;
    tracing::info!(tenant = %tenant.name, augmentation = %id, dataset = %dataset_id,
                   jobs = job_count, "augmentation queued");
    for kind in kinds.keys() {
        state
            .events
            .publish(Event::Wake {
                kind: kind.to_string(),
            })
            .await;
    }
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/v1/augmentations/{id}"))],
        Json(AugmentationRef {
            id,
            status: AugmentationState::Queued,
        }),
    )
        .into_response())
}

/// Jobs inserted per statement.
const JOBS_PER_INSERT: usize = 1000;

/// Inserts the graph's jobs (in plan order, which is their queue order) and
/// their dependency edges, a thousand per statement.
async fn insert_jobs(
    tx: &mut sqlx::Transaction<'_, sqlx::Postgres>,
    augmentation_id: Uuid,
    jobs: Vec<NewJob>,
    max_attempts: i32,
) -> Result<(), ApiError> {
    let ids: HashMap<&str, Uuid> = jobs
        .iter()
        .map(|job| (job.key.as_str(), Uuid::new_v4()))
        .collect();
    let id_of = |key: &str| {
        ids.get(key)
            .copied()
            .ok_or_else(|| ApiError::internal(format!("the plan names no job `{key}`")))
    };
    for chunk in jobs.chunks(JOBS_PER_INSERT) {
        let job_ids = chunk
            .iter()
            .map(|j| id_of(&j.key))
            .collect::<Result<Vec<_>, _>>()?;
        let keys: Vec<&str> = chunk.iter().map(|j| j.key.as_str()).collect();
        let kinds: Vec<&str> = chunk.iter().map(|j| j.kind).collect();
        let inputs: Vec<&Value> = chunk.iter().map(|j| &j.input).collect();
        sqlx::query(
            "INSERT INTO jobs (id, augmentation_id, key, kind, state, input, max_attempts)
             SELECT t.id, $1, t.key, t.kind, $2, i.input, $3
             FROM unnest($4::uuid[], $5::text[], $6::text[]) WITH ORDINALITY AS t (id, key, kind, n)
             JOIN jsonb_array_elements($7::jsonb) WITH ORDINALITY AS i (input, n) ON i.n = t.n
             ORDER BY t.n",
        )
        .bind(augmentation_id)
        .bind(JobState::Queued)
        .bind(max_attempts)
        .bind(&job_ids)
        .bind(&keys)
        .bind(&kinds)
        .bind(sqlx::types::Json(&inputs))
        .execute(&mut **tx)
        .await?;
        let mut from = Vec::new();
        let mut to = Vec::new();
        for (job, job_id) in chunk.iter().zip(&job_ids) {
            for dep in &job.deps {
                from.push(*job_id);
                to.push(id_of(dep)?);
            }
        }
        if !from.is_empty() {
            sqlx::query(
                "INSERT INTO job_dependencies (job_id, depends_on)
                 SELECT * FROM unnest($1::uuid[], $2::uuid[])",
            )
            .bind(&from)
            .bind(&to)
            .execute(&mut **tx)
            .await?;
        }
    }
    Ok(())
}

/// An augmentation's row with its job summary (migration 0003: counts per
/// state and `done`, maintained with the jobs).
#[derive(sqlx::FromRow)]
struct SummaryRow {
    id: Uuid,
    dataset_id: Uuid,
    cancelled_at: Option<DateTime<Utc>>,
    created_at: DateTime<Utc>,
    jobs_queued: i32,
    jobs_running: i32,
    jobs_succeeded: i32,
    jobs_failed: i32,
    jobs_cancelled: i32,
    done: f64,
    kinds: sqlx::types::Json<BTreeMap<String, i64>>,
}

/// `SELECT` of a [`SummaryRow`] from `augmentations`, then `$rest`.
macro_rules! select_summary {
    ($rest:literal) => {
        concat!(
            "SELECT id, dataset_id, cancelled_at, created_at, jobs_queued, jobs_running, \
             jobs_succeeded, jobs_failed, jobs_cancelled, done, kinds FROM augmentations ",
            $rest
        )
    };
}

/// The status of a summary row, with its failed jobs' errors (read only when
/// some job failed).
async fn status_of(state: &AppState, row: SummaryRow) -> Result<AugmentationStatus, ApiError> {
    let mut jobs = JobCounts::default();
    jobs.add(JobState::Queued, row.jobs_queued.into());
    jobs.add(JobState::Running, row.jobs_running.into());
    jobs.add(JobState::Succeeded, row.jobs_succeeded.into());
    jobs.add(JobState::Failed, row.jobs_failed.into());
    jobs.add(JobState::Cancelled, row.jobs_cancelled.into());
    let errors: Vec<(Uuid, String, Option<String>, String)> = if jobs.failed > 0 {
        sqlx::query_as(
            "SELECT id, key, input->>'clip_name', error FROM jobs
             WHERE augmentation_id = $1 AND state = $2 AND error IS NOT NULL ORDER BY seq",
        )
        .bind(row.id)
        .bind(JobState::Failed)
        .fetch_all(&state.db)
        .await?
    } else {
        Vec::new()
    };
    Ok(AugmentationStatus {
        id: row.id,
        dataset_id: row.dataset_id,
        status: AugmentationState::of_jobs(row.cancelled_at.is_some(), &jobs),
        progress: if jobs.total == 0 {
            1.0
        } else {
            (row.done / jobs.total as f64).clamp(0.0, 1.0)
        },
        jobs,
        kinds: row.kinds.0,
        errors: errors
            .into_iter()
            .map(|(job, key, clip, error)| JobError {
                job,
                key,
                clip,
                error,
            })
            .collect(),
        created_at: row.created_at,
    })
}

/// Reads the status; `None` when it does not exist or belongs to another tenant.
///
/// One lookup by primary key (the cancellation mark and the job counts are in
/// the same row, so they come from one snapshot), and one indexed query of the
/// failed jobs' errors when there are any.
pub async fn load_status(
    state: &AppState,
    tenant_id: Uuid,
    id: Uuid,
) -> Result<Option<AugmentationStatus>, ApiError> {
    let row: Option<SummaryRow> =
        sqlx::query_as(select_summary!("WHERE id = $1 AND tenant_id = $2"))
            .bind(id)
            .bind(tenant_id)
            .fetch_optional(&state.db)
            .await?;
    match row {
        Some(row) => Ok(Some(status_of(state, row).await?)),
        None => Ok(None),
    }
}

/// Status, progress and job counts
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}",
    operation_id = "getAugmentation",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The augmentation's id")),
    responses(
        (status = 200, description = "Status", body = AugmentationStatus),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn get(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Json<AugmentationStatus>, ApiError> {
    load_status(&state, tenant.id, id)
        .await?
        .map(Json)
        .ok_or_else(|| ApiError::not_found("augmentation"))
}

/// List the dataset's augmentations
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}/augmentations",
    operation_id = "listAugmentations",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The dataset's id")),
    responses(
        (status = 200, description = "Augmentations", body = AugmentationList),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn list(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(dataset_id): Path<Uuid>,
) -> Result<Json<AugmentationList>, ApiError> {
    datasets::find(&state, &tenant, dataset_id).await?;
    let rows: Vec<SummaryRow> = sqlx::query_as(select_summary!(
        "WHERE dataset_id = $1 AND tenant_id = $2 ORDER BY created_at, id"
    ))
    .bind(dataset_id)
    .bind(tenant.id)
    .fetch_all(&state.db)
    .await?;
    let mut out = Vec::with_capacity(rows.len());
    for row in rows {
        out.push(status_of(&state, row).await?);
    }
    Ok(Json(AugmentationList { augmentations: out }))
}

/// Cancel (running jobs stop at their next heartbeat)
#[utoipa::path(
    delete,
    path = "/v1/augmentations/{id}",
    operation_id = "cancelAugmentation",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The augmentation's id")),
    responses(
        (status = 202, description = "Cancelled", body = AugmentationRef),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn cancel(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Response, ApiError> {
    load_status(&state, tenant.id, id)
        .await?
        .ok_or_else(|| ApiError::not_found("augmentation"))?;
    let changed = queue::cancel_augmentation(&state.db, id).await?;
    tracing::info!(augmentation = %id, jobs = changed, "augmentation cancelled");
    state.events.publish(Event::Augmentation { id }).await;
    Ok((
        StatusCode::ACCEPTED,
        Json(AugmentationRef {
            id,
            status: AugmentationState::Cancelled,
        }),
    )
        .into_response())
}

struct Follow {
    state: AppState,
    tenant_id: Uuid,
    id: Uuid,
    events: tokio::sync::broadcast::Receiver<Event>,
    last: Option<AugmentationStatus>,
    done: bool,
}

/// Server-sent events: `status` events (same body as GET /v1/augmentations/{id}) on every change until the augmentation ends
///
/// One `status` event now and one after every change; a `deleted` event if the
/// augmentation's dataset is deleted. Woken by Redis events, with a database
/// poll as the fallback.
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}/events",
    operation_id = "augmentationEvents",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The augmentation's id")),
    responses(
        (status = 200, description = "Event stream", content_type = "text/event-stream", body = String),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn events(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Sse<impl Stream<Item = Result<SseEvent, Infallible>>>, ApiError> {
    load_status(&state, tenant.id, id)
        .await?
        .ok_or_else(|| ApiError::not_found("augmentation"))?;
    let follow = Follow {
        events: state.events.subscribe(),
        state,
        tenant_id: tenant.id,
        id,
        last: None,
        done: false,
    };
    let stream = futures_util::stream::unfold(follow, |mut f| async move {
        loop {
            if f.done {
                return None;
            }
            match load_status(&f.state, f.tenant_id, f.id).await {
                Ok(Some(status)) if f.last.as_ref() != Some(&status) => {
                    f.done = status.status.is_terminal();
                    let event = SseEvent::default()
                        .event("status")
                        .json_data(&status)
                        .unwrap_or_else(|_| SseEvent::default().comment("encoding failed"));
                    f.last = Some(status);
                    return Some((Ok(event), f));
                }
                Ok(Some(_)) => {}
                Ok(None) => {
                    f.done = true;
                    return Some((Ok(SseEvent::default().event("deleted").data("{}")), f));
                }
                Err(_) => {}
            }
            wait_for_change(&mut f.events, f.id, f.state.config.queue.poll_interval).await;
        }
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

/// Returns after an event about this augmentation or after `poll`.
async fn wait_for_change(
    events: &mut tokio::sync::broadcast::Receiver<Event>,
    id: Uuid,
    poll: Duration,
) {
    let wait = async {
        loop {
            match events.recv().await {
                Ok(Event::Augmentation { id: changed }) if changed == id => return,
                Ok(_) => {}
                Err(RecvError::Lagged(_)) => return,
                Err(RecvError::Closed) => std::future::pending::<()>().await,
            }
        }
    };
    let _ = tokio::time::timeout(poll, wait).await;
}

/// Zip of every output (BVH, masks) with manifest.json as the CLI writes it
///
/// With the correction reports the manifest names. Only once the augmentation
/// has succeeded (409 before).
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}/results",
    operation_id = "augmentationResults",
    tag = "augmentations",
    params(("id" = Uuid, Path, description = "The augmentation's id")),
    responses(
        (status = 200, description = "Zip", content_type = "application/zip", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
        (status = 409, response = Problem),
    )
)]
pub async fn results(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Response, ApiError> {
    let status = load_status(&state, tenant.id, id)
        .await?
        .ok_or_else(|| ApiError::not_found("augmentation"))?;
    if status.status != AugmentationState::Succeeded {
        return Err(ApiError::conflict(format!(
            "the augmentation is {}; results can be downloaded once it has succeeded",
            status.status
        )));
    }
    let outputs: Vec<(String, Option<sqlx::types::Json<Value>>)> =
        sqlx::query_as("SELECT key, output FROM jobs WHERE augmentation_id = $1 ORDER BY seq")
            .bind(id)
            .fetch_all(&state.db)
            .await?;
    let mut entries = Vec::new();
    let mut files = Vec::new();
    for (key, output) in outputs {
        let output: JobOutput = output
            .map(|o| serde_json::from_value(o.0))
            .transpose()
            .map_err(|e| {
                ApiError::internal(format!("{key}: stored job output is unreadable: {e}"))
            })?
            .unwrap_or_default();
        entries.extend(output.manifest);
        files.extend(output.files);
    }
    let manifest = motionaug_protocol::recipe::manifest_json(entries)
        .map_err(|e| ApiError::internal(format!("cannot write the manifest: {e}")))?;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let zip_err =
        |e: &dyn std::fmt::Display| ApiError::internal(format!("cannot build the zip: {e}"));
    for name in files {
        let content: Option<Vec<u8>> = sqlx::query_scalar(
            "SELECT content FROM artifacts WHERE augmentation_id = $1 AND name = $2",
        )
        .bind(id)
        .bind(&name)
        .fetch_optional(&state.db)
        .await?;
        let content = content.ok_or_else(|| {
            ApiError::internal(format!("result file `{name}` is missing from the store"))
        })?;
        zip.start_file(name.as_str(), options)
            .map_err(|e| zip_err(&e))?;
        zip.write_all(&content).map_err(|e| zip_err(&e))?;
    }
    zip.start_file("manifest.json", options)
        .map_err(|e| zip_err(&e))?;
    zip.write_all(manifest.as_bytes())
        .map_err(|e| zip_err(&e))?;
    let bytes = zip.finish().map_err(|e| zip_err(&e))?.into_inner();
    Ok((
        [
            (header::CONTENT_TYPE, "application/zip".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"augmentation-{id}.zip\""),
            ),
        ],
        bytes,
    )
        .into_response())
}
