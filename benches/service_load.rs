//! Load benchmark of `flatmesh serve` on loopback (not a test): every worker is kept busy by
//! slow `flatten` jobs while many concurrent clients poll job status and submit small jobs.
//! Prints p50/p99/max latencies and throughput. Target: status polls under 5 ms p99 while the
//! workers are saturated. In the paced phase each client sends one request every INTERVAL_MS
//! (20), the clients' phases spread evenly over that interval; the closed-loop phase sends
//! the next request as soon as the last one is answered.
//!
//! Run: `cargo bench --bench service_load` (env CLIENTS, SECONDS, INTERVAL_MS to change the
//! load; BUSY=0 for a control run with idle workers).

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

fn main() {
    let clients = env("CLIENTS", 32);
    let seconds = env("SECONDS", 10);
    let dir = std::env::temp_dir().join(format!("flatmesh-load-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut child = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--max-queued",
            "100000",
            "--data-dir",
        ])
        .arg(&dir)
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
        let n_slow = if busy { workers * (seconds / 3 + 2) } else { 0 };
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
        // wait until the workers are busy
        loop {
            let v: Value = c
                .get(format!("{base}/readyz"))
                .send()
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            if !busy || v["running"].as_u64() == Some(workers as u64) {
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
            phase(
                &c,
                &base,
                &label,
                clients,
                seconds,
                interval_ms,
                workers,
                &slow_ids,
                &small,
            )
            .await;
        }
    });
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

/// One measuring phase: `clients` tasks, each polling a running job's status and submitting a
/// small job every tenth request, every `interval_ms` (0: as fast as answers come back).
#[allow(clippy::too_many_arguments)]
async fn phase(
    c: &reqwest::Client,
    base: &str,
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
        let base = base.to_string();
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
    let v: Value = c
        .get(format!("{base}/readyz"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let total = polls.len() + submits.len();
    println!(
        "service_load [{label}{}]: {clients} clients, {elapsed:.1} s, jobs running at end: {}",
        if interval_ms > 0 {
            format!(", one request per client every {interval_ms} ms")
        } else {
            String::new()
        },
        v["running"]
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
