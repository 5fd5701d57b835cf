//! Opening the folds and slivers an optimiser left in a flattenable mesh without losing
//! flattenability (issue 12: "no output has more folds than its input; no corner angle below
//! the stated minimum unless the input had one").
//!
//! fl-mesh and develop reach θ = 2π by normal steps that, on whole garments, concentrate the
//! change into a few isolated hinges turning past 120° (`geometry::FOLD_ANGLE`): on the
//! t-shirt 18 single edges, scattered 5–12 rings inside the panels, each a local pinch rather
//! than a crease line. The constraint set θ = 2π leaves about two degrees of freedom per
//! vertex, so such a pinch can usually be opened by moving its neighbourhood along the
//! constraints. That is what this does, one fold at a time, and then likewise one sliver (a
//! face with a corner below the task's minimum) at a time (regions far enough apart to share
//! nothing are opened at once on the rayon pool, with the result of one after the other):
//!
//! - Region: the vertices within [`RINGS`] edges of the fold's hinge (its two faces), or of
//!   the sliver, that the
//!   caller lets move; the rest of the mesh stays bit-identical. Rows: every constrained
//!   vertex whose angle sum those moves change (the region and its one-ring).
//! - Objective: ½ Σ_e (φ_e − t_e)₊² over the hinges the region moves (φ_e the turning angle
//!   between the normals across e; t_e = 60° (`CREASE_ANGLE`) on the fold being opened and on
//!   any other fold there, max(60°, min(φ_e at the start, 110°)) elsewhere, so no neighbour may
//!   sharpen past where it was to absorb the fold, and one close to 120° is pushed below it
//!   before a step tips it over), ½ Σ_c (α⁰_c − α_c)₊² over the region's corners (α⁰ =
//!   min(10°, the corner at the start); 1.5 times the minimum, with weight [`SLIVER_WEIGHT`],
//!   for a corner below it), ½ Σ_e (l_e − l⁰_e)²/h̄² over its edges for a fold (bend, don't
//!   stretch; a fold that bending did not open is tried once more without it; a sliver's
//!   repair is a change of lengths, so not there), and ½ μ |x − x⁰|²/h̄², a small pull to
//!   the start that makes the Gauss–Newton Hessian regular.
//! - Step: sequential quadratic programming on the KKT system
//!   `[H + σI, Aᵀ; A, −εI]` (A = ∂θ/∂x of the rows, FL paper Props. 1–2) with a
//!   Levenberg–Marquardt trust region σ (÷3 after a taken step, ×4 after a refused one), and
//!   up to [`MAX_CORRECTIONS`] re-solves with the same factorisation against the rows'
//!   residual at the trial, as develop's objective phase does. Regions hold 50–70 vertices
//!   (about 300 unknowns); the system is factored as LDLᵀ on the region's pattern
//!   (`linalg::LdltSolver`, its ordering once per region). A dense LU took 1.6 ms per
//!   iteration there and most of unfold's time: on develop's t-shirt (five regions, about
//!   570 iterations) unfold took 0.65 s with it and 0.40 s with this, the same folds opened. A
//!   region stops when every term is at its target, when σ passes [`SIGMA_MAX`], or when its
//!   step moves nothing by [`STEP_TOLERANCE`]. At most [`MAX_TARGETS`] folds are tried.
//! - A trial is taken only when every row keeps |2π − θ| within max(tolerance / 2, its value
//!   at the start), the objective falls, no triangle degenerates, the region's fold count does
//!   not grow and its smallest corner stays at or above min(1°, the region's smallest at the
//!   start); a sliver's region may not add a face below the minimum either. The region's result
//!   is kept only if it has fewer folds (a sliver's: fewer folds plus slivers) than it started
//!   with. A fold's region may leave a corner between 1° and the minimum; the sliver pass then
//!   takes such faces too. Measured on the six converged shared garments with new folds
//!   (issue 12 note): holding the minimum in fold regions as well left 157 folds and 20
//!   slivers; this order leaves 121 and 45.
//!
//! Folds the caller does not list (the input's own, e.g. a designed pleat) get no region of
//! their own and are counted like any other, so a region never trades one for another; one
//! that lies in a listed fold's region is pushed down like it.

// Index loops over xyz and slots read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use crate::algorithms::{AlgoError, Control, Progress};
use crate::geometry::{
    corner_angle, corner_angle_gradient, turning_angle_gradient, CREASE_ANGLE, FOLD_ANGLE,
    SLIVER_DEGREES,
};
use crate::mesh::{is_degenerate_triangle, Mesh, NONE};
use serde::Serialize;
use std::f64::consts::{PI, TAU};

