//! `/v1/datasets`: upload (all or nothing), list, show, delete.

use axum::Json;
use axum::extract::{Multipart, Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use serde::Serialize;
use utoipa::ToSchema;
use uuid::Uuid;

use crate::auth::Tenant;
use crate::configuration::Limits;
use crate::error::{ApiError, Problem, from_rejection};
use crate::events::Event;
use crate::openapi::DatasetUpload;
use crate::startup::AppState;
use crate::upload::{UploadFile, check_part_name, parse_upload};
use crate::upload_memory::{self, Reservation};
use crate::{queue, quota};

/// A stored clip.
#[derive(Debug, Serialize, sqlx::FromRow, ToSchema)]
#[schema(as = Clip)]
pub struct ClipSummary {
    pub id: Uuid,
    /// The file's stem, unique in the dataset.
    pub name: String,
    pub frames: i32,
    pub fps: f64,
    pub joints: i32,
}

/// A dataset in the list of a tenant's datasets.
#[derive(Debug, Serialize, sqlx::FromRow, ToSchema)]
#[schema(as = DatasetListItem)]
pub struct DatasetRow {
    pub id: Uuid,
    pub name: String,
    pub created_at: DateTime<Utc>,
    pub clip_count: i64,
}

/// A dataset with its clips in upload order.
#[derive(Debug, Serialize, ToSchema)]
pub struct Dataset {
    pub id: Uuid,
    pub name: String,
    /// When it was uploaded (not part of the answer to the upload itself).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = DateTime<Utc>)]
    pub created_at: Option<DateTime<Utc>>,
    pub clips: Vec<ClipSummary>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct DatasetList {
    pub datasets: Vec<DatasetRow>,
}

/// Reads the multipart body: `file` parts (any number) and an optional `name`.
/// Every byte is reserved from the upload memory budget as it streams in.
async fn read_parts(
    mut multipart: Multipart,
    limits: &Limits,
    reservation: &mut Reservation,
) -> Result<(Option<String>, Vec<UploadFile>), ApiError> {
    let max_files = limits.max_files;
    let mut name = None;
    let mut files = Vec::new();
    loop {
        let mut field = match multipart.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => break,
            Err(e) => return Err(from_rejection(e.status(), e.body_text())),
        };
        match field.name() {
            Some("file") => {
                let file_name = field
                    .file_name()
                    .map(str::to_string)
                    .filter(|n| !n.is_empty())
                    .ok_or_else(|| {
                        ApiError::bad_request("every `file` part needs a filename")
                            .with_field("file")
                    })?;
                check_part_name(&file_name)?;
                let mut bytes = Vec::new();
                while let Some(chunk) = field.chunk().await.map_err(|e| {
                    from_rejection(e.status(), format!("{file_name}: {}", e.body_text()))
                })? {
                    upload_memory::append(
                        &mut bytes,
                        &chunk,
                        limits.max_upload_bytes,
                        reservation,
                    )?;
                }
                files.push(UploadFile {
                    label: file_name.clone(),
                    name: file_name,
                    bytes,
                });
                if files.len() > max_files {
                    return Err(ApiError::too_large(format!(
                        "too many files: at most {max_files} per upload"
                    )));
                }
            }
            Some("name") => {
                let mut text = Vec::new();
                while let Some(chunk) = field
                    .chunk()
                    .await
                    .map_err(|e| from_rejection(e.status(), e.body_text()))?
                {
                    text.extend_from_slice(&chunk);
                    if text.len() > 1024 {
                        break;
                    }
                }
                let text = String::from_utf8_lossy(&text).trim().to_string();
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

/// Upload a dataset (all or nothing)
///
/// Every file is checked before anything is stored: one bad file refuses the
/// whole upload, naming the file and, where it can, the line.
#[utoipa::path(
    post,
    path = "/v1/datasets",
    operation_id = "createDataset",
    tag = "datasets",
    request_body(content = inline(DatasetUpload), content_type = "multipart/form-data"),
    responses(
        (status = 201, description = "Stored", body = Dataset,
            headers(("Location" = String, description = "The dataset's URL"))),
        (status = 400, response = Problem),
        (status = 401, response = Problem),
        (status = 413, response = Problem),
        (status = 422, response = Problem),
        (status = 429, response = Problem),
        (status = 503, response = Problem),
    )
)]
pub async fn create(
    State(state): State<AppState>,
    tenant: Tenant,
    multipart: Result<Multipart, axum::extract::multipart::MultipartRejection>,
) -> Result<Response, ApiError> {
    let multipart = multipart.map_err(|e| from_rejection(e.status(), e.body_text()))?;
    let limits = state.config.limits.clone();
    // Held until the upload is stored or refused: a slot, and the memory of
    // its body and unpacked zips.
    let mut reservation = state.uploads.start().await;
    let (name, files) = read_parts(multipart, &limits, &mut reservation).await?;
    let default_name = files[0].name.clone();
    let (clips, _reservation) = tokio::task::spawn_blocking(move || {
        let clips = parse_upload(files, &limits, &mut reservation);
        (clips, reservation)
    })
    .await
    .map_err(|e| ApiError::internal(format!("parsing the upload failed: {e}")))?;
    let clips = clips?;
    let dataset_id = Uuid::new_v4();
    let name = name.unwrap_or(default_name);
    let bytes: usize = clips
        .iter()
        .map(|c| c.source.len() + c.skeleton.as_ref().map_or(0, Vec::len))
        .sum();
    let mut tx = state.db.begin().await?;
    quota::lock_tenant(&mut tx, tenant.id).await?;
    let usage = quota::usage(&mut *tx, tenant.id).await?;
    quota::check_stored(&state.config.quotas, &usage, bytes.max(1) as u64)?;
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
            motionaug_protocol::ClipFormat::Npz => "npz",
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
    let body = Dataset {
        id: dataset_id,
        name,
        created_at: None,
        clips: summaries,
    };
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, format!("/v1/datasets/{dataset_id}"))],
        Json(body),
    )
        .into_response())
}

