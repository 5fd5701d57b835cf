//! The jobs domain: which job kinds exist, what each needs and runs, and what a finished job
//! produces. It sits between the algorithms (pure functions on meshes) and the two front ends
//! (the CLI's `flatmesh run` and the service), which both go through it, so that a kind is
//! declared once: [`Kind`] lists the kinds, [`JobSpec`] holds a kind with its typed parameters,
//! and every per-kind decision is one exhaustive `match` below (adding a kind without handling
//! it anywhere does not compile). [`artifacts`] turns an outcome into the files a user
//! downloads, the same for the CLI and the service.

pub mod artifacts;

use crate::algorithms::{
    self, develop, fl_mesh, flatten, parse_params, perturb, report_job, segment, subdivide,
    AlgoError, Control,
};
use crate::mesh::Mesh;
use serde::Serialize;

/// A job kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// The flattenability report of the input.
    Report,
    /// Flat patterns (LPFB).
    Flatten,
    /// Make the mesh flattenable (FL-mesh optimisation).
    FlMesh,
    /// Variational subdivision of an FL mesh.
    Subdivide,
    /// Local flattenable perturbation against a reference body.
    Perturb,
    /// Developability by minimum deformation (Wang–Tang, Su et al.).
    Develop,
    /// Quasi-developable segmentation (VSA, min-cut, LPFB merging) and its patterns.
    Segment,
}

/// Whether a kind takes a reference body (`reference_mesh_id`, `--reference`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// A reference is refused.
    None,
    /// A reference may be given.
    Optional,
    /// A reference must be given.
    Required,
}

impl Kind {
    /// Every kind, in the order the CLI and the API list them.
    pub const ALL: [Kind; 7] = [
        Kind::Report,
        Kind::Flatten,
        Kind::FlMesh,
        Kind::Subdivide,
        Kind::Perturb,
        Kind::Develop,
        Kind::Segment,
    ];

