//! `/v1/datasets`: upload (all or nothing), list, show, delete.

use axum::Json;
use axum::extract::{Multipart, Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use serde::Serialize;
use serde_json::json;
use uuid::Uuid;

use crate::auth::Tenant;
use crate::error::{ApiError, from_rejection};
use crate::events::Event;
use crate::queue;
use crate::startup::AppState;
use crate::upload::{UploadFile, parse_upload};

#[derive(Debug, Serialize, sqlx::FromRow)]
pub struct ClipSummary {
    pub id: Uuid,
    pub name: String,
    pub frames: i32,
    pub fps: f64,
    pub joints: i32,
}

#[derive(Debug, Serialize, sqlx::FromRow)]
pub struct DatasetRow {
    pub id: Uuid,
    pub name: String,
    pub created_at: DateTime<Utc>,
    pub clip_count: i64,
}

/// Reads the multipart body: `file` parts (any number) and an optional `name`.
async fn read_parts(
    mut multipart: Multipart,
    max_files: usize,
) -> Result<(Option<String>, Vec<UploadFile>), ApiError> {
    let mut name = None;
    let mut files = Vec::new();
    loop {
        let field = match multipart.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => break,
            Err(e) => return Err(from_rejection(e.status(), e.body_text())),
        };
        match field.name() {
            Some("file") => {
                let file_name = field
                    .file_name()
                    .map(|n| n.rsplit(['/', '\\']).next().unwrap_or(n).to_string())
                    .filter(|n| !n.is_empty())
                    .ok_or_else(|| {
                        ApiError::bad_request("every `file` part needs a filename")
                            .with_field("file")
                    })?;
                let bytes = field.bytes().await.map_err(|e| {
                    from_rejection(e.status(), format!("{file_name}: {}", e.body_text()))
                })?;
                files.push(UploadFile {
                    label: file_name.clone(),
                    name: file_name,
                    bytes: bytes.to_vec(),
                });
                if files.len() > max_files {
                    return Err(ApiError::too_large(format!(
                        "too many files: at most {max_files} per upload"
                    )));
                }
            }
            Some("name") => {
                let text = field
                    .text()
                    .await
                    .map_err(|e| from_rejection(e.status(), e.body_text()))?;
                let text = text.trim().to_string();
                if text.is_empty() || text.len() > 200 {
                    return Err(
                        ApiError::unprocessable("`name` must be 1 to 200 characters")
                            .with_field("name"),
                    );
                }
                name = Some(text);
            }
            other => {
                return Err(ApiError::bad_request(format!(
                    "unknown form field `{}`; send `file` parts and an optional `name`",
                    other.unwrap_or("")
                ))
                .with_field(other.unwrap_or("").to_string()));
            }
        }
    }
    if files.is_empty() {
        return Err(ApiError::unprocessable(
            "no files: send one or more multipart parts named `file`",
        )
        .with_field("file"));
    }
    Ok((name, files))
}

