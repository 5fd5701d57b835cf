//! Pure measures on a [`Mesh`]: corner angles, angle sums θ, flattenability ϖ, D[M], G[M],
//! discrete Gaussian curvature, areas, normals, and the analytic gradients of θ.
//!
//! Conventions (wang-tang paper, Eq. 2 and 5): only a vertex whose closed fan lies in one patch
//! is interior; everywhere else g = 0 and ϖ = 0. A vertex counts as developable for D[M] when
//! ϖ ≤ [`DEVELOPABLE_TOLERANCE`].

use crate::mesh::{cross, dot, sub, Mesh, VertexKind};
use std::f64::consts::{PI, TAU};

/// ϖ at or below this many radians counts as a developable point in D[M] (Eq. 2). It is the
/// tolerance the FL-mesh solver drives ϖ_max to, and far above the ~1e-13 rad noise of summing
/// a dozen f64 angles.
pub const DEVELOPABLE_TOLERANCE: f64 = 1e-6;

/// The angle at `a` in triangle (a, b, c), in [0, π]. `atan2(|e1×e2|, e1·e2)` keeps full
/// relative precision near 0 and π, where `acos` of a dot product loses half the digits.
#[inline]
pub fn corner_angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let n = cross(e1, e2);
    dot(n, n).sqrt().atan2(dot(e1, e2))
}

/// The three corner angles of every face.
pub fn corner_angles(mesh: &Mesh) -> Vec<[f64; 3]> {
    (0..mesh.num_faces())
        .map(|f| {
            let [a, b, c] = mesh.face_positions(f);
            [
                corner_angle(a, b, c),
                corner_angle(b, c, a),
                corner_angle(c, a, b),
            ]
        })
        .collect()
}

/// θ(v): the sum of the corner angles at each vertex over all its faces (0 when unreferenced).
pub fn angle_sums(mesh: &Mesh) -> Vec<f64> {
    let mut theta = vec![0.0; mesh.num_vertices()];
    angle_sums_into(mesh, mesh.positions(), &mut theta);
    theta
}

/// [`angle_sums`] with the mesh's connectivity and the positions `pos`, into `theta`
/// (overwritten; an optimiser's iterate, without allocating).
pub fn angle_sums_into(mesh: &Mesh, pos: &[[f64; 3]], theta: &mut [f64]) {
    theta.fill(0.0);
    for t in mesh.triangles() {
        let [a, b, c] = t.map(|v| v as usize);
        theta[a] += corner_angle(pos[a], pos[b], pos[c]);
        theta[b] += corner_angle(pos[b], pos[c], pos[a]);
        theta[c] += corner_angle(pos[c], pos[a], pos[b]);
    }
}

/// θ(v) for one vertex, from its fan.
pub fn angle_sum_at(mesh: &Mesh, v: u32) -> f64 {
    angle_sum_with(mesh, mesh.positions(), v)
}

/// θ(v) with the mesh's connectivity and the positions `pos` (an optimiser's iterate).
pub fn angle_sum_with(mesh: &Mesh, pos: &[[f64; 3]], v: u32) -> f64 {
    let p = pos[v as usize];
    mesh.conn()
        .fan_of(v)
        .iter()
        .map(|&h| {
            let t = mesh.triangles()[h as usize / 3];
            let k = h as usize % 3;
            corner_angle(
                p,
                pos[t[(k + 1) % 3] as usize],
                pos[t[(k + 2) % 3] as usize],
            )
        })
        .sum()
}

/// ϖ(v) = |2π − θ(v)| at interior vertices, 0 elsewhere (Eq. 5: g = 0 on the boundary).
pub fn flattenability(mesh: &Mesh, theta: &[f64]) -> Vec<f64> {
    mesh.conn()
        .kinds()
        .iter()
        .zip(theta)
        .map(|(k, &t)| {
            if *k == VertexKind::Interior {
                (TAU - t).abs()
            } else {
                0.0
            }
        })
        .collect()
}

/// ϖ_max: the largest [`flattenability`] of the mesh (0 without interior vertices).
pub fn max_flattenability(mesh: &Mesh) -> f64 {
    let theta = angle_sums(mesh);
    flattenability(mesh, &theta).into_iter().fold(0.0, f64::max)
}

