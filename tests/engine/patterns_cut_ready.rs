//! Cut-ready patterns (seam allowance, notches, grain, UVs on the mesh) against independent
//! truths: closed-form areas of offset rectangles, brute-force segment crossings, 3D points
//! recomputed from the mesh, vertical mesh edges, and round trips through the writers.

use flatmesh::algorithms::flatten::{self, finish::Grain, Params};
use flatmesh::algorithms::Silent;
use flatmesh::mesh::{Mesh, RawMesh};
use flatmesh::pattern::{Patterns, Piece};

/// A flat w × h rectangle (metres) in the plane z = 0 turned by `turn` radians about z, as an
/// nx × ny grid; faces left of x = `split`·w are patch `left`, the rest `right` (no split when
/// `split` ≥ 1).
fn rectangle(w: f64, h: f64, nx: usize, ny: usize, split: f64, turn: f64) -> Mesh {
    let (s, c) = turn.sin_cos();
    let mut positions = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (w * i as f64 / nx as f64, h * j as f64 / ny as f64);
            positions.push([c * x - s * y, s * x + c * y, 0.0]);
        }
    }
    let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
    let (mut triangles, mut face_patch) = (Vec::new(), Vec::new());
    for j in 0..ny {
        for i in 0..nx {
            let p = u32::from((i as f64 + 0.5) / nx as f64 > split);
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            face_patch.extend([p, p]);
        }
    }
    let two = face_patch.contains(&1);
    Mesh::new(RawMesh {
        positions,
        triangles,
        face_patch,
        patch_names: if two {
            vec!["left".into(), "right".into()]
        } else {
            vec!["whole".into()]
        },
        uv: None,
    })
    .expect("valid mesh")
    .0
}

fn flatten_with(mesh: &Mesh, params: serde_json::Value) -> (Patterns, Vec<String>, Mesh) {
    let p: Params = serde_json::from_value(params).expect("params");
    let out = flatten::run(mesh, &p, &Silent::default()).expect("flatten");
    (
        out.patterns.expect("patterns"),
        out.summary.job_warnings,
        out.mesh.expect("the mesh with its UVs"),
    )
}

fn area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|k| {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum::<f64>()
        / 2.0
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt()
}

/// Distance from p to a piece's sew line (every boundary loop).
fn to_sew_line(pc: &Piece, p: [f64; 2]) -> f64 {
    let mut best = f64::MAX;
    for lp in &pc.boundary_loops {
        for k in 0..lp.len() {
            let (a, b) = (
                pc.uv[lp[k] as usize],
                pc.uv[lp[(k + 1) % lp.len()] as usize],
            );
            best = best.min(seg_dist(p, a, b));
        }
    }
    best
}

/// Whether two closed segments properly cross (brute force, exact orientation signs).
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    // The sign (0 on the line: f64::signum gives ±1 for ±0).
    let o = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        let x = (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]);
        f64::from(i8::from(x > 0.0) - i8::from(x < 0.0))
    };
    o(a, b, c) * o(a, b, d) < 0.0 && o(c, d, a) * o(c, d, b) < 0.0
}

/// Proper crossings among the edges of a set of closed polygons (adjacent edges excluded).
fn crossings(polys: &[Vec<[f64; 2]>]) -> usize {
    let edges: Vec<([f64; 2], [f64; 2])> = polys
        .iter()
        .flat_map(|p| (0..p.len()).map(move |k| (p[k], p[(k + 1) % p.len()])))
        .collect();
    let mut n = 0;
    for i in 0..edges.len() {
        for j in i + 1..edges.len() {
            if cross(edges[i].0, edges[i].1, edges[j].0, edges[j].1) {
                n += 1;
            }
        }
    }
    n
}

fn diameter(pc: &Piece) -> f64 {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for q in &pc.uv {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2)).sqrt()
}

