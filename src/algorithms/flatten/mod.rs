//! The `flatten` job: every patch becomes a flat sewing-pattern piece whose boundary keeps its
//! 3D edge lengths (wang-lpfb-quasi-developable-segmentation, Sec. 3 and 4.1).
//!
//! Per piece (a connected component of a patch; rayon over pieces):
//! 1. topology ([`cut`]): wedge-split vertices, boundary loops, outer loop = longest in 3D;
//! 2. real cuts ([`cut::plan_cuts`], beyond the paper): an inner loop stays a hole only if it
//!    can close in the plane, i.e. a disk filling it would enclose no Gaussian curvature
//!    (Gauss–Bonnet, [`cut::loop_turning`]); a tube's other rim, a cone's small rim, a sleeve
//!    opening cannot, and are cut open to the outer loop along shortest interior paths. A
//!    closed piece is cut along a shortest-path tree through its curved vertices. The paper
//!    keeps every loop as a hole (Sec. 3.2), which for a tube gives flipped triangles and a
//!    boundary stretched 30-fold; `cuts = "virtual"` still does that;
//! 3. the virtual cut of Sec. 3.2 for the holes that stay (Dijkstra paths inner → outer);
//! 4. LPFB ([`lpfb`]): Eq. 9/10 solved by Eq. 11–14, boundary by Eq. 6–7, mapped back from the
//!    cut loop to the loops of the piece (Sec. 3.2 step 6). Beyond the paper, by default the
//!    θ targets of Eq. 8 are not the surface angles a_i but a_i corrected for the curvature
//!    inside the piece ([`param::CotanSystem::angle_shift`], Boundary First Flattening's
//!    Yamabe step with boundary scale 0): with a_i, a non-developable piece's whole angle
//!    defect is left to the interior solve, which on the noisy half-cylinders gave 3–9 times
//!    the area distortion of BFF and on raw garments hundreds of flipped triangles; the
//!    lengths stay exact either way. `boundary_angles = "surface"` is the paper;
//! 5. interior ([`param`]): intrinsic parameterization with the LPFB fixed, Eq. 15–18, then by
//!    default ARAP steps with the boundary still fixed (`interior = "harmonic"` is the paper);
//! 6. measures ([`measures`]): A(Ω), L²/L∞ stretch, Π_L, Π_θ, flips, S(Ω), σ1/σ2 stretch, the
//!    worst boundary edge against 3D, ϖ_max of the piece.
//!
//! `method = "lscm"` replaces 3–5 by a free-boundary LSCM (baseline, as in Table 1).
//! Seams: every chain of edges shared by two pieces, with its 3D length and its length on both,
//! and every real cut as a seam of its piece with itself. Two boundary edges that join the same
//! two positions bit for bit are sewn (`joints`): panels exported unwelded, a slit opened by
//! copies.
//!
//! A piece that cannot be flattened (genus > 0, closed with its curvature spread out) is
//! skipped with a warning naming it and its triangles; the others are still produced.
//!
//! Units: the JSON pattern is in the mesh's own units. The mesh's unit is the parameter
//! `input_unit`, guessed from the mesh's size by default ([`Unit::guess`]: garment exports
//! come in m, cm, mm and MakeHuman's dm, and a guess that is wrong by 10× is obvious in the
//! drawing, whereas a fixed default of metres drew a centimetre mesh 64 m wide); the SVG and
//! DXF drawings are scaled to `unit` (default `mm`).

pub mod cut;
pub mod finish;
pub mod lpfb;
pub mod marker;
pub mod measures;
pub mod param;

use super::{AlgoError, Control, Outcome};
use crate::geometry::DEVELOPABLE_TOLERANCE;
use crate::mesh::{Mesh, NONE};
use crate::pattern::{Patterns, Piece, Seam};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::time::Instant;

/// Flattening method.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Length-preserved free boundary + intrinsic parameterization (the paper).
    #[default]
    Lpfb,
    /// Least-squares conformal map, free boundary (baseline).
    Lscm,
}

/// A length unit for the input mesh and the drawings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Unit {
    /// Millimetre.
    #[default]
    Mm,
    /// Centimetre.
    Cm,
    /// Decimetre (MakeHuman's unit).
    Dm,
    /// Metre.
    M,
    /// Inch.
    In,
}

impl Unit {
    /// The unit of a name as written in files.
    pub fn parse(name: &str) -> Option<Unit> {
        [Unit::Mm, Unit::Cm, Unit::Dm, Unit::M, Unit::In]
            .into_iter()
            .find(|u| u.name() == name)
    }

    /// The unit's name as written in files.
    pub fn name(self) -> &'static str {
        match self {
            Unit::Mm => "mm",
            Unit::Cm => "cm",
            Unit::Dm => "dm",
            Unit::M => "m",
            Unit::In => "in",
        }
    }
}

impl Unit {
    /// The unit a mesh of this bounding-box diagonal is most likely in, taking the pieces to be
    /// garment-sized: the one unit that puts the diagonal in [0.3, 3) m (a garment is 0.3–2 m,
    /// a whole outfit in T-pose up to ~2.6 m). Below that range metres, above it millimetres.
    /// So diagonal d < 3 → m, 3 ≤ d < 30 → dm, 30 ≤ d < 300 → cm, else mm.
    pub fn guess(diagonal: f64) -> Unit {
        if diagonal.is_nan() || diagonal < 3.0 {
            Unit::M
        } else if diagonal < 30.0 {
            Unit::Dm
        } else if diagonal < 300.0 {
            Unit::Cm
        } else {
            Unit::Mm
        }
    }
}

