//! `/v1/jobs`: submit, poll, list, cancel, delete, download results.

use super::{blocking, hex, hv, media_type, mesh_part, multipart_err, new_id, sha256_hex};
use super::{etag_matches, get_mesh_rec, json_with_etag, page_size, page_token, request_base};
use super::{read_body, store_mesh, ApiResult};
use crate::algorithms::AlgoError;
use crate::io;
use crate::jobs::{JobSpec, Kind, SpecError};
use crate::service::domain::{now_ms, JobRecord, Status};
use crate::service::problem::Problem;
use crate::service::state::AppState;
use crate::service::store::{Inserted, JobFilter};
use crate::service::tenants::{scoped_key, Tenant};
use crate::service::views::job_json;
use crate::service::webhook;
use axum::body::Bytes;
use axum::extract::{Extension, Multipart, Path, Query, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use serde_json::{json, Map, Value};
use sha2::{Digest, Sha256};
use std::collections::HashMap;

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
        webhook::check_url(u, st.webhooks.allow_private())
            .map_err(|e| Problem::invalid("callback_url", format!("callback_url: {e}")))?;
    }
    Ok(())
}

fn queue_full(st: &AppState) -> Problem {
    st.metrics.rejected_full();
    Problem::new(
        StatusCode::TOO_MANY_REQUESTS,
        "queue-full",
        format!(
            "the job queue is full ({} waiting); retry later",
            st.exec.limits.max_queued
        ),
    )
    .retry_after(st.exec.retry_after_full())
}

/// `POST /v1/jobs`: JSON `{kind, mesh_id, reference_mesh_id?, params?, callback_url?}` or
/// multipart with parts `job` (JSON without mesh ids), `mesh` and optionally `reference`.
/// The request is parsed and checked whole, then a replay (same Idempotency-Key) is answered
/// with its job, and only then are uploads stored and the job inserted.
pub async fn submit_job(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    headers: HeaderMap,
    request: axum::extract::Request,
) -> ApiResult {
    let key = idempotency_key(&headers)?.map(|k| scoped_key(&tenant, &k));
    let base = request_base(&st, &headers);
    let media = media_type(&headers).unwrap_or_default();
    let mut req = match media.as_str() {
        "application/json" => read_json_submit(&st, &tenant, request).await?,
        "multipart/form-data" => read_multipart_submit(&st, request).await?,
        _ => {
            return Err(Problem::unsupported_media(format!(
                "media type `{media}`: expected application/json or multipart/form-data"
            )))
        }
    };
    if let (Some(k), false) = (&key, req.uploads.is_empty()) {
        let (store, k) = (st.store.clone(), k.clone());
        if let Some(j) = blocking(move || Ok(store.find_idempotent(&k)?)).await? {
            let after = st.exec.eta.after_poll(&j.kind, None);
            return submitted(&st, &base, j, &req.hash, true, after);
        }
    }
    // The uploads are validated like POST /v1/meshes and then referenced by id.
    let mut stored_here = Vec::new();
    for (field, bytes, format) in std::mem::take(&mut req.uploads) {
        let (rec, created) = store_mesh(&st, &tenant, bytes, format, field).await?;
        if field == "mesh" {
            req.faces = mesh_faces(&rec);
        }
        let id = rec.id;
        match field {
            "mesh" => req.submit.mesh_id = Some(id.clone()),
            _ => req.submit.reference_mesh_id = Some(id.clone()),
        }
        if created {
            stored_here.push(id);
        }
    }
    insert_job(&st, &tenant, &base, key, req, stored_here).await
}

/// Faces of a stored mesh, from its summary.
fn mesh_faces(rec: &crate::service::domain::MeshRecord) -> usize {
    rec.summary["faces"].as_u64().unwrap_or(0) as usize
}

/// The `Idempotency-Key` header, when given.
fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>, Problem> {
    let Some(v) = headers.get("idempotency-key") else {
        return Ok(None);
    };
    let s = v
        .to_str()
        .ok()
        .filter(|s| !s.is_empty() && s.len() <= 255)
        .ok_or_else(|| {
            Problem::bad_request("Idempotency-Key must be 1 to 255 visible ASCII characters")
        })?;
    Ok(Some(s.to_string()))
}

