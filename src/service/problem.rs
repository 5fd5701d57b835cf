//! RFC 9457 problem details (`application/problem+json`), the one error shape of the API.

use super::domain::JobError;
use super::store::StoreError;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

/// Media type of every error body.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// A problem object. `type` is a relative URI naming the kind of problem (`/problems/{slug}`,
/// documented in openapi.yaml); `field` names the request member at fault where there is one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Problem {
    /// URI reference identifying the problem type.
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary of the problem type.
    pub title: String,
    /// HTTP status code.
    pub status: u16,
    /// Explanation specific to this occurrence.
    pub detail: String,
    /// The request path, where known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// The request member at fault (`params.tolerance`, `kind`, `mesh_id`, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// Seconds after which a retry may succeed (429, 503).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub retry_after: Option<u64>,
}

impl Problem {
    /// A problem of the given status, type slug and detail.
    pub fn new(status: StatusCode, slug: &str, detail: impl Into<String>) -> Problem {
        Problem {
            kind: format!("/problems/{slug}"),
            title: status.canonical_reason().unwrap_or("Error").to_string(),
            status: status.as_u16(),
            detail: detail.into(),
            instance: None,
            field: None,
            retry_after: None,
        }
    }
    /// 400 malformed request.
    pub fn bad_request(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::BAD_REQUEST, "bad-request", detail)
    }
    /// 404 for a missing resource.
    pub fn not_found(what: &str, id: &str) -> Problem {
        Problem::new(
            StatusCode::NOT_FOUND,
            "not-found",
            format!("no {what} `{id}`"),
        )
    }
    /// 409: the resource is in a state that forbids the request.
    pub fn conflict(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::CONFLICT, "conflict", detail)
    }
    /// 422 naming the request member at fault.
    pub fn invalid(field: &str, detail: impl Into<String>) -> Problem {
        let mut p = Problem::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid-request", detail);
        p.field = Some(field.to_string());
        p
    }
    /// 500: something broke on our side; details go to the log.
    pub fn internal(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", detail)
    }
    /// 415 for a body of the wrong media type.
    pub fn unsupported_media(detail: impl Into<String>) -> Problem {
        Problem::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported-media-type",
            detail,
        )
    }
    /// With a retry hint (sets `Retry-After`).
    pub fn retry_after(mut self, seconds: u64) -> Problem {
        self.retry_after = Some(seconds);
        self
    }
    /// With its `type` absolute under the API's base URL (where `GET /problems/{slug}`
    /// documents it); unchanged when `base` is empty.
    pub fn under(mut self, base: &str) -> Problem {
        if self.kind.starts_with('/') {
            self.kind = format!("{base}{}", self.kind);
        }
        self
    }
    /// The HTTP status.
    pub fn status_code(&self) -> StatusCode {
        StatusCode::from_u16(self.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR)
    }
}