/// Area of the triangle a, b, c.
pub fn triangle_area(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let n = cross(sub(b, a), sub(c, a));
    0.5 * dot(n, n).sqrt()
}

/// Area of every face.
pub fn face_areas(mesh: &Mesh) -> Vec<f64> {
    (0..mesh.num_faces())
        .map(|f| {
            let [a, b, c] = mesh.face_positions(f);
            triangle_area(a, b, c)
        })
        .collect()
}

/// A_q = ⅓ Σ A_j over the faces at each vertex (Eq. 1–2); these sum to the mesh area.
pub fn vertex_areas(mesh: &Mesh, face_area: &[f64]) -> Vec<f64> {
    let mut a = vec![0.0; mesh.num_vertices()];
    for (t, &fa) in mesh.triangles().iter().zip(face_area) {
        for &v in t {
            a[v as usize] += fa / 3.0;
        }
    }
    a
}

/// Discrete Gaussian curvature κ = (2π − θ) / (⅓ Σ A_j) (Eq. 1) at every vertex with a closed
/// fan (interior and seam vertices); `None` on the free boundary and at unreferenced vertices.
pub fn gaussian_curvature(mesh: &Mesh, theta: &[f64], vertex_area: &[f64]) -> Vec<Option<f64>> {
    mesh.conn()
        .kinds()
        .iter()
        .enumerate()
        .map(|(v, k)| match k {
            VertexKind::Interior | VertexKind::Seam => Some((TAU - theta[v]) / vertex_area[v]),
            _ => None,
        })
        .collect()
}

/// D[M] (Eq. 2): the area-weighted share of developable points, boundary vertices counting as
/// developable (θ_sum := 2π there). In [0, 1]; 1 means every interior vertex has
/// ϖ ≤ `tolerance`.
pub fn developability_d(varpi: &[f64], vertex_area: &[f64], tolerance: f64) -> f64 {
    let total: f64 = vertex_area.iter().sum();
    if total <= 0.0 {
        return 1.0;
    }
    let dev: f64 = varpi
        .iter()
        .zip(vertex_area)
        .filter(|(w, _)| **w <= tolerance)
        .map(|(_, a)| a)
        .sum();
    (dev / total).clamp(0.0, 1.0)
}

/// G[M] = Σ g(q)² (Eq. 4–5), g = 2π − θ at interior vertices and 0 elsewhere.
pub fn developability_g(varpi: &[f64]) -> f64 {
    varpi.iter().map(|w| w * w).sum()
}

/// Unit normal of every face (counter-clockwise = front).
pub fn face_normals(mesh: &Mesh) -> Vec<[f64; 3]> {
    (0..mesh.num_faces())
        .map(|f| {
            let [a, b, c] = mesh.face_positions(f);
            normalize(cross(sub(b, a), sub(c, a)))
        })
        .collect()
}

/// Angle-weighted unit vertex normals (independent of how a fan is triangulated); zero at
/// unreferenced vertices.
pub fn vertex_normals(mesh: &Mesh) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0; 3]; mesh.num_vertices()];
    let fnrm = face_normals(mesh);
    for ((t, ang), fnv) in mesh.triangles().iter().zip(corner_angles(mesh)).zip(&fnrm) {
        for k in 0..3 {
            let v = &mut n[t[k] as usize];
            for i in 0..3 {
                v[i] += ang[k] * fnv[i];
            }
        }
    }
    n.into_iter().map(normalize).collect()
}

/// `v / |v|`, or zero for a zero vector (never NaN).
#[inline]
pub fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = dot(v, v).sqrt();
    if l > 0.0 && l.is_finite() {
        [v[0] / l, v[1] / l, v[2] / l]
    } else {
        [0.0; 3]
    }
}

