//! `then = fl-mesh`: every chart made exactly flattenable on its own, and split until it is
//! (not in the paper, which stops at quasi-developable charts).
//!
//! Each chart is a mesh of its own whose boundary (its seams with the other charts and its
//! slits) fl-mesh never moves, so the charts still sew together and their fl-mesh runs are
//! independent: they run in parallel (rayon), one fl-mesh per chart rather than one on the
//! whole cut mesh, so that a chart that fails is known. A chart is accepted when fl-mesh
//! converges on it and its flattening (the final flattening's settings) neither overlaps
//! itself nor stretches an edge by more than `max_stretch_pct`. Any other chart is split
//! in two by [`vsa::split`] and both halves start again from the input's positions: a chart
//! whose boundary is fixed may have no developable interior (a near-closed pouch), and an
//! isometric pattern may wrap onto itself, but a smaller chart has fewer angle sums to meet
//! with a boundary that bends less, and a chart with no interior vertex is flat already. So
//! splitting ends; `max_charts` bounds it.

use super::dual::Dual;
use super::vsa;
use crate::algorithms::flatten::{self, cut::Piece3};
use crate::algorithms::{fl_mesh, AlgoError, Control, Progress};
use crate::mesh::{Mesh, RawMesh};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Most charts splitting goes to (`max_charts`' own upper bound).
pub const MAX_CHARTS: usize = 4096;

/// What fl-mesh did on one final chart.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ChartRun {
    /// The chart (final numbering).
    pub chart: u32,
    /// Its faces.
    pub faces: usize,
    /// Its interior (free) vertices.
    pub free_vertices: usize,
    /// fl-mesh converged on it.
    pub converged: bool,
    /// fl-mesh iterations.
    pub iterations: usize,
    /// ϖ_max of the chart after fl-mesh.
    pub max_flattenability: f64,
    /// Largest edge stretch of its flattening, percent.
    pub stretch_max_pct: f64,
    /// Its flattening overlaps itself.
    pub overlap: bool,
}

/// One chart that failed and was split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// Round it was tested in (1: the merged charts).
    pub round: usize,
    /// Its faces.
    pub faces: usize,
    /// Why it failed.
    pub reason: String,
}

/// What `then = fl-mesh` did (`fl_mesh` in the report).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FlCharts {
    /// Every final chart converged, and its pattern neither overlaps nor stretches too much.
    pub converged: bool,
    /// Why it ended.
    pub stop_reason: String,
    /// Rounds of testing (1 when no chart was split).
    pub rounds: usize,
    /// Charts split because they failed.
    pub failures: Vec<Failure>,
    /// fl-mesh iterations over all runs, failed ones included.
    pub iterations: usize,
    /// Largest ϖ_max over the final charts.
    pub max_flattenability: f64,
    /// Output vertices with ϖ above the tolerance at the end (on charts that failed).
    pub stuck_vertices: Vec<u32>,
    /// Per final chart.
    pub charts: Vec<ChartRun>,
}

/// The result: chart labels after splitting, and every face corner's position.
pub struct Developed {
    /// Chart of every input face (not renumbered).
    pub labels: Vec<u32>,
    /// Position of corner `3f + i` of every face.
    pub corners: Vec<[f64; 3]>,
    /// One corner `(f, i)` of every vertex left above the tolerance.
    pub stuck: Vec<(u32, u8)>,
    /// What happened.
    pub report: FlCharts,
}

/// Acceptance settings.
pub struct Settings<'a> {
    /// fl-mesh's parameters.
    pub fl_mesh: &'a fl_mesh::Params,
    /// The final flattening's parameters.
    pub flatten: &'a flatten::Params,
    /// Largest edge stretch of an accepted chart's pattern, percent.
    pub max_stretch_pct: f64,
    /// Most charts: no split beyond it ([`MAX_CHARTS`] in `segment`).
    pub max_charts: usize,
}

/// One chart's test.
struct Tested {
    run: ChartRun,
    /// Each face of the chart with its corners' positions.
    corners: Vec<(u32, [[f64; 3]; 3])>,
    /// One corner of every vertex stuck above the tolerance.
    stuck: Vec<(u32, u8)>,
    refusal: Option<String>,
}

/// Forwards cancellation, swallows the per-chart progress (charts run at once).
struct Quiet<'a>(&'a dyn Control);

impl Control for Quiet<'_> {
    fn progress(&self, _: &Progress) {}
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
    fn cancelled_before(&self, seconds: f64) -> bool {
        self.0.cancelled_before(seconds)
    }
}

