//! Operational routes: health, readiness, metrics, version, the API description.

use super::{blocking, ApiResult};
use crate::jobs::Kind;
use crate::service::domain::Status;
use crate::service::problem::{self, Problem};
use crate::service::state::AppState;
use axum::extract::{Path, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::json;

/// The OpenAPI 3.1 description, as written.
pub const OPENAPI: &str = include_str!("../../../openapi.yaml");

/// `GET /healthz`: the process answers.
pub async fn healthz() -> Response {
    Json(json!({"status": "ok"})).into_response()
}

/// `GET /readyz`: this replica can serve requests (its store answers; 503 otherwise). A
/// full queue or a full disk is not unreadiness: the replica still answers polls and
/// downloads, so it reports `queue_full` (429s on submit) and `storage_full` (507s).
pub async fn readyz(State(st): State<AppState>) -> ApiResult {
    let (store, exec) = (st.store.clone(), st.exec.clone());
    let (queued, storage_full) = blocking(move || {
        let unavailable = |e: crate::service::store::StoreError| {
            Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "unavailable",
                format!("store: {e}"),
            )
            .retry_after(5)
        };
        store.ping().map_err(unavailable)?;
        // A full store still serves reads, downloads and deletes, so it is reported, not
        // unready.
        let storage_full = !crate::service::store::has_room(&*store).map_err(unavailable)?;
        Ok((store.count_with_status(Status::Queued)?, storage_full))
    })
    .await?;
    let max_queued = exec.limits.max_queued;
    Ok(Json(json!({
        "status": "ready",
        "queued": queued,
        "max_queued": max_queued,
        "queue_full": queued >= max_queued,
        "storage_full": storage_full,
        "running": st.exec.running(),
    }))
    .into_response())
}

/// `GET /metrics`.
pub async fn metrics(State(st): State<AppState>) -> Response {
    // The queue is the store's, shared by every replica: its depth as of now, not as of this
    // replica's last submit or claim (unchanged when the store does not answer).
    let store = st.store.clone();
    if let Ok(n) = blocking(move || Ok(store.count_with_status(Status::Queued)?)).await {
        st.metrics.set_queued(n);
    }
    st.metrics.set_queue_limit(st.exec.limits.max_queued);
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        st.metrics.render(),
    )
        .into_response()
}

/// `GET /version`.
pub async fn version() -> Response {
    Json(json!({
        "name": "flatmesh",
        "version": env!("CARGO_PKG_VERSION"),
        "kinds": Kind::names(),
    }))
    .into_response()
}

/// `GET /openapi.yaml`.
pub async fn openapi() -> Response {
    ([(header::CONTENT_TYPE, "application/yaml")], OPENAPI).into_response()
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A small HTML page (problem type documentation: what a problem's `type` resolves to).
fn page(title: &str, body: &str) -> Response {
    let html = format!(
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title></head>\
         <body>{body}</body></html>",
        html_escape(title)
    );
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], html).into_response()
}

/// `GET /problems`: every problem type of the API.
pub async fn problem_types() -> Response {
    let items: String = problem::TYPES
        .iter()
        .map(|(slug, title, _)| {
            format!(
                "<li><a href=\"problems/{slug}\"><code>{slug}</code></a>: {}</li>",
                html_escape(title)
            )
        })
        .collect();
    page(
        "flatmesh problem types",
        &format!("<h1>Problem types</h1><p>Every error of the API is an RFC 9457 problem whose <code>type</code> is one of these.</p><ul>{items}</ul>"),
    )
}

/// `GET /problems/{slug}`: what a problem type means and what to do about it.
pub async fn problem_type(Path(slug): Path<String>) -> ApiResult {
    let (slug, title, text) = problem::TYPES
        .iter()
        .find(|(s, _, _)| *s == slug)
        .ok_or_else(|| Problem::not_found("problem type", &slug))?;
    Ok(page(
        &format!("{slug}: {title}"),
        &format!(
            "<h1><code>{slug}</code>: {}</h1><p>{}</p><p><a href=\"../problems\">All problem types</a></p>",
            html_escape(title),
            html_escape(text)
        ),
    ))
}
