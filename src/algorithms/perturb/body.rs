//! The reference body H of Eq. 20: signed distance s(v) = (v − h)·n_h from its closest point h,
//! positive outside. The closest point comes from the crate's closest-point hierarchy
//! ([`crate::spatial::TriangleBvh`]: exact, already used for Hausdorff distances, no second
//! spatial index to keep in step); the sign from the angle-weighted pseudo-normal of the
//! feature (face, edge or vertex) that holds h (Bærentzen & Aanæs 2005), which, unlike the
//! normal of the face that holds h, gives the right side everywhere on a closed surface.
//!
//! Orientation: each closed component must enclose positive volume; one that does not is
//! flipped (and said so). An open body's orientation is taken as given (a warning says so):
//! only the user knows which side the wearer is on.

use crate::geometry::corner_angle;
use crate::mesh::{cross, dot, sub, Mesh};
use crate::spatial::TriangleBvh;
use std::collections::HashMap;

/// A reference body ready for signed-distance queries.
pub struct Body {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    grid: TriangleBvh,
    face_normal: Vec<[f64; 3]>,
    vertex_normal: Vec<[f64; 3]>,
    edge_normal: HashMap<(u32, u32), [f64; 3]>,
    /// Every component closed (so the signed distance is 1-Lipschitz).
    closed: bool,
}

/// What a query found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearance {
    /// Signed distance, positive outside.
    pub signed: f64,
    /// Unit direction in which `signed` grows fastest at the query point.
    pub gradient: [f64; 3],
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = dot(v, v).sqrt();
    if n > 0.0 {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        [0.0; 3]
    }
}

fn add_to(a: &mut [f64; 3], b: [f64; 3], w: f64) {
    for k in 0..3 {
        a[k] += w * b[k];
    }
}

impl Body {
    /// Prepare `mesh` as a body; the warnings say what was assumed or repaired.
    pub fn new(mesh: &Mesh) -> (Body, Vec<String>) {
        let mut warnings = Vec::new();
        let positions = mesh.positions().to_vec();
        let mut triangles = mesh.triangles().to_vec();
        let (flipped, open) = orient_components(mesh, &mut triangles);
        if flipped > 0 {
            warnings.push(format!(
                "reference body: {flipped} closed component(s) enclosed negative volume (normals \
                 inwards) and were flipped"
            ));
        }
        if open > 0 {
            warnings.push(format!(
                "reference body: {open} component(s) are open; their outside is taken to be the \
                 side their triangles' normals point to"
            ));
        }
        let face_normal: Vec<[f64; 3]> = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                unit(cross(sub(b, a), sub(c, a)))
            })
            .collect();
        let mut vertex_normal = vec![[0.0; 3]; positions.len()];
        let mut edge_normal: HashMap<(u32, u32), [f64; 3]> = HashMap::new();
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                let w = corner_angle(
                    positions[a as usize],
                    positions[b as usize],
                    positions[c as usize],
                );
                add_to(&mut vertex_normal[a as usize], face_normal[f], w);
                let e = (a.min(b), a.max(b));
                add_to(
                    edge_normal.entry(e).or_insert([0.0; 3]),
                    face_normal[f],
                    1.0,
                );
            }
        }
        let vertex_normal = vertex_normal.into_iter().map(unit).collect();
        let edge_normal = edge_normal.into_iter().map(|(e, n)| (e, unit(n))).collect();
        let grid = TriangleBvh::new(&positions, &triangles);
        (
            Body {
                positions,
                triangles,
                grid,
                face_normal,
                vertex_normal,
                edge_normal,
                closed: open == 0,
            },
            warnings,
        )
    }

    /// Whether every component is closed (its signed distance is then 1-Lipschitz).
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Signed distance of `p` to the body and its gradient.
    pub fn clearance(&self, p: [f64; 3]) -> Clearance {
        let (h, d2, f) = self.grid.closest(p);
        let n = self.pseudo_normal(f as usize, h);
        let d = sub(p, h);
        let dist = d2.sqrt();
        let side = if dot(d, n) < 0.0 { -1.0 } else { 1.0 };
        // Off the surface the gradient is the unit offset (signed); on it, the pseudo-normal.
        let gradient = if dist > 1e-12 * (1.0 + dot(p, p).sqrt()) {
            let u = unit(d);
            [side * u[0], side * u[1], side * u[2]]
        } else {
            n
        };
        Clearance {
            signed: side * dist,
            gradient,
        }
    }

    /// The pseudo-normal of the feature of face `f` that holds `h`.
    fn pseudo_normal(&self, f: usize, h: [f64; 3]) -> [f64; 3] {
        let t = self.triangles[f];
        let [a, b, c] = t.map(|v| self.positions[v as usize]);
        let bary = barycentric(h, a, b, c);
        let eps = 1e-9;
        let zero: Vec<usize> = (0..3).filter(|&k| bary[k] <= eps).collect();
        match zero.len() {
            0 => self.face_normal[f],
            1 => {
                // On the edge opposite the zero coordinate.
                let k = zero[0];
                let (u, v) = (t[(k + 1) % 3], t[(k + 2) % 3]);
                self.edge_normal
                    .get(&(u.min(v), u.max(v)))
                    .copied()
                    .unwrap_or(self.face_normal[f])
            }
            _ => {
                let k = (0..3).find(|k| !zero.contains(k)).unwrap_or(0);
                self.vertex_normal[t[k] as usize]
            }
        }
    }
}

