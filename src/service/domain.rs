//! The records of the job service: what a job and an uploaded mesh are, independent of how
//! they are stored (the [`super::store::Store`] backends) or shown (the HTTP handlers, which
//! turn a [`JobError`] into an RFC 9457 problem).

use serde::{Deserialize, Serialize};

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Lifecycle of a job (AIP-151 style): queued → running → succeeded | failed | cancelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Waiting for a worker.
    Queued,
    /// On a worker.
    Running,
    /// Finished with results.
    Succeeded,
    /// Finished with an error (see `error`).
    Failed,
    /// Cancelled by the client.
    Cancelled,
}

impl Status {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Queued => "queued",
            Status::Running => "running",
            Status::Succeeded => "succeeded",
            Status::Failed => "failed",
            Status::Cancelled => "cancelled",
        }
    }
    /// Parse the wire name.
    pub fn parse(s: &str) -> Option<Status> {
        Some(match s {
            "queued" => Status::Queued,
            "running" => Status::Running,
            "succeeded" => Status::Succeeded,
            "failed" => Status::Failed,
            "cancelled" => Status::Cancelled,
            _ => return None,
        })
    }
    /// Whether the job has ended.
    pub fn is_terminal(self) -> bool {
        matches!(self, Status::Succeeded | Status::Failed | Status::Cancelled)
    }
}

/// An uploaded mesh. Its bytes are the blob `meshes/{id}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshRecord {
    /// Id (`m_…`).
    pub id: String,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// `obj`, `gltf`, `glb` or `off`.
    pub format: String,
    /// Bytes uploaded.
    pub size: u64,
    /// Hex SHA-256 of the bytes (the ETag).
    pub sha256: String,
    /// Summary shown to clients (vertices, faces, patches, max ϖ, warnings).
    pub summary: serde_json::Value,
    /// Whose it is: the tenant of the API key that uploaded it (`""`: the default tenant,
    /// of bare keys and of a server without keys). Only its tenant sees it.
    #[serde(default)]
    pub tenant: String,
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRecord {
    /// Insertion order (list order, page tokens).
    pub seq: i64,
    /// Id (`j_…`).
    pub id: String,
    /// Job kind (a [`crate::jobs::Kind`] name).
    pub kind: String,
    /// Input mesh.
    pub mesh_id: String,
    /// Reference mesh, for kinds that use one.
    pub reference_mesh_id: Option<String>,
    /// Validated parameters.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Webhook target.
    pub callback_url: Option<String>,
    /// Lifecycle state.
    pub status: Status,
    /// Last progress report (JSON object), persisted on state changes.
    pub progress: Option<serde_json::Value>,
    /// Why the job failed.
    pub error: Option<JobError>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    /// When a worker last started it.
    pub started_at: Option<i64>,
    /// When it ended.
    pub finished_at: Option<i64>,
    /// When its results are deleted.
    pub expires_at: Option<i64>,
    /// How many times a worker started it (restarts re-queue running jobs).
    pub attempts: u32,
    /// Names of the stored artifacts (`report.json`, `mesh.glb`, …), blobs `jobs/{id}/{name}`.
    pub artifacts: Vec<String>,
    /// What a succeeded job reached, shown at the top level of the job: `converged`,
    /// `max_flattenability` (measured on the output), `stop_reason`.
    pub outcome: Option<serde_json::Value>,
    /// Client's `Idempotency-Key`.
    pub idempotency_key: Option<String>,
    /// Hash of the request that created the job (to detect a reused key).
    pub request_hash: Option<String>,
    /// The API's base URL as the submitting client reached it (`https://host[/prefix]`),
    /// for the absolute links of the job's webhook when no public URL is configured.
    pub base_url: Option<String>,
    /// Whose it is (as [`MeshRecord::tenant`]).
    pub tenant: String,
}

