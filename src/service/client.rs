//! `flatmesh client`: talk to a running server (upload, submit, wait, download, health).

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Connection options and the command.
#[derive(Debug, clap::Args)]
pub struct ClientArgs {
    /// Base URL of the server.
    #[arg(long, env = "FLATMESH_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
    /// Bearer API key.
    #[arg(long, env = "FLATMESH_API_KEY", hide_env_values = true)]
    pub api_key: Option<String>,
    /// What to do.
    #[command(subcommand)]
    pub command: ClientCommand,
}

/// Client subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ClientCommand {
    /// Upload a mesh (OBJ, glTF, GLB); prints the mesh JSON (its `id`).
    Upload {
        /// The mesh file.
        file: PathBuf,
    },
    /// Submit a job; prints the job JSON (its `id`).
    Submit {
        /// Job kind.
        kind: String,
        /// Id of an uploaded mesh.
        #[arg(long, conflicts_with = "mesh")]
        mesh_id: Option<String>,
        /// A mesh file, uploaded with the job (one multipart request when the reference, if
        /// any, is a file too; else uploaded first).
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Id of an uploaded reference mesh.
        #[arg(long, conflicts_with = "reference")]
        reference_mesh_id: Option<String>,
        /// A reference mesh file, uploaded with the job.
        #[arg(long)]
        reference: Option<PathBuf>,
        /// A parameter, KEY=VALUE (VALUE read as JSON when it parses).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Webhook URL called when the job ends.
        #[arg(long)]
        callback_url: Option<String>,
        /// Idempotency key (a retried submit returns the same job).
        #[arg(long)]
        idempotency_key: Option<String>,
    },
    /// Wait for a job to end, showing progress; exit 0 only if it succeeded.
    Wait {
        /// Job id.
        job_id: String,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 3600)]
        timeout: u64,
    },
    /// Download a result of a succeeded job.
    Download {
        /// Job id.
        job_id: String,
        /// `result` (report JSON), `mesh` or `patterns`.
        #[arg(long, default_value = "result")]
        what: String,
        /// glb|gltf|obj for mesh, json|svg|dxf for patterns.
        #[arg(long)]
        format: Option<String>,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Exit 0 when `GET /healthz` answers 200 (container healthchecks).
    Health,
}

fn sets(sets: &[String]) -> Result<serde_json::Map<String, Value>, String> {
    let mut m = serde_json::Map::new();
    for s in sets {
        let (k, v) = s
            .split_once('=')
            .ok_or_else(|| format!("--set {s:?}: expected KEY=VALUE"))?;
        let v = serde_json::from_str(v).unwrap_or_else(|_| Value::String(v.into()));
        m.insert(k.trim().to_string(), v);
    }
    Ok(m)
}

fn mesh_media(path: &std::path::Path) -> &'static str {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("glb") => "model/gltf-binary",
        Some("gltf") => "model/gltf+json",
        Some("obj") => "model/obj",
        _ => "application/octet-stream",
    }
}

/// Read a response: JSON on success, the problem's detail as the error otherwise.
/// `POST /v1/meshes` with the file's bytes; the stored mesh's JSON.
async fn upload(http: &reqwest::Client, base: &str, file: &Path) -> Result<Value, String> {
    let bytes = std::fs::read(file).map_err(|x| format!("{}: {x}", file.display()))?;
    let r = http
        .post(format!("{base}/v1/meshes"))
        .header("content-type", mesh_media(file))
        .body(bytes)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    json_or_problem(r).await
}

/// The id of the mesh stored from `file`.
async fn uploaded_id(http: &reqwest::Client, base: &str, file: &Path) -> Result<String, String> {
    let m = upload(http, base, file).await?;
    m["id"]
        .as_str()
        .map(str::to_string)
        .ok_or_else(|| format!("{}: the upload answered no mesh id", file.display()))
}

/// A multipart part holding the file, named and typed by its extension.
fn file_part(path: &Path) -> Result<reqwest::multipart::Part, String> {
    let bytes = std::fs::read(path).map_err(|x| format!("{}: {x}", path.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "mesh".into());
    reqwest::multipart::Part::bytes(bytes)
        .file_name(name)
        .mime_str(mesh_media(path))
        .map_err(|e| e.to_string())
}

async fn json_or_problem(res: reqwest::Response) -> Result<Value, String> {
    let status = res.status();
    let body = res.bytes().await.map_err(|e| e.to_string())?;
    let v: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
    if status.is_success() {
        Ok(v)
    } else {
        let detail = v
            .get("detail")
            .and_then(Value::as_str)
            .map(str::to_string)
            .unwrap_or_else(|| String::from_utf8_lossy(&body).into_owned());
        let field = v
            .get("field")
            .and_then(Value::as_str)
            .map(|f| format!(" [{f}]"))
            .unwrap_or_default();
        Err(format!("{status}: {detail}{field}"))
    }
}

/// Run a client command; the error is one line for stderr.
pub fn run(args: ClientArgs) -> Result<(), String> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    rt.block_on(run_async(args))
}

