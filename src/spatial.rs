//! Exact closest points on a triangle set, through parry's bounding-volume hierarchy (a
//! well-kept crate, ../shared/CRATES.md). Used for the distance of an optimised mesh to its
//! input, the "closest" anchors of the FL-mesh solver and perturb's reference body.
//!
//! It replaced a uniform grid of triangle bounding boxes, which binned a long thin triangle in
//! every cell of its box: a 60k-triangle fan (3.5 MB of OBJ) took 3.7 GB (issue 20). The
//! hierarchy's memory is linear in the triangles whatever their shape, and it measured faster
//! where it matters (`cargo bench --bench closest`, 2-core VM): on a 100k-face noisy saddle,
//! 5k queries 4.8 ms against the grid's 20.0 ms, built in 34 ms against 4 ms; on a 20k-triangle
//! fan, 2k queries 5.4 ms against 26.2 ms, built in 3.4 ms against 141 ms.

use crate::mesh::{dot, sub};

/// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_point_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return lerp(a, ab, v);
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return lerp(a, ac, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return lerp(b, sub(c, b), w);
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // Degenerate triangle: fall back to the nearest vertex.
        let da = dot(ap, ap);
        let db = dot(bp, bp);
        let dc = dot(cp, cp);
        return if da <= db && da <= dc {
            a
        } else if db <= dc {
            b
        } else {
            c
        };
    }
    let v = vb / denom;
    let w = vc / denom;
    [
        a[0] + ab[0] * v + ac[0] * w,
        a[1] + ab[1] * v + ac[1] * w,
        a[2] + ab[2] * v + ac[2] * w,
    ]
}

/// Squared distance from `p` to the nearest of `triangles` by trying every one: the truth
/// [`TriangleBvh`] is checked against (tests, benchmarks).
pub fn brute_closest_d2(p: [f64; 3], positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let q = closest_point_on_triangle(
                p,
                positions[t[0] as usize],
                positions[t[1] as usize],
                positions[t[2] as usize],
            );
            let d = sub(q, p);
            dot(d, d)
        })
        .fold(f64::INFINITY, f64::min)
}

fn lerp(a: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    [a[0] + d[0] * t, a[1] + d[1] * t, a[2] + d[2] * t]
}

/// Exact closest points on a triangle set through parry's bounding-volume hierarchy.
pub struct TriangleBvh {
    mesh: parry3d_f64::shape::TriMesh,
}

impl std::fmt::Debug for TriangleBvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleBvh")
            .field("triangles", &self.mesh.indices().len())
            .finish()
    }
}

impl TriangleBvh {
    /// The hierarchy of `triangles` (at least one) over `positions`.
    ///
    /// # Panics
    /// When `triangles` is empty (every caller holds a validated mesh, which has faces).
    pub fn new(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Self {
        use parry3d_f64::math::Vector;
        let vertices = positions
            .iter()
            .map(|p| Vector::new(p[0], p[1], p[2]))
            .collect();
        let mesh = parry3d_f64::shape::TriMesh::new(vertices, triangles.to_vec())
            .expect("a triangle set of at least one triangle");
        Self { mesh }
    }

    /// The closest point to finite `p` on the triangles, its squared distance and the
    /// triangle.
    pub fn closest(&self, p: [f64; 3]) -> ([f64; 3], f64, u32) {
        use parry3d_f64::query::PointQueryWithLocation;
        let (_, (tri, _)) = self.mesh.project_local_point_and_get_location(
            parry3d_f64::math::Vector::new(p[0], p[1], p[2]),
            false,
        );
        // The point itself from the triangle parry chose, by the same formula as every
        // brute-force check: its rounding then agrees with theirs to the last bit.
        let [a, b, c] = self.mesh.indices()[tri as usize].map(|i| {
            let v = self.mesh.vertices()[i as usize];
            [v.x, v.y, v.z]
        });
        let q = closest_point_on_triangle(p, a, b, c);
        let d = sub(q, p);
        (q, dot(d, d), tri)
    }
}

/// Two-sided vertex-to-surface distance between meshes A and B: the larger of
/// max over A's vertices of the distance to B's surface and vice versa. It is a lower bound of
/// the true Hausdorff distance, exact up to how far a face interior can stray between vertex
/// samples (for meshes this fine, a small fraction of an edge length).
pub fn vertex_surface_hausdorff(
    a_pos: &[[f64; 3]],
    a_tri: &[[u32; 3]],
    b_pos: &[[f64; 3]],
    b_tri: &[[u32; 3]],
) -> f64 {
    use rayon::prelude::*;
    let one = |pos: &[[f64; 3]], tri: &[[u32; 3]], grid: &TriangleBvh| -> f64 {
        let mut used = vec![false; pos.len()];
        for t in tri {
            for &i in t {
                used[i as usize] = true;
            }
        }
        pos.par_iter()
            .zip(used.par_iter())
            .filter(|(_, &u)| u)
            .map(|(p, _)| grid.closest(*p).1)
            .reduce(|| 0.0, f64::max)
            .sqrt()
    };
    // The two hierarchies are independent: build them side by side.
    let (gb, ga) = rayon::join(
        || TriangleBvh::new(b_pos, b_tri),
        || TriangleBvh::new(a_pos, a_tri),
    );
    one(a_pos, a_tri, &gb).max(one(b_pos, b_tri, &ga))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_points_match_brute_force() {
        // A wavy 12×12 grid of triangles.
        let n = 12;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                pos.push([x, y, 0.2 * (3.0 * x).sin() * (2.0 * y).cos()]);
            }
        }
        let mut tri = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = (j * (n + 1) + i) as u32;
                let w = v + n as u32 + 1;
                tri.push([v, v + 1, w + 1]);
                tri.push([v, w + 1, w]);
            }
        }
        let g = TriangleBvh::new(&pos, &tri);
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let p = [rnd() * 2.0 - 0.5, rnd() * 2.0 - 0.5, rnd() - 0.5];
            let brute = brute_closest_d2(p, &pos, &tri);
            let (_, d2, _) = g.closest(p);
            assert!(
                (d2 - brute).abs() <= 1e-12 * (1.0 + brute),
                "{d2} vs {brute}"
            );
        }
    }
}