/// Rings of neighbours around a fold's hinge that may move. Measured on the six converged
/// shared garments with new folds, with a first version of the objective (issue 12 note):
/// 2, 3, 4, 3 then 5, 2 then 4, and three passes over the folds, all left 133–142 of their 398
/// new folds; 3 alone was the cheapest.
const RINGS: usize = 3;
/// Most vertices a region may move (a regular mesh's 3 rings hold 50–70; the KKT system has
/// about five unknowns per vertex, and its pattern's slot map is n × n, so this bounds it
/// near 600 × 600, 1.4 MB), and most vertices its breadth-first search may reach (16 times
/// that bounds the corners of the rows' fans): a hub of 60k long fan triangles would
/// otherwise ask for a 230 GB slot map.
const MAX_REGION: usize = 120;
const MAX_REGION_REACH: usize = 1000;
/// Most folds tried per mesh (a crumpled mesh has thousands; each costs a few solves).
const MAX_TARGETS: usize = 2000;
/// Iterations per region: 60 left one of the test strip's four crease edges folded; on the
/// garments the totals were alike.
const MAX_ITERATIONS: usize = 200;
/// Re-solves against the rows' residual after a trial.
const MAX_CORRECTIONS: usize = 6;
/// Pull to the start, in units of h̄ (relative to the hinge terms, O(1) in radians).
const CLOSENESS: f64 = 1e-3;
/// Weight of Σ (l − l⁰)² / h̄² over the region's edges: the fold opens by bending, as a sheet
/// would, not by stretching. Measured with develop (issue 12 note): without it the t-shirt's
/// δS rose 9.91 → 11.10 % and gc_tee_sim's 13.1 → 17.7 % for their folds; with 1 they end at
/// 9.92 % and 13.5 % (folds 10 → 1 and 55 → 9); 10 opened far fewer (6 and 29 left). Not for
/// a sliver, whose repair is a change of lengths. A fold this leaves is tried again with 0:
/// measured with fl-mesh on the six shared garments with new folds (issue 12 note), 99 → 91
/// left (t-shirt 4 → 2, gc_tee_sim 1 → 0, casualsuit 85 → 83, robert 4 → 1); develop's δS
/// unchanged to 0.01 % on the five it flattens (sportsuit 16 → 15 folds). With 0 alone the
/// totals were worse (robert 23 → 39, slivers up on all four).
const STRETCH: f64 = 1.0;
const SIGMA_START: f64 = 1.0;
const SIGMA_MIN: f64 = 1e-8;
const SIGMA_MAX: f64 = 1e6;
/// A region is done when its step moves no vertex by this share of h̄ (a millionth of an
/// edge): without it every region ended on a run of refused steps, σ growing ×4 each to
/// SIGMA_MAX, of 1e-7–1e-14 h̄ (t-shirt: 84 of its 491 iterations). Measured with develop:
/// unfold's iterations t-shirt 491 → 368, gc_tee_sim 1982 → 1769, mh_classicshoes_medium
/// 415 → 350, with the same folds and slivers opened and δS equal to 1e-5.
const STEP_TOLERANCE: f64 = 1e-6;
/// The (2,2) block's −εI: keeps the system solvable where a row's gradient vanishes.
const REGULARISATION: f64 = 1e-10;
/// A row held above the tolerance is corrected back to this share of where it started (0.5
/// was measured worse on diffavatar_shirt_artist: 1 region opened instead of 3, since the
/// corrections' longer moves raised the objective).
const HELD_INSIDE: f64 = 0.95;
/// A sliver's corners (below the task's minimum) are pushed up to this many times it.
const SLIVER_MARGIN: f64 = 1.5;
/// Weight of a sliver corner's term (one below the task's minimum, pushed to
/// [`SLIVER_MARGIN`] times it) against the hinge terms. With 1 a fold's hinge, about a radian
/// past its target, outweighs a corner a few degrees short of 3°, so the steps sharpened the
/// sliver until the corner floor refused them. Measured with fl-mesh on the six converged
/// shared garments with new folds (issue 12 note of 2026-11-27), folds left / faces below 2°
/// in total: 1 → 91 / 36, 10 → 85 / 21, 30 → 86 / 16, 100 → 77 / 17, 365 (1/t²) → 78 / 17
/// with robert's folds 1 → 7; at 100 mh_female_sportsuit01 ends with no fold and every corner
/// ≥ 2° (was 3 folds, 0.82°). develop's results (its minimum is 1°) were unchanged.
const SLIVER_WEIGHT: f64 = 100.0;
/// Corners below this (or below where they started, if lower) are pushed back up.
const CORNER_ONSET: f64 = PI / 18.0;
/// Hinges within this of [`FOLD_ANGLE`] are pushed below it: their penalty would otherwise
/// start at zero slope and the step would tip them over, which the fold count refuses.
const MARGIN: f64 = PI / 18.0;

/// What [`unfold`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Unfolded {
    /// The positions, moved only where a fold or sliver was repaired.
    pub positions: Vec<[f64; 3]>,
    /// The figures for the report.
    pub summary: Summary,
}

/// What [`unfold`] did, for a job's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Folds of the mesh (listed or not) before.
    pub folds_before: usize,
    /// Folds of the mesh after.
    pub folds_after: usize,
    /// Faces with a corner below the minimum, before.
    pub slivers_before: usize,
    /// Faces with a corner below the minimum, after.
    pub slivers_after: usize,
    /// Listed folds and slivers still there when their turn came (a neighbour's region may
    /// repair one).
    pub tried: usize,
    /// Of those, how many are repaired at the end.
    pub opened: usize,
}

/// What to repair and under which limits.
#[derive(Debug, Clone, Copy)]
pub struct Task<'a> {
    /// Fold edges to open (edge ids of the mesh).
    pub folds: &'a [u32],
    /// Faces whose smallest corner, below `min_corner`, to open up (face ids).
    pub slivers: &'a [u32],
    /// Radians: a corner below this counts as a sliver's.
    pub min_corner: f64,
    /// Which vertices may move.
    pub movable: &'a [bool],
    /// Which vertices' angle sums are held.
    pub constrained: &'a [bool],
    /// ϖ tolerance: every constrained vertex stays within max(tolerance / 2, where it was)
    /// (half, so that writing the result to a file keeps it within the tolerance).
    pub tolerance: f64,
}

/// Open the task's folds, then its slivers, of `mesh` placed at `pos`, one neighbourhood at
/// a time (see the module doc).
pub fn unfold(
    mesh: &Mesh,
    pos: &[[f64; 3]],
    task: &Task<'_>,
    control: &dyn Control,
) -> Result<Unfolded, AlgoError> {
    let folds_before = crate::geometry::fold_count_at(mesh, pos);
    let slivers_before = sliver_count(mesh, pos, task.min_corner);
    let mut out = Unfolded {
        positions: pos.to_vec(),
        summary: Summary {
            folds_before,
            folds_after: folds_before,
            slivers_before,
            slivers_after: slivers_before,
            ..Summary::default()
        },
    };
    let h = crate::geometry::mean_edge_length(mesh);
    if !(h > 0.0 && h.is_finite()) {
        return Ok(out);
    }
    let mut scratch = Scratch::new(mesh.num_vertices());
    // Folds first, then slivers: the task's and any a fold's region left (a fold's region
    // may take a corner down to min(1°, its smallest); the sliver pass lifts it again).
    let folds: Vec<Seed> = task
        .folds
        .iter()
        .filter_map(|&e| hinge_of(mesh, e).map(Seed::Fold))
        .take(MAX_TARGETS)
        .collect();
    let mut done = 0;
    repair(
        mesh,
        &folds,
        task,
        h,
        &mut scratch,
        &mut out,
        &mut done,
        control,
    )?;
    let listed: std::collections::HashSet<u32> = task.slivers.iter().copied().collect();
    let slivers: Vec<Seed> = task
        .slivers
        .iter()
        .copied()
        .chain((0..mesh.num_faces() as u32).filter(|&f| {
            !listed.contains(&f)
                && smallest_of(mesh, &out.positions, f) < task.min_corner
                && smallest_of(mesh, pos, f) >= task.min_corner
        }))
        .map(Seed::Sliver)
        .take(MAX_TARGETS.saturating_sub(folds.len()))
        .collect();
    repair(
        mesh,
        &slivers,
        task,
        h,
        &mut scratch,
        &mut out,
        &mut done,
        control,
    )?;
    out.summary.folds_after = crate::geometry::fold_count_at(mesh, &out.positions);
    out.summary.slivers_after = sliver_count(mesh, &out.positions, task.min_corner);
    Ok(out)
}

