//! Piece topology: one piece per connected component of a patch, its vertices split into
//! wedges (so a vertex where the patch touches itself becomes two 2D vertices), its boundary
//! loops, and the virtual cut of Sec. 3.2 (wang-lpfb): multi-source Dijkstra paths that join
//! every inner loop to the outer loop, and the cut disk P_d whose single boundary loop LPFB
//! lays out.

use super::super::AlgoError;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, HashSet};
use std::f64::consts::PI;

#[inline]
fn next(c: usize) -> usize {
    if c % 3 == 2 {
        c - 2
    } else {
        c + 1
    }
}

#[inline]
fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Wedges of a triangle list: corners are joined across every edge shared by two faces with
/// opposite orientation, unless `is_cut` says the edge is cut. Returns the wedge of each corner
/// (`3f + i`), the number of wedges, and whether each half-edge lies on the boundary of the
/// result (no twin, or cut).
pub(crate) fn wedges(
    tris: &[[u32; 3]],
    is_cut: impl Fn(u32, u32) -> bool,
) -> (Vec<u32>, usize, Vec<bool>) {
    let nh = tris.len() * 3;
    let he = half_edges_sorted(tris);
    let mut sets = crate::mesh::disjoint::DisjointSets::new(nh);
    let mut boundary = vec![true; nh];
    let mut i = 0;
    while i < he.len() {
        let mut j = i + 1;
        while j < he.len() && he[j].0 == he[i].0 && he[j].1 == he[i].1 {
            j += 1;
        }
        if j - i == 2 && !is_cut(he[i].0, he[i].1) {
            let (c, d) = (he[i].2 as usize, he[i + 1].2 as usize);
            let (fc, fd) = (c / 3, d / 3);
            // c runs a → b; d must run b → a (consistent orientation): then the corner of c
            // at a meets the corner after d, and the corner after c meets d's, at b.
            if tris[fc][c % 3] != tris[fd][d % 3] {
                sets.union(c as u32, next(d) as u32);
                sets.union(next(c) as u32, d as u32);
                boundary[c] = false;
                boundary[d] = false;
            }
        }
        i = j;
    }
    let mut class = vec![u32::MAX; nh];
    let mut root_class = vec![u32::MAX; nh];
    let mut n = 0u32;
    for (c, cl) in class.iter_mut().enumerate() {
        let r = sets.find(c as u32) as usize;
        if root_class[r] == u32::MAX {
            root_class[r] = n;
            n += 1;
        }
        *cl = root_class[r];
    }
    (class, n as usize, boundary)
}

/// Every half-edge as (lower vertex, higher vertex, corner `3f + i`), sorted: a counting sort
/// on the lower vertex, then each bucket (a vertex's few edges) by insertion (by a comparison
/// sort when a vertex has many). Segmentation
/// builds pieces for hundreds of candidate charts; a comparison sort of the tuples here was
/// 12 % of segmenting a 34k-face scan.
fn half_edges_sorted(tris: &[[u32; 3]]) -> Vec<(u32, u32, u32)> {
    let nv = tris
        .iter()
        .flatten()
        .map(|&v| v as usize + 1)
        .max()
        .unwrap_or(0);
    let mut start = vec![0u32; nv + 1];
    for t in tris {
        for i in 0..3 {
            start[t[i].min(t[(i + 1) % 3]) as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        start[v + 1] += start[v];
    }
    let mut he = vec![(0u32, 0u32, 0u32); tris.len() * 3];
    let mut fill = start.clone();
    for (f, t) in tris.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = key(t[i], t[(i + 1) % 3]);
            let slot = &mut fill[a as usize];
            he[*slot as usize] = (a, b, (3 * f + i) as u32);
            *slot += 1;
        }
    }
    for v in 0..nv {
        let bucket = &mut he[start[v] as usize..start[v + 1] as usize];
        if bucket.len() > 16 {
            // A high-valence vertex (a fan): no quadratic insertion sort.
            bucket.sort_unstable();
            continue;
        }
        for k in 1..bucket.len() {
            let mut j = k;
            while j > 0 && bucket[j - 1] > bucket[j] {
                bucket.swap(j - 1, j);
                j -= 1;
            }
        }
    }
    he
}

