//! The executor: jobs are claimed from the store's queue (bounded, shared by every process on
//! the store) under a lease, run on a dedicated rayon pool (never on the async runtime's
//! threads) with a per-job time limit, cooperative cancellation through the algorithms'
//! [`Control`] (cancels requested through any process arrive with the heartbeat), and panics
//! caught and turned into a failed job.

use super::domain::{now_ms, ErrorCode, JobError, JobRecord, Status};
use super::metrics::Metrics;
use super::store::{CancelOutcome, Lease, Store, StoreError};
use super::views::rfc3339;
use crate::algorithms::{AlgoError, Control, Progress};
use crate::io;
use crate::jobs::{artifacts, Input, JobOutcome, JobSpec};
use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

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
    /// How long a claim on a running job lasts without a heartbeat.
    pub lease: Duration,
}

/// In-memory state of a job running in this process.
#[derive(Debug, Default)]
pub struct Live {
    /// Set by a cancel (here, or seen in a heartbeat), a delete or a lost lease; the time limit
    /// is [`JobControl::timed_out`].
    pub cancel: AtomicBool,
    /// Latest progress (JSON object), read by status polls here and written to the store by
    /// the next heartbeat.
    pub progress: Mutex<Option<serde_json::Value>>,
    /// Progress changed since the last heartbeat.
    progress_dirty: AtomicBool,
    /// The claim was lost (lease expired and taken, or the job was deleted): the result is
    /// dropped.
    lost: AtomicBool,
    /// The worker (claim-loop thread) holding the job.
    worker: String,
}

/// The function that runs a job ([`JobSpec::run`]; tests substitute their own).
pub type Runner = fn(&JobSpec, &Input, &dyn Control) -> Result<JobOutcome, AlgoError>;

/// Runs jobs: worker threads claim queued jobs from the store (so that every process on one
/// store shares one queue and a job runs once), run them on a rayon pool, renew their leases
/// from a heartbeat thread (which also carries progress to the store and cancels requested
/// through any process back to the worker), and record the end only while they still hold the
/// job. Jobs whose process died are queued again when their lease runs out.
pub struct Executor {
    pool: rayon::ThreadPool,
    runner: Runner,
    store: Arc<dyn Store>,
    /// This process's worker id prefix (`host-pid-random`).
    worker: String,
    live: Mutex<HashMap<String, Arc<Live>>>,
    /// Wakes idle claim loops: a generation counter and its condition variable.
    wake: (Mutex<u64>, Condvar),
    running: AtomicUsize,
    /// Executor limits.
    pub limits: Limits,
    metrics: Arc<Metrics>,
    /// Run times learnt from this process's jobs (for `Retry-After`).
    pub eta: super::eta::Eta,
    /// Set when a job could not store its results for lack of space: claims wait until
    /// then, and probe the storage ([`Executor::room_for_results`]).
    room: Mutex<RoomWait>,
}

/// How often an idle claim loop looks for work queued by another process.
const POLL: Duration = Duration::from_millis(200);

/// How long claims wait after a job found the storage full: doubled from the first to the
/// last each time another job does before one stores its results, so that a disk with room
/// for a probe but not for the results is not worked against in a loop.
const ROOM_WAIT: (Duration, Duration) = (Duration::from_secs(5), Duration::from_secs(300));

/// The wait of [`Executor::room_for_results`].
#[derive(Debug, Default)]
struct RoomWait {
    /// Claims wait until then (None: they do not wait).
    until: Option<Instant>,
    /// The last wait set.
    wait: Duration,
}

/// A running job's [`Control`]: its cancel flag and its time limit. A step is not started when
/// it would end past the deadline, its duration taken as the larger of what the algorithm
/// expects ([`Control::cancelled_before`]) and the stretch between the last two checks (an
/// iteration predicts the next), so that a job ends at its limit rather than one step past it.
struct JobControl<'a> {
    live: &'a Live,
    start: Instant,
    limit: Duration,
    /// Microseconds after `start` of the last check.
    last_check: AtomicU64,
    /// Set when the time limit stopped the job: microseconds after `start`, plus one.
    timed_out_at: AtomicU64,
}

