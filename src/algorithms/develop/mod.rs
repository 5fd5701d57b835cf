//! The `develop` job: developability by minimum deformation. Keep every edge as close as
//! possible to its input length while driving each interior angle sum to 2π
//! (wang-tang-developability-by-minimum-deformation, Sec. 3–6; su-shape-preserved-developability).
//!
//! - `method = "global"` (default): min E = Σ_e (l_e − l⁰_e)² subject to θ = 2π at every
//!   interior vertex (Eq. 8). `solver = "sqp"` (default, beyond the paper; `sqp.rs`) solves it
//!   exactly to g_max ≤ 1e-6, with a feasibility restoration by fl-mesh when it stalls
//!   ([`restore`]); `solver = "penalty_cg"` is the paper's penalty J = E + (ρ/2)G²
//!   with its ρ schedule and 5 CG steps per ρ (`cg.rs`).
//! - `method = "local"`: the paper's heap-driven moves along fixed normals within ±δ_T
//!   (Sec. 5, `local.rs`).
//! - `method = "loop"`: Su et al.: `levels` of Loop subdivision (`loop_subdivision.rs`), then
//!   the global method against the subdivided mesh's edge lengths; reports their Table 1.
//!
//! The mesh is welded: a seam vertex is one position, so G0 continuity across seams is exact
//! (Sec. 4.2's linked vertex sets are implicit), and it is not interior, so g = 0 there
//! (Eq. 5). `global` moves every vertex unless `fix_boundary` (then boundary and seam vertices
//! stay bit-identical); `local` never moves them (Sec. 5.2). With `global` and `local`, an
//! input already within the tolerance comes back unchanged after 0 iterations (`loop`: its
//! subdivided mesh M_L does). Choices where the papers are vague
//! follow ../shared/notes/paper-notes.md parts B and C (stop on |g| not g², analytic
//! gradients, the CG sign, ρ per phase, D at named tolerances).

mod cg;
pub mod energy;
mod local;
mod loop_subdivision;
mod sqp;

pub use local::{t_and_slope, vertex_normals_unweighted};
pub use loop_subdivision::loop_subdivide;

use super::bad_param as bad;
use super::{AlgoError, Control, Distance, Outcome};
use crate::mesh::Mesh;
use energy::{big_g, g_max, Model};
use serde::{Deserialize, Serialize};

/// Which method runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Eq. 8 on the whole mesh (Sec. 4).
    #[default]
    Global,
    /// Heap-driven moves along the original normals (Sec. 5).
    Local,
    /// Loop subdivision, then `global` against its edge lengths (Su et al.).
    Loop,
}

/// The solver of `global` and `loop`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// min E + closeness s.t. θ = 2π, by SQP (exactly flattenable).
    #[default]
    Sqp,
    /// The paper's penalty J = E + (ρ/2) G² with conjugate gradients.
    PenaltyCg,
}

/// The preconditioner of `penalty_cg`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Preconditioner {
    /// Plain nonlinear CG, as the paper.
    #[default]
    None,
    /// P = E's Gauss–Newton Hessian + 2ρG ΛᵀΛ + a small closeness and a graph Laplacian,
    /// factorised once per phase (beyond the paper).
    GaussNewton,
}

/// The update of `local`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Update {
    /// Gauss–Newton on the residuals, accepted only when T falls.
    #[default]
    GaussNewton,
    /// The paper's Eq. 19, δ ← δ − T/Ṫ.
    Newton,
}

