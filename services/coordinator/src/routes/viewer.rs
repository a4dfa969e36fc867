//! The viewer page (the `viewer` crate's bundle) at `/viewer/`, and what it
//! reads, for the tenant whose key the page sends (another tenant's datasets,
//! augmentations and files are "not found", as everywhere in `/v1`):
//!
//! * `/v1/datasets/{id}/library` and `/v1/augmentations/{id}/library`: the
//!   clips to list, each with the URLs of its parts (the shape `motionaug view`
//!   sends); an augmentation's library holds the outputs of its finished jobs
//!   so far (with their synthesised / corrected versions and the sources) and
//!   every correction job with its learning curve (the report's once it has
//!   finished, the worker's live `curve.json` while it trains);
//! * `.../view/{part}`: a clip's meta (JSON), frames (float32 positions,
//!   `?start=S&count=N`) or flags (a byte per frame and point);
//! * `/v1/augmentations/{id}/files/{*file}`: one stored file (a result, a report).
//!
//! Prepared clips are cached in this process by content hash, so paging
//! through a clip parses it once.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::Path as FsPath;
use std::sync::{Arc, Mutex, OnceLock};

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Redirect, Response};
use motionaug_protocol::{JobOutput, artifacts};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::openapi::path::{Parameter, ParameterBuilder, ParameterIn};
use utoipa::openapi::{self, ContentBuilder, Object, Ref, RefOr, Required, ResponseBuilder};
use utoipa::{IntoParams, IntoResponses, PartialSchema, ToSchema};
use uuid::Uuid;
use viewer::ClipView;
use viewer::library::{Descriptor, Role, Urls};

use crate::auth::Tenant;
use crate::error::{ApiError, Problem};
use crate::openapi::Binary;
use crate::routes::{augmentations, datasets};
use crate::startup::AppState;

/// The viewer page
#[utoipa::path(
    get,
    path = "/viewer/",
    operation_id = "viewerPage",
    tag = "viewer",
    security(),
    responses((status = 200, description = "HTML", content_type = "text/html", body = String))
)]
pub async fn page() -> Response {
    asset_response("index.html")
}

/// The viewer page (redirects to `/viewer/`)
#[utoipa::path(
    get,
    path = "/viewer",
    operation_id = "viewerRedirect",
    tag = "viewer",
    security(),
    responses((status = 308, description = "To /viewer/"))
)]
pub async fn redirect() -> Redirect {
    Redirect::permanent("/viewer/")
}

/// A file of the viewer page (script, style)
#[utoipa::path(
    get,
    path = "/viewer/{*file}",
    operation_id = "viewerAsset",
    tag = "viewer",
    security(),
    params(("file" = String, Path, description = "The file")),
    responses(
        (status = 200, description = "The file", body = inline(Binary)),
        (status = 404, response = Problem),
    )
)]
pub async fn asset(Path(file): Path<String>) -> Response {
    asset_response(&file)
}

fn asset_response(file: &str) -> Response {
    match viewer::assets::get(file) {
        Some(a) => ([(header::CONTENT_TYPE, a.mime)], a.bytes).into_response(),
        None => ApiError::not_found("file").into_response(),
    }
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ViewerInfo {
    /// `service`: the page asks for an API key and lists datasets.
    pub mode: String,
}

/// What the viewer page is talking to
#[utoipa::path(
    get,
    path = "/viewer/api/info",
    operation_id = "viewerInfo",
    tag = "viewer",
    security(),
    responses((status = 200, description = "Mode", body = ViewerInfo))
)]
pub async fn info() -> Json<ViewerInfo> {
    Json(ViewerInfo {
        mode: "service".into(),
    })
}

