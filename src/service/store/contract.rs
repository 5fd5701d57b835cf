//! The behaviour of [`Store`] as an executable suite: every backend runs [`check`] against a
//! fresh, empty store (tests/api/store_contract.rs: SQLite and PostgreSQL). It covers the index
//! and blob operations the service uses, then the coordination contract. `open` gives a
//! second handle on the same store, as a second process would have, so that "exactly once"
//! is checked across handles.

use super::{CancelOutcome, Delivery, Inserted, JobFilter, Lease, Store};
use crate::service::domain::{JobRecord, MeshRecord, Status};
use std::collections::HashSet;
use std::sync::Arc;

const LEASE: i64 = 10_000;

fn queued(id: &str) -> JobRecord {
    JobRecord::queued(id, "report", "m_x", 0)
}

/// A job's status, read both ways the service reads it: `get_job` and the status-poll
/// path (which a backend may answer from a cache); the two must agree on this handle.
fn status(s: &dyn Store, id: &str) -> Status {
    let j = s.get_job(id).unwrap().expect("job exists");
    assert_eq!(
        poll(s, id),
        Some(j.clone()),
        "a status poll reads this handle's writes"
    );
    j.status
}

/// The job as a status poll reads it ([`Store::get_job_async`], else
/// [`Store::try_get_job_now`], else `get_job`).
fn poll(s: &dyn Store, id: &str) -> Option<JobRecord> {
    // One runtime for the whole suite: connections a pool opens here are driven by it.
    static RT: std::sync::OnceLock<tokio::runtime::Runtime> = std::sync::OnceLock::new();
    if let Some(f) = s.get_job_async(id) {
        let rt = RT.get_or_init(|| {
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .enable_all()
                .build()
                .expect("a runtime")
        });
        return rt.block_on(f).unwrap();
    }
    match s.try_get_job_now(id) {
        Some(r) => r.unwrap(),
        None => s.get_job(id).unwrap(),
    }
}