/// Boundary loops of a wedge split: cycles of wedges along boundary half-edges, surface on
/// the left. Each loop entry also records the half-edge leaving it.
pub(crate) fn walk_loops(
    class: &[u32],
    nclass: usize,
    boundary: &[bool],
) -> Result<Vec<Vec<(u32, u32)>>, String> {
    let mut out = vec![u32::MAX; nclass];
    for (c, &b) in boundary.iter().enumerate() {
        if b {
            let w = class[c] as usize;
            if out[w] != u32::MAX {
                return Err(format!(
                    "a vertex has two outgoing boundary edges (half-edges {} and {c})",
                    out[w]
                ));
            }
            out[w] = c as u32;
        }
    }
    let mut seen = vec![false; boundary.len()];
    let mut loops = Vec::new();
    for (c0, &b) in boundary.iter().enumerate() {
        if !b || seen[c0] {
            continue;
        }
        let mut lp = Vec::new();
        let mut c = c0;
        loop {
            if seen[c] {
                if c != c0 {
                    return Err("boundary walk did not close".into());
                }
                break;
            }
            seen[c] = true;
            lp.push((class[c], c as u32));
            let to = class[next(c)] as usize;
            let nc = out[to];
            if nc == u32::MAX {
                return Err("boundary walk reached a vertex with no outgoing edge".into());
            }
            c = nc as usize;
        }
        loops.push(lp);
    }
    Ok(loops)
}

/// One piece before flattening: a connected component of a patch with wedge-split vertices.
#[derive(Debug, Clone)]
pub struct Piece3 {
    /// Piece name (the patch name, `#k` appended when a patch has several components).
    pub name: String,
    /// Global face of each local triangle.
    pub faces: Vec<u32>,
    /// Global vertex of each local vertex.
    pub vertex_ids: Vec<u32>,
    /// 3D position of each local vertex.
    pub pos: Vec<[f64; 3]>,
    /// Local triangles.
    pub tris: Vec<[u32; 3]>,
    /// 3D corner angles of each local triangle, at its vertices in order (computed once:
    /// the cuts, the boundary angles and LPFB all need them).
    pub corners: Vec<[f64; 3]>,
    /// Boundary loops (local vertices, surface on the left); outer (longest in 3D) first.
    pub loops: Vec<Vec<u32>>,
}

pub(crate) fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

impl Piece3 {
    /// Build a piece from global faces. Fails, naming the piece, when it has genus > 0 (a
    /// closed piece has no boundary loop: [`plan_cuts`] cuts it open or refuses it).
    pub fn build(
        name: String,
        faces: Vec<u32>,
        all_tris: &[[u32; 3]],
        all_pos: &[[f64; 3]],
    ) -> Result<Piece3, AlgoError> {
        Self::build_cut(name, faces, all_tris, all_pos, &HashSet::new())
    }

    /// [`Piece3::build`], cut open along the edges in `cut` as well (global vertex pairs, lower
    /// id first): segmentation's dangling cuts inside a chart.
    pub(crate) fn build_cut(
        name: String,
        faces: Vec<u32>,
        all_tris: &[[u32; 3]],
        all_pos: &[[f64; 3]],
        cut: &HashSet<(u32, u32)>,
    ) -> Result<Piece3, AlgoError> {
        let gtris: Vec<[u32; 3]> = faces.iter().map(|&f| all_tris[f as usize]).collect();
        Self::from_triangles(name, faces, &gtris, |v| all_pos[v as usize], cut)
    }

    /// The same piece cut open along `paths` (local vertices): every path edge becomes two
    /// boundary edges, one per side.
    pub fn cut_open(&self, paths: &[Vec<u32>]) -> Result<Piece3, AlgoError> {
        let mut cut = HashSet::new();
        for path in paths {
            for w in path.windows(2) {
                let (a, b) = (
                    self.vertex_ids[w[0] as usize],
                    self.vertex_ids[w[1] as usize],
                );
                cut.insert(key(a, b));
            }
        }
        let gtris: Vec<[u32; 3]> = self
            .tris
            .iter()
            .map(|t| t.map(|w| self.vertex_ids[w as usize]))
            .collect();
        let mut pos_of = HashMap::new();
        for (w, &v) in self.vertex_ids.iter().enumerate() {
            pos_of.insert(v, self.pos[w]);
        }
        Self::from_triangles(
            self.name.clone(),
            self.faces.clone(),
            &gtris,
            |v| pos_of[&v],
            &cut,
        )
    }

