//! The shared store: PostgreSQL for the index and the blobs, so that several replicas serve
//! one database and the database is the one thing to back up.
//!
//! Driver: tokio-postgres with a deadpool pool, on a small runtime of the store's own: the
//! [`Store`] trait is blocking (its callers are worker threads and the HTTP handlers'
//! blocking pool), so every method is one `block_on` of one statement or one transaction.
//! Migrations are numbered, recorded in `flatmesh_migrations` and applied at start-up under
//! an advisory lock (replicas starting together apply each once). Blobs are `bytea` rows
//! (one value is at most 1 GB in PostgreSQL; uploads are far below that, bounded by
//! `--max-upload-bytes`). A queued job is announced by `NOTIFY flatmesh_jobs` in the
//! inserting transaction; one listener per store, on a connection of its own, wakes idle
//! workers at once (they also poll) and keeps the status-poll cache ([`super::job_cache`])
//! true to the database: every change to a job row is announced on
//! `flatmesh_job_changes` by a trigger.

use super::job_cache::{JobCache, Token};
use super::{Blobs, CancelOutcome, Delivery, Inserted, JobFilter, Lease, Store, StoreError};
use crate::service::domain::{JobError, JobRecord, MeshRecord, Status};
use deadpool_postgres::{Manager, ManagerConfig, Pool, RecyclingMethod, Runtime};
use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio_postgres::{NoTls, Row};

fn backend(message: impl std::fmt::Display) -> StoreError {
    StoreError::Backend {
        backend: "postgres",
        message: message.to_string(),
    }
}

impl From<tokio_postgres::Error> for StoreError {
    fn from(e: tokio_postgres::Error) -> StoreError {
        // The server's own message (with its detail) rather than "db error".
        match e.as_db_error() {
            Some(db) if *db.code() == tokio_postgres::error::SqlState::DISK_FULL => {
                StoreError::Full(format!("the database: {}", db.message()))
            }
            Some(db) => backend(format!("{}: {}", db.code().code(), db.message())),
            None => backend(e),
        }
    }
}

impl From<deadpool_postgres::PoolError> for StoreError {
    fn from(e: deadpool_postgres::PoolError) -> StoreError {
        backend(e)
    }
}