/// Repair each seed still there in turn; `done` counts regions for progress. Seeds far
/// enough apart to share nothing ([`batch_end`]) are opened at once on the rayon pool and
/// applied in their order, which is what one after the other gives, bit for bit.
#[allow(clippy::too_many_arguments)]
fn repair(
    mesh: &Mesh,
    seeds: &[Seed],
    task: &Task<'_>,
    h: f64,
    scratch: &mut Scratch,
    out: &mut Unfolded,
    done: &mut usize,
    control: &dyn Control,
) -> Result<(), AlgoError> {
    use rayon::prelude::*;
    let pending = |p: &[[f64; 3]], seed: &Seed| match *seed {
        Seed::Fold(q) => is_fold(p, q),
        Seed::Sliver(f) => smallest_of(mesh, p, f) < task.min_corner,
    };
    let mut next = 0;
    while next < seeds.len() {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        // The batch: the seeds from `next` on, up to the first whose neighbourhood meets an
        // earlier one's (BATCH_RINGS), with their regions.
        let end = batch_end(mesh, seeds, next, scratch);
        let mut batch: Vec<(&Seed, Region)> = Vec::new();
        for seed in &seeds[next..end] {
            *done += 1;
            control.progress(&Progress {
                stage: "unfold".into(),
                iteration: *done,
                max_flattenability: None,
                step_norm: None,
            });
            if !pending(&out.positions, seed) {
                continue; // repaired by a neighbour's region
            }
            out.summary.tried += 1;
            let Some(region) = Region::new(mesh, seed.vertices(mesh), RINGS, task, scratch) else {
                continue; // a neighbourhood too large (a hub of long fans)
            };
            if !region.verts.is_empty() {
                batch.push((seed, region));
            }
        }
        next = end;
        // A fold first by bending (lengths held), then, where that did not open it, freely:
        // the first attempts of the whole batch at once, the second ones after.
        let first = |seed: &Seed| match seed {
            Seed::Fold(_) => STRETCH,
            Seed::Sliver(_) => 0.0,
        };
        let positions = &out.positions;
        let moved: Vec<Option<Vec<[f64; 3]>>> = batch
            .par_iter()
            .map(|(seed, region)| region.open(mesh, positions, task, seed, h, first(seed)))
            .collect();
        for ((_, region), moved) in batch.iter().zip(moved) {
            if let Some(moved) = moved {
                for (s, &v) in region.verts.iter().enumerate() {
                    out.positions[v as usize] = moved[s];
                }
            }
        }
        for (seed, region) in &batch {
            if matches!(seed, Seed::Fold(_)) && pending(&out.positions, seed) {
                if let Some(moved) = region.open(mesh, &out.positions, task, seed, h, 0.0) {
                    for (s, &v) in region.verts.iter().enumerate() {
                        out.positions[v as usize] = moved[s];
                    }
                }
            }
            if !pending(&out.positions, seed) {
                out.summary.opened += 1;
            }
        }
    }
    Ok(())
}

/// Seeds closer than this many rings share work: a region moves the vertices within
/// [`RINGS`] of its seed and reads those within two rings of them (its faces' hinges, its
/// rows' fans), so two seeds more than 2 (RINGS + 1) rings apart read nothing the other
/// writes, and opening them at once gives what one after the other does.
const BATCH_RINGS: usize = RINGS + 1;
/// Regions per thread of the pool in one batch: a cancellation is seen between batches, so
/// it waits for about this many regions (each tens of milliseconds on a garment).
const BATCH_PER_THREAD: usize = 4;

/// The end of the batch that starts at `from`: every seed before it lies more than
/// 2 BATCH_RINGS rings from every earlier seed of the batch (at least one seed is taken).
fn batch_end(mesh: &Mesh, seeds: &[Seed], from: usize, scratch: &mut Scratch) -> usize {
    let conn = mesh.conn();
    // The BATCH_RINGS neighbourhood of a seed, breadth first; `scratch.near` marks those of
    // the batch so far (cleared before returning).
    let neighbourhood = |seed: &Seed, seen: &mut Vec<bool>| -> Vec<u32> {
        let mut ball = seed.vertices(mesh).to_vec();
        ball.sort_unstable();
        ball.dedup();
        for &v in &ball {
            seen[v as usize] = true;
        }
        let mut layer = (0, ball.len());
        for _ in 0..BATCH_RINGS {
            for k in layer.0..layer.1 {
                for &w in conn.ring_of(ball[k]) {
                    if !seen[w as usize] {
                        seen[w as usize] = true;
                        ball.push(w);
                    }
                }
            }
            layer = (layer.1, ball.len());
        }
        for &v in &ball {
            seen[v as usize] = false;
        }
        ball
    };
    scratch.near.resize(mesh.num_vertices(), false);
    scratch.seen.resize(mesh.num_vertices(), false);
    let mut marked = Vec::new();
    let most = BATCH_PER_THREAD * rayon::current_num_threads().max(1);
    let mut end = from;
    while end < seeds.len() && end - from < most {
        let ball = neighbourhood(&seeds[end], &mut scratch.seen);
        if end > from && ball.iter().any(|&v| scratch.near[v as usize]) {
            break;
        }
        for &v in &ball {
            scratch.near[v as usize] = true;
        }
        marked.extend(ball);
        end += 1;
    }
    for v in marked {
        scratch.near[v as usize] = false;
    }
    end
}

/// Add w r² (r a residual with gradient `g` per slot, NONE: a fixed vertex) to the
/// Gauss–Newton model: w g gᵀ into `k`, −w r g into `rhs`.
fn add_term(k: &mut Lower, rhs: &mut [f64], slots: &[u32], g: &[[f64; 3]], r: f64, w: f64) {
    for (a, &sa) in slots.iter().enumerate() {
        if sa == NONE {
            continue;
        }
        let sa = 3 * sa as usize;
        for i in 0..3 {
            rhs[sa + i] -= w * r * g[a][i];
        }
        for (b, &sb) in slots.iter().enumerate() {
            if sb == NONE {
                continue;
            }
            let sb = 3 * sb as usize;
            for i in 0..3 {
                for j in 0..3 {
                    k.add(sa + i, sb + j, w * g[a][i] * g[b][j]);
                }
            }
        }
    }
}

/// A region's KKT matrix as its pattern's lower triangle, assembled in place. It replaced a
/// dense n × n buffer, cleared every iteration and gathered into the pattern's values (the
/// same sums in the same order, so the same factorisation): its clearing alone was 2 % of
/// develop's instructions on the t-shirt.
struct Lower {
    n: usize,
    /// Per (r, c) with r ≥ c, at r·n + c: its index in `values` (u32::MAX off the pattern).
    slot: Vec<u32>,
    /// In the order of the pattern `Region::kkt_pattern` returns.
    values: Vec<f64>,
}

