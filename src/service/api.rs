//! HTTP handlers. Every error is a [`Problem`]; CPU work (parsing meshes, reports) runs on
//! blocking threads, jobs on the executor's pool.

use super::jobs::now_ms;
use super::problem::Problem;
use super::store::{Inserted, JobFilter, JobRecord, MeshRecord, Status};
use super::AppState;
use crate::algorithms::AlgoError;
use crate::io;
use crate::jobs::{JobSpec, Kind, SpecError};
use axum::body::Bytes;
use axum::extract::{Multipart, Path, Query, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Map, Value};
use sha2::{Digest, Sha256};
use std::collections::HashMap;

type ApiResult = Result<Response, Problem>;

/// RFC 3339 UTC timestamp of milliseconds since the epoch.
pub fn rfc3339(ms: i64) -> String {
    let t = std::time::UNIX_EPOCH + std::time::Duration::from_millis(ms.max(0) as u64);
    humantime::format_rfc3339_millis(t).to_string()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn new_id(prefix: &str) -> String {
    format!("{prefix}_{}", uuid::Uuid::new_v4().simple())
}

/// The public JSON of a job. `progress` overrides the stored progress (live value).
pub fn job_json(j: &JobRecord, progress: Option<Value>, base: &str) -> Value {
    let me = format!("{base}/v1/jobs/{}", j.id);
    let mut links = Map::new();
    links.insert("self".into(), json!(me));
    if !j.status.is_terminal() {
        links.insert("cancel".into(), json!(format!("{me}/cancel")));
    }
    if j.status == Status::Succeeded {
        links.insert("result".into(), json!(format!("{me}/result")));
        links.insert("mesh".into(), json!(format!("{me}/mesh?format=glb")));
        if j.artifacts.iter().any(|a| a == "patterns.json") {
            links.insert(
                "patterns".into(),
                json!(format!("{me}/patterns?format=json")),
            );
        }
    }
    let outcome = |k: &str| j.outcome.as_ref().and_then(|o| o.get(k)).cloned();
    json!({
        "id": j.id,
        "kind": j.kind,
        "status": j.status.as_str(),
        "mesh_id": j.mesh_id,
        "reference_mesh_id": j.reference_mesh_id,
        "params": j.params,
        "callback_url": j.callback_url,
        "progress": progress.or_else(|| j.progress.clone()),
        "error": j.error,
        "attempts": j.attempts,
        "converged": outcome("converged"),
        "max_flattenability": outcome("max_flattenability"),
        "stop_reason": outcome("stop_reason"),
        "created_at": rfc3339(j.created_at),
        "started_at": j.started_at.map(rfc3339),
        "finished_at": j.finished_at.map(rfc3339),
        "expires_at": j.expires_at.map(rfc3339),
        "links": links,
    })
}

fn mesh_json(m: &MeshRecord) -> Value {
    let mut v = m.summary.clone();
    if let Some(o) = v.as_object_mut() {
        o.insert("id".into(), json!(m.id));
        o.insert("created_at".into(), json!(rfc3339(m.created_at)));
        o.insert("format".into(), json!(m.format));
        o.insert("size".into(), json!(m.size));
        o.insert(
            "links".into(),
            json!({"self": format!("/v1/meshes/{}", m.id), "report": format!("/v1/meshes/{}/report", m.id)}),
        );
    }
    v
}

fn media_type(headers: &HeaderMap) -> Option<String> {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .map(|s| {
            s.split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        })
}

/// The mesh format of a media type, or of the bytes for `application/octet-stream`.
fn format_of(media: &str, filename: Option<&str>, bytes: &[u8]) -> Option<io::Format> {
    match media {
        "model/gltf-binary" => Some(io::Format::Glb),
        "model/gltf+json" => Some(io::Format::Gltf),
        "model/obj" => Some(io::Format::Obj),
        "model/off" => Some(io::Format::Off),
        "" | "application/octet-stream" | "text/plain" => filename
            .and_then(|f| f.rsplit_once('.'))
            .and_then(|(_, ext)| io::Format::from_extension(ext))
            .or_else(|| io::Format::sniff(bytes)),
        _ => None,
    }
}

const MESH_TYPES: &str = "model/gltf-binary, model/gltf+json, model/obj or multipart/form-data";

/// Parse, validate and store a mesh; `field` names it in errors.
async fn store_mesh(
    st: &AppState,
    bytes: Bytes,
    format: io::Format,
    field: &str,
) -> Result<MeshRecord, Problem> {
    let field_owned = field.to_string();
    let parsed = tokio::task::spawn_blocking(move || {
        let r = io::load(&bytes, format).map(|(mesh, warnings)| {
            let report = crate::report::Report::compute(&mesh, &warnings);
            json!({
                "vertices": report.vertices,
                "faces": report.faces,
                "patches": report.patches.iter().map(|p| p.name.clone()).collect::<Vec<_>>(),
                "interior_vertices": report.interior_vertices,
                "max_flattenability": report.max_flattenability,
                "developable": report.max_flattenability <= report.developable_tolerance,
                "warnings": warnings,
            })
        });
        (bytes, r)
    })
    .await
    .map_err(|e| Problem::internal(format!("mesh parser crashed: {e}")))?;
    let (bytes, summary) = parsed;
    let summary = summary.map_err(|e| {
        Problem::invalid(
            &field_owned,
            format!("invalid {} mesh: {e}", format.extension()),
        )
    })?;
    let rec = MeshRecord {
        id: new_id("m"),
        created_at: now_ms(),
        format: format.extension().to_string(),
        size: bytes.len() as u64,
        sha256: sha256_hex(&bytes),
        summary,
    };
    let store = st.store.clone();
    let r2 = rec.clone();
    tokio::task::spawn_blocking(move || {
        store.put_blob(&format!("meshes/{}", r2.id), &bytes)?;
        store.insert_mesh(&r2)
    })
    .await
    .map_err(|e| Problem::internal(e.to_string()))??;
    st.metrics.uploaded();
    Ok(rec)
}

fn multipart_err(e: axum::extract::multipart::MultipartError) -> Problem {
    let status = e.status();
    Problem::new(status, super::problem::slug_for(status), e.body_text())
}

/// A file part of a multipart body: its bytes and mesh format.
async fn mesh_part(
    field: axum::extract::multipart::Field<'_>,
    name: &str,
) -> Result<(Bytes, io::Format), Problem> {
    let media = field
        .content_type()
        .map(|s| {
            s.split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        })
        .unwrap_or_default();
    let filename = field.file_name().map(str::to_string);
    let bytes = field.bytes().await.map_err(multipart_err)?;
    let format = format_of(&media, filename.as_deref(), &bytes).ok_or_else(|| {
        Problem::unsupported_media(format!(
            "part `{name}`: media type `{media}` is not a mesh format (expected {MESH_TYPES})"
        ))
    })?;
    Ok((bytes, format))
}

/// `POST /v1/meshes`.
pub async fn upload_mesh(
    State(st): State<AppState>,
    headers: HeaderMap,
    request: axum::extract::Request,
) -> ApiResult {
    let media = media_type(&headers).unwrap_or_default();
    let rec = if media == "multipart/form-data" {
        let mut mp = <Multipart as axum::extract::FromRequest<()>>::from_request(request, &())
            .await
            .map_err(|e| Problem::bad_request(e.body_text()))?;
        let mut rec = None;
        while let Some(field) = mp.next_field().await.map_err(multipart_err)? {
            if field.name() == Some("mesh") && rec.is_none() {
                let (bytes, format) = mesh_part(field, "mesh").await?;
                rec = Some(store_mesh(&st, bytes, format, "mesh").await?);
            }
        }
        rec.ok_or_else(|| Problem::invalid("mesh", "the multipart body has no `mesh` part"))?
    } else {
        let bytes = axum::body::to_bytes(request.into_body(), st.max_upload)
            .await
            .map_err(|_| {
                Problem::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "payload-too-large",
                    format!("the body exceeds {} bytes", st.max_upload),
                )
            })?;
        let format = format_of(&media, None, &bytes).ok_or_else(|| {
            Problem::unsupported_media(format!(
                "media type `{media}` is not a mesh format (expected {MESH_TYPES})"
            ))
        })?;
        store_mesh(&st, bytes, format, "body").await?
    };
    let mut res = (StatusCode::CREATED, Json(mesh_json(&rec))).into_response();
    let h = res.headers_mut();
    h.insert(header::LOCATION, hv(&format!("/v1/meshes/{}", rec.id)));
    h.insert(header::ETAG, hv(&format!("\"{}\"", rec.sha256)));
    Ok(res)
}

