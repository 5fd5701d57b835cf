//! The analytic gradients of θ (Prop. 1 and 2 of wang-flattenable-laplacian-meshes) against
//! central finite differences and against the paper's cotangent formulas, on random meshes.

use flatmesh::geometry::{angle_sum_at, theta_gradient};
use flatmesh::mesh::{Mesh, RawMesh};
use proptest::prelude::*;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
/// By atan2 of |u × v| and u · v: acos loses half the digits near 0 and π (an error of
/// 1e-8 rad there made the paper's formula disagree with ours at 1e-9 on a random fan).
fn angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (u, v) = (sub(b, a), sub(c, a));
    let w = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    norm(w).atan2(dot(u, v))
}

/// A closed fan around vertex 0 with `k` neighbours at random angles, radii and heights.
fn fan(k: usize, params: &[(f64, f64, f64)]) -> RawMesh {
    let mut positions = vec![[0.0, 0.0, params[0].2 * 0.5]];
    let mut acc = 0.0;
    let total: f64 = params.iter().take(k).map(|p| p.0).sum();
    for p in params.iter().take(k) {
        acc += p.0 / total * std::f64::consts::TAU;
        positions.push([p.1 * acc.cos(), p.1 * acc.sin(), p.2]);
    }
    let triangles = (0..k as u32)
        .map(|i| [0, 1 + i, 1 + (i + 1) % k as u32])
        .collect();
    RawMesh {
        positions,
        triangles,
        ..RawMesh::default()
    }
}

/// Central differences of θ(q) with respect to the position of vertex `p`.
fn fd_gradient(mesh: &Mesh, q: u32, p: u32) -> [f64; 3] {
    let r = mesh.conn().ring_of(q)[0];
    let h = 1e-6 * norm(sub(mesh.position(r), mesh.position(q)));
    let mut g = [0.0; 3];
    for (k, gk) in g.iter_mut().enumerate() {
        let mut plus = mesh.positions().to_vec();
        let mut minus = plus.clone();
        plus[p as usize][k] += h;
        minus[p as usize][k] -= h;
        let mp = mesh.with_positions(plus).unwrap();
        let mm = mesh.with_positions(minus).unwrap();
        *gk = (angle_sum_at(&mp, q) - angle_sum_at(&mm, q)) / (2.0 * h);
    }
    g
}

/// Eq. 13 written out independently: for neighbour p of q, the angles at q beside edge qp.
fn paper_eq13(mesh: &Mesh, q: u32, p: u32) -> [f64; 3] {
    let (vq, vp) = (mesh.position(q), mesh.position(p));
    let lpq = norm(sub(vp, vq));
    let mut g = [0.0; 3];
    for t in mesh.triangles() {
        if !(t.contains(&q) && t.contains(&p)) {
            continue;
        }
        let a = *t.iter().find(|&&x| x != q && x != p).unwrap();
        let va = mesh.position(a);
        let xi = angle(vq, vp, va);
        let laq = norm(sub(va, vq));
        for i in 0..3 {
            g[i] += xi.cos() / xi.sin() / (lpq * lpq) * (vp[i] - vq[i])
                - (va[i] - vq[i]) / (lpq * laq * xi.sin());
        }
    }
    g
}

/// Eq. 12 with the |pq|² of Appendix B: Σ_q (cot ξ_{q,p} + cot γ_{q,p}) / |pq|² (v_q − v_p),
/// the angles taken at the neighbour q.
fn paper_eq12(mesh: &Mesh, p: u32) -> [f64; 3] {
    let vp = mesh.position(p);
    let mut g = [0.0; 3];
    for t in mesh.triangles() {
        let Some(k) = t.iter().position(|&x| x == p) else {
            continue;
        };
        for (q, a) in [
            (t[(k + 1) % 3], t[(k + 2) % 3]),
            (t[(k + 2) % 3], t[(k + 1) % 3]),
        ] {
            let (vq, va) = (mesh.position(q), mesh.position(a));
            let ang = angle(vq, vp, va);
            let l2 = dot(sub(vq, vp), sub(vq, vp));
            for i in 0..3 {
                g[i] += ang.cos() / ang.sin() / l2 * (vq[i] - vp[i]);
            }
        }
    }
    g
}