    fn from_triangles(
        name: String,
        faces: Vec<u32>,
        gtris: &[[u32; 3]],
        pos_of: impl Fn(u32) -> [f64; 3],
        cut: &HashSet<(u32, u32)>,
    ) -> Result<Piece3, AlgoError> {
        let (class, n, boundary) = wedges(gtris, |a, b| cut.contains(&(a, b)));
        let mut vertex_ids = vec![0u32; n];
        for (c, &w) in class.iter().enumerate() {
            vertex_ids[w as usize] = gtris[c / 3][c % 3];
        }
        let tris: Vec<[u32; 3]> = (0..gtris.len())
            .map(|f| [class[3 * f], class[3 * f + 1], class[3 * f + 2]])
            .collect();
        let pos: Vec<[f64; 3]> = vertex_ids.iter().map(|&v| pos_of(v)).collect();
        let loops = walk_loops(&class, n, &boundary)
            .map_err(|e| AlgoError::Input(format!("patch `{name}`: {e}")))?;
        let nb = boundary.iter().filter(|&&b| b).count();
        let edges = (3 * tris.len() + nb) / 2;
        let chi = n as i64 - edges as i64 + tris.len() as i64;
        let genus2 = 2 - loops.len() as i64 - chi;
        if genus2 != 0 {
            return Err(AlgoError::Input(format!(
                "patch `{name}` has genus {} (Euler characteristic {chi} with {} boundary \
                 loops); only disks, with or without holes, and closed surfaces of genus 0 can \
                 be flattened",
                genus2 / 2,
                loops.len()
            )));
        }
        let mut loops: Vec<Vec<u32>> = loops
            .into_iter()
            .map(|l| l.into_iter().map(|(w, _)| w).collect())
            .collect();
        let len = |l: &Vec<u32>| -> f64 {
            (0..l.len())
                .map(|k| dist(pos[l[k] as usize], pos[l[(k + 1) % l.len()] as usize]))
                .sum()
        };
        let lens: Vec<f64> = loops.iter().map(len).collect();
        let outer = (0..loops.len())
            .max_by(|&a, &b| lens[a].partial_cmp(&lens[b]).unwrap_or(Ordering::Equal))
            .unwrap_or(0);
        if !loops.is_empty() {
            loops.swap(0, outer);
        }
        let corners = tris
            .iter()
            .map(|t| {
                let q = t.map(|w| pos[w as usize]);
                [0, 1, 2]
                    .map(|i| crate::geometry::corner_angle(q[i], q[(i + 1) % 3], q[(i + 2) % 3]))
            })
            .collect();
        Ok(Piece3 {
            name,
            faces,
            vertex_ids,
            pos,
            tris,
            corners,
            loops,
        })
    }

    /// Angle sum of each local vertex: the 3D corner angles of its wedge.
    pub fn angle_sums(&self) -> Vec<f64> {
        let mut sum = vec![0.0; self.pos.len()];
        for (t, a) in self.tris.iter().zip(&self.corners) {
            for i in 0..3 {
                sum[t[i] as usize] += a[i];
            }
        }
        sum
    }

    /// 3D area.
    pub fn area(&self) -> f64 {
        self.tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|w| self.pos[w as usize]);
                crate::geometry::triangle_area(a, b, c)
            })
            .sum()
    }
}

/// Geodesic turning of a boundary loop, Σ (π − a_i) over its vertices (a_i the surface's
/// inner angle there). Filling the loop with a disk D, Gauss–Bonnet (do Carmo, Differential
/// Geometry of Curves and Surfaces, Sec. 4-5; discretely the angle-defect form) gives the
/// Gaussian curvature D would enclose, K(D) = 2π + turning for an inner loop (traversed with
/// the piece, not D, on its left). A hole can lie closed in the plane only if K(D) = 0.
pub fn loop_turning(lp: &[u32], angle_sums: &[f64]) -> f64 {
    lp.iter().map(|&v| PI - angle_sums[v as usize]).sum()
}

/// How the extra boundary loops of a piece are treated.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Cuts {
    /// A hole that encloses curvature (|K(D)| above the tolerance) is cut open, the others
    /// stay holes (default).
    #[default]
    Auto,
    /// Every inner loop stays a hole, closed in the plane (the paper's virtual cuts).
    Virtual,
    /// Every inner loop is cut open to the outer loop.
    Real,
}

