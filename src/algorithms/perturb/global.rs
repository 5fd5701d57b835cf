//! `method = "global"`: the problem of Eq. 20 on the whole mesh at once — closest to the input
//! (J_pos of Eq. 5 with v⁰ the input), θ = 2π at every interior vertex, every vertex outside
//! the body — solved by fl-mesh's SQP (its LDLᵀ of the KKT system, merit line search, feasibility
//! corrections and shape penalty) with H = I (w1 = `fairing`, w2 = 1) and the body as
//! inequality rows with an active set (`fl_mesh::contact`). No refinement: the connectivity,
//! and so every vertex id, is the input's.
//!
//! Why: Algorithm 2's many τ-damped local solves converge linearly at best and stall near the
//! paper's own 1e-3 (paper-notes A.7); one Newton-type iteration on the whole mesh costs about
//! as much as a few hundred local SVDs and converges to ϖ_max ≤ 1e-6 on almost flattenable
//! input in tens of iterations.

use super::body::Body;
use super::{HistoryEntry, Params, Run, Stop};
use crate::algorithms::fl_mesh::{self, Keep};
use crate::algorithms::{AlgoError, Control};
use crate::mesh::Mesh;

/// Run the global method.
pub(super) fn run(
    mesh: &Mesh,
    body: Option<&Body>,
    params: &Params,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let fl = fl_mesh::Params {
        w1: params.fairing,
        w2: 1.0,
        tolerance: params.tolerance(),
        max_iterations: params.max_iterations,
        stall_iterations: params.stall_iterations,
        shape_penalty: params.shape_penalty,
        refine: false,
        // Measured with fl-mesh's corpus only; perturb keeps the step it was measured with.
        step_radius: 0.0,
        // A perturbation stays near its input; the cone start moves a whole disk.
        cone_start: fl_mesh::ConeStart::Never,
        ..fl_mesh::Params::default()
    };
    let keep = body.map(|b| Keep {
        obstacle: b,
        clearance: params.clearance,
    });
    let (out, report) = fl_mesh::solve_clear_of(mesh, &fl, keep, control)?;
    let mut best = f64::INFINITY;
    let history = report
        .history
        .iter()
        .map(|h| {
            best = best.min(h.max_flattenability);
            HistoryEntry {
                iteration: h.iteration,
                max_flattenability: h.max_flattenability,
                best,
                centres: 0,
            }
        })
        .collect();
    let stop = if report.converged {
        Stop::Tolerance
    } else if report.stop_reason.contains("max_iterations") {
        Stop::MaxIterations
    } else {
        Stop::Stall
    };
    Ok(Run {
        positions: out.positions().to_vec(),
        iterations: report.iterations,
        best_iteration: report.best_iteration,
        centres: 0,
        stop,
        stop_detail: report.stop_reason,
        history,
        max_flattenability: report.max_flattenability,
    })
}
