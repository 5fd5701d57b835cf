//! `solver = "penalty_cg"`: the paper's global method (Sec. 4.1). Phases k = 0, 1, …: set
//! ρ_k = Σ l⁰² / (n_e G[M^k]²), run `cg_steps` (5) nonlinear conjugate-gradient steps on
//! J = E + (ρ_k/2) G² from M^k, giving M^{k+1}; stop when |G[M^{k+1}] − G[M^k]| / G[M⁰] < η
//! (0.01 %), when g_max ≤ `tolerance`, or after `max_iterations` (200) phases.
//!
//! The CG details the paper leaves to [45] (paper-notes B.2): Polak–Ribière+ directions,
//! restarted at every phase (ρ changes J) and whenever a direction is not a descent one, and
//! a strong-Wolfe line search (c1 = 1e-4, c2 = 0.1, at most 20 evaluations; Nocedal–Wright
//! Alg. 3.5–3.6) written here because it is twenty lines on top of the J evaluation we need
//! anyway; a crate's line search would want its own problem trait around the same closure.
//! The first trial of a phase moves the farthest vertex by one mean edge length; later ones
//! follow α_{k−1} g_{k−1}·d_{k−1} / g_k·d_k (N–W 3.60). Trials that make a triangle
//! degenerate, or J not finite, count as an increase. Of the phase iterates, the one with the lowest G is
//! returned (the last one, unless a phase made G worse): G is what the penalty drives down;
//! g_max may rise while G falls (on the hemisphere fixture it does for the whole run).
//!
//! What the schedule can reach (measured, issue 16 note of 2026-11-26). ρ_k G_k² is fixed, so
//! the phases converge to a stationary point of E + c·log G (c = mean l⁰²), not to G = 0:
//! where flattening costs real stretch the pull c∇G/G is spent against E. The paper's
//! inputs were near developable (g⁰_max 0.09–0.19) and ended near 1e-3. On gf_skirt_3D_0
//! (g⁰_max 0.034) 5 steps per phase reach 6.7e-3 in 200 phases and 50 steps 9.9e-7 in 293; on
//! diffavatar_tshirt (g⁰_max 0.52, which needs δS ≈ 10 % to flatten) the phases stall at
//! g_max 0.22 (5 steps, η) and 0.17 (50 steps × 1000 phases, G and ρ constant: the fixed
//! point), on mh_shoes01 at 0.26. An augmented Lagrangian on the vector g with the same CG
//! (first-order multipliers, ρ grown when g_max did not fall) was tried and not kept: 3.3e-3
//! on the t-shirt and 2.4e-2 on the shoe after 10,000 CG steps, with ρ growing past 1e18
//! (capping it made every mesh worse). `sqp` is the solver that reaches 1e-6 on both.
//!
//! Beyond the paper, two options (defaults: the paper's) that make the same penalty reach
//! the constraint where it costs stretch:
//! - `rho_growth` γ > 1: ρ_k = max(the paper's ρ_k, γ ρ_{k−1}), so ρ grows without bound and
//!   the fixed point above goes away; the η test is then taken relative to G[Mᵏ] (relative to
//!   G[M⁰] it ends the run while each phase still halves G: t-shirt 3.2e-3 after 31 phases).
//! - `preconditioner = gauss_newton`: the CG is preconditioned (PR+ with z = P⁻¹∇J) by
//!   P = H_E + 2μI + 2κL + 2ρG ΛᵀΛ, the Gauss–Newton Hessian of J without its rank-one part
//!   (H_E = Σ 2uuᵀ per edge, Λ = ∂θ/∂v), plus a small closeness μ and a graph Laplacian L that
//!   make it definite and its directions smooth. It is the `sqp` KKT system with −h̄²/(2ρG) in
//!   its (2,2) block, factorised once per phase on the same symbolic analysis; each CG step
//!   costs one more solve, and the first trial of a step is the direction's own length (at most
//!   ten mean edges). Plain CG is first order on a problem whose conditioning grows with ρ:
//!   with γ = 2 alone the t-shirt reached 2.2e-2 in 277 phases, ρ past 1e21.
//!
//! Measured with both (γ = 2; every open shared mesh in the issue 16 note of 2026-11-27):
//! t-shirt 1.2e-7 in 102 phases (δS 8.1 %, `sqp` 9.9 %; 5.2 s), gf_skirt_3D_0 1.4e-7 in 12,
//! gf_dress 5.6e-4, gc_tee_sim 3.0e-5; mh_shoes01 stalls at 4.2e-2, where `sqp` without its
//! restoration stalls too (3.5e-2: each upper is a pouch that only a start from a cone
//! flattens). The penalty has no shape guard: those results have corners below 0.01° and new
//! folds (t-shirt 12), which the job's warnings report; `sqp` keeps every corner ≥ 1°.
//!
//! `restore = true` (off by default here) follows a stall with `sqp`'s feasibility restoration
//! (fl-mesh from the input, then this solver from its result, `super::restore`). A
//! flattenable start is within the tolerance, so the penalty returns it unchanged: the answer
//! is fl-mesh's, and E is not lowered from there (the phases' ρ = Σl⁰²/(n_e G²) grows as
//! 1/G² near such a start). With both options above it takes mh_shoes01 to 5.2e-7 (δS 66 %)
//! and reaches 1e-6 on 17 of the 22 open shared meshes, as `sqp` does, with new folds on 9
//! (issue 16 note, 2026-11-28). With the paper's schedule alone it takes the t-shirt from its
//! stall at 0.22 to 1.3e-8 but crumpled (30 folds, δS 34 %): restoration does not replace the
//! two options above where they converge.

