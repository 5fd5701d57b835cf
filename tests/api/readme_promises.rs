//! README promises that no other test checks, each against a running `flatmesh serve` or its
//! `--help`: the configuration table and the client synopsis, patterns of every kind that
//! changes the mesh (and why there are none when its output cannot be flattened), the input
//! mesh's warnings on the job, `?format=off`, refused callback targets, keys and CORS origins
//! from the environment, the client's `--api-key`, and `--request-timeout`.

use crate::common;

use common::*;
use serde_json::{json, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(args)
        .arg("--help")
        .output()
        .unwrap();
    assert!(out.status.success());
    String::from_utf8(out.stdout).unwrap()
}

/// A `--help` option: its flag, `[env: …]` and `[default: …]`.
#[derive(Debug, Default)]
struct HelpOption {
    env: Option<String>,
    default: Option<String>,
}

/// The options of a clap `--help` text, by flag (`--help` left out).
fn help_options(text: &str) -> BTreeMap<String, HelpOption> {
    let mut out: BTreeMap<String, HelpOption> = BTreeMap::new();
    let mut current: Option<String> = None;
    let mut body = String::new();
    let mut flush = |flag: &Option<String>, body: &str| {
        let Some(flag) = flag else { return };
        let env = body
            .split("[env: ")
            .nth(1)
            .map(|s| s.split(['=', ']']).next().unwrap().to_string());
        let default = body
            .split("[default: ")
            .nth(1)
            .map(|s| s.split(']').next().unwrap().to_string());
        if flag != "--help" {
            out.insert(flag.clone(), HelpOption { env, default });
        }
    };
    for line in text.lines() {
        let t = line.trim_start();
        let t = t.strip_prefix("-h, ").unwrap_or(t);
        if t.starts_with("--") {
            flush(&current, &body);
            current = Some(t.split_whitespace().next().unwrap().to_string());
            body = t.to_string();
        } else {
            body.push(' ');
            body.push_str(t);
        }
    }
    flush(&current, &body);
    out
}

/// The README's configuration table: flag → (environment variable, default cell).
fn readme_table() -> BTreeMap<String, (String, String)> {
    let readme = std::fs::read_to_string("README.md").unwrap();
    readme
        .lines()
        .filter(|l| l.starts_with("| `--"))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                cells[1].trim_matches('`').to_string(),
                (cells[2].trim_matches('`').to_string(), cells[3].to_string()),
            )
        })
        .collect()
}

/// Every flag of `flatmesh serve --help` is a row of the README's table with the same
/// environment variable and default, and every row is a flag.
#[test]
fn configuration_table_is_serve_help() {
    let options = help_options(&help(&["serve"]));
    let table = readme_table();
    assert_eq!(
        options.keys().collect::<BTreeSet<_>>(),
        table.keys().collect::<BTreeSet<_>>(),
        "flags of `serve --help` vs rows of the README's table"
    );
    // Defaults the README words instead of quoting, with what the help says for them.
    let worded = [("--workers", "0", "one per core")];
    for (flag, o) in &options {
        let (env, cell) = &table[flag];
        assert_eq!(o.env.as_deref(), Some(env.as_str()), "{flag}");
        match &o.default {
            Some(d) => {
                let quoted = cell.starts_with(&format!("`{d}`"));
                let words = worded
                    .iter()
                    .any(|(f, v, w)| f == flag && v == d && cell.starts_with(w));
                assert!(quoted || words, "{flag}: default `{d}`, README says {cell}");
            }
            None => assert!(
                !cell.starts_with('`'),
                "{flag} has no default, README says {cell}"
            ),
        }
    }
}

