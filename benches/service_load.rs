//! Load benchmark of `flatmesh serve` on loopback (not a test): every worker is kept busy by
//! slow `flatten` jobs while many concurrent clients poll job status and submit small jobs.
//! Prints p50/p99/max latencies and throughput. Target: status polls under 5 ms p99 while the
//! workers are saturated. In the paced phase each client sends one request every INTERVAL_MS
//! (20), the clients' phases spread evenly over that interval; the closed-loop phase sends
//! the next request as soon as the last one is answered.
//!
//! Run: `cargo bench --bench service_load` (env CLIENTS, SECONDS, INTERVAL_MS to change the
//! load; BUSY=0 for a control run with idle workers).
//!
//! With REPLICAS=N (PostgreSQL's binaries installed): the same phases against N replicas of
//! `flatmesh serve` on one throwaway PostgreSQL database (clients spread over the replicas,
//! every replica's workers busy), then, on a fresh database, JOBS small `report` jobs (1000,
//! from eight submitters) through the replicas in turn while eight clients poll job status:
//! prints the jobs finished per second and the status-poll latencies.
//!
//! Measured (2-core VM, SECONDS=6, one run each): SQLite, paced with both workers busy:
//! polls p50 0.11–0.15 / p99 0.44–0.85 ms. PostgreSQL, same load, polls answered from the replica's
//! job cache (`store::job_cache`): 1 replica p50 0.16 / p99 1.96 ms, 2 replicas 0.19 / 1.91,
//! 3 replicas 0.16 / 4.08 (before the cache: 19–22 and 32 ms; the polls waited for the
//! database backends to be scheduled on the saturated cores). Closed loop (overload) p99
//! 7–9 ms.
//! Small-job throughput: 1 replica 209–287 jobs/s, 2 replicas 313–342, 3 replicas 300–326
//! (two cores: beyond two processes the replicas share them); polls in that phase miss the
//! cache (every job changes within milliseconds), p99 3–100 ms.

use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn saddle_obj(n: usize) -> Vec<u8> {
    let mut s = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let x = i as f64 / n as f64 * 2.0 - 1.0;
            let y = j as f64 / n as f64 * 2.0 - 1.0;
            s += &format!("v {x:.6} {y:.6} {:.6}\n", 0.3 * (x * x - y * y));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i + 1;
            let (b, c) = (a + 1, a + n + 1);
            s += &format!("f {a} {b} {}\nf {a} {} {c}\n", c + 1, c + 1);
        }
    }
    s.into_bytes()
}

/// Send a request that creates something; its `id`.
async fn post_for_id(req: reqwest::RequestBuilder) -> String {
    let v: Value = req.send().await.unwrap().json().await.unwrap();
    v["id"].as_str().unwrap().to_string()
}

/// Jobs running over every replica, from their `/readyz`.
async fn running_jobs(c: &reqwest::Client, bases: &[String]) -> usize {
    let mut running = 0;
    for b in bases {
        let v: Value = c
            .get(format!("{b}/readyz"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        running += v["running"].as_u64().unwrap_or(0) as usize;
    }
    running
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() as f64 - 1.0) * p).round() as usize]
}

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

#[allow(dead_code)]
#[path = "../tests/common/pg.rs"]
mod pg;

