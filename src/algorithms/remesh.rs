//! Mending by connectivity what moving vertices could not: the folds and slivers an optimiser
//! left in a flattenable mesh after `unfold` (issue 12: "no output has more folds than its
//! input; no corner angle below the stated minimum unless the input had one").
//!
//! What is left after `unfold` is mostly not a shape but a bad choice of edges (measured on
//! GarmentTransfer's shirt and t-shirt, diffavatar_tshirt and pf_robert_shirt_14, issue 12
//! note of 2026-11-27):
//! - a cap, a face with a corner near 180° (165.8°/13.8°/0.46°): its long edge is the wrong
//!   diagonal of the quad it forms with its neighbour, and flipping it makes two fair faces;
//! - a needle, two vertices nearly coincident (0.024°/70.8°/109.2°): no flip helps; collapsing
//!   the short edge does;
//! - a fold whose two faces overlap: flipping its edge takes the other diagonal.
//!
//! Each target gets one operation, taken only if it makes its neighbourhood better by
//! (folds, faces with a corner below the minimum, then the smallest corner): every edge of
//! the faces it touches is counted, so it never trades a fold here for one next door. On a
//! crumpled spot every way of removing a sliver folds an edge before θ is solved again
//! (mh_female_casualsuit02), so the caller may ask for slivers first (`slivers_first`) and
//! judge the whole mesh after the re-solve. The
//! angle sums of the four (flip) or the fan's (collapse) vertices change, so the caller
//! re-solves θ = 2π from the result (`fl_mesh`; a few iterations, as the surface is already
//! flattenable elsewhere).
//!
//! Invariants: boundary and seam vertices never move, a seam edge is never flipped, only
//! vertices the caller lets move are removed, and a collapse keeps the link condition (the two
//! endpoints share exactly the two opposite vertices), so the surface stays a manifold with
//! the same Euler characteristic. Vertex numbering is kept: a removed vertex stays in the
//! vertex list, unreferenced, at the position of the vertex it was merged into (the callers'
//! "input vertex i is output vertex i" holds). Texture coordinates are dropped, as
//! refinement does: the faces they were given for are gone.

use crate::geometry::{corner_angle, normalize, FOLD_ANGLE};
use crate::mesh::{cross, dot, is_degenerate_triangle, sub, Mesh, RawMesh, VertexKind};
use serde::Serialize;

/// Most faces around any vertex an operation touches (a regular mesh has 6): a sliver at a hub
/// of thousands of faces is left alone rather than scored in time quadratic in its fan.
const MAX_FAN: usize = 32;

/// What to mend.
#[derive(Debug, Clone, Copy)]
pub struct Task<'a> {
    /// Folded edges to open, as vertex pairs.
    pub folds: &'a [[u32; 2]],
    /// Faces with a corner below `min_corner`, as vertex triples.
    pub slivers: &'a [[u32; 3]],
    /// Vertices a collapse may remove or move (free interior vertices).
    pub movable: &'a [bool],
    /// The smallest corner wanted, radians.
    pub min_corner: f64,
    /// Judge every operation by slivers first, folds second: a fold that removing a sliver
    /// makes may still open when θ = 2π is solved again, which the caller then judges on the
    /// whole mesh.
    pub slivers_first: bool,
}

/// What mending did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Edges flipped.
    pub flips: usize,
    /// Edges collapsed.
    pub collapses: usize,
    /// Each collapse as [removed, kept]: the removed vertex is unreferenced from then on.
    pub merged: Vec<[u32; 2]>,
}

/// A mended mesh (same vertex count; see the module doc) and what was done.
#[derive(Debug, Clone)]
pub struct Mended {
    /// The mesh.
    pub mesh: Mesh,
    /// The operations.
    pub summary: Summary,
}

