//! Interior of a piece: intrinsic parameterization with the boundary fixed (Eq. 15–18 of
//! wang-lpfb, the cotangent weights of Desbrun et al.), and the free-boundary LSCM baseline.
//!
//! With the fixed rows of Eq. 18 eliminated, the cotangent matrix of Eq. 17 (with its sign
//! flipped) is the P1 stiffness matrix restricted to the free vertices: symmetric positive
//! definite for any triangulation, obtuse angles included. It is factored once by sparse
//! Cholesky and both coordinates are solved with that one factor.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky};
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

/// A sparse Cholesky factor of a symmetric positive-definite matrix given by its lower
/// triangle (duplicates summed), kept so that several right-hand sides can be solved one after
/// another (the ARAP global steps) with one factorisation. Sequential: pieces already run in
/// parallel, and on two cores faer's own threads were no faster (../shared/CRATES.md); its
/// high-level solve, run from inside a rayon task, took longer than the factorisation.
struct SpdFactor {
    sym: SymbolicCholesky<usize>,
    values: Vec<f64>,
    buf: MemBuffer,
}

impl SpdFactor {
    fn new(n: usize, trip: &[Triplet<usize, usize, f64>], ncols: usize) -> Result<Self, String> {
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
            sym.solve_in_place_scratch::<f64>(ncols, par),
        ]))
        .map_err(|e| format!("out of memory for the Cholesky factor: {e:?}"))?;
        let mut values = vec![0.0f64; sym.len_val()];
        sym.factorize_numeric_llt(
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
        Ok(SpdFactor { sym, values, buf })
    }

    fn solve(&mut self, rhs: &mut Mat<f64>) {
        LltRef::new(&self.sym, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.buf),
        );
    }
}

/// Solve A X = rhs in place (see [`SpdFactor`]).
fn spd_solve(
    n: usize,
    trip: &[Triplet<usize, usize, f64>],
    rhs: &mut Mat<f64>,
) -> Result<(), String> {
    SpdFactor::new(n, trip, rhs.ncols())?.solve(rhs);
    Ok(())
}

/// The interior solve after LPFB.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Interior {
    /// Cotangent-harmonic with the boundary fixed (Eq. 15–18, the paper).
    Harmonic,
    /// That, then as-rigid-as-possible local/global steps with the boundary still fixed.
    /// Default: it lowers the largest stretch of every piece measured and the area
    /// distortion of near-developable ones (the figures in benches/flatten.rs) for 25–45 %
    /// more time; on strongly curved pieces it trades a few percent of area for that.
    #[default]
    Arap,
}

/// Most ARAP local/global iterations of [`CotanSystem::fill`].
pub const ARAP_ITERATIONS: usize = 20;

/// Where LPFB's boundary angles aim (the θ targets of Eq. 8).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BoundaryAngles {
    /// The surface angles corrected by [`CotanSystem::angle_shift`]: the interior's curvature
    /// is spread conformally instead of being left to the interior solve. Default: it lowers
    /// the area distortion of non-developable pieces several-fold (benches/flatten.rs).
    #[default]
    Conformal,
    /// The surface's inner angles a_i (Eq. 8 as written).
    Surface,
}

/// The cotangent system of a piece with its boundary vertices eliminated (the matrix of
/// Eq. 17 with the fixed rows of Eq. 18 removed, sign flipped): factored once and shared by
/// the conformal boundary angles ([`CotanSystem::angle_shift`]) and the interior solves
/// ([`CotanSystem::fill`]), since both eliminate the same vertices.
pub struct CotanSystem {
    w: Vec<[f64; 3]>,
    free_id: Vec<usize>,
    nf: usize,
    factor: Option<SpdFactor>,
}

impl CotanSystem {
    /// Assemble and factor; `boundary[v]` marks the vertices the solves will fix.
    pub fn new(pos: &[[f64; 3]], tris: &[[u32; 3]], boundary: &[bool]) -> Result<Self, String> {
        let mut free_id = vec![usize::MAX; pos.len()];
        let mut nf = 0;
        for (v, &b) in boundary.iter().enumerate() {
            if !b {
                free_id[v] = nf;
                nf += 1;
            }
        }
        let w = half_cots(pos, tris);
        // lower triangle only (the factorisation reads Side::Lower); the diagonal is summed
        // here so the triplet list holds about one entry per edge and face
        let mut trip = Vec::with_capacity(tris.len() * 3 + nf);
        let mut diag = vec![0.0; nf];
        for (t, wt) in tris.iter().zip(&w) {
            for i in 0..3 {
                let (a, b) = (t[opposite(i).0] as usize, t[opposite(i).1] as usize);
                let (fa, fb) = (free_id[a], free_id[b]);
                for fp in [fa, fb] {
                    if fp != usize::MAX {
                        diag[fp] += wt[i];
                    }
                }
                if fa != usize::MAX && fb != usize::MAX {
                    trip.push(Triplet::new(fa.max(fb), fa.min(fb), -wt[i]));
                }
            }
        }
        trip.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
        let factor = if nf > 0 {
            Some(SpdFactor::new(nf, &trip, 2)?)
        } else {
            None
        };
        Ok(CotanSystem {
            w,
            free_id,
            nf,
            factor,
        })
    }

