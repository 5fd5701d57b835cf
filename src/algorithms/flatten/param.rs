//! Interior of a piece: intrinsic parameterization with the boundary fixed (Eq. 15–18 of
//! wang-lpfb, the cotangent weights of Desbrun et al.), and the free-boundary LSCM baseline.
//!
//! With the fixed rows of Eq. 18 eliminated, the cotangent matrix of Eq. 17 (with its sign
//! flipped) is the P1 stiffness matrix restricted to the free vertices: symmetric positive
//! definite for any triangulation, obtuse angles included. It is factored once by sparse
//! Cholesky and both coordinates are solved with that one factor.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::factorize_symbolic_cholesky;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

/// ½ cot of each corner angle of each triangle (the weight of the opposite edge).
pub fn half_cots(pos: &[[f64; 3]], tris: &[[u32; 3]]) -> Vec<[f64; 3]> {
    tris.iter()
        .map(|t| {
            let p = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
            let mut w = [0.0; 3];
            for i in 0..3 {
                let a = p[i];
                let b = p[(i + 1) % 3];
                let c = p[(i + 2) % 3];
                let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let d = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2];
                let cr = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                let s = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
                w[i] = if s > 0.0 { 0.5 * d / s } else { 0.0 };
            }
            w
        })
        .collect()
}

/// Solve A X = rhs in place for a symmetric positive-definite A given by its lower triangle
/// (duplicates summed): one symbolic and one numeric Cholesky, every column of `rhs` solved
/// with that one factor. Sequential: pieces already run in parallel, and on two cores faer's
/// own threads were no faster (../shared/CRATES.md); its high-level solve, run from inside a
/// rayon task, took longer than the factorisation.
fn spd_solve(
    n: usize,
    trip: &[Triplet<usize, usize, f64>],
    rhs: &mut Mat<f64>,
) -> Result<(), String> {
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, trip)
        .map_err(|e| format!("sparse assembly failed: {e:?}"))?;
    let sym = factorize_symbolic_cholesky(
        a.symbolic(),
        Side::Lower,
        Default::default(),
        Default::default(),
    )
    .map_err(|e| format!("symbolic Cholesky failed: {e:?}"))?;
    let par = Par::Seq;
    let mut buf = MemBuffer::try_new(StackReq::any_of(&[
        sym.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        sym.solve_in_place_scratch::<f64>(rhs.ncols(), par),
    ]))
    .map_err(|e| format!("out of memory for the Cholesky factor: {e:?}"))?;
    let mut values = vec![0.0f64; sym.len_val()];
    let llt = sym
        .factorize_numeric_llt(
            &mut values,
            a.as_ref(),
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| {
            format!("Cholesky failed ({e:?}): the cotangent system is not positive definite")
        })?;
    llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), par, MemStack::new(&mut buf));
    Ok(())
}

/// Eq. 15–18: planar positions of all vertices, the `fixed` ones kept where they are and the
/// others the cotangent-harmonic interpolation (x and y with one Cholesky factor).
pub fn harmonic_fill(
    pos: &[[f64; 3]],
    tris: &[[u32; 3]],
    fixed: &[Option<[f64; 2]>],
) -> Result<Vec<[f64; 2]>, String> {
    let nv = pos.len();
    let mut free_id = vec![usize::MAX; nv];
    let mut nf = 0;
    for v in 0..nv {
        if fixed[v].is_none() {
            free_id[v] = nf;
            nf += 1;
        }
    }
    let mut uv: Vec<[f64; 2]> = fixed.iter().map(|f| f.unwrap_or([0.0, 0.0])).collect();
    if nf == 0 {
        return Ok(uv);
    }
    let w = half_cots(pos, tris);
    // lower triangle only (the factorisation reads Side::Lower); the diagonal is summed here
    // so the triplet list holds about one entry per edge and face
    let mut trip = Vec::with_capacity(tris.len() * 3 + nf);
    let mut diag = vec![0.0; nf];
    let mut rhs = Mat::<f64>::zeros(nf, 2);
    for (t, wt) in tris.iter().zip(&w) {
        for i in 0..3 {
            let (a, b) = (t[(i + 1) % 3] as usize, t[(i + 2) % 3] as usize);
            let wij = wt[i];
            let (fa, fb) = (free_id[a], free_id[b]);
            for (fp, q) in [(fa, b), (fb, a)] {
                if fp == usize::MAX {
                    continue;
                }
                diag[fp] += wij;
                if free_id[q] == usize::MAX {
                    let u = fixed[q].unwrap_or([0.0, 0.0]);
                    rhs[(fp, 0)] += wij * u[0];
                    rhs[(fp, 1)] += wij * u[1];
                }
            }
            if fa != usize::MAX && fb != usize::MAX {
                trip.push(Triplet::new(fa.max(fb), fa.min(fb), -wij));
            }
        }
    }
    trip.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
    spd_solve(nf, &trip, &mut rhs)?;
    for v in 0..nv {
        let f = free_id[v];
        if f != usize::MAX {
            uv[v] = [rhs[(f, 0)], rhs[(f, 1)]];
        }
    }
    if uv.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
        return Err("the interior solve produced a non-finite position".into());
    }
    Ok(uv)
}

