//! `segment`: cut a mesh into quasi-developable charts and flatten them
//! (wang-lpfb-quasi-developable-segmentation, Sec. 2 and 4; choices in paper-notes D).
//!
//! Stages, each a function of its own: [`vsa::run`] (error-controlled VSA into nearly planar
//! charts), [`mincut::refine`] (min-cut smoothing of the chart boundaries in a fuzzy band),
//! [`merge::split_until_within`] (not in the paper: a chart that does not flatten within the
//! bounds on its own is split in two until each does, so that every output chart has been
//! tested), [`merge::run`] (greedy boundary-curve merging, accepted only when the merged chart
//! flattens within the bounds), then the charts become the patches of a cut mesh (charts not
//! welded to each other, slits split), and that mesh is flattened by [`flatten::run`]: the
//! patterns and measures are exactly what `flatten` gives for it; the seams between charts
//! and the slits are found on the input, where the charts are still joined.
//!
//! Merging and the final flattening use the same flattening (`interior`, `boundary_angles`;
//! holes closed by the paper's virtual cut), so every accepted chart's pattern is the one
//! tested. The paper's LPFB + IP is `interior = harmonic, boundary_angles = surface`; the
//! defaults are `flatten`'s (ARAP interior, conformal boundary angles), which flatten a
//! chart with less stretch and so accept larger charts at the same bounds.
//!
//! Beyond the paper, which stops at quasi-developable charts: `then = fl-mesh` runs
//! [`fl_charts::run`] before the final flattening: fl-mesh on every chart on its own, its
//! boundary fixed (so the charts still sew together), a chart that fails (fl-mesh stalls,
//! or its isometric pattern overlaps or stretches) split until each passes. fl-mesh's
//! refinement is refused there (it would add vertices and split faces, breaking the maps
//! back to the input). That final flattening opens holes that enclose curvature by a real
//! cut (`cuts = auto`, as `flatten` by default): a developable ring around a sleeve cannot
//! be laid flat with its hole closed.
//!
//! Step 3, [`denoise::run`], is optional and off by default: it moves the chart-boundary
//! vertices of the user's mesh (the output mesh, the merging and the patterns then use the
//! moved positions; `denoise_max_displacement` and `hausdorff_to_input` say by how much).

pub mod denoise;
pub mod dual;
pub mod fl_charts;
pub mod merge;
pub mod mincut;
pub mod vsa;

use super::fl_mesh;
use super::flatten::{self, cut::Cuts, param};
use super::flatten::{InputUnit, Unit};
use super::{bad_param, AlgoError, Control, Outcome};
use crate::mesh::{Mesh, RawMesh, NONE};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::time::Instant;

/// How charts are merged.
///
/// The paper prefers `boundary` (Fig. 6b) because it ends with fewer, larger charts; but
/// the curves it leaves inside a chart are slits, seams of the chart with itself, so they
/// cost sewing too. Measured on nine shared meshes (t-shirt, dress, jumpsuit, suit, two
/// shoes, spot, hemisphere, shirt), `patch` always needed less seam length in all,
/// slits included: 2% to 98% less (dress 2821 against 5814, jumpsuit 1.1 against 55,
/// shoes01 31 against 44), with more pieces on most (t-shirt 5 against 2, spot 21 against 3)
/// and 1.3–2.9× the time. Seam length is what sewing costs, so `patch` is the default.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MergeMode {
    /// Remove one boundary curve per merge; the others become slits (the paper's, Fig. 6b).
    Boundary,
    /// Remove every curve between the two charts: no slits (Fig. 6a).
    #[default]
    Patch,
}

fn d_vsa_tolerance() -> f64 {
    5e-4
}
fn d_max_charts() -> usize {
    256
}
fn d_lloyd() -> usize {
    50
}
fn d_rings() -> usize {
    3
}
fn d_area() -> f64 {
    10.0
}
fn d_l2() -> f64 {
    2.0
}
fn d_max_stretch() -> f64 {
    0.1
}
fn d_true() -> bool {
    true
}
fn d_fl_mesh() -> fl_mesh::Params {
    fl_mesh::Params {
        refine: false,
        ..fl_mesh::Params::default()
    }
}