use super::energy::{big_g, g_max, Model};
use super::sqp::{Kkt, REGULARISATION};
use super::{HistoryEntry, Params, Preconditioner, Run, Stop};
use crate::algorithms::{AlgoError, Control, Progress};

const C1: f64 = 1e-4;
const C2: f64 = 0.1;
const MAX_EVALUATIONS: usize = 20;
/// ρ stays finite however long it grows (`rho_growth` 1000 would pass f64's range in 103
/// phases); J and its gradient stay finite with it for any G a run can have.
const RHO_MAX: f64 = 1e250;
/// `gauss_newton` preconditioner: weight μ of the 2μI that makes E's Gauss–Newton Hessian
/// definite (rigid motions and isometric bendings leave E unchanged).
const PRECONDITIONER_CLOSENESS: f64 = 1e-3;
/// `gauss_newton` preconditioner: weight κ of the graph Laplacian 2κL (over h̄²) that makes its
/// directions smooth (a Sobolev gradient). Without it the t-shirt stalls at g_max 2.7e-2 with
/// ρ past 1e50, as `sqp` does with its smoothness 0 (least-stretch steps concentrate the change
/// where θ's linearisation is poor); measured on the t-shirt (ρ growth 2, η 1e-12): κ = 0.1
/// 3.2e-7, 0.3 3.3e-5, 1 1.2e-7, 3 7.9e-5, 10 1.5e-5, δS 7.8–8.3 %.
const PRECONDITIONER_SMOOTHNESS: f64 = 1.0;

