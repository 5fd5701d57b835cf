//! Step 3 (optional): LSE denoising of the chart boundaries (wang-lpfb Sec. 2 step 3). Each
//! face takes its chart's normal n_f (normalised Σ |T| n_T over the chart, recomputed before
//! every sweep: the faces next to a noisy boundary tilt the first mean), and every vertex
//! where two or more charts meet minimises E(v_i) = Σ_{j ∈ star(i)} Σ_{f ∈ F_ij} (n_f·(v_i −
//! v_j))². The sum runs over the faces f around v_i and the two other corners j of each, so
//! E's Hessian is 2M with M = Σ_f 2 n_f n_fᵀ.
//!
//! The paper's update (Taubin's, v ← v + λ Σ n_f n_fᵀ (v_j − v_i)) leaves λ and the
//! iteration count open (paper-notes D.3); here each vertex jumps to its exact minimiser,
//! Δv = M⁺ Σ n_f n_fᵀ (v_j − v_i), eigenvalues of M below 1e-2·trace M dropped: a vertex
//! between two charts lands on the line where their planes through its neighbours meet, a
//! three-chart corner on their common point, and nothing drifts along the boundary. (The
//! 1e-6 of paper-notes D.3 let two charts whose planes meet at a few degrees, two charts of
//! one side of a noisy box, throw a vertex far along their near-parallel intersection: on a
//! box with noisy boundaries 238 of those moves turned faces over and were refused, and the
//! noise went down by a third only. An eigenvalue of 1e-2·trace is planes ≈ 11° apart.)
//! Gauss–Seidel sweeps in vertex order until the largest move is below 1e-4 of the mean edge
//! length, or 20 sweeps. A move that would make a face degenerate or turn it over is skipped.
//! Only chart-boundary vertices move, so this changes the user's geometry: off by default.

use crate::geometry;
use crate::mesh::{cross, sub, Mesh};

/// What denoising did.
#[derive(Debug, Clone)]
pub struct Denoised {
    /// The new positions (every vertex; only chart-boundary vertices differ).
    pub positions: Vec<[f64; 3]>,
    /// Chart-boundary vertices (those allowed to move).
    pub candidates: usize,
    /// Largest distance a vertex moved from the input.
    pub max_displacement: f64,
    /// Sweeps run.
    pub sweeps: usize,
    /// Moves skipped because a face would degenerate or turn over.
    pub refused: usize,
}

/// Chart normals: normalised Σ |T| n_T over each chart.
pub fn chart_normals(
    tris: &[[u32; 3]],
    pos: &[[f64; 3]],
    labels: &[u32],
    k: usize,
) -> Vec<[f64; 3]> {
    let mut sum = vec![[0.0f64; 3]; k];
    for (t, &l) in tris.iter().zip(labels) {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        // |T| n_T = ½ (b − a) × (c − a)
        let n = cross(sub(b, a), sub(c, a));
        for d in 0..3 {
            sum[l as usize][d] += 0.5 * n[d];
        }
    }
    sum.into_iter().map(geometry::normalize).collect()
}

