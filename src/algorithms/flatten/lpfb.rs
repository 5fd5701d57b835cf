//! Length-preserved free boundary (LPFB), Sec. 3.1–3.3 of wang-lpfb: the boundary of a disk
//! is laid out edge by edge with its 3D lengths (Eq. 6–7), and only the inner turning angles
//! θ_i are unknown. They minimise Σ ½(θ_i − a_i)² subject to the closed-path theorem and
//! closure (Eq. 9), plus the coincidence of cut-path copies for patches with holes (Eq. 10).
//!
//! The SQP step of Eq. 12 is solved through the reduced system ΛΛᵀ δλ = ΛB_θ − B_λ (Eq. 13)
//! and δθ = B_θ − Λᵀδλ (Eq. 14), densely: LU with full pivoting when ΛΛᵀ has full rank, an SVD
//! pseudo-inverse otherwise. Start θ_i = a_i, λ = 1; stop when ‖∇J‖ < tolerance.
//!
//! Choices where the paper is silent, stated here:
//! - Lengths are divided by their mean inside the solver, so the tolerance on ‖∇J‖ means the
//!   same for a piece in metres or in millimetres (the optimal θ does not depend on scale).
//! - Along a cut path, the coincidence of every copy pair (Eq. 10 taken literally) is redundant
//!   once the two copies of each cut edge have equal length, as they do by construction:
//!   ΛΛᵀ loses one rank per path vertex at the solution. We impose the same feasible set with
//!   independent rows: for each path, Eq. 10's coincidence of the two copies of its first
//!   vertex, and for each cut edge that its two copies are antiparallel,
//!   φ_b − φ_a = π + 2πk (linear in θ; k is fixed from θ = a). Equal lengths and antiparallel
//!   copies carry the coincidence along the whole path.
//! - Once ‖∇J‖ is below the tolerance, a few Gauss–Newton steps on the constraints alone
//!   (δθ = −Λᵀ(ΛΛᵀ)⁺g, quadratically convergent) close the loop to rounding error, so that the
//!   closing edge keeps its length to ~1e-14 relative like every other edge.

use super::super::{AlgoError, Control, Progress};
use faer::Mat;
use std::f64::consts::PI;

/// The LPFB problem on one boundary loop (the cut loop for a patch with holes).
#[derive(Debug, Clone)]
pub struct Problem {
    /// l_k: 3D length of loop edge k (from entry k to entry k+1).
    pub lengths: Vec<f64>,
    /// a_i: surface inner angle at entry i.
    pub angles: Vec<f64>,
    /// Eq. 10 coincidence pairs (α, β), α < β ≤ n: Σ_{k=α}^{β−1} l_k (cos φ_k, sin φ_k) = 0.
    pub pairs: Vec<(usize, usize)>,
    /// Cut-edge copies (a, b), a < b: their directions differ by π (mod 2π).
    pub antiparallel: Vec<(usize, usize)>,
}

/// The solved boundary.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Inner turning angles θ_i.
    pub theta: Vec<f64>,
    /// Planar position of each loop entry (Eq. 6), entry 0 at the origin.
    pub positions: Vec<[f64; 2]>,
    /// SQP iterations taken (Eq. 12).
    pub iterations: usize,
    /// Whether ‖∇J‖ fell below the tolerance.
    pub converged: bool,
    /// Final ‖∇J‖ (lengths normalised by their mean).
    pub grad_norm: f64,
    /// Iterations where ΛΛᵀ was rank deficient and the SVD pseudo-inverse was used.
    pub svd_steps: usize,
    /// Largest constraint residual after the closing steps (normalised lengths, radians).
    pub constraint_residual: f64,
    /// Step halvings taken by the line search over all iterations.
    pub backtracks: usize,
}

/// Neumaier's compensated sum: the running sums of Eq. 6–7 run over the whole loop, and plain
/// summation lets rounding random-walk to ~n^1.5 ε, which would cap how well the loop closes
/// for boundaries of thousands of edges.
#[derive(Default, Clone, Copy)]
struct Acc {
    s: f64,
    c: f64,
}