fn hv(s: &str) -> HeaderValue {
    HeaderValue::from_str(s).unwrap_or(HeaderValue::from_static(""))
}

async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, Problem> + Send + 'static,
) -> Result<T, Problem> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Problem::internal(format!("worker crashed: {e}")))?
}

async fn get_mesh_rec(st: &AppState, id: &str) -> Result<MeshRecord, Problem> {
    let store = st.store.clone();
    let id2 = id.to_string();
    blocking(move || Ok(store.get_mesh(&id2)?))
        .await?
        .ok_or_else(|| Problem::not_found("mesh", id))
}

/// `GET /v1/meshes/{id}`.
pub async fn get_mesh(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    let rec = get_mesh_rec(&st, &id).await?;
    let mut res = Json(mesh_json(&rec)).into_response();
    res.headers_mut()
        .insert(header::ETAG, hv(&format!("\"{}\"", rec.sha256)));
    Ok(res)
}

/// `GET /v1/meshes/{id}/report`: the flattenability report, computed now.
pub async fn mesh_report(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    let rec = get_mesh_rec(&st, &id).await?;
    let store = st.store.clone();
    let body = blocking(move || {
        let bytes = store
            .get_blob(&format!("meshes/{}", rec.id))?
            .ok_or_else(|| Problem::internal("mesh bytes lost"))?;
        let format = io::Format::from_extension(&rec.format)
            .ok_or_else(|| Problem::internal("stored format unknown"))?;
        let (mesh, warnings) =
            io::load(&bytes, format).map_err(|e| Problem::internal(e.to_string()))?;
        let report = crate::report::Report::compute(&mesh, &warnings);
        serde_json::to_vec(&report).map_err(|e| Problem::internal(e.to_string()))
    })
    .await?;
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}

