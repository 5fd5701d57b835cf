//! Texture-coordinate islands, as patches: a garment exported from a 3D design tool carries its
//! sewing pattern as the islands of its UV layout (measured on ../shared/meshes, issue 12 note
//! of 2026-11-27: diffavatar_tshirt's 4 islands are its front, back and two sleeves, the
//! MakeHuman suits have 7–45, one per panel, the shoes 7–8). An OBJ keeps those cuts only in
//! its `vt` indices, so the welded surface reads as one patch; a glTF exporter splits the
//! vertices there instead, which the reader keeps as cuts already.
//!
//! Two faces of one patch are in one island when they share an edge whose two endpoints have
//! the same texture coordinates in both faces (compared exactly: an exporter writes a shared
//! corner once). Islands never cross the file's patches, so they refine them. A cut that ends
//! inside one island (a slit: most tubes, a sleeve or a trouser leg, are laid out flat by one)
//! cannot be a seam between patches, so it is opened by splitting its vertices
//! ([`with_island_patches`]); held fixed, it stays closed in space. Measured on the real
//! garments, 0–194 of their cut edges are slits.

use super::disjoint::DisjointSets;
use super::{Mesh, MeshError, RawMesh, NONE};
use std::collections::HashMap;

/// The UV islands of a mesh, each inside one of its patches.
#[derive(Debug, Clone, PartialEq)]
pub struct UvIslands {
    /// Island of each face, numbered by decreasing size (ties: by first face).
    pub face_island: Vec<u32>,
    /// The file's patch each island lies in.
    pub island_patch: Vec<u32>,
    /// Edges inside a patch whose two faces disagree on the texture coordinates: the cuts
    /// (a slit inside one island included).
    pub seam_edges: usize,
}

impl UvIslands {
    /// Number of islands.
    pub fn count(&self) -> usize {
        self.island_patch.len()
    }
}

/// The islands of `mesh`'s texture coordinates; `None` when it has none.
pub fn uv_islands(mesh: &Mesh) -> Option<UvIslands> {
    let uv = mesh.uv()?;
    let nf = mesh.num_faces();
    let mut sets = DisjointSets::new(nf);
    let tris = mesh.triangles();
    let patch = mesh.face_patch();
    // Texture coordinate of vertex v at face f.
    let at = |f: usize, v: u32| -> Option<[u64; 2]> {
        let k = tris[f].iter().position(|&x| x == v)?;
        let c = uv.coords.get(uv.triangles[f][k] as usize)?;
        Some([c[0].to_bits(), c[1].to_bits()])
    };
    let mut seam_edges = 0;
    let conn = mesh.conn();
    for (e, &[f, g]) in conn.edge_faces().iter().enumerate() {
        if g == NONE || patch[f as usize] != patch[g as usize] {
            continue;
        }
        let [a, b] = conn.edges()[e];
        let (f, g) = (f as usize, g as usize);
        if at(f, a) == at(g, a) && at(f, b) == at(g, b) {
            sets.union(f as u32, g as u32);
        } else {
            seam_edges += 1;
        }
    }
    // Roots to island numbers, largest first.
    let roots: Vec<u32> = (0..nf as u32).map(|f| sets.find(f)).collect();
    let mut size = vec![0usize; nf];
    for &r in &roots {
        size[r as usize] += 1;
    }
    let mut order: Vec<u32> = (0..nf as u32).filter(|&f| roots[f as usize] == f).collect();
    order.sort_by_key(|&r| (std::cmp::Reverse(size[r as usize]), r));
    let mut number = vec![NONE; nf];
    for (i, &r) in order.iter().enumerate() {
        number[r as usize] = i as u32;
    }
    Some(UvIslands {
        face_island: roots.iter().map(|&r| number[r as usize]).collect(),
        island_patch: order.iter().map(|&r| patch[r as usize]).collect(),
        seam_edges,
    })
}

/// A mesh cut along its texture layout.
#[derive(Debug, Clone)]
pub struct IslandMesh {
    /// One patch per island; the slits opened.
    pub mesh: Mesh,
    /// Vertices appended to open the slits (copies of the vertex they split from).
    pub opened: usize,
}

