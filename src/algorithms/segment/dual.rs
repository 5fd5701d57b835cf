//! The dual graph segmentation works on: faces as nodes, an arc across every edge shared by
//! two faces (of one patch when the designer's seams are kept), with the edge's length and
//! the dihedral term 1 − n_f·n_g the min-cut weights use.

use crate::geometry;
use crate::mesh::{Mesh, NONE};

/// Face adjacency of a mesh, three slots per face (`NONE` where there is no neighbour).
pub struct Dual {
    /// Neighbour across side i (half-edge 3f + i) of face f, or `NONE`.
    pub next: Vec<[u32; 3]>,
    /// Mesh edge of side i of face f.
    pub edge: Vec<[u32; 3]>,
    /// Length of every mesh edge.
    pub edge_length: Vec<f64>,
    /// Unit normal of every face.
    pub normal: Vec<[f64; 3]>,
    /// Area of every face.
    pub area: Vec<f64>,
}

impl Dual {
    /// The dual graph of `mesh`; with `keep_patches`, faces of different patches are not
    /// neighbours (their shared edge stays a seam whatever happens).
    pub fn new(mesh: &Mesh, keep_patches: bool) -> Dual {
        let conn = mesh.conn();
        let fp = mesh.face_patch();
        let nf = mesh.num_faces();
        let mut next = vec![[NONE; 3]; nf];
        let mut edge = vec![[NONE; 3]; nf];
        for f in 0..nf {
            for i in 0..3 {
                let c = (3 * f + i) as u32;
                edge[f][i] = conn.edge_of(c);
                let t = conn.twin(c);
                if t != NONE {
                    let g = (t / 3) as usize;
                    if !keep_patches || fp[g] == fp[f] {
                        next[f][i] = g as u32;
                    }
                }
            }
        }
        Dual {
            next,
            edge,
            edge_length: geometry::edge_lengths(mesh, mesh.positions()),
            normal: geometry::face_normals(mesh),
            area: geometry::face_areas(mesh),
        }
    }

    /// Number of faces.
    pub fn len(&self) -> usize {
        self.next.len()
    }

    /// Whether there are no faces.
    pub fn is_empty(&self) -> bool {
        self.next.is_empty()
    }

    /// Neighbours of face `f` with the shared edge: (neighbour, edge).
    pub fn arcs(&self, f: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..3).filter_map(move |i| {
            let g = self.next[f][i];
            (g != NONE).then_some((g as usize, self.edge[f][i] as usize))
        })
    }

    /// 1 − cos of the angle between the normals of faces f and g (0 across a flat edge, 2
    /// across a fold).
    pub fn bend(&self, f: usize, g: usize) -> f64 {
        let (a, b) = (self.normal[f], self.normal[g]);
        (1.0 - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])).max(0.0)
    }
}

/// Connected components of the faces through dual arcs whose two faces `joined` accepts:
/// the component of every face, numbered in order of their lowest face, and their count.
pub fn components(dual: &Dual, joined: impl Fn(usize, usize) -> bool) -> (Vec<u32>, usize) {
    let nf = dual.len();
    let mut comp = vec![NONE; nf];
    let mut n = 0u32;
    let mut stack = Vec::new();
    for f0 in 0..nf {
        if comp[f0] != NONE {
            continue;
        }
        comp[f0] = n;
        stack.push(f0);
        while let Some(f) = stack.pop() {
            for (g, _) in dual.arcs(f) {
                if comp[g] == NONE && joined(f, g) {
                    comp[g] = n;
                    stack.push(g);
                }
            }
        }
        n += 1;
    }
    (comp, n as usize)
}