/// `DELETE /v1/meshes/{id}`: 409 while a queued or running job uses it.
pub async fn delete_mesh(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    let store = st.store.clone();
    let id2 = id.clone();
    blocking(move || {
        if store.get_mesh(&id2)?.is_none() {
            return Err(Problem::not_found("mesh", &id2));
        }
        if store.mesh_in_use(&id2)? {
            return Err(Problem::conflict(format!(
                "mesh `{id2}` is used by a queued or running job"
            )));
        }
        store.delete_mesh(&id2)?;
        store.delete_blobs(&format!("meshes/{id2}"))?;
        Ok(())
    })
    .await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// A job request, as parsed from JSON (or from the `job` part of a multipart body).
struct Submit {
    kind: String,
    mesh_id: Option<String>,
    reference_mesh_id: Option<String>,
    params: Map<String, Value>,
    callback_url: Option<String>,
}

fn opt_string(o: &Map<String, Value>, key: &str) -> Result<Option<String>, Problem> {
    match o.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => Err(Problem::invalid(key, format!("`{key}` must be a string"))),
    }
}

fn parse_submit(body: &[u8], multipart: bool) -> Result<Submit, Problem> {
    let v: Value = serde_json::from_slice(body)
        .map_err(|e| Problem::bad_request(format!("the body is not valid JSON: {e}")))?;
    let Value::Object(o) = v else {
        return Err(Problem::bad_request("the body must be a JSON object"));
    };
    let allowed: &[&str] = if multipart {
        &["kind", "params", "callback_url"]
    } else {
        &[
            "kind",
            "mesh_id",
            "reference_mesh_id",
            "params",
            "callback_url",
        ]
    };
    if let Some(k) = o.keys().find(|k| !allowed.contains(&k.as_str())) {
        return Err(Problem::invalid(
            k,
            format!("unknown member `{k}` (allowed: {})", allowed.join(", ")),
        ));
    }
    let kind =
        opt_string(&o, "kind")?.ok_or_else(|| Problem::invalid("kind", "`kind` is required"))?;
    let mesh_id = opt_string(&o, "mesh_id")?;
    if !multipart && mesh_id.is_none() {
        return Err(Problem::invalid("mesh_id", "`mesh_id` is required"));
    }
    let params = match o.get("params") {
        None | Some(Value::Null) => Map::new(),
        Some(Value::Object(p)) => p.clone(),
        Some(_) => return Err(Problem::invalid("params", "`params` must be an object")),
    };
    Ok(Submit {
        kind,
        mesh_id,
        reference_mesh_id: opt_string(&o, "reference_mesh_id")?,
        params,
        callback_url: opt_string(&o, "callback_url")?,
    })
}