/// Gradient of the corner angle at `a` in triangle (a, b, c) with respect to `b` and to `c`.
/// The angle grows when `b` moves in the plane away from `c`, at rate 1/|ab|; the gradient with
/// respect to `a` is minus their sum. Written with the face normal instead of 1/sin, so it stays
/// accurate for angles near 0 and π.
#[inline]
pub fn corner_angle_gradient(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let n = cross(e1, e2);
    let nn = dot(n, n).sqrt();
    let d1 = nn * dot(e1, e1);
    let d2 = nn * dot(e2, e2);
    let g1 = cross(n, e1);
    let g2 = cross(n, e2);
    (
        [-g1[0] / d1, -g1[1] / d1, -g1[2] / d1],
        [g2[0] / d2, g2[1] / d2, g2[2] / d2],
    )
}

/// Second derivatives of the corner angle α at `a` in triangle (a, b, c), in terms of
/// u = b − a and w = c − a: blocks ∂²α/∂u², ∂²α/∂u∂w and ∂²α/∂w² (the blocks for a follow
/// from ∂/∂a = −∂/∂u − ∂/∂w). With n̂ the face normal and t_u = n̂ × û, t_w = n̂ × ŵ (û and
/// ŵ turned a quarter turn about n̂; t_u points to w's side):
///
/// ```text
/// ∂²α/∂u²  =  (û t_uᵀ + t_u ûᵀ)/|u|² + cot α/|u|² n̂n̂ᵀ      (in plane α = arg w − arg u)
/// ∂²α/∂w²  = −(ŵ t_wᵀ + t_w ŵᵀ)/|w|² + cot α/|w|² n̂n̂ᵀ
/// ∂²α/∂u∂w = −1/(|u||w| sin α) n̂n̂ᵀ                          (out of plane only)
/// ```
///
/// The in-plane and out-of-plane parts decouple (α is even in the out-of-plane components),
/// so with `positive_part_of = Some(y)` it returns the positive semidefinite part of y ∇²α
/// instead, block by block in closed form: the convexified constraint curvature of a
/// Lagrangian. `None` for a degenerate corner.
pub fn corner_angle_hessian(
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
    positive_part_of: Option<f64>,
) -> Option<[[[f64; 3]; 3]; 3]> {
    let u = sub(b, a);
    let w = sub(c, a);
    let (lu, lw) = (dot(u, u).sqrt(), dot(w, w).sqrt());
    let n = cross(u, w);
    let ln = dot(n, n).sqrt();
    if !(lu > 0.0 && lw > 0.0 && ln > 0.0 && ln.is_finite()) {
        return None;
    }
    let uh = u.map(|x| x / lu);
    let wh = w.map(|x| x / lw);
    let nh = n.map(|x| x / ln);
    let tu = cross(nh, uh);
    let tw = cross(nh, wh);
    let sin = ln / (lu * lw);
    let cot = dot(u, w) / ln;
    let outer = |p: [f64; 3], q: [f64; 3], k: f64| {
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = k * p[i] * q[j];
            }
        }
        m
    };
    let add = |m: &mut [[f64; 3]; 3], o: [[f64; 3]; 3]| {
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += o[i][j];
            }
        }
    };
    // Out of plane: [[cot/|u|², −1/(|u||w| sin)], [·, cot/|w|²]] on (n̂·δu, n̂·δw).
    let (p, q, r) = (cot / (lu * lu), -1.0 / (lu * lw * sin), cot / (lw * lw));
    let (mut uu, mut uw, mut ww) = ([[0.0; 3]; 3], [[0.0; 3]; 3], [[0.0; 3]; 3]);
    match positive_part_of {
        None => {
            add(&mut uu, outer(uh, tu, 1.0 / (lu * lu)));
            add(&mut uu, outer(tu, uh, 1.0 / (lu * lu)));
            add(&mut ww, outer(wh, tw, -1.0 / (lw * lw)));
            add(&mut ww, outer(tw, wh, -1.0 / (lw * lw)));
            add(&mut uu, outer(nh, nh, p));
            add(&mut uw, outer(nh, nh, q));
            add(&mut ww, outer(nh, nh, r));
        }
        Some(y) => {
            // y(û t_uᵀ + t_u ûᵀ)/|u|² has eigenvalues ±y/|u|² on (û ± t_u)/√2.
            let s = y.signum();
            let vu = [0, 1, 2].map(|i| uh[i] + s * tu[i]);
            let vw = [0, 1, 2].map(|i| wh[i] - s * tw[i]);
            add(&mut uu, outer(vu, vu, 0.5 * y.abs() / (lu * lu)));
            add(&mut ww, outer(vw, vw, 0.5 * y.abs() / (lw * lw)));
            let (p, q, r) = (y * p, y * q, y * r);
            let mean = 0.5 * (p + r);
            let radius = (0.25 * (p - r) * (p - r) + q * q).sqrt();
            let (hi, lo) = (mean + radius, mean - radius);
            let (pp, qq, rr) = if lo >= 0.0 {
                (p, q, r)
            } else if hi <= 0.0 {
                (0.0, 0.0, 0.0)
            } else {
                // hi times the projector on its eigenvector (q, hi − p) or (hi − r, q).
                let (e0, e1) = if (hi - p).abs() + q.abs() >= (hi - r).abs() + q.abs() {
                    (q, hi - p)
                } else {
                    (hi - r, q)
                };
                let norm = e0 * e0 + e1 * e1;
                if norm > 0.0 {
                    (
                        hi * e0 * e0 / norm,
                        hi * e0 * e1 / norm,
                        hi * e1 * e1 / norm,
                    )
                } else {
                    (hi, 0.0, hi)
                }
            };
            add(&mut uu, outer(nh, nh, pp));
            add(&mut uw, outer(nh, nh, qq));
            add(&mut ww, outer(nh, nh, rr));
        }
    }
    let all = [uu, uw, ww];
    all.iter()
        .all(|m| m.iter().flatten().all(|x| x.is_finite()))
        .then_some(all)
}