/// `mesh` with one patch per island, named `island<k>`, or `<patch>.island<k>` when the file
/// named its patches (k from 1, largest first), and every cut that ends inside an island (a
/// slit: a sleeve's or a trouser leg's seam, which closes the island into a tube) opened. The
/// corners of a vertex are grouped by the faces around it that share an edge, across any edge
/// but a slit's (so across the seam to the next island too); each group after the first gets
/// a copy of the vertex, appended. So a slit's tip and its end on a seam keep one vertex, and
/// the seam stays welded. The copies sit where the vertex is and lie on the opened cut, so
/// they are held like any boundary vertex. Positions, faces and texture coordinates are
/// otherwise kept.
pub fn with_island_patches(mesh: &Mesh, islands: &UvIslands) -> Result<IslandMesh, MeshError> {
    let names = mesh.patch_names();
    let unnamed = names.len() == 1 && names[0] == "default";
    let patch_names = islands
        .island_patch
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            if unnamed {
                format!("island{}", i + 1)
            } else {
                format!("{}.island{}", names[p as usize], i + 1)
            }
        })
        .collect();
    let mut raw = mesh.to_raw();
    if let Some(uv) = mesh.uv() {
        open_slits(mesh, uv, islands, &mut raw);
    }
    let (cut, _) = Mesh::new(RawMesh {
        face_patch: islands.face_island.clone(),
        patch_names,
        ..raw
    })?;
    // Counted on the result: a repair on the way in (a bow tie) would split vertices too.
    let opened = cut.num_vertices() - mesh.num_vertices();
    Ok(IslandMesh { mesh: cut, opened })
}

