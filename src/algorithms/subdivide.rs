//! The `subdivide` job: variational subdivision of FL meshes (wang-flattenable-laplacian-meshes,
//! Sec. 3). Each level
//! 1. splits every edge longer than 0.5 L̄ (L̄ the mean edge length of the level's input), so
//!    that a triangle becomes 1, 2, 3 or 4 triangles;
//! 2. places each new vertex: on a boundary or seam edge at the arc-length middle of the edge's
//!    interpolation curve when the user gave one (the curve is then split in two with the edge,
//!    Fig. 8a), else by the boundary mask of the modified Butterfly scheme (Zorin et al. 1996,
//!    the 4-point rule 9/16, −1/16 over the boundary vertices of the previous level, Fig. 8b);
//!    new inner vertices start at their edge's midpoint and are moved by 10 runs of the
//!    1st-order umbrella operator (Eq. 14, 16) and then 100 runs of the 2nd-order one (Eq. 15,
//!    17), while the previous level's vertices stay where they are;
//! 3. runs `fl-mesh` (Sec. 2) on the level.
//!
//! Vertex numbering only grows: level k's vertices are level k−1's (including any that
//! fl-mesh's √3 refinement added), then the new ones; input vertex i stays vertex i.
//!
//! The summary ([`Summary`]) has `levels` (per level vertices, faces, split edges, measured
//! ϖ_max, converged, iterations), `iterations` and `refined` over all levels (`refined` ids in
//! the numbering of the level they were refined in, which keeps all earlier ids), the last
//! level's `stop_reason`, `stuck_vertices` and `history`, and `hausdorff_to_input` against the
//! job's input. fl-mesh is called through [`fl_mesh::solve`], typed.
//!
//! Where the paper is silent: a face with two split edges is cut along the shorter diagonal of
//! the quadrilateral left over; the umbrella runs are Jacobi sweeps (every vertex updated from
//! the previous sweep's positions), so the result does not depend on vertex order; an edge on a
//! seam between patches is a boundary edge of each patch, so its new vertex is placed like a
//! boundary vertex (along the first patch's boundary loop) and stays fixed in fl-mesh.

use super::{fl_mesh, AlgoError, Control, Outcome, Progress};
use crate::geometry;
use crate::mesh::{Mesh, RawMesh, VertexKind, NONE};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// A user-given interpolation curve of one boundary edge of the input (Fig. 8a).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    /// The edge's two input vertex indices; the polyline runs from the first to the second.
    pub edge: [u32; 2],
    /// Polyline points, the first at `edge[0]` and the last at `edge[1]`.
    pub points: Vec<[f64; 3]>,
}

/// Parameters of `subdivide`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Subdivision levels (each: split, fair, fl-mesh).
    pub levels: usize,
    /// Interpolation curves of boundary edges (input numbering).
    pub curves: Vec<Curve>,
    /// Edges longer than this times the mean edge length are split (the paper's 0.5).
    pub split_ratio: f64,
    /// Runs of the 1st-order umbrella operator, Eq. 16 (the paper's 10).
    pub first_order_runs: usize,
    /// Runs of the 2nd-order umbrella operator, Eq. 17 (the paper's 100).
    pub second_order_runs: usize,
    /// Run fl-mesh on each level (step 3); `false` gives the plain variational subdivision.
    pub flatten_levels: bool,
    /// Parameters of the fl-mesh run on each level.
    pub fl_mesh: fl_mesh::Params,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            levels: 1,
            curves: Vec::new(),
            split_ratio: 0.5,
            first_order_runs: 10,
            second_order_runs: 100,
            flatten_levels: true,
            fl_mesh: fl_mesh::Params::default(),
        }
    }
}

fn bad(key: impl Into<String>, message: String) -> AlgoError {
    AlgoError::InvalidParam {
        key: key.into(),
        message,
    }
}