/// Analytic gradient of θ(q) with respect to q itself (Prop. 1, Eq. 12) and to each
/// neighbour p (Prop. 2, Eq. 13). Writes `(vertex, gradient)` pairs into `out`: first q, then
/// its ring neighbours in counter-clockwise order.
///
/// Summing [`corner_angle_gradient`] over q's fan gives exactly the paper's expressions: for a
/// neighbour p the two corners at q beside edge qp contribute
/// `(cot ξ + cot γ)/|pq|² (p − q) − (q₊ − q)/(|pq||q₊q| sin ξ) − (q₋ − q)/(|pq||q₋q| sin γ)`
/// (Eq. 13), and for q itself the 1/sin terms cancel (Appendix B), leaving
/// `Σ (cot ξ + cot γ)/|pq|² (p − q)`. Eq. 12 as printed divides by |pq| only; Appendix B's
/// derivation and finite differences (tests/engine/gradients.rs) both give |pq|².
pub fn theta_gradient(mesh: &Mesh, q: u32, out: &mut Vec<(u32, [f64; 3])>) {
    theta_gradient_with(mesh, mesh.positions(), q, out)
}

/// [`theta_gradient`] with the mesh's connectivity and the positions `pos`.
pub fn theta_gradient_with(mesh: &Mesh, pos: &[[f64; 3]], q: u32, out: &mut Vec<(u32, [f64; 3])>) {
    out.clear();
    let conn = mesh.conn();
    let ring = conn.ring_of(q);
    out.push((q, [0.0; 3]));
    out.extend(ring.iter().map(|&p| (p, [0.0; 3])));
    let closed = ring.len() == conn.fan_of(q).len();
    let pq = pos[q as usize];
    let n = ring.len();
    for (j, &h) in conn.fan_of(q).iter().enumerate() {
        let t = mesh.triangles()[h as usize / 3];
        let k = h as usize % 3;
        let (b, c) = (t[(k + 1) % 3], t[(k + 2) % 3]);
        let (gb, gc) = corner_angle_gradient(pq, pos[b as usize], pos[c as usize]);
        // Face j spans ring[j] -> ring[j+1].
        let jb = 1 + j;
        let jc = 1 + if closed { (j + 1) % n } else { j + 1 };
        debug_assert_eq!(out[jb].0, b);
        debug_assert_eq!(out[jc].0, c);
        for i in 0..3 {
            out[jb].1[i] += gb[i];
            out[jc].1[i] += gc[i];
            out[0].1[i] -= gb[i] + gc[i];
        }
    }
}