#[test]
fn a_uniform_allowance_offsets_a_rectangle_exactly() {
    // 0.4 m × 0.3 m, allowance 10 mm: the cut line is the rectangle grown by 0.01 on every
    // side (mitred 90° corners stay square corners), area (w + 2d)(h + 2d).
    let mesh = rectangle(0.4, 0.3, 8, 6, 2.0, 0.7);
    let (pat, warnings, _) = flatten_with(&mesh, serde_json::json!({"input_unit": "m"}));
    assert!(warnings.is_empty(), "{warnings:?}");
    let pc = &pat.pieces[0];
    assert_eq!(pc.cut_lines.len(), 1, "one cut line, no hole");
    let cut = &pc.cut_lines[0];
    let (w, h, d) = (0.4, 0.3, 0.01);
    let diam = diameter(pc);
    let want = (w + 2.0 * d) * (h + 2.0 * d);
    assert!(
        (area(cut) - want).abs() <= 1e-9 * want,
        "cut-line area {} vs {want}",
        area(cut)
    );
    // Every cut-line edge lies on the line of a sew-line edge moved out by exactly d (the
    // straight offset), and no cut-line point comes closer than d to the sew line.
    let sew: Vec<([f64; 2], [f64; 2])> = pc
        .boundary_loops
        .iter()
        .flat_map(|lp| {
            (0..lp.len()).map(move |k| {
                (
                    pc.uv[lp[k] as usize],
                    pc.uv[lp[(k + 1) % lp.len()] as usize],
                )
            })
        })
        .collect();
    let off_line = |p: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = (dx * dx + dy * dy).sqrt();
        ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx) / l
    };
    for k in 0..cut.len() {
        let (a, b) = (cut[k], cut[(k + 1) % cut.len()]);
        let on = sew.iter().any(|&(p, q)| {
            (off_line(a, p, q).abs() - d).abs() <= 1e-9 * diam
                && (off_line(b, p, q).abs() - d).abs() <= 1e-9 * diam
        });
        assert!(
            on,
            "cut-line edge {k} ({a:?} → {b:?}) is not on an offset line at {d}"
        );
        let dist = to_sew_line(pc, a);
        assert!(
            dist >= d - 1e-9 * diam,
            "cut-line point {k} at {dist} from the sew line"
        );
    }
    assert_eq!(
        crossings(&pc.cut_lines),
        0,
        "the cut line is a simple polygon"
    );
    assert!(area(cut) > 0.0, "outer cut line counter-clockwise");
}

#[test]
fn per_seam_overrides_and_hems_apply_to_their_edges_only() {
    // Two patches side by side (seam at x = w/2): the seam gets 15 mm, hems 0. The left piece
    // is then its rectangle grown by 15 mm on the seam side only: area (w/2 + 0.015) h.
    let mesh = rectangle(0.4, 0.3, 8, 6, 0.5, 0.0);
    let (pat, _, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "m", "hem_allowance": 0,
            "seam_allowances": [{"patches": ["right", "left"], "allowance": 15}]}),
    );
    assert_eq!(pat.pieces.len(), 2);
    assert_eq!(pat.seams.len(), 1);
    for pc in &pat.pieces {
        assert_eq!(pc.cut_lines.len(), 1, "{}", pc.patch);
        let want = (0.2 + 0.015) * 0.3;
        let got = area(&pc.cut_lines[0]);
        assert!(
            (got - want).abs() <= 1e-9 * want,
            "piece {}: cut-line area {got} vs {want}",
            pc.patch
        );
        assert_eq!(crossings(&pc.cut_lines), 0);
    }
    // Without any allowance there is no cut line.
    let (pat, _, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "m", "seam_allowance": 0}),
    );
    assert!(pat.pieces.iter().all(|p| p.cut_lines.is_empty()));
}

#[test]
fn square_corners_cut_the_mitre_at_the_allowance() {
    // A right-angle corner squared at the allowance d cuts a triangle of legs d(√2 − 1)·√2
    // off each mitred corner: area (w+2d)(h+2d) − 4 · d²(√2 − 1)².
    let mesh = rectangle(0.4, 0.3, 8, 6, 2.0, 0.0);
    let (pat, _, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "m", "corners": "square"}),
    );
    let d: f64 = 0.01;
    let s2 = 2f64.sqrt();
    let want = 0.42 * 0.32 - 4.0 * d * d * (s2 - 1.0) * (s2 - 1.0);
    let got = area(&pat.pieces[0].cut_lines[0]);
    assert!((got - want).abs() <= 1e-9 * want, "{got} vs {want}");
}

