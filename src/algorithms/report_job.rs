//! The `report` job: the flattenability report of the input, as a job (large meshes take a
//! while, and the service then serves it like any other result). No parameters.

use super::{AlgoError, Control, Outcome, Progress};
use crate::mesh::Mesh;
use serde::{Deserialize, Serialize};

/// No parameters; unknown keys are refused.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

/// No figures of its own: the job's report is the mesh report.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Summary {}

/// Leave the mesh as it is; the caller reports on it.
pub fn run(
    _mesh: &Mesh,
    _params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    if control.cancelled() {
        return Err(AlgoError::Cancelled);
    }
    control.progress(&Progress {
        stage: "report".into(),
        ..Progress::default()
    });
    Ok(Outcome::default())
}