/// What runs on the cut mesh before the final flattening.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Then {
    /// Nothing: quasi-developable charts, as the paper.
    #[default]
    #[serde(rename = "none")]
    Nothing,
    /// fl-mesh with every chart boundary fixed: exactly flattenable charts.
    #[serde(rename = "fl-mesh")]
    FlMesh,
}

/// Parameters of `segment`; unknown keys are refused.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// VSA stops adding charts when every chart's L^{2,1} error over the total area is at
    /// most this (5e-4).
    #[serde(default = "d_vsa_tolerance")]
    pub vsa_tolerance: f64,
    /// Most VSA charts (256).
    #[serde(default = "d_max_charts")]
    pub max_charts: usize,
    /// Most Lloyd iterations per VSA round (50).
    #[serde(default = "d_lloyd")]
    pub lloyd_iterations: usize,
    /// Width of the min-cut band in face rings around each boundary (3; 0 skips refinement).
    #[serde(default = "d_rings")]
    pub fuzzy_rings: usize,
    /// Move the chart-boundary vertices onto the intersections of their charts' planes
    /// (the paper's step 3; false: it changes the user's geometry).
    #[serde(default)]
    pub denoise: bool,
    /// Largest |A(Ω)| of a merged chart, percent (10, the paper's).
    #[serde(default = "d_area")]
    pub max_area_distortion: f64,
    /// Largest L² stretch of a merged chart (2.0, the paper's).
    #[serde(default = "d_l2")]
    pub max_l2_stretch: f64,
    /// Refuse a merge whose flattening overlaps itself (true).
    #[serde(default = "d_true")]
    pub reject_overlap: bool,
    /// Test a refused curve again when one of its charts has grown (false: the paper).
    #[serde(default)]
    pub retry_rejected: bool,
    /// `patch` (default: every curve between the two charts; no slits) or `boundary` (the
    /// paper's: one curve per merge, the others left as slits).
    #[serde(default)]
    pub merge: MergeMode,
    /// Keep the input's patches: segment within each, never across its seams (true).
    #[serde(default = "d_true")]
    pub keep_patches: bool,
    /// Interior solve of the flattening: `arap` (default) or `harmonic` (the paper's IP).
    #[serde(default)]
    pub interior: param::Interior,
    /// LPFB's boundary angle targets: `conformal` (default) or `surface` (the paper's).
    #[serde(default)]
    pub boundary_angles: param::BoundaryAngles,
    /// Unit of the SVG and DXF drawings (`mm` default, `cm`, `m`, `in`).
    #[serde(default)]
    pub unit: Unit,
    /// Unit the mesh's coordinates are in (`auto` default: guessed from its size).
    #[serde(default)]
    pub input_unit: InputUnit,
    /// `none` (default) or `fl-mesh`: make every chart exactly flattenable, its boundary
    /// fixed, before flattening.
    #[serde(default)]
    pub then: Then,
    /// Parameters of that fl-mesh run (fl-mesh's defaults, refinement off).
    #[serde(default = "d_fl_mesh")]
    pub fl_mesh: fl_mesh::Params,
    /// With `then = fl-mesh`: a chart whose pattern stretches an edge by more than this
    /// (percent, 0.1) is split, as one on which fl-mesh stalls or whose pattern overlaps.
    #[serde(default = "d_max_stretch")]
    pub max_stretch: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            vsa_tolerance: d_vsa_tolerance(),
            max_charts: d_max_charts(),
            lloyd_iterations: d_lloyd(),
            fuzzy_rings: d_rings(),
            denoise: false,
            max_area_distortion: d_area(),
            max_l2_stretch: d_l2(),
            reject_overlap: true,
            retry_rejected: false,
            merge: MergeMode::Patch,
            keep_patches: true,
            interior: param::Interior::default(),
            boundary_angles: param::BoundaryAngles::default(),
            unit: Unit::default(),
            input_unit: InputUnit::default(),
            then: Then::Nothing,
            fl_mesh: d_fl_mesh(),
            max_stretch: d_max_stretch(),
        }
    }
}