#[test]
fn the_grain_runs_up_the_drawing() {
    // The rectangle turned in its plane: its 3D +Y edges... are not vertical in 3D when
    // turned, so use an upright rectangle in a vertical plane, turned about the vertical.
    for turn in [0.0, 0.6, 2.0] {
        let mesh = rectangle(0.4, 0.3, 8, 6, 2.0, turn);
        // Tilt into the plane x–y so that 3D +Y has a known image: the mesh lies in z = 0
        // and its grid rows run along (cos turn, sin turn).
        let (pat, _, _) = flatten_with(&mesh, serde_json::json!({"input_unit": "m"}));
        let pc = &pat.pieces[0];
        let pos = mesh.positions();
        // Every mesh edge that is vertical in 3D (along ±Y) is vertical in the drawing.
        let mut checked = 0;
        for t in &pc.triangles {
            for k in 0..3 {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                let (pa, pb) = (
                    pos[pc.vertex_ids[a] as usize],
                    pos[pc.vertex_ids[b] as usize],
                );
                let len = ((pb[0] - pa[0]).powi(2) + (pb[1] - pa[1]).powi(2)).sqrt();
                if (pb[0] - pa[0]).abs() <= 1e-12 * len.max(1e-300) && len > 0.0 {
                    let dx = pc.uv[b][0] - pc.uv[a][0];
                    assert!(
                        dx.abs() <= 1e-9 * len,
                        "turn {turn}: vertical edge has dx {dx}"
                    );
                    assert!(
                        (pc.uv[b][1] - pc.uv[a][1]).signum() == (pb[1] - pa[1]).signum(),
                        "turn {turn}: up stays up"
                    );
                    checked += 1;
                }
            }
        }
        if turn == 0.0 {
            assert!(checked > 0);
        }
        let [a, b] = pc.grain.expect("a grain line");
        assert_eq!(a[0], b[0], "grain line vertical");
        assert!(b[1] > a[1]);
    }
    // A piece lying across the grain direction (horizontal, grain up) falls back to its
    // principal axis and says so.
    let mesh = rectangle(0.4, 0.1, 8, 2, 2.0, 0.0);
    let flat: Vec<[f64; 3]> = mesh.positions().iter().map(|p| [p[0], 0.0, p[1]]).collect();
    let mesh = mesh.with_positions(flat).unwrap();
    let (pat, warnings, _) = flatten_with(&mesh, serde_json::json!({"input_unit": "m"}));
    assert!(
        warnings.iter().any(|w| w.contains("principal axis")),
        "{warnings:?}"
    );
    let pc = &pat.pieces[0];
    let h = pc.uv.iter().map(|q| q[1]).fold(f64::MIN, f64::max)
        - pc.uv.iter().map(|q| q[1]).fold(f64::MAX, f64::min);
    assert!(
        (h - 0.4).abs() < 1e-9,
        "the long side runs along the grain: height {h}"
    );
    let _ = Grain::Principal;
}

/// Every notch's 3D point, from the mesh: the point at t on its edge.
fn notch_points(pat: &Patterns, pos: &[[f64; 3]]) -> Vec<((usize, usize), usize, [f64; 3])> {
    let mut out = Vec::new();
    for pc in &pat.pieces {
        for n in &pc.notches {
            let (a, b) = (
                pos[pc.vertex_ids[n.edge[0] as usize] as usize],
                pos[pc.vertex_ids[n.edge[1] as usize] as usize],
            );
            let p = [0, 1, 2].map(|k| a[k] + n.t * (b[k] - a[k]));
            // The 2D point is the same t on the 2D edge.
            let (qa, qb) = (pc.uv[n.edge[0] as usize], pc.uv[n.edge[1] as usize]);
            let q = [qa[0] + n.t * (qb[0] - qa[0]), qa[1] + n.t * (qb[1] - qa[1])];
            assert!(
                (q[0] - n.at[0]).abs() + (q[1] - n.at[1]).abs()
                    <= 1e-12 * (1.0 + q[0].abs() + q[1].abs())
            );
            out.push(((n.seam, n.number), n.side, p));
        }
    }
    out
}

fn check_notches_match(pat: &Patterns, pos: &[[f64; 3]], what: &str) -> usize {
    let points = notch_points(pat, pos);
    type Sides = Vec<(usize, [f64; 3])>;
    let mut by: std::collections::HashMap<(usize, usize), Sides> = Default::default();
    for (key, side, p) in points {
        by.entry(key).or_default().push((side, p));
    }
    for ((seam, number), list) in &by {
        assert_eq!(
            list.len(),
            2,
            "{what}: seam {seam} notch {number} has {} sides",
            list.len()
        );
        let len = pat.seams[*seam].length_3d;
        let (p, q) = (list[0].1, list[1].1);
        let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        assert!(
            d <= 1e-9 * len,
            "{what}: seam {seam} notch {number}: sides {d} apart in 3D (seam {len})"
        );
    }
    by.len()
}

