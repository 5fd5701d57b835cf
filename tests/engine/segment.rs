//! `segment`: VSA, min-cut, merging and the cut mesh, checked against independent truths
//! (brute-force min cuts, recomputed chart errors and measures, seams summed from
//! positions) and the known answers.

use flatmesh::algorithms::flatten;
use flatmesh::algorithms::segment::{self, dual::Dual, mincut, vsa, MergeMode, Params};
use flatmesh::algorithms::Silent;
use flatmesh::corpus::pattern_checks::{area_3d, signed_area};
use flatmesh::mesh::{Mesh, RawMesh};
use std::path::Path;

fn fixture(name: &str) -> Mesh {
    flatmesh::io::load_path(Path::new(&format!("fixtures/{name}.obj")))
        .unwrap()
        .0
}

fn shared(rel: &str) -> Option<Mesh> {
    let path = flatmesh::corpus::shared_mesh_for_tests(rel)?;
    Some(flatmesh::io::load_path(&path).unwrap().0)
}

/// A closed cube of side 1, n × n squares per side, each split in two triangles.
fn cube(n: usize) -> Mesh {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut vid = |p: [f64; 3], positions: &mut Vec<[f64; 3]>| -> u32 {
        let key = p.map(|x| (x * n as f64).round() as i64);
        *index.entry(key).or_insert_with(|| {
            positions.push(p);
            (positions.len() - 1) as u32
        })
    };
    // Each side: origin, u, v with u × v pointing outwards.
    let sides: [([f64; 3], [f64; 3], [f64; 3]); 6] = [
        ([0., 0., 0.], [0., 1., 0.], [1., 0., 0.]),
        ([0., 0., 1.], [1., 0., 0.], [0., 1., 0.]),
        ([0., 0., 0.], [1., 0., 0.], [0., 0., 1.]),
        ([0., 1., 0.], [0., 0., 1.], [1., 0., 0.]),
        ([0., 0., 0.], [0., 0., 1.], [0., 1., 0.]),
        ([1., 0., 0.], [0., 1., 0.], [0., 0., 1.]),
    ];
    let h = 1.0 / n as f64;
    for (o, u, v) in sides {
        let at = |i: usize, j: usize| {
            [0, 1, 2].map(|k| o[k] + u[k] * i as f64 * h + v[k] * j as f64 * h)
        };
        for i in 0..n {
            for j in 0..n {
                let a = vid(at(i, j), &mut positions);
                let b = vid(at(i + 1, j), &mut positions);
                let c = vid(at(i + 1, j + 1), &mut positions);
                let d = vid(at(i, j + 1), &mut positions);
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
    }
    Mesh::new(RawMesh {
        positions,
        triangles,
        ..RawMesh::default()
    })
    .unwrap()
    .0
}

fn run(mesh: &Mesh, params: &Params) -> flatmesh::algorithms::Outcome<segment::Summary> {
    segment::run(mesh, params, &Silent::default()).unwrap()
}

/// Charts connected and partitioning the faces, by breadth-first search over shared edges.
fn assert_partition(mesh: &Mesh, labels: &[u32], what: &str) {
    assert_eq!(labels.len(), mesh.num_faces(), "{what}");
    let conn = mesh.conn();
    let k = labels.iter().map(|&l| l as usize + 1).max().unwrap();
    let mut seen = vec![false; labels.len()];
    let mut pieces = vec![0; k];
    for f0 in 0..labels.len() {
        if seen[f0] {
            continue;
        }
        pieces[labels[f0] as usize] += 1;
        let mut stack = vec![f0];
        seen[f0] = true;
        while let Some(f) = stack.pop() {
            for i in 0..3 {
                let t = conn.twin((3 * f + i) as u32);
                if t == flatmesh::mesh::NONE {
                    continue;
                }
                let g = (t / 3) as usize;
                if !seen[g] && labels[g] == labels[f] {
                    seen[g] = true;
                    stack.push(g);
                }
            }
        }
    }
    for (l, &n) in pieces.iter().enumerate() {
        assert!(n <= 1, "{what}: chart {l} is in {n} pieces");
    }
}

/// E(R_i)/A recomputed: the area-weighted mean normal is the L^{2,1} proxy.
fn chart_errors(mesh: &Mesh, labels: &[u32], k: usize) -> Vec<f64> {
    let mut sum = vec![[0.0f64; 3]; k];
    let mut total = 0.0;
    let mut normals = Vec::new();
    for f in 0..mesh.num_faces() {
        let [a, b, c] = mesh.face_positions(f);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let area = 0.5 * len;
        total += area;
        let unit = n.map(|x| x / len);
        for d in 0..3 {
            sum[labels[f] as usize][d] += area * unit[d];
        }
        normals.push((unit, area));
    }
    let proxies: Vec<[f64; 3]> = sum
        .iter()
        .map(|s| {
            let l = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
            s.map(|x| x / l)
        })
        .collect();
    let mut e = vec![0.0; k];
    for (f, (n, a)) in normals.iter().enumerate() {
        let p = proxies[labels[f] as usize];
        e[labels[f] as usize] +=
            a * ((n[0] - p[0]).powi(2) + (n[1] - p[1]).powi(2) + (n[2] - p[2]).powi(2));
    }
    e.iter().map(|x| x / total).collect()
}

#[test]
fn vsa_partitions_connected_charts_within_the_tolerance() {
    let cases: Vec<(String, Mesh)> = ["saddle", "hemisphere_cap", "cylinder_noisy", "two_holes"]
        .iter()
        .map(|n| (n.to_string(), fixture(n)))
        .chain([("cube".to_string(), cube(4))])
        .collect();
    for (name, mesh) in cases {
        let dual = Dual::new(&mesh, true);
        let tol = 5e-4;
        let v = vsa::run(&dual, tol, 256, 50, &Silent::default()).unwrap();
        let k = v.proxies.len();
        assert_partition(&mesh, &v.labels, &name);
        let e = chart_errors(&mesh, &v.labels, k);
        for (i, (&mine, &theirs)) in e.iter().zip(&v.errors).enumerate() {
            assert!(
                (mine - theirs).abs() <= 1e-9 * mine.max(1e-12),
                "{name} chart {i}: {mine} vs {theirs}"
            );
            assert!(mine <= tol, "{name}: chart {i} error {mine} above {tol}");
        }
        if name == "cube" {
            // Planar charts, none across an edge of the cube (several seeds may land on one
            // side in a round: six or more charts).
            assert!(k >= 6, "{k} charts");
            assert!(e.iter().all(|&x| x < 1e-20), "{e:?}");
        }
    }
}

/// Max flow = min cut on random small graphs, the min cut found by trying every cut.
#[test]
fn dinic_max_flow_equals_the_brute_force_min_cut() {
    let mut seed = 12345u64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _case in 0..200 {
        let n = 2 + (rnd() * 8.0) as usize;
        // Arcs one way, both ways (as the band's dual edges) and uncapacitated from the
        // source (as the band's ties to a chart).
        let mut arcs = Vec::new();
        let mut g = mincut::FlowGraph::new(n);
        let (s, t) = (0, n - 1);
        for u in 0..n {
            for v in u + 1..n {
                let r = rnd();
                let c = (rnd() * 10.0).floor() + if rnd() < 0.2 { 0.5 } else { 0.0 };
                if r < 0.2 {
                    arcs.push((u, v, c));
                    g.add(u, v, c, 0.0);
                } else if r < 0.4 {
                    arcs.push((v, u, c));
                    g.add(v, u, c, 0.0);
                } else if r < 0.6 {
                    arcs.push((u, v, c));
                    arcs.push((v, u, c));
                    g.add(u, v, c, c);
                } else if r < 0.7 && u == s && v != t {
                    arcs.push((u, v, f64::INFINITY));
                    g.add(u, v, f64::INFINITY, 0.0);
                }
            }
        }
        let flow = g.max_flow(s, t);
        let mut best = f64::INFINITY;
        for mask in 0u32..(1 << n) {
            if mask & 1 == 0 || mask & (1 << t) != 0 {
                continue;
            }
            let cap: f64 = arcs
                .iter()
                .filter(|&&(u, v, _)| mask & (1 << u) != 0 && mask & (1 << v) == 0)
                .map(|a| a.2)
                .sum();
            best = best.min(cap);
        }
        assert!(
            (flow - best).abs() < 1e-9,
            "n {n}: flow {flow} min cut {best} {arcs:?}"
        );
        let side = g.source_side(s);
        assert!(side[s] && !side[t]);
        assert!((g.cut_capacity(&side) - best).abs() < 1e-9);
    }
}

#[test]
fn min_cut_refinement_changes_labels_only_in_its_band() {
    let mut meshes = vec![
        ("saddle".to_string(), fixture("saddle")),
        ("hemisphere_cap".to_string(), fixture("hemisphere_cap")),
    ];
    if let Some(m) = shared("paper/bff_hemisphere.obj") {
        meshes.push(("bff_hemisphere".into(), m));
    }
    for (name, mesh) in meshes {
        let dual = Dual::new(&mesh, true);
        let v = vsa::run(&dual, 5e-4, 256, 50, &Silent::default()).unwrap();
        let k = v.proxies.len();
        let mut labels = v.labels.clone();
        let r = mincut::refine(&dual, &mut labels, k, 3);
        assert!(!r.pairs.is_empty(), "{name}: no pair was cut");
        for p in &r.pairs {
            assert!(
                (p.flow - p.cut).abs() <= 1e-9 * p.flow.max(1.0),
                "{name}: flow {} cut {}",
                p.flow,
                p.cut
            );
        }
        for (f, (l, l0)) in labels.iter().zip(&v.labels).enumerate() {
            if l != l0 {
                assert!(r.in_band[f], "{name}: face {f} changed outside every band");
            }
        }
        assert_partition(&mesh, &labels, &name);
        let distinct: std::collections::HashSet<u32> = labels.iter().copied().collect();
        assert_eq!(distinct.len(), k, "{name}: the chart count changed");
    }
}

/// Area distortion (%), L² stretch and overlap of a piece, from its uv and the 3D positions
/// of the mesh it was flattened from; overlap by brute force over boundary segments, copies
/// of one 3D point (slit sides) allowed to touch.
fn independent_measures(mesh: &Mesh, p: &flatmesh::pattern::Piece) -> (f64, f64, bool) {
    let (mut a2, mut a3, mut l2) = (0.0, 0.0, 0.0);
    let mut flipped = false;
    for &t in &p.triangles {
        let s = signed_area(p, t);
        flipped |= s <= 0.0;
        let area = area_3d(mesh, p, t);
        a2 += s;
        a3 += area;
        let [q0, q1, q2] = t.map(|v| p.uv[v as usize]);
        let [p0, p1, p2] = t.map(|v| mesh.position(p.vertex_ids[v as usize]));
        // Jacobian of the 2D → 3D map: [p1 − p0, p2 − p0] · inverse([q1 − q0, q2 − q0]).
        let (e1, e2) = (
            [q1[0] - q0[0], q1[1] - q0[1]],
            [q2[0] - q0[0], q2[1] - q0[1]],
        );
        let det = e1[0] * e2[1] - e2[0] * e1[1];
        let inv = [[e2[1] / det, -e2[0] / det], [-e1[1] / det, e1[0] / det]];
        let d1: Vec<f64> = (0..3).map(|k| p1[k] - p0[k]).collect();
        let d2: Vec<f64> = (0..3).map(|k| p2[k] - p0[k]).collect();
        let col = |j: usize| -> Vec<f64> {
            (0..3)
                .map(|k| d1[k] * inv[0][j] + d2[k] * inv[1][j])
                .collect()
        };
        let (ss, st) = (col(0), col(1));
        let a: f64 = ss.iter().map(|x| x * x).sum();
        let c: f64 = st.iter().map(|x| x * x).sum();
        l2 += (a + c) / 2.0 * area;
    }
    let segs: Vec<(u32, u32)> = p
        .boundary_loops
        .iter()
        .flat_map(|lp| (0..lp.len()).map(move |k| (lp[k], lp[(k + 1) % lp.len()])))
        .collect();
    let pos3 = |v: u32| mesh.position(p.vertex_ids[v as usize]).map(f64::to_bits);
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut crossing = false;
    for i in 0..segs.len() {
        for j in i + 1..segs.len() {
            let (s, t) = (segs[i], segs[j]);
            if [t.0, t.1]
                .iter()
                .any(|&v| pos3(v) == pos3(s.0) || pos3(v) == pos3(s.1))
            {
                continue;
            }
            let (a, b, c, d) = (
                p.uv[s.0 as usize],
                p.uv[s.1 as usize],
                p.uv[t.0 as usize],
                p.uv[t.1 as usize],
            );
            let (o1, o2, o3, o4) = (
                orient(a, b, c),
                orient(a, b, d),
                orient(c, d, a),
                orient(c, d, b),
            );
            if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
                crossing = true;
            }
        }
    }
    (
        100.0 * (a2 - a3) / a3,
        (l2 / a3).sqrt(),
        flipped || crossing,
    )
}

/// Every final chart flattened again, by `flatten` (defaults, but `cuts = virtual`, as
/// segment flattens) from the downloaded cut mesh, is within the bounds by independently computed measures; seams sew back: both
/// sides of each have the 3D length of the input's edges there.
fn check_output(name: &str, mesh: &Mesh, params: &Params) -> segment::Summary {
    let out = run(mesh, params);
    let s = out.summary;
    let cut = out.mesh.unwrap();
    assert_partition(mesh, &s.face_charts, name);
    assert_eq!(cut.num_faces(), mesh.num_faces());
    for (w, &v) in s.vertex_map.iter().enumerate() {
        assert_eq!(
            cut.position(w as u32),
            mesh.position(v),
            "{name}: vertex {w}"
        );
    }
    // `flatten` with the settings segment flattens with: holes closed by the virtual cut.
    let same = flatten::Params {
        cuts: flatten::cut::Cuts::Virtual,
        ..flatten::Params::default()
    };
    let again = flatten::run(&cut, &same, &Silent::default()).unwrap();
    let pieces = &again.patterns.as_ref().unwrap().pieces;
    assert_eq!(
        pieces.len(),
        s.charts.merged,
        "{name}: a chart was skipped: {:?}",
        again.summary.job_warnings
    );
    for p in pieces {
        let (a, l2, overlap) = independent_measures(&cut, p);
        assert!(
            a.abs() <= params.max_area_distortion + 1e-6,
            "{name} {}: A {a}",
            p.patch
        );
        assert!(
            l2 <= params.max_l2_stretch + 1e-9,
            "{name} {}: L2 {l2}",
            p.patch
        );
        assert!(!overlap, "{name} {}: overlaps", p.patch);
    }
    assert!(s.all_within_bounds, "{name}");
    // Seams: each side's edges summed in 3D from the cut mesh match the input's length.
    let patterns = out.patterns.unwrap();
    for seam in &patterns.seams {
        let mut side_len = [0.0; 2];
        for (side, len) in side_len.iter_mut().enumerate() {
            let p = &patterns.pieces[seam.pieces[side]];
            for e in &seam.edges[side] {
                let [a, b] = e.map(|w| cut.position(p.vertex_ids[w as usize]));
                *len +=
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            }
        }
        // A slit's sides are its two flaps, each a path: consecutive edges meet.
        if seam.pieces[0] == seam.pieces[1] {
            for side in &seam.edges {
                for w in side.windows(2) {
                    assert_eq!(
                        w[0][1], w[1][0],
                        "{name}: slit side is not a path: {side:?}"
                    );
                }
            }
        }
        for l in side_len {
            assert!(
                (l - seam.length_3d).abs() <= 1e-9 * seam.length_3d.max(1.0),
                "{name}: seam {:?} {side_len:?} vs {}",
                seam.patches,
                seam.length_3d
            );
        }
    }
    s
}

#[test]
fn developable_patches_end_as_one_chart() {
    for name in ["cylinder", "cone", "cylinder_noisy", "two_holes"] {
        let s = check_output(name, &fixture(name), &Params::default());
        assert!(s.charts.vsa > 1, "{name}: VSA should split a curved patch");
        assert_eq!(s.charts.merged, 1, "{name}: {:?}", s.charts);
    }
}

#[test]
fn a_cube_merges_to_at_most_the_papers_count() {
    let s = check_output("cube", &cube(4), &Params::default());
    assert!(s.charts.vsa >= 6);
    assert!(s.charts.merged <= 5, "{:?}", s.charts);
    // Boundary-based merging keeps slits, so every merge it accepts of planar faces is an
    // exact unfolding (a net).
    let boundary = Params {
        merge: MergeMode::Boundary,
        ..Params::default()
    };
    let s = check_output("cube boundary", &cube(4), &boundary);
    assert!(s.charts.merged <= 5, "{:?}", s.charts);
    for c in s.merge_log.iter().filter(|c| c.accepted) {
        assert!(c.area_distortion_pct.unwrap().abs() < 1e-9, "{c:?}");
    }
}

#[test]
fn the_hemisphere_needs_more_than_one_chart_without_slits() {
    let Some(mesh) = shared("paper/bff_hemisphere.obj") else {
        return;
    };
    // The default (patch-based) merging leaves no slits.
    let s = check_output("bff_hemisphere", &mesh, &Params::default());
    assert!(s.charts.merged > 1, "{:?}", s.charts);
    assert_eq!(s.dangling_edges, 0);
    // Boundary-based merging may keep it in one piece, but only with slits (dangling cuts).
    let boundary = Params {
        merge: MergeMode::Boundary,
        ..Params::default()
    };
    let s = check_output("bff_hemisphere boundary", &mesh, &boundary);
    assert!(
        s.charts.merged > 1 || s.dangling_edges > 0,
        "{:?}",
        s.charts
    );
}

#[test]
fn closed_models_merge_far_below_their_vsa_count() {
    let Some(spot) = shared("classic/od_spot_lowres.obj") else {
        return;
    };
    let s = check_output("spot", &spot, &Params::default());
    assert!(s.charts.merged * 5 <= s.charts.vsa, "{:?}", s.charts);
}

#[test]
fn the_same_input_gives_the_same_charts_on_any_thread_count() {
    let mesh = fixture("saddle");
    let a = run(&mesh, &Params::default()).summary;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = pool.install(|| run(&mesh, &Params::default()).summary);
    assert_eq!(a.face_charts, b.face_charts);
    assert_eq!(a.merge_log.len(), b.merge_log.len());
    for (x, y) in a.merge_log.iter().zip(&b.merge_log) {
        assert_eq!(
            (x.curve, x.charts, x.accepted),
            (y.curve, y.charts, y.accepted)
        );
    }
}

#[test]
fn every_merge_decision_follows_its_measures() {
    let mesh = fixture("saddle");
    let p = Params::default();
    let s = run(&mesh, &p).summary;
    assert!(s.charts.merged > 1, "the saddle should need several charts");
    assert!(s.merge_log.iter().any(|c| !c.accepted));
    for c in &s.merge_log {
        match (c.area_distortion_pct, c.l2_stretch, c.overlap) {
            (Some(a), Some(l2), Some(o)) => {
                let ok = a.abs() <= p.max_area_distortion && l2 <= p.max_l2_stretch && o == 0;
                assert_eq!(c.accepted, ok, "{c:?}");
            }
            _ => assert!(!c.accepted && c.reason.is_some(), "{c:?}"),
        }
    }
}

#[test]
fn parameters_out_of_range_are_named() {
    let mesh = fixture("cone");
    for (key, p) in [
        (
            "vsa_tolerance",
            Params {
                vsa_tolerance: 0.0,
                ..Params::default()
            },
        ),
        (
            "max_l2_stretch",
            Params {
                max_l2_stretch: 0.9,
                ..Params::default()
            },
        ),
        (
            "max_charts",
            Params {
                max_charts: 0,
                ..Params::default()
            },
        ),
    ] {
        match segment::run(&mesh, &p, &Silent::default()) {
            Err(flatmesh::algorithms::AlgoError::InvalidParam { key: k, .. }) => assert_eq!(k, key),
            other => panic!("{key}: {:?}", other.map(|_| ())),
        }
    }
}

/// Corner angle sum at every vertex whose fan is closed (each of its edges shared by two
/// faces), by brute force from the positions.
fn closed_fan_angle_sums(mesh: &Mesh) -> Vec<(u32, f64)> {
    let mut sum = vec![0.0f64; mesh.num_vertices()];
    let mut open = vec![false; mesh.num_vertices()];
    let mut count = std::collections::HashMap::new();
    for t in mesh.triangles() {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            let [p, q, r] = [t[i], t[(i + 1) % 3], t[(i + 2) % 3]].map(|v| mesh.position(v));
            let u = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
            let w = [r[0] - p[0], r[1] - p[1], r[2] - p[2]];
            let dot = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
            let cr = [
                u[1] * w[2] - u[2] * w[1],
                u[2] * w[0] - u[0] * w[2],
                u[0] * w[1] - u[1] * w[0],
            ];
            sum[t[i] as usize] += (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2])
                .sqrt()
                .atan2(dot);
        }
    }
    for (&(a, b), &n) in &count {
        if n != 2 {
            open[a as usize] = true;
            open[b as usize] = true;
        }
    }
    (0..mesh.num_vertices() as u32)
        .filter(|&v| !open[v as usize] && sum[v as usize] > 0.0)
        .map(|v| (v, sum[v as usize]))
        .collect()
}