/// The global method keeps vertices outside the body through fl-mesh's obstacle rows.
impl crate::algorithms::fl_mesh::Obstacle for Body {
    fn clearance(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let c = Body::clearance(self, p);
        (c.signed, c.gradient)
    }
    fn is_closed(&self) -> bool {
        Body::is_closed(self)
    }
}

/// Barycentric coordinates of `p` (in the plane of a, b, c).
fn barycentric(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (v0, v1, v2) = (sub(b, a), sub(c, a), sub(p, a));
    let (d00, d01, d11) = (dot(v0, v0), dot(v0, v1), dot(v1, v1));
    let (d20, d21) = (dot(v2, v0), dot(v2, v1));
    let den = d00 * d11 - d01 * d01;
    if den <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    [1.0 - v - w, v, w]
}

/// Flip the closed components of negative signed volume in `triangles`; returns how many
/// were flipped and how many components are open.
fn orient_components(mesh: &Mesh, triangles: &mut [[u32; 3]]) -> (usize, usize) {
    let conn = mesh.conn();
    // Components of faces through shared edges.
    let nf = triangles.len();
    let mut comp = vec![usize::MAX; nf];
    let mut count = 0;
    for start in 0..nf {
        if comp[start] != usize::MAX {
            continue;
        }
        comp[start] = count;
        let mut stack = vec![start];
        while let Some(f) = stack.pop() {
            for k in 0..3 {
                let twin = conn.twin((3 * f + k) as u32);
                if twin != crate::mesh::NONE {
                    let g = twin as usize / 3;
                    if comp[g] == usize::MAX {
                        comp[g] = count;
                        stack.push(g);
                    }
                }
            }
        }
        count += 1;
    }
    let mut volume = vec![0.0; count];
    let mut open = vec![false; count];
    for (f, t) in triangles.iter().enumerate() {
        let [a, b, c] = t.map(|v| mesh.position(v));
        volume[comp[f]] += dot(a, cross(b, c)) / 6.0;
        for k in 0..3 {
            if conn.twin((3 * f + k) as u32) == crate::mesh::NONE {
                open[comp[f]] = true;
            }
        }
    }
    let mut flipped = 0;
    for c in 0..count {
        if !open[c] && volume[c] < 0.0 {
            flipped += 1;
        }
    }
    for (f, t) in triangles.iter_mut().enumerate() {
        if !open[comp[f]] && volume[comp[f]] < 0.0 {
            t.swap(1, 2);
        }
    }
    (flipped, open.iter().filter(|&&o| o).count())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::RawMesh;

    /// The unit cube, triangulated, normals out (or in when `inward`).
    fn cube(inward: bool) -> Mesh {
        let coords: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64])
            .collect();
        let quads: [[u32; 4]; 6] = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut tris = Vec::new();
        for q in quads {
            let (a, b) = ([q[0], q[1], q[2]], [q[0], q[2], q[3]]);
            for mut t in [a, b] {
                if inward {
                    t.swap(1, 2);
                }
                tris.push(t);
            }
        }
        let raw = RawMesh {
            face_patch: vec![0; tris.len()],
            positions: coords,
            triangles: tris,
            patch_names: vec!["body".into()],
            uv: None,
        };
        Mesh::new(raw).unwrap().0
    }

    #[test]
    fn signed_distance_of_a_cube_either_way_round() {
        for inward in [false, true] {
            let (body, warnings) = Body::new(&cube(inward));
            assert_eq!(warnings.len(), usize::from(inward), "{warnings:?}");
            // Face, edge and corner regions, outside and inside.
            let cases = [
                ([0.5, 0.5, 1.5], 0.5),
                ([0.5, 0.5, 0.75], -0.25),
                ([1.5, 1.5, 0.5], 0.5f64.hypot(0.5)),
                ([2.0, 2.0, 2.0], 3f64.sqrt()),
                ([0.9, 0.9, 0.9], -0.1),
                ([1.0, 1.0, 0.5], 0.0),
            ];
            for (p, want) in cases {
                let c = body.clearance(p);
                assert!((c.signed - want).abs() < 1e-12, "{p:?}: {c:?} want {want}");
                assert!((dot(c.gradient, c.gradient) - 1.0).abs() < 1e-12);
            }
            // The gradient is the derivative of the signed distance.
            let p = [1.3, 0.4, 1.2];
            let c = body.clearance(p);
            let h = 1e-6;
            for k in 0..3 {
                let (mut a, mut b) = (p, p);
                a[k] += h;
                b[k] -= h;
                let fd = (body.clearance(a).signed - body.clearance(b).signed) / (2.0 * h);
                assert!((fd - c.gradient[k]).abs() < 1e-6, "{k}: {fd} vs {c:?}");
            }
        }
    }
}