/// A clip as the viewer lists it (see the `viewer` crate).
#[derive(Debug, Serialize, ToSchema)]
#[schema(as = ViewerClip)]
pub struct ClipItem {
    pub id: String,
    pub name: String,
    /// The source clip it comes from (or the dataset).
    pub group: String,
    /// source, source_corrected, synthesised, corrected, debiased, clip.
    pub role: String,
    /// Its manifest entry, for outputs.
    #[schema(value_type = Object)]
    pub entry: Option<Value>,
    pub frames: Option<u64>,
    pub fps: Option<f64>,
    pub masked: bool,
    /// Ids of the clips to play beside it (itself included).
    pub versions: Vec<String>,
    /// Shown in the list (intermediate versions are not).
    pub listed: bool,
    /// URLs of its meta, frames, flags, correction report and file.
    #[schema(value_type = Object)]
    pub urls: Value,
}

impl From<Descriptor> for ClipItem {
    fn from(d: Descriptor) -> Self {
        ClipItem {
            role: serde_json::to_value(d.role)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            urls: serde_json::to_value(&d.urls).unwrap_or(Value::Null),
            id: d.id,
            name: d.name,
            group: d.group,
            entry: d.entry,
            frames: d.frames,
            fps: d.fps,
            masked: d.masked,
            versions: d.versions,
            listed: d.listed,
        }
    }
}

/// A correction job and its learning curve.
#[derive(Debug, Serialize, ToSchema)]
pub struct CorrectionItem {
    /// The job's key, e.g. `correct:walk__00_noise_000`.
    pub key: String,
    pub clip: Option<String>,
    pub state: String,
    pub progress: f64,
    /// Whether it passed every acceptance criterion (once finished).
    pub accepted: Option<bool>,
    /// [wall_s, samples, r_norm] of each deterministic rollout so far.
    pub curve: Vec<[f64; 3]>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Library {
    pub title: String,
    pub clips: Vec<ClipItem>,
    /// Correction jobs (augmentations only).
    pub corrections: Vec<CorrectionItem>,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct Page {
    /// First frame (frames only; default 0).
    pub start: Option<usize>,
    /// Number of frames (frames only; default: to the end).
    pub count: Option<usize>,
}

/// The parts of a clip the page reads.
fn clip_urls(base: &str, report: Option<String>, download: Option<String>) -> Urls {
    Urls {
        meta: format!("{base}/meta"),
        frames: format!("{base}/frames"),
        flags: format!("{base}/flags"),
        report,
        download,
    }
}

type DatasetClip = (Uuid, String, String, i32, f64);

async fn dataset_clips(state: &AppState, dataset: Uuid) -> Result<Vec<DatasetClip>, ApiError> {
    Ok(sqlx::query_as(
        "SELECT id, name, source_name, frames, fps FROM clips WHERE dataset_id = $1 ORDER BY position",
    )
    .bind(dataset)
    .fetch_all(&state.db)
    .await?)
}

fn source_item(dataset: Uuid, group: &str, clip: &DatasetClip) -> ClipItem {
    let (id, name, _, frames, fps) = clip;
    let base = format!("/v1/datasets/{dataset}/clips/{id}/view");
    ClipItem {
        id: id.to_string(),
        name: name.clone(),
        group: group.to_string(),
        role: "source".into(),
        entry: None,
        frames: Some(*frames as u64),
        fps: Some(*fps),
        masked: false,
        versions: vec![id.to_string()],
        listed: true,
        urls: serde_json::to_value(clip_urls(&base, None, None)).unwrap_or(Value::Null),
    }
}

/// The clips of a dataset for the viewer
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}/library",
    operation_id = "datasetLibrary",
    tag = "viewer",
    params(("id" = Uuid, Path, description = "The dataset's id")),
    responses(
        (status = 200, description = "Clips", body = Library),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn dataset_library(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Json<Library>, ApiError> {
    let dataset = datasets::find(&state, &tenant, id).await?;
    let clips = dataset_clips(&state, id).await?;
    Ok(Json(Library {
        title: dataset.name.clone(),
        clips: clips
            .iter()
            .map(|c| source_item(id, &dataset.name, c))
            .collect(),
        corrections: Vec::new(),
    }))
}

/// A stored clip: file name, bytes, ASF name and bytes, frame rate.
type StoredClip = (String, Vec<u8>, Option<String>, Option<Vec<u8>>, f64);

/// A dataset clip's meta, frames or flags
#[utoipa::path(
    get,
    path = "/v1/datasets/{id}/clips/{clip}/view/{part}",
    operation_id = "datasetClipView",
    tag = "viewer",
    params(
        ("id" = Uuid, Path, description = "The dataset's id"),
        ("clip" = Uuid, Path, description = "The clip's id"),
        PartParams,
    ),
    responses(PartResponses)
)]
pub async fn dataset_clip_view(
    State(state): State<AppState>,
    tenant: Tenant,
    Path((id, clip, part)): Path<(Uuid, Uuid, String)>,
    Query(page): Query<Page>,
) -> Result<Response, ApiError> {
    datasets::find(&state, &tenant, id).await?;
    clip_part(format!("clip:{clip}"), &part, &page, async {
        let row: Option<StoredClip> = sqlx::query_as(
            "SELECT source_name, source, skeleton_name, skeleton, fps FROM clips
             WHERE id = $1 AND dataset_id = $2",
        )
        .bind(clip)
        .bind(id)
        .fetch_optional(&state.db)
        .await?;
        let (source_name, source, skeleton_name, skeleton, fps) =
            row.ok_or_else(|| ApiError::not_found("clip"))?;
        Ok(move || {
            let options = motion::LoadOptions {
                fps: Some(fps),
                ..motion::LoadOptions::default()
            };
            let skeleton = skeleton_name.as_deref().zip(skeleton.as_deref());
            let motion = motion::io::parse_named(&source_name, &source, skeleton, &options)
                .map_err(|e| e.to_string())?;
            ClipView::from_motion(&stem(&source_name), &motion, None).map_err(|e| e.to_string())
        })
    })
    .await
}

fn stem(name: &str) -> String {
    FsPath::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.to_string())
}