/// Run the penalty method from `start`, moving only vertices with `movable`.
pub(super) fn run(
    model: &Model<'_>,
    start: &[[f64; 3]],
    movable: &[bool],
    params: &Params,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let nv = start.len();
    let h = crate::geometry::mean_edge_length(model.mesh());
    let ne = model.rest().len().max(1) as f64;
    let sum_l0_sq: f64 = model.rest().iter().map(|l| l * l).sum();
    let tol = params.tolerance();
    let mut ws = Work::new(nv);
    let mut pos = start.to_vec();
    model.g(&pos, &mut ws.g);
    let g0 = big_g(&ws.g);
    let mut run = Run::new(start, g_max(&ws.g));
    let mut big_gk = g0;
    let mut best_g = g0;
    let mut prev_rho = 0.0_f64;
    if run.g_max <= tol || g0 == 0.0 {
        run.stop = Stop::Tolerance;
        return Ok(run);
    }
    let mut kkt = match params.preconditioner {
        Preconditioner::None => None,
        Preconditioner::GaussNewton => Some(Kkt::new(model, movable, control)?),
    };
    for k in 1..=params.max_iterations {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        let rho = (sum_l0_sq / (ne * big_gk * big_gk))
            .max(prev_rho * params.rho_growth)
            .min(RHO_MAX);
        prev_rho = rho;
        if let Some(kkt) = kkt.as_mut() {
            // P's penalty block is the Gauss–Newton part ρG·2ΛᵀΛ of (ρ/2)G²'s Hessian; the
            // KKT system carries it as −ε = −h̄²/(2ρG) in its (2,2) block.
            let eps = h * h / (2.0 * rho * big_gk);
            kkt.fill(
                model,
                &pos,
                h,
                PRECONDITIONER_CLOSENESS,
                PRECONDITIONER_SMOOTHNESS,
                (eps - REGULARISATION).max(0.0),
            )?;
        }
        let steps = phase(
            model,
            &mut pos,
            movable,
            rho,
            h,
            params.cg_steps,
            kkt.as_mut(),
            &mut ws,
        )?;
        run.inner += steps.taken;
        run.evaluations += steps.evaluations;
        model.g(&pos, &mut ws.g);
        let next_g = big_g(&ws.g);
        let gm = g_max(&ws.g);
        run.iterations = k;
        run.history.push(HistoryEntry {
            iteration: k,
            max_flattenability: gm,
            big_g: next_g,
            e: model.e(&pos),
            rho: Some(rho),
            cg_steps: Some(steps.taken),
            step_length: None,
            damping: None,
        });
        control.progress(&Progress {
            stage: "penalty_cg".into(),
            iteration: k,
            max_flattenability: Some(gm),
            step_norm: None,
        });
        if next_g < best_g {
            best_g = next_g;
            run.g_max = gm;
            run.best_iteration = k;
            run.positions.copy_from_slice(&pos);
        }
        if gm <= tol {
            run.g_max = gm;
            run.best_iteration = k;
            run.positions.copy_from_slice(&pos);
            run.stop = Stop::Tolerance;
            return Ok(run);
        }
        if steps.taken == 0 {
            run.stop = Stop::LineSearch;
            return Ok(run);
        }
        // The paper's η is relative to G[M⁰]; with ρ made to grow G keeps falling by factors,
        // and that test ends the run at g_max ≈ 3e-3 on the t-shirt while each phase still
        // halves G, so there the change is taken relative to G[Mᵏ].
        let scale = if params.rho_growth > 1.0 { big_gk } else { g0 };
        if (next_g - big_gk).abs() / scale < params.eta {
            run.stop = Stop::Eta;
            return Ok(run);
        }
        big_gk = next_g;
    }
    run.stop = Stop::MaxIterations;
    Ok(run)
}

/// Scratch arrays of one run.
struct Work {
    g: Vec<f64>,
    tmp: Vec<[f64; 3]>,
    grad: Vec<[f64; 3]>,
    trial_grad: Vec<[f64; 3]>,
    dir: Vec<[f64; 3]>,
    trial: Vec<[f64; 3]>,
    /// P⁻¹ times `grad` and `trial_grad` (the gradient itself without a preconditioner).
    pre: Vec<[f64; 3]>,
    trial_pre: Vec<[f64; 3]>,
}

impl Work {
    fn new(nv: usize) -> Self {
        Work {
            g: vec![0.0; nv],
            tmp: vec![[0.0; 3]; nv],
            grad: vec![[0.0; 3]; nv],
            trial_grad: vec![[0.0; 3]; nv],
            dir: vec![[0.0; 3]; nv],
            trial: vec![[0.0; 3]; nv],
            pre: vec![[0.0; 3]; nv],
            trial_pre: vec![[0.0; 3]; nv],
        }
    }
}

struct Steps {
    taken: usize,
    evaluations: usize,
}