/// Least-squares conformal map with a free boundary (Lévy et al. 2002), written as the
/// conformal energy E_C = E_D − A (Dirichlet energy minus the signed area of the image,
/// Desbrun et al. 2002 show the equivalence). Two vertices of the outer loop, the farthest
/// apart found by two sweeps, are pinned on the x axis. LSCM is defined up to a similarity
/// and the pins fix it, but their distance in the plane is not known beforehand (the 3D
/// chord is shorter than the developed distance on a curved patch), so the result is then
/// scaled uniformly about the first pin until its total boundary length equals the 3D one:
/// the scale a pattern maker would choose, exact on a developable piece, and it leaves A(Ω)
/// meaningful for comparison with LPFB.
pub fn lscm(
    pos: &[[f64; 3]],
    tris: &[[u32; 3]],
    loops: &[Vec<u32>],
) -> Result<Vec<[f64; 2]>, String> {
    let nv = pos.len();
    let outer = &loops[0];
    let far = |from: u32| -> u32 {
        *outer
            .iter()
            .max_by(|&&a, &&b| {
                super::cut::dist(pos[from as usize], pos[a as usize])
                    .partial_cmp(&super::cut::dist(pos[from as usize], pos[b as usize]))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .unwrap_or(&outer[0])
    };
    let pa = far(outer[0]);
    let pb = far(pa);
    if pa == pb {
        return Err("LSCM: cannot find two distinct boundary vertices to pin".into());
    }
    let d = super::cut::dist(pos[pa as usize], pos[pb as usize]);
    // unknown index: 2v (u), 2v+1 (v)
    let mut pinned: Vec<Option<f64>> = vec![None; 2 * nv];
    pinned[2 * pa as usize] = Some(0.0);
    pinned[2 * pa as usize + 1] = Some(0.0);
    pinned[2 * pb as usize] = Some(d);
    pinned[2 * pb as usize + 1] = Some(0.0);
    let mut fid = vec![usize::MAX; 2 * nv];
    let mut nf = 0;
    for i in 0..2 * nv {
        if pinned[i].is_none() {
            fid[i] = nf;
            nf += 1;
        }
    }
    let mut trip = Vec::with_capacity(tris.len() * 18);
    let mut rhs = Mat::<f64>::zeros(nf, 1);
    let mut add = |i: usize, j: usize, val: f64, trip: &mut Vec<Triplet<usize, usize, f64>>| {
        let fi = fid[i];
        if fi == usize::MAX {
            return;
        }
        match pinned[j] {
            Some(x) => rhs[(fi, 0)] -= val * x,
            // lower triangle only: the factorisation reads Side::Lower
            None if fid[j] <= fi => trip.push(Triplet::new(fi, fid[j], val)),
            None => {}
        }
    };
    let w = half_cots(pos, tris);
    for (t, wt) in tris.iter().zip(&w) {
        for i in 0..3 {
            let (a, b) = (t[(i + 1) % 3] as usize, t[(i + 2) % 3] as usize);
            let wij = wt[i];
            for c in 0..2 {
                add(2 * a + c, 2 * a + c, wij, &mut trip);
                add(2 * b + c, 2 * b + c, wij, &mut trip);
                add(2 * a + c, 2 * b + c, -wij, &mut trip);
                add(2 * b + c, 2 * a + c, -wij, &mut trip);
            }
        }
    }
    // − Hessian of A = ½ Σ_{i→j on ∂} (u_i v_j − u_j v_i)
    for lp in loops {
        for k in 0..lp.len() {
            let (i, j) = (lp[k] as usize, lp[(k + 1) % lp.len()] as usize);
            add(2 * i, 2 * j + 1, -0.5, &mut trip);
            add(2 * j + 1, 2 * i, -0.5, &mut trip);
            add(2 * j, 2 * i + 1, 0.5, &mut trip);
            add(2 * i + 1, 2 * j, 0.5, &mut trip);
        }
    }
    spd_solve(nf, &trip, &mut rhs)?;
    let val = |i: usize| pinned[i].unwrap_or_else(|| rhs[(fid[i], 0)]);
    let mut uv: Vec<[f64; 2]> = (0..nv).map(|v| [val(2 * v), val(2 * v + 1)]).collect();
    let (mut per2, mut per3) = (0.0, 0.0);
    for lp in loops {
        for k in 0..lp.len() {
            let (i, j) = (lp[k] as usize, lp[(k + 1) % lp.len()] as usize);
            per3 += super::cut::dist(pos[i], pos[j]);
            per2 += ((uv[i][0] - uv[j][0]).powi(2) + (uv[i][1] - uv[j][1]).powi(2)).sqrt();
        }
    }
    if !(per2 > 0.0 && per2.is_finite()) {
        return Err("LSCM collapsed the boundary to a point".into());
    }
    let k = per3 / per2;
    for q in &mut uv {
        q[0] *= k;
        q[1] *= k;
    }
    if uv.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
        return Err("LSCM produced a non-finite position".into());
    }
    Ok(uv)
}