impl Params {
    /// Range checks that need no mesh (curves are checked against the mesh by [`run`]).
    pub fn check(&self) -> Result<(), AlgoError> {
        if self.levels == 0 || self.levels > 6 {
            return Err(bad(
                "levels",
                format!(
                    "must be in 1..=6 (each level multiplies the faces by up to 4), got {}",
                    self.levels
                ),
            ));
        }
        if !(self.split_ratio.is_finite() && self.split_ratio > 0.0) {
            return Err(bad(
                "split_ratio",
                format!("must be finite and > 0, got {}", self.split_ratio),
            ));
        }
        if self.first_order_runs > 10_000 || self.second_order_runs > 10_000 {
            return Err(bad(
                if self.first_order_runs > 10_000 {
                    "first_order_runs"
                } else {
                    "second_order_runs"
                },
                "must be at most 10000".into(),
            ));
        }
        for (i, c) in self.curves.iter().enumerate() {
            if c.points.len() < 2 {
                return Err(bad(
                    format!("curves[{i}].points"),
                    format!("needs at least 2 points, got {}", c.points.len()),
                ));
            }
            if let Some(j) = c
                .points
                .iter()
                .position(|p| p.iter().any(|x| !x.is_finite()))
            {
                return Err(bad(
                    format!("curves[{i}].points[{j}]"),
                    "is not a finite point".into(),
                ));
            }
        }
        self.fl_mesh.check().map_err(|e| match e {
            AlgoError::InvalidParam { key, message } => AlgoError::InvalidParam {
                key: format!("fl_mesh.{key}"),
                message,
            },
            other => other,
        })
    }
}

/// One level's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LevelReport {
    /// 1 for the first subdivision of the input.
    pub level: usize,
    /// Vertices and faces of the level's output.
    pub vertices: usize,
    /// Faces of the level's output.
    pub faces: usize,
    /// Edges split at this level.
    pub split_edges: usize,
    /// ϖ_max of the level's output, measured by `geometry`.
    pub max_flattenability: f64,
    /// fl-mesh converged on this level (true when fl-mesh is off and ϖ_max is within its
    /// tolerance).
    pub converged: bool,
    /// fl-mesh iterations on this level.
    pub iterations: usize,
    /// Vertices fl-mesh refined on this level.
    pub refined: Vec<u32>,
}

/// Undirected edge key.
fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn lerp(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [
        a[0] + t * (b[0] - a[0]),
        a[1] + t * (b[1] - a[1]),
        a[2] + t * (b[2] - a[2]),
    ]
}

/// Split a polyline at its arc-length middle: (middle point, first half, second half).
pub fn split_polyline(points: &[[f64; 3]]) -> ([f64; 3], Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let total: f64 = points.windows(2).map(|w| dist(w[0], w[1])).sum();
    let half = 0.5 * total;
    let mut run = 0.0;
    for i in 0..points.len() - 1 {
        let l = dist(points[i], points[i + 1]);
        if run + l >= half && l > 0.0 {
            let t = ((half - run) / l).clamp(0.0, 1.0);
            let m = lerp(points[i], points[i + 1], t);
            let mut first = points[..=i].to_vec();
            first.push(m);
            let mut second = vec![m];
            second.extend_from_slice(&points[i + 1..]);
            return (m, first, second);
        }
        run += l;
    }
    // Zero length: every point coincides.
    let m = points[0];
    (m, vec![m, m], vec![m, m])
}

/// Curves keyed by undirected edge, each oriented from the smaller vertex index to the larger.
type Curves = HashMap<(u32, u32), Vec<[f64; 3]>>;

/// Check the user's curves against the input mesh and key them by edge.
fn curves_of(mesh: &Mesh, curves: &[Curve]) -> Result<Curves, AlgoError> {
    let conn = mesh.conn();
    let fp = mesh.face_patch();
    let mut boundary: HashMap<(u32, u32), ()> = HashMap::new();
    for (e, f) in conn.edges().iter().zip(conn.edge_faces()) {
        if f[1] == NONE || fp[f[0] as usize] != fp[f[1] as usize] {
            boundary.insert(key(e[0], e[1]), ());
        }
    }
    let (lo, hi) = mesh.bbox();
    let tol = 1e-6 * dist(lo, hi).max(f64::MIN_POSITIVE);
    let mut out = Curves::new();
    for (i, c) in curves.iter().enumerate() {
        let [a, b] = c.edge;
        let n = mesh.num_vertices() as u32;
        if a >= n || b >= n || a == b {
            return Err(bad(
                format!("curves[{i}].edge"),
                format!("[{a}, {b}] is not an edge of the mesh ({n} vertices)"),
            ));
        }
        let k = key(a, b);
        if !boundary.contains_key(&k) {
            return Err(bad(
                format!("curves[{i}].edge"),
                format!("[{a}, {b}] is not a boundary or seam edge of the mesh"),
            ));
        }
        if out.contains_key(&k) {
            return Err(bad(
                format!("curves[{i}].edge"),
                format!("[{a}, {b}] has a curve already"),
            ));
        }
        let mut pts = c.points.clone();
        let (pa, pb) = (mesh.position(a), mesh.position(b));
        let (first, last) = (pts[0], pts[pts.len() - 1]);
        if dist(first, pa) > tol || dist(last, pb) > tol {
            return Err(bad(
                format!("curves[{i}].points"),
                format!(
                    "must run from vertex {a} to vertex {b}: the ends are {:.3e} and {:.3e} away \
                     (tolerance {tol:.1e})",
                    dist(first, pa),
                    dist(last, pb)
                ),
            ));
        }
        // The curve interpolates the vertices exactly.
        let m = pts.len();
        pts[0] = pa;
        pts[m - 1] = pb;
        if a > b {
            pts.reverse();
        }
        out.insert(k, pts);
    }
    Ok(out)
}