impl JobRecord {
    /// A queued job of `kind` on mesh `mesh_id` with no parameters, callback or history.
    pub fn queued(id: &str, kind: &str, mesh_id: &str, created_at: i64) -> JobRecord {
        JobRecord {
            seq: 0,
            id: id.into(),
            kind: kind.into(),
            mesh_id: mesh_id.into(),
            reference_mesh_id: None,
            params: serde_json::Map::new(),
            callback_url: None,
            status: Status::Queued,
            progress: None,
            error: None,
            created_at,
            started_at: None,
            finished_at: None,
            expires_at: None,
            attempts: 0,
            artifacts: vec![],
            outcome: None,
            idempotency_key: None,
            request_hash: None,
            base_url: None,
            tenant: String::new(),
        }
    }
}

/// What kind of failure ended a job; each is a problem type of the API (`/problems/{slug}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCode {
    /// The job's request or input mesh is unusable (names the field).
    InvalidRequest,
    /// The run exceeded the job time limit.
    TimeLimit,
    /// The algorithm stopped with an error.
    AlgorithmFailed,
    /// The job's process kept stopping while it ran (max attempts).
    Interrupted,
    /// Something broke on our side (storage, a panic).
    Internal,
}

impl ErrorCode {
    const ALL: [ErrorCode; 5] = [
        ErrorCode::InvalidRequest,
        ErrorCode::TimeLimit,
        ErrorCode::AlgorithmFailed,
        ErrorCode::Interrupted,
        ErrorCode::Internal,
    ];
    /// The problem type slug.
    pub fn slug(self) -> &'static str {
        match self {
            ErrorCode::InvalidRequest => "invalid-request",
            ErrorCode::TimeLimit => "time-limit",
            ErrorCode::AlgorithmFailed => "algorithm-failed",
            ErrorCode::Interrupted => "interrupted",
            ErrorCode::Internal => "internal",
        }
    }
    /// Whether the fault is on the server's side (HTTP 500) rather than the request's (422).
    pub fn is_server_fault(self) -> bool {
        matches!(self, ErrorCode::Interrupted | ErrorCode::Internal)
    }
}

impl Serialize for ErrorCode {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&format!("/problems/{}", self.slug()))
    }
}

impl<'de> Deserialize<'de> for ErrorCode {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let uri = String::deserialize(d)?;
        let slug = uri.strip_prefix("/problems/").unwrap_or(&uri);
        ErrorCode::ALL
            .into_iter()
            .find(|c| c.slug() == slug)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown job error type `{uri}`")))
    }
}

/// Why a job failed, as stored. Serialised with the member names of a problem object
/// (`type`, `detail`, `field`), so rows written when the stored error was the HTTP problem
/// itself still decode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobError {
    /// The kind of failure.
    #[serde(rename = "type")]
    pub code: ErrorCode,
    /// What happened, for the client.
    pub detail: String,
    /// The request member at fault (`params.tolerance`, `mesh_id`, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

impl JobError {
    /// An error of `code`.
    pub fn new(code: ErrorCode, detail: impl Into<String>) -> JobError {
        JobError {
            code,
            detail: detail.into(),
            field: None,
        }
    }
    /// The request member `field` is at fault.
    pub fn invalid(field: &str, detail: impl Into<String>) -> JobError {
        JobError {
            field: Some(field.to_string()),
            ..JobError::new(ErrorCode::InvalidRequest, detail)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_stored_as_problems_still_decode() {
        let old = r#"{"type":"/problems/time-limit","title":"Unprocessable Entity","status":422,"detail":"too long"}"#;
        let e: JobError = serde_json::from_str(old).unwrap();
        assert_eq!(e, JobError::new(ErrorCode::TimeLimit, "too long"));
        let back: JobError = serde_json::from_str(&serde_json::to_string(&e).unwrap()).unwrap();
        assert_eq!(back, e);
        let bad = r#"{"type":"/problems/nope","detail":"x"}"#;
        assert!(serde_json::from_str::<JobError>(bad).is_err());
    }
}