impl<'a> JobControl<'a> {
    fn new(live: &'a Live, start: Instant, limit: Duration) -> Self {
        Self {
            live,
            start,
            limit,
            last_check: AtomicU64::new(0),
            timed_out_at: AtomicU64::new(0),
        }
    }

    /// When the time limit stopped the job (seconds after its start), if it did.
    fn timed_out(&self) -> Option<f64> {
        match self.timed_out_at.load(Ordering::Relaxed) {
            0 => None,
            t => Some((t - 1) as f64 * 1e-6),
        }
    }
}

impl Control for JobControl<'_> {
    fn progress(&self, p: &Progress) {
        let v = serde_json::json!({
            "stage": p.stage,
            "iteration": p.iteration,
            "max_flattenability": p.max_flattenability.filter(|x| x.is_finite()),
            "step_norm": p.step_norm.filter(|x| x.is_finite()),
            "updated_at": rfc3339(now_ms()),
        });
        *self.live.progress.lock().unwrap_or_else(|e| e.into_inner()) = Some(v);
        self.live.progress_dirty.store(true, Ordering::Relaxed);
    }
    fn cancelled(&self) -> bool {
        self.cancelled_before(0.0)
    }
    fn cancelled_before(&self, seconds: f64) -> bool {
        if self.live.cancel.load(Ordering::Relaxed) {
            return true;
        }
        let now = self.start.elapsed().as_micros().min(u64::MAX as u128 / 2) as u64;
        // The first check has no stretch before it to go by (loading the input is no step).
        let last_stretch = match self.last_check.swap(now, Ordering::Relaxed) {
            0 => 0,
            before => now.saturating_sub(before),
        };
        let next = (seconds.clamp(0.0, 1e9) * 1e6) as u64;
        let limit = self.limit.as_micros().min(u64::MAX as u128 / 4) as u64;
        if now.saturating_add(next.max(last_stretch)) >= limit {
            let _ = self.timed_out_at.compare_exchange(
                0,
                now + 1,
                Ordering::Relaxed,
                Ordering::Relaxed,
            );
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
    /// An executor running jobs with [`JobSpec::run`]; its threads start at once.
    pub fn new(
        store: Arc<dyn Store>,
        limits: Limits,
        metrics: Arc<Metrics>,
    ) -> std::io::Result<Arc<Executor>> {
        Executor::with_runner(store, limits, metrics, JobSpec::run)
    }

    /// As [`Executor::new`], running jobs with `runner`.
    pub fn with_runner(
        store: Arc<dyn Store>,
        limits: Limits,
        metrics: Arc<Metrics>,
        runner: Runner,
    ) -> std::io::Result<Arc<Executor>> {
        let nice = limits.nice;
        let workers = limits.workers.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|i| format!("flatmesh-worker-{i}"))
            // Jobs yield the CPU to the HTTP threads, so that status polls stay fast while
            // every worker is busy (Linux: setpriority on a thread id sets that thread only).
            .start_handler(move |_| lower_priority(nice))
            .build()
            .map_err(std::io::Error::other)?;
        let host = std::fs::read_to_string("/etc/hostname").unwrap_or_default();
        let worker = format!(
            "{}-{}-{}",
            host.trim(),
            std::process::id(),
            &uuid::Uuid::new_v4().simple().to_string()[..8]
        );
        let exec = Arc::new(Executor {
            pool,
            runner,
            store,
            worker,
            live: Mutex::new(HashMap::new()),
            wake: (Mutex::new(0), Condvar::new()),
            running: AtomicUsize::new(0),
            limits,
            metrics,
            eta: Default::default(),
            room: Mutex::new(RoomWait::default()),
        });
        for k in 0..workers {
            let me = Arc::clone(&exec);
            std::thread::Builder::new()
                .name(format!("flatmesh-claim-{k}"))
                .spawn(move || me.claim_loop(k))?;
        }
        let me = Arc::clone(&exec);
        std::thread::Builder::new()
            .name("flatmesh-heartbeat".into())
            .spawn(move || me.heartbeat_loop())?;
        // Jobs queued through other processes wake idle claim loops at once where the store
        // can say so (PostgreSQL); they poll every POLL in any case.
        let weak = Arc::downgrade(&exec);
        if let Err(e) = exec.store.watch_queue(Arc::new(move || {
            if let Some(e) = weak.upgrade() {
                e.wake_workers();
            }
        })) {
            tracing::warn!(error = %e, "no queue notifications; idle workers poll");
        }
        Ok(exec)
    }

    /// This process's worker id prefix (`host-pid-random`).
    pub fn worker_id(&self) -> &str {
        &self.worker
    }

    /// Jobs waiting for a worker, in the store (all processes).
    pub fn queued(&self) -> usize {
        self.store.count_with_status(Status::Queued).unwrap_or(0)
    }
    /// Jobs running in this process.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::Relaxed)
    }
    /// Whether the queue has room for another job.
    pub fn has_room(&self) -> bool {
        self.queued() < self.limits.max_queued
    }
    /// `Retry-After` for a full queue.
    pub fn retry_after_full(&self) -> u64 {
        self.eta
            .after_full(self.limits.max_queued, self.limits.workers)
    }

    /// The in-memory state of a job running in this process.
    pub fn live(&self, id: &str) -> Option<Arc<Live>> {
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(id)
            .cloned()
    }

    /// A job was queued: wake an idle claim loop (other processes find it by polling).
    pub fn enqueued(&self) {
        self.metrics.set_queued(self.queued());
        self.wake_workers();
    }

    fn wake_workers(&self) {
        let (m, cv) = &self.wake;
        *m.lock().unwrap_or_else(|e| e.into_inner()) += 1;
        cv.notify_all();
    }

    /// False while the storage is known to be full: a job that could not store its results
    /// went back to the queue, and claiming it (or any other) again before space returns
    /// would only run it to the same end. After the wait, a small probe write decides.
    fn room_for_results(&self) -> bool {
        let mut room = self.room.lock().unwrap_or_else(|e| e.into_inner());
        match room.until {
            None => true,
            Some(t) if Instant::now() < t => false,
            Some(_) => match super::store::has_room(&*self.store) {
                Ok(true) => {
                    room.until = None;
                    tracing::info!("the storage has room again; claiming jobs");
                    true
                }
                _ => {
                    room.until = Some(Instant::now() + room.wait);
                    false
                }
            },
        }
    }

    /// A job whose results found the storage full goes back to the queue (its partial
    /// results deleted, its attempt uncounted) and this process stops claiming until space
    /// returns. False when it could not be put back (it is then ended as failed).
    fn requeue_for_space(&self, worker: &str, id: &str, live: &Live) -> bool {
        // A job no longer held here (its lease lost) is another worker's, files included.
        if live.cancel.load(Ordering::Relaxed) || live.lost.load(Ordering::Relaxed) {
            return false;
        }
        let _ = self.store.delete_blobs(&format!("jobs/{id}"));
        // Claims here wait from before the release, so no thread of this process takes the
        // job straight back.
        let mut room = self.room.lock().unwrap_or_else(|e| e.into_inner());
        let (until, wait) = (room.until, room.wait);
        room.wait = (room.wait * 2).clamp(ROOM_WAIT.0, ROOM_WAIT.1);
        room.until = Some(Instant::now() + room.wait);
        match self.store.release(worker, id) {
            Ok(true) => {
                tracing::warn!(job = %id, wait = ?room.wait,
                    "storage full: job queued again, claims wait for space");
                true
            }
            Ok(false) => {
                (room.until, room.wait) = (until, wait);
                false
            }
            Err(e) => {
                (room.until, room.wait) = (until, wait);
                tracing::error!(job = %id, error = %e, "cannot queue the job again");
                false
            }
        }
    }

    /// Wait until woken or [`POLL`] has passed, whichever is first.
    fn wait_for_work(&self, seen: u64) -> u64 {
        let (m, cv) = &self.wake;
        let g = m.lock().unwrap_or_else(|e| e.into_inner());
        if *g != seen {
            return *g;
        }
        let (g, _) = cv.wait_timeout(g, POLL).unwrap_or_else(|e| e.into_inner());
        *g
    }

    /// At start-up: jobs whose lease ran out (their process died) are queued again. Returns
    /// how many jobs are queued and how many were cancelled while their process was down.
    pub fn recover(self: &Arc<Self>) -> Result<(usize, usize), StoreError> {
        let cancelled = self.requeue_expired()?;
        Ok((self.queued(), cancelled))
    }

    /// Queue again the running jobs whose lease ran out; returns how many ended cancelled.
    fn requeue_expired(&self) -> Result<usize, StoreError> {
        let now = now_ms();
        let back = self.store.requeue_expired(now, now + self.retention_ms())?;
        let mut cancelled = 0;
        for j in &back {
            if j.status == Status::Cancelled {
                cancelled += 1;
                self.metrics.finished(Status::Cancelled);
            } else {
                tracing::warn!(job = %j.id, attempts = j.attempts, "lease ran out; job queued again");
            }
        }
        if back.len() > cancelled {
            self.wake_workers();
        }
        Ok(cancelled)
    }

    fn retention_ms(&self) -> i64 {
        self.limits.retention.as_millis() as i64
    }

    fn lease_ms(&self) -> i64 {
        self.limits.lease.as_millis().max(1) as i64
    }

    /// Cancel a job: a queued one ends at once; a running one (in any process) stops at its
    /// worker's next heartbeat. None when there is no such job; `Err` with the job when it had
    /// already ended.
    pub fn cancel(&self, id: &str) -> Result<Option<Result<JobRecord, JobRecord>>, StoreError> {
        let now = now_ms();
        Ok(
            match self
                .store
                .request_cancel(id, now, now + self.retention_ms())?
            {
                CancelOutcome::NotFound => None,
                CancelOutcome::Cancelled(j) => {
                    self.metrics.finished(Status::Cancelled);
                    self.metrics.set_queued(self.queued());
                    Some(Ok(j))
                }
                CancelOutcome::Requested(j) => {
                    if let Some(l) = self.live(id) {
                        l.cancel.store(true, Ordering::Relaxed);
                    }
                    Some(Ok(j))
                }
                CancelOutcome::Ended(j) => Some(Err(j)),
            },
        )
    }

    /// One claim loop: take the oldest queued job, run it, repeat; idle, wait for a wake-up.
    fn claim_loop(self: Arc<Self>, k: usize) {
        let worker = format!("{}/{k}", self.worker);
        let mut seen = 0;
        loop {
            if !self.room_for_results() {
                std::thread::sleep(POLL);
                continue;
            }
            match self.store.claim(&worker, now_ms(), self.lease_ms()) {
                Ok(Some(job)) => {
                    self.metrics.set_queued(self.queued());
                    self.run_claimed(&worker, job);
                }
                Ok(None) => seen = self.wait_for_work(seen),
                Err(e) => {
                    tracing::error!(error = %e, "cannot claim a job");
                    seen = self.wait_for_work(seen);
                }
            }
        }
    }

    /// Renew the leases of the jobs running here (with their progress), pass cancels
    /// requested anywhere on to them, and queue again the jobs of processes that died.
    fn heartbeat_loop(self: Arc<Self>) {
        let every = (self.limits.lease / 4).max(Duration::from_millis(20));
        loop {
            std::thread::sleep(every);
            let running: Vec<(String, Arc<Live>)> = self
                .live
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .iter()
                .map(|(id, l)| (id.clone(), Arc::clone(l)))
                .collect();
            for (id, l) in running {
                let progress = if l.progress_dirty.swap(false, Ordering::Relaxed) {
                    l.progress.lock().unwrap_or_else(|e| e.into_inner()).clone()
                } else {
                    None
                };
                match self.store.heartbeat(
                    &l.worker,
                    &id,
                    now_ms(),
                    self.lease_ms(),
                    progress.as_ref(),
                ) {
                    Ok(Lease::Held { cancel_requested }) => {
                        if cancel_requested {
                            l.cancel.store(true, Ordering::Relaxed);
                        }
                    }
                    Ok(Lease::Lost) => {
                        l.lost.store(true, Ordering::Relaxed);
                        l.cancel.store(true, Ordering::Relaxed);
                    }
                    Err(e) => tracing::error!(job = %id, error = %e, "heartbeat failed"),
                }
            }
            if let Err(e) = self.requeue_expired() {
                tracing::error!(error = %e, "cannot requeue expired jobs");
            }
            self.metrics.set_queued(self.queued());
        }
    }

    /// Run a job this worker holds and record how it ended (only while it still holds it).
    fn run_claimed(&self, worker: &str, mut job: JobRecord) {
        let id = job.id.clone();
        if job.attempts > self.limits.max_attempts {
            job.status = Status::Failed;
            job.finished_at = Some(now_ms());
            job.expires_at = Some(now_ms() + self.retention_ms());
            job.error = Some(JobError::new(
                ErrorCode::Interrupted,
                format!(
                    "the job was interrupted {} times (its process stopped while running it; \
                     limit {})",
                    job.attempts - 1,
                    self.limits.max_attempts
                ),
            ));
            if let Ok(true) = self.store.finish(worker, &job) {
                self.metrics.finished(Status::Failed);
            }
            return;
        }
        let live = Arc::new(Live {
            worker: worker.to_string(),
            ..Live::default()
        });
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id.clone(), Arc::clone(&live));
        self.running.fetch_add(1, Ordering::AcqRel);
        self.metrics.set_running(self.running());
        let start = Instant::now();
        let control = JobControl::new(&live, start, self.limits.time_limit);
        tracing::info!(job = %id, kind = %job.kind, attempt = job.attempts, worker, "job started");
        let result = self
            .pool
            .install(|| catch_unwind(AssertUnwindSafe(|| self.execute(&job, &control))));
        let seconds = start.elapsed().as_secs_f64();
        if matches!(result, Ok(Err(ExecError::StorageFull(_))))
            && self.requeue_for_space(worker, &id, &live)
        {
            self.not_running(&id);
            self.metrics.set_queued(self.queued());
            return;
        }
        if matches!(result, Ok(Ok(_))) {
            self.room.lock().unwrap_or_else(|e| e.into_inner()).wait = Duration::ZERO;
        }
        let (status, error, artifacts, reached) = self.ending(&job, &control, result);
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
        job.expires_at = Some(now_ms() + self.retention_ms());
        let recorded = !live.lost.load(Ordering::Relaxed)
            && match self.store.finish(worker, &job) {
                Ok(held) => held,
                Err(e) => {
                    tracing::error!(job = %id, error = %e, "cannot record job end");
                    false
                }
            };
        self.not_running(&id);
        if !recorded {
            // Deleted while running, or its lease ran out and the job is queued again: what
            // it produced is dropped (a deleted job's files go with it).
            if matches!(self.store.get_job(&id), Ok(None)) {
                let _ = self.store.delete_blobs(&format!("jobs/{id}"));
            }
            tracing::warn!(job = %id, "job no longer held by this worker; its result is dropped");
            return;
        }
        self.metrics.finished(status);
        self.metrics.job_seconds(seconds);
        tracing::info!(job = %id, status = status.as_str(), seconds, "job ended");
    }

    /// Job `id` no longer runs here.
    fn not_running(&self, id: &str) {
        self.live
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(id);
        self.running.fetch_sub(1, Ordering::AcqRel);
        self.metrics.set_running(self.running());
    }

    /// Status, error, artifacts and outcome of a run.
    #[allow(clippy::type_complexity)]
    fn ending(
        &self,
        job: &JobRecord,
        control: &JobControl<'_>,
        result: Result<
            Result<(Vec<String>, serde_json::Value), ExecError>,
            Box<dyn std::any::Any + Send>,
        >,
    ) -> (
        Status,
        Option<JobError>,
        Vec<String>,
        Option<serde_json::Value>,
    ) {
        match result {
            // Optional stages that keep what came before when stopped (fl-mesh's detour,
            // restarts, part retries and remeshing) end Ok after a cancel; the client's cancel
            // still wins, and what the run wrote goes. Not after a lost lease: the job (and its
            // files) may be another worker's by now, and this result is dropped anyway.
            Ok(Ok(_))
                if control.live.cancel.load(Ordering::Relaxed)
                    && !control.live.lost.load(Ordering::Relaxed) =>
            {
                if let Err(e) = self.store.delete_blobs(&format!("jobs/{}", job.id)) {
                    tracing::error!(job = %job.id, error = %e, "cannot delete a cancelled job's files");
                }
                (Status::Cancelled, None, vec![], None)
            }
            Ok(Ok((artifacts, outcome))) => (Status::Succeeded, None, artifacts, Some(outcome)),
            Ok(Err(ExecError::Algo(AlgoError::Cancelled))) => {
                if let Some(at) = control.timed_out() {
                    let limit = self.limits.time_limit.as_secs_f64();
                    let detail = if at >= limit {
                        format!("the job exceeded its time limit of {limit} s")
                    } else {
                        format!(
                            "the job was stopped after {at:.2} s: its next step would have \
                             ended past its time limit of {limit} s"
                        )
                    };
                    let p = JobError::new(ErrorCode::TimeLimit, detail);
                    (Status::Failed, Some(p), vec![], None)
                } else {
                    (Status::Cancelled, None, vec![], None)
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
                    Some(JobError::invalid(&field, e.to_string())),
                    vec![],
                    None,
                )
            }
            Ok(Err(ExecError::Algo(e))) => (
                Status::Failed,
                Some(JobError::new(ErrorCode::AlgorithmFailed, e.to_string())),
                vec![],
                None,
            ),
            Ok(Err(ExecError::Input(p))) => (Status::Failed, Some(p), vec![], None),
            Ok(Err(ExecError::StorageFull(e))) => (
                Status::Failed,
                Some(JobError::new(
                    ErrorCode::Internal,
                    format!("{e}; the job could not be queued again: submit it again"),
                )),
                vec![],
                None,
            ),
            Err(panic) => {
                let msg = panic_message(panic.as_ref());
                tracing::error!(job = %job.id, panic = %msg, "job panicked");
                (
                    Status::Failed,
                    Some(JobError::new(
                        ErrorCode::Internal,
                        format!("the {} algorithm failed unexpectedly: {msg}", job.kind),
                    )),
                    vec![],
                    None,
                )
            }
        }
    }

    /// Load the inputs, run the algorithm, store the artifacts. Returns their names and what
    /// the job reached ([`reached`]).
    fn execute(
        &self,
        job: &JobRecord,
        control: &JobControl<'_>,
    ) -> Result<(Vec<String>, serde_json::Value), ExecError> {
        let spec = JobSpec::parse(&job.kind, &job.params)
            .map_err(|e| ExecError::Input(JobError::invalid("params", e.to_string())))?;
        let (mesh, warnings) = self.load_mesh(&job.mesh_id, "mesh_id")?;
        let reference = match &job.reference_mesh_id {
            Some(r) => Some(self.load_mesh(r, "reference_mesh_id")?.0),
            None => None,
        };
        let input = Input { mesh, reference };
        let start = Instant::now();
        let outcome = (self.runner)(&spec, &input, control).map_err(ExecError::Algo)?;
        let seconds = start.elapsed().as_secs_f64();
        self.eta
            .record(&job.kind, input.mesh.triangles().len(), seconds);
        let rendered = artifacts::render(spec.kind(), &input.mesh, &outcome, &warnings, seconds);
        let mut names = Vec::new();
        for a in &rendered.artifacts {
            self.store
                .put_blob(&format!("jobs/{}/{}", job.id, a.name), &a.bytes)
                .map_err(ExecError::storage)?;
            names.push(a.name.to_string());
        }
        let reached = serde_json::json!({
            "converged": outcome.figures.converged(),
            "max_flattenability": rendered.max_flattenability,
            "stop_reason": outcome.figures.stop_reason(),
            "warnings": job_warnings(&spec, &outcome, &warnings, rendered.max_flattenability),
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
            .map_err(ExecError::storage)?
            .ok_or_else(|| {
                ExecError::Input(JobError::invalid(field, format!("mesh `{id}` was deleted")))
            })?;
        let bytes = self
            .store
            .get_blob(&format!("meshes/{id}"))
            .map_err(ExecError::storage)?
            .ok_or_else(|| ExecError::internal(format!("mesh `{id}` lost")))?;
        let format = io::Format::from_extension(&rec.format)
            .ok_or_else(|| ExecError::internal("stored format unknown".into()))?;
        io::load(&bytes, format)
            .map_err(|e| ExecError::Input(JobError::invalid(field, format!("mesh `{id}`: {e}"))))
    }

    /// Delete expired results, then uploads that no job uses and that are older than the
    /// retention period (called periodically). How many of each went.
    pub fn sweep(&self) -> Result<(usize, usize), StoreError> {
        let expired = self.store.expired_jobs(now_ms())?;
        for j in &expired {
            self.store.delete_blobs(&format!("jobs/{}", j.id))?;
            self.store.delete_job(&j.id)?;
        }
        let meshes = self
            .store
            .delete_unused_meshes(now_ms() - self.retention_ms())?;
        for id in &meshes {
            self.store.delete_blobs(&format!("meshes/{id}"))?;
        }
        Ok((expired.len(), meshes.len()))
    }

    /// Delete a job: a running job is cancelled first; its row and artifacts go.
    pub fn delete(&self, id: &str) -> Result<bool, StoreError> {
        if let Some(l) = self.live(id) {
            l.cancel.store(true, Ordering::Relaxed);
        }
        let store = self.store.as_ref();
        super::store::delete_with_blobs(store, &format!("jobs/{id}"), || store.delete_job(id))
    }
}

enum ExecError {
    Algo(AlgoError),
    Input(JobError),
    /// The storage was full: the job can run again once there is space.
    StorageFull(String),
}

impl ExecError {
    fn internal(detail: String) -> ExecError {
        ExecError::Input(JobError::new(ErrorCode::Internal, detail))
    }
    fn storage(e: StoreError) -> ExecError {
        tracing::error!(error = %e, "store error while running a job");
        match e {
            StoreError::Full(_) => ExecError::StorageFull(e.to_string()),
            e => ExecError::internal(format!("storage error: {e}")),
        }
    }
}

/// What a client should know about a succeeded job before using its results (shown at the
/// top level of the job as `warnings`): an optimiser that stopped short of its tolerance
/// (its result is its best iterate), patterns that could not be made or have defects, and
/// the input mesh's own warnings.
fn job_warnings(
    spec: &JobSpec,
    outcome: &crate::jobs::JobOutcome,
    input: &[crate::mesh::Warning],
    max_flattenability: f64,
) -> serde_json::Value {
    let mut out = Vec::new();
    if outcome.figures.converged() == Some(false) {
        out.push(serde_json::json!({
            "code": "not_converged",
            "message": format!(
                "{} stopped before reaching its tolerance ({}); the results are its best \
                 iterate, ϖ_max {max_flattenability:.3e} rad",
                spec.kind().name(),
                outcome.figures.stop_reason().unwrap_or("no reason given"),
            ),
        }));
    }
    if let Some(why) = &outcome.patterns_unavailable {
        out.push(serde_json::json!({"code": "patterns_unavailable", "message": why}));
    }
    for w in outcome.shape.iter().flat_map(|s| &s.warnings) {
        out.push(serde_json::json!({"code": "shape", "message": w}));
    }
    for w in outcome
        .figures
        .pattern_warnings()
        .iter()
        .chain(&outcome.pattern_warnings)
    {
        out.push(serde_json::json!({"code": "pattern", "message": w}));
    }
    for w in input {
        out.push(serde_json::json!({"code": w.code, "message": w.message}));
    }
    serde_json::Value::Array(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::domain::MeshRecord;
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

    /// Whether [`ignores_cancel`] waits for a stop before it runs the job.
    static WAIT_FOR_STOP: AtomicBool = AtomicBool::new(true);

    /// Runs a job the way fl-mesh's optional stages end when stopped: it waits for the stop,
    /// then does its work anyway and returns it.
    fn ignores_cancel(
        spec: &JobSpec,
        input: &Input,
        control: &dyn Control,
    ) -> Result<JobOutcome, AlgoError> {
        let t = Instant::now();
        while WAIT_FOR_STOP.load(Ordering::Relaxed)
            && !control.cancelled()
            && t.elapsed() < Duration::from_secs(30)
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        spec.run(input, &crate::algorithms::Silent::default())
    }

    fn job(id: &str, mesh_id: &str, boom: bool) -> JobRecord {
        let kind = if boom { "fl-mesh" } else { "report" };
        JobRecord::queued(id, kind, mesh_id, now_ms())
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

    /// A store in a fresh directory with `fixtures/flat_disk.obj` uploaded as mesh `m1`.
    fn store_with_disk(name: &str) -> (Arc<dyn Store>, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("flatmesh-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store: Arc<dyn Store> = Arc::new(SqliteStore::open(&dir).unwrap());
        let obj = std::fs::read("fixtures/flat_disk.obj").unwrap();
        store.put_blob("meshes/m1", &obj).unwrap();
        store
            .insert_mesh(&MeshRecord {
                id: "m1".into(),
                created_at: 0,
                format: "obj".into(),
                size: obj.len() as u64,
                sha256: String::new(),
                summary: serde_json::json!({}),
                tenant: String::new(),
            })
            .unwrap();
        (store, dir)
    }

    fn limits() -> Limits {
        Limits {
            workers: 1,
            max_queued: 4,
            time_limit: Duration::from_secs(60),
            retention: Duration::from_secs(60),
            max_attempts: 3,
            nice: 10,
            lease: Duration::from_secs(5),
        }
    }

    /// A client's cancel ends a running job `cancelled`, with no results, even when its run
    /// returns a result after the stop (as fl-mesh's optional stages do).
    #[test]
    fn a_cancel_wins_over_a_run_that_returns_a_result() {
        let (store, dir) = store_with_disk("exec-cancel");
        let metrics = Arc::new(Metrics::default());
        let exec = Executor::with_runner(store.clone(), limits(), metrics, ignores_cancel).unwrap();
        store.insert_job(&job("j1", "m1", false)).unwrap();
        exec.enqueued();
        let t = Instant::now();
        while store.get_job("j1").unwrap().unwrap().status != Status::Running {
            assert!(t.elapsed() < Duration::from_secs(30), "j1 never ran");
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(matches!(exec.cancel("j1"), Ok(Some(Ok(_)))));
        let j1 = wait_end(store.as_ref(), "j1");
        assert_eq!(j1.status, Status::Cancelled, "{:?}", j1.error);
        assert!(j1.artifacts.is_empty(), "{:?}", j1.artifacts);
        assert!(j1.outcome.is_none());
        assert_eq!(store.get_blob("jobs/j1/report.json").unwrap(), None);
        // Without a cancel the same runner's job succeeds with its files.
        WAIT_FOR_STOP.store(false, Ordering::Relaxed);
        store.insert_job(&job("j2", "m1", false)).unwrap();
        exec.enqueued();
        let j2 = wait_end(store.as_ref(), "j2");
        assert_eq!(j2.status, Status::Succeeded, "{:?}", j2.error);
        assert!(j2.artifacts.iter().any(|a| a == "report.json"));
        assert!(store.get_blob("jobs/j2/report.json").unwrap().is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A panic inside an algorithm fails that job with a 500 problem; the pool keeps working.
    #[test]
    fn panic_fails_the_job_and_the_pool_survives() {
        let (store, dir) = store_with_disk("exec");
        let metrics = Arc::new(Metrics::default());
        let exec = Executor::with_runner(store.clone(), limits(), metrics, runner).unwrap();
        for (id, boom) in [("j1", true), ("j2", false)] {
            store.insert_job(&job(id, "m1", boom)).unwrap();
            assert!(exec.has_room());
            exec.enqueued();
        }
        let j1 = wait_end(store.as_ref(), "j1");
        assert_eq!(j1.status, Status::Failed);
        let e = j1.error.unwrap();
        assert_eq!(e.code, ErrorCode::Internal);
        assert!(e.detail.contains("index out of bounds"), "{}", e.detail);
        assert!(j1.artifacts.is_empty());
        let j2 = wait_end(store.as_ref(), "j2");
        assert_eq!(j2.status, Status::Succeeded, "{:?}", j2.error);
        assert!(j2.artifacts.iter().any(|a| a == "report.json"));
        assert_eq!(exec.running(), 0);
        assert_eq!(exec.queued(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
