//! The REST job service (`flatmesh serve`): axum on tokio for HTTP, jobs on a dedicated rayon
//! pool ([`jobs::Executor`]), durable state behind [`store::Store`] (SQLite + blob files by
//! default), RFC 9457 problems for every error, Standard Webhooks callbacks.

// `Problem` (~144 bytes) is the error of every handler; errors are the cold path of a
// network service, so boxing it would only add noise.
#![allow(clippy::result_large_err)]

pub mod api;
pub mod client;
pub mod jobs;
pub mod metrics;
pub mod problem;
pub mod store;
pub mod store_contract;
pub mod webhook;

use axum::extract::{DefaultBodyLimit, Request};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use problem::Problem;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::TimeoutLayer;
use tower_http::trace::TraceLayer;

/// The OpenAPI 3.1 description, as written.
pub const OPENAPI: &str = include_str!("openapi.yaml");

/// Every route of the router, `(method, path)`; `openapi.yaml` lists exactly these (a test
/// checks both directions, and each is requested against the live server).
pub const ROUTES: &[(&str, &str)] = &[
    ("get", "/healthz"),
    ("get", "/readyz"),
    ("get", "/metrics"),
    ("get", "/version"),
    ("get", "/openapi.yaml"),
    ("post", "/v1/meshes"),
    ("get", "/v1/meshes/{id}"),
    ("delete", "/v1/meshes/{id}"),
    ("get", "/v1/meshes/{id}/report"),
    ("post", "/v1/jobs"),
    ("get", "/v1/jobs"),
    ("get", "/v1/jobs/{id}"),
    ("delete", "/v1/jobs/{id}"),
    ("post", "/v1/jobs/{id}/cancel"),
    ("get", "/v1/jobs/{id}/result"),
    ("get", "/v1/jobs/{id}/mesh"),
    ("get", "/v1/jobs/{id}/patterns"),
];

fn parse_duration(s: &str) -> Result<Duration, String> {
    if let Ok(secs) = s.parse::<u64>() {
        return Ok(Duration::from_secs(secs));
    }
    humantime::parse_duration(s).map_err(|e| e.to_string())
}

fn parse_size(s: &str) -> Result<usize, String> {
    let s = s.trim();
    let (num, mult) = match s.find(|c: char| !c.is_ascii_digit()) {
        None => (s, 1usize),
        Some(i) => {
            let m = match s[i..].trim().to_ascii_lowercase().as_str() {
                "b" => 1,
                "k" | "kb" | "kib" => 1 << 10,
                "m" | "mb" | "mib" => 1 << 20,
                "g" | "gb" | "gib" => 1 << 30,
                other => return Err(format!("unknown size unit `{other}`")),
            };
            (&s[..i], m)
        }
    };
    num.parse::<usize>()
        .map_err(|e| e.to_string())?
        .checked_mul(mult)
        .ok_or_else(|| "size too large".to_string())
}

/// Configuration of `flatmesh serve`; every flag has an environment variable.
#[derive(Debug, Clone, clap::Args)]
pub struct Config {
    /// Address to listen on (port 0 picks a free port; the address is printed on stdout).
    #[arg(long, env = "FLATMESH_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Directory of the embedded store (SQLite index, uploads, results).
    #[arg(long, env = "FLATMESH_DATA_DIR", default_value = "flatmesh-data")]
    pub data_dir: PathBuf,
    /// Worker threads running jobs (0: one per core).
    #[arg(long, env = "FLATMESH_WORKERS", default_value_t = 0)]
    pub workers: usize,
    /// Largest request body (uploads), e.g. `256MiB`.
    #[arg(long, env = "FLATMESH_MAX_UPLOAD", default_value = "256MiB", value_parser = parse_size)]
    pub max_upload: usize,
    /// Most jobs waiting for a worker; beyond it submits get 429.
    #[arg(long, env = "FLATMESH_MAX_QUEUED", default_value_t = 64)]
    pub max_queued: usize,
    /// Wall-clock limit of one job run, e.g. `30m`.
    #[arg(long, env = "FLATMESH_JOB_TIME_LIMIT", default_value = "1h", value_parser = parse_duration)]
    pub job_time_limit: Duration,
    /// How long results of ended jobs are kept, e.g. `7d`.
    #[arg(long, env = "FLATMESH_RETENTION", default_value = "7d", value_parser = parse_duration)]
    pub retention: Duration,
    /// Runs of a job interrupted by a restart before it fails.
    #[arg(long, env = "FLATMESH_MAX_ATTEMPTS", default_value_t = 3)]
    pub max_attempts: u32,
    /// How long a worker's claim on a running job lasts without a heartbeat (it renews it
    /// every quarter of that): a job whose process died runs again after this, e.g. `30s`.
    #[arg(long, env = "FLATMESH_LEASE", default_value = "30s", value_parser = parse_duration)]
    pub lease: Duration,
    /// Nice value of the job threads (Linux; 0-19): higher keeps HTTP answers fast while
    /// every worker is busy.
    #[arg(long, env = "FLATMESH_WORKER_NICE", default_value_t = 10, value_parser = clap::value_parser!(i32).range(0..=19))]
    pub worker_nice: i32,
    /// Bearer API keys (comma-separated); when set, every /v1 route requires one.
    #[arg(long = "api-key", env = "FLATMESH_API_KEYS", value_delimiter = ',')]
    pub api_keys: Vec<String>,
    /// Origins allowed by CORS (comma-separated, `*` for any); none: no CORS headers.
    #[arg(
        long = "cors-origin",
        env = "FLATMESH_CORS_ORIGINS",
        value_delimiter = ','
    )]
    pub cors_origins: Vec<String>,
    /// Webhook signing secret `whsec_<base64>`; without it one is generated and kept in the
    /// data directory (`webhook_secret`).
    #[arg(long, env = "FLATMESH_WEBHOOK_SECRET", hide_env_values = true)]
    pub webhook_secret: Option<String>,
    /// Allow webhooks to private, loopback and link-local addresses.
    #[arg(long, env = "FLATMESH_ALLOW_PRIVATE_CALLBACKS")]
    pub allow_private_callbacks: bool,
    /// Deadline of one HTTP request (uploads included), e.g. `5m`.
    #[arg(long, env = "FLATMESH_REQUEST_TIMEOUT", default_value = "5m", value_parser = parse_duration)]
    pub request_timeout: Duration,
    /// Delays between webhook attempts, comma-separated (e.g. `1s,5s,30s,2m,10m`).
    #[arg(long, env = "FLATMESH_WEBHOOK_BACKOFF", value_delimiter = ',', value_parser = parse_duration, default_value = "1s,5s,30s,2m,10m")]
    pub webhook_backoff: Vec<Duration>,
}

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    /// Durable state.
    pub store: Arc<dyn store::Store>,
    /// Job runner.
    pub exec: Arc<jobs::Executor>,
    /// Counters.
    pub metrics: Arc<metrics::Metrics>,
    /// Webhook sender.
    pub webhooks: Arc<webhook::Webhooks>,
    /// Largest body.
    pub max_upload: usize,
    api_keys: Arc<Vec<String>>,
}

