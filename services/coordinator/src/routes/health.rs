//! Liveness, readiness and Prometheus metrics.

use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::error::{ApiError, Problem};
use crate::startup::AppState;

/// Liveness
///
/// The process is up.
#[utoipa::path(
    get,
    path = "/healthz",
    operation_id = "healthz",
    tag = "operations",
    security(),
    responses((status = 200, description = "ok", content_type = "text/plain", body = String))
)]
pub async fn healthz() -> &'static str {
    "ok"
}

/// What the coordinator can reach.
#[derive(Debug, Serialize, ToSchema)]
pub struct Readiness {
    /// `ok` or `unreachable`.
    pub database: &'static str,
    /// `ok`, `unreachable` or `disabled` (no REDIS_URL).
    pub redis: &'static str,
}

/// Readiness (database reachable; Redis reported)
///
/// Ready when the database answers. Redis is reported but optional: without it
/// events fall back to polling.
#[utoipa::path(
    get,
    path = "/readyz",
    operation_id = "readyz",
    tag = "operations",
    security(),
    responses(
        (status = 200, description = "ready", body = Readiness),
        (status = 503, description = "not ready", body = Readiness),
    )
)]
pub async fn readyz(State(state): State<AppState>) -> Response {
    let db_ok = sqlx::query_scalar::<_, i32>("SELECT 1")
        .fetch_one(&state.db)
        .await
        .is_ok();
    let redis = match state.events.redis_ok().await {
        None => "disabled",
        Some(true) => "ok",
        Some(false) => "unreachable",
    };
    let status = if db_ok {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    let body = Readiness {
        database: if db_ok { "ok" } else { "unreachable" },
        redis,
    };
    (status, Json(body)).into_response()
}

/// Prometheus metrics
///
/// Queue depth and worker count are read from Postgres at scrape time.
#[utoipa::path(
    get,
    path = "/metrics",
    operation_id = "metrics",
    tag = "operations",
    security(),
    responses(
        (status = 200, description = "metrics", content_type = "application/openmetrics-text", body = String),
        (status = 500, response = Problem),
    )
)]
pub async fn metrics(State(state): State<AppState>) -> Result<Response, ApiError> {
    let text = state
        .metrics
        .render(&state.db, state.config.queue.lease)
        .await?;
    Ok((
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        text,
    )
        .into_response())
}