/// The 422 for a job the registry refuses, naming the request field at fault.
fn spec_problem(e: SpecError) -> Problem {
    match e {
        SpecError::UnknownKind(_) => Problem::invalid("kind", e.to_string()),
        SpecError::Params(AlgoError::InvalidParam { ref key, .. }) => {
            let field = if key.is_empty() {
                "params".to_string()
            } else {
                format!("params.{key}")
            };
            Problem::invalid(&field, e.to_string())
        }
        SpecError::Params(other) => Problem::invalid("params", other.to_string()),
        SpecError::Reference(m) => Problem::invalid("reference_mesh_id", m),
    }
}

/// Checks that need no database: kind, params, callback URL, and (when `has_reference` is
/// known) whether the kind takes a reference body.
fn validate_submit(st: &AppState, s: &Submit, has_reference: Option<bool>) -> Result<(), Problem> {
    let spec = JobSpec::parse(&s.kind, &s.params).map_err(spec_problem)?;
    if let Some(r) = has_reference {
        spec.check_reference(r).map_err(spec_problem)?;
    }
    if let Some(u) = &s.callback_url {
        super::webhook::check_url(u, st.webhooks.allow_private())
            .map_err(|e| Problem::invalid("callback_url", format!("callback_url: {e}")))?;
    }
    Ok(())
}

fn queue_full(st: &AppState) -> Problem {
    Problem::new(
        StatusCode::TOO_MANY_REQUESTS,
        "queue-full",
        format!(
            "the job queue is full ({} waiting); retry later",
            st.exec.limits.max_queued
        ),
    )
    .retry_after(st.retry_after_secs())
}

