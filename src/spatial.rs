//! Exact closest points on a triangle soup through a uniform grid of triangle bounding boxes,
//! searched in growing shells until no unvisited cell can hold a closer point. Used for the
//! distance of an optimised mesh to its input and for the "closest" start of the FL-mesh
//! solver.

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

fn lerp(a: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    [a[0] + d[0] * t, a[1] + d[1] * t, a[2] + d[2] * t]
}

/// A uniform grid over a triangle set for exact closest-point queries.
#[derive(Debug, Clone)]
pub struct TriangleGrid {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl TriangleGrid {
    /// Bin every triangle into the cells its bounding box overlaps; about one triangle per cell.
    pub fn new(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Self {
        let (lo, hi) = crate::mesh::bbox_of(
            triangles
                .iter()
                .flat_map(|t| t.iter().map(|&i| positions[i as usize])),
        );
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let diag = dot(ext, ext).sqrt().max(1e-300);
        let vol: f64 = ext.iter().map(|e| e.max(diag * 1e-3)).product();
        let cell = (vol / triangles.len().max(1) as f64)
            .cbrt()
            .max(diag * 1e-4);
        let dims = [0, 1, 2].map(|k| ((ext[k] / cell).floor() as usize + 1).min(1 << 10));
        let ncell = dims[0] * dims[1] * dims[2];
        let mut count = vec![0u32; ncell + 1];
        let grid = Self {
            positions: positions.to_vec(),
            triangles: triangles.to_vec(),
            lo,
            cell,
            dims,
            start: Vec::new(),
            items: Vec::new(),
        };
        let ranges: Vec<([usize; 3], [usize; 3])> = triangles
            .iter()
            .map(|t| {
                let (a, b) = crate::mesh::bbox_of(t.iter().map(|&i| positions[i as usize]));
                (grid.cell_of(a), grid.cell_of(b))
            })
            .collect();
        for (a, b) in &ranges {
            for_cells(*a, *b, |c| count[grid.index(c)] += 1);
        }
        let mut start = vec![0u32; ncell + 1];
        for i in 0..ncell {
            start[i + 1] = start[i] + count[i];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; start[ncell] as usize];
        for (f, (a, b)) in ranges.iter().enumerate() {
            for_cells(*a, *b, |c| {
                let k = grid.index(c);
                items[fill[k] as usize] = f as u32;
                fill[k] += 1;
            });
        }
        Self {
            start,
            items,
            ..grid
        }
    }

    fn cell_of(&self, p: [f64; 3]) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let c = ((p[k] - self.lo[k]) / self.cell).floor();
            if c.is_nan() || c < 0.0 {
                0
            } else {
                (c as usize).min(self.dims[k] - 1)
            }
        })
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The closest point to `p` on the triangles, its squared distance and the triangle.
    pub fn closest(&self, p: [f64; 3]) -> ([f64; 3], f64, u32) {
        let c0 = self.cell_of(p);
        let mut best = ([0.0; 3], f64::INFINITY, u32::MAX);
        // Distance from p to the box of cells within shell r of c0 bounds every unvisited
        // triangle's distance from below once r grows past it.
        let maxr = self.dims.iter().copied().max().unwrap_or(1);
        for r in 0..=maxr {
            let lo = [0, 1, 2].map(|k| c0[k].saturating_sub(r));
            let hi = [0, 1, 2].map(|k| (c0[k] + r).min(self.dims[k] - 1));
            for_cells(lo, hi, |c| {
                let on_shell = (0..3).any(|k| c[k] + r == c0[k] || c[k] == c0[k] + r);
                if !on_shell {
                    return;
                }
                let k = self.index(c);
                for &f in &self.items[self.start[k] as usize..self.start[k + 1] as usize] {
                    let t = self.triangles[f as usize];
                    let q = closest_point_on_triangle(
                        p,
                        self.positions[t[0] as usize],
                        self.positions[t[1] as usize],
                        self.positions[t[2] as usize],
                    );
                    let d = sub(q, p);
                    let d2 = dot(d, d);
                    if d2 < best.1 {
                        best = (q, d2, f);
                    }
                }
            });
            // Everything not yet visited lies outside the box of cells lo..=hi.
            let mut gap = f64::INFINITY;
            for k in 0..3 {
                if lo[k] > 0 {
                    gap = gap.min(p[k] - (self.lo[k] + lo[k] as f64 * self.cell));
                }
                if hi[k] + 1 < self.dims[k] {
                    gap = gap.min(self.lo[k] + (hi[k] + 1) as f64 * self.cell - p[k]);
                }
            }
            if gap == f64::INFINITY || (best.1.is_finite() && gap.max(0.0).powi(2) >= best.1) {
                break;
            }
        }
        best
    }
}

fn for_cells(a: [usize; 3], b: [usize; 3], mut f: impl FnMut([usize; 3])) {
    for z in a[2]..=b[2] {
        for y in a[1]..=b[1] {
            for x in a[0]..=b[0] {
                f([x, y, z]);
            }
        }
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
    let one = |pos: &[[f64; 3]], tri: &[[u32; 3]], grid: &TriangleGrid| -> f64 {
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
    let gb = TriangleGrid::new(b_pos, b_tri);
    let ga = TriangleGrid::new(a_pos, a_tri);
    one(a_pos, a_tri, &gb).max(one(b_pos, b_tri, &ga))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_matches_brute_force() {
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
        let g = TriangleGrid::new(&pos, &tri);
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let p = [rnd() * 2.0 - 0.5, rnd() * 2.0 - 0.5, rnd() - 0.5];
            let brute = tri
                .iter()
                .map(|t| {
                    let q = closest_point_on_triangle(
                        p,
                        pos[t[0] as usize],
                        pos[t[1] as usize],
                        pos[t[2] as usize],
                    );
                    let d = sub(q, p);
                    dot(d, d)
                })
                .fold(f64::INFINITY, f64::min);
            let (_, d2, _) = g.closest(p);
            assert!(
                (d2 - brute).abs() <= 1e-12 * (1.0 + brute),
                "{d2} vs {brute}"
            );
        }
    }
}