/// The unit of the mesh's coordinates: a [`Unit`], or `auto` (default) to guess it from the
/// mesh's size ([`Unit::guess`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum InputUnit {
    /// Guess from the bounding-box diagonal.
    #[default]
    Auto,
    /// Millimetre.
    Mm,
    /// Centimetre.
    Cm,
    /// Decimetre.
    Dm,
    /// Metre.
    M,
    /// Inch.
    In,
}

impl InputUnit {
    /// The unit given, None for `auto`.
    pub fn fixed(self) -> Option<Unit> {
        match self {
            InputUnit::Auto => None,
            InputUnit::Mm => Some(Unit::Mm),
            InputUnit::Cm => Some(Unit::Cm),
            InputUnit::Dm => Some(Unit::Dm),
            InputUnit::M => Some(Unit::M),
            InputUnit::In => Some(Unit::In),
        }
    }
}

fn default_curvature_tolerance() -> f64 {
    1e-3
}
fn default_max_iterations() -> usize {
    200
}
fn default_tolerance() -> f64 {
    1e-5
}
fn default_mitre_limit() -> f64 {
    3.0
}

/// Seam allowance when none is given, in millimetres.
pub const DEFAULT_SEAM_ALLOWANCE_MM: f64 = 10.0;
/// Arc length between notches when none is given, in millimetres.
pub const DEFAULT_NOTCH_SPACING_MM: f64 = 50.0;
/// Width of the roll for the cost estimate when none is given, in millimetres.
pub const DEFAULT_FABRIC_WIDTH_MM: f64 = 1500.0;

/// Parameters of `flatten`; unknown keys are refused.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// `lpfb` (default) or `lscm`.
    #[serde(default)]
    pub method: Method,
    /// Unit of the SVG and DXF drawings (`mm` default, `cm`, `m`, `in`).
    #[serde(default)]
    pub unit: Unit,
    /// Unit the mesh's coordinates are in (`auto` default: guessed from its size).
    #[serde(default)]
    pub input_unit: InputUnit,
    /// How inner boundary loops are treated: `auto` (default), `virtual`, `real`.
    #[serde(default)]
    pub cuts: cut::Cuts,
    /// Interior solve after LPFB: `arap` (default) or `harmonic` (the paper's Eq. 15–18).
    #[serde(default)]
    pub interior: param::Interior,
    /// LPFB's boundary angle targets: `conformal` (default: surface angles corrected for the
    /// interior curvature, as Boundary First Flattening) or `surface` (Eq. 8 as written).
    #[serde(default)]
    pub boundary_angles: param::BoundaryAngles,
    /// Curvature (radians) a hole may enclose and still stay closed in the plane, and above
    /// which a vertex of a closed piece counts as curved (1e-3).
    #[serde(default = "default_curvature_tolerance")]
    pub curvature_tolerance: f64,
    /// Most SQP iterations of LPFB (Eq. 12) per piece.
    #[serde(default = "default_max_iterations")]
    pub max_iterations: usize,
    /// Stop LPFB when ‖∇J‖ falls below this (the paper's 1e-5).
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Draw the triangles in the SVG as well as the outlines.
    #[serde(default)]
    pub svg_triangles: bool,
    /// Seam allowance in the drawing unit (default 10 mm); 0 draws no cut line.
    #[serde(default)]
    pub seam_allowance: Option<f64>,
    /// Allowance on free boundary edges (hems, necklines), in the drawing unit (default: the
    /// seam allowance).
    #[serde(default)]
    pub hem_allowance: Option<f64>,
    /// Allowances for the seams between two named pieces (the same name twice: that piece's
    /// real cuts), in the drawing unit.
    #[serde(default)]
    pub seam_allowances: Vec<finish::SeamAllowance>,
    /// Cut-line corners: `mitre` (default) or `square`.
    #[serde(default)]
    pub corners: finish::Corners,
    /// A mitred corner reaching further than this many allowances from its sew-line corner is
    /// squared off there (3).
    #[serde(default = "default_mitre_limit")]
    pub mitre_limit: f64,
    /// Arc length between notches along a seam, in the drawing unit (default 50 mm; 0: at the
    /// seam ends only).
    #[serde(default)]
    pub notch_spacing: Option<f64>,
    /// Grain: `up` (default: the mesh's +Y axis), `principal` (each piece's longest axis),
    /// `none` (pieces as flattened), or a 3D direction `[x, y, z]`.
    #[serde(default)]
    pub grain: finish::Grain,
    /// Width of the fabric roll for the cost estimate, in the drawing unit (default 1500 mm).
    #[serde(default)]
    pub fabric_width: Option<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            method: Method::Lpfb,
            unit: Unit::Mm,
            input_unit: InputUnit::Auto,
            cuts: cut::Cuts::Auto,
            interior: param::Interior::Arap,
            boundary_angles: param::BoundaryAngles::Conformal,
            curvature_tolerance: default_curvature_tolerance(),
            max_iterations: default_max_iterations(),
            tolerance: default_tolerance(),
            svg_triangles: false,
            seam_allowance: None,
            hem_allowance: None,
            seam_allowances: Vec::new(),
            corners: finish::Corners::Mitre,
            mitre_limit: default_mitre_limit(),
            notch_spacing: None,
            grain: finish::Grain::Up,
            fabric_width: None,
        }
    }
}