/// The real cuts of a piece and what was decided.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CutPlan {
    /// Cut paths (local vertices), each from what it joins to the tree it ends on.
    pub paths: Vec<Vec<u32>>,
    /// K(D) of every inner loop (in the order of `Piece3::loops[1..]`).
    pub enclosed_curvature: Vec<f64>,
    /// Which inner loops stay holes.
    pub holes: Vec<bool>,
    /// Vertices a closed piece was cut through (its curved vertices).
    pub cone_points: usize,
}

/// Longest cut tree of a closed piece, in units of √area: a box-like shape needs about 3 (a
/// cube 2.9, a capped cylinder of height 2r 3.4, an icosahedron 3.7); a smooth closed shape,
/// whose curvature is spread over every vertex, needs a tree through nearly all of them.
pub const CLOSED_CUT_BUDGET: f64 = 8.0;

/// Decide the real cuts of a piece.
///
/// Open piece: each inner loop whose enclosed curvature K(D) (see [`loop_turning`]) exceeds
/// `tolerance` in magnitude cannot close flat as a hole; with `Cuts::Auto` it is joined to the
/// outer loop by the shortest interior edge path ([`grow_tree`], roots the outer loop and the
/// loops joined so far). The path runs where the cut costs least seam length; it never
/// touches a hole that stays.
///
/// Closed piece (genus 0): the curvature sits at its curved vertices (|2π − θ| above
/// `tolerance`); cut along a shortest-path tree through all of them, the piece is a disk
/// whose interior is flat. Refused (an error naming why) when the tree would be longer than
/// [`CLOSED_CUT_BUDGET`]·√area or there are fewer than two curved vertices.
pub fn plan_cuts(p: &Piece3, mode: Cuts, tolerance: f64) -> Result<CutPlan, String> {
    let sums = p.angle_sums();
    let mut plan = CutPlan::default();
    if p.loops.is_empty() {
        let adj = interior_adjacency(p);
        let mut curved: Vec<u32> = (0..p.pos.len() as u32)
            .filter(|&v| (2.0 * PI - sums[v as usize]).abs() > tolerance)
            .collect();
        plan.cone_points = curved.len();
        if curved.len() < 2 {
            return Err(format!(
                "it is closed and its curvature is spread thinly ({} vertices curved by more \
                 than {tolerance:e} rad), so no short cut opens it flat",
                curved.len()
            ));
        }
        curved.sort_by(|&a, &b| {
            let k = |v: u32| (2.0 * PI - sums[v as usize]).abs();
            k(b).total_cmp(&k(a)).then(a.cmp(&b))
        });
        let groups: Vec<Vec<u32>> = curved[1..].iter().map(|&v| vec![v]).collect();
        let budget = CLOSED_CUT_BUDGET * p.area().sqrt();
        let blocked = vec![false; p.pos.len()];
        plan.paths = grow_tree(&p.pos, &adj, &curved[..1], &groups, &blocked, budget).map_err(
            |e| match e {
                GrowError::TooLong => format!(
                    "it is closed and curved at {} of its {} vertices: a cut through them all \
                     would be longer than {CLOSED_CUT_BUDGET}·√area, so it is not a pattern \
                     piece (a button, a collider, a body?)",
                    curved.len(),
                    p.pos.len()
                ),
                GrowError::Unreachable(_) => "its curved vertices are not connected".into(),
            },
        )?;
        return Ok(plan);
    }
    let inner = &p.loops[1..];
    plan.enclosed_curvature = inner
        .iter()
        .map(|lp| 2.0 * PI + loop_turning(lp, &sums))
        .collect();
    plan.holes = plan
        .enclosed_curvature
        .iter()
        .map(|k| match mode {
            Cuts::Auto => k.abs() <= tolerance,
            Cuts::Virtual => true,
            Cuts::Real => false,
        })
        .collect();
    let to_cut: Vec<Vec<u32>> = inner
        .iter()
        .zip(&plan.holes)
        .filter(|(_, &h)| !h)
        .map(|(lp, _)| lp.clone())
        .collect();
    if to_cut.is_empty() {
        return Ok(plan);
    }
    // Built only when a path is needed: most pieces have none (segmentation tests hundreds).
    let adj = interior_adjacency(p);
    let mut blocked = vec![false; p.pos.len()];
    for (lp, &h) in inner.iter().zip(&plan.holes) {
        if h {
            for &v in lp {
                blocked[v as usize] = true;
            }
        }
    }
    plan.paths = grow_tree(&p.pos, &adj, &p.loops[0], &to_cut, &blocked, f64::INFINITY)
        .map_err(|_| "a boundary loop cannot be reached from the outer loop".to_string())?;
    Ok(plan)
}

