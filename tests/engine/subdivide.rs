//! subdivide (Sec. 3 of wang-flattenable-laplacian-meshes): split cases, boundary placement,
//! the umbrella operators' fixed points and the full pipeline, judged with the mesh core's own
//! measures and with quantities the tests compute themselves.
#![allow(clippy::needless_range_loop)]

use flatmesh::algorithms::subdivide::{self, Curve, Params};
use flatmesh::algorithms::{AlgoError, Silent};
use flatmesh::geometry;
use flatmesh::mesh::{Mesh, RawMesh, VertexKind};
use std::collections::HashMap;

fn fixture(name: &str) -> Mesh {
    let f = flatmesh::fixtures::by_name(name).expect("fixture exists");
    Mesh::new(f.mesh).expect("fixture is valid").0
}

fn mesh(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
    let n = triangles.len();
    Mesh::new(RawMesh {
        positions,
        triangles,
        face_patch: vec![0; n],
        patch_names: vec!["p".into()],
        uv: None,
    })
    .expect("valid")
    .0
}

fn max_varpi(m: &Mesh) -> f64 {
    let theta = geometry::angle_sums(m);
    let w = geometry::flattenability(m, &theta);
    assert!(w.iter().all(|x| x.is_finite()));
    w.into_iter().fold(0.0, f64::max)
}

