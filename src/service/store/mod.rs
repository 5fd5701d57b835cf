//! Durable state: the job and mesh index behind the [`Store`] trait and the bytes behind
//! [`Blobs`] (uploaded meshes `meshes/{id}`, job artifacts `jobs/{id}/{name}`). The embedded
//! default is [`SqliteStore`] (SQLite for the index, [`FileBlobs`] under the data directory);
//! [`PgStore`] is the shared database for several replicas (index and blobs in PostgreSQL).
//! Both run the same [`contract`] suite. Nothing here knows of HTTP.

pub mod contract;
mod files;
mod job_cache;
mod postgres;
mod sqlite;

pub use files::FileBlobs;
pub use postgres::PgStore;
pub use sqlite::SqliteStore;

use super::domain::{JobRecord, MeshRecord, Status};

/// A storage failure (the service answers 500 and logs it). Backend-neutral: a backend turns
/// its driver's errors into [`StoreError::Backend`].
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database refused or failed.
    #[error("{backend}: {message}")]
    Backend {
        /// Which backend (`sqlite`, `postgres`).
        backend: &'static str,
        /// The driver's message.
        message: String,
    },
    /// A blob could not be read or written.
    #[error("blob {0}: {1}")]
    Io(String, std::io::Error),
    /// A stored row does not decode.
    #[error("corrupt row: {0}")]
    Corrupt(String),
    /// The storage is full (no space left, quota exceeded): nothing was written.
    #[error("storage full: {0}")]
    Full(String),
}

/// Delete a row with `delete_row` and the blobs under `prefix`. When the storage is too full
/// for the row's delete to be written (SQLite needs room in its log), the blobs go first and
/// the row is tried again: a full disk must not keep the API from freeing space.
pub fn delete_with_blobs(
    blobs: &dyn Blobs,
    prefix: &str,
    delete_row: impl Fn() -> Result<bool, StoreError>,
) -> Result<bool, StoreError> {
    let existed = match delete_row() {
        Err(StoreError::Full(_)) => {
            blobs.delete_blobs(prefix)?;
            delete_row()?
        }
        other => other?,
    };
    blobs.delete_blobs(prefix)?;
    Ok(existed)
}

/// Whether the store has room for at least a small result: a 64 KiB probe blob is written
/// under a unique key and deleted. `Ok(false)` when the write finds the storage full.
pub fn has_room(blobs: &dyn Blobs) -> Result<bool, StoreError> {
    let key = format!("probe/{}", uuid::Uuid::new_v4().simple());
    match blobs.put_blob(&key, &[0u8; 64 << 10]) {
        Err(StoreError::Full(_)) => Ok(false),
        other => {
            other?;
            blobs.delete_blobs(&key)?;
            Ok(true)
        }
    }
}

/// Whether an I/O error means the storage is full (ENOSPC, EDQUOT).
pub fn is_full(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::StorageFull
        || e.kind() == std::io::ErrorKind::QuotaExceeded
        || matches!(e.raw_os_error(), Some(28) | Some(122))
}

/// Named byte strings: uploads and results. Keys are built by the service from generated ids
/// (`meshes/{id}`, `jobs/{id}/{name}`); `jobs/{id}` names all of a job's blobs at once.
pub trait Blobs: Send + Sync {
    /// Store a blob atomically (a reader sees the old bytes or the new, never a part).
    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError>;
    /// Read a blob; None when absent.
    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError>;
    /// Delete a blob, or every blob under a prefix; absent is fine.
    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError>;
}

/// Filters and page of `GET /v1/jobs`.
#[derive(Debug, Clone, Default)]
pub struct JobFilter {
    /// Only this tenant's jobs.
    pub tenant: String,
    /// Only jobs in this state.
    pub status: Option<Status>,
    /// Only jobs of this kind.
    pub kind: Option<String>,
    /// Only jobs inserted before this sequence number (the page token).
    pub before_seq: Option<i64>,
    /// Page size.
    pub limit: usize,
}

/// Result of an insert that may hit an existing idempotency key.
#[derive(Debug)]
pub enum Inserted {
    /// A new job.
    New(JobRecord),
    /// The job created earlier with the same idempotency key.
    Existing(JobRecord),
}