/// A checked job request: what to insert, the mesh uploads still to store (multipart), and
/// the hash that tells a replay of it from a different request under the same key.
struct Request {
    submit: Submit,
    uploads: Vec<(&'static str, Bytes, io::Format)>,
    hash: String,
    /// Faces of the input mesh (for the `Retry-After` estimate).
    faces: usize,
}

fn request_hash(mut hasher: Sha256, s: &Submit) -> String {
    hasher.update(format!(
        "kind={};params={};callback={:?}",
        s.kind,
        Value::Object(s.params.clone()),
        s.callback_url
    ));
    hex(&hasher.finalize())
}

/// A JSON submit: the meshes it names must exist.
async fn read_json_submit(
    st: &AppState,
    tenant: &Tenant,
    request: axum::extract::Request,
) -> Result<Request, Problem> {
    let body = read_body(request.into_body(), st.max_upload).await?;
    let submit = parse_submit(&body, false)?;
    validate_submit(st, &submit, Some(submit.reference_mesh_id.is_some()))?;
    let mut hasher = Sha256::new();
    let mut faces = 0;
    for (field, id) in [
        ("mesh_id", &submit.mesh_id),
        ("reference_mesh_id", &submit.reference_mesh_id),
    ] {
        if let Some(id) = id {
            let Ok(rec) = get_mesh_rec(st, tenant, id).await else {
                return Err(Problem::invalid(field, format!("no mesh `{id}`")));
            };
            if field == "mesh_id" {
                faces = mesh_faces(&rec);
            }
            hasher.update(format!("{field}={id};"));
        }
    }
    let hash = request_hash(hasher, &submit);
    Ok(Request {
        submit,
        uploads: vec![],
        hash,
        faces,
    })
}

/// A multipart submit: the `job` part and the mesh parts, parsed but not yet stored.
async fn read_multipart_submit(
    st: &AppState,
    request: axum::extract::Request,
) -> Result<Request, Problem> {
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
                validate_submit(st, &s, None)?;
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
    let submit =
        job.ok_or_else(|| Problem::invalid("job", "the multipart body has no `job` part"))?;
    JobSpec::parse(&submit.kind, &submit.params)
        .and_then(|spec| spec.check_reference(reference.is_some()))
        .map_err(|e| match e {
            SpecError::Reference(m) => Problem::invalid("reference", m),
            e => spec_problem(e),
        })?;
    let (mb, mf) =
        mesh.ok_or_else(|| Problem::invalid("mesh", "the multipart body has no `mesh` part"))?;
    let mut hasher = Sha256::new();
    hasher.update(format!("mesh={};", sha256_hex(&mb)));
    let mut uploads = vec![("mesh", mb, mf)];
    if let Some((rb, rf)) = reference {
        hasher.update(format!("reference={};", sha256_hex(&rb)));
        uploads.push(("reference", rb, rf));
    }
    let hash = request_hash(hasher, &submit);
    Ok(Request {
        submit,
        uploads,
        hash,
        faces: 0,
    })
}

/// Insert the job when the queue has room (a replay is answered even when it has none);
/// meshes stored for a request that lost an idempotency race are deleted again.
async fn insert_job(
    st: &AppState,
    tenant: &Tenant,
    base: &str,
    key: Option<String>,
    req: Request,
    stored_here: Vec<String>,
) -> ApiResult {
    // What the job would make, against the same budget as an upload.
    let spec = JobSpec::parse(&req.submit.kind, &req.submit.params).map_err(spec_problem)?;
    let out = spec.output_faces(req.faces);
    if out > st.mesh_limits.max_triangles {
        forget_uploads(st, stored_here).await?;
        return Err(Problem::invalid(
            "params.levels",
            format!(
                "this job would make a mesh of {out} faces from {}; this server allows {} \
                 (--max-triangles): fewer levels, or a coarser mesh",
                req.faces, st.mesh_limits.max_triangles
            ),
        ));
    }
    let mut record = JobRecord::queued(
        &new_id("j"),
        &req.submit.kind,
        &req.submit.mesh_id.unwrap_or_default(),
        now_ms(),
    );
    record.reference_mesh_id = req.submit.reference_mesh_id;
    record.params = req.submit.params;
    record.callback_url = req.submit.callback_url;
    record.idempotency_key = key;
    record.tenant = tenant.0.clone();
    record.request_hash = Some(req.hash.clone());
    record.base_url = Some(base.to_string()).filter(|b| !b.is_empty());
    let (store, exec) = (st.store.clone(), st.exec.clone());
    let inserted = blocking(move || {
        // The queue is counted in the store (shared by every process): a bound, not a lock.
        let queued = exec.queued();
        if queued >= exec.limits.max_queued {
            // A full queue still answers a replayed request with its job.
            if let Some(k) = &record.idempotency_key {
                if let Some(j) = store.find_idempotent(k)? {
                    return Ok((Some(Inserted::Existing(j)), queued));
                }
            }
            return Ok((None, queued));
        }
        Ok((Some(store.insert_job(&record)?), queued))
    })
    .await;
    let (inserted, queued) = match inserted {
        Ok(v) => v,
        Err(p) => {
            // The job could not be stored (a full store, say): nor are its uploads kept.
            let _ = forget_uploads(st, stored_here).await;
            return Err(p);
        }
    };
    let retry =
        st.exec
            .eta
            .after_submit(&req.submit.kind, req.faces, queued, st.exec.limits.workers);
    match inserted {
        None => {
            // Nothing is kept for a refused request.
            forget_uploads(st, stored_here).await?;
            Err(queue_full(st))
        }
        Some(Inserted::New(j)) => {
            let exec = st.exec.clone();
            // Counting the queue for the metrics reads the store: off the async threads.
            let _ = tokio::task::spawn_blocking(move || exec.enqueued()).await;
            st.metrics.submitted();
            submitted(st, base, j, &req.hash, false, retry)
        }
        Some(Inserted::Existing(j)) => {
            // A concurrent retry with the same key won the race: the meshes stored for this
            // request are not referenced by any job.
            let _ = forget_uploads(st, stored_here).await;
            submitted(st, base, j, &req.hash, true, retry)
        }
    }
}

/// Delete the meshes a multipart submit stored when no job will use them (the submit was
/// refused, or lost an idempotency race).
async fn forget_uploads(st: &AppState, stored_here: Vec<String>) -> Result<(), Problem> {
    if stored_here.is_empty() {
        return Ok(());
    }
    let store = st.store.clone();
    blocking(move || {
        for id in stored_here {
            // Kept when another request was given it by its hash meanwhile, or a job uses it.
            if store.forget_mesh(&id)? {
                store.delete_blobs(&format!("meshes/{id}"))?;
            }
        }
        Ok(())
    })
    .await
}

/// The 202 for a new or replayed job; a replay whose request differs is refused.
fn submitted(
    st: &AppState,
    base: &str,
    job: JobRecord,
    request_hash: &str,
    replayed: bool,
    retry_after: u64,
) -> ApiResult {
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
    let mut res = (StatusCode::ACCEPTED, Json(job_json(&job, live, base))).into_response();
    let h = res.headers_mut();
    h.insert(header::LOCATION, hv(&format!("{base}/v1/jobs/{}", job.id)));
    h.insert(header::RETRY_AFTER, HeaderValue::from(retry_after));
    if replayed {
        h.insert("idempotent-replayed", HeaderValue::from_static("true"));
    }
    Ok(res)
}

/// A job by id. Status polls are the hot path: when the store can answer at once (a free
/// SQLite reader: a primary-key read in WAL mode never waits for the writer) it is asked on
/// this thread, since the hand-off to a blocking thread costs more than the read (status poll
/// p99 with both workers busy 4.8 -> 3.3-4.1 ms in `benches/service_load.rs`).
async fn get_job_rec(st: &AppState, tenant: &Tenant, id: &str) -> Result<JobRecord, Problem> {
    let found = if let Some(fut) = st.store.get_job_async(id) {
        fut.await?
    } else {
        match st.store.try_get_job_now(id) {
            Some(r) => r?,
            None => {
                let store = st.store.clone();
                let id2 = id.to_string();
                blocking(move || Ok(store.get_job(&id2)?)).await?
            }
        }
    };
    found
        .filter(|j| j.tenant == tenant.0)
        .ok_or_else(|| Problem::not_found("job", id))
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
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult {
    let j = get_job_rec(&st, &tenant, &id).await?;
    let base = request_base(&st, &headers);
    let mut res = json_with_etag(&headers, &job_json(&j, live_progress(&st, &j), &base));
    if !j.status.is_terminal() {
        let running_for = (j.status == Status::Running)
            .then(|| j.started_at.map(|t| (now_ms() - t) as f64 / 1e3))
            .flatten();
        let after = st.exec.eta.after_poll(&j.kind, running_for);
        res.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(after));
    }
    Ok(res)
}

/// `GET /v1/jobs?status=&kind=&page_size=&page_token=`, newest first.
pub async fn list_jobs(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Query(q): Query<HashMap<String, String>>,
    headers: HeaderMap,
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
    let limit = page_size(&q)?;
    let listing = format!(
        "status={}&kind={}",
        status.map_or("", |s| s.as_str()),
        kind.as_deref().unwrap_or("")
    );
    let before_seq = q
        .get("page_token")
        .map(|t| page_token::decode(t, &listing).map_err(|e| Problem::invalid("page_token", e)))
        .transpose()?;
    let filter = JobFilter {
        tenant: tenant.0,
        status,
        kind,
        before_seq,
        limit: limit + 1,
    };
    let store = st.store.clone();
    let mut jobs = blocking(move || Ok(store.list_jobs(&filter)?)).await?;
    let base = request_base(&st, &headers);
    let next = if jobs.len() > limit {
        jobs.truncate(limit);
        jobs.last().map(|j| page_token::encode(j.seq, &listing))
    } else {
        None
    };
    let items: Vec<Value> = jobs
        .iter()
        .map(|j| job_json(j, live_progress(&st, j), &base))
        .collect();
    Ok(Json(json!({"jobs": items, "next_page_token": next})).into_response())
}

/// `POST /v1/jobs/{id}/cancel`: 202 with the job (a running job stops at its next
/// iteration); 200 with the job when it is already cancelled (a retried cancel); 409 when it
/// ended otherwise.
pub async fn cancel_job(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult {
    get_job_rec(&st, &tenant, &id).await?;
    let base = request_base(&st, &headers);
    let exec = st.exec.clone();
    let id2 = id.clone();
    let r = blocking(move || Ok(exec.cancel(&id2)?)).await?;
    match r {
        None => Err(Problem::not_found("job", &id)),
        Some(Err(j)) if j.status == Status::Cancelled => {
            Ok((StatusCode::OK, Json(job_json(&j, None, &base))).into_response())
        }
        Some(Err(j)) => Err(Problem::conflict(format!(
            "job `{id}` already ended ({})",
            j.status.as_str()
        ))),
        Some(Ok(j)) => {
            let live = live_progress(&st, &j);
            Ok((StatusCode::ACCEPTED, Json(job_json(&j, live, &base))).into_response())
        }
    }
}

/// `DELETE /v1/jobs/{id}`: the job and its results (a running job is cancelled).
pub async fn delete_job(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
) -> ApiResult {
    get_job_rec(&st, &tenant, &id).await?;
    let exec = st.exec.clone();
    let id2 = id.clone();
    if blocking(move || Ok(exec.delete(&id2)?)).await? {
        Ok(StatusCode::NO_CONTENT.into_response())
    } else {
        Err(Problem::not_found("job", &id))
    }
}

/// Whether `Accept` asks for `application/octet-stream` and not for `media` itself.
fn accepts_only_octets(headers: &HeaderMap, media: &str) -> bool {
    let Some(accept) = headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let types: Vec<&str> = accept
        .split(',')
        .map(|t| t.split(';').next().unwrap_or("").trim())
        .collect();
    types.contains(&"application/octet-stream") && !types.contains(&media)
}

/// A succeeded job's file, with a strong ETag (`If-None-Match` → 304 without reading it).
async fn artifact(
    st: &AppState,
    tenant: &Tenant,
    headers: &HeaderMap,
    id: &str,
    name: &str,
    media: &str,
) -> ApiResult {
    let j = get_job_rec(st, tenant, id).await?;
    if j.status != Status::Succeeded {
        return Err(Problem::conflict(format!(
            "job `{id}` has no results: it is {}",
            j.status.as_str()
        )));
    }
    if !j.artifacts.iter().any(|a| a == name) {
        // Patterns a mesh-changing job could not derive: say why (the job's warning).
        let why = j
            .outcome
            .as_ref()
            .and_then(|o| o["warnings"].as_array())
            .into_iter()
            .flatten()
            .find(|w| name.starts_with("patterns.") && w["code"] == "patterns_unavailable")
            .and_then(|w| w["message"].as_str())
            .map(|m| format!(": {m}"))
            .unwrap_or_default();
        return Err(Problem::new(
            StatusCode::NOT_FOUND,
            "not-found",
            format!("job `{id}` ({}) produced no {name}{why}", j.kind),
        ));
    }
    // A succeeded job's files never change: its id and the file name identify the bytes.
    let etag = format!(
        "\"{}\"",
        &sha256_hex(format!("{id}/{name}").as_bytes())[..32]
    );
    if etag_matches(headers, &etag) {
        let mut res = StatusCode::NOT_MODIFIED.into_response();
        res.headers_mut().insert(header::ETAG, hv(&etag));
        return Ok(res);
    }
    let store = st.store.clone();
    let key = format!("jobs/{id}/{name}");
    let id2 = id.to_string();
    let bytes = blocking(move || match store.get_blob(&key)? {
        Some(b) => Ok(b),
        // Deleted (expired, or through another replica) since the job was read: gone, not
        // lost; the job read above may have come from a status-poll cache.
        None if store.get_job(&id2)?.is_none() => Err(Problem::not_found("job", &id2)),
        None => Err(Problem::internal("result lost")),
    })
    .await?;
    let disposition = format!("attachment; filename=\"{id}-{name}\"");
    // A client that asks for bytes as such gets them typed so (generated clients parse by
    // the first media type they know, and none knows model/gltf-binary or image/vnd.dxf).
    let media = if accepts_only_octets(headers, media) {
        "application/octet-stream"
    } else {
        media
    };
    Ok((
        [
            (header::CONTENT_TYPE, media.to_string()),
            (header::CONTENT_DISPOSITION, disposition),
            (header::ETAG, etag),
        ],
        bytes,
    )
        .into_response())
}

/// `GET /v1/jobs/{id}/result`: the report JSON of the output mesh (per-vertex ϖ).
pub async fn job_result(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult {
    artifact(
        &st,
        &tenant,
        &headers,
        &id,
        "report.json",
        "application/json",
    )
    .await
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
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
    headers: HeaderMap,
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
        // Any level number is a valid request; one the job does not have is a 404.
        Some(l) => match l.parse::<u64>() {
            Ok(k) if k >= 1 => format!("level_{k}.{f}"),
            _ => {
                return Err(Problem::invalid(
                    "level",
                    format!("`{l}` is not a level number (1, 2, …)"),
                ))
            }
        },
    };
    artifact(&st, &tenant, &headers, &id, &name, media).await
}

/// `GET /v1/jobs/{id}/patterns?format=json|svg|dxf|dxf-plain` (jobs that flatten).
pub async fn job_patterns(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
    headers: HeaderMap,
) -> ApiResult {
    let f = format_param(&q, "json", &["json", "svg", "dxf", "dxf-plain"])?;
    let media = match f.as_str() {
        "json" => "application/json",
        "svg" => "image/svg+xml",
        _ => "image/vnd.dxf",
    };
    let name = match f.as_str() {
        "dxf-plain" => "patterns-plain.dxf".to_string(),
        _ => format!("patterns.{f}"),
    };
    artifact(&st, &tenant, &headers, &id, &name, media).await
}