impl Params {
    /// Range checks.
    pub fn check(&self) -> Result<(), AlgoError> {
        if !(self.vsa_tolerance > 0.0 && self.vsa_tolerance < 1.0) {
            return Err(bad_param("vsa_tolerance", "must be in (0, 1)"));
        }
        if !(1..=4096).contains(&self.max_charts) {
            return Err(bad_param("max_charts", "must be in 1..=4096"));
        }
        if !(1..=1000).contains(&self.lloyd_iterations) {
            return Err(bad_param("lloyd_iterations", "must be in 1..=1000"));
        }
        if self.fuzzy_rings > 50 {
            return Err(bad_param("fuzzy_rings", "must be in 0..=50"));
        }
        // Zero slack would refuse every chart that is not exactly flat, down to single faces.
        if !(self.max_area_distortion > 0.0 && self.max_area_distortion <= 100.0) {
            return Err(bad_param(
                "max_area_distortion",
                "must be in (0, 100] (percent)",
            ));
        }
        if !(self.max_l2_stretch > 1.0 && self.max_l2_stretch.is_finite()) {
            return Err(bad_param(
                "max_l2_stretch",
                "must be above 1 (no flattening stretches less) and finite",
            ));
        }
        if !(self.max_stretch > 0.0 && self.max_stretch.is_finite()) {
            return Err(bad_param(
                "max_stretch",
                "must be above 0 (percent) and finite",
            ));
        }
        if self.fl_mesh.refine {
            return Err(bad_param(
                "fl_mesh.refine",
                "must be false: refinement would add vertices and split faces of the cut mesh",
            ));
        }
        self.fl_mesh.check().map_err(|e| match e {
            AlgoError::InvalidParam { key, message } => AlgoError::InvalidParam {
                key: format!("fl_mesh.{key}"),
                message,
            },
            other => other,
        })
    }

    /// The flattening merging tests with and the output is made with.
    fn flatten(&self) -> flatten::Params {
        flatten::Params {
            unit: self.unit,
            input_unit: self.input_unit,
            cuts: Cuts::Virtual,
            interior: self.interior,
            boundary_angles: self.boundary_angles,
            ..flatten::Params::default()
        }
    }
}

/// Chart counts after each stage (the paper's "68 → 68 → 7").
#[derive(Debug, Clone, Default, Serialize)]
pub struct Counts {
    /// After VSA.
    pub vsa: usize,
    /// After min-cut refinement (the same by construction).
    pub refined: usize,
    /// After splitting the charts that do not flatten within the bounds on their own.
    pub tested: usize,
    /// After merging.
    pub merged: usize,
}

/// Seconds per stage.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Seconds {
    /// VSA.
    pub vsa: f64,
    /// Min-cut refinement.
    pub refine: f64,
    /// Merging (every candidate's flattening included).
    pub merge: f64,
    /// Cutting the mesh and flattening the final charts.
    pub flatten: f64,
    /// Wall time.
    pub total: f64,
}