/// Reports progress with the level in the stage name.
struct LevelControl<'a> {
    inner: &'a dyn Control,
    level: usize,
    levels: usize,
}

impl Control for LevelControl<'_> {
    fn progress(&self, p: &Progress) {
        self.inner.progress(&Progress {
            stage: format!("level {}/{} {}", self.level, self.levels, p.stage),
            ..p.clone()
        });
    }
    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
    fn cancelled_before(&self, seconds: f64) -> bool {
        self.inner.cancelled_before(seconds)
    }
}

/// What `subdivide` reports.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Per level.
    pub levels: Vec<LevelReport>,
    /// The last level converged.
    pub converged: bool,
    /// fl-mesh iterations over all levels.
    pub iterations: usize,
    /// Vertices fl-mesh refined, over all levels (ids in the numbering of their level).
    pub refined: Vec<u32>,
    /// ϖ_max of the output, measured by `geometry`.
    pub max_flattenability: f64,
    /// Why the last level's fl-mesh run ended (absent when fl-mesh is off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
    /// Interior vertices of the output still above fl-mesh's tolerance.
    pub stuck_vertices: Vec<u32>,
    /// The last level's fl-mesh iteration history.
    pub history: Vec<fl_mesh::HistoryEntry>,
    /// Hausdorff distance from the output to the job's input.
    pub hausdorff_to_input: super::Distance,
}

/// Run `subdivide`.
pub fn run(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    let mut curves = curves_of(mesh, &params.curves)?;
    let mut current = mesh.clone();
    let mut levels = Vec::with_capacity(params.levels);
    let mut summary = Summary::default();
    for level in 1..=params.levels {
        let ctl = LevelControl {
            inner: control,
            level,
            levels: params.levels,
        };
        let (split, split_edges) = subdivide_level(&current, &mut curves, params, &ctl)?;
        let (out, fl) = if params.flatten_levels {
            // A level models the finer surface of its control mesh: the developable cone
            // would replace it by another shape, so never, whatever `fl_mesh` says.
            // Nor are its faces changed: the next level subdivides this level's connectivity.
            let fl = fl_mesh::Params {
                cone_start: fl_mesh::ConeStart::Never,
                remesh: false,
                ..params.fl_mesh.clone()
            };
            let (m, r) = fl_mesh::solve(&split, &fl, &ctl)?;
            (m, Some(r))
        } else {
            (split, None)
        };
        let theta = geometry::angle_sums(&out);
        let w = geometry::flattenability(&out, &theta)
            .into_iter()
            .fold(0.0, f64::max);
        let report = LevelReport {
            level,
            vertices: out.num_vertices(),
            faces: out.num_faces(),
            split_edges,
            max_flattenability: w,
            converged: fl
                .as_ref()
                .map_or(w <= params.fl_mesh.tolerance, |r| r.converged),
            iterations: fl.as_ref().map_or(0, |r| r.iterations),
            refined: fl.as_ref().map(|r| r.refined.clone()).unwrap_or_default(),
        };
        control.progress(&Progress {
            stage: format!("level {level}/{} done", params.levels),
            iteration: level,
            max_flattenability: Some(w),
            step_norm: None,
        });
        summary.iterations += report.iterations;
        summary.refined.extend_from_slice(&report.refined);
        summary.converged = report.converged;
        summary.max_flattenability = w;
        summary.levels.push(report);
        if let Some(r) = fl {
            summary.stop_reason = Some(r.stop_reason);
            summary.stuck_vertices = r.stuck_vertices;
            summary.history = r.history;
        }
        levels.push(out.clone());
        current = out;
    }
    summary.hausdorff_to_input = super::Distance::hausdorff_reported(&current, mesh, control);
    Ok(Outcome {
        mesh: Some(current),
        patterns: None,
        summary,
        levels,
    })
}