/// Flip or collapse where that improves each target's neighbourhood; `None` when nothing
/// could be improved (or the result would not be a valid mesh, which the checks above should
/// exclude).
pub fn mend(mesh: &Mesh, task: &Task<'_>) -> Option<Mended> {
    let mut soup = Soup::new(mesh, task);
    let mut summary = Summary::default();
    for &[a, b] in task.folds {
        if soup.flip(a, b, task.slivers_first) {
            summary.flips += 1;
        }
    }
    for &t in task.slivers {
        match soup.sliver(t) {
            Some(Op::Flip) => summary.flips += 1,
            Some(Op::Collapse(removed, kept)) => {
                summary.collapses += 1;
                summary.merged.push([removed, kept]);
            }
            None => {}
        }
    }
    if summary.flips + summary.collapses == 0 {
        return None;
    }
    let raw = soup.into_raw(mesh);
    let (mended, warnings) = Mesh::new(raw).ok()?;
    // Anything repaired on the way in (orientation, bow ties, patches) would mean the
    // operations broke the surface: refuse rather than pass it on.
    if warnings.iter().any(|w| w.code != "unreferenced_vertices") {
        return None;
    }
    Some(Mended {
        mesh: mended,
        summary,
    })
}

enum Op {
    Flip,
    /// [removed, kept].
    Collapse(u32, u32),
}

/// The local score: folds, slivers, then minus the smallest corner (lower is better).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Score {
    folds: usize,
    slivers: usize,
    smallest: f64,
}

impl Score {
    fn better_than(&self, other: &Score, slivers_first: bool) -> bool {
        let key = |s: &Score| {
            if slivers_first {
                (s.slivers, s.folds)
            } else {
                (s.folds, s.slivers)
            }
        };
        key(self) < key(other) || (key(self) == key(other) && self.smallest > other.smallest)
    }
}

/// A triangle soup with vertex-to-face lists that flips and collapses edit in place.
struct Soup<'a> {
    pos: Vec<[f64; 3]>,
    tris: Vec<[u32; 3]>,
    alive: Vec<bool>,
    patch: Vec<u32>,
    /// Faces of each vertex (dead ones pruned as they die).
    vf: Vec<Vec<u32>>,
    interior: Vec<bool>,
    task: &'a Task<'a>,
}

impl<'a> Soup<'a> {
    fn new(mesh: &Mesh, task: &'a Task<'a>) -> Self {
        let tris = mesh.triangles().to_vec();
        let mut vf = vec![Vec::new(); mesh.num_vertices()];
        for (f, t) in tris.iter().enumerate() {
            for &v in t {
                vf[v as usize].push(f as u32);
            }
        }
        let interior = mesh
            .conn()
            .kinds()
            .iter()
            .map(|k| *k == VertexKind::Interior)
            .collect();
        Soup {
            pos: mesh.positions().to_vec(),
            alive: vec![true; tris.len()],
            patch: mesh.face_patch().to_vec(),
            tris,
            vf,
            interior,
            task,
        }
    }

    fn into_raw(self, mesh: &Mesh) -> RawMesh {
        let keep = |f: &usize| self.alive[*f];
        RawMesh {
            triangles: (0..self.tris.len())
                .filter(keep)
                .map(|f| self.tris[f])
                .collect(),
            face_patch: (0..self.tris.len())
                .filter(keep)
                .map(|f| self.patch[f])
                .collect(),
            positions: self.pos,
            patch_names: mesh.patch_names().to_vec(),
            uv: None,
        }
    }

    fn faces_of_edge(&self, a: u32, b: u32) -> Vec<u32> {
        self.vf[a as usize]
            .iter()
            .copied()
            .filter(|&f| self.tris[f as usize].contains(&b))
            .collect()
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self.vf[v as usize]
            .iter()
            .flat_map(|&f| self.tris[f as usize])
            .filter(|&x| x != v)
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    fn corners(&self, t: [u32; 3]) -> [f64; 3] {
        let p = t.map(|v| self.pos[v as usize]);
        [0, 1, 2].map(|k| corner_angle(p[k], p[(k + 1) % 3], p[(k + 2) % 3]))
    }

    fn normal(&self, f: u32) -> [f64; 3] {
        let [a, b, c] = self.tris[f as usize].map(|v| self.pos[v as usize]);
        normalize(cross(sub(b, a), sub(c, a)))
    }

    fn degenerate(&self, f: u32) -> bool {
        let [a, b, c] = self.tris[f as usize].map(|v| self.pos[v as usize]);
        is_degenerate_triangle(a, b, c)
    }

    /// Folds on every edge of `faces` (each edge once), slivers among `faces` and their
    /// smallest corner.
    fn score(&self, faces: &[u32]) -> Score {
        let limit = FOLD_ANGLE.cos();
        let mut seen: Vec<[u32; 2]> = Vec::new();
        let mut folds = 0;
        let mut slivers = 0;
        let mut smallest = f64::INFINITY;
        for &f in faces {
            let t = self.tris[f as usize];
            let least = self.corners(t).into_iter().fold(f64::INFINITY, f64::min);
            smallest = smallest.min(least);
            if least < self.task.min_corner {
                slivers += 1;
            }
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = [a.min(b), a.max(b)];
                if seen.contains(&key) {
                    continue;
                }
                seen.push(key);
                let pair = self.faces_of_edge(a, b);
                if pair.len() == 2 && dot(self.normal(pair[0]), self.normal(pair[1])) < limit {
                    folds += 1;
                }
            }
        }
        Score {
            folds,
            slivers,
            smallest,
        }
    }

