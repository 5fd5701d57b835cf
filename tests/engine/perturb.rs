//! `perturb` (FL Sec. 4, Algorithm 2), checked with independent truths: a dense solve of the
//! KKT system Eq. 22, ϖ recomputed from corner angles, brute-force closest points on the body.

use faer::linalg::solvers::Solve;
use flatmesh::algorithms::perturb::{self, min_norm_step, Method, Params};
use flatmesh::algorithms::Silent;
use flatmesh::geometry::{angle_sums, flattenability};
use flatmesh::mesh::{Mesh, RawMesh};
use proptest::prelude::*;

fn mesh(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
    let raw = RawMesh {
        face_patch: vec![0; triangles.len()],
        positions,
        triangles,
        patch_names: vec!["p".into()],
        uv: None,
    };
    Mesh::new(raw).unwrap().0
}

fn load(name: &str) -> Mesh {
    let bytes = std::fs::read(format!("fixtures/{name}.obj")).unwrap();
    flatmesh::io::load(&bytes, flatmesh::io::Format::Obj)
        .unwrap()
        .0
}

/// ϖ_max recomputed from the corner angles.
fn varpi_max(m: &Mesh) -> f64 {
    flattenability(m, &angle_sums(m))
        .into_iter()
        .fold(0.0, f64::max)
}

/// An n×m grid over [0,1]², z from `f`.
fn grid(n: usize, f: impl Fn(f64, f64, usize) -> f64) -> Mesh {
    let mut p = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            p.push([x, y, f(x, y, p.len())]);
        }
    }
    let mut t = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = (j * (n + 1) + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    mesh(p, t)
}

/// The paper's Algorithm 2 with its defaults.
fn local() -> Params {
    Params {
        method: Method::Local,
        ..Params::default()
    }
}

fn run(m: &Mesh, body: Option<&Mesh>, p: &Params) -> (Mesh, perturb::Summary) {
    let o = perturb::run(m, body, p, &Silent::default()).unwrap();
    (o.mesh.unwrap(), o.summary)
}

/// Eq. 22 solved as the whole KKT system [[I, Λᵀ], [Λ, 0]] by a dense LU with full pivoting:
/// the SVD-based step must agree, and satisfy Λδ = B_λ.
#[test]
fn local_step_is_the_kkt_solution() {
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    for (m, n) in [(5, 12), (20, 33), (1, 3), (30, 30)] {
        let lam = faer::Mat::<f64>::from_fn(m, n, |_, _| rnd());
        let bp: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let bl: Vec<f64> = (0..m).map(|_| rnd()).collect();
        let (delta, mult) = min_norm_step(&lam, &bp, &bl);
        let k = faer::Mat::<f64>::from_fn(n + m, n + m, |i, j| match (i < n, j < n) {
            (true, true) => f64::from(u8::from(i == j)),
            (true, false) => lam[(j - n, i)],
            (false, true) => lam[(i - n, j)],
            (false, false) => 0.0,
        });
        let rhs = faer::Mat::<f64>::from_fn(n + m, 1, |i, _| if i < n { bp[i] } else { bl[i - n] });
        let x = k.full_piv_lu().solve(&rhs);
        for i in 0..n {
            assert!((x[(i, 0)] - delta[i]).abs() < 1e-9, "{m}x{n} δ[{i}]");
        }
        for i in 0..m {
            assert!((x[(n + i, 0)] - mult[i]).abs() < 1e-8, "{m}x{n} λ[{i}]");
            let r: f64 = (0..n).map(|j| lam[(i, j)] * delta[j]).sum();
            assert!((r - bl[i]).abs() < 1e-10, "{m}x{n}: Λδ = B_λ row {i}");
        }
    }
}

#[test]
fn within_tolerance_comes_back_bit_identical() {
    let m = load("cylinder");
    for p in [local(), Params::default()] {
        let (out, s) = run(&m, None, &p);
        assert_eq!(out.positions(), m.positions());
        assert_eq!(s.iterations, 0);
        assert!(s.converged);
        assert_eq!(s.moved_vertices, 0);
    }
}