    /// Per vertex, how far the flat boundary angle should differ from the surface's inner
    /// angle so that a map keeping the boundary lengths is conformal inside: the Yamabe step
    /// of Boundary First Flattening (Sawhney & Crane 2017, Sec. 4) with boundary scale factor
    /// u = 0. Solve L_II u_I = −Ω_I (Ω the angle defects 2π − θ), then the flat turning at a
    /// boundary vertex is k̃_b = k_b + (L u)_b, so its inner angle target is a_b − (L u)_b;
    /// the value returned is (L u)_b (0 at interior vertices). The shifts sum to Σ Ω_I, so
    /// the targets satisfy the closed-path theorem exactly (discrete Gauss–Bonnet). LPFB
    /// then keeps every boundary length exact and moves the angles as little as it must to
    /// close the loop, where BFF would move the lengths.
    pub fn angle_shift(
        &mut self,
        tris: &[[u32; 3]],
        angle_sums: &[f64],
    ) -> Result<Vec<f64>, String> {
        let mut shift = vec![0.0; self.free_id.len()];
        let Some(factor) = self.factor.as_mut() else {
            return Ok(shift);
        };
        let mut u = Mat::<f64>::zeros(self.nf, 1);
        for (v, &f) in self.free_id.iter().enumerate() {
            if f != usize::MAX {
                u[(f, 0)] = -(2.0 * std::f64::consts::PI - angle_sums[v]);
            }
        }
        factor.solve(&mut u);
        // (L u)_b = Σ_j w_bj (u_b − u_j) = −Σ_{j interior} w_bj u_j, as u_b = 0
        for (t, wt) in tris.iter().zip(&self.w) {
            for i in 0..3 {
                let (a, b) = (t[opposite(i).0] as usize, t[opposite(i).1] as usize);
                for (p, q) in [(a, b), (b, a)] {
                    if self.free_id[p] == usize::MAX && self.free_id[q] != usize::MAX {
                        shift[p] -= wt[i] * u[(self.free_id[q], 0)];
                    }
                }
            }
        }
        match shift.iter().position(|s| !s.is_finite()) {
            Some(v) => Err(format!(
                "the conformal boundary angle at vertex {v} is not finite (degenerate triangles)"
            )),
            None => Ok(shift),
        }
    }

    /// Eq. 15–18: planar positions of all vertices, the boundary ones taken from `fixed` and
    /// the others the cotangent-harmonic interpolation (x and y with the one factor). With
    /// `arap_iterations` > 0, at most that many as-rigid-as-possible iterations follow (Liu
    /// et al. 2008, "A local/global approach to mesh parameterization") with the boundary
    /// still fixed: the local step fits to each triangle the rotation closest to its map, the
    /// global step solves the same system with the rotated 3D edges on the right. They stop
    /// when the ARAP energy falls by less than 1e-4 relative, and the harmonic map is kept
    /// instead when ARAP would flip more triangles than it.
    pub fn fill(
        &mut self,
        pos: &[[f64; 3]],
        tris: &[[u32; 3]],
        fixed: &[Option<[f64; 2]>],
        arap_iterations: usize,
    ) -> Result<Vec<[f64; 2]>, String> {
        let free_id = &self.free_id;
        if let Some(v) =
            (0..fixed.len()).find(|&v| fixed[v].is_some() != (free_id[v] == usize::MAX))
        {
            return Err(format!(
                "vertex {v}: the interior solve fixes exactly the boundary vertices (internal error)"
            ));
        }
        let mut uv: Vec<[f64; 2]> = fixed.iter().map(|f| f.unwrap_or([0.0, 0.0])).collect();
        let Some(factor) = self.factor.as_mut() else {
            return Ok(uv);
        };
        // the right-hand side from the fixed vertices, the same for every solve
        let mut base = Mat::<f64>::zeros(self.nf, 2);
        for (t, wt) in tris.iter().zip(&self.w) {
            for i in 0..3 {
                let (a, b) = (t[opposite(i).0] as usize, t[opposite(i).1] as usize);
                for (p, q) in [(a, b), (b, a)] {
                    if let (f, Some(x)) = (free_id[p], fixed[q]) {
                        if f != usize::MAX {
                            base[(f, 0)] += wt[i] * x[0];
                            base[(f, 1)] += wt[i] * x[1];
                        }
                    }
                }
            }
        }
        let mut rhs = base.clone();
        factor.solve(&mut rhs);
        for (v, &f) in free_id.iter().enumerate() {
            if f != usize::MAX {
                uv[v] = [rhs[(f, 0)], rhs[(f, 1)]];
            }
        }
        if arap_iterations > 0 {
            let arap = arap_steps(
                tris,
                &self.w,
                &local_frames(pos, tris),
                free_id,
                &base,
                factor,
                &uv,
                arap_iterations,
            );
            if arap.iter().all(|p| p[0].is_finite() && p[1].is_finite())
                && flipped(&arap, tris) <= flipped(&uv, tris)
            {
                uv = arap;
            }
        }
        if uv.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
            return Err("the interior solve produced a non-finite position".into());
        }
        Ok(uv)
    }
}