/// Numbered migrations, applied in order, each once.
const MIGRATIONS: &[(i32, &str)] = &[
    (
        1,
        "
CREATE TABLE meshes (
  id TEXT PRIMARY KEY,
  created_at BIGINT NOT NULL,
  format TEXT NOT NULL,
  size BIGINT NOT NULL,
  sha256 TEXT NOT NULL,
  summary TEXT NOT NULL
);
CREATE TABLE jobs (
  seq BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
  id TEXT NOT NULL UNIQUE,
  kind TEXT NOT NULL,
  mesh_id TEXT NOT NULL,
  reference_mesh_id TEXT,
  params TEXT NOT NULL,
  callback_url TEXT,
  status TEXT NOT NULL,
  progress TEXT,
  error TEXT,
  created_at BIGINT NOT NULL,
  started_at BIGINT,
  finished_at BIGINT,
  expires_at BIGINT,
  attempts INTEGER NOT NULL DEFAULT 0,
  artifacts TEXT NOT NULL DEFAULT '[]',
  idempotency_key TEXT UNIQUE,
  request_hash TEXT,
  outcome TEXT,
  worker TEXT,
  lease_until BIGINT,
  cancel_requested BOOLEAN NOT NULL DEFAULT FALSE
);
CREATE INDEX jobs_status ON jobs(status, seq);
CREATE INDEX jobs_mesh ON jobs(mesh_id);
CREATE INDEX jobs_ref ON jobs(reference_mesh_id);
CREATE TABLE blobs (
  key TEXT PRIMARY KEY,
  bytes BYTEA NOT NULL
);
",
    ),
    (
        2,
        "
CREATE TABLE deliveries (
  id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
  job_id TEXT NOT NULL,
  event TEXT NOT NULL,
  due_at BIGINT NOT NULL,
  attempts INTEGER NOT NULL DEFAULT 0,
  worker TEXT,
  lease_until BIGINT
);
CREATE INDEX deliveries_due ON deliveries(due_at, id);
",
    ),
    (
        3,
        "
CREATE TABLE settings (
  key TEXT PRIMARY KEY,
  value TEXT NOT NULL
);
",
    ),
    (
        4,
        "
CREATE FUNCTION flatmesh_job_changed() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
  PERFORM pg_notify('flatmesh_job_changes', OLD.id);
  RETURN NULL;
END $$;
-- Only what a status poll shows (not lease renewals), and never a queued job's: those are
-- not cached, so claims and cancels of queued jobs (most of a busy queue's writes) stay
-- silent. Every NOTIFY serialises commits, so each one costs throughput.
CREATE TRIGGER jobs_changed AFTER UPDATE ON jobs
  FOR EACH ROW WHEN (OLD.status <> 'queued' AND
    (OLD.status, OLD.progress, OLD.error, OLD.started_at, OLD.finished_at, OLD.expires_at,
     OLD.attempts, OLD.artifacts, OLD.outcome)
    IS DISTINCT FROM
    (NEW.status, NEW.progress, NEW.error, NEW.started_at, NEW.finished_at, NEW.expires_at,
     NEW.attempts, NEW.artifacts, NEW.outcome))
  EXECUTE FUNCTION flatmesh_job_changed();
CREATE TRIGGER jobs_deleted AFTER DELETE ON jobs
  FOR EACH ROW WHEN (OLD.status <> 'queued') EXECUTE FUNCTION flatmesh_job_changed();
",
    ),
    (
        5,
        "ALTER TABLE jobs ADD COLUMN base_url TEXT;
CREATE INDEX meshes_sha256 ON meshes(sha256);
CREATE INDEX meshes_created ON meshes(created_at, id);",
    ),
    (
        6,
        "ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT '';
ALTER TABLE meshes ADD COLUMN tenant TEXT NOT NULL DEFAULT '';",
    ),
    (7, "ALTER TABLE meshes ADD COLUMN reused_at BIGINT;"),
];

const JOB_COLS: &str = "seq, id, kind, mesh_id, reference_mesh_id, params, callback_url, status, \
    progress, error, created_at, started_at, finished_at, expires_at, attempts, artifacts, \
    idempotency_key, request_hash, outcome, base_url, tenant";

/// The channel a queued job is announced on.
const CHANNEL: &str = "flatmesh_jobs";
/// The channel every change to a job row is announced on (payload: the job id).
const CHANGES: &str = "flatmesh_job_changes";

/// How often the listener checks that its connection still answers (and how long it waits).
const KEEPALIVE: Duration = Duration::from_secs(2);

/// Called when a job is queued (idle workers claim).
type QueueWaker = Arc<dyn Fn() + Send + Sync>;

/// PostgreSQL index and blobs.
pub struct PgStore {
    /// Runs the pool's connections; `None` only while dropping.
    rt: Option<tokio::runtime::Runtime>,
    pool: Pool,
    /// Status polls answered from memory while the listener runs.
    cache: Arc<JobCache>,
    /// Registered by [`Store::watch_queue`].
    wakers: Arc<Mutex<Vec<QueueWaker>>>,
}

impl Drop for PgStore {
    fn drop(&mut self) {
        // A runtime may not be dropped (blocking) on an async thread; let it go quietly.
        if let Some(rt) = self.rt.take() {
            rt.shutdown_background();
        }
    }
}

fn json<T: serde::de::DeserializeOwned>(col: &str, s: &str) -> Result<T, StoreError> {
    serde_json::from_str(s).map_err(|e| StoreError::Corrupt(format!("jobs.{col}: {e}")))
}

fn to_json<T: serde::Serialize>(v: &T) -> Result<String, StoreError> {
    serde_json::to_string(v).map_err(|e| StoreError::Corrupt(e.to_string()))
}

fn job_from_row(r: &Row) -> Result<JobRecord, StoreError> {
    let status: String = r.try_get(7)?;
    let opt_json = |i: usize, col: &str| -> Result<Option<serde_json::Value>, StoreError> {
        let s: Option<String> = r.try_get(i)?;
        s.map(|s| json(col, &s)).transpose()
    };
    let error: Option<String> = r.try_get(9)?;
    let attempts: i32 = r.try_get(14)?;
    Ok(JobRecord {
        seq: r.try_get(0)?,
        id: r.try_get(1)?,
        kind: r.try_get(2)?,
        mesh_id: r.try_get(3)?,
        reference_mesh_id: r.try_get(4)?,
        params: json("params", &r.try_get::<_, String>(5)?)?,
        callback_url: r.try_get(6)?,
        status: Status::parse(&status)
            .ok_or_else(|| StoreError::Corrupt(format!("jobs.status: {status}")))?,
        progress: opt_json(8, "progress")?,
        error: error.map(|e| json::<JobError>("error", &e)).transpose()?,
        created_at: r.try_get(10)?,
        started_at: r.try_get(11)?,
        finished_at: r.try_get(12)?,
        expires_at: r.try_get(13)?,
        attempts: u32::try_from(attempts).unwrap_or(0),
        artifacts: json("artifacts", &r.try_get::<_, String>(15)?)?,
        idempotency_key: r.try_get(16)?,
        request_hash: r.try_get(17)?,
        base_url: r.try_get(19)?,
        tenant: r.try_get(20)?,
        outcome: opt_json(18, "outcome")?,
    })
}

/// Queue the webhook of job `id`, which has just ended, when it has a callback (inside the
/// transaction that ended it).
async fn queue_delivery(
    tx: &deadpool_postgres::Transaction<'_>,
    id: &str,
    due_at: i64,
) -> Result<(), StoreError> {
    tx.execute(
        "INSERT INTO deliveries (job_id, event, due_at) \
         SELECT id, 'job.' || status, $2 FROM jobs WHERE id = $1 AND callback_url IS NOT NULL",
        &[&id, &due_at],
    )
    .await?;
    Ok(())
}

fn jobs_from(rows: &[Row]) -> Result<Vec<JobRecord>, StoreError> {
    rows.iter().map(job_from_row).collect()
}

impl PgStore {
    /// Connect to `url` (`postgres://user:pass@host:port/db`, or key=value form), with at
    /// most `max_connections` in the pool, and apply the migrations.
    pub fn open(url: &str, max_connections: usize) -> Result<PgStore, StoreError> {
        let config: tokio_postgres::Config = url
            .parse()
            .map_err(|e| backend(format!("database URL: {e}")))?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("flatmesh-pg")
            .enable_all()
            .build()
            .map_err(|e| backend(format!("runtime: {e}")))?;
        let manager = Manager::from_config(
            config.clone(),
            NoTls,
            ManagerConfig {
                recycling_method: RecyclingMethod::Fast,
            },
        );
        let pool = Pool::builder(manager)
            .max_size(max_connections.max(1))
            .runtime(Runtime::Tokio1)
            .wait_timeout(Some(Duration::from_secs(10)))
            .create_timeout(Some(Duration::from_secs(10)))
            .build()
            .map_err(|e| backend(format!("pool: {e}")))?;
        let store = PgStore {
            rt: Some(rt),
            pool,
            cache: Arc::default(),
            wakers: Arc::default(),
        };
        store.migrate()?;
        let mut listener = config;
        // Named, so that an operator (or a test) can tell it from the pool's connections.
        listener.application_name("flatmesh-listener");
        store.start_listener(listener);
        Ok(store)
    }

    /// Listen for queued jobs and job changes for as long as the store lives, reconnecting
    /// after a lost connection (meanwhile the cache is off and idle workers poll).
    fn start_listener(&self, config: tokio_postgres::Config) {
        let Some(rt) = &self.rt else {
            return;
        };
        let (cache, wakers) = (self.cache.clone(), self.wakers.clone());
        rt.spawn(async move {
            loop {
                if let Err(e) = listen(&config, &cache, &wakers).await {
                    tracing::warn!(error = %e, "database notifications lost; reconnecting");
                }
                cache.set_live(false);
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        });
    }

    fn run<T>(&self, f: impl Future<Output = Result<T, StoreError>>) -> Result<T, StoreError> {
        match &self.rt {
            Some(rt) => rt.block_on(f),
            None => Err(backend("the store is closing")),
        }
    }

    /// Apply every migration not yet recorded, each in its own transaction, under a
    /// transaction-scoped advisory lock so that replicas starting at once take turns.
    fn migrate(&self) -> Result<(), StoreError> {
        self.run(async {
            let mut c = self.pool.get().await?;
            for (version, sql) in MIGRATIONS {
                let tx = c.transaction().await?;
                // The lock first: even creating the bookkeeping table races otherwise.
                tx.execute("SELECT pg_advisory_xact_lock(7071317)", &[])
                    .await?;
                tx.batch_execute(
                    "CREATE TABLE IF NOT EXISTS flatmesh_migrations (
                       version INTEGER PRIMARY KEY, applied_at BIGINT NOT NULL)",
                )
                .await?;
                let done = tx
                    .query_opt(
                        "SELECT 1 FROM flatmesh_migrations WHERE version = $1",
                        &[version],
                    )
                    .await?
                    .is_some();
                if !done {
                    tx.batch_execute(sql).await?;
                    tx.execute(
                        "INSERT INTO flatmesh_migrations (version, applied_at) VALUES ($1, $2)",
                        &[version, &crate::service::domain::now_ms()],
                    )
                    .await?;
                    tracing::info!(version, "applied a database migration");
                }
                tx.commit().await?;
            }
            Ok(())
        })
    }

    /// Whether status polls are answered from this store's cache now (its listener is
    /// connected), and how many have been (tests and diagnostics).
    pub fn status_cache(&self) -> (bool, u64) {
        self.cache.stats()
    }

    /// The migrations applied, in order (tests and diagnostics).
    pub fn migrations(&self) -> Result<Vec<i32>, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let rows = c
                .query(
                    "SELECT version FROM flatmesh_migrations ORDER BY version",
                    &[],
                )
                .await?;
            Ok(rows.iter().map(|r| r.get(0)).collect())
        })
    }

    async fn select_meshes(
        &self,
        sql_where: &str,
        args: &[&(dyn tokio_postgres::types::ToSql + Sync)],
        tail: &str,
    ) -> Result<Vec<MeshRecord>, StoreError> {
        let c = self.pool.get().await?;
        let st = c
            .prepare_cached(&format!(
                "SELECT id, created_at, format, size, sha256, summary, tenant FROM meshes \
                 WHERE {sql_where} {tail}"
            ))
            .await?;
        c.query(&st, args)
            .await?
            .iter()
            .map(|r| {
                let size: i64 = r.try_get(3)?;
                let summary: String = r.try_get(5)?;
                Ok(MeshRecord {
                    id: r.try_get(0)?,
                    created_at: r.try_get(1)?,
                    format: r.try_get(2)?,
                    size: size as u64,
                    sha256: r.try_get(4)?,
                    tenant: r.try_get(6)?,
                    summary: serde_json::from_str(&summary)
                        .map_err(|e| StoreError::Corrupt(format!("meshes.summary: {e}")))?,
                })
            })
            .collect()
    }

    async fn select(
        &self,
        sql_where: &str,
        args: &[&(dyn tokio_postgres::types::ToSql + Sync)],
        tail: &str,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let c = self.pool.get().await?;
        let st = c
            .prepare_cached(&format!(
                "SELECT {JOB_COLS} FROM jobs WHERE {sql_where} {tail}"
            ))
            .await?;
        jobs_from(&c.query(&st, args).await?)
    }
}