/// Run fl-mesh on every chart of `labels` (`k` labels), splitting failed ones until each
/// passes. `slits` are the mesh edges cut inside charts.
pub fn run(
    mesh: &Mesh,
    dual: &Dual,
    labels: &[u32],
    k: usize,
    slits: &[u32],
    settings: &Settings,
    control: &dyn Control,
) -> Result<Developed, AlgoError> {
    let slit_edges: HashSet<u32> = slits.iter().copied().collect();
    let slits = &super::vertex_pairs(mesh, slits);
    let mut labels = labels.to_vec();
    let mut members = vec![Vec::new(); k];
    for (f, &c) in labels.iter().enumerate() {
        members[c as usize].push(f as u32);
    }
    let mut results: Vec<Option<Tested>> = (0..k).map(|_| None).collect();
    let mut todo: Vec<u32> = (0..k as u32)
        .filter(|&c| !members[c as usize].is_empty())
        .collect();
    let mut report = FlCharts::default();
    let done = AtomicUsize::new(0);
    while !todo.is_empty() {
        report.rounds += 1;
        let tests: Vec<Result<Tested, AlgoError>> = todo
            .par_iter()
            .map(|&c| {
                let t = test(mesh, &members[c as usize], slits, settings, control);
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                control.progress(&Progress {
                    stage: "fl-mesh on charts".into(),
                    iteration: n,
                    max_flattenability: None,
                    step_norm: None,
                });
                t
            })
            .collect();
        let mut next = Vec::new();
        for (&c, t) in todo.iter().zip(tests) {
            let t = t?;
            report.iterations += t.run.iterations;
            let faces = &members[c as usize];
            let can_split = faces.len() >= 2 && members.len() < settings.max_charts;
            match (&t.refusal, can_split) {
                (Some(why), true) => {
                    report.failures.push(Failure {
                        round: report.rounds,
                        faces: faces.len(),
                        reason: why.clone(),
                    });
                    let part = vsa::split(dual, faces);
                    let halves = [false, true].map(|side| {
                        let half: Vec<u32> = faces
                            .iter()
                            .zip(&part)
                            .filter(|&(_, &p)| p == side)
                            .map(|(&f, _)| f)
                            .collect();
                        pieces(dual, &half, &slit_edges)
                    });
                    // The first piece keeps the label; a half that slits cut apart gives
                    // one chart per piece.
                    let mut parts = halves.into_iter().flatten();
                    members[c as usize] = parts.next().unwrap_or_default();
                    next.push(c);
                    for part in parts {
                        let new = members.len() as u32;
                        for &f in &part {
                            labels[f as usize] = new;
                        }
                        members.push(part);
                        results.push(None);
                        next.push(new);
                    }
                }
                _ => results[c as usize] = Some(t),
            }
        }
        todo = next;
    }
    let mut corners = vec![[0.0; 3]; 3 * mesh.num_faces()];
    let (mut failed, mut stuck) = (0, Vec::new());
    for (c, t) in results.into_iter().enumerate() {
        let Some(t) = t else { continue };
        for (f, p) in t.corners {
            corners[3 * f as usize..3 * f as usize + 3].copy_from_slice(&p);
        }
        failed += usize::from(t.refusal.is_some());
        report.max_flattenability = report.max_flattenability.max(t.run.max_flattenability);
        stuck.extend(t.stuck);
        report.charts.push(ChartRun {
            chart: c as u32,
            ..t.run
        });
    }
    report.converged = failed == 0;
    let split = report.failures.len();
    report.stop_reason = if failed == 0 {
        format!("every chart flattenable ({split} split on the way)")
    } else {
        format!(
            "{failed} chart(s) still fail after {split} split(s) (at {} charts, or single faces)",
            members.len()
        )
    };
    Ok(Developed {
        labels,
        corners,
        stuck,
        report,
    })
}