/// Sum of the turning (π − θ) at the boundary vertices of a patch plus the angle defects
/// (2π − θ) at its other vertices, with θ taken over the patch's faces only. By Gauss–Bonnet
/// this equals 2π χ(patch) exactly for any triangle mesh; tests use it as an independent check.
pub fn patch_total_curvature(mesh: &Mesh, patch: u32) -> f64 {
    let topo = &mesh.conn().patches()[patch as usize];
    let mut theta = vec![0.0f64; mesh.num_vertices()];
    let mut used = vec![false; mesh.num_vertices()];
    for &f in &topo.faces {
        let t = mesh.triangles()[f as usize];
        let [a, b, c] = mesh.face_positions(f as usize);
        let ang = [
            corner_angle(a, b, c),
            corner_angle(b, c, a),
            corner_angle(c, a, b),
        ];
        for k in 0..3 {
            theta[t[k] as usize] += ang[k];
            used[t[k] as usize] = true;
        }
    }
    let mut on_boundary = vec![0usize; mesh.num_vertices()];
    for lp in &topo.boundary_loops {
        for &v in lp {
            on_boundary[v as usize] += 1;
        }
    }
    let mut total = 0.0;
    for v in 0..mesh.num_vertices() {
        if !used[v] {
            continue;
        }
        // A vertex on k boundary wedges of the patch contributes 2π − θ − kπ (k = 0 inside,
        // k = 1 the turning π − θ); with this count the identity holds even at pinches.
        total += TAU - theta[v] - PI * on_boundary[v] as f64;
    }
    total
}

/// Adjacent face normals turning by more than this count as a fold (120°): a crease a sheet
/// could only take by creasing it hard, never a smooth drape.
pub const FOLD_ANGLE: f64 = 2.0 * PI / 3.0;

/// Edges with two faces whose unit normals turn by more than [`FOLD_ANGLE`] (seams included:
/// a fold across a seam is still a fold).
pub fn fold_edges(mesh: &Mesh) -> Vec<u32> {
    fold_edges_at(mesh, mesh.positions()).collect()
}

/// [`fold_edges`] of the mesh's faces placed at `pos` (an optimiser's iterate), without
/// allocating.
pub fn fold_edges_at<'a>(mesh: &'a Mesh, pos: &'a [[f64; 3]]) -> impl Iterator<Item = u32> + 'a {
    let limit = FOLD_ANGLE.cos();
    let normal = move |f: u32| {
        let [a, b, c] = mesh.triangles()[f as usize].map(|v| pos[v as usize]);
        normalize(cross(sub(b, a), sub(c, a)))
    };
    mesh.conn()
        .edge_faces()
        .iter()
        .enumerate()
        .filter(move |(_, f)| f[1] != crate::mesh::NONE && dot(normal(f[0]), normal(f[1])) < limit)
        .map(|(e, _)| e as u32)
}

/// A corner below this many degrees is a sliver: what optimisers may not create and the job
/// report warns about.
pub const SLIVER_DEGREES: f64 = 1.0;

/// Adjacent face normals turning by more than this count as a crease (60°): short of a fold,
/// but more than a smooth drape turns between neighbouring triangles.
pub const CREASE_ANGLE: f64 = PI / 3.0;

/// New creases (edges turning past [`CREASE_ANGLE`]) on more than this share of a mesh's
/// edges make it crumpled: flattenable by creasing all over rather than by a smooth change of
/// shape (fl-mesh's crumpled noisy saddles: 8–10 %; its converged domes 0–0.1 %; whole
/// garments 8–16 %, against 0.1–1 % creased in their inputs).
pub const CRUMPLED_SHARE: f64 = 0.01;

/// How many edges with two faces turn by more than [`CREASE_ANGLE`].
pub fn crease_count(mesh: &Mesh) -> usize {
    let fnrm = face_normals(mesh);
    let limit = CREASE_ANGLE.cos();
    mesh.conn()
        .edge_faces()
        .iter()
        .filter(|f| f[1] != crate::mesh::NONE)
        .filter(|f| dot(fnrm[f[0] as usize], fnrm[f[1] as usize]) < limit)
        .count()
}

