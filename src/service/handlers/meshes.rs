//! `/v1/meshes`: upload, read, report, delete.

use super::{
    blocking, format_of, get_mesh_rec, hv, json_with_etag, media_type, mesh_part, multipart_err,
    page_size, page_token, parse_slot, read_body, request_base, store_mesh,
};
use super::{ApiResult, MESH_TYPES};
use crate::io;
use crate::service::problem::Problem;
use crate::service::state::AppState;
use crate::service::tenants::Tenant;
use crate::service::views::mesh_json;
use axum::extract::{Extension, Multipart, Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::IntoResponse;
use std::collections::HashMap;

/// `POST /v1/meshes` (`?format=obj|glb|gltf|off` names the format of a raw body, for
/// clients that can only send `application/octet-stream`).
pub async fn upload_mesh(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Query(q): Query<HashMap<String, String>>,
    headers: HeaderMap,
    request: axum::extract::Request,
) -> ApiResult {
    let named = q
        .get("format")
        .map(|f| {
            io::Format::from_extension(f).ok_or_else(|| {
                Problem::invalid(
                    "format",
                    format!("unknown mesh format `{f}` (obj, glb, gltf, off)"),
                )
            })
        })
        .transpose()?;
    let media = media_type(&headers).unwrap_or_default();
    let rec = if media == "multipart/form-data" {
        let mut mp = <Multipart as axum::extract::FromRequest<()>>::from_request(request, &())
            .await
            .map_err(|e| Problem::bad_request(e.body_text()))?;
        let mut rec = None;
        while let Some(field) = mp.next_field().await.map_err(multipart_err)? {
            if field.name() == Some("mesh") && rec.is_none() {
                let (bytes, format) = mesh_part(field, "mesh").await?;
                rec = Some(store_mesh(&st, &tenant, bytes, format, "mesh").await?);
            }
        }
        rec.ok_or_else(|| Problem::invalid("mesh", "the multipart body has no `mesh` part"))?
    } else {
        let bytes = read_body(request.into_body(), st.max_upload).await?;
        let sniffed = matches!(
            media.as_str(),
            "" | "application/octet-stream" | "text/plain"
        );
        let format = named
            .or_else(|| format_of(&media, None, &bytes))
            .ok_or_else(|| {
                if sniffed {
                    // The media type is fine; the content is not a format we know.
                    Problem::invalid(
                        "body",
                        "the content is not a GLB, glTF, OBJ or OFF mesh (name the format \
                         with ?format= if it is one)",
                    )
                } else {
                    Problem::unsupported_media(format!(
                        "media type `{media}` is not a mesh format (expected {MESH_TYPES})"
                    ))
                }
            })?;
        store_mesh(&st, &tenant, bytes, format, "body").await?
    };
    let (rec, created) = rec;
    let base = request_base(&st, &headers);
    let mut res = json_with_etag(&HeaderMap::new(), &mesh_json(&rec, &base));
    // The same bytes again: the mesh already stored, 200 rather than 201.
    if created {
        *res.status_mut() = StatusCode::CREATED;
    }
    res.headers_mut().insert(
        header::LOCATION,
        hv(&format!("{base}/v1/meshes/{}", rec.id)),
    );
    Ok(res)
}

/// `GET /v1/meshes?page_size=&page_token=`, newest first.
pub async fn list_meshes(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Query(q): Query<HashMap<String, String>>,
    headers: HeaderMap,
) -> ApiResult {
    let limit = page_size(&q)?;
    let after = q
        .get("page_token")
        .map(|t| {
            page_token::decode_position(t, "meshes").map_err(|e| Problem::invalid("page_token", e))
        })
        .transpose()?;
    let store = st.store.clone();
    let mut meshes = blocking(move || {
        let after = after.as_ref().map(|(at, id)| (*at, id.as_str()));
        Ok(store.list_meshes(&tenant.0, after, limit + 1)?)
    })
    .await?;
    let next = if meshes.len() > limit {
        meshes.truncate(limit);
        meshes
            .last()
            .map(|m| page_token::encode_position(m.created_at, &m.id, "meshes"))
    } else {
        None
    };
    let base = request_base(&st, &headers);
    let items: Vec<serde_json::Value> = meshes.iter().map(|m| mesh_json(m, &base)).collect();
    Ok(axum::Json(serde_json::json!({"meshes": items, "next_page_token": next})).into_response())
}

/// `GET /v1/meshes/{id}`, with a strong ETag and `If-None-Match` → 304.
pub async fn get_mesh(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult {
    let rec = get_mesh_rec(&st, &tenant, &id).await?;
    let base = request_base(&st, &headers);
    Ok(json_with_etag(&headers, &mesh_json(&rec, &base)))
}

/// `GET /v1/meshes/{id}/report`: the flattenability report, computed now.
pub async fn mesh_report(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
) -> ApiResult {
    let rec = get_mesh_rec(&st, &tenant, &id).await?;
    let store = st.store.clone();
    // Parsed again, so under the same bound on parses at once as uploads.
    let slot = parse_slot(&st).await?;
    let body = blocking(move || {
        let _slot = slot;
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
pub async fn delete_mesh(
    State(st): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
) -> ApiResult {
    let store = st.store.clone();
    let id2 = id.clone();
    blocking(move || {
        if store.get_mesh(&id2)?.is_none_or(|m| m.tenant != tenant.0) {
            return Err(Problem::not_found("mesh", &id2));
        }
        if store.mesh_in_use(&id2)? {
            return Err(Problem::conflict(format!(
                "mesh `{id2}` is used by a queued or running job"
            )));
        }
        let s = store.as_ref();
        crate::service::store::delete_with_blobs(s, &format!("meshes/{id2}"), || {
            s.delete_mesh(&id2)
        })?;
        Ok(())
    })
    .await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}
