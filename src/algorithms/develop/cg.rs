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

use super::energy::{big_g, g_max, Model};
use super::{HistoryEntry, Params, Run, Stop};
use crate::algorithms::{AlgoError, Control, Progress};

const C1: f64 = 1e-4;
const C2: f64 = 0.1;
const MAX_EVALUATIONS: usize = 20;

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
    if run.g_max <= tol || g0 == 0.0 {
        run.stop = Stop::Tolerance;
        return Ok(run);
    }
    for k in 1..=params.max_iterations {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        let rho = sum_l0_sq / (ne * big_gk * big_gk);
        let steps = phase(model, &mut pos, movable, rho, h, params.cg_steps, &mut ws);
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
        if (next_g - big_gk).abs() / g0 < params.eta {
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
        }
    }
}

struct Steps {
    taken: usize,
    evaluations: usize,
}

/// `steps` PR+ conjugate-gradient steps on J_ρ from `pos` (updated in place).
fn phase(
    model: &Model<'_>,
    pos: &mut [[f64; 3]],
    movable: &[bool],
    rho: f64,
    h: f64,
    steps: usize,
    ws: &mut Work,
) -> Steps {
    let mut out = Steps {
        taken: 0,
        evaluations: 1,
    };
    let mut f = model.j_gradient(pos, rho, &mut ws.g, &mut ws.tmp, &mut ws.grad);
    mask(&mut ws.grad, movable);
    for (d, g) in ws.dir.iter_mut().zip(&ws.grad) {
        *d = g.map(|x| -x);
    }
    let mut prev_slope = 0.0;
    let mut prev_alpha = 0.0;
    for _ in 0..steps {
        let mut slope = dot_all(&ws.grad, &ws.dir);
        if slope >= 0.0 {
            for (d, g) in ws.dir.iter_mut().zip(&ws.grad) {
                *d = g.map(|x| -x);
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
        let cap = h / dmax;
        let alpha0 = if prev_alpha > 0.0 {
            (prev_alpha * prev_slope / slope).min(cap)
        } else {
            cap
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
        // Polak–Ribière+: β = max(0, g₊·(g₊ − g) / g·g).
        let gg = dot_all(&ws.grad, &ws.grad);
        let mut num = 0.0;
        for (a, b) in ws.trial_grad.iter().zip(&ws.grad) {
            for k in 0..3 {
                num += a[k] * (a[k] - b[k]);
            }
        }
        let beta = if gg > 0.0 { (num / gg).max(0.0) } else { 0.0 };
        std::mem::swap(&mut ws.grad, &mut ws.trial_grad);
        for (d, g) in ws.dir.iter_mut().zip(&ws.grad) {
            for k in 0..3 {
                d[k] = -g[k] + beta * d[k];
            }
        }
        prev_slope = slope;
        prev_alpha = alpha;
    }
    out
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
