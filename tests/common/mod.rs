//! The harness of the black-box service tests: a real `flatmesh serve` on a random loopback
//! port, requests through reqwest, every JSON body checked against openapi.yaml's schemas.

#![allow(dead_code)] // each test binary uses part of it

pub mod pg;

use serde_json::Value;
use std::cell::RefCell;
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub struct Server {
    child: Child,
    /// `http://127.0.0.1:PORT`.
    pub base: String,
    /// Its data directory.
    pub dir: PathBuf,
}

impl Server {
    pub fn start(dir: &Path, args: &[&str]) -> Server {
        Server::start_with_env(dir, args, &[])
    }
    /// [`Server::start`] with these environment variables set; without them the keys and
    /// CORS origins of the caller's shell are cleared, so that it cannot change a test.
    pub fn start_with_env(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Server {
        std::fs::create_dir_all(dir).unwrap();
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join("server.log"))
            .unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
            .arg("serve")
            .args(["--bind", "127.0.0.1:0", "--data-dir"])
            .arg(dir)
            .args(args)
            .env_remove("FLATMESH_API_KEYS")
            .env_remove("FLATMESH_CORS_ORIGINS")
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .expect("start flatmesh serve");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
            .to_string();
        Server {
            child,
            base,
            dir: dir.to_path_buf(),
        }
    }
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
    /// SIGKILL: the process dies without any chance to tidy up.
    pub fn kill(mut self) -> PathBuf {
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.dir.clone()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("flatmesh-svc-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

pub fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(format!("fixtures/{name}.obj")).expect("fixture file")
}

/// A long thin strip (3000 × 3 square cells, slightly curved) whose flatten with [`SLOW`] runs
/// for minutes at a few ms per iteration: long enough to outlast any test's time limit on a fast
/// machine (the 250² saddle used before finished its 100000 iterations in about 3 s, under the
/// two-process test's 4 s limit), short per iteration so cancels and progress come promptly.
pub fn slow_obj() -> Vec<u8> {
    let h = 0.001;
    grid_obj(3000, 3, |i, j| {
        let (x, y) = (i as f64 * h, j as f64 * h);
        format!("{x:.6} {y:.6} {:.6}", 0.03 * ((x - 1.5).powi(2) - y * y))
    })
}

/// An OBJ grid of nx × ny cells, two triangles each; `vertex(i, j)` writes the coordinates
/// of grid point (i, j), row by row.
pub fn grid_obj(nx: usize, ny: usize, mut vertex: impl FnMut(usize, usize) -> String) -> Vec<u8> {
    let mut s = String::new();
    for j in 0..=ny {
        for i in 0..=nx {
            s += &format!("v {}\n", vertex(i, j));
        }
    }
    for j in 0..ny {
        for i in 0..nx {
            let a = j * (nx + 1) + i + 1;
            let (b, c) = (a + 1, a + nx + 1);
            s += &format!("f {a} {b} {}\nf {a} {} {c}\n", c + 1, c + 1);
        }
    }
    s.into_bytes()
}

pub const SLOW: &str = r#"{"tolerance": 1e-300, "max_iterations": 100000}"#;

// ---------------------------------------------------------------- openapi

pub fn openapi() -> Value {
    let text = std::fs::read_to_string("openapi.yaml").unwrap();
    let y: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    serde_json::to_value(y).unwrap()
}

/// Validate `v` against `#/components/schemas/{name}` of openapi.yaml (JSON Schema 2020-12,
/// formats asserted), with boon: jsonschema's build took 150 s of CI's CPU, boon's 10.
pub fn check(name: &str, v: &Value) {
    const DOC: &str = "http://flatmesh.test/openapi.json";
    struct Validator {
        compiler: boon::Compiler,
        schemas: boon::Schemas,
        compiled: HashMap<String, boon::SchemaIndex>,
    }
    thread_local! {
        static VALIDATOR: RefCell<Validator> = RefCell::new({
            let mut compiler = boon::Compiler::new();
            compiler.set_default_draft(boon::Draft::V2020_12);
            compiler.enable_format_assertions();
            compiler.add_resource(DOC, openapi()).expect("openapi.yaml loads");
            Validator { compiler, schemas: boon::Schemas::new(), compiled: HashMap::new() }
        });
    }
    VALIDATOR.with(|cell| {
        let mut guard = cell.borrow_mut();
        let Validator {
            compiler,
            schemas,
            compiled,
        } = &mut *guard;
        let index = *compiled.entry(name.to_string()).or_insert_with(|| {
            compiler
                .compile(&format!("{DOC}#/components/schemas/{name}"), schemas)
                .unwrap_or_else(|e| panic!("schema {name} compiles: {e:#}"))
        });
        if let Err(e) = schemas.validate(v, index) {
            panic!("{name} does not match openapi.yaml: {e:#}\n{v:#}");
        }
    });
}

pub async fn json_of(res: reqwest::Response, schema: &str) -> Value {
    let v: Value = res.json().await.expect("JSON body");
    check(schema, &v);
    v
}

/// Assert a problem+json answer of `status`, valid against the schema; returns it.
pub async fn problem(res: reqwest::Response, status: u16) -> Value {
    assert_eq!(res.status().as_u16(), status, "status");
    assert_eq!(
        res.headers()["content-type"].to_str().unwrap(),
        "application/problem+json"
    );
    let v = json_of(res, "Problem").await;
    assert_eq!(v["status"], status);
    v
}

/// A multipart part holding fixture `name` as an OBJ file called `file`.
pub fn obj_part(name: &str, file: &str) -> reqwest::multipart::Part {
    reqwest::multipart::Part::bytes(fixture(name))
        .file_name(file.to_string())
        .mime_str("model/obj")
        .unwrap()
}

/// `POST /v1/jobs` with a multipart body.
pub async fn post_jobs_form(
    c: &reqwest::Client,
    s: &Server,
    form: reqwest::multipart::Form,
) -> reqwest::Response {
    c.post(s.url("/v1/jobs"))
        .multipart(form)
        .send()
        .await
        .unwrap()
}

pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap()
}

pub async fn upload(c: &reqwest::Client, s: &Server, bytes: Vec<u8>) -> Value {
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body(bytes)
        .send()
        .await
        .unwrap();
    // 200: these bytes were uploaded before, the stored mesh.
    assert!([200, 201].contains(&r.status().as_u16()), "{}", r.status());
    json_of(r, "Mesh").await
}

pub async fn submit(c: &reqwest::Client, s: &Server, body: Value) -> Value {
    check("JobRequest", &body);
    let r = c.post(s.url("/v1/jobs")).json(&body).send().await.unwrap();
    assert_eq!(r.status(), 202, "{:?}", r.text().await);
    json_of(r, "Job").await
}

/// GET a succeeded job's result (report.json), checked against the `Report` schema.
pub async fn job_result(c: &reqwest::Client, s: &Server, id: &str) -> Value {
    json_of(
        c.get(s.url(&format!("/v1/jobs/{id}/result")))
            .send()
            .await
            .unwrap(),
        "Report",
    )
    .await
}

/// GET `path` and its body, whatever the status.
pub async fn download(c: &reqwest::Client, s: &Server, path: &str) -> Vec<u8> {
    c.get(s.url(path))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap()
        .to_vec()
}

pub async fn job(c: &reqwest::Client, s: &Server, id: &str) -> Value {
    let r = c
        .get(s.url(&format!("/v1/jobs/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    json_of(r, "Job").await
}

/// A reference body for `perturb` around the `cylinder_noisy` fixture: the noiseless
/// cylinder pulled towards its axis (x, y by 0.9), as OBJ (open: accepted with a warning).
pub fn shrunk_cylinder_obj() -> Vec<u8> {
    let (cyl, _) = flatmesh::io::load(&fixture("cylinder"), flatmesh::io::Format::Obj).unwrap();
    let mut obj = String::new();
    for p in cyl.positions() {
        obj += &format!("v {} {} {}\n", 0.9 * p[0], 0.9 * p[1], p[2]);
    }
    for t in cyl.triangles() {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    obj.into_bytes()
}

/// Every triangle edge of a `Patterns` JSON: (its length in the drawing, the length of the
/// same edge on the 3D mesh whose `positions` the pieces' `vertex_ids` index).
pub fn pattern_edges(pat: &Value, positions: &[[f64; 3]]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for piece in pat["pieces"].as_array().unwrap() {
        let vid: Vec<usize> = piece["vertex_ids"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let uv: Vec<[f64; 2]> = piece["uv"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()])
            .collect();
        for t in piece["triangles"].as_array().unwrap() {
            for k in 0..3 {
                let a = t[k].as_u64().unwrap() as usize;
                let b = t[(k + 1) % 3].as_u64().unwrap() as usize;
                let d2 = ((uv[a][0] - uv[b][0]).powi(2) + (uv[a][1] - uv[b][1]).powi(2)).sqrt();
                let (p, q) = (positions[vid[a]], positions[vid[b]]);
                let d3 = (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt();
                out.push((d2, d3));
            }
        }
    }
    out
}

/// Every file under `dir`, recursively, sorted.
pub fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The server's Prometheus text.
pub async fn metrics_text(c: &reqwest::Client, s: &Server) -> String {
    c.get(s.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap()
}

pub async fn wait_for(c: &reqwest::Client, s: &Server, id: &str, want: &[&str]) -> Value {
    let start = Instant::now();
    loop {
        let j = job(c, s, id).await;
        if want.contains(&j["status"].as_str().unwrap()) {
            return j;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "job {id} still {} (waiting for {want:?})",
            j["status"]
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}