impl IntoResponse for Problem {
    fn into_response(mut self) -> Response {
        let status = self.status_code();
        // Details quote what the client sent (a kind, a member name, an id): a bounded
        // quote, never a 50 MB echo.
        cap(&mut self.detail, MAX_DETAIL);
        if let Some(f) = &mut self.field {
            cap(f, MAX_FIELD);
        }
        let body = serde_json::to_vec(&self).unwrap_or_default();
        let mut res = (status, body).into_response();
        let h = res.headers_mut();
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if let Some(s) = self.retry_after {
            h.insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if status == StatusCode::UNAUTHORIZED {
            h.insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        res
    }
}

/// Longest `detail` sent, in bytes.
const MAX_DETAIL: usize = 2000;
/// Longest `field` sent, in bytes.
const MAX_FIELD: usize = 200;

/// Cut `s` to at most `max` bytes (on a character boundary), marking the cut with `…`.
fn cap(s: &mut String, max: usize) {
    if s.len() <= max {
        return;
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    s.truncate(end);
    s.push('…');
}

impl From<StoreError> for Problem {
    fn from(e: StoreError) -> Problem {
        if let StoreError::Full(_) = e {
            tracing::warn!(error = %e, "storage full");
            return Problem::new(
                StatusCode::INSUFFICIENT_STORAGE,
                "insufficient-storage",
                "the server's storage is full: nothing of this request was kept; retry once \
                 space is freed (reads, downloads and deletes still work)",
            )
            .retry_after(60);
        }
        // Paths and driver messages go to the log, not to the client.
        tracing::error!(error = %e, "store error");
        Problem::internal("storage error (the server log has the details)")
    }
}

/// A failed job's error as the problem object clients see: 500 for faults on our side
/// (interrupted runs, storage, panics), 422 for the request's.
impl From<&JobError> for Problem {
    fn from(e: &JobError) -> Problem {
        let status = if e.code.is_server_fault() {
            StatusCode::INTERNAL_SERVER_ERROR
        } else {
            StatusCode::UNPROCESSABLE_ENTITY
        };
        let mut p = Problem::new(status, e.code.slug(), e.detail.clone());
        p.field = e.field.clone();
        p
    }
}

/// Every problem type the API uses: slug, title, what it means and what to do. Served as
/// documentation at `GET /problems/{slug}`, where each problem's absolute `type` points.
pub const TYPES: &[(&str, &str, &str)] = &[
    ("bad-request", "Bad Request", "The request is malformed: its body is not valid JSON, not an object, or a multipart body cannot be read. Fix the request; retrying it unchanged fails again."),
    ("unauthorized", "Unauthorized", "API keys are configured and the request has no valid `Authorization: Bearer <key>` header (the scheme is case-insensitive)."),
    ("not-found", "Not Found", "No such route, mesh or job (it may have expired: ended jobs are kept for the retention period), or the job produced no such file."),
    ("method-not-allowed", "Method Not Allowed", "The route exists but not with this HTTP method."),
    ("request-timeout", "Request Timeout", "The request (an upload included) took longer than the server's request timeout."),
    ("conflict", "Conflict", "The resource is in a state that forbids the request: results of a job that has not succeeded, a mesh still used by a queued or running job, a cancel of a job that already succeeded or failed."),
    ("insufficient-storage", "Insufficient Storage", "The server's storage (its data directory or database) is full: nothing of the request was kept. Retry after the time in `Retry-After`, once the operator has freed space; reads, downloads and deletes still work."),
    ("uri-too-long", "URI Too Long", "The request target (the URL's path and query) is longer than the server reads. Nothing asks for URLs that long: check the client."),
    ("header-fields-too-large", "Request Header Fields Too Large", "The request's head is larger than the server reads (about 400 KB, or more than 100 header fields). Send fewer or shorter headers."),
    ("payload-too-large", "Payload Too Large", "The body is larger than the server's upload limit, or the mesh it holds expands to more triangles or vertices than the server's `--max-triangles` (counted after glTF instancing and polygon triangulation, before the mesh is read)."),
    ("unsupported-media-type", "Unsupported Media Type", "The body's media type is not one this route takes (meshes: model/gltf-binary, model/gltf+json, model/obj, application/octet-stream or multipart/form-data; jobs: application/json or multipart/form-data)."),
    ("invalid-request", "Unprocessable Content", "The request is well-formed but a member is wrong: `field` names it (`kind`, `params.tolerance`, `mesh_id`, `page_token`, …) and `detail` says what is expected. For a failed job: its input mesh or parameters turned out unusable."),
    ("queue-full", "Too Many Requests", "The job queue is full. Retry after the `Retry-After` seconds; polls and downloads are still served."),
    ("too-many-requests", "Too Many Requests", "Too many requests; retry after the `Retry-After` seconds."),
    ("unavailable", "Service Unavailable", "The server cannot reach its store; retry after the `Retry-After` seconds."),
    ("internal", "Internal Server Error", "Something broke on the server's side; the log has the details (search it for the response's `x-request-id`)."),
    ("time-limit", "Unprocessable Content", "A job reached the server's job time limit, or was about to start a step that would have ended past it, and was stopped. Submit it with a looser tolerance or fewer iterations, or ask for a longer limit."),
    ("algorithm-failed", "Unprocessable Content", "The algorithm stopped with an error on this input (`detail` says why), for example a mesh it cannot handle."),
    ("interrupted", "Internal Server Error", "The job's process stopped while it ran, as many times as the server allows (`--max-attempts`); submit it again."),
    ("cancelled", "Cancelled", "A client cancelled the job (before it started or while it ran); it has no results. Not an error of the job itself."),
];

/// Slug of a problem type for statuses produced by middleware (limits, timeouts, routing).
pub fn slug_for(status: StatusCode) -> &'static str {
    match status.as_u16() {
        400 => "bad-request",
        401 => "unauthorized",
        404 => "not-found",
        405 => "method-not-allowed",
        408 => "request-timeout",
        409 => "conflict",
        413 => "payload-too-large",
        415 => "unsupported-media-type",
        422 => "invalid-request",
        429 => "too-many-requests",
        503 => "unavailable",
        507 => "insufficient-storage",
        _ => "internal",
    }
}
