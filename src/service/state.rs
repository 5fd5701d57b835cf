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
    /// Bearer keys accepted on /v1, each with its tenant (none: open, one tenant).
    pub api_keys: Arc<Vec<super::tenants::ApiKey>>,
    /// `--public-url`: the base of absolute URLs (else taken from each request).
    pub public_url: Option<Arc<str>>,
    /// What an upload may expand to (`--max-triangles`).
    pub mesh_limits: crate::io::Limits,
    /// Meshes parsed at once ([`PARSE_SLOTS`]): parsing is where an upload's memory goes.
    pub parse_slots: Arc<tokio::sync::Semaphore>,
}

/// Most meshes one process parses at once (uploads and reports); each takes up to about
/// 200 bytes per triangle of `--max-triangles` while it is parsed and checked.
pub const PARSE_SLOTS: usize = 2;