/// `POST /v1/jobs`: JSON `{kind, mesh_id, reference_mesh_id?, params?, callback_url?}` or
/// multipart with parts `job` (JSON without mesh ids), `mesh` and optionally `reference`.
pub async fn submit_job(
    State(st): State<AppState>,
    headers: HeaderMap,
    request: axum::extract::Request,
) -> ApiResult {
    let key = match headers.get("idempotency-key") {
        None => None,
        Some(v) => {
            let s = v
                .to_str()
                .ok()
                .filter(|s| !s.is_empty() && s.len() <= 255)
                .ok_or_else(|| {
                    Problem::bad_request(
                        "Idempotency-Key must be 1 to 255 visible ASCII characters",
                    )
                })?;
            Some(s.to_string())
        }
    };
    let media = media_type(&headers).unwrap_or_default();
    let mut hasher = Sha256::new();
    let mut submit;
    // multipart uploads, stored only once the request is known not to be a replay
    let mut uploads: Vec<(&str, Bytes, io::Format)> = Vec::new();
    if media == "application/json" {
        let body = axum::body::to_bytes(request.into_body(), st.max_upload)
            .await
            .map_err(|_| {
                Problem::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "payload-too-large",
                    "body too large",
                )
            })?;
        submit = parse_submit(&body, false)?;
        validate_submit(&st, &submit, Some(submit.reference_mesh_id.is_some()))?;
        for (field, id) in [
            ("mesh_id", submit.mesh_id.clone()),
            ("reference_mesh_id", submit.reference_mesh_id.clone()),
        ] {
            if let Some(id) = id {
                if get_mesh_rec(&st, &id).await.is_err() {
                    return Err(Problem::invalid(field, format!("no mesh `{id}`")));
                }
                hasher.update(format!("{field}={id};"));
            }
        }
    } else if media == "multipart/form-data" {
        let mut mp = <Multipart as axum::extract::FromRequest<()>>::from_request(request, &())
            .await
            .map_err(|e| Problem::bad_request(e.body_text()))?;
        let mut job: Option<Submit> = None;
        let mut mesh = None;
        let mut reference = None;
        while let Some(field) = mp.next_field().await.map_err(multipart_err)? {
            match field.name().unwrap_or("") {
                "job" => {
                    let b = field.bytes().await.map_err(multipart_err)?;
                    let s = parse_submit(&b, true)?;
                    validate_submit(&st, &s, None)?;
                    job = Some(s);
                }
                "mesh" => mesh = Some(mesh_part(field, "mesh").await?),
                "reference" => reference = Some(mesh_part(field, "reference").await?),
                other => {
                    return Err(Problem::invalid(
                        other,
                        format!("unknown part `{other}` (allowed: job, mesh, reference)"),
                    ))
                }
            }
        }
        submit =
            job.ok_or_else(|| Problem::invalid("job", "the multipart body has no `job` part"))?;
        JobSpec::parse(&submit.kind, &submit.params)
            .and_then(|spec| spec.check_reference(reference.is_some()))
            .map_err(|e| match e {
                SpecError::Reference(m) => Problem::invalid("reference", m),
                e => spec_problem(e),
            })?;
        let (mb, mf) =
            mesh.ok_or_else(|| Problem::invalid("mesh", "the multipart body has no `mesh` part"))?;
        hasher.update(format!("mesh={};", sha256_hex(&mb)));
        if let Some((rb, _)) = &reference {
            hasher.update(format!("reference={};", sha256_hex(rb)));
        }
        uploads.push(("mesh", mb, mf));
        if let Some((rb, rf)) = reference {
            uploads.push(("reference", rb, rf));
        }
    } else {
        return Err(Problem::unsupported_media(format!(
            "media type `{media}`: expected application/json or multipart/form-data"
        )));
    }
    hasher.update(format!(
        "kind={};params={};callback={:?}",
        submit.kind,
        Value::Object(submit.params.clone()),
        submit.callback_url
    ));
    let request_hash = hex(&hasher.finalize());
    let replay = match &key {
        Some(k) if !uploads.is_empty() => {
            let (store, k) = (st.store.clone(), k.clone());
            blocking(move || Ok(store.find_idempotent(&k)?)).await?
        }
        _ => None,
    };
    // The uploads are validated like POST /v1/meshes and then referenced by id.
    let mut stored_here = Vec::new();
    if replay.is_none() {
        for (field, bytes, format) in uploads {
            let id = store_mesh(&st, bytes, format, field).await?.id;
            match field {
                "mesh" => submit.mesh_id = Some(id.clone()),
                _ => submit.reference_mesh_id = Some(id.clone()),
            }
            stored_here.push(id);
        }
    }
    if let Some(j) = replay {
        return submitted(&st, j, &request_hash, true);
    }
    let reserved = st.exec.reserve();
    let record = JobRecord {
        seq: 0,
        id: new_id("j"),
        kind: submit.kind,
        mesh_id: submit.mesh_id.unwrap_or_default(),
        reference_mesh_id: submit.reference_mesh_id,
        params: submit.params,
        callback_url: submit.callback_url,
        status: Status::Queued,
        progress: None,
        error: None,
        created_at: now_ms(),
        started_at: None,
        finished_at: None,
        expires_at: None,
        attempts: 0,
        artifacts: vec![],
        idempotency_key: key.clone(),
        request_hash: Some(request_hash.clone()),
        outcome: None,
    };
    let store = st.store.clone();
    let inserted = blocking(move || {
        if !reserved {
            // A full queue still answers a replayed request with its job.
            if let Some(k) = &record.idempotency_key {
                if let Some(j) = store.find_idempotent(k)? {
                    return Ok(Some(Inserted::Existing(j)));
                }
            }
            return Ok(None);
        }
        Ok(Some(store.insert_job(&record)?))
    })
    .await;
    let inserted = match inserted {
        Ok(i) => i,
        Err(p) => {
            if reserved {
                st.exec.release();
            }
            return Err(p);
        }
    };
    match inserted {
        None => Err(queue_full(&st)),
        Some(Inserted::New(j)) => {
            st.exec.enqueue(j.id.clone(), true);
            st.metrics.submitted();
            submitted(&st, j, &request_hash, false)
        }
        Some(Inserted::Existing(j)) => {
            if reserved {
                st.exec.release();
            }
            // A concurrent retry with the same key won the race: the meshes stored for this
            // request are not referenced by any job.
            let store = st.store.clone();
            let _ = blocking(move || {
                for id in stored_here {
                    store.delete_mesh(&id)?;
                    store.delete_blobs(&format!("meshes/{id}"))?;
                }
                Ok(())
            })
            .await;
            submitted(&st, j, &request_hash, true)
        }
    }
}

