//! OBJ and OFF readers and the OBJ writer.

use flatmesh::geometry::face_areas;
use flatmesh::io::{self, obj, Format};
use flatmesh::mesh::Mesh;

fn load(text: &str) -> Mesh {
    io::load(text.as_bytes(), Format::Obj).unwrap().0
}

#[test]
fn all_index_forms_and_negative_indices() {
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n\
                f 1 2 3\nf 1/1 3/3 4/1\n";
    let m = load(text);
    assert_eq!(m.triangles(), &[[0, 1, 2], [0, 2, 3]]);
    let forms = [
        "f 1 2 3",
        "f 1/1 2/2 3/3",
        "f 1//1 2//1 3//1",
        "f 1/1/1 2/2/1 3/3/1",
        "f -4 -3 -2",
        "f -4/-3 -3/-2 -2/-1",
        "f -4//-1 -3//-1 -2//-1",
        "f -4/-3/-1 -3/-2/-1 -2/-1/-1",
    ];
    let head = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n";
    for f in forms {
        let m = load(&format!("{head}{f}\n"));
        assert_eq!(m.triangles(), &[[0, 1, 2]], "{f}");
    }
    // Texture coordinates are kept when every face has them.
    let m = load(&format!("{head}f 1/1 2/2 3/3\n"));
    let uv = m.uv().unwrap();
    assert_eq!(uv.triangles, vec![[0, 1, 2]]);
    assert_eq!(uv.coords[2], [1.0, 1.0]);
}

#[test]
fn comments_crlf_blank_lines_and_continuations() {
    let text =
        "# header\r\n\r\nv 0 0 0 # origin\r\nv 1 0 0\r\n   \r\nv 0 1 \\\r\n 0\r\nf 1 2 3\r\n";
    let m = load(text);
    assert_eq!(m.num_vertices(), 3);
    assert_eq!(m.position(2), [0.0, 1.0, 0.0]);
}

#[test]
fn groups_and_objects_start_patches() {
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nv 1 2 0\n\
                f 1 2 3\no body\ng front\nf 1 3 4\ng back\nf 2 5 6\nf 2 6 3\ng front\nf 4 3 7\n";
    let m = load(text);
    assert_eq!(m.patch_names(), &["default", "body/front", "body/back"]);
    assert_eq!(m.face_patch(), &[0, 1, 2, 2, 1]);
}

#[test]
fn vertex_order_is_the_files() {
    let text = "v 5 5 5\nv 0 0 0\nv 0 1 0\nv 1 0 0\nf 2 4 3\n";
    let m = load(text);
    assert_eq!(m.position(0), [5.0, 5.0, 5.0]);
    assert_eq!(m.position(3), [1.0, 0.0, 0.0]);
    assert_eq!(m.triangles(), &[[1, 3, 2]]);
}

/// A non-convex L-shaped hexagon: the triangulation must cover exactly its area with every
/// triangle facing the polygon's way.
#[test]
fn non_convex_polygons_triangulate_correctly() {
    // L shape, counter-clockwise in the plane z = x + y (tilted, so the projection matters).
    let pts2 = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 1.0],
        [1.0, 1.0],
        [1.0, 2.0],
        [0.0, 2.0],
    ];
    let mut text = String::new();
    for p in pts2 {
        text += &format!("v {} {} {}\n", p[0], p[1], p[0] + p[1]);
    }
    // Start the face at the reflex corner, where a fan would be wrong.
    text += "f 4 5 6 1 2 3\n";
    let m = load(&text);
    assert_eq!(m.num_faces(), 4);
    // Area in 3D: the plane z = x + y scales planar area by sqrt(3); the L has area 3.
    let area: f64 = face_areas(&m).iter().sum();
    assert!((area - 3.0 * 3f64.sqrt()).abs() < 1e-12, "area {area}");
    // Every triangle's normal points along +(−1,−1,1) like the polygon.
    for n in flatmesh::geometry::face_normals(&m) {
        assert!(n[2] > 0.0 && (n[0] + 1.0 / 3f64.sqrt()).abs() < 1e-12);
    }
}

#[test]
fn quads_split_along_the_diagonal_whose_triangles_agree() {
    // An arrowhead: the diagonal from the reflex corner (0–2) is the longer one, and the
    // shorter (1–3) would leave a flipped triangle outside the quad.
    let text = "v -5 0 0\nv 1 -1 0\nv 0.9 0 0\nv 1 1 0\nf 1 2 3 4\n";
    let m = load(text);
    let area: f64 = face_areas(&m).iter().sum();
    assert!((area - 5.9).abs() < 1e-12, "area {area}");
    for n in flatmesh::geometry::face_normals(&m) {
        assert!(n[2] > 0.999, "normal {n:?}");
    }
    // A convex non-planar quad goes along its shorter diagonal wherever the face starts.
    let verts = "v 0 0 0\nv 2 0 0.3\nv 3 2 0\nv 0 1 0.3\n";
    for face in ["f 1 2 3 4\n", "f 2 3 4 1\n", "f 3 4 1 2\n", "f 4 1 2 3\n"] {
        let m = load(&format!("{verts}{face}"));
        let mut diag: Vec<[u32; 2]> = Vec::new();
        for t in m.triangles() {
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                if b - a == 2 {
                    diag.push([a, b]);
                }
            }
        }
        // |v1 − v3| = √(4 + 1) < |v0 − v2| = √(9 + 4).
        assert_eq!(diag, vec![[1, 3], [1, 3]], "{face}");
    }
}

#[test]
fn writer_round_trips_exactly() {
    let text = "v 0.1 0.2 0.30000000000000004\nv 1e-300 0 0\nv 1 1 0\nv 0 1 0\n\
                g a\nf 1 2 3\ng b c\nf 1 3 4\n";
    let (m, _) = io::load(text.as_bytes(), Format::Obj).unwrap();
    let written = obj::write(&m.to_raw());
    let (m2, w) = io::load(written.as_bytes(), Format::Obj).unwrap();
    assert!(w.is_empty());
    assert_eq!(m.positions(), m2.positions(), "bit-identical coordinates");
    assert_eq!(m.triangles(), m2.triangles());
    assert_eq!(m.patch_names(), m2.patch_names());
    assert_eq!(m.face_patch(), m2.face_patch());
}

#[test]
fn off_reader() {
    let text = "OFF\n# a square and a triangle\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n\
                4 0 1 2 3\n3 1 4 2 255 0 0\n";
    let (m, _) = io::load(text.as_bytes(), Format::Off).unwrap();
    assert_eq!(m.num_faces(), 3);
    assert_eq!(m.num_vertices(), 5);
    let e = io::load(b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", Format::Off).unwrap_err();
    assert!(e.to_string().contains("OFF line 6"), "{e}");
    // A forged count allocates nothing: past the limit it is refused at the header, under it
    // the file fails where it ends.
    let e = io::load(b"OFF\n4000000000 1 0\n0 0 0\n", Format::Off).unwrap_err();
    assert!(
        e.to_string().contains("announces 4000000000 vertices"),
        "{e}"
    );
    let e = io::load(b"OFF\n1000000 1 0\n0 0 0\n", Format::Off).unwrap_err();
    assert!(e.to_string().contains("ended early"), "{e}");
    let e = io::load(b"OFF\n3 1 0\n0 0 0\n1 0 0\n", Format::Off).unwrap_err();
    assert!(e.to_string().contains("ended early"), "{e}");
}
