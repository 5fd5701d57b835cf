//! The report against closed-form answers, connectivity against hand-built meshes, and the
//! `flatmesh report` command's contract (JSON fields, exit codes).

use flatmesh::io::{self, Format};
use flatmesh::mesh::{Mesh, RawMesh, VertexKind};
use flatmesh::report::Report;
use std::f64::consts::{PI, TAU};
use std::process::Command;

/// A square pyramid without its base: apex 0 at height h over the square (±1, 0), (0, ±1).
fn pyramid(h: f64) -> Mesh {
    let raw = RawMesh {
        positions: vec![
            [0.0, 0.0, h],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]],
        ..RawMesh::default()
    };
    Mesh::new(raw).unwrap().0
}

#[test]
fn pyramid_apex_matches_closed_form() {
    for h in [0.0, 1e-4, 0.3, 1.0, 5.0] {
        let m = pyramid(h);
        let r = Report::compute(&m, &[]);
        // Each face's apex angle: cos α = h² / (1 + h²).
        let theta = 4.0 * (h * h / (1.0 + h * h)).acos();
        let varpi = TAU - theta;
        assert!((r.per_vertex[0].angle_sum - theta).abs() < 1e-14, "h = {h}");
        assert!((r.max_flattenability - varpi).abs() < 1e-14, "h = {h}");
        assert_eq!(r.interior_vertices, 1);
        assert_eq!(r.max_flattenability_vertex, Some(0));
        // κ = ϖ / (⅓ Σ A_j); each face has area ½ |(1,0,−h) × (0,1,−h)| = ½ sqrt(2h² + 1).
        let area = 4.0 * 0.5 * (2.0 * h * h + 1.0).sqrt();
        let kappa = r.per_vertex[0].gaussian_curvature.unwrap();
        assert!((kappa - varpi / (area / 3.0)).abs() < 1e-12 * kappa.abs().max(1.0));
        assert!((r.area - area).abs() < 1e-14);
        assert!((r.g - varpi * varpi).abs() <= 1e-14 * (1.0 + varpi * varpi));
        // D: the apex carries a third of the area; boundary vertices count as developable.
        let d = if varpi <= 1e-6 { 1.0 } else { 2.0 / 3.0 };
        assert!((r.d - d).abs() < 1e-12, "h = {h}: D = {}", r.d);
        assert_eq!(r.histogram.iter().map(|b| b.count).sum::<usize>(), 1);
        let bin = r.histogram.iter().find(|b| b.count == 1).unwrap();
        assert!(bin.lo < varpi || varpi == 0.0);
        assert!(bin.hi.is_none_or(|hi| varpi <= hi));
        for v in 1..5 {
            assert_eq!(r.per_vertex[v].kind, "boundary");
            assert_eq!(r.per_vertex[v].flattenability, 0.0);
            assert_eq!(r.per_vertex[v].gaussian_curvature, None);
        }
    }
}

#[test]
fn fans_and_loops_are_ordered_counter_clockwise() {
    let m = pyramid(0.5);
    let c = m.conn();
    // Seen from +z the faces run counter-clockwise, and so does the apex's ring.
    let ring = c.ring_of(0);
    assert_eq!(ring.len(), 4);
    let start = ring.iter().position(|&v| v == 1).unwrap();
    let rotated: Vec<u32> = (0..4).map(|k| ring[(start + k) % 4]).collect();
    assert_eq!(rotated, vec![1, 2, 3, 4]);
    // A boundary vertex's ring runs from one boundary neighbour round to the other,
    // counter-clockwise seen from +z: at (1, 0), vertex 2 lies at 135°, 0 at 180°, 4 at 225°.
    assert_eq!(c.ring_of(1), &[2, 0, 4]);
    assert_eq!(c.kind(0), VertexKind::Interior);
    // One boundary loop, traversed with the surface on its left (counter-clockwise from +z).
    let loops = c.boundary_loops();
    assert_eq!(loops.len(), 1);
    let l = &loops[0];
    let s = l.iter().position(|&v| v == 1).unwrap();
    let rotated: Vec<u32> = (0..4).map(|k| l[(s + k) % 4]).collect();
    assert_eq!(rotated, vec![1, 2, 3, 4]);
    assert_eq!(c.edges().len(), 8);
    assert_eq!(c.patches()[0].euler_characteristic(), 1);
}

