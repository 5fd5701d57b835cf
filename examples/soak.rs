//! Soak test of `flatmesh serve` (not in CI: it runs for minutes). A server under a file
//! descriptor and an address-space limit gets, at saturation, concurrent uploads (new bytes
//! and repeated ones), JSON and multipart submits (past the queue bound, so 429s too), status
//! polls, result downloads and deletes. At the end it prints the requests by status class,
//! the 5xx count (must be 0), poll latency p50/p99, and the server's resident memory after
//! the first minute and at the end.
//!
//! Run: `cargo build --release && cargo run --release --example soak -- [MINUTES] [CLIENTS]`
//! (defaults 10 and 32).
//! The server runs with `ulimit -n 512 -v 4000000` (512 descriptors, 4 GB of address space)
//! and `--max-connections 256 --max-queued 32`. Exit status 1 when a 5xx was seen or the
//! resident memory grew by more than 10 % after the first minute.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Requests by status class (index 1–5), and poll latencies in ms.
#[derive(Default)]
struct Tally {
    by_class: [AtomicU64; 6],
    polls_ms: Mutex<Vec<f64>>,
    failures: AtomicU64,
}

impl Tally {
    fn count(&self, status: u16) {
        self.by_class[(status / 100).min(5) as usize].fetch_add(1, Ordering::Relaxed);
    }
}

fn rss_mb(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// A small mesh whose bytes differ by `salt` (so each is a new upload).
fn mesh_bytes(salt: u64) -> Vec<u8> {
    let mut obj = std::fs::read_to_string("fixtures/cone_noisy.obj").expect("fixture");
    obj += &format!("# {salt}\n");
    obj.into_bytes()
}

/// One client: loops over the request mix until `until`.
async fn client(k: u64, base: String, until: Instant, tally: Arc<Tally>) {
    let c = reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap();
    let mut jobs: Vec<String> = Vec::new();
    let mut round = 0u64;
    while Instant::now() < until {
        round += 1;
        let step = async {
            // Upload: new bytes mostly, the same bytes every fourth time.
            let salt = if round % 4 == 0 { 0 } else { k << 32 | round };
            let r = c
                .post(format!("{base}/v1/meshes"))
                .header("content-type", "model/obj")
                .body(mesh_bytes(salt))
                .send()
                .await?;
            tally.count(r.status().as_u16());
            let mesh: serde_json::Value = r.json().await?;
            let Some(mid) = mesh["id"].as_str() else {
                return Ok::<(), reqwest::Error>(());
            };
            // Submit: JSON, or multipart with a mesh of its own.
            let r = if round % 3 == 0 {
                let form = reqwest::multipart::Form::new()
                    .text("job", r#"{"kind":"report"}"#)
                    .part(
                        "mesh",
                        reqwest::multipart::Part::bytes(mesh_bytes(k << 40 | round))
                            .file_name("m.obj")
                            .mime_str("model/obj")?,
                    );
                c.post(format!("{base}/v1/jobs"))
                    .multipart(form)
                    .send()
                    .await?
            } else {
                let kind = if round % 2 == 0 { "report" } else { "flatten" };
                c.post(format!("{base}/v1/jobs"))
                    .json(&serde_json::json!({"kind": kind, "mesh_id": mid}))
                    .send()
                    .await?
            };
            tally.count(r.status().as_u16());
            if r.status() == 202 {
                let j: serde_json::Value = r.json().await?;
                if let Some(id) = j["id"].as_str() {
                    jobs.push(id.to_string());
                }
            }
            // Poll the oldest job; download its result when it is done, then delete it.
            if let Some(id) = jobs.first().cloned() {
                let t = Instant::now();
                let r = c.get(format!("{base}/v1/jobs/{id}")).send().await?;
                tally
                    .polls_ms
                    .lock()
                    .unwrap()
                    .push(t.elapsed().as_secs_f64() * 1e3);
                tally.count(r.status().as_u16());
                let j: serde_json::Value = r.json().await?;
                if j["status"] == "succeeded" {
                    let r = c.get(format!("{base}/v1/jobs/{id}/result")).send().await?;
                    tally.count(r.status().as_u16());
                    let _ = r.bytes().await?;
                }
                if j["status"]
                    .as_str()
                    .is_some_and(|s| s != "queued" && s != "running")
                {
                    let r = c.delete(format!("{base}/v1/jobs/{id}")).send().await?;
                    tally.count(r.status().as_u16());
                    jobs.remove(0);
                }
            }
            Ok(())
        };
        if step.await.is_err() {
            tally.failures.fetch_add(1, Ordering::Relaxed);
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
}

fn main() {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let minutes = args.first().copied().unwrap_or(10);
    let clients = args.get(1).copied().unwrap_or(32);
    let dir = std::env::temp_dir().join(format!("flatmesh-soak-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let exe = std::env::current_exe()
        .unwrap()
        .parent()
        .unwrap()
        .parent()
        .unwrap()
        .join("flatmesh");
    let script = format!(
        "ulimit -n 512 && ulimit -v 4000000 && exec {} serve --bind 127.0.0.1:0 --data-dir {} \
         --max-connections 256 --max-queued 32",
        exe.display(),
        dir.display()
    );
    let mut child = Command::new("sh")
        .args(["-c", &script])
        .env("FLATMESH_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the server (build it first: cargo build --release)");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let base = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap_or_else(|| panic!("the server did not start: {line:?}"))
        .to_string();
    let pid = child.id();
    println!("soak: {minutes} min, {clients} clients against {base} (pid {pid})");
    let tally = Arc::new(Tally::default());
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let start = Instant::now();
    let until = start + Duration::from_secs(60 * minutes);
    let rss_first = rt.block_on(async {
        let tasks: Vec<_> = (0..clients)
            .map(|k| tokio::spawn(client(k, base.clone(), until, tally.clone())))
            .collect();
        tokio::time::sleep(Duration::from_secs(60.min(60 * minutes))).await;
        let first = rss_mb(pid);
        println!("after 1 min: RSS {first:.0} MB");
        for t in tasks {
            let _ = t.await;
        }
        first
    });
    let rss_end = rss_mb(pid);
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    let mut polls = tally.polls_ms.lock().unwrap().clone();
    polls.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        polls
            .get(((polls.len().max(1) - 1) as f64 * p) as usize)
            .copied()
    };
    let classes: Vec<u64> = tally
        .by_class
        .iter()
        .map(|a| a.load(Ordering::Relaxed))
        .collect();
    let total: u64 = classes.iter().sum();
    let growth = (rss_end - rss_first) / rss_first * 100.0;
    println!(
        "requests {total} in {:.0} s: 2xx {}, 3xx {}, 4xx {}, 5xx {}; transport failures {}",
        start.elapsed().as_secs_f64(),
        classes[2],
        classes[3],
        classes[4],
        classes[5],
        tally.failures.load(Ordering::Relaxed)
    );
    println!(
        "status polls: {} , p50 {:.2} ms, p99 {:.2} ms",
        polls.len(),
        pct(0.5).unwrap_or(f64::NAN),
        pct(0.99).unwrap_or(f64::NAN)
    );
    println!("RSS after 1 min {rss_first:.0} MB, at the end {rss_end:.0} MB ({growth:+.1} %)");
    if total == 0 || classes[5] > 0 || growth.is_nan() || growth > 10.0 {
        std::process::exit(1);
    }
}
