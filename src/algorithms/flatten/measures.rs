//! Distortion of a flat piece against its 3D patch (Sec. 4.1 of wang-lpfb and beyond).
//!
//! - A(Ω), Eq. 19: (Σ A_T − Σ A_T⁰) / Σ A_T⁰ in percent, A_T the signed 2D area.
//! - Sander et al.'s texture stretch of the map 2D → 3D: per triangle the singular values
//!   Γ ≥ γ, L²(T) = √((Γ² + γ²)/2), L∞(T) = Γ; L² = √(Σ L²(T)² A_T⁰ / Σ A_T⁰), L∞ = max Γ.
//! - Π_L (Eq. 1) and Π_θ (Eq. 2) on the boundary; Π_θ compares a_v with the 2D inner angle
//!   (sum of the 2D corner angles at v).
//! - Principal stretches σ1 ≥ σ2 of the map 3D → 2D per face, summarised as the largest and
//!   area-weighted mean stretch (σ1 − 1) and compression (1 − σ2), in percent.
//! - S(Ω): 1 when a triangle is flipped or degenerate in 2D, or the boundary loops intersect
//!   themselves or each other, else 0 — decided on the CPU with exact orientation predicates
//!   (error-bounded filter, exact expansion arithmetic when the filter cannot decide). A
//!   locally injective map of a disk with a simple boundary is globally injective, so these
//!   two tests together decide overlap exactly (the paper rasterised on the GPU).

use serde::Serialize;

/// Per-piece distortion figures (see module doc).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Measures {
    /// Total 3D area.
    pub area_3d: f64,
    /// Total signed 2D area.
    pub area_2d: f64,
    /// A(Ω), Eq. 19, percent.
    pub area_distortion_pct: f64,
    /// Sander L² stretch (1 is the lower bound).
    pub l2_stretch: f64,
    /// Sander L∞ stretch.
    pub linf_stretch: f64,
    /// Π_L, Eq. 1 (mesh units).
    pub pi_l: f64,
    /// Π_θ, Eq. 2 (radians).
    pub pi_theta: f64,
    /// Largest |l_e − l_e⁰| / l_e⁰ over boundary edges.
    pub boundary_length_max_rel_error: f64,
    /// The boundary edge where that is reached, as mesh vertices.
    pub boundary_worst_edge: [u32; 2],
    /// ϖ_max = max |2π − θ| over the piece's interior vertices (3D): 0 for a developable piece.
    pub varpi_max: f64,
    /// |perimeter_2D − perimeter_3D| / perimeter_3D.
    pub perimeter_rel_error: f64,
    /// Triangles with non-positive 2D area.
    pub flipped_triangles: usize,
    /// Pairs of boundary segments that touch or cross (adjacent ones excepted).
    pub boundary_intersections: usize,
    /// S(Ω): 1 when the piece overlaps itself, else 0.
    pub overlap: u8,
    /// max (σ1 − 1) · 100.
    pub stretch_max_pct: f64,
    /// area-weighted mean (σ1 − 1) · 100.
    pub stretch_mean_pct: f64,
    /// max (1 − σ2) · 100.
    pub compression_max_pct: f64,
    /// area-weighted mean (1 − σ2) · 100.
    pub compression_mean_pct: f64,
}

fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn norm3(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}
fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn angle2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let e1 = [b[0] - a[0], b[1] - a[1]];
    let e2 = [c[0] - a[0], c[1] - a[1]];
    (e1[0] * e2[1] - e1[1] * e2[0])
        .abs()
        .atan2(e1[0] * e2[0] + e1[1] * e2[1])
}

/// Singular values (σ1 ≥ σ2) of a 2×2 matrix [[a, b], [c, d]].
pub fn sv2(a: f64, b: f64, c: f64, d: f64) -> (f64, f64) {
    let e = (a + d) / 2.0;
    let f = (a - d) / 2.0;
    let g = (c + b) / 2.0;
    let h = (c - b) / 2.0;
    let q = (e * e + h * h).sqrt();
    let r = (f * f + g * g).sqrt();
    (q + r, (q - r).abs())
}

/// Exact sign of the orientation of (a, b, c): +1 left turn, −1 right turn, 0 collinear.
pub fn orient2d(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> i8 {
    let l = (a[0] - c[0]) * (b[1] - c[1]);
    let r = (a[1] - c[1]) * (b[0] - c[0]);
    let det = l - r;
    let bound = 3.3306690738754716e-16 * (l.abs() + r.abs());
    if det > bound {
        return 1;
    }
    if -det > bound {
        return -1;
    }
    exact_orient(a, b, c)
}

fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    let err = (a - (s - bb)) + (b - bb);
    (s, err)
}

fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

