//! Durable state: the job and mesh index behind the [`Store`] trait, with the embedded default
//! [`SqliteStore`] (SQLite for the index, plain files under the data directory for blobs:
//! uploaded meshes and job artifacts). A shared database for several replicas implements the
//! same trait.

use super::problem::Problem;
use rusqlite::{params, Connection, OptionalExtension};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A storage failure (the service answers 500 and logs it).
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// SQLite said no.
    #[error("database: {0}")]
    Db(#[from] rusqlite::Error),
    /// A blob could not be read or written.
    #[error("blob {0}: {1}")]
    Io(String, std::io::Error),
    /// A stored row does not decode.
    #[error("corrupt row: {0}")]
    Corrupt(String),
}

/// Lifecycle of a job (AIP-151 style): queued → running → succeeded | failed | cancelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Waiting for a worker.
    Queued,
    /// On a worker.
    Running,
    /// Finished with results.
    Succeeded,
    /// Finished with an error (see `error`).
    Failed,
    /// Cancelled by the client.
    Cancelled,
}

impl Status {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Queued => "queued",
            Status::Running => "running",
            Status::Succeeded => "succeeded",
            Status::Failed => "failed",
            Status::Cancelled => "cancelled",
        }
    }
    /// Parse the wire name.
    pub fn parse(s: &str) -> Option<Status> {
        Some(match s {
            "queued" => Status::Queued,
            "running" => Status::Running,
            "succeeded" => Status::Succeeded,
            "failed" => Status::Failed,
            "cancelled" => Status::Cancelled,
            _ => return None,
        })
    }
    /// Whether the job has ended.
    pub fn is_terminal(self) -> bool {
        matches!(self, Status::Succeeded | Status::Failed | Status::Cancelled)
    }
}

/// An uploaded mesh. Its bytes are the blob `meshes/{id}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshRecord {
    /// Id (`m_…`).
    pub id: String,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// `obj`, `gltf`, `glb` or `off`.
    pub format: String,
    /// Bytes uploaded.
    pub size: u64,
    /// Hex SHA-256 of the bytes (the ETag).
    pub sha256: String,
    /// Summary shown to clients (vertices, faces, patches, max ϖ, warnings).
    pub summary: serde_json::Value,
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRecord {
    /// Insertion order (list order, page tokens).
    pub seq: i64,
    /// Id (`j_…`).
    pub id: String,
    /// Job kind (one of `algorithms::KINDS`).
    pub kind: String,
    /// Input mesh.
    pub mesh_id: String,
    /// Reference mesh, for kinds that use one.
    pub reference_mesh_id: Option<String>,
    /// Validated parameters.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Webhook target.
    pub callback_url: Option<String>,
    /// Lifecycle state.
    pub status: Status,
    /// Last progress report (JSON object), persisted on state changes.
    pub progress: Option<serde_json::Value>,
    /// Why the job failed.
    pub error: Option<Problem>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// When a worker last started it.
    pub started_at: Option<i64>,
    /// When it ended.
    pub finished_at: Option<i64>,
    /// When its results are deleted.
    pub expires_at: Option<i64>,
    /// How many times a worker started it (restarts re-queue running jobs).
    pub attempts: u32,
    /// Names of the stored artifacts (`report.json`, `mesh.glb`, …), blobs `jobs/{id}/{name}`.
    pub artifacts: Vec<String>,
    /// What a succeeded job reached, shown at the top level of the job: `converged`,
    /// `max_flattenability` (measured on the output), `stop_reason`.
    pub outcome: Option<serde_json::Value>,
    /// Client's `Idempotency-Key`.
    pub idempotency_key: Option<String>,
    /// Hash of the request that created the job (to detect a reused key).
    pub request_hash: Option<String>,
}

impl JobRecord {
    /// A queued job of `kind` on mesh `mesh_id` with no parameters, callback or history.
    pub fn queued(id: &str, kind: &str, mesh_id: &str, created_at: i64) -> JobRecord {
        JobRecord {
            seq: 0,
            id: id.into(),
            kind: kind.into(),
            mesh_id: mesh_id.into(),
            reference_mesh_id: None,
            params: serde_json::Map::new(),
            callback_url: None,
            status: Status::Queued,
            progress: None,
            error: None,
            created_at,
            started_at: None,
            finished_at: None,
            expires_at: None,
            attempts: 0,
            artifacts: vec![],
            outcome: None,
            idempotency_key: None,
            request_hash: None,
        }
    }
}