pub async fn create(
    State(state): State<AppState>,
    tenant: Tenant,
    multipart: Result<Multipart, axum::extract::multipart::MultipartRejection>,
) -> Result<Response, ApiError> {
    let multipart = multipart.map_err(|e| from_rejection(e.status(), e.body_text()))?;
    let limits = state.config.limits.clone();
    let (name, files) = read_parts(multipart, limits.max_files).await?;
    let default_name = files[0].name.clone();
    let clips = tokio::task::spawn_blocking(move || parse_upload(files, &limits))
        .await
        .map_err(|e| ApiError::internal(format!("parsing the upload failed: {e}")))??;
    let dataset_id = Uuid::new_v4();
    let name = name.unwrap_or(default_name);
    let mut tx = state.db.begin().await?;
    sqlx::query("INSERT INTO datasets (id, tenant_id, name) VALUES ($1, $2, $3)")
        .bind(dataset_id)
        .bind(tenant.id)
        .bind(&name)
        .execute(&mut *tx)
        .await?;
    let mut summaries = Vec::with_capacity(clips.len());
    for (position, clip) in clips.into_iter().enumerate() {
        let id = Uuid::new_v4();
        sqlx::query(
            "INSERT INTO clips (id, dataset_id, position, name, format, source_name, source,
                                skeleton_name, skeleton, frames, fps, joints, joint_names)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13)",
        )
        .bind(id)
        .bind(dataset_id)
        .bind(position as i32)
        .bind(&clip.name)
        .bind(match clip.format {
            motionaug_protocol::ClipFormat::Bvh => "bvh",
            motionaug_protocol::ClipFormat::Amc => "amc",
        })
        .bind(&clip.source_name)
        .bind(&clip.source)
        .bind(&clip.skeleton_name)
        .bind(&clip.skeleton)
        .bind(clip.frames as i32)
        .bind(clip.fps)
        .bind(clip.joints as i32)
        .bind(sqlx::types::Json(&clip.joint_names))
        .execute(&mut *tx)
        .await?;
        summaries.push(ClipSummary {
            id,
            name: clip.name,
            frames: clip.frames as i32,
            fps: clip.fps,
            joints: clip.joints as i32,
        });
    }
    tx.commit().await?;
    tracing::info!(tenant = %tenant.name, dataset = %dataset_id, clips = summaries.len(), "dataset uploaded");
    let body = json!({ "id": dataset_id, "name": name, "clips": summaries });
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, format!("/v1/datasets/{dataset_id}"))],
        Json(body),
    )
        .into_response())
}

pub async fn list(
    State(state): State<AppState>,
    tenant: Tenant,
) -> Result<Json<serde_json::Value>, ApiError> {
    let rows: Vec<DatasetRow> = sqlx::query_as(
        "SELECT d.id, d.name, d.created_at,
                (SELECT count(*) FROM clips c WHERE c.dataset_id = d.id) AS clip_count
         FROM datasets d WHERE d.tenant_id = $1 ORDER BY d.created_at, d.id",
    )
    .bind(tenant.id)
    .fetch_all(&state.db)
    .await?;
    Ok(Json(json!({ "datasets": rows })))
}

/// The dataset if it belongs to the tenant (another tenant's dataset is "not found").
pub async fn find(state: &AppState, tenant: &Tenant, id: Uuid) -> Result<DatasetRow, ApiError> {
    sqlx::query_as(
        "SELECT d.id, d.name, d.created_at,
                (SELECT count(*) FROM clips c WHERE c.dataset_id = d.id) AS clip_count
         FROM datasets d WHERE d.id = $1 AND d.tenant_id = $2",
    )
    .bind(id)
    .bind(tenant.id)
    .fetch_optional(&state.db)
    .await?
    .ok_or_else(|| ApiError::not_found("dataset"))
}

pub async fn get(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let dataset = find(&state, &tenant, id).await?;
    let clips: Vec<ClipSummary> = sqlx::query_as(
        "SELECT id, name, frames, fps, joints FROM clips WHERE dataset_id = $1 ORDER BY position",
    )
    .bind(id)
    .fetch_all(&state.db)
    .await?;
    Ok(Json(json!({
        "id": dataset.id,
        "name": dataset.name,
        "created_at": dataset.created_at,
        "clips": clips,
    })))
}

/// Deletes the dataset with its clips, augmentations and results; running jobs
/// of its augmentations are told to stop at their next heartbeat.
pub async fn delete(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<StatusCode, ApiError> {
    find(&state, &tenant, id).await?;
    let augmentations: Vec<Uuid> =
        sqlx::query_scalar("SELECT id FROM augmentations WHERE dataset_id = $1")
            .bind(id)
            .fetch_all(&state.db)
            .await?;
    for aug in &augmentations {
        queue::cancel_augmentation(&state.db, *aug).await?;
    }
    sqlx::query("DELETE FROM datasets WHERE id = $1 AND tenant_id = $2")
        .bind(id)
        .bind(tenant.id)
        .execute(&state.db)
        .await?;
    for aug in augmentations {
        state.events.publish(Event::Augmentation { id: aug }).await;
    }
    Ok(StatusCode::NO_CONTENT)
}
