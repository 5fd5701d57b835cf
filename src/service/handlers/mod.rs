//! HTTP handlers, one module per resource. Every error is a [`Problem`]; CPU work (parsing
//! meshes, reports) runs on blocking threads, jobs on the executor's pool.

pub mod jobs;
pub mod meshes;
pub mod ops;
mod page_token;

use super::domain::{now_ms, MeshRecord};
use super::problem::{self, Problem};
use super::state::AppState;
use super::tenants::Tenant;
use crate::io;
use axum::body::Bytes;
use axum::http::{header, HeaderMap, HeaderValue};
use axum::response::Response;
use serde_json::json;
use sha2::{Digest, Sha256};

type ApiResult = Result<Response, Problem>;

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn new_id(prefix: &str) -> String {
    format!("{prefix}_{}", uuid::Uuid::new_v4().simple())
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

/// Parse, validate and store a mesh; `field` names it in errors. Bytes already stored (the
/// same SHA-256) are not parsed or stored again: the earlier upload is returned, with
/// `false` for "not created here".
async fn store_mesh(
    st: &AppState,
    tenant: &Tenant,
    bytes: Bytes,
    format: io::Format,
    field: &str,
) -> Result<(MeshRecord, bool), Problem> {
    let field_owned = field.to_string();
    let sha256 = sha256_hex(&bytes);
    let (store, sha, who) = (st.store.clone(), sha256.clone(), tenant.0.clone());
    if let Some(existing) = blocking(move || {
        Ok(store.find_mesh_by_sha256(&who, &sha, crate::service::domain::now_ms())?)
    })
    .await?
    {
        return Ok((existing, false));
    }
    let slot = parse_slot(st).await?;
    let limits = st.mesh_limits;
    let parsed = tokio::task::spawn_blocking(move || {
        // Held by the parse itself: a client that goes away does not free it early.
        let _slot = slot;
        let r = io::load_limited(&bytes, format, &limits).map(|(mesh, warnings)| {
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
        if let io::ReadError::TooLarge { .. } = e {
            return Problem::new(
                axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                "payload-too-large",
                format!(
                    "{field_owned}: {e} by this server (--max-triangles); send a smaller \
                     mesh or split it"
                ),
            );
        }
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
        sha256,
        summary,
        tenant: tenant.0.clone(),
    };
    let store = st.store.clone();
    let r2 = rec.clone();
    tokio::task::spawn_blocking(move || {
        let key = format!("meshes/{}", r2.id);
        store.put_blob(&key, &bytes)?;
        // Nothing of a refused upload is kept (a full index, say).
        store.insert_mesh(&r2).inspect_err(|_| {
            let _ = store.delete_blobs(&key);
        })
    })
    .await
    .map_err(|e| Problem::internal(e.to_string()))??;
    st.metrics.uploaded();
    Ok((rec, true))
}

/// One of the few slots for parsing a mesh: parsing is where an upload's memory goes, so a
/// bounded number run at once, each bounded by the triangle limit (counted before the mesh
/// is read).
async fn parse_slot(st: &AppState) -> Result<tokio::sync::OwnedSemaphorePermit, Problem> {
    st.parse_slots
        .clone()
        .acquire_owned()
        .await
        .map_err(|_| Problem::internal("parser slots closed"))
}

/// A whole request body of at most `limit` bytes: 413 past the limit, 400 when it could not
/// be read (the client stopped sending, a malformed chunked encoding).
async fn read_body(body: axum::body::Body, limit: usize) -> Result<Bytes, Problem> {
    axum::body::to_bytes(body, limit).await.map_err(|e| {
        let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(&e);
        while let Some(c) = cause {
            if c.is::<http_body_util::LengthLimitError>() {
                return Problem::new(
                    axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                    "payload-too-large",
                    format!("the body exceeds {limit} bytes (the server's --max-upload)"),
                );
            }
            cause = c.source();
        }
        Problem::bad_request(format!("the body could not be read: {e}"))
    })
}

fn multipart_err(e: axum::extract::multipart::MultipartError) -> Problem {
    let status = e.status();
    Problem::new(status, problem::slug_for(status), e.body_text())
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
    // The request's own media type was fine: a part that is no mesh is a bad member (422),
    // not an unsupported request (415).
    let format = format_of(&media, filename.as_deref(), &bytes).ok_or_else(|| {
        Problem::invalid(
            name,
            format!(
                "part `{name}`: neither its media type (`{media}`), its file name nor its \
                 content says which mesh format it is (GLB, glTF, OBJ, OFF)"
            ),
        )
    })?;
    Ok((bytes, format))
}

fn hv(s: &str) -> HeaderValue {
    HeaderValue::from_str(s).unwrap_or(HeaderValue::from_static(""))
}

/// The API's base URL for absolute links: `--public-url` when configured, else what the
/// request says of how the client reached us (RFC 7239 `Forwarded`, then `X-Forwarded-Proto`
/// / `X-Forwarded-Host`, then `Host`); "" (relative links) when nothing usable is said.
pub fn base_url(public: Option<&str>, headers: &HeaderMap) -> String {
    if let Some(p) = public {
        return p.to_string();
    }
    let header = |name: &str| {
        headers
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(|v| v.split(',').next().unwrap_or("").trim().to_string())
            .filter(|v| !v.is_empty())
    };
    let (mut proto, mut host) = (None, None);
    if let Some(fwd) = header("forwarded") {
        for pair in fwd.split(';') {
            if let Some((k, v)) = pair.split_once('=') {
                let v = v.trim().trim_matches('"').to_string();
                match k.trim().to_ascii_lowercase().as_str() {
                    "proto" => proto = Some(v),
                    "host" => host = Some(v),
                    _ => {}
                }
            }
        }
    }
    let proto = proto
        .or_else(|| header("x-forwarded-proto"))
        .unwrap_or_else(|| "http".into())
        .to_ascii_lowercase();
    let Some(host) = host
        .or_else(|| header("x-forwarded-host"))
        .or_else(|| header("host"))
    else {
        return String::new();
    };
    // A host (and port) only: anything else would make links point elsewhere or break them.
    let host_ok = !host.is_empty()
        && host
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || ".-:[]_".contains(c));
    if !matches!(proto.as_str(), "http" | "https") || !host_ok {
        return String::new();
    }
    format!("{proto}://{host}")
}

/// The `page_size` query parameter of a listing: 1–100, default 20.
fn page_size(q: &std::collections::HashMap<String, String>) -> Result<usize, Problem> {
    match q.get("page_size") {
        None => Ok(20),
        Some(s) => s
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=100).contains(n))
            .ok_or_else(|| Problem::invalid("page_size", "page_size must be in 1..=100")),
    }
}

/// The base URL of a request to this service (see [`base_url`]).
fn request_base(st: &AppState, headers: &HeaderMap) -> String {
    base_url(st.public_url.as_deref(), headers)
}

/// Whether an `If-None-Match` header matches `etag` (a quoted strong tag; `W/` prefixes are
/// compared weakly, as RFC 9110 13.1.2 asks of GET).
fn etag_matches(headers: &HeaderMap, etag: &str) -> bool {
    headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.split(',').any(|t| {
                let t = t.trim();
                t == "*" || t.strip_prefix("W/").unwrap_or(t) == etag
            })
        })
}