/// Filters and page of `GET /v1/jobs`.
#[derive(Debug, Clone, Default)]
pub struct JobFilter {
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
pub trait Store: Send + Sync {
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
    /// Store a blob atomically (write, then rename).
    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError>;
    /// Read a blob; None when absent.
    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError>;
    /// Delete a blob or a directory of blobs; absent is fine.
    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError>;
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
    /// How many jobs are in state `s`.
    fn count_with_status(&self, s: Status) -> Result<usize, StoreError>;
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

/// SQLite index (`flatmesh.sqlite3`, WAL) plus blob files under the data directory.
pub struct SqliteStore {
    /// The one writer.
    conn: Mutex<Connection>,
    /// Readers (WAL lets them read while the writer writes), taken round robin.
    readers: Vec<Mutex<Connection>>,
    /// Runs WAL checkpoints, so that commits on the request path never do.
    checkpointer: Mutex<Connection>,
    next_reader: std::sync::atomic::AtomicUsize,
    dir: PathBuf,
}

const READERS: usize = 4;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meshes (
  id TEXT PRIMARY KEY,
  created_at INTEGER NOT NULL,
  format TEXT NOT NULL,
  size INTEGER NOT NULL,
  sha256 TEXT NOT NULL,
  summary TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS jobs (
  seq INTEGER PRIMARY KEY AUTOINCREMENT,
  id TEXT NOT NULL UNIQUE,
  kind TEXT NOT NULL,
  mesh_id TEXT NOT NULL,
  reference_mesh_id TEXT,
  params TEXT NOT NULL,
  callback_url TEXT,
  status TEXT NOT NULL,
  progress TEXT,
  error TEXT,
  created_at INTEGER NOT NULL,
  started_at INTEGER,
  finished_at INTEGER,
  expires_at INTEGER,
  attempts INTEGER NOT NULL DEFAULT 0,
  artifacts TEXT NOT NULL DEFAULT '[]',
  idempotency_key TEXT UNIQUE,
  request_hash TEXT,
  outcome TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs(status, seq);
CREATE INDEX IF NOT EXISTS jobs_mesh ON jobs(mesh_id);
CREATE INDEX IF NOT EXISTS jobs_ref ON jobs(reference_mesh_id);
";

const JOB_COLS: &str = "seq, id, kind, mesh_id, reference_mesh_id, params, callback_url, status, \
    progress, error, created_at, started_at, finished_at, expires_at, attempts, artifacts, \
    idempotency_key, request_hash, outcome";

fn json_err(e: serde_json::Error) -> rusqlite::Error {
    rusqlite::Error::ToSqlConversionFailure(Box::new(e))
}

fn job_from_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<JobRecord> {
    let bad = |i: usize, what: String| {
        rusqlite::Error::FromSqlConversionFailure(
            i,
            rusqlite::types::Type::Text,
            Box::<dyn std::error::Error + Send + Sync>::from(what),
        )
    };
    let params: String = r.get(5)?;
    let status: String = r.get(7)?;
    let progress: Option<String> = r.get(8)?;
    let error: Option<String> = r.get(9)?;
    let artifacts: String = r.get(15)?;
    let outcome: Option<String> = r.get(18)?;
    Ok(JobRecord {
        seq: r.get(0)?,
        id: r.get(1)?,
        kind: r.get(2)?,
        mesh_id: r.get(3)?,
        reference_mesh_id: r.get(4)?,
        params: serde_json::from_str(&params).map_err(|e| bad(5, e.to_string()))?,
        callback_url: r.get(6)?,
        status: Status::parse(&status).ok_or_else(|| bad(7, status.clone()))?,
        progress: progress
            .map(|p| serde_json::from_str(&p))
            .transpose()
            .map_err(|e| bad(8, e.to_string()))?,
        error: error
            .map(|p| serde_json::from_str(&p))
            .transpose()
            .map_err(|e| bad(9, e.to_string()))?,
        created_at: r.get(10)?,
        started_at: r.get(11)?,
        finished_at: r.get(12)?,
        expires_at: r.get(13)?,
        attempts: r.get(14)?,
        artifacts: serde_json::from_str(&artifacts).map_err(|e| bad(15, e.to_string()))?,
        idempotency_key: r.get(16)?,
        request_hash: r.get(17)?,
        outcome: outcome
            .map(|p| serde_json::from_str(&p))
            .transpose()
            .map_err(|e| bad(18, e.to_string()))?,
    })
}

/// Stores made by older versions get the columns added since (empty for their jobs): the
/// outcome, and the lease of the coordination contract (a running job without a lease counts
/// as expired, so it is queued again).
fn add_columns(conn: &Connection) -> rusqlite::Result<()> {
    for (name, decl) in [
        ("outcome", "outcome TEXT"),
        ("worker", "worker TEXT"),
        ("lease_until", "lease_until INTEGER"),
        (
            "cancel_requested",
            "cancel_requested INTEGER NOT NULL DEFAULT 0",
        ),
    ] {
        let has: bool = conn
            .prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = ?1")?
            .exists([name])?;
        if !has {
            conn.execute_batch(&format!("ALTER TABLE jobs ADD COLUMN {decl}"))?;
        }
    }
    Ok(())
}

impl SqliteStore {
    /// Open (creating) the store in `dir`.
    pub fn open(dir: &Path) -> Result<SqliteStore, StoreError> {
        std::fs::create_dir_all(dir.join("blobs"))
            .map_err(|e| StoreError::Io(dir.display().to_string(), e))?;
        let conn = Connection::open(dir.join("flatmesh.sqlite3"))?;
        // WAL + NORMAL: a committed transaction survives a process crash (not necessarily a
        // power cut, which would need synchronous=FULL at a cost on every status change).
        conn.pragma_update(None, "journal_mode", "WAL")?;
        conn.pragma_update(None, "synchronous", "NORMAL")?;
        conn.busy_timeout(std::time::Duration::from_secs(5))?;
        conn.execute_batch(SCHEMA)?;
        add_columns(&conn)?;
        // No automatic checkpoint inside a commit (it fsyncs, ~10-40 ms on a busy disk);
        // `maintain` checkpoints from its own connection instead.
        conn.pragma_update(None, "wal_autocheckpoint", 0)?;
        let checkpointer = Connection::open(dir.join("flatmesh.sqlite3"))?;
        checkpointer.busy_timeout(std::time::Duration::from_secs(5))?;
        let mut readers = Vec::with_capacity(READERS);
        for _ in 0..READERS {
            let r = Connection::open_with_flags(
                dir.join("flatmesh.sqlite3"),
                rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY
                    | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX,
            )?;
            r.busy_timeout(std::time::Duration::from_secs(5))?;
            readers.push(Mutex::new(r));
        }
        Ok(SqliteStore {
            conn: Mutex::new(conn),
            readers,
            checkpointer: Mutex::new(checkpointer),
            next_reader: std::sync::atomic::AtomicUsize::new(0),
            dir: dir.to_path_buf(),
        })
    }

    fn conn(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A read connection: a free one if any, else the next in turn.
    fn reader(&self) -> std::sync::MutexGuard<'_, Connection> {
        for r in &self.readers {
            if let Ok(g) = r.try_lock() {
                return g;
            }
        }
        let i = self
            .next_reader
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            % self.readers.len();
        self.readers[i].lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Every read connection, locked (tests of what happens when none is free).
    #[cfg(test)]
    pub(crate) fn hold_readers_for_test(&self) -> Vec<std::sync::MutexGuard<'_, Connection>> {
        self.readers.iter().map(|r| r.lock().unwrap()).collect()
    }

    fn blob_path(&self, key: &str) -> PathBuf {
        // Keys are built by the service from generated ids; refuse anything that could escape.
        let clean: String = key
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/') {
                    c
                } else {
                    '_'
                }
            })
            .collect::<String>()
            .replace("..", "__");
        self.dir.join("blobs").join(clean)
    }

