//! Every kind of bad input is refused with an error naming the element, or repaired with a
//! warning, as documented in `flatmesh::mesh`.

use flatmesh::io::{self, Format, ReadError};
use flatmesh::mesh::{Mesh, MeshError, RawMesh, VertexKind};
use flatmesh::report::Report;

fn raw(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> RawMesh {
    RawMesh {
        positions,
        triangles,
        ..RawMesh::default()
    }
}

fn obj(text: &str) -> Result<(Mesh, Vec<flatmesh::mesh::Warning>), ReadError> {
    io::load(text.as_bytes(), Format::Obj)
}

const SQUARE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

#[test]
fn empty_mesh() {
    assert_eq!(Mesh::new(RawMesh::default()).unwrap_err(), MeshError::Empty);
    let e = obj("# nothing\nv 0 0 0\n").unwrap_err();
    assert_eq!(e, ReadError::Mesh(MeshError::Empty));
    assert_eq!(e.to_string(), "the mesh has no faces");
}

#[test]
fn index_out_of_range() {
    let e = Mesh::new(raw(vec![[0.0; 3]; 3], vec![[0, 1, 5]])).unwrap_err();
    assert_eq!(
        e,
        MeshError::IndexOutOfRange {
            face: 0,
            corner: 2,
            index: 5,
            vertices: 3
        }
    );
    let e = obj(&format!("{SQUARE}f 1 2 3\nf 1 3 9\n")).unwrap_err();
    assert!(matches!(e, ReadError::Syntax { line: 6, .. }), "{e}");
    assert!(
        e.to_string().contains("vertex index 9 is out of range"),
        "{e}"
    );
    let e = obj(&format!("{SQUARE}f 1 2 -7\n")).unwrap_err();
    assert!(e.to_string().contains("line 5"), "{e}");
    let e = obj(&format!("{SQUARE}f 0 1 2\n")).unwrap_err();
    assert!(e.to_string().contains("index 0 is invalid"), "{e}");
    let e = obj(&format!("{SQUARE}vt 0 0\nf 1/1 2/2 3/1\n")).unwrap_err();
    assert!(e.to_string().contains("texture index 2"), "{e}");
    let e = obj(&format!("{SQUARE}f 1//1 2//1 3//1\n")).unwrap_err();
    assert!(e.to_string().contains("normal index 1"), "{e}");
}

#[test]
fn non_finite_coordinate() {
    let e = obj("v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n").unwrap_err();
    assert!(matches!(
        e,
        ReadError::Mesh(MeshError::NonFinite {
            vertex: 2,
            axis: 'y',
            ..
        })
    ));
    let e = obj("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert!(e.to_string().contains("vertex 1 has a non-finite z"), "{e}");
    let e = obj("v 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert!(e.to_string().contains("line 2"), "{e}");
}

#[test]
fn degenerate_faces() {
    let e = Mesh::new(raw(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 1]],
    ))
    .unwrap_err();
    assert!(matches!(
        e,
        MeshError::DegenerateFace {
            face: 0,
            reason: "repeated vertex",
            ..
        }
    ));
    // Collinear points: zero area.
    let e = obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 4\nf 1 2 3\n").unwrap_err();
    assert_eq!(
        e,
        ReadError::Mesh(MeshError::DegenerateFace {
            face: 1,
            vertices: [0, 1, 2],
            reason: "zero area"
        })
    );
    assert!(e
        .to_string()
        .contains("face 1 (vertices 0 1 2) is degenerate"));
    let e = obj(&format!("{SQUARE}f 1 2\n")).unwrap_err();
    assert!(e.to_string().contains("face with 2 vertices"), "{e}");
}

#[test]
fn non_manifold_edge() {
    // Three triangles on edge 0-1.
    let e = Mesh::new(raw(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [0.5, -1.0, 0.0],
            [0.5, 0.0, 1.0],
        ],
        vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    ))
    .unwrap_err();
    assert_eq!(
        e,
        MeshError::NonManifoldEdge {
            a: 0,
            b: 1,
            faces: vec![0, 1, 2]
        }
    );
    assert_eq!(
        e.to_string(),
        "non-manifold edge 0-1: shared by 3 faces (0, 1, 2)"
    );
}

#[test]
fn bow_tie_vertex_is_split_one_vertex_per_fan() {
    // Two triangles touching only at vertex 0 (a bow-tie): the second fan gets vertex 5, at
    // the same position; no index of the input changes.
    let (mesh, warnings) = Mesh::new(raw(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [-1.0, -1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 3, 4]],
    ))
    .unwrap();
    assert_eq!(mesh.num_vertices(), 6);
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [5, 3, 4]]);
    assert_eq!(mesh.position(5), mesh.position(0));
    assert_eq!(mesh.conn().boundary_loops().len(), 2);
    let w = warnings
        .iter()
        .find(|w| w.code == "bow_tie_vertices_split")
        .expect("a warning");
    assert!(w.message.contains("0 → 0 and 5"), "{}", w.message);
}

#[test]
fn bow_tie_with_three_fans_gets_two_new_vertices() {
    // Three triangles around vertex 0, pairwise touching only there.
    let (mesh, warnings) = Mesh::new(raw(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [-1.0, -1.0, 0.0],
            [0.0, 1.0, 1.0],
            [0.0, 1.0, 2.0],
        ],
        vec![[0, 1, 2], [0, 3, 4], [0, 5, 6]],
    ))
    .unwrap();
    assert_eq!(mesh.num_vertices(), 9);
    let at_origin = mesh.triangles().iter().map(|t| t[0]).collect::<Vec<_>>();
    assert_eq!(at_origin, vec![0, 7, 8]);
    assert!(warnings
        .iter()
        .any(|w| w.code == "bow_tie_vertices_split" && w.message.starts_with("1 vertices")));
}

