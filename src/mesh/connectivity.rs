//! Connectivity of a validated triangle mesh, built once in O(n) (bucket sort by vertex).
//!
//! Half-edge `c = 3f + i` runs from `t[f][i]` to `t[f][(i+1)%3]`. Each vertex's fan is stored
//! counter-clockwise (seen from the front, i.e. consistent with face orientation) as a list
//! of half-edges leaving the vertex; a boundary vertex's fan starts at its boundary edge, so
//! its neighbours run from one boundary neighbour round to the other.

use super::{MeshError, Warning};

/// Marks a missing half-edge (boundary) or face.
pub const NONE: u32 = u32::MAX;

/// Where a vertex sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VertexKind {
    /// No face uses it; ignored by every measure.
    Unreferenced,
    /// Its fan is open: it lies on the mesh's free boundary.
    Boundary,
    /// Its fan is closed but spans several patches: it lies on a seam.
    Seam,
    /// Its closed fan lies in one patch: an interior vertex, where ϖ is defined.
    Interior,
}

/// Per-patch connectivity summary.
#[derive(Debug, Clone)]
pub struct PatchTopology {
    /// Faces of the patch, ascending.
    pub faces: Vec<u32>,
    /// Number of distinct vertices used by the patch.
    pub vertices: usize,
    /// Number of distinct edges of the patch (a seam edge counts once for each patch).
    pub edges: usize,
    /// Number of the patch's interior vertices.
    pub interior_vertices: usize,
    /// Ordered boundary loops of the patch (free boundary and seams), each a cycle of
    /// vertices traversed with the patch on the left (counter-clockwise around the patch).
    pub boundary_loops: Vec<Vec<u32>>,
}

impl PatchTopology {
    /// Euler characteristic V − E + F of the patch.
    pub fn euler_characteristic(&self) -> i64 {
        self.vertices as i64 - self.edges as i64 + self.faces.len() as i64
    }
}

/// Immutable connectivity: twins, edges, ordered fans, boundary loops, patches.
#[derive(Debug, Clone)]
pub struct Connectivity {
    num_vertices: usize,
    twin: Vec<u32>,
    he_edge: Vec<u32>,
    edges: Vec<[u32; 2]>,
    edge_faces: Vec<[u32; 2]>,
    fan_off: Vec<u32>,
    fan: Vec<u32>,
    ring_off: Vec<u32>,
    ring: Vec<u32>,
    kind: Vec<VertexKind>,
    boundary_loops: Vec<Vec<u32>>,
    patches: Vec<PatchTopology>,
    shared: Vec<u32>,
    face_patch: Vec<u32>,
}

#[inline]
fn next(c: u32) -> u32 {
    if c % 3 == 2 {
        c - 2
    } else {
        c + 1
    }
}
#[inline]
fn prev(c: u32) -> u32 {
    if c % 3 == 0 {
        c + 2
    } else {
        c - 1
    }
}

/// Half-edges grouped by undirected edge: `(key, half-edge)` sorted by key, built by bucketing
/// on the lower vertex and sorting each (small) bucket.
fn group_half_edges(nv: usize, tris: &[[u32; 3]]) -> Vec<(u32, u32, u32)> {
    let nh = tris.len() * 3;
    let mut count = vec![0u32; nv + 1];
    for t in tris {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            count[a.min(b) as usize + 1] += 1;
        }
    }
    for i in 0..nv {
        count[i + 1] += count[i];
    }
    let mut fill = count.clone();
    let mut out = vec![(0u32, 0u32, 0u32); nh];
    for (f, t) in tris.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            let lo = a.min(b);
            let slot = &mut fill[lo as usize];
            out[*slot as usize] = (lo, a.max(b), (3 * f + i) as u32);
            *slot += 1;
        }
    }
    for v in 0..nv {
        let s = &mut out[count[v] as usize..count[v + 1] as usize];
        if s.len() > 1 {
            s.sort_unstable_by_key(|e| (e.1, e.2));
        }
    }
    out
}