    fn select_jobs(
        &self,
        sql_where: &str,
        args: &[&dyn rusqlite::ToSql],
        tail: &str,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let c = self.reader();
        let mut st = c.prepare_cached(&format!(
            "SELECT {JOB_COLS} FROM jobs WHERE {sql_where} {tail}"
        ))?;
        let rows = st.query_map(args, job_from_row)?;
        Ok(rows.collect::<Result<Vec<_>, _>>()?)
    }
}

/// One job by its primary key.
fn job_by_id(c: &Connection, id: &str) -> Result<Option<JobRecord>, StoreError> {
    let mut st = c.prepare_cached(&format!("SELECT {JOB_COLS} FROM jobs WHERE id = ?1"))?;
    Ok(st.query_row([id], job_from_row).optional()?)
}

impl Store for SqliteStore {
    fn ping(&self) -> Result<(), StoreError> {
        self.conn().query_row("SELECT 1", [], |_| Ok(()))?;
        Ok(())
    }

    fn insert_mesh(&self, m: &MeshRecord) -> Result<(), StoreError> {
        self.conn().execute(
            "INSERT INTO meshes (id, created_at, format, size, sha256, summary) VALUES (?1,?2,?3,?4,?5,?6)",
            params![m.id, m.created_at, m.format, m.size as i64, m.sha256, m.summary.to_string()],
        )?;
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        let c = self.reader();
        let mut st = c.prepare_cached(
            "SELECT id, created_at, format, size, sha256, summary FROM meshes WHERE id = ?1",
        )?;
        let row = st
            .query_row([id], |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, i64>(3)? as u64,
                    r.get::<_, String>(4)?,
                    r.get::<_, String>(5)?,
                ))
            })
            .optional()?;
        row.map(|(id, created_at, format, size, sha256, summary)| {
            Ok(MeshRecord {
                id,
                created_at,
                format,
                size,
                sha256,
                summary: serde_json::from_str(&summary)
                    .map_err(|e| StoreError::Corrupt(e.to_string()))?,
            })
        })
        .transpose()
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        Ok(self
            .conn()
            .execute("DELETE FROM meshes WHERE id = ?1", [id])?
            > 0)
    }

    fn mesh_in_use(&self, id: &str) -> Result<bool, StoreError> {
        let n: i64 = self.conn().query_row(
            "SELECT COUNT(*) FROM jobs WHERE (mesh_id = ?1 OR reference_mesh_id = ?1) \
             AND status IN ('queued','running')",
            [id],
            |r| r.get(0),
        )?;
        Ok(n > 0)
    }

    fn insert_job(&self, j: &JobRecord) -> Result<Inserted, StoreError> {
        let mut c = self.conn();
        let tx = c.transaction()?;
        if let Some(key) = &j.idempotency_key {
            let existing = tx
                .query_row(
                    &format!("SELECT {JOB_COLS} FROM jobs WHERE idempotency_key = ?1"),
                    [key],
                    job_from_row,
                )
                .optional()?;
            if let Some(e) = existing {
                return Ok(Inserted::Existing(e));
            }
        }
        tx.execute(
            "INSERT INTO jobs (id, kind, mesh_id, reference_mesh_id, params, callback_url, status, \
             progress, error, created_at, started_at, finished_at, expires_at, attempts, artifacts, \
             idempotency_key, request_hash, outcome) \
             VALUES (?1,?2,?3,?4,?5,?6,?7,?8,?9,?10,?11,?12,?13,?14,?15,?16,?17,?18)",
            params![
                j.id,
                j.kind,
                j.mesh_id,
                j.reference_mesh_id,
                serde_json::to_string(&j.params).map_err(json_err)?,
                j.callback_url,
                j.status.as_str(),
                j.progress.as_ref().map(|p| p.to_string()),
                j.error.as_ref().map(serde_json::to_string).transpose().map_err(json_err)?,
                j.created_at,
                j.started_at,
                j.finished_at,
                j.expires_at,
                j.attempts,
                serde_json::to_string(&j.artifacts).map_err(json_err)?,
                j.idempotency_key,
                j.request_hash,
                j.outcome.as_ref().map(|p| p.to_string()),
            ],
        )?;
        let seq = tx.last_insert_rowid();
        tx.commit()?;
        Ok(Inserted::New(JobRecord { seq, ..j.clone() }))
    }

    fn find_idempotent(&self, key: &str) -> Result<Option<JobRecord>, StoreError> {
        Ok(self.select_jobs("idempotency_key = ?1", &[&key], "")?.pop())
    }

    fn get_job(&self, id: &str) -> Result<Option<JobRecord>, StoreError> {
        job_by_id(&self.reader(), id)
    }

    fn try_get_job_now(&self, id: &str) -> Option<Result<Option<JobRecord>, StoreError>> {
        // Only with a reader nobody holds: a WAL read never waits for the writer.
        let c = self.readers.iter().find_map(|r| r.try_lock().ok())?;
        Some(job_by_id(&c, id))
    }

    fn update_job(&self, j: &JobRecord) -> Result<(), StoreError> {
        self.conn().execute(
            "UPDATE jobs SET status=?2, progress=?3, error=?4, started_at=?5, finished_at=?6, \
             expires_at=?7, attempts=?8, artifacts=?9, outcome=?10 WHERE id=?1",
            params![
                j.id,
                j.status.as_str(),
                j.progress.as_ref().map(|p| p.to_string()),
                j.error
                    .as_ref()
                    .map(serde_json::to_string)
                    .transpose()
                    .map_err(json_err)?,
                j.started_at,
                j.finished_at,
                j.expires_at,
                j.attempts,
                serde_json::to_string(&j.artifacts).map_err(json_err)?,
                j.outcome.as_ref().map(|p| p.to_string()),
            ],
        )?;
        Ok(())
    }

    fn delete_job(&self, id: &str) -> Result<bool, StoreError> {
        Ok(self
            .conn()
            .execute("DELETE FROM jobs WHERE id = ?1", [id])?
            > 0)
    }

    fn list_jobs(&self, f: &JobFilter) -> Result<Vec<JobRecord>, StoreError> {
        let status = f.status.map(|s| s.as_str());
        let limit = f.limit as i64;
        self.select_jobs(
            "(?1 IS NULL OR status = ?1) AND (?2 IS NULL OR kind = ?2) AND (?3 IS NULL OR seq < ?3)",
            &[&status, &f.kind, &f.before_seq, &limit],
            "ORDER BY seq DESC LIMIT ?4",
        )
    }

    fn jobs_with_status(&self, s: Status) -> Result<Vec<JobRecord>, StoreError> {
        self.select_jobs("status = ?1", &[&s.as_str()], "ORDER BY seq ASC")
    }

    fn expired_jobs(&self, now: i64) -> Result<Vec<JobRecord>, StoreError> {
        self.select_jobs(
            "expires_at IS NOT NULL AND expires_at < ?1 AND status IN ('succeeded','failed','cancelled')",
            &[&now],
            "ORDER BY seq ASC",
        )
    }

    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError> {
        let path = self.blob_path(key);
        let io = |e| StoreError::Io(key.to_string(), e);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, bytes).map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)?;
        Ok(())
    }

    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError> {
        match std::fs::read(self.blob_path(key)) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StoreError::Io(key.to_string(), e)),
        }
    }

    fn maintain(&self) -> Result<(), StoreError> {
        // PASSIVE: copies what it can without blocking readers or the writer.
        let c = self.checkpointer.lock().unwrap_or_else(|e| e.into_inner());
        c.query_row("PRAGMA wal_checkpoint(PASSIVE)", [], |_| Ok(()))?;
        Ok(())
    }

    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError> {
        let path = self.blob_path(prefix);
        let r = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        match r {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(StoreError::Io(prefix.to_string(), e)),
        }
    }

    // Each of these is one statement (or one IMMEDIATE transaction), so it is atomic across
    // every process that has the database open.

    fn claim(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<JobRecord>, StoreError> {
        let c = self.conn();
        let mut st = c.prepare_cached(&format!(
            "UPDATE jobs SET status='running', worker=?1, lease_until=?2 + ?3, started_at=?2, \
             attempts=attempts+1, progress=NULL, outcome=NULL, cancel_requested=0 \
             WHERE seq = (SELECT seq FROM jobs WHERE status='queued' ORDER BY seq LIMIT 1) \
             RETURNING {JOB_COLS}"
        ))?;
        Ok(st
            .query_row(params![worker, now, lease_ms], job_from_row)
            .optional()?)
    }

    fn heartbeat(
        &self,
        worker: &str,
        id: &str,
        now: i64,
        lease_ms: i64,
        progress: Option<&serde_json::Value>,
    ) -> Result<Lease, StoreError> {
        let c = self.conn();
        let mut st = c.prepare_cached(
            "UPDATE jobs SET lease_until=?3 + ?4, progress=COALESCE(?5, progress) \
             WHERE id=?1 AND worker=?2 AND status='running' RETURNING cancel_requested",
        )?;
        let flag: Option<i64> = st
            .query_row(
                params![id, worker, now, lease_ms, progress.map(|p| p.to_string())],
                |r| r.get(0),
            )
            .optional()?;
        Ok(match flag {
            Some(f) => Lease::Held {
                cancel_requested: f != 0,
            },
            None => Lease::Lost,
        })
    }

    fn finish(&self, worker: &str, j: &JobRecord) -> Result<bool, StoreError> {
        let n = self.conn().execute(
            "UPDATE jobs SET status=?3, progress=?4, error=?5, finished_at=?6, expires_at=?7, \
             artifacts=?8, outcome=?9, worker=NULL, lease_until=NULL \
             WHERE id=?1 AND worker=?2 AND status='running'",
            params![
                j.id,
                worker,
                j.status.as_str(),
                j.progress.as_ref().map(|p| p.to_string()),
                j.error
                    .as_ref()
                    .map(serde_json::to_string)
                    .transpose()
                    .map_err(json_err)?,
                j.finished_at,
                j.expires_at,
                serde_json::to_string(&j.artifacts).map_err(json_err)?,
                j.outcome.as_ref().map(|o| o.to_string()),
            ],
        )?;
        Ok(n == 1)
    }

    fn request_cancel(
        &self,
        id: &str,
        now: i64,
        expires_at: i64,
    ) -> Result<CancelOutcome, StoreError> {
        let mut c = self.conn();
        let tx = c.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
        let Some(mut j) = job_by_id(&tx, id)? else {
            return Ok(CancelOutcome::NotFound);
        };
        let out = match j.status {
            Status::Queued => {
                tx.execute(
                    "UPDATE jobs SET status='cancelled', finished_at=?2, expires_at=?3 WHERE id=?1",
                    params![id, now, expires_at],
                )?;
                j.status = Status::Cancelled;
                j.finished_at = Some(now);
                j.expires_at = Some(expires_at);
                CancelOutcome::Cancelled(j)
            }
            Status::Running => {
                tx.execute("UPDATE jobs SET cancel_requested=1 WHERE id=?1", [id])?;
                CancelOutcome::Requested(j)
            }
            _ => CancelOutcome::Ended(j),
        };
        tx.commit()?;
        Ok(out)
    }

    fn requeue_expired(&self, now: i64, expires_at: i64) -> Result<Vec<JobRecord>, StoreError> {
        let c = self.conn();
        let mut st = c.prepare_cached(&format!(
            "UPDATE jobs SET \
               status = CASE WHEN cancel_requested = 1 THEN 'cancelled' ELSE 'queued' END, \
               finished_at = CASE WHEN cancel_requested = 1 THEN ?1 ELSE NULL END, \
               expires_at = CASE WHEN cancel_requested = 1 THEN ?2 ELSE NULL END, \
               worker=NULL, lease_until=NULL, progress=NULL \
             WHERE status='running' AND (lease_until IS NULL OR lease_until < ?1) \
             RETURNING {JOB_COLS}"
        ))?;
        let rows = st.query_map(params![now, expires_at], job_from_row)?;
        Ok(rows.collect::<Result<Vec<_>, _>>()?)
    }

    fn count_with_status(&self, s: Status) -> Result<usize, StoreError> {
        let n: i64 = self.reader().query_row(
            "SELECT COUNT(*) FROM jobs WHERE status = ?1",
            [s.as_str()],
            |r| r.get(0),
        )?;
        Ok(n as usize)
    }
}