    /// The kind's name in requests, on the command line and in the API.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Report => "report",
            Kind::Flatten => "flatten",
            Kind::FlMesh => "fl-mesh",
            Kind::Subdivide => "subdivide",
            Kind::Perturb => "perturb",
            Kind::Develop => "develop",
            Kind::Segment => "segment",
        }
    }

    /// The kind called `name`.
    pub fn from_name(name: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Every kind's name.
    pub fn names() -> Vec<&'static str> {
        Kind::ALL.iter().map(|k| k.name()).collect()
    }

    /// One line on what the kind does (CLI help).
    pub fn about(self) -> &'static str {
        match self {
            Kind::Report => "the flattenability report of the input; the mesh is unchanged",
            Kind::Flatten => {
                "cut-ready sewing-pattern pieces (LPFB), one per connected part of each \
                 patch, with seam allowance, notches and grain; also writes patterns.json, \
                 .svg, .dxf (AAMA) and patterns-plain.dxf, and the mesh carries the pattern as \
                 texture coordinates"
            }
            Kind::FlMesh => {
                "make the mesh flattenable (FL-mesh optimisation); the best iterate is written, \
                 never worse than the input in ϖ_max"
            }
            Kind::Subdivide => {
                "variational subdivision of an FL mesh (Sec. 3 of Wang's FL meshes); also \
                 writes level_<k>.glb, .gltf and .obj for every level"
            }
            Kind::Perturb => {
                "flattenable perturbation (Sec. 4 of Wang's FL meshes): the closest flattenable \
                 mesh, never into the reference body (global: whole-mesh SQP; local: the \
                 paper's Algorithm 2)"
            }
            Kind::Develop => {
                "developability by minimum deformation (Wang and Tang): every edge kept as close \
                 to its input length as θ = 2π at every interior vertex allows (global: exact \
                 SQP or the paper's penalty CG; local: moves along the normals; loop: Su et al., \
                 Loop subdivision first, also writes level_<k>.*)"
            }
            Kind::Segment => {
                "cut the mesh into quasi-developable charts (Wang's LPFB segmentation: VSA, \
                 min-cut refinement, merging while the merged chart flattens within the \
                 bounds) and flatten them; the mesh written has one patch per chart"
            }
        }
    }

    /// Its parameters with their defaults (CLI help; openapi.yaml has the schemas).
    pub fn params_help(self) -> &'static str {
        match self {
            Kind::Report => "none",
            Kind::Flatten => {
                "method=lpfb|lscm (lpfb), unit=mm|cm|dm|m|in (drawing unit, mm), \
                 input_unit=auto|mm|cm|dm|m|in (the mesh's unit; auto guesses it from the size), \
                 cuts=auto|virtual|real (auto: loops that enclose curvature are cut open, the \
                 others stay holes), curvature_tolerance (1e-3 rad), interior=arap|harmonic \
                 (arap), boundary_angles=conformal|surface (conformal), max_iterations (200), \
                 tolerance (1e-5), svg_triangles=true|false (false), seam_allowance (10 mm, \
                 in the drawing unit; 0: no cut line), hem_allowance (the seam allowance), \
                 seam_allowances ([{\"patches\": [A, B], \"allowance\": X}]), \
                 corners=mitre|square (mitre), mitre_limit (3), notch_spacing (50 mm; 0: seam \
                 ends only), grain=up|principal|none (up: the mesh's +Y; or a 3D \
                 direction [x, y, z]), \
                 fabric_width (1500 mm, for the cost estimate)"
            }
            Kind::FlMesh => {
                "w1 (1), w2 (0.1), tau (0.25), step_rule=merit|fixed|lm (merit), \
                 anchor=input|closest (input), until=flattenable|stationary (flattenable), \
                 tolerance (1e-6 rad), step_tolerance (1e-5), max_iterations (600), \
                 refine=true|false (true), max_refinements (3), stall_iterations (40), \
                 linear_solver=ldlt|lu (ldlt), shape_guard=true|false (false), shape_penalty \
                 (1; 0: the paper's model), min_angle (2 degrees), step_radius (0.5 mean \
                 edge lengths; 0: none), cone_start=auto|fallback|first|never (auto: a disk \
                 whose fitted total curvature is >= 0.25 or <= -1 rad (3 standard errors \
                 clear of 0) starts from the developable cone over its boundary, others as \
                 fallback; fallback: a disk \
                 that did not converge, or converged by crumpling, is run again from the \
                 cone), retry=true|false (true: a run that stalled before max_iterations is \
                 retried, its independent parts alone from the input and then once more from \
                 their best result, or a one-part mesh from its best result; each run gets \
                 max_iterations of its own), unfold=true|false (true: the folds, then the \
                 corners below min_angle, the run made are then repaired where that keeps \
                 every vertex flattenable, and a run of the paper's model that converged by \
                 folding is run again from the penalised result; not with until=stationary), \
                 detour=true|false (true: a stalled run still unconverged after the retries goes \
                 through develop's SQP, boundary held, and fl-mesh once more from there, and \
                 is replaced when that lowers the max flattenability; not with \
                 until=stationary), remesh=true|false (true: the new folds and corners below \
                 min_angle that a result still has after unfold are mended by edge flips and \
                 collapses and solved again, kept when that leaves fewer, or, on an \
                 unconverged result, when that lowers the max flattenability; a collapsed \
                 vertex stays in the output unreferenced; not with until=stationary), \
                 patches=auto|file|uv (auto: the islands of the file's texture layout are the \
                 patches when they cut the file's into at most 256 of 16 faces or more on \
                 average, and the file's o/g groups or glTF primitives when those islands \
                 stall and the file's become flattenable; each patch is made flattenable on \
                 its own, its seams held unless seams frees them; a cut inside an island is \
                 opened by appending copies of its vertices), seams=auto|held|free (auto: held, and when the \
                 islands of a one-patch file stall they are solved again with their seams \
                 free, kept if that converges or lowers the max flattenability, and when \
                 they converge with more folds than the input, kept if that converges with \
                 fewer; free: the \
                 seams between patches move with the surface, welded, and only the boundary \
                 is held)"
            }
            Kind::Subdivide => {
                "levels (1; or --levels), curves (or --curves), split_ratio (0.5), \
                 first_order_runs (10), second_order_runs (100), flatten_levels=true|false \
                 (true), fl_mesh={...} (the fl-mesh parameters used on each level)"
            }
            Kind::Perturb => {
                "method=global|local (global; local: Algorithm 2), tolerance (1e-6 rad for \
                 global, 1e-3 for local), clearance (0: least signed distance to the reference \
                 body, mesh units), max_iterations (global: 300), stall_iterations (global: \
                 40), fairing (global: 0), shape_penalty (global: 1), rings (local: 3), tau \
                 (local: 0.1), inner_iterations (local: 5), heap_fraction (local: 0.5), \
                 stall_outer (local: 10), max_outer (local: 50), parallel=true|false (local: \
                 true; false: the paper's strict heap order)"
            }
            Kind::Develop => {
                "method=global|local|loop (global), tolerance (g_max in rad: 1e-6 for global and \
                 loop, 1e-4 for local), d_tolerance (where D[M] is reported: [1e-6, 1e-4, 1e-3, \
                 1e-2]), solver=sqp|penalty_cg (global and loop: sqp), max_iterations (global \
                 and loop: 200), fix_boundary=true|false (global and loop: false), \
                 patches=file|auto|uv (file; uv: one patch per island of the file's texture \
                 layout, auto: uv when the layout cuts the file's patches into a sewing \
                 pattern, as fl-mesh's patches; seams stay welded and move unless \
                 fix_boundary, never with local), closeness \
                 (sqp: 1e-2), smoothness (sqp: 10, then 0 once flattenable), fold_barrier (sqp: 1; 0: \
                 off; once flattenable, the hinges turning past 90 degrees or the input's own \
                 angle are penalised), corner_barrier (sqp: 1000; 0: off; once flattenable, \
                 the corners closing below 3 degrees or the input's own corner are \
                 penalised), step_tolerance \
                 (sqp: 1e-4), stall_iterations (sqp: 40), restore=true|false (global and \
                 loop; sqp: true, penalty_cg: false; an unflattenable stall is followed by \
                 fl-mesh from the input, boundary fixed, and the same solver again from its \
                 result when that is flattenable or lower, with \
                 max_iterations of its own; up to three rounds, the second from the result so \
                 far, the third only when the second lowered g_max), \
                 unfold=true|false (sqp: true; a flattenable result's new folds and corners \
                 below 1 degree are repaired along the constraints), eta \
                 (penalty_cg: 1e-4), cg_steps (penalty_cg: 5), rho_growth (penalty_cg: 1, the \
                 paper's schedule; > 1: rho grows at least that much a phase, eta then relative \
                 to the last G), preconditioner=none|gauss_newton (penalty_cg: none; \
                 gauss_newton: each phase's CG preconditioned by the Gauss-Newton Hessian of \
                 the penalty, with rho_growth 2 it reaches the constraint where the paper's \
                 stalls, no shape guard), delta_t (local: the mean edge \
                 length), max_moves (local: 500000), update=gauss_newton|newton (local: \
                 gauss_newton), relaxation (local gauss_newton: 1.8), min_gain (local \
                 gauss_newton: 1e-2, a move must also lower G = sum g^2 by this share of its mean per \
                 vertex; 0: no floor), levels (loop: 1)"
            }
            Kind::Segment => {
                "vsa_tolerance (5e-4: largest chart L^{2,1} error over the total area), \
                 max_charts (256), lloyd_iterations (50), fuzzy_rings (3; 0 skips the min-cut), \
                 denoise=true|false (false: the paper's step 3 moves the user's geometry), \
                 max_area_distortion (10 %), max_l2_stretch (2.0), reject_overlap=true|false \
                 (true), retry_rejected=true|false (false), merge=patch|boundary (patch), \
                 keep_patches=true|false (true: never across the input's seams), \
                 interior=arap|harmonic (arap), boundary_angles=conformal|surface (conformal), \
                 unit=mm|cm|dm|m|in (mm), input_unit=auto|mm|cm|dm|m|in (auto), \
                 then=none|fl-mesh (none; fl-mesh: every chart made exactly flattenable, its \
                 boundary fixed, before flattening; a chart that fails is split), \
                 fl_mesh={...} (the fl-mesh parameters of that run; refine must stay false), \
                 max_stretch (0.1 %: with then=fl-mesh, a chart whose pattern stretches more \
                 is split)"
            }
        }
    }

    /// Whether it takes a reference body.
    pub fn reference(self) -> Reference {
        match self {
            Kind::Report
            | Kind::Flatten
            | Kind::FlMesh
            | Kind::Subdivide
            | Kind::Develop
            | Kind::Segment => Reference::None,
            Kind::Perturb => Reference::Optional,
        }
    }
}