/// `then = fl-mesh`: every chart converged, so every interior vertex of the output has its
/// angle sum at 2π (brute force, to 1e-6 rad); chart boundaries stay where they were (so
/// the charts still sew together); the charts partition the faces, connected; every
/// pattern edge has its 3D length within 0.1 % and no pattern overlaps itself (brute
/// force). Returns the report.
fn check_exact(name: &str, mesh: &Mesh, params: &Params) -> segment::Summary {
    let params = Params {
        then: segment::Then::FlMesh,
        ..params.clone()
    };
    let out = run(mesh, &params);
    let s = out.summary;
    let fl = s.fl_mesh.as_ref().expect("fl-mesh ran");
    assert!(fl.converged, "{name}: {}", fl.stop_reason);
    assert_partition(mesh, &s.face_charts, name);
    assert_eq!(fl.charts.len(), s.charts.merged, "{name}");
    let cut = out.mesh.as_ref().unwrap();
    for (v, sum) in closed_fan_angle_sums(cut) {
        assert!(
            (sum - 2.0 * std::f64::consts::PI).abs() <= 1e-6,
            "{name}: vertex {v} has angle sum {sum}"
        );
    }
    for v in 0..cut.num_vertices() as u32 {
        if cut.conn().kind(v) == flatmesh::mesh::VertexKind::Boundary {
            assert_eq!(
                cut.position(v),
                mesh.position(s.vertex_map[v as usize]),
                "{name}: boundary vertex {v} moved"
            );
        }
    }
    let pieces = &out.patterns.as_ref().unwrap().pieces;
    assert_eq!(pieces.len(), s.charts.merged, "{name}");
    for p in pieces {
        let e = flatmesh::corpus::pattern_checks::edge_length_error(cut, p);
        assert!(
            e <= 1e-3,
            "{name} {}: an edge is {:.3} % off its 3D length",
            p.patch,
            100.0 * e
        );
        assert!(
            !independent_measures(cut, p).2,
            "{name} {}: the pattern overlaps itself",
            p.patch
        );
    }
    s
}

