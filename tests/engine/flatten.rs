//! `flatten` against independent truths: exactly developable patches (cylinder and cone
//! strips, whose unrolling is computed here in closed form, and the ipc dress panels whose
//! `vt` is their own pattern), boundary lengths, virtual cutting, measures, LSCM, export.

use flatmesh::algorithms::flatten::{self, param::BoundaryAngles, Method, Params};
use flatmesh::algorithms::{self, Silent};
use flatmesh::mesh::{Mesh, RawMesh};
use flatmesh::pattern::{Patterns, Piece};
use std::f64::consts::PI;
use std::path::Path;

fn mesh_of(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
    let n = triangles.len();
    Mesh::new(RawMesh {
        positions,
        triangles,
        face_patch: vec![0; n],
        patch_names: vec!["p".into()],
        uv: None,
    })
    .expect("valid mesh")
    .0
}

/// A grid of nu × nv vertices through `f(i, j)`, two triangles per cell, CCW when f maps
/// (i, j) to a right-handed parameterization; `keep(i, j)` says whether cell (i, j) exists.
fn grid(
    nu: usize,
    nv: usize,
    f: impl Fn(usize, usize) -> [f64; 3],
    keep: impl Fn(usize, usize) -> bool,
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            pos.push(f(i, j));
        }
    }
    let id = |i: usize, j: usize| (j * nu + i) as u32;
    let mut tris = Vec::new();
    for j in 0..nv - 1 {
        for i in 0..nu - 1 {
            if !keep(i, j) {
                continue;
            }
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    // drop unreferenced vertices
    let mut used = vec![u32::MAX; pos.len()];
    let mut p2 = Vec::new();
    for t in &mut tris {
        for v in t.iter_mut() {
            if used[*v as usize] == u32::MAX {
                used[*v as usize] = p2.len() as u32;
                p2.push(pos[*v as usize]);
            }
            *v = used[*v as usize];
        }
    }
    (p2, tris)
}

/// Distances of `a`'s points to `b`'s after the best rigid motion (rotation + translation,
/// Kabsch in 2D) of `a` onto `b`.
fn rigid_fit_distances(a: &[[f64; 2]], b: &[[f64; 2]]) -> Vec<f64> {
    let n = a.len() as f64;
    let ca = a
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0] / n, s[1] + p[1] / n]);
    let cb = b
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0] / n, s[1] + p[1] / n]);
    let (mut sc, mut ss) = (0.0, 0.0);
    for (p, q) in a.iter().zip(b) {
        let (p0, p1) = (p[0] - ca[0], p[1] - ca[1]);
        let (q0, q1) = (q[0] - cb[0], q[1] - cb[1]);
        sc += p0 * q0 + p1 * q1;
        ss += p0 * q1 - p1 * q0;
    }
    let th = ss.atan2(sc);
    let (c, s) = (th.cos(), th.sin());
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            let (p0, p1) = (p[0] - ca[0], p[1] - ca[1]);
            let x = c * p0 - s * p1 + cb[0] - q[0];
            let y = s * p0 + c * p1 + cb[1] - q[1];
            (x * x + y * y).sqrt()
        })
        .collect()
}

/// Largest distance after the best rigid fit of `a` onto `b`.
fn rigid_fit_max_error(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    rigid_fit_distances(a, b).into_iter().fold(0.0, f64::max)
}

fn diameter2(p: &[[f64; 2]]) -> f64 {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for q in p {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2)).sqrt()
}

fn flatten_mesh(mesh: &Mesh, method: Method) -> Patterns {
    let params = Params {
        method,
        ..Params::default()
    };
    flatten::run(mesh, &params, &Silent::default())
        .expect("flatten")
        .patterns
        .expect("patterns")
}

/// Largest relative error of a boundary edge length, 2D against 3D, independently of the
/// measures module.
fn boundary_rel_error(mesh: &Mesh, piece: &Piece) -> f64 {
    let mut worst: f64 = 0.0;
    for lp in &piece.boundary_loops {
        for k in 0..lp.len() {
            let (i, j) = (lp[k] as usize, lp[(k + 1) % lp.len()] as usize);
            let (a, b) = (
                mesh.position(piece.vertex_ids[i]),
                mesh.position(piece.vertex_ids[j]),
            );
            let l3 = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            let (p, q) = (piece.uv[i], piece.uv[j]);
            let l2 = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
            worst = worst.max((l2 - l3).abs() / l3);
        }
    }
    worst
}

fn loop_len_2d(piece: &Piece, lp: &[u32]) -> f64 {
    (0..lp.len())
        .map(|k| {
            let (p, q) = (
                piece.uv[lp[k] as usize],
                piece.uv[lp[(k + 1) % lp.len()] as usize],
            );
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
        })
        .sum()
}