/// det = ax·by − ax·cy − bx·ay + bx·cy + cx·ay − cx·by, each product split exactly into two
/// doubles and summed as a non-overlapping expansion (Shewchuk's grow-expansion).
fn exact_orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> i8 {
    let terms = [
        (a[0], b[1], 1.0),
        (a[0], c[1], -1.0),
        (b[0], a[1], -1.0),
        (b[0], c[1], 1.0),
        (c[0], a[1], 1.0),
        (c[0], b[1], -1.0),
    ];
    let mut e = [0.0f64; 12];
    let mut len = 0;
    for (x, y, s) in terms {
        let (p, q) = two_prod(x, y);
        for v in [p * s, q * s] {
            // grow-expansion: add v to e, keeping components exact
            let mut qv = v;
            for comp in e[..len].iter_mut() {
                let (sum, err) = two_sum(qv, *comp);
                *comp = err;
                qv = sum;
            }
            e[len] = qv;
            len += 1;
        }
    }
    // the most significant non-zero component decides the sign (components are ordered by
    // magnitude after grow-expansion, largest last)
    for &x in e[..len].iter().rev() {
        if x > 0.0 {
            return 1;
        }
        if x < 0.0 {
            return -1;
        }
    }
    0
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Whether closed segments ab and cd share a point.
pub fn segments_intersect(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = orient2d(a, b, c);
    let d2 = orient2d(a, b, d);
    let d3 = orient2d(c, d, a);
    let d4 = orient2d(c, d, b);
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    (d1 == 0 && on_segment(a, b, c))
        || (d2 == 0 && on_segment(a, b, d))
        || (d3 == 0 && on_segment(c, d, a))
        || (d4 == 0 && on_segment(c, d, b))
}

/// Number of intersecting pairs among boundary segments. Segments sharing an endpoint are not
/// compared; segments with endpoints that are copies of one 3D point (`vertex_ids` equal)
/// count only when they properly cross. Sweep by x.
pub fn boundary_intersections(uv: &[[f64; 2]], loops: &[Vec<u32>], vertex_ids: &[u32]) -> usize {
    let mut segs: Vec<(f64, f64, u32, u32)> = Vec::new();
    for lp in loops {
        for k in 0..lp.len() {
            let (i, j) = (lp[k], lp[(k + 1) % lp.len()]);
            let (a, b) = (uv[i as usize], uv[j as usize]);
            segs.push((a[0].min(b[0]), a[0].max(b[0]), i, j));
        }
    }
    segs.sort_by(|x, y| x.0.partial_cmp(&y.0).unwrap_or(std::cmp::Ordering::Equal));
    let mut count = 0;
    for s in 0..segs.len() {
        let (_, xmax, i, j) = segs[s];
        let (a, b) = (uv[i as usize], uv[j as usize]);
        for &(xmin2, _, k, l) in &segs[s + 1..] {
            if xmin2 > xmax {
                break;
            }
            if [k, l].iter().any(|&v| v == i || v == j) {
                continue;
            }
            let (c, d) = (uv[k as usize], uv[l as usize]);
            if a[1].max(b[1]) < c[1].min(d[1]) || c[1].max(d[1]) < a[1].min(b[1]) {
                continue;
            }
            // Segments ending at copies of one 3D point may touch there (and lie on each
            // other along a slit); only a proper crossing counts for them.
            let gid = |v: u32| vertex_ids[v as usize];
            let copies = [k, l].iter().any(|&v| gid(v) == gid(i) || gid(v) == gid(j));
            let hit = if copies {
                let (d1, d2) = (orient2d(a, b, c), orient2d(a, b, d));
                let (d3, d4) = (orient2d(c, d, a), orient2d(c, d, b));
                d1 * d2 < 0 && d3 * d4 < 0
            } else {
                segments_intersect(a, b, c, d)
            };
            if hit {
                count += 1;
            }
        }
    }
    count
}

/// For each vertex, the first vertex at bit-identical 3D position: copies of one surface
/// point, whether split into wedges here or already split in the mesh (a slit cut into a
/// segmentation chart), whose boundary segments may touch in 2D.
fn coincident(pos: &[[f64; 3]]) -> Vec<u32> {
    let mut first = std::collections::HashMap::with_capacity(pos.len());
    pos.iter()
        .enumerate()
        .map(|(v, p)| *first.entry(p.map(f64::to_bits)).or_insert(v as u32))
        .collect()
}

/// All measures of a piece: 3D positions and 2D positions of its vertices, its triangles,
/// its boundary loops.
pub fn compute(
    pos: &[[f64; 3]],
    uv: &[[f64; 2]],
    tris: &[[u32; 3]],
    loops: &[Vec<u32>],
    vertex_ids: &[u32],
) -> Measures {
    let mut m = Measures::default();
    let mut l2_num = 0.0;
    let (mut st_sum, mut co_sum, mut w_sum) = (0.0, 0.0, 0.0);
    let mut inner2d = vec![0.0; pos.len()];
    let mut inner3d = vec![0.0; pos.len()];
    for t in tris {
        let p = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
        let q = [uv[t[0] as usize], uv[t[1] as usize], uv[t[2] as usize]];
        for i in 0..3 {
            inner2d[t[i] as usize] += angle2(q[i], q[(i + 1) % 3], q[(i + 2) % 3]);
            inner3d[t[i] as usize] +=
                crate::geometry::corner_angle(p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
        }
        // local orthonormal frame of the 3D triangle
        let e1 = sub3(p[1], p[0]);
        let e2 = sub3(p[2], p[0]);
        let l1 = norm3(e1);
        let n = cross3(e1, e2);
        let a3 = 0.5 * norm3(n);
        let x = [e1[0] / l1, e1[1] / l1, e1[2] / l1];
        let y = cross3(crate::geometry::normalize(n), x);
        // 3D edge matrix P = [[l1, e2·x], [0, e2·y]]
        let (p11, p12, p22) = (
            l1,
            e2[0] * x[0] + e2[1] * x[1] + e2[2] * x[2],
            e2[0] * y[0] + e2[1] * y[1] + e2[2] * y[2],
        );
        let f1 = [q[1][0] - q[0][0], q[1][1] - q[0][1]];
        let f2 = [q[2][0] - q[0][0], q[2][1] - q[0][1]];
        let a2 = 0.5 * (f1[0] * f2[1] - f1[1] * f2[0]);
        m.area_3d += a3;
        m.area_2d += a2;
        if a2 <= 0.0 || orient2d(q[0], q[1], q[2]) <= 0 {
            m.flipped_triangles += 1;
        }
        if a3 <= 0.0 || p22 == 0.0 {
            continue;
        }
        // J = Q P⁻¹ (3D → 2D), P⁻¹ = [[1/p11, −p12/(p11 p22)], [0, 1/p22]]
        let j11 = f1[0] / p11;
        let j21 = f1[1] / p11;
        let j12 = (f2[0] - j11 * p12) / p22;
        let j22 = (f2[1] - j21 * p12) / p22;
        let (s1, s2) = sv2(j11, j12, j21, j22);
        st_sum += (s1 - 1.0) * a3;
        co_sum += (1.0 - s2) * a3;
        w_sum += a3;
        m.stretch_max_pct = m.stretch_max_pct.max((s1 - 1.0) * 100.0);
        m.compression_max_pct = m.compression_max_pct.max((1.0 - s2) * 100.0);
        // 2D → 3D: Γ = 1/σ2, γ = 1/σ1
        if s2 > 0.0 {
            let (gg, g) = (1.0 / s2, 1.0 / s1);
            l2_num += (gg * gg + g * g) / 2.0 * a3;
            m.linf_stretch = m.linf_stretch.max(gg);
        } else {
            m.linf_stretch = f64::MAX;
            l2_num = f64::MAX;
        }
    }
    if w_sum > 0.0 {
        m.stretch_mean_pct = st_sum / w_sum * 100.0;
        m.compression_mean_pct = co_sum / w_sum * 100.0;
    }
    m.l2_stretch = if m.area_3d > 0.0 && l2_num < f64::MAX {
        (l2_num / m.area_3d).sqrt()
    } else {
        f64::MAX
    };
    if m.area_3d > 0.0 {
        m.area_distortion_pct = (m.area_2d - m.area_3d) / m.area_3d * 100.0;
    }
    let (mut nb, mut sum_l, mut sum_t) = (0usize, 0.0, 0.0);
    let mut on_boundary = vec![false; pos.len()];
    let (mut per2, mut per3) = (0.0, 0.0);
    for lp in loops {
        for k in 0..lp.len() {
            let (i, j) = (lp[k] as usize, lp[(k + 1) % lp.len()] as usize);
            let l0 = super::cut::dist(pos[i], pos[j]);
            let d = [uv[j][0] - uv[i][0], uv[j][1] - uv[i][1]];
            let l = (d[0] * d[0] + d[1] * d[1]).sqrt();
            sum_l += (l - l0).abs();
            if l0 > 0.0 && (l - l0).abs() / l0 > m.boundary_length_max_rel_error {
                m.boundary_length_max_rel_error = (l - l0).abs() / l0;
                m.boundary_worst_edge = [vertex_ids[i], vertex_ids[j]];
            }
            on_boundary[i] = true;
            sum_t += (inner3d[i] - inner2d[i]).abs();
            per2 += l;
            per3 += l0;
            nb += 1;
        }
    }
    if nb > 0 {
        m.pi_l = sum_l / nb as f64;
        m.pi_theta = sum_t / nb as f64;
    }
    if per3 > 0.0 {
        m.perimeter_rel_error = (per2 - per3).abs() / per3;
    }
    m.varpi_max = (0..pos.len())
        .filter(|&v| !on_boundary[v])
        .map(|v| (std::f64::consts::TAU - inner3d[v]).abs())
        .fold(0.0, f64::max);
    m.boundary_intersections = boundary_intersections(uv, loops, &coincident(pos));
    m.overlap = (m.flipped_triangles > 0 || m.boundary_intersections > 0) as u8;
    m
}