impl Acc {
    #[inline]
    fn add(&mut self, x: f64) {
        let t = self.s + x;
        if self.s.abs() >= x.abs() {
            self.c += (self.s - t) + x;
        } else {
            self.c += (x - t) + self.s;
        }
        self.s = t;
    }
    #[inline]
    fn value(&self) -> f64 {
        self.s + self.c
    }
}

struct Work {
    n: usize,
    r: usize,
    lam_mat: Vec<f64>, // r × n, row-major
    g: Vec<f64>,
    phi: Vec<f64>,
    ex: Vec<f64>,
    ey: Vec<f64>,
}

impl Work {
    /// Evaluate φ (Eq. 7), the constraints g and their Jacobian Λ (Appendix, Statement 3).
    /// `tau` holds the turning angles τ_i = π − θ_i.
    fn eval(&mut self, p: &Problem, l: &[f64], tau: &[f64], ap_target: &[f64]) {
        let n = self.n;
        // φ_k (0-based) = (k+1)π − Σ_{b ≤ k} θ_b, summed as turning angles Σ (π − θ_b) so
        // that no term is large: (k+1)π − Σθ would cancel ~nπ and lose ~n·1e-16 rad.
        let mut s = Acc::default();
        for k in 0..n {
            s.add(tau[k]);
            self.phi[k] = s.value();
            self.ex[k] = l[k] * self.phi[k].cos();
            self.ey[k] = l[k] * self.phi[k].sin();
        }
        // row 0: closed-path theorem, (n − 2)π − Σθ = Σ(π − θ) − 2π = 0
        self.g[0] = s.value() - 2.0 * PI;
        self.lam_mat[..n].iter_mut().for_each(|x| *x = -1.0);
        let mut row = 1;
        let ranges = std::iter::once((0usize, n)).chain(p.pairs.iter().copied());
        for (a, b) in ranges {
            let (rx, ry) = (row, row + 1);
            let (mut sx, mut sy) = (Acc::default(), Acc::default());
            // suffix sums over k ∈ [a, b), k ≥ i: ∂(l cos φ_k)/∂θ_i = l sin φ_k for i ≤ k
            for i in (0..n).rev() {
                if i >= a && i < b {
                    sx.add(self.ex[i]);
                    sy.add(self.ey[i]);
                }
                self.lam_mat[rx * n + i] = sy.value();
                self.lam_mat[ry * n + i] = -sx.value();
            }
            self.g[rx] = sx.value();
            self.g[ry] = sy.value();
            row += 2;
        }
        for (j, &(a, b)) in p.antiparallel.iter().enumerate() {
            self.g[row] = self.phi[b] - self.phi[a] - ap_target[j];
            let r = &mut self.lam_mat[row * n..(row + 1) * n];
            for (i, x) in r.iter_mut().enumerate() {
                *x = if i > a && i <= b { -1.0 } else { 0.0 };
            }
            row += 1;
        }
        debug_assert_eq!(row, self.r);
    }

    /// ΛΛᵀ as a dense matrix, by faer's blocked product: with the coincidence rows of a
    /// virtual cut r reaches hundreds, and entry-by-entry dot products were 30 % of a
    /// segmentation's time on a 34k-face scan.
    fn gram(&self) -> Mat<f64> {
        let (n, r) = (self.n, self.r);
        let lam = faer::MatRef::from_row_major_slice(&self.lam_mat[..r * n], r, n);
        lam * lam.transpose()
    }
}