/// Steps 1 and 2 of one level: the split mesh with its new vertices placed. Returns it and the
/// number of edges split. `curves` are re-keyed to the new edges.
pub fn subdivide_level(
    mesh: &Mesh,
    curves: &mut Curves,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, usize), AlgoError> {
    let conn = mesh.conn();
    let pos = mesh.positions();
    let tris = mesh.triangles();
    let fp = mesh.face_patch();
    let edges = conn.edges();
    if edges.is_empty() {
        return Err(AlgoError::Input("the mesh has no edges to split".into()));
    }
    let mean = edges
        .iter()
        .map(|e| dist(pos[e[0] as usize], pos[e[1] as usize]))
        .sum::<f64>()
        / edges.len() as f64;
    let limit = params.split_ratio * mean;

    // Boundary neighbours along each patch's boundary loops (previous level, fixed): for the
    // directed loop edge (a, b), the vertex before a and the one after b.
    let mut along: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for patch in conn.patches() {
        for lp in &patch.boundary_loops {
            let n = lp.len();
            for i in 0..n {
                let (p0, a, b, p3) = (lp[(i + n - 1) % n], lp[i], lp[(i + 1) % n], lp[(i + 2) % n]);
                along
                    .entry(key(a, b))
                    .or_insert(if a < b { (p0, p3) } else { (p3, p0) });
            }
        }
    }

    // Step 1: new vertex per long edge.
    let mut positions = pos.to_vec();
    let mut new_of: HashMap<(u32, u32), u32> = HashMap::new();
    let mut movable = vec![false; pos.len()];
    for (e, f) in edges.iter().zip(conn.edge_faces()) {
        let (a, b) = (e[0], e[1]);
        let (pa, pb) = (pos[a as usize], pos[b as usize]);
        if dist(pa, pb) <= limit {
            continue;
        }
        let v = positions.len() as u32;
        let k = key(a, b);
        let on_boundary = f[1] == NONE || fp[f[0] as usize] != fp[f[1] as usize];
        let p = if let Some(c) = curves.remove(&k) {
            // Fig. 8a: the middle of the curve; each half goes with its sub-edge.
            let (m, first, second) = split_polyline(&c);
            curves.insert(key(k.0, v), first);
            curves.insert(key(v, k.1), second);
            m
        } else if on_boundary {
            match along.get(&k) {
                // Fig. 8b: modified Butterfly boundary mask, k.0 → k.1 with p0 before k.0 and
                // p3 after k.1.
                Some(&(p0, p3)) => {
                    let (q0, q3) = (pos[p0 as usize], pos[p3 as usize]);
                    std::array::from_fn(|i| {
                        9.0 / 16.0 * (pa[i] + pb[i]) - 1.0 / 16.0 * (q0[i] + q3[i])
                    })
                }
                None => lerp(pa, pb, 0.5),
            }
        } else {
            movable.push(true);
            positions.push(lerp(pa, pb, 0.5));
            new_of.insert(k, v);
            continue;
        };
        movable.push(false);
        positions.push(p);
        new_of.insert(k, v);
    }
    let split_edges = new_of.len();

    // Faces: 1, 2, 3 or 4 children, orientation kept.
    let mut triangles = Vec::with_capacity(tris.len() * 4);
    let mut face_patch = Vec::with_capacity(tris.len() * 4);
    for (t, &p) in tris.iter().zip(fp) {
        let m: [Option<u32>; 3] =
            std::array::from_fn(|i| new_of.get(&key(t[i], t[(i + 1) % 3])).copied());
        let count = m.iter().filter(|x| x.is_some()).count();
        let before = triangles.len();
        match count {
            0 => triangles.push(*t),
            1 => {
                // Rotate so that edge (t0, t1) is split.
                let i = (0..3).find(|&i| m[i].is_some()).unwrap_or(0);
                let (a, b, c) = (t[i], t[(i + 1) % 3], t[(i + 2) % 3]);
                let mab = m[i].unwrap_or(a);
                triangles.push([a, mab, c]);
                triangles.push([mab, b, c]);
            }
            2 => {
                // Rotate so that edge (t2, t0) is the one not split.
                let i = (0..3).find(|&i| m[(i + 2) % 3].is_none()).unwrap_or(0);
                let (a, b, c) = (t[i], t[(i + 1) % 3], t[(i + 2) % 3]);
                let mab = m[i].unwrap_or(a);
                let mbc = m[(i + 1) % 3].unwrap_or(b);
                triangles.push([mab, b, mbc]);
                // Quadrilateral a, mab, mbc, c: cut along the shorter diagonal.
                let d1 = dist(positions[a as usize], positions[mbc as usize]);
                let d2 = dist(positions[mab as usize], positions[c as usize]);
                if d1 <= d2 {
                    triangles.push([a, mab, mbc]);
                    triangles.push([a, mbc, c]);
                } else {
                    triangles.push([a, mab, c]);
                    triangles.push([mab, mbc, c]);
                }
            }
            _ => {
                let (a, b, c) = (t[0], t[1], t[2]);
                let (mab, mbc, mca) = (m[0].unwrap_or(a), m[1].unwrap_or(b), m[2].unwrap_or(c));
                triangles.push([a, mab, mca]);
                triangles.push([mab, b, mbc]);
                triangles.push([mca, mbc, c]);
                triangles.push([mab, mbc, mca]);
            }
        }
        face_patch.extend(std::iter::repeat_n(p, triangles.len() - before));
    }
    let raw = RawMesh {
        positions,
        triangles,
        face_patch,
        patch_names: mesh.patch_names().to_vec(),
        uv: None,
    };
    let (split, _) =
        Mesh::new(raw).map_err(|e| AlgoError::Input(format!("subdivision failed: {e}")))?;

    // Step 2: move the new inner vertices (Eq. 14–17).
    let moved = umbrella(&split, &movable, params, control)?;
    let out = split
        .with_positions(moved)
        .map_err(|e| AlgoError::Input(format!("fairing failed: {e}")))?;
    Ok((out, split_edges))
}