    /// More than [`MAX_FAN`] faces around `v`.
    fn hub(&self, v: u32) -> bool {
        self.vf[v as usize].len() > MAX_FAN
    }

    /// Faces a vertex must keep: three around an interior one, one at a boundary or seam.
    fn can_lose_a_face(&self, v: u32) -> bool {
        let need = if self.interior[v as usize] { 4 } else { 2 };
        self.vf[v as usize].len() >= need
    }

    /// Flip edge (a, b) if both its faces are in one patch and the flip improves their score
    /// (folds on every edge of the two faces, then slivers, or slivers first).
    fn flip(&mut self, a: u32, b: u32, slivers_first: bool) -> bool {
        if self.hub(a) || self.hub(b) {
            return false;
        }
        let fs = self.faces_of_edge(a, b);
        let [f1, f2] = fs[..] else { return false };
        if self.patch[f1 as usize] != self.patch[f2 as usize] {
            return false;
        }
        let t1 = self.tris[f1 as usize];
        let t2 = self.tris[f2 as usize];
        // Orient: t1 = (a, b, c) and t2 = (b, a, d) up to rotation.
        let rot = |t: [u32; 3], x: u32| {
            let i = t.iter().position(|&v| v == x).unwrap_or(0);
            [t[i], t[(i + 1) % 3], t[(i + 2) % 3]]
        };
        let (t1, t2, f1, f2) = if rot(t1, a)[1] == b {
            (t1, t2, f1, f2)
        } else {
            (t2, t1, f2, f1)
        };
        let r1 = rot(t1, a);
        let r2 = rot(t2, b);
        if r1[1] != b || r2[1] != a {
            return false;
        }
        let (c, d) = (r1[2], r2[2]);
        if c == d
            || self.hub(c)
            || self.hub(d)
            || !self.faces_of_edge(c, d).is_empty()
            || !self.can_lose_a_face(a)
            || !self.can_lose_a_face(b)
        {
            return false;
        }
        let before = self.score(&[f1, f2]);
        self.tris[f1 as usize] = [a, d, c];
        self.tris[f2 as usize] = [d, b, c];
        self.vf[b as usize].retain(|&f| f != f1);
        self.vf[a as usize].retain(|&f| f != f2);
        self.vf[d as usize].push(f1);
        self.vf[c as usize].push(f2);
        let ok = !self.degenerate(f1)
            && !self.degenerate(f2)
            && self.score(&[f1, f2]).better_than(&before, slivers_first);
        if !ok {
            self.tris[f1 as usize] = t1;
            self.tris[f2 as usize] = t2;
            self.vf[b as usize].push(f1);
            self.vf[a as usize].push(f2);
            self.vf[d as usize].retain(|&f| f != f1);
            self.vf[c as usize].retain(|&f| f != f2);
        }
        ok
    }