/// Why a job cannot be accepted, naming the request field at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// The kind does not exist.
    #[error("unknown job kind `{0}` (available: {kinds})", kinds = Kind::names().join(", "))]
    UnknownKind(String),
    /// A parameter is unknown or out of range.
    #[error("{0}")]
    Params(AlgoError),
    /// The reference body was given to a kind that does not use one, or is missing.
    #[error("{0}")]
    Reference(String),
}

/// A job kind with its typed, checked parameters.
#[derive(Debug, Clone)]
pub enum JobSpec {
    /// `report`.
    Report(report_job::Params),
    /// `flatten`.
    Flatten(flatten::Params),
    /// `fl-mesh`.
    FlMesh(fl_mesh::Params),
    /// `subdivide`.
    Subdivide(subdivide::Params),
    /// `perturb`.
    Perturb(perturb::Params),
    /// `develop`.
    Develop(develop::Params),
    /// `segment`.
    Segment(segment::Params),
}

impl JobSpec {
    /// Parse and range-check the parameters of `kind`.
    pub fn parse(
        kind: &str,
        params: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<JobSpec, SpecError> {
        let k = Kind::from_name(kind).ok_or_else(|| SpecError::UnknownKind(kind.into()))?;
        Ok(match k {
            Kind::Report => JobSpec::Report(parse_params(params).map_err(SpecError::Params)?),
            Kind::Flatten => {
                let p: flatten::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::Flatten(p)
            }
            Kind::FlMesh => {
                let p: fl_mesh::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::FlMesh(p)
            }
            Kind::Subdivide => {
                let p: subdivide::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::Subdivide(p)
            }
            Kind::Perturb => {
                let p: perturb::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::Perturb(p)
            }
            Kind::Develop => {
                let p: develop::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::Develop(p)
            }
            Kind::Segment => {
                let p: segment::Params = parse_params(params).map_err(SpecError::Params)?;
                p.check().map_err(SpecError::Params)?;
                JobSpec::Segment(p)
            }
        })
    }

    /// Refuse a reference body given to a kind that does not use one, or missing for a kind
    /// that needs one.
    pub fn check_reference(&self, has_reference: bool) -> Result<(), SpecError> {
        let kind = self.kind().name();
        match (self.kind().reference(), has_reference) {
            (Reference::None, true) => Err(SpecError::Reference(format!(
                "`{kind}` does not use a reference body; leave it out"
            ))),
            (Reference::Required, false) => Err(SpecError::Reference(format!(
                "`{kind}` needs a reference body"
            ))),
            _ => Ok(()),
        }
    }

    /// Most faces a mesh the job makes can have, from its input's (each subdivision level
    /// multiplies them by four): what a server checks against its budget before queueing.
    pub fn output_faces(&self, input_faces: usize) -> usize {
        let levels = match self {
            JobSpec::Subdivide(p) => p.levels,
            JobSpec::Develop(p) if p.method == develop::Method::Loop => p.levels,
            _ => 0,
        };
        input_faces.saturating_mul(4usize.saturating_pow(levels.min(64) as u32))
    }

    /// Its kind.
    pub fn kind(&self) -> Kind {
        match self {
            JobSpec::Report(_) => Kind::Report,
            JobSpec::Flatten(_) => Kind::Flatten,
            JobSpec::FlMesh(_) => Kind::FlMesh,
            JobSpec::Subdivide(_) => Kind::Subdivide,
            JobSpec::Perturb(_) => Kind::Perturb,
            JobSpec::Develop(_) => Kind::Develop,
            JobSpec::Segment(_) => Kind::Segment,
        }
    }

    /// The parameters as JSON, every default filled in.
    pub fn params(&self) -> serde_json::Value {
        match self {
            JobSpec::Report(p) => serde_json::to_value(p),
            JobSpec::Flatten(p) => serde_json::to_value(p),
            JobSpec::FlMesh(p) => serde_json::to_value(p),
            JobSpec::Subdivide(p) => serde_json::to_value(p),
            JobSpec::Perturb(p) => serde_json::to_value(p),
            JobSpec::Develop(p) => serde_json::to_value(p),
            JobSpec::Segment(p) => serde_json::to_value(p),
        }
        .unwrap_or_default()
    }

    /// Run it; a kind that changes the mesh without flattening it also gets the patterns of
    /// its output ([`artifacts::derive_patterns`]).
    pub fn run(&self, input: &Input, control: &dyn Control) -> Result<JobOutcome, AlgoError> {
        let mut outcome = self.run_algorithm(input, control)?;
        outcome.shape = artifacts::check_shape(&input.mesh, &outcome);
        artifacts::derive_patterns(&mut outcome, control)?;
        Ok(outcome)
    }

    fn run_algorithm(&self, input: &Input, control: &dyn Control) -> Result<JobOutcome, AlgoError> {
        let mesh = &input.mesh;
        Ok(match self {
            JobSpec::Report(p) => report_job::run(mesh, p, control)?.into_job(Figures::Report),
            JobSpec::Flatten(p) => flatten::run(mesh, p, control)?.into_job(Figures::Flatten),
            JobSpec::FlMesh(p) => fl_mesh::run(mesh, p, control)?.into_job(Figures::FlMesh),
            JobSpec::Subdivide(p) => subdivide::run(mesh, p, control)?.into_job(Figures::Subdivide),
            JobSpec::Perturb(p) => {
                perturb::run(mesh, input.reference.as_ref(), p, control)?.into_job(Figures::Perturb)
            }
            JobSpec::Develop(p) => develop::run(mesh, p, control)?.into_job(Figures::Develop),
            JobSpec::Segment(p) => {
                segment::run(mesh, p, control)?.into_job(|s| Figures::Segment(Box::new(s)))
            }
        })
    }
}

/// Everything a job needs.
#[derive(Debug, Clone)]
pub struct Input {
    /// The mesh to work on.
    pub mesh: Mesh,
    /// A reference body, for the kinds that take one ([`Kind::reference`]).
    pub reference: Option<Mesh>,
}

/// An algorithm's own figures, typed per kind; serialised as the algorithm's struct.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum Figures {
    /// `report` has none.
    Report(report_job::Summary),
    /// `flatten`.
    Flatten(flatten::Summary),
    /// `fl-mesh`.
    FlMesh(fl_mesh::Summary),
    /// `subdivide`.
    Subdivide(subdivide::Summary),
    /// `perturb`.
    Perturb(perturb::Summary),
    /// `develop`.
    Develop(develop::Summary),
    /// `segment` (boxed: its per-face and per-vertex maps make it the largest).
    Segment(Box<segment::Summary>),
}