impl Lower {
    /// Add to entry (r, c); the upper triangle, which the LDLᵀ does not read, is skipped, and
    /// so is an entry off the pattern (none is written: the pattern holds every coupling).
    fn add(&mut self, r: usize, c: usize, v: f64) {
        if r >= c {
            if let Some(x) = self.values.get_mut(self.slot[r * self.n + c] as usize) {
                *x += v;
            }
        }
    }

    /// Set diagonal entry i.
    fn set_diagonal(&mut self, i: usize, v: f64) {
        if let Some(x) = self.values.get_mut(self.slot[i * self.n + i] as usize) {
            *x = v;
        }
    }
}

/// What a region is built around.
enum Seed {
    Fold([u32; 4]),
    Sliver(u32),
}

impl Seed {
    /// The hinge's four vertices, or the sliver's three.
    fn vertices<'a>(&'a self, mesh: &'a Mesh) -> &'a [u32] {
        match self {
            Seed::Fold(q) => q,
            Seed::Sliver(f) => &mesh.triangles()[*f as usize],
        }
    }
}

/// Smallest corner of face f at `p`.
fn smallest_of(mesh: &Mesh, p: &[[f64; 3]], f: u32) -> f64 {
    let [a, b, c] = mesh.triangles()[f as usize].map(|v| p[v as usize]);
    corner_angle(a, b, c)
        .min(corner_angle(b, c, a))
        .min(corner_angle(c, a, b))
}

/// Faces with a corner below `min_corner` at `p`.
fn sliver_count(mesh: &Mesh, p: &[[f64; 3]], min_corner: f64) -> usize {
    (0..mesh.num_faces() as u32)
        .filter(|&f| smallest_of(mesh, p, f) < min_corner)
        .count()
}

/// Edge e's hinge (i, j, k, l): faces (i, j, k) and (j, i, l), or None on the boundary.
pub(crate) fn hinge_of(mesh: &Mesh, e: u32) -> Option<[u32; 4]> {
    let f = *mesh.conn().edge_faces().get(e as usize)?;
    if f[1] == NONE {
        return None;
    }
    let [a, b] = mesh.conn().edges()[e as usize];
    let t0 = mesh.triangles()[f[0] as usize];
    let t1 = mesh.triangles()[f[1] as usize];
    let k0 = (0..3).find(|&k| t0[k] == a)?;
    let (i, j) = if t0[(k0 + 1) % 3] == b {
        (a, b)
    } else {
        (b, a)
    };
    let apex = |t: [u32; 3]| t.into_iter().find(|&x| x != i && x != j);
    Some([i, j, apex(t0)?, apex(t1)?])
}

/// Whether hinge q folds at `pos`, by the same test as `geometry::fold_edges` (unit normals'
/// dot product below cos 120°; the faces' corners taken in another rotation, which can differ
/// in the last bits only).
fn is_fold(pos: &[[f64; 3]], q: [u32; 4]) -> bool {
    let [i, j, k, l] = q.map(|v| pos[v as usize]);
    let n1 = crate::geometry::normalize(crate::mesh::cross(
        crate::mesh::sub(j, i),
        crate::mesh::sub(k, i),
    ));
    let n2 = crate::geometry::normalize(crate::mesh::cross(
        crate::mesh::sub(i, j),
        crate::mesh::sub(l, j),
    ));
    crate::mesh::dot(n1, n2) < FOLD_ANGLE.cos()
}

fn hinge_angle(pos: &[[f64; 3]], q: [u32; 4]) -> f64 {
    let p = q.map(|v| pos[v as usize]);
    turning_angle_gradient(p[0], p[1], p[2], p[3]).0
}

/// Per-vertex scratch shared by the regions (reset after each).
struct Scratch {
    slot: Vec<u32>,
    row: Vec<u32>,
    face: Vec<bool>,
    /// Vertices near a seed of the batch being built, and a breadth-first search's visits.
    near: Vec<bool>,
    seen: Vec<bool>,
}

impl Scratch {
    fn new(nv: usize) -> Self {
        Scratch {
            slot: vec![NONE; nv],
            row: vec![NONE; nv],
            face: Vec::new(),
            near: Vec::new(),
            seen: Vec::new(),
        }
    }
}

/// One fold's neighbourhood: moving vertices, rows, faces and hinges they change.
struct Region {
    verts: Vec<u32>,
    rows: Vec<u32>,
    faces: Vec<u32>,
    /// Per face, its vertices' slots (NONE: fixed).
    face_slots: Vec<[u32; 3]>,
    /// Edges with a moving end, and their ends' slots.
    edges: Vec<([u32; 2], [u32; 2])>,
    /// Hinges (i, j, k, l) the moving vertices change, and each one's slot per vertex
    /// (NONE: fixed).
    hinges: Vec<([u32; 4], [u32; 4])>,
    /// Per row, its fan as (face, corner) and the slots of the corner's three vertices.
    fans: Vec<Vec<([u32; 3], [u32; 3])>>,
}