/// Parameters of `develop` (defaults are the papers' unless said otherwise).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// `global` (default), `local` or `loop`.
    pub method: Method,
    /// `global`/`loop`: `sqp` (default) or `penalty_cg` (the paper's).
    pub solver: Solver,
    /// Target g_max in radians; none: 1e-6 for `global` and `loop`, the paper's ε = 1e-4 for
    /// `local`.
    pub tolerance: Option<f64>,
    /// `global`/`loop`: most outer iterations (ρ phases) for `penalty_cg`, Newton iterations
    /// for `sqp`.
    pub max_iterations: usize,
    /// `global`/`loop`: keep boundary and seam vertices where they are.
    pub fix_boundary: bool,
    /// `penalty_cg`: stop when |G[Mⁱ] − G[Mⁱ⁻¹]| / G[M⁰] < eta.
    pub eta: f64,
    /// `penalty_cg`: CG steps per ρ.
    pub cg_steps: usize,
    /// `penalty_cg`: least growth γ of ρ from one phase to the next (ρ_k ≥ γ ρ_{k−1}, and
    /// η then relative to the last G); 1: the paper's schedule, whose ρ_k G_k² is fixed.
    pub rho_growth: f64,
    /// `penalty_cg`: `none` (the paper's plain CG) or `gauss_newton` (see the `cg` module).
    pub preconditioner: Preconditioner,
    /// `sqp`: weight μ of Σ|v − v⁰|² beside E (both over h̄²).
    pub closeness: f64,
    /// `sqp`: weight κ of the displacement's Dirichlet energy Σ_e |d_a − d_b|² beside E
    /// (over h̄²) until the mesh is flattenable, 0 from there on; 0: least stretch
    /// throughout.
    pub smoothness: f64,
    /// `sqp`: weight β of the barrier β Σ_e (φ_e − t_e)₊² on the turning angles across edges
    /// sharper than 90° (or than the input's own angle there) once flattenable; 0: off.
    pub fold_barrier: f64,
    /// `sqp`: weight of the barrier Σ_c (t_c − a_c)₊² on the corner angles below 3° (or
    /// below the input's own corner there) once flattenable; 0: off.
    pub corner_barrier: f64,
    /// `sqp`: once flattenable, stop when a step (times 1 + σ, its trust-region shortening)
    /// moves no vertex more than this many mean edge lengths.
    pub step_tolerance: f64,
    /// `sqp`: iterations without g_max halving that end an unflattenable run.
    pub stall_iterations: usize,
    /// `global`/`loop`: when the run stalls unflattenable (not when `max_iterations` ends it),
    /// restore feasibility with `fl-mesh` from the input (boundary fixed, no refinement), then
    /// run the same solver again from its result; up to three rounds (`RESTORE_ROUNDS`), the
    /// later ones from the result so far. None: on for `sqp`, off for `penalty_cg` (the
    /// paper's method alone).
    pub restore: Option<bool>,
    /// `local`: largest offset δ_T along a normal, mesh units; none: the mean edge length L̄.
    pub delta_t: Option<f64>,
    /// `local`: most heap pops (N_max).
    pub max_moves: usize,
    /// `local`: `gauss_newton` (default) or `newton` (the paper's Eq. 19).
    pub update: Update,
    /// `local`, `gauss_newton`: over-relaxation ω of each move, in (0, 2).
    pub relaxation: f64,
    /// `local`, `gauss_newton`: a move must also lower G = Σg² by this share of its mean
    /// per interior vertex, G/n (0: only its own T's 0.1 %; see the `local` module).
    pub min_gain: f64,
    /// `loop`: Loop subdivision levels.
    pub levels: usize,
    /// Tolerances (radians) at which D[M] is reported.
    pub d_tolerance: Vec<f64>,
    /// The patches whose interior vertices must reach 2π (seams welded; they move unless
    /// `fix_boundary`): `file` (default), `uv` (one per island of the texture layout) or
    /// `auto` (`uv` when the layout cuts the file's patches into a sewing pattern), chosen as
    /// fl-mesh chooses them ([`super::fl_mesh::choose_patches`]).
    pub patches: super::fl_mesh::Patches,
    /// `sqp`: repair the folds (edges whose normals turn past 120°), then the corners below 1°,
    /// of a flattenable result that the start did not have, moving their neighbourhoods along
    /// θ = 2π (the `unfold` module; beyond the papers).
    pub unfold: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            method: Method::Global,
            solver: Solver::Sqp,
            tolerance: None,
            max_iterations: 200,
            fix_boundary: false,
            eta: 1e-4,
            cg_steps: 5,
            rho_growth: 1.0,
            preconditioner: Preconditioner::None,
            closeness: 1e-2,
            smoothness: 10.0,
            fold_barrier: 1.0,
            corner_barrier: 1000.0,
            step_tolerance: 1e-4,
            stall_iterations: 40,
            restore: None,
            delta_t: None,
            max_moves: 500_000,
            update: Update::GaussNewton,
            relaxation: 1.8,
            min_gain: 1e-2,
            levels: 1,
            d_tolerance: vec![1e-6, 1e-4, 1e-3, 1e-2],
            patches: super::fl_mesh::Patches::File,
            unfold: true,
        }
    }
}

impl Params {
    /// Whether a stalled `global`/`loop` run is restored (see `restore`).
    pub fn restores(&self) -> bool {
        self.restore.unwrap_or(self.solver == Solver::Sqp)
    }

    /// The tolerance in force.
    pub fn tolerance(&self) -> f64 {
        self.tolerance.unwrap_or(match self.method {
            Method::Global | Method::Loop => crate::geometry::DEVELOPABLE_TOLERANCE,
            Method::Local => 1e-4,
        })
    }

