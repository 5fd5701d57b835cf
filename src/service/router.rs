//! The router: every route in one table (method, path, whether it needs an API key, handler),
//! from which both the axum router and [`routes`] (checked against openapi.yaml) are built;
//! and the middleware every response passes through.

use super::config::Config;
use super::handlers::{base_url, jobs, meshes, ops};
use super::problem::{self, Problem};
use super::state::AppState;
use super::telemetry;
use super::tenants::{self, Tenant};
use axum::extract::{DefaultBodyLimit, Request};
use axum::handler::Handler;
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{on, MethodFilter, MethodRouter};
use axum::Router;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::TimeoutLayer;
use tower_http::trace::TraceLayer;

/// The HTTP methods the API uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// GET
    Get,
    /// POST
    Post,
    /// DELETE
    Delete,
}

impl Method {
    /// Lower-case name, as openapi.yaml's path items spell it.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Get => "get",
            Method::Post => "post",
            Method::Delete => "delete",
        }
    }
    fn filter(self) -> MethodFilter {
        match self {
            Method::Get => MethodFilter::GET,
            Method::Post => MethodFilter::POST,
            Method::Delete => MethodFilter::DELETE,
        }
    }
}

/// One route of the table.
struct Route {
    method: Method,
    path: &'static str,
    /// Behind the API keys (every /v1 route).
    keyed: bool,
    handler: MethodRouter<AppState>,
}

fn route<H, T>(method: Method, path: &'static str, handler: H) -> Route
where
    H: Handler<T, AppState>,
    T: 'static,
{
    Route {
        method,
        path,
        keyed: path.starts_with("/v1/"),
        handler: on(method.filter(), handler),
    }
}

fn table() -> Vec<Route> {
    use Method::{Delete, Get, Post};
    vec![
        route(Get, "/healthz", ops::healthz),
        route(Get, "/readyz", ops::readyz),
        route(Get, "/metrics", ops::metrics),
        route(Get, "/version", ops::version),
        route(Get, "/openapi.yaml", ops::openapi),
        route(Get, "/problems", ops::problem_types),
        route(Get, "/problems/{slug}", ops::problem_type),
        route(Post, "/v1/meshes", meshes::upload_mesh),
        route(Get, "/v1/meshes", meshes::list_meshes),
        route(Get, "/v1/meshes/{id}", meshes::get_mesh),
        route(Delete, "/v1/meshes/{id}", meshes::delete_mesh),
        route(Get, "/v1/meshes/{id}/report", meshes::mesh_report),
        route(Post, "/v1/jobs", jobs::submit_job),
        route(Get, "/v1/jobs", jobs::list_jobs),
        route(Get, "/v1/jobs/{id}", jobs::get_job),
        route(Delete, "/v1/jobs/{id}", jobs::delete_job),
        route(Post, "/v1/jobs/{id}/cancel", jobs::cancel_job),
        route(Get, "/v1/jobs/{id}/result", jobs::job_result),
        route(Get, "/v1/jobs/{id}/mesh", jobs::job_mesh),
        route(Get, "/v1/jobs/{id}/patterns", jobs::job_patterns),
    ]
}

/// Every route served, `(method, path)`; openapi.yaml lists exactly these (a test checks
/// both directions, and requests each against the live server).
pub fn routes() -> Vec<(&'static str, &'static str)> {
    table()
        .into_iter()
        .map(|r| (r.method.as_str(), r.path))
        .collect()
}

/// Turn every error response that is not yet a problem (axum rejections, 404/405 of the
/// router, limits, timeouts, panics) into `application/problem+json`; count responses.
async fn problem_layer(st: axum::extract::State<AppState>, req: Request, next: Next) -> Response {
    let path = req.uri().path().to_string();
    let base = base_url(st.public_url.as_deref(), req.headers());
    let res = next.run(req).await;
    st.metrics.request(res.status().as_u16());
    let status = res.status();
    if status.as_u16() < 400 {
        return res;
    }
    let is_problem = res
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(problem::PROBLEM_JSON.as_bytes()));
    let (parts, body) = res.into_parts();
    if is_problem {
        // Its `type` absolute, resolving to the problem's documentation on this server.
        let text = axum::body::to_bytes(body, 1 << 16)
            .await
            .unwrap_or_default();
        let Ok(p) = serde_json::from_slice::<Problem>(&text) else {
            return Response::from_parts(parts, axum::body::Body::from(text));
        };
        let body = serde_json::to_vec(&p.under(&base)).unwrap_or_default();
        let mut out = Response::from_parts(parts, axum::body::Body::from(body));
        out.headers_mut().remove(header::CONTENT_LENGTH);
        return out;
    }
    let text = axum::body::to_bytes(body, 4096).await.unwrap_or_default();
    let mut detail = String::from_utf8_lossy(&text).trim().to_string();
    if detail.is_empty() {
        detail = match status {
            StatusCode::NOT_FOUND => format!("no route for {path}"),
            StatusCode::METHOD_NOT_ALLOWED => format!("method not allowed on {path}"),
            _ => status.canonical_reason().unwrap_or("error").to_string(),
        };
    }
    let mut p = Problem::new(status, problem::slug_for(status), detail).under(&base);
    p.instance = Some(path);
    let mut out = p.into_response();
    for (k, v) in parts.headers.iter() {
        if k != header::CONTENT_TYPE && k != header::CONTENT_LENGTH {
            out.headers_mut().insert(k.clone(), v.clone());
        }
    }
    out
}