impl Store for PgStore {
    fn ping(&self) -> Result<(), StoreError> {
        self.run(async {
            self.pool.get().await?.simple_query("SELECT 1").await?;
            Ok(())
        })
    }

    fn insert_mesh(&self, m: &MeshRecord) -> Result<(), StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            c.execute(
                "INSERT INTO meshes (id, created_at, format, size, sha256, summary, tenant) \
                 VALUES ($1,$2,$3,$4,$5,$6,$7)",
                &[
                    &m.id,
                    &m.created_at,
                    &m.format,
                    &(m.size as i64),
                    &m.sha256,
                    &m.summary.to_string(),
                    &m.tenant,
                ],
            )
            .await?;
            Ok(())
        })
    }

    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        self.run(async { Ok(self.select_meshes("id = $1", &[&id], "").await?.pop()) })
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            Ok(c.execute("DELETE FROM meshes WHERE id = $1", &[&id])
                .await?
                > 0)
        })
    }

    fn mesh_in_use(&self, id: &str) -> Result<bool, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let r = c
                .query_one(
                    "SELECT EXISTS (SELECT 1 FROM jobs WHERE (mesh_id = $1 OR \
                     reference_mesh_id = $1) AND status IN ('queued','running'))",
                    &[&id],
                )
                .await?;
            Ok(r.try_get(0)?)
        })
    }

    fn list_meshes(
        &self,
        tenant: &str,
        after: Option<(i64, &str)>,
        limit: usize,
    ) -> Result<Vec<MeshRecord>, StoreError> {
        let (at, id) = (after.map(|a| a.0), after.map(|a| a.1));
        let limit = limit as i64;
        self.run(async {
            self.select_meshes(
                "tenant = $4 AND ($1::BIGINT IS NULL OR (created_at, id) < ($1, $2::TEXT))",
                &[&at, &id, &limit, &tenant],
                "ORDER BY created_at DESC, id DESC LIMIT $3",
            )
            .await
        })
    }

    fn find_mesh_by_sha256(
        &self,
        tenant: &str,
        sha256: &str,
        now: i64,
    ) -> Result<Option<MeshRecord>, StoreError> {
        self.run(async {
            let found = self
                .select_meshes(
                    "sha256 = $1 AND tenant = $2",
                    &[&sha256, &tenant],
                    "ORDER BY created_at, id LIMIT 1",
                )
                .await?
                .pop();
            // Deleted since it was read: not found, so the caller stores its own copy.
            Ok(match found {
                Some(m) => {
                    let marked = self
                        .pool
                        .get()
                        .await?
                        .execute(
                            "UPDATE meshes SET reused_at = GREATEST(COALESCE(reused_at, 0), $2) \
                             WHERE id = $1",
                            &[&m.id, &now],
                        )
                        .await?;
                    (marked == 1).then_some(m)
                }
                None => None,
            })
        })
    }

    fn forget_mesh(&self, id: &str) -> Result<bool, StoreError> {
        self.run(async {
            let n = self
                .pool
                .get()
                .await?
                .execute(
                    "DELETE FROM meshes m WHERE id = $1 AND reused_at IS NULL AND NOT EXISTS \
                     (SELECT 1 FROM jobs j WHERE j.mesh_id = m.id OR j.reference_mesh_id = m.id)",
                    &[&id],
                )
                .await?;
            Ok(n > 0)
        })
    }

    fn delete_unused_meshes(&self, before: i64) -> Result<Vec<String>, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let rows = c
                .query(
                    "DELETE FROM meshes m \
                     WHERE GREATEST(created_at, COALESCE(reused_at, 0)) < $1 AND NOT EXISTS \
                     (SELECT 1 FROM jobs j WHERE j.mesh_id = m.id OR j.reference_mesh_id = m.id) \
                     RETURNING id",
                    &[&before],
                )
                .await?;
            rows.iter()
                .map(|r| r.try_get(0).map_err(StoreError::from))
                .collect()
        })
    }

    fn insert_job(&self, j: &JobRecord) -> Result<Inserted, StoreError> {
        let params = to_json(&j.params)?;
        let error = j.error.as_ref().map(to_json).transpose()?;
        let artifacts = to_json(&j.artifacts)?;
        let progress = j.progress.as_ref().map(|p| p.to_string());
        let outcome = j.outcome.as_ref().map(|p| p.to_string());
        let attempts = j.attempts as i32;
        self.run(async {
            let mut c = self.pool.get().await?;
            let tx = c.transaction().await?;
            // ON CONFLICT: two replicas inserting one idempotency key at once both succeed,
            // one with the new job and one with the existing.
            let row = tx
                .query_opt(
                    "INSERT INTO jobs (id, kind, mesh_id, reference_mesh_id, params, \
                     callback_url, status, progress, error, created_at, started_at, \
                     finished_at, expires_at, attempts, artifacts, idempotency_key, \
                     request_hash, outcome, base_url, tenant) \
                     VALUES ($1,$2,$3,$4,$5,$6,$7,$8,$9,$10,$11,$12,$13,$14,$15,$16,$17,$18,$19,\
                     $20) \
                     ON CONFLICT (idempotency_key) DO NOTHING RETURNING seq",
                    &[
                        &j.id,
                        &j.kind,
                        &j.mesh_id,
                        &j.reference_mesh_id,
                        &params,
                        &j.callback_url,
                        &j.status.as_str(),
                        &progress,
                        &error,
                        &j.created_at,
                        &j.started_at,
                        &j.finished_at,
                        &j.expires_at,
                        &attempts,
                        &artifacts,
                        &j.idempotency_key,
                        &j.request_hash,
                        &outcome,
                        &j.base_url,
                        &j.tenant,
                    ],
                )
                .await?;
            let Some(row) = row else {
                let rows = tx
                    .query(
                        &format!("SELECT {JOB_COLS} FROM jobs WHERE idempotency_key = $1"),
                        &[&j.idempotency_key],
                    )
                    .await?;
                let existing = jobs_from(&rows)?
                    .pop()
                    .ok_or_else(|| backend("idempotency key conflict without a job"))?;
                tx.commit().await?;
                return Ok(Inserted::Existing(existing));
            };
            if j.status == Status::Queued {
                tx.execute(&format!("NOTIFY {CHANNEL}"), &[]).await?;
            }
            tx.commit().await?;
            Ok(Inserted::New(JobRecord {
                seq: row.try_get(0)?,
                ..j.clone()
            }))
        })
    }

    fn find_idempotent(&self, key: &str) -> Result<Option<JobRecord>, StoreError> {
        self.run(async {
            Ok(self
                .select("idempotency_key = $1", &[&key], "")
                .await?
                .pop())
        })
    }

    fn get_job(&self, id: &str) -> Result<Option<JobRecord>, StoreError> {
        self.run(async { Ok(self.select("id = $1", &[&id], "").await?.pop()) })
    }

    fn get_job_async(
        &self,
        id: &str,
    ) -> Option<futures_util::future::BoxFuture<'static, Result<Option<JobRecord>, StoreError>>>
    {
        if let Some(j) = self.cache.get(id) {
            return Some(Box::pin(std::future::ready(Ok(Some(j)))));
        }
        // Taken before the query, so that a change committed after its snapshot revokes it.
        let fill = self.cache.begin(id).map(|token| Fill {
            cache: self.cache.clone(),
            id: id.to_string(),
            token: Some(token),
        });
        let (pool, id) = (self.pool.clone(), id.to_string());
        Some(Box::pin(async move {
            let c = pool.get().await?;
            let st = c
                .prepare_cached(&format!("SELECT {JOB_COLS} FROM jobs WHERE id = $1"))
                .await?;
            let found = jobs_from(&c.query(&st, &[&id]).await?)?.pop();
            if let Some(f) = fill {
                f.store(found.as_ref());
            }
            Ok(found)
        }))
    }

    fn update_job(&self, j: &JobRecord) -> Result<(), StoreError> {
        let progress = j.progress.as_ref().map(|p| p.to_string());
        let error = j.error.as_ref().map(to_json).transpose()?;
        let artifacts = to_json(&j.artifacts)?;
        let outcome = j.outcome.as_ref().map(|p| p.to_string());
        let attempts = j.attempts as i32;
        let r = self.run(async {
            let c = self.pool.get().await?;
            c.execute(
                "UPDATE jobs SET status=$2, progress=$3, error=$4, started_at=$5, \
                 finished_at=$6, expires_at=$7, attempts=$8, artifacts=$9, outcome=$10 \
                 WHERE id=$1",
                &[
                    &j.id,
                    &j.status.as_str(),
                    &progress,
                    &error,
                    &j.started_at,
                    &j.finished_at,
                    &j.expires_at,
                    &attempts,
                    &artifacts,
                    &outcome,
                ],
            )
            .await?;
            Ok(())
        });
        self.cache.invalidate(&j.id);
        r
    }

    fn delete_job(&self, id: &str) -> Result<bool, StoreError> {
        let r = self.run(async {
            let c = self.pool.get().await?;
            Ok(c.execute("DELETE FROM jobs WHERE id = $1", &[&id]).await? > 0)
        });
        self.cache.invalidate(id);
        r
    }

    fn list_jobs(&self, f: &JobFilter) -> Result<Vec<JobRecord>, StoreError> {
        let status = f.status.map(|s| s.as_str());
        let limit = f.limit as i64;
        self.run(async {
            self.select(
                "tenant = $5 AND ($1::TEXT IS NULL OR status = $1) \
                 AND ($2::TEXT IS NULL OR kind = $2) AND ($3::BIGINT IS NULL OR seq < $3)",
                &[&status, &f.kind, &f.before_seq, &limit, &f.tenant],
                "ORDER BY seq DESC LIMIT $4",
            )
            .await
        })
    }

    fn jobs_with_status(&self, s: Status) -> Result<Vec<JobRecord>, StoreError> {
        self.run(async {
            self.select("status = $1", &[&s.as_str()], "ORDER BY seq ASC")
                .await
        })
    }

    fn expired_jobs(&self, now: i64) -> Result<Vec<JobRecord>, StoreError> {
        self.run(async {
            self.select(
                "expires_at IS NOT NULL AND expires_at < $1 \
                 AND status IN ('succeeded','failed','cancelled')",
                &[&now],
                "ORDER BY seq ASC",
            )
            .await
        })
    }

    fn claim(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<JobRecord>, StoreError> {
        let r = self.run(async {
            let c = self.pool.get().await?;
            // SKIP LOCKED: replicas claiming at once take different jobs, none waits.
            let st = c
                .prepare_cached(&format!(
                    "UPDATE jobs SET status='running', worker=$1, lease_until=$2::BIGINT + $3::BIGINT, \
                     started_at=$2, attempts=attempts+1, progress=NULL, outcome=NULL, \
                     cancel_requested=FALSE \
                     WHERE seq = (SELECT seq FROM jobs WHERE status='queued' ORDER BY seq \
                                  LIMIT 1 FOR UPDATE SKIP LOCKED) \
                     RETURNING {JOB_COLS}"
                ))
                .await?;
            Ok(jobs_from(&c.query(&st, &[&worker, &now, &lease_ms]).await?)?.pop())
        });
        if let Ok(Some(j)) = &r {
            self.cache.invalidate(&j.id);
        }
        r
    }

    fn heartbeat(
        &self,
        worker: &str,
        id: &str,
        now: i64,
        lease_ms: i64,
        progress: Option<&serde_json::Value>,
    ) -> Result<Lease, StoreError> {
        let progress_given = progress.is_some();
        let progress = progress.map(|p| p.to_string());
        let r = self.run(async {
            let c = self.pool.get().await?;
            let st = c
                .prepare_cached(
                    "UPDATE jobs SET lease_until=$3::BIGINT + $4::BIGINT, progress=COALESCE($5, progress) \
                     WHERE id=$1 AND worker=$2 AND status='running' RETURNING cancel_requested",
                )
                .await?;
            let row = c
                .query_opt(&st, &[&id, &worker, &now, &lease_ms, &progress])
                .await?;
            Ok(match row {
                Some(r) => Lease::Held {
                    cancel_requested: r.try_get(0)?,
                },
                None => Lease::Lost,
            })
        });
        // Only progress is visible (a lease renewal alone changes nothing a poll shows).
        if progress_given {
            self.cache.invalidate(id);
        }
        r
    }

    fn finish(&self, worker: &str, j: &JobRecord) -> Result<bool, StoreError> {
        let progress = j.progress.as_ref().map(|p| p.to_string());
        let error = j.error.as_ref().map(to_json).transpose()?;
        let artifacts = to_json(&j.artifacts)?;
        let outcome = j.outcome.as_ref().map(|p| p.to_string());
        let r = self.run(async {
            let mut c = self.pool.get().await?;
            let tx = c.transaction().await?;
            let n = tx
                .execute(
                    "UPDATE jobs SET status=$3, progress=$4, error=$5, finished_at=$6, \
                     expires_at=$7, artifacts=$8, outcome=$9, worker=NULL, lease_until=NULL \
                     WHERE id=$1 AND worker=$2 AND status='running'",
                    &[
                        &j.id,
                        &worker,
                        &j.status.as_str(),
                        &progress,
                        &error,
                        &j.finished_at,
                        &j.expires_at,
                        &artifacts,
                        &outcome,
                    ],
                )
                .await?;
            if n == 1 {
                queue_delivery(&tx, &j.id, j.finished_at.unwrap_or(0)).await?;
            }
            tx.commit().await?;
            Ok(n == 1)
        });
        self.cache.invalidate(&j.id);
        r
    }

    fn request_cancel(
        &self,
        id: &str,
        now: i64,
        expires_at: i64,
    ) -> Result<CancelOutcome, StoreError> {
        let r = self.run(async {
            let mut c = self.pool.get().await?;
            let tx = c.transaction().await?;
            let rows = tx
                .query(
                    &format!("SELECT {JOB_COLS} FROM jobs WHERE id = $1 FOR UPDATE"),
                    &[&id],
                )
                .await?;
            let Some(mut j) = jobs_from(&rows)?.pop() else {
                return Ok(CancelOutcome::NotFound);
            };
            let out = match j.status {
                Status::Queued => {
                    tx.execute(
                        "UPDATE jobs SET status='cancelled', finished_at=$2, expires_at=$3 \
                         WHERE id=$1",
                        &[&id, &now, &expires_at],
                    )
                    .await?;
                    queue_delivery(&tx, id, now).await?;
                    j.status = Status::Cancelled;
                    j.finished_at = Some(now);
                    j.expires_at = Some(expires_at);
                    CancelOutcome::Cancelled(j)
                }
                Status::Running => {
                    tx.execute("UPDATE jobs SET cancel_requested=TRUE WHERE id=$1", &[&id])
                        .await?;
                    CancelOutcome::Requested(j)
                }
                _ => CancelOutcome::Ended(j),
            };
            tx.commit().await?;
            Ok(out)
        });
        self.cache.invalidate(id);
        r
    }

    fn release(&self, worker: &str, id: &str) -> Result<bool, StoreError> {
        let r = self.run(async {
            let c = self.pool.get().await?;
            let n = c
                .execute(
                    "UPDATE jobs SET status='queued', worker=NULL, lease_until=NULL, \
                     progress=NULL, attempts=GREATEST(attempts - 1, 0) \
                     WHERE id=$1 AND worker=$2 AND status='running' AND NOT cancel_requested",
                    &[&id, &worker],
                )
                .await?;
            Ok(n == 1)
        });
        self.cache.invalidate(id);
        r
    }

    fn requeue_expired(&self, now: i64, expires_at: i64) -> Result<Vec<JobRecord>, StoreError> {
        let r = self.run(async {
            let mut c = self.pool.get().await?;
            let tx = c.transaction().await?;
            let rows = tx
                .query(
                    &format!(
                        "UPDATE jobs SET \
                           status = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'queued' END, \
                           finished_at = CASE WHEN cancel_requested THEN $1::BIGINT ELSE NULL END, \
                           expires_at = CASE WHEN cancel_requested THEN $2::BIGINT ELSE NULL END, \
                           worker=NULL, lease_until=NULL, progress=NULL \
                         WHERE status='running' AND (lease_until IS NULL OR lease_until < $1) \
                         RETURNING {JOB_COLS}"
                    ),
                    &[&now, &expires_at],
                )
                .await?;
            let back = jobs_from(&rows)?;
            for j in back.iter().filter(|j| j.status == Status::Cancelled) {
                queue_delivery(&tx, &j.id, now).await?;
            }
            if back.iter().any(|j| j.status == Status::Queued) {
                tx.execute(&format!("NOTIFY {CHANNEL}"), &[]).await?;
            }
            tx.commit().await?;
            Ok(back)
        });
        for j in r.iter().flatten() {
            self.cache.invalidate(&j.id);
        }
        r
    }

    fn claim_delivery(
        &self,
        worker: &str,
        now: i64,
        lease_ms: i64,
    ) -> Result<Option<Delivery>, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let st = c
                .prepare_cached(
                    "UPDATE deliveries SET worker=$1, lease_until=$2::BIGINT + $3::BIGINT \
                     WHERE id = (SELECT id FROM deliveries WHERE due_at <= $2 \
                                 AND (lease_until IS NULL OR lease_until < $2) \
                                 ORDER BY due_at, id LIMIT 1 FOR UPDATE SKIP LOCKED) \
                     RETURNING id, job_id, event, attempts",
                )
                .await?;
            let Some(r) = c.query_opt(&st, &[&worker, &now, &lease_ms]).await? else {
                return Ok(None);
            };
            let attempts: i32 = r.try_get(3)?;
            Ok(Some(Delivery {
                id: r.try_get(0)?,
                job_id: r.try_get(1)?,
                event: r.try_get(2)?,
                attempts: u32::try_from(attempts).unwrap_or(0),
            }))
        })
    }

    fn end_delivery(&self, id: i64, worker: &str) -> Result<bool, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let n = c
                .execute(
                    "DELETE FROM deliveries WHERE id = $1 AND worker = $2",
                    &[&id, &worker],
                )
                .await?;
            Ok(n == 1)
        })
    }

    fn retry_delivery(&self, id: i64, worker: &str, due_at: i64) -> Result<bool, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let n = c
                .execute(
                    "UPDATE deliveries SET attempts = attempts + 1, due_at = $3, worker = NULL, \
                     lease_until = NULL WHERE id = $1 AND worker = $2",
                    &[&id, &worker, &due_at],
                )
                .await?;
            Ok(n == 1)
        })
    }

    fn count_with_status(&self, s: Status) -> Result<usize, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let st = c
                .prepare_cached("SELECT COUNT(*) FROM jobs WHERE status = $1")
                .await?;
            let n: i64 = c.query_one(&st, &[&s.as_str()]).await?.try_get(0)?;
            Ok(n as usize)
        })
    }

    fn shared_webhook_secret(&self, candidate: &str) -> Result<Option<String>, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            c.execute(
                "INSERT INTO settings (key, value) VALUES ('webhook_secret', $1) \
                 ON CONFLICT (key) DO NOTHING",
                &[&candidate],
            )
            .await?;
            let r = c
                .query_one(
                    "SELECT value FROM settings WHERE key = 'webhook_secret'",
                    &[],
                )
                .await?;
            Ok(Some(r.try_get(0)?))
        })
    }

    fn watch_queue(&self, wake: QueueWaker) -> Result<(), StoreError> {
        self.wakers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(wake);
        Ok(())
    }
}

