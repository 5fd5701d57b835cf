//! Issue 20's time-limit bar, black box, in a test binary of its own so that no other test
//! shares the two cores while it measures how long a worker is held.

mod common;

use common::*;
use serde_json::json;

/// A saddle of 2·cells² faces with normal noise (deterministic), as OBJ.
fn noisy_saddle_obj(cells: usize) -> Vec<u8> {
    let h = 2.0 / cells as f64;
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    grid_obj(cells, cells, |i, j| {
        let (x, y) = (i as f64 * h - 1.0, j as f64 * h - 1.0);
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let inner = i > 0 && j > 0 && i < cells && j < cells;
        let noise = if inner {
            0.1 * h * ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
        } else {
            0.0
        };
        format!("{x} {y} {}", 0.5 * (x * x - y * y) + noise)
    })
}

fn seconds_between(from: &serde_json::Value, to: &serde_json::Value) -> f64 {
    let t = |v: &serde_json::Value| humantime::parse_rfc3339(v.as_str().unwrap()).unwrap();
    t(to).duration_since(t(from)).unwrap().as_secs_f64()
}

/// Done when: "a worker is never held past the time limit by more than one second, on every
/// kind". Each job is long on this mesh (fl-mesh alone takes ~90 s); with a 1 s limit each
/// must fail with `time-limit` within 2 s of its start, including subdivide and Loop develop,
/// whose first fl-mesh factorisation on the subdivided mesh (~200k faces) cannot be
/// interrupted, and the next job must start right after.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_kind_ends_within_a_second_of_its_time_limit() {
    let s = Server::start(
        &tmp("time-limit-kinds"),
        &["--workers", "1", "--job-time-limit", "1s"],
    );
    let c = client();
    let mesh = upload(&c, &s, noisy_saddle_obj(160)).await;
    let id = mesh["id"].as_str().unwrap();
    // `local` on the 51k-face saddle ran 0.95 s and ended stalled inside the limit
    // (measured 2026-11-29): it gets four times the faces.
    let big = upload(&c, &s, noisy_saddle_obj(320)).await;
    let big_id = big["id"].as_str().unwrap();
    // (kind, params, mesh)
    let runs = [
        (
            "flatten",
            json!({"tolerance": 1e-300, "max_iterations": 100000}),
            id,
        ),
        ("fl-mesh", json!({}), id),
        ("subdivide", json!({"levels": 1}), id),
        ("perturb", json!({}), id),
        ("develop", json!({"method": "global"}), id),
        // 500000 moves take ~0.5 s here since they got cheaper: ten times as many, and no
        // min_gain floor, which could end the run stalled inside the limit.
        (
            "develop",
            json!({"method": "local", "max_moves": 5_000_000, "min_gain": 0}),
            big_id,
        ),
        ("develop", json!({"method": "loop"}), id),
        ("segment", json!({}), id),
    ];
    let mut jobs = Vec::new();
    for (kind, params, mesh_id) in &runs {
        let j = submit(
            &c,
            &s,
            json!({"kind": kind, "mesh_id": mesh_id, "params": params}),
        )
        .await;
        jobs.push(j["id"].as_str().unwrap().to_string());
    }
    let mut previous_end: Option<serde_json::Value> = None;
    for ((kind, params, _), jid) in runs.iter().zip(&jobs) {
        let end = wait_for(&c, &s, jid, &["succeeded", "failed", "cancelled"]).await;
        let held = seconds_between(&end["started_at"], &end["finished_at"]);
        eprintln!(
            "{kind} {params}: held {held:.2} s, {}",
            end["error"]["detail"]
        );
        assert_eq!(end["status"], "failed", "{kind} {params}: {end}");
        assert_eq!(end["error"]["type"], s.url("/problems/time-limit"), "{end}");
        assert!(
            held <= 2.0,
            "{kind} {params} held its worker {held:.2} s: {end}"
        );
        if let Some(prev) = &previous_end {
            let idle = seconds_between(prev, &end["started_at"]);
            assert!(
                idle <= 0.5,
                "{kind}: the worker started it {idle:.2} s late"
            );
        }
        previous_end = Some(end["finished_at"].clone());
    }
}
