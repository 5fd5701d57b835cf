//! A browser's view of CORS: a page served from one loopback origin makes an authenticated
//! (`Authorization: Bearer`), idempotent (`Idempotency-Key`) JSON call to flatmesh on another
//! port, in headless Chromium, and reads the answer. Chromium is Debian's, installed by
//! `.ci/run`; without it the test says so and skips, except under `CI=true`.
//!
//! Measured: Chromium 148 also lets the call through with the old `Access-Control-Allow-
//! Headers: *` (it does not yet enforce the Fetch rule that `*` never covers
//! `Authorization`; Firefox and Safari do), so the names themselves are checked by the
//! preflight assertions of tests/api/service.rs::api_keys.

use crate::common;

use common::*;
use std::io::{Read, Write};
use std::process::Command;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_authenticated_cross_origin_call_from_a_browser_succeeds() {
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| std::path::Path::new(p).exists());
    let Some(chromium) = chromium else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true but no chromium (.ci/run installs it)"
        );
        eprintln!("SKIPPED: browser CORS test (no chromium; run .ci/run to install it)");
        return;
    };
    // The page's origin must be known to the server before it starts: reserve the port.
    let page_listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let page_origin = format!("http://{}", page_listener.local_addr().unwrap());
    drop(page_listener);
    let s = Server::start(
        &tmp("browser"),
        &["--api-key", "secret-key", "--cors-origin", &page_origin],
    );
    let c = client();
    let m = c
        .post(s.url("/v1/meshes"))
        .bearer_auth("secret-key")
        .header("content-type", "model/obj")
        .body(fixture("cylinder"))
        .send()
        .await
        .unwrap();
    assert_eq!(m.status(), 201);
    let mesh_id = m.json::<serde_json::Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    // The page submits a job (preflighted: JSON, Authorization, Idempotency-Key), then reads
    // a header the server exposes, and writes what it got into the document.
    let page = format!(
        r#"<!doctype html><html><body><pre id="out">pending</pre><script>
(async () => {{
  const out = document.getElementById("out");
  try {{
    const r = await fetch("{base}/v1/jobs", {{
      method: "POST",
      headers: {{
        "Authorization": "Bearer secret-key",
        "Content-Type": "application/json",
        "Idempotency-Key": "browser-1"
      }},
      body: JSON.stringify({{ kind: "report", mesh_id: "{mesh_id}" }})
    }});
    const j = await r.json();
    out.textContent = "status=" + r.status + " kind=" + j.kind + " location=" + r.headers.get("location");
  }} catch (e) {{
    out.textContent = "error=" + e;
  }}
}})();
</script></body></html>"#,
        base = s.base
    );
    // Serve it on the reserved port.
    let listener = std::net::TcpListener::bind(page_origin.trim_start_matches("http://")).unwrap();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let mut stream = stream;
            let mut buf = [0u8; 4096];
            let _ = stream.read(&mut buf);
            let _ = write!(
                stream,
                "HTTP/1.1 200 OK\r\ncontent-type: text/html\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{}",
                page.len(),
                page
            );
        }
    });
    let profile = tmp("browser-profile");
    let dom = tokio::task::spawn_blocking({
        let origin = page_origin.clone();
        move || {
            Command::new(chromium)
                .args([
                    "--headless=new",
                    "--no-sandbox",
                    "--disable-gpu",
                    "--disable-quic",
                    "--no-first-run",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                    "--virtual-time-budget=10000",
                    "--dump-dom",
                ])
                .arg(format!("--user-data-dir={}", profile.display()))
                .arg(format!("{origin}/"))
                .output()
                .unwrap()
        }
    })
    .await
    .unwrap();
    let html = String::from_utf8_lossy(&dom.stdout);
    let want = format!("status=202 kind=report location={}/v1/jobs/", s.base);
    assert!(
        html.contains(&want),
        "the page got no answer through CORS:\n{html}\n{}",
        String::from_utf8_lossy(&dom.stderr)
    );
}