fn close(a: [f64; 3], b: [f64; 3], rel: f64) -> bool {
    let scale = norm(a).max(norm(b)).max(1.0);
    norm(sub(a, b)) <= rel * scale
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn gradients_match_finite_differences_and_paper(
        k in 3usize..10,
        params in proptest::collection::vec((0.3f64..1.0, 0.5f64..2.0, -0.8f64..0.8), 10),
    ) {
        let raw = fan(k, &params);
        let Ok((mesh, _)) = Mesh::new(raw) else { return Ok(()) };
        prop_assume!(mesh.conn().is_interior(0));
        let mut grads = Vec::new();
        theta_gradient(&mesh, 0, &mut grads);
        prop_assert_eq!(grads.len(), k + 1);
        for &(p, g) in &grads {
            let fd = fd_gradient(&mesh, 0, p);
            prop_assert!(close(g, fd, 1e-6), "vertex {}: analytic {:?} vs FD {:?}", p, g, fd);
            let paper = if p == 0 { paper_eq12(&mesh, 0) } else { paper_eq13(&mesh, 0, p) };
            prop_assert!(close(g, paper, 1e-9), "vertex {}: analytic {:?} vs paper {:?}", p, g, paper);
        }
        // Translating the whole fan leaves θ unchanged: the gradients sum to zero.
        let mut s = [0.0; 3];
        for (_, g) in &grads { for i in 0..3 { s[i] += g[i]; } }
        prop_assert!(norm(s) <= 1e-9 * grads.iter().map(|g| norm(g.1)).fold(1.0, f64::max));
    }
}

/// Every interior vertex of a noisy grid, including obtuse and very acute corners.
#[test]
fn gradients_on_noisy_grid() {
    let n = 8usize;
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut positions = Vec::new();
    for j in 0..n {
        for i in 0..n {
            positions.push([i as f64 + 0.6 * rnd(), j as f64 + 0.6 * rnd(), 0.8 * rnd()]);
        }
    }
    let mut triangles = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    let (mesh, _) = Mesh::new(RawMesh {
        positions,
        triangles,
        ..RawMesh::default()
    })
    .unwrap();
    let mut grads = Vec::new();
    let mut checked = 0;
    for q in mesh.conn().interior_vertices() {
        theta_gradient(&mesh, q, &mut grads);
        for &(p, g) in &grads {
            let fd = fd_gradient(&mesh, q, p);
            assert!(close(g, fd, 1e-6), "θ({q}) wrt {p}: {g:?} vs {fd:?}");
            checked += 1;
        }
    }
    assert_eq!(
        checked,
        36 * 7,
        "6x6 interior vertices, each with 6 neighbours plus itself"
    );
}

/// The turning-angle gradient against central differences, on random hinges bent both ways
/// (folds included).
#[test]
fn turning_angle_gradient_matches_finite_differences() {
    let mut s = 0x2545f4914f6cdd1du64;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut checked = 0;
    for _ in 0..200 {
        let p: Vec<[f64; 3]> = (0..4).map(|_| [rnd(), rnd(), rnd()]).collect();
        let (phi, g) = flatmesh::geometry::turning_angle_gradient(p[0], p[1], p[2], p[3]);
        if !(0.05..std::f64::consts::PI - 0.05).contains(&phi) {
            continue;
        }
        for v in 0..4 {
            for c in 0..3 {
                let h = 1e-6;
                let mut q = p.clone();
                q[v][c] += h;
                let up = flatmesh::geometry::turning_angle_gradient(q[0], q[1], q[2], q[3]).0;
                q[v][c] -= 2.0 * h;
                let dn = flatmesh::geometry::turning_angle_gradient(q[0], q[1], q[2], q[3]).0;
                let fd = (up - dn) / (2.0 * h);
                let scale = 1.0 + norm(g[v]);
                assert!(
                    (fd - g[v][c]).abs() <= 1e-5 * scale,
                    "vertex {v} coord {c}: analytic {} fd {fd} (φ = {phi})",
                    g[v][c]
                );
            }
        }
        checked += 1;
    }
    assert!(checked > 100, "only {checked} hinges checked");
}

