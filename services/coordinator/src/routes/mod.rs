//! HTTP routes: the public `/v1` API, the internal worker API and the operational
//! endpoints (health, metrics, OpenAPI).
//!
//! Every route is registered with `routes!`, which takes its path and methods from
//! the handler's `#[utoipa::path]`: the router and the OpenAPI document are built
//! together here, so a route cannot exist without being documented.

use axum::extract::DefaultBodyLimit;
use utoipa_axum::router::{OpenApiRouter, UtoipaMethodRouterExt};
use utoipa_axum::routes;

use crate::configuration::Limits;
use crate::openapi;
use crate::startup::AppState;

pub mod augmentations;
pub mod datasets;
pub mod docs;
pub mod health;
pub mod limits;
pub mod viewer;
pub mod worker;

/// JSON bodies other than uploads and artifacts (recipes, worker reports).
pub const JSON_BODY_LIMIT: usize = 4 << 20;

/// Every route with its OpenAPI operation. Uploads and worker files get their own
/// body limits; every other body is limited to [`JSON_BODY_LIMIT`].
pub fn router(limits: &Limits) -> OpenApiRouter<AppState> {
    let upload_limit = DefaultBodyLimit::max(limits.max_upload_bytes);
    let artifact_limit = DefaultBodyLimit::max(limits.max_artifact_bytes);
    OpenApiRouter::with_openapi(openapi::base())
        // Public API (tenant API key).
        .routes(routes!(datasets::create).layer(upload_limit))
        .routes(routes!(datasets::list))
        .routes(routes!(datasets::get, datasets::delete))
        .routes(routes!(augmentations::create, augmentations::list))
        .routes(routes!(augmentations::get, augmentations::cancel))
        .routes(routes!(augmentations::events))
        .routes(routes!(augmentations::results))
        // The viewer page and what it reads (tenant API key for /v1).
        .routes(routes!(viewer::dataset_library))
        .routes(routes!(viewer::dataset_clip_view))
        .routes(routes!(viewer::augmentation_library))
        .routes(routes!(viewer::augmentation_clip_view))
        .routes(routes!(viewer::augmentation_file))
        .routes(routes!(viewer::page))
        .routes(routes!(viewer::redirect))
        .routes(routes!(viewer::info))
        .routes(routes!(viewer::asset))
        .routes(routes!(limits::get))
        // Internal worker API (worker token).
        .routes(routes!(worker::claim))
        .routes(routes!(worker::heartbeat))
        .routes(routes!(worker::complete))
        .routes(routes!(worker::fail))
        .routes(routes!(worker::release))
        .routes(routes!(worker::put_checkpoint, worker::get_checkpoint).layer(artifact_limit))
        .routes(routes!(worker::put_artifact).layer(artifact_limit))
        .routes(routes!(worker::get_input))
        .routes(routes!(worker::clip_source))
        .routes(routes!(worker::clip_skeleton))
        // Operations (no authentication).
        .routes(routes!(health::healthz))
        .routes(routes!(health::readyz))
        .routes(routes!(health::metrics))
        .routes(routes!(docs::openapi))
        .routes(routes!(docs::page))
        .routes(routes!(docs::index))
        .layer(DefaultBodyLimit::max(JSON_BODY_LIMIT))
        .fallback(|| async { crate::error::ApiError::not_found("route") })
}