impl Params {
    /// Range checks.
    pub fn check(&self) -> Result<(), AlgoError> {
        if self.max_iterations == 0 || self.max_iterations > 100_000 {
            return Err(AlgoError::InvalidParam {
                key: "max_iterations".into(),
                message: format!("must be in 1..=100000, got {}", self.max_iterations),
            });
        }
        if !(self.curvature_tolerance > 0.0 && self.curvature_tolerance < 1.0) {
            return Err(AlgoError::InvalidParam {
                key: "curvature_tolerance".into(),
                message: format!("must be in (0, 1), got {}", self.curvature_tolerance),
            });
        }
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(AlgoError::InvalidParam {
                key: "tolerance".into(),
                message: format!("must be in (0, 1), got {}", self.tolerance),
            });
        }
        let mm = crate::pattern::mm_per(self.unit.name()).unwrap_or(1.0);
        let unit = self.unit.name();
        let length = |key: &str, v: Option<f64>, min_mm: f64| -> Result<(), AlgoError> {
            match v {
                Some(x) if !(x.is_finite() && x >= 0.0 && x * mm <= 1000.0) => {
                    Err(AlgoError::InvalidParam {
                        key: key.into(),
                        message: format!("must be in 0..={} {unit}, got {x}", 1000.0 / mm),
                    })
                }
                Some(x) if x > 0.0 && x * mm < min_mm => Err(AlgoError::InvalidParam {
                    key: key.into(),
                    message: format!("must be 0 or at least {} {unit}, got {x}", min_mm / mm),
                }),
                _ => Ok(()),
            }
        };
        length("seam_allowance", self.seam_allowance, 0.0)?;
        length("hem_allowance", self.hem_allowance, 0.0)?;
        length("notch_spacing", self.notch_spacing, 1.0)?;
        if let Some(w) = self.fabric_width {
            if !(w.is_finite() && w > 0.0 && w * mm <= 100_000.0) {
                return Err(AlgoError::InvalidParam {
                    key: "fabric_width".into(),
                    message: format!("must be in (0, {}] {unit}, got {w}", 100_000.0 / mm),
                });
            }
        }
        if self.seam_allowances.len() > 10_000 {
            return Err(AlgoError::InvalidParam {
                key: "seam_allowances".into(),
                message: format!("at most 10000 entries, got {}", self.seam_allowances.len()),
            });
        }
        for (k, o) in self.seam_allowances.iter().enumerate() {
            length(
                &format!("seam_allowances[{k}].allowance"),
                Some(o.allowance),
                0.0,
            )?;
        }
        if !(self.mitre_limit >= 1.0 && self.mitre_limit <= 100.0) {
            return Err(AlgoError::InvalidParam {
                key: "mitre_limit".into(),
                message: format!("must be in 1..=100, got {}", self.mitre_limit),
            });
        }
        if let finish::Grain::Direction(g) = self.grain {
            let l = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if !(l.is_finite() && l > 0.0) {
                return Err(AlgoError::InvalidParam {
                    key: "grain".into(),
                    message: format!("must be a finite, non-zero direction, got {g:?}"),
                });
            }
        }
        Ok(())
    }

    /// The roll width of the cost estimate, in the drawing unit.
    pub fn fabric_width(&self) -> f64 {
        let mm = crate::pattern::mm_per(self.unit.name()).unwrap_or(1.0);
        self.fabric_width.unwrap_or(DEFAULT_FABRIC_WIDTH_MM / mm)
    }

    /// Grain, notches and allowances in mesh units for a mesh in `input_unit`.
    pub fn finish(&self, input_unit: Unit) -> finish::Finish {
        let mm = crate::pattern::mm_per(self.unit.name()).unwrap_or(1.0);
        // mesh units per drawing unit
        let k = mm / crate::pattern::mm_per(input_unit.name()).unwrap_or(1.0);
        let seam = self
            .seam_allowance
            .unwrap_or(DEFAULT_SEAM_ALLOWANCE_MM / mm);
        finish::Finish {
            seam_allowance: seam * k,
            hem_allowance: self.hem_allowance.unwrap_or(seam) * k,
            overrides: self
                .seam_allowances
                .iter()
                .map(|o| (o.patches.clone(), o.allowance * k))
                .collect(),
            mitre_limit: match self.corners {
                finish::Corners::Mitre => self.mitre_limit,
                finish::Corners::Square => 1.0,
            },
            notch_spacing: self.notch_spacing.unwrap_or(DEFAULT_NOTCH_SPACING_MM / mm) * k,
            grain: self.grain,
        }
    }
}

/// What flattening one piece produced besides the piece.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PieceInfo {
    /// Piece name.
    pub piece: String,
    /// Faces.
    pub faces: usize,
    /// Boundary loops of the piece as given.
    pub loops: usize,
    /// Real cuts made (each a seam of the piece with itself).
    pub real_cuts: usize,
    /// Inner loops kept as holes, closed in the plane.
    pub holes: usize,
    /// K(D) = 2π + turning of each inner loop as given: the curvature a disk filling it would
    /// enclose (0 for a hole that can close flat).
    pub enclosed_curvature: Vec<f64>,
    /// Curved vertices a closed piece was cut through.
    pub cone_points: usize,
    /// Cut paths of the virtual cut (one per hole).
    pub cut_paths: usize,
    /// LPFB SQP iterations.
    pub iterations: usize,
    /// Whether LPFB reached its tolerance (always true for LSCM).
    pub converged: bool,
    /// Final ‖∇J‖ of LPFB.
    pub grad_norm: f64,
    /// Iterations that needed the SVD pseudo-inverse.
    pub svd_steps: usize,
    /// Step halvings of the LPFB line search.
    pub backtracks: usize,
    /// Largest LPFB constraint residual after closing.
    pub constraint_residual: f64,
    /// Largest distance between copies of one vertex on the LPFB of the cut disk, relative to
    /// the piece's diameter (0 without holes).
    pub cut_coincidence: f64,
    /// Seconds in LPFB, interior solve, measures.
    pub seconds_lpfb: f64,
    /// Seconds in the interior (or LSCM) solve.
    pub seconds_param: f64,
    /// Seconds in the measures.
    pub seconds_measures: f64,
    /// The real cuts as mesh vertex paths, for the seams.
    #[serde(skip)]
    pub real_cut_paths: Vec<Vec<u32>>,
}

