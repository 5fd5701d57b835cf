//! Independent parts: a mesh's patch components, extracted, solved alone and put back.
//!
//! Boundary and seam vertices never move (with `seams = free` they do, and the parts are not
//! used), so the interior vertices of two different connected
//! parts of a patch share no constraint of Eq. 7 (only the shape penalty's hinges across a
//! seam see both sides): each part is a problem of its own, and any part's result can be
//! combined with any other's. Solved together they still share the step
//! rule (Armijo on ‖2π − θ‖₂ over all vertices, the trial with the lowest ϖ_max, one damping
//! μ, one stall window), so one part's trouble changes every other part's path, and the
//! disk-only developable cone never applies to a garment's disk-shaped parts.
//!
//! A part is the faces of one patch reached from each other across edges of that patch, with
//! the vertices they use. Its free vertices are exactly the whole's free vertices in it: a
//! seam vertex has faces of another patch outside the part, so it is on the part's
//! boundary, and a boundary vertex stays one. Parts are extracted and merged back without
//! changing an unrefined vertex's index or any face's orientation; where that cannot be
//! guaranteed (a part that fails validation otherwise), [`split`] declines and the mesh is
//! treated as one part. A seam vertex whose faces of one part form two separate wedges is
//! held in a copy per wedge ([`extract`]); declining there sent the unseen
//! mh_male_casualsuit02 (two sleeve islands with such a vertex) to a restart of the whole
//! that converged with 2 new folds in 49 s, where its six islands alone converge without
//! (issue 12 note of 2026-11-28: 0 new folds, smallest corner 0.44° → 2.71°, 13.6 s).

use crate::mesh::{Mesh, RawMesh, NONE};

/// One part: its own mesh, and where its vertices and faces sit in the whole.
pub(super) struct Part {
    /// The patch's name, `#k` appended when the patch has several parts (as flatten names
    /// its pieces).
    pub name: String,
    pub mesh: Mesh,
    /// Global index of each of the part's vertices.
    pub vertices: Vec<u32>,
    /// Global index of each of the part's faces.
    pub faces: Vec<u32>,
}

/// The parts of `mesh` that have an interior vertex, or None when the mesh is one part
/// (nothing to split) or a part cannot be extracted faithfully.
pub(super) fn split(mesh: &Mesh) -> Option<Vec<Part>> {
    let groups = crate::mesh::patch_components(mesh);
    if groups.len() < 2 {
        return None;
    }
    let mut parts = Vec::new();
    for (name, faces) in groups {
        let part = extract(mesh, name, faces)?;
        if part.mesh.conn().interior_vertices().next().is_some() {
            parts.push(part);
        }
    }
    (parts.len() >= 2).then_some(parts)
}

/// The part made of `faces`, or None when it does not validate as the same faces with the
/// same orientation and its free vertices are not the whole mesh's free vertices in it.
///
/// A seam vertex whose faces of this part form two or more separate wedges (a bow-tie within
/// the part: the unseen mh_male_casualsuit02's sleeve islands have one) is split as the
/// reader splits one, a copy at the same position per further wedge, numbered after the
/// part's vertices; `vertices` then names its global vertex once per copy. Such a vertex is on
/// the part's boundary in every copy, so it is held and every copy keeps its position.
fn extract(mesh: &Mesh, name: String, faces: Vec<u32>) -> Option<Part> {
    let mut local = vec![NONE; mesh.num_vertices()];
    let mut vertices = Vec::new();
    let mut triangles = Vec::with_capacity(faces.len());
    for &f in &faces {
        let t = mesh.triangles()[f as usize].map(|v| {
            if local[v as usize] == NONE {
                local[v as usize] = vertices.len() as u32;
                vertices.push(v);
            }
            local[v as usize]
        });
        triangles.push(t);
    }
    let patch = mesh.face_patch()[faces[0] as usize] as usize;
    let name_of_patch = mesh.patch_names()[patch].clone();
    let (sub, copies) = submesh_splitting(mesh, &vertices, triangles, name_of_patch)?;
    let copied: Vec<u32> = copies.iter().map(|&l| vertices[l as usize]).collect();
    vertices.extend(copied);
    let conn = mesh.conn();
    let faithful = (0..vertices.len() as u32)
        .all(|l| sub.conn().is_interior(l) == conn.is_interior(vertices[l as usize]));
    faithful.then_some(Part {
        name,
        mesh: sub,
        vertices,
        faces,
    })
}