fn check_duplicates(nv: usize, tris: &[[u32; 3]]) -> Result<(), MeshError> {
    // Bucket faces by their smallest vertex, then compare sorted triples within a bucket.
    let mut count = vec![0u32; nv + 1];
    let key = |t: &[u32; 3]| {
        let mut s = *t;
        s.sort_unstable();
        s
    };
    for t in tris {
        count[key(t)[0] as usize + 1] += 1;
    }
    for i in 0..nv {
        count[i + 1] += count[i];
    }
    let mut fill = count.clone();
    let mut order = vec![(0u32, 0u32, 0u32); tris.len()];
    for (f, t) in tris.iter().enumerate() {
        let k = key(t);
        let slot = &mut fill[k[0] as usize];
        order[*slot as usize] = (k[1], k[2], f as u32);
        *slot += 1;
    }
    for v in 0..nv {
        let s = &mut order[count[v] as usize..count[v + 1] as usize];
        if s.len() > 1 {
            s.sort_unstable();
            for w in s.windows(2) {
                if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
                    return Err(MeshError::DuplicateFace {
                        face: w[1].2 as usize,
                        first: w[0].2 as usize,
                        vertices: tris[w[1].2 as usize],
                    });
                }
            }
        }
    }
    Ok(())
}

impl Connectivity {
    /// Build connectivity, repairing orientation of orientable components in place
    /// (`tris` may have faces flipped; a warning says which).
    pub(crate) fn build(
        nv: usize,
        tris: &mut [[u32; 3]],
        face_patch: &[u32],
        num_patches: usize,
        warnings: &mut Vec<Warning>,
    ) -> Result<Connectivity, MeshError> {
        check_duplicates(nv, tris)?;
        let mut groups = group_half_edges(nv, tris);
        let mut orientation_ok = true;
        let mut i = 0;
        while i < groups.len() {
            let mut j = i + 1;
            while j < groups.len() && groups[j].0 == groups[i].0 && groups[j].1 == groups[i].1 {
                j += 1;
            }
            if j - i > 2 {
                let mut faces: Vec<u32> = groups[i..j].iter().map(|g| g.2 / 3).collect();
                faces.sort_unstable();
                return Err(MeshError::NonManifoldEdge {
                    a: groups[i].0,
                    b: groups[i].1,
                    faces,
                });
            }
            if j - i == 2 {
                let (c0, c1) = (groups[i].2, groups[i + 1].2);
                let t0 = tris[c0 as usize / 3][c0 as usize % 3];
                let t1 = tris[c1 as usize / 3][c1 as usize % 3];
                if t0 == t1 {
                    orientation_ok = false;
                }
            }
            i = j;
        }
        if !orientation_ok {
            let flipped = orient(tris, &groups)?;
            let first: Vec<String> = flipped.iter().take(10).map(|f| f.to_string()).collect();
            warnings.push(Warning::new(
                "orientation_repaired",
                format!(
                    "{} faces were flipped to agree with their neighbours (faces {}{})",
                    flipped.len(),
                    first.join(", "),
                    if flipped.len() > 10 { ", …" } else { "" }
                ),
            ));
            groups = group_half_edges(nv, tris);
        }

        let nh = tris.len() * 3;
        let mut twin = vec![NONE; nh];
        let mut he_edge = vec![NONE; nh];
        let mut edges = Vec::with_capacity(nh / 2 + 1);
        let mut edge_faces = Vec::with_capacity(nh / 2 + 1);
        let mut i = 0;
        while i < groups.len() {
            let e = edges.len() as u32;
            edges.push([groups[i].0, groups[i].1]);
            let c0 = groups[i].2;
            he_edge[c0 as usize] = e;
            if i + 1 < groups.len()
                && groups[i + 1].0 == groups[i].0
                && groups[i + 1].1 == groups[i].1
            {
                let c1 = groups[i + 1].2;
                twin[c0 as usize] = c1;
                twin[c1 as usize] = c0;
                he_edge[c1 as usize] = e;
                edge_faces.push([c0 / 3, c1 / 3]);
                i += 2;
            } else {
                edge_faces.push([c0 / 3, NONE]);
                i += 1;
            }
        }
        drop(groups);

        // Outgoing half-edges of each vertex (CSR), then walk each fan counter-clockwise.
        let mut out_off = vec![0u32; nv + 1];
        for t in tris.iter() {
            for &v in t {
                out_off[v as usize + 1] += 1;
            }
        }
        for v in 0..nv {
            out_off[v + 1] += out_off[v];
        }
        let mut fill = out_off.clone();
        let mut out = vec![0u32; nh];
        for (f, t) in tris.iter().enumerate() {
            for (k, &v) in t.iter().enumerate() {
                out[fill[v as usize] as usize] = (3 * f + k) as u32;
                fill[v as usize] += 1;
            }
        }
        drop(fill);
        let head = |c: u32| tris[c as usize / 3][(c as usize % 3 + 1) % 3];
        let tail = |c: u32| tris[c as usize / 3][c as usize % 3];

        let mut fan = Vec::with_capacity(nh);
        let mut ring_off = Vec::with_capacity(nv + 1);
        let mut ring = Vec::with_capacity(nh + nv);
        let mut kind = vec![VertexKind::Unreferenced; nv];
        ring_off.push(0u32);
        for v in 0..nv {
            let outs = &out[out_off[v] as usize..out_off[v + 1] as usize];
            if outs.is_empty() {
                ring_off.push(ring.len() as u32);
                continue;
            }
            let start = outs
                .iter()
                .copied()
                .find(|&h| twin[h as usize] == NONE)
                .unwrap_or(outs[0]);
            let open = twin[start as usize] == NONE;
            let fan_start = fan.len();
            let mut h = start;
            loop {
                fan.push(h);
                ring.push(head(h));
                let p = prev(h);
                let t = twin[p as usize];
                if t == NONE {
                    ring.push(tail(p));
                    break;
                }
                if t == start || fan.len() - fan_start > outs.len() {
                    break;
                }
                h = t;
            }
            if fan.len() - fan_start != outs.len() {
                return Err(MeshError::NonManifoldVertex {
                    vertex: v as u32,
                    fans: count_fans(outs, &twin),
                });
            }
            kind[v] = if open {
                VertexKind::Boundary
            } else {
                let p0 = face_patch[start as usize / 3];
                if fan[fan_start..]
                    .iter()
                    .all(|&h| face_patch[h as usize / 3] == p0)
                {
                    VertexKind::Interior
                } else {
                    VertexKind::Seam
                }
            };
            ring_off.push(ring.len() as u32);
        }
        // Each vertex's fan has as many half-edges as its outgoing list: same CSR layout.
        let fan_off = out_off;

        let mut conn = Connectivity {
            num_vertices: nv,
            twin,
            he_edge,
            edges,
            edge_faces,
            fan_off,
            fan,
            ring_off,
            ring,
            kind,
            boundary_loops: Vec::new(),
            patches: Vec::new(),
            shared: Vec::new(),
            face_patch: face_patch.to_vec(),
        };
        conn.boundary_loops = conn.loops(tris, |c| conn.twin[c as usize] == NONE);
        conn.build_patches(tris, num_patches);
        let unref = conn
            .kind
            .iter()
            .filter(|k| **k == VertexKind::Unreferenced)
            .count();
        if unref > 0 {
            let first: Vec<String> = (0..nv)
                .filter(|&v| conn.kind[v] == VertexKind::Unreferenced)
                .take(10)
                .map(|v| v.to_string())
                .collect();
            warnings.push(Warning::new(
                "unreferenced_vertices",
                format!(
                    "{unref} vertices are used by no face and are ignored (vertices {}{})",
                    first.join(", "),
                    if unref > 10 { ", …" } else { "" }
                ),
            ));
        }
        Ok(conn)
    }