/// The durable state of the service. Implementations are shared between the async handlers
/// and the worker threads, so every method is a short blocking call.
pub trait Store: Blobs {
    /// Cheap liveness check of the backend.
    fn ping(&self) -> Result<(), StoreError>;
    /// Record an uploaded mesh (its blob is written first).
    fn insert_mesh(&self, m: &MeshRecord) -> Result<(), StoreError>;
    /// A mesh by id.
    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError>;
    /// Forget a mesh; false when absent.
    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError>;
    /// Whether a queued or running job uses the mesh.
    fn mesh_in_use(&self, id: &str) -> Result<bool, StoreError>;
    /// Meshes newest first (by upload time, then id), at most `limit`, after the position
    /// `after` (the `(created_at, id)` of the previous page's last mesh).
    fn list_meshes(
        &self,
        tenant: &str,
        after: Option<(i64, &str)>,
        limit: usize,
    ) -> Result<Vec<MeshRecord>, StoreError>;
    /// A stored mesh with exactly these bytes (hex SHA-256), the oldest when several, marked
    /// as handed out again at `now`: its retention restarts, and the request that stored it
    /// can no longer take it back ([`Store::forget_mesh`]).
    fn find_mesh_by_sha256(
        &self,
        tenant: &str,
        sha256: &str,
        now: i64,
    ) -> Result<Option<MeshRecord>, StoreError>;
    /// Delete the meshes uploaded (or last handed out again) before `before` that no job
    /// refers to (expired uploads), each checked and deleted in one statement; their ids
    /// (their blobs are the caller's).
    fn delete_unused_meshes(&self, before: i64) -> Result<Vec<String>, StoreError>;
    /// Take back a mesh the calling request stored, in one statement: deleted only when it
    /// was never handed out again by its hash and no job refers to it. Whether it was.
    fn forget_mesh(&self, id: &str) -> Result<bool, StoreError>;
    /// Insert a job, or return the one with the same idempotency key. `seq` is assigned.
    fn insert_job(&self, j: &JobRecord) -> Result<Inserted, StoreError>;
    /// The job created with an idempotency key.
    fn find_idempotent(&self, key: &str) -> Result<Option<JobRecord>, StoreError>;
    /// A job by id.
    fn get_job(&self, id: &str) -> Result<Option<JobRecord>, StoreError>;
    /// `get_job` when it can be answered without waiting (no lock to wait for, no network):
    /// None means "ask `get_job` from a blocking thread". Lets the async status poll skip a
    /// thread hand-off.
    fn try_get_job_now(&self, _id: &str) -> Option<Result<Option<JobRecord>, StoreError>> {
        None
    }
    /// `get_job` as a future for the async handlers, where the backend is asynchronous
    /// (PostgreSQL): no blocking-pool hop. None: use [`Store::try_get_job_now`] or `get_job`.
    fn get_job_async(
        &self,
        _id: &str,
    ) -> Option<futures_util::future::BoxFuture<'static, Result<Option<JobRecord>, StoreError>>>
    {
        None
    }
    /// Overwrite a job's mutable fields.
    fn update_job(&self, j: &JobRecord) -> Result<(), StoreError>;
    /// Delete a job row; false when absent.
    fn delete_job(&self, id: &str) -> Result<bool, StoreError>;
    /// Jobs newest first, filtered.
    fn list_jobs(&self, f: &JobFilter) -> Result<Vec<JobRecord>, StoreError>;
    /// Jobs in a state, oldest first (recovery after a restart).
    fn jobs_with_status(&self, s: Status) -> Result<Vec<JobRecord>, StoreError>;
    /// Finished jobs whose results expired before `now`.
    fn expired_jobs(&self, now: i64) -> Result<Vec<JobRecord>, StoreError>;
    /// Periodic housekeeping off the request path (called about once a second).
    fn maintain(&self) -> Result<(), StoreError> {
        Ok(())
    }

    // Coordination: every process serving one store runs jobs through these, so that a job
    // runs once whichever process took it, a cancel reaches the process running it, and a
    // job whose process died runs again. Each is one atomic step of the backend.