/// What `segment` reports besides the cut mesh and the patterns.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Chart counts per stage.
    pub charts: Counts,
    /// Largest E(R_i)/A over the VSA charts.
    pub vsa_max_error: f64,
    /// VSA seed-insertion rounds and Lloyd iterations.
    pub vsa_rounds: usize,
    /// Lloyd iterations over all rounds.
    pub vsa_lloyd_iterations: usize,
    /// Chart pairs cut by min-cut, skipped pairs, faces moved, island faces reassigned.
    pub refine_pairs: usize,
    /// Pairs skipped (a chart inside its band).
    pub refine_skipped: usize,
    /// Faces whose chart the min-cut changed.
    pub refine_moved_faces: usize,
    /// Faces reassigned to keep charts connected.
    pub refine_island_faces: usize,
    /// Charts split in two because they did not flatten within the bounds on their own.
    pub splits: usize,
    /// With `denoise`: the chart-boundary vertices (those allowed to move).
    pub denoise_vertices: usize,
    /// With `denoise`: the largest distance a vertex moved.
    pub denoise_max_displacement: f64,
    /// With `denoise`: Gauss–Seidel sweeps.
    pub denoise_sweeps: usize,
    /// Candidates tested, in order, with their measures and the decision.
    pub merge_log: Vec<merge::Candidate>,
    /// Flattenings run while merging.
    pub merge_evaluations: usize,
    /// Edges left as cuts inside a chart (split in the output mesh).
    pub dangling_edges: usize,
    /// Final chart of every input face (the output mesh's patch of that face).
    pub face_charts: Vec<u32>,
    /// Input vertex of every output vertex (the output splits the dangling cuts).
    pub vertex_map: Vec<u32>,
    /// Worst |A(Ω)| (percent) and L² over the final pieces.
    pub worst_area_distortion_pct: f64,
    /// Worst L² stretch over the final pieces.
    pub worst_l2_stretch: f64,
    /// Every final piece is within the bounds and does not overlap.
    pub all_within_bounds: bool,
    /// Largest edge stretch over the final pieces, percent (flatten's `stretch_max_pct`).
    pub worst_stretch_max_pct: f64,
    /// What fl-mesh did on the charts, split until each passed (`then = fl-mesh`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fl_mesh: Option<fl_charts::FlCharts>,
    /// Hausdorff distance from the output mesh to the input (0 unless `then = fl-mesh` or
    /// `denoise`).
    pub hausdorff_to_input: super::Distance,
    /// The final flattening, as `flatten` reports it.
    pub flatten: flatten::Summary,
    /// Seconds per stage.
    pub stage_seconds: Seconds,
}