#[derive(PartialEq)]
struct Item(f64, u32);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.partial_cmp(&self.0)
            .unwrap_or(Ordering::Equal)
            .then(o.1.cmp(&self.1))
    }
}

/// Interior-edge adjacency of a piece (both directions): the edges a cut may run along.
fn interior_adjacency(p: &Piece3) -> Vec<Vec<u32>> {
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); p.pos.len()];
    let (_, _, boundary) = wedges(&p.tris, |_, _| false);
    for (f, t) in p.tris.iter().enumerate() {
        for i in 0..3 {
            if !boundary[3 * f + i] {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                if a < b {
                    adj[a as usize].push(b);
                    adj[b as usize].push(a);
                }
            }
        }
    }
    adj
}

/// Why [`grow_tree`] stopped short.
#[derive(Debug, Clone, PartialEq)]
pub enum GrowError {
    /// This target group cannot be reached along interior edges.
    Unreachable(usize),
    /// The paths would be longer in total than the budget.
    TooLong,
}

/// Shortest-path tree growth (a Prim-like Steiner heuristic): starting from `roots`, join the
/// nearest target group not yet joined by a shortest path over interior edges (3D lengths) to
/// everything joined so far, then add the group and the path to the tree; repeat until every
/// group is joined. Each path starts on its group and ends on the tree, and by symmetry of
/// shortest paths is the shortest path from that group to the tree, so paths never cross.
///
/// Distances to the tree are kept between rounds and only lowered by a Dijkstra wave from each
/// new path (so k rounds cost about one Dijkstra plus the waves, not k Dijkstras). Paths never
/// pass through a vertex of a group not yet joined, nor through a `blocked` vertex. Returns
/// the paths in the order they were made.
pub fn grow_tree(
    pos: &[[f64; 3]],
    adj: &[Vec<u32>],
    roots: &[u32],
    groups: &[Vec<u32>],
    blocked: &[bool],
    max_length: f64,
) -> Result<Vec<Vec<u32>>, GrowError> {
    let n = pos.len();
    let mut group_of = vec![u32::MAX; n];
    for (g, vs) in groups.iter().enumerate() {
        for &v in vs {
            group_of[v as usize] = g as u32;
        }
    }
    let mut in_tree = vec![false; n];
    let mut d = vec![f64::INFINITY; n];
    let mut prev = vec![u32::MAX; n];
    let mut wave = BinaryHeap::new();
    let mut targets = BinaryHeap::new();
    let mut joined = vec![false; groups.len()];
    fn add(v: u32, in_tree: &mut [bool], d: &mut [f64], wave: &mut BinaryHeap<Item>) {
        in_tree[v as usize] = true;
        d[v as usize] = 0.0;
        wave.push(Item(0.0, v));
    }
    for &r in roots {
        add(r, &mut in_tree, &mut d, &mut wave);
    }
    let (mut paths, mut total) = (Vec::new(), 0.0);
    for _round in 0..groups.len() {
        while let Some(Item(dv, v)) = wave.pop() {
            if dv > d[v as usize] {
                continue;
            }
            if group_of[v as usize] != u32::MAX && !in_tree[v as usize] {
                targets.push(Item(dv, v)); // a group not joined: reached, not crossed
                continue;
            }
            for &w in &adj[v as usize] {
                if in_tree[w as usize] || blocked[w as usize] {
                    continue;
                }
                let nd = dv + dist(pos[v as usize], pos[w as usize]);
                if nd < d[w as usize] {
                    d[w as usize] = nd;
                    prev[w as usize] = v;
                    wave.push(Item(nd, w));
                }
            }
        }
        let t = loop {
            match targets.pop() {
                None => {
                    let g = joined.iter().position(|&j| !j).unwrap_or(0);
                    return Err(GrowError::Unreachable(g));
                }
                Some(Item(dt, t)) => {
                    let g = group_of[t as usize] as usize;
                    if dt <= d[t as usize] && !in_tree[t as usize] && !joined[g] {
                        break t;
                    }
                }
            }
        };
        total += d[t as usize];
        if total > max_length {
            return Err(GrowError::TooLong);
        }
        let mut path = vec![t];
        let mut v = t;
        while !in_tree[v as usize] {
            v = prev[v as usize];
            path.push(v);
        }
        let g = group_of[t as usize] as usize;
        joined[g] = true;
        for &v in groups[g].iter().chain(&path) {
            if !in_tree[v as usize] {
                add(v, &mut in_tree, &mut d, &mut wave);
            }
        }
        paths.push(path);
    }
    Ok(paths)
}

