//! Logs: `tracing` to stderr, filtered by `FLATMESH_LOG` (default `info`), and one span per
//! HTTP request carrying its request id. Counters are in [`super::metrics`].

use axum::extract::Request;

/// Install the log subscriber (once; later calls keep the first).
pub fn init() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FLATMESH_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // Colour codes only for a person at a terminal, never in a log file or collector.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// The span of one request: method, path and `x-request-id`.
pub fn http_span(req: &Request) -> tracing::Span {
    let id = req
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    tracing::info_span!("http", method = %req.method(), path = %req.uri().path(), request_id = %id)
}