/// Where a piece is in the input, for messages: its patch (OBJ group, glTF primitive) and the
/// range of its triangles in mesh order.
fn describe(name: &str, faces: &[u32]) -> String {
    let lo = faces.iter().min().copied().unwrap_or(0);
    let hi = faces.iter().max().copied().unwrap_or(0);
    format!(
        "piece `{name}` (triangles {lo}–{hi}, {} in all)",
        faces.len()
    )
}

fn diameter(pos: &[[f64; 3]]) -> f64 {
    let (lo, hi) = crate::mesh::bbox_of(pos.iter().copied());
    cut::dist(lo, hi)
}

/// The loop's θ targets a_i − shift (see [`param::CotanSystem::angle_shift`]). A boundary
/// vertex with several copies on the loop (the end of a virtual cut path) shares its shift
/// among them in proportion to their angles; copies of interior vertices (cut path vertices)
/// keep a_i.
fn shifted_targets(cl: &cut::CutLoop, shift: &[f64]) -> Vec<f64> {
    let mut total = vec![0.0; shift.len()];
    for (&v, &a) in cl.vertex.iter().zip(&cl.angle) {
        total[v as usize] += a;
    }
    cl.vertex
        .iter()
        .zip(&cl.angle)
        .map(|(&v, &a)| {
            let v = v as usize;
            if total[v] > 0.0 {
                a - shift[v] * a / total[v]
            } else {
                a
            }
        })
        .collect()
}

/// LPFB of a piece (Sec. 3): planar positions of its boundary vertices, with solver figures.
/// `shift` moves the θ targets off the surface angles (the conformal boundary angles).
pub fn lpfb_boundary(
    p: &cut::Piece3,
    params: &Params,
    shift: Option<&[f64]>,
    control: &dyn Control,
    info: &mut PieceInfo,
) -> Result<Vec<Option<[f64; 2]>>, AlgoError> {
    let err = |e: String| AlgoError::Input(format!("piece `{}`: {e}", p.name));
    let paths = cut::cut_paths(p)?;
    let cl = cut::cut_loop(p, &paths, &p.corners).map_err(err)?;
    let n = cl.vertex.len();
    let lengths: Vec<f64> = (0..n)
        .map(|k| {
            cut::dist(
                p.pos[cl.vertex[k] as usize],
                p.pos[cl.vertex[(k + 1) % n] as usize],
            )
        })
        .collect();
    let angles = match shift {
        None => cl.angle.clone(),
        Some(s) => shifted_targets(&cl, s),
    };
    let problem = lpfb::Problem {
        lengths,
        angles,
        pairs: cl.seeds.clone(),
        antiparallel: cl.cut_edges.clone(),
    };
    let sol = lpfb::solve(
        &problem,
        params.max_iterations,
        params.tolerance,
        control,
        &format!("lpfb {}", p.name),
    )?;
    info.cut_paths = paths.len();
    info.iterations = sol.iterations;
    info.converged = sol.converged;
    info.grad_norm = sol.grad_norm;
    info.svd_steps = sol.svd_steps;
    info.backtracks = sol.backtracks;
    info.constraint_residual = sol.constraint_residual;
    // Sec. 3.2 step 6: back to the piece. Boundary vertices take their (single) copy; cut
    // path vertices have several copies, whose spread is the coincidence residual.
    let mut fixed: Vec<Option<[f64; 2]>> = vec![None; p.pos.len()];
    let mut first: Vec<Option<[f64; 2]>> = vec![None; p.pos.len()];
    let mut spread: f64 = 0.0;
    for (k, &v) in cl.vertex.iter().enumerate() {
        let x = sol.positions[k];
        match first[v as usize] {
            None => first[v as usize] = Some(x),
            Some(y) => spread = spread.max(((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2)).sqrt()),
        }
    }
    let diam = diameter(&p.pos);
    info.cut_coincidence = if diam > 0.0 { spread / diam } else { spread };
    for lp in &p.loops {
        for &v in lp {
            fixed[v as usize] = first[v as usize];
        }
    }
    Ok(fixed)
}

