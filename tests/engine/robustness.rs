//! Untrusted input never panics: random OBJ text and random triangle soups either load or are
//! refused, and what loads satisfies the connectivity invariants.

use flatmesh::io::{self, Format};
use flatmesh::mesh::{Mesh, RawMesh, VertexKind};
use flatmesh::report::Report;
use proptest::prelude::*;

fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("v".to_string()),
        Just("vt".to_string()),
        Just("vn".to_string()),
        Just("f".to_string()),
        Just("g".to_string()),
        Just("o".to_string()),
        Just("#".to_string()),
        Just("\\".to_string()),
        Just("nan".to_string()),
        Just("1e400".to_string()),
        Just("//".to_string()),
        (-5i64..8).prop_map(|i| i.to_string()),
        (-2.0f64..2.0).prop_map(|x| x.to_string()),
        ((-4i64..6), (-4i64..6)).prop_map(|(a, b)| format!("{a}/{b}")),
        ((-4i64..6), (-4i64..6)).prop_map(|(a, b)| format!("{a}//{b}")),
        "[a-z/ ]{0,4}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_obj_text_never_panics(lines in proptest::collection::vec(
        proptest::collection::vec(token(), 0..6), 0..30)) {
        let text: String = lines.iter().map(|l| l.join(" ") + "\n").collect();
        if let Ok((mesh, warnings)) = io::load(text.as_bytes(), Format::Obj) {
            let r = Report::compute(&mesh, &warnings);
            prop_assert!(r.max_flattenability.is_finite());
        }
        let _ = io::load(text.as_bytes(), Format::Off);
    }

    #[test]
    fn random_triangle_soups_load_or_are_refused(
        nv in 3usize..12,
        tris in proptest::collection::vec((0u32..12, 0u32..12, 0u32..12), 1..24),
        coords in proptest::collection::vec(-1.0f64..1.0, 36),
        patches in proptest::collection::vec(0u32..3, 24),
    ) {
        let positions: Vec<[f64; 3]> =
            (0..nv).map(|i| [coords[3 * i], coords[3 * i + 1], coords[3 * i + 2]]).collect();
        let triangles: Vec<[u32; 3]> = tris.iter().map(|&(a, b, c)| [a, b, c]).collect();
        let face_patch = patches[..triangles.len()].to_vec();
        check_invariants(RawMesh {
            positions,
            triangles,
            face_patch,
            patch_names: vec!["a".into(), "b".into(), "c".into()],
            uv: None,
        })?;
    }

    /// Grids with faces removed (holes, pinches), faces flipped (orientation repair), vertices
    /// welded (non-manifold cases) and random patches: mostly valid, often strange.
    #[test]
    fn damaged_grids_keep_connectivity_invariants(
        n in 2usize..7,
        m in 2usize..7,
        remove in proptest::collection::vec(any::<bool>(), 72),
        flip in proptest::collection::vec(0u8..10, 72),
        patches in proptest::collection::vec(0u32..3, 72),
        noise in proptest::collection::vec(-0.3f64..0.3, 49),
        weld in proptest::option::of((0u32..49, 0u32..49)),
    ) {
        let mut positions = Vec::new();
        for j in 0..=m {
            for i in 0..=n {
                positions.push([i as f64, j as f64, noise[(j * 7 + i) % 49]]);
            }
        }
        let mut triangles = Vec::new();
        let mut face_patch = Vec::new();
        for j in 0..m {
            for i in 0..n {
                let a = (j * (n + 1) + i) as u32;
                let (b, c, d) = (a + 1, a + (n + 1) as u32, a + (n + 2) as u32);
                for t in [[a, b, d], [a, d, c]] {
                    let f = triangles.len();
                    if remove[f % 72] && f % 3 == 0 {
                        continue;
                    }
                    triangles.push(if flip[f % 72] == 0 { [t[0], t[2], t[1]] } else { t });
                    face_patch.push(patches[f % 72]);
                }
            }
        }
        if let Some((x, y)) = weld {
            let nvtx = positions.len() as u32;
            let (x, y) = (x % nvtx, y % nvtx);
            for t in triangles.iter_mut() {
                for v in t.iter_mut() {
                    if *v == y {
                        *v = x;
                    }
                }
            }
        }
        check_invariants(RawMesh {
            positions,
            triangles,
            face_patch,
            patch_names: vec!["a".into(), "b".into(), "c".into()],
            uv: None,
        })?;
    }
}

fn check_invariants(raw: RawMesh) -> Result<(), TestCaseError> {
    let Ok((mesh, _)) = Mesh::new(raw) else {
        return Ok(());
    };
    let c = mesh.conn();
    let mut fan_total = 0;
    for v in 0..mesh.num_vertices() as u32 {
        let fan = c.fan_of(v);
        let ring = c.ring_of(v);
        fan_total += fan.len();
        match c.kind(v) {
            VertexKind::Unreferenced => prop_assert!(fan.is_empty()),
            VertexKind::Boundary => prop_assert_eq!(ring.len(), fan.len() + 1),
            VertexKind::Interior | VertexKind::Seam => prop_assert_eq!(ring.len(), fan.len()),
        }
        // Consecutive fan faces share the edge to the ring neighbour between them.
        for (j, &h) in fan.iter().enumerate() {
            let t = mesh.triangles()[h as usize / 3];
            let k = h as usize % 3;
            prop_assert_eq!(t[k], v);
            prop_assert_eq!(t[(k + 1) % 3], ring[j]);
            prop_assert_eq!(t[(k + 2) % 3], ring[(j + 1) % ring.len()]);
        }
    }
    prop_assert_eq!(fan_total, 3 * mesh.num_faces());
    // Every boundary half-edge appears in exactly one loop.
    let loop_len: usize = c.boundary_loops().iter().map(|l| l.len()).sum();
    let boundary_edges = c
        .edge_faces()
        .iter()
        .filter(|f| f[1] == flatmesh::mesh::NONE)
        .count();
    prop_assert_eq!(loop_len, boundary_edges);
    for p in 0..mesh.num_patches() as u32 {
        let k = flatmesh::geometry::patch_total_curvature(&mesh, p);
        let chi = c.patches()[p as usize].euler_characteristic() as f64;
        prop_assert!(
            (k - std::f64::consts::TAU * chi).abs() < 1e-9,
            "patch {}: {} vs χ {}",
            p,
            k,
            chi
        );
    }
    Ok(())
}

#[test]
fn huge_polygons_are_refused() {
    let mut text = String::new();
    let n = flatmesh::io::obj::MAX_POLYGON + 1;
    for i in 0..n {
        let a = i as f64 / n as f64 * std::f64::consts::TAU;
        text += &format!("v {} {} 0\n", a.cos(), a.sin());
    }
    text += "f";
    for i in 1..=n {
        text += &format!(" {i}");
    }
    text += "\n";
    let e = io::load(text.as_bytes(), Format::Obj).unwrap_err();
    assert!(e.to_string().contains("more than 1024 vertices"), "{e}");
}