    /// Check ranges.
    pub fn check(&self) -> Result<(), AlgoError> {
        if !(self.tolerance() > 0.0 && self.tolerance() < 1.0) {
            return Err(bad("tolerance", "must be in (0, 1) rad"));
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(bad("max_iterations", "must be in 1..=100000"));
        }
        if !(self.eta > 0.0 && self.eta < 1.0) {
            return Err(bad("eta", "must be in (0, 1)"));
        }
        if !(self.rho_growth >= 1.0 && self.rho_growth <= 1e3) {
            return Err(bad("rho_growth", "must be in [1, 1000]"));
        }
        if !(1..=1000).contains(&self.cg_steps) {
            return Err(bad("cg_steps", "must be in 1..=1000"));
        }
        if !(self.closeness > 0.0 && self.closeness.is_finite()) {
            return Err(bad(
                "closeness",
                "must be finite and > 0 (it makes the problem well posed)",
            ));
        }
        if !(self.smoothness >= 0.0 && self.smoothness.is_finite()) {
            return Err(bad("smoothness", "must be finite and ≥ 0"));
        }
        if !(self.fold_barrier >= 0.0 && self.fold_barrier <= 1e6) {
            return Err(bad("fold_barrier", "must be in [0, 1e6]"));
        }
        if !(self.corner_barrier >= 0.0 && self.corner_barrier <= 1e9) {
            return Err(bad("corner_barrier", "must be in [0, 1e9]"));
        }
        if !(self.step_tolerance > 0.0 && self.step_tolerance < 1.0) {
            return Err(bad("step_tolerance", "must be in (0, 1)"));
        }
        if !(2..=1000).contains(&self.stall_iterations) {
            return Err(bad("stall_iterations", "must be in 2..=1000"));
        }
        if let Some(d) = self.delta_t {
            if !(d >= 0.0 && d.is_finite()) {
                return Err(bad("delta_t", "must be a finite distance ≥ 0 (mesh units)"));
            }
        }
        if !(self.relaxation > 0.0 && self.relaxation < 2.0) {
            return Err(bad("relaxation", "must be in (0, 2)"));
        }
        if !(self.min_gain >= 0.0 && self.min_gain <= 1.0) {
            return Err(bad("min_gain", "must be in [0, 1]"));
        }
        if !(1..=100_000_000).contains(&self.max_moves) {
            return Err(bad("max_moves", "must be in 1..=100000000"));
        }
        if !(1..=4).contains(&self.levels) {
            return Err(bad(
                "levels",
                "must be in 1..=4 (each level has 4× the faces)",
            ));
        }
        if self.d_tolerance.is_empty()
            || self.d_tolerance.len() > 16
            || self.d_tolerance.iter().any(|t| !(*t > 0.0 && *t < 1.0))
        {
            return Err(bad(
                "d_tolerance",
                "must be a list of 1 to 16 tolerances in (0, 1) rad",
            ));
        }
        Ok(())
    }
}

/// Why the run stopped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    /// g_max within the tolerance (`sqp`: and stationary: the step below `step_tolerance`,
    /// the trust region shut, or the objective no longer falling).
    #[default]
    Tolerance,
    /// `penalty_cg`: the relative change of G fell below η.
    Eta,
    /// The iteration budget ran out.
    MaxIterations,
    /// `sqp`: g_max did not halve within `stall_iterations`.
    Stall,
    /// No step lowered the objective (`penalty_cg`: J; `sqp`: the merit).
    LineSearch,
    /// `local`: only stalled vertices are above ε.
    Stalled,
    /// `local`: `max_moves` pops.
    MaxMoves,
}

impl Stop {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Stop::Tolerance => "tolerance",
            Stop::Eta => "eta",
            Stop::MaxIterations => "max_iterations",
            Stop::Stall => "stall",
            Stop::LineSearch => "line_search",
            Stop::Stalled => "stalled",
            Stop::MaxMoves => "max_moves",
        }
    }
}

/// One iteration of `global` (a ρ phase of `penalty_cg`, a Newton step of `sqp`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HistoryEntry {
    /// Iteration (1-based).
    pub iteration: usize,
    /// g_max (= ϖ_max) after it.
    pub max_flattenability: f64,
    /// G after it.
    pub big_g: f64,
    /// E after it.
    pub e: f64,
    /// `penalty_cg`: the phase's ρ.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rho: Option<f64>,
    /// `penalty_cg`: CG steps taken in the phase.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cg_steps: Option<usize>,
    /// `sqp`: the objective step's weight w when the step was taken, 0 when it was refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step_length: Option<f64>,
    /// `sqp`: the Levenberg–Marquardt damping λ of the (2,2) block for the next iteration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping: Option<f64>,
}

/// What a method reached, before the figures are measured.
#[derive(Debug, Clone, Default)]
pub(crate) struct Run {
    pub positions: Vec<[f64; 3]>,
    pub iterations: usize,
    pub inner: usize,
    pub evaluations: usize,
    pub best_iteration: usize,
    pub stop: Stop,
    pub stop_detail: String,
    pub history: Vec<HistoryEntry>,
    pub g_max: f64,
    pub g_max_input: f64,
    pub stalled: Vec<u32>,
}