/// Keeps a status poll's answer for the cache unless a change revoked its token; dropped
/// unused (the poll failed or was abandoned), it frees the slot.
struct Fill {
    cache: Arc<JobCache>,
    id: String,
    /// Taken by [`Fill::store`]; still here when dropped unused.
    token: Option<Token>,
}

impl Fill {
    fn store(mut self, job: Option<&JobRecord>) {
        if let Some(t) = self.token.take() {
            self.cache.fill(&self.id, t, job);
        }
    }
}

impl Drop for Fill {
    fn drop(&mut self) {
        if let Some(t) = self.token.take() {
            self.cache.fill(&self.id, t, None);
        }
    }
}

/// One LISTEN session, until its connection ends: wake the workers for every queued job,
/// drop the cached row of every changed job, and keep the cache live meanwhile.
async fn listen(
    config: &tokio_postgres::Config,
    cache: &Arc<JobCache>,
    wakers: &Arc<Mutex<Vec<QueueWaker>>>,
) -> Result<(), StoreError> {
    let timed = |what: &'static str| move |_| backend(format!("listener: {what} timed out"));
    let (client, mut conn) = tokio::time::timeout(KEEPALIVE, config.connect(NoTls))
        .await
        .map_err(timed("connecting"))??;
    let (cache2, wakers) = (cache.clone(), wakers.clone());
    let mut driver = tokio::spawn(async move {
        let mut messages = futures_util::stream::poll_fn(move |cx| conn.poll_message(cx));
        while let Some(m) = futures_util::StreamExt::next(&mut messages).await {
            match m {
                Ok(tokio_postgres::AsyncMessage::Notification(n)) if n.channel() == CHANGES => {
                    cache2.invalidate(n.payload());
                }
                Ok(tokio_postgres::AsyncMessage::Notification(_)) => {
                    let wakers = wakers.lock().unwrap_or_else(|e| e.into_inner()).clone();
                    for wake in wakers {
                        wake();
                    }
                }
                Ok(_) => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    });
    let result = async {
        tokio::time::timeout(
            KEEPALIVE,
            client.batch_execute(&format!("LISTEN {CHANNEL}; LISTEN {CHANGES}")),
        )
        .await
        .map_err(timed("LISTEN"))??;
        cache.set_live(true);
        // A connection can die without a word (a firewall dropping an idle one), and a
        // pooler in between may drop the LISTEN: check now and then that this session still
        // listens on both channels, and give it up when it does not answer so.
        let mut tick = tokio::time::interval(KEEPALIVE);
        let channels = vec![CHANNEL, CHANGES];
        let params: [&(dyn tokio_postgres::types::ToSql + Sync); 1] = [&channels];
        loop {
            tokio::select! {
                r = &mut driver => {
                    return match r {
                        Ok(r) => Ok(r?),
                        Err(e) => Err(backend(format!("listener: {e}"))),
                    };
                }
                _ = tick.tick() => {
                    let check = client.query_one(
                        "SELECT count(*) FROM pg_listening_channels() c WHERE c = ANY($1)",
                        &params,
                    );
                    match tokio::time::timeout(KEEPALIVE, check).await {
                        Ok(Ok(row)) if row.get::<_, i64>(0) == 2 => {}
                        Ok(Ok(_)) => return Err(backend("listener: no longer listening")),
                        Ok(Err(e)) => return Err(e.into()),
                        Err(_) => return Err(backend("listener: keepalive timed out")),
                    }
                }
            }
        }
    }
    .await;
    cache.set_live(false);
    driver.abort();
    result
}

impl Blobs for PgStore {
    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            c.execute(
                "INSERT INTO blobs (key, bytes) VALUES ($1, $2) \
                 ON CONFLICT (key) DO UPDATE SET bytes = EXCLUDED.bytes",
                &[&key, &bytes],
            )
            .await?;
            Ok(())
        })
    }

    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            let st = c
                .prepare_cached("SELECT bytes FROM blobs WHERE key = $1")
                .await?;
            Ok(match c.query_opt(&st, &[&key]).await? {
                Some(r) => Some(r.try_get(0)?),
                None => None,
            })
        })
    }

    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError> {
        self.run(async {
            let c = self.pool.get().await?;
            // starts_with, not LIKE: keys contain `_`, a LIKE wildcard.
            c.execute(
                "DELETE FROM blobs WHERE key = $1 OR starts_with(key, $1 || '/')",
                &[&prefix],
            )
            .await?;
            Ok(())
        })
    }
}