/// A job row of an augmentation.
type JobRow = (
    String,
    String,
    String,
    f64,
    Option<sqlx::types::Json<Value>>,
    Option<String>,
);

async fn jobs(state: &AppState, augmentation: Uuid) -> Result<Vec<JobRow>, ApiError> {
    Ok(sqlx::query_as(
        "SELECT key, kind, state, progress, output, input->>'clip_name' FROM jobs
         WHERE augmentation_id = $1 ORDER BY seq",
    )
    .bind(augmentation)
    .fetch_all(&state.db)
    .await?)
}

fn output_of(row: &JobRow) -> JobOutput {
    row.4
        .as_ref()
        .and_then(|o| serde_json::from_value(o.0.clone()).ok())
        .unwrap_or_default()
}

/// The augmentation's dataset, or "not found" for another tenant's.
async fn augmentation_dataset(
    state: &AppState,
    tenant: &Tenant,
    id: Uuid,
) -> Result<(Uuid, String), ApiError> {
    let status = augmentations::load_status(state, tenant.id, id)
        .await?
        .ok_or_else(|| ApiError::not_found("augmentation"))?;
    let dataset = datasets::find(state, tenant, status.dataset_id).await?;
    Ok((dataset.id, dataset.name))
}

async fn artifact(
    state: &AppState,
    augmentation: Uuid,
    name: &str,
) -> Result<Option<Vec<u8>>, ApiError> {
    Ok(
        sqlx::query_scalar(
            "SELECT content FROM artifacts WHERE augmentation_id = $1 AND name = $2",
        )
        .bind(augmentation)
        .bind(name)
        .fetch_optional(&state.db)
        .await?,
    )
}

fn role_of(entry: &Value) -> Role {
    if entry.get("debiased").and_then(Value::as_bool) == Some(true) {
        Role::Debiased
    } else if entry.get("correction").is_some_and(|c| !c.is_null()) {
        Role::Corrected
    } else {
        Role::Synthesised
    }
}