/// The virtual cut (Sec. 3.2, steps 2–3): returns the cut paths, each a list of local vertices
/// starting on the inner loop it attaches and ending on the outer loop or on an earlier path.
/// The paper joins each inner loop to the outer one by a shortest path; [`grow_tree`] with
/// the outer loop as root and the inner loops as groups does that, nearest loop first.
pub fn cut_paths(p: &Piece3) -> Result<Vec<Vec<u32>>, AlgoError> {
    if p.loops.len() <= 1 {
        return Ok(Vec::new());
    }
    let adj = interior_adjacency(p);
    let blocked = vec![false; p.pos.len()];
    grow_tree(
        &p.pos,
        &adj,
        &p.loops[0],
        &p.loops[1..],
        &blocked,
        f64::INFINITY,
    )
    .map_err(|_| {
        AlgoError::Input(format!(
            "patch `{}`: an inner boundary loop cannot be reached from the outer loop",
            p.name
        ))
    })
}

/// The cut disk P_d: its single boundary loop (as piece vertices, surface on the left), the
/// surface inner angle a_i of each loop entry (sum of the corner angles in its wedge), and for
/// every cut edge the two loop positions where it occurs.
#[derive(Debug, Clone)]
pub struct CutLoop {
    /// Piece vertex of each loop entry.
    pub vertex: Vec<u32>,
    /// Surface inner angle a_i of each entry.
    pub angle: Vec<f64>,
    /// For each path: the loop indices of the two copies of its first vertex (on the inner
    /// loop it attaches), ascending; the Eq. 10 coincidence pair.
    pub seeds: Vec<(usize, usize)>,
    /// For each cut edge, the two loop edge indices where it occurs, ascending.
    pub cut_edges: Vec<(usize, usize)>,
}

/// Cut the piece along `paths` (Sec. 3.2 step 3) and return the boundary of P_d.
pub fn cut_loop(p: &Piece3, paths: &[Vec<u32>], corner: &[[f64; 3]]) -> Result<CutLoop, String> {
    let mut cut: HashMap<(u32, u32), usize> = HashMap::new();
    for path in paths {
        for w in path.windows(2) {
            cut.insert(key(w[0], w[1]), usize::MAX);
        }
    }
    let (class, n, boundary) = wedges(&p.tris, |a, b| cut.contains_key(&(a, b)));
    let loops = walk_loops(&class, n, &boundary)?;
    if loops.len() != 1 {
        return Err(format!(
            "the virtual cut left {} boundary loops instead of one",
            loops.len()
        ));
    }
    let lp = &loops[0];
    let mut angle_of = vec![0.0; n];
    for (c, &w) in class.iter().enumerate() {
        angle_of[w as usize] += corner[c / 3][c % 3];
    }
    let vertex: Vec<u32> = lp
        .iter()
        .map(|&(_, c)| p.tris[c as usize / 3][c as usize % 3])
        .collect();
    let angle: Vec<f64> = lp.iter().map(|&(w, _)| angle_of[w as usize]).collect();
    let nl = vertex.len();
    let mut occ: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for k in 0..nl {
        let kk = key(vertex[k], vertex[(k + 1) % nl]);
        if cut.contains_key(&kk) {
            occ.entry(kk).or_default().push(k);
        }
    }
    let mut cut_edges = Vec::new();
    for path in paths {
        for w in path.windows(2) {
            let o = occ.get(&key(w[0], w[1])).cloned().unwrap_or_default();
            if o.len() != 2 {
                return Err(format!(
                    "cut edge ({}, {}) occurs {} times on the cut loop",
                    w[0],
                    w[1],
                    o.len()
                ));
            }
            cut_edges.push((o[0], o[1]));
        }
    }
    let mut seeds = Vec::new();
    for path in paths {
        let (t, p1) = (path[0], path[1]);
        let o = &occ[&key(t, p1)];
        // the copy of t at each occurrence: the start of the edge if it runs t → p1, else its end
        let copy = |k: usize| if vertex[k] == t { k } else { k + 1 };
        let (a, b) = (copy(o[0]), copy(o[1]));
        seeds.push((a.min(b), a.max(b)));
    }
    Ok(CutLoop {
        vertex,
        angle,
        seeds,
        cut_edges,
    })
}