impl AppState {
    /// A `Retry-After` estimate for a full queue: one typical job per worker.
    pub fn retry_after_secs(&self) -> u64 {
        5
    }
}

/// Turn every error response that is not yet a problem (axum rejections, 404/405 of the
/// router, limits, timeouts, panics) into `application/problem+json`; count responses.
async fn problem_layer(st: axum::extract::State<AppState>, req: Request, next: Next) -> Response {
    let path = req.uri().path().to_string();
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
    if is_problem {
        return res;
    }
    let (parts, body) = res.into_parts();
    let text = axum::body::to_bytes(body, 4096).await.unwrap_or_default();
    let mut detail = String::from_utf8_lossy(&text).trim().to_string();
    if detail.is_empty() {
        detail = match status {
            StatusCode::NOT_FOUND => format!("no route for {path}"),
            StatusCode::METHOD_NOT_ALLOWED => format!("method not allowed on {path}"),
            _ => status.canonical_reason().unwrap_or("error").to_string(),
        };
    }
    let mut p = Problem::new(status, problem::slug_for(status), detail);
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
async fn auth_layer(st: axum::extract::State<AppState>, req: Request, next: Next) -> Response {
    if st.api_keys.is_empty() {
        return next.run(req).await;
    }
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim);
    // Compare with every key, without stopping early.
    let ok = given.is_some_and(|g| {
        st.api_keys.iter().fold(false, |acc, k| {
            let eq = k.len() == g.len()
                && k.bytes().zip(g.bytes()).fold(0u8, |d, (a, b)| d | (a ^ b)) == 0;
            acc | eq
        })
    });
    if ok {
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
    let v1 = Router::new()
        .route(ROUTES[5].1, post(api::upload_mesh))
        .route(ROUTES[6].1, get(api::get_mesh).delete(api::delete_mesh))
        .route(ROUTES[8].1, get(api::mesh_report))
        .route(ROUTES[9].1, post(api::submit_job).get(api::list_jobs))
        .route(ROUTES[11].1, get(api::get_job).delete(api::delete_job))
        .route(ROUTES[13].1, post(api::cancel_job))
        .route(ROUTES[14].1, get(api::job_result))
        .route(ROUTES[15].1, get(api::job_mesh))
        .route(ROUTES[16].1, get(api::job_patterns))
        .route_layer(middleware::from_fn_with_state(st.clone(), auth_layer));
    let mut app = Router::new()
        .route(ROUTES[0].1, get(api::healthz))
        .route(ROUTES[1].1, get(api::readyz))
        .route(ROUTES[2].1, get(api::metrics))
        .route(ROUTES[3].1, get(api::version))
        .route(ROUTES[4].1, get(api::openapi))
        .merge(v1)
        .layer(DefaultBodyLimit::max(cfg.max_upload))
        .layer(middleware::from_fn_with_state(st.clone(), problem_layer))
        .layer(CatchPanicLayer::custom(panic_to_problem))
        .layer(TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            cfg.request_timeout,
        ))
        .layer(CompressionLayer::new())
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &Request| {
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("");
                tracing::info_span!("http", method = %req.method(), path = %req.uri().path(), request_id = %id)
            }),
        )
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
        app = app.layer(
            CorsLayer::new()
                .allow_origin(origin)
                .allow_methods(Any)
                .allow_headers(Any)
                .expose_headers([header::LOCATION, header::ETAG, header::RETRY_AFTER]),
        );
    }
    app.with_state(st)
}