/// The 6×6 matrix of `corner_angle_hessian`'s blocks in (u, w) = (b − a, c − a).
fn hessian6(h: &[[[f64; 3]; 3]; 3]) -> [[f64; 6]; 6] {
    let mut m = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = h[0][i][j];
            m[i][3 + j] = h[1][i][j];
            m[3 + j][i] = h[1][i][j];
            m[3 + i][3 + j] = h[2][i][j];
        }
    }
    m
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// ∂²α against second central differences of the angle itself (atan2, not the gradient
    /// code), and the positive part of y∇²α: positive semidefinite and ≥ y∇²α (the
    /// difference is positive semidefinite), checked on random directions.
    #[test]
    fn corner_angle_hessian_matches_finite_differences(
        pts in proptest::collection::vec(-1.0f64..1.0, 9),
        y in -3.0f64..3.0,
        dirs in proptest::collection::vec(-1.0f64..1.0, 60),
    ) {
        let a = [pts[0], pts[1], pts[2]];
        let b = [pts[3], pts[4], pts[5]];
        let c = [pts[6], pts[7], pts[8]];
        let alpha = angle(a, b, c);
        prop_assume!(alpha > 0.2 && alpha < std::f64::consts::PI - 0.2);
        prop_assume!(norm(sub(b, a)) > 0.2 && norm(sub(c, a)) > 0.2);
        let h = flatmesh::geometry::corner_angle_hessian(a, b, c, None).unwrap();
        let m = hessian6(&h);
        let f = |x: &[f64; 6]| {
            angle([0.0; 3], [b[0] - a[0] + x[0], b[1] - a[1] + x[1], b[2] - a[2] + x[2]],
                  [c[0] - a[0] + x[3], c[1] - a[1] + x[4], c[2] - a[2] + x[5]])
        };
        // Steps relative to the shorter edge, Richardson-extrapolated (error O(e⁴)): a fixed
        // 1e-4 missed by 2e-5 relative on a 0.21-long edge.
        let e = 1e-3 * norm(sub(b, a)).min(norm(sub(c, a)));
        for i in 0..6 {
            for j in 0..6 {
                let second = |e: f64| {
                    let at = |si: f64, sj: f64| {
                        let mut x = [0.0; 6];
                        x[i] += si * e;
                        x[j] += sj * e;
                        f(&x)
                    };
                    (at(1.0, 1.0) - at(1.0, -1.0) - at(-1.0, 1.0) + at(-1.0, -1.0)) / (4.0 * e * e)
                };
                let fd = (4.0 * second(0.5 * e) - second(e)) / 3.0;
                prop_assert!((m[i][j] - fd).abs() <= 1e-5 * (1.0 + fd.abs()),
                    "({i},{j}): analytic {} vs FD {fd}", m[i][j]);
            }
        }
        let p = hessian6(&flatmesh::geometry::corner_angle_hessian(a, b, c, Some(y)).unwrap());
        for d in dirs.chunks(6) {
            let quad = |m: &[[f64; 6]; 6]| -> f64 {
                (0..6).map(|i| (0..6).map(|j| d[i] * m[i][j] * d[j]).sum::<f64>()).sum()
            };
            let (qp, qm) = (quad(&p), y * quad(&m));
            prop_assert!(qp >= -1e-9 * (1.0 + qm.abs()), "not PSD: {qp}");
            prop_assert!(qp >= qm - 1e-9 * (1.0 + qm.abs()), "below y∇²α: {qp} < {qm}");
        }
    }
}