    /// Cycles of half-edges selected by `is_boundary`, each as its vertices in order.
    fn loops(&self, tris: &[[u32; 3]], is_boundary: impl Fn(u32) -> bool) -> Vec<Vec<u32>> {
        let nh = tris.len() * 3;
        let mut seen = vec![false; nh];
        let mut loops = Vec::new();
        let tail = |c: u32| tris[c as usize / 3][c as usize % 3];
        for c0 in 0..nh as u32 {
            if seen[c0 as usize] || !is_boundary(c0) {
                continue;
            }
            let mut lp = Vec::new();
            let mut c = c0;
            while !seen[c as usize] {
                seen[c as usize] = true;
                lp.push(tail(c));
                // Rotate about the head vertex, staying inside the selected region, to the
                // next selected half-edge (terminates: fans are manifold).
                let mut n = next(c);
                let mut guard = 0usize;
                while !is_boundary(n) {
                    n = next(self.twin[n as usize]);
                    guard += 1;
                    if guard > nh {
                        break;
                    }
                }
                c = n;
            }
            loops.push(lp);
        }
        loops
    }

    fn build_patches(&mut self, tris: &[[u32; 3]], np: usize) {
        let fp = &self.face_patch;
        let mut patches: Vec<PatchTopology> = (0..np)
            .map(|_| PatchTopology {
                faces: Vec::new(),
                vertices: 0,
                edges: 0,
                interior_vertices: 0,
                boundary_loops: Vec::new(),
            })
            .collect();
        for (f, &p) in fp.iter().enumerate() {
            patches[p as usize].faces.push(f as u32);
        }
        // Vertex counts per patch, and vertices shared by several patches.
        let mut shared = Vec::new();
        let mut seen_patch: Vec<u32> = Vec::with_capacity(8);
        for v in 0..self.num_vertices {
            seen_patch.clear();
            for &h in self.fan_of(v as u32) {
                let p = fp[h as usize / 3];
                if !seen_patch.contains(&p) {
                    seen_patch.push(p);
                }
            }
            for &p in &seen_patch {
                patches[p as usize].vertices += 1;
            }
            if seen_patch.len() > 1 {
                shared.push(v as u32);
            }
            if self.kind[v] == VertexKind::Interior {
                patches[seen_patch[0] as usize].interior_vertices += 1;
            }
        }
        for (e, ef) in self.edge_faces.iter().enumerate() {
            let _ = e;
            let p0 = fp[ef[0] as usize];
            patches[p0 as usize].edges += 1;
            if ef[1] != NONE && fp[ef[1] as usize] != p0 {
                patches[fp[ef[1] as usize] as usize].edges += 1;
            }
        }
        let twin = &self.twin;
        let is_pb = |c: u32| {
            let t = twin[c as usize];
            t == NONE || fp[t as usize / 3] != fp[c as usize / 3]
        };
        for lp in self.loops(tris, is_pb) {
            // Every vertex of a loop is in the patch of the half-edge that starts the loop;
            // find it from the first half-edge of the loop.
            let v0 = lp[0];
            let v1 = lp[1 % lp.len()];
            let p = self
                .fan_of(v0)
                .iter()
                .find(|&&h| tris[h as usize / 3][(h as usize % 3 + 1) % 3] == v1 && is_pb(h))
                .map(|&h| fp[h as usize / 3])
                .unwrap_or(0);
            patches[p as usize].boundary_loops.push(lp);
        }
        self.patches = patches;
        self.shared = shared;
    }