async fn run_async(args: ClientArgs) -> Result<(), String> {
    let base = args.server.trim_end_matches('/').to_string();
    let mut headers = reqwest::header::HeaderMap::new();
    if let Some(k) = &args.api_key {
        headers.insert(
            reqwest::header::AUTHORIZATION,
            format!("Bearer {k}").parse().map_err(|_| "bad API key")?,
        );
    }
    let http = reqwest::Client::builder()
        .default_headers(headers)
        .user_agent(concat!("flatmesh-client/", env!("CARGO_PKG_VERSION")))
        .build()
        .map_err(|e| e.to_string())?;
    let e = |e: reqwest::Error| e.to_string();
    match args.command {
        ClientCommand::Health => {
            let r = http
                .get(format!("{base}/healthz"))
                .timeout(Duration::from_secs(5))
                .send()
                .await
                .map_err(e)?;
            if r.status().is_success() {
                Ok(())
            } else {
                Err(format!("unhealthy: {}", r.status()))
            }
        }
        ClientCommand::Upload { file } => {
            println!("{}", upload(&http, &base, &file).await?);
            Ok(())
        }
        ClientCommand::Submit {
            kind,
            mesh_id,
            mesh,
            reference_mesh_id,
            reference,
            set,
            callback_url,
            idempotency_key,
        } => {
            let params = sets(&set)?;
            let mut req = http.post(format!("{base}/v1/jobs"));
            if let Some(k) = idempotency_key {
                req = req.header("idempotency-key", k);
            }
            // The multipart job part names no mesh ids: with an id for one input and a file
            // for the other, the file is uploaded first and the job sent as JSON.
            let req = if let (Some(path), None) = (&mesh, &reference_mesh_id) {
                let job = serde_json::json!({"kind": kind, "params": params, "callback_url": callback_url});
                let mut form = reqwest::multipart::Form::new()
                    .part(
                        "job",
                        reqwest::multipart::Part::text(job.to_string())
                            .mime_str("application/json")
                            .map_err(e)?,
                    )
                    .part("mesh", file_part(path)?);
                if let Some(r) = &reference {
                    form = form.part("reference", file_part(r)?);
                }
                req.multipart(form)
            } else {
                let mesh_id = match (mesh_id, &mesh) {
                    (Some(id), _) => id,
                    (None, Some(path)) => uploaded_id(&http, &base, path).await?,
                    (None, None) => return Err("give --mesh-id or --mesh".into()),
                };
                let reference_mesh_id = match (reference_mesh_id, &reference) {
                    (Some(id), _) => Some(id),
                    (None, Some(path)) => Some(uploaded_id(&http, &base, path).await?),
                    (None, None) => None,
                };
                req.json(&serde_json::json!({
                    "kind": kind, "mesh_id": mesh_id, "reference_mesh_id": reference_mesh_id,
                    "params": params, "callback_url": callback_url,
                }))
            };
            let r = req.send().await.map_err(e)?;
            println!("{}", json_or_problem(r).await?);
            Ok(())
        }
        ClientCommand::Wait { job_id, timeout } => {
            let start = Instant::now();
            let mut etag: Option<String> = None;
            let mut last = Value::Null;
            let tty = std::io::IsTerminal::is_terminal(&std::io::stderr());
            loop {
                let mut req = http.get(format!("{base}/v1/jobs/{job_id}"));
                if let Some(t) = &etag {
                    req = req.header("if-none-match", t);
                }
                let r = req.send().await.map_err(e)?;
                if r.status() != reqwest::StatusCode::NOT_MODIFIED {
                    etag = r
                        .headers()
                        .get("etag")
                        .and_then(|v| v.to_str().ok())
                        .map(str::to_string);
                    last = json_or_problem(r).await?;
                    let status = last["status"].as_str().unwrap_or("?");
                    let p = &last["progress"];
                    let mut line = format!(
                        "{job_id} {status} [{:>5.1}s]",
                        start.elapsed().as_secs_f64()
                    );
                    if let Some(stage) = p["stage"].as_str() {
                        line += &format!(" {stage} #{}", p["iteration"]);
                        if let Some(w) = p["max_flattenability"].as_f64() {
                            line += &format!(" ϖ_max {w:.3e}");
                        }
                    }
                    if tty {
                        eprint!("\r\x1b[2K{line}");
                    } else {
                        eprintln!("{line}");
                    }
                }
                match last["status"].as_str() {
                    Some("succeeded") => {
                        if tty {
                            eprintln!();
                        }
                        println!("{last}");
                        return Ok(());
                    }
                    Some("failed") | Some("cancelled") => {
                        if tty {
                            eprintln!();
                        }
                        println!("{last}");
                        return Err(format!(
                            "job {}: {}",
                            last["status"].as_str().unwrap_or(""),
                            last["error"]["detail"].as_str().unwrap_or("")
                        ));
                    }
                    _ => {}
                }
                if start.elapsed() > Duration::from_secs(timeout) {
                    return Err(format!("timed out after {timeout} s"));
                }
                tokio::time::sleep(Duration::from_millis(250)).await;
            }
        }
        ClientCommand::Download {
            job_id,
            what,
            format,
            out,
        } => {
            let url = match what.as_str() {
                "result" => format!("{base}/v1/jobs/{job_id}/result"),
                "mesh" | "patterns" => {
                    let f = format
                        .unwrap_or_else(|| if what == "mesh" { "glb" } else { "json" }.to_string());
                    format!("{base}/v1/jobs/{job_id}/{what}?format={f}")
                }
                other => return Err(format!("--what {other}: expected result, mesh or patterns")),
            };
            let r = http.get(url).send().await.map_err(e)?;
            if !r.status().is_success() {
                return Err(json_or_problem(r).await.err().unwrap_or_default());
            }
            let bytes = r.bytes().await.map_err(e)?;
            std::fs::write(&out, &bytes).map_err(|x| format!("{}: {x}", out.display()))?;
            println!("{}", out.display());
            Ok(())
        }
    }
}