/// 1st-order (Eq. 16) then 2nd-order (Eq. 17) umbrella runs on the `movable` vertices, Jacobi
/// style. N(v) is the one-ring of v in the split mesh.
fn umbrella(
    mesh: &Mesh,
    movable: &[bool],
    params: &Params,
    control: &dyn Control,
) -> Result<Vec<[f64; 3]>, AlgoError> {
    let conn = mesh.conn();
    let n = mesh.num_vertices();
    let mut p = mesh.positions().to_vec();
    let mut u = vec![[0.0; 3]; n];
    let movers: Vec<u32> = (0..n as u32)
        .filter(|&v| movable[v as usize] && conn.kind(v) == VertexKind::Interior)
        .collect();
    if movers.is_empty() {
        return Ok(p);
    }
    // Eq. 14 for every vertex with neighbours.
    let umbrella_vec = |p: &[[f64; 3]], u: &mut [[f64; 3]]| {
        for v in 0..n {
            let ring = conn.ring_of(v as u32);
            if ring.is_empty() {
                u[v] = [0.0; 3];
                continue;
            }
            let mut s = [0.0; 3];
            for &j in ring {
                for k in 0..3 {
                    s[k] += p[j as usize][k];
                }
            }
            let inv = 1.0 / ring.len() as f64;
            u[v] = std::array::from_fn(|k| s[k] * inv - p[v][k]);
        }
    };
    // ν of Eq. 17 per mover (connectivity only).
    let nu: Vec<f64> = movers
        .iter()
        .map(|&v| {
            let ring = conn.ring_of(v);
            1.0 + ring
                .iter()
                .map(|&j| 1.0 / conn.ring_of(j).len().max(1) as f64)
                .sum::<f64>()
                / ring.len() as f64
        })
        .collect();
    let total = params.first_order_runs + params.second_order_runs;
    for run in 0..total {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        umbrella_vec(&p, &mut u);
        if run < params.first_order_runs {
            // Eq. 16: v ← v + u(v).
            for &v in &movers {
                let v = v as usize;
                for k in 0..3 {
                    p[v][k] += u[v][k];
                }
            }
        } else {
            // Eq. 15 then Eq. 17: v ← v − u²(v)/ν.
            for (i, &v) in movers.iter().enumerate() {
                let ring = conn.ring_of(v);
                let mut s = [0.0; 3];
                for &j in ring {
                    for k in 0..3 {
                        s[k] += u[j as usize][k];
                    }
                }
                let inv = 1.0 / ring.len() as f64;
                let u2: [f64; 3] = std::array::from_fn(|k| s[k] * inv - u[v as usize][k]);
                // u is from the previous sweep for every vertex, so updating p in place keeps
                // the sweep a Jacobi one.
                for k in 0..3 {
                    p[v as usize][k] -= u2[k] / nu[i];
                }
            }
        }
        if run % 10 == 9 {
            control.progress(&Progress {
                stage: if run < params.first_order_runs {
                    "umbrella 1st order".into()
                } else {
                    "umbrella 2nd order".into()
                },
                iteration: run + 1,
                max_flattenability: None,
                step_norm: None,
            });
        }
    }
    if p.iter().any(|q| q.iter().any(|x| !x.is_finite())) {
        return Err(AlgoError::Input(
            "umbrella fairing produced a non-finite position".into(),
        ));
    }
    Ok(p)
}
