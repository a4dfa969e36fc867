//! The OpenAPI document and a self-contained HTML page that renders it (no CDN,
//! so it works offline).

use axum::Extension;
use axum::http::header;
use axum::response::{Html, IntoResponse};

use crate::openapi::OpenApiJson;

const PAGE: &str = include_str!("../../static/docs.html");

/// This document
///
/// Generated from the coordinator's handlers and types.
#[utoipa::path(
    get,
    path = "/openapi.json",
    operation_id = "openapi",
    tag = "operations",
    security(),
    responses((status = 200, description = "OpenAPI", content_type = "application/json", body = Object))
)]
pub async fn openapi(Extension(document): Extension<OpenApiJson>) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/json")], document.0)
}

/// API documentation page (works offline)
#[utoipa::path(
    get,
    path = "/docs",
    operation_id = "docs",
    tag = "operations",
    security(),
    responses((status = 200, description = "HTML", content_type = "text/html", body = String))
)]
pub async fn page() -> Html<&'static str> {
    Html(PAGE)
}

/// The API documentation page, at the root
#[utoipa::path(
    get,
    path = "/",
    operation_id = "index",
    tag = "operations",
    security(),
    responses((status = 200, description = "HTML", content_type = "text/html", body = String))
)]
pub async fn index() -> Html<&'static str> {
    Html(PAGE)
}