#[test]
fn then_fl_mesh_makes_every_chart_isometric() {
    let patch = Params::default();
    check_exact("saddle", &fixture("saddle"), &patch);
    check_exact("hemisphere_cap", &fixture("hemisphere_cap"), &patch);
    for rel in [
        "garment/diffavatar_tshirt.obj",
        "shoe/mh_shoes01.obj",
        "classic/od_spot_lowres.obj",
    ] {
        if let Some(m) = shared(rel) {
            check_exact(rel, &m, &patch);
        }
    }
    // With slits (boundary merging) too.
    if let Some(m) = shared("classic/od_spot_lowres.obj") {
        let boundary = Params {
            merge: MergeMode::Boundary,
            ..Params::default()
        };
        check_exact("spot boundary", &m, &boundary);
    }
}

/// A sphere with one small hole, `n` rings of `2n` quads from the hole's rim to the pole.
fn pouch(n: usize) -> Mesh {
    let m = 2 * n;
    let ring = |i: usize| {
        // Polar angle from 40° at the rim to 180° at the pole.
        let t = (40.0 + 140.0 * i as f64 / n as f64).to_radians();
        (0..m)
            .map(|j| {
                let a = std::f64::consts::TAU * j as f64 / m as f64;
                [t.sin() * a.cos(), t.sin() * a.sin(), t.cos()]
            })
            .collect::<Vec<_>>()
    };
    let mut positions: Vec<[f64; 3]> = (0..n).flat_map(ring).collect();
    positions.push([0.0, 0.0, -1.0]);
    let pole = (positions.len() - 1) as u32;
    let at = |i: usize, j: usize| (i * m + j % m) as u32;
    let mut triangles = Vec::new();
    for i in 0..n - 1 {
        for j in 0..m {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    for j in 0..m {
        triangles.push([at(n - 1, j), pole, at(n - 1, j + 1)]);
    }
    Mesh::new(RawMesh {
        positions,
        triangles,
        ..RawMesh::default()
    })
    .unwrap()
    .0
}

/// A chart that fl-mesh cannot make flattenable with its boundary fixed, or whose
/// isometric pattern wraps onto itself, is split until every piece passes: a pouch kept as
/// one chart (one VSA chart, bounds so loose that it is not split before fl-mesh) must be
/// split, and ends with every piece exactly flattenable.
#[test]
fn then_fl_mesh_splits_a_chart_it_cannot_flatten() {
    let loose = Params {
        max_charts: 1,
        max_area_distortion: 100.0,
        max_l2_stretch: 1e6,
        reject_overlap: false,
        ..Params::default()
    };
    for n in [6, 12] {
        let s = check_exact(&format!("pouch {n}"), &pouch(n), &loose);
        let fl = s.fl_mesh.unwrap();
        assert!(
            s.charts.tested == 1 && !fl.failures.is_empty(),
            "pouch {n}: nothing was split ({:?}, {:?})",
            s.charts,
            fl.stop_reason
        );
        assert_eq!(
            fl.charts.iter().map(|c| c.faces).sum::<usize>(),
            s.face_charts.len()
        );
    }
}

#[test]
fn pseudo_inverse_solves_and_drops_the_null_space() {
    // Rank 2: M = R diag(2, 3, 0) Rᵀ with R a rotation about a general axis; M⁺ r has no
    // component along the null vector R e_z.
    let (c, s) = (0.6f64, 0.8f64);
    let rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    let (c2, s2) = (0.28f64, 0.96f64);
    let rx = [[1.0, 0.0, 0.0], [0.0, c2, -s2], [0.0, s2, c2]];
    let mut rot = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                rot[i][j] += rx[i][k] * rz[k][j];
            }
        }
    }
    let d = [2.0, 3.0, 0.0];
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                m[i][j] += rot[i][k] * d[k] * rot[j][k];
            }
        }
    }
    let r = [1.0, -2.0, 5.0];
    let x = segment::denoise::pseudo_solve(m, r);
    // Expected: Σ_k u_k (u_k·r)/d_k over the two non-zero d_k.
    let mut want = [0.0; 3];
    for k in 0..2 {
        let u = [rot[0][k], rot[1][k], rot[2][k]];
        let ur: f64 = (0..3).map(|i| u[i] * r[i]).sum();
        for i in 0..3 {
            want[i] += u[i] * ur / d[k];
        }
    }
    for i in 0..3 {
        assert!((x[i] - want[i]).abs() < 1e-12, "{x:?} vs {want:?}");
    }
}