/// The 202 for a new or replayed job; a replay whose request differs is refused.
fn submitted(st: &AppState, job: JobRecord, request_hash: &str, replayed: bool) -> ApiResult {
    if replayed && job.request_hash.as_deref() != Some(request_hash) {
        return Err(Problem::invalid(
            "Idempotency-Key",
            "this Idempotency-Key was used with a different request",
        ));
    }
    let live = st
        .exec
        .live(&job.id)
        .and_then(|l| l.progress.lock().ok()?.clone());
    let mut res = (StatusCode::ACCEPTED, Json(job_json(&job, live, ""))).into_response();
    let h = res.headers_mut();
    h.insert(header::LOCATION, hv(&format!("/v1/jobs/{}", job.id)));
    h.insert(header::RETRY_AFTER, HeaderValue::from(1));
    if replayed {
        h.insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    Ok(res)
}

/// A job by id. Status polls are the hot path: when the store can answer at once (a free
/// SQLite reader: a primary-key read in WAL mode never waits for the writer) it is asked on
/// this thread, since the hand-off to a blocking thread costs more than the read (status poll
/// p99 with both workers busy 4.8 -> 3.3-4.1 ms in `benches/service_load.rs`).
async fn get_job_rec(st: &AppState, id: &str) -> Result<JobRecord, Problem> {
    let found = match st.store.try_get_job_now(id) {
        Some(r) => r?,
        None => {
            let store = st.store.clone();
            let id2 = id.to_string();
            blocking(move || Ok(store.get_job(&id2)?)).await?
        }
    };
    found.ok_or_else(|| Problem::not_found("job", id))
}

fn live_progress(st: &AppState, j: &JobRecord) -> Option<Value> {
    if j.status.is_terminal() {
        return None;
    }
    st.exec
        .live(&j.id)
        .and_then(|l| l.progress.lock().ok()?.clone())
}

/// `GET /v1/jobs/{id}`, with a strong ETag and `If-None-Match` → 304.
pub async fn get_job(
    State(st): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult {
    let j = get_job_rec(&st, &id).await?;
    let body = serde_json::to_vec(&job_json(&j, live_progress(&st, &j), "")).unwrap_or_default();
    let etag = format!("\"{}\"", &sha256_hex(&body)[..32]);
    let matches = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"));
    let mut res = if matches {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        ([(header::CONTENT_TYPE, "application/json")], body).into_response()
    };
    res.headers_mut().insert(header::ETAG, hv(&etag));
    if !j.status.is_terminal() {
        res.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(1));
    }
    Ok(res)
}

/// `GET /v1/jobs?status=&kind=&page_size=&page_token=`, newest first.
pub async fn list_jobs(
    State(st): State<AppState>,
    Query(q): Query<HashMap<String, String>>,
) -> ApiResult {
    let status = q
        .get("status")
        .map(|s| {
            Status::parse(s).ok_or_else(|| {
                Problem::invalid(
                    "status",
                    format!("unknown status `{s}` (queued, running, succeeded, failed, cancelled)"),
                )
            })
        })
        .transpose()?;
    let kind = q.get("kind").cloned();
    if let Some(k) = &kind {
        if Kind::from_name(k).is_none() {
            return Err(Problem::invalid("kind", format!("unknown job kind `{k}`")));
        }
    }
    let limit = match q.get("page_size") {
        None => 20,
        Some(s) => s
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=100).contains(n))
            .ok_or_else(|| Problem::invalid("page_size", "page_size must be in 1..=100"))?,
    };
    let before_seq = q
        .get("page_token")
        .map(|t| {
            t.parse::<i64>()
                .map_err(|_| Problem::invalid("page_token", "not a page token from this API"))
        })
        .transpose()?;
    let filter = JobFilter {
        status,
        kind,
        before_seq,
        limit: limit + 1,
    };
    let store = st.store.clone();
    let mut jobs = blocking(move || Ok(store.list_jobs(&filter)?)).await?;
    let next = if jobs.len() > limit {
        jobs.truncate(limit);
        jobs.last().map(|j| j.seq.to_string())
    } else {
        None
    };
    let items: Vec<Value> = jobs
        .iter()
        .map(|j| job_json(j, live_progress(&st, j), ""))
        .collect();
    Ok(Json(json!({"jobs": items, "next_page_token": next})).into_response())
}

