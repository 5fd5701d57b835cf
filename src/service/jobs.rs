//! The executor: jobs run on a dedicated rayon pool (never on the async runtime's threads),
//! behind a bounded queue, with a per-job time limit, cooperative cancellation through the
//! algorithms' [`Control`], and panics caught and turned into a failed job.

use super::metrics::Metrics;
use super::problem::Problem;
use super::store::{JobRecord, Status, Store, StoreError};
use super::webhook::Webhooks;
use crate::algorithms::{AlgoError, Control, Progress};
use crate::io;
use crate::jobs::{artifacts, Input, JobOutcome, JobSpec};
use axum::http::StatusCode;
use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Executor limits.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Worker threads.
    pub workers: usize,
    /// Most jobs waiting for a worker; beyond it submit answers 429.
    pub max_queued: usize,
    /// Wall-clock limit of one run.
    pub time_limit: Duration,
    /// How long results stay after a job ends.
    pub retention: Duration,
    /// Runs started before a job that keeps being interrupted (process killed) fails.
    pub max_attempts: u32,
    /// Nice value of the worker threads (Linux), so that HTTP threads get the CPU first.
    pub nice: i32,
}

/// In-memory state of a queued or running job.
#[derive(Debug, Default)]
pub struct Live {
    /// Set by `POST /cancel`.
    pub cancel: AtomicBool,
    /// Latest progress (JSON object), read by status polls.
    pub progress: Mutex<Option<serde_json::Value>>,
}

/// The function that runs a job ([`JobSpec::run`]; tests substitute their own).
pub type Runner = fn(&JobSpec, &Input, &dyn Control) -> Result<JobOutcome, AlgoError>;

/// Runs jobs.
pub struct Executor {
    pool: rayon::ThreadPool,
    runner: Runner,
    store: Arc<dyn Store>,
    live: Mutex<HashMap<String, Arc<Live>>>,
    /// Serialises status transitions between handlers (cancel) and workers.
    transition: Mutex<()>,
    queued: AtomicUsize,
    running: AtomicUsize,
    /// Limits in force.
    pub limits: Limits,
    metrics: Arc<Metrics>,
    webhooks: Arc<Webhooks>,
}

/// A [`Control`] bound to one job: cancelled by the client or by the time limit.
struct JobControl<'a> {
    live: &'a Live,
    deadline: Instant,
    timed_out: AtomicBool,
}

impl Control for JobControl<'_> {
    fn progress(&self, p: &Progress) {
        let v = serde_json::json!({
            "stage": p.stage,
            "iteration": p.iteration,
            "max_flattenability": p.max_flattenability.filter(|x| x.is_finite()),
            "step_norm": p.step_norm.filter(|x| x.is_finite()),
            "updated_at": super::api::rfc3339(now_ms()),
        });
        *self.live.progress.lock().unwrap_or_else(|e| e.into_inner()) = Some(v);
    }
    fn cancelled(&self) -> bool {
        if self.live.cancel.load(Ordering::Relaxed) {
            return true;
        }
        if Instant::now() >= self.deadline {
            self.timed_out.store(true, Ordering::Relaxed);
            return true;
        }
        false
    }
}

#[cfg(target_os = "linux")]
fn lower_priority(nice: i32) {
    // SAFETY: plain syscalls on the calling thread; failure leaves the priority unchanged.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, nice);
    }
}

#[cfg(not(target_os = "linux"))]
fn lower_priority(_: i32) {}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "panic".to_string()
    }
}

impl Executor {
    /// A pool of `limits.workers` threads.
    pub fn new(
        store: Arc<dyn Store>,
        limits: Limits,
        metrics: Arc<Metrics>,
        webhooks: Arc<Webhooks>,
    ) -> std::io::Result<Arc<Executor>> {
        Executor::with_runner(store, limits, metrics, webhooks, JobSpec::run)
    }

