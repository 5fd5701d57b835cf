//! Algorithms: one module per capability, each a pure function
//! `run(&Mesh, &Params, &dyn Control) -> Result<Outcome, AlgoError>` that knows nothing of HTTP,
//! files or threads (../shared/DESIGN.md). This module holds what they share: progress and
//! cancellation ([`Control`]), typed parameters parsed from JSON, and the shape of an outcome.
//! Which algorithm a job kind runs is the registry's business ([`crate::jobs`]).

pub mod develop;
pub mod fl_mesh;
pub mod flatten;
pub mod perturb;
pub mod remesh;
pub mod report_job;
pub mod segment;
pub mod subdivide;
pub mod unfold;

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
    /// [`Control::cancelled`] before a step that cannot be interrupted and is expected to take
    /// `seconds` (a sparse factorisation): a caller with a deadline also says stop when the
    /// step would end past it. Wrappers must forward it.
    fn cancelled_before(&self, seconds: f64) -> bool {
        let _ = seconds;
        self.cancelled()
    }
}

/// Progress of a later or partial run under its own stage names (`newton, no shape
/// penalty`, `part 2 of 5 alone, newton`, …), so that a client sees its iterations restart
/// with a new stage.
pub(crate) struct Renamed<'a> {
    control: &'a dyn Control,
    label: std::borrow::Cow<'static, str>,
    before: bool,
}

impl<'a> Renamed<'a> {
    /// Stages read "`stage`, `label`".
    pub(crate) fn after(control: &'a dyn Control, label: &'static str) -> Self {
        Renamed {
            control,
            label: label.into(),
            before: false,
        }
    }
    /// Stages read "`label`, `stage`".
    pub(crate) fn before(control: &'a dyn Control, label: String) -> Self {
        Renamed {
            control,
            label: label.into(),
            before: true,
        }
    }
}

impl Control for Renamed<'_> {
    fn progress(&self, p: &Progress) {
        let stage = if self.before {
            format!("{}, {}", self.label, p.stage)
        } else {
            format!("{}, {}", p.stage, self.label)
        };
        self.control.progress(&Progress { stage, ..p.clone() });
    }
    fn cancelled(&self) -> bool {
        self.control.cancelled()
    }
    fn cancelled_before(&self, seconds: f64) -> bool {
        self.control.cancelled_before(seconds)
    }
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
    /// The input cannot be processed, with the element at fault.
    #[error("{0}")]
    Input(String),
}

/// How far each vertex moved from `a` to `b` (same vertex numbering).
pub(crate) fn displacement(a: &Mesh, b: &Mesh) -> Vec<f64> {
    a.positions()
        .iter()
        .zip(b.positions())
        .map(|(&p, &q)| {
            let d = crate::mesh::sub(p, q);
            crate::mesh::dot(d, d).sqrt()
        })
        .collect()
}

/// An [`AlgoError::InvalidParam`] naming `key` (parameter range checks).
pub(crate) fn bad_param(key: &str, message: &str) -> AlgoError {
    AlgoError::InvalidParam {
        key: key.into(),
        message: message.into(),
    }
}

/// What a run produced: an output mesh (for optimisers), flat patterns (for flattening), and
/// the algorithm's own figures `S`, a typed struct of each algorithm (`fl_mesh::Summary`, …).
#[derive(Debug, Clone, Default)]
pub struct Outcome<S> {
    /// The optimised mesh, when the algorithm changes the mesh.
    pub mesh: Option<Mesh>,
    /// Flat patterns, when the algorithm flattens.
    pub patterns: Option<crate::pattern::Patterns>,
    /// The algorithm's figures (iterations, converged, history, …).
    pub summary: S,
    /// Intermediate meshes, for algorithms that make a sequence (`subdivide`: every level's
    /// mesh, the last equal to `mesh`).
    pub levels: Vec<Mesh>,
}

/// Hausdorff distance between an output and its input, absolute (mesh units) and relative to
/// the input's bounding-box diagonal.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Distance {
    /// Mesh units.
    pub absolute: f64,
    /// Divided by the input's bounding-box diagonal.
    pub relative: f64,
}

