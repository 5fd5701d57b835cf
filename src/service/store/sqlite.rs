//! The embedded store: a SQLite index (`flatmesh.sqlite3`, WAL) in the data directory, blobs
//! as files beside it ([`FileBlobs`]). Every coordination step is one statement or one
//! IMMEDIATE transaction, so several processes may share the directory.

use super::{
    Blobs, CancelOutcome, Delivery, FileBlobs, Inserted, JobFilter, Lease, Store, StoreError,
};
use crate::service::domain::{JobRecord, MeshRecord, Status};
use rusqlite::{params, Connection, OptionalExtension};
use std::path::Path;
use std::sync::Mutex;

impl From<rusqlite::Error> for StoreError {
    fn from(e: rusqlite::Error) -> StoreError {
        if e.sqlite_error_code() == Some(rusqlite::ErrorCode::DiskFull) {
            return StoreError::Full(format!("the index: {e}"));
        }
        StoreError::Backend {
            backend: "sqlite",
            message: e.to_string(),
        }
    }
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
    blobs: FileBlobs,
    /// The write-ahead log, watched by `maintain`.
    wal_path: std::path::PathBuf,
}

const READERS: usize = 4;

/// Size of the write-ahead log beyond which `maintain` empties it.
const WAL_LIMIT: u64 = 64 << 20;

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
  outcome TEXT,
  base_url TEXT
);
CREATE TABLE IF NOT EXISTS deliveries (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  job_id TEXT NOT NULL,
  event TEXT NOT NULL,
  due_at INTEGER NOT NULL,
  attempts INTEGER NOT NULL DEFAULT 0,
  worker TEXT,
  lease_until INTEGER
);
CREATE INDEX IF NOT EXISTS deliveries_due ON deliveries(due_at, id);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs(status, seq);
CREATE INDEX IF NOT EXISTS jobs_mesh ON jobs(mesh_id);
CREATE INDEX IF NOT EXISTS jobs_ref ON jobs(reference_mesh_id);
CREATE INDEX IF NOT EXISTS meshes_sha256 ON meshes(sha256);
CREATE INDEX IF NOT EXISTS meshes_created ON meshes(created_at, id);
";

const JOB_COLS: &str = "seq, id, kind, mesh_id, reference_mesh_id, params, callback_url, status, \
    progress, error, created_at, started_at, finished_at, expires_at, attempts, artifacts, \
    idempotency_key, request_hash, outcome, base_url, tenant";

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
        base_url: r.get(19)?,
        tenant: r.get(20)?,
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
    for (table, name, decl) in [
        ("jobs", "outcome", "outcome TEXT"),
        ("jobs", "base_url", "base_url TEXT"),
        ("jobs", "worker", "worker TEXT"),
        ("jobs", "lease_until", "lease_until INTEGER"),
        (
            "jobs",
            "cancel_requested",
            "cancel_requested INTEGER NOT NULL DEFAULT 0",
        ),
        ("jobs", "tenant", "tenant TEXT NOT NULL DEFAULT ''"),
        ("meshes", "tenant", "tenant TEXT NOT NULL DEFAULT ''"),
        ("meshes", "reused_at", "reused_at INTEGER"),
    ] {
        let has: bool = conn
            .prepare(&format!(
                "SELECT 1 FROM pragma_table_info('{table}') WHERE name = ?1"
            ))?
            .exists([name])?;
        if !has {
            conn.execute_batch(&format!("ALTER TABLE {table} ADD COLUMN {decl}"))?;
        }
    }
    Ok(())
}