/// Solve M x = rhs densely: LU with full pivoting when M has full rank, else the SVD
/// pseudo-inverse (Eq. 13). Returns whether the SVD was used.
fn dense_solve(m: &Mat<f64>, rhs: &[f64]) -> Result<(Vec<f64>, bool), String> {
    let r = m.nrows();
    let lu = m.full_piv_lu();
    let u = lu.U();
    let mut dmax: f64 = 0.0;
    let mut dmin = f64::INFINITY;
    for i in 0..r {
        let d = u[(i, i)].abs();
        dmax = dmax.max(d);
        dmin = dmin.min(d);
    }
    if dmax > 0.0 && dmin > 1e-12 * dmax && dmin.is_finite() {
        use faer::linalg::solvers::Solve;
        let mut x = Mat::from_fn(r, 1, |i, _| rhs[i]);
        lu.solve_in_place(x.as_mut());
        let v: Vec<f64> = (0..r).map(|i| x[(i, 0)]).collect();
        if v.iter().all(|x| x.is_finite()) {
            return Ok((v, false));
        }
    }
    let svd = m.svd().map_err(|e| format!("SVD failed: {e:?}"))?;
    let (uu, s, vv) = (svd.U(), svd.S(), svd.V());
    let s = s.column_vector();
    let smax = (0..r).map(|i| s[i].abs()).fold(0.0, f64::max);
    let mut x = vec![0.0; r];
    for k in 0..r {
        let sk = s[k];
        if sk.abs() <= 1e-12 * smax || sk == 0.0 {
            continue;
        }
        let c: f64 = (0..r).map(|i| uu[(i, k)] * rhs[i]).sum::<f64>() / sk;
        for (i, xi) in x.iter_mut().enumerate() {
            *xi += vv[(i, k)] * c;
        }
    }
    Ok((x, true))
}

/// out −= Λᵀ c, Λ row-major with rows of length n.
fn sub_lam_t(lam_mat: &[f64], n: usize, c: &[f64], out: &mut [f64]) {
    for (row, &cj) in lam_mat.chunks_exact(n).zip(c) {
        if cj != 0.0 {
            for (o, x) in out.iter_mut().zip(row) {
                *o -= x * cj;
            }
        }
    }
}

