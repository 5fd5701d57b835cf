//! Loop subdivision (Loop 1987), the first step of Su et al.'s method, with seams and the free
//! boundary as crease curves so that patches stay welded (paper-notes C.2).
//!
//! Every edge gets an odd vertex: 3/8 (a + b) + 1/8 (c + d) across an interior edge with
//! opposite vertices c and d, ½ (a + b) on a crease (a boundary or seam edge). Every old vertex
//! moves to (1 − nβ) v + β Σ neighbours, β = (5/8 − (3/8 + ¼ cos 2π/n)²) / n, when no crease
//! passes through it; to ¾ v + ⅛ (a + b) when exactly two crease edges (to a and b) meet
//! there; and stays where it is otherwise (corners where seams meet the boundary, a vertex of
//! a single triangle). Each triangle becomes four in its own patch; old vertices keep their
//! ids and the odd vertex of edge e is number V + e, so V′ = V + E and F′ = 4F. Every rule is
//! an affine combination, so affine maps commute with it and a planar mesh stays planar.
//! Texture coordinates are split linearly (midpoints), so a file's own pattern is kept.

use crate::mesh::{Mesh, RawMesh, UvLayer, NONE};

/// One level of Loop subdivision of `mesh`.
pub fn loop_subdivide(mesh: &Mesh) -> RawMesh {
    let conn = mesh.conn();
    let pos = mesh.positions();
    let tris = mesh.triangles();
    let fp = mesh.face_patch();
    let nv = mesh.num_vertices();
    let edges = conn.edges();
    let crease: Vec<bool> = conn
        .edge_faces()
        .iter()
        .map(|f| f[1] == NONE || fp[f[0] as usize] != fp[f[1] as usize])
        .collect();
    // Opposite vertex of each face across each of its edges, and each face's three edge ids.
    let mut face_edges = vec![[0u32; 3]; tris.len()];
    let mut opposite: Vec<[u32; 2]> = vec![[NONE; 2]; edges.len()];
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let e = conn.edge_of((3 * f + k) as u32);
            face_edges[f][k] = e;
            let o = t[(k + 2) % 3];
            let slot = if opposite[e as usize][0] == NONE {
                0
            } else {
                1
            };
            opposite[e as usize][slot] = o;
        }
    }
    let mut out = Vec::with_capacity(nv + edges.len());
    // Even vertices.
    let mut crease_nb: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for (e, ends) in edges.iter().enumerate() {
        if crease[e] {
            crease_nb[ends[0] as usize].push(ends[1]);
            crease_nb[ends[1] as usize].push(ends[0]);
        }
    }
    for v in 0..nv {
        let p = pos[v];
        let ring = conn.ring_of(v as u32);
        let faces = conn.fan_of(v as u32).len();
        out.push(match crease_nb[v].len() {
            0 if !ring.is_empty() => {
                let n = ring.len() as f64;
                let c = 0.375 + 0.25 * (std::f64::consts::TAU / n).cos();
                let beta = (0.625 - c * c) / n;
                let mut q = p.map(|x| (1.0 - n * beta) * x);
                for &r in ring {
                    for k in 0..3 {
                        q[k] += beta * pos[r as usize][k];
                    }
                }
                q
            }
            2 if faces > 1 => {
                let (a, b) = (pos[crease_nb[v][0] as usize], pos[crease_nb[v][1] as usize]);
                [0, 1, 2].map(|k| 0.75 * p[k] + 0.125 * (a[k] + b[k]))
            }
            _ => p,
        });
    }
    // Odd vertices.
    for (e, ends) in edges.iter().enumerate() {
        let (a, b) = (pos[ends[0] as usize], pos[ends[1] as usize]);
        let [c, d] = opposite[e];
        out.push(if crease[e] || d == NONE {
            [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]))
        } else {
            let (c, d) = (pos[c as usize], pos[d as usize]);
            [0, 1, 2].map(|k| 0.375 * (a[k] + b[k]) + 0.125 * (c[k] + d[k]))
        });
    }
    let mut triangles = Vec::with_capacity(4 * tris.len());
    let mut face_patch = Vec::with_capacity(4 * tris.len());
    for (f, t) in tris.iter().enumerate() {
        // Edge k of face f runs from corner k to corner k + 1.
        let m = face_edges[f].map(|e| nv as u32 + e);
        triangles.push([t[0], m[0], m[2]]);
        triangles.push([m[0], t[1], m[1]]);
        triangles.push([m[2], m[1], t[2]]);
        triangles.push([m[0], m[1], m[2]]);
        face_patch.extend([fp[f]; 4]);
    }
    let uv = mesh.uv().map(|uv| {
        let mut coords = uv.coords.clone();
        let mut out_tris = Vec::with_capacity(4 * uv.triangles.len());
        for t in &uv.triangles {
            let base = coords.len() as u32;
            for k in 0..3 {
                let (a, b) = (uv.coords[t[k] as usize], uv.coords[t[(k + 1) % 3] as usize]);
                coords.push([0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])]);
            }
            let m = [base, base + 1, base + 2];
            out_tris.push([t[0], m[0], m[2]]);
            out_tris.push([m[0], t[1], m[1]]);
            out_tris.push([m[2], m[1], t[2]]);
            out_tris.push([m[0], m[1], m[2]]);
        }
        UvLayer {
            coords,
            triangles: out_tris,
        }
    });
    RawMesh {
        positions: out,
        triangles,
        face_patch,
        patch_names: mesh.patch_names().to_vec(),
        uv,
    }
}
