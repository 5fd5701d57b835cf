//! Hostile input and operation (issue 20), black box: a real `flatmesh serve` and what an
//! attacker or a careless operator would send it.

mod common;

use common::*;
use serde_json::json;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A webhook receiver on `addr` counting POSTs to /hook; its port.
async fn receiver(addr: &str, hits: Arc<AtomicUsize>) -> std::io::Result<u16> {
    let app = axum::Router::new().route(
        "/hook",
        axum::routing::post(move || {
            let hits = hits.clone();
            async move {
                hits.fetch_add(1, Ordering::SeqCst);
                axum::http::StatusCode::NO_CONTENT
            }
        }),
    );
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let port = listener.local_addr()?.port();
    tokio::spawn(async move { axum::serve(listener, app).await });
    Ok(port)
}

async fn metric(c: &reqwest::Client, s: &Server, line: &str) -> u64 {
    let text = c
        .get(s.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(line)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("{line} not in {text}"))
}

/// Submit a report job on `mesh` with this callback; wait for it to end.
async fn report_with_callback(c: &reqwest::Client, s: &Server, mesh: &str, url: &str) {
    let j = submit(
        c,
        s,
        json!({"kind": "report", "mesh_id": mesh, "callback_url": url}),
    )
    .await;
    let done = wait_for(c, s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
}

async fn wait_until(what: &str, mut ok: impl AsyncFnMut() -> bool) {
    let t0 = Instant::now();
    while !ok().await {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "{what}: not within 20 s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A callback by a name that resolves to this host passes the submit check (names are not
/// resolved then) but is never called: the sender's resolver hands the connection only
/// global addresses, and the refusal is final (no retry). With `--allow-private-callbacks`
/// the same name is called, and so is an IPv6 literal (its brackets are not part of the
/// address).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn callbacks_connect_only_to_checked_addresses() {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .unwrap_or_default()
        .trim()
        .to_string();
    let resolved: Vec<std::net::SocketAddr> = tokio::net::lookup_host((host.as_str(), 0))
        .await
        .map(|a| a.collect())
        .unwrap_or_default();
    let hits = Arc::new(AtomicUsize::new(0));
    let port = receiver("0.0.0.0:0", hits.clone()).await.unwrap();
    let c = client();
    let backoff = ["--webhook-backoff", "100ms,100ms"];
    if host.is_empty() || resolved.is_empty() || !resolved.iter().all(|a| a.ip().is_ipv4()) {
        eprintln!("SKIPPED the by-name half: this host's name {host:?} resolves to {resolved:?}");
    } else {
        let by_name = format!("http://{host}:{port}/hook");
        let strict = Server::start(&tmp("hostile-hooks"), &backoff);
        let m = upload(&c, &strict, fixture("cone")).await;
        report_with_callback(&c, &strict, m["id"].as_str().unwrap(), &by_name).await;
        let failed = "flatmesh_webhook_deliveries_total{outcome=\"failed\"}";
        wait_until("the refused delivery", async || {
            metric(&c, &strict, failed).await == 1
        })
        .await;
        tokio::time::sleep(Duration::from_millis(500)).await;
        assert_eq!(metric(&c, &strict, failed).await, 1, "retried");
        assert_eq!(hits.load(Ordering::SeqCst), 0, "{by_name} was called");

        let open = Server::start(
            &tmp("hostile-hooks-open"),
            &[&backoff[..], &["--allow-private-callbacks"]].concat(),
        );
        let m = upload(&c, &open, fixture("cone")).await;
        report_with_callback(&c, &open, m["id"].as_str().unwrap(), &by_name).await;
        wait_until("delivery by name", async || {
            hits.load(Ordering::SeqCst) == 1
        })
        .await;
    }

    let hits6 = Arc::new(AtomicUsize::new(0));
    match receiver("[::1]:0", hits6.clone()).await {
        Err(e) => eprintln!("SKIPPED the IPv6 half: cannot listen on [::1]: {e}"),
        Ok(port6) => {
            let open = Server::start(
                &tmp("hostile-hooks-v6"),
                &[&backoff[..], &["--allow-private-callbacks"]].concat(),
            );
            let m = upload(&c, &open, fixture("cone")).await;
            let url = format!("http://[::1]:{port6}/hook");
            report_with_callback(&c, &open, m["id"].as_str().unwrap(), &url).await;
            wait_until("delivery to [::1]", async || {
                hits6.load(Ordering::SeqCst) == 1
            })
            .await;
        }
    }
}

/// An empty API key is a start-up error, not authentication turned off.
#[test]
fn an_empty_api_key_is_refused_at_start_up() {
    let dir = tmp("hostile-empty-key");
    for (args, env) in [
        (vec!["--api-key", ""], None),
        (vec!["--api-key", "k1,"], None),
        (vec![], Some(",")),
        (vec![], Some("")),
    ] {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"));
        cmd.args(["serve", "--bind", "127.0.0.1:0", "--data-dir"])
            .arg(&dir)
            .args(&args)
            .env_remove("FLATMESH_API_KEYS");
        if let Some(v) = env {
            cmd.env("FLATMESH_API_KEYS", v);
        }
        let out = cmd.output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} {env:?}: started");
        assert!(err.contains("empty key"), "{args:?} {env:?}: {err}");
    }
}
