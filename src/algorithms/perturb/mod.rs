//! The `perturb` job: local flattenable perturbation against an optional reference body
//! (wang-flattenable-laplacian-meshes, Sec. 4, Eq. 18–24, Algorithm 2). An almost flattenable
//! mesh is improved by small moves around its least flattenable vertices, keeping clear of the
//! body it is worn on.
//!
//! `method = "global"` (the default, beyond the paper; see `global.rs`) solves the same
//! problem (Eq. 20) on the whole mesh at once with fl-mesh's SQP and the body as inequality
//! rows with an active set, to ϖ_max ≤ 1e-6 (`tolerance` defaults to 1e-6 for it, to the
//! paper's 1e-3 for `local`). Measured (issue 15 note, examples/perturb_corpus: fl-mesh
//! outputs given four small bumps): it reaches 1e-6 in 2–30 iterations on 39 of the 40 cases
//! whose fl-mesh output is flattenable (the exception carries folds and 0.07° slivers), where
//! Algorithm 2 reaches its 1e-3 on 30; on the 3.5k-vertex sleeve of benches/perturb it takes
//! 0.91 s to 3e-7, local 1.10 s to 7.4e-4 (0.91 s to a stall at 3.5e-3 in the strict order).
//!
//! `method = "local"` is Algorithm 2 (with the departures listed below): a max-heap of
//! interior vertices keyed by ϖ; while its top exceeds `heap_fraction`·ϖ_best, the top vertex is popped and the interior
//! vertices of its r-ring disk (V_act, Eq. 18) move to make the interior vertices of its
//! (r+1)-ring disk (V_dev, Eq. 19) flattenable, closest to the input (J_pos, Eq. 5), by
//! `inner_iterations` damped steps v ← v + τδ of the KKT system Eq. 22. After each outer
//! iteration the best positions so far are kept (l.15–17); the run stops when ϖ_best ≤
//! `tolerance`, after `stall_outer` outer iterations without a new best, or after
//! `max_outer`. Defaults are the paper's (r = 3, τ = 0.1, 5 inner iterations, 0.5, 1e-3 rad,
//! 10, 50).
//!
//! Choices where the paper is vague (../shared/notes/paper-notes.md, part A.3):
//! - The position term sums over V_act (Eq. 20), not V_dev (Eq. 21's typo; the extra terms
//!   are constants). v⁰ is the input position for the whole run, so drift cannot accumulate.
//! - "More than 5 times" is read as `inner_iterations` = 5, "more than 50" as 50 outer.
//! - ϖ_max in l.6 is the recorded best. The heap is rebuilt from the current ϖ at the start of
//!   every outer iteration (l.18's re-insertion and re-keying); within one, keys are stale, as
//!   written.
//! - The step is the minimum-norm solution of Eq. 22 through a thin SVD of Λ itself, singular
//!   values below 1e-3·σ_max dropped ([`min_norm_step`]; why that cutoff: `SVD_CUTOFF` in
//!   local.rs), not of ΛΛᵀ (Eq. 23), which would square the condition number; where Eq. 23 is
//!   well posed the two agree (tested against an independent dense solve of Eq. 22).
//! - Rows are scaled so that all are O(1): θ rows by the mean edge length h̄.
//! - Body constraints (Eq. 20's inequality) by an active set rather than the paper's equality
//!   linearisation: V_collid = the moved vertices with signed clearance s below `clearance`;
//!   after a solve, rows whose multiplier would pull the vertex towards the body (λ > 0) are
//!   dropped and the system solved again. The row of vertex r is ∇s(v_r)·δ_r = clearance − s_r,
//!   ∇s the unit offset from the closest point (the pseudo-normal on the surface).
//! - Hard guarantee beyond the linearisation: every damped step is checked with the exact
//!   signed distance; a vertex may not end below min(`clearance`, where it started). A vertex
//!   that would is added to the active set and the step solved again; if that does not help,
//!   the step is halved (up to 10 times) or not taken. So a vertex that starts at ≥ clearance
//!   never ends below it, and penetrating vertices never increase.
//! - Step cap (beyond the paper): a damped step moves no vertex farther than 0.05 h̄
//!   (`STEP_CAP` in local.rs). The minimum-norm step of a disk whose outer θ rows are weakly
//!   coupled can be many edge lengths long even at τ = 0.1; measured without the cap, on the
//!   fixture cylinder made flattenable and given four small bumps, the first outer iteration
//!   took ϖ_max 0.05 → 1.47 rad and no outer iteration ever beat the input, and the 3.5k-vertex
//!   sleeve of benches/perturb ran 68 s without improving (5.7e-3); with it, the cylinder
//!   converges (6.9e-4, 28 outer) and the sleeve reaches 3.5e-3 in 1.2 s.
//! - Parallel waves (beyond the paper, `parallel`, default on): the centres of an outer
//!   iteration are known when it starts (keys are stale within it), so those whose
//!   (r+1)-ring disks are disjoint run together on the rayon pool (local.rs,
//!   `perturb_in_waves`); `parallel = false` keeps the strict heap order. Measured on this
//!   2-core machine: 1.65–1.7× the centres per second (3.5k sleeve 4.2 → 2.6 ms per centre,
//!   mh_shoes01 after fl-mesh with bumps 2.3 → 1.35 ms); the order differs, so the runs do
//!   too: the sleeve reaches the tolerance (7.4e-4 in 16 outer iterations, 1.2 s) where the
//!   strict order stalls at 3.5e-3 (11, 0.9 s).
//! - Closest points are recomputed for every query with the grid (exact), not tracked locally
//!   as in [48]; measured fast enough at these sizes.
//!
//! An input whose ϖ_max is within `tolerance` comes back bit-identical after 0 iterations
//! (`global` with a body: only when every interior vertex is also at the clearance; `local`
//! stops on ϖ alone). `converged` asks for both. Boundary and seam vertices never move (they
//! are not interior); with `local`, vertices outside every popped centre's r-ring disk are
//! never written.