#[test]
fn duplicate_face() {
    let e = obj(&format!("{SQUARE}f 1 2 3\nf 1 3 4\nf 3 1 2\n")).unwrap_err();
    assert_eq!(
        e,
        ReadError::Mesh(MeshError::DuplicateFace {
            face: 2,
            first: 0,
            vertices: [2, 0, 1]
        })
    );
}

#[test]
fn inconsistent_orientation_is_repaired() {
    // Face 1 is wound the wrong way relative to faces 0 and 2: the minority is flipped.
    let (mesh, warnings) = obj(&format!("{SQUARE}v 2 0 0\nf 1 2 3\nf 1 4 3\nf 2 5 3\n")).unwrap();
    assert_eq!(warnings.len(), 1);
    assert_eq!(warnings[0].code, "orientation_repaired");
    assert!(
        warnings[0].message.starts_with("1 faces were flipped"),
        "{}",
        warnings[0].message
    );
    assert!(
        warnings[0].message.contains("faces 1)"),
        "{}",
        warnings[0].message
    );
    assert_eq!(mesh.triangles()[0], [0, 1, 2]);
    assert_eq!(mesh.triangles()[1], [0, 2, 3]);
    assert_eq!(mesh.triangles()[2], [1, 4, 2]);
    // Now the shared edge has two opposite half-edges.
    assert_eq!(mesh.conn().boundary_loops().len(), 1);
    assert_eq!(mesh.conn().boundary_loops()[0].len(), 5);
}

#[test]
fn non_orientable_surface_is_refused() {
    // A Möbius strip of 6 quads.
    let n = 6usize;
    let mut positions = Vec::new();
    for i in 0..n {
        let t = i as f64 / n as f64 * std::f64::consts::TAU;
        for s in [-0.3, 0.3] {
            let w = s * (t / 2.0).cos();
            let r = 1.0 + w;
            positions.push([r * t.cos(), r * t.sin(), s * (t / 2.0).sin()]);
        }
    }
    let mut triangles = Vec::new();
    for i in 0..n as u32 {
        let (a, b) = (2 * i, 2 * i + 1);
        let (c, d) = if i + 1 == n as u32 {
            (1, 0)
        } else {
            (2 * i + 2, 2 * i + 3)
        };
        triangles.push([a, c, d]);
        triangles.push([a, d, b]);
    }
    let e = Mesh::new(raw(positions, triangles)).unwrap_err();
    assert!(matches!(e, MeshError::NonOrientable { .. }), "{e}");
    assert!(e.to_string().starts_with("non-orientable surface: faces"));
}

#[test]
fn unreferenced_vertices_are_kept_and_ignored() {
    let (mesh, warnings) = obj("v 9 9 9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 7 7 7\nf 2 3 4\n").unwrap();
    assert_eq!(mesh.num_vertices(), 5, "indices stay the file's");
    assert_eq!(mesh.triangles()[0], [1, 2, 3]);
    assert_eq!(mesh.conn().kind(0), VertexKind::Unreferenced);
    assert_eq!(warnings[0].code, "unreferenced_vertices");
    assert!(
        warnings[0].message.contains("vertices 0, 4"),
        "{}",
        warnings[0].message
    );
    let report = Report::compute(&mesh, &warnings);
    assert_eq!(report.per_vertex[0].kind, "unreferenced");
    assert_eq!(report.per_vertex[0].flattenability, 0.0);
    assert!(report.area > 0.49 && report.area < 0.51);
    assert_eq!(report.warnings, warnings);
}

#[test]
fn bad_patch_ids_and_lengths() {
    let mut r = raw(
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    );
    r.face_patch = vec![3];
    r.patch_names = vec!["a".into()];
    assert!(matches!(
        Mesh::new(r.clone()).unwrap_err(),
        MeshError::PatchOutOfRange {
            face: 0,
            patch: 3,
            patches: 1
        }
    ));
    r.face_patch = vec![0, 0];
    assert!(matches!(
        Mesh::new(r).unwrap_err(),
        MeshError::Inconsistent { .. }
    ));
}

#[test]
fn with_positions_rejects_nan_and_degeneracy() {
    let (mesh, _) = obj(&format!("{SQUARE}f 1 2 3\nf 1 3 4\n")).unwrap();
    let mut p = mesh.positions().to_vec();
    p[2][0] = f64::NAN;
    assert!(matches!(
        mesh.with_positions(p).unwrap_err(),
        MeshError::NonFinite {
            vertex: 2,
            axis: 'x',
            ..
        }
    ));
    let mut p = mesh.positions().to_vec();
    p[2] = p[0];
    assert!(matches!(
        mesh.with_positions(p).unwrap_err(),
        MeshError::DegenerateFace { face: 0, .. }
    ));
}

#[test]
fn unknown_format_and_garbage() {
    assert_eq!(Format::sniff(b"\x00\x01\x02"), None);
    assert_eq!(Format::sniff(b"glTF\x02\0\0\0"), Some(Format::Glb));
    assert_eq!(Format::sniff(b"OFF\n3 1 0\n"), Some(Format::Off));
    assert_eq!(Format::sniff(b"  {\"asset\":{}}"), Some(Format::Gltf));
    assert_eq!(Format::sniff(b"# x\nv 0 0 0\n"), Some(Format::Obj));
    // Random bytes fed to each text reader never panic.
    let mut state = 1u64;
    for len in [0usize, 1, 7, 64, 1000] {
        let bytes: Vec<u8> = (0..len)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 56) as u8
            })
            .collect();
        let _ = io::load(&bytes, Format::Obj);
        let _ = io::load(&bytes, Format::Off);
    }
}
