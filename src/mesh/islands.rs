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
//! inside one island (a slit from the hem, as on diffavatar_tshirt's front) is no seam: its
//! faces stay in one patch, welded, and its vertices must be flat like any other.

use super::{Mesh, MeshError, RawMesh, Warning, NONE};

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
    let mut parent: Vec<u32> = (0..nf as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
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
            let (rf, rg) = (find(&mut parent, f as u32), find(&mut parent, g as u32));
            parent[rf.max(rg) as usize] = rf.min(rg);
        } else {
            seam_edges += 1;
        }
    }
    // Roots to island numbers, largest first.
    let roots: Vec<u32> = (0..nf as u32).map(|f| find(&mut parent, f)).collect();
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

/// `mesh` with one patch per island: named `island<k>`, or `<patch>.island<k>` when the file
/// named its patches (k from 1, largest first). Positions, faces and texture coordinates are
/// kept; only the seams change, so vertices on an island's rim are no longer interior.
pub fn with_island_patches(
    mesh: &Mesh,
    islands: &UvIslands,
) -> Result<(Mesh, Vec<Warning>), MeshError> {
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
    Mesh::new(RawMesh {
        face_patch: islands.face_island.clone(),
        patch_names,
        ..mesh.to_raw()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::UvLayer;

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

    #[test]
    fn a_cut_layout_splits_the_surface_into_its_islands() {
        let m = strip(true);
        let is = uv_islands(&m).expect("has uv");
        assert_eq!(is.count(), 2);
        assert_eq!(is.seam_edges, 1);
        assert_eq!(is.face_island, vec![0, 0, 0, 0, 1, 1, 1, 1]);
        let (p, _) = with_island_patches(&m, &is).expect("valid");
        assert_eq!(p.patch_names(), ["island1", "island2"]);
        // The cut's two vertices now lie on a seam; the welded mesh had none there.
        assert!(m.conn().shared_vertices().is_empty());
        assert_eq!(p.conn().shared_vertices(), [4, 5]);
        assert_eq!(p.positions(), m.positions());
        assert_eq!(p.triangles(), m.triangles());
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
