//! Upgrading: a data directory written by a version from before the store's coordination
//! contract (no leases, no cancel flag, no webhook outbox) opens in this one with every job
//! kept: finished results download unchanged, a job the old process was running when it
//! stopped runs again, a queued job runs.

use crate::common;

use common::*;
use serde_json::json;

/// The SQLite schema as `flatmesh serve` created it before leases (git a9e88d7^,
/// src/service/store.rs), verbatim.
const SCHEMA_BEFORE_LEASES: &str = "
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

const OLD_JOB_COLS: &str = "seq, id, kind, mesh_id, reference_mesh_id, params, callback_url, \
    status, progress, error, created_at, started_at, finished_at, expires_at, attempts, \
    artifacts, idempotency_key, request_hash, outcome";

fn columns(c: &rusqlite::Connection, table: &str) -> Vec<String> {
    let mut st = c.prepare("SELECT name FROM pragma_table_info(?1)").unwrap();
    st.query_map([table], |r| r.get(0))
        .unwrap()
        .map(|r| r.unwrap())
        .collect()
}

/// Rewrite the index in `dir` as the old version would have left it: its schema exactly,
/// the same meshes and jobs; job `running` marked as running (the old process stopped
/// mid-run) and job `queued` as never started.
fn write_old_index(dir: &std::path::Path, running: &str, queued: &str) {
    let db = dir.join("flatmesh.sqlite3");
    let old = dir.join("old.sqlite3");
    {
        let c = rusqlite::Connection::open(&old).unwrap();
        c.execute_batch(SCHEMA_BEFORE_LEASES).unwrap();
        c.execute("ATTACH ?1 AS cur", [db.to_str().unwrap()])
            .unwrap();
        c.execute_batch(&format!(
            "INSERT INTO main.meshes SELECT id, created_at, format, size, sha256, summary \
             FROM cur.meshes;
             INSERT INTO main.jobs ({OLD_JOB_COLS}) SELECT {OLD_JOB_COLS} FROM cur.jobs;"
        ))
        .unwrap();
        c.execute(
            "UPDATE main.jobs SET status = 'running', finished_at = NULL, expires_at = NULL, \
             artifacts = '[]', outcome = NULL, progress = '{\"stage\":\"lpfb\"}' WHERE id = ?1",
            [running],
        )
        .unwrap();
        c.execute(
            "UPDATE main.jobs SET status = 'queued', started_at = NULL, finished_at = NULL, \
             expires_at = NULL, attempts = 0, artifacts = '[]', outcome = NULL, \
             progress = NULL WHERE id = ?1",
            [queued],
        )
        .unwrap();
        c.execute("DETACH cur", []).unwrap();
        // What the old version had: no lease columns, no outbox.
        assert!(!columns(&c, "jobs").contains(&"lease_until".to_string()));
        assert!(columns(&c, "deliveries").is_empty());
    }
    for suffix in ["", "-wal", "-shm"] {
        let _ = std::fs::remove_file(dir.join(format!("flatmesh.sqlite3{suffix}")));
    }
    std::fs::rename(&old, &db).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_data_directory_from_before_leases_keeps_its_jobs() {
    let dir = tmp("upgrade");
    let c = client();
    let s = Server::start(&dir, &["--workers", "1"]);
    let cyl = upload(&c, &s, fixture("cylinder")).await;
    let mut ids = vec![];
    for kind in ["flatten", "report", "report"] {
        let j = submit(&c, &s, json!({"kind": kind, "mesh_id": cyl["id"]})).await;
        let id = j["id"].as_str().unwrap().to_string();
        wait_for(&c, &s, &id, &["succeeded"]).await;
        ids.push(id);
    }
    let (done, running, queued) = (&ids[0], &ids[1], &ids[2]);
    let patterns = download(&c, &s, &format!("/v1/jobs/{done}/patterns?format=dxf")).await;
    let mut done_before = job(&c, &s, done).await;
    let dir = s.kill();
    write_old_index(&dir, running, queued);

    let s = Server::start(&dir, &["--workers", "1", "--lease", "1s"]);
    // Finished: as it was (but for its links: the server now listens on another port),
    // results unchanged.
    let mut done_after = job(&c, &s, done).await;
    for j in [&mut done_before, &mut done_after] {
        j.as_object_mut().unwrap().remove("links");
    }
    assert_eq!(done_after, done_before);
    assert_eq!(
        download(&c, &s, &format!("/v1/jobs/{done}/patterns?format=dxf")).await,
        patterns
    );
    // Interrupted by the old process's stop: runs again (its second attempt), succeeds.
    let r = wait_for(&c, &s, running, &["succeeded", "failed", "cancelled"]).await;
    assert_eq!(r["status"], "succeeded", "{r}");
    assert_eq!(r["attempts"], 2, "{r}");
    // Queued: runs once.
    let q = wait_for(&c, &s, queued, &["succeeded", "failed", "cancelled"]).await;
    assert_eq!(q["status"], "succeeded", "{q}");
    assert_eq!(q["attempts"], 1, "{q}");
    let listed: serde_json::Value =
        serde_json::from_slice(&download(&c, &s, "/v1/jobs?page_size=10").await).unwrap();
    assert_eq!(listed["jobs"].as_array().map(Vec::len), Some(3), "{listed}");
    drop(s);
    // The index now has what this version needs.
    let conn = rusqlite::Connection::open(dir.join("flatmesh.sqlite3")).unwrap();
    for col in ["worker", "lease_until", "cancel_requested"] {
        assert!(columns(&conn, "jobs").contains(&col.to_string()), "{col}");
    }
    assert!(!columns(&conn, "deliveries").is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}