/// The cube's chart-boundary vertices (one chart per side), pushed off by noise, go back
/// onto the planes of the sides they lie on; a noise-free cube does not move. (With VSA's
/// charts the cube may get a chart one face row wide, all of whose vertices are on its
/// boundary: sliding it along its normal costs nothing, so no noise-free answer is implied.)
#[test]
fn denoising_puts_chart_boundaries_back_on_the_box() {
    let clean = cube(8);
    let dual = Dual::new(&clean, true);
    let labels: Vec<u32> = dual
        .normal
        .iter()
        .map(|n| {
            let axis = (0..3)
                .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
                .unwrap();
            (2 * axis + (n[axis] > 0.0) as usize) as u32
        })
        .collect();
    let k = 6;
    let still = segment::denoise::run(&clean, &labels, k);
    assert_eq!(still.max_displacement, 0.0);
    let mut pos = clean.positions().to_vec();
    let conn = clean.conn();
    let mut seed = 7u64;
    let mut noise = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02
    };
    let mut moved = Vec::new();
    for w in 0..pos.len() as u32 {
        let charts: std::collections::HashSet<u32> = conn
            .fan_of(w)
            .iter()
            .map(|&h| labels[(h / 3) as usize])
            .collect();
        if charts.len() > 1 {
            for x in pos[w as usize].iter_mut() {
                *x += noise();
            }
            moved.push(w);
        }
    }
    let noisy = clean.with_positions(pos).unwrap();
    // Distance to the intersection of the cube's sides through the clean position.
    let off = |p: [f64; 3], p0: [f64; 3]| -> f64 {
        (0..3)
            .filter(|&c| p0[c] == 0.0 || p0[c] == 1.0)
            .map(|c| (p[c] - p0[c]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let before = moved
        .iter()
        .map(|&w| off(noisy.position(w), clean.position(w)))
        .fold(0.0, f64::max);
    let d = segment::denoise::run(&noisy, &labels, k);
    let after = moved
        .iter()
        .map(|&w| off(d.positions[w as usize], clean.position(w)))
        .fold(0.0, f64::max);
    assert!(
        after <= 1e-3 * before,
        "{before} → {after} ({} sweeps, {} refused, {} charts)",
        d.sweeps,
        d.refused,
        k
    );
    for w in 0..noisy.num_vertices() {
        if !moved.contains(&(w as u32)) {
            assert_eq!(d.positions[w], noisy.position(w as u32));
        }
    }
}