/// Split the vertices of the slits of `raw` (a copy of `mesh`'s data) in place: corners
/// (3·face + k) are joined across every shared edge but a slit's, and each vertex keeps its
/// index for the group of its first corner.
fn open_slits(mesh: &Mesh, uv: &super::UvLayer, islands: &UvIslands, raw: &mut RawMesh) {
    let tris = mesh.triangles();
    let mut sets = DisjointSets::new(3 * tris.len());
    let corner = |f: usize, v: u32| tris[f].iter().position(|&x| x == v).map(|k| 3 * f + k);
    let coord = |c: usize| {
        let t = uv.triangles[c / 3][c % 3] as usize;
        uv.coords.get(t).map(|q| [q[0].to_bits(), q[1].to_bits()])
    };
    let conn = mesh.conn();
    for (e, &[f, g]) in conn.edge_faces().iter().enumerate() {
        if g == NONE {
            continue;
        }
        let (f, g) = (f as usize, g as usize);
        let ends = conn.edges()[e].map(|v| (corner(f, v), corner(g, v)));
        let pairs: Vec<(usize, usize)> = ends.iter().filter_map(|&(a, b)| Some((a?, b?))).collect();
        if pairs.len() != 2 {
            continue;
        }
        let slit = islands.face_island[f] == islands.face_island[g]
            && pairs.iter().any(|&(a, b)| coord(a) != coord(b));
        if slit {
            continue;
        }
        for (a, b) in pairs {
            sets.union(a as u32, b as u32);
        }
    }
    // The group each vertex keeps, then a copy per further group.
    let mut kept: HashMap<u32, u32> = HashMap::new();
    let mut copies: HashMap<u32, u32> = HashMap::new();
    for c in 0..3 * tris.len() {
        let v = tris[c / 3][c % 3];
        let root = sets.find(c as u32);
        if *kept.entry(v).or_insert(root) == root {
            continue;
        }
        let positions = &mut raw.positions;
        let copy = *copies.entry(root).or_insert_with(|| {
            positions.push(positions[v as usize]);
            (positions.len() - 1) as u32
        });
        raw.triangles[c / 3][c % 3] = copy;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::UvLayer;

    /// A one-patch mesh with a texture layout.
    fn with_layout(
        positions: Vec<[f64; 3]>,
        triangles: Vec<[u32; 3]>,
        coords: Vec<[f64; 2]>,
        uv_tris: Vec<[u32; 3]>,
    ) -> Mesh {
        let raw = RawMesh {
            positions,
            face_patch: vec![0; triangles.len()],
            triangles,
            patch_names: vec!["default".into()],
            uv: Some(UvLayer {
                coords,
                triangles: uv_tris,
            }),
        };
        Mesh::new(raw).expect("valid").0
    }

    /// A strip of four squares (two triangles each) along x, welded, whose texture layout is
    /// cut between the second and third square: two islands of four faces, one seam edge.
    fn strip(cut: bool) -> Mesh {
        let positions: Vec<[f64; 3]> = (0..5)
            .flat_map(|i| [[i as f64, 0.0, 0.0], [i as f64, 1.0, 0.0]])
            .collect();
        let mut triangles = Vec::new();
        for i in 0..4u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
        // Texture coordinates: one per vertex, but the column x = 2 is written twice (for the
        // left and the right island) when cut, the right copy shifted as a layout would.
        let mut coords: Vec<[f64; 2]> = positions.iter().map(|p| [p[0], p[1]]).collect();
        coords.push([2.5, 0.0]);
        coords.push([2.5, 1.0]);
        let uv_tris = triangles
            .iter()
            .enumerate()
            .map(|(f, t)| {
                t.map(|v| {
                    let right = f >= 4;
                    match (cut && right, v) {
                        (true, 4) => 10,
                        (true, 5) => 11,
                        _ => v,
                    }
                })
            })
            .collect();
        with_layout(positions, triangles, coords, uv_tris)
    }

    #[test]
    fn a_cut_layout_splits_the_surface_into_its_islands() {
        let m = strip(true);
        let is = uv_islands(&m).expect("has uv");
        assert_eq!(is.count(), 2);
        assert_eq!(is.seam_edges, 1);
        assert_eq!(is.face_island, vec![0, 0, 0, 0, 1, 1, 1, 1]);
        let cut = with_island_patches(&m, &is).expect("valid");
        assert_eq!(cut.opened, 0);
        let p = cut.mesh;
        assert_eq!(p.patch_names(), ["island1", "island2"]);
        // The cut's two vertices now lie on a seam; the welded mesh had none there.
        assert!(m.conn().shared_vertices().is_empty());
        assert_eq!(p.conn().shared_vertices(), [4, 5]);
        assert_eq!(p.positions(), m.positions());
        assert_eq!(p.triangles(), m.triangles());
    }

    /// A flat 3×3 grid whose layout is slit from the bottom edge's middle (vertex 1) to the
    /// centre (vertex 4): one island, one cut edge; vertex 1 is copied for the faces right of
    /// the slit, the centre (the slit's tip, one coordinate) is not, and becomes a boundary
    /// vertex of the opened sheet.
    #[test]
    fn a_slit_inside_an_island_is_opened() {
        let positions: Vec<[f64; 3]> = (0..9)
            .map(|i| [(i % 3) as f64, (i / 3) as f64, 0.0])
            .collect();
        let mut triangles = Vec::new();
        for (x, y) in [(0u32, 0u32), (1, 0), (0, 1), (1, 1)] {
            let a = 3 * y + x;
            triangles.push([a, a + 1, a + 4]);
            triangles.push([a, a + 4, a + 3]);
        }
        let mut coords: Vec<[f64; 2]> = positions.iter().map(|p| [p[0], p[1]]).collect();
        coords.push([1.1, 0.0]);
        // Faces 2 and 3 (the bottom-right square) see vertex 1 at the copy.
        let uv_tris = triangles
            .iter()
            .enumerate()
            .map(|(f, t)| t.map(|v| if v == 1 && (f == 2 || f == 3) { 9 } else { v }))
            .collect();
        let m = with_layout(positions, triangles, coords, uv_tris);
        assert!(m.conn().is_interior(4));
        let is = uv_islands(&m).expect("has uv");
        assert_eq!((is.count(), is.seam_edges), (1, 1));
        let cut = with_island_patches(&m, &is).expect("valid");
        assert_eq!(cut.opened, 1);
        let p = cut.mesh;
        assert_eq!(p.num_vertices(), 10);
        assert_eq!(p.positions()[9], p.positions()[1]);
        assert!(
            !p.conn().is_interior(4),
            "the slit's tip is on the opened cut"
        );
        assert_eq!(p.conn().boundary_loops().len(), 1);
        assert_eq!(p.conn().boundary_loops()[0].len(), 10);
    }

    /// A tube of two rings of six squares, each ring its own island laid out flat by a slit
    /// along one generator: the bottom ring's at i = 0, the top ring's at i = 3, each from its
    /// free rim to the seam between the rings. Each slit copies its rim vertex only; where it
    /// ends on the seam the vertex stays one, and every seam edge still joins both rings.
    #[test]
    fn a_slit_that_ends_on_a_seam_leaves_the_seam_welded() {
        let n = 6u32;
        let positions: Vec<[f64; 3]> = (0..3 * n)
            .map(|v| {
                let a = std::f64::consts::TAU * (v % n) as f64 / n as f64;
                [a.cos(), a.sin(), (v / n) as f64]
            })
            .collect();
        let (mut triangles, mut uv_tris) = (Vec::new(), Vec::new());
        let mut coords: Vec<[f64; 2]> = Vec::new();
        let mut coord = |u: u32, v: f64| {
            let q = [u as f64, v];
            coords.iter().position(|&c| c == q).unwrap_or_else(|| {
                coords.push(q);
                coords.len() - 1
            }) as u32
        };
        for j in 0..2 {
            // The ring's slit column: its layout runs from the slit round to it again.
            let slit = if j == 0 { 0 } else { 3 };
            for i in 0..n {
                let (i1, jv) = ((i + 1) % n, j as f64 + 10.0 * j as f64);
                let u0 = (i + n - slit) % n;
                let u1 = if i1 == slit { n } else { (i1 + n - slit) % n };
                let (a, b, c, d) = (j * n + i, j * n + i1, (j + 1) * n + i1, (j + 1) * n + i);
                let (ta, tb) = (coord(u0, jv), coord(u1, jv));
                let (tc, td) = (coord(u1, jv + 1.0), coord(u0, jv + 1.0));
                triangles.push([a, b, c]);
                uv_tris.push([ta, tb, tc]);
                triangles.push([a, c, d]);
                uv_tris.push([ta, tc, td]);
            }
        }
        let m = with_layout(positions, triangles, coords, uv_tris);
        let is = uv_islands(&m).expect("has uv");
        // The seam between the rings (6 edges) and the two slits.
        assert_eq!((is.count(), is.seam_edges), (2, 8));
        let cut = with_island_patches(&m, &is).expect("valid");
        assert_eq!(cut.opened, 2);
        let p = cut.mesh;
        // The copies: of the bottom rim's vertex 0 and the top rim's vertex 15.
        let mut copied: Vec<[f64; 3]> = p.positions()[18..].to_vec();
        copied.sort_by(|a, b| a[2].total_cmp(&b[2]));
        assert_eq!(copied, [p.positions()[0], p.positions()[15]]);
        let conn = p.conn();
        for i in 0..n {
            let pair = [n + i, n + (i + 1) % n];
            let pair = [pair[0].min(pair[1]), pair[0].max(pair[1])];
            let e = conn.edges().iter().position(|&x| x == pair).expect("edge");
            assert_ne!(
                conn.edge_faces()[e][1],
                NONE,
                "seam edge {pair:?} came apart"
            );
        }
        // Free boundary: both rims and the two sides of each slit.
        let free = conn.edge_faces().iter().filter(|f| f[1] == NONE).count();
        assert_eq!(free, 6 + 6 + 2 * 2);
    }

    #[test]
    fn an_uncut_layout_is_one_island_and_no_layout_none() {
        let m = strip(false);
        let is = uv_islands(&m).expect("has uv");
        assert_eq!((is.count(), is.seam_edges), (1, 0));
        let bare = Mesh::new(RawMesh {
            uv: None,
            ..m.to_raw()
        })
        .expect("valid")
        .0;
        assert!(uv_islands(&bare).is_none());
    }
}