/// The clips and corrections of an augmentation for the viewer
///
/// The outputs of its finished jobs so far, each with its versions (source,
/// synthesised, corrected), and every correction job with its learning curve.
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}/library",
    operation_id = "augmentationLibrary",
    tag = "viewer",
    params(("id" = Uuid, Path, description = "The augmentation's id")),
    responses(
        (status = 200, description = "Clips and corrections", body = Library),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn augmentation_library(
    State(state): State<AppState>,
    tenant: Tenant,
    Path(id): Path<Uuid>,
) -> Result<Json<Library>, ApiError> {
    let (dataset, dataset_name) = augmentation_dataset(&state, &tenant, id).await?;
    let sources = dataset_clips(&state, dataset).await?;
    let rows = jobs(&state, id).await?;
    let base = format!("/v1/augmentations/{id}");
    let view_urls = |file: &str, report: Option<String>, download: bool| Urls {
        meta: format!("{base}/view/meta/{file}"),
        frames: format!("{base}/view/frames/{file}"),
        flags: format!("{base}/view/flags/{file}"),
        report,
        download: download.then(|| format!("{base}/files/{file}")),
    };
    let mut clips: Vec<ClipItem> = Vec::new();
    // Versions by clip name: work clips (synthesised, then corrected) as jobs made them.
    let mut versions: HashMap<String, Vec<String>> = HashMap::new();
    let mut finals = Vec::new();
    for row in &rows {
        let (_, kind, ..) = row;
        let output = output_of(row);
        for work in &output.clips {
            let role = if kind.starts_with("correct") {
                Role::Corrected
            } else {
                Role::Synthesised
            };
            let item = Descriptor {
                id: work.file.clone(),
                name: format!(
                    "{} ({})",
                    work.name,
                    if role == Role::Corrected {
                        "corrected"
                    } else {
                        "synthesised"
                    }
                ),
                group: group_of(&work.entry),
                role,
                entry: Some(work.entry.clone()),
                frames: work.entry.get("frames").and_then(Value::as_u64),
                fps: work.entry.get("fps").and_then(Value::as_f64),
                masked: false,
                versions: Vec::new(),
                listed: false,
                urls: view_urls(&work.file, None, false),
            };
            versions
                .entry(work.name.clone())
                .or_default()
                .push(work.file.clone());
            clips.push(item.into());
        }
        finals.extend(
            output
                .manifest
                .into_iter()
                .zip(std::iter::repeat(kind.clone())),
        );
    }
    let mut listed = Vec::new();
    for source in &sources {
        listed.push(source_item(dataset, &source.1, source));
    }
    for (entry, _) in finals {
        let Some(file) = entry
            .get("file")
            .and_then(Value::as_str)
            .map(str::to_string)
        else {
            continue;
        };
        let name = stem(&file);
        let group = group_of(&entry);
        let mut ids: Vec<String> = sources
            .iter()
            .filter(|s| s.1 == group)
            .map(|s| s.0.to_string())
            .collect();
        let original = artifacts::original_corrected(&group);
        if rows.iter().any(|r| output_of(r).work.contains(&original)) {
            ids.push(original.clone());
            if !clips.iter().any(|c| c.id == original) {
                clips.push(
                    Descriptor {
                        id: original.clone(),
                        name: format!("{group} (corrected)"),
                        group: group.clone(),
                        role: Role::SourceCorrected,
                        entry: None,
                        frames: None,
                        fps: None,
                        masked: false,
                        versions: vec![original.clone()],
                        listed: false,
                        urls: view_urls(
                            &original,
                            Some(format!(
                                "{base}/files/{}",
                                artifacts::original_report(&group)
                            )),
                            false,
                        ),
                    }
                    .into(),
                );
            }
        }
        ids.extend(versions.get(&name).cloned().unwrap_or_default());
        ids.push(file.clone());
        let report = entry
            .get("correction")
            .and_then(|c| c.get("report"))
            .and_then(Value::as_str)
            .map(|r| format!("{base}/files/{r}"));
        let masked = entry.get("op").and_then(Value::as_str) == Some("mask");
        let item = Descriptor {
            id: file.clone(),
            name,
            group,
            role: role_of(&entry),
            frames: entry.get("frames").and_then(Value::as_u64),
            fps: entry.get("fps").and_then(Value::as_f64),
            entry: Some(entry),
            masked,
            versions: ids,
            listed: true,
            urls: view_urls(&file, report, true),
        };
        listed.push(item.into());
    }
    // Each source with its outputs (stable: sources first, outputs in job order).
    listed.sort_by(|a, b| a.group.cmp(&b.group));
    listed.extend(clips);

    let mut corrections = Vec::new();
    for row in &rows {
        let (key, kind, job_state, progress, _, clip) = row;
        if !kind.starts_with("correct") {
            continue;
        }
        let Some(clip) = clip.clone() else { continue };
        let (report_name, curve_name) = if kind == "correct_original" {
            (
                artifacts::original_report(&clip),
                artifacts::original_curve(&clip),
            )
        } else {
            (
                artifacts::correction_report(&clip),
                artifacts::correction_curve(&clip),
            )
        };
        let report: Option<Value> = artifact(&state, id, &report_name)
            .await?
            .and_then(|b| serde_json::from_slice(&b).ok());
        let (curve, accepted) = match &report {
            Some(r) => (
                serde_json::from_value(r["curve"].clone()).unwrap_or_default(),
                r.get("accepted").and_then(Value::as_bool),
            ),
            None => (
                artifact(&state, id, &curve_name)
                    .await?
                    .and_then(|b| serde_json::from_slice(&b).ok())
                    .unwrap_or_default(),
                None,
            ),
        };
        corrections.push(CorrectionItem {
            key: key.clone(),
            clip: Some(clip),
            state: job_state.clone(),
            progress: *progress,
            accepted,
            curve,
        });
    }
    Ok(Json(Library {
        title: format!("{dataset_name}: augmentation {}", &id.to_string()[..8]),
        clips: listed,
        corrections,
    }))
}

fn group_of(entry: &Value) -> String {
    stem(entry.get("source").and_then(Value::as_str).unwrap_or(""))
}

/// One of an augmentation's clips: meta, frames or flags
///
/// `file` is an output (`<name>.bvh`) or a clip kept between jobs (`work/...npz`).
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}/view/{part}/{*file}",
    operation_id = "augmentationClipView",
    tag = "viewer",
    params(
        ("id" = Uuid, Path, description = "The augmentation's id"),
        ("file" = String, Path, description = "The clip's file"),
        PartParams,
    ),
    responses(PartResponses)
)]
pub async fn augmentation_clip_view(
    State(state): State<AppState>,
    tenant: Tenant,
    Path((id, part, file)): Path<(Uuid, String, String)>,
    Query(page): Query<Page>,
) -> Result<Response, ApiError> {
    let (dataset, _) = augmentation_dataset(&state, &tenant, id).await?;
    let sha: Option<Vec<u8>> =
        sqlx::query_scalar("SELECT sha256 FROM artifacts WHERE augmentation_id = $1 AND name = $2")
            .bind(id)
            .bind(&file)
            .fetch_optional(&state.db)
            .await?;
    let sha = sha.ok_or_else(|| ApiError::not_found("file"))?;
    let key = format!("artifact:{id}:{}", hex(&sha));
    clip_part(key, &part, &page, load_output(&state, dataset, id, file)).await
}