impl Distance {
    /// Vertex-to-surface Hausdorff distance between `output` and `input`, both ways.
    pub fn hausdorff(output: &Mesh, input: &Mesh) -> Distance {
        let (lo, hi) = input.bbox();
        let diag = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
        let absolute = crate::spatial::vertex_surface_hausdorff(
            output.positions(),
            output.triangles(),
            input.positions(),
            input.triangles(),
        );
        Distance {
            absolute,
            relative: if diag > 0.0 { absolute / diag } else { 0.0 },
        }
    }

    /// [`Distance::hausdorff`] as a stage of its own in the progress: on hostile inputs (a
    /// 60k-spoke fan) its closest-point queries take seconds that would otherwise show as the
    /// previous stage standing still.
    pub fn hausdorff_reported(output: &Mesh, input: &Mesh, control: &dyn Control) -> Distance {
        Self::report_stage(control);
        Self::hausdorff(output, input)
    }

    /// The progress stage of [`Distance::hausdorff_reported`], for a caller that measures the
    /// distance inside a summary of its own.
    pub fn report_stage(control: &dyn Control) {
        control.progress(&Progress {
            stage: "distance to input".into(),
            iteration: 0,
            max_flattenability: None,
            step_norm: None,
        });
    }
}

/// A deserialisation message with JSON's words for Rust's types ("expected usize" →
/// "expected a non-negative integer"): clients write JSON, not Rust.
fn plain_types(msg: &str) -> String {
    const WORDS: &[(&str, &str)] = &[
        ("usize", "a non-negative integer"),
        ("u64", "a non-negative integer"),
        ("u32", "a non-negative integer"),
        ("u16", "a non-negative integer"),
        ("u8", "a non-negative integer"),
        ("isize", "an integer"),
        ("i64", "an integer"),
        ("i32", "an integer"),
        ("f64", "a number"),
        ("f32", "a number"),
        ("a sequence", "an array"),
        ("a map", "an object"),
    ];
    let mut out = msg.to_string();
    for (rust, json) in WORDS {
        out = out.replace(&format!("expected {rust}"), &format!("expected {json}"));
    }
    // "expected struct FlattenParams" → "expected an object"
    if let Some(i) = out.find("expected struct ") {
        let rest = &out[i + "expected struct ".len()..];
        let end = rest
            .find(|c: char| !c.is_alphanumeric() && c != '_')
            .unwrap_or(rest.len());
        out = format!("{}expected an object{}", &out[..i], &rest[end..]);
    }
    out
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
        let msg = plain_types(&e.inner().to_string());
        let key = if path == "." { String::new() } else { path };
        AlgoError::InvalidParam { key, message: msg }
    })
}

#[cfg(test)]
mod plain_type_tests {
    #[derive(serde::Deserialize, Debug)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct P {
        levels: Option<usize>,
        tolerance: Option<f64>,
        curves: Option<Vec<u32>>,
    }

    fn message(v: serde_json::Value) -> String {
        let serde_json::Value::Object(o) = v else {
            unreachable!()
        };
        match super::parse_params::<P>(&o) {
            Err(super::AlgoError::InvalidParam { message, .. }) => message,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn messages_name_json_types_not_rust_ones() {
        let cases = [
            (serde_json::json!({"levels": "2"}), "a non-negative integer"),
            (serde_json::json!({"levels": -1}), "a non-negative integer"),
            (serde_json::json!({"tolerance": "x"}), "a number"),
            (serde_json::json!({"curves": 3}), "an array"),
            (
                serde_json::json!({"curves": [1.5]}),
                "a non-negative integer",
            ),
        ];
        for (v, want) in cases {
            let m = message(v.clone());
            assert!(m.contains(want), "{v}: {m}");
            for rust in ["usize", "u32", "f64", "sequence", "struct"] {
                assert!(!m.contains(rust), "{v}: {m}");
            }
        }
    }
}