/// Run `segment` on a mesh.
pub fn run(
    input: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    let t0 = Instant::now();
    let mesh = input;
    if mesh.num_faces() == 0 {
        return Err(AlgoError::Input("the mesh has no faces".into()));
    }
    let dual = dual::Dual::new(mesh, params.keep_patches);
    let v = vsa::run(
        &dual,
        params.vsa_tolerance,
        params.max_charts,
        params.lloyd_iterations,
        control,
    )?;
    let k = v.proxies.len();
    let t_vsa = t0.elapsed().as_secs_f64();
    let mut labels = v.labels.clone();
    let refinement = if params.fuzzy_rings > 0 {
        mincut::refine(&dual, &mut labels, k, params.fuzzy_rings)
    } else {
        mincut::Refinement::default()
    };
    let refined = count(&labels);
    let denoised = params.denoise.then(|| denoise::run(mesh, &labels, k));
    let moved_mesh;
    let (mesh, dual) = match &denoised {
        Some(d) => {
            moved_mesh = input
                .with_positions(d.positions.clone())
                .map_err(|e| AlgoError::Input(format!("denoising failed: {e}")))?;
            let dual = dual::Dual::new(&moved_mesh, params.keep_patches);
            (&moved_mesh, dual)
        }
        None => (input, dual),
    };
    let t_refine = t0.elapsed().as_secs_f64();
    let criteria = merge::Criteria {
        max_area_distortion: params.max_area_distortion,
        max_l2_stretch: params.max_l2_stretch,
        reject_overlap: params.reject_overlap,
        retry_rejected: params.retry_rejected,
        patch_based: params.merge == MergeMode::Patch,
        flatten: params.flatten(),
    };
    let (k_tested, splits) =
        merge::split_until_within(mesh, &dual, &mut labels, k, &criteria, control)?;
    let merged = merge::run(mesh, &dual, &labels, k_tested, &criteria, control)?;
    let t_merge = t0.elapsed().as_secs_f64();
    let face_charts = renumber(&merged.labels);
    // One-edge slits no mesh can hold open were zipped when tested; zip them here too.
    let zipped = merge::isolated_slits(mesh, |f| face_charts[f], &merged.dangling);
    let unzipped = |edges: &[u32]| -> Vec<u32> {
        edges
            .iter()
            .copied()
            .filter(|e| !zipped.contains(e))
            .collect()
    };
    let (dangling, cut_edges) = (unzipped(&merged.dangling), unzipped(&merged.cut));
    // After fl-mesh a chart with a hole is developable but the hole may enclose curvature,
    // which no flattening can close without stretch: `cuts = auto` opens such holes by a real
    // cut (a seam of the piece with itself), as `flatten` does by default.
    let final_flatten = match params.then {
        Then::Nothing => criteria.flatten.clone(),
        Then::FlMesh => flatten::Params {
            cuts: Cuts::Auto,
            ..criteria.flatten.clone()
        },
    };
    let (face_charts, cut_mesh, vertex_map, fl_report) = match params.then {
        Then::Nothing => {
            let (m, map) = cut_mesh(mesh, &face_charts, &cut_edges)?;
            (face_charts, m, map, None)
        }
        Then::FlMesh => {
            let settings = fl_charts::Settings {
                fl_mesh: &params.fl_mesh,
                flatten: &final_flatten,
                max_stretch_pct: params.max_stretch,
                max_charts: fl_charts::MAX_CHARTS,
            };
            let k = count(&face_charts);
            let d = fl_charts::run(mesh, &dual, &face_charts, k, &dangling, &settings, control)?;
            let face_charts = renumber(&d.labels);
            let cut_edges = cut_between(mesh, &face_charts, &dangling);
            let (m, map) = cut_mesh(mesh, &face_charts, &cut_edges)?;
            let (m, stuck) = with_corners(&m, &d.corners, &d.stuck)?;
            let mut report = d.report;
            report.stuck_vertices = stuck;
            let mut first = std::collections::HashMap::new();
            for (f, &l) in d.labels.iter().enumerate() {
                first.entry(l).or_insert(f);
            }
            for c in &mut report.charts {
                c.chart = face_charts[first[&c.chart]];
            }
            report.charts.sort_by_key(|c| c.chart);
            (face_charts, m, map, Some(report))
        }
    };
    let hausdorff_to_input = super::Distance::hausdorff_reported(&cut_mesh, input, control);
    let mut flat = flatten::run(&cut_mesh, &final_flatten, control)?;
    let mut cut_mesh = cut_mesh;
    if let Some(patterns) = flat.patterns.as_mut() {
        seams_on_input(mesh, patterns, &vertex_map, &dangling);
        // Notches and allowances again, now that the pieces have their seams.
        let unit = Unit::parse(&patterns.input_unit).unwrap_or_default();
        let warnings =
            flatten::finish::apply(patterns, cut_mesh.positions(), &final_flatten.finish(unit));
        flat.summary.job_warnings.extend(warnings);
        flat.summary.cost = flatten::marker::estimate(patterns, final_flatten.fabric_width());
        let mut seen = HashSet::new();
        flat.summary.job_warnings.retain(|w| seen.insert(w.clone()));
        if let Some(uv) = patterns.uv_layer(cut_mesh.num_faces()) {
            if let Ok(m) = cut_mesh.with_uv(uv) {
                cut_mesh = m;
            }
        }
        flat.summary.seams = patterns
            .seams
            .iter()
            .map(flatten::SeamSummary::from)
            .collect();
    }
    // Every chart flattened (none skipped) and each within the bounds.
    let worst = Worst::of(&flat.summary.pieces, params);
    let within = worst.within && flat.summary.pieces.len() == count(&face_charts);
    let t_end = t0.elapsed().as_secs_f64();
    let summary = Summary {
        charts: Counts {
            vsa: k,
            refined,
            tested: k_tested,
            merged: count(&face_charts),
        },
        vsa_max_error: v.errors.iter().copied().fold(0.0, f64::max),
        vsa_rounds: v.rounds,
        vsa_lloyd_iterations: v.lloyd_iterations,
        refine_pairs: refinement.pairs.len(),
        refine_skipped: refinement.skipped,
        refine_moved_faces: refinement.pairs.iter().map(|p| p.moved).sum(),
        refine_island_faces: refinement.islands,
        splits,
        denoise_vertices: denoised.as_ref().map_or(0, |d| d.candidates),
        denoise_max_displacement: denoised.as_ref().map_or(0.0, |d| d.max_displacement),
        denoise_sweeps: denoised.as_ref().map_or(0, |d| d.sweeps),
        merge_evaluations: merged.evaluations,
        merge_log: merged.log,
        dangling_edges: dangling.len(),
        face_charts,
        vertex_map,
        worst_area_distortion_pct: worst.area,
        worst_l2_stretch: worst.l2,
        all_within_bounds: within,
        worst_stretch_max_pct: worst.stretch,
        fl_mesh: fl_report,
        hausdorff_to_input,
        flatten: flat.summary,
        stage_seconds: Seconds {
            vsa: t_vsa,
            refine: t_refine - t_vsa,
            merge: t_merge - t_refine,
            flatten: t_end - t_merge,
            total: t_end,
        },
    };
    Ok(Outcome {
        mesh: Some(cut_mesh),
        patterns: flat.patterns,
        summary,
        levels: Vec::new(),
    })
}