impl Figures {
    /// Whether an iterative kind converged (None for kinds that do not iterate).
    pub fn converged(&self) -> Option<bool> {
        match self {
            Figures::Report(_) | Figures::Flatten(_) => None,
            Figures::Segment(s) => s.fl_mesh.as_ref().map(|r| r.converged),
            Figures::FlMesh(s) => Some(s.report.converged),
            Figures::Subdivide(s) => Some(s.converged),
            Figures::Perturb(s) => Some(s.converged),
            Figures::Develop(s) => Some(s.converged),
        }
    }

    /// Why an iterative kind stopped.
    pub fn stop_reason(&self) -> Option<&str> {
        match self {
            Figures::Report(_) | Figures::Flatten(_) => None,
            Figures::Segment(s) => s.fl_mesh.as_ref().map(|r| r.stop_reason.as_str()),
            Figures::FlMesh(s) => Some(&s.report.stop_reason),
            Figures::Subdivide(s) => s.stop_reason.as_deref(),
            Figures::Perturb(s) => Some(&s.stop_detail),
            Figures::Develop(s) => Some(&s.stop_detail),
        }
    }

    /// Problems of the patterns a kind made itself (pieces skipped, or outside the bounds);
    /// derived patterns keep theirs in [`JobOutcome::pattern_warnings`].
    pub fn pattern_warnings(&self) -> &[String] {
        match self {
            Figures::Flatten(s) => &s.job_warnings,
            Figures::Segment(s) => &s.flatten.job_warnings,
            _ => &[],
        }
    }