#[test]
fn notches_of_a_seam_fall_on_the_same_3d_points() {
    // The two-panel tube: two seams along its height, curved panels.
    let f = flatmesh::fixtures::by_name("tube_two_panels").unwrap();
    let mesh = Mesh::new(f.mesh).unwrap().0;
    let (pat, warnings, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "dm", "notch_spacing": 20}),
    );
    assert!(!pat.seams.is_empty());
    assert!(
        !warnings.iter().any(|w| w.contains("notches")),
        "{warnings:?}"
    );
    let n = check_notches_match(&pat, mesh.positions(), "tube");
    // Each open seam: both ends and every 20 mm of 3D length in between.
    let mut want = 0;
    for s in &pat.seams {
        let l_mm = s.length_3d * 100.0;
        let mut k = 1.0;
        while k * 20.0 < l_mm - 5.0 {
            k += 1.0;
        }
        want += k as usize + 1;
    }
    assert_eq!(n, want, "notch count");
    // LSCM does not keep lengths; the notches still meet in 3D.
    let (pat, _, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "dm", "method": "lscm", "notch_spacing": 20}),
    );
    assert!(check_notches_match(&pat, mesh.positions(), "tube lscm") > 0);
}

#[test]
fn real_garments_get_simple_cut_lines_and_matching_notches() {
    let Some(root) =
        flatmesh::corpus::shared_root_for_tests("cut-ready patterns of the shared garments")
    else {
        return;
    };
    for name in [
        "garment/gf_dress.obj",
        "garment/mh_female_casualsuit02.obj",
        "garment/diffavatar_tshirt.obj",
        "shoe/mh_shoes01.obj",
    ] {
        let bytes = std::fs::read(root.join(name)).unwrap();
        let raw = flatmesh::io::obj::read(&bytes).unwrap().0;
        let mesh = Mesh::new(raw).unwrap().0;
        let (pat, _, out) = flatten_with(&mesh, serde_json::json!({}));
        check_notches_match(&pat, mesh.positions(), name);
        let allowance = 10.0 / flatmesh::pattern::mm_per(&pat.input_unit).unwrap();
        for pc in &pat.pieces {
            assert!(!pc.cut_lines.is_empty(), "{name} {}", pc.patch);
            assert_eq!(
                crossings(&pc.cut_lines),
                0,
                "{name} {}: cut line crosses itself",
                pc.patch
            );
            // The cut line keeps the allowance from the sew line (within the 0.1 % of it that
            // the sew line is simplified by before offsetting).
            let diam = diameter(pc);
            let slack = flatten::finish::SIMPLIFY * allowance + 1e-9 * diam;
            for p in pc.cut_lines.iter().flatten() {
                let d = to_sew_line(pc, *p);
                assert!(
                    d >= allowance - slack,
                    "{name} {}: cut-line point {d} from the sew line",
                    pc.patch
                );
            }
        }
        assert!(out.uv().is_some(), "{name}: the output mesh has UVs");
    }
}