    /// Number of vertices (including unreferenced ones).
    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }
    /// Twin of half-edge `c`, or [`NONE`] on the free boundary.
    #[inline]
    pub fn twin(&self, c: u32) -> u32 {
        self.twin[c as usize]
    }
    /// Undirected edges as `[lo, hi]` vertex pairs.
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }
    /// The one or two faces of each edge (`[f, NONE]` on the free boundary).
    pub fn edge_faces(&self) -> &[[u32; 2]] {
        &self.edge_faces
    }
    /// Edge index of half-edge `c`.
    #[inline]
    pub fn edge_of(&self, c: u32) -> u32 {
        self.he_edge[c as usize]
    }
    /// Half-edges leaving `v`, counter-clockwise; half-edge `h` lies in face `h / 3` with `v`
    /// at corner `h % 3`.
    #[inline]
    pub fn fan_of(&self, v: u32) -> &[u32] {
        &self.fan[self.fan_off[v as usize] as usize..self.fan_off[v as usize + 1] as usize]
    }
    /// Neighbours of `v` counter-clockwise (for a boundary vertex, from one boundary
    /// neighbour round to the other, so one more than its faces).
    #[inline]
    pub fn ring_of(&self, v: u32) -> &[u32] {
        &self.ring[self.ring_off[v as usize] as usize..self.ring_off[v as usize + 1] as usize]
    }
    /// Where vertex `v` sits.
    #[inline]
    pub fn kind(&self, v: u32) -> VertexKind {
        self.kind[v as usize]
    }
    /// Kinds of all vertices.
    pub fn kinds(&self) -> &[VertexKind] {
        &self.kind
    }
    /// Whether `v` is interior to its patch (closed fan, one patch): where ϖ is defined.
    #[inline]
    pub fn is_interior(&self, v: u32) -> bool {
        self.kind[v as usize] == VertexKind::Interior
    }
    /// Vertices used by at least one face.
    pub fn referenced_vertices(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.num_vertices as u32).filter(|&v| self.kind[v as usize] != VertexKind::Unreferenced)
    }
    /// Interior vertices, ascending.
    pub fn interior_vertices(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.num_vertices as u32).filter(|&v| self.kind[v as usize] == VertexKind::Interior)
    }
    /// Boundary loops of the whole mesh (free boundary only), interior on the left.
    pub fn boundary_loops(&self) -> &[Vec<u32>] {
        &self.boundary_loops
    }
    /// Per-patch topology.
    pub fn patches(&self) -> &[PatchTopology] {
        &self.patches
    }
    /// Vertices used by faces of more than one patch, ascending.
    pub fn shared_vertices(&self) -> &[u32] {
        &self.shared
    }
    /// Number of connected components (through shared edges).
    pub fn components(&self, num_faces: usize) -> usize {
        let mut sets = super::disjoint::DisjointSets::new(num_faces);
        for ef in &self.edge_faces {
            if ef[1] != NONE {
                sets.union(ef[0], ef[1]);
            }
        }
        (0..num_faces as u32).filter(|&f| sets.find(f) == f).count()
    }
}

