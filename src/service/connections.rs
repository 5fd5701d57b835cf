//! The accept loop: HTTP/1.1 connections served by hyper with a deadline for each request
//! head (a client that sends its headers slowly, or never, is dropped: slowloris; an idle
//! keep-alive connection likewise) and a cap on open connections (accepting waits for a free
//! slot, so file descriptors stay bounded). `axum::serve` offers neither, hence this loop.
//! Heads hyper cannot parse get a problem body ([`super::head_errors`]).

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

/// Bounds on connections.
#[derive(Debug, Clone)]
pub struct ConnLimits {
    /// Most connections open at once.
    pub max_connections: usize,
    /// Time allowed for a request's head (request line and headers) to arrive.
    pub header_timeout: Duration,
    /// Base of problem `type` URLs in the answers to heads that cannot be parsed
    /// (`--public-url`; empty: relative).
    pub problem_base: Arc<str>,
}

/// How long in-flight requests get to finish once shutdown begins.
const DRAIN: Duration = Duration::from_secs(30);

/// Serve `app` on `listener` until `shutdown` completes, then let open requests finish.
pub async fn serve(
    listener: tokio::net::TcpListener,
    app: axum::Router,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()>,
) {
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    let slots = Arc::new(tokio::sync::Semaphore::new(limits.max_connections.max(1)));
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let slot = tokio::select! {
            s = Arc::clone(&slots).acquire_owned() => match s {
                Ok(s) => s,
                Err(_) => break,
            },
            () = &mut shutdown => break,
        };
        let stream = tokio::select! {
            r = listener.accept() => match r {
                Ok((s, _)) => s,
                Err(e) => {
                    // Out of file descriptors, or a connection reset before it was taken:
                    // wait a little rather than spin.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let _ = stream.set_nodelay(true);
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        let io = super::head_errors::ProblemAnswers::new(
            hyper_util::rt::TokioIo::new(stream),
            Arc::clone(&limits.problem_base),
        );
        let conn = http.serve_connection(io, service);
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            let _ = conn.await;
            drop(slot);
        });
    }
    // New clients are refused at once (they can go to another replica) while open requests
    // finish.
    drop(listener);
    if tokio::time::timeout(DRAIN, graceful.shutdown())
        .await
        .is_err()
    {
        tracing::warn!("requests still open after {DRAIN:?}; stopping anyway");
    }
}