/// List datasets
#[utoipa::path(
    get,
    path = "/v1/datasets",
    operation_id = "listDatasets",
    tag = "datasets",
    responses(
        (status = 200, description = "Datasets", body = DatasetList),
        (status = 401, response = Problem),
    )
)]
pub async fn list(
    State(state): State<AppState>,
    tenant: Tenant,
) -> Result<Json<DatasetList>, ApiError> {
    let rows: Vec<DatasetRow> = sqlx::query_as(
        "SELECT d.id, d.name, d.created_at,
                (SELECT count(*) FROM clips c WHERE c.dataset_id = d.id) AS clip_count
         FROM datasets d WHERE d.tenant_id = $1 ORDER BY d.created_at, d.id",
    )
    .bind(tenant.id)
    .fetch_all(&state.db)
    .await?;
    Ok(Json(DatasetList { datasets: rows }))
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

/// Show a dataset with its clips
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}",
    operation_id = "getDataset",
    tag = "datasets",
    params(("id" = Uuid, Path, description = "The dataset's id")),
    responses(
        (status = 200, description = "Dataset", body = Dataset),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn get(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Json<Dataset>, ApiError> {
    let dataset = find(&state, &tenant, id).await?;
    let clips: Vec<ClipSummary> = sqlx::query_as(
        "SELECT id, name, frames, fps, joints FROM clips WHERE dataset_id = $1 ORDER BY position",
    )
    .bind(id)
    .fetch_all(&state.db)
    .await?;
    Ok(Json(Dataset {
        id: dataset.id,
        name: dataset.name,
        created_at: Some(dataset.created_at),
        clips,
    }))
}

/// Delete a dataset, its clips, augmentations and results (running jobs are cancelled)
///
/// Running jobs of its augmentations are told to stop at their next heartbeat.
#[utoipa::path(
    delete,
    path = "/v1/datasets/{id}",
    operation_id = "deleteDataset",
    tag = "datasets",
    params(("id" = Uuid, Path, description = "The dataset's id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
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