mod body;
mod global;
mod local;

pub use body::{Body, Clearance};
pub use local::min_norm_step;

use super::bad_param as bad;
use super::{AlgoError, Control, Distance, Outcome};
use crate::mesh::Mesh;
use serde::{Deserialize, Serialize};

/// Which algorithm runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Eq. 20 on the whole mesh by fl-mesh's SQP, to ϖ_max ≤ 1e-6 (see `global`).
    #[default]
    Global,
    /// Algorithm 2 of the paper.
    Local,
}

/// Parameters of `perturb` (`local`'s defaults are the paper's).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// `global` (default) or `local` (Algorithm 2).
    pub method: Method,
    /// Ring number r of the moved disk V_act (Eq. 18).
    pub rings: usize,
    /// Damping τ of each step.
    pub tau: f64,
    /// Damped steps per popped vertex.
    pub inner_iterations: usize,
    /// Vertices are popped while their ϖ exceeds this fraction of the best ϖ_max.
    pub heap_fraction: f64,
    /// Target ϖ_max in radians; none: 1e-6 for `global`, the paper's ε = 1e-3 for `local`.
    pub tolerance: Option<f64>,
    /// Outer iterations without a new best ϖ_max before stopping.
    pub stall_outer: usize,
    /// `local`: run centres whose disks are ≥ 2r+3 rings apart in parallel waves (false: the
    /// paper's strict heap order, one after the other).
    pub parallel: bool,
    /// Most outer iterations.
    pub max_outer: usize,
    /// Least signed distance to the reference body, in mesh units (the paper's ϵ).
    pub clearance: f64,
    /// `global`: most Newton iterations.
    pub max_iterations: usize,
    /// `global`: iterations without ϖ_max halving that end the run.
    pub stall_iterations: usize,
    /// `global`: weight of fl-mesh's fairness term J_fair against J_pos (0: J_pos alone, as
    /// Eq. 20).
    pub fairing: f64,
    /// `global`: fl-mesh's shape penalty κ against new creases and slivers (0: none).
    pub shape_penalty: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            method: Method::Global,
            rings: 3,
            tau: 0.1,
            inner_iterations: 5,
            heap_fraction: 0.5,
            tolerance: None,
            stall_outer: 10,
            parallel: true,
            max_outer: 50,
            clearance: 0.0,
            max_iterations: 300,
            stall_iterations: 40,
            fairing: 0.0,
            shape_penalty: 1.0,
        }
    }
}

impl Params {
    /// The tolerance in force: the given one, else 1e-6 (`global`) or 1e-3 (`local`).
    pub fn tolerance(&self) -> f64 {
        self.tolerance.unwrap_or(match self.method {
            Method::Global => crate::geometry::DEVELOPABLE_TOLERANCE,
            Method::Local => 1e-3,
        })
    }