impl Region {
    fn new(
        mesh: &Mesh,
        seed: &[u32],
        rings: usize,
        task: &Task<'_>,
        scratch: &mut Scratch,
    ) -> Option<Self> {
        let (movable, constrained) = (task.movable, task.constrained);
        let conn = mesh.conn();
        // Breadth-first over the rings (every vertex reached, moving or not, to find them).
        let mut seen: Vec<u32> = Vec::new();
        let mut depth_of = std::collections::HashMap::new();
        for &v in seed {
            if depth_of.insert(v, 0usize).is_none() {
                seen.push(v);
            }
        }
        let mut at = 0;
        while at < seen.len() {
            let v = seen[at];
            at += 1;
            let d = depth_of[&v];
            if d == rings {
                continue;
            }
            for &w in conn.ring_of(v) {
                if let std::collections::hash_map::Entry::Vacant(slot) = depth_of.entry(w) {
                    slot.insert(d + 1);
                    seen.push(w);
                    if seen.len() > MAX_REGION_REACH {
                        return None;
                    }
                }
            }
        }
        let verts: Vec<u32> = seen.into_iter().filter(|&v| movable[v as usize]).collect();
        // The rows' fans bound the work per iteration as the vertices bound the matrix.
        let fan_corners: usize = verts
            .iter()
            .flat_map(|&v| std::iter::once(v).chain(conn.ring_of(v).iter().copied()))
            .map(|w| conn.fan_of(w).len())
            .sum();
        if verts.len() > MAX_REGION || fan_corners > MAX_REGION_REACH * 16 {
            return None;
        }
        for (s, &v) in verts.iter().enumerate() {
            scratch.slot[v as usize] = s as u32;
        }
        let mut rows = Vec::new();
        for &v in &verts {
            for &w in std::iter::once(&v).chain(conn.ring_of(v)) {
                if constrained[w as usize] && scratch.row[w as usize] == NONE {
                    scratch.row[w as usize] = rows.len() as u32;
                    rows.push(w);
                }
            }
        }
        let tris = mesh.triangles();
        scratch.face.resize(tris.len(), false);
        let mut faces = Vec::new();
        for &v in &verts {
            for &he in conn.fan_of(v) {
                let f = he / 3;
                if !scratch.face[f as usize] {
                    scratch.face[f as usize] = true;
                    faces.push(f);
                }
            }
        }
        let mut hinges = Vec::new();
        let mut edges = Vec::new();
        let mut edges_seen = std::collections::HashSet::new();
        for &f in &faces {
            for k in 0..3 {
                let e = conn.edge_of(3 * f + k as u32);
                if edges_seen.insert(e) {
                    let ends = conn.edges()[e as usize];
                    let slots = ends.map(|v| scratch.slot[v as usize]);
                    if slots != [NONE; 2] {
                        edges.push((ends, slots));
                    }
                    if let Some(q) = hinge_of(mesh, e) {
                        hinges.push((q, q.map(|v| scratch.slot[v as usize])));
                    }
                }
            }
        }
        let face_slots = faces
            .iter()
            .map(|&f| tris[f as usize].map(|v| scratch.slot[v as usize]))
            .collect();
        let fans = rows
            .iter()
            .map(|&v| {
                conn.fan_of(v)
                    .iter()
                    .map(|&he| {
                        let (f, k) = ((he / 3) as usize, (he % 3) as usize);
                        let t = tris[f];
                        let c = [t[k], t[(k + 1) % 3], t[(k + 2) % 3]];
                        (c, c.map(|x| scratch.slot[x as usize]))
                    })
                    .collect()
            })
            .collect();
        for &v in &verts {
            scratch.slot[v as usize] = NONE;
        }
        for &v in &rows {
            scratch.row[v as usize] = NONE;
        }
        for &f in &faces {
            scratch.face[f as usize] = false;
        }
        Some(Region {
            verts,
            rows,
            faces,
            face_slots,
            edges,
            hinges,
            fans,
        })
    }