impl Run {
    fn new(start: &[[f64; 3]], g_max: f64) -> Self {
        Run {
            positions: start.to_vec(),
            g_max,
            g_max_input: g_max,
            ..Run::default()
        }
    }
}

/// D[M] at one tolerance, before and after.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DAt {
    /// |2π − θ| at or below this counts as developable.
    pub tolerance: f64,
    /// D of the input (for `loop`: of the control mesh M₀).
    pub before: f64,
    /// D of the output.
    pub after: f64,
}

/// Su et al.'s Table 1 for a `loop` run (its header's G means D: paper-notes C.3.1).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoopTable {
    /// Subdivision levels.
    pub levels: usize,
    /// Vertices of M₀ and of each level.
    pub vertices: Vec<usize>,
    /// Per tolerance of `d_tolerance`: D[M₀], D[M_L], D[M_R] and δD (percent; null when
    /// D[M_L] = 0).
    pub rows: Vec<LoopRow>,
    /// δS = Σ|l − l⁰| / Σ l⁰ between M_L (l⁰) and M_R (l).
    pub delta_s: f64,
    /// G of M₀, M_L, M_R.
    pub big_g: [f64; 3],
    /// g_max of M₀, M_L, M_R.
    pub g_max: [f64; 3],
    /// Hausdorff distance between M_L and M_R.
    pub hausdorff_ml_mr: Distance,
}

/// One tolerance's row of [`LoopTable`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LoopRow {
    /// The tolerance.
    pub tolerance: f64,
    /// D[M₀].
    pub d_m0: f64,
    /// D[M_L].
    pub d_ml: f64,
    /// D[M_R].
    pub d_mr: f64,
    /// δD = (D[M_R] − D[M_L]) / D[M_L], percent.
    pub delta_d: Option<f64>,
}

/// The figures of a `develop` run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// The method that ran.
    pub method: Method,
    /// The solver (`global`, `loop`).
    pub solver: Option<Solver>,
    /// g_max of the output within the tolerance.
    pub converged: bool,
    /// Why it stopped.
    pub stop_reason: Stop,
    /// The stop in words.
    pub stop_detail: String,
    /// Outer iterations (`penalty_cg`), Newton iterations (`sqp`) or heap pops (`local`).
    pub iterations: usize,
    /// CG steps (`penalty_cg`), heap pops (`local`, as `iterations`), corrections taken and
    /// refused trials shortened on the same factorisation (`sqp`).
    pub inner_steps: usize,
    /// The iteration whose positions are returned (0: the start).
    pub best_iteration: usize,
    /// The tolerance in force.
    pub tolerance: f64,
    /// g⁰_max: max |2π − θ| over interior vertices of the start (for `loop`: of M_L).
    pub g_max_before: f64,
    /// g*_max of the output.
    pub g_max_after: f64,
    /// G (Eq. 4) of the start and the output.
    pub big_g_before: f64,
    /// See `big_g_before`.
    pub big_g_after: f64,
    /// E (Eq. 7) of the output against the rest lengths (the start's: 0 before).
    pub e_after: f64,
    /// D[M] before (the input; for `loop` M₀) and after at each of `d_tolerance`; every
    /// interior vertex counts, also those `impossible_vertices` leaves out of g.
    pub d: Vec<DAt>,
    /// δS = Σ|l − l⁰| / Σ l⁰ against the rest lengths.
    pub delta_s: f64,
    /// Hausdorff distance from the output to the input.
    pub hausdorff_to_input: Distance,
    /// Largest displacement of a vertex from the start.
    pub max_displacement: f64,
    /// Displacement of every vertex from the start (for `loop`: from M_L).
    pub displacement: Vec<f64>,
    /// Interior vertices still above the tolerance, worst first.
    pub stuck_vertices: Vec<u32>,
    /// `local`: vertices stalled above ε at the end (refused or clamped moves), worst first.
    pub stalled_vertices: Vec<u32>,
    /// Interior vertices of closed components with Euler characteristic ≠ 0 (Gauss–Bonnet:
    /// they cannot all reach 2π): the solver leaves them where they are; every figure here
    /// (g_max, G, converged, stuck_vertices) still counts them.
    pub impossible_vertices: usize,
    /// Per iteration (`global`, `loop`).
    pub history: Vec<HistoryEntry>,
    /// `loop`: Su et al.'s Table 1.
    pub table: Option<LoopTable>,
    /// `sqp` with `unfold`, when the result had folds or corners below 1° the start did not:
    /// what repairing them did (counts of the whole mesh).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unfold: Option<super::unfold::Summary>,
    /// The patches that were made flattenable (the parameter `patches`) and why.
    pub patches: super::fl_mesh::PatchesUsed,
}