/// Bearer API keys on /v1 (when configured).
/// Request bodies are read as sent: a compressed one (`Content-Encoding` other than
/// `identity`) would otherwise be parsed as if it were not, so it is refused with 415.
async fn refuse_encoded_bodies(req: Request, next: Next) -> Response {
    let encoding = req.headers().get(header::CONTENT_ENCODING).map(|v| {
        String::from_utf8_lossy(v.as_bytes())
            .trim()
            .to_ascii_lowercase()
    });
    match encoding {
        Some(e) if !e.is_empty() && e != "identity" => Problem::unsupported_media(format!(
            "Content-Encoding `{e}`: request bodies are not decompressed here; send them \
             uncompressed"
        ))
        .into_response(),
        _ => next.run(req).await,
    }
}

async fn auth_layer(st: axum::extract::State<AppState>, mut req: Request, next: Next) -> Response {
    if st.api_keys.is_empty() {
        req.extensions_mut().insert(Tenant::default());
        return next.run(req).await;
    }
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer_token);
    let key = given.and_then(|g| tenants::find_key(&st.api_keys, g));
    if let Some(k) = key {
        req.extensions_mut().insert(Tenant(k.tenant.clone()));
        next.run(req).await
    } else {
        Problem::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "a valid `Authorization: Bearer <api key>` header is required",
        )
        .into_response()
    }
}

/// The token of an `Authorization: Bearer <token>` value; the scheme is case-insensitive
/// (RFC 9110, 11.1).
fn bearer_token(value: &str) -> Option<&str> {
    let (scheme, token) = value.trim().split_once(char::is_whitespace)?;
    let token = token.trim();
    (scheme.eq_ignore_ascii_case("bearer") && !token.is_empty()).then_some(token)
}

fn panic_to_problem(err: Box<dyn std::any::Any + Send + 'static>) -> Response {
    let msg = err
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| err.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into());
    tracing::error!(panic = %msg, "handler panicked");
    Problem::internal("the server failed while handling the request").into_response()
}

/// The router with all middleware.
pub fn router(st: AppState, cfg: &Config) -> Router {
    let (mut keyed, mut open) = (Router::new(), Router::new());
    // Routes of one path with different methods merge into one method router.
    for r in table() {
        if r.keyed {
            keyed = keyed.route(r.path, r.handler);
        } else {
            open = open.route(r.path, r.handler);
        }
    }
    let keyed = keyed
        .route_layer(middleware::from_fn(refuse_encoded_bodies))
        .route_layer(middleware::from_fn_with_state(st.clone(), auth_layer));
    let mut app = open
        .merge(keyed)
        .layer(DefaultBodyLimit::max(cfg.max_upload))
        .layer(CatchPanicLayer::custom(panic_to_problem))
        .layer(TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            cfg.request_timeout,
        ))
        // Outside the timeout and the panic catcher, so that their answers are problems too.
        .layer(middleware::from_fn_with_state(st.clone(), problem_layer))
        .layer(CompressionLayer::new())
        .layer(TraceLayer::new_for_http().make_span_with(telemetry::http_span))
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid));
    if !cfg.cors_origins.is_empty() {
        let origin = if cfg.cors_origins.iter().any(|o| o == "*") {
            AllowOrigin::any()
        } else {
            AllowOrigin::list(
                cfg.cors_origins
                    .iter()
                    .filter_map(|o| HeaderValue::from_str(o).ok()),
            )
        };
        // Named, not `*`: the Fetch standard does not let a wildcard cover `Authorization`,
        // so with `*` every authenticated browser call fails its preflight.
        app = app.layer(
            CorsLayer::new()
                .allow_origin(origin)
                .allow_methods([
                    axum::http::Method::GET,
                    axum::http::Method::POST,
                    axum::http::Method::DELETE,
                ])
                .allow_headers([
                    header::AUTHORIZATION,
                    header::CONTENT_TYPE,
                    header::IF_NONE_MATCH,
                    header::HeaderName::from_static("idempotency-key"),
                    header::HeaderName::from_static("x-request-id"),
                ])
                .expose_headers([
                    header::LOCATION,
                    header::ETAG,
                    header::RETRY_AFTER,
                    header::HeaderName::from_static("x-request-id"),
                    header::HeaderName::from_static("idempotent-replayed"),
                ])
                .max_age(std::time::Duration::from_secs(600)),
        );
    }
    app.with_state(st)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bearer_scheme_is_case_insensitive() {
        for v in ["Bearer k1", "bearer k1", "BEARER   k1 ", " Bearer\tk1"] {
            assert_eq!(bearer_token(v), Some("k1"), "{v:?}");
        }
        for v in ["Basic k1", "Bearerk1", "Bearer ", "k1", ""] {
            assert_eq!(bearer_token(v), None, "{v:?}");
        }
    }
}