    /// The region's positions with fewer folds than at `pos`, or None.
    fn open(
        &self,
        mesh: &Mesh,
        pos: &[[f64; 3]],
        task: &Task<'_>,
        seed: &Seed,
        h: f64,
        stretch: f64,
    ) -> Option<Vec<[f64; 3]>> {
        // A fold opens by bending (lengths held); a sliver is a matter of lengths, and a
        // fold's region counts only folds (the sliver pass comes after it).
        let (stretch_weight, hold_slivers) = match seed {
            Seed::Fold(_) => (stretch, false),
            Seed::Sliver(_) => (0.0, true),
        };
        let (tolerance, min_corner) = (task.tolerance, task.min_corner);
        let m = self.verts.len();
        let r = self.rows.len();
        let n = 3 * m + r;
        let x0: Vec<[f64; 3]> = self.verts.iter().map(|&v| pos[v as usize]).collect();
        let mut work = pos.to_vec();
        let residual = |p: &[[f64; 3]], out: &mut Vec<f64>| {
            out.clear();
            out.extend(self.fans.iter().map(|fan| {
                TAU - fan
                    .iter()
                    .map(|(c, _)| {
                        let [a, b, d] = c.map(|v| p[v as usize]);
                        corner_angle(a, b, d)
                    })
                    .sum::<f64>()
            }));
        };
        let mut c = Vec::with_capacity(r);
        residual(&work, &mut c);
        let bound: Vec<f64> = c.iter().map(|x| x.abs().max(0.5 * tolerance)).collect();
        // Where a row the run left above the tolerance (an unconverged mesh) is held: its
        // start, and the corrections bring it back just inside it when a trial pushed it out.
        // Steering such rows to 0, as the others, asked a region to close what the whole run
        // could not: on diffavatar_shirt_artist (ϖ_max 4.2e-4, every row of every region above
        // the tolerance) each trial was refused and 0 of its 72 regions opened; holding them,
        // 3 did (folds 53 → 47, its input has 49). Converged meshes have no such row.
        let held: Vec<f64> = c
            .iter()
            .map(|&x| if x.abs() > tolerance { x } else { 0.0 })
            .collect();
        let settled = |ct: &[f64]| {
            ct.iter()
                .zip(&bound)
                .zip(&held)
                .all(|((x, b), a)| x.abs() <= if *a != 0.0 { *b } else { 0.5 * b })
        };
        let targets: Vec<f64> = self
            .hinges
            .iter()
            .map(|(q, _)| {
                let phi = hinge_angle(pos, *q);
                if phi > FOLD_ANGLE {
                    CREASE_ANGLE
                } else {
                    CREASE_ANGLE.max(phi.min(FOLD_ANGLE - MARGIN))
                }
            })
            .collect();
        let folds = |p: &[[f64; 3]]| self.hinges.iter().filter(|(q, _)| is_fold(p, *q)).count();
        let smallest = |p: &[[f64; 3]]| {
            self.faces
                .iter()
                .fold(f64::INFINITY, |s, &f| s.min(smallest_of(mesh, p, f)))
        };
        let corner_at = |p: &[[f64; 3]], f: u32, k: usize| {
            let t = mesh.triangles()[f as usize];
            corner_angle(
                p[t[k] as usize],
                p[t[(k + 1) % 3] as usize],
                p[t[(k + 2) % 3] as usize],
            )
        };
        // Per face corner: (target, weight) of its term.
        let corner_terms: Vec<[(f64, f64); 3]> = self
            .faces
            .iter()
            .map(|&f| {
                [0, 1, 2].map(|k| {
                    let a = corner_at(pos, f, k);
                    if a < min_corner {
                        (SLIVER_MARGIN * min_corner, SLIVER_WEIGHT)
                    } else {
                        (CORNER_ONSET.min(a), 1.0)
                    }
                })
            })
            .collect();
        let slivers = |p: &[[f64; 3]]| {
            self.faces
                .iter()
                .filter(|&&f| smallest_of(mesh, p, f) < min_corner)
                .count()
        };
        let length = |p: &[[f64; 3]], e: [u32; 2]| {
            let d = crate::mesh::sub(p[e[0] as usize], p[e[1] as usize]);
            crate::mesh::dot(d, d).sqrt()
        };
        let rest: Vec<f64> = self.edges.iter().map(|(e, _)| length(pos, *e)).collect();
        // (½ Σ hinge² + ½ Σ corner², that plus the pull and the stretch): the penalty alone
        // says when to stop.
        let objective = |p: &[[f64; 3]]| {
            let corners: f64 = self
                .faces
                .iter()
                .zip(&corner_terms)
                .map(|(&f, terms)| {
                    (0..3)
                        .map(|k| {
                            let (t, w) = terms[k];
                            w * (t - corner_at(p, f, k)).max(0.0).powi(2)
                        })
                        .sum::<f64>()
                })
                .sum();
            let hinge: f64 = self
                .hinges
                .iter()
                .zip(&targets)
                .map(|((q, _), &t)| (hinge_angle(p, *q) - t).max(0.0).powi(2))
                .sum();
            let pull: f64 = self
                .verts
                .iter()
                .zip(&x0)
                .map(|(&v, q)| {
                    let d = crate::mesh::sub(p[v as usize], *q);
                    crate::mesh::dot(d, d)
                })
                .sum();
            let stretch: f64 = self
                .edges
                .iter()
                .zip(&rest)
                .map(|((e, _), &l0)| (length(p, *e) - l0).powi(2))
                .sum();
            let penalty = 0.5 * (hinge + corners);
            (
                penalty,
                penalty + 0.5 * (CLOSENESS * pull + stretch_weight * stretch) / (h * h),
            )
        };
        let folds0 = folds(pos);
        let slivers0 = slivers(pos);
        let floor = smallest(pos).min(SLIVER_DEGREES.to_radians());
        let mut f = objective(&work).1;
        let mut sigma = SIGMA_START;
        let mut trial = work.clone();
        let mut ct = Vec::with_capacity(r);
        let mut best: Option<(usize, f64, Vec<[f64; 3]>)> = None;
        // Assembled afresh every iteration on the region's pattern (see `kkt_pattern`).
        let (pattern, slot) = self.kkt_pattern();
        let mut kmat = Lower {
            n,
            slot,
            values: vec![0.0; pattern.len()],
        };
        let signs = (0..n).map(|i| if i < 3 * m { 1 } else { -1 }).collect();
        let groups: Vec<u32> = (0..n)
            .map(|i| if i < 3 * m { i / 3 } else { i - 2 * m } as u32)
            .collect();
        let mut lu = crate::linalg::LdltSolver::new(n, &pattern, signs, Some(&groups)).ok()?;
        let mut rhs = vec![0.0; n];
        let mut corr = vec![0.0; n];
        for _ in 0..MAX_ITERATIONS {
            // K = [H + σI, Aᵀ; A, −εI] in units of h̄; right-hand side [−∇f; 2π − θ].
            let kmat = &mut kmat;
            kmat.values.fill(0.0);
            rhs.fill(0.0);
            for i in 0..3 * m {
                kmat.set_diagonal(i, CLOSENESS + sigma);
            }
            for (s, &v) in self.verts.iter().enumerate() {
                for i in 0..3 {
                    rhs[3 * s + i] = -CLOSENESS * (work[v as usize][i] - x0[s][i]) / h;
                }
            }
            // Gauss–Newton terms w r², gradients in units of h̄.
            for ((q, slots), &t) in self.hinges.iter().zip(&targets) {
                let p = q.map(|v| work[v as usize]);
                let (phi, g) = turning_angle_gradient(p[0], p[1], p[2], p[3]);
                if phi > t {
                    let g = g.map(|x| x.map(|y| y * h));
                    add_term(kmat, &mut rhs, slots, &g, phi - t, 1.0);
                }
            }
            for ((&fc, slots), terms) in self.faces.iter().zip(&self.face_slots).zip(&corner_terms)
            {
                let tri = mesh.triangles()[fc as usize];
                for k in 0..3 {
                    let p = [0, 1, 2].map(|x| work[tri[(k + x) % 3] as usize]);
                    let alpha = corner_angle(p[0], p[1], p[2]);
                    let (t, w) = terms[k];
                    if alpha < t {
                        // r = t − α: ∇r = −∇α.
                        let (gb, gc) = corner_angle_gradient(p[0], p[1], p[2]);
                        let g = [
                            [0, 1, 2].map(|i| gb[i] + gc[i]),
                            gb.map(|x| -x),
                            gc.map(|x| -x),
                        ]
                        .map(|x| x.map(|y| y * h));
                        let sl = [0, 1, 2].map(|x| slots[(k + x) % 3]);
                        add_term(kmat, &mut rhs, &sl, &g, t - alpha, w);
                    }
                }
            }
            // Stretch: r = (l − l⁰)/h̄, gradient ±u (the unit edge direction).
            for ((e, slots), &l0) in self.edges.iter().zip(&rest) {
                let d = crate::mesh::sub(work[e[0] as usize], work[e[1] as usize]);
                let l = crate::mesh::dot(d, d).sqrt();
                if l > 0.0 && stretch_weight > 0.0 {
                    let u = d.map(|x| x / l);
                    let g = [u, u.map(|x| -x)];
                    add_term(kmat, &mut rhs, slots, &g, (l - l0) / h, stretch_weight);
                }
            }
            for (row, fan) in self.fans.iter().enumerate() {
                let ri = 3 * m + row;
                kmat.set_diagonal(ri, -REGULARISATION);
                rhs[ri] = c[row] - held[row];
                for (corner, slots) in fan {
                    let [a, b, d] = corner.map(|v| work[v as usize]);
                    let (gb, gd) = corner_angle_gradient(a, b, d);
                    let grads = [[0, 1, 2].map(|i| -(gb[i] + gd[i])), gb, gd];
                    for x in 0..3 {
                        if slots[x] == NONE {
                            continue;
                        }
                        for i in 0..3 {
                            let col = 3 * slots[x] as usize + i;
                            kmat.add(ri, col, grads[x][i] * h);
                        }
                    }
                }
            }
            let solved = lu
                .factor(&kmat.values)
                .and_then(|()| lu.solve_in_place(&mut rhs));
            if solved.is_err() || rhs.iter().any(|x| !x.is_finite()) {
                sigma *= 4.0;
                if sigma > SIGMA_MAX {
                    break;
                }
                continue;
            }
            if rhs[..3 * m].iter().all(|x| x.abs() < STEP_TOLERANCE) {
                break;
            }
            trial.copy_from_slice(&work);
            self.place(&mut trial, &rhs, h);
            // Back onto the rows with the same factorisation.
            for _ in 0..MAX_CORRECTIONS {
                residual(&trial, &mut ct);
                if settled(&ct) {
                    break;
                }
                corr[..3 * m].fill(0.0);
                for ((x, &r), &a) in corr[3 * m..].iter_mut().zip(&ct).zip(&held) {
                    *x = r - HELD_INSIDE * a;
                }
                if lu.solve_in_place(&mut corr).is_err() || corr.iter().any(|x| !x.is_finite()) {
                    break;
                }
                self.place(&mut trial, &corr, h);
            }
            residual(&trial, &mut ct);
            let sound = self.faces.iter().all(|&fc| {
                let [a, b, d] = mesh.triangles()[fc as usize].map(|v| trial[v as usize]);
                !is_degenerate_triangle(a, b, d)
            });
            let (penalty, ft) = objective(&trial);
            let taken = sound
                && ft.is_finite()
                && ft < f
                && ct.iter().zip(&bound).all(|(x, b)| x.abs() <= *b)
                && folds(&trial) <= folds0
                && (!hold_slivers || slivers(&trial) <= slivers0)
                && smallest(&trial) >= floor;
            if taken {
                std::mem::swap(&mut work, &mut trial);
                std::mem::swap(&mut c, &mut ct);
                f = ft;
                sigma = (sigma / 3.0).max(SIGMA_MIN);
                let nf = folds(&work) + if hold_slivers { slivers(&work) } else { 0 };
                if best.as_ref().is_none_or(|(bf, bo, _)| (nf, f) < (*bf, *bo)) {
                    best = Some((
                        nf,
                        f,
                        self.verts.iter().map(|&v| work[v as usize]).collect(),
                    ));
                }
                // Every hinge and corner at its target: nothing left to open.
                if penalty == 0.0 {
                    break;
                }
            } else {
                sigma *= 4.0;
                if sigma > SIGMA_MAX {
                    break;
                }
            }
        }
        let defects0 = folds0 + if hold_slivers { slivers0 } else { 0 };
        best.filter(|(nf, _, _)| *nf < defects0).map(|(_, _, p)| p)
    }

