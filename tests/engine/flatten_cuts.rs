//! Pieces that are not disks: tubes, cone frustums, tubes with holes, closed boxes. Each shape
//! is exactly developable away from where it must be cut, so its pattern must be an isometry:
//! checked triangle by triangle (2D against 3D edge lengths), with orientation from signed
//! areas and overlap from a brute-force test of every pair of boundary segments
//! (flatmesh::corpus::pattern_checks), none of which uses the flatten module's own measures.

use flatmesh::algorithms::flatten::{self, cut::Cuts, InputUnit, Params, Unit};
use flatmesh::algorithms::{AlgoError, Silent};
use flatmesh::corpus::pattern_checks::{
    area_distortion, boundary_crossings, boundary_length_error, edge_length_error, flipped,
    signed_area,
};
use flatmesh::mesh::{Mesh, RawMesh};
use flatmesh::pattern::Patterns;
use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

/// Triangles from quads, vertices welded by position (exact constructions meet exactly, up to
/// the rounding of sin/cos at 2π, far below the 1e-9 grid used here).
#[derive(Default)]
struct Builder {
    pos: Vec<[f64; 3]>,
    index: HashMap<[i64; 3], u32>,
    tris: Vec<[u32; 3]>,
    patch: Vec<u32>,
}

impl Builder {
    fn v(&mut self, p: [f64; 3]) -> u32 {
        let k = p.map(|x| (x * 1e9).round() as i64);
        let n = self.pos.len() as u32;
        *self.index.entry(k).or_insert_with(|| {
            self.pos.push(p);
            n
        })
    }
    /// Quad a, b, c, d counter-clockwise seen from the front, split along alternating diagonals.
    fn quad(&mut self, q: [[f64; 3]; 4], alt: bool, patch: u32) {
        let [a, b, c, d] = q.map(|p| self.v(p));
        if alt {
            self.tris.extend([[a, b, c], [a, c, d]]);
        } else {
            self.tris.extend([[a, b, d], [b, c, d]]);
        }
        self.patch.extend([patch, patch]);
    }
    fn tri(&mut self, t: [[f64; 3]; 3], patch: u32) {
        let t = t.map(|p| self.v(p));
        self.tris.push(t);
        self.patch.push(patch);
    }
    fn mesh(self, names: &[&str]) -> Mesh {
        Mesh::new(RawMesh {
            positions: self.pos,
            triangles: self.tris,
            face_patch: self.patch,
            patch_names: names.iter().map(|s| s.to_string()).collect(),
            uv: None,
        })
        .expect("valid mesh")
        .0
    }
}

/// Side of a cone frustum (a cylinder when r0 = r1): n around, m up, height h. The quads
/// between two generators are planar, so the surface is exactly developable. `skip(i, j)`
/// leaves quads out (holes).
fn frustum(
    b: &mut Builder,
    n: usize,
    m: usize,
    (r0, r1, h): (f64, f64, f64),
    skip: impl Fn(usize, usize) -> bool,
) {
    let p = |i: usize, j: usize| {
        let t = TAU * (i % n) as f64 / n as f64;
        let s = j as f64 / m as f64;
        let r = r0 + (r1 - r0) * s;
        [r * t.cos(), r * t.sin(), h * s]
    };
    for j in 0..m {
        for i in 0..n {
            if !skip(i, j) {
                b.quad(
                    [p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)],
                    (i + j) % 2 == 0,
                    0,
                );
            }
        }
    }
}

/// A flat disk cap of radius r at height z in `rings` rings, facing +z when `up`.
fn cap(b: &mut Builder, n: usize, rings: usize, r: f64, z: f64, up: bool) {
    let p = |i: usize, k: usize| {
        let t = TAU * (i % n) as f64 / n as f64;
        let rr = r * k as f64 / rings as f64;
        [rr * t.cos(), rr * t.sin(), z]
    };
    for i in 0..n {
        let (a, c) = (p(i, 1), p(i + 1, 1));
        let o = [0.0, 0.0, z];
        if up {
            b.tri([o, a, c], 0);
        } else {
            b.tri([o, c, a], 0);
        }
        for k in 1..rings {
            let q = [p(i, k), p(i, k + 1), p(i + 1, k + 1), p(i + 1, k)];
            let q = if up { [q[0], q[3], q[2], q[1]] } else { q };
            b.quad(q, (i + k) % 2 == 0, 0);
        }
    }
}

