//! The fixtures against what is known about them independently of the code that measures
//! them: topology counted here from the triangle list, Gauss–Bonnet with angles computed here
//! by the law of cosines, and the committed files against the generator.

use flatmesh::fixtures::{self, Fixture};
use flatmesh::geometry;
use flatmesh::mesh::{Mesh, RawMesh};
use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::path::Path;

/// Corner angle at `a` by the law of cosines (deliberately not the library's atan2 form).
fn angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let d = |p: [f64; 3], q: [f64; 3]| {
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    let (ab, ac, bc) = (d(a, b), d(a, c), d(b, c));
    ((ab * ab + ac * ac - bc * bc) / (2.0 * ab * ac))
        .clamp(-1.0, 1.0)
        .acos()
}

/// Topology of the faces `faces` of `raw`, counted from scratch: (V, E, F, boundary edges,
/// boundary loops, per-vertex count of boundary edges, per-vertex angle sum).
struct Counted {
    euler: i64,
    loops: usize,
    boundary_degree: Vec<usize>,
    theta: Vec<f64>,
    used: Vec<bool>,
}

fn count(raw: &RawMesh, faces: &[usize]) -> Counted {
    let n = raw.positions.len();
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    let mut used = vec![false; n];
    let mut theta = vec![0.0; n];
    for &f in faces {
        let t = raw.triangles[f];
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            used[a as usize] = true;
            theta[a as usize] += angle(
                raw.positions[a as usize],
                raw.positions[b as usize],
                raw.positions[c as usize],
            );
        }
    }
    let v = used.iter().filter(|&&u| u).count() as i64;
    let mut boundary_degree = vec![0; n];
    // union–find over boundary edges: each boundary loop is one component when loops are
    // disjoint, which holds for every fixture (no pinched boundary vertex)
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for (&(a, b), &c) in &edges {
        assert!(c <= 2, "edge {a}-{b} has {c} faces");
        if c == 1 {
            boundary_degree[a as usize] += 1;
            boundary_degree[b as usize] += 1;
            let (ra, rb) = (find(&mut parent, a as usize), find(&mut parent, b as usize));
            parent[ra] = rb;
        }
    }
    let mut roots = std::collections::HashSet::new();
    for (x, &deg) in boundary_degree.iter().enumerate() {
        if deg > 0 {
            assert_eq!(deg, 2, "pinched boundary at vertex {x}");
            roots.insert(find(&mut parent, x));
        }
    }
    Counted {
        euler: v - edges.len() as i64 + faces.len() as i64,
        loops: roots.len(),
        boundary_degree,
        theta,
        used,
    }
}

/// Σ (2π − θ) inside + Σ (π − θ) on the boundary, which Gauss–Bonnet says is 2πχ.
fn total_curvature(c: &Counted) -> f64 {
    (0..c.theta.len())
        .filter(|&v| c.used[v])
        .map(|v| {
            if c.boundary_degree[v] > 0 {
                PI - c.theta[v]
            } else {
                TAU - c.theta[v]
            }
        })
        .sum()
}

fn load(f: &Fixture) -> Mesh {
    let (mesh, warnings) = Mesh::new(f.mesh.clone()).expect("fixture is valid");
    assert!(warnings.is_empty(), "{}: {warnings:?}", f.name);
    mesh
}

#[test]
fn committed_files_are_what_the_generator_writes() {
    let dir = Path::new("fixtures");
    for f in fixtures::all() {
        let path = dir.join(format!("{}.obj", f.name));
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
            panic!("{}: {e} (run `flatmesh fixtures fixtures`)", path.display())
        });
        assert!(
            text == f.obj(),
            "{} differs from the generator",
            path.display()
        );
        // and reading the file gives the generator's mesh exactly, without a warning
        let (mesh, warnings) = flatmesh::io::load_path(&path).expect("fixture loads");
        assert!(warnings.is_empty(), "{}: {warnings:?}", f.name);
        assert_eq!(mesh.positions(), f.mesh.positions.as_slice(), "{}", f.name);
        let mut a: Vec<[u32; 3]> = mesh.triangles().to_vec();
        let mut b = f.mesh.triangles.clone();
        a.sort();
        b.sort();
        assert_eq!(a, b, "{}", f.name);
        assert_eq!(mesh.patch_names(), f.mesh.patch_names.as_slice());
    }
    let readme = std::fs::read_to_string(dir.join("README.md")).expect("fixtures/README.md");
    assert_eq!(readme, fixtures::readme());
}