/// δD of Su et al.'s Table 1, percent: (D[M_R] − D[M_L]) / D[M_L] × 100; None when D[M_L] = 0.
pub fn delta_d(d_ml: f64, d_mr: f64) -> Option<f64> {
    (d_ml > 0.0).then(|| (d_mr - d_ml) / d_ml * 100.0)
}

/// δS = Σ|l − l⁰| / Σ l⁰ (0 when every l⁰ is 0).
pub fn delta_s(rest: &[f64], lengths: &[f64]) -> f64 {
    let total: f64 = rest.iter().sum();
    if total <= 0.0 {
        return 0.0;
    }
    rest.iter()
        .zip(lengths)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / total
}

/// D[M] (Eq. 2) at `tolerance`.
pub fn developability(mesh: &Mesh, tolerance: f64) -> f64 {
    let theta = crate::geometry::angle_sums(mesh);
    let varpi = crate::geometry::flattenability(mesh, &theta);
    let area = crate::geometry::vertex_areas(mesh, &crate::geometry::face_areas(mesh));
    crate::geometry::developability_d(&varpi, &area, tolerance)
}

/// Most faces a `loop` run may subdivide to (memory: the solver's factor grows faster than
/// the faces; 1M faces is about 500k vertices).
pub const MAX_LOOP_FACES: usize = 1_000_000;

/// 2π − θ at every interior vertex, 0 elsewhere (Eq. 5), straight from `geometry`.
fn defects(mesh: &Mesh) -> Vec<f64> {
    let theta = crate::geometry::angle_sums(mesh);
    (0..mesh.num_vertices() as u32)
        .map(|v| {
            if mesh.conn().is_interior(v) {
                std::f64::consts::TAU - theta[v as usize]
            } else {
                0.0
            }
        })
        .collect()
}

/// Run `develop`.
pub fn run(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    // From here on "the input" is the mesh with the patches chosen: the same surface, its
    // seams where the patches say (and a cut inside an island opened by copies of its
    // vertices), so every figure before and after is measured on the same patches.
    let (work, mut patches) = super::fl_mesh::choose_patches(mesh, params.patches)?;
    patches.seams = if params.fix_boundary || params.method == Method::Local {
        "held"
    } else {
        "free"
    }
    .into();
    let mesh = &work;
    let mut levels = Vec::new();
    let start = match params.method {
        Method::Loop => {
            let faces = mesh.num_faces().saturating_mul(1 << (2 * params.levels));
            if faces > MAX_LOOP_FACES {
                return Err(bad(
                    "levels",
                    &format!(
                        "{} levels of Loop subdivision would make {faces} faces from {}; at \
                         most {MAX_LOOP_FACES} are allowed (fewer levels, or a coarser mesh)",
                        params.levels,
                        mesh.num_faces()
                    ),
                ));
            }
            let mut m = mesh.clone();
            for _ in 0..params.levels {
                if control.cancelled() {
                    return Err(AlgoError::Cancelled);
                }
                m = Mesh::new(loop_subdivide(&m))
                    .map_err(|e| AlgoError::Input(format!("Loop subdivision: {e}")))?
                    .0;
                levels.push(m.clone());
            }
            m
        }
        Method::Global | Method::Local => mesh.clone(),
    };
    let model = Model::new(&start);
    let nv = start.num_vertices();
    // The two sides of a cut that `patches = uv` opened inside an island (a sleeve's seam)
    // are separate vertices at one position; free, they would drift apart and open the seam
    // in 3D (mh_female_sportsuit01: its 53 copies 0.07 apart at the median, 1.4 % of the
    // diagonal at most), so both sides are held, as fl-mesh holds them with its seams held.
    let sewn = if patches.opened_vertices > 0 {
        coincident_vertices(&start)
    } else {
        vec![false; nv]
    };
    let movable: Vec<bool> = (0..nv as u32)
        .map(|v| match start.conn().kind(v) {
            crate::mesh::VertexKind::Unreferenced => false,
            crate::mesh::VertexKind::Interior => true,
            _ => !params.fix_boundary && !sewn[v as usize],
        })
        .collect();
    let run = match (params.method, params.solver) {
        (Method::Local, _) => local::run(&model, start.positions(), params, control)?,
        (_, solver) => {
            // The solver from `from`, E and closeness measured from the input as always.
            let solve = |from: &[[f64; 3]], control: &dyn Control| match solver {
                Solver::Sqp => sqp::run(&model, start.positions(), from, &movable, params, control),
                Solver::PenaltyCg => cg::run(&model, from, &movable, params, control),
            };
            let first = solve(start.positions(), control)?;
            // Only a stall: a run cut short by `max_iterations` was given its budget.
            if first.g_max <= params.tolerance()
                || !params.restores()
                || first.stop == Stop::MaxIterations
            {
                first
            } else {
                restore_rounds(&start, first, params, &solve, control)?
            }
        }
    };
    let mut out = start
        .with_positions(run.positions.clone())
        .map_err(|e| AlgoError::Input(format!("the optimised mesh is invalid: {e}")))?;
    let mut unfolded = None;
    if params.unfold && params.method != Method::Local && params.solver == Solver::Sqp {
        if let Some((m, u)) = open_new_folds(&start, &out, &model, &movable, params, control)? {
            out = m;
            unfolded = Some(u);
        }
    }
    // summarise measures the distance to the input, which can take seconds.
    Distance::report_stage(control);
    let mut summary = summarise(mesh, &levels, &start, &out, &model, &run, params);
    summary.unfold = unfolded;
    summary.patches = patches;
    Ok(Outcome {
        mesh: Some(out),
        patterns: None,
        summary,
        levels,
    })
}

