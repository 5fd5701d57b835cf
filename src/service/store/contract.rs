//! The coordination contract of [`Store`] as an executable suite: every backend runs
//! [`check`] against a fresh, empty store (the SQLite one in tests/store_contract.rs; the
//! PostgreSQL one will run the same). `open` gives a second handle on the same store, as a
//! second process would have, so that "exactly once" is checked across handles.

use super::{CancelOutcome, Lease, Store};
use crate::service::domain::{JobRecord, Status};
use std::collections::HashSet;
use std::sync::Arc;

const LEASE: i64 = 10_000;

fn queued(id: &str) -> JobRecord {
    JobRecord::queued(id, "report", "m_x", 0)
}

fn status(s: &dyn Store, id: &str) -> Status {
    s.get_job(id).unwrap().expect("job exists").status
}

/// Run the whole contract; panics at the first violation, naming it.
pub fn check(store: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    claims_in_order_and_once(store);
    heartbeats_and_cancels(store);
    expired_leases_requeue(store);
    concurrent_claims_are_exclusive(store, open);
}

fn claims_in_order_and_once(s: &dyn Store) {
    assert!(s.claim("w1", 0, LEASE).unwrap().is_none(), "empty store");
    for id in ["j_a1", "j_a2", "j_a3"] {
        s.insert_job(&queued(id)).unwrap();
    }
    assert_eq!(s.count_with_status(Status::Queued).unwrap(), 3);
    let a = s.claim("w1", 100, LEASE).unwrap().expect("a job");
    assert_eq!(a.id, "j_a1", "oldest first");
    assert_eq!(
        (a.status, a.attempts, a.started_at),
        (Status::Running, 1, Some(100))
    );
    let b = s.claim("w2", 100, LEASE).unwrap().expect("a job");
    assert_eq!(b.id, "j_a2");
    assert_eq!(status(s, "j_a1"), Status::Running);
    assert_eq!(s.count_with_status(Status::Running).unwrap(), 2);
    // finishing: only the holder, only once
    let mut done = a.clone();
    done.status = Status::Succeeded;
    done.finished_at = Some(200);
    done.artifacts = vec!["report.json".into()];
    assert!(!s.finish("w2", &done).unwrap(), "w2 does not hold j_a1");
    assert!(s.finish("w1", &done).unwrap());
    assert!(!s.finish("w1", &done).unwrap(), "a job ends once");
    let got = s.get_job("j_a1").unwrap().unwrap();
    assert_eq!(
        (got.status, got.artifacts),
        (Status::Succeeded, done.artifacts)
    );
    assert_eq!(
        s.heartbeat("w1", "j_a1", 300, LEASE, None).unwrap(),
        Lease::Lost
    );
    let mut b_done = b;
    b_done.status = Status::Succeeded;
    assert!(s.finish("w2", &b_done).unwrap());
    let c = s.claim("w1", 400, LEASE).unwrap().expect("j_a3");
    c_finish(s, "w1", c);
}

fn c_finish(s: &dyn Store, worker: &str, mut j: JobRecord) {
    j.status = Status::Succeeded;
    assert!(s.finish(worker, &j).unwrap());
}

fn heartbeats_and_cancels(s: &dyn Store) {
    for id in ["j_b1", "j_b2"] {
        s.insert_job(&queued(id)).unwrap();
    }
    let b1 = s.claim("w1", 0, LEASE).unwrap().unwrap();
    assert_eq!(b1.id, "j_b1");
    let p = serde_json::json!({"stage": "newton", "iteration": 3});
    assert_eq!(
        s.heartbeat("w1", "j_b1", 10, LEASE, Some(&p)).unwrap(),
        Lease::Held {
            cancel_requested: false
        }
    );
    assert_eq!(
        s.get_job("j_b1").unwrap().unwrap().progress,
        Some(p.clone())
    );
    assert_eq!(
        s.heartbeat("w2", "j_b1", 10, LEASE, None).unwrap(),
        Lease::Lost,
        "not the holder"
    );
    // a heartbeat without progress keeps the last one
    s.heartbeat("w1", "j_b1", 20, LEASE, None).unwrap();
    assert_eq!(s.get_job("j_b1").unwrap().unwrap().progress, Some(p));
    // a queued job is cancelled at once and never claimed
    match s.request_cancel("j_b2", 30, 9_999).unwrap() {
        CancelOutcome::Cancelled(j) => assert_eq!(j.status, Status::Cancelled),
        other => panic!("queued cancel: {other:?}"),
    }
    assert_eq!(status(s, "j_b2"), Status::Cancelled);
    assert!(s.claim("w3", 40, LEASE).unwrap().is_none());
    // a running one is flagged for its worker
    assert!(matches!(
        s.request_cancel("j_b1", 50, 9_999).unwrap(),
        CancelOutcome::Requested(_)
    ));
    assert_eq!(
        s.heartbeat("w1", "j_b1", 60, LEASE, None).unwrap(),
        Lease::Held {
            cancel_requested: true
        }
    );
    let mut end = b1;
    end.status = Status::Cancelled;
    assert!(s.finish("w1", &end).unwrap());
    assert!(matches!(
        s.request_cancel("j_b1", 70, 9_999).unwrap(),
        CancelOutcome::Ended(_)
    ));
    assert_eq!(
        s.request_cancel("j_nope", 70, 9_999).unwrap(),
        CancelOutcome::NotFound
    );
}