#[test]
fn write_all_writes_every_fixture_and_the_readme() {
    let dir = std::env::temp_dir().join(format!("flatmesh-fixtures-{}", std::process::id()));
    let paths = fixtures::write_all(&dir).expect("write");
    assert_eq!(paths.len(), fixtures::all().len() + 1);
    for f in fixtures::all() {
        let text = std::fs::read_to_string(dir.join(format!("{}.obj", f.name))).unwrap();
        assert_eq!(text, f.obj());
    }
    std::fs::remove_dir_all(&dir).ok();
    assert!(fixtures::by_name("cone").is_some());
    assert!(fixtures::by_name("no_such_fixture").is_none());
    let names: std::collections::HashSet<_> = fixtures::all().iter().map(|f| f.name).collect();
    assert_eq!(names.len(), 10, "names are unique");
}

#[test]
fn topology_matches_the_construction() {
    for f in fixtures::all() {
        let all: Vec<usize> = (0..f.mesh.triangles.len()).collect();
        let c = count(&f.mesh, &all);
        assert_eq!(c.euler, f.euler, "{}: χ", f.name);
        assert_eq!(c.loops, f.boundary_loops, "{}: boundary loops", f.name);
        let mesh = load(&f);
        assert_eq!(
            mesh.conn().boundary_loops().len(),
            f.boundary_loops,
            "{}",
            f.name
        );
        assert!(c.used.iter().all(|&u| u), "{}: unreferenced vertex", f.name);
    }
}

#[test]
fn gauss_bonnet_holds_per_mesh_and_per_patch() {
    for f in fixtures::all() {
        let all: Vec<usize> = (0..f.mesh.triangles.len()).collect();
        let c = count(&f.mesh, &all);
        let k = total_curvature(&c);
        assert!(
            (k - TAU * c.euler as f64).abs() < 1e-9,
            "{}: total curvature {k} vs 2πχ = {}",
            f.name,
            TAU * c.euler as f64
        );
        let mesh = load(&f);
        for (p, _) in f.mesh.patch_names.iter().enumerate() {
            let faces = patch_faces(&f.mesh, p);
            let cp = count(&f.mesh, &faces);
            let kp = total_curvature(&cp);
            assert!(
                (kp - TAU * cp.euler as f64).abs() < 1e-9,
                "{} patch {p}",
                f.name
            );
            let lib = geometry::patch_total_curvature(&mesh, p as u32);
            assert!(
                (lib - kp).abs() < 1e-9,
                "{} patch {p}: {lib} vs {kp}",
                f.name
            );
        }
    }
}

