//! The REST job service (`flatmesh serve`). The layers, each importing only those below it:
//! [`domain`] (job and mesh records) ← [`store`] (durable state and coordination) ←
//! [`problem`], [`views`], [`metrics`] ← [`webhook`] ← [`worker`] (claims and runs jobs on a
//! rayon pool) ← [`state`] ← [`handlers`] (one module per resource) ← [`router`] (routes by
//! name, middleware) ← this module's [`serve`]. [`config`] and [`telemetry`] stand aside;
//! [`client`] is the CLI's client of a running service. A test checks that no module imports
//! one above it.

// `Problem` (~144 bytes) is the error of every handler; errors are the cold path of a
// network service, so boxing it would only add noise.
#![allow(clippy::result_large_err)]

pub mod client;
pub mod config;
pub mod connections;
pub mod domain;
pub mod eta;
pub mod handlers;
pub mod head_errors;
pub mod metrics;
pub mod problem;
pub mod router;
pub mod state;
pub mod store;
pub mod telemetry;
pub mod tenants;
pub mod views;
pub mod webhook;
pub mod worker;

pub use config::Config;
pub use handlers::ops::OPENAPI;
pub use router::routes;

use metrics::Metrics;
use state::AppState;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use store::{PgStore, SqliteStore, Store};
use webhook::Webhooks;
use worker::{Executor, Limits};

/// How often freed heap memory is handed back to the system.
const TRIM_EVERY: Duration = Duration::from_secs(30);

/// Hand memory the allocator keeps after frees back to the system: glibc keeps freed pages
/// of its per-thread arenas, so a server's resident size creeps up under load although what
/// it holds does not (4 minutes into a soak: 13 MB in use, 20 MB held).
fn return_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free memory; it is thread-safe.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Threads for blocking work of the HTTP side (store calls, parses).
const BLOCKING_THREADS: usize = 32;

/// Run the server until SIGINT/SIGTERM. Prints `listening on http://ADDR` on stdout once
/// the socket is bound.
pub fn serve(cfg: Config) -> Result<(), String> {
    telemetry::init();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("flatmesh-http")
        // Store calls and parses run here; beyond this many at once they wait for a thread
        // (each store serialises its writes anyway) instead of growing the process by a
        // thread per waiting request (tokio's default allows 512).
        .max_blocking_threads(BLOCKING_THREADS)
        .build()
        .map_err(|e| e.to_string())?;
    rt.block_on(serve_async(cfg))
}

/// The store the configuration names: PostgreSQL with `--database-url`, else SQLite in the
/// data directory (opened off the async threads: both block).
async fn open_store(cfg: &Config) -> Result<Arc<dyn Store>, String> {
    let (url, dir, conns) = (
        cfg.database_url.clone(),
        cfg.data_dir.clone(),
        cfg.database_connections,
    );
    tokio::task::spawn_blocking(move || -> Result<Arc<dyn Store>, String> {
        Ok(match url {
            Some(url) => Arc::new(
                PgStore::open(&url, conns).map_err(|e| format!("cannot open the database: {e}"))?,
            ),
            None => Arc::new(
                SqliteStore::open(&dir)
                    .map_err(|e| format!("cannot open the store in {}: {e}", dir.display()))?,
            ),
        })
    })
    .await
    .map_err(|e| e.to_string())?
}

async fn serve_async(cfg: Config) -> Result<(), String> {
    // An empty key would otherwise be dropped and, if it was the only one, turn
    // authentication off without a word.
    let api_keys = tenants::parse_api_keys(&cfg.api_keys)
        .map_err(|e| format!("--api-key / FLATMESH_API_KEYS: {e}"))?;
    std::fs::create_dir_all(&cfg.data_dir)
        .map_err(|e| format!("cannot create {}: {e}", cfg.data_dir.display()))?;
    let store = open_store(&cfg).await?;
    let metrics = Arc::new(Metrics::default());
    let (given, st, dir) = (
        cfg.webhook_secret.clone(),
        store.clone(),
        cfg.data_dir.clone(),
    );
    let key = tokio::task::spawn_blocking(move || {
        webhook::signing_key(given.as_deref(), st.as_ref(), &dir)
    })
    .await
    .map_err(|e| e.to_string())??;
    let mut hooks = Webhooks::new(
        key,
        cfg.allow_private_callbacks,
        tokio::runtime::Handle::current(),
        metrics.clone(),
    );
    hooks.backoff = cfg.webhook_backoff.clone();
    hooks.base = cfg.public_url.clone().unwrap_or_default();
    let webhooks = Arc::new(hooks);
    let workers = if cfg.workers == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        cfg.workers
    };
    let limits = Limits {
        workers,
        max_queued: cfg.max_queued,
        time_limit: cfg.job_time_limit,
        retention: cfg.retention,
        max_attempts: cfg.max_attempts,
        nice: cfg.worker_nice,
        lease: cfg.lease,
    };
    let exec = Executor::new(store.clone(), limits, metrics.clone()).map_err(|e| e.to_string())?;
    let ex = exec.clone();
    let (queued, cancelled) = tokio::task::spawn_blocking(move || ex.recover())
        .await
        .map_err(|e| format!("recovery: {e}"))?
        .map_err(|e| format!("recovery: {e}"))?;
    tracing::info!(queued, cancelled, workers, "store recovered");
    webhooks.start(store.clone(), format!("{}-webhooks", exec.worker_id()));
    let st = AppState {
        store,
        exec: exec.clone(),
        metrics,
        webhooks,
        max_upload: cfg.max_upload,
        public_url: cfg.public_url.as_deref().map(Arc::from),
        api_keys: Arc::new(api_keys),
        mesh_limits: crate::io::Limits {
            max_triangles: cfg.max_triangles,
        },
        parse_slots: Arc::new(tokio::sync::Semaphore::new(state::PARSE_SLOTS)),
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
                Ok(Ok((jobs, meshes))) if jobs + meshes > 0 => {
                    tracing::info!(jobs, meshes, "expired jobs and unused uploads deleted")
                }
                Ok(Err(e)) => tracing::error!(error = %e, "sweep failed"),
                _ => {}
            }
        }
    });
    tokio::spawn(async {
        let mut tick = tokio::time::interval(TRIM_EVERY);
        loop {
            tick.tick().await;
            let _ = tokio::task::spawn_blocking(return_free_memory).await;
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
    let app = router::router(st, &cfg);
    let listener = tokio::net::TcpListener::bind(&cfg.bind)
        .await
        .map_err(|e| format!("cannot bind {}: {e}", cfg.bind))?;
    let addr: SocketAddr = listener.local_addr().map_err(|e| e.to_string())?;
    println!("listening on http://{addr}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
    tracing::info!(%addr, "serving");
    let limits = connections::ConnLimits {
        max_connections: cfg.max_connections,
        header_timeout: cfg.header_timeout,
        problem_base: Arc::from(cfg.public_url.as_deref().unwrap_or("")),
    };
    connections::serve(listener, app, limits, shutdown()).await;
    Ok(())
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