fn main() {
    let clients = env("CLIENTS", 32);
    let seconds = env("SECONDS", 10);
    let replicas = env("REPLICAS", 0);
    // REPLICAS=N: N processes on one throwaway PostgreSQL database; else one on SQLite.
    let cluster = if replicas > 0 {
        match pg::PgCluster::start("service_load on PostgreSQL") {
            Some(c) => Some(c),
            None => return,
        }
    } else {
        None
    };
    let url = cluster.as_ref().map(|c| c.database("load"));
    let dir = std::env::temp_dir().join(format!("flatmesh-load-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut procs: Vec<(std::process::Child, String)> = (0..replicas.max(1))
        .map(|k| start_server(url.as_deref(), &dir.join(format!("r{k}"))))
        .collect();
    let bases: Vec<String> = procs.iter().map(|p| p.1.clone()).collect();
    let base = bases[0].clone();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async move {
        let c = reqwest::Client::new();
        let up = |bytes: Vec<u8>| {
            post_for_id(
                c.post(format!("{base}/v1/meshes"))
                    .header("content-type", "model/obj")
                    .body(bytes),
            )
        };
        let slow = up(saddle_obj(250)).await;
        let small = up(std::fs::read("fixtures/cylinder.obj").unwrap()).await;
        let workers = std::thread::available_parallelism().map_or(1, |n| n.get());
        // Enough slow jobs to keep every worker busy for the whole run (BUSY=0: none, a
        // control run with idle workers that polls a finished small job instead).
        let busy = env("BUSY", 1) != 0;
        let mut slow_ids = vec![];
        let n_slow = if busy {
            workers * bases.len() * (seconds / 3 + 2)
        } else {
            0
        };
        let submit = |body: Value| post_for_id(c.post(format!("{base}/v1/jobs")).json(&body));
        if !busy {
            let id = submit(json!({"kind": "report", "mesh_id": small})).await;
            slow_ids = vec![id; workers];
        }
        for _ in 0..n_slow {
            slow_ids.push(
                submit(json!({"kind": "flatten", "mesh_id": slow,
                    "params": {"tolerance": 1e-300, "max_iterations": 100000}}))
                .await,
            );
        }
        // wait until the workers are busy (every replica's)
        loop {
            let running = running_jobs(&c, &bases).await;
            if !busy || running == workers * bases.len() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        for (label, interval_ms) in [("paced", env("INTERVAL_MS", 20)), ("closed-loop", 0)] {
            let label = if busy {
                format!("{label}, {workers} workers busy with slow jobs")
            } else {
                format!("{label}, control: no slow jobs")
            };
            let label = if bases.len() > 1 || url.is_some() {
                format!("{label}; {} replica(s) on PostgreSQL", bases.len())
            } else {
                label
            };
            phase(
                &c,
                &bases,
                &label,
                clients,
                seconds,
                interval_ms,
                workers * bases.len(),
                &slow_ids,
                &small,
            )
            .await;
        }
    });
    for (child, _) in &mut procs {
        let _ = child.kill();
        let _ = child.wait();
    }
    // The small-job throughput of the replicas, on a fresh database each.
    if let Some(cluster) = &cluster {
        for (child, _) in &mut procs {
            let _ = child.wait();
        }
        let url = cluster.database("throughput");
        let mut procs: Vec<(std::process::Child, String)> = (0..replicas)
            .map(|k| start_server(Some(&url), &dir.join(format!("t{k}"))))
            .collect();
        let bases: Vec<String> = procs.iter().map(|p| p.1.clone()).collect();
        rt.block_on(replicas_phase(&url, &bases, 8, env("JOBS", 1000)));
        for (child, _) in &mut procs {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// One measuring phase: `clients` tasks, each polling a running job's status and submitting a
/// small job every tenth request, every `interval_ms` (0: as fast as answers come back).
#[allow(clippy::too_many_arguments)]
async fn phase(
    c: &reqwest::Client,
    bases: &[String],
    label: &str,
    clients: usize,
    seconds: usize,
    interval_ms: usize,
    workers: usize,
    slow_ids: &[String],
    small: &str,
) {
    let start = Instant::now();
    let end = start + Duration::from_secs(seconds as u64);
    let mut tasks = vec![];
    for k in 0..clients {
        let c = c.clone();
        let base = bases[k % bases.len()].clone();
        let poll_id = slow_ids[k % workers].clone();
        let small = small.to_string();
        tasks.push(tokio::spawn(async move {
            let (mut polls, mut submits, mut errors) = (vec![], vec![], 0usize);
            let mut i = 0usize;
            // Independent clients are not phase-locked: spread their first requests over one
            // interval (all 32 at the same instant would measure a burst's queue instead).
            if interval_ms > 0 {
                let offset = Duration::from_micros((interval_ms * 1000 * k / clients) as u64);
                tokio::time::sleep(offset).await;
            }
            let mut tick = (interval_ms > 0).then(|| {
                let mut t = tokio::time::interval(Duration::from_millis(interval_ms as u64));
                t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                t
            });
            while Instant::now() < end {
                if let Some(t) = tick.as_mut() {
                    t.tick().await;
                }
                i += 1;
                let t = Instant::now();
                // one submit for every 10 polls
                if i % 10 == 0 {
                    let r = c
                        .post(format!("{base}/v1/jobs"))
                        .json(&json!({"kind": "report", "mesh_id": small}))
                        .send()
                        .await;
                    match r {
                        Ok(r) if r.status() == 202 => {
                            let _ = r.bytes().await;
                            submits.push(t.elapsed().as_secs_f64() * 1e3)
                        }
                        _ => errors += 1,
                    }
                } else {
                    let r = c.get(format!("{base}/v1/jobs/{poll_id}")).send().await;
                    match r {
                        Ok(r) if r.status() == 200 => {
                            let _ = r.bytes().await;
                            polls.push(t.elapsed().as_secs_f64() * 1e3)
                        }
                        _ => errors += 1,
                    }
                }
            }
            (polls, submits, errors)
        }));
    }
    let (mut polls, mut submits, mut errors) = (vec![], vec![], 0);
    for t in tasks {
        let (p, s, e) = t.await.unwrap();
        polls.extend(p);
        submits.extend(s);
        errors += e;
    }
    let elapsed = start.elapsed().as_secs_f64();
    let running = running_jobs(c, bases).await;
    let total = polls.len() + submits.len();
    println!(
        "service_load [{label}{}]: {clients} clients, {elapsed:.1} s, jobs running at end: {}",
        if interval_ms > 0 {
            format!(", one request per client every {interval_ms} ms")
        } else {
            String::new()
        },
        running
    );
    println!(
        "  status polls: n={} p50={:.2} ms p99={:.2} ms max={:.2} ms",
        polls.len(),
        pct(&mut polls, 0.5),
        pct(&mut polls, 0.99),
        pct(&mut polls, 1.0)
    );
    println!(
        "  submits:      n={} p50={:.2} ms p99={:.2} ms max={:.2} ms",
        submits.len(),
        pct(&mut submits, 0.5),
        pct(&mut submits, 0.99),
        pct(&mut submits, 1.0)
    );
    println!(
        "  throughput:   {:.0} requests/s, errors {errors}",
        total as f64 / elapsed
    );
}

/// `flatmesh serve` on database `url` (None: SQLite in `dir`); its base URL.
fn start_server(url: Option<&str>, dir: &std::path::Path) -> (std::process::Child, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_flatmesh"));
    cmd.args(["serve", "--bind", "127.0.0.1:0", "--max-queued", "100000"]);
    if let Some(url) = url {
        cmd.args(["--database-url", url]);
    }
    let mut child = cmd
        .arg("--data-dir")
        .arg(dir)
        .env("FLATMESH_LOG", "warn")
        .env(
            "FLATMESH_WORKER_NICE",
            std::env::var("WORKER_NICE").unwrap_or_else(|_| "10".into()),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start server");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let base = line.trim().trim_start_matches("listening on ").to_string();
    (child, base)
}

async fn replicas_phase(url: &str, bases: &[String], clients: usize, jobs: usize) {
    let (db, conn) = tokio_postgres::connect(url, tokio_postgres::NoTls)
        .await
        .unwrap();
    tokio::spawn(conn);
    let c = reqwest::Client::new();
    let small = post_for_id(
        c.post(format!("{}/v1/meshes", bases[0]))
            .header("content-type", "model/obj")
            .body(std::fs::read("fixtures/cylinder.obj").unwrap()),
    )
    .await;
    // Eight submitters at once, through the replicas in turn.
    let start = Instant::now();
    let mut subs = vec![];
    for s in 0..8 {
        let (c, bases, small) = (c.clone(), bases.to_vec(), small.clone());
        subs.push(tokio::spawn(async move {
            let mut mine = vec![];
            for k in (s..jobs).step_by(8) {
                let base = &bases[k % bases.len()];
                mine.push(
                    post_for_id(
                        c.post(format!("{base}/v1/jobs"))
                            .json(&json!({"kind": "report", "mesh_id": small})),
                    )
                    .await,
                );
            }
            mine
        }));
    }
    let mut ids = Vec::with_capacity(jobs);
    for t in subs {
        ids.extend(t.await.unwrap());
    }
    let submitted = start.elapsed().as_secs_f64();
    // Pollers until every job has ended.
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut tasks = vec![];
    for k in 0..clients {
        let (c, bases, ids, done) = (c.clone(), bases.to_vec(), ids.clone(), done.clone());
        tasks.push(tokio::spawn(async move {
            let mut lat = vec![];
            let mut i = k;
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                let base = &bases[i % bases.len()];
                let id = &ids[(i * 7) % ids.len()];
                let t = Instant::now();
                if let Ok(r) = c.get(format!("{base}/v1/jobs/{id}")).send().await {
                    let _ = r.bytes().await;
                    lat.push(t.elapsed().as_secs_f64() * 1e3);
                }
                i += clients;
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            lat
        }));
    }
    loop {
        let left: i64 = db
            .query_one(
                "SELECT COUNT(*) FROM jobs WHERE status IN ('queued','running')",
                &[],
            )
            .await
            .unwrap()
            .get(0);
        if left == 0 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let elapsed = start.elapsed().as_secs_f64();
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let mut polls = vec![];
    for t in tasks {
        polls.extend(t.await.unwrap());
    }
    let ok: i64 = db
        .query_one("SELECT COUNT(*) FROM jobs WHERE status = 'succeeded'", &[])
        .await
        .unwrap()
        .get(0);
    println!(
        "service_load [{} replica(s) on PostgreSQL]: {jobs} report jobs ({ok} succeeded) in \
         {elapsed:.2} s = {:.1} jobs/s (submitting took {submitted:.2} s)",
        bases.len(),
        jobs as f64 / elapsed
    );
    println!(
        "  status polls: n={} p50={:.2} ms p99={:.2} ms max={:.2} ms",
        polls.len(),
        pct(&mut polls, 0.5),
        pct(&mut polls, 0.99),
        pct(&mut polls, 1.0)
    );
}