fn loop_len_3d(mesh: &Mesh, piece: &Piece, lp: &[u32]) -> f64 {
    (0..lp.len())
        .map(|k| {
            let a = mesh.position(piece.vertex_ids[lp[k] as usize]);
            let b = mesh.position(piece.vertex_ids[lp[(k + 1) % lp.len()] as usize]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .sum()
}

/// Cylinder strip of radius r over angle span `span`, height h; its true pattern puts vertex
/// (i, j) at (i · 2r sin(Δt/2), z_j): the strips between generators are planar rectangles of
/// chord width.
fn cylinder(
    nu: usize,
    nv: usize,
    span: f64,
    keep: impl Fn(usize, usize) -> bool,
) -> (Mesh, Vec<[f64; 2]>) {
    let (r, h) = (0.4, 0.9);
    let dt = span / (nu - 1) as f64;
    let z = |j: usize| h * (j as f64 / (nv - 1) as f64).powf(1.3); // uneven rows
    let (pos, tris) = grid(
        nu,
        nv,
        |i, j| {
            let t = i as f64 * dt;
            [r * t.cos(), r * t.sin(), z(j)]
        },
        keep,
    );
    let chord = 2.0 * r * (dt / 2.0).sin();
    let truth: Vec<[f64; 2]> = pos
        .iter()
        .map(|p| {
            let t = p[1].atan2(p[0]);
            let i = (t / dt).round();
            [i * chord, p[2]]
        })
        .collect();
    (mesh_of(pos, tris), truth)
}

/// Cone strip: generators g(t) = (sin β cos t, sin β sin t, cos β) at uneven angles t_i,
/// points at slant distance s_j. The quads between two generators lie in the plane through
/// the apex, so the mesh is developable; its unrolling puts generator i at the polar angle
/// ψ_i = Σ_{k<i} ∠(g_k, g_{k+1}) and the point at (s_j cos ψ_i, s_j sin ψ_i).
fn cone(nu: usize, nv: usize) -> (Mesh, Vec<[f64; 2]>) {
    let beta: f64 = 0.5;
    let t = |i: usize| 2.4 * (i as f64 / (nu - 1) as f64).powf(1.2);
    let s = |j: usize| 0.3 + 0.7 * j as f64 / (nv - 1) as f64;
    let g = |i: usize| {
        let ti = t(i);
        [beta.sin() * ti.cos(), beta.sin() * ti.sin(), beta.cos()]
    };
    let (pos, tris) = grid(nu, nv, |i, j| g(i).map(|x| x * s(j)), |_, _| true);
    let mut psi = vec![0.0];
    for i in 0..nu - 1 {
        let (a, b) = (g(i), g(i + 1));
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let ang = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            .sqrt()
            .atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
        psi.push(psi[i] + ang);
    }
    // grid() renumbered vertices by first use; map back through positions
    let truth_of = |p: [f64; 3]| -> [f64; 2] {
        let sj = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let ti = p[1].atan2(p[0]);
        let i = (0..nu)
            .min_by(|&a, &b| (t(a) - ti).abs().partial_cmp(&(t(b) - ti).abs()).unwrap())
            .unwrap();
        // (ψ, s) is a left-handed chart here (grid cells run +ψ then +s), so the unrolling
        // that keeps the triangles counter-clockwise is the mirror image
        [sj * psi[i].cos(), -sj * psi[i].sin()]
    };
    let truth: Vec<[f64; 2]> = pos.iter().map(|&p| truth_of(p)).collect();
    (mesh_of(pos, tris), truth)
}

fn check_exact(mesh: &Mesh, truth: &[[f64; 2]], label: &str) {
    let pat = flatten_mesh(mesh, Method::Lpfb);
    assert_eq!(pat.pieces.len(), 1);
    let piece = &pat.pieces[0];
    let ours: Vec<[f64; 2]> = piece.uv.clone();
    let want: Vec<[f64; 2]> = piece
        .vertex_ids
        .iter()
        .map(|&v| truth[v as usize])
        .collect();
    let err = rigid_fit_max_error(&ours, &want) / diameter2(&want);
    let bl = boundary_rel_error(mesh, piece);
    println!(
        "{label}: max vertex error / diameter = {err:.3e}, boundary length rel error = {bl:.3e}"
    );
    assert!(err <= 1e-6, "{label}: error {err}");
    assert!(bl <= 1e-9, "{label}: boundary {bl}");
    assert_eq!(piece.measures["flipped_triangles"], 0);
    assert_eq!(piece.measures["overlap"], 0);
}

#[test]
fn cylinder_strip_matches_its_unrolling() {
    let (mesh, truth) = cylinder(40, 25, 2.0, |_, _| true);
    check_exact(&mesh, &truth, "cylinder");
}

#[test]
fn cone_strip_matches_its_unrolling() {
    let (mesh, truth) = cone(36, 20);
    check_exact(&mesh, &truth, "cone");
}

fn shared(rel: &str) -> Option<Mesh> {
    let path = flatmesh::corpus::shared_mesh_for_tests(rel)?;
    Some(flatmesh::io::load_path(&path).expect("load").0)
}

/// The 2D truth of each 3D vertex through the file's `vt` (face corners).
fn uv_truth(mesh: &Mesh) -> Vec<Option<[f64; 2]>> {
    let uv = mesh.uv().expect("vt");
    let mut out = vec![None; mesh.num_vertices()];
    for (t, ut) in mesh.triangles().iter().zip(&uv.triangles) {
        for k in 0..3 {
            out[t[k] as usize] = Some(uv.coords[ut[k] as usize]);
        }
    }
    out
}

/// Truth of a piece's vertices, mirrored when the truth's triangles run clockwise (a file's
/// `vt` may be a mirror image; a pattern cut from the other side of the cloth is the same).
fn piece_truth(piece: &Piece, truth: &[Option<[f64; 2]>]) -> Vec<[f64; 2]> {
    let mut want: Vec<[f64; 2]> = piece
        .vertex_ids
        .iter()
        .map(|&v| truth[v as usize].expect("uv for every vertex"))
        .collect();
    let signed: f64 = piece
        .triangles
        .iter()
        .map(|t| {
            let (a, b, c) = (
                want[t[0] as usize],
                want[t[1] as usize],
                want[t[2] as usize],
            );
            (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        })
        .sum();
    if signed < 0.0 {
        want.iter_mut().for_each(|q| q[1] = -q[1]);
    }
    want
}

/// In-plane coordinates of a (planar) piece's 3D vertices.
fn in_plane(mesh: &Mesh, piece: &Piece) -> Vec<[f64; 2]> {
    let mut n = [0.0; 3];
    for &f in &piece.faces {
        let [a, b, c] = mesh.face_positions(f as usize);
        let (u, v) = (
            [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
            [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
        );
        n[0] += u[1] * v[2] - u[2] * v[1];
        n[1] += u[2] * v[0] - u[0] * v[2];
        n[2] += u[0] * v[1] - u[1] * v[0];
    }
    let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = n.map(|x| x / nn);
    let lp = &piece.boundary_loops[0];
    let (a, b) = (
        mesh.position(piece.vertex_ids[lp[0] as usize]),
        mesh.position(piece.vertex_ids[lp[1] as usize]),
    );
    let mut e = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let d = e[0] * n[0] + e[1] * n[1] + e[2] * n[2];
    e = [e[0] - d * n[0], e[1] - d * n[1], e[2] - d * n[2]];
    let el = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    let e = e.map(|x| x / el);
    let f = [
        n[1] * e[2] - n[2] * e[1],
        n[2] * e[0] - n[0] * e[2],
        n[0] * e[1] - n[1] * e[0],
    ];
    piece
        .vertex_ids
        .iter()
        .map(|&v| {
            let p = mesh.position(v);
            [
                p[0] * e[0] + p[1] * e[1] + p[2] * e[2],
                p[0] * f[0] + p[1] * f[1] + p[2] * f[2],
            ]
        })
        .collect()
}

#[test]
fn ipc_dress_panels_match_their_vt_pattern() {
    let Some(mesh) = shared("garment/ipc_dress_knife_stage.obj") else {
        return;
    };
    let truth = uv_truth(&mesh);
    let pat = flatten_mesh(&mesh, Method::Lpfb);
    assert_eq!(pat.pieces.len(), 14);
    let mut worst: f64 = 0.0;
    let mut worst_bl: f64 = 0.0;
    for piece in &pat.pieces {
        let want = piece_truth(piece, &truth);
        let diam = diameter2(&want);
        let err = rigid_fit_max_error(&piece.uv, &want) / diam;
        // The file prints 7 significant digits: each vt coordinate is off by up to half a unit
        // in the last place, 5e-7 · |value|; the fit can add as much again.
        let quantum = 5e-7
            * want
                .iter()
                .flat_map(|q| [q[0].abs(), q[1].abs()])
                .fold(0.0, f64::max);
        // Second truth, free of vt rounding: the panel is planar in 3D, so its in-plane
        // coordinates (area-weighted normal, frame from the first boundary edge) are its pattern.
        let plane = in_plane(&mesh, piece);
        let err_plane = rigid_fit_max_error(&piece.uv, &plane) / diam;
        let bl = boundary_rel_error(&mesh, piece);
        println!(
            "{}: diameter {diam:.4}; vs vt max error/diam {err:.3e} (vt quantum/diam {:.1e}); \
             vs 3D plane {err_plane:.3e}; boundary rel {bl:.3e}",
            piece.patch,
            quantum / diam
        );
        assert!(err_plane <= 1e-6, "{}: {err_plane}", piece.patch);
        assert!(err <= 1e-6 + 4.0 * quantum / diam, "{}: {err}", piece.patch);
        assert!(bl <= 1e-9, "{}: {bl}", piece.patch);
        worst = worst.max(err);
        worst_bl = worst_bl.max(bl);
    }
    println!("ipc dress: worst {worst:.3e}, worst boundary {worst_bl:.3e}");
    // the drawing places the 14 pieces without overlap (bounding boxes pairwise disjoint)
    let (off, w, h) = flatmesh::io::pattern::layout(&pat);
    let s = flatmesh::io::pattern::scale(&pat);
    assert_eq!(s, 1000.0);
    let boxes: Vec<([f64; 2], [f64; 2])> = pat
        .pieces
        .iter()
        .zip(&off)
        .map(|(p, o)| {
            let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
            for q in &p.uv {
                for k in 0..2 {
                    lo[k] = lo[k].min(q[k] * s + o[k]);
                    hi[k] = hi[k].max(q[k] * s + o[k]);
                }
            }
            (lo, hi)
        })
        .collect();
    for (i, a) in boxes.iter().enumerate() {
        assert!(a.0[0] >= 0.0 && a.0[1] >= 0.0 && a.1[0] <= w && a.1[1] <= h);
        for b in &boxes[i + 1..] {
            assert!(a.1[0] < b.0[0] || b.1[0] < a.0[0] || a.1[1] < b.0[1] || b.1[1] < a.0[1]);
        }
    }
}

/// mh_classicshoes_medium, whose panels are unwelded (most of its boundary edges have a twin
/// joining the same two positions): every such pair, found here from positions alone, is
/// one edge on one side of a seam and its twin on the other, and the seams between pieces
/// keep their length on both.
#[test]
fn an_unwelded_shoe_is_sewn_between_its_pieces() {
    let Some(mesh) = shared("shoe/mh_classicshoes_medium.obj") else {
        return;
    };
    let key = |v: u32| mesh.position(v).map(f64::to_bits);
    let mut count: std::collections::HashMap<Vec<[u64; 3]>, Vec<[u32; 2]>> =
        std::collections::HashMap::new();
    let mut uses: std::collections::HashMap<[u32; 2], usize> = std::collections::HashMap::new();
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
            *uses.entry([a, b]).or_default() += 1;
        }
    }
    for (&[a, b], &n) in &uses {
        if n == 1 {
            let mut k = vec![key(a), key(b)];
            k.sort_unstable();
            count.entry(k).or_default().push([a, b]);
        }
    }
    let twins: Vec<[[u32; 2]; 2]> = count
        .into_values()
        .filter(|es| es.len() == 2)
        .map(|es| [es[0], es[1]])
        .collect();
    assert!(twins.len() >= 200, "{} twin pairs", twins.len());
    let pat = flatten_mesh(&mesh, Method::Lpfb);
    // (seam, side) → its edges as sorted pairs of mesh vertices
    let mut sides: Vec<[std::collections::HashSet<[u32; 2]>; 2]> = Vec::new();
    for s in &pat.seams {
        sides.push([0, 1].map(|k| {
            let piece = &pat.pieces[s.pieces[k]];
            s.edges[k]
                .iter()
                .map(|e| {
                    let [a, b] = e.map(|v| piece.vertex_ids[v as usize]);
                    [a.min(b), a.max(b)]
                })
                .collect()
        }));
    }
    for [e, f] in &twins {
        assert!(
            sides
                .iter()
                .any(|[x, y]| (x.contains(e) && y.contains(f)) || (x.contains(f) && y.contains(e))),
            "boundary edges {e:?} and {f:?} meet but are on no seam's two sides"
        );
    }
    let between: Vec<_> = pat
        .seams
        .iter()
        .filter(|s| s.pieces[0] != s.pieces[1])
        .collect();
    assert!(between.len() >= 6, "{} seams between pieces", between.len());
    for s in between {
        for l in s.lengths {
            assert!(
                (l - s.length_3d).abs() <= 1e-9 * s.length_3d,
                "{l} against {}",
                s.length_3d
            );
        }
    }
}

#[test]
fn gf_skirt_against_its_flat_pattern() {
    let (Some(m3), Some(m2)) = (
        shared("garment/gf_skirt_3D_0.obj"),
        shared("garment/gf_skirt_UV_0.obj"),
    ) else {
        return;
    };
    assert_eq!(m3.num_vertices(), m2.num_vertices());
    for method in [Method::Lpfb, Method::Lscm] {
        let pat = flatten_mesh(&m3, method);
        let piece = &pat.pieces[0];
        let truth: Vec<Option<[f64; 2]>> = (0..m2.num_vertices() as u32)
            .map(|v| {
                let p = m2.position(v);
                Some([p[0], p[1]])
            })
            .collect();
        let want = piece_truth(piece, &truth);
        // Kabsch fit, then RMS and max of the residual
        let err_max = rigid_fit_max_error(&piece.uv, &want);
        let diam = diameter2(&want);
        let rms = rigid_fit_rms(&piece.uv, &want);
        println!(
            "gf_skirt {method:?}: RMS {rms:.4} max {err_max:.4} (diameter {diam:.2}; RMS/diam {:.3e}); \
             A {:.3}% L2 {:.4}",
            rms / diam,
            piece.measures["area_distortion_pct"].as_f64().unwrap(),
            piece.measures["l2_stretch"].as_f64().unwrap()
        );
        // sanity: the 3D panel is not developable, but the patterns agree to a few percent
        assert!(rms / diam < 0.05, "{method:?}: RMS {rms}");
        if method == Method::Lpfb {
            assert!(boundary_rel_error(&m3, piece) <= 1e-9);
        }
    }
}

/// Root-mean-square distance after the best rigid fit of `a` onto `b`.
fn rigid_fit_rms(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    let d = rigid_fit_distances(a, b);
    (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt()
}

/// A cylinder strip with two rectangular holes (χ = −1, three loops): developable, so its
/// pattern is known, and the virtual cut must keep every loop's length.
#[test]
fn two_holes_keep_every_loop_and_cut_copies_coincide() {
    let hole = |i: usize, j: usize| {
        !((8..13).contains(&i) && (6..11).contains(&j)
            || (24..30).contains(&i) && (12..17).contains(&j))
    };
    let (mesh, truth) = cylinder(40, 25, 2.0, hole);
    let out = flatten::run(&mesh, &Params::default(), &Silent::default()).unwrap();
    let pat = out.patterns.unwrap();
    let piece = &pat.pieces[0];
    assert_eq!(piece.boundary_loops.len(), 3);
    for lp in &piece.boundary_loops {
        let (l2, l3) = (loop_len_2d(piece, lp), loop_len_3d(&mesh, piece, lp));
        assert!((l2 - l3).abs() / l3 <= 1e-9, "loop {l2} vs {l3}");
    }
    let bl = boundary_rel_error(&mesh, piece);
    assert!(bl <= 1e-9, "{bl}");
    let solver = &out.summary.pieces[0].solver;
    let coincide = solver.cut_coincidence;
    assert_eq!(solver.cut_paths, 2);
    assert!(coincide <= 1e-9, "cut copies apart by {coincide}");
    let want: Vec<[f64; 2]> = piece
        .vertex_ids
        .iter()
        .map(|&v| truth[v as usize])
        .collect();
    let err = rigid_fit_max_error(&piece.uv, &want) / diameter2(&want);
    println!(
        "two holes (developable): error {err:.3e}, boundary {bl:.3e}, coincidence {coincide:.3e}"
    );
    assert!(err <= 1e-6, "{err}");
    // outer loop counter-clockwise, holes clockwise (surface on the left)
    let area = |lp: &Vec<u32>| -> f64 {
        (0..lp.len())
            .map(|k| {
                let (p, q) = (
                    piece.uv[lp[k] as usize],
                    piece.uv[lp[(k + 1) % lp.len()] as usize],
                );
                p[0] * q[1] - q[0] * p[1]
            })
            .sum::<f64>()
            / 2.0
    };
    assert!(area(&piece.boundary_loops[0]) > 0.0);
    assert!(piece.boundary_loops[1..].iter().all(|l| area(l) < 0.0));
}

/// A spherical cap with two holes: not developable, so LPFB has work to do (λ ≠ 0), and the
/// cut copies must still coincide and every loop keep its length.
#[test]
fn curved_patch_with_two_holes() {
    let (nu, nv) = (40, 40);
    let hole = |i: usize, j: usize| {
        !((8..14).contains(&i) && (8..14).contains(&j)
            || (24..31).contains(&i) && (20..27).contains(&j))
    };
    let (pos, tris) = grid(
        nu,
        nv,
        |i, j| {
            let (x, y) = (
                i as f64 / (nu - 1) as f64 - 0.5,
                j as f64 / (nv - 1) as f64 - 0.5,
            );
            let r = 0.9;
            [x, y, (r * r - x * x - y * y).sqrt()]
        },
        hole,
    );
    let mesh = mesh_of(pos, tris);
    // by default the holes, which enclose curvature, are cut open to the rim
    let auto = flatten::run(&mesh, &Params::default(), &Silent::default()).unwrap();
    let k = &auto.summary.pieces[0].solver.enclosed_curvature;
    println!("curved two holes: enclosed curvature {k:?}");
    assert_eq!(auto.patterns.unwrap().pieces[0].boundary_loops.len(), 1);
    let params = Params {
        cuts: flatten::cut::Cuts::Virtual,
        ..Params::default()
    };
    let out = flatten::run(&mesh, &params, &Silent::default()).unwrap();
    let pat = out.patterns.unwrap();
    let piece = &pat.pieces[0];
    assert_eq!(piece.boundary_loops.len(), 3);
    for lp in &piece.boundary_loops {
        let (l2, l3) = (loop_len_2d(piece, lp), loop_len_3d(&mesh, piece, lp));
        assert!((l2 - l3).abs() / l3 <= 1e-9, "loop {l2} vs {l3}");
    }
    let bl = boundary_rel_error(&mesh, piece);
    let solver = &out.summary.pieces[0].solver;
    let coincide = solver.cut_coincidence;
    println!("curved two holes: boundary {bl:.3e}, coincidence {coincide:.3e}, solver {solver:?}");
    assert!(bl <= 1e-9);
    assert!(coincide <= 1e-9);
    assert!(solver.converged);
    assert_eq!(piece.measures["overlap"], 0);
}

/// A polar grid (20 rings of 64) through `f(ρ, t)`, ρ ∈ [0, 1] from the centre, t the angle.
fn polar_mesh(f: impl Fn(f64, f64) -> [f64; 3]) -> Mesh {
    let (nr, nt) = (20usize, 64usize);
    let mut pos = vec![f(0.0, 0.0)];
    for i in 1..=nr {
        for k in 0..nt {
            pos.push(f(i as f64 / nr as f64, 2.0 * PI * k as f64 / nt as f64));
        }
    }
    let id = |i: usize, k: usize| (1 + (i - 1) * nt + k % nt) as u32;
    let mut tris = Vec::new();
    for k in 0..nt {
        tris.push([0, id(1, k), id(1, k + 1)]);
    }
    for i in 1..nr {
        for k in 0..nt {
            tris.push([id(i, k), id(i + 1, k), id(i + 1, k + 1)]);
            tris.push([id(i, k), id(i + 1, k + 1), id(i, k + 1)]);
        }
    }
    mesh_of(pos, tris)
}

/// Spherical cap to `deg` degrees from the pole.
fn sphere_cap(deg: f64) -> Mesh {
    polar_mesh(|rho, t| {
        let phi = deg.to_radians() * rho;
        [phi.sin() * t.cos(), phi.sin() * t.sin(), phi.cos()]
    })
}

/// A piece that cannot lie flat (a whole T-shirt body as one patch, χ = −2) is still
/// flattened, but the job says so in words; a piece that can lie flat gets no such warning.
/// With the defaults the T-shirt lies without a flip (the paper as written, surface angles
/// and harmonic interior, gives 5), so the warning is about its distortion. A pattern smaller
/// than its surface is warned about as well as a larger one: a 60° spherical cap laid out
/// from its boundary's lengths has the area of the flat disk of that perimeter, π sin²60° R²
/// against the cap's π R² (−25 %), and the pouch (a sphere with a small opening, like a
/// closed-toe sock) far less.
#[test]
fn unflattenable_piece_is_named_in_a_warning() {
    for (label, mesh, bound) in [
        ("cap", sphere_cap(60.0), 100.0 * (0.75 - 1.0)),
        ("pouch", flatmesh::corpus::pouch(24), -80.0),
    ] {
        let out = flatten::run(&mesh, &Params::default(), &Silent::default()).unwrap();
        let piece = &out.patterns.as_ref().unwrap().pieces[0];
        assert_eq!(piece.measures["flipped_triangles"], 0, "{label}");
        let a = piece.measures["area_distortion_pct"].as_f64().unwrap();
        assert!(a < 0.9 * bound, "{label}: area distortion {a} %");
        let ws = &out.summary.job_warnings;
        assert_eq!(ws.len(), 1, "{label}: {ws:?}");
        assert!(
            ws[0].contains("not developable") && ws[0].contains(&format!("{a:+.1} %")),
            "{label}: {}",
            ws[0]
        );
    }
    let Some(shirt) = shared("garment/diffavatar_tshirt.obj") else {
        return;
    };
    let out = flatten::run(&shirt, &Params::default(), &Silent::default()).unwrap();
    let piece = &out.patterns.as_ref().unwrap().pieces[0];
    let flips = piece.measures["flipped_triangles"].as_u64().unwrap();
    let ws = &out.summary.job_warnings;
    println!("t-shirt: {flips} flips, warnings {ws:?}");
    assert_eq!(flips, 0);
    assert_eq!(ws.len(), 1);
    let w = &ws[0];
    assert!(w.contains(&format!("piece `{}`", piece.patch)) && w.contains("not developable"));
    assert!(w.contains("area distortion") && w.contains("ϖ_max"));
    let paper = Params {
        boundary_angles: BoundaryAngles::Surface,
        interior: flatten::param::Interior::Harmonic,
        ..Params::default()
    };
    let out = flatten::run(&shirt, &paper, &Silent::default()).unwrap();
    let piece = &out.patterns.as_ref().unwrap().pieces[0];
    assert!(piece.measures["flipped_triangles"].as_u64().unwrap() > 0);
    let w = &out.summary.job_warnings[0];
    assert!(w.contains(&format!("piece `{}`", piece.patch)) && w.contains("flipped"));
}

#[test]
fn hemisphere_has_no_flip_and_no_overlap_lpfb_beside_lscm() {
    let mut meshes = vec![("procedural cap".to_string(), sphere_cap(75.0))];
    meshes.push((
        "fixture hemisphere_cap".into(),
        flatmesh::io::load_path(Path::new("fixtures/hemisphere_cap.obj"))
            .unwrap()
            .0,
    ));
    if let Some(m) = shared("paper/bff_hemisphere.obj") {
        meshes.push(("bff_hemisphere".into(), m));
    }
    for (name, mesh) in &meshes {
        let lp = flatten_mesh(mesh, Method::Lpfb);
        let ls = flatten_mesh(mesh, Method::Lscm);
        let (a, b) = (&lp.pieces[0], &ls.pieces[0]);
        let f = |p: &Piece, k: &str| p.measures[k].as_f64().unwrap();
        println!(
            "{name}: LPFB A(Ω) {:.3}% L² {:.4} L∞ {:.3} flips {} S {} | LSCM A(Ω) {:.3}% L² {:.4} L∞ {:.3} flips {} S {}",
            f(a, "area_distortion_pct"), f(a, "l2_stretch"), f(a, "linf_stretch"), a.measures["flipped_triangles"], a.measures["overlap"],
            f(b, "area_distortion_pct"), f(b, "l2_stretch"), f(b, "linf_stretch"), b.measures["flipped_triangles"], b.measures["overlap"]
        );
        assert_eq!(a.measures["flipped_triangles"], 0, "{name}");
        assert_eq!(a.measures["overlap"], 0, "{name}");
        assert!(boundary_rel_error(mesh, a) <= 1e-9);
        // independent recomputation of the flip count and of Eq. 19
        let (mut a2, mut a3, mut flips) = (0.0, 0.0, 0);
        for (t, &gf) in a.triangles.iter().zip(&a.faces) {
            let (p, q, r) = (
                a.uv[t[0] as usize],
                a.uv[t[1] as usize],
                a.uv[t[2] as usize],
            );
            let s = ((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])) / 2.0;
            flips += (s <= 0.0) as usize;
            a2 += s;
            let [x, y, z] = mesh.face_positions(gf as usize);
            let (u, v) = (
                [y[0] - x[0], y[1] - x[1], y[2] - x[2]],
                [z[0] - x[0], z[1] - x[1], z[2] - x[2]],
            );
            let c = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            a3 += (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() / 2.0;
        }
        assert_eq!(flips, 0);
        let eq19 = (a2 - a3) / a3 * 100.0;
        assert!((eq19 - f(a, "area_distortion_pct")).abs() < 1e-9 * eq19.abs().max(1.0));
        // L² is bounded below by 1 (Sander)
        assert!(f(a, "l2_stretch") >= 1.0 - 1e-12 && f(b, "l2_stretch") >= 1.0 - 1e-12);
    }
}

/// The cylinder strip split into two patches along the generator i = 20: one seam whose 3D
/// length is the strip's height, 0.9, exactly.
fn two_patch_cylinder() -> Mesh {
    let (mesh, _) = cylinder(40, 25, 2.0, |_, _| true);
    let mut raw = mesh.to_raw();
    let dt = 2.0 / 39.0;
    raw.face_patch = raw
        .triangles
        .iter()
        .map(|t| {
            let c: f64 = t
                .iter()
                .map(|&v| {
                    let p = raw.positions[v as usize];
                    p[1].atan2(p[0]) / dt
                })
                .sum::<f64>()
                / 3.0;
            (c > 20.0) as u32
        })
        .collect();
    raw.patch_names = vec!["left panel".into(), "right/panel".into()];
    Mesh::new(raw).unwrap().0
}

#[test]
fn seams_keep_their_length_on_both_pieces() {
    let mesh = two_patch_cylinder();
    for method in [Method::Lpfb, Method::Lscm] {
        let pat = flatten_mesh(&mesh, method);
        assert_eq!(pat.pieces.len(), 2);
        assert_eq!(pat.seams.len(), 1);
        let s = &pat.seams[0];
        assert!((s.length_3d - 0.9).abs() < 1e-12, "{}", s.length_3d);
        assert_eq!(
            s.patches,
            ["left panel".to_string(), "right/panel".to_string()]
        );
        assert_eq!(s.edges[0].len(), 24);
        assert_eq!(s.edges[1].len(), 24);
        println!(
            "{method:?}: seam 3D {} on pieces {:?}",
            s.length_3d, s.lengths
        );
        if method == Method::Lpfb {
            for l in s.lengths {
                assert!((l - 0.9).abs() / 0.9 <= 1e-9, "{l}");
            }
        }
    }
}

/// `mesh` with the faces that `side` picks given their own copies of the vertices that
/// `along` picks: the edges between them open into boundary edges at the same positions, as
/// in a file exported with its panels unwelded or a slit opened by copies.
fn unweld(mesh: &Mesh, side: impl Fn([f64; 3]) -> bool, along: impl Fn([f64; 3]) -> bool) -> Mesh {
    let mut raw = mesh.to_raw();
    let mut copy: std::collections::HashMap<u32, u32> = std::collections::HashMap::new();
    for t in 0..raw.triangles.len() {
        let c = raw.triangles[t]
            .iter()
            .map(|&v| raw.positions[v as usize])
            .fold([0.0; 3], |a, p| {
                [a[0] + p[0] / 3.0, a[1] + p[1] / 3.0, a[2] + p[2] / 3.0]
            });
        if !side(c) {
            continue;
        }
        for k in 0..3 {
            let v = raw.triangles[t][k];
            if along(raw.positions[v as usize]) {
                let n = raw.positions.len() as u32;
                let w = *copy.entry(v).or_insert(n);
                if w == n {
                    let p = raw.positions[v as usize];
                    raw.positions.push(p);
                }
                raw.triangles[t][k] = w;
            }
        }
    }
    assert!(!copy.is_empty(), "nothing unwelded");
    Mesh::new(raw).unwrap().0
}

/// The two-patch cylinder with its panels unwelded along the seam: the seam is found by
/// position and is the welded one's (3D length 0.9, 24 edges a side, lengths kept).
#[test]
fn unwelded_panels_are_sewn_where_their_edges_meet() {
    let welded = two_patch_cylinder();
    let dt = 2.0 / 39.0;
    let angle = |p: [f64; 3]| p[1].atan2(p[0]) / dt;
    let mesh = unweld(
        &welded,
        |c| angle(c) > 20.0,
        |p| (angle(p) - 20.0).abs() < 1e-6,
    );
    assert_eq!(mesh.num_vertices(), welded.num_vertices() + 25);
    let (a, b) = (
        flatten_mesh(&welded, Method::Lpfb),
        flatten_mesh(&mesh, Method::Lpfb),
    );
    assert_eq!(b.pieces.len(), 2);
    assert_eq!(b.seams.len(), 1, "{:?}", b.seams);
    let (s, w) = (&b.seams[0], &a.seams[0]);
    assert_eq!(s.patches, w.patches);
    assert!((s.length_3d - 0.9).abs() < 1e-12, "{}", s.length_3d);
    assert_eq!([s.edges[0].len(), s.edges[1].len()], [24, 24]);
    for l in s.lengths {
        assert!((l - 0.9).abs() / 0.9 <= 1e-9, "{l}");
    }
    // One piece: the panels, unwelded and in one patch, are two components sewn together.
    let mut raw = mesh.to_raw();
    raw.face_patch = vec![0; raw.triangles.len()];
    raw.patch_names = vec!["panels".into()];
    let one = flatten_mesh(&Mesh::new(raw).unwrap().0, Method::Lpfb);
    assert_eq!(one.pieces.len(), 2);
    assert_eq!(one.seams.len(), 1);
    assert_eq!(one.seams[0].pieces, [0, 1]);
}

/// A dart: the cylinder strip slit from its bottom edge halfway up generator 20, the slit
/// opened by copies. It is a seam of the piece with itself, one side each of the slit, as
/// long in 3D as the generator's first 12 rows, and as long on both sides.
#[test]
fn a_slit_opened_by_copies_is_a_seam_of_its_piece() {
    let (strip, _) = cylinder(40, 25, 2.0, |_, _| true);
    let dt = 2.0 / 39.0;
    let angle = |p: [f64; 3]| p[1].atan2(p[0]) / dt;
    let tip = 0.9 * (12.0f64 / 24.0).powf(1.3);
    let mesh = unweld(
        &strip,
        |c| angle(c) > 20.0 && c[2] < tip,
        |p| (angle(p) - 20.0).abs() < 1e-6 && p[2] < tip - 1e-9,
    );
    assert_eq!(mesh.num_vertices(), strip.num_vertices() + 12);
    let pat = flatten_mesh(&mesh, Method::Lpfb);
    assert_eq!(pat.pieces.len(), 1);
    assert_eq!(pat.seams.len(), 1, "{:?}", pat.seams);
    let s = &pat.seams[0];
    assert_eq!(s.pieces, [0, 0]);
    assert!(
        (s.length_3d - tip).abs() < 1e-12,
        "{} against {tip}",
        s.length_3d
    );
    assert_eq!([s.edges[0].len(), s.edges[1].len()], [12, 12]);
    // The sides are the slit's two boundaries on the piece: no piece vertex is on both.
    let ends = |k: usize| -> std::collections::HashSet<u32> {
        s.edges[k].iter().flatten().copied().collect()
    };
    assert_eq!(
        ends(0).intersection(&ends(1)).count(),
        1,
        "only the tip is shared"
    );
    for l in s.lengths {
        assert!((l - tip).abs() / tip <= 1e-9, "{l} against {tip}");
    }
}

#[test]
fn exports_read_back() {
    use flatmesh::io::pattern;
    let mesh = two_patch_cylinder();
    let pat = flatten_mesh(&mesh, Method::Lpfb);
    // JSON round trip
    let back: Patterns = serde_json::from_str(&pattern::to_json(&pat)).unwrap();
    assert_eq!(back.pieces.len(), 2);
    for (a, b) in pat.pieces.iter().zip(&back.pieces) {
        assert_eq!(a.vertex_ids, b.vertex_ids);
        assert_eq!(a.triangles, b.triangles);
        assert_eq!(a.boundary_loops, b.boundary_loops);
        for (p, q) in a.uv.iter().zip(&b.uv) {
            assert!((p[0] - q[0]).abs() <= 1e-15 && (p[1] - q[1]).abs() <= 1e-15);
        }
    }
    // DXF: outlines come back on their own layers, in mm (input in m), placed as `layout` says
    let dxf = pattern::to_dxf_plain(&pat);
    let polys = pattern::read_dxf_polylines(&dxf).unwrap();
    assert_eq!(polys.len(), 2);
    let (off, _, _) = pattern::layout(&pat);
    let mut boxes = Vec::new();
    for (i, piece) in pat.pieces.iter().enumerate() {
        let pl = &polys[i];
        assert_eq!(pl.layer, pattern::layer_name(i, &piece.patch));
        assert!(pl.closed);
        let lp = &piece.boundary_loops[0];
        assert_eq!(pl.points.len(), lp.len());
        for (k, &v) in lp.iter().enumerate() {
            let q = piece.uv[v as usize];
            let want = [q[0] * 1000.0 + off[i][0], q[1] * 1000.0 + off[i][1]];
            let got = pl.points[k];
            assert!((got[0] - want[0]).abs() <= 1e-9 * want[0].abs().max(1.0));
            assert!((got[1] - want[1]).abs() <= 1e-9 * want[1].abs().max(1.0));
        }
        // perimeter in mm against the 3D perimeter in m
        let per: f64 = (0..pl.points.len())
            .map(|k| {
                let (a, b) = (pl.points[k], pl.points[(k + 1) % pl.points.len()]);
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
            })
            .sum();
        let per3 = loop_len_3d(&mesh, piece, lp) * 1000.0;
        assert!((per - per3).abs() / per3 < 1e-9, "{per} vs {per3}");
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in &pl.points {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        boxes.push((lo, hi));
    }
    let (a, b) = (boxes[0], boxes[1]);
    let disjoint = a.1[0] < b.0[0] || b.1[0] < a.0[0] || a.1[1] < b.0[1] || b.1[1] < a.0[1];
    assert!(disjoint, "pieces overlap in the drawing: {boxes:?}");
    // SVG: real size in mm, one group per piece, seam labels on both pieces
    let svg = pattern::to_svg(&pat);
    assert!(svg.contains(r#"width=""#) && svg.contains(r#"mm" height=""#));
    assert_eq!(svg.matches("<g id=\"piece-").count(), 2);
    assert_eq!(svg.matches(">S0</text>").count(), 2);
    assert!(!svg.contains("NaN"));
}

#[test]
fn params_are_checked() {
    let bad = |json: &str| {
        let m: serde_json::Map<String, serde_json::Value> = serde_json::from_str(json).unwrap();
        flatmesh::jobs::JobSpec::parse("flatten", &m).map_err(|e| match e {
            flatmesh::jobs::SpecError::Params(a) => a,
            other => panic!("{other}"),
        })
    };
    assert!(bad(r#"{}"#).is_ok());
    assert!(bad(r#"{"method": "lscm", "unit": "in", "input_unit": "cm"}"#).is_ok());
    assert!(
        matches!(bad(r#"{"methd": "lscm"}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "methd")
    );
    // a bad value names its key even when other keys are fine
    assert!(
        matches!(bad(r#"{"unit": "cm", "method": "abf"}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "method")
    );
    assert!(
        matches!(bad(r#"{"unit": "ft"}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "unit")
    );
    assert!(
        matches!(bad(r#"{"max_iterations": "many"}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "max_iterations")
    );
    assert!(
        matches!(bad(r#"{"tolerance": 0}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "tolerance")
    );
    assert!(
        matches!(bad(r#"{"max_iterations": 0}"#), Err(algorithms::AlgoError::InvalidParam { key, .. }) if key == "max_iterations")
    );
}

#[test]
fn cancellation_is_honoured() {
    let (mesh, _) = cylinder(20, 10, 2.0, |_, _| true);
    let c = Silent::default();
    c.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    assert_eq!(
        flatten::run(&mesh, &Params::default(), &c).unwrap_err(),
        algorithms::AlgoError::Cancelled
    );
}

#[test]
fn cli_writes_patterns() {
    let dir = std::env::temp_dir().join(format!("flatmesh-flatten-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("two.obj");
    std::fs::write(
        &obj,
        flatmesh::io::obj::write(&two_patch_cylinder().to_raw()),
    )
    .unwrap();
    let out = dir.join("out");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["run", "flatten"])
        .arg(&obj)
        .arg("--out")
        .arg(&out)
        .args(["--set", "method=lscm", "--set", "unit=cm"])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for f in [
        "patterns.json",
        "patterns.svg",
        "patterns.dxf",
        "report.json",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let rep: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(rep["job"]["method"], "lscm");
    assert_eq!(rep["job"]["pieces"].as_array().unwrap().len(), 2);
    assert_eq!(rep["job"]["seams"].as_array().unwrap().len(), 1);
    assert!(rep["job"]["timings"]["total_s"].as_f64().unwrap() >= 0.0);
    let svg = std::fs::read_to_string(out.join("patterns.svg")).unwrap();
    assert!(svg.contains(r#"cm" height=""#));
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["run", "flatten"])
        .arg(&obj)
        .arg("--out")
        .arg(&out)
        .args(["--set", "method=magic"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A flat 3D grid mapped by the linear map diag(1.1, 0.9): σ1 = 1.1 and σ2 = 0.9 on every
/// face, so stretch 10 %, compression 10 %, A(Ω) = (0.99 − 1) · 100 %, Sander
/// L² = √((1/0.9² + 1/1.1²)/2), L∞ = 1/0.9.
#[test]
fn measures_of_a_known_linear_map() {
    use flatten::measures;
    let (pos, tris) = grid(
        6,
        5,
        |i, j| [i as f64 * 0.2, j as f64 * 0.25, 0.0],
        |_, _| true,
    );
    let mesh = mesh_of(pos.clone(), tris.clone());
    let uv: Vec<[f64; 2]> = pos.iter().map(|p| [1.1 * p[0], 0.9 * p[1]]).collect();
    let loops = mesh.conn().boundary_loops().to_vec();
    let ids: Vec<u32> = (0..pos.len() as u32).collect();
    let m = measures::compute(&pos, &uv, &tris, &loops, &ids);
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12 * b.abs().max(1.0);
    assert!(
        close(m.stretch_max_pct, 10.0) && close(m.stretch_mean_pct, 10.0),
        "{m:?}"
    );
    assert!(close(m.compression_max_pct, 10.0) && close(m.compression_mean_pct, 10.0));
    assert!(close(m.area_distortion_pct, -1.0));
    assert!(close(
        m.l2_stretch,
        ((1.0 / 0.81 + 1.0 / 1.21) / 2.0f64).sqrt()
    ));
    assert!(close(m.linf_stretch, 1.0 / 0.9));
    assert_eq!(
        (m.flipped_triangles, m.boundary_intersections, m.overlap),
        (0, 0, 0)
    );
    // Π_θ: corners of the rectangle keep π/2, other boundary angles stay π: 0
    assert!(m.pi_theta < 1e-12);
    // Π_L: mean |l − l0| over the boundary: horizontal edges +0.02, vertical −0.025
    let (nh, nv) = (2 * 5, 2 * 4);
    let want = (nh as f64 * 0.02 + nv as f64 * 0.025) / (nh + nv) as f64;
    assert!(close(m.pi_l, want), "{} vs {want}", m.pi_l);
}

/// A helical strip (valid in 3D) laid flat as a planar annular strip of 1.25 turns: no
/// triangle is flipped, but the boundary crosses itself, so S(Ω) = 1. Reflecting the strip
/// flips every triangle.
#[test]
fn overlap_is_detected_from_boundary_crossings_and_flips() {
    use flatten::measures;
    let (nu, nv) = (80, 3);
    let ang = |i: usize| 2.5 * PI * i as f64 / (nu - 1) as f64;
    let rad = |j: usize| 1.2 - 0.1 * j as f64; // +angle then inward: counter-clockwise cells
    let (pos, tris) = grid(
        nu,
        nv,
        |i, j| [rad(j) * ang(i).cos(), rad(j) * ang(i).sin(), 0.3 * ang(i)],
        |_, _| true,
    );
    let mesh = mesh_of(pos.clone(), tris.clone());
    let uv: Vec<[f64; 2]> = pos.iter().map(|p| [p[0], p[1]]).collect();
    let loops = mesh.conn().boundary_loops().to_vec();
    let ids: Vec<u32> = (0..pos.len() as u32).collect();
    let m = measures::compute(&pos, &uv, &tris, &loops, &ids);
    assert_eq!(m.flipped_triangles, 0);
    assert!(m.boundary_intersections > 0);
    assert_eq!(m.overlap, 1);
    let mirrored: Vec<[f64; 2]> = uv.iter().map(|q| [q[0], -q[1]]).collect();
    let m2 = measures::compute(&pos, &mirrored, &tris, &loops, &ids);
    assert_eq!(m2.flipped_triangles, tris.len());
    assert_eq!(m2.overlap, 1);
}

#[test]
fn exact_orientation_decides_near_collinear_points() {
    use flatten::measures::orient2d;
    // points on the line y = x at large offsets, nudged by one ulp: f64 arithmetic would
    // round the determinant to zero or to the wrong sign
    let a = [0.5, 0.5];
    let b = [12.0, 12.0];
    for k in 0..200 {
        let x = 24.0 + k as f64;
        let up = [x, f64::from_bits(x.to_bits() + 1)];
        let down = [x, f64::from_bits(x.to_bits() - 1)];
        assert_eq!(orient2d(a, b, up), 1);
        assert_eq!(orient2d(a, b, down), -1);
        assert_eq!(orient2d(a, b, [x, x]), 0);
    }
}

/// LSCM is exact on a developable patch (a conformal map with the pins at their true
/// distance is the isometry), so the baseline is checked against the same closed-form
/// unrolling as LPFB.
#[test]
fn lscm_is_exact_on_developable_strips() {
    let (mesh, truth) = cylinder(30, 20, 2.0, |_, _| true);
    let (mesh2, truth2) = cone(30, 20);
    for (m, t, label) in [(&mesh, &truth, "cylinder"), (&mesh2, &truth2, "cone")] {
        let pat = flatten_mesh(m, Method::Lscm);
        let piece = &pat.pieces[0];
        let want: Vec<[f64; 2]> = piece.vertex_ids.iter().map(|&v| t[v as usize]).collect();
        let err = rigid_fit_max_error(&piece.uv, &want) / diameter2(&want);
        println!("LSCM {label}: max error / diameter {err:.3e}");
        assert!(err <= 1e-6, "{label}: {err}");
        assert_eq!(piece.measures["flipped_triangles"], 0);
    }
}

#[test]
fn svg_triangles_and_components_as_pieces() {
    // two disjoint strips in one patch: two pieces, named after the patch with #1, #2
    let (p1, t1) = grid(5, 4, |i, j| [i as f64, j as f64, 0.0], |_, _| true);
    let (p2, t2) = grid(
        4,
        3,
        |i, j| [10.0 + i as f64, j as f64, 0.5 * i as f64],
        |_, _| true,
    );
    let off = p1.len() as u32;
    let mut pos = p1;
    pos.extend(p2);
    let mut tris = t1;
    tris.extend(t2.iter().map(|t| t.map(|v| v + off)));
    let mesh = mesh_of(pos, tris);
    let mut params = Params {
        svg_triangles: true,
        ..Params::default()
    };
    params.unit = flatten::Unit::Cm;
    params.input_unit = flatten::InputUnit::Mm;
    let pat = flatten::run(&mesh, &params, &Silent::default())
        .unwrap()
        .patterns
        .unwrap();
    let names: Vec<&str> = pat.pieces.iter().map(|p| p.patch.as_str()).collect();
    assert_eq!(names, ["p#1", "p#2"]);
    assert_eq!(flatmesh::io::pattern::scale(&pat), 0.1);
    let svg = flatmesh::io::pattern::to_svg(&pat);
    let n_tri: usize = pat.pieces.iter().map(|p| p.triangles.len()).sum();
    let n_cut: usize = pat.pieces.iter().map(|p| p.cut_lines.len()).sum();
    assert_eq!(n_cut, 2, "one cut line per piece");
    assert_eq!(
        svg.matches('Z').count(),
        n_tri + 2 + n_cut,
        "one Z per triangle, per sew line and per cut line"
    );
}

/// Random wavy height fields with 0–3 random holes: every run succeeds, every loop keeps its
/// edge lengths to 1e-9, cut copies coincide, and no coordinate is NaN.
#[test]
fn random_patches_keep_boundary_lengths() {
    let mut state: u64 = 12345;
    let mut rnd = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for case in 0..24 {
        let n = 8 + (rnd() * 20.0) as usize;
        let (fx, fy, amp) = (1.0 + 4.0 * rnd(), 1.0 + 4.0 * rnd(), 0.4 * rnd());
        let holes: Vec<(usize, usize, usize)> = (0..(rnd() * 4.0) as usize)
            .map(|_| {
                let s = 1 + (rnd() * 2.0) as usize;
                (
                    2 + (rnd() * (n - 6) as f64) as usize,
                    2 + (rnd() * (n - 6) as f64) as usize,
                    s,
                )
            })
            .collect();
        let keep = |i: usize, j: usize| {
            !holes
                .iter()
                .any(|&(hi, hj, s)| i >= hi && i < hi + s && j >= hj && j < hj + s)
        };
        let (pos, tris) = grid(
            n,
            n,
            |i, j| {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                [x, y, amp * (fx * x).sin() * (fy * y).cos()]
            },
            keep,
        );
        let mesh = mesh_of(pos, tris);
        let out = match flatten::run(&mesh, &Params::default(), &Silent::default()) {
            Ok(o) => o,
            // overlapping holes can merge into a shape that is not a disk with holes
            Err(e) => panic!("case {case}: {e}"),
        };
        let pat = out.patterns.unwrap();
        for (k, piece) in pat.pieces.iter().enumerate() {
            assert!(piece
                .uv
                .iter()
                .all(|q| q[0].is_finite() && q[1].is_finite()));
            let bl = boundary_rel_error(&mesh, piece);
            assert!(bl <= 1e-9, "case {case}: boundary {bl}");
            let s = &out.summary.pieces[k].solver;
            assert!(s.cut_coincidence <= 1e-9, "case {case}: {s:?}");
        }
    }
}

/// An independent flattening of a developable piece, for truths on meshes with no closed
/// form: lay the triangles out one by one (breadth first across edges) from their 3D edge
/// lengths, each new vertex on the left of its triangle's oriented edge. No optimisation, no
/// linear solve; exact when every interior angle sum is 2π.
fn unfold(mesh: &Mesh, piece: &Piece) -> Vec<[f64; 2]> {
    use std::collections::{HashMap, VecDeque};
    let p3 = |v: u32| mesh.position(piece.vertex_ids[v as usize]);
    let d = |a: u32, b: u32| {
        let (x, y) = (p3(a), p3(b));
        ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt()
    };
    let mut edge_tris: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, t) in piece.triangles.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            edge_tris.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let mut uv: Vec<Option<[f64; 2]>> = vec![None; piece.uv.len()];
    let t0 = piece.triangles[0];
    uv[t0[0] as usize] = Some([0.0, 0.0]);
    uv[t0[1] as usize] = Some([d(t0[0], t0[1]), 0.0]);
    let place = |uv: &mut Vec<Option<[f64; 2]>>, p: u32, q: u32, c: u32| {
        let (pp, qq) = (uv[p as usize].unwrap(), uv[q as usize].unwrap());
        let l = ((qq[0] - pp[0]).powi(2) + (qq[1] - pp[1]).powi(2)).sqrt();
        let u = [(qq[0] - pp[0]) / l, (qq[1] - pp[1]) / l];
        let (a, b) = (d(p, c), d(q, c));
        let x = (l * l + a * a - b * b) / (2.0 * l);
        let h = (a * a - x * x).max(0.0).sqrt();
        uv[c as usize] = Some([pp[0] + x * u[0] - h * u[1], pp[1] + x * u[1] + h * u[0]]);
    };
    place(&mut uv, t0[0], t0[1], t0[2]);
    let mut done = vec![false; piece.triangles.len()];
    done[0] = true;
    let mut queue = VecDeque::from([0usize]);
    while let Some(f) = queue.pop_front() {
        let t = piece.triangles[f];
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            for &g in &edge_tris[&(a.min(b), a.max(b))] {
                if done[g] {
                    continue;
                }
                done[g] = true;
                let s = piece.triangles[g];
                let k = (0..3).find(|&k| s[k] == b).unwrap();
                // in g the edge runs b → a; its third vertex is on the left of b → a
                let c = s[(k + 2) % 3];
                if uv[c as usize].is_none() {
                    place(&mut uv, b, a, c);
                }
                queue.push_back(g);
            }
        }
    }
    uv.into_iter()
        .map(|q| q.expect("connected piece"))
        .collect()
}

#[test]
fn unfolding_agrees_with_the_closed_forms() {
    // the independent unfolding itself against the analytic truths
    let (mesh, truth) = cone(30, 20);
    let pat = flatten_mesh(&mesh, Method::Lpfb);
    let piece = &pat.pieces[0];
    let un = unfold(&mesh, piece);
    let want: Vec<[f64; 2]> = piece
        .vertex_ids
        .iter()
        .map(|&v| truth[v as usize])
        .collect();
    assert!(rigid_fit_max_error(&un, &want) / diameter2(&want) < 1e-9);
}

/// The committed fixtures (fixtures/<name>.obj, written by the fixtures module): the
/// developable ones against the triangle-by-triangle unfolding, all with exact boundary
/// lengths. Skips with a message while the fixtures are not in the tree.
#[test]
fn fixtures_flatten_exactly() {
    let dir = Path::new("fixtures");
    let mut seen = 0;
    for name in [
        "flat_disk",
        "cylinder",
        "cone",
        "two_holes",
        "tube_two_panels",
        "cube_cuts",
    ] {
        let path = dir.join(format!("{name}.obj"));
        seen += 1;
        let mesh = flatmesh::io::load_path(&path).expect("fixture loads").0;
        let out = flatten::run(&mesh, &Params::default(), &Silent::default()).expect(name);
        let pat = out.patterns.unwrap();
        for (k, piece) in pat.pieces.iter().enumerate() {
            let bl = boundary_rel_error(&mesh, piece);
            for lp in &piece.boundary_loops {
                let (l2, l3) = (loop_len_2d(piece, lp), loop_len_3d(&mesh, piece, lp));
                assert!((l2 - l3).abs() / l3 <= 1e-9, "{name}: loop {l2} vs {l3}");
            }
            let coincide = out.summary.pieces[k].solver.cut_coincidence;
            let un = unfold(&mesh, piece);
            let err = rigid_fit_max_error(&piece.uv, &un) / diameter2(&un);
            println!(
                "fixture {name} piece {}: loops {}, boundary {bl:.3e}, cut coincidence {coincide:.3e}, vs unfolding {err:.3e}",
                piece.patch,
                piece.boundary_loops.len()
            );
            assert!(bl <= 1e-9 && coincide <= 1e-9, "{name}");
            // exactly developable pieces (the unfolding closes up) must match it
            if piece.boundary_loops.len() == 1 && unfolding_is_consistent(&mesh, piece, &un) {
                assert!(err <= 1e-6, "{name}: {err}");
            }
        }
    }
    println!("{seen} fixtures checked");
}

/// Whether the unfolding reproduces every 3D edge length (it does when the piece is
/// developable; otherwise the BFS tree leaves some edges wrong and it is no truth).
fn unfolding_is_consistent(mesh: &Mesh, piece: &Piece, un: &[[f64; 2]]) -> bool {
    piece.triangles.iter().all(|t| {
        (0..3).all(|i| {
            let (a, b) = (t[i] as usize, t[(i + 1) % 3] as usize);
            let (x, y) = (
                mesh.position(piece.vertex_ids[a]),
                mesh.position(piece.vertex_ids[b]),
            );
            let l3 = ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt();
            let l2 = ((un[a][0] - un[b][0]).powi(2) + (un[a][1] - un[b][1]).powi(2)).sqrt();
            (l2 - l3).abs() <= 1e-9 * l3
        })
    })
}

/// Two cells of a second patch touching at one vertex: patch 0 then has two holes that
/// touch, so that vertex is split into two 2D vertices (wedges) of its piece, and the holes
/// form one loop through it twice. The mesh itself is manifold. Lengths are kept, and the
/// pieces are exact (the strip is developable).
#[test]
fn holes_touching_at_a_vertex() {
    let (mesh, truth) = cylinder(14, 12, 1.5, |_, _| true);
    let mut raw = mesh.to_raw();
    let dt = 1.5 / 13.0;
    let zs: Vec<f64> = {
        let mut z: Vec<f64> = raw.positions.iter().map(|p| p[2]).collect();
        z.sort_by(|a, b| a.partial_cmp(b).unwrap());
        z.dedup();
        z
    };
    let cell = |p: [f64; 3]| {
        (
            (p[1].atan2(p[0]) / dt).floor() as i64,
            zs.iter().filter(|&&z| z <= p[2]).count() as i64 - 1,
        )
    };
    raw.face_patch = raw
        .triangles
        .iter()
        .map(|t| {
            let c = t.iter().fold([0.0; 3], |s, &v| {
                let p = raw.positions[v as usize];
                [s[0] + p[0] / 3.0, s[1] + p[1] / 3.0, s[2] + p[2] / 3.0]
            });
            let (i, j) = cell(c);
            ((i, j) == (5, 5) || (i, j) == (6, 6)) as u32
        })
        .collect();
    raw.patch_names = vec!["body".into(), "insets".into()];
    assert_eq!(raw.face_patch.iter().filter(|&&p| p == 1).count(), 4);
    let mesh = Mesh::new(raw).unwrap().0;
    let out = flatten::run(&mesh, &Params::default(), &Silent::default()).unwrap();
    let pat = out.patterns.unwrap();
    let names: Vec<&str> = pat.pieces.iter().map(|p| p.patch.as_str()).collect();
    assert_eq!(names, ["body", "insets#1", "insets#2"]);
    let body = &pat.pieces[0];
    let n_body = body
        .vertex_ids
        .iter()
        .collect::<std::collections::HashSet<_>>()
        .len();
    assert_eq!(body.uv.len(), n_body + 1, "one vertex split in two");
    assert_eq!(body.boundary_loops.len(), 2);
    for piece in &pat.pieces {
        assert!(boundary_rel_error(&mesh, piece) <= 1e-9);
        let want: Vec<[f64; 2]> = piece
            .vertex_ids
            .iter()
            .map(|&v| truth[v as usize])
            .collect();
        let err = rigid_fit_max_error(&piece.uv, &want) / diameter2(&want);
        assert!(err <= 1e-6, "{}: {err}", piece.patch);
    }
    // the insets share seams with the body: 4 edges each, lengths equal on both sides
    assert_eq!(pat.seams.len(), 2);
    for s in &pat.seams {
        assert!((s.lengths[0] - s.length_3d).abs() <= 1e-9 * s.length_3d);
        assert!((s.lengths[1] - s.length_3d).abs() <= 1e-9 * s.length_3d);
    }
}

#[test]
fn smallest_pieces() {
    // one triangle and a two-triangle quad: no interior vertex, LPFB alone places everything
    let tri = mesh_of(
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.3], [0.2, 0.9, 0.1]],
        vec![[0, 1, 2]],
    );
    let quad = mesh_of(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.5],
            [0.0, 1.0, 0.5],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    for m in [&tri, &quad] {
        for method in [Method::Lpfb, Method::Lscm] {
            let piece = &flatten_mesh(m, method).pieces[0];
            let un = unfold(m, piece);
            let err = rigid_fit_max_error(&piece.uv, &un) / diameter2(&un);
            assert!(err < 1e-12, "{method:?}: {err}");
        }
    }
}

/// The conformal boundary angles (the Yamabe step of Boundary First Flattening with u = 0 on
/// the boundary) against truths computed here: their shifts add up to the interior's angle
/// defects recounted from the corner angles (discrete Gauss–Bonnet), vanish on a developable
/// piece, and on noisy near-developable pieces the pattern's area distortion, recomputed from
/// the pattern, falls well below that of the paper's surface angles while every boundary
/// edge keeps its 3D length and no triangle flips.
#[test]
fn conformal_boundary_angles() {
    use flatmesh::algorithms::flatten::param::CotanSystem;
    use flatmesh::corpus::pattern_checks::{area_distortion, boundary_length_error, flipped};
    use flatmesh::corpus::{Family, Procedural};
    let noisy = |family, noise| {
        Procedural {
            family,
            faces: 2000,
            noise,
        }
        .mesh()
    };
    for (name, mesh) in [
        ("dome", noisy(Family::Dome, 0.01)),
        ("saddle", noisy(Family::Saddle, 0.1)),
        ("cone", noisy(Family::Cone, 0.0)),
    ] {
        let (pos, tris) = (mesh.positions(), mesh.triangles());
        let mut sums = vec![0.0; pos.len()];
        for t in tris {
            let q = t.map(|v| pos[v as usize]);
            for i in 0..3 {
                sums[t[i] as usize] +=
                    flatmesh::geometry::corner_angle(q[i], q[(i + 1) % 3], q[(i + 2) % 3]);
            }
        }
        let interior: Vec<bool> = (0..pos.len() as u32)
            .map(|v| mesh.conn().is_interior(v))
            .collect();
        let boundary: Vec<bool> = interior.iter().map(|i| !i).collect();
        let shift = CotanSystem::new(pos, tris, &boundary)
            .unwrap()
            .angle_shift(tris, &sums)
            .unwrap();
        let defects: f64 = (0..pos.len())
            .filter(|&v| interior[v])
            .map(|v| 2.0 * PI - sums[v])
            .sum();
        let total: f64 = shift.iter().sum();
        let largest = shift.iter().fold(0.0f64, |m, s| m.max(s.abs()));
        println!("{name}: Σ shift {total:.6e}, Σ Ω {defects:.6e}, largest {largest:.3e}");
        assert!((total - defects).abs() <= 1e-9 * (1.0 + defects.abs()));
        assert!(shift.iter().zip(&interior).all(|(s, &i)| !i || *s == 0.0));
        if name == "cone" {
            assert!(largest < 1e-10, "a developable piece needs no shift");
        }
    }
    let fixture = |n: &str| {
        Mesh::new(flatmesh::fixtures::by_name(n).unwrap().mesh)
            .unwrap()
            .0
    };
    for (name, mesh) in [
        ("cone-2000-0.1", noisy(Family::Cone, 0.1)),
        ("pleats-2000-0.1", noisy(Family::Pleats, 0.1)),
        ("tube-2000-0.01", noisy(Family::Tube, 0.01)),
        ("fixture cylinder_noisy", fixture("cylinder_noisy")),
    ] {
        let mut distortion = [0.0; 2];
        for (k, boundary_angles) in [BoundaryAngles::Conformal, BoundaryAngles::Surface]
            .into_iter()
            .enumerate()
        {
            let params = Params {
                boundary_angles,
                ..Params::default()
            };
            let out = flatten::run(&mesh, &params, &Silent::default()).unwrap();
            let pieces = &out.patterns.as_ref().unwrap().pieces;
            distortion[k] = area_distortion(&mesh, pieces).0;
            if k == 0 {
                for p in pieces {
                    assert_eq!(flipped(p), 0, "{name}");
                    assert!(boundary_length_error(&mesh, p) <= 1e-9, "{name}");
                }
            }
        }
        println!(
            "{name}: mean |ln(A2D/A3D)| conformal {:.5}, surface {:.5}",
            distortion[0], distortion[1]
        );
        assert!(
            distortion[0] < 0.8 * distortion[1],
            "{name}: {distortion:?}"
        );
    }
}
