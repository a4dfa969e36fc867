//! HTTP routes: the public `/v1` API, the internal worker API and the operational
//! endpoints (health, metrics, OpenAPI).

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::routing::{get, post, put};

use crate::startup::AppState;

pub mod augmentations;
pub mod datasets;
pub mod docs;
pub mod health;
pub mod worker;

/// JSON bodies other than uploads and artifacts (recipes, worker reports).
pub const JSON_BODY_LIMIT: usize = 4 << 20;

pub fn router(state: AppState) -> Router<AppState> {
    let limits = &state.config.limits;
    let public = Router::new()
        .route(
            "/v1/datasets",
            post(datasets::create)
                .layer(DefaultBodyLimit::max(limits.max_upload_bytes))
                .get(datasets::list),
        )
        .route(
            "/v1/datasets/{id}",
            get(datasets::get).delete(datasets::delete),
        )
        .route(
            "/v1/datasets/{id}/augmentations",
            post(augmentations::create).get(augmentations::list),
        )
        .route(
            "/v1/augmentations/{id}",
            get(augmentations::get).delete(augmentations::cancel),
        )
        .route("/v1/augmentations/{id}/events", get(augmentations::events))
        .route(
            "/v1/augmentations/{id}/results",
            get(augmentations::results),
        );
    let internal = Router::new()
        .route("/internal/v1/jobs/claim", post(worker::claim))
        .route("/internal/v1/jobs/{id}/heartbeat", post(worker::heartbeat))
        .route("/internal/v1/jobs/{id}/complete", post(worker::complete))
        .route("/internal/v1/jobs/{id}/fail", post(worker::fail))
        .route("/internal/v1/jobs/{id}/release", post(worker::release))
        .route(
            "/internal/v1/jobs/{id}/checkpoint",
            put(worker::put_checkpoint)
                .get(worker::get_checkpoint)
                .layer(DefaultBodyLimit::max(limits.max_artifact_bytes)),
        )
        .route(
            "/internal/v1/jobs/{id}/artifacts/{*name}",
            put(worker::put_artifact).layer(DefaultBodyLimit::max(limits.max_artifact_bytes)),
        )
        .route(
            "/internal/v1/jobs/{id}/inputs/{*name}",
            get(worker::get_input),
        )
        .route("/internal/v1/clips/{id}/source", get(worker::clip_source))
        .route(
            "/internal/v1/clips/{id}/skeleton",
            get(worker::clip_skeleton),
        );
    let ops = Router::new()
        .route("/healthz", get(health::healthz))
        .route("/readyz", get(health::readyz))
        .route("/metrics", get(health::metrics))
        .route("/openapi.json", get(docs::openapi))
        .route("/docs", get(docs::page))
        .route("/", get(docs::page));
    public
        .merge(internal)
        .merge(ops)
        .layer(DefaultBodyLimit::max(JSON_BODY_LIMIT))
        .fallback(|| async { crate::error::ApiError::not_found("route") })
}