/// The README's `flatmesh client` synopsis names every subcommand, flag and environment
/// variable of `flatmesh client --help` and of its subcommands, and nothing else.
#[test]
fn client_synopsis_is_client_help() {
    let readme = std::fs::read_to_string("README.md").unwrap();
    let start = readme.find("Client: `flatmesh client").unwrap();
    let para = &readme[start..];
    let para = &para[..para.find("\n\n").unwrap()];
    let top = help(&["client"]);
    let commands: Vec<String> = top
        .split("Commands:")
        .nth(1)
        .unwrap()
        .split("Options:")
        .next()
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect();
    assert!(commands.len() >= 5, "{commands:?}");
    let mut flags = BTreeSet::new();
    let mut envs = BTreeSet::new();
    for text in
        std::iter::once(top.clone()).chain(commands.iter().map(|c| help(&["client", c.as_str()])))
    {
        for (flag, o) in help_options(&text) {
            flags.insert(flag);
            envs.extend(o.env);
        }
    }
    let words: BTreeSet<String> = para
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-' || c == '_'))
        .map(str::to_string)
        .collect();
    for c in &commands {
        assert!(words.contains(c), "subcommand {c} missing from: {para}");
    }
    let named: BTreeSet<String> = words
        .iter()
        .filter(|w| w.starts_with("--"))
        .cloned()
        .collect();
    assert_eq!(named, flags, "README client synopsis vs --help");
    for e in &envs {
        assert!(words.contains(e), "{e} missing from: {para}");
    }
}

/// Relative error of the pattern's edge lengths against the mesh's, after the one scale
/// factor between the mesh's unit and the drawing's (the median ratio).
fn pattern_edge_error(pat: &Value, mesh: &flatmesh::mesh::Mesh) -> f64 {
    let pairs = pattern_edges(pat, mesh.positions());
    assert!(!pairs.is_empty(), "no pattern edges");
    let mut ratios: Vec<f64> = pairs.iter().map(|(a, b)| a / b).collect();
    ratios.sort_by(f64::total_cmp);
    let scale = ratios[ratios.len() / 2];
    pairs
        .iter()
        .map(|(d2, d3)| (d2 / scale - d3).abs() / d3)
        .fold(0.0, f64::max)
}

/// A closed torus (genus 1): a mesh `flatten` refuses to flatten.
fn torus_obj() -> Vec<u8> {
    let (n, m, big, small) = (16, 8, 2.0f64, 0.7f64);
    let mut obj = String::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                std::f64::consts::TAU * i as f64 / n as f64,
                std::f64::consts::TAU * j as f64 / m as f64,
            );
            let r = big + small * v.cos();
            obj += &format!("v {} {} {}\n", r * u.cos(), r * u.sin(), small * v.sin());
        }
    }
    for i in 0..n {
        for j in 0..m {
            let id = |i: usize, j: usize| (i % n) * m + (j % m) + 1;
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            obj += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        }
    }
    obj.into_bytes()
}