fn expired_leases_requeue(s: &dyn Store) {
    for id in ["j_c1", "j_c2"] {
        s.insert_job(&queued(id)).unwrap();
    }
    let c1 = s.claim("w1", 1_000, LEASE).unwrap().unwrap();
    let c2 = s.claim("w2", 1_000, LEASE).unwrap().unwrap();
    assert_eq!((c1.id.as_str(), c2.id.as_str()), ("j_c1", "j_c2"));
    s.request_cancel("j_c2", 1_500, 9_999).unwrap();
    // w1 keeps its lease alive, w2 dies
    s.heartbeat("w1", "j_c1", 1_000 + LEASE - 1, LEASE, None)
        .unwrap();
    assert!(
        s.requeue_expired(1_000 + LEASE - 1, 50_000)
            .unwrap()
            .is_empty(),
        "no lease has run out yet"
    );
    let back = s.requeue_expired(1_000 + LEASE + 1, 50_000).unwrap();
    let ids: Vec<&str> = back.iter().map(|j| j.id.as_str()).collect();
    assert_eq!(ids, ["j_c2"], "only the lease that ran out");
    assert_eq!(
        status(s, "j_c2"),
        Status::Cancelled,
        "a cancel requested before the worker died still ends the job"
    );
    assert_eq!(status(s, "j_c1"), Status::Running);
    // lapse w1 too: the job runs again, once, with its attempts counted
    let back = s.requeue_expired(1_000 + 3 * LEASE, 50_000).unwrap();
    assert_eq!(back.len(), 1);
    assert_eq!(status(s, "j_c1"), Status::Queued);
    assert_eq!(
        s.heartbeat("w1", "j_c1", 0, LEASE, None).unwrap(),
        Lease::Lost
    );
    let mut late = c1;
    late.status = Status::Succeeded;
    assert!(
        !s.finish("w1", &late).unwrap(),
        "a lost lease writes nothing"
    );
    let again = s.claim("w3", 2_000 + 3 * LEASE, LEASE).unwrap().unwrap();
    assert_eq!((again.id.as_str(), again.attempts), ("j_c1", 2));
    c_finish(s, "w3", again);
}

fn concurrent_claims_are_exclusive(s: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    let n = 40;
    for k in 0..n {
        s.insert_job(&queued(&format!("j_d{k:03}"))).unwrap();
    }
    let handles: Vec<Arc<dyn Store>> = (0..4).map(|_| open()).collect();
    let claimed: Vec<Vec<String>> = std::thread::scope(|sc| {
        let ts: Vec<_> = handles
            .iter()
            .enumerate()
            .map(|(w, h)| {
                sc.spawn(move || {
                    let mut mine = Vec::new();
                    while let Some(j) = h.claim(&format!("w{w}"), 0, LEASE).unwrap() {
                        mine.push(j.id);
                    }
                    mine
                })
            })
            .collect();
        ts.into_iter().map(|t| t.join().unwrap()).collect()
    });
    let all: Vec<&String> = claimed.iter().flatten().collect();
    let unique: HashSet<&String> = all.iter().copied().collect();
    assert_eq!(all.len(), n, "every job claimed");
    assert_eq!(unique.len(), n, "no job claimed twice");
}