/// Solve the LPFB problem (Eq. 9/10 by Eq. 11–14) and lay the boundary out (Eq. 6–7).
pub fn solve(
    p: &Problem,
    max_iterations: usize,
    tolerance: f64,
    control: &dyn Control,
    stage: &str,
) -> Result<Solution, AlgoError> {
    let n = p.lengths.len();
    if n < 3 || p.angles.len() != n {
        return Err(AlgoError::Input(format!(
            "{stage}: a boundary loop needs at least 3 edges (has {n})"
        )));
    }
    let mean = p.lengths.iter().sum::<f64>() / n as f64;
    if !(mean > 0.0 && mean.is_finite()) {
        return Err(AlgoError::Input(format!(
            "{stage}: boundary edge lengths are degenerate"
        )));
    }
    let l: Vec<f64> = p.lengths.iter().map(|x| x / mean).collect();
    let r = 3 + 2 * p.pairs.len() + p.antiparallel.len();
    let mut w = Work {
        n,
        r,
        lam_mat: vec![0.0; r * n],
        g: vec![0.0; r],
        phi: vec![0.0; n],
        ex: vec![0.0; n],
        ey: vec![0.0; n],
    };
    // The unknowns are stored as turning angles τ_i = π − θ_i: near a smooth boundary τ is
    // small, so its unit in the last place is far below θ's (≈ 4e-16), and the last Newton
    // corrections (~1e-17 per angle on a loop of a thousand edges) are not rounded away.
    let tau0: Vec<f64> = p.angles.iter().map(|a| PI - a).collect();
    let mut tau = tau0.clone();
    // k of each antiparallel pair from θ = a, where the 3D surface fixes it (Sec. 3.2).
    let mut ap_target = vec![0.0; p.antiparallel.len()];
    {
        let mut phi = vec![0.0; n];
        let mut s = Acc::default();
        for k in 0..n {
            s.add(tau[k]);
            phi[k] = s.value();
        }
        for (j, &(a, b)) in p.antiparallel.iter().enumerate() {
            let d = phi[b] - phi[a] - PI;
            ap_target[j] = PI + (d / (2.0 * PI)).round() * 2.0 * PI;
        }
    }
    // Beyond the paper, which starts at θ = a: spread the closed-path deficit 2π − Σ(π − a)
    // over the vertices in proportion to their share of the boundary length. This satisfies
    // the linear constraint at once and, where the surface is curved, starts near the circle
    // the optimum resembles (a hemisphere's geodesic rim has a ≈ π everywhere: θ = a is a
    // straight line, from which full SQP steps wander into self-crossing stationary points).
    // The optimum is the same; only the path to it changes.
    {
        let mut s = Acc::default();
        tau0.iter().for_each(|&t| s.add(t));
        let deficit = 2.0 * PI - s.value();
        let total: f64 = l.iter().sum();
        for i in 0..n {
            tau[i] += deficit * 0.5 * (l[(i + n - 1) % n] + l[i]) / total;
        }
    }
    let mut lambda = vec![1.0; r];
    let mut tau_try = vec![0.0; n];
    let mut mu = 0.0f64;
    let mut backtracks = 0;
    let mut fresh = false;
    let mut b_theta = vec![0.0; n];
    let mut iterations = 0;
    let mut converged = false;
    let mut grad_norm;
    let mut svd_steps = 0;
    let mut rhs = vec![0.0; r];
    loop {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        // the line search already evaluated the accepted point
        if !std::mem::take(&mut fresh) {
            w.eval(p, &l, &tau, &ap_target);
        }
        // B_θ = −∂J/∂θ = −(θ − a) − Λᵀλ ; B_λ = −g  (Appendix, Statements 1–2)
        // θ − a = (π − τ) − (π − τ0) = τ0 − τ
        for ((b, t), t0) in b_theta.iter_mut().zip(&tau).zip(&tau0) {
            *b = t - t0;
        }
        sub_lam_t(&w.lam_mat, n, &lambda, &mut b_theta);
        grad_norm = (b_theta.iter().map(|x| x * x).sum::<f64>()
            + w.g.iter().map(|x| x * x).sum::<f64>())
        .sqrt();
        if !grad_norm.is_finite() {
            return Err(AlgoError::Input(format!(
                "{stage}: LPFB diverged (‖∇J‖ not finite at iteration {iterations})"
            )));
        }
        control.progress(&Progress {
            stage: stage.to_string(),
            iteration: iterations,
            max_flattenability: None,
            step_norm: Some(grad_norm),
        });
        if grad_norm < tolerance {
            converged = true;
            break;
        }
        if iterations >= max_iterations {
            break;
        }
        // Eq. 13: ΛΛᵀ δλ = Λ B_θ − B_λ
        let m = w.gram();
        for ((x, row), g) in rhs.iter_mut().zip(w.lam_mat.chunks_exact(n)).zip(&w.g) {
            *x = row.iter().zip(&b_theta).map(|(a, b)| a * b).sum::<f64>() + g;
        }
        let (dl, used_svd) =
            dense_solve(&m, &rhs).map_err(|e| AlgoError::Input(format!("{stage}: {e}")))?;
        svd_steps += used_svd as usize;
        // Eq. 14: δθ = B_θ − Λᵀ δλ
        sub_lam_t(&w.lam_mat, n, &dl, &mut b_theta);
        // Step length (beyond the paper's full step): backtrack on the ℓ1 merit
        // ½‖θ − a‖² + μ‖g‖₁, with μ above the new multipliers so that the SQP direction
        // descends; full steps are kept once the constraints hold to 1e-10, where the merit
        // could refuse them for second-order reasons (Maratos) and Newton converges anyway.
        let lam_max = lambda
            .iter()
            .zip(&dl)
            .fold(0.0f64, |m, (a, b)| m.max((a + b).abs()));
        mu = mu.max(1.5 * lam_max + 1e-3);
        let merit = |w: &Work, t: &[f64]| -> f64 {
            0.5 * t
                .iter()
                .zip(&tau0)
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                + mu * w.g.iter().map(|g| g.abs()).sum::<f64>()
        };
        let m0 = merit(&w, &tau);
        let mut alpha = 1.0;
        loop {
            for ((t, &t0), d) in tau_try.iter_mut().zip(&tau).zip(&b_theta) {
                *t = t0 - alpha * d; // θ += α δθ
            }
            w.eval(p, &l, &tau_try, &ap_target);
            let gmax = w.g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            if merit(&w, &tau_try) <= m0 || gmax <= 1e-10 || alpha < 1e-6 {
                break;
            }
            alpha *= 0.5;
            backtracks += 1;
        }
        fresh = true;
        std::mem::swap(&mut tau, &mut tau_try);
        for (l, d) in lambda.iter_mut().zip(&dl) {
            *l += alpha * d;
        }
        iterations += 1;
    }
    // Close the loop to rounding error: Gauss–Newton on g alone.
    let mut resid = f64::INFINITY;
    for _ in 0..20 {
        w.eval(p, &l, &tau, &ap_target);
        let nr = w.g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        if nr.partial_cmp(&resid) != Some(std::cmp::Ordering::Less) {
            break;
        }
        resid = nr;
        if nr <= 1e-15 * n as f64 {
            break;
        }
        let m = w.gram();
        let (dl, used_svd) =
            dense_solve(&m, &w.g).map_err(|e| AlgoError::Input(format!("{stage}: {e}")))?;
        svd_steps += used_svd as usize;
        // θ −= Λᵀ dl, i.e. τ += Λᵀ dl
        for (row, &c) in w.lam_mat.chunks_exact(n).zip(&dl) {
            for (t, x) in tau.iter_mut().zip(row) {
                *t += x * c;
            }
        }
    }
    w.eval(p, &l, &tau, &ap_target);
    let constraint_residual = w.g.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    // Eq. 6: positions with the true (unnormalised) lengths
    let mut positions = Vec::with_capacity(n);
    let (mut x, mut y) = (Acc::default(), Acc::default());
    for k in 0..n {
        positions.push([x.value(), y.value()]);
        x.add(p.lengths[k] * w.phi[k].cos());
        y.add(p.lengths[k] * w.phi[k].sin());
    }
    Ok(Solution {
        theta: tau.iter().map(|t| PI - t).collect(),
        positions,
        iterations,
        converged,
        grad_norm,
        svd_steps,
        constraint_residual,
        backtracks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Λ (Appendix, Statement 3) against central finite differences of g.
    #[test]
    fn jacobian_matches_finite_differences() {
        let n = 11;
        let p = Problem {
            lengths: (0..n)
                .map(|k| 1.0 + 0.3 * ((k * 7) % 5) as f64 / 5.0)
                .collect(),
            angles: vec![0.0; n],
            pairs: vec![(2, 7), (4, 11)],
            antiparallel: vec![(1, 8), (3, 6)],
        };
        let r = 3 + 2 * p.pairs.len() + p.antiparallel.len();
        let mk = || Work {
            n,
            r,
            lam_mat: vec![0.0; r * n],
            g: vec![0.0; r],
            phi: vec![0.0; n],
            ex: vec![0.0; n],
            ey: vec![0.0; n],
        };
        let theta: Vec<f64> = (0..n).map(|k| 2.4 + 0.1 * (k as f64).sin()).collect();
        let target = vec![PI; p.antiparallel.len()];
        let mut w = mk();
        let tau: Vec<f64> = theta.iter().map(|t| PI - t).collect();
        w.eval(&p, &p.lengths, &tau, &target);
        let h = 1e-6;
        for i in 0..n {
            let (mut a, mut b) = (mk(), mk());
            let mut tp = tau.clone();
            tp[i] -= h; // θ_i + h
            a.eval(&p, &p.lengths, &tp, &target);
            tp[i] += 2.0 * h; // θ_i − h
            b.eval(&p, &p.lengths, &tp, &target);
            for j in 0..r {
                let fd = (a.g[j] - b.g[j]) / (2.0 * h);
                let an = w.lam_mat[j * n + i];
                assert!((fd - an).abs() < 1e-7, "row {j} col {i}: fd {fd} vs Λ {an}");
            }
        }
    }

    /// A redundant constraint (the closure pair repeated) makes ΛΛᵀ singular: the SVD path
    /// must be taken and give the same boundary as the full-rank problem.
    #[test]
    fn rank_deficient_system_uses_the_svd() {
        let n = 16;
        let p = Problem {
            lengths: (0..n)
                .map(|k| 1.0 + 0.5 * (k as f64 * 0.7).sin().abs())
                .collect(),
            angles: (0..n)
                .map(|k| PI - 2.0 * PI / n as f64 + 0.05 * (k as f64).cos())
                .collect(),
            pairs: vec![],
            antiparallel: vec![],
        };
        let c = crate::algorithms::Silent::default();
        let full = solve(&p, 100, 1e-10, &c, "t").unwrap();
        let mut q = p.clone();
        q.pairs = vec![(0, n)];
        let red = solve(&q, 100, 1e-10, &c, "t").unwrap();
        assert!(full.converged && red.converged);
        assert_eq!(full.svd_steps, 0);
        assert!(red.svd_steps > 0);
        for (a, b) in full.theta.iter().zip(&red.theta) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }

    /// Equal lengths and equal surface angles: by symmetry the optimum is the regular polygon,
    /// θ_i = (n − 2)π / n, whatever a is.
    #[test]
    fn regular_polygon_is_the_optimum_for_equal_data() {
        let n = 24;
        let p = Problem {
            lengths: vec![0.3; n],
            angles: vec![3.0; n],
            pairs: vec![],
            antiparallel: vec![],
        };
        let s = solve(&p, 100, 1e-12, &crate::algorithms::Silent::default(), "t").unwrap();
        let want = (n as f64 - 2.0) * PI / n as f64;
        for t in &s.theta {
            assert!((t - want).abs() < 1e-12, "{t} vs {want}");
        }
        // circumradius of the regular 24-gon with side 0.3
        let rad = 0.3 / (2.0 * (PI / n as f64).sin());
        let c = s.positions.iter().fold([0.0, 0.0], |a, q| {
            [a[0] + q[0] / n as f64, a[1] + q[1] / n as f64]
        });
        for q in &s.positions {
            let d = ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)).sqrt();
            assert!((d - rad).abs() < 1e-12);
        }
    }

    /// A geodesic rim (a hemisphere's equator: every a_i = π) starts as a straight line under
    /// θ = a. The solver must still reach the optimum, a convex closed polygon, rather than a
    /// self-crossing stationary point (which full SQP steps from θ = a ran into).
    #[test]
    fn straight_rim_closes_into_a_convex_polygon() {
        let n = 48;
        let p = Problem {
            lengths: (0..n)
                .map(|k| 0.13 * (1.0 + 0.2 * (k as f64 * 0.9).sin()))
                .collect(),
            angles: vec![PI; n],
            pairs: vec![],
            antiparallel: vec![],
        };
        let s = solve(&p, 200, 1e-10, &crate::algorithms::Silent::default(), "t").unwrap();
        assert!(s.converged, "‖∇J‖ = {}", s.grad_norm);
        // convex: every turning angle positive, summing to 2π
        let turn: f64 = s.theta.iter().map(|t| PI - t).sum();
        assert!((turn - 2.0 * PI).abs() < 1e-12);
        assert!(s.theta.iter().all(|&t| t < PI && t > 0.0), "{:?}", s.theta);
        // the loop closes: the last edge leads back to the first vertex with its own length
        let (a, b) = (s.positions[n - 1], s.positions[0]);
        let last = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
        assert!((last - p.lengths[n - 1]).abs() < 1e-12 * p.lengths[n - 1].max(1.0));
    }
}