#[test]
fn the_flattened_mesh_carries_its_pattern_as_uvs_through_obj_and_gltf() {
    let mesh = rectangle(0.4, 0.3, 8, 6, 0.5, 0.3);
    let (pat, _, out) = flatten_with(&mesh, serde_json::json!({"input_unit": "m"}));
    let uv = out.uv().expect("uvs").clone();
    // Each corner's UV is its point in the drawing (DXF coordinates, mm).
    let (off, _, _) = pat.layout();
    let s = pat.scale();
    for (i, pc) in pat.pieces.iter().enumerate() {
        for (t, &f) in pc.triangles.iter().zip(&pc.faces) {
            for (k, &corner) in t.iter().enumerate() {
                let q = pc.uv[corner as usize];
                let c = uv.coords[uv.triangles[f as usize][k] as usize];
                assert!((c[0] - (q[0] * s + off[i][0])).abs() < 1e-9);
                assert!((c[1] - (q[1] * s + off[i][1])).abs() < 1e-9);
            }
        }
    }
    let corner_uv = |m: &Mesh, f: usize, k: usize| {
        let l = m.uv().unwrap();
        l.coords[l.triangles[f][k] as usize]
    };
    // OBJ: exact, faces grouped by patch (one `g` each) in their order.
    let mut order: Vec<usize> = (0..out.num_faces()).collect();
    order.sort_by_key(|&f| out.face_patch()[f]);
    let text = flatmesh::io::obj::write(&out.to_raw());
    let back = Mesh::new(flatmesh::io::obj::read(text.as_bytes()).unwrap().0)
        .unwrap()
        .0;
    for (g, &f) in order.iter().enumerate() {
        for k in 0..3 {
            assert_eq!(corner_uv(&back, g, k), corner_uv(&out, f, k));
        }
    }
    // glTF (f32): the faces come back patch by patch, each face's corners at their UVs; the
    // patches are welded back along the seam (one surface again).
    let glb = flatmesh::io::gltf::write_glb(&out, None);
    let (raw, _) = flatmesh::io::gltf::read(&glb).unwrap();
    let back = Mesh::new(raw).unwrap().0;
    assert_eq!(back.num_vertices(), out.num_vertices(), "seam welded");
    let range = 500.0;
    for (g, &f) in order.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (corner_uv(&back, g, k), corner_uv(&out, f, k));
            assert!(
                (a[0] - b[0]).abs() <= 1e-6 * range && (a[1] - b[1]).abs() <= 1e-6 * range,
                "face {f} corner {k}: {a:?} vs {b:?}"
            );
            let (pa, pb) = (
                back.positions()[back.triangles()[g][k] as usize],
                out.positions()[out.triangles()[f][k] as usize],
            );
            assert!((0..3).all(|c| (pa[c] - pb[c]).abs() < 1e-6));
        }
    }
}

#[test]
fn bad_finishing_parameters_are_named() {
    let mesh = rectangle(0.4, 0.3, 4, 3, 2.0, 0.0);
    for (params, key) in [
        (serde_json::json!({"seam_allowance": -1}), "seam_allowance"),
        (serde_json::json!({"notch_spacing": 0.001}), "notch_spacing"),
        (serde_json::json!({"mitre_limit": 0.5}), "mitre_limit"),
        (serde_json::json!({"grain": [0, 0, 0]}), "grain"),
        (
            serde_json::json!({"seam_allowances": [{"patches": ["a", "b"], "allowance": 5000}]}),
            "seam_allowances[0].allowance",
        ),
    ] {
        let p: Params = serde_json::from_value(params.clone()).expect("parses");
        match flatten::run(&mesh, &p, &Silent::default()) {
            Err(flatmesh::algorithms::AlgoError::InvalidParam { key: k, .. }) => {
                assert_eq!(k, key, "{params}")
            }
            other => panic!("{params}: {:?}", other.map(|_| ())),
        }
    }
    assert!(serde_json::from_value::<Params>(serde_json::json!({"grain": "sideways"})).is_err());
}