    /// Merge `w` into `u` (u moves to the midpoint if it may move, else stays) if the link
    /// condition holds, no face turns over and the fans' score improves.
    fn collapse(&mut self, w: u32, u: u32, slivers_first: bool) -> bool {
        if !self.task.movable[w as usize] || !self.interior[w as usize] {
            return false;
        }
        if self.hub(u) || self.hub(w) {
            return false;
        }
        let fs = self.faces_of_edge(u, w);
        let [g1, g2] = fs[..] else { return false };
        let other = |f: u32| {
            self.tris[f as usize]
                .into_iter()
                .find(|&x| x != u && x != w)
                .unwrap_or(u)
        };
        let (c, d) = (other(g1), other(g2));
        if self.hub(c) || self.hub(d) {
            return false;
        }
        let mut common: Vec<u32> = self.neighbours(u);
        let nw = self.neighbours(w);
        common.retain(|x| nw.contains(x));
        if common.len() != 2
            || !common.contains(&c)
            || !common.contains(&d)
            || !self.can_lose_a_face(c)
            || !self.can_lose_a_face(d)
        {
            return false;
        }
        let mut region: Vec<u32> = self.vf[u as usize].clone();
        region.extend(self.vf[w as usize].iter().copied());
        region.sort_unstable();
        region.dedup();
        let before = self.score(&region);
        let normals: Vec<[f64; 3]> = region.iter().map(|&f| self.normal(f)).collect();
        let saved_tris: Vec<[u32; 3]> = region.iter().map(|&f| self.tris[f as usize]).collect();
        let saved_vf = [u, w, c, d].map(|v| self.vf[v as usize].clone());
        let saved_pos = [self.pos[u as usize], self.pos[w as usize]];
        // Apply.
        if self.task.movable[u as usize] {
            let (p, q) = (self.pos[u as usize], self.pos[w as usize]);
            self.pos[u as usize] = [0, 1, 2].map(|k| 0.5 * (p[k] + q[k]));
        }
        self.pos[w as usize] = self.pos[u as usize];
        for g in [g1, g2] {
            self.alive[g as usize] = false;
        }
        let moved: Vec<u32> = self.vf[w as usize]
            .iter()
            .copied()
            .filter(|&f| f != g1 && f != g2)
            .collect();
        for &f in &moved {
            for x in self.tris[f as usize].iter_mut() {
                if *x == w {
                    *x = u;
                }
            }
        }
        self.vf[w as usize].clear();
        self.vf[u as usize].retain(|&f| f != g1 && f != g2);
        self.vf[u as usize].extend(moved.iter().copied());
        self.vf[c as usize].retain(|&f| f != g1 && f != g2);
        self.vf[d as usize].retain(|&f| f != g1 && f != g2);
        let after: Vec<u32> = region
            .iter()
            .copied()
            .filter(|&f| f != g1 && f != g2)
            .collect();
        let kept_shape = region.iter().zip(&normals).all(|(&f, n)| {
            !self.alive[f as usize] || (!self.degenerate(f) && dot(self.normal(f), *n) > 0.0)
        });
        let ok = kept_shape && self.score(&after).better_than(&before, slivers_first);
        if !ok {
            for (&f, t) in region.iter().zip(saved_tris) {
                self.tris[f as usize] = t;
            }
            for g in [g1, g2] {
                self.alive[g as usize] = true;
            }
            for (v, list) in [u, w, c, d].into_iter().zip(saved_vf) {
                self.vf[v as usize] = list;
            }
            self.pos[u as usize] = saved_pos[0];
            self.pos[w as usize] = saved_pos[1];
        }
        ok
    }