    /// Interior vertices an optimiser left above its tolerance.
    pub fn stuck_vertices(&self) -> &[u32] {
        match self {
            Figures::Report(_) | Figures::Flatten(_) => &[],
            Figures::Segment(s) => s.fl_mesh.as_ref().map_or(&[], |r| &r.stuck_vertices),
            Figures::FlMesh(s) => &s.report.stuck_vertices,
            Figures::Subdivide(s) => &s.stuck_vertices,
            Figures::Perturb(s) => &s.stuck_vertices,
            Figures::Develop(s) => &s.stuck_vertices,
        }
    }

    /// Warnings for the user about the result (pieces skipped or not usable).
    pub fn warnings(&self) -> &[String] {
        match self {
            Figures::Flatten(s) => &s.job_warnings,
            Figures::Segment(s) => &s.flatten.job_warnings,
            Figures::Perturb(s) => &s.warnings,
            Figures::Report(_)
            | Figures::FlMesh(_)
            | Figures::Subdivide(_)
            | Figures::Develop(_) => &[],
        }
    }
}

/// What a job produced.
#[derive(Debug, Clone)]
pub struct JobOutcome {
    /// The output mesh, for kinds that change the mesh.
    pub mesh: Option<Mesh>,
    /// Flat patterns, for kinds that flatten.
    pub patterns: Option<crate::pattern::Patterns>,
    /// Every level's mesh (`subdivide`).
    pub levels: Vec<Mesh>,
    /// The algorithm's figures.
    pub figures: Figures,
    /// Warnings of the patterns derived from a mesh-changing job's output.
    pub pattern_warnings: Vec<String>,
    /// Why a mesh-changing job's output could not be flattened.
    pub patterns_unavailable: Option<String>,
    /// Folds and slivers of a mesh-changing job's output against its input.
    pub shape: Option<artifacts::ShapeCheck>,
}

trait IntoJob<S> {
    fn into_job(self, wrap: fn(S) -> Figures) -> JobOutcome;
}

impl<S> IntoJob<S> for algorithms::Outcome<S> {
    fn into_job(self, wrap: fn(S) -> Figures) -> JobOutcome {
        JobOutcome {
            mesh: self.mesh,
            patterns: self.patterns,
            levels: self.levels,
            figures: wrap(self.summary),
            pattern_warnings: Vec::new(),
            patterns_unavailable: None,
            shape: None,
        }
    }
}