/// The seams of the patterns, found on the input where the charts are still joined: each
/// piece's vertices mapped back to input vertices (face by face, so two copies of one vertex
/// stay apart), with the slits `dangling`; flatten's own real cuts (a seam of a piece with
/// itself) are kept, its seams between pieces cannot exist on the unwelded cut mesh.
fn seams_on_input(
    mesh: &Mesh,
    patterns: &mut crate::pattern::Patterns,
    vertex_map: &[u32],
    dangling: &[u32],
) {
    let mut mapped = patterns.pieces.clone();
    for p in &mut mapped {
        for v in &mut p.vertex_ids {
            *v = vertex_map[*v as usize];
        }
    }
    let slits: HashSet<u32> = dangling.iter().copied().collect();
    let mut seams = flatten::seams_and_slits(mesh, &mapped, &slits);
    seams.extend(
        patterns
            .seams
            .drain(..)
            .filter(|s| s.pieces[0] == s.pieces[1]),
    );
    patterns.seams = seams;
}

/// The worst measures over the final pieces, and whether each is within the bounds
/// (flatten's own warnings about distortion under the bounds do not count).
struct Worst {
    area: f64,
    l2: f64,
    stretch: f64,
    within: bool,
}

impl Worst {
    fn of(pieces: &[flatten::PieceSummary], params: &Params) -> Worst {
        let mut w = Worst {
            area: 0.0,
            l2: 0.0,
            stretch: 0.0,
            within: true,
        };
        for p in pieces {
            let get = |k: &str| {
                p.measures
                    .get(k)
                    .and_then(|v| v.as_f64())
                    .unwrap_or(f64::MAX)
            };
            let (a, l2, overlap) = (
                get("area_distortion_pct").abs(),
                get("l2_stretch"),
                get("overlap"),
            );
            w.area = w.area.max(a);
            w.l2 = w.l2.max(l2);
            w.stretch = w.stretch.max(get("stretch_max_pct"));
            w.within &= a <= params.max_area_distortion
                && l2 <= params.max_l2_stretch
                && (!params.reject_overlap || overlap == 0.0);
        }
        w
    }
}

/// Mesh edges `edges` as vertex pairs, smaller first (how pieces are told where to cut).
pub fn vertex_pairs(mesh: &Mesh, edges: &[u32]) -> HashSet<(u32, u32)> {
    let all = mesh.conn().edges();
    edges
        .iter()
        .map(|&e| {
            let [a, b] = all[e as usize];
            (a.min(b), a.max(b))
        })
        .collect()
}