fn plain(ratio: f64) -> Params {
    Params {
        split_ratio: ratio,
        flatten_levels: false,
        ..Params::default()
    }
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

/// Signed area of a planar triangle (z = 0), positive when counter-clockwise.
fn signed_area(m: &Mesh, t: [u32; 3]) -> f64 {
    let p = m.positions();
    let (a, b, c) = (p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
}

/// χ = V − E + F counted from the triangle list.
fn euler(m: &Mesh) -> i64 {
    let mut edges = std::collections::HashSet::new();
    let mut verts = std::collections::HashSet::new();
    for t in m.triangles() {
        for i in 0..3 {
            verts.insert(t[i]);
            edges.insert((t[i].min(t[(i + 1) % 3]), t[i].max(t[(i + 1) % 3])));
        }
    }
    verts.len() as i64 - edges.len() as i64 + m.num_faces() as i64
}

fn boundary_edge_count(m: &Mesh) -> usize {
    let mut count: HashMap<(u32, u32), usize> = HashMap::new();
    for t in m.triangles() {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(
        count.values().all(|&c| c <= 2),
        "an edge in more than two faces"
    );
    count.values().filter(|&&c| c == 1).count()
}

/// A 3-4-5 triangle (mean edge 4): the ratio picks how many edges are longer than ratio·4, so
/// the triangle becomes 1, 2, 3 or 4 triangles, all counter-clockwise, no T-junctions (the
/// boundary has exactly 3 + split edges), old vertices untouched.
#[test]
fn one_two_three_or_four_children() {
    let m = mesh(
        vec![[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]],
        vec![[0, 1, 2]],
    );
    for (ratio, split, faces) in [(1.3, 0, 1), (1.1, 1, 2), (0.9, 2, 3), (0.5, 3, 4)] {
        let mut curves = HashMap::new();
        let (s, n) = subdivide::subdivide_level(&m, &mut curves, &plain(ratio), &Silent::default())
            .expect("splits");
        assert_eq!(n, split, "ratio {ratio}");
        assert_eq!(s.num_faces(), faces, "ratio {ratio}");
        assert_eq!(s.num_vertices(), 3 + split);
        assert_eq!(boundary_edge_count(&s), 3 + split);
        assert_eq!(&s.positions()[..3], m.positions());
        for &t in s.triangles() {
            assert!(
                signed_area(&s, t) > 0.0,
                "ratio {ratio}: face {t:?} flipped"
            );
        }
        assert!(s.positions().iter().all(|p| p[2] == 0.0));
    }
}

/// The modified Butterfly boundary mask on the unit disk: every new boundary vertex lies far
/// closer to the circle than the chord midpoint (4-point rule: O(h⁴) against O(h²)), and on a
/// straight, evenly spaced boundary it is exactly the midpoint.
#[test]
fn butterfly_boundary_follows_the_circle() {
    let disk = fixture("flat_disk");
    let conn = disk.conn();
    let ring: Vec<u32> = conn.boundary_loops()[0].clone();
    for &v in &ring {
        assert!(
            (norm(disk.position(v)) - 1.0).abs() < 1e-12,
            "fixture rim on the circle"
        );
    }
    let n0 = disk.num_vertices();
    let mut curves = HashMap::new();
    let (s, _) = subdivide::subdivide_level(&disk, &mut curves, &plain(0.5), &Silent::default())
        .expect("splits");
    let sc = s.conn();
    // Chord sagitta of the rim.
    let h = dist(disk.position(ring[0]), disk.position(ring[1]));
    let sagitta = 1.0 - (1.0 - h * h / 4.0).sqrt();
    let mut checked = 0;
    for v in n0..s.num_vertices() {
        if sc.kind(v as u32) == VertexKind::Boundary {
            let err = (norm(s.positions()[v]) - 1.0).abs();
            assert!(
                err < 0.05 * sagitta,
                "vertex {v}: {err:e} vs sagitta {sagitta:e}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, ring.len(), "every rim edge split once");

    // Straight rim: a 6 × 2 strip of the plane, evenly spaced.
    let mut p = vec![];
    for j in 0..3 {
        for i in 0..7 {
            p.push([i as f64, j as f64, 0.0]);
        }
    }
    let mut t = vec![];
    for j in 0..2u32 {
        for i in 0..6u32 {
            let a = j * 7 + i;
            t.push([a, a + 1, a + 8]);
            t.push([a, a + 8, a + 7]);
        }
    }
    let strip = mesh(p, t);
    let mut curves = HashMap::new();
    let (s, _) = subdivide::subdivide_level(&strip, &mut curves, &plain(0.5), &Silent::default())
        .expect("splits");
    let sc = s.conn();
    for v in strip.num_vertices()..s.num_vertices() {
        let q = s.positions()[v];
        if sc.kind(v as u32) == VertexKind::Boundary && q[1] == 0.0 && q[0] > 1.0 && q[0] < 5.0 {
            assert_eq!(q[0].fract(), 0.5, "bottom rim vertex {v} at {q:?}");
        }
    }
}

/// A curve on a rim edge: the new vertex is at the polyline's arc-length middle (computed
/// here), and at the next level the halves put vertices at the quarter points.
#[test]
fn curves_are_interpolated_at_their_arc_length_middle() {
    let disk = fixture("flat_disk");
    let ring = disk.conn().boundary_loops()[0].clone();
    let (a, b) = (ring[0], ring[1]);
    let (pa, pb) = (disk.position(a), disk.position(b));
    // A bent polyline in z: a, an offset point at 1/3, b.
    let mid = [
        pa[0] + (pb[0] - pa[0]) / 3.0,
        pa[1] + (pb[1] - pa[1]) / 3.0,
        0.2,
    ];
    let points = vec![pa, mid, pb];
    let (l1, l2) = (dist(pa, mid), dist(mid, pb));
    let at = |s: f64| -> [f64; 3] {
        if s <= l1 {
            let t = s / l1;
            std::array::from_fn(|k| pa[k] + t * (mid[k] - pa[k]))
        } else {
            let t = (s - l1) / l2;
            std::array::from_fn(|k| mid[k] + t * (pb[k] - mid[k]))
        }
    };
    let total = l1 + l2;
    let p = Params {
        levels: 2,
        curves: vec![Curve {
            edge: [a, b],
            points,
        }],
        flatten_levels: false,
        ..Params::default()
    };
    let out = subdivide::run(&disk, &p, &Silent::default()).expect("runs");
    let closest = |m: &Mesh, q: [f64; 3]| {
        m.positions()
            .iter()
            .map(|&x| dist(x, q))
            .fold(f64::INFINITY, f64::min)
    };
    assert!(closest(&out.levels[0], at(0.5 * total)) < 1e-12);
    for f in [0.25, 0.75] {
        assert!(
            closest(&out.levels[1], at(f * total)) < 1e-12,
            "quarter {f}"
        );
    }
}

/// The umbrella operators' fixed points, checked with Eq. 14 and 15 computed here on the
/// output: many 1st-order runs make every new inner vertex the centroid of its ring (u = 0);
/// many 2nd-order runs make u² = 0 there. Old vertices never move.
#[test]
fn umbrella_runs_reach_their_fixed_points() {
    let m = fixture("saddle");
    let n0 = m.num_vertices();
    for (first, second) in [(3000, 0), (0, 6000)] {
        let p = Params {
            first_order_runs: first,
            second_order_runs: second,
            ..plain(0.5)
        };
        let mut curves = HashMap::new();
        let (s, _) =
            subdivide::subdivide_level(&m, &mut curves, &p, &Silent::default()).expect("splits");
        assert_eq!(&s.positions()[..n0], m.positions());
        let c = s.conn();
        let pos = s.positions();
        let u: Vec<[f64; 3]> = (0..s.num_vertices())
            .map(|v| {
                let r = c.ring_of(v as u32);
                std::array::from_fn(|k| {
                    r.iter().map(|&j| pos[j as usize][k]).sum::<f64>() / r.len() as f64 - pos[v][k]
                })
            })
            .collect();
        let mut worst = 0.0f64;
        let mut movers = 0;
        for v in n0..s.num_vertices() {
            if c.kind(v as u32) != VertexKind::Interior {
                continue;
            }
            movers += 1;
            let r = c.ring_of(v as u32);
            let res: [f64; 3] = if second == 0 {
                u[v]
            } else {
                std::array::from_fn(|k| {
                    r.iter().map(|&j| u[j as usize][k]).sum::<f64>() / r.len() as f64 - u[v][k]
                })
            };
            worst = worst.max(norm(res));
        }
        assert!(movers > 0);
        assert!(
            worst < 1e-9,
            "first {first} second {second}: residual {worst:e}"
        );
    }
}

/// The whole pipeline with two levels: every level flattenable by the mesh core's measure,
/// input boundary bit-identical, topology (χ, boundary loops, patches) unchanged, numbering
/// only grows.
#[test]
fn two_levels_on_fixtures_are_flattenable() {
    for name in ["cone_noisy", "tube_two_panels"] {
        let m = fixture(name);
        let p = Params {
            levels: 2,
            ..Params::default()
        };
        let out = subdivide::run(&m, &p, &Silent::default()).expect("runs");
        assert_eq!(out.levels.len(), 2);
        let chi = euler(&m);
        let loops = m.conn().boundary_loops().len();
        let mut prev = m.num_vertices();
        for (k, lv) in out.levels.iter().enumerate() {
            let w = max_varpi(lv);
            assert!(w <= 1e-6, "{name} level {}: ϖ_max {w:e}", k + 1);
            assert!(
                lv.num_vertices() > prev,
                "{name}: level {} adds vertices",
                k + 1
            );
            prev = lv.num_vertices();
            assert_eq!(euler(lv), chi, "{name}");
            assert_eq!(lv.conn().boundary_loops().len(), loops, "{name}");
            assert_eq!(lv.num_patches(), m.num_patches());
            boundary_edge_count(lv);
        }
        let last = out.mesh.as_ref().unwrap();
        assert_eq!(last.positions(), out.levels[1].positions());
        for v in 0..m.num_vertices() {
            if m.conn().kind(v as u32) != VertexKind::Interior {
                assert_eq!(
                    last.positions()[v],
                    m.positions()[v],
                    "{name}: vertex {v} moved"
                );
            }
        }
        assert_eq!(out.summary.levels.len(), out.levels.len());
        for (r, lv) in out.summary.levels.iter().zip(&out.levels) {
            assert_eq!(r.vertices, lv.num_vertices());
            assert_eq!(r.max_flattenability, max_varpi(lv));
        }
    }
}

#[test]
fn bad_parameters_are_named() {
    let m = fixture("cone_noisy");
    let key_of = |params: serde_json::Value| -> String {
        let map = params.as_object().unwrap().clone();
        let err = match flatmesh::jobs::JobSpec::parse("subdivide", &map) {
            Err(flatmesh::jobs::SpecError::Params(e)) => e,
            Err(other) => panic!("{other}"),
            Ok(spec) => {
                let input = flatmesh::jobs::Input {
                    mesh: m.clone(),
                    reference: None,
                };
                spec.run(&input, &Silent::default()).expect_err("refused")
            }
        };
        match err {
            AlgoError::InvalidParam { key, .. } => key,
            other => panic!("{other:?}"),
        }
    };
    use serde_json::json;
    assert_eq!(key_of(json!({"bogus": 1})), "bogus");
    assert_eq!(key_of(json!({"levels": 0})), "levels");
    assert_eq!(key_of(json!({"levels": "two"})), "levels");
    assert_eq!(
        key_of(json!({"fl_mesh": {"tolerance": -1.0}})),
        "fl_mesh.tolerance"
    );
    assert_eq!(key_of(json!({"fl_mesh": {"nope": 1}})), "fl_mesh.nope");
    // vertex 0 of the cone is a corner; find an interior vertex and one of its edges
    let c = m.conn();
    let v = c.interior_vertices().next().unwrap();
    let w = c.ring_of(v)[0];
    let pv = m.position(v);
    let pw = m.position(w);
    assert_eq!(
        key_of(json!({"curves": [{"edge": [v, w], "points": [pv, pw]}]})),
        "curves[0].edge"
    );
    let rim = c.boundary_loops()[0].clone();
    let (a, b) = (rim[0], rim[1]);
    let (pa, pb) = (m.position(a), m.position(b));
    assert_eq!(
        key_of(json!({"curves": [{"edge": [a, b], "points": [pa, [9.0, 9.0, 9.0]]}]})),
        "curves[0].points"
    );
    assert_eq!(
        key_of(json!({"curves": [{"edge": [a, b], "points": [pa]}]})),
        "curves[0].points"
    );
    assert_eq!(
        key_of(
            json!({"curves": [{"edge": [a, b], "points": [pa, pb]}, {"edge": [a, 99999], "points": [pa, pb]}]})
        ),
        "curves[1].edge"
    );
    // a curve given from b to a is accepted (reversed)
    let ok = Params {
        curves: vec![Curve {
            edge: [b, a],
            points: vec![pb, pa],
        }],
        flatten_levels: false,
        ..Params::default()
    };
    subdivide::run(&m, &ok, &Silent::default()).expect("reversed curve accepted");
}

#[test]
fn cancel_is_honoured() {
    let m = fixture("cone_noisy");
    let s = Silent::default();
    s.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    let r = subdivide::run(&m, &Params::default(), &s);
    assert!(matches!(r, Err(AlgoError::Cancelled)), "{r:?}");
}

/// `flatmesh run subdivide --levels 2 --curves FILE`: files, report fields, and the level
/// meshes read back from disk are flattenable with the input's vertices first.
#[test]
fn cli_run_subdivide() {
    let m = fixture("cone_noisy");
    let rim = m.conn().boundary_loops()[0].clone();
    let (a, b) = (rim[0], rim[1]);
    let (pa, pb) = (m.position(a), m.position(b));
    let bulge = [
        0.5 * (pa[0] + pb[0]) + 0.01,
        0.5 * (pa[1] + pb[1]),
        0.5 * (pa[2] + pb[2]),
    ];
    let dir = std::env::temp_dir().join(format!("flatmesh-subdiv-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let curves = dir.join("curves.json");
    std::fs::write(
        &curves,
        serde_json::json!({"curves": [{"edge": [a, b], "points": [pa, bulge, pb]}]}).to_string(),
    )
    .unwrap();
    let out = dir.join("out");
    let bin = env!("CARGO_BIN_EXE_flatmesh");
    let o = std::process::Command::new(bin)
        .args([
            "run",
            "subdivide",
            "fixtures/cone_noisy.obj",
            "--levels",
            "2",
        ])
        .arg("--curves")
        .arg(&curves)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    for k in [
        "iterations",
        "converged",
        "history",
        "refined",
        "hausdorff_to_input",
        "seconds",
        "levels",
    ] {
        assert!(report["job"].get(k).is_some(), "report.json lacks job.{k}");
    }
    assert_eq!(report["job"]["levels"].as_array().unwrap().len(), 2);
    let input = flatmesh::io::load_path(std::path::Path::new("fixtures/cone_noisy.obj"))
        .unwrap()
        .0;
    for k in 1..=2 {
        let (lv, _) = flatmesh::io::load_path(&out.join(format!("level_{k}.obj"))).unwrap();
        assert!(max_varpi(&lv) <= 1e-6, "level {k}");
        assert!(out.join(format!("level_{k}.glb")).exists());
        for &v in &rim {
            assert_eq!(lv.position(v), input.position(v), "rim vertex {v}");
        }
    }
    // The curve's arc-length middle (computed here) is a vertex of the last level (the edge is
    // split at level 1 or 2, and the middle stays).
    let (l1, _) = flatmesh::io::load_path(&out.join("level_2.obj")).unwrap();
    let (d1, d2) = (dist(pa, bulge), dist(bulge, pb));
    let target: [f64; 3] = if d1 >= d2 {
        let t = 0.5 * (d1 + d2) / d1;
        std::array::from_fn(|k| pa[k] + t * (bulge[k] - pa[k]))
    } else {
        let t = (0.5 * (d1 + d2) - d1) / d2;
        std::array::from_fn(|k| bulge[k] + t * (pb[k] - bulge[k]))
    };
    let near = l1
        .positions()
        .iter()
        .map(|&x| dist(x, target))
        .fold(f64::INFINITY, f64::min);
    assert!(near < 1e-12, "curve middle not interpolated: {near:e}");
    // --levels belongs to subdivide only
    let o = std::process::Command::new(bin)
        .args(["run", "fl-mesh", "fixtures/cone_noisy.obj", "--levels", "2"])
        .arg("--out")
        .arg(dir.join("x"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--levels"));
    let _ = std::fs::remove_dir_all(&dir);
}