/// Flatten one piece.
pub fn flatten_piece(
    given: &cut::Piece3,
    params: &Params,
    control: &dyn Control,
) -> Result<(Piece, PieceInfo), AlgoError> {
    let err = |e: String| AlgoError::Input(format!("piece `{}`: {e}", given.name));
    let plan = cut::plan_cuts(given, params.cuts, params.curvature_tolerance).map_err(err)?;
    let mut info = PieceInfo {
        piece: given.name.clone(),
        faces: given.tris.len(),
        loops: given.loops.len(),
        real_cuts: plan.paths.len(),
        holes: plan.holes.iter().filter(|&&h| h).count(),
        enclosed_curvature: plan.enclosed_curvature.clone(),
        cone_points: plan.cone_points,
        converged: true,
        real_cut_paths: plan
            .paths
            .iter()
            .map(|path| path.iter().map(|&w| given.vertex_ids[w as usize]).collect())
            .collect(),
        ..PieceInfo::default()
    };
    let opened;
    let p = if plan.paths.is_empty() {
        given
    } else {
        opened = given.cut_open(&plan.paths)?;
        &opened
    };
    if p.loops.len() != 1 + info.holes {
        return Err(err(format!(
            "cutting left {} boundary loops, expected {}",
            p.loops.len(),
            1 + info.holes
        )));
    }
    let t0 = Instant::now();
    let uv = match params.method {
        Method::Lpfb => {
            let mut boundary = vec![false; p.pos.len()];
            for &v in p.loops.iter().flatten() {
                boundary[v as usize] = true;
            }
            let mut system = param::CotanSystem::new(&p.pos, &p.tris, &boundary).map_err(err)?;
            let shift = match params.boundary_angles {
                param::BoundaryAngles::Surface => None,
                param::BoundaryAngles::Conformal => {
                    Some(system.angle_shift(&p.tris, &p.angle_sums()).map_err(err)?)
                }
            };
            let fixed = lpfb_boundary(p, params, shift.as_deref(), control, &mut info)?;
            info.seconds_lpfb = t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let arap = match params.interior {
                param::Interior::Harmonic => 0,
                param::Interior::Arap => param::ARAP_ITERATIONS,
            };
            let uv = system.fill(&p.pos, &p.tris, &fixed, arap).map_err(err)?;
            info.seconds_param = t1.elapsed().as_secs_f64();
            uv
        }
        Method::Lscm => {
            if control.cancelled() {
                return Err(AlgoError::Cancelled);
            }
            control.progress(&super::Progress {
                stage: format!("lscm {}", p.name),
                ..super::Progress::default()
            });
            let uv = param::lscm(&p.pos, &p.tris, &p.loops).map_err(err)?;
            info.seconds_param = t0.elapsed().as_secs_f64();
            uv
        }
    };
    let t2 = Instant::now();
    let m = measures::compute(&p.pos, &uv, &p.tris, &p.loops, &p.vertex_ids);
    info.seconds_measures = t2.elapsed().as_secs_f64();
    let perimeter: f64 = p
        .loops
        .iter()
        .map(|lp| {
            (0..lp.len())
                .map(|k| {
                    let (a, b) = (uv[lp[k] as usize], uv[lp[(k + 1) % lp.len()] as usize]);
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
                })
                .sum::<f64>()
        })
        .sum();
    let mut mv = match serde_json::to_value(&m) {
        Ok(serde_json::Value::Object(o)) => o,
        _ => serde_json::Map::new(),
    };
    mv.insert("method".into(), serde_json::json!(params.method));
    let piece = Piece {
        patch: p.name.clone(),
        vertex_ids: p.vertex_ids.clone(),
        uv,
        triangles: p.tris.clone(),
        boundary_loops: p.loops.clone(),
        area: m.area_2d,
        perimeter,
        measures: mv,
        faces: p.faces.clone(),
        ..Piece::default()
    };
    Ok((piece, info))
}

/// Seams: chains of mesh edges whose two faces lie in different pieces, grouped by piece
/// pair and split into connected chains. Lengths in 3D and on both pieces. An edge is also
/// sewn when two boundary edges join the same two positions bit for bit (a file whose panels
/// are not welded, a slit opened by copies): see `joints`.
pub fn seams(mesh: &Mesh, pieces: &[Piece]) -> Vec<Seam> {
    seams_and_slits(mesh, pieces, &HashSet::new())
}

/// An edge of the sewn surface seen from its two faces.
struct Joint {
    /// The mesh edge, or None for two boundary edges sewn by position.
    edge: Option<u32>,
    faces: [u32; 2],
    /// The edge's ends as each face has them: `ends[1][k]` sits where `ends[0][k]` does.
    ends: [[u32; 2]; 2],
}

/// Every interior edge, and every pair of boundary edges that join the same two positions bit
/// for bit (exactly two such edges, in different faces). Without the pairs, a file exported
/// with its panels unwelded (mh_classicshoes_medium: 544 of its 592 boundary edges) got
/// patterns with no seam and no notch between its pieces.
fn joints(mesh: &Mesh) -> Vec<Joint> {
    let conn = mesh.conn();
    let mut out: Vec<Joint> = conn
        .edge_faces()
        .iter()
        .enumerate()
        .filter(|(_, ef)| ef[1] != NONE)
        .map(|(e, ef)| Joint {
            edge: Some(e as u32),
            faces: *ef,
            ends: [conn.edges()[e]; 2],
        })
        .collect();
    let mut pairs: Vec<[usize; 2]> = crate::mesh::boundary_edges_by_position(mesh)
        .into_iter()
        .filter_map(|es| <[usize; 2]>::try_from(es).ok())
        .collect();
    pairs.sort_unstable();
    let key = |v: u32| mesh.position(v).map(f64::to_bits);
    for [e0, e1] in pairs {
        let (f0, f1) = (conn.edge_faces()[e0][0], conn.edge_faces()[e1][0]);
        let ([a, b], [c, d]) = (conn.edges()[e0], conn.edges()[e1]);
        if f0 == f1 {
            continue;
        }
        let other = if key(c) == key(a) { [c, d] } else { [d, c] };
        out.push(Joint {
            edge: None,
            faces: [f0, f1],
            ends: [[a, b], other],
        });
    }
    out
}