/// The one-patch mesh of `source`'s `vertices` (in that order) and `triangles` (local
/// indices), or None when it does not validate as exactly those triangles (same order and
/// orientation).
fn submesh(
    source: &Mesh,
    vertices: &[u32],
    triangles: Vec<[u32; 3]>,
    patch_name: String,
) -> Option<Mesh> {
    let kept = triangles.clone();
    let (sub, copies) = submesh_splitting(source, vertices, triangles, patch_name)?;
    (copies.is_empty() && sub.triangles() == &kept[..]).then_some(sub)
}

/// [`submesh`], but a vertex whose triangles form separate wedges may be split as the reader
/// splits it: with the local vertex each copy (numbered from `vertices.len()` on) was made
/// from. None when anything else about the triangles changed.
fn submesh_splitting(
    source: &Mesh,
    vertices: &[u32],
    triangles: Vec<[u32; 3]>,
    patch_name: String,
) -> Option<(Mesh, Vec<u32>)> {
    let raw = RawMesh {
        positions: vertices.iter().map(|&v| source.position(v)).collect(),
        face_patch: vec![0; triangles.len()],
        triangles,
        patch_names: vec![patch_name],
        uv: None,
    };
    let kept = raw.triangles.clone();
    let n = vertices.len();
    let (sub, _) = Mesh::new(raw).ok()?;
    let mut copies = vec![NONE; sub.num_vertices().checked_sub(n)?];
    if sub.triangles().len() != kept.len() {
        return None;
    }
    for (t, k) in sub.triangles().iter().zip(&kept) {
        for (&a, &b) in t.iter().zip(k) {
            if a == b {
                continue;
            }
            let slot = copies.get_mut((a as usize).checked_sub(n)?)?;
            if *slot != NONE && *slot != b {
                return None;
            }
            *slot = b;
        }
    }
    (!copies.contains(&NONE)).then_some((sub, copies))
}

/// The whole mesh with each part's output put back: moved vertices in place, and where a
/// part was refined its faces replaced in place and its new faces and vertices appended
/// (part by part, in their order), so every input index keeps its meaning.
pub(super) fn merge(mesh: &Mesh, parts: &[Part], outs: &[&Mesh]) -> RawMesh {
    let mut raw = mesh.to_raw();
    for (part, out) in parts.iter().zip(outs) {
        let n = part.vertices.len();
        let first_new = raw.positions.len() as u32;
        for (l, &p) in out.positions().iter().enumerate() {
            if l < n {
                raw.positions[part.vertices[l] as usize] = p;
            } else {
                raw.positions.push(p);
            }
        }
        if out.triangles() == part.mesh.triangles() {
            continue;
        }
        raw.uv = None;
        let global = |l: u32| global_vertex(part, first_new, l);
        let patch = raw.face_patch[part.faces[0] as usize];
        for (k, t) in out.triangles().iter().enumerate() {
            let t = t.map(global);
            match part.faces.get(k) {
                Some(&f) => raw.triangles[f as usize] = t,
                None => {
                    raw.triangles.push(t);
                    raw.face_patch.push(patch);
                }
            }
        }
    }
    raw
}

/// Global index of a part's vertex `l` after [`merge`]: `first_new` is where the part's
/// appended vertices start in the merged mesh.
pub(super) fn global_vertex(part: &Part, first_new: u32, l: u32) -> u32 {
    let n = part.vertices.len() as u32;
    if l < n {
        part.vertices[l as usize]
    } else {
        first_new + (l - n)
    }
}

