//! How records are shown: the public JSON of jobs and meshes (HTTP responses and webhook
//! payloads alike) and timestamps.

use super::domain::{JobRecord, MeshRecord, Status};
use super::problem::Problem;
use serde_json::{json, Map, Value};

/// RFC 3339 UTC timestamp of milliseconds since the epoch.
pub fn rfc3339(ms: i64) -> String {
    let t = std::time::UNIX_EPOCH + std::time::Duration::from_millis(ms.max(0) as u64);
    humantime::format_rfc3339_millis(t).to_string()
}

/// The progress of an ended job: its final state (`stage` is the status), the iteration it
/// ended at and the stage it was in (`ended_in`), not a stale sub-step.
fn final_progress(j: &JobRecord) -> Value {
    let last = j.progress.as_ref();
    let field = |k: &str| last.and_then(|p| p.get(k)).cloned();
    let max_flattenability = match j.status {
        Status::Succeeded => j
            .outcome
            .as_ref()
            .and_then(|o| o.get("max_flattenability"))
            .cloned(),
        _ => field("max_flattenability"),
    };
    let mut p = json!({
        "stage": j.status.as_str(),
        "iteration": field("iteration").unwrap_or(json!(0)),
        "updated_at": rfc3339(j.finished_at.unwrap_or(j.created_at)),
    });
    if let Some(v) = max_flattenability.filter(|v| !v.is_null()) {
        p["max_flattenability"] = v;
    }
    if let Some(s) = field("stage") {
        p["ended_in"] = s;
    }
    p
}

/// A cancelled job's `error`: why it has no results.
fn cancelled_problem(j: &JobRecord) -> Problem {
    let mut p = Problem::new(
        axum::http::StatusCode::CONFLICT,
        "cancelled",
        if j.started_at.is_some() {
            "the job was cancelled while it ran; it has no results"
        } else {
            "the job was cancelled before it started; it has no results"
        },
    );
    p.title = "Cancelled".into();
    p
}

/// The public JSON of a job. `progress` overrides the stored progress (live value).
pub fn job_json(j: &JobRecord, progress: Option<Value>, base: &str) -> Value {
    let me = format!("{base}/v1/jobs/{}", j.id);
    let mut links = Map::new();
    links.insert("self".into(), json!(me));
    if !j.status.is_terminal() {
        links.insert("cancel".into(), json!(format!("{me}/cancel")));
    }
    if j.status == Status::Succeeded {
        links.insert("result".into(), json!(format!("{me}/result")));
        links.insert("mesh".into(), json!(format!("{me}/mesh?format=glb")));
        if j.artifacts.iter().any(|a| a == "patterns.json") {
            links.insert(
                "patterns".into(),
                json!(format!("{me}/patterns?format=json")),
            );
        }
    }
    let outcome = |k: &str| j.outcome.as_ref().and_then(|o| o.get(k)).cloned();
    json!({
        "id": j.id,
        "kind": j.kind,
        "status": j.status.as_str(),
        "mesh_id": j.mesh_id,
        "reference_mesh_id": j.reference_mesh_id,
        "params": j.params,
        "callback_url": j.callback_url,
        "progress": if j.status.is_terminal() {
            Some(final_progress(j))
        } else {
            progress.or_else(|| j.progress.clone())
        },
        "error": match (&j.error, j.status) {
            (Some(e), _) => Some(Problem::from(e).under(base)),
            (None, Status::Cancelled) => Some(cancelled_problem(j).under(base)),
            (None, _) => None,
        },
        "warnings": outcome("warnings").unwrap_or_else(|| json!([])),
        "attempts": j.attempts,
        "converged": outcome("converged"),
        "max_flattenability": outcome("max_flattenability"),
        "stop_reason": outcome("stop_reason"),
        "created_at": rfc3339(j.created_at),
        "started_at": j.started_at.map(rfc3339),
        "finished_at": j.finished_at.map(rfc3339),
        "expires_at": j.expires_at.map(rfc3339),
        "links": links,
    })
}

/// The public JSON of an uploaded mesh: its summary, id, times and links (under `base`).
pub fn mesh_json(m: &MeshRecord, base: &str) -> Value {
    let mut v = m.summary.clone();
    if let Some(o) = v.as_object_mut() {
        o.insert("id".into(), json!(m.id));
        o.insert("created_at".into(), json!(rfc3339(m.created_at)));
        o.insert("format".into(), json!(m.format));
        o.insert("size".into(), json!(m.size));
        o.insert(
            "links".into(),
            json!({
                "self": format!("{base}/v1/meshes/{}", m.id),
                "report": format!("{base}/v1/meshes/{}/report", m.id),
            }),
        );
    }
    v
}