    /// Check ranges.
    pub fn check(&self) -> Result<(), AlgoError> {
        if !(1..=10).contains(&self.rings) {
            return Err(bad("rings", "must be in 1..=10"));
        }
        if !(self.tau > 0.0 && self.tau <= 1.0) {
            return Err(bad("tau", "must be in (0, 1]"));
        }
        if !(1..=100).contains(&self.inner_iterations) {
            return Err(bad("inner_iterations", "must be in 1..=100"));
        }
        if !(0.0..1.0).contains(&self.heap_fraction) {
            return Err(bad("heap_fraction", "must be in [0, 1)"));
        }
        if !(self.tolerance() > 0.0 && self.tolerance() < 1.0) {
            return Err(bad("tolerance", "must be in (0, 1) rad"));
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(bad("max_iterations", "must be in 1..=100000"));
        }
        if !(2..=1000).contains(&self.stall_iterations) {
            return Err(bad("stall_iterations", "must be in 2..=1000"));
        }
        if !(self.fairing >= 0.0 && self.fairing.is_finite()) {
            return Err(bad("fairing", "must be finite and ≥ 0"));
        }
        if !(self.shape_penalty >= 0.0 && self.shape_penalty.is_finite()) {
            return Err(bad("shape_penalty", "must be finite and ≥ 0"));
        }
        if !(1..=10_000).contains(&self.stall_outer) {
            return Err(bad("stall_outer", "must be in 1..=10000"));
        }
        if !(1..=10_000).contains(&self.max_outer) {
            return Err(bad("max_outer", "must be in 1..=10000"));
        }
        if !(self.clearance >= 0.0 && self.clearance.is_finite()) {
            return Err(bad(
                "clearance",
                "must be a finite distance ≥ 0 (mesh units)",
            ));
        }
        Ok(())
    }
}

/// Why the run stopped (l.19).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    /// ϖ_max within the tolerance.
    Tolerance,
    /// `stall_outer` outer iterations without a new best.
    Stall,
    /// `max_outer` outer iterations (`local`).
    MaxOuter,
    /// `max_iterations` Newton iterations (`global`).
    MaxIterations,
}

impl Stop {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Stop::Tolerance => "tolerance",
            Stop::Stall => "stall",
            Stop::MaxOuter => "max_outer",
            Stop::MaxIterations => "max_iterations",
        }
    }
}

/// One outer iteration (`local`) or Newton iteration (`global`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HistoryEntry {
    /// Iteration (1-based).
    pub iteration: usize,
    /// ϖ_max after it (`local`), before its step (`global`, as fl-mesh's history).
    pub max_flattenability: f64,
    /// Best ϖ_max so far.
    pub best: f64,
    /// Vertices popped from the heap (0 for `global`).
    pub centres: usize,
}

/// What a method reached, before the figures are measured.
pub(super) struct Run {
    pub positions: Vec<[f64; 3]>,
    pub iterations: usize,
    pub best_iteration: usize,
    pub centres: usize,
    pub stop: Stop,
    pub stop_detail: String,
    pub history: Vec<HistoryEntry>,
    pub max_flattenability: f64,
}

/// How the output sits against the reference body.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BodyFigures {
    /// The clearance asked for.
    pub clearance: f64,
    /// Vertices inside the body (signed distance < 0), before and after.
    pub penetrating_before: usize,
    /// See `penetrating_before`.
    pub penetrating_after: usize,
    /// Least signed distance of a vertex, before and after.
    pub min_clearance_before: f64,
    /// See `min_clearance_before`.
    pub min_clearance_after: f64,
    /// Signed distance of every vertex to the body, before.
    pub clearance_before: Vec<f64>,
    /// And after.
    pub clearance_after: Vec<f64>,
}

/// The figures of a `perturb` run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// The algorithm that ran.
    pub method: Method,
    /// ϖ_max within the tolerance and, with a body, every interior vertex at the clearance
    /// or beyond (to 1e-6 mean edge lengths).
    pub converged: bool,
    /// Why it stopped (`tolerance`, `stall`, `max_outer`, `max_iterations`).
    pub stop_reason: Stop,
    /// The stop in words (for `global`, fl-mesh's stop reason).
    pub stop_detail: String,
    /// Outer iterations (`local`) or Newton iterations (`global`) run.
    pub iterations: usize,
    /// The iteration whose positions are returned (0: the input).
    pub best_iteration: usize,
    /// Vertices popped from the heap over the run.
    pub centres: usize,
    /// ϖ_max of the input.
    pub max_flattenability_before: f64,
    /// ϖ_max of the output.
    pub max_flattenability_after: f64,
    /// Interior vertices still above the tolerance, worst first.
    pub stuck_vertices: Vec<u32>,
    /// Vertices that moved.
    pub moved_vertices: usize,
    /// Largest displacement of a vertex.
    pub max_displacement: f64,
    /// Displacement of every vertex.
    pub displacement: Vec<f64>,
    /// Against the reference body, when one was given.
    pub body: Option<BodyFigures>,
    /// Hausdorff distance between output and input.
    pub hausdorff_to_input: Distance,
    /// One entry per outer iteration.
    pub history: Vec<HistoryEntry>,
    /// What was assumed about the body.
    pub warnings: Vec<String>,
}