    /// The lower triangle of the region's KKT pattern, every coupling a term can make: the
    /// 3×3 blocks of the slots a hinge, a face (its corners) or an edge joins, and each row's
    /// entries for the slots of its fan; and per (r, c) with r ≥ c, at r·n + c, its index in
    /// that list (u32::MAX off it), for [`Lower`]. Sparse: a dense LU of these 300–600
    /// unknowns was most of unfold's time (0.6 s on the t-shirt's five regions).
    fn kkt_pattern(&self) -> (Vec<(usize, usize)>, Vec<u32>) {
        let m = self.verts.len();
        let n = 3 * m + self.rows.len();
        let mut slot = vec![u32::MAX; n * n];
        let mut out = Vec::new();
        let mut put = |r: usize, c: usize| {
            let (r, c) = (r.max(c), r.min(c));
            if slot[r * n + c] == u32::MAX {
                slot[r * n + c] = out.len() as u32;
                out.push((r, c));
            }
        };
        let blocks = |slots: &[u32], put: &mut dyn FnMut(usize, usize)| {
            for &a in slots.iter().filter(|&&a| a != NONE) {
                for &b in slots.iter().filter(|&&b| b != NONE) {
                    for i in 0..3 {
                        for j in 0..3 {
                            put(3 * a as usize + i, 3 * b as usize + j);
                        }
                    }
                }
            }
        };
        for s in 0..m as u32 {
            blocks(&[s], &mut put);
        }
        for (_, slots) in &self.hinges {
            blocks(slots, &mut put);
        }
        for slots in &self.face_slots {
            blocks(slots, &mut put);
        }
        for (_, slots) in &self.edges {
            blocks(slots, &mut put);
        }
        for (row, fan) in self.fans.iter().enumerate() {
            let ri = 3 * m + row;
            put(ri, ri);
            for (_, slots) in fan {
                for &sl in slots.iter().filter(|&&sl| sl != NONE) {
                    for i in 0..3 {
                        put(ri, 3 * sl as usize + i);
                    }
                }
            }
        }
        (out, slot)
    }