/// The smallest corner angle of every face.
pub fn min_corner_angles(mesh: &Mesh) -> Vec<f64> {
    corner_angles(mesh)
        .into_iter()
        .map(|a| a[0].min(a[1]).min(a[2]))
        .collect()
}

/// The smallest corner angle of the whole mesh, radians (π when it has no face).
pub fn smallest_corner(mesh: &Mesh) -> f64 {
    smallest_corner_at(mesh, mesh.positions())
}

/// [`smallest_corner`] of the mesh's faces placed at `pos` (an optimiser's iterate), without
/// allocating.
pub fn smallest_corner_at(mesh: &Mesh, pos: &[[f64; 3]]) -> f64 {
    mesh.triangles().iter().fold(PI, |m, t| {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        m.min(corner_angle(a, b, c))
            .min(corner_angle(b, c, a))
            .min(corner_angle(c, a, b))
    })
}

/// How many of [`fold_edges`] the mesh's faces placed at `pos` have, without allocating.
pub fn fold_count_at(mesh: &Mesh, pos: &[[f64; 3]]) -> usize {
    fold_edges_at(mesh, pos).count()
}

/// Mean edge length (0 for a mesh without edges): the length scale of a mesh.
pub fn mean_edge_length(mesh: &Mesh) -> f64 {
    let l = edge_lengths(mesh, mesh.positions());
    if l.is_empty() {
        return 0.0;
    }
    l.iter().sum::<f64>() / l.len() as f64
}

/// Length of every edge of `mesh.conn().edges()` at positions `pos`.
pub fn edge_lengths(mesh: &Mesh, pos: &[[f64; 3]]) -> Vec<f64> {
    mesh.conn()
        .edges()
        .iter()
        .map(|e| {
            let d = sub(pos[e[0] as usize], pos[e[1] as usize]);
            dot(d, d).sqrt()
        })
        .collect()
}

/// Turning angle φ ∈ [0, π] between the normals of triangles (i, j, k) and (j, i, l) across
/// their shared edge i–j (0 when flat, [`FOLD_ANGLE`] and above a fold), and its gradient with
/// respect to p_i, p_j, p_k, p_l (the hinge formulas of Bridson et al. 2003, signed by the
/// direction the hinge bends). Zero gradient when a triangle is degenerate or φ is 0 or π,
/// where φ is not differentiable.
pub fn turning_angle_gradient(
    pi: [f64; 3],
    pj: [f64; 3],
    pk: [f64; 3],
    pl: [f64; 3],
) -> (f64, [[f64; 3]; 4]) {
    let e = sub(pj, pi);
    let n1 = cross(e, sub(pk, pi));
    let n2 = cross(sub(pl, pj), e);
    let (a1, a2, le) = (dot(n1, n1), dot(n2, n2), dot(e, e).sqrt());
    let sin = dot(e, cross(n1, n2)) / le;
    let cos = dot(n1, n2);
    let signed = sin.atan2(cos);
    let phi = signed.abs();
    if !(a1 > 0.0 && a2 > 0.0 && le > 0.0) || phi == 0.0 || !phi.is_finite() {
        return (if phi.is_finite() { phi } else { 0.0 }, [[0.0; 3]; 4]);
    }
    let s = -signed.signum();
    let u1 = n1.map(|x| s * le * x / a1);
    let u2 = n2.map(|x| s * le * x / a2);
    let (d1i, d1j) = (dot(sub(pk, pi), e) / le, dot(sub(pk, pj), e) / le);
    let (d2i, d2j) = (dot(sub(pl, pi), e) / le, dot(sub(pl, pj), e) / le);
    let ui = [0, 1, 2].map(|c| s * (d1j * n1[c] / a1 + d2j * n2[c] / a2));
    let uj = [0, 1, 2].map(|c| -s * (d1i * n1[c] / a1 + d2i * n2[c] / a2));
    (phi, [ui, uj, u1, u2])
}