/// Denoise the chart boundaries of `mesh` (charts `labels`, 0..k).
pub fn run(mesh: &Mesh, labels: &[u32], k: usize) -> Denoised {
    let conn = mesh.conn();
    let tris = mesh.triangles();
    let nv = mesh.num_vertices();
    let mut pos = mesh.positions().to_vec();
    let movable: Vec<u32> = (0..nv as u32)
        .filter(|&v| {
            let mut first = None;
            conn.fan_of(v).iter().any(|&h| {
                let l = labels[(h / 3) as usize];
                *first.get_or_insert(l) != l
            })
        })
        .collect();
    let tol = 1e-4 * geometry::mean_edge_length(mesh);
    let mut out = Denoised {
        positions: Vec::new(),
        candidates: movable.len(),
        max_displacement: 0.0,
        sweeps: 0,
        refused: 0,
    };
    for _ in 0..20 {
        out.sweeps += 1;
        let chart_n = chart_normals(tris, &pos, labels, k);
        let mut largest: f64 = 0.0;
        for &v in &movable {
            let p = pos[v as usize];
            let mut m = [[0.0f64; 3]; 3];
            let mut r = [0.0f64; 3];
            for &h in conn.fan_of(v) {
                let f = (h / 3) as usize;
                let n = chart_n[labels[f] as usize];
                let t = tris[f];
                for &j in t.iter().filter(|&&j| j != v) {
                    let d: [f64; 3] = std::array::from_fn(|c| pos[j as usize][c] - p[c]);
                    let nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
                    for a in 0..3 {
                        r[a] += n[a] * nd;
                        for b in 0..3 {
                            m[a][b] += n[a] * n[b];
                        }
                    }
                }
            }
            let step = pseudo_solve(m, r);
            let q: [f64; 3] = std::array::from_fn(|c| p[c] + step[c]);
            let len = (step[0] * step[0] + step[1] * step[1] + step[2] * step[2]).sqrt();
            if len == 0.0 || !len.is_finite() {
                continue;
            }
            if !keeps_faces(mesh, &pos, v, q) {
                out.refused += 1;
                continue;
            }
            pos[v as usize] = q;
            largest = largest.max(len);
        }
        if largest < tol {
            break;
        }
    }
    out.max_displacement = movable
        .iter()
        .map(|&v| {
            let (a, b) = (pos[v as usize], mesh.positions()[v as usize]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max);
    out.positions = pos;
    out
}

/// Whether moving `v` to `q` leaves every face around it non-degenerate and facing the way
/// it faced in the input.
fn keeps_faces(mesh: &Mesh, pos: &[[f64; 3]], v: u32, q: [f64; 3]) -> bool {
    let tris = mesh.triangles();
    mesh.conn().fan_of(v).iter().all(|&h| {
        let f = (h / 3) as usize;
        let t = tris[f];
        let at = |w: u32| if w == v { q } else { pos[w as usize] };
        let [a, b, c] = t.map(at);
        if crate::mesh::is_degenerate_triangle(a, b, c) {
            return false;
        }
        let [a0, b0, c0] = t.map(|w| mesh.positions()[w as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let n0 = cross(sub(b0, a0), sub(c0, a0));
        n[0] * n0[0] + n[1] * n0[1] + n[2] * n0[2] > 0.0
    })
}

/// M⁺ r for a symmetric positive semi-definite 3×3 M, eigenvalues below 1e-2·trace M
/// dropped (cyclic Jacobi rotations).
pub fn pseudo_solve(mut m: [[f64; 3]; 3], r: [f64; 3]) -> [f64; 3] {
    let trace = m[0][0] + m[1][1] + m[2][2];
    if trace.is_nan() || trace <= 0.0 {
        return [0.0; 3];
    }
    let mut vecs = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = m[0][1].abs() + m[0][2].abs() + m[1][2].abs();
        if off <= 1e-15 * trace {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if m[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // M ← Jᵀ M J with the rotation J in the (p, q) plane; V ← V J.
            for row in m.iter_mut() {
                let (a, b) = (row[p], row[q]);
                row[p] = c * a - s * b;
                row[q] = s * a + c * b;
            }
            let (rp, rq) = (m[p], m[q]);
            m[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            m[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in vecs.iter_mut() {
                let (a, b) = (row[p], row[q]);
                row[p] = c * a - s * b;
                row[q] = s * a + c * b;
            }
        }
    }
    let mut x = [0.0; 3];
    for e in 0..3 {
        let lambda = m[e][e];
        if lambda <= 1e-2 * trace {
            continue;
        }
        let u = [vecs[0][e], vecs[1][e], vecs[2][e]];
        let ur = u[0] * r[0] + u[1] * r[1] + u[2] * r[2];
        for c in 0..3 {
            x[c] += u[c] * ur / lambda;
        }
    }
    x
}
