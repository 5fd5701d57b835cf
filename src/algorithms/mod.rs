//! Algorithms: one module per capability, each a pure function
//! `run(&Mesh, &Params, &dyn Control) -> Result<Outcome, AlgoError>` that knows nothing of HTTP,
//! files or threads (../shared/DESIGN.md). This module holds what they share: progress and
//! cancellation ([`Control`]), typed parameters parsed from JSON, and the dispatcher by job
//! kind used by the CLI (`flatmesh run`) and the service alike.

pub mod fl_mesh;
pub mod flatten;
pub mod report_job;
pub mod subdivide;

use crate::mesh::Mesh;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

/// One progress report; algorithms send one per iteration.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Progress {
    /// What the algorithm is doing (`newton`, `refine`, `level 2`, `lpfb`, …).
    pub stage: String,
    /// Iteration within the stage.
    pub iteration: usize,
    /// Current ϖ_max (radians), where the algorithm tracks it.
    pub max_flattenability: Option<f64>,
    /// Norm of the last step, where there is one.
    pub step_norm: Option<f64>,
}

/// How an algorithm reports progress and learns that it should stop. Implementations must be
/// cheap: algorithms call them once per iteration.
pub trait Control: Sync {
    /// Record progress.
    fn progress(&self, p: &Progress);
    /// Whether the caller asked to stop; algorithms check once per iteration and then return
    /// [`AlgoError::Cancelled`].
    fn cancelled(&self) -> bool;
}

/// A [`Control`] that ignores progress and can be cancelled through a flag.
#[derive(Debug, Default)]
pub struct Silent {
    /// Set to request cancellation.
    pub cancel: AtomicBool,
}

impl Control for Silent {
    fn progress(&self, _: &Progress) {}
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Why an algorithm did not produce a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlgoError {
    /// The caller cancelled.
    #[error("cancelled")]
    Cancelled,
    /// A parameter is unknown or has a bad value; `key` names it.
    #[error("parameter `{key}`: {message}")]
    InvalidParam {
        /// The parameter's name (empty when the whole object is malformed).
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The job kind does not exist.
    #[error("unknown job kind `{0}` (available: {kinds})", kinds = KINDS.join(", "))]
    UnknownKind(String),
    /// The input cannot be processed, with the element at fault.
    #[error("{0}")]
    Input(String),
}

/// The job kinds implemented, in the order the CLI lists them.
pub const KINDS: &[&str] = &["report", "flatten", "fl-mesh", "subdivide"];

/// What a run produced: an output mesh (for optimisers), and a JSON object of
/// algorithm-specific figures (iterations, converged, history, …) merged into `report.json`.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// The optimised mesh, when the algorithm changes the mesh.
    pub mesh: Option<Mesh>,
    /// Flat patterns, when the algorithm flattens.
    pub patterns: Option<crate::pattern::Patterns>,
    /// Extra figures, a JSON object.
    pub summary: serde_json::Map<String, serde_json::Value>,
    /// Intermediate meshes, for algorithms that make a sequence (`subdivide`: every level's
    /// mesh, the last equal to `mesh`).
    pub levels: Vec<Mesh>,
}

/// Everything a job needs.
#[derive(Debug, Clone)]
pub struct Input {
    /// The mesh to work on.
    pub mesh: Mesh,
    /// A reference body (for `perturb`), when given.
    pub reference: Option<Mesh>,
}

/// Parse typed parameters from a JSON object, naming the offending key on failure. Parameter
/// structs use `#[serde(deny_unknown_fields)]` so that unknown keys are refused.
pub fn parse_params<P: DeserializeOwned>(
    params: &serde_json::Map<String, serde_json::Value>,
) -> Result<P, AlgoError> {
    let value = serde_json::Value::Object(params.clone());
    serde_path_to_error::deserialize(value).map_err(|e| {
        // The path names the member at fault (`levels`, `curves[0].edge`, `fl_mesh.nope` for
        // an unknown nested field); "." is the object itself.
        let path = e.path().to_string();
        let msg = e.inner().to_string();
        let key = if path == "." { String::new() } else { path };
        AlgoError::InvalidParam { key, message: msg }
    })
}

/// Check a job's parameters without running it (the service refuses bad jobs up front).
pub fn validate(
    kind: &str,
    params: &serde_json::Map<String, serde_json::Value>,
) -> Result<(), AlgoError> {
    match kind {
        "report" => parse_params::<report_job::Params>(params).map(|_| ()),
        "flatten" => parse_params::<flatten::Params>(params)?.check(),
        "fl-mesh" => parse_params::<fl_mesh::Params>(params)?.check(),
        "subdivide" => parse_params::<subdivide::Params>(params)?.check(),
        other => Err(AlgoError::UnknownKind(other.to_string())),
    }
}

/// Run a job of `kind` on `input`.
pub fn run(
    kind: &str,
    input: &Input,
    params: &serde_json::Map<String, serde_json::Value>,
    control: &dyn Control,
) -> Result<Outcome, AlgoError> {
    match kind {
        "report" => report_job::run(&input.mesh, &parse_params(params)?, control),
        "flatten" => flatten::run(&input.mesh, &parse_params(params)?, control),
        "fl-mesh" => fl_mesh::run(&input.mesh, &parse_params(params)?, control),
        "subdivide" => subdivide::run(&input.mesh, &parse_params(params)?, control),
        other => Err(AlgoError::UnknownKind(other.to_string())),
    }
}