/// The parts of `out` — a result of the whole `mesh` (refinement appends vertices and faces
/// and rewrites refined faces in place, within a patch component) — each numbered as its
/// part (its vertices first, then the new vertices of its refined fans in increasing order;
/// its faces, then its appended faces in order), so that [`merge`] can put it back, with each
/// vertex's id in `out`. None when one does not validate as exactly those faces.
pub(super) fn restrict(out: &Mesh, mesh: &Mesh, parts: &[Part]) -> Option<Vec<(Mesh, Vec<u32>)>> {
    const SPLIT: u32 = NONE - 1;
    let (nv, nf) = (mesh.num_vertices(), mesh.num_faces());
    let mut group_of = vec![NONE; out.num_faces()];
    let groups = crate::mesh::patch_components(out);
    for (g, (_, faces)) in groups.iter().enumerate() {
        for &f in faces {
            group_of[f as usize] = g as u32;
        }
    }
    let mut appended: Vec<Vec<u32>> = vec![Vec::new(); groups.len()];
    for f in nf..out.num_faces() {
        appended[group_of[f] as usize].push(f as u32);
    }
    let mut local = vec![NONE; out.num_vertices()];
    parts
        .iter()
        .map(|part| {
            let group = group_of[part.faces[0] as usize] as usize;
            let faces: Vec<u32> = part.faces.iter().chain(&appended[group]).copied().collect();
            let mut vertices = part.vertices.clone();
            let mut new: Vec<u32> = faces
                .iter()
                .flat_map(|&f| out.triangles()[f as usize])
                .filter(|&v| v as usize >= nv)
                .collect();
            new.sort_unstable();
            new.dedup();
            vertices.extend(new);
            // A vertex the part split ([`extract`]) has several local ids: a face picks its
            // copy through the part's own triangle of that face (refinement rewrites a face in
            // place keeping the edge opposite the refined vertex, and a split vertex, held,
            // is never refined); an appended face that uses one declines.
            let mut split = Vec::new();
            for (l, &v) in vertices.iter().enumerate() {
                if local[v as usize] != NONE {
                    split.push(v);
                }
                local[v as usize] = l as u32;
            }
            for &v in &split {
                local[v as usize] = SPLIT;
            }
            let mut triangles = Vec::with_capacity(faces.len());
            for (k, &f) in faces.iter().enumerate() {
                let own = part
                    .faces
                    .get(k)
                    .map(|&g| (mesh.triangles()[g as usize], part.mesh.triangles()[k]));
                let t = out.triangles()[f as usize].map(|v| match local[v as usize] {
                    SPLIT => own
                        .and_then(|(g, l)| g.iter().position(|&x| x == v).map(|j| l[j]))
                        .unwrap_or(NONE),
                    l => l,
                });
                if t.contains(&NONE) || group_of[f as usize] as usize != group {
                    return None;
                }
                triangles.push(t);
            }
            for &v in &vertices {
                local[v as usize] = NONE;
            }
            let name = part.mesh.patch_names()[0].clone();
            let sub = submesh(out, &vertices, triangles, name)?;
            Some((sub, vertices))
        })
        .collect()
}