/// `steps` PR+ conjugate-gradient steps on J_ρ from `pos` (updated in place), preconditioned
/// by `kkt` when given (its factorisation filled for this phase).
#[allow(clippy::too_many_arguments)]
fn phase(
    model: &Model<'_>,
    pos: &mut [[f64; 3]],
    movable: &[bool],
    rho: f64,
    h: f64,
    steps: usize,
    mut kkt: Option<&mut Kkt>,
    ws: &mut Work,
) -> Result<Steps, AlgoError> {
    let mut out = Steps {
        taken: 0,
        evaluations: 1,
    };
    let mut f = model.j_gradient(pos, rho, &mut ws.g, &mut ws.tmp, &mut ws.grad);
    mask(&mut ws.grad, movable);
    apply(kkt.as_deref_mut(), &ws.grad, &mut ws.pre, movable)?;
    for (d, z) in ws.dir.iter_mut().zip(&ws.pre) {
        *d = z.map(|x| -x);
    }
    let mut prev_slope = 0.0;
    let mut prev_alpha = 0.0;
    for _ in 0..steps {
        let mut slope = dot_all(&ws.grad, &ws.dir);
        if slope >= 0.0 {
            for (d, z) in ws.dir.iter_mut().zip(&ws.pre) {
                *d = z.map(|x| -x);
            }
            slope = dot_all(&ws.grad, &ws.dir);
        }
        let dmax = ws
            .dir
            .iter()
            .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
            .fold(0.0, f64::max);
        if slope.is_nan() || slope >= 0.0 || dmax == 0.0 {
            break;
        }
        let alpha0 = if kkt.is_some() {
            // A Newton-like direction: its own length first, at most ten mean edges.
            (10.0 * h / dmax).min(1.0)
        } else if prev_alpha > 0.0 {
            (prev_alpha * prev_slope / slope).min(h / dmax)
        } else {
            h / dmax
        };
        let mut last_alpha = f64::NAN;
        let mut phi = |alpha: f64| -> (f64, f64) {
            for ((t, p), d) in ws.trial.iter_mut().zip(pos.iter()).zip(&ws.dir) {
                for k in 0..3 {
                    t[k] = p[k] + alpha * d[k];
                }
            }
            if degenerate(model.mesh(), &ws.trial) {
                last_alpha = alpha;
                return (f64::INFINITY, 0.0);
            }
            let v = model.j_gradient(&ws.trial, rho, &mut ws.g, &mut ws.tmp, &mut ws.trial_grad);
            mask(&mut ws.trial_grad, movable);
            last_alpha = alpha;
            let s = dot_all(&ws.trial_grad, &ws.dir);
            if v.is_finite() && s.is_finite() {
                (v, s)
            } else {
                (f64::INFINITY, 0.0)
            }
        };
        let (alpha, fa, evaluations) = strong_wolfe(&mut phi, f, slope, alpha0);
        out.evaluations += evaluations;
        if alpha == 0.0 {
            break;
        }
        for (p, d) in pos.iter_mut().zip(&ws.dir) {
            for k in 0..3 {
                p[k] += alpha * d[k];
            }
        }
        if alpha != last_alpha {
            model.j_gradient(pos, rho, &mut ws.g, &mut ws.tmp, &mut ws.trial_grad);
            mask(&mut ws.trial_grad, movable);
            out.evaluations += 1;
        }
        f = fa;
        out.taken += 1;
        apply(
            kkt.as_deref_mut(),
            &ws.trial_grad,
            &mut ws.trial_pre,
            movable,
        )?;
        // Polak–Ribière+ (preconditioned): β = max(0, g₊·(z₊ − z) / g·z), z = P⁻¹g.
        let gz = dot_all(&ws.grad, &ws.pre);
        let mut num = 0.0;
        for ((a, zn), zo) in ws.trial_grad.iter().zip(&ws.trial_pre).zip(&ws.pre) {
            for k in 0..3 {
                num += a[k] * (zn[k] - zo[k]);
            }
        }
        let beta = if gz > 0.0 { (num / gz).max(0.0) } else { 0.0 };
        std::mem::swap(&mut ws.grad, &mut ws.trial_grad);
        std::mem::swap(&mut ws.pre, &mut ws.trial_pre);
        for (d, z) in ws.dir.iter_mut().zip(&ws.pre) {
            for k in 0..3 {
                d[k] = -z[k] + beta * d[k];
            }
        }
        prev_slope = slope;
        prev_alpha = alpha;
    }
    Ok(out)
}