/// FL Sec. 4 sanity (paper-notes A.6 item 8): the noisy cylinder reaches ϖ_max < 1e-3 without
/// a body (`global`: ≤ 1e-6); boundary vertices never move.
#[test]
fn noisy_cylinder_without_body() {
    let m = load("cylinder_noisy");
    let before = varpi_max(&m);
    for (p, target) in [(local(), 1e-3), (Params::default(), 1e-6)] {
        let (out, s) = run(&m, None, &p);
        let after = varpi_max(&out);
        eprintln!(
            "cylinder_noisy {:?}: ϖ_max {before:.3e} -> {after:.3e}, {:?} after {}",
            p.method, s.stop_reason, s.iterations
        );
        assert!(after <= before);
        assert!((after - s.max_flattenability_after).abs() < 1e-12);
        assert!(after <= target, "{after} after {} iterations", s.iterations);
        assert!(s.converged);
        for v in 0..m.num_vertices() as u32 {
            if !m.conn().is_interior(v) {
                assert_eq!(out.position(v), m.position(v), "boundary vertex {v} moved");
            }
        }
    }
}

/// Two bumps far apart on a plane: only vertices near them move (locality).
#[test]
fn only_vertices_near_the_bumps_move() {
    let n = 40;
    let bump = |x: f64, y: f64, cx: f64, cy: f64| {
        let r2 = ((x - cx).powi(2) + (y - cy).powi(2)) * 400.0;
        0.01 * (-r2).exp()
    };
    let m = grid(n, |x, y, _| bump(x, y, 0.25, 0.25) + bump(x, y, 0.75, 0.75));
    let p = local();
    let (out, s) = run(&m, None, &p);
    assert!(s.max_flattenability_after <= s.max_flattenability_before);
    assert!(s.moved_vertices > 0, "{s:?}");
    let h = 1.0 / n as f64;
    // Where the bumps are non-flat (ϖ > 1e-9) the mesh may change within a generous margin of
    // rings; farther away not a bit.
    let w = flattenability(&m, &angle_sums(&m));
    let hot: Vec<[f64; 3]> = (0..m.num_vertices())
        .filter(|&v| w[v] > 1e-9)
        .map(|v| m.positions()[v])
        .collect();
    let margin = 3.0 * (p.rings as f64 + 1.0) * h * std::f64::consts::SQRT_2;
    for v in 0..m.num_vertices() {
        let q = m.positions()[v];
        let far = hot
            .iter()
            .all(|a| ((a[0] - q[0]).powi(2) + (a[1] - q[1]).powi(2)).sqrt() > margin);
        if far {
            assert_eq!(out.positions()[v], q, "far vertex {v} moved");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]
    /// Never worse: on noisy grids ϖ_max(out) ≤ ϖ_max(in), boundary bit-identical.
    #[test]
    fn never_worse_on_noisy_grids(n in 4usize..12, amp in 0.0f64..0.05, seed in 0u64..1000) {
        let m = grid(n, |x, y, i| {
            let s = (seed as f64 + i as f64 * 12.9898).sin() * 43758.5453;
            amp * (s - s.floor() - 0.5) + 0.1 * x * y
        });
        let global = Params { max_iterations: 30, ..Params::default() };
        let strict = Params { max_outer: 8, parallel: false, ..local() };
        for p in [Params { max_outer: 8, ..local() }, strict, global] {
            let (out, s) = run(&m, None, &p);
            prop_assert!(varpi_max(&out) <= varpi_max(&m) + 1e-15);
            prop_assert_eq!(s.iterations == 0, varpi_max(&m) <= p.tolerance());
            for v in 0..m.num_vertices() as u32 {
                if !m.conn().is_interior(v) {
                    prop_assert_eq!(out.position(v), m.position(v));
                }
            }
        }
    }
}

/// Brute-force signed distance to a closed body: closest point over every triangle, sign by
/// the winding number (independent of the pseudo-normals the algorithm uses).
fn brute_signed(body: &Mesh, p: [f64; 3]) -> f64 {
    flatmesh::corpus::brute_signed_distance(body, p)
}

use flatmesh::corpus::{arm, sleeve};

/// The sleeve around a slightly thinner arm: with clearance c every vertex that started at
/// ≥ c ends at ≥ c − 1e-9·h̄ (brute-force distance), penetrating vertices never increase.
#[test]
fn sleeve_stays_clear_of_the_arm() {
    let body = arm(0.3, 2.0, 48, 40);
    let garment = sleeve(0.32, 2.0, 36, 30, 0.04);
    let h = flatmesh::geometry::mean_edge_length(&garment);
    for (method, clearance) in [
        (Method::Local, 0.0),
        (Method::Local, 0.01),
        (Method::Global, 0.0),
        (Method::Global, 0.01),
    ] {
        let p = Params {
            method,
            clearance,
            ..Params::default()
        };
        let (out, s) = run(&garment, Some(&body), &p);
        let fig = s.body.as_ref().unwrap();
        let (mut pen_in, mut pen_out, mut deep_out) = (0, 0, 0);
        let mut started_clear = 0;
        for v in 0..garment.num_vertices() as u32 {
            let a = brute_signed(&body, garment.position(v));
            let b = brute_signed(&body, out.position(v));
            assert!(
                (a - fig.clearance_before[v as usize]).abs() < 1e-12,
                "vertex {v} before"
            );
            assert!(
                (b - fig.clearance_after[v as usize]).abs() < 1e-12,
                "vertex {v} after"
            );
            pen_in += usize::from(a < 0.0);
            pen_out += usize::from(b < 0.0);
            deep_out += usize::from(b < -1e-9 * h);
            if a >= clearance {
                started_clear += 1;
                assert!(
                    b >= clearance - 1e-9 * h,
                    "c={clearance}: vertex {v} {a} -> {b}"
                );
            }
        }
        eprintln!(
            "{method:?} c={clearance}: ϖ_max {:.3e} -> {:.3e} ({}, {} its), penetrating {pen_in} -> {pen_out}, \
             min clearance {:.4} -> {:.4}, moved {}",
            s.max_flattenability_before,
            s.max_flattenability_after,
            s.stop_reason.as_str(),
            s.iterations,
            fig.min_clearance_before,
            fig.min_clearance_after,
            s.moved_vertices
        );
        assert!(started_clear > garment.num_vertices() / 2);
        assert!(pen_out <= pen_in);
        assert!(s.max_flattenability_after <= s.max_flattenability_before);
        assert!(
            s.max_flattenability_after < s.max_flattenability_before,
            "improved"
        );
        if method == Method::Global {
            // The dents can be pushed out: a round sleeve clear of the arm is developable.
            assert!(s.converged, "{}", s.stop_detail);
            assert!(varpi_max(&out) <= 1e-6);
            // Pushed out to the surface, within the tolerance of the guarantee above (one
            // vertex ends 1.7e-13 inside: rounding of the contact constraint at c = 0).
            assert_eq!(deep_out, 0);
        }
    }
}

/// The real pair of the issue: the MakeHuman elegant suit on the female body it was made for
/// (same frame). The raw suit is far from flattenable (ϖ_max 0.95), so neither method
/// converges here within the budget; what is checked is the body guarantee on real data, by
/// brute-force distances: with clearance c (0 and 5 mm), every vertex that started at ≥ c ends
/// at ≥ c − 1e-9·h̄, penetrating vertices never increase, and ϖ_max never rises. (Convergence
/// on almost flattenable garments against their bodies: examples/perturb_corpus.)
#[test]
fn elegant_suit_keeps_clear_of_the_female_body() {
    use rayon::prelude::*;
    let (Some(g), Some(b)) = (
        flatmesh::corpus::shared_mesh_for_tests("garment/mh_female_elegantsuit01.obj"),
        flatmesh::corpus::shared_mesh_for_tests("body/mh_female_generic.obj"),
    ) else {
        return;
    };
    let garment = flatmesh::io::load_path(&g).unwrap().0;
    let body = flatmesh::io::load_path(&b).unwrap().0;
    let h = flatmesh::geometry::mean_edge_length(&garment);
    let signed = |m: &Mesh| -> Vec<f64> {
        m.positions()
            .par_iter()
            .map(|&p| brute_signed(&body, p))
            .collect()
    };
    let before = signed(&garment);
    // The MakeHuman unit is the decimetre: 0.05 is 5 mm.
    // `local` is left out: on this input no outer iteration beats the input (its best record
    // is the input, so the check would hold vacuously); its guarantee is tested on the sleeve.
    for (method, clearance) in [(Method::Global, 0.0), (Method::Global, 0.05)] {
        let p = Params {
            method,
            clearance,
            max_iterations: 40,
            ..Params::default()
        };
        let (out, s) = run(&garment, Some(&body), &p);
        let after = signed(&out);
        let pen = |v: &[f64]| v.iter().filter(|&&s| s < 0.0).count();
        eprintln!(
            "elegantsuit {method:?} c={clearance}: ϖ_max {:.3e} -> {:.3e} in {} its ({}), \
             penetrating {} -> {}, moved {}",
            s.max_flattenability_before,
            varpi_max(&out),
            s.iterations,
            s.stop_detail,
            pen(&before),
            pen(&after),
            s.moved_vertices
        );
        assert!(
            s.moved_vertices > 0,
            "{method:?} c={clearance} moved nothing"
        );
        assert!(varpi_max(&out) <= varpi_max(&garment));
        assert!(pen(&after) <= pen(&before));
        for v in 0..garment.num_vertices() {
            if before[v] >= clearance {
                assert!(
                    after[v] >= clearance - 1e-9 * h,
                    "{method:?} c={clearance}: vertex {v} {} -> {}",
                    before[v],
                    after[v]
                );
            }
        }
    }
}

/// `local`'s parallel waves give the same bits on every run (the moves of a wave are disjoint
/// and written back in wave order), and the paper's strict order is still there to compare.
#[test]
fn parallel_waves_are_deterministic() {
    let body = arm(0.3, 2.0, 48, 40);
    let garment = sleeve(0.32, 2.0, 36, 30, 0.04);
    let (a, sa) = run(&garment, Some(&body), &local());
    let (b, _) = run(&garment, Some(&body), &local());
    assert_eq!(a.positions(), b.positions());
    let strict = Params {
        parallel: false,
        ..local()
    };
    let (c, sc) = run(&garment, Some(&body), &strict);
    eprintln!(
        "waves: ϖ {:.3e} in {} outer ({} centres); strict order: {:.3e} in {} ({})",
        sa.max_flattenability_after,
        sa.iterations,
        sa.centres,
        sc.max_flattenability_after,
        sc.iterations,
        sc.centres
    );
    assert!(sc.max_flattenability_after <= sc.max_flattenability_before);
    assert!(varpi_max(&c) <= varpi_max(&garment));
}

/// A real garment against a body that follows it (no body of its own fits any shared garment
/// fl-mesh makes flattenable: the MakeHuman suits are not, and the sport suit's fl-mesh output
/// sits up to 7 cm inside the MakeHuman proxy body): gf_skirt_3D_0 made flattenable by fl-mesh,
/// a body 0.3 h̄ under it, four dents of 0.6 h̄ pushed into the body. Global must end flattenable
/// (ϖ_max ≤ 1e-6) with no interior vertex inside the body, and no vertex that started outside
/// may end inside (brute-force distances over every body triangle).
#[test]
fn real_skirt_with_dents_into_a_body_that_follows_it() {
    use rayon::prelude::*;
    let Some(path) = flatmesh::corpus::shared_mesh_for_tests("garment/gf_skirt_3D_0.obj") else {
        return;
    };
    let raw = flatmesh::io::load_path(&path).unwrap().0;
    let (flat, _) = flatmesh::algorithms::fl_mesh::solve(
        &raw,
        &flatmesh::algorithms::fl_mesh::Params::default(),
        &Silent::default(),
    )
    .unwrap();
    assert!(varpi_max(&flat) <= 1e-6);
    let h = flatmesh::geometry::mean_edge_length(&flat);
    let body = flatmesh::corpus::body_under(&flat, 0.3 * h);
    let garment = flatmesh::corpus::with_bumps(&flat, 4, -0.6, 4.0, 5);
    let signed = |m: &Mesh| -> Vec<f64> {
        m.positions()
            .par_iter()
            .map(|&p| flatmesh::corpus::brute_signed_distance_open(&body, p))
            .collect()
    };
    let before = signed(&garment);
    let (out, s) = run(&garment, Some(&body), &Params::default());
    let after = signed(&out);
    // Inside: deeper than `converged` allows (1e-6 h̄: a vertex the rows push out from inside
    // ends at the clearance, 0 here, to Newton accuracy).
    let inside = |v: &[f64]| {
        (0..v.len())
            .filter(|&i| garment.conn().is_interior(i as u32) && v[i] < -1e-6 * h)
            .count()
    };
    eprintln!(
        "skirt over its body: ϖ_max {:.3e} -> {:.3e} in {} its ({}), interior vertices inside {} -> {}",
        varpi_max(&garment),
        varpi_max(&out),
        s.iterations,
        s.stop_detail,
        inside(&before),
        inside(&after)
    );
    assert!(inside(&before) > 0, "the dents reach into the body");
    assert!(s.converged, "{}", s.stop_detail);
    assert!(varpi_max(&out) <= 1e-6);
    assert_eq!(inside(&after), 0);
    for v in 0..garment.num_vertices() {
        if before[v] >= 0.0 {
            assert!(
                after[v] >= -1e-9 * h,
                "vertex {v}: {} -> {}",
                before[v],
                after[v]
            );
        }
    }
}
