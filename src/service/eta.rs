//! How long jobs take, learnt from the jobs this process ran, for `Retry-After`: a client
//! told "1 s" for a job that takes a minute polls sixty times for nothing, and one told
//! "5 s" for a 50 ms report waits a hundred times too long.
//!
//! Per kind, an exponentially weighted mean of the run time per face (jobs scale roughly
//! with the mesh) and of the run time itself (for polls, which know the kind but not the
//! mesh). Before a kind has run here, a prior: a fraction of a second for `report`, a few
//! seconds for the rest.

use std::collections::HashMap;
use std::sync::Mutex;

/// Weight of the newest run in the means.
const ALPHA: f64 = 0.3;

#[derive(Clone, Copy)]
struct Means {
    seconds_per_face: f64,
    seconds: f64,
}

/// Learnt run times.
#[derive(Default)]
pub struct Eta {
    by_kind: Mutex<HashMap<String, Means>>,
}

fn prior(kind: &str) -> Means {
    let seconds = if kind == "report" { 0.2 } else { 5.0 };
    Means {
        seconds,
        // as if the typical job had 20k faces
        seconds_per_face: seconds / 20_000.0,
    }
}

/// `Retry-After` seconds: at least 1, at most `max`, rounded up.
fn clamp(seconds: f64, max: u64) -> u64 {
    if seconds.is_finite() {
        (seconds.ceil().max(1.0) as u64).min(max)
    } else {
        max
    }
}

impl Eta {
    fn means(&self, kind: &str) -> Means {
        self.by_kind
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(kind)
            .copied()
            .unwrap_or_else(|| prior(kind))
    }

    /// A run of `kind` on `faces` faces took `seconds`.
    pub fn record(&self, kind: &str, faces: usize, seconds: f64) {
        if !seconds.is_finite() || seconds < 0.0 {
            return;
        }
        let mut g = self.by_kind.lock().unwrap_or_else(|e| e.into_inner());
        let per_face = seconds / faces.max(1) as f64;
        let m = g.entry(kind.to_string()).or_insert(Means {
            seconds,
            seconds_per_face: per_face,
        });
        m.seconds += ALPHA * (seconds - m.seconds);
        m.seconds_per_face += ALPHA * (per_face - m.seconds_per_face);
    }

    /// Expected run time of a `kind` job on `faces` faces.
    pub fn run_seconds(&self, kind: &str, faces: usize) -> f64 {
        self.means(kind).seconds_per_face * faces as f64
    }

    /// When to look again at a job just submitted: its expected run plus the wait for the
    /// `queued` jobs ahead of it on `workers` workers (1–60 s).
    pub fn after_submit(&self, kind: &str, faces: usize, queued: usize, workers: usize) -> u64 {
        let ahead = queued as f64 * self.mean_any() / workers.max(1) as f64;
        clamp(ahead + self.run_seconds(kind, faces), 60)
    }

    /// When to poll a job of `kind` again: queued, its typical run; running for
    /// `running_for` seconds, what is typically left of it (1–30 s).
    pub fn after_poll(&self, kind: &str, running_for: Option<f64>) -> u64 {
        let typical = self.means(kind).seconds;
        let left = match running_for {
            Some(t) => typical - t,
            None => typical,
        };
        clamp(left, 30)
    }

    /// When a full queue (`queued` jobs on `workers` workers) may have room (1–600 s).
    pub fn after_full(&self, queued: usize, workers: usize) -> u64 {
        clamp(
            self.mean_any() / workers.max(1) as f64 * queued.max(1) as f64 / 4.0,
            600,
        )
    }

    /// The mean run time over the kinds run here (a prior when none has run).
    fn mean_any(&self) -> f64 {
        let g = self.by_kind.lock().unwrap_or_else(|e| e.into_inner());
        if g.is_empty() {
            return prior("").seconds;
        }
        g.values().map(|m| m.seconds).sum::<f64>() / g.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_follow_what_ran_and_stay_in_bounds() {
        let eta = Eta::default();
        // Priors: a report is quick, others take seconds.
        assert_eq!(eta.after_poll("report", None), 1);
        assert_eq!(eta.after_poll("fl-mesh", None), 5);
        // A kind that takes 20 s on 10k faces: a 40k-face job is expected to take ~80 s.
        for _ in 0..30 {
            eta.record("fl-mesh", 10_000, 20.0);
        }
        assert!((eta.run_seconds("fl-mesh", 40_000) - 80.0).abs() < 1.0);
        assert_eq!(
            eta.after_submit("fl-mesh", 40_000, 0, 2),
            60,
            "capped at a minute"
        );
        assert_eq!(eta.after_submit("fl-mesh", 5_000, 0, 2), 10);
        // Queued jobs ahead add their share of the workers' time.
        assert!(eta.after_submit("fl-mesh", 5_000, 4, 2) > 10);
        // Polls: what is left of a typical run, at least a second.
        assert_eq!(eta.after_poll("fl-mesh", Some(15.0)), 5);
        assert_eq!(eta.after_poll("fl-mesh", Some(100.0)), 1);
        assert_eq!(eta.after_poll("fl-mesh", None), 20);
        // A full queue of 64 such jobs on 2 workers drains a quarter in ~160 s.
        let full = eta.after_full(64, 2);
        assert!((100..=600).contains(&full), "{full}");
        // Nonsense is ignored, and nothing is ever 0 or unbounded.
        eta.record("fl-mesh", 10, f64::NAN);
        eta.record("fl-mesh", 10, -1.0);
        assert_eq!(eta.after_poll("fl-mesh", None), 20);
        assert_eq!(clamp(f64::INFINITY, 30), 30);
        assert_eq!(clamp(0.0, 30), 1);
    }
}