fn webhook_key(cfg: &Config) -> Result<Vec<u8>, String> {
    if let Some(s) = &cfg.webhook_secret {
        return webhook::decode_secret(s);
    }
    let path = cfg.data_dir.join("webhook_secret");
    if let Ok(s) = std::fs::read_to_string(&path) {
        return webhook::decode_secret(&s);
    }
    use base64::Engine;
    let mut key = Vec::with_capacity(32);
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    key.extend_from_slice(uuid::Uuid::new_v4().as_bytes());
    let secret = format!(
        "whsec_{}",
        base64::engine::general_purpose::STANDARD.encode(&key)
    );
    std::fs::write(&path, secret).map_err(|e| format!("{}: {e}", path.display()))?;
    tracing::info!(path = %path.display(), "generated a webhook signing secret");
    Ok(key)
}

/// Run the server until SIGINT/SIGTERM. Prints `listening on http://ADDR` on stdout once
/// the socket is bound.
pub fn serve(cfg: Config) -> Result<(), String> {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FLATMESH_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .try_init();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("flatmesh-http")
        .build()
        .map_err(|e| e.to_string())?;
    rt.block_on(serve_async(cfg))
}

async fn serve_async(cfg: Config) -> Result<(), String> {
    std::fs::create_dir_all(&cfg.data_dir)
        .map_err(|e| format!("cannot create {}: {e}", cfg.data_dir.display()))?;
    let store: Arc<dyn store::Store> = Arc::new(
        store::SqliteStore::open(&cfg.data_dir)
            .map_err(|e| format!("cannot open the store in {}: {e}", cfg.data_dir.display()))?,
    );
    let metrics = Arc::new(metrics::Metrics::default());
    let mut hooks = webhook::Webhooks::new(
        webhook_key(&cfg)?,
        cfg.allow_private_callbacks,
        tokio::runtime::Handle::current(),
        metrics.clone(),
    );
    hooks.backoff = cfg.webhook_backoff.clone();
    let webhooks = Arc::new(hooks);
    let workers = if cfg.workers == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        cfg.workers
    };
    let limits = jobs::Limits {
        workers,
        max_queued: cfg.max_queued,
        time_limit: cfg.job_time_limit,
        retention: cfg.retention,
        max_attempts: cfg.max_attempts,
        nice: cfg.worker_nice,
        lease: cfg.lease,
    };
    let exec = jobs::Executor::new(store.clone(), limits, metrics.clone(), webhooks.clone())
        .map_err(|e| e.to_string())?;
    let (queued, cancelled) = exec.recover().map_err(|e| format!("recovery: {e}"))?;
    tracing::info!(queued, cancelled, workers, "store recovered");
    let st = AppState {
        store,
        exec: exec.clone(),
        metrics,
        webhooks,
        max_upload: cfg.max_upload,
        api_keys: Arc::new(
            cfg.api_keys
                .iter()
                .filter(|k| !k.is_empty())
                .cloned()
                .collect(),
        ),
    };
    // Expired results go at a quarter of the retention, at most once a minute.
    let sweeper = exec.clone();
    let every = (cfg.retention / 4).clamp(Duration::from_millis(200), Duration::from_secs(60));
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(every);
        loop {
            tick.tick().await;
            let ex = sweeper.clone();
            match tokio::task::spawn_blocking(move || ex.sweep()).await {
                Ok(Ok(n)) if n > 0 => tracing::info!(n, "expired jobs deleted"),
                Ok(Err(e)) => tracing::error!(error = %e, "sweep failed"),
                _ => {}
            }
        }
    });
    let maint = st.store.clone();
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        loop {
            tick.tick().await;
            let m = maint.clone();
            if let Ok(Err(e)) = tokio::task::spawn_blocking(move || m.maintain()).await {
                tracing::warn!(error = %e, "store maintenance failed");
            }
        }
    });
    let app = router(st, &cfg);
    let listener = tokio::net::TcpListener::bind(&cfg.bind)
        .await
        .map_err(|e| format!("cannot bind {}: {e}", cfg.bind))?;
    let addr: SocketAddr = listener.local_addr().map_err(|e| e.to_string())?;
    println!("listening on http://{addr}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
    tracing::info!(%addr, "serving");
    axum::serve(listener, app)
        .with_graceful_shutdown(shutdown())
        .await
        .map_err(|e| e.to_string())
}

async fn shutdown() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! { _ = ctrl_c => {}, _ = term => {} }
    tracing::info!("shutting down; running jobs are re-queued at the next start");
}