/// A JSON representation with a strong ETag of its bytes, or 304 when the client has it.
fn json_with_etag(headers: &HeaderMap, value: &serde_json::Value) -> Response {
    use axum::response::IntoResponse;
    let body = serde_json::to_vec(value).unwrap_or_default();
    let etag = format!("\"{}\"", &sha256_hex(&body)[..32]);
    let mut res = if etag_matches(headers, &etag) {
        axum::http::StatusCode::NOT_MODIFIED.into_response()
    } else {
        ([(header::CONTENT_TYPE, "application/json")], body).into_response()
    };
    res.headers_mut().insert(header::ETAG, hv(&etag));
    res
}

async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, Problem> + Send + 'static,
) -> Result<T, Problem> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Problem::internal(format!("worker crashed: {e}")))?
}

/// A mesh record by id (404 when absent or another tenant's).
async fn get_mesh_rec(st: &AppState, tenant: &Tenant, id: &str) -> Result<MeshRecord, Problem> {
    let store = st.store.clone();
    let id2 = id.to_string();
    blocking(move || Ok(store.get_mesh(&id2)?))
        .await?
        .filter(|m| m.tenant == tenant.0)
        .ok_or_else(|| Problem::not_found("mesh", id))
}

#[cfg(test)]
mod tests {
    use super::base_url;
    use axum::http::HeaderMap;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(*k, v.parse().unwrap());
        }
        h
    }

    #[test]
    fn base_url_prefers_configuration_then_forwarded_then_host() {
        let h = headers(&[("host", "10.0.0.5:8080")]);
        assert_eq!(
            base_url(Some("https://api.example.com/fm"), &h),
            "https://api.example.com/fm"
        );
        assert_eq!(base_url(None, &h), "http://10.0.0.5:8080");
        let h = headers(&[
            ("host", "10.0.0.5:8080"),
            (
                "forwarded",
                "for=1.2.3.4;proto=https;host=\"api.example.com\", for=5.6.7.8",
            ),
        ]);
        assert_eq!(base_url(None, &h), "https://api.example.com");
        let h = headers(&[
            ("host", "10.0.0.5:8080"),
            ("x-forwarded-proto", "https"),
            ("x-forwarded-host", "gw.example.com, inner"),
        ]);
        assert_eq!(base_url(None, &h), "https://gw.example.com");
        // Nothing usable: relative links rather than wrong ones.
        assert_eq!(base_url(None, &HeaderMap::new()), "");
        assert_eq!(base_url(None, &headers(&[("host", "evil.com/path")])), "");
        assert_eq!(
            base_url(
                None,
                &headers(&[("host", "a.com"), ("x-forwarded-proto", "ftp")])
            ),
            ""
        );
    }
}
