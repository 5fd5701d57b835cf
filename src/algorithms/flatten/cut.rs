//! Piece topology: one piece per connected component of a patch, its vertices split into
//! wedges (so a vertex where the patch touches itself becomes two 2D vertices), its boundary
//! loops, and the virtual cut of Sec. 3.2 (wang-lpfb): multi-source Dijkstra paths that join
//! every inner loop to the outer loop, and the cut disk P_d whose single boundary loop LPFB
//! lays out.

use super::super::AlgoError;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

#[inline]
fn next(c: usize) -> usize {
    if c % 3 == 2 {
        c - 2
    } else {
        c + 1
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
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
    let mut he: Vec<(u32, u32, u32)> = Vec::with_capacity(nh);
    for (f, t) in tris.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = key(t[i], t[(i + 1) % 3]);
            he.push((a, b, (3 * f + i) as u32));
        }
    }
    he.sort_unstable();
    let mut parent: Vec<u32> = (0..nh as u32).collect();
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
                union(&mut parent, c as u32, next(d) as u32);
                union(&mut parent, next(c) as u32, d as u32);
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
        let r = find(&mut parent, c as u32) as usize;
        if root_class[r] == u32::MAX {
            root_class[r] = n;
            n += 1;
        }
        *cl = root_class[r];
    }
    (class, n as usize, boundary)
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
    /// Boundary loops (local vertices, surface on the left); outer (longest in 3D) first.
    pub loops: Vec<Vec<u32>>,
}

pub(crate) fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

impl Piece3 {
    /// Build a piece from global faces. Fails, naming the piece, when it is closed or not a
    /// disk with holes (genus > 0).
    pub fn build(
        name: String,
        faces: Vec<u32>,
        all_tris: &[[u32; 3]],
        all_pos: &[[f64; 3]],
    ) -> Result<Piece3, AlgoError> {
        let gtris: Vec<[u32; 3]> = faces.iter().map(|&f| all_tris[f as usize]).collect();
        let (class, n, boundary) = wedges(&gtris, |_, _| false);
        let mut vertex_ids = vec![0u32; n];
        for (c, &w) in class.iter().enumerate() {
            vertex_ids[w as usize] = gtris[c / 3][c % 3];
        }
        let tris: Vec<[u32; 3]> = (0..gtris.len())
            .map(|f| [class[3 * f], class[3 * f + 1], class[3 * f + 2]])
            .collect();
        let pos: Vec<[f64; 3]> = vertex_ids.iter().map(|&v| all_pos[v as usize]).collect();
        let loops = walk_loops(&class, n, &boundary)
            .map_err(|e| AlgoError::Input(format!("patch `{name}`: {e}")))?;
        if loops.is_empty() {
            return Err(AlgoError::Input(format!(
                "patch `{name}` is closed (no boundary loop): cut it into pieces with a boundary \
                 before flattening"
            )));
        }
        let nb = boundary.iter().filter(|&&b| b).count();
        let edges = (3 * tris.len() + nb) / 2;
        let chi = n as i64 - edges as i64 + tris.len() as i64;
        let genus2 = 2 - loops.len() as i64 - chi;
        if genus2 != 0 {
            return Err(AlgoError::Input(format!(
                "patch `{name}` has genus {} (Euler characteristic {chi} with {} boundary \
                 loops); only disks, with or without holes, can be flattened",
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
        loops.swap(0, outer);
        Ok(Piece3 {
            name,
            faces,
            vertex_ids,
            pos,
            tris,
            loops,
        })
    }
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

/// The virtual cut (Sec. 3.2, steps 2–3): returns the cut paths, each a list of local vertices
/// starting on the inner loop it attaches and ending on the outer loop or on an earlier path.
/// Each round is one multi-source Dijkstra over interior edges (3D lengths) from everything
/// already attached to the nearest inner loop not yet attached; by symmetry of shortest paths
/// this is the paper's shortest path from that inner loop to the attached set, and the paths
/// never cross.
pub fn cut_paths(p: &Piece3) -> Result<Vec<Vec<u32>>, AlgoError> {
    let n = p.pos.len();
    if p.loops.len() <= 1 {
        return Ok(Vec::new());
    }
    // adjacency over interior edges only
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
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
    // loop id per vertex
    let mut on_loop = vec![u32::MAX; n];
    for (li, l) in p.loops.iter().enumerate() {
        for &v in l {
            on_loop[v as usize] = li as u32;
        }
    }
    let mut attached_loop = vec![false; p.loops.len()];
    attached_loop[0] = true;
    let mut attached = vec![false; n];
    for &v in &p.loops[0] {
        attached[v as usize] = true;
    }
    let mut paths = Vec::new();
    let mut d = vec![f64::INFINITY; n];
    let mut prev = vec![u32::MAX; n];
    for _round in 1..p.loops.len() {
        d.iter_mut().for_each(|x| *x = f64::INFINITY);
        prev.iter_mut().for_each(|x| *x = u32::MAX);
        let mut heap = BinaryHeap::new();
        for v in 0..n {
            if attached[v] {
                d[v] = 0.0;
                heap.push(Item(0.0, v as u32));
            }
        }
        let mut hit = None;
        while let Some(Item(dv, v)) = heap.pop() {
            if dv > d[v as usize] {
                continue;
            }
            let lv = on_loop[v as usize];
            if !attached[v as usize] && lv != u32::MAX && !attached_loop[lv as usize] {
                hit = Some(v);
                break;
            }
            for &w in &adj[v as usize] {
                if attached[w as usize] {
                    continue;
                }
                let nd = dv + dist(p.pos[v as usize], p.pos[w as usize]);
                if nd < d[w as usize] {
                    d[w as usize] = nd;
                    prev[w as usize] = v;
                    heap.push(Item(nd, w));
                }
            }
        }
        let Some(t) = hit else {
            return Err(AlgoError::Input(format!(
                "patch `{}`: an inner boundary loop cannot be reached from the outer loop",
                p.name
            )));
        };
        let mut path = vec![t];
        let mut v = t;
        while !attached[v as usize] {
            v = prev[v as usize];
            path.push(v);
        }
        let li = on_loop[t as usize] as usize;
        attached_loop[li] = true;
        for &v in &p.loops[li] {
            attached[v as usize] = true;
        }
        for &v in &path {
            attached[v as usize] = true;
        }
        paths.push(path);
    }
    Ok(paths)
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