/// What preparing an augmentation's clip `file` needs from the database
/// (the file, the mask of an output, its manifest entry for the IK marks),
/// and the preparation.
async fn load_output(
    state: &AppState,
    dataset: Uuid,
    id: Uuid,
    file: String,
) -> Result<impl FnOnce() -> Result<ClipView, String> + Send + 'static, ApiError> {
    let content = artifact(state, id, &file)
        .await?
        .ok_or_else(|| ApiError::not_found("file"))?;
    let name = stem(&file);
    // An output's mask is in its NPZ; its IK edit in its manifest entry.
    let mask_npz = if file.ends_with(".bvh") {
        artifact(state, id, &format!("{}.npz", file.trim_end_matches(".bvh"))).await?
    } else {
        None
    };
    let rows = jobs(state, id).await?;
    let entry = rows.iter().find_map(|r| {
        let o = output_of(r);
        o.manifest
            .into_iter()
            .find(|e| e.get("file").and_then(Value::as_str) == Some(file.as_str()))
            .or_else(|| {
                o.clips
                    .into_iter()
                    .find(|c| c.file == file)
                    .map(|c| c.entry)
            })
    });
    let source_fps: Option<f64> = match &entry {
        Some(e) => {
            sqlx::query_scalar("SELECT fps FROM clips WHERE dataset_id = $1 AND name = $2")
                .bind(dataset)
                .bind(group_of(e))
                .fetch_optional(&state.db)
                .await?
        }
        None => None,
    };
    Ok(move || {
        let (motion, mask) = if file.ends_with(".bvh") {
            let m = motion::io::parse_bvh(&content, &file, motion::Unit::Auto)
                .map_err(|e| e.to_string())?;
            let mask = mask_npz.and_then(|b| {
                motion::npz::read(&b)
                    .ok()?
                    .into_iter()
                    .find(|a| a.name == "mask")?
                    .to_u8()
                    .map(|v| v.into_iter().map(|x| x != 0).collect::<Vec<bool>>())
            });
            (m, mask)
        } else {
            match pipeline::decode_clip(&content) {
                Ok((m, mask)) => (m, mask.map(|k| k.visible)),
                Err(_) => viewer::clip::npz_motion(&content, &file).map_err(|e| e.to_string())?,
            }
        };
        let mask = mask.filter(|m| m.len() == motion.frames() * motion.joints());
        let mut view =
            ClipView::from_motion(&name, &motion, mask.as_deref()).map_err(|e| e.to_string())?;
        if let Some(e) = &entry {
            let synth_fps = if e.get("correction").is_some_and(|c| !c.is_null()) {
                source_fps
            } else {
                e.get("fps").and_then(Value::as_f64)
            };
            if let (Some(effector), Some(keyframe), Some(fps)) = (
                e.get("effector").and_then(Value::as_str),
                e.get("keyframe").and_then(Value::as_u64),
                synth_fps,
            ) {
                let target = e
                    .get("target")
                    .and_then(|t| serde_json::from_value::<[f64; 3]>(t.clone()).ok());
                view = view.with_ik(effector, keyframe as f64 / fps, target);
            }
        }
        Ok(view)
    })
}