/// Run `perturb` on `mesh`, keeping clear of `reference` when given.
pub fn run(
    mesh: &Mesh,
    reference: Option<&Mesh>,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    let mut warnings = Vec::new();
    let body = reference.map(|r| {
        let (b, w) = Body::new(r);
        warnings.extend(w);
        if !boxes_overlap(mesh, r) {
            warnings.push(
                "reference body: its bounding box does not overlap the mesh's; it constrains \
                 nothing (a different unit or frame?)"
                    .into(),
            );
        }
        b
    });
    let run = match params.method {
        Method::Global => global::run(mesh, body.as_ref(), params, control)?,
        Method::Local => local::run(mesh, body.as_ref(), params, control)?,
    };
    let out = mesh
        .with_positions(run.positions)
        .map_err(|e| AlgoError::Input(format!("the perturbed mesh is invalid: {e}")))?;
    let displacement = super::displacement(mesh, &out);
    let body_figures = body.as_ref().map(|b| {
        let before: Vec<f64> = mesh
            .positions()
            .iter()
            .map(|&p| b.clearance(p).signed)
            .collect();
        let after: Vec<f64> = out
            .positions()
            .iter()
            .map(|&p| b.clearance(p).signed)
            .collect();
        let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        BodyFigures {
            clearance: params.clearance,
            penetrating_before: before.iter().filter(|&&s| s < 0.0).count(),
            penetrating_after: after.iter().filter(|&&s| s < 0.0).count(),
            min_clearance_before: min(&before),
            min_clearance_after: min(&after),
            clearance_before: before,
            clearance_after: after,
        }
    });
    // Converged also means clear of the body: every vertex that can move (interior) at the
    // clearance or beyond, to 1e-6 mean edge lengths.
    let h = crate::geometry::mean_edge_length(mesh);
    let too_close = body_figures.as_ref().map_or(0, |b| {
        b.clearance_after
            .iter()
            .enumerate()
            .filter(|&(v, &s)| mesh.conn().is_interior(v as u32) && s < params.clearance - 1e-6 * h)
            .count()
    });
    let hausdorff_to_input = Distance::hausdorff_reported(&out, mesh, control);
    let (_, before) = local::varpi(mesh, mesh.positions());
    let (w, _) = local::varpi(&out, out.positions());
    let mut stuck_vertices: Vec<u32> = (0..w.len() as u32)
        .filter(|&v| w[v as usize] > params.tolerance())
        .collect();
    stuck_vertices.sort_by(|a, b| w[*b as usize].total_cmp(&w[*a as usize]));
    let summary = Summary {
        method: params.method,
        converged: run.max_flattenability <= params.tolerance() && too_close == 0,
        stop_reason: run.stop,
        stop_detail: match too_close {
            0 => run.stop_detail,
            k => format!(
                "{}; {k} interior vertices closer to the body than the clearance",
                run.stop_detail
            ),
        },
        iterations: run.iterations,
        best_iteration: run.best_iteration,
        centres: run.centres,
        max_flattenability_before: before,
        max_flattenability_after: run.max_flattenability,
        stuck_vertices,
        moved_vertices: displacement.iter().filter(|&&d| d > 0.0).count(),
        max_displacement: displacement.iter().copied().fold(0.0, f64::max),
        displacement,
        body: body_figures,
        hausdorff_to_input,
        history: run.history,
        warnings,
    };
    Ok(Outcome {
        mesh: Some(out),
        patterns: None,
        summary,
        levels: Vec::new(),
    })
}

/// Whether the bounding boxes of `a` and `b` overlap.
fn boxes_overlap(a: &Mesh, b: &Mesh) -> bool {
    let ((alo, ahi), (blo, bhi)) = (a.bbox(), b.bbox());
    (0..3).all(|k| alo[k] <= bhi[k] && blo[k] <= ahi[k])
}