    /// Take the oldest queued job for `worker`, leased until `now + lease_ms`: it becomes
    /// running, its attempts grow by one, its progress and outcome are cleared.
    fn claim(&self, worker: &str, now: i64, lease_ms: i64)
        -> Result<Option<JobRecord>, StoreError>;
    /// Extend `worker`'s lease on job `id` (and record `progress` when given); says whether a
    /// cancel was requested, or that the lease is lost (expired and taken, or the job ended
    /// or was deleted), in which case the worker must stop and not write its result.
    fn heartbeat(
        &self,
        worker: &str,
        id: &str,
        now: i64,
        lease_ms: i64,
        progress: Option<&serde_json::Value>,
    ) -> Result<Lease, StoreError>;
    /// Record the end of a job `worker` holds (status, error, artifacts, outcome, times from
    /// `j`); false, and nothing written, when it no longer holds it.
    ///
    /// Every step that ends a job (this, the cancel of a queued job, an expired lease with a
    /// cancel requested) also queues one webhook [`Delivery`] when the job has a callback,
    /// in the same atomic step: a process that dies right after cannot lose it.
    fn finish(&self, worker: &str, j: &JobRecord) -> Result<bool, StoreError>;
    /// Cancel job `id`: a queued job ends cancelled at once (results kept until
    /// `expires_at`), a running one is flagged for its worker's next heartbeat.
    fn request_cancel(
        &self,
        id: &str,
        now: i64,
        expires_at: i64,
    ) -> Result<CancelOutcome, StoreError>;
    /// Running jobs whose lease ran out before `now`: queued again (or cancelled, when a
    /// cancel was requested), and returned.
    fn requeue_expired(&self, now: i64, expires_at: i64) -> Result<Vec<JobRecord>, StoreError>;
    /// Put job `id`, running under `worker`, back at its place in the queue with its attempt
    /// uncounted (its run could not store its results: the storage was full). False when
    /// `worker` no longer holds it or a cancel was requested (the caller then ends it).
    fn release(&self, worker: &str, id: &str) -> Result<bool, StoreError>;
    /// How many jobs are in state `s`.
    fn count_with_status(&self, s: Status) -> Result<usize, StoreError>;
    /// Take the oldest due webhook delivery for `worker`, leased until `now + lease_ms` (a
    /// sender that dies leaves it to another after that).
    fn claim_delivery(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<Delivery>, StoreError>;
    /// A delivery `worker` holds is done (delivered, or given up): remove it. False when it
    /// no longer holds it.
    fn end_delivery(&self, id: i64, worker: &str) -> Result<bool, StoreError>;
    /// A delivery `worker` holds failed: try again at `due_at`, one more attempt counted.
    fn retry_delivery(&self, id: i64, worker: &str, due_at: i64) -> Result<bool, StoreError>;
    /// The webhook signing secret every process on this store shares: the stored one, or
    /// `candidate`, stored, when there is none yet (the first process to ask sets it). None
    /// when the store keeps no secret (SQLite: the file beside it does).
    fn shared_webhook_secret(&self, _candidate: &str) -> Result<Option<String>, StoreError> {
        Ok(None)
    }
    /// Call `wake` whenever a job may have been queued by any process (a backend that can
    /// push this, as PostgreSQL's LISTEN/NOTIFY, wakes idle workers at once; without it
    /// they find work by polling).
    fn watch_queue(&self, _wake: std::sync::Arc<dyn Fn() + Send + Sync>) -> Result<(), StoreError> {
        Ok(())
    }
}

/// A webhook call waiting in the outbox: job `job_id` ended as `event` (`job.succeeded`, …).
#[derive(Debug, Clone, PartialEq)]
pub struct Delivery {
    /// Outbox row id (the webhook id is made from it, the same on every attempt).
    pub id: i64,
    /// The job.
    pub job_id: String,
    /// `job.<status>`.
    pub event: String,
    /// Attempts made before this claim.
    pub attempts: u32,
}

/// What a heartbeat learns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lease {
    /// The worker still holds the job.
    Held {
        /// Someone asked to cancel it.
        cancel_requested: bool,
    },
    /// The worker no longer holds it.
    Lost,
}

/// What a cancel request did.
#[derive(Debug, Clone, PartialEq)]
pub enum CancelOutcome {
    /// No such job.
    NotFound,
    /// It was queued and is now cancelled.
    Cancelled(JobRecord),
    /// It is running; its worker will stop at its next heartbeat.
    Requested(JobRecord),
    /// It had already ended.
    Ended(JobRecord),
}