/// One stored file of an augmentation (a result, a correction report)
#[utoipa::path(
    get,
    path = "/v1/augmentations/{id}/files/{*file}",
    operation_id = "augmentationFile",
    tag = "viewer",
    params(
        ("id" = Uuid, Path, description = "The augmentation's id"),
        ("file" = String, Path, description = "The file's name, as the manifest gives it"),
    ),
    responses(
        (status = 200, description = "The file", body = inline(Binary)),
        (status = 401, response = Problem),
        (status = 404, response = Problem),
    )
)]
pub async fn augmentation_file(
    State(state): State<AppState>,
    tenant: Tenant,
    Path((id, file)): Path<(Uuid, String)>,
) -> Result<Response, ApiError> {
    augmentation_dataset(&state, &tenant, id).await?;
    let content = artifact(&state, id, &file)
        .await?
        .ok_or_else(|| ApiError::not_found("file"))?;
    let mime = if file.ends_with(".json") {
        "application/json"
    } else {
        "application/octet-stream"
    };
    let download = FsPath::new(&file)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok((
        [
            (header::CONTENT_TYPE, mime.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{download}\""),
            ),
        ],
        content,
    )
        .into_response())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Prepared clips of this process, most recent last.
const CACHED_CLIPS: usize = 16;

type Cache = Mutex<VecDeque<(String, Arc<ClipView>)>>;

fn cache() -> &'static Cache {
    static CACHE: OnceLock<Cache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(VecDeque::new()))
}