/// fl-mesh on one chart (`faces`, cut along `slits` inside it), then its flattening.
fn test(
    mesh: &Mesh,
    faces: &[u32],
    slits: &HashSet<(u32, u32)>,
    settings: &Settings,
    control: &dyn Control,
) -> Result<Tested, AlgoError> {
    let quiet = Quiet(control);
    let piece = Piece3::build_cut(
        format!("chart of face {}", faces[0]),
        faces.to_vec(),
        mesh.triangles(),
        mesh.positions(),
        slits,
    );
    let piece = match piece {
        Ok(p) => p,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => {
            return Ok(Tested {
                run: ChartRun {
                    faces: faces.len(),
                    ..ChartRun::default()
                },
                corners: faces
                    .iter()
                    .map(|&f| (f, mesh.face_positions(f as usize)))
                    .collect(),
                stuck: Vec::new(),
                refusal: Some(format!("the chart cannot be flattened: {e}")),
            })
        }
    };
    let input_corners = |pos: &[[f64; 3]]| -> Vec<(u32, [[f64; 3]; 3])> {
        piece
            .faces
            .iter()
            .zip(&piece.tris)
            .map(|(&f, t)| (f, t.map(|v| pos[v as usize])))
            .collect()
    };
    let refused = |why: String| Tested {
        run: ChartRun {
            faces: faces.len(),
            ..ChartRun::default()
        },
        corners: input_corners(&piece.pos),
        stuck: Vec::new(),
        refusal: Some(why),
    };
    let raw = RawMesh {
        positions: piece.pos.clone(),
        triangles: piece.tris.clone(),
        face_patch: vec![0; piece.tris.len()],
        patch_names: vec!["chart".into()],
        uv: None,
    };
    let sub = match Mesh::new(raw) {
        Ok((m, _)) => m,
        Err(e) => return Ok(refused(format!("the chart is not a valid mesh: {e}"))),
    };
    // A chart that does not converge is split, which keeps its shape; the developable cone
    // would move it by 10–20 % of its diagonal. So never, whatever `fl_mesh` says.
    let params = fl_mesh::Params {
        cone_start: fl_mesh::ConeStart::Never,
        ..settings.fl_mesh.clone()
    };
    let (solved, r) = match fl_mesh::solve_once(&sub, &params, &quiet) {
        Ok(x) => x,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => return Ok(refused(format!("fl-mesh failed: {e}"))),
    };
    let flat = match flatten::run(&solved, settings.flatten, &quiet) {
        Ok(x) => x,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => return Ok(refused(format!("flattening failed: {e}"))),
    };
    let (mut stretch, mut overlap) = (0.0f64, false);
    for p in &flat.summary.pieces {
        let get = |k: &str| p.measures.get(k).and_then(|v| v.as_f64());
        stretch = stretch.max(get("stretch_max_pct").unwrap_or(f64::INFINITY));
        overlap |= get("overlap").is_none_or(|o| o != 0.0);
    }
    let pieces = flat.summary.pieces.len();
    let refusal = if !r.converged {
        Some(format!(
            "fl-mesh did not converge (ϖ_max {:.2e}: {})",
            r.max_flattenability, r.stop_reason
        ))
    } else if pieces == 0 {
        Some("the flattening has no piece".into())
    } else if overlap {
        Some("its isometric pattern overlaps itself".into())
    } else if stretch.is_nan() || stretch > settings.max_stretch_pct {
        Some(format!(
            "its pattern stretches by {stretch:.3} % (more than {} %)",
            settings.max_stretch_pct
        ))
    } else {
        None
    };
    Ok(Tested {
        run: ChartRun {
            chart: 0,
            faces: faces.len(),
            free_vertices: r.free_vertices,
            converged: r.converged,
            iterations: r.iterations,
            max_flattenability: r.max_flattenability,
            stretch_max_pct: stretch,
            overlap,
        },
        corners: input_corners(solved.positions()),
        stuck: corner_of(&piece, &r.stuck_vertices),
        refusal,
    })
}

/// One corner `(global face, i)` of each local vertex of `vertices`.
fn corner_of(piece: &Piece3, vertices: &[u32]) -> Vec<(u32, u8)> {
    let mut first = vec![None; piece.pos.len()];
    for (t, tri) in piece.tris.iter().enumerate().rev() {
        for (i, &v) in tri.iter().enumerate() {
            first[v as usize] = Some((piece.faces[t], i as u8));
        }
    }
    vertices
        .iter()
        .filter_map(|&v| first.get(v as usize).copied().flatten())
        .collect()
}

/// The connected pieces of `faces`, joined across dual arcs that are not `slits`.
fn pieces(dual: &Dual, faces: &[u32], slits: &HashSet<u32>) -> Vec<Vec<u32>> {
    let inside: HashSet<u32> = faces.iter().copied().collect();
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for &f0 in faces {
        if !seen.insert(f0) {
            continue;
        }
        let (mut piece, mut stack) = (vec![f0], vec![f0]);
        while let Some(f) = stack.pop() {
            for (g, e) in dual.arcs(f as usize) {
                let g = g as u32;
                if inside.contains(&g) && !slits.contains(&(e as u32)) && seen.insert(g) {
                    piece.push(g);
                    stack.push(g);
                }
            }
        }
        piece.sort_unstable();
        out.push(piece);
    }
    out
}