/// [`seams`], plus the mesh edges in `slits` whose two faces lie in one piece that is cut
/// there (segmentation's dangling cuts), each simple path of them a seam of that piece with
/// itself: side 0 the faces on its left (where an edge runs in walking order), as
/// [`cut_seams`]. Boundary edges sewn by position within one piece are such a slit too.
pub fn seams_and_slits(mesh: &Mesh, pieces: &[Piece], slits: &HashSet<u32>) -> Vec<Seam> {
    // global face → (piece, local triangle)
    let mut where_: Vec<(u32, u32)> = vec![(u32::MAX, 0); mesh.num_faces()];
    for (pi, p) in pieces.iter().enumerate() {
        for (t, &f) in p.faces.iter().enumerate() {
            where_[f as usize] = (pi as u32, t as u32);
        }
    }
    let joints = joints(mesh);
    // Chains are built on one vertex per position, so that both sides of a sewn edge and
    // the welded edges beside it join up.
    let mut first: HashMap<[u64; 3], u32> = HashMap::new();
    let canon: Vec<u32> = (0..mesh.num_vertices() as u32)
        .map(|v| *first.entry(mesh.position(v).map(f64::to_bits)).or_insert(v))
        .collect();
    let pair = |j: &Joint| j.ends[0].map(|v| canon[v as usize]);
    let mut groups: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (k, j) in joints.iter().enumerate() {
        let (pa, pb) = (where_[j.faces[0] as usize].0, where_[j.faces[1] as usize].0);
        let cut = j.edge.is_none_or(|e| slits.contains(&e));
        if (pa != pb || cut) && pa != u32::MAX && pb != u32::MAX {
            groups.entry((pa.min(pb), pa.max(pb))).or_default().push(k);
        }
    }
    let pairs: Vec<[u32; 2]> = joints.iter().map(pair).collect();
    let mut keys: Vec<(u32, u32)> = groups.keys().copied().collect();
    keys.sort_unstable();
    // 2D position of global vertex v in piece `pi` through face f
    let uv_of = |pi: u32, f: u32, v: u32| -> Option<[f64; 2]> {
        let p = &pieces[pi as usize];
        let t = p.triangles[where_[f as usize].1 as usize];
        t.iter()
            .find(|&&w| p.vertex_ids[w as usize] == v)
            .map(|&w| p.uv[w as usize])
    };
    let d2 = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let mut out = Vec::new();
    for k in keys {
        let members = &groups[&k];
        // chains: union joints sharing a (canonical) vertex
        let mut vid: HashMap<u32, u32> = HashMap::new();
        for &j in members {
            for v in pairs[j] {
                let n = vid.len() as u32;
                vid.entry(v).or_insert(n);
            }
        }
        let mut sets = crate::mesh::disjoint::DisjointSets::new(vid.len());
        for &j in members {
            let [a, b] = pairs[j];
            sets.union(vid[&a], vid[&b]);
        }
        let mut chains: Vec<(u32, Vec<usize>)> = Vec::new();
        for &j in members {
            let r = sets.find(vid[&pairs[j][0]]);
            match chains.iter_mut().find(|c| c.0 == r) {
                Some(c) => c.1.push(j),
                None => chains.push((r, vec![j])),
            }
        }
        // A slit's sides are its left and right: it is split into simple paths, each edge
        // directed along its path.
        let runs: Vec<(Vec<usize>, Vec<[u32; 2]>)> = chains
            .into_iter()
            .flat_map(|(_, ch)| {
                if k.0 == k.1 {
                    simple_paths(&ch, &pairs)
                } else {
                    let dir = ch.iter().map(|&j| pairs[j]).collect();
                    vec![(ch, dir)]
                }
            })
            .collect();
        for (ch, dir) in runs {
            let mut s = Seam {
                patches: [
                    pieces[k.0 as usize].patch.clone(),
                    pieces[k.1 as usize].patch.clone(),
                ],
                pieces: [k.0 as usize, k.1 as usize],
                ..Seam::default()
            };
            for (&j, &d) in ch.iter().zip(&dir) {
                let joint = &joints[j];
                let forward = d == pairs[j];
                let [p0, q0] = joint.ends[0];
                s.length_3d += cut::dist(mesh.position(p0), mesh.position(q0));
                for (&f, &[p, q]) in joint.faces.iter().zip(&joint.ends) {
                    // this face's copies of the walk's ends
                    let (a, b) = if forward { (p, q) } else { (q, p) };
                    let pi = where_[f as usize].0;
                    let side = if k.0 == k.1 {
                        // side 0: the face where the edge runs a → b
                        let t = mesh.triangles()[f as usize];
                        let runs = (0..3).any(|i| t[i] == a && t[(i + 1) % 3] == b);
                        usize::from(!runs)
                    } else if pi == k.0 {
                        0
                    } else {
                        1
                    };
                    if let (Some(ua), Some(ub)) = (uv_of(pi, f, a), uv_of(pi, f, b)) {
                        s.lengths[side] += d2(ua, ub);
                        let p = &pieces[pi as usize];
                        let t = p.triangles[where_[f as usize].1 as usize];
                        let ia = t.iter().find(|&&w| p.vertex_ids[w as usize] == a);
                        let ib = t.iter().find(|&&w| p.vertex_ids[w as usize] == b);
                        if let (Some(&ia), Some(&ib)) = (ia, ib) {
                            s.edges[side].push([ia, ib]);
                        }
                    }
                }
            }
            out.push(s);
        }
    }
    out
}

/// A connected set of edges split into simple paths (broken where the degree is not 2) and
/// loops, each as its edges in walking order, directed along the walk. Deterministic: walks
/// start from the lowest vertex, and take the lowest unused edge.
fn simple_paths(chain: &[usize], edges: &[[u32; 2]]) -> Vec<(Vec<usize>, Vec<[u32; 2]>)> {
    let mut at: HashMap<u32, Vec<usize>> = HashMap::new();
    for &e in chain {
        for v in edges[e] {
            at.entry(v).or_default().push(e);
        }
    }
    let mut starts: Vec<u32> = at.keys().copied().collect();
    starts.sort_unstable_by_key(|v| (at[v].len() == 2, *v));
    let mut used: HashSet<usize> = HashSet::new();
    let mut out = Vec::new();
    for s0 in starts {
        while let Some(&e0) = at[&s0].iter().filter(|e| !used.contains(e)).min() {
            let (mut order, mut dirs) = (Vec::new(), Vec::new());
            let (mut v, mut e) = (s0, e0);
            loop {
                used.insert(e);
                let [p, q] = edges[e];
                let w = if p == v { q } else { p };
                order.push(e);
                dirs.push([v, w]);
                v = w;
                if at[&v].len() != 2 {
                    break;
                }
                match at[&v].iter().find(|x| !used.contains(x)) {
                    Some(&n) => e = n,
                    None => break,
                }
            }
            out.push((order, dirs));
        }
    }
    out
}