fn cache_get(key: &str) -> Option<Arc<ClipView>> {
    let cache = cache().lock().ok()?;
    cache.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())
}

/// The clip under `key`, prepared by `make` (off the async threads) when not cached.
async fn cached(
    key: &str,
    make: impl FnOnce() -> Result<ClipView, String> + Send + 'static,
) -> Result<Arc<ClipView>, ApiError> {
    if let Some(hit) = cache_get(key) {
        return Ok(hit);
    }
    let view = tokio::task::spawn_blocking(make)
        .await
        .map_err(|e| ApiError::internal(format!("preparing the clip failed: {e}")))?
        .map_err(ApiError::unprocessable)?;
    let view = Arc::new(view);
    if let Ok(mut cache) = cache().lock() {
        cache.retain(|(k, _)| k != key);
        cache.push_back((key.to_string(), view.clone()));
        while cache.len() > CACHED_CLIPS {
            cache.pop_front();
        }
    }
    Ok(view)
}

/// The parts of a clip the page reads, and their query.
const PARTS: [&str; 3] = ["meta", "frames", "flags"];

/// `part` (a path parameter) and the page of frames (query), shared by both
/// clip views.
pub struct PartParams;

impl IntoParams for PartParams {
    fn into_params(_: impl Fn() -> Option<ParameterIn>) -> Vec<Parameter> {
        let part = ParameterBuilder::new()
            .name("part")
            .parameter_in(ParameterIn::Path)
            .required(Required::True)
            .description(Some(
                "meta (JSON), frames (float32 [count, points, 3]) or flags (u8 [frames, points])",
            ))
            .schema(Some(String::schema()))
            .build();
        std::iter::once(part)
            .chain(Page::into_params(|| Some(ParameterIn::Query)))
            .collect()
    }
}

/// The answers of both clip views.
pub struct PartResponses;

impl IntoResponses for PartResponses {
    fn responses() -> BTreeMap<String, RefOr<openapi::Response>> {
        let part = ResponseBuilder::new()
            .description("The part: meta in JSON, frames and flags in bytes")
            .content(
                "application/json",
                ContentBuilder::new().schema(Some(Object::new())).build(),
            )
            .content(
                "application/octet-stream",
                ContentBuilder::new().schema(Some(Binary::schema())).build(),
            )
            .build();
        let problem = || RefOr::Ref(Ref::from_response_name("Problem"));
        BTreeMap::from([
            ("200".to_string(), part.into()),
            ("400".to_string(), problem()),
            ("401".to_string(), problem()),
            ("404".to_string(), problem()),
        ])
    }
}

/// A clip's `part` from the cache under `key`, or prepared (off the async
/// threads) by what `load` reads from the database; an unknown part is
/// "not found" before anything is read.
async fn clip_part<P>(
    key: String,
    part: &str,
    page: &Page,
    load: impl Future<Output = Result<P, ApiError>>,
) -> Result<Response, ApiError>
where
    P: FnOnce() -> Result<ClipView, String> + Send + 'static,
{
    if !PARTS.contains(&part) {
        return Err(ApiError::not_found("part (meta, frames or flags)"));
    }
    let view = match cache_get(&key) {
        Some(view) => view,
        None => cached(&key, load.await?).await?,
    };
    part_response(&view, part, page)
}

fn part_response(view: &ClipView, part: &str, page: &Page) -> Result<Response, ApiError> {
    let binary = |bytes: Vec<u8>| {
        ([(header::CONTENT_TYPE, "application/octet-stream")], bytes).into_response()
    };
    match part {
        "meta" => Ok(Json(view.meta().clone()).into_response()),
        "flags" => Ok(binary(view.flags().to_vec())),
        "frames" => {
            let start = page.start.unwrap_or(0);
            let count = page.count.unwrap_or(view.meta().frames);
            view.frames_bytes(start, count)
                .map(binary)
                .map_err(|e| ApiError::bad_request(e.to_string()))
        }
        _ => Err(ApiError::not_found("part (meta, frames or flags)")),
    }
}
