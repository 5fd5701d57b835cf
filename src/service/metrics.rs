//! Prometheus text metrics, hand-rolled with atomics (a handful of series).

use super::domain::Status;
use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};

/// Counters and gauges of the service.
#[derive(Debug, Default)]
pub struct Metrics {
    requests: [AtomicU64; 5],
    submitted: AtomicU64,
    finished: [AtomicU64; 5],
    queued: AtomicU64,
    queue_limit: AtomicU64,
    rejected_full: AtomicU64,
    running: AtomicU64,
    job_micros: AtomicU64,
    uploads: AtomicU64,
    webhooks_ok: AtomicU64,
    webhooks_failed: AtomicU64,
}

fn status_index(s: Status) -> usize {
    match s {
        Status::Queued => 0,
        Status::Running => 1,
        Status::Succeeded => 2,
        Status::Failed => 3,
        Status::Cancelled => 4,
    }
}

impl Metrics {
    /// One HTTP response of class `status / 100`.
    pub fn request(&self, status: u16) {
        let i = (status / 100).clamp(1, 5) as usize - 1;
        self.requests[i].fetch_add(1, Ordering::Relaxed);
    }
    /// A job accepted.
    pub fn submitted(&self) {
        self.submitted.fetch_add(1, Ordering::Relaxed);
    }
    /// A mesh stored.
    pub fn uploaded(&self) {
        self.uploads.fetch_add(1, Ordering::Relaxed);
    }
    /// A job ended.
    pub fn finished(&self, s: Status) {
        self.finished[status_index(s)].fetch_add(1, Ordering::Relaxed);
    }
    /// Queue length now.
    pub fn set_queued(&self, n: usize) {
        self.queued.store(n as u64, Ordering::Relaxed);
    }
    /// The bound of the queue (`--max-queued`).
    pub fn set_queue_limit(&self, n: usize) {
        self.queue_limit.store(n as u64, Ordering::Relaxed);
    }
    /// A submit refused because the queue was full (429).
    pub fn rejected_full(&self) {
        self.rejected_full.fetch_add(1, Ordering::Relaxed);
    }
    /// Jobs on workers now.
    pub fn set_running(&self, n: usize) {
        self.running.store(n as u64, Ordering::Relaxed);
    }
    /// Time one job spent running.
    pub fn job_seconds(&self, s: f64) {
        self.job_micros
            .fetch_add((s * 1e6) as u64, Ordering::Relaxed);
    }
    /// A webhook delivery outcome.
    pub fn webhook(&self, ok: bool) {
        if ok {
            self.webhooks_ok.fetch_add(1, Ordering::Relaxed);
        } else {
            self.webhooks_failed.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The Prometheus text exposition.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        s += "# HELP flatmesh_http_responses_total HTTP responses by status class.\n";
        s += "# TYPE flatmesh_http_responses_total counter\n";
        for (i, c) in self.requests.iter().enumerate() {
            let _ = writeln!(
                s,
                "flatmesh_http_responses_total{{class=\"{}xx\"}} {}",
                i + 1,
                g(c)
            );
        }
        s += "# HELP flatmesh_jobs_submitted_total Jobs accepted.\n# TYPE flatmesh_jobs_submitted_total counter\n";
        let _ = writeln!(s, "flatmesh_jobs_submitted_total {}", g(&self.submitted));
        s += "# HELP flatmesh_jobs_finished_total Jobs ended, by final status.\n# TYPE flatmesh_jobs_finished_total counter\n";
        for st in [Status::Succeeded, Status::Failed, Status::Cancelled] {
            let _ = writeln!(
                s,
                "flatmesh_jobs_finished_total{{status=\"{}\"}} {}",
                st.as_str(),
                g(&self.finished[status_index(st)])
            );
        }
        s += "# HELP flatmesh_jobs_queued Jobs waiting for a worker.\n# TYPE flatmesh_jobs_queued gauge\n";
        let _ = writeln!(s, "flatmesh_jobs_queued {}", g(&self.queued));
        s += "# HELP flatmesh_jobs_queue_limit Most jobs the queue holds (--max-queued); submits beyond it get 429.\n# TYPE flatmesh_jobs_queue_limit gauge\n";
        let _ = writeln!(s, "flatmesh_jobs_queue_limit {}", g(&self.queue_limit));
        s += "# HELP flatmesh_jobs_rejected_total Submits refused with 429 because the queue was full.\n# TYPE flatmesh_jobs_rejected_total counter\n";
        let _ = writeln!(
            s,
            "flatmesh_jobs_rejected_total{{reason=\"queue_full\"}} {}",
            g(&self.rejected_full)
        );
        s += "# HELP flatmesh_jobs_running Jobs on a worker.\n# TYPE flatmesh_jobs_running gauge\n";
        let _ = writeln!(s, "flatmesh_jobs_running {}", g(&self.running));
        s += "# HELP flatmesh_job_run_seconds_total Worker time spent on jobs.\n# TYPE flatmesh_job_run_seconds_total counter\n";
        let _ = writeln!(
            s,
            "flatmesh_job_run_seconds_total {}",
            g(&self.job_micros) as f64 / 1e6
        );
        s += "# HELP flatmesh_meshes_uploaded_total Meshes stored.\n# TYPE flatmesh_meshes_uploaded_total counter\n";
        let _ = writeln!(s, "flatmesh_meshes_uploaded_total {}", g(&self.uploads));
        s += "# HELP flatmesh_webhook_deliveries_total Webhook deliveries by outcome.\n# TYPE flatmesh_webhook_deliveries_total counter\n";
        let _ = writeln!(
            s,
            "flatmesh_webhook_deliveries_total{{outcome=\"ok\"}} {}",
            g(&self.webhooks_ok)
        );
        let _ = writeln!(
            s,
            "flatmesh_webhook_deliveries_total{{outcome=\"failed\"}} {}",
            g(&self.webhooks_failed)
        );
        s
    }
}