/// Seams of the real cuts: each cut path is a seam of its piece with itself, side 0 the faces
/// on the path's left (where the edge runs in path order), side 1 those on its right; both
/// sides list their edges in path order.
pub fn cut_seams(mesh: &Mesh, pieces: &[Piece], infos: &[PieceInfo]) -> Vec<Seam> {
    let mut out = Vec::new();
    for (pi, (p, info)) in pieces.iter().zip(infos).enumerate() {
        if info.real_cut_paths.is_empty() {
            continue;
        }
        // mesh half-edge (a → b) → the piece's (a', b')
        let mut half: HashMap<(u32, u32), [u32; 2]> = HashMap::new();
        for t in &p.triangles {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                half.insert((p.vertex_ids[a as usize], p.vertex_ids[b as usize]), [a, b]);
            }
        }
        let len2 = |e: [u32; 2]| {
            let (a, b) = (p.uv[e[0] as usize], p.uv[e[1] as usize]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
        };
        for path in &info.real_cut_paths {
            let mut s = Seam {
                patches: [p.patch.clone(), p.patch.clone()],
                pieces: [pi, pi],
                ..Seam::default()
            };
            for w in path.windows(2) {
                let (u, v) = (w[0], w[1]);
                s.length_3d += cut::dist(mesh.position(u), mesh.position(v));
                if let Some(&e) = half.get(&(u, v)) {
                    s.lengths[0] += len2(e);
                    s.edges[0].push(e);
                }
                if let Some(&[b, a]) = half.get(&(v, u)) {
                    s.lengths[1] += len2([a, b]);
                    s.edges[1].push([a, b]);
                }
            }
            out.push(s);
        }
    }
    out
}

/// What is wrong with a flattened piece, in words, or None.
fn piece_warning(p: &Piece, i: &PieceInfo, params: &Params) -> Option<String> {
    let num = |k: &str| p.measures.get(k).and_then(|v| v.as_f64()).unwrap_or(0.0);
    let mut what = Vec::new();
    if !i.converged {
        what.push(format!(
            "LPFB did not converge (‖∇J‖ = {:.3e} after {} iterations)",
            i.grad_norm, i.iterations
        ));
    }
    let bl = num("boundary_length_max_rel_error");
    if bl > BOUNDARY_LENGTH_TOLERANCE {
        let e = p
            .measures
            .get("boundary_worst_edge")
            .cloned()
            .unwrap_or_default();
        what.push(format!(
            "boundary edge {e} differs from its 3D length by {:.2e} relative",
            bl
        ));
    }
    let flips = num("flipped_triangles") as u64;
    if flips > 0 || num("overlap") > 0.0 {
        let varpi = num("varpi_max");
        let curved_holes: Vec<String> = i
            .enclosed_curvature
            .iter()
            .filter(|k| k.abs() > params.curvature_tolerance)
            .map(|k| format!("{k:.3}"))
            .collect();
        let why = if i.holes > 0 && !curved_holes.is_empty() {
            format!(
                "its holes enclose curvature ({} rad) and cannot close flat: flatten with \
                 cuts=auto or cuts=real",
                curved_holes.join(", ")
            )
        } else if varpi > DEVELOPABLE_TOLERANCE {
            format!(
                "it is not developable (ϖ_max {varpi:.3e} rad): make it more developable \
                 (fl-mesh) or split it into patches"
            )
        } else {
            format!(
                "it is developable (ϖ_max {varpi:.1e} rad) but its flat shape wraps onto \
                 itself: split it into patches"
            )
        };
        let overlap = if flips > 0 {
            format!("{flips} flipped triangles")
        } else {
            "the pattern overlaps itself".to_string()
        };
        what.push(format!("{overlap}; {why}"));
    } else if num("varpi_max") > DEVELOPABLE_TOLERANCE
        && num("area_distortion_pct").abs() > DISTORTION_WARNING_PCT
    {
        // Signed: a pattern smaller than its surface (a closed-toe sock laid out from its
        // opening: −94 %) is as wrong as a larger one.
        what.push(format!(
            "it is not developable (ϖ_max {:.3e} rad), so its pattern is distorted (area \
             distortion {:+.1} %, stretch up to {:.1} %, compression up to {:.1} %): make it \
             more developable (fl-mesh) or split it into patches",
            num("varpi_max"),
            num("area_distortion_pct"),
            num("stretch_max_pct"),
            num("compression_max_pct")
        ));
    }
    (!what.is_empty()).then(|| format!("piece `{}`: {}", p.patch, what.join("; ")))
}

/// A boundary edge whose 2D length differs from 3D by more than this (relative) is named in a
/// warning: LPFB lays the boundary out with the 3D lengths, so it reaches ~1e-14.
pub const BOUNDARY_LENGTH_TOLERANCE: f64 = 1e-9;

/// A(Ω) (Eq. 19, percent) above which a piece that is not developable is warned about even
/// when it does not overlap: about what woven fabric gives without showing it.
pub const DISTORTION_WARNING_PCT: f64 = 1.0;

/// What `flatten` reports besides the patterns.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// `lpfb` or `lscm`.
    pub method: Method,
    /// The unit the mesh was read in.
    pub input_unit: String,
    /// Why, when it was guessed (`input_unit = auto`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_unit_guessed: Option<String>,
    /// Unit of the drawings.
    pub unit: Unit,
    /// How inner loops were treated.
    pub cuts: cut::Cuts,
    /// Per piece.
    pub pieces: Vec<PieceSummary>,
    /// Seams between pieces and real cuts.
    pub seams: Vec<SeamSummary>,
    /// Pieces skipped or not usable as they are, each with the reason.
    pub job_warnings: Vec<String>,
    /// Every piece's LPFB converged.
    pub all_converged: bool,
    /// Piece area, cut-line length and the fabric a simple marker needs.
    pub cost: marker::Cost,
    /// Seconds per stage.
    pub timings: Timings,
}

