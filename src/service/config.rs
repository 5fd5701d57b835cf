//! Configuration of `flatmesh serve`: flags, each with an environment variable.

use std::path::PathBuf;
use std::time::Duration;

fn parse_duration(s: &str) -> Result<Duration, String> {
    if let Ok(secs) = s.parse::<u64>() {
        return Ok(Duration::from_secs(secs));
    }
    humantime::parse_duration(s).map_err(|e| e.to_string())
}

fn parse_size(s: &str) -> Result<usize, String> {
    let s = s.trim();
    let (num, mult) = match s.find(|c: char| !c.is_ascii_digit()) {
        None => (s, 1usize),
        Some(i) => {
            let m = match s[i..].trim().to_ascii_lowercase().as_str() {
                "b" => 1,
                "k" | "kb" | "kib" => 1 << 10,
                "m" | "mb" | "mib" => 1 << 20,
                "g" | "gb" | "gib" => 1 << 30,
                other => return Err(format!("unknown size unit `{other}`")),
            };
            (&s[..i], m)
        }
    };
    num.parse::<usize>()
        .map_err(|e| e.to_string())?
        .checked_mul(mult)
        .ok_or_else(|| "size too large".to_string())
}

/// Configuration of `flatmesh serve`; every flag has an environment variable.
#[derive(Debug, Clone, clap::Args)]
pub struct Config {
    /// Address to listen on (port 0 picks a free port; the address is printed on stdout).
    #[arg(long, env = "FLATMESH_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Directory of the embedded store (SQLite index, uploads, results); with
    /// `--database-url`, only the generated webhook secret is kept there.
    #[arg(long, env = "FLATMESH_DATA_DIR", default_value = "flatmesh-data")]
    pub data_dir: PathBuf,
    /// PostgreSQL database shared by every replica (`postgres://user:pass@host:5432/db`):
    /// jobs, uploads and results all live there. Without it, the embedded SQLite store in
    /// the data directory.
    #[arg(long, env = "FLATMESH_DATABASE_URL", hide_env_values = true)]
    pub database_url: Option<String>,
    /// Most PostgreSQL connections of this replica.
    #[arg(long, env = "FLATMESH_DATABASE_CONNECTIONS", default_value_t = 16)]
    pub database_connections: usize,
    /// Worker threads running jobs (0: one per core).
    #[arg(long, env = "FLATMESH_WORKERS", default_value_t = 0)]
    pub workers: usize,
    /// Largest request body (uploads), e.g. `256MiB`.
    #[arg(long, env = "FLATMESH_MAX_UPLOAD", default_value = "256MiB", value_parser = parse_size)]
    pub max_upload: usize,
    /// Most triangles (and vertices) an uploaded mesh may expand to, after glTF instancing
    /// and polygon triangulation, counted before it is read; beyond it the upload gets 413.
    /// Parsing takes up to about 200 bytes per triangle, two uploads at a time.
    #[arg(long, env = "FLATMESH_MAX_TRIANGLES", default_value_t = 2_000_000)]
    pub max_triangles: usize,
    /// Most jobs waiting for a worker; beyond it submits get 429.
    #[arg(long, env = "FLATMESH_MAX_QUEUED", default_value_t = 64)]
    pub max_queued: usize,
    /// Wall-clock limit of one job run, e.g. `30m`; a step expected to end past it is not
    /// started (the job then fails with `time-limit`).
    #[arg(long, env = "FLATMESH_JOB_TIME_LIMIT", default_value = "1h", value_parser = parse_duration)]
    pub job_time_limit: Duration,
    /// How long results of ended jobs are kept, and uploads that no job uses, e.g. `7d`.
    #[arg(long, env = "FLATMESH_RETENTION", default_value = "7d", value_parser = parse_duration)]
    pub retention: Duration,
    /// Runs of a job interrupted by a restart before it fails.
    #[arg(long, env = "FLATMESH_MAX_ATTEMPTS", default_value_t = 3)]
    pub max_attempts: u32,
    /// How long a worker's claim on a running job lasts without a heartbeat (it renews it
    /// every quarter of that): a job whose process died runs again after this, e.g. `30s`.
    #[arg(long, env = "FLATMESH_LEASE", default_value = "30s", value_parser = parse_duration)]
    pub lease: Duration,
    /// Nice value of the job threads (Linux; 0-19): higher keeps HTTP answers fast while
    /// every worker is busy.
    #[arg(long, env = "FLATMESH_WORKER_NICE", default_value_t = 10, value_parser = clap::value_parser!(i32).range(0..=19))]
    pub worker_nice: i32,
    /// The API's public base URL (`https://flatmesh.example.com`, with a path prefix if it is
    /// served under one) for absolute links, `Location` headers, problem types and webhook
    /// payloads; without it they are built from each request's `Forwarded` /
    /// `X-Forwarded-Proto` / `X-Forwarded-Host` or `Host` header.
    #[arg(long, env = "FLATMESH_PUBLIC_URL", value_parser = parse_public_url)]
    pub public_url: Option<String>,
    /// Bearer API keys (comma-separated); when set, every /v1 route requires one.
    #[arg(long = "api-key", env = "FLATMESH_API_KEYS", value_delimiter = ',')]
    pub api_keys: Vec<String>,
    /// Origins allowed by CORS (comma-separated, `*` for any); none: no CORS headers.
    #[arg(
        long = "cors-origin",
        env = "FLATMESH_CORS_ORIGINS",
        value_delimiter = ','
    )]
    pub cors_origins: Vec<String>,
    /// Webhook signing secret `whsec_<base64>`; without it one is generated and kept in the
    /// data directory (`webhook_secret`), or with `--database-url` in the database, shared
    /// by every replica.
    #[arg(long, env = "FLATMESH_WEBHOOK_SECRET", hide_env_values = true)]
    pub webhook_secret: Option<String>,
    /// Allow webhooks to private, loopback and link-local addresses.
    #[arg(long, env = "FLATMESH_ALLOW_PRIVATE_CALLBACKS")]
    pub allow_private_callbacks: bool,
    /// Deadline of one HTTP request (uploads included), e.g. `5m`.
    #[arg(long, env = "FLATMESH_REQUEST_TIMEOUT", default_value = "5m", value_parser = parse_duration)]
    pub request_timeout: Duration,
    /// Most client connections open at once; further ones wait to be accepted. Each takes a
    /// file descriptor: allow this plus about 256 (`ulimit -n`).
    #[arg(long, env = "FLATMESH_MAX_CONNECTIONS", default_value_t = 1024)]
    pub max_connections: usize,
    /// Time a client has to send a request's head (request line and headers), and most time
    /// a keep-alive connection stays idle, e.g. `10s`.
    #[arg(long, env = "FLATMESH_HEADER_TIMEOUT", default_value = "10s", value_parser = parse_duration)]
    pub header_timeout: Duration,
    /// Delays between webhook attempts, comma-separated (e.g. `1s,5s,30s,2m,10m`).
    #[arg(long, env = "FLATMESH_WEBHOOK_BACKOFF", value_delimiter = ',', value_parser = parse_duration, default_value = "1s,5s,30s,2m,10m")]
    pub webhook_backoff: Vec<Duration>,
}

/// An absolute http(s) URL without query or fragment, returned without its trailing `/`.
fn parse_public_url(s: &str) -> Result<String, String> {
    let u = url::Url::parse(s).map_err(|e| format!("not a URL: {e}"))?;
    if !matches!(u.scheme(), "http" | "https") || u.host_str().is_none() {
        return Err("must be an http(s) URL with a host".into());
    }
    if u.query().is_some() || u.fragment().is_some() {
        return Err("must not have a query or fragment".into());
    }
    Ok(u.as_str().trim_end_matches('/').to_string())
}
