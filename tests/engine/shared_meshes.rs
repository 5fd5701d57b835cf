//! Every mesh of ../shared/meshes loads (or is refused with the right error), and
//! `flatmesh report --json` agrees with an independent recomputation of the angle sums.
//!
//! The recomputation here shares no code with the crate: its own OBJ parsing (triangles;
//! quads split along a diagonal whose triangles face the same way, else the shorter: the
//! documented rule), and Kahan's half-angle formula instead of the crate's atan2.

use std::path::{Path, PathBuf};
use std::process::Command;

fn shared_meshes() -> Option<Vec<PathBuf>> {
    let dir = flatmesh::corpus::shared_root_for_tests("every shared mesh against a recount")?;
    let mut out = Vec::new();
    for sub in std::fs::read_dir(&dir).unwrap() {
        let sub = sub.unwrap().path();
        if sub.is_dir() {
            for f in std::fs::read_dir(&sub).unwrap() {
                let f = f.unwrap().path();
                if f.extension().is_some_and(|e| e == "obj") {
                    out.push(f);
                }
            }
        }
    }
    out.sort();
    assert!(
        out.len() >= 15,
        "expected the 15 shared meshes, found {}",
        out.len()
    );
    Some(out)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// Kahan's angle between u and v: 2 atan(|û − v̂| / |û + v̂|), accurate near 0 and π.
fn kahan_angle(u: [f64; 3], v: [f64; 3]) -> f64 {
    let (lu, lv) = (norm(u), norm(v));
    let uu = [u[0] / lu, u[1] / lu, u[2] / lu];
    let vv = [v[0] / lv, v[1] / lv, v[2] / lv];
    2.0 * norm(sub(uu, vv)).atan2(norm([uu[0] + vv[0], uu[1] + vv[1], uu[2] + vv[2]]))
}

/// Independent angle sums: (number of `v` lines, θ per vertex).
fn independent_angle_sums(text: &str) -> (usize, Vec<f64>) {
    let mut v: Vec<[f64; 3]> = Vec::new();
    let mut faces: Vec<Vec<usize>> = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|x| x.parse().unwrap()).collect();
                v.push([c[0], c[1], c[2]]);
            }
            Some("f") => faces.push(
                it.map(|t| {
                    let i: i64 = t.split('/').next().unwrap().parse().unwrap();
                    if i < 0 {
                        (v.len() as i64 + i) as usize
                    } else {
                        i as usize - 1
                    }
                })
                .collect(),
            ),
            _ => {}
        }
    }
    let mut theta = vec![0.0; v.len()];
    let mut tri = |a: usize, b: usize, c: usize| {
        theta[a] += kahan_angle(sub(v[b], v[a]), sub(v[c], v[a]));
        theta[b] += kahan_angle(sub(v[c], v[b]), sub(v[a], v[b]));
        theta[c] += kahan_angle(sub(v[a], v[c]), sub(v[b], v[c]));
    };
    for f in &faces {
        match f.len() {
            3 => tri(f[0], f[1], f[2]),
            4 => {
                // A diagonal is usable when its two triangles face the same way (a non-convex
                // quad has one such diagonal); when both or neither (a twisted quad), the shorter.
                let cr = |a: [f64; 3], b: [f64; 3]| {
                    [
                        a[1] * b[2] - a[2] * b[1],
                        a[2] * b[0] - a[0] * b[2],
                        a[0] * b[1] - a[1] * b[0],
                    ]
                };
                let nrm = |a: usize, b: usize, c: usize| cr(sub(v[b], v[a]), sub(v[c], v[a]));
                let agree =
                    |p: [f64; 3], q: [f64; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2] > 0.0;
                let ok13 = agree(nrm(f[0], f[1], f[3]), nrm(f[1], f[2], f[3]));
                let ok02 = agree(nrm(f[0], f[1], f[2]), nrm(f[0], f[2], f[3]));
                let shorter13 = norm(sub(v[f[1]], v[f[3]])) < norm(sub(v[f[0]], v[f[2]]));
                let use13 = if ok13 == ok02 { shorter13 } else { ok13 };
                if use13 {
                    tri(f[0], f[1], f[3]);
                    tri(f[1], f[2], f[3]);
                } else {
                    tri(f[0], f[1], f[2]);
                    tri(f[0], f[2], f[3]);
                }
            }
            n => panic!("the shared meshes have triangles and quads only, found a {n}-gon"),
        }
    }
    (v.len(), theta)
}