/// A cube of side 1 with k × k quads per face, faces outward.
fn cube(b: &mut Builder, k: usize, patch: u32) {
    let faces: [([f64; 3], [f64; 3], [f64; 3]); 6] = [
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]), // z = 0, −z
        ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), // z = 1
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]), // y = 0, −y
        ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]), // y = 1
        ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]), // x = 0, −x
        ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]), // x = 1
    ];
    for (o, u, v) in faces {
        let p = |i: usize, j: usize| {
            let (s, t) = (i as f64 / k as f64, j as f64 / k as f64);
            [0, 1, 2].map(|c| o[c] + s * u[c] + t * v[c])
        };
        for j in 0..k {
            for i in 0..k {
                b.quad(
                    [p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)],
                    (i + j) % 2 == 0,
                    patch,
                );
            }
        }
    }
}

/// A sphere of radius r at `c`: an octahedron subdivided `levels` times, projected.
fn sphere(b: &mut Builder, levels: usize, c: [f64; 3], r: f64, patch: u32) {
    let mut tris: Vec<[[f64; 3]; 3]> = Vec::new();
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let neg = |p: [f64; 3]| p.map(|a| -a);
    for (a, bb) in [(x, y), (y, neg(x)), (neg(x), neg(y)), (neg(y), x)] {
        tris.push([a, bb, z]);
        tris.push([bb, a, neg(z)]);
    }
    let unit = |p: [f64; 3]| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        p.map(|a| a / l)
    };
    let mid = |p: [f64; 3], q: [f64; 3]| unit([0, 1, 2].map(|k| p[k] + q[k]));
    for _ in 0..levels {
        tris = tris
            .into_iter()
            .flat_map(|[a, bb, cc]| {
                let (ab, bc, ca) = (mid(a, bb), mid(bb, cc), mid(cc, a));
                [[a, ab, ca], [ab, bb, bc], [ca, bc, cc], [ab, bc, ca]]
            })
            .collect();
    }
    for t in tris {
        b.tri(t.map(|p| [0, 1, 2].map(|k| c[k] + r * p[k])), patch);
    }
}

/// The patterns and the summary as report.json shows it.
fn run(mesh: &Mesh, params: &Params) -> (Patterns, serde_json::Map<String, serde_json::Value>) {
    let out = flatten::run(mesh, params, &Silent::default()).expect("flatten");
    let summary = match serde_json::to_value(&out.summary) {
        Ok(serde_json::Value::Object(o)) => o,
        other => panic!("summary is not an object: {other:?}"),
    };
    (out.patterns.expect("patterns"), summary)
}