/// `POST /v1/jobs/{id}/cancel`: 202 with the job (a running job stops at its next
/// iteration); 409 when it already ended.
pub async fn cancel_job(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    let exec = st.exec.clone();
    let id2 = id.clone();
    let r = blocking(move || Ok(exec.cancel(&id2)?)).await?;
    match r {
        None => Err(Problem::not_found("job", &id)),
        Some(Err(j)) => Err(Problem::conflict(format!(
            "job `{id}` already ended ({})",
            j.status.as_str()
        ))),
        Some(Ok(j)) => {
            let live = live_progress(&st, &j);
            Ok((StatusCode::ACCEPTED, Json(job_json(&j, live, ""))).into_response())
        }
    }
}

/// `DELETE /v1/jobs/{id}`: the job and its results (a running job is cancelled).
pub async fn delete_job(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    let exec = st.exec.clone();
    let id2 = id.clone();
    if blocking(move || Ok(exec.delete(&id2)?)).await? {
        Ok(StatusCode::NO_CONTENT.into_response())
    } else {
        Err(Problem::not_found("job", &id))
    }
}

async fn artifact(st: &AppState, id: &str, name: &str, media: &str) -> ApiResult {
    let j = get_job_rec(st, id).await?;
    if j.status != Status::Succeeded {
        return Err(Problem::conflict(format!(
            "job `{id}` has no results: it is {}",
            j.status.as_str()
        )));
    }
    if !j.artifacts.iter().any(|a| a == name) {
        return Err(Problem::new(
            StatusCode::NOT_FOUND,
            "not-found",
            format!("job `{id}` ({}) produced no {name}", j.kind),
        ));
    }
    let store = st.store.clone();
    let key = format!("jobs/{id}/{name}");
    let bytes = blocking(move || {
        store
            .get_blob(&key)?
            .ok_or_else(|| Problem::internal("result lost"))
    })
    .await?;
    let disposition = format!("attachment; filename=\"{id}-{name}\"");
    Ok((
        [
            (header::CONTENT_TYPE, media.to_string()),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        bytes,
    )
        .into_response())
}

/// `GET /v1/jobs/{id}/result`: the report JSON of the output mesh (per-vertex ϖ).
pub async fn job_result(State(st): State<AppState>, Path(id): Path<String>) -> ApiResult {
    artifact(&st, &id, "report.json", "application/json").await
}

fn format_param(
    q: &HashMap<String, String>,
    default: &str,
    allowed: &[&str],
) -> Result<String, Problem> {
    let f = q.get("format").map(String::as_str).unwrap_or(default);
    if allowed.contains(&f) {
        Ok(f.to_string())
    } else {
        Err(Problem::invalid(
            "format",
            format!("unknown format `{f}` (allowed: {})", allowed.join(", ")),
        ))
    }
}

/// `GET /v1/jobs/{id}/mesh?format=glb|gltf|obj`.
pub async fn job_mesh(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
) -> ApiResult {
    let f = format_param(&q, "glb", &["glb", "gltf", "obj"])?;
    let media = match f.as_str() {
        "glb" => "model/gltf-binary",
        "gltf" => "model/gltf+json",
        _ => "model/obj",
    };
    // `?level=k`: level k's mesh of a `subdivide` job (404 when the job has no such level).
    let name = match q.get("level") {
        None => format!("mesh.{f}"),
        Some(l) => match l.parse::<u32>() {
            Ok(k) if k >= 1 => format!("level_{k}.{f}"),
            _ => {
                return Err(Problem::invalid(
                    "level",
                    format!("`{l}` is not a level number (1, 2, …)"),
                ))
            }
        },
    };
    artifact(&st, &id, &name, media).await
}

/// `GET /v1/jobs/{id}/patterns?format=json|svg|dxf` (jobs that flatten).
pub async fn job_patterns(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
) -> ApiResult {
    let f = format_param(&q, "json", &["json", "svg", "dxf"])?;
    let media = match f.as_str() {
        "json" => "application/json",
        "svg" => "image/svg+xml",
        _ => "image/vnd.dxf",
    };
    let name = format!("patterns.{f}");
    artifact(&st, &id, &name, media).await
}

/// `GET /healthz`: the process answers.
pub async fn healthz() -> Response {
    Json(json!({"status": "ok"})).into_response()
}

/// `GET /readyz`: the store answers and the queue has room (503 otherwise).
pub async fn readyz(State(st): State<AppState>) -> ApiResult {
    let store = st.store.clone();
    blocking(move || {
        store.ping().map_err(|e| {
            Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "unavailable",
                format!("store: {e}"),
            )
        })
    })
    .await?;
    if !st.exec.has_room() {
        return Err(Problem::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "unavailable",
            "the job queue is full",
        )
        .retry_after(st.retry_after_secs()));
    }
    Ok(
        Json(json!({"status": "ready", "queued": st.exec.queued(), "running": st.exec.running()}))
            .into_response(),
    )
}

/// `GET /metrics`.
pub async fn metrics(State(st): State<AppState>) -> Response {
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
    ([(header::CONTENT_TYPE, "application/yaml")], super::OPENAPI).into_response()
}