/// The Python with ezdxf that `.ci/run` installs (`target/ci-venv`, or `FLATMESH_CLIENT_VENV`);
/// None (said) outside CI when it is missing.
fn ezdxf_python() -> Option<std::path::PathBuf> {
    let dir = std::env::var_os("FLATMESH_CLIENT_VENV")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ci-venv"));
    let py = dir.join("bin/python");
    let ok = std::process::Command::new(&py)
        .args(["-c", "import ezdxf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "CI=true but no ezdxf in {} (.ci/run installs it)",
        dir.display()
    );
    eprintln!(
        "SKIPPED: no ezdxf in {}; run .ci/run to install it",
        dir.display()
    );
    None
}

#[test]
fn the_aama_dxf_reads_back_in_ezdxf_with_its_blocks_and_layers() {
    use flatmesh::io::pattern::{self, aama};
    let f = flatmesh::fixtures::by_name("tube_two_panels").unwrap();
    let mesh = Mesh::new(f.mesh).unwrap().0;
    let (pat, _, _) = flatten_with(&mesh, serde_json::json!({"input_unit": "dm"}));
    let dxf = pattern::to_dxf(&pat);
    // Our own reader finds every polyline of every block.
    let polys = pattern::read_dxf_polylines(&dxf).unwrap();
    let cut: usize = pat.pieces.iter().map(|p| p.cut_lines.len()).sum();
    let sew: usize = pat.pieces.iter().map(|p| p.boundary_loops.len()).sum();
    assert_eq!(polys.len(), cut + sew);
    let Some(py) = ezdxf_python() else {
        return;
    };
    let path = std::env::temp_dir().join(format!("flatmesh-aama-{}.dxf", std::process::id()));
    std::fs::write(&path, &dxf).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/dxf/read_aama.py");
    let out = std::process::Command::new(py)
        .arg(script)
        .arg(&path)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for layer in [
        aama::BOUNDARY,
        aama::NOTCHES,
        aama::GRAIN,
        aama::INTERNAL_CUTOUTS,
        aama::SEW,
        aama::ANNOTATION,
    ] {
        assert!(
            v["layers"].as_array().unwrap().iter().any(|l| l == layer),
            "layer {layer}"
        );
    }
    let s = pat.scale();
    let (off, _, _) = pat.layout();
    let inserts = v["inserts"].as_array().unwrap();
    assert_eq!(inserts.len(), pat.pieces.len());
    for (i, pc) in pat.pieces.iter().enumerate() {
        let name = pattern::block_name(i, &pc.patch);
        let b = &v["blocks"][&name];
        assert!(b.is_object(), "block {name}");
        let count = |k: &str| b["entities"][k].as_u64().unwrap_or(0) as usize;
        assert_eq!(count("POLYLINE@1"), 1, "{name}: one cut line");
        assert_eq!(
            count("POLYLINE@14"),
            pc.boundary_loops.len(),
            "{name}: sew lines"
        );
        assert_eq!(count("LINE@4"), pc.notches.len(), "{name}: notches");
        assert!(!pc.notches.is_empty());
        assert_eq!(count("LINE@7"), 1, "{name}: grain line");
        let texts: Vec<String> = b["texts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| format!("{}|{}", t[0].as_str().unwrap(), t[1].as_str().unwrap()))
            .collect();
        assert!(
            texts.contains(&format!("1|Piece Name: {}", pc.patch)),
            "{texts:?}"
        );
        assert!(texts.contains(&"1|Quantity: 1".to_string()), "{texts:?}");
        // The cut line, in drawing units, as ezdxf reads it.
        let got = &b["closed_polylines"]["1"][0];
        let want = &pc.cut_lines[0];
        assert_eq!(got.as_array().unwrap().len(), want.len());
        for (g, w) in got.as_array().unwrap().iter().zip(want) {
            assert!((g[0].as_f64().unwrap() - w[0] * s).abs() < 1e-9 * (1.0 + (w[0] * s).abs()));
            assert!((g[1].as_f64().unwrap() - w[1] * s).abs() < 1e-9 * (1.0 + (w[1] * s).abs()));
        }
        // The grain line is vertical; each notch starts on the cut line.
        let g = &b["lines"]["7"][0];
        assert_eq!(g[0][0].as_f64(), g[1][0].as_f64());
        for (n, l) in pc.notches.iter().zip(b["lines"]["4"].as_array().unwrap()) {
            assert!(
                (l[0][0].as_f64().unwrap() - n.cut_at[0] * s).abs()
                    < 1e-9 * (1.0 + (n.cut_at[0] * s).abs())
            );
        }
        let ins = inserts
            .iter()
            .find(|x| x[0] == name.as_str())
            .expect("inserted");
        assert!((ins[1].as_f64().unwrap() - off[i][0]).abs() < 1e-9 * (1.0 + off[i][0].abs()));
        assert!((ins[2].as_f64().unwrap() - off[i][1]).abs() < 1e-9 * (1.0 + off[i][1].abs()));
    }
}

/// Rasterise each piece's outer cut line (the largest path of its group) of an SVG drawing
/// with resvg's parser and tiny-skia; returns the pieces' masks, the mask size in pixels, and
/// the page and each piece's stroke bounding box in the SVG's own pixels.
#[allow(clippy::type_complexity)]
fn piece_masks(
    svg: &str,
    px_per_unit: f32,
) -> (
    Vec<Vec<u8>>,
    (u32, u32),
    resvg::usvg::Size,
    Vec<resvg::usvg::Rect>,
) {
    use resvg::{tiny_skia, usvg};
    let tree = usvg::Tree::from_str(svg, &usvg::Options::default()).expect("the SVG parses");
    let size = tree.size();
    let (w, h) = (
        (size.width() * px_per_unit).ceil() as u32,
        (size.height() * px_per_unit).ceil() as u32,
    );
    let mut masks = Vec::new();
    let mut boxes = Vec::new();
    for i in 0.. {
        let Some(usvg::Node::Group(g)) = tree.node_by_id(&format!("piece-{i}")) else {
            break;
        };
        boxes.push(g.abs_stroke_bounding_box());
        let outer = g
            .children()
            .iter()
            .filter_map(|n| match n {
                usvg::Node::Path(p) => Some(p),
                _ => None,
            })
            .max_by(|a, b| {
                let area = |p: &usvg::Path| p.data().bounds().width() * p.data().bounds().height();
                area(a).total_cmp(&area(b))
            })
            .expect("a path");
        let mut mask = tiny_skia::Mask::new(w, h).unwrap();
        let t = outer.abs_transform().post_scale(px_per_unit, px_per_unit);
        mask.fill_path(outer.data(), tiny_skia::FillRule::Winding, false, t);
        masks.push(mask.data().to_vec());
    }
    (masks, (w, h), size, boxes)
}

#[test]
fn the_svg_pieces_fit_the_page_and_do_not_overlap() {
    let mut cases: Vec<(String, Mesh)> = vec![
        ("two rectangles".into(), rectangle(0.4, 0.3, 8, 6, 0.5, 0.0)),
        (
            "tube".into(),
            Mesh::new(flatmesh::fixtures::by_name("tube_two_panels").unwrap().mesh)
                .unwrap()
                .0,
        ),
    ];
    if let Some(root) = flatmesh::corpus::shared_root_for_tests("SVG of a many-piece suit") {
        let bytes = std::fs::read(root.join("garment/mh_female_casualsuit02.obj")).unwrap();
        cases.push((
            "casual suit".into(),
            Mesh::new(flatmesh::io::obj::read(&bytes).unwrap().0)
                .unwrap()
                .0,
        ));
    }
    for (name, mesh) in cases {
        let (pat, _, _) = flatten_with(&mesh, serde_json::json!({}));
        let svg = flatmesh::io::pattern::to_svg(&pat);
        // About 2000 pixels across the page.
        let probe = resvg::usvg::Tree::from_str(&svg, &resvg::usvg::Options::default()).unwrap();
        let px = 2000.0 / probe.size().width().max(probe.size().height());
        let (masks, (w, h), page, boxes) = piece_masks(&svg, px);
        assert_eq!(masks.len(), pat.pieces.len(), "{name}: one group per piece");
        for (i, b) in boxes.iter().enumerate() {
            assert!(
                b.left() >= 0.0
                    && b.top() >= 0.0
                    && b.right() <= page.width()
                    && b.bottom() <= page.height(),
                "{name}: piece {i} at {b:?} leaves the page {page:?}"
            );
        }
        let mut cover = vec![0u8; (w * h) as usize];
        let mut overlap = 0usize;
        for m in &masks {
            let filled = m.iter().filter(|&&a| a > 0).count();
            assert!(filled > 0, "{name}: a piece drew nothing");
            for (c, &a) in cover.iter_mut().zip(m) {
                if a > 0 {
                    overlap += usize::from(*c > 0);
                    *c = 1;
                }
            }
        }
        assert_eq!(overlap, 0, "{name}: pieces overlap on {overlap} pixels");
    }
}

#[test]
fn the_cost_estimate_adds_up_for_two_rectangles() {
    // Two 200 × 300 mm panels with a 10 mm allowance all round: each cut piece is 220 × 320.
    let mesh = rectangle(0.4, 0.3, 8, 6, 0.5, 0.0);
    let run = |width: f64| {
        let p: Params =
            serde_json::from_value(serde_json::json!({"input_unit": "m", "fabric_width": width}))
                .unwrap();
        flatten::run(&mesh, &p, &Silent::default()).unwrap().summary
    };
    let s = run(1500.0);
    let c = &s.cost;
    assert_eq!(c.unit, "mm");
    assert!((c.piece_area - 2.0 * 220.0 * 320.0).abs() < 1e-6, "{c:?}");
    assert!(
        (c.cut_length - 2.0 * 2.0 * (220.0 + 320.0)).abs() < 1e-6,
        "{c:?}"
    );
    // Side by side on one shelf of a 1500 mm roll.
    assert!((c.fabric_length.unwrap() - 320.0).abs() < 1e-6, "{c:?}");
    let want = 100.0 * 140_800.0 / (1500.0 * 320.0);
    assert!((c.utilisation_pct.unwrap() - want).abs() < 1e-6);
    assert!((c.length_bound - 140_800.0 / 1500.0).abs() < 1e-6);
    // A 300 mm roll takes one piece per shelf.
    let c = run(300.0).cost;
    assert!((c.fabric_length.unwrap() - 640.0).abs() < 1e-6, "{c:?}");
    // A 200 mm roll is narrower than either piece: no length, both named.
    let s = run(200.0);
    assert_eq!(s.cost.fabric_length, None);
    assert_eq!(s.cost.utilisation_pct, None);
    assert_eq!(s.cost.too_wide, ["left", "right"]);
}

/// A flat disk of radius 0.2 m (`rings` × `sectors`), in three patches: `a` (angles 0–π), `b1`
/// (π–3π/2) and `b2` (3π/2–2π).
fn three_patch_disk(rings: usize, sectors: usize) -> Mesh {
    use std::f64::consts::PI;
    let mut positions = vec![[0.0, 0.0, 0.0]];
    for i in 1..=rings {
        for j in 0..sectors {
            let (r, t) = (
                0.2 * i as f64 / rings as f64,
                2.0 * PI * j as f64 / sectors as f64,
            );
            positions.push([r * t.cos(), r * t.sin(), 0.0]);
        }
    }
    let id = |i: usize, j: usize| {
        if i == 0 {
            0
        } else {
            (1 + (i - 1) * sectors + j % sectors) as u32
        }
    };
    let (mut triangles, mut face_patch) = (Vec::new(), Vec::new());
    let patch = |j: usize| {
        let t = 2.0 * PI * (j as f64 + 0.5) / sectors as f64;
        if t < PI {
            0
        } else if t < 1.5 * PI {
            1
        } else {
            2
        }
    };
    for j in 0..sectors {
        triangles.push([0, id(1, j), id(1, j + 1)]);
        face_patch.push(patch(j));
        for i in 1..rings {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            face_patch.extend([patch(j), patch(j)]);
        }
    }
    Mesh::new(RawMesh {
        positions,
        triangles,
        face_patch,
        patch_names: vec!["a".into(), "b1".into(), "b2".into()],
        uv: None,
    })
    .unwrap()
    .0
}

#[test]
fn a_change_of_allowance_on_a_straight_run_is_a_step_not_a_spike() {
    // Piece `a`'s straight edge is two seams meeting at the centre (to b1 at 30 mm, to b2 at
    // 10 mm) with a turn of ~0 there after flattening; its rim is a hem without allowance.
    // Where the offset lines of 30 and 10 mm would meet (far away, or never), the cut line
    // must step instead: nowhere further from the sew line than mitre_limit × 30 mm.
    let mesh = three_patch_disk(6, 32);
    let (pat, _, _) = flatten_with(
        &mesh,
        serde_json::json!({"input_unit": "m", "hem_allowance": 0, "seam_allowances": [
            {"patches": ["a", "b1"], "allowance": 30}, {"patches": ["a", "b2"], "allowance": 10}]}),
    );
    for pc in &pat.pieces {
        let diam = diameter(pc);
        assert_eq!(crossings(&pc.cut_lines), 0, "{}", pc.patch);
        for p in pc.cut_lines.iter().flatten() {
            let d = to_sew_line(pc, *p);
            assert!(
                d <= 3.0 * 0.03 + 1e-9 * diam,
                "{}: cut-line point {d} m from the sew line",
                pc.patch
            );
        }
    }
    let a = pat.pieces.iter().find(|p| p.patch == "a").unwrap();
    // Half disk r = 0.2 grown by 30 mm on one half of its diameter and 10 mm on the other:
    // at least its area plus those two strips (the joins at the rim add a little).
    let strips = 0.2 * 0.03 + 0.2 * 0.01;
    let got = area(&a.cut_lines[0]);
    let sew = area(
        &a.boundary_loops[0]
            .iter()
            .map(|&v| a.uv[v as usize])
            .collect::<Vec<_>>(),
    );
    assert!(
        got >= sew + strips * (1.0 - 1e-6) && got <= sew + strips * 1.2,
        "{got} vs {sew} + {strips}"
    );
}