/// One piece in [`Summary`].
#[derive(Debug, Clone, Serialize)]
pub struct PieceSummary {
    /// Piece name.
    pub piece: String,
    /// 2D area.
    pub area: f64,
    /// 2D perimeter.
    pub perimeter: f64,
    /// The piece's measures (as in patterns.json).
    pub measures: serde_json::Map<String, serde_json::Value>,
    /// What the solver did.
    pub solver: PieceInfo,
}

/// One seam in [`Summary`].
#[derive(Debug, Clone, Serialize)]
pub struct SeamSummary {
    /// The two pieces' names (the same twice for a real cut).
    pub patches: [String; 2],
    /// 3D length.
    pub length_3d: f64,
    /// Length on each side in 2D.
    pub lengths: [f64; 2],
}

impl From<&Seam> for SeamSummary {
    fn from(s: &Seam) -> Self {
        SeamSummary {
            patches: s.patches.clone(),
            length_3d: s.length_3d,
            lengths: s.lengths,
        }
    }
}

/// Seconds per stage of `flatten`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    /// Components and topology.
    pub topology_s: f64,
    /// LPFB, summed over pieces.
    pub lpfb_s: f64,
    /// Interior solves, summed over pieces.
    pub param_s: f64,
    /// Measures, summed over pieces.
    pub measures_s: f64,
    /// Seams.
    pub seams_s: f64,
    /// Wall time.
    pub total_s: f64,
}

/// Run `flatten` on a mesh.
pub fn run(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    let t0 = Instant::now();
    let mut job_warnings = Vec::new();
    let diagonal = diameter(mesh.positions());
    let input_unit = params
        .input_unit
        .fixed()
        .unwrap_or_else(|| Unit::guess(diagonal));
    let comps = crate::mesh::patch_components(mesh);
    let t_topo = t0.elapsed().as_secs_f64();
    let results: Vec<Result<(Piece, PieceInfo), AlgoError>> = comps
        .par_iter()
        .map(|(name, faces)| {
            let p = cut::Piece3::build(
                name.clone(),
                faces.clone(),
                mesh.triangles(),
                mesh.positions(),
            )?;
            flatten_piece(&p, params, control)
        })
        .collect();
    let mut pieces = Vec::with_capacity(results.len());
    let mut infos = Vec::with_capacity(results.len());
    for (r, (name, faces)) in results.into_iter().zip(&comps) {
        match r {
            Ok((p, i)) => {
                pieces.push(p);
                infos.push(i);
            }
            Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
            Err(e) => {
                let e = e.to_string();
                let why = e.strip_prefix(&format!("piece `{name}`: ")).unwrap_or(&e);
                job_warnings.push(format!("{} skipped: {why}", describe(name, faces)));
            }
        }
    }
    if pieces.is_empty() {
        return Err(AlgoError::Input(format!(
            "no piece could be flattened: {}",
            job_warnings.join("; ")
        )));
    }
    let t1 = Instant::now();
    let mut seams = seams(mesh, &pieces);
    seams.extend(cut_seams(mesh, &pieces, &infos));
    let t_seams = t1.elapsed().as_secs_f64();
    job_warnings.extend(
        pieces
            .iter()
            .zip(&infos)
            .filter_map(|(p, i)| piece_warning(p, i, params)),
    );
    let summary = Summary {
        method: params.method,
        input_unit: input_unit.name().to_string(),
        input_unit_guessed: (params.input_unit == InputUnit::Auto).then(|| {
            format!(
                "input_unit not given: `{}` assumed from the bounding-box diagonal {:.4} (the unit \
                 that puts it in [0.3, 3) m); pass input_unit to override",
                input_unit.name(),
                diagonal
            )
        }),
        unit: params.unit,
        cuts: params.cuts,
        pieces: pieces
            .iter()
            .zip(&infos)
            .map(|(p, i)| PieceSummary {
                piece: p.patch.clone(),
                area: p.area,
                perimeter: p.perimeter,
                measures: p.measures.clone(),
                solver: i.clone(),
            })
            .collect(),
        seams: seams.iter().map(SeamSummary::from).collect(),
        job_warnings,
        all_converged: infos.iter().all(|i| i.converged),
        cost: marker::Cost::default(),
        timings: Timings {
            topology_s: t_topo,
            lpfb_s: infos.iter().map(|i| i.seconds_lpfb).sum(),
            param_s: infos.iter().map(|i| i.seconds_param).sum(),
            measures_s: infos.iter().map(|i| i.seconds_measures).sum(),
            seams_s: t_seams,
            total_s: t0.elapsed().as_secs_f64(),
        },
    };
    let mut patterns = Patterns {
        pieces,
        seams,
        input_unit: input_unit.name().to_string(),
        unit: params.unit.name().to_string(),
        svg_triangles: params.svg_triangles,
    };
    let finish_warnings =
        finish::apply(&mut patterns, mesh.positions(), &params.finish(input_unit));
    let mut summary = summary;
    summary.job_warnings.extend(finish_warnings);
    // A piece wider than the roll is named in the estimate (`too_wide`), not warned about:
    // the pieces themselves are fine.
    summary.cost = marker::estimate(&patterns, params.fabric_width());
    let mesh = patterns
        .uv_layer(mesh.num_faces())
        .and_then(|uv| mesh.with_uv(uv).ok());
    if mesh.is_none() {
        summary.job_warnings.push(
            "the output mesh has no texture coordinates: some of its faces are in no piece".into(),
        );
    }
    Ok(Outcome {
        mesh,
        patterns: Some(patterns),
        summary,
        levels: Vec::new(),
    })
}