/// Per vertex: whether another vertex sits at exactly its position (bitwise).
fn coincident_vertices(mesh: &Mesh) -> Vec<bool> {
    let mut first: std::collections::HashMap<[u64; 3], usize> = std::collections::HashMap::new();
    let mut out = vec![false; mesh.num_vertices()];
    for (v, p) in mesh.positions().iter().enumerate() {
        let key = p.map(f64::to_bits);
        if let Some(&u) = first.get(&key) {
            out[u] = true;
            out[v] = true;
        } else {
            first.insert(key, v);
        }
    }
    out
}

/// The folds and slivers (a corner below 1°) of a flattenable `out` that `start` did not
/// have, repaired where that keeps every constrained vertex within the tolerance
/// ([`super::unfold::unfold`]); None when there were none, or the result is not flattenable
/// (the unfolding keeps each vertex where it was, but a stalled run's answer is the best
/// iterate, which is left as it is).
fn open_new_folds(
    start: &Mesh,
    out: &Mesh,
    model: &Model<'_>,
    movable: &[bool],
    params: &Params,
    control: &dyn Control,
) -> Result<Option<(Mesh, super::unfold::Summary)>, AlgoError> {
    let tol = params.tolerance();
    let constrained: Vec<bool> = (0..start.num_vertices())
        .map(|v| model.is_interior(v))
        .collect();
    let theta = crate::geometry::angle_sums(out);
    let g_max = (0..start.num_vertices())
        .filter(|&v| constrained[v])
        .map(|v| (std::f64::consts::TAU - theta[v]).abs())
        .fold(0.0, f64::max);
    if g_max > tol {
        return Ok(None);
    }
    let old: std::collections::HashSet<u32> =
        crate::geometry::fold_edges(start).into_iter().collect();
    let folds: Vec<u32> = crate::geometry::fold_edges(out)
        .into_iter()
        .filter(|e| !old.contains(e))
        .collect();
    // Corners below 1° (what the objective phase's shape floor allows at most) that the
    // start did not have.
    let min_corner = crate::geometry::SLIVER_DEGREES.to_radians();
    let (small0, small) = (
        crate::geometry::min_corner_angles(start),
        crate::geometry::min_corner_angles(out),
    );
    let slivers: Vec<u32> = (0..out.num_faces())
        .filter(|&f| small[f] < min_corner && small0[f] >= min_corner)
        .map(|f| f as u32)
        .collect();
    if folds.is_empty() && slivers.is_empty() {
        return Ok(None);
    }
    let task = super::unfold::Task {
        folds: &folds,
        slivers: &slivers,
        min_corner,
        movable,
        constrained: &constrained,
        tolerance: tol,
    };
    let done = super::unfold::unfold(out, out.positions(), &task, control)?;
    Ok(out
        .with_positions(done.positions)
        .ok()
        .map(|m| (m, done.summary)))
}

/// Most restoration rounds (fl-mesh, then the SQP from its result): the first starts fl-mesh
/// from the input, the later ones from the result so far (the second whatever the first did,
/// the third only when the second lowered g_max). Measured on whole garments (issue 16 note):
/// the second round made mh_female_casualsuit02 flattenable (5.4e-3 after the first) and
/// took mh_male_worksuit01 from 8.7e-2 (the first round's fl-mesh ended higher, 0.69) to
/// 1.1e-2, the third to 5.7e-3.
const RESTORE_ROUNDS: usize = 3;

/// The solver of a `global`/`loop` run, started from the given positions.
type Solve<'a> = dyn Fn(&[[f64; 3]], &dyn Control) -> Result<Run, AlgoError> + 'a;

/// [`restore`] in up to [`RESTORE_ROUNDS`] rounds, the first from the input.
fn restore_rounds(
    start: &Mesh,
    first: Run,
    params: &Params,
    solve: &Solve<'_>,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let mut run = restore(start, start, first, params, solve, control)?;
    for _ in 1..RESTORE_ROUNDS {
        if run.g_max <= params.tolerance() || run.stop == Stop::MaxIterations {
            break;
        }
        let from = start
            .with_positions(run.positions.clone())
            .map_err(|e| AlgoError::Input(format!("the optimised mesh is invalid: {e}")))?;
        let before = run.g_max;
        run = restore(start, &from, run, params, solve, control)?;
        if run.g_max >= before {
            break;
        }
    }
    Ok(run)
}

