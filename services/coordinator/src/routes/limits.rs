//! `GET /v1/limits`: every limit and quota in force, and what the tenant uses
//! of its quotas, so a client can see a refusal coming (and read the names a
//! 422 / 429 problem's `limit` member gives).

use axum::Json;
use axum::extract::State;
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::Tenant;
use crate::error::{ApiError, Problem};
use crate::quota;
use crate::routes::JSON_BODY_LIMIT;
use crate::startup::AppState;

/// One quota of the tenant.
#[derive(Debug, Serialize, ToSchema)]
pub struct Quota {
    /// The name a refusal's `limit` member gives.
    pub name: &'static str,
    pub max: u64,
    /// What the tenant uses now (absent for a per-request quota).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(nullable = false)]
    pub used: Option<f64>,
    /// The status of a request that would pass it.
    pub status: u16,
    pub meaning: &'static str,
}

/// Limits of one request (the same for every tenant).
#[derive(Debug, Serialize, ToSchema)]
pub struct RequestLimits {
    pub max_upload_bytes: u64,
    pub max_files: u64,
    pub max_frames: u64,
    pub max_unzipped_bytes: u64,
    pub max_json_body_bytes: u64,
    pub max_artifact_bytes: u64,
    /// Uploads read and checked at once (others wait).
    pub max_concurrent_uploads: u64,
    /// Memory all uploads of one coordinator may hold together.
    pub upload_memory_bytes: u64,
}

/// The upper bound of one numeric recipe field.
#[derive(Debug, Serialize, ToSchema)]
pub struct RecipeBound {
    pub table: &'static str,
    pub field: &'static str,
    pub max: f64,
    pub unit: &'static str,
}

/// Bounds of recipes (the pipeline and synth crates').
#[derive(Debug, Serialize, ToSchema)]
pub struct RecipeLimits {
    /// `[[ops]]` tables.
    pub max_ops: u64,
    /// `copies` of an op, of `[vae]` and of `[interaction]`.
    pub max_copies: u64,
    /// Every other numeric field the tables' own crates leave open; the ops'
    /// parameters and acceptance criteria are bounded by their crates (a value
    /// out of range is a 422 naming it).
    pub bounds: Vec<RecipeBound>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct LimitsDoc {
    pub quotas: Vec<Quota>,
    pub requests: RequestLimits,
    pub recipe: RecipeLimits,
}

/// Limits, quotas and the tenant's use of them
#[utoipa::path(
    get,
    path = "/v1/limits",
    operation_id = "getLimits",
    tag = "limits",
    responses(
        (status = 200, description = "Limits", body = LimitsDoc),
        (status = 401, response = Problem),
    )
)]
pub async fn get(
    State(state): State<AppState>,
    tenant: Tenant,
) -> Result<Json<LimitsDoc>, ApiError> {
    let usage = quota::usage(&state.db, tenant.id).await?;
    let q = &state.config.quotas;
    let l = &state.config.limits;
    let quotas = vec![
        Quota {
            name: "outputs_per_augmentation",
            max: q.outputs_per_augmentation,
            used: None,
            status: 422,
            meaning: "new clips one augmentation may make",
        },
        Quota {
            name: "active_augmentations",
            max: q.active_augmentations,
            used: Some(usage.active_augmentations as f64),
            status: 429,
            meaning: "augmentations with jobs still queued or running",
        },
        Quota {
            name: "correction_seconds",
            max: q.correction_seconds,
            used: Some(usage.correction_seconds),
            status: 429,
            meaning: "correction budget ([correct] time_budget_s x correction jobs) of the \
                      unfinished augmentations together",
        },
        Quota {
            name: "stored_bytes",
            max: q.stored_bytes,
            used: Some(usage.stored_bytes as f64),
            status: 429,
            meaning: "uploaded files, results and checkpoints",
        },
    ];
    Ok(Json(LimitsDoc {
        quotas,
        requests: RequestLimits {
            max_upload_bytes: l.max_upload_bytes as u64,
            max_files: l.max_files as u64,
            max_frames: l.max_frames as u64,
            max_unzipped_bytes: l.max_unzipped_bytes,
            max_json_body_bytes: JSON_BODY_LIMIT as u64,
            max_artifact_bytes: l.max_artifact_bytes as u64,
            max_concurrent_uploads: l.max_concurrent_uploads as u64,
            upload_memory_bytes: l.upload_memory_bytes,
        },
        recipe: RecipeLimits {
            max_ops: pipeline::recipe::bounds::MAX_OPS as u64,
            max_copies: pipeline::recipe::bounds::MAX_COPIES as u64,
            bounds: pipeline::recipe::bounds::ALL
                .iter()
                .map(|b| RecipeBound {
                    table: b.table,
                    field: b.field,
                    max: b.max,
                    unit: b.unit,
                })
                .collect(),
        },
    }))
}
