//! `flatten` against independent truths: exactly developable patches (cylinder and cone
//! strips, whose unrolling is computed here in closed form, and the ipc dress panels whose
//! `vt` is their own pattern), boundary lengths, virtual cutting, measures, LSCM, export.

use flatmesh::algorithms::flatten::{self, Method, Params};
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

/// Best rigid motion (rotation + translation, Kabsch in 2D) of `a` onto `b`; returns the
/// largest distance after the fit.
fn rigid_fit_max_error(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
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
        .fold(0.0, f64::max)
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

#[test]
fn debug_cyl_info() {
    let (mesh, _truth) = cylinder(40, 25, 2.0, |_, _| true);
    let o = flatten::run(&mesh, &Params::default(), &Silent::default()).unwrap();
    println!(
        "{}",
        serde_json::to_string_pretty(&o.summary["pieces"][0]["solver"]).unwrap()
    );
    println!(
        "{}",
        serde_json::to_string_pretty(&o.summary["pieces"][0]["measures"]).unwrap()
    );
}
