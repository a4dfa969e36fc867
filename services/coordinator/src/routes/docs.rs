//! The OpenAPI document and a self-contained HTML page that renders it (no CDN,
//! so it works offline).

use axum::http::header;
use axum::response::{Html, IntoResponse};

pub const OPENAPI: &str = include_str!("../../static/openapi.json");
const PAGE: &str = include_str!("../../static/docs.html");

pub async fn openapi() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/json")], OPENAPI)
}

pub async fn page() -> Html<&'static str> {
    Html(PAGE)
}