/// Status polls on one handle follow changes made through another within `within`
/// (a backend that caches polls learns of them by notification), and again right after
/// changes of its own.
fn status_polls_follow_other_handles(s: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    let other = open();
    let follows = |id: &str, want: Option<Status>| {
        let t = std::time::Instant::now();
        loop {
            let got = poll(s, id).map(|j| j.status);
            if got == want {
                return;
            }
            assert!(
                t.elapsed() < std::time::Duration::from_secs(5),
                "a poll here still shows {got:?} for {id}, changed elsewhere to {want:?}"
            );
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    };
    other.insert_job(&queued("j_p1")).unwrap();
    assert_eq!(poll(s, "j_p1").unwrap().status, Status::Queued);
    let j = other.claim("w_other", 0, LEASE).unwrap().unwrap();
    assert_eq!(j.id, "j_p1");
    follows("j_p1", Some(Status::Running));
    // polled again: a cache would now hold it
    assert_eq!(poll(s, "j_p1").unwrap().status, Status::Running);
    // a lease renewal alone changes nothing a poll shows
    let beat = other.heartbeat("w_other", "j_p1", 1, LEASE, None);
    assert!(matches!(beat.unwrap(), Lease::Held { .. }));
    assert_eq!(poll(s, "j_p1"), other.get_job("j_p1").unwrap());
    let beat = other.heartbeat(
        "w_other",
        "j_p1",
        1,
        LEASE,
        Some(&serde_json::json!({"iteration": 7})),
    );
    assert!(matches!(beat.unwrap(), Lease::Held { .. }));
    let t = std::time::Instant::now();
    while poll(s, "j_p1").unwrap().progress != Some(serde_json::json!({"iteration": 7})) {
        assert!(
            t.elapsed() < std::time::Duration::from_secs(5),
            "progress did not follow"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    // a cancel requested here is no visible change; its end, finished elsewhere, is
    s.request_cancel("j_p1", 2, 100).unwrap();
    let mut done = other.get_job("j_p1").unwrap().unwrap();
    done.status = Status::Cancelled;
    done.finished_at = Some(3);
    assert!(other.finish("w_other", &done).unwrap());
    follows("j_p1", Some(Status::Cancelled));
    // deleted elsewhere: gone here too
    assert!(other.delete_job("j_p1").unwrap());
    follows("j_p1", None);
    // and changes made here show at once, whatever was polled before
    s.insert_job(&queued("j_p2")).unwrap();
    assert_eq!(poll(s, "j_p2").unwrap().status, Status::Queued);
    let mut u = s.get_job("j_p2").unwrap().unwrap();
    u.status = Status::Failed;
    s.update_job(&u).unwrap();
    assert_eq!(poll(s, "j_p2").unwrap().status, Status::Failed);
    assert!(s.delete_job("j_p2").unwrap());
    assert_eq!(poll(s, "j_p2"), None);
}

/// Run the whole contract; panics at the first violation, naming it.
pub fn check(store: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    store.ping().unwrap();
    meshes_and_blobs(store);
    jobs_index(store, open);
    claims_in_order_and_once(store);
    heartbeats_and_cancels(store);
    expired_leases_requeue(store);
    released_jobs_run_again(store);
    concurrent_claims_are_exclusive(store, open);
    status_polls_follow_other_handles(store, open);
    webhook_outbox(store, open);
}

fn meshes_and_blobs(s: &dyn Store) {
    let m = MeshRecord {
        id: "m_1".into(),
        created_at: 5,
        format: "obj".into(),
        size: 1 << 40,
        sha256: "ab".repeat(32),
        summary: serde_json::json!({"vertices": 3, "name": "ünïcode ✓"}),
        tenant: "acme".into(),
    };
    assert!(s.get_mesh("m_1").unwrap().is_none());
    s.insert_mesh(&m).unwrap();
    assert!(s.insert_mesh(&m).is_err(), "a mesh id is unique");
    assert_eq!(s.get_mesh("m_1").unwrap().as_ref(), Some(&m));
    // blobs: binary, overwritten atomically, deleted by exact key or by `prefix/`
    let bytes: Vec<u8> = (0..=255u8).cycle().take(70_000).collect();
    s.put_blob("meshes/m_1", &bytes).unwrap();
    assert_eq!(s.get_blob("meshes/m_1").unwrap(), Some(bytes));
    s.put_blob("meshes/m_1", b"v2").unwrap();
    assert_eq!(s.get_blob("meshes/m_1").unwrap(), Some(b"v2".to_vec()));
    for k in ["jobs/j_1/a.json", "jobs/j_1/b.glb", "jobs/j_10/a.json"] {
        s.put_blob(k, k.as_bytes()).unwrap();
    }
    s.delete_blobs("jobs/j_1").unwrap();
    assert_eq!(s.get_blob("jobs/j_1/a.json").unwrap(), None);
    assert_eq!(s.get_blob("jobs/j_1/b.glb").unwrap(), None);
    assert_eq!(
        s.get_blob("jobs/j_10/a.json").unwrap().as_deref(),
        Some(&b"jobs/j_10/a.json"[..]),
        "a prefix is a path: jobs/j_1 is not jobs/j_10"
    );
    s.delete_blobs("jobs/j_nothing").unwrap();
    s.delete_blobs("jobs/j_10").unwrap();
    s.delete_blobs("meshes/m_1").unwrap();
    assert_eq!(s.get_blob("meshes/m_1").unwrap(), None);
    // in use while a queued or running job names it (as mesh or reference)
    assert!(!s.mesh_in_use("m_1").unwrap());
    let mut j = JobRecord::queued("j_m1", "report", "m_other", 1);
    j.reference_mesh_id = Some("m_1".into());
    s.insert_job(&j).unwrap();
    assert!(s.mesh_in_use("m_1").unwrap());
    let mut done = j;
    done.status = Status::Failed;
    s.update_job(&done).unwrap();
    assert!(!s.mesh_in_use("m_1").unwrap());
    assert!(s.delete_job("j_m1").unwrap());
    assert!(s.delete_mesh("m_1").unwrap());
    assert!(!s.delete_mesh("m_1").unwrap());
    meshes_index(s);
}

/// Listing (newest first, paged by position, one tenant's), lookup by content (within a
/// tenant), and unused uploads.
fn meshes_index(s: &dyn Store) {
    let mesh = |id: &str, created_at: i64, sha: &str| MeshRecord {
        id: id.into(),
        created_at,
        format: "obj".into(),
        size: 3,
        sha256: sha.repeat(64),
        summary: serde_json::json!({"faces": 1}),
        tenant: String::new(),
    };
    // Another tenant's upload of the same bytes, listed and found only for that tenant.
    let other = MeshRecord {
        tenant: "other".into(),
        ..mesh("m_other", 5, "a")
    };
    s.insert_mesh(&other).unwrap();
    assert_eq!(
        ids_of(s.list_meshes("other", None, 10).unwrap()),
        ["m_other"]
    );
    assert_eq!(
        s.find_mesh_by_sha256("other", &"a".repeat(64), 6).unwrap(),
        Some(other.clone())
    );
    assert!(s
        .find_mesh_by_sha256("", &"a".repeat(64), 6)
        .unwrap()
        .is_none());
    let ids = |v: Vec<MeshRecord>| v.into_iter().map(|m| m.id).collect::<Vec<_>>();
    for m in [
        mesh("m_a", 10, "a"),
        mesh("m_b", 20, "b"),
        mesh("m_c", 20, "a"),
    ] {
        s.insert_mesh(&m).unwrap();
    }
    assert_eq!(
        ids(s.list_meshes("", None, 10).unwrap()),
        ["m_c", "m_b", "m_a"]
    );
    assert_eq!(ids(s.list_meshes("", None, 1).unwrap()), ["m_c"]);
    assert_eq!(
        ids(s.list_meshes("", Some((20, "m_c")), 1).unwrap()),
        ["m_b"]
    );
    assert_eq!(
        ids(s.list_meshes("", Some((20, "m_b")), 5).unwrap()),
        ["m_a"]
    );
    assert!(s.list_meshes("", Some((10, "m_a")), 5).unwrap().is_empty());
    // the same bytes: the tenant's oldest upload
    assert_eq!(
        s.find_mesh_by_sha256("", &"a".repeat(64), 12)
            .unwrap()
            .unwrap(),
        mesh("m_a", 10, "a")
    );
    assert!(s
        .find_mesh_by_sha256("", &"f".repeat(64), 12)
        .unwrap()
        .is_none());
    assert!(s.delete_mesh("m_other").unwrap());
    // unused: uploaded before the cut-off and named by no job (of any status)
    let mut j = JobRecord::queued("j_uses_a", "report", "m_b", 30);
    j.reference_mesh_id = Some("m_a".into());
    j.status = Status::Succeeded;
    s.insert_job(&j).unwrap();
    assert_eq!(s.delete_unused_meshes(100).unwrap(), ["m_c"]);
    assert!(s.get_mesh("m_c").unwrap().is_none());
    assert!(s.delete_unused_meshes(100).unwrap().is_empty());
    assert!(s.delete_job("j_uses_a").unwrap());
    // m_a was handed out again at 12: kept until then
    assert!(s.delete_unused_meshes(12).unwrap().is_empty());
    assert_eq!(s.delete_unused_meshes(15).unwrap(), ["m_a"]);
    assert_eq!(s.delete_unused_meshes(100).unwrap(), ["m_b"]);
    assert!(s.list_meshes("", None, 10).unwrap().is_empty());
    // A request takes back what it stored, unless another request was handed the mesh by
    // its hash meanwhile or a job uses it.
    for m in [
        mesh("m_d", 40, "d"),
        mesh("m_e", 40, "e"),
        mesh("m_f", 40, "f"),
    ] {
        s.insert_mesh(&m).unwrap();
    }
    assert!(s.forget_mesh("m_d").unwrap());
    assert!(s.get_mesh("m_d").unwrap().is_none());
    assert!(!s.forget_mesh("m_d").unwrap(), "already gone");
    assert!(s
        .find_mesh_by_sha256("", &"e".repeat(64), 41)
        .unwrap()
        .is_some());
    assert!(!s.forget_mesh("m_e").unwrap(), "handed out again");
    assert!(s.get_mesh("m_e").unwrap().is_some());
    s.insert_job(&JobRecord::queued("j_uses_f", "report", "m_f", 42))
        .unwrap();
    assert!(!s.forget_mesh("m_f").unwrap(), "a job uses it");
    assert!(s.delete_job("j_uses_f").unwrap());
    // m_e was handed out again at 41, m_f uploaded at 40
    assert_eq!(s.delete_unused_meshes(41).unwrap(), ["m_f"]);
    assert_eq!(s.delete_unused_meshes(42).unwrap(), ["m_e"]);
}

fn ids_of(v: Vec<MeshRecord>) -> Vec<String> {
    v.into_iter().map(|m| m.id).collect()
}

fn jobs_index(s: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    // every field round-trips
    let mut j = JobRecord::queued("j_i1", "flatten", "m_a", 10);
    j.params = serde_json::json!({"unit": "cm", "n": 1.5e-300})
        .as_object()
        .unwrap()
        .clone();
    j.callback_url = Some("https://example.com/hook?a=b".into());
    j.idempotency_key = Some("key-1".into());
    j.request_hash = Some("h1".into());
    j.base_url = Some("https://api.example.com/flatmesh".into());
    let Inserted::New(stored) = s.insert_job(&j).unwrap() else {
        panic!("a new key inserts");
    };
    assert!(stored.seq > 0);
    assert_eq!(s.get_job("j_i1").unwrap().unwrap(), stored);
    // the same key returns the first job, from any handle, and inserts nothing
    let mut again = JobRecord::queued("j_i2", "flatten", "m_a", 11);
    again.idempotency_key = Some("key-1".into());
    match open().insert_job(&again).unwrap() {
        Inserted::Existing(e) => assert_eq!(e.id, "j_i1"),
        Inserted::New(_) => panic!("an idempotency key inserts once"),
    }
    assert!(s.get_job("j_i2").unwrap().is_none());
    assert_eq!(s.find_idempotent("key-1").unwrap().unwrap().id, "j_i1");
    assert!(s.find_idempotent("key-none").unwrap().is_none());
    // update keeps what it does not own and writes what it does
    let mut u = stored.clone();
    u.status = Status::Succeeded;
    u.progress = Some(serde_json::json!({"stage": "lpfb", "iteration": 2}));
    u.started_at = Some(12);
    u.finished_at = Some(20);
    u.expires_at = Some(1_000);
    u.attempts = 3;
    u.artifacts = vec!["report.json".into(), "mesh.glb".into()];
    u.outcome = Some(serde_json::json!({"converged": true}));
    u.error = None;
    s.update_job(&u).unwrap();
    assert_eq!(s.get_job("j_i1").unwrap().unwrap(), u);
    // listing: newest first, filtered by status and kind, paged by seq
    for (k, kind) in ["report", "flatten", "report"].iter().enumerate() {
        s.insert_job(&JobRecord::queued(&format!("j_l{k}"), kind, "m_a", 30))
            .unwrap();
    }
    let all = s
        .list_jobs(&JobFilter {
            limit: 10,
            ..JobFilter::default()
        })
        .unwrap();
    let ids: Vec<&str> = all.iter().map(|j| j.id.as_str()).collect();
    assert_eq!(ids, ["j_l2", "j_l1", "j_l0", "j_i1"]);
    // another tenant's job is listed only for that tenant, and its tenant round-trips
    let mut theirs = JobRecord::queued("j_theirs", "report", "m_a", 31);
    theirs.tenant = "acme".into();
    s.insert_job(&theirs).unwrap();
    assert_eq!(s.get_job("j_theirs").unwrap().unwrap().tenant, "acme");
    let listed = |tenant: &str| {
        s.list_jobs(&JobFilter {
            tenant: tenant.into(),
            limit: 10,
            ..JobFilter::default()
        })
        .unwrap()
        .into_iter()
        .map(|j| j.id)
        .collect::<Vec<_>>()
    };
    assert_eq!(listed("acme"), ["j_theirs"]);
    assert_eq!(listed(""), ids);
    assert!(s.delete_job("j_theirs").unwrap());
    let reports = s
        .list_jobs(&JobFilter {
            kind: Some("report".into()),
            status: Some(Status::Queued),
            limit: 10,
            ..JobFilter::default()
        })
        .unwrap();
    assert_eq!(
        reports.iter().map(|j| j.id.as_str()).collect::<Vec<_>>(),
        ["j_l2", "j_l0"]
    );
    let page = s
        .list_jobs(&JobFilter {
            before_seq: Some(all[1].seq),
            limit: 1,
            ..JobFilter::default()
        })
        .unwrap();
    assert_eq!(
        page.iter().map(|j| j.id.as_str()).collect::<Vec<_>>(),
        ["j_l0"]
    );
    assert_eq!(
        s.jobs_with_status(Status::Queued)
            .unwrap()
            .iter()
            .map(|j| j.id.as_str())
            .collect::<Vec<_>>(),
        ["j_l0", "j_l1", "j_l2"],
        "oldest first"
    );
    // expiry: only ended jobs whose results expired
    let expired = s.expired_jobs(1_001).unwrap();
    assert_eq!(
        expired.iter().map(|j| j.id.as_str()).collect::<Vec<_>>(),
        ["j_i1"]
    );
    assert!(s.expired_jobs(999).unwrap().is_empty());
    for id in ["j_i1", "j_l0", "j_l1", "j_l2"] {
        assert!(s.delete_job(id).unwrap());
    }
    assert!(!s.delete_job("j_i1").unwrap());
    assert_eq!(s.count_with_status(Status::Queued).unwrap(), 0);
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

/// A job released by its worker (its results found the storage full) is queued again at its
/// place, its attempt uncounted; only its holder can release it, and not once a cancel was
/// requested.
fn released_jobs_run_again(s: &dyn Store) {
    for id in ["j_r1", "j_r2"] {
        s.insert_job(&queued(id)).unwrap();
    }
    let r1 = s.claim("w1", 1_000, LEASE).unwrap().unwrap();
    assert_eq!((r1.id.as_str(), r1.attempts), ("j_r1", 1));
    assert!(!s.release("w2", "j_r1").unwrap(), "not w2's to release");
    assert!(s.release("w1", "j_r1").unwrap());
    assert_eq!(status(s, "j_r1"), Status::Queued);
    assert!(!s.release("w1", "j_r1").unwrap(), "released once");
    assert_eq!(
        s.heartbeat("w1", "j_r1", 1_001, LEASE, None).unwrap(),
        Lease::Lost
    );
    let again = s.claim("w2", 1_002, LEASE).unwrap().unwrap();
    assert_eq!(
        (again.id.as_str(), again.attempts),
        ("j_r1", 1),
        "first in the queue again, the attempt not counted"
    );
    s.request_cancel("j_r1", 1_003, 9_999).unwrap();
    assert!(!s.release("w2", "j_r1").unwrap(), "a cancel was requested");
    c_finish(s, "w2", again);
    let r2 = s.claim("w1", 1_004, LEASE).unwrap().unwrap();
    assert_eq!(r2.id, "j_r2");
    c_finish(s, "w1", r2);
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

fn with_callback(id: &str) -> JobRecord {
    let mut j = queued(id);
    j.callback_url = Some("https://example.com/hook".into());
    j
}

fn drain(s: &dyn Store, now: i64) -> Vec<Delivery> {
    let mut out = Vec::new();
    while let Some(d) = s.claim_delivery("drain", now, LEASE).unwrap() {
        assert!(s.end_delivery(d.id, "drain").unwrap());
        out.push(d);
    }
    out
}

/// Every step that ends a job with a callback queues one delivery, atomically; deliveries
/// are claimed under a lease like jobs, retried when asked, and ended once.
fn webhook_outbox(s: &dyn Store, open: &dyn Fn() -> Arc<dyn Store>) {
    assert!(
        drain(s, i64::MAX / 4).is_empty(),
        "no job with a callback has ended yet"
    );
    // finish: one delivery with the end's event; none for a job without a callback
    s.insert_job(&with_callback("j_w1")).unwrap();
    s.insert_job(&queued("j_w2")).unwrap();
    for w in ["w1", "w2"] {
        let mut j = s.claim(w, 100, LEASE).unwrap().unwrap();
        j.status = Status::Succeeded;
        j.finished_at = Some(200);
        assert!(s.finish(w, &j).unwrap());
    }
    assert!(
        s.claim_delivery("h1", 199, LEASE).unwrap().is_none(),
        "not due before the job ended"
    );
    let d = s
        .claim_delivery("h1", 300, LEASE)
        .unwrap()
        .expect("one delivery");
    assert_eq!(
        (d.job_id.as_str(), d.event.as_str(), d.attempts),
        ("j_w1", "job.succeeded", 0)
    );
    // leased: nobody else takes it, nor ends it
    assert!(s.claim_delivery("h2", 300, LEASE).unwrap().is_none());
    assert!(!s.end_delivery(d.id, "h2").unwrap());
    // retried: not due before its time, then due with one attempt counted
    assert!(s.retry_delivery(d.id, "h1", 5_000).unwrap());
    assert!(!s.retry_delivery(d.id, "h1", 5_000).unwrap(), "released");
    assert!(s.claim_delivery("h2", 4_999, LEASE).unwrap().is_none());
    let d2 = s.claim_delivery("h2", 5_000, LEASE).unwrap().unwrap();
    assert_eq!((d2.id, d2.attempts), (d.id, 1));
    // a sender that dies: after its lease another takes it, and the dead one cannot end it
    let d3 = s
        .claim_delivery("h3", 5_000 + LEASE + 1, LEASE)
        .unwrap()
        .expect("lease ran out");
    assert_eq!(d3.id, d.id);
    assert!(!s.end_delivery(d.id, "h2").unwrap());
    assert!(s.end_delivery(d.id, "h3").unwrap());
    assert!(
        drain(s, i64::MAX / 4).is_empty(),
        "a finish queues one delivery"
    );
    // a queued job cancelled, and a running one whose worker died after a cancel request
    s.insert_job(&with_callback("j_w3")).unwrap();
    s.insert_job(&with_callback("j_w4")).unwrap();
    s.request_cancel("j_w3", 400, 9_999).unwrap();
    let j4 = s.claim("w4", 400, LEASE).unwrap().unwrap();
    assert_eq!(j4.id, "j_w4");
    s.request_cancel("j_w4", 410, 9_999).unwrap();
    assert!(
        drain(s, i64::MAX / 4).iter().all(|d| d.job_id == "j_w3"),
        "a running job's cancel request is not its end"
    );
    s.requeue_expired(400 + LEASE + 1, 9_999).unwrap();
    let ended: Vec<(String, String)> = drain(s, i64::MAX / 4)
        .into_iter()
        .map(|d| (d.job_id, d.event))
        .collect();
    assert_eq!(ended, [("j_w4".to_string(), "job.cancelled".to_string())]);
    // claims from several handles at once take each delivery once
    let n = 20;
    for k in 0..n {
        let id = format!("j_wd{k:02}");
        s.insert_job(&with_callback(&id)).unwrap();
        s.request_cancel(&id, 500, 9_999).unwrap();
    }
    let handles: Vec<Arc<dyn Store>> = (0..4).map(|_| open()).collect();
    let got: Vec<Vec<i64>> = std::thread::scope(|sc| {
        let ts: Vec<_> = handles
            .iter()
            .enumerate()
            .map(|(w, h)| {
                sc.spawn(move || {
                    let me = format!("h{w}");
                    let mut mine = Vec::new();
                    while let Some(d) = h.claim_delivery(&me, 600, LEASE).unwrap() {
                        assert!(h.end_delivery(d.id, &me).unwrap());
                        mine.push(d.id);
                    }
                    mine
                })
            })
            .collect();
        ts.into_iter().map(|t| t.join().unwrap()).collect()
    });
    let all: Vec<i64> = got.into_iter().flatten().collect();
    let unique: HashSet<i64> = all.iter().copied().collect();
    assert_eq!((all.len(), unique.len()), (n, n), "each delivery once");
}