    /// `p` moved by h̄ times the first 3m entries of `step`.
    fn place(&self, p: &mut [[f64; 3]], step: &[f64], h: f64) {
        for (s, &v) in self.verts.iter().enumerate() {
            for i in 0..3 {
                p[v as usize][i] += h * step[3 * s + i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::Silent;
    use crate::mesh::RawMesh;

    /// A 12 × 4 grid of unit squares bent about its vertical grid lines, by ±10° (alternating)
    /// and by `beta` about the line x = 6 (an isometry of the flat grid, so every interior
    /// angle sum stays 2π, and no vertex is planar, where θ's gradient would vanish); its four
    /// crease edges; and which vertices are in the two end columns.
    fn folded_strip(beta: f64) -> (Mesh, Vec<u32>, Vec<bool>) {
        let (nx, ny) = (12usize, 4usize);
        let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
        let mut profile = vec![[0.0f64, 0.0]];
        let mut heading = 0.0f64;
        for i in 0..nx {
            if i > 0 {
                heading += if i == 6 {
                    beta
                } else if i % 2 == 0 {
                    10f64.to_radians()
                } else {
                    -10f64.to_radians()
                };
            }
            let [x, z] = profile[i];
            profile.push([x + heading.cos(), z + heading.sin()]);
        }
        let mut positions = Vec::new();
        let mut ends = Vec::new();
        for j in 0..=ny {
            for (i, [x, z]) in profile.iter().enumerate() {
                positions.push([*x, j as f64, *z]);
                ends.push(i == 0 || i == nx);
            }
        }
        let mut triangles = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        let nf = triangles.len();
        let raw = RawMesh {
            positions,
            triangles,
            face_patch: vec![0; nf],
            patch_names: vec!["strip".into()],
            uv: None,
        };
        let (mesh, _) = Mesh::new(raw).expect("valid strip");
        let crease: Vec<u32> = (0..ny)
            .map(|j| {
                let (a, b) = (id(6, j), id(6, j + 1));
                let e = mesh
                    .conn()
                    .edges()
                    .iter()
                    .position(|&e| e == [a.min(b), a.max(b)])
                    .expect("crease edge");
                e as u32
            })
            .collect();
        (mesh, crease, ends)
    }

    #[test]
    fn a_sharp_straight_crease_opens_into_a_bend_and_stays_flattenable() {
        let (mesh, crease, ends) = folded_strip(150f64.to_radians());
        let interior: Vec<bool> = (0..mesh.num_vertices() as u32)
            .map(|v| mesh.conn().is_interior(v))
            .collect();
        // The two end columns hold the strip; the rest may move.
        let movable: Vec<bool> = ends.iter().map(|&e| !e).collect();
        assert!(crate::geometry::max_flattenability(&mesh) < 1e-12);
        let tol = 1e-6;
        let task = Task {
            folds: &crease,
            slivers: &[],
            min_corner: 2f64.to_radians(),
            movable: &movable,
            constrained: &interior,
            tolerance: tol,
        };
        let done = unfold(&mesh, mesh.positions(), &task, &Silent::default()).expect("runs");
        assert_eq!(done.summary.folds_before, 4);
        assert_eq!(done.summary.folds_after, 0, "{:?}", done.summary);
        let out = mesh.with_positions(done.positions.clone()).expect("sound");
        // Independent checks on the output itself.
        assert_eq!(crate::geometry::fold_edges(&out).len(), 0);
        let theta = crate::geometry::angle_sums(&out);
        for v in 0..mesh.num_vertices() {
            if interior[v] {
                assert!(
                    (TAU - theta[v]).abs() <= 0.5 * tol,
                    "vertex {v}: {}",
                    theta[v]
                );
            }
            if !movable[v] {
                assert_eq!(
                    out.positions()[v],
                    mesh.positions()[v],
                    "fixed vertex {v} moved"
                );
            }
        }
        assert!(crate::geometry::smallest_corner(&out) >= SLIVER_DEGREES.to_radians());
    }

    #[test]
    fn far_apart_folds_opened_at_once_give_what_one_after_another_gives() {
        // Two copies of the folded strip (separate components, so their folds are far apart),
        // their creases listed alternately: the first two seeds make one batch.
        let (strip, crease, ends) = folded_strip(150f64.to_radians());
        let n = strip.num_vertices() as u32;
        let mut positions = strip.positions().to_vec();
        positions.extend_from_slice(strip.positions());
        let mut triangles = strip.triangles().to_vec();
        triangles.extend(strip.triangles().iter().map(|t| t.map(|v| v + n)));
        let nf = triangles.len();
        let raw = RawMesh {
            positions,
            triangles,
            face_patch: vec![0; nf],
            patch_names: vec!["strips".into()],
            uv: None,
        };
        let (mesh, _) = Mesh::new(raw).expect("valid strips");
        let edge = |a: u32, b: u32| {
            mesh.conn()
                .edges()
                .iter()
                .position(|&e| e == [a.min(b), a.max(b)])
                .expect("crease edge") as u32
        };
        let folds: Vec<u32> = crease
            .iter()
            .flat_map(|&e| {
                let [a, b] = strip.conn().edges()[e as usize];
                [edge(a, b), edge(a + n, b + n)]
            })
            .collect();
        let movable: Vec<bool> = ends.iter().chain(&ends).map(|&e| !e).collect();
        let interior: Vec<bool> = (0..mesh.num_vertices() as u32)
            .map(|v| mesh.conn().is_interior(v))
            .collect();
        let task = |folds| Task {
            folds,
            slivers: &[],
            min_corner: 2f64.to_radians(),
            movable: &movable,
            constrained: &interior,
            tolerance: 1e-6,
        };
        let seeds: Vec<Seed> = folds
            .iter()
            .filter_map(|&e| hinge_of(&mesh, e).map(Seed::Fold))
            .collect();
        let mut scratch = Scratch::new(mesh.num_vertices());
        assert_eq!(batch_end(&mesh, &seeds, 0, &mut scratch), 2);
        let at_once =
            unfold(&mesh, mesh.positions(), &task(&folds), &Silent::default()).expect("runs");
        assert_eq!(at_once.summary.folds_before, 8);
        assert_eq!(at_once.summary.folds_after, 0, "{:?}", at_once.summary);
        let mut pos = mesh.positions().to_vec();
        for e in &folds {
            pos = unfold(
                &mesh,
                &pos,
                &task(std::slice::from_ref(e)),
                &Silent::default(),
            )
            .expect("runs")
            .positions;
        }
        assert!(pos != mesh.positions());
        assert_eq!(at_once.positions, pos);
    }

    #[test]
    fn folds_not_listed_are_left_alone() {
        let (mesh, _, _) = folded_strip(150f64.to_radians());
        let all = vec![true; mesh.num_vertices()];
        let task = Task {
            folds: &[],
            slivers: &[],
            min_corner: 2f64.to_radians(),
            movable: &all,
            constrained: &all,
            tolerance: 1e-6,
        };
        let done = unfold(&mesh, mesh.positions(), &task, &Silent::default()).expect("runs");
        assert_eq!(done.positions, mesh.positions());
        assert_eq!(done.summary.folds_after, 4);
        assert_eq!(done.summary.tried, 0);
    }

    #[test]
    fn a_sliver_slid_along_a_ruling_opens_up_and_stays_flattenable() {
        // No crease; vertex (3, 2) slid up its ruling to 0.03 below (3, 3): an isometry of
        // the development, so θ stays 2π, and four faces get corners far below 2°.
        let (mut mesh, _, ends) = folded_strip(10f64.to_radians());
        let v = 2 * 13 + 3;
        let mut p = mesh.positions().to_vec();
        p[v][1] += 0.97;
        mesh = mesh.with_positions(p).expect("sound");
        assert!(crate::geometry::max_flattenability(&mesh) < 1e-12);
        let min_corner = 2f64.to_radians();
        let slivers: Vec<u32> = (0..mesh.num_faces() as u32)
            .filter(|&f| smallest_of(&mesh, mesh.positions(), f) < min_corner)
            .collect();
        assert!(slivers.len() >= 2, "{slivers:?}");
        let interior: Vec<bool> = (0..mesh.num_vertices() as u32)
            .map(|v| mesh.conn().is_interior(v))
            .collect();
        let movable: Vec<bool> = ends.iter().map(|&e| !e).collect();
        let tol = 1e-6;
        let task = Task {
            folds: &[],
            slivers: &slivers,
            min_corner,
            movable: &movable,
            constrained: &interior,
            tolerance: tol,
        };
        let done = unfold(&mesh, mesh.positions(), &task, &Silent::default()).expect("runs");
        let out = mesh.with_positions(done.positions.clone()).expect("sound");
        assert_eq!(done.summary.slivers_before, slivers.len());
        assert_eq!(done.summary.slivers_after, 0, "{:?}", done.summary);
        assert!(crate::geometry::smallest_corner(&out) >= min_corner);
        assert_eq!(crate::geometry::fold_edges(&out).len(), 0);
        assert!(crate::geometry::max_flattenability(&out) <= 0.5 * tol);
    }
}