/// The feasibility restoration after a run that stalled unflattenable (beyond the paper; the
/// issue's "feasibility-restoration phase"), written for `sqp` and used by `penalty_cg` too
/// when asked (`restore`): fl-mesh, whose globalisation
/// (non-monotone steps, retries, the developable cone) reaches θ = 2π where the SQP's
/// monotone Levenberg–Marquardt steps stall with every vertex at a similar g, is run from
/// the input with the boundary fixed and without refinement (the vertex set must stay E's);
/// from its flattenable result the same solver runs again (the SQP now in its objective
/// phase, lowering E + closeness along the constraints; the penalty from a point already
/// within its tolerance), with v⁰ still the input. Any constraint point
/// is as good a start as another for Eq. 8, so this changes where the solver ends, not what it
/// solves. `iterations` and `history` count both solver runs (fl-mesh's own iterations are in
/// the detail); `best_iteration` is the first run's count when the restoration's result
/// itself is returned (mh_shoes01: the SQP from it was stationary at once). From the input,
/// not from the solver's best iterate: that one is crumpled where the SQP stalled (mh_shoes01:
/// 128 folds, a corner of 0.002°), and fl-mesh from it stalled at 8.8e-4 where from the
/// input it converges. A restoration that does not converge but ends below the first run's
/// g_max is a start too (the solver keeps its best iterate, so it ends there at worst). When
/// the restoration ends no lower, or the run from its result ends no lower than the first, the
/// first run is returned and the detail says so.
fn restore(
    start: &Mesh,
    from: &Mesh,
    first: Run,
    params: &Params,
    solve: &Solve<'_>,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    use super::fl_mesh;
    let tol = params.tolerance();
    let fl = fl_mesh::Params {
        refine: false,
        tolerance: tol,
        // The objective phase moves on from here; its own shape floor keeps the folds.
        unfold: false,
        // The rounds alternate with the SQP already (`restore_rounds`).
        detour: false,
        // The SQP goes on with the input's faces.
        remesh: false,
        ..fl_mesh::Params::default()
    };
    let said = |first: &Run| {
        if first.stop_detail.is_empty() {
            first.stop.as_str().to_string()
        } else {
            first.stop_detail.clone()
        }
    };
    let origin = if std::ptr::eq(from, start) {
        "the input"
    } else {
        "the result so far"
    };
    let restoration = super::Renamed::after(control, "restoration");
    let (flat, report) = match fl_mesh::solve(from, &fl, &restoration) {
        Ok(done) => done,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => {
            let stop_detail = format!("{}; fl-mesh restoration failed: {e}", said(&first));
            return Ok(Run {
                stop_detail,
                ..first
            });
        }
    };
    // An unconverged restoration is still a start when it got lower than the SQP did (whole
    // garments: gt_tshirt2 of the issue 16 note, restoration 7.4e-4 against the SQP's 3.7e-2).
    if !report.converged && report.max_flattenability >= first.g_max {
        let stop_detail = format!(
            "{}; fl-mesh restoration from {origin} did not reach the tolerance either \
             (ϖ_max {:.2e}: {})",
            said(&first),
            report.max_flattenability,
            report.stop_reason
        );
        return Ok(Run {
            stop_detail,
            ..first
        });
    }
    if flat.num_vertices() != start.num_vertices() {
        let stop_detail = format!(
            "{}; fl-mesh restoration changed the vertex set (internal error), not used",
            said(&first)
        );
        return Ok(Run {
            stop_detail,
            ..first
        });
    }
    let second = solve(
        flat.positions(),
        &super::Renamed::after(control, "after restoration"),
    )?;
    // Never worse: fl-mesh's ϖ and E's g are measured by different code, so a start at the
    // tolerance could come back above it.
    if second.g_max > tol && second.g_max >= first.g_max {
        let stop_detail = format!(
            "{}; the run from fl-mesh's restoration ended no lower (g_max {:.2e}), not used",
            said(&first),
            second.g_max
        );
        return Ok(Run {
            stop_detail,
            ..first
        });
    }
    let first_said = said(&first);
    let offset = first.iterations;
    let mut history = first.history;
    history.extend(second.history.iter().map(|h| HistoryEntry {
        iteration: h.iteration + offset,
        ..*h
    }));
    let restored = if report.converged {
        format!("flattenable in {} iterations", report.iterations)
    } else {
        format!(
            "ϖ_max {:.2e} in {} iterations, lower than the first run's ({})",
            report.max_flattenability, report.iterations, report.stop_reason
        )
    };
    // A later round's first run is the earlier rounds, already named.
    let name = solver_name(params.solver);
    let first_said = match first_said.strip_prefix(&format!("{name}: ")) {
        Some(rest) => rest.to_string(),
        None => first_said,
    };
    let stop_detail = format!(
        "{name}: {} at g_max {:.2e}; fl-mesh restoration from {origin} (boundary fixed, no \
         refinement): {restored}; {name} from there: {}",
        first_said,
        first.g_max,
        if second.stop_detail.is_empty() {
            second.stop.as_str()
        } else {
            &second.stop_detail
        }
    );
    Ok(Run {
        iterations: offset + second.iterations,
        inner: first.inner + second.inner,
        evaluations: first.evaluations + second.evaluations,
        best_iteration: offset + second.best_iteration,
        stop_detail,
        history,
        g_max_input: first.g_max_input,
        ..second
    })
}