impl SqliteStore {
    /// Meshes matching `sql_where` (with `tail`: order, limit), read on a reader.
    fn select_meshes(
        &self,
        sql_where: &str,
        args: &[&dyn rusqlite::ToSql],
        tail: &str,
    ) -> Result<Vec<MeshRecord>, StoreError> {
        let c = self.reader();
        let mut st = c.prepare_cached(&format!(
            "SELECT id, created_at, format, size, sha256, summary, tenant FROM meshes \
             WHERE {sql_where} {tail}"
        ))?;
        let rows = st
            .query_map(args, |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, i64>(3)? as u64,
                    r.get::<_, String>(4)?,
                    r.get::<_, String>(5)?,
                    r.get::<_, String>(6)?,
                ))
            })?
            .collect::<rusqlite::Result<Vec<_>>>()?;
        rows.into_iter()
            .map(|(id, created_at, format, size, sha256, summary, tenant)| {
                Ok(MeshRecord {
                    id,
                    created_at,
                    format,
                    size,
                    sha256,
                    tenant,
                    summary: serde_json::from_str(&summary)
                        .map_err(|e| StoreError::Corrupt(e.to_string()))?,
                })
            })
            .collect()
    }

    /// Open (creating) the store in `dir`.
    pub fn open(dir: &Path) -> Result<SqliteStore, StoreError> {
        std::fs::create_dir_all(dir).map_err(|e| StoreError::Io(dir.display().to_string(), e))?;
        let conn = Connection::open(dir.join("flatmesh.sqlite3"))?;
        // WAL + NORMAL: a committed transaction survives a process crash (not necessarily a
        // power cut, which would need synchronous=FULL at a cost on every status change).
        conn.pragma_update(None, "journal_mode", "WAL")?;
        conn.pragma_update(None, "synchronous", "NORMAL")?;
        conn.busy_timeout(std::time::Duration::from_secs(5))?;
        conn.pragma_update(None, "cache_size", -1024)?;
        conn.execute_batch(SCHEMA)?;
        add_columns(&conn)?;
        // No automatic checkpoint inside a commit (it fsyncs, ~10-40 ms on a busy disk);
        // `maintain` checkpoints from its own connection instead.
        conn.pragma_update(None, "wal_autocheckpoint", 0)?;
        // When the log restarts, it is cut back to this size rather than kept at its largest.
        conn.pragma_update(None, "journal_size_limit", WAL_LIMIT as i64)?;
        let checkpointer = Connection::open(dir.join("flatmesh.sqlite3"))?;
        checkpointer.busy_timeout(std::time::Duration::from_secs(5))?;
        checkpointer.pragma_update(None, "cache_size", -64)?;
        let mut readers = Vec::with_capacity(READERS);
        for _ in 0..READERS {
            let r = Connection::open_with_flags(
                dir.join("flatmesh.sqlite3"),
                rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY
                    | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX,
            )?;
            r.busy_timeout(std::time::Duration::from_secs(5))?;
            r.pragma_update(None, "cache_size", -256)?;
            readers.push(Mutex::new(r));
        }
        let blobs = FileBlobs::new(dir.join("blobs"));
        let swept = blobs.sweep_temporary();
        if swept > 0 {
            tracing::info!(
                swept,
                "deleted blobs left half-written by a process that died"
            );
        }
        Ok(SqliteStore {
            conn: Mutex::new(conn),
            readers,
            checkpointer: Mutex::new(checkpointer),
            next_reader: std::sync::atomic::AtomicUsize::new(0),
            blobs,
            wal_path: dir.join("flatmesh.sqlite3-wal"),
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
    fn hold_readers_for_test(&self) -> Vec<std::sync::MutexGuard<'_, Connection>> {
        self.readers.iter().map(|r| r.lock().unwrap()).collect()
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

/// Queue the webhook of job `id`, which has just ended, when it has a callback.
fn queue_delivery(c: &Connection, id: &str, due_at: i64) -> rusqlite::Result<()> {
    c.prepare_cached(
        "INSERT INTO deliveries (job_id, event, due_at) \
         SELECT id, 'job.' || status, ?2 FROM jobs WHERE id = ?1 AND callback_url IS NOT NULL",
    )?
    .execute(params![id, due_at])?;
    Ok(())
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
            "INSERT INTO meshes (id, created_at, format, size, sha256, summary, tenant) \
             VALUES (?1,?2,?3,?4,?5,?6,?7)",
            params![
                m.id,
                m.created_at,
                m.format,
                m.size as i64,
                m.sha256,
                m.summary.to_string(),
                m.tenant
            ],
        )?;
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        Ok(self
            .select_meshes("id = ?1", &[&id as &dyn rusqlite::ToSql], "")?
            .pop())
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

    fn list_meshes(
        &self,
        tenant: &str,
        after: Option<(i64, &str)>,
        limit: usize,
    ) -> Result<Vec<MeshRecord>, StoreError> {
        let (at, id) = (after.map(|a| a.0), after.map(|a| a.1));
        self.select_meshes(
            "tenant = ?4 AND (?1 IS NULL OR (created_at, id) < (?1, ?2))",
            &[&at, &id, &(limit as i64), &tenant],
            "ORDER BY created_at DESC, id DESC LIMIT ?3",
        )
    }

    fn find_mesh_by_sha256(
        &self,
        tenant: &str,
        sha256: &str,
        now: i64,
    ) -> Result<Option<MeshRecord>, StoreError> {
        let found = self
            .select_meshes(
                "sha256 = ?1 AND tenant = ?2",
                &[&sha256 as &dyn rusqlite::ToSql, &tenant],
                "ORDER BY created_at, id LIMIT 1",
            )?
            .pop();
        // Deleted since it was read (expired, or taken back by the request that stored it):
        // not found, so the caller stores its own copy.
        Ok(match found {
            Some(m) => {
                let marked = self.conn().execute(
                    "UPDATE meshes SET reused_at = MAX(COALESCE(reused_at, 0), ?2) WHERE id = ?1",
                    params![m.id, now],
                )?;
                (marked == 1).then_some(m)
            }
            None => None,
        })
    }

    fn forget_mesh(&self, id: &str) -> Result<bool, StoreError> {
        let n = self.conn().execute(
            "DELETE FROM meshes AS m WHERE id = ?1 AND reused_at IS NULL AND NOT EXISTS \
             (SELECT 1 FROM jobs j WHERE j.mesh_id = m.id OR j.reference_mesh_id = m.id)",
            [id],
        )?;
        Ok(n > 0)
    }

    fn delete_unused_meshes(&self, before: i64) -> Result<Vec<String>, StoreError> {
        let c = self.conn();
        let mut st = c.prepare_cached(
            "DELETE FROM meshes AS m WHERE MAX(created_at, COALESCE(reused_at, 0)) < ?1 \
             AND NOT EXISTS \
             (SELECT 1 FROM jobs j WHERE j.mesh_id = m.id OR j.reference_mesh_id = m.id) \
             RETURNING id",
        )?;
        let ids = st
            .query_map([before], |r| r.get(0))?
            .collect::<rusqlite::Result<Vec<String>>>()?;
        Ok(ids)
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
             idempotency_key, request_hash, outcome, base_url, tenant) \
             VALUES (?1,?2,?3,?4,?5,?6,?7,?8,?9,?10,?11,?12,?13,?14,?15,?16,?17,?18,?19,?20)",
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
                j.base_url,
                j.tenant,
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
            "tenant = ?5 AND (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR kind = ?2) \
             AND (?3 IS NULL OR seq < ?3)",
            &[&status, &f.kind, &f.before_seq, &limit, &f.tenant],
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

    fn maintain(&self) -> Result<(), StoreError> {
        // PASSIVE: copies what it can without blocking readers or the writer. Under reads
        // that never pause it never lets the log restart, and the log grew by gigabytes a
        // minute in the soak test; past WAL_LIMIT a TRUNCATE checkpoint waits (up to the
        // busy timeout) for the readers of old frames and empties it.
        let c = self.checkpointer.lock().unwrap_or_else(|e| e.into_inner());
        let wal = std::fs::metadata(&self.wal_path).map_or(0, |m| m.len());
        let mode = if wal > WAL_LIMIT {
            "TRUNCATE"
        } else {
            "PASSIVE"
        };
        c.query_row(&format!("PRAGMA wal_checkpoint({mode})"), [], |_| Ok(()))?;
        Ok(())
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
        let mut c = self.conn();
        let tx = c.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
        let n = tx.execute(
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
        if n == 1 {
            queue_delivery(&tx, &j.id, j.finished_at.unwrap_or(0))?;
        }
        tx.commit()?;
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
                queue_delivery(&tx, id, now)?;
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
        let mut c = self.conn();
        let tx = c.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
        let back = {
            let mut st = tx.prepare_cached(&format!(
                "UPDATE jobs SET \
                   status = CASE WHEN cancel_requested = 1 THEN 'cancelled' ELSE 'queued' END, \
                   finished_at = CASE WHEN cancel_requested = 1 THEN ?1 ELSE NULL END, \
                   expires_at = CASE WHEN cancel_requested = 1 THEN ?2 ELSE NULL END, \
                   worker=NULL, lease_until=NULL, progress=NULL \
                 WHERE status='running' AND (lease_until IS NULL OR lease_until < ?1) \
                 RETURNING {JOB_COLS}"
            ))?;
            let rows = st.query_map(params![now, expires_at], job_from_row)?;
            rows.collect::<Result<Vec<_>, _>>()?
        };
        for j in back.iter().filter(|j| j.status == Status::Cancelled) {
            queue_delivery(&tx, &j.id, now)?;
        }
        tx.commit()?;
        Ok(back)
    }

    fn release(&self, worker: &str, id: &str) -> Result<bool, StoreError> {
        let c = self.conn();
        let n = c.execute(
            "UPDATE jobs SET status='queued', worker=NULL, lease_until=NULL, progress=NULL, \
             attempts=MAX(attempts - 1, 0) \
             WHERE id=?1 AND worker=?2 AND status='running' AND cancel_requested=0",
            params![id, worker],
        )?;
        Ok(n == 1)
    }

    fn claim_delivery(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<Delivery>, StoreError> {
        let c = self.conn();
        let mut st = c.prepare_cached(
            "UPDATE deliveries SET worker=?1, lease_until=?2 + ?3 \
             WHERE id = (SELECT id FROM deliveries WHERE due_at <= ?2 \
                         AND (lease_until IS NULL OR lease_until < ?2) \
                         ORDER BY due_at, id LIMIT 1) \
             RETURNING id, job_id, event, attempts",
        )?;
        Ok(st
            .query_row(params![worker, now, lease_ms], |r| {
                Ok(Delivery {
                    id: r.get(0)?,
                    job_id: r.get(1)?,
                    event: r.get(2)?,
                    attempts: r.get(3)?,
                })
            })
            .optional()?)
    }

    fn end_delivery(&self, id: i64, worker: &str) -> Result<bool, StoreError> {
        Ok(self.conn().execute(
            "DELETE FROM deliveries WHERE id = ?1 AND worker = ?2",
            params![id, worker],
        )? == 1)
    }

    fn retry_delivery(&self, id: i64, worker: &str, due_at: i64) -> Result<bool, StoreError> {
        Ok(self.conn().execute(
            "UPDATE deliveries SET attempts = attempts + 1, due_at = ?3, worker = NULL, \
             lease_until = NULL WHERE id = ?1 AND worker = ?2",
            params![id, worker, due_at],
        )? == 1)
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

impl Blobs for SqliteStore {
    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError> {
        self.blobs.put_blob(key, bytes)
    }
    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError> {
        self.blobs.get_blob(key)
    }
    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError> {
        self.blobs.delete_blobs(prefix)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A store written before jobs had an outcome opens, keeps its jobs, and records outcomes.
    #[test]
    fn store_without_outcome_column_is_upgraded() {
        let dir = std::env::temp_dir().join(format!("flatmesh-old-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        {
            let store = SqliteStore::open(&dir).unwrap();
            store
                .insert_job(&JobRecord::queued("j_old", "report", "m1", 0))
                .unwrap();
        }
        {
            let c = rusqlite::Connection::open(dir.join("flatmesh.sqlite3")).unwrap();
            c.execute_batch("ALTER TABLE jobs DROP COLUMN outcome")
                .unwrap();
        }
        let store = SqliteStore::open(&dir).unwrap();
        let mut j = store.get_job("j_old").unwrap().unwrap();
        assert_eq!(j.outcome, None);
        j.outcome = Some(serde_json::json!({"converged": true}));
        store.update_job(&j).unwrap();
        assert_eq!(store.get_job("j_old").unwrap().unwrap().outcome, j.outcome);
        drop(store);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The non-blocking read agrees with `get_job`, and declines (None) rather than waits
    /// when every reader is held.
    #[test]
    fn try_get_job_now_matches_get_job_and_never_waits() {
        let dir = std::env::temp_dir().join(format!("flatmesh-trynow-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = SqliteStore::open(&dir).unwrap();
        store
            .insert_job(&JobRecord::queued("j1", "report", "m1", 0))
            .unwrap();
        let mut j = store.get_job("j1").unwrap().unwrap();
        j.status = Status::Running;
        j.progress = Some(serde_json::json!({"stage": "newton", "iteration": 3}));
        store.update_job(&j).unwrap();
        let now = store
            .try_get_job_now("j1")
            .expect("a reader is free")
            .unwrap();
        assert_eq!(now, store.get_job("j1").unwrap());
        assert_eq!(now.unwrap().status, Status::Running);
        assert_eq!(store.try_get_job_now("nope").unwrap().unwrap(), None);
        let held = store.hold_readers_for_test();
        assert!(store.try_get_job_now("j1").is_none());
        drop(held);
        assert!(store.try_get_job_now("j1").is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