/// z = P⁻¹ g with the factorised `kkt`, or z = g without one.
fn apply(
    kkt: Option<&mut Kkt>,
    g: &[[f64; 3]],
    z: &mut [[f64; 3]],
    movable: &[bool],
) -> Result<(), AlgoError> {
    match kkt {
        Some(kkt) => {
            kkt.precondition(g, z)?;
            mask(z, movable);
        }
        None => z.copy_from_slice(g),
    }
    Ok(())
}

/// Whether a triangle is degenerate at `pos` (θ stays finite there, so J alone would not
/// refuse it, but the output could not be a valid mesh).
fn degenerate(mesh: &crate::mesh::Mesh, pos: &[[f64; 3]]) -> bool {
    mesh.triangles().iter().any(|t| {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        crate::mesh::is_degenerate_triangle(a, b, c)
    })
}

fn mask(v: &mut [[f64; 3]], movable: &[bool]) {
    for (x, &m) in v.iter_mut().zip(movable) {
        if !m {
            *x = [0.0; 3];
        }
    }
}

fn dot_all(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
        .sum()
}

/// A step α > 0 along a descent direction satisfying the strong Wolfe conditions for
/// φ(α) = (value, slope), from φ(0) = `f0` with slope `d0` < 0 and first trial `alpha0`
/// (Nocedal–Wright Alg. 3.5 with the zoom of Alg. 3.6, safeguarded quadratic interpolation).
/// Returns (α, φ(α), evaluations); α = 0 when no sufficient decrease was found.
pub(super) fn strong_wolfe(
    phi: &mut dyn FnMut(f64) -> (f64, f64),
    f0: f64,
    d0: f64,
    alpha0: f64,
) -> (f64, f64, usize) {
    let armijo = |a: f64, f: f64| f <= f0 + C1 * a * d0;
    let curvature = |d: f64| d.abs() <= -C2 * d0;
    let (mut a_prev, mut f_prev, mut d_prev) = (0.0, f0, d0);
    let mut a = alpha0;
    let mut evals = 0;
    // Bracketing: (lo, hi) with lo satisfying Armijo and lower than hi, once found.
    let (mut lo, mut f_lo, mut d_lo, mut hi, mut f_hi);
    loop {
        let (f, d) = phi(a);
        evals += 1;
        if !armijo(a, f) || (evals > 1 && f >= f_prev) {
            (lo, f_lo, d_lo, hi, f_hi) = (a_prev, f_prev, d_prev, a, f);
            break;
        }
        if curvature(d) {
            return (a, f, evals);
        }
        if d >= 0.0 {
            (lo, f_lo, d_lo, hi, f_hi) = (a, f, d, a_prev, f_prev);
            break;
        }
        if evals >= MAX_EVALUATIONS {
            return (a, f, evals);
        }
        (a_prev, f_prev, d_prev) = (a, f, d);
        a *= 2.0;
    }
    while evals < MAX_EVALUATIONS {
        // Minimiser of the quadratic through (lo, f_lo, d_lo) and (hi, f_hi), kept inside the
        // middle 80 % of the bracket; bisection when the quadratic is useless.
        let w = hi - lo;
        let denom = 2.0 * (f_hi - f_lo - d_lo * w);
        let mut t = if f_hi.is_finite() && denom > 0.0 {
            lo - d_lo * w * w / denom
        } else {
            lo + 0.5 * w
        };
        let (a_min, a_max) = (lo.min(hi), lo.max(hi));
        let margin = 0.1 * (a_max - a_min);
        t = t.clamp(a_min + margin, a_max - margin);
        let (f, d) = phi(t);
        evals += 1;
        if !armijo(t, f) || f >= f_lo {
            (hi, f_hi) = (t, f);
        } else {
            if curvature(d) {
                return (t, f, evals);
            }
            if d * (hi - lo) >= 0.0 {
                (hi, f_hi) = (lo, f_lo);
            }
            (lo, f_lo, d_lo) = (t, f, d);
        }
        if (hi - lo).abs() <= 1e-14 * lo.abs().max(1e-300) {
            break;
        }
    }
    if lo > 0.0 {
        (lo, f_lo, evals)
    } else {
        (0.0, f0, evals)
    }
}