/// `subdivide`, `perturb` and `develop` serve the patterns of their output mesh, in every
/// format (each pattern's edges are the output mesh's, up to the drawing unit); an output
/// that cannot be flattened leaves the job succeeded, says why under
/// `job.patterns_unavailable` and in its warnings, and its patterns answer 404 with the
/// reason.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn patterns_of_kinds_that_change_the_mesh() {
    let s = Server::start(&tmp("promise-patterns"), &[]);
    let c = client();
    let cone = upload(&c, &s, fixture("cone_noisy")).await;
    let cylinder = upload(&c, &s, fixture("cylinder_noisy")).await;
    let body = upload(&c, &s, shrunk_cylinder_obj()).await;
    let requests = [
        json!({"kind": "subdivide", "mesh_id": cone["id"]}),
        json!({"kind": "develop", "mesh_id": cone["id"], "params": {"method": "loop"}}),
        json!({"kind": "perturb", "mesh_id": cylinder["id"], "reference_mesh_id": body["id"]}),
    ];
    for request in requests {
        let kind = request["kind"].as_str().unwrap();
        let j = submit(&c, &s, request.clone()).await;
        let id = j["id"].as_str().unwrap();
        let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
        assert_eq!(done["status"], "succeeded", "{done}");
        let pat = json_of(
            c.get(s.url(&format!("/v1/jobs/{id}/patterns?format=json")))
                .send()
                .await
                .unwrap(),
            "Patterns",
        )
        .await;
        let mesh = download(&c, &s, &format!("/v1/jobs/{id}/mesh?format=obj")).await;
        let (mesh, _) = flatmesh::io::load(&mesh, flatmesh::io::Format::Obj).unwrap();
        let err = pattern_edge_error(&pat, &mesh);
        println!("{kind}: pattern edge error {err:.2e}");
        assert!(err < 1e-3, "{kind}: pattern edges differ by {err}");
        for (format, media, marker) in [
            ("svg", "image/svg+xml", "<svg"),
            ("dxf", "image/vnd.dxf", "SECTION"),
        ] {
            let r = c
                .get(s.url(&format!("/v1/jobs/{id}/patterns?format={format}")))
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 200, "{kind} {format}");
            assert_eq!(r.headers()["content-type"], media);
            let text = r.text().await.unwrap();
            assert!(text.contains(marker), "{kind} {format}");
        }
    }

    let torus = upload(&c, &s, torus_obj()).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "fl-mesh", "mesh_id": torus["id"], "params": {"max_iterations": 3}}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let warning = done["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["code"] == "patterns_unavailable")
        .unwrap_or_else(|| panic!("no patterns_unavailable warning: {done}"));
    let why = warning["message"].as_str().unwrap();
    assert!(why.contains("genus 1"), "{why}");
    let result = job_result(&c, &s, id).await;
    assert_eq!(result["job"]["patterns_unavailable"], why);
    let p = problem(
        c.get(s.url(&format!("/v1/jobs/{id}/patterns")))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    assert!(p["detail"].as_str().unwrap().contains(why), "{p}");
    // The mesh itself is there.
    let r = c
        .get(s.url(&format!("/v1/jobs/{id}/mesh")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
}

/// A job lists its input mesh's warnings and its patterns' problems among its own; `?format=off` reads an OFF body
/// sent as bytes, and a body that is not what `?format=` names is a 422.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn input_warnings_and_named_formats() {
    let s = Server::start(&tmp("promise-input"), &[]);
    let c = client();
    let mut obj = fixture("cylinder");
    obj.extend_from_slice(b"v 9 9 9\n");
    let m = upload(&c, &s, obj).await;
    let j = submit(&c, &s, json!({"kind": "report", "mesh_id": m["id"]})).await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert!(
        done["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w["code"] == "unreferenced_vertices"),
        "{done}"
    );

    // A piece that cannot be flattened (a torus beside a cone): the pattern's problem is
    // among the job's warnings.
    let (cone, _) = flatmesh::io::load(&fixture("cone"), flatmesh::io::Format::Obj).unwrap();
    let mut two = String::new();
    for p in cone.positions() {
        two += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in cone.triangles() {
        two += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let n = cone.num_vertices();
    for line in String::from_utf8(torus_obj()).unwrap().lines() {
        match line.split_once(' ') {
            Some(("v", xyz)) => {
                let c: Vec<f64> = xyz.split(' ').map(|x| x.parse().unwrap()).collect();
                two += &format!("v {} {} {}\n", c[0] + 10.0, c[1], c[2]);
            }
            Some(("f", ids)) => {
                let ids: Vec<String> = ids
                    .split(' ')
                    .map(|i| (i.parse::<usize>().unwrap() + n).to_string())
                    .collect();
                two += &format!("f {}\n", ids.join(" "));
            }
            _ => {}
        }
    }
    let m = upload(&c, &s, two.into_bytes()).await;
    let j = submit(&c, &s, json!({"kind": "flatten", "mesh_id": m["id"]})).await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let pattern = done["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["code"] == "pattern")
        .unwrap_or_else(|| panic!("no pattern warning: {done}"));
    assert!(
        pattern["message"].as_str().unwrap().contains("genus 1"),
        "{pattern}"
    );

    let mut off = format!("OFF\n{} {} 0\n", cone.num_vertices(), cone.num_faces());
    for p in cone.positions() {
        off += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for t in cone.triangles() {
        off += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    let r = c
        .post(s.url("/v1/meshes?format=off"))
        .header("content-type", "application/octet-stream")
        .body(off)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let m = json_of(r, "Mesh").await;
    assert_eq!(m["format"], "off", "{m}");
    assert_eq!(m["faces"], cone.num_faces() as u64, "{m}");
    let r = c
        .post(s.url("/v1/meshes?format=off"))
        .header("content-type", "application/octet-stream")
        .body(fixture("cone"))
        .send()
        .await
        .unwrap();
    let p = problem(r, 422).await;
    assert_eq!(p["field"], "body", "{p}");
}

/// Callbacks to link-local (cloud metadata), private, shared, unspecified and loopback
/// addresses are refused at submit, in IPv4, IPv6 and IPv4-mapped form, unless
/// `--allow-private-callbacks`; a public host is accepted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn callback_targets() {
    let strict = Server::start(&tmp("promise-callbacks"), &[]);
    let open = Server::start(
        &tmp("promise-callbacks-open"),
        &["--allow-private-callbacks"],
    );
    let c = client();
    let refused = [
        "http://169.254.169.254/latest/meta-data",
        "http://[fe80::1]/hook",
        "http://192.168.1.10/hook",
        "http://172.16.0.1/hook",
        "http://100.64.0.1/hook",
        "http://0.0.0.0/hook",
        "http://[::ffff:127.0.0.1]/hook",
        "http://[fd00::1]/hook",
        "http://api.localhost/hook",
        "http://LocalHost./hook",
    ];
    for s in [&strict, &open] {
        let m = upload(&c, s, fixture("cone")).await;
        for url in refused {
            let body = json!({"kind": "report", "mesh_id": m["id"], "callback_url": url});
            let r = c.post(s.url("/v1/jobs")).json(&body).send().await.unwrap();
            if std::ptr::eq(s, &strict) {
                let p = problem(r, 422).await;
                assert_eq!(p["field"], "callback_url", "{url}: {p}");
            } else {
                assert_eq!(r.status(), 202, "{url} with --allow-private-callbacks");
            }
        }
        let body = json!({"kind": "report", "mesh_id": m["id"],
                          "callback_url": "https://hooks.example.com/flatmesh"});
        let r = c.post(s.url("/v1/jobs")).json(&body).send().await.unwrap();
        assert_eq!(r.status(), 202);
    }
}

/// `FLATMESH_API_KEYS` and `FLATMESH_CORS_ORIGINS=*` from the environment: keys are required
/// and accepted, and a browser on any origin may send `Authorization`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keys_and_any_origin_from_the_environment() {
    let s = Server::start_with_env(
        &tmp("promise-env"),
        &[],
        &[
            ("FLATMESH_API_KEYS", "e1,e2"),
            ("FLATMESH_CORS_ORIGINS", "*"),
        ],
    );
    let c = client();
    problem(c.get(s.url("/v1/jobs")).send().await.unwrap(), 401).await;
    let r = c
        .get(s.url("/v1/jobs"))
        .bearer_auth("e2")
        .header("origin", "https://cad.example.org")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let origin = r.headers()["access-control-allow-origin"].to_str().unwrap();
    assert!(
        ["*", "https://cad.example.org"].contains(&origin),
        "{origin}"
    );
    let r = c
        .request(reqwest::Method::OPTIONS, s.url("/v1/meshes"))
        .header("origin", "http://localhost:5173")
        .header("access-control-request-method", "POST")
        .header(
            "access-control-request-headers",
            "authorization,content-type",
        )
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let h = r.headers();
    let origin = h["access-control-allow-origin"].to_str().unwrap();
    assert!(["*", "http://localhost:5173"].contains(&origin), "{origin}");
    let allowed = h["access-control-allow-headers"]
        .to_str()
        .unwrap()
        .to_lowercase();
    assert!(
        allowed.split(',').any(|a| a.trim() == "authorization"),
        "{allowed}"
    );
}

fn flatmesh_client(base: &str, args: &[&str], env: &[(&str, &str)]) -> (bool, String) {
    run_client(&[&["--server", base][..], args].concat(), env)
}

/// `flatmesh client ARGS` with only these of its variables set: success, stdout + stderr.
fn run_client(args: &[&str], env: &[(&str, &str)]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .arg("client")
        .args(args)
        .env_remove("FLATMESH_API_KEY")
        .env_remove("FLATMESH_SERVER")
        .envs(env.iter().copied())
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr),
    )
}

/// `flatmesh client --api-key` (or `FLATMESH_API_KEY`) talks to a server that requires
/// keys; without one it fails saying why; `health` needs none.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_api_key() {
    let s = Server::start(&tmp("promise-client-key"), &["--api-key", "k1"]);
    let upload = ["upload", "fixtures/cone.obj"];
    let (ok, out) = flatmesh_client(&s.base, &upload, &[]);
    assert!(!ok, "{out}");
    assert!(out.contains("401"), "{out}");
    let (ok, out) = flatmesh_client(&s.base, &[&["--api-key", "k1"][..], &upload].concat(), &[]);
    assert!(ok, "{out}");
    let m: Value = serde_json::from_str(&out).unwrap();
    assert!(m["id"].as_str().unwrap().starts_with("m_"), "{m}");
    let (ok, out) = flatmesh_client(&s.base, &upload, &[("FLATMESH_API_KEY", "k1")]);
    assert!(ok, "{out}");
    let (ok, out) = flatmesh_client(&s.base, &["health"], &[]);
    assert!(ok, "{out}");
}

/// A request that has not finished within `--request-timeout` (here a body that stops
/// arriving) is answered 408 with a problem, and the server goes on serving.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn request_timeout() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let s = Server::start(&tmp("promise-timeout"), &["--request-timeout", "1s"]);
    let addr = s.base.strip_prefix("http://").unwrap();
    let mut tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/meshes HTTP/1.1\r\nhost: {addr}\r\ncontent-type: model/obj\r\n\
         content-length: 100000\r\n\r\nv 0 0 0\n"
    );
    tcp.write_all(head.as_bytes()).await.unwrap();
    let t0 = Instant::now();
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    while !String::from_utf8_lossy(&answer).contains("}") {
        let n = tokio::time::timeout(Duration::from_secs(10), tcp.read(&mut buf))
            .await
            .expect("no answer within 10 s")
            .unwrap();
        if n == 0 {
            break;
        }
        answer.extend_from_slice(&buf[..n]);
    }
    let waited = t0.elapsed();
    let answer = String::from_utf8_lossy(&answer).to_string();
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(answer.contains("application/problem+json"), "{answer}");
    assert!(
        waited >= Duration::from_millis(900) && waited < Duration::from_secs(8),
        "answered after {waited:?}"
    );
    let r = client().get(s.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
}

/// `flatmesh client submit` takes each input as an id or a file, in every combination (a
/// perturb job with its reference body), finds the server through `FLATMESH_SERVER`, and
/// `wait --timeout` gives up on a job that runs longer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_inputs_as_ids_or_files() {
    let s = Server::start(&tmp("promise-client-inputs"), &["--workers", "1"]);
    let c = client();
    let dir = tmp("promise-client-inputs-files");
    std::fs::create_dir_all(&dir).unwrap();
    let body_file = dir.join("body.obj");
    std::fs::write(&body_file, shrunk_cylinder_obj()).unwrap();
    let body_file = body_file.to_str().unwrap();
    let garment = "fixtures/cylinder_noisy.obj";
    let server = [("FLATMESH_SERVER", s.base.as_str())];
    let id_of = |out: &str| -> String {
        let v: Value = serde_json::from_str(out).unwrap_or_else(|e| panic!("{e}: {out}"));
        v["id"].as_str().unwrap().to_string()
    };
    let (ok, out) = run_client(&["upload", garment], &server);
    assert!(ok, "{out}");
    let garment_id = id_of(&out);
    let (ok, out) = run_client(&["upload", body_file], &server);
    assert!(ok, "{out}");
    let body_id = id_of(&out);
    let combos: [[&str; 4]; 4] = [
        ["--mesh", garment, "--reference", body_file],
        ["--mesh", garment, "--reference-mesh-id", &body_id],
        ["--mesh-id", &garment_id, "--reference", body_file],
        ["--mesh-id", &garment_id, "--reference-mesh-id", &body_id],
    ];
    for combo in combos {
        let args = [&["submit", "perturb"][..], &combo].concat();
        let (ok, out) = run_client(&args, &server);
        assert!(ok, "{combo:?}: {out}");
        let id = id_of(&out);
        let j = job(&c, &s, &id).await;
        // Same bytes, same stored mesh (uploads are deduplicated by content).
        assert_eq!(j["mesh_id"], garment_id.as_str(), "{combo:?}: {j}");
        assert_eq!(j["reference_mesh_id"], body_id.as_str(), "{combo:?}: {j}");
        let (ok, out) = run_client(&["wait", &id, "--timeout", "120"], &server);
        assert!(ok, "{combo:?}: {out}");
    }
    // No input at all, and a body given to a kind that uses none: refused, saying why.
    let (ok, out) = run_client(&["submit", "perturb"], &server);
    assert!(!ok && out.contains("--mesh-id or --mesh"), "{out}");
    let (ok, out) = run_client(
        &[
            "submit",
            "flatten",
            "--mesh",
            garment,
            "--reference",
            body_file,
        ],
        &server,
    );
    assert!(!ok && out.contains("reference"), "{out}");
    let slow = dir.join("slow.obj");
    std::fs::write(&slow, slow_obj()).unwrap();
    let (ok, out) = run_client(
        &[
            "submit",
            "flatten",
            "--mesh",
            slow.to_str().unwrap(),
            "--set",
            &format!("max_iterations={}", 100_000),
            "--set",
            "tolerance=1e-300",
        ],
        &server,
    );
    assert!(ok, "{out}");
    let id = id_of(&out);
    let t0 = Instant::now();
    let (ok, out) = run_client(&["wait", &id, "--timeout", "1"], &server);
    assert!(!ok, "{out}");
    assert!(t0.elapsed() < Duration::from_secs(30), "{out}");
    let r = c
        .post(s.url(&format!("/v1/jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202, "a cancel of a running job is accepted");
}

/// The load benchmark reads exactly the environment variables the README lists for it.
#[test]
fn load_benchmark_variables_are_documented() {
    let bench = std::fs::read_to_string("benches/service_load.rs").unwrap();
    // `env("X", default)` and `std::env::var("X")`; not `.env("X", …)`, which sets the
    // server's.
    let mut read = BTreeSet::new();
    let parts: Vec<&str> = bench.split("env(\"").collect();
    for w in parts.windows(2) {
        let name = w[1].split('"').next().unwrap();
        if !w[0].ends_with('.') && name.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
            read.insert(name.to_string());
        }
    }
    for s in bench.split("std::env::var(\"").skip(1) {
        read.insert(s.split('"').next().unwrap().to_string());
    }
    let readme = std::fs::read_to_string("README.md").unwrap();
    let start = readme.find("`cargo bench --bench service_load`").unwrap();
    let para = &readme[start..];
    let para = &para[..para.find("\n\n").unwrap()];
    let listed: BTreeSet<String> = para
        .split('`')
        .skip(1)
        .step_by(2)
        .map(|w| w.split('=').next().unwrap().to_string())
        .filter(|w| w.chars().all(|c| c.is_ascii_uppercase() || c == '_'))
        .collect();
    assert!(read.len() >= 5, "{read:?}");
    assert_eq!(read, listed);
}

/// The job threads run at `--worker-nice` (Linux: read from /proc while a job runs), and a
/// value outside 0–19 is refused at start-up.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn worker_threads_run_at_the_nice_value() {
    let out = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["serve", "--worker-nice", "20"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    if !Path::new("/proc/self/task").exists() {
        eprintln!("SKIPPED: no /proc here");
        return;
    }
    let s = Server::start(
        &tmp("promise-nice"),
        &["--workers", "1", "--worker-nice", "7"],
    );
    let c = client();
    let m = upload(&c, &s, slow_obj()).await;
    let params: Value = serde_json::from_str(SLOW).unwrap();
    let j = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": m["id"], "params": params}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let running = wait_for(&c, &s, id, &["running"]).await;
    assert_eq!(running["status"], "running");
    let mut nice = BTreeMap::new();
    for task in std::fs::read_dir(format!("/proc/{}/task", s.pid())).unwrap() {
        let task = task.unwrap().path();
        let comm = std::fs::read_to_string(task.join("comm")).unwrap_or_default();
        let stat = std::fs::read_to_string(task.join("stat")).unwrap_or_default();
        // Fields after the command's closing parenthesis: state is field 3, nice field 19.
        let Some(rest) = stat.rsplit_once(") ").map(|x| x.1) else {
            continue;
        };
        let n: i32 = rest.split_whitespace().nth(16).unwrap().parse().unwrap();
        nice.insert(comm.trim().to_string(), n);
    }
    // Relative to the nice value this test runs at (the server inherits it; only a
    // privileged process can go below it).
    let own = std::fs::read_to_string("/proc/self/stat").unwrap();
    let own: i32 = own
        .rsplit_once(") ")
        .unwrap()
        .1
        .split_whitespace()
        .nth(16)
        .unwrap()
        .parse()
        .unwrap();
    let worker = nice.get("flatmesh-worker").copied();
    let allowed = if own <= 7 { vec![7] } else { vec![7, own] };
    assert!(
        worker.is_some_and(|w| allowed.contains(&w)),
        "{nice:?} (this process at {own})"
    );
    assert_eq!(nice.get("flatmesh-http"), Some(&own), "{nice:?}");
    c.post(s.url(&format!("/v1/jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
}