fn d2(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Everything the issue asks of an exactly developable shape: isometric (so stretch ≤ 1e-6 %),
/// no flip, no overlap, boundary edges to 1e-9, both sides of each cut of equal length.
fn check_exact(label: &str, mesh: &Mesh, pat: &Patterns) {
    check_isometric(label, mesh, pat, true)
}

/// As [`check_exact`]; `apart` false skips the overlap test (a cut through a hole that
/// encloses no curvature is a slit whose two sides lie on each other).
fn check_isometric(label: &str, mesh: &Mesh, pat: &Patterns, apart: bool) {
    for p in &pat.pieces {
        let iso = edge_length_error(mesh, p);
        let bnd = boundary_length_error(mesh, p);
        let flips = p
            .triangles
            .iter()
            .filter(|&&t| signed_area(p, t) <= 0.0)
            .count();
        let cross = boundary_crossings(p);
        println!(
            "{label} `{}`: {} triangles, {} loops, isometry {iso:.2e}, boundary {bnd:.2e}, \
             flips {flips}, boundary crossings {cross}",
            p.patch,
            p.triangles.len(),
            p.boundary_loops.len()
        );
        assert!(iso <= 1e-8, "{label}: isometry error {iso}");
        assert!(bnd <= 1e-9, "{label}: boundary error {bnd}");
        assert_eq!(flips, 0, "{label}: flipped triangles");
        if apart {
            assert_eq!(cross, 0, "{label}: the pattern overlaps itself");
            assert_eq!(p.measures["overlap"], 0, "{label}: measures disagree");
        }
    }
    for s in pat.seams.iter().filter(|s| s.pieces[0] == s.pieces[1]) {
        let p = &pat.pieces[s.pieces[0]];
        let side = |k: usize| -> f64 {
            s.edges[k]
                .iter()
                .map(|e| d2(p.uv[e[0] as usize], p.uv[e[1] as usize]))
                .sum()
        };
        let (a, b) = (side(0), side(1));
        assert!(!s.edges[0].is_empty() && s.edges[0].len() == s.edges[1].len());
        assert!(
            (a - b).abs() <= 1e-9 * s.length_3d,
            "{label}: sides {a} {b}"
        );
        assert!((a - s.length_3d).abs() <= 1e-9 * s.length_3d);
        assert!((s.lengths[0] - a).abs() <= 1e-12 * a && (s.lengths[1] - b).abs() <= 1e-12 * b);
    }
}

fn self_seams(pat: &Patterns) -> usize {
    pat.seams
        .iter()
        .filter(|s| s.pieces[0] == s.pieces[1])
        .count()
}

fn solver(summary: &serde_json::Map<String, serde_json::Value>, k: usize) -> &serde_json::Value {
    &summary["pieces"][k]["solver"]
}

#[test]
fn tube_is_cut_once_and_unrolls_exactly() {
    let mut b = Builder::default();
    frustum(&mut b, 48, 20, (0.3, 0.3, 0.8), |_, _| false);
    let mesh = b.mesh(&["sleeve"]);
    let (pat, summary) = run(&mesh, &Params::default());
    check_exact("tube", &mesh, &pat);
    assert_eq!(pat.pieces.len(), 1);
    assert_eq!(pat.pieces[0].boundary_loops.len(), 1, "cut open: one loop");
    assert_eq!(self_seams(&pat), 1);
    let k = solver(&summary, 0)["enclosed_curvature"][0]
        .as_f64()
        .unwrap();
    assert!((k - TAU).abs() < 1e-9, "a cylinder's rim encloses 2π: {k}");
    // the unrolled tube is a rectangle 2πr (chords) by h
    let p = &pat.pieces[0];
    let area: f64 = p.triangles.iter().map(|&t| signed_area(p, t)).sum();
    let chord = 2.0 * 0.3 * (PI / 48.0).sin();
    assert!((area - 48.0 * chord * 0.8).abs() < 1e-9);
}

#[test]
fn cone_frustum_is_cut_once_and_unrolls_exactly() {
    let mut b = Builder::default();
    frustum(&mut b, 40, 12, (0.5, 0.2, 0.6), |_, _| false);
    let mesh = b.mesh(&["cone"]);
    let (pat, summary) = run(&mesh, &Params::default());
    check_exact("frustum", &mesh, &pat);
    assert_eq!(self_seams(&pat), 1);
    // the small rim of a cone of half-angle β encloses 2π(1 − sin β) (polygonal: the apex's
    // angle defect, 2π minus the sum of the apex angles of the 40 planar sectors)
    let slant = (0.3f64.powi(2) + 0.6f64.powi(2)).sqrt();
    let apex_height: f64 = 0.6 * 0.5 / 0.3;
    let side = (0.5f64.powi(2) + apex_height.powi(2)).sqrt();
    let chord = 2.0 * 0.5 * (PI / 40.0).sin();
    let sector = 2.0 * (chord / 2.0 / side).asin();
    let want = TAU - 40.0 * sector;
    let k = solver(&summary, 0)["enclosed_curvature"][0]
        .as_f64()
        .unwrap();
    assert!(
        (k.abs() - want).abs() < 1e-9,
        "{k} against {want} (slant {slant})"
    );
}

#[test]
fn tube_with_two_holes_keeps_the_holes_and_cuts_the_rim() {
    let mut b = Builder::default();
    let hole =
        |i: usize, j: usize| (i == 5 && (4..6).contains(&j)) || ((20..23).contains(&i) && j == 9);
    frustum(&mut b, 36, 14, (0.4, 0.4, 1.0), hole);
    let mesh = b.mesh(&["body"]);
    let (pat, summary) = run(&mesh, &Params::default());
    check_exact("tube with holes", &mesh, &pat);
    let s = solver(&summary, 0);
    assert_eq!(s["loops"], 4);
    assert_eq!(s["real_cuts"], 1);
    assert_eq!(s["holes"], 2);
    assert_eq!(pat.pieces[0].boundary_loops.len(), 3, "cut rim + two holes");
    assert_eq!(self_seams(&pat), 1);
    // with cuts=real every inner loop is cut; the holes enclose no curvature, so each of their
    // cuts is a slit whose sides lie on each other
    let (pat, summary) = run(
        &mesh,
        &Params {
            cuts: Cuts::Real,
            ..Params::default()
        },
    );
    check_isometric("tube with holes, cuts=real", &mesh, &pat, false);
    assert_eq!(solver(&summary, 0)["real_cuts"], 3);
    assert_eq!(pat.pieces[0].boundary_loops.len(), 1);
    assert_eq!(self_seams(&pat), 3);
}

#[test]
fn capped_cylinder_is_cut_through_its_rims() {
    let mut b = Builder::default();
    frustum(&mut b, 32, 10, (0.25, 0.25, 0.5), |_, _| false);
    cap(&mut b, 32, 4, 0.25, 0.0, false);
    cap(&mut b, 32, 4, 0.25, 0.5, true);
    let mesh = b.mesh(&["can"]);
    let (pat, summary) = run(&mesh, &Params::default());
    check_exact("capped cylinder", &mesh, &pat);
    assert_eq!(pat.pieces.len(), 1);
    assert_eq!(pat.pieces[0].boundary_loops.len(), 1);
    assert_eq!(solver(&summary, 0)["cone_points"], 64, "every rim vertex");
}

#[test]
fn cube_and_octahedron_become_nets() {
    let mut b = Builder::default();
    cube(&mut b, 3, 0);
    let mesh = b.mesh(&["box"]);
    let (pat, summary) = run(&mesh, &Params::default());
    check_exact("cube", &mesh, &pat);
    assert_eq!(solver(&summary, 0)["cone_points"], 8);
    assert_eq!(self_seams(&pat), 7, "a tree through 8 corners has 7 paths");
    let area: f64 = pat.pieces[0]
        .triangles
        .iter()
        .map(|&t| signed_area(&pat.pieces[0], t))
        .sum();
    assert!((area - 6.0).abs() < 1e-12);

    let mut b = Builder::default();
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let neg = |p: [f64; 3]| p.map(|a: f64| -a);
    for (a, c) in [(x, y), (y, neg(x)), (neg(x), neg(y)), (neg(y), x)] {
        b.tri([a, c, z], 0);
        b.tri([c, a, neg(z)], 0);
    }
    let mesh = b.mesh(&["octahedron"]);
    let (pat, _) = run(&mesh, &Params::default());
    check_exact("octahedron", &mesh, &pat);
    assert_eq!(pat.pieces[0].triangles.len(), 8);
}

#[test]
fn a_closed_smooth_component_is_skipped_by_name_and_the_rest_is_produced() {
    let mut b = Builder::default();
    frustum(&mut b, 24, 8, (0.3, 0.3, 0.5), |_, _| false);
    sphere(&mut b, 3, [2.0, 0.0, 0.0], 0.05, 1);
    let mesh = b.mesh(&["sleeve", "button"]);
    let first_button = mesh.face_patch().iter().position(|&p| p == 1).unwrap();
    let (pat, summary) = run(&mesh, &Params::default());
    assert_eq!(pat.pieces.len(), 1);
    assert_eq!(pat.pieces[0].patch, "sleeve");
    check_exact("sleeve beside a button", &mesh, &pat);
    let warnings: Vec<&str> = summary["job_warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    let w = warnings
        .iter()
        .find(|w| w.contains("`button`"))
        .unwrap_or_else(|| panic!("no warning names the button: {warnings:?}"));
    assert!(w.contains("skipped") && w.contains("closed"), "{w}");
    assert!(
        w.contains(&format!(
            "triangles {first_button}–{}",
            mesh.num_faces() - 1
        )),
        "{w}"
    );
    // nothing but the button: the job fails and says why
    let mut b = Builder::default();
    sphere(&mut b, 3, [0.0; 3], 0.05, 0);
    let e = flatten::run(&b.mesh(&["button"]), &Params::default(), &Silent::default()).unwrap_err();
    assert!(
        matches!(&e, AlgoError::Input(m) if m.contains("no piece") && m.contains("`button`")),
        "{e}"
    );
}

#[test]
fn cuts_virtual_keeps_the_old_holes_and_says_why_it_overlaps() {
    let mut b = Builder::default();
    frustum(&mut b, 48, 20, (0.3, 0.3, 0.8), |_, _| false);
    let mesh = b.mesh(&["sleeve"]);
    let params = Params {
        cuts: Cuts::Virtual,
        input_unit: InputUnit::M,
        ..Params::default()
    };
    let (pat, summary) = run(&mesh, &params);
    let p = &pat.pieces[0];
    assert_eq!(p.boundary_loops.len(), 2);
    let flips = p
        .triangles
        .iter()
        .filter(|&&t| signed_area(p, t) <= 0.0)
        .count();
    assert!(
        flips > 0 || boundary_crossings(p) > 0,
        "a tube cannot lie flat uncut"
    );
    let w = summary["job_warnings"][0].as_str().unwrap();
    assert!(
        w.contains("enclose curvature") && w.contains("cuts=auto"),
        "{w}"
    );
}

#[test]
fn the_input_unit_is_guessed_from_the_size_and_reported() {
    for (d, u) in [
        (0.2, Unit::M),
        (1.9, Unit::M),
        (18.5, Unit::Dm),
        (102.9, Unit::Cm),
        (256.0, Unit::Cm),
        (987.0, Unit::Mm),
        (f64::NAN, Unit::M),
    ] {
        assert_eq!(Unit::guess(d), u, "diagonal {d}");
    }
    // a 1.2 m tube drawn in centimetres: guessed cm, drawn 1:1
    let mut b = Builder::default();
    frustum(&mut b, 24, 8, (30.0, 30.0, 80.0), |_, _| false);
    let mesh = b.mesh(&["sleeve"]);
    let (pat, summary) = run(&mesh, &Params::default());
    assert_eq!(summary["input_unit"], "cm");
    let why = summary["input_unit_guessed"].as_str().unwrap();
    assert!(why.contains("`cm` assumed"), "{why}");
    assert_eq!(pat.input_unit, "cm");
    assert_eq!(
        flatmesh::io::pattern::scale(&pat),
        10.0,
        "cm to the default mm"
    );
    let params = Params {
        input_unit: InputUnit::M,
        ..Params::default()
    };
    let (_, summary) = run(&mesh, &params);
    assert_eq!(summary["input_unit"], "m");
    assert!(!summary.contains_key("input_unit_guessed"));
}

#[test]
fn a_torus_is_refused_by_name() {
    let mut b = Builder::default();
    let (n, m) = (16, 8);
    let p = |i: usize, j: usize| {
        let (u, v) = (
            TAU * (i % n) as f64 / n as f64,
            TAU * (j % m) as f64 / m as f64,
        );
        let r = 1.0 + 0.3 * v.cos();
        [r * u.cos(), r * u.sin(), 0.3 * v.sin()]
    };
    for j in 0..m {
        for i in 0..n {
            b.quad(
                [p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)],
                true,
                0,
            );
        }
    }
    let e = flatten::run(&b.mesh(&["ring"]), &Params::default(), &Silent::default()).unwrap_err();
    assert!(
        matches!(&e, AlgoError::Input(m) if m.contains("`ring`") && m.contains("genus 1")),
        "{e}"
    );
}

/// The ARAP interior (the default) keeps an isometry isometric, keeps the boundary exact, and on a noisy
/// half-cylinder (radial noise ±0.2 % of the radius, as benches/flatten.rs) spreads the area
/// more evenly than the harmonic interior.
#[test]
fn arap_interior_is_exact_when_it_can_be_and_lowers_area_distortion() {
    let arap = Params::default();
    let harmonic_params = Params {
        interior: flatten::param::Interior::Harmonic,
        ..Params::default()
    };
    let mut b = Builder::default();
    frustum(&mut b, 40, 12, (0.5, 0.2, 0.6), |_, _| false);
    let mesh = b.mesh(&["cone"]);
    check_exact("frustum, arap", &mesh, &run(&mesh, &arap).0);

    let mut state: u64 = 7;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let n = 60;
    let mut b = Builder::default();
    let mut p = vec![[0.0; 3]; n * n];
    for j in 0..n {
        for i in 0..n {
            let t = PI * i as f64 / (n - 1) as f64;
            let r = 0.5 * (1.0 + 0.004 * rnd());
            p[j * n + i] = [r * t.cos(), r * t.sin(), j as f64 / (n - 1) as f64];
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let q = [
                p[j * n + i],
                p[j * n + i + 1],
                p[(j + 1) * n + i + 1],
                p[(j + 1) * n + i],
            ];
            b.quad(q, true, 0);
        }
    }
    let mesh = b.mesh(&["half cylinder"]);
    let (harmonic, _) = run(&mesh, &harmonic_params);
    let (rigid, _) = run(&mesh, &arap);
    let (h, r) = (
        area_distortion(&mesh, &harmonic.pieces).0,
        area_distortion(&mesh, &rigid.pieces).0,
    );
    println!("noisy half-cylinder: mean |ln(A2D/A3D)| harmonic {h:.5}, arap {r:.5}");
    assert!(r < h);
    for pat in [&harmonic, &rigid] {
        let p = &pat.pieces[0];
        assert!(boundary_length_error(&mesh, p) <= 1e-9);
        assert_eq!(
            p.triangles
                .iter()
                .filter(|&&t| signed_area(p, t) <= 0.0)
                .count(),
            0
        );
    }
}

/// Whole garments (one patch each, hem plus neck and two sleeves or straps) made flattenable by
/// fl-mesh flatten into one piece each, cut open along three seams, with no flipped triangle,
/// no overlap and every triangle edge within 0.01 % of its 3D length.
#[test]
fn garments_made_flattenable_flatten_without_overlap() {
    let Some(root) =
        flatmesh::corpus::shared_root_for_tests("garments through fl-mesh and flatten")
    else {
        return;
    };
    for rel in [
        "garment/diffavatar_tshirt.obj",
        "garment/gc_tee_sim.obj",
        "garment/gf_dress.obj",
    ] {
        let (mesh, _) = flatmesh::io::load_path(&root.join(rel)).expect("loads");
        let (flat, _) =
            flatmesh::algorithms::fl_mesh::solve(&mesh, &Default::default(), &Silent::default())
                .expect("fl-mesh runs");
        assert!(flatmesh::corpus::max_flattenability(&flat) <= 1e-6, "{rel}");
        let (pat, summary) = run(&flat, &Params::default());
        assert_eq!(pat.pieces.len(), 1, "{rel}");
        let p = &pat.pieces[0];
        let (edge, bnd) = (edge_length_error(&flat, p), boundary_length_error(&flat, p));
        let (flips, cross) = (flipped(p), boundary_crossings(p));
        println!(
            "{rel}: edge error {edge:.2e}, boundary {bnd:.2e}, flips {flips}, crossings {cross}"
        );
        assert_eq!(solver(&summary, 0)["real_cuts"], 3, "{rel}");
        assert_eq!((flips, cross), (0, 0), "{rel}");
        assert!(edge <= 1e-4 && bnd <= 1e-9, "{rel}: {edge} {bnd}");
        assert!(
            summary["job_warnings"].as_array().unwrap().is_empty(),
            "{rel}"
        );
    }
}