    /// As [`Executor::new`], running jobs with `runner`.
    pub fn with_runner(
        store: Arc<dyn Store>,
        limits: Limits,
        metrics: Arc<Metrics>,
        webhooks: Arc<Webhooks>,
        runner: Runner,
    ) -> std::io::Result<Arc<Executor>> {
        let nice = limits.nice;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(limits.workers.max(1))
            .thread_name(|i| format!("flatmesh-worker-{i}"))
            // Jobs yield the CPU to the HTTP threads, so that status polls stay fast while
            // every worker is busy (Linux: setpriority on a thread id sets that thread only).
            .start_handler(move |_| lower_priority(nice))
            .build()
            .map_err(std::io::Error::other)?;
        Ok(Arc::new(Executor {
            pool,
            runner,
            store,
            live: Mutex::new(HashMap::new()),
            transition: Mutex::new(()),
            queued: AtomicUsize::new(0),
            running: AtomicUsize::new(0),
            limits,
            metrics,
            webhooks,
        }))
    }

    /// Jobs waiting for a worker.
    pub fn queued(&self) -> usize {
        self.queued.load(Ordering::Relaxed)
    }
    /// Jobs on a worker.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::Relaxed)
    }
    /// Whether the queue can take another job.
    pub fn has_room(&self) -> bool {
        self.queued() < self.limits.max_queued
    }

    /// Reserve a queue slot; false when the queue is full. Release with [`Executor::release`]
    /// unless the job is then [`Executor::enqueue`]d.
    pub fn reserve(&self) -> bool {
        self.queued
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |q| {
                (q < self.limits.max_queued).then_some(q + 1)
            })
            .is_ok()
    }
    /// Give back a reserved slot.
    pub fn release(&self) {
        self.queued.fetch_sub(1, Ordering::AcqRel);
    }

    /// Live progress of a queued or running job.
    pub fn live(&self, id: &str) -> Option<Arc<Live>> {
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(id)
            .cloned()
    }

    fn lock_transition(&self) -> std::sync::MutexGuard<'_, ()> {
        self.transition.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Put a stored, queued job on the pool; its slot must be reserved (or, at recovery,
    /// counted by this call).
    pub fn enqueue(self: &Arc<Self>, id: String, reserved: bool) {
        if !reserved {
            self.queued.fetch_add(1, Ordering::AcqRel);
        }
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id.clone(), Arc::new(Live::default()));
        self.metrics.set_queued(self.queued());
        let me = Arc::clone(self);
        self.pool.spawn(move || me.work(id));
    }

    /// After a restart: re-queue jobs that were running (up to `max_attempts` runs) and
    /// queue everything that was waiting, in submission order.
    pub fn recover(self: &Arc<Self>) -> Result<(usize, usize), StoreError> {
        let mut failed = 0;
        for mut j in self.store.jobs_with_status(Status::Running)? {
            if j.attempts >= self.limits.max_attempts {
                j.status = Status::Failed;
                j.finished_at = Some(now_ms());
                j.expires_at = Some(now_ms() + self.limits.retention.as_millis() as i64);
                j.error = Some(Problem::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "interrupted",
                    format!(
                        "the server stopped while the job was running, {} times (limit {})",
                        j.attempts, self.limits.max_attempts
                    ),
                ));
                failed += 1;
            } else {
                j.status = Status::Queued;
                j.progress = None;
                j.outcome = None;
            }
            self.store.update_job(&j)?;
        }
        let queued = self.store.jobs_with_status(Status::Queued)?;
        let n = queued.len();
        for j in queued {
            self.enqueue(j.id, false);
        }
        Ok((n, failed))
    }

    /// Cancel a job: a queued job ends at once, a running one is asked to stop (it ends at
    /// its next iteration). Returns the job as it is now; `Err(job)` when already finished.
    pub fn cancel(&self, id: &str) -> Result<Option<Result<JobRecord, JobRecord>>, StoreError> {
        let _t = self.lock_transition();
        let Some(mut j) = self.store.get_job(id)? else {
            return Ok(None);
        };
        match j.status {
            Status::Queued => {
                if let Some(l) = self.live(id) {
                    l.cancel.store(true, Ordering::Relaxed);
                }
                j.status = Status::Cancelled;
                j.finished_at = Some(now_ms());
                j.expires_at = Some(now_ms() + self.limits.retention.as_millis() as i64);
                self.store.update_job(&j)?;
                self.metrics.finished(Status::Cancelled);
                self.webhooks.notify(&j);
                Ok(Some(Ok(j)))
            }
            Status::Running => {
                if let Some(l) = self.live(id) {
                    l.cancel.store(true, Ordering::Relaxed);
                }
                Ok(Some(Ok(j)))
            }
            _ => Ok(Some(Err(j))),
        }
    }

    /// Worker body: one job.
    fn work(self: Arc<Self>, id: String) {
        self.queued.fetch_sub(1, Ordering::AcqRel);
        self.metrics.set_queued(self.queued());
        let live = self.live(&id).unwrap_or_default();
        let job = {
            let _t = self.lock_transition();
            match self.store.get_job(&id) {
                Ok(Some(mut j)) if j.status == Status::Queued => {
                    j.status = Status::Running;
                    j.started_at = Some(now_ms());
                    j.attempts += 1;
                    if let Err(e) = self.store.update_job(&j) {
                        tracing::error!(job = %id, error = %e, "cannot start job");
                        None
                    } else {
                        Some(j)
                    }
                }
                Ok(_) => None, // cancelled or deleted while queued
                Err(e) => {
                    tracing::error!(job = %id, error = %e, "cannot load job");
                    None
                }
            }
        };
        let Some(mut job) = job else {
            self.live
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .remove(&id);
            return;
        };
        self.running.fetch_add(1, Ordering::AcqRel);
        self.metrics.set_running(self.running());
        let start = Instant::now();
        let control = JobControl {
            live: &live,
            deadline: start + self.limits.time_limit,
            timed_out: AtomicBool::new(false),
        };
        tracing::info!(job = %id, kind = %job.kind, attempt = job.attempts, "job started");
        let result = catch_unwind(AssertUnwindSafe(|| self.execute(&job, &control)));
        let seconds = start.elapsed().as_secs_f64();
        let mut reached = None;
        let (status, error, artifacts) = match result {
            Ok(Ok((artifacts, outcome))) => {
                reached = Some(outcome);
                (Status::Succeeded, None, artifacts)
            }
            Ok(Err(ExecError::Algo(AlgoError::Cancelled))) => {
                if control.timed_out.load(Ordering::Relaxed) {
                    let p = Problem::new(
                        StatusCode::UNPROCESSABLE_ENTITY,
                        "time-limit",
                        format!(
                            "the job exceeded its time limit of {} s",
                            self.limits.time_limit.as_secs_f64()
                        ),
                    );
                    (Status::Failed, Some(p), vec![])
                } else {
                    (Status::Cancelled, None, vec![])
                }
            }
            Ok(Err(ExecError::Algo(e @ AlgoError::InvalidParam { .. }))) => {
                let field = match &e {
                    AlgoError::InvalidParam { key, .. } if !key.is_empty() => {
                        format!("params.{key}")
                    }
                    _ => "params".into(),
                };
                (
                    Status::Failed,
                    Some(Problem::invalid(&field, e.to_string())),
                    vec![],
                )
            }
            Ok(Err(ExecError::Algo(e))) => (
                Status::Failed,
                Some(Problem::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    "algorithm-failed",
                    e.to_string(),
                )),
                vec![],
            ),
            Ok(Err(ExecError::Input(p))) => (Status::Failed, Some(p), vec![]),
            Err(panic) => {
                let msg = panic_message(panic.as_ref());
                tracing::error!(job = %id, panic = %msg, "job panicked");
                (
                    Status::Failed,
                    Some(Problem::internal(format!(
                        "the {} algorithm failed unexpectedly: {msg}",
                        job.kind
                    ))),
                    vec![],
                )
            }
        };
        {
            let _t = self.lock_transition();
            // Deleted while running: drop what it produced.
            match self.store.get_job(&id) {
                Ok(Some(_)) => {
                    job.status = status;
                    job.error = error;
                    job.artifacts = artifacts;
                    job.outcome = reached;
                    job.progress = live
                        .progress
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .clone();
                    job.finished_at = Some(now_ms());
                    job.expires_at = Some(now_ms() + self.limits.retention.as_millis() as i64);
                    if let Err(e) = self.store.update_job(&job) {
                        tracing::error!(job = %id, error = %e, "cannot record job end");
                    }
                }
                _ => {
                    let _ = self.store.delete_blobs(&format!("jobs/{id}"));
                }
            }
            self.live
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .remove(&id);
        }
        self.running.fetch_sub(1, Ordering::AcqRel);
        self.metrics.set_running(self.running());
        self.metrics.finished(status);
        self.metrics.job_seconds(seconds);
        tracing::info!(job = %id, status = status.as_str(), seconds, "job ended");
        self.webhooks.notify(&job);
    }

    /// Load the inputs, run the algorithm, store the artifacts. Returns their names and what
    /// the job reached ([`reached`]).
    fn execute(
        &self,
        job: &JobRecord,
        control: &JobControl<'_>,
    ) -> Result<(Vec<String>, serde_json::Value), ExecError> {
        let spec = JobSpec::parse(&job.kind, &job.params)
            .map_err(|e| ExecError::Input(Problem::invalid("params", e.to_string())))?;
        let (mesh, warnings) = self.load_mesh(&job.mesh_id, "mesh_id")?;
        let reference = match &job.reference_mesh_id {
            Some(r) => Some(self.load_mesh(r, "reference_mesh_id")?.0),
            None => None,
        };
        let input = Input { mesh, reference };
        let start = Instant::now();
        let outcome = (self.runner)(&spec, &input, control).map_err(ExecError::Algo)?;
        let seconds = start.elapsed().as_secs_f64();
        let rendered = artifacts::render(spec.kind(), &input.mesh, &outcome, &warnings, seconds);
        let mut names = Vec::new();
        for a in &rendered.artifacts {
            self.store
                .put_blob(&format!("jobs/{}/{}", job.id, a.name), &a.bytes)
                .map_err(|e| ExecError::Input(e.into()))?;
            names.push(a.name.to_string());
        }
        let reached = serde_json::json!({
            "converged": outcome.figures.converged(),
            "max_flattenability": rendered.max_flattenability,
            "stop_reason": outcome.figures.stop_reason(),
        });
        Ok((names, reached))
    }

    fn load_mesh(
        &self,
        id: &str,
        field: &str,
    ) -> Result<(crate::mesh::Mesh, Vec<crate::mesh::Warning>), ExecError> {
        let rec = self
            .store
            .get_mesh(id)
            .map_err(|e| ExecError::Input(e.into()))?
            .ok_or_else(|| {
                ExecError::Input(Problem::invalid(field, format!("mesh `{id}` was deleted")))
            })?;
        let bytes = self
            .store
            .get_blob(&format!("meshes/{id}"))
            .map_err(|e| ExecError::Input(e.into()))?
            .ok_or_else(|| ExecError::Input(Problem::internal(format!("mesh `{id}` lost"))))?;
        let format = io::Format::from_extension(&rec.format)
            .ok_or_else(|| ExecError::Input(Problem::internal("stored format unknown")))?;
        io::load(&bytes, format)
            .map_err(|e| ExecError::Input(Problem::invalid(field, format!("mesh `{id}`: {e}"))))
    }

    /// Delete expired results (called periodically).
    pub fn sweep(&self) -> Result<usize, StoreError> {
        let expired = self.store.expired_jobs(now_ms())?;
        for j in &expired {
            let _t = self.lock_transition();
            self.store.delete_blobs(&format!("jobs/{}", j.id))?;
            self.store.delete_job(&j.id)?;
        }
        Ok(expired.len())
    }

    /// Delete a job: a running job is cancelled first; its row and artifacts go.
    pub fn delete(&self, id: &str) -> Result<bool, StoreError> {
        let _t = self.lock_transition();
        if let Some(l) = self.live(id) {
            l.cancel.store(true, Ordering::Relaxed);
        }
        let existed = self.store.delete_job(id)?;
        self.store.delete_blobs(&format!("jobs/{id}"))?;
        Ok(existed)
    }
}