#[test]
fn seams_split_patches_but_keep_the_surface_whole() {
    // The pyramid with two faces in patch "a" and two in "b": the apex becomes a seam vertex.
    let mut raw = pyramid(0.5).to_raw();
    raw.face_patch = vec![0, 0, 1, 1];
    raw.patch_names = vec!["a".into(), "b".into()];
    let (m, _) = Mesh::new(raw).unwrap();
    let c = m.conn();
    assert_eq!(c.kind(0), VertexKind::Seam);
    assert_eq!(c.shared_vertices(), &[0, 1, 3]);
    for p in c.patches() {
        assert_eq!(p.boundary_loops.len(), 1);
        assert_eq!(
            p.boundary_loops[0].len(),
            4,
            "two outer edges and two seam edges"
        );
        assert_eq!(p.euler_characteristic(), 1);
    }
    let r = Report::compute(&m, &[]);
    assert_eq!(r.interior_vertices, 0, "ϖ is only defined inside a patch");
    assert_eq!(r.per_vertex[0].kind, "seam");
    assert!(r.per_vertex[0].gaussian_curvature.is_some());
    // Gauss–Bonnet per patch: turning + defects = 2π χ.
    for p in 0..2 {
        let k = flatmesh::geometry::patch_total_curvature(&m, p);
        assert!((k - TAU).abs() < 1e-12, "patch {p}: {k}");
    }
}

#[test]
fn closed_surface_total_defect_is_4pi() {
    // An octahedron: χ = 2, every vertex has defect 2π − 4·π/3.
    let m = flatmesh::corpus::octahedron();
    let r = Report::compute(&m, &[]);
    assert_eq!(r.interior_vertices, 6);
    assert_eq!(r.boundary_loops, 0);
    assert!((r.max_flattenability - (TAU - 4.0 * PI / 3.0)).abs() < 1e-14);
    let total: f64 = r.per_vertex.iter().map(|v| TAU - v.angle_sum).sum();
    assert!((total - 4.0 * PI).abs() < 1e-12);
}

fn flatmesh(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cli_report_json_and_exit_codes() {
    let dir = std::env::temp_dir().join(format!("flatmesh-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = dir.join("pyramid.obj");
    std::fs::write(&good, io::obj::write(&pyramid(0.5).to_raw())).unwrap();
    let out = flatmesh(&["report", "--json", good.to_str().unwrap()]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "vertices",
        "faces",
        "patches",
        "interior_vertices",
        "max_flattenability",
        "mean_flattenability",
        "rms_flattenability",
        "wang_tang_d",
        "wang_tang_g",
        "histogram",
        "per_vertex",
        "warnings",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    for key in [
        "name",
        "faces",
        "vertices",
        "interior_vertices",
        "boundary_loops",
    ] {
        assert!(v["patches"][0].get(key).is_some(), "patch missing {key}");
    }
    for key in ["index", "interior", "flattenability", "gaussian_curvature"] {
        assert!(
            v["per_vertex"][0].get(key).is_some(),
            "per_vertex missing {key}"
        );
    }
    let expected = TAU - 4.0 * (0.25f64 / 1.25).acos();
    assert!((v["max_flattenability"].as_f64().unwrap() - expected).abs() < 1e-12);

    // Human summary by default.
    let out = flatmesh(&["report", good.to_str().unwrap()]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("5 vertices, 4 faces"), "{text}");

    // Invalid input: exit 2, one line on stderr naming the problem.
    let bad = dir.join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
    let out = flatmesh(&["report", "--json", bad.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("face 0 (vertices 0 1 2) is degenerate: zero area"),
        "{err}"
    );
    assert!(out.stdout.is_empty());

    // A missing file is not invalid input: exit 1.
    let out = flatmesh(&["report", dir.join("missing.obj").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn load_sniffs_format_without_extension() {
    let text = io::obj::write(&pyramid(0.2).to_raw());
    assert_eq!(Format::sniff(text.as_bytes()), Some(Format::Obj));
    let (m, _) = io::load(text.as_bytes(), Format::Obj).unwrap();
    assert_eq!(m.num_faces(), 4);
}