/// Interior edges between faces of different charts, and `dangling`, ascending.
fn cut_between(mesh: &Mesh, charts: &[u32], dangling: &[u32]) -> Vec<u32> {
    let slit: HashSet<u32> = dangling.iter().copied().collect();
    let ef = mesh.conn().edge_faces();
    (0..ef.len() as u32)
        .filter(|&e| {
            let [f, g] = ef[e as usize];
            g != NONE && (charts[f as usize] != charts[g as usize] || slit.contains(&e))
        })
        .collect()
}

/// `cut` (the input cut into its charts, faces in the input's order) with every face
/// corner at `corners[3f + i]`, and the output vertex of each corner of `stuck`.
fn with_corners(
    cut: &Mesh,
    corners: &[[f64; 3]],
    stuck: &[(u32, u8)],
) -> Result<(Mesh, Vec<u32>), AlgoError> {
    let mut pos = cut.positions().to_vec();
    for (f, t) in cut.triangles().iter().enumerate() {
        for (i, &v) in t.iter().enumerate() {
            pos[v as usize] = corners[3 * f + i];
        }
    }
    let m = cut
        .with_positions(pos)
        .map_err(|e| AlgoError::Input(format!("fl-mesh on the charts failed: {e}")))?;
    let mut ids: Vec<u32> = stuck
        .iter()
        .map(|&(f, i)| cut.triangles()[f as usize][i as usize])
        .collect();
    ids.sort_unstable();
    ids.dedup();
    Ok((m, ids))
}

/// Number of distinct labels.
fn count(labels: &[u32]) -> usize {
    labels.iter().collect::<HashSet<_>>().len()
}

/// Labels renumbered 0.. in order of each chart's lowest face.
pub fn renumber(labels: &[u32]) -> Vec<u32> {
    let mut map = std::collections::HashMap::new();
    labels
        .iter()
        .map(|l| {
            let n = map.len() as u32;
            *map.entry(*l).or_insert(n)
        })
        .collect()
}

/// The mesh cut along `cut` (mesh edge ids: chart boundaries and dangling cuts), one patch
/// per chart: its vertices (each an input vertex, `vertex_map`) and faces (the input's, in
/// order). Charts are not welded to each other: a dangling cut that ends on a chart's
/// boundary cannot be split in a mesh whose charts share vertices, and a re-flattening of
/// this mesh must see exactly the pieces merging tested.
pub fn cut_mesh(mesh: &Mesh, charts: &[u32], cut: &[u32]) -> Result<(Mesh, Vec<u32>), AlgoError> {
    let cut = vertex_pairs(mesh, cut);
    let tris = mesh.triangles();
    let (class, n, _) = flatten::cut::wedges(tris, |a, b| cut.contains(&(a, b)));
    let mut vertex_map = vec![0u32; n];
    for (c, &w) in class.iter().enumerate() {
        vertex_map[w as usize] = tris[c / 3][c % 3];
    }
    let k = charts.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let src = mesh.patch_names();
    let fp = mesh.face_patch();
    let mut names = vec![String::new(); k];
    for (f, &c) in charts.iter().enumerate() {
        if names[c as usize].is_empty() {
            names[c as usize] = if src.len() > 1 {
                format!("{}.chart{}", src[fp[f] as usize], c)
            } else {
                format!("chart{c}")
            };
        }
    }
    let raw = RawMesh {
        positions: vertex_map
            .iter()
            .map(|&v| mesh.positions()[v as usize])
            .collect(),
        triangles: (0..tris.len())
            .map(|f| [class[3 * f], class[3 * f + 1], class[3 * f + 2]])
            .collect(),
        face_patch: charts.to_vec(),
        patch_names: names,
        uv: None,
    };
    let (m, _) = Mesh::new(raw)
        .map_err(|e| AlgoError::Input(format!("cutting the mesh into its charts failed: {e}")))?;
    Ok((m, vertex_map))
}
