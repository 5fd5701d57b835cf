//! `flatmesh serve` on PostgreSQL (`--database-url`): one replica keeps everything in the
//! database, and three replicas on one database act as one service: any replica answers
//! for any job, a cancel sent to one stops a job running on another, and of 24 jobs
//! submitted through all three, with one replica killed (SIGKILL) while it runs a job,
//! every job ends once, succeeded, with the same status, attempts and results through every
//! replica. Each test starts a throwaway PostgreSQL cluster (tests/common/pg.rs).

use crate::common;

use common::pg::PgCluster;
use common::*;
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// Query the test database directly (what a replica holds, what rows exist).
async fn db(url: &str) -> tokio_postgres::Client {
    let (client, conn) = tokio_postgres::connect(url, tokio_postgres::NoTls)
        .await
        .unwrap();
    tokio::spawn(conn);
    client
}

/// Blob rows whose key starts with `prefix`.
async fn blob_count(db: &tokio_postgres::Client, prefix: &str) -> i64 {
    db.query_one(
        "SELECT COUNT(*) FROM blobs WHERE starts_with(key, $1)",
        &[&prefix],
    )
    .await
    .unwrap()
    .get(0)
}

/// The worker holding a running job, if any.
async fn holder(db: &tokio_postgres::Client, id: &str) -> Option<String> {
    db.query_opt(
        "SELECT worker FROM jobs WHERE id = $1 AND status = 'running'",
        &[&id],
    )
    .await
    .unwrap()
    .and_then(|r| r.get(0))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_replica_keeps_everything_in_the_database() {
    let Some(pg) = PgCluster::start("serve on PostgreSQL") else {
        return;
    };
    let url = pg.database("one");
    let dir = tmp("pg-one");
    let s = Server::start(&dir, &["--database-url", &url, "--workers", "1"]);
    let c = client();
    let mesh = upload(&c, &s, fixture("cylinder")).await;
    let id = submit(&c, &s, json!({"kind": "flatten", "mesh_id": mesh["id"]})).await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let end = wait_for(&c, &s, &id, &["succeeded", "failed", "cancelled"]).await;
    assert_eq!(end["status"], "succeeded", "{end}");
    let result = job_result(&c, &s, &id).await;
    assert_eq!(result["job"]["kind"], "flatten");
    let svg = download(&c, &s, &format!("/v1/jobs/{id}/patterns?format=svg")).await;
    assert!(String::from_utf8_lossy(&svg).contains("<svg"));
    // Nothing but the webhook secret in the data directory: index and blobs are in the db.
    assert!(!dir.join("flatmesh.sqlite3").exists());
    assert!(!dir.join("blobs").exists());
    let d = db(&url).await;
    let n = blob_count(&d, &format!("jobs/{id}/")).await;
    assert!(n >= 3, "{n} artifacts stored");
    // Deleting the job deletes its blobs.
    let r = c
        .delete(s.url(&format!("/v1/jobs/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    let n = blob_count(&d, &format!("jobs/{id}/")).await;
    assert_eq!(n, 0);
    // A restart finds the mesh again.
    drop(s);
    let s = Server::start(&dir, &["--database-url", &url, "--workers", "1"]);
    let r = c
        .get(s.url(&format!("/v1/meshes/{}", mesh["id"].as_str().unwrap())))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    // Readiness is the database's: not ready while it is away (the process stays live),
    // ready again once it is back.
    assert_eq!(c.get(s.url("/readyz")).send().await.unwrap().status(), 200);
    pg.stop();
    let r = c.get(s.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 503);
    assert!(r.headers().contains_key("retry-after"));
    assert_eq!(c.get(s.url("/healthz")).send().await.unwrap().status(), 200);
    pg.start_again();
    let t = Instant::now();
    while c.get(s.url("/readyz")).send().await.unwrap().status() != 200 {
        assert!(t.elapsed() < Duration::from_secs(20), "not ready again");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// A flatten that runs for about half a second and succeeds (LPFB stops at its iteration
/// limit): long enough that a replica is killed while it holds one.
fn medium_job(mesh: &Value, hook: &str) -> Value {
    json!({"kind": "flatten", "mesh_id": mesh["id"], "callback_url": hook,
           "params": {"tolerance": 1e-300, "max_iterations": 300}})
}

/// One received webhook: the signed content `id.timestamp.body`, the signature header, and
/// the body.
type Hook = (String, String, Value);

/// A webhook receiver on loopback: every POST, in order.
async fn receiver() -> (String, std::sync::Arc<std::sync::Mutex<Vec<Hook>>>) {
    let got = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let g = got.clone();
    let app = axum::Router::new().route(
        "/hook",
        axum::routing::post(
            move |headers: axum::http::HeaderMap, body: axum::body::Bytes| {
                let g = g.clone();
                async move {
                    let h = |k: &str| headers[k].to_str().unwrap().to_string();
                    let signed = format!(
                        "{}.{}.{}",
                        h("webhook-id"),
                        h("webhook-timestamp"),
                        String::from_utf8_lossy(&body)
                    );
                    let v: Value = serde_json::from_slice(&body).unwrap();
                    g.lock().unwrap().push((signed, h("webhook-signature"), v));
                    axum::http::StatusCode::NO_CONTENT
                }
            },
        ),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}/hook", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, app).await });
    (url, got)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_replicas_act_as_one_service() {
    let Some(pg) = PgCluster::start("three replicas on PostgreSQL") else {
        return;
    };
    let url = pg.database("three");
    let d = db(&url).await;
    let (hook, got) = receiver().await;
    let args = [
        "--database-url",
        &url,
        "--workers",
        "1",
        "--lease",
        "1s",
        "--job-time-limit",
        "20s",
        "--allow-private-callbacks",
    ];
    let dirs = [tmp("pg-a"), tmp("pg-b"), tmp("pg-c")];
    let mut reps: Vec<Server> = dirs.iter().map(|d| Server::start(d, &args)).collect();
    let c = client();
    // Uploaded through A, used through B and C.
    let strip = upload(&c, &reps[0], slow_obj()).await;
    let slow: Value = serde_json::from_str(SLOW).unwrap();
    let slow_job = json!({"kind": "flatten", "mesh_id": strip["id"], "params": slow,
                          "callback_url": hook});

    // A cancel sent to one replica stops a job running on another.
    let id = submit(&c, &reps[1], slow_job.clone()).await["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_for(&c, &reps[1], &id, &["running"]).await;
    let w = holder(&d, &id).await.expect("a running job has a holder");
    let other = reps
        .iter()
        .find(|r| !w.contains(&format!("-{}-", r.pid())))
        .unwrap();
    let t0 = Instant::now();
    let r = c
        .post(other.url(&format!("/v1/jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let end = wait_for(&c, other, &id, &["cancelled", "failed", "succeeded"]).await;
    assert_eq!(end["status"], "cancelled", "{end}");
    eprintln!("cross-replica cancel took {:?}", t0.elapsed());

    // 24 jobs through all three; kill one replica while it holds a job.
    let mut ids = Vec::new();
    for k in 0..24 {
        let via = &reps[k % 3];
        ids.push(
            submit(&c, via, medium_job(&strip, &hook)).await["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    let victim = reps[2].pid();
    let t0 = Instant::now();
    let killed = loop {
        let mut found = None;
        for id in &ids {
            if holder(&d, id)
                .await
                .is_some_and(|w| w.contains(&format!("-{victim}-")))
            {
                found = Some(id.clone());
                break;
            }
        }
        if let Some(id) = found {
            break id;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "C never ran a job");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    reps.pop().unwrap().kill();
    for id in &ids {
        let end = wait_for(&c, &reps[0], id, &["succeeded", "failed", "cancelled"]).await;
        assert_eq!(end["status"], "succeeded", "{end}");
        let via_b = job(&c, &reps[1], id).await;
        assert_eq!(end["status"], via_b["status"], "{id}");
        assert_eq!(end["attempts"], via_b["attempts"], "{id}");
        // Results are the same bytes through either replica.
        let path = format!("/v1/jobs/{id}/result");
        assert_eq!(
            download(&c, &reps[0], &path).await,
            download(&c, &reps[1], &path).await,
            "{id}"
        );
    }
    let k = job(&c, &reps[0], &killed).await;
    assert!(
        k["attempts"].as_u64().unwrap() >= 2,
        "the killed replica's job ran again: {k}"
    );
    // Ran to the end once: exactly one finish per job in the database.
    let unfinished: i64 = d
        .query_one(
            "SELECT COUNT(*) FROM jobs WHERE status <> 'succeeded' AND id = ANY($1)",
            &[&ids],
        )
        .await
        .unwrap()
        .get(0);
    assert_eq!(unfinished, 0);
    // Queue depth is the store's: every replica reports the same empty queue, whichever
    // claimed or submitted last.
    for r in &reps {
        let m = String::from_utf8(download(&c, r, "/metrics").await).unwrap();
        assert!(
            m.lines().any(|l| l == "flatmesh_jobs_queued 0"),
            "{}: {}",
            r.base,
            m.lines()
                .find(|l| l.starts_with("flatmesh_jobs_queued "))
                .unwrap_or("none")
        );
    }
    // Each job's webhook arrives once (the cancelled one's too), with its end.
    let mut want: Vec<(String, &str)> = ids.iter().map(|i| (i.clone(), "job.succeeded")).collect();
    want.push((id.clone(), "job.cancelled"));
    let t0 = Instant::now();
    while got.lock().unwrap().len() < want.len() && t0.elapsed() < Duration::from_secs(40) {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    let hooks = got.lock().unwrap().clone();
    for (job_id, event) in &want {
        let mine: Vec<&Hook> = hooks
            .iter()
            .filter(|(_, _, v)| v["data"]["id"].as_str() == Some(job_id.as_str()))
            .collect();
        assert_eq!(mine.len(), 1, "{job_id}: {} webhooks", mine.len());
        assert_eq!(mine[0].2["type"], *event, "{job_id}");
    }
    assert_eq!(hooks.len(), want.len());
    // No secret was given: the replicas share the one the first stored, and every
    // signature, whichever replica sent it, verifies with it.
    let secret: String = d
        .query_one(
            "SELECT value FROM settings WHERE key = 'webhook_secret'",
            &[],
        )
        .await
        .unwrap()
        .get(0);
    let key = flatmesh::service::webhook::decode_secret(&secret).unwrap();
    for (signed, sig, _) in &hooks {
        use hmac::Mac;
        let mut mac = hmac::Hmac::<sha2::Sha256>::new_from_slice(&key).unwrap();
        mac.update(signed.as_bytes());
        let want = base64::Engine::encode(
            &base64::engine::general_purpose::STANDARD,
            mac.finalize().into_bytes(),
        );
        assert_eq!(sig, &format!("v1,{want}"));
    }
    // Ended once: one "job ended" line over the three replicas' logs.
    let logs: String = dirs
        .iter()
        .map(|d| std::fs::read_to_string(d.join("server.log")).unwrap_or_default())
        .collect();
    for id in &ids {
        let ended = logs
            .lines()
            .filter(|l| l.contains("job ended") && l.contains(id.as_str()))
            .count();
        assert_eq!(ended, 1, "{id} ended {ended} times");
    }
}

/// The bounded queue counts the store's queued jobs: with every worker of two replicas busy
/// and one job queued through A, B refuses the next with 429 (`--max-queued 1`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_queue_bound_holds_across_replicas() {
    let Some(pg) = PgCluster::start("queue bound across replicas") else {
        return;
    };
    let url = pg.database("bound");
    let args = [
        "--database-url",
        &url,
        "--workers",
        "1",
        "--max-queued",
        "1",
    ];
    let (a, b) = (
        Server::start(&tmp("bound-a"), &args),
        Server::start(&tmp("bound-b"), &args),
    );
    let c = client();
    let strip = upload(&c, &a, slow_obj()).await;
    let slow: Value = serde_json::from_str(SLOW).unwrap();
    let job = json!({"kind": "flatten", "mesh_id": strip["id"], "params": slow});
    let mut ids = vec![];
    for s in [&a, &b] {
        ids.push(
            submit(&c, s, job.clone()).await["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    // Both workers busy (one per replica), so the next job stays queued.
    let t = Instant::now();
    loop {
        let mut running = 0;
        for id in &ids {
            running += (job_status(&c, &a, id).await == "running") as usize;
        }
        if running == 2 {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "both workers never busy"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    ids.push(
        submit(&c, &a, job.clone()).await["id"]
            .as_str()
            .unwrap()
            .to_string(),
    );
    let r = c.post(b.url("/v1/jobs")).json(&job).send().await.unwrap();
    assert!(r.headers().contains_key("retry-after"));
    problem(r, 429).await;
    for id in &ids {
        let _ = c.post(a.url(&format!("/v1/jobs/{id}/cancel"))).send().await;
    }
}

async fn job_status(c: &reqwest::Client, s: &Server, id: &str) -> String {
    job(c, s, id).await["status"]
        .as_str()
        .unwrap_or("")
        .to_string()
}