fn count_fans(outs: &[u32], twin: &[u32]) -> usize {
    // Fans are chains of outgoing half-edges linked by twin(prev(h)); count chain starts
    // (open fans) and closed cycles.
    let mut seen = vec![false; outs.len()];
    // By hash, not by scanning: a vertex of a hostile file can have 10⁵ faces.
    let index: std::collections::HashMap<u32, usize> =
        outs.iter().enumerate().map(|(k, &h)| (h, k)).collect();
    let pos = |h: u32| index.get(&h).copied();
    let mut fans = 0;
    for s in 0..outs.len() {
        if seen[s] {
            continue;
        }
        fans += 1;
        // walk both ways
        let mut h = outs[s];
        seen[s] = true;
        for _ in 0..outs.len() {
            let t = twin[prev(h) as usize];
            match (t != NONE).then(|| pos(t)).flatten() {
                Some(k) if !seen[k] => {
                    seen[k] = true;
                    h = t;
                }
                _ => break,
            }
        }
        let mut h = outs[s];
        for _ in 0..outs.len() {
            let t = twin[h as usize];
            if t == NONE {
                break;
            }
            match pos(next(t)) {
                Some(k) if !seen[k] => {
                    seen[k] = true;
                    h = next(t);
                }
                _ => break,
            }
        }
    }
    fans
}

/// Orient every component consistently, flipping the minority of its faces. Returns the flipped
/// faces, or the edge where a non-orientable component fails.
fn orient(tris: &mut [[u32; 3]], groups: &[(u32, u32, u32)]) -> Result<Vec<u32>, MeshError> {
    let nf = tris.len();
    // Face adjacency through manifold edges: (neighbour, same_direction) for each corner.
    let mut adj = vec![(NONE, false); nf * 3];
    let mut i = 0;
    while i < groups.len() {
        if i + 1 < groups.len() && groups[i + 1].0 == groups[i].0 && groups[i + 1].1 == groups[i].1
        {
            let (c0, c1) = (groups[i].2 as usize, groups[i + 1].2 as usize);
            let same = tris[c0 / 3][c0 % 3] == tris[c1 / 3][c1 % 3];
            adj[c0] = ((c1 / 3) as u32, same);
            adj[c1] = ((c0 / 3) as u32, same);
            i += 2;
        } else {
            i += 1;
        }
    }
    let mut flip: Vec<Option<bool>> = vec![None; nf];
    let mut stack = Vec::new();
    for f0 in 0..nf {
        if flip[f0].is_some() {
            continue;
        }
        flip[f0] = Some(false);
        stack.push(f0);
        while let Some(f) = stack.pop() {
            let ff = flip[f].unwrap_or(false);
            for k in 0..3 {
                let (g, same) = adj[3 * f + k];
                if g == NONE {
                    continue;
                }
                let want = ff ^ same;
                match flip[g as usize] {
                    None => {
                        flip[g as usize] = Some(want);
                        stack.push(g as usize);
                    }
                    Some(x) if x != want => {
                        let (a, b) = (tris[f][k], tris[f][(k + 1) % 3]);
                        return Err(MeshError::NonOrientable {
                            a: a.min(b),
                            b: a.max(b),
                            f0: (f as u32).min(g),
                            f1: (f as u32).max(g),
                        });
                    }
                    _ => {}
                }
            }
        }
    }
    // Each component keeps the orientation most of its faces already have: flip the minority.
    let mut comp = vec![NONE; nf];
    let mut comp_flips: Vec<(usize, usize)> = Vec::new();
    for f0 in 0..nf {
        if comp[f0] != NONE {
            continue;
        }
        let id = comp_flips.len() as u32;
        let (mut total, mut flips) = (0usize, 0usize);
        comp[f0] = id;
        stack.push(f0);
        while let Some(f) = stack.pop() {
            total += 1;
            flips += usize::from(flip[f] == Some(true));
            for k in 0..3 {
                let g = adj[3 * f + k].0;
                if g != NONE && comp[g as usize] == NONE {
                    comp[g as usize] = id;
                    stack.push(g as usize);
                }
            }
        }
        comp_flips.push((total, flips));
    }
    let mut flipped = Vec::new();
    for f in 0..nf {
        let (total, flips) = comp_flips[comp[f] as usize];
        let invert = 2 * flips > total;
        if (flip[f] == Some(true)) != invert {
            tris[f].swap(1, 2);
            flipped.push(f as u32);
        }
    }
    Ok(flipped)
}