fn run_report(path: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["report", "--json"])
        .arg(path)
        .output()
        .unwrap()
}

#[test]
fn every_shared_mesh_reports_or_is_refused_precisely() {
    let Some(paths) = shared_meshes() else {
        return;
    };
    let mut checked = 0;
    for path in &paths {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let out = run_report(path);
        if name == "diffavatar_polo.obj" {
            // The collar is attached along edges shared by three faces.
            assert_eq!(out.status.code(), Some(2), "{name}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(err.lines().count(), 1, "one line on stderr: {err}");
            assert!(err.contains("non-manifold edge"), "{err}");
            assert!(err.contains("shared by 3 faces"), "{err}");
            continue;
        }
        if name == "diffavatar_shirt_pifu.obj" {
            // The manifest's bad-input example: a reconstruction with zero-area triangles.
            assert_eq!(out.status.code(), Some(2), "{name}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(err.lines().count(), 1, "one line on stderr: {err}");
            assert!(
                err.contains("face 124 (vertices 83 84 85) is degenerate"),
                "{err}"
            );
            continue;
        }
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let text = std::fs::read_to_string(path).unwrap();
        let (nv, theta) = independent_angle_sums(&text);
        assert_eq!(json["vertices"].as_u64().unwrap() as usize, nv, "{name}");
        let per_vertex = json["per_vertex"].as_array().unwrap();
        assert_eq!(per_vertex.len(), nv);
        let mut max_diff = 0.0f64;
        let mut max_varpi = 0.0f64;
        for (i, pv) in per_vertex.iter().enumerate() {
            assert_eq!(pv["index"].as_u64().unwrap() as usize, i);
            let a = pv["angle_sum"].as_f64().unwrap();
            max_diff = max_diff.max((a - theta[i]).abs());
            let w = pv["flattenability"].as_f64().unwrap();
            if pv["interior"].as_bool().unwrap() {
                assert!(
                    (w - (std::f64::consts::TAU - theta[i]).abs()).abs() <= 1e-9,
                    "{name} vertex {i}"
                );
                max_varpi = max_varpi.max(w);
            } else {
                assert_eq!(w, 0.0);
            }
        }
        assert!(
            max_diff <= 1e-9,
            "{name}: angle sums differ by {max_diff:e} rad"
        );
        let reported = json["max_flattenability"].as_f64().unwrap();
        assert!((reported - max_varpi).abs() <= 1e-9, "{name}");
        let d = json["wang_tang_d"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&d), "{name}: D = {d}");
        checked += 1;
    }
    assert!(checked >= paths.len() - 2);
}

/// Known facts from MANIFEST.tsv, independent of our code: counts, loops, components.
#[test]
fn shared_mesh_topology_matches_the_manifest() {
    let Some(_) = shared_meshes() else {
        return;
    };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let manifest = std::fs::read_to_string(dir.join("MANIFEST.tsv")).unwrap();
    let mut lines = manifest.lines();
    let header: Vec<&str> = lines.next().unwrap().split('\t').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut checked = 0;
    for line in lines {
        let f: Vec<&str> = line.split('\t').collect();
        let file = f[col("file")];
        // Non-manifold edges are refused and bow-tie vertices split by the reader (tested in
        // tests/engine/validation.rs), so the manifest's counts do not apply to those files.
        if f[col("nonmanifold_edges")] != "0" || f[col("nonmanifold_vertices")] != "0" {
            continue;
        }
        let (mesh, _) = flatmesh::io::load_path(&dir.join(file)).unwrap();
        let conn = mesh.conn();
        assert_eq!(
            mesh.num_vertices().to_string(),
            f[col("vertices")],
            "{file}"
        );
        assert_eq!(mesh.num_faces().to_string(), f[col("triangles")], "{file}");
        assert_eq!(
            conn.boundary_loops().len().to_string(),
            f[col("boundary_loops")],
            "{file}"
        );
        assert_eq!(
            conn.components(mesh.num_faces()).to_string(),
            f[col("components")],
            "{file}"
        );
        let boundary_edges: usize = conn.boundary_loops().iter().map(|l| l.len()).sum();
        assert_eq!(
            boundary_edges.to_string(),
            f[col("boundary_edges")],
            "{file}"
        );
        checked += 1;
    }
    assert!(checked >= 14, "only {checked} meshes checked");
}