/// The solver's name as in the parameters.
fn solver_name(solver: Solver) -> &'static str {
    match solver {
        Solver::Sqp => "sqp",
        Solver::PenaltyCg => "penalty_cg",
    }
}

/// The figures, measured on the meshes (not taken from the solver).
fn summarise(
    input: &Mesh,
    levels: &[Mesh],
    start: &Mesh,
    out: &Mesh,
    model: &Model<'_>,
    run: &Run,
    params: &Params,
) -> Summary {
    let nv = start.num_vertices();
    // Measured on every interior vertex, those of closed components that cannot become
    // flattenable included (the solver leaves them out; the figures must not).
    let (g0, g1) = (defects(start), defects(out));
    let impossible = (0..nv)
        .filter(|&v| start.conn().is_interior(v as u32) && !model.is_interior(v))
        .count();
    let tol = params.tolerance();
    let displacement = super::displacement(start, out);
    let mut stuck: Vec<u32> = (0..nv as u32)
        .filter(|&v| g1[v as usize].abs() > tol)
        .collect();
    stuck.sort_by(|a, b| g1[*b as usize].abs().total_cmp(&g1[*a as usize].abs()));
    let lengths = crate::geometry::edge_lengths(out, out.positions());
    let d = params
        .d_tolerance
        .iter()
        .map(|&t| DAt {
            tolerance: t,
            before: developability(input, t),
            after: developability(out, t),
        })
        .collect();
    let table = (params.method == Method::Loop).then(|| {
        let vertices = std::iter::once(input)
            .chain(levels)
            .map(Mesh::num_vertices)
            .collect();
        let g_in = defects(input);
        LoopTable {
            levels: params.levels,
            vertices,
            rows: params
                .d_tolerance
                .iter()
                .map(|&t| {
                    let (d_ml, d_mr) = (developability(start, t), developability(out, t));
                    LoopRow {
                        tolerance: t,
                        d_m0: developability(input, t),
                        d_ml,
                        d_mr,
                        delta_d: delta_d(d_ml, d_mr),
                    }
                })
                .collect(),
            delta_s: delta_s(model.rest(), &lengths),
            big_g: [big_g(&g_in), big_g(&g0), big_g(&g1)],
            g_max: [g_max(&g_in), g_max(&g0), g_max(&g1)],
            hausdorff_ml_mr: Distance::hausdorff(out, start),
        }
    });
    Summary {
        method: params.method,
        solver: (params.method != Method::Local).then_some(params.solver),
        converged: g_max(&g1) <= tol,
        stop_reason: run.stop,
        stop_detail: match (run.stop_detail.is_empty(), impossible) {
            (true, 0) => run.stop.as_str().to_string(),
            (false, 0) => run.stop_detail.clone(),
            (_, k) => format!(
                "{}; {k} interior vertices lie on closed components whose Euler characteristic \
                 is not 0, which no deformation makes flattenable (Gauss–Bonnet)",
                if run.stop_detail.is_empty() {
                    run.stop.as_str()
                } else {
                    &run.stop_detail
                }
            ),
        },
        iterations: run.iterations,
        inner_steps: run.inner,
        best_iteration: run.best_iteration,
        tolerance: tol,
        g_max_before: g_max(&g0),
        g_max_after: g_max(&g1),
        big_g_before: big_g(&g0),
        big_g_after: big_g(&g1),
        e_after: model.e(out.positions()),
        d,
        delta_s: delta_s(model.rest(), &lengths),
        hausdorff_to_input: Distance::hausdorff(out, input),
        max_displacement: displacement.iter().copied().fold(0.0, f64::max),
        displacement,
        stuck_vertices: stuck,
        stalled_vertices: run.stalled.clone(),
        impossible_vertices: impossible,
        history: run.history.clone(),
        table,
        unfold: None,
        patches: super::fl_mesh::PatchesUsed::default(),
    }
}