/// Parts (indices into `parts`) on either side of a seam edge that `merged` folds (adjacent
/// normals turning past [`crate::geometry::FOLD_ANGLE`]) and neither `whole_out` nor the input
/// `mesh` does (an input's own fold at a seam, a lapel turned over, is no new fold). A seam edge
/// keeps its two input faces' indices in both: refinement rewrites a fan triangle in place and
/// keeps its edge opposite the refined vertex, the only one a seam edge can be.
pub(super) fn new_seam_folds(
    mesh: &Mesh,
    parts: &[Part],
    whole_out: &Mesh,
    merged: &Mesh,
) -> Vec<usize> {
    let mut part_of = vec![NONE; mesh.num_faces()];
    for (k, part) in parts.iter().enumerate() {
        for &f in &part.faces {
            part_of[f as usize] = k as u32;
        }
    }
    let limit = crate::geometry::FOLD_ANGLE.cos();
    let normal = |m: &Mesh, f: u32| {
        let [a, b, c] = m.face_positions(f as usize);
        let n = crate::mesh::cross(crate::mesh::sub(b, a), crate::mesh::sub(c, a));
        let l = crate::mesh::dot(n, n).sqrt();
        n.map(|x| x / l)
    };
    let folded = |m: &Mesh, f: u32, g: u32| crate::mesh::dot(normal(m, f), normal(m, g)) < limit;
    let mut out = Vec::new();
    for &[f, g] in mesh.conn().edge_faces() {
        if g == NONE || part_of[f as usize] == part_of[g as usize] {
            continue;
        }
        if folded(merged, f, g) && !folded(whole_out, f, g) && !folded(mesh, f, g) {
            for p in [part_of[f as usize], part_of[g as usize]] {
                if p != NONE {
                    out.push(p as usize);
                }
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::RawMesh;

    /// Two unit grids of `k`×`k` cells side by side, sharing the column x = k, as two
    /// patches (a seam) or one; interior grid points lifted by a pseudo-random 0–0.4.
    fn two_panels(k: u32, seam: bool) -> Mesh {
        two_panels_with(k, seam, |i, j| 0.1 * ((i * 7 + j * 3) % 5) as f64)
    }

    /// [`two_panels`] with the height of grid point (i, j) off the panels' borders given.
    /// A grid of `w`×`h` vertices, vertex (i, j) at `at(i, j)`, both triangles of cell (i, j)
    /// in patch `patch(i, j)` of `names`.
    fn grid(
        (w, h): (u32, u32),
        at: impl Fn(u32, u32) -> [f64; 3],
        patch: impl Fn(u32, u32) -> u32,
        names: &[&str],
    ) -> Mesh {
        let positions = (0..w * h).map(|v| at(v % w, v / w)).collect();
        let mut triangles = Vec::new();
        let mut face_patch = Vec::new();
        for j in 0..h - 1 {
            for i in 0..w - 1 {
                let a = j * w + i;
                triangles.push([a, a + 1, a + w + 1]);
                triangles.push([a, a + w + 1, a + w]);
                face_patch.extend([patch(i, j); 2]);
            }
        }
        let raw = RawMesh {
            positions,
            triangles,
            face_patch,
            patch_names: names.iter().map(|&n| n.into()).collect(),
            uv: None,
        };
        Mesh::new(raw).unwrap().0
    }

    /// Two k×k panels side by side (patches "left" and "right" when `seam`), flat on their
    /// boundaries and at height `z` inside.
    fn two_panels_with(k: u32, seam: bool, z: impl Fn(u32, u32) -> f64) -> Mesh {
        let at = |i: u32, j: u32| {
            let inside = i % k != 0 && j % k != 0;
            [i as f64, j as f64, if inside { z(i, j) } else { 0.0 }]
        };
        let patch = |i: u32, _| u32::from(seam && i >= k);
        grid((2 * k + 1, k + 1), at, patch, &["left", "right"])
    }

    #[test]
    fn a_mesh_that_stalls_whole_is_retried_part_by_part_and_never_worse() {
        use super::super::{solve, Params};
        use crate::geometry::max_flattenability;
        // Left: a noisy saddle; right: a noisy dome.
        let k = 10;
        let mesh = two_panels_with(k, true, |i, j| {
            let (x, y) = ((i % k) as f64 - 5.0, j as f64 - 5.0);
            let noise = 0.15 * ((i * 7 + j * 13) % 5) as f64;
            noise
                + if i < k {
                    0.15 * (x * x - y * y)
                } else {
                    0.15 * (50.0 - x * x - y * y)
                }
        });
        // A stall (ϖ_max not halving within two iterations) before the budget.
        let params = Params {
            max_iterations: 30,
            stall_iterations: 2,
            refine: false,
            ..Params::default()
        };
        let (out, r) = solve(&mesh, &params, &crate::algorithms::Silent::default()).unwrap();
        assert_eq!(r.parts.len(), 2, "{}", r.stop_reason);
        // Every part's figure is its own ϖ_max measured on the output, never above its input's.
        for (part, row) in split(&mesh).unwrap().iter().zip(&r.parts) {
            let mine: Vec<[f64; 3]> = part.vertices.iter().map(|&v| out.position(v)).collect();
            let measured = max_flattenability(&part.mesh.with_positions(mine).unwrap());
            assert_eq!(row.max_flattenability, measured);
            assert!(measured <= max_flattenability(&part.mesh));
            assert_eq!(row.converged, measured <= params.tolerance);
        }
        assert_eq!(r.converged, r.parts.iter().all(|p| p.converged));
        assert!(max_flattenability(&out) <= max_flattenability(&mesh));
        assert_eq!(r.max_flattenability, max_flattenability(&out));
        // Boundary and seam bit-identical; one history over every run.
        for v in 0..mesh.num_vertices() as u32 {
            if !mesh.conn().is_interior(v) {
                assert_eq!(out.position(v), mesh.position(v));
            }
        }
        assert_eq!(r.history.len(), r.iterations);
        let own: usize = r.parts.iter().map(|p| p.iterations).sum();
        assert!(own > 0 && r.iterations > own, "{:?}", r.parts);
        // Here the whole run stalls but each part alone converges (the dome from its cone,
        // which a mesh of two patches never gets).
        assert!(r.converged, "{:?}", r.parts);
        assert!(r.parts.iter().all(|p| p.kept == "alone"), "{:?}", r.parts);
    }

    #[test]
    fn a_seam_splits_a_mesh_into_parts_whose_free_vertices_are_the_wholes() {
        let mesh = two_panels(4, true);
        let parts = split(&mesh).expect("two patches across a seam are two parts");
        assert_eq!(parts.len(), 2);
        let mut free: Vec<u32> = parts
            .iter()
            .flat_map(|p| {
                p.mesh
                    .conn()
                    .interior_vertices()
                    .map(|l| p.vertices[l as usize])
            })
            .collect();
        free.sort_unstable();
        let whole: Vec<u32> = mesh.conn().interior_vertices().collect();
        assert_eq!(free, whole);
        // Every face lands in exactly one part, with its vertices.
        let mut faces: Vec<u32> = parts.iter().flat_map(|p| p.faces.clone()).collect();
        faces.sort_unstable();
        assert_eq!(faces, (0..mesh.num_faces() as u32).collect::<Vec<_>>());
        for p in &parts {
            for (k, &f) in p.faces.iter().enumerate() {
                let t = p.mesh.triangles()[k].map(|l| p.vertices[l as usize]);
                assert_eq!(t, mesh.triangles()[f as usize]);
            }
        }
        // One patch without the seam: one part, nothing to split.
        assert!(split(&two_panels(4, false)).is_none());
    }

    /// A flat 7 × 7 grid of unit cells: patch "b" is two 2 × 2 blocks meeting only at the
    /// grid point (3, 3), patch "a" everything else, so "a" meets itself there too: two
    /// wedges of one part at one seam vertex (a bow-tie within the part). Every grid point is
    /// lifted by a pseudo-random 0–0.2, so that there is something to solve.
    fn bow_tie_panels() -> Mesh {
        let w = 8u32;
        let at = |i: u32, j: u32| [i as f64, j as f64, 0.05 * (((j * w + i) * 7) % 5) as f64];
        let patch = |i: u32, j: u32| {
            let b = ((1..3).contains(&i) && (1..3).contains(&j))
                || ((3..5).contains(&i) && (3..5).contains(&j));
            u32::from(b)
        };
        grid((w, w), at, patch, &["a", "b"])
    }

    #[test]
    fn a_part_that_meets_itself_at_a_seam_vertex_is_split_there_and_merges_back() {
        let mesh = bow_tie_panels();
        let parts = split(&mesh).expect("a bow-tie within a part no longer declines the split");
        assert_eq!(parts.len(), 3);
        let a = &parts[0];
        // Grid point (3, 3) is vertex 27: "a" holds it twice, once per wedge, both on its
        // boundary; every other vertex once.
        let ids: Vec<usize> = (0..a.vertices.len())
            .filter(|&l| a.vertices[l] == 27)
            .collect();
        assert_eq!(ids.len(), 2);
        for &l in &ids {
            assert!(!a.mesh.conn().is_interior(l as u32));
            assert_eq!(a.mesh.position(l as u32), mesh.position(27));
        }
        let mut unique = a.vertices.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), a.vertices.len() - 1);
        // Its faces are the whole's, and its free vertices the whole's free vertices in it.
        for (k, &f) in a.faces.iter().enumerate() {
            let t = a.mesh.triangles()[k].map(|l| a.vertices[l as usize]);
            assert_eq!(t, mesh.triangles()[f as usize]);
        }
        let mut free: Vec<u32> = parts
            .iter()
            .flat_map(|p| {
                p.mesh
                    .conn()
                    .interior_vertices()
                    .map(|l| p.vertices[l as usize])
            })
            .collect();
        free.sort_unstable();
        assert_eq!(free, mesh.conn().interior_vertices().collect::<Vec<_>>());
        // Merged unchanged it is the mesh; restricted, the mesh gives each part back.
        let outs: Vec<&Mesh> = parts.iter().map(|p| &p.mesh).collect();
        let raw = merge(&mesh, &parts, &outs);
        assert_eq!(raw.positions, mesh.positions());
        assert_eq!(raw.triangles, mesh.triangles());
        let back = restrict(&mesh, &mesh, &parts).expect("restricted");
        for (p, (m, ids)) in parts.iter().zip(&back) {
            assert_eq!(m.triangles(), p.mesh.triangles());
            assert_eq!(ids, &p.vertices);
        }
        // Solved, it ends flattenable, measured on the output's own angles, with the split
        // vertex where it was.
        let params = super::super::Params::default();
        let (out, _) = super::super::solve(&mesh, &params, &crate::algorithms::Silent::default())
            .expect("solved");
        assert!(crate::geometry::max_flattenability(&out) <= params.tolerance);
        assert_eq!(out.position(27), mesh.position(27));
    }

    #[test]
    fn merging_unchanged_parts_gives_back_the_mesh_and_refined_ones_keep_every_index() {
        let mesh = two_panels(3, true);
        let parts = split(&mesh).unwrap();
        let outs: Vec<&Mesh> = parts.iter().map(|p| &p.mesh).collect();
        let raw = merge(&mesh, &parts, &outs);
        assert_eq!(raw.positions, mesh.positions());
        assert_eq!(raw.triangles, mesh.triangles());
        assert_eq!(raw.face_patch, mesh.face_patch());
        // Refine one interior vertex of the second part: its faces are replaced in place,
        // new ones appended with its patch, and every input vertex keeps its position.
        let second = &parts[1];
        let v = second.mesh.conn().interior_vertices().next().unwrap();
        let refined = Mesh::new(super::super::refine_sqrt3(&second.mesh, &[v]))
            .unwrap()
            .0;
        let outs = [&parts[0].mesh, &refined];
        let raw = merge(&mesh, &parts, &outs);
        let merged = Mesh::new(raw).unwrap().0;
        assert_eq!(
            merged.num_vertices(),
            mesh.num_vertices() + refined.num_vertices() - second.mesh.num_vertices()
        );
        assert_eq!(
            merged.num_faces(),
            mesh.num_faces() + refined.num_faces() - second.mesh.num_faces()
        );
        assert_eq!(&merged.positions()[..mesh.num_vertices()], mesh.positions());
        let right = merged.face_patch()[second.faces[0] as usize];
        assert!(merged.face_patch()[mesh.num_faces()..]
            .iter()
            .all(|&p| p == right));
        // The appended vertices are the centroids that refining the whole at the same vertex
        // appends (the fans may start at another face, hence sorted).
        let whole = super::super::refine_sqrt3(&mesh, &[second.vertices[v as usize]]);
        let sorted = |p: &[[f64; 3]]| {
            let mut p = p.to_vec();
            p.sort_by(|a, b| a.partial_cmp(b).unwrap());
            p
        };
        let n = mesh.num_vertices();
        assert_eq!(
            sorted(&merged.positions()[n..]),
            sorted(&whole.positions[n..])
        );
        // Restricting the whole's refinement gives each part back as the part's refinement.
        let whole = Mesh::new(whole).unwrap().0;
        let back = restrict(&whole, &mesh, &parts).expect("the refined whole splits back");
        assert_eq!(back[0].0.positions(), parts[0].mesh.positions());
        assert_eq!(back[1].0.num_vertices(), refined.num_vertices());
        assert_eq!(back[1].0.num_faces(), refined.num_faces());
        let outs: Vec<&Mesh> = back.iter().map(|(m, _)| m).collect();
        let again = merge(&mesh, &parts, &outs);
        assert_eq!(sorted(&again.positions), sorted(whole.positions()));
        assert_eq!(again.triangles.len(), whole.num_faces());
        // Both parts refined in the whole (the first's new vertices come first in the merge,
        // so the second's are offset by them): split back and merged, every appended vertex
        // and face is there, and each part's share matches refining that part alone.
        let picks: Vec<u32> = parts
            .iter()
            .map(|p| p.vertices[p.mesh.conn().interior_vertices().next().unwrap() as usize])
            .collect();
        let both = Mesh::new(super::super::refine_sqrt3(&mesh, &picks))
            .unwrap()
            .0;
        let back = restrict(&both, &mesh, &parts).expect("splits back");
        for (p, (m, _)) in parts.iter().zip(&back) {
            let v = p.mesh.conn().interior_vertices().next().unwrap();
            let alone = super::super::refine_sqrt3(&p.mesh, &[v]);
            assert_eq!(m.num_vertices(), alone.positions.len());
            assert_eq!(m.num_faces(), alone.triangles.len());
        }
        let outs: Vec<&Mesh> = back.iter().map(|(m, _)| m).collect();
        let again = Mesh::new(merge(&mesh, &parts, &outs)).unwrap().0;
        assert_eq!(sorted(again.positions()), sorted(both.positions()));
        assert_eq!(again.num_faces(), both.num_faces());
        let n0 = back[0].0.num_vertices() - parts[0].vertices.len();
        let first_new = mesh.num_vertices() as u32;
        // The second part's first new vertex lands after the first part's.
        let l = parts[1].vertices.len() as u32;
        assert_eq!(
            global_vertex(&parts[1], first_new + n0 as u32, l),
            first_new + n0 as u32
        );
        assert_eq!(again.position(first_new + n0 as u32), back[1].0.position(l));
    }
}