enum ExecError {
    Algo(AlgoError),
    Input(Problem),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::store::{SqliteStore, Store};

    /// Runs jobs as the service does, except that every `fl-mesh` job panics.
    fn runner(
        spec: &JobSpec,
        input: &Input,
        control: &dyn Control,
    ) -> Result<JobOutcome, AlgoError> {
        if spec.kind() == crate::jobs::Kind::FlMesh {
            panic!("index out of bounds: the len is 3 but the index is 7");
        }
        spec.run(input, control)
    }

    fn job(id: &str, mesh_id: &str, boom: bool) -> JobRecord {
        JobRecord {
            seq: 0,
            id: id.into(),
            kind: if boom { "fl-mesh" } else { "report" }.into(),
            mesh_id: mesh_id.into(),
            reference_mesh_id: None,
            params: serde_json::Map::new(),
            callback_url: None,
            status: Status::Queued,
            progress: None,
            error: None,
            created_at: now_ms(),
            started_at: None,
            finished_at: None,
            expires_at: None,
            attempts: 0,
            artifacts: vec![],
            idempotency_key: None,
            request_hash: None,
            outcome: None,
        }
    }

    fn wait_end(store: &dyn Store, id: &str) -> JobRecord {
        let t = Instant::now();
        loop {
            let j = store.get_job(id).unwrap().unwrap();
            if j.status.is_terminal() {
                return j;
            }
            assert!(
                t.elapsed() < Duration::from_secs(30),
                "job {id} did not end"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// A store written before jobs had an outcome opens, keeps its jobs, and records outcomes.
    #[test]
    fn store_without_outcome_column_is_upgraded() {
        let dir = std::env::temp_dir().join(format!("flatmesh-old-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        {
            let store = SqliteStore::open(&dir).unwrap();
            store.insert_job(&job("j_old", "m1", false)).unwrap();
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

    /// A panic inside an algorithm fails that job with a 500 problem; the pool keeps working.
    #[test]
    fn panic_fails_the_job_and_the_pool_survives() {
        let dir = std::env::temp_dir().join(format!("flatmesh-exec-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store: Arc<dyn Store> = Arc::new(SqliteStore::open(&dir).unwrap());
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let metrics = Arc::new(Metrics::default());
        let hooks = Arc::new(Webhooks::new(
            vec![1; 32],
            false,
            rt.handle().clone(),
            metrics.clone(),
        ));
        let limits = Limits {
            workers: 1,
            max_queued: 4,
            time_limit: Duration::from_secs(60),
            retention: Duration::from_secs(60),
            max_attempts: 3,
            nice: 10,
        };
        let exec = Executor::with_runner(store.clone(), limits, metrics, hooks, runner).unwrap();
        let obj = std::fs::read("fixtures/flat_disk.obj").unwrap();
        store.put_blob("meshes/m1", &obj).unwrap();
        store
            .insert_mesh(&crate::service::store::MeshRecord {
                id: "m1".into(),
                created_at: 0,
                format: "obj".into(),
                size: obj.len() as u64,
                sha256: String::new(),
                summary: serde_json::json!({}),
            })
            .unwrap();
        for (id, boom) in [("j1", true), ("j2", false)] {
            store.insert_job(&job(id, "m1", boom)).unwrap();
            assert!(exec.reserve());
            exec.enqueue(id.into(), true);
        }
        let j1 = wait_end(store.as_ref(), "j1");
        assert_eq!(j1.status, Status::Failed);
        let e = j1.error.unwrap();
        assert_eq!(e.status, 500);
        assert!(e.detail.contains("index out of bounds"), "{}", e.detail);
        assert!(j1.artifacts.is_empty());
        let j2 = wait_end(store.as_ref(), "j2");
        assert_eq!(j2.status, Status::Succeeded, "{:?}", j2.error);
        assert!(j2.artifacts.iter().any(|a| a == "report.json"));
        assert_eq!(exec.running(), 0);
        assert_eq!(exec.queued(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The non-blocking read agrees with `get_job`, and declines (None) rather than waits
    /// when every reader is held.
    #[test]
    fn try_get_job_now_matches_get_job_and_never_waits() {
        let dir = std::env::temp_dir().join(format!("flatmesh-trynow-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = SqliteStore::open(&dir).unwrap();
        store.insert_job(&job("j1", "m1", false)).unwrap();
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
