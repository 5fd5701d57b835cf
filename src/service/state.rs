//! What every handler shares.

use super::metrics::Metrics;
use super::store::Store;
use super::webhook::Webhooks;
use super::worker::Executor;
use std::sync::Arc;

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    /// Durable state.
    pub store: Arc<dyn Store>,
    /// Job runner.
    pub exec: Arc<Executor>,
    /// Counters.
    pub metrics: Arc<Metrics>,
    /// Webhook sender.
    pub webhooks: Arc<Webhooks>,
    /// Largest body.
    pub max_upload: usize,
    /// Bearer keys accepted on /v1 (none: open).
    pub api_keys: Arc<Vec<String>>,
    /// `--public-url`: the base of absolute URLs (else taken from each request).
    pub public_url: Option<Arc<str>>,
}