/// ϖ from the library against the angle sums counted here, and what each fixture promises.
#[test]
fn flattenability_is_what_the_construction_says() {
    for f in fixtures::all() {
        let mesh = load(&f);
        let theta = geometry::angle_sums(&mesh);
        let w = geometry::flattenability(&mesh, &theta);
        let mut interior = Vec::new();
        for (p, _) in f.mesh.patch_names.iter().enumerate() {
            let faces = patch_faces(&f.mesh, p);
            let c = count(&f.mesh, &faces);
            for v in 0..c.theta.len() {
                // interior of its patch and not touching another patch
                let whole = count_fan(&f.mesh, v);
                if c.used[v] && c.boundary_degree[v] == 0 && whole == faces_of(&f.mesh, v, p) {
                    interior.push((v, c.theta[v]));
                }
            }
        }
        assert!(!interior.is_empty(), "{}", f.name);
        assert_eq!(
            interior.len(),
            mesh.conn().interior_vertices().count(),
            "{}: interior count",
            f.name
        );
        for &(v, th) in &interior {
            assert!(mesh.conn().is_interior(v as u32), "{} vertex {v}", f.name);
            assert!(
                (w[v] - (TAU - th).abs()).abs() < 1e-12,
                "{} vertex {v}",
                f.name
            );
        }
        let max = interior.iter().map(|&(v, _)| w[v]).fold(0.0, f64::max);
        match f.name {
            _ if f.developable => assert!(max <= 1e-12, "{}: ϖ_max {max}", f.name),
            "cylinder_noisy" | "cone_noisy" => {
                assert!(max > 1e-4, "{}: ϖ_max {max}", f.name);
                // the noise is small: still far from a crease
                assert!(max < 0.1, "{}: ϖ_max {max}", f.name);
            }
            "hemisphere_cap" | "tube_two_panels" => {
                // positive curvature: every interior angle sum falls short of 2π
                for &(v, th) in &interior {
                    assert!(th < TAU - 1e-6, "{} vertex {v}: θ = {th}", f.name);
                }
            }
            "saddle" => {
                for &(v, th) in &interior {
                    assert!(th > TAU + 1e-6, "{} vertex {v}: θ = {th}", f.name);
                }
            }
            "cube_cuts" => {
                let corners: Vec<usize> = interior
                    .iter()
                    .filter(|&&(v, _)| w[v] > 1e-12)
                    .map(|&(v, _)| v)
                    .collect();
                assert_eq!(corners.len(), 4, "four cube corners are interior");
                for &v in &corners {
                    assert!((w[v] - FRAC_PI_2).abs() < 1e-12);
                    let p = f.mesh.positions[v];
                    assert!(p[2] == 0.0 && (p[0] == 0.0 || p[0] == 1.0));
                    assert!(p[1] == 0.0 || p[1] == 1.0);
                }
            }
            other => panic!("fixture {other} has no expectation here"),
        }
    }
}

/// The faces of patch `p`.
fn patch_faces(raw: &RawMesh, p: usize) -> Vec<usize> {
    (0..raw.triangles.len())
        .filter(|&t| raw.face_patch[t] == p as u32)
        .collect()
}

fn count_fan(raw: &RawMesh, v: usize) -> usize {
    raw.triangles
        .iter()
        .filter(|t| t.contains(&(v as u32)))
        .count()
}

fn faces_of(raw: &RawMesh, v: usize, patch: usize) -> usize {
    raw.triangles
        .iter()
        .zip(&raw.face_patch)
        .filter(|(t, &p)| p as usize == patch && t.contains(&(v as u32)))
        .count()
}

/// The developable fixtures unroll to shapes known in closed form: the cylinder to a
/// 3π/2 × 2 rectangle, so its boundary is 2·(3π/2) + 2·2 long; the cone's rulings keep their
/// length; the noisy ones keep the boundary of the clean ones exactly.
#[test]
fn boundary_lengths_match_closed_forms() {
    let boundary_length = |raw: &RawMesh| -> f64 {
        let mesh = Mesh::new(raw.clone()).unwrap().0;
        mesh.conn()
            .boundary_loops()
            .iter()
            .map(|lp| {
                (0..lp.len())
                    .map(|i| {
                        let (a, b) = (
                            raw.positions[lp[i] as usize],
                            raw.positions[lp[(i + 1) % lp.len()] as usize],
                        );
                        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2))
                            .sqrt()
                    })
                    .sum::<f64>()
            })
            .sum()
    };
    let cyl = fixtures::by_name("cylinder").unwrap();
    // the curved edges are polygons: 24 chords of angle π/16 on each of the two arcs
    let chord = 2.0 * (PI / 32.0).sin();
    let expect = 2.0 * 24.0 * chord + 2.0 * 2.0;
    assert!((boundary_length(&cyl.mesh) - expect).abs() < 1e-12);
    let noisy = fixtures::by_name("cylinder_noisy").unwrap();
    assert!((boundary_length(&noisy.mesh) - expect).abs() < 1e-12);
    let cone = fixtures::by_name("cone").unwrap();
    let cone_noisy = fixtures::by_name("cone_noisy").unwrap();
    let (a, b) = (
        boundary_length(&cone.mesh),
        boundary_length(&cone_noisy.mesh),
    );
    assert!((a - b).abs() < 1e-12);
    // two straight rulings of length 1.5 plus chords on circles of radius s·sin 30°
    let arc = |s: f64| 24.0 * 2.0 * 0.5 * s * (4.0 * PI / 3.0 / 48.0).sin();
    assert!((a - (3.0 + arc(1.0) + arc(2.5))).abs() < 1e-12, "{a}");
}