/// Each triangle laid flat by its 3D edge lengths: corner 0 at the origin, corner 1 on +x.
fn local_frames(pos: &[[f64; 3]], tris: &[[u32; 3]]) -> Vec<[[f64; 2]; 3]> {
    tris.iter()
        .map(|t| {
            let p = t.map(|v| pos[v as usize]);
            let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
            let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
            let l1 = (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]).sqrt();
            let x = if l1 > 0.0 {
                e1.map(|c| c / l1)
            } else {
                [1.0, 0.0, 0.0]
            };
            let px = e2[0] * x[0] + e2[1] * x[1] + e2[2] * x[2];
            let l2sq = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
            [
                [0.0, 0.0],
                [l1, 0.0],
                [px, (l2sq - px * px).max(0.0).sqrt()],
            ]
        })
        .collect()
}

fn flipped(uv: &[[f64; 2]], tris: &[[u32; 3]]) -> usize {
    tris.iter()
        .filter(|t| {
            let [a, b, c] = t.map(|v| uv[v as usize]);
            (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) <= 0.0
        })
        .count()
}

/// Edge (a, b) of triangle corner i: the edge opposite corner i, whose weight is w[i].
#[inline]
fn opposite(i: usize) -> (usize, usize) {
    ((i + 1) % 3, (i + 2) % 3)
}

/// ARAP local/global iterations from `start` (see [`arap_fill`]).
// i runs over a triangle's corners and indexes its weights, frame and vertices alike
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
fn arap_steps(
    tris: &[[u32; 3]],
    w: &[[f64; 3]],
    frames: &[[[f64; 2]; 3]],
    free_id: &[usize],
    base: &Mat<f64>,
    factor: &mut SpdFactor,
    start: &[[f64; 2]],
    iterations: usize,
) -> Vec<[f64; 2]> {
    let mut uv = start.to_vec();
    let mut rot = vec![[1.0, 0.0]; tris.len()]; // (cos, sin) per triangle
    let mut last = f64::INFINITY;
    let rotate = |r: [f64; 2], d: [f64; 2]| [r[0] * d[0] - r[1] * d[1], r[1] * d[0] + r[0] * d[1]];
    for it in 0..iterations {
        // local step: per triangle the rotation R maximising tr(Rᵀ S), S = Σ_edges
        // w (u_a − u_b)(x_a − x_b)ᵀ; the energy is measured with the previous rotations
        let mut energy = 0.0;
        for (k, (t, wt)) in tris.iter().zip(w).enumerate() {
            let x = frames[k];
            let mut s = [0.0; 4];
            for i in 0..3 {
                let (a, b) = opposite(i);
                let du = [
                    uv[t[a] as usize][0] - uv[t[b] as usize][0],
                    uv[t[a] as usize][1] - uv[t[b] as usize][1],
                ];
                let dx = [x[a][0] - x[b][0], x[a][1] - x[b][1]];
                s[0] += wt[i] * du[0] * dx[0];
                s[1] += wt[i] * du[0] * dx[1];
                s[2] += wt[i] * du[1] * dx[0];
                s[3] += wt[i] * du[1] * dx[1];
                let r = rotate(rot[k], dx);
                energy += wt[i] * ((du[0] - r[0]).powi(2) + (du[1] - r[1]).powi(2));
            }
            // The rotation by atan2(y, x) is (x, y)/|(x, y)|: no trigonometry needed.
            let (c, sn) = (s[0] + s[3], s[2] - s[1]);
            let n = c.hypot(sn);
            rot[k] = if n > 0.0 { [c / n, sn / n] } else { [1.0, 0.0] };
        }
        if it > 0 && (energy.is_nan() || energy >= last * (1.0 - 1e-4)) {
            break;
        }
        last = energy;
        // global step: L u = base + Σ_t Σ_edges w R_t (x_a − x_b) on the free rows
        let mut rhs = base.clone();
        for (k, (t, wt)) in tris.iter().zip(w).enumerate() {
            let x = frames[k];
            for i in 0..3 {
                let (a, b) = opposite(i);
                let r = rotate(rot[k], [x[a][0] - x[b][0], x[a][1] - x[b][1]]);
                for (v, sign) in [(t[a], 1.0), (t[b], -1.0)] {
                    let f = free_id[v as usize];
                    if f != usize::MAX {
                        rhs[(f, 0)] += sign * wt[i] * r[0];
                        rhs[(f, 1)] += sign * wt[i] * r[1];
                    }
                }
            }
        }
        factor.solve(&mut rhs);
        for (v, &f) in free_id.iter().enumerate() {
            if f != usize::MAX {
                uv[v] = [rhs[(f, 0)], rhs[(f, 1)]];
            }
        }
    }
    uv
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