    /// One operation on a sliver still present as it was: a cap (a corner of 120° or more)
    /// flips its long edge first, a needle collapses its short edge first; then the other.
    fn sliver(&mut self, t: [u32; 3]) -> Option<Op> {
        let least = *t.iter().min_by_key(|&&v| self.vf[v as usize].len())?;
        let f = *self.vf[least as usize].iter().find(|&&f| {
            let s = self.tris[f as usize];
            t.iter().all(|v| s.contains(v))
        })?;
        let t = self.tris[f as usize];
        let angles = self.corners(t);
        let arg = |better: fn(f64, f64) -> bool| {
            (0..3).fold(0, |i, k| if better(angles[k], angles[i]) { k } else { i })
        };
        let (big, small) = (arg(|x, y| x > y), arg(|x, y| x < y));
        let long = (t[(big + 1) % 3], t[(big + 2) % 3]);
        let short = (t[(small + 1) % 3], t[(small + 2) % 3]);
        let cap = angles[big] >= FOLD_ANGLE;
        let first = self.task.slivers_first;
        let try_flip = |s: &mut Self| s.flip(long.0, long.1, first).then_some(Op::Flip);
        let try_collapse = |s: &mut Self| {
            let (p, q) = short;
            if s.collapse(q, p, first) {
                Some(Op::Collapse(q, p))
            } else if s.collapse(p, q, first) {
                Some(Op::Collapse(p, q))
            } else {
                None
            }
        };
        if cap {
            try_flip(self).or_else(|| try_collapse(self))
        } else {
            try_collapse(self).or_else(|| try_flip(self))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh::new(RawMesh {
            positions,
            triangles,
            ..RawMesh::default()
        })
        .expect("valid")
        .0
    }

    /// A flat quad cut by its long diagonal into a cap (corner ≈ 178°) and a fair face:
    /// the flip takes the short diagonal and every corner rises above the minimum.
    #[test]
    fn a_cap_is_mended_by_flipping_its_long_edge() {
        // Vertex 1 lies 0.01 off the segment 0-2, so face (0, 1, 2) has a corner of ~179°.
        let m = mesh(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.98, 0.0],
                [2.0, 2.0, 0.0],
                [-1.0, 3.0, 0.0],
                [3.0, -1.0, 0.0],
            ],
            // (0, 1, 2) is the cap, (0, 2, 3) the face across its long edge 0-2.
            vec![[0, 4, 1], [4, 2, 1], [0, 1, 2], [0, 2, 3]],
        );
        let movable = vec![false; 5];
        let before = crate::geometry::smallest_corner(&m);
        assert!(before < 2f64.to_radians());
        let task = Task {
            folds: &[],
            slivers: &[[0, 1, 2]],
            movable: &movable,
            min_corner: 2f64.to_radians(),
            slivers_first: false,
        };
        let done = mend(&m, &task).expect("a flip");
        assert_eq!((done.summary.flips, done.summary.collapses), (1, 0));
        // Every position bit-identical (a flip moves nothing), the same number of faces.
        assert_eq!(done.mesh.positions(), m.positions());
        assert_eq!(done.mesh.num_faces(), m.num_faces());
        assert!(crate::geometry::smallest_corner(&done.mesh) > before);
    }

    /// A hexagon fan whose centre is split into two interior vertices 2·10⁻³ apart: two
    /// needles. Collapsing their short edge leaves the regular fan, the removed vertex
    /// unreferenced at the kept one's position.
    #[test]
    fn a_needle_is_mended_by_collapsing_its_short_edge() {
        let e = 1e-3;
        let ring = |k: usize| {
            let a = k as f64 * std::f64::consts::PI / 3.0;
            [a.cos(), a.sin(), 0.0]
        };
        let mut positions: Vec<[f64; 3]> = (0..6).map(ring).collect();
        positions.push([-e, 0.0, 0.0]); // u = 6
        positions.push([e, 0.0, 0.0]); // w = 7
        let (u, w) = (6, 7);
        let m = mesh(
            positions,
            vec![
                [w, 0, 1],
                [u, w, 1],
                [u, 1, 2],
                [u, 2, 3],
                [u, 3, 4],
                [u, 4, w],
                [w, 4, 5],
                [w, 5, 0],
            ],
        );
        let movable: Vec<bool> = (0..8).map(|v| v >= 6).collect();
        let task = Task {
            folds: &[],
            slivers: &[[u, w, 1], [u, 4, w]],
            movable: &movable,
            min_corner: 2f64.to_radians(),
            slivers_first: false,
        };
        let done = mend(&m, &task).expect("a collapse");
        assert_eq!((done.summary.flips, done.summary.collapses), (0, 1));
        let [removed, kept] = done.summary.merged[0];
        assert_eq!([removed.min(kept), removed.max(kept)], [u, w]);
        let out = &done.mesh;
        assert_eq!(out.num_vertices(), 8);
        assert_eq!(out.num_faces(), 6);
        assert!(out.triangles().iter().all(|t| !t.contains(&removed)));
        assert_eq!(out.position(removed), out.position(kept));
        assert!(out.position(kept).iter().all(|x| x.abs() < 1e-15));
        let smallest = crate::geometry::smallest_corner(out).to_degrees();
        assert!((smallest - 60.0).abs() < 1e-9, "{smallest}");
        // The boundary is untouched.
        assert_eq!(&out.positions()[..6], &m.positions()[..6]);
    }

    /// Nothing to gain, nothing done: a fair fan's faces given as targets come back `None`.
    #[test]
    fn a_fair_mesh_is_left_alone() {
        let mut positions: Vec<[f64; 3]> = (0..6)
            .map(|k| {
                let a = k as f64 * std::f64::consts::PI / 3.0;
                [a.cos(), a.sin(), 0.0]
            })
            .collect();
        positions.push([0.0, 0.0, 0.0]);
        let triangles: Vec<[u32; 3]> = (0..6).map(|k| [6, k, (k + 1) % 6]).collect();
        let m = mesh(positions, triangles.clone());
        let movable: Vec<bool> = (0..7).map(|v| v == 6).collect();
        let task = Task {
            folds: &[[6, 0]],
            slivers: &[triangles[0]],
            movable: &movable,
            min_corner: 2f64.to_radians(),
            slivers_first: false,
        };
        assert!(mend(&m, &task).is_none());
    }

    /// A disk of 20000 thin faces around one hub, every one a sliver: the hub's fan is too
    /// large to score, so nothing is done (rather than work quadratic in the fan).
    #[test]
    fn a_hub_is_left_alone() {
        let k = 20_000u32;
        let mut positions = vec![[0.0, 0.0, 0.0]];
        positions.extend((0..k).map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / f64::from(k);
            [a.cos(), a.sin(), 0.0]
        }));
        let triangles: Vec<[u32; 3]> = (0..k).map(|i| [0, 1 + i, 1 + (i + 1) % k]).collect();
        let m = mesh(positions, triangles.clone());
        let movable = vec![false; m.num_vertices()];
        let task = Task {
            folds: &[],
            slivers: &triangles,
            movable: &movable,
            min_corner: 2f64.to_radians(),
            slivers_first: false,
        };
        assert!(mend(&m, &task).is_none());
    }

    /// A random height-field grid, some vertices pulled next to a neighbour (needles) or onto
    /// the middle of an opposite edge (caps), each quad cut along a random diagonal.
    fn crumpled_grid(n: usize, seed: u64) -> Option<Mesh> {
        let mut state = seed | 1;
        let mut rand = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let id = |i: usize, j: usize| (i * n + j) as u32;
        let mut pos: Vec<[f64; 3]> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k / n) as f64, (k % n) as f64);
                [
                    i + 0.3 * (rand() - 0.5),
                    j + 0.3 * (rand() - 0.5),
                    1.5 * (rand() - 0.5),
                ]
            })
            .collect();
        let mut tris = Vec::new();
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if rand() < 0.5 {
                    tris.extend([[a, b, c], [a, c, d]]);
                } else {
                    tris.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        for i in 1..n - 1 {
            for j in 1..n - 1 {
                let v = id(i, j) as usize;
                let r = rand();
                if r < 0.15 {
                    // A needle: next to its right neighbour.
                    let w = pos[id(i + 1, j) as usize];
                    let t = 1e-3 * rand();
                    pos[v] = [0, 1, 2].map(|k| w[k] + t * (pos[v][k] - w[k]) + 1e-4);
                } else if r < 0.3 {
                    // A cap: near the middle of its two neighbours along j.
                    let (p, q) = (pos[id(i, j - 1) as usize], pos[id(i, j + 1) as usize]);
                    pos[v] = [0, 1, 2].map(|k| 0.5 * (p[k] + q[k]) + 2e-3 * (rand() - 0.5));
                }
            }
        }
        Mesh::new(RawMesh {
            positions: pos,
            triangles: tris,
            ..RawMesh::default()
        })
        .ok()
        .map(|(m, _)| m)
    }

    fn euler(m: &Mesh) -> i64 {
        let v = m.conn().referenced_vertices().count() as i64;
        v - m.conn().edges().len() as i64 + m.num_faces() as i64
    }

    /// The targets of a crumpled grid: every fold and every face with a corner below 10°.
    fn targets(m: &Mesh) -> (Vec<[u32; 2]>, Vec<[u32; 3]>, Vec<bool>) {
        let edges = m.conn().edges();
        let folds = crate::geometry::fold_edges(m)
            .into_iter()
            .map(|e| edges[e as usize])
            .collect();
        let small = crate::geometry::min_corner_angles(m);
        let slivers = (0..m.num_faces())
            .filter(|&f| small[f] < 10f64.to_radians())
            .map(|f| m.triangles()[f])
            .collect();
        let movable = (0..m.num_vertices() as u32)
            .map(|v| m.conn().is_interior(v))
            .collect();
        (folds, slivers, movable)
    }

    /// The property below is not vacuous: on 40 crumpled grids mending flips and collapses
    /// (measured: 38 of 40 mended, 54 flips and 88 collapses).
    #[test]
    fn crumpled_grids_get_flips_and_collapses() {
        let (mut meshes, mut mended, mut flips, mut collapses) = (0, 0, 0, 0);
        for seed in 1..=40u64 {
            let Some(m) = crumpled_grid(7, seed * 7919) else {
                continue;
            };
            meshes += 1;
            let (folds, slivers, movable) = targets(&m);
            let task = Task {
                folds: &folds,
                slivers: &slivers,
                movable: &movable,
                min_corner: 10f64.to_radians(),
                slivers_first: false,
            };
            if let Some(done) = mend(&m, &task) {
                mended += 1;
                flips += done.summary.flips;
                collapses += done.summary.collapses;
            }
        }
        eprintln!("{mended} of {meshes} mended: {flips} flips, {collapses} collapses");
        assert!(
            meshes >= 35 && 4 * mended >= 3 * meshes,
            "{mended} of {meshes} mended"
        );
        assert!(
            flips >= 30 && collapses >= 40,
            "{flips} flips, {collapses} collapses"
        );
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// On random crumpled grids with every fold and sliver (a corner below 10°) as a
        /// target: the mended mesh keeps its vertex numbering and Euler characteristic, its
        /// boundary bit-identical, removes only interior vertices (each left unreferenced on a
        /// surviving vertex), loses two faces per collapse, and never has more folds (in
        /// strict mode) or more slivers (slivers first) than it started with.
        #[test]
        fn mending_keeps_the_surface_and_never_adds_what_it_ranks_first(
            n in 4usize..9,
            seed in 1u64..u64::MAX,
            slivers_first in proptest::bool::ANY,
        ) {
            let Some(m) = crumpled_grid(n, seed) else { return Ok(()) };
            let min_corner = 10f64.to_radians();
            let (folds, slivers, movable) = targets(&m);
            let task = Task { folds: &folds, slivers: &slivers, movable: &movable, min_corner, slivers_first };
            let Some(done) = mend(&m, &task) else { return Ok(()) };
            let out = &done.mesh;
            let k = done.summary.collapses;
            proptest::prop_assert_eq!(out.num_vertices(), m.num_vertices());
            proptest::prop_assert_eq!(out.num_faces() + 2 * k, m.num_faces());
            proptest::prop_assert_eq!(
                out.conn().referenced_vertices().count() + k,
                m.conn().referenced_vertices().count()
            );
            proptest::prop_assert_eq!(euler(out), euler(&m));
            for v in 0..m.num_vertices() {
                if !m.conn().is_interior(v as u32) {
                    proptest::prop_assert_eq!(out.positions()[v], m.positions()[v]);
                }
            }
            for &[removed, kept] in &done.summary.merged {
                proptest::prop_assert!(m.conn().is_interior(removed));
                proptest::prop_assert!(out.triangles().iter().all(|t| !t.contains(&removed)));
                proptest::prop_assert!(kept != removed);
            }
            let count = |x: &Mesh| {
                let small = crate::geometry::min_corner_angles(x);
                (
                    crate::geometry::fold_edges(x).len(),
                    small.iter().filter(|&&a| a < min_corner).count(),
                )
            };
            let ((f0, s0), (f1, s1)) = (count(&m), count(out));
            if slivers_first {
                proptest::prop_assert!(s1 <= s0, "slivers {} -> {}", s0, s1);
            } else {
                proptest::prop_assert!(f1 <= f0, "folds {} -> {}", f0, f1);
            }
        }
    }
}
