//! `solver = "sqp"` (the default, beyond the paper; paper-notes B.8 (c)): Eq. 8 itself, min E
//! subject to θ_i = 2π at every interior vertex, by sequential quadratic programming instead of
//! a penalty, so that the answer is exactly flattenable (g_max ≤ 1e-6) where the paper's
//! penalty runs all stall near 1e-3 (its Table 1).
//!
//! Objective f = (E + μ Σ_v |v − v⁰|² + κ Σ_e |d_a − d_b|²) / h̄², d = v − v⁰, μ = `closeness`
//! (default 1e-2): E alone is blind to rigid motions and to every isometric bending, so its
//! Hessian is singular; the small pull to the input picks, among the minimum-deformation
//! answers, the one nearest the input. κ, the Dirichlet energy of the displacement on the same
//! edge pattern, is `smoothness` (default 10) until the run is flattenable, then 0 until it is
//! stationary, so the answer is that of min E + μ closeness. Why: θ depends on edge lengths
//! only, so the least-stretch step (κ = 0)
//! concentrates the change and makes θ's linearisation poor, and a garment's total angle defect
//! must be carried to its boundary (Gauss–Bonnet), which damped least-stretch steps do like a
//! slow diffusion; smooth steps carry it. Measured on the 22 open shared meshes (issue 16
//! note): converged 5 with κ = 0 throughout (the t-shirt stalls at 2.0e-2, δS 2.9 %), 9 with
//! κ = 10 (the t-shirt 9.4e-7 with δS 9.9 %, gf_dress, pf_try3, bff_hemisphere newly).
//! `smoothness = 0` is the least-stretch model throughout. Once flattenable, f also holds
//! `fold_barrier` × Σ_e (φ_e − t_e)₊² over the hinges and `corner_barrier` × Σ_c (t_c −
//! a_c)₊² over the corners ([`ShapeBarrier`]), so that the objective phase bends its steps
//! away from folds and slivers instead of having them refused by the shape floor. Until
//! 2026-11-29 an objective phase with κ = 10 (to its own stationary point) came between
//! restoration and κ = 0; it bought nothing the κ = 0 phase does not (issue 16 note: on the
//! 35-case subset, with backtracking, iterations 3498 → 3086, δS lower on 7 cases
//! (saddle-2000-0.1 11.95 → 4.91 %), higher on 4 (mh_female_sportsuit01 26.99 → 30.22 %),
//! folds fewer (gc_tee_sim 12 → 3)).
//!
//! Each iteration solves the KKT system
//!
//! ```text
//! [ H   Λᵀ ] [δ]   [ −∇f    ]
//! [ Λ  −εI ] [y] = [ 2π − θ ]
//! ```
//!
//! with H the Gauss–Newton Hessian of f (2 u uᵀ per edge, u its unit direction, plus 2μ I and
//! κ's graph Laplacian), the (2,2) block −(ε + λ)I with the damping λ below, and Λ = ∂θ/∂v (FL
//! Props. 1–2), in units of h̄ so that all blocks are O(1). The pattern is fixed, so the
//! symbolic factorisation (AMD on the vertex graph, a vertex's x, y, z and y kept together) is
//! computed once and only the numeric LDLᵀ every iteration.
//!
//! Globalisation, as fl-mesh's (feasibility first, the objective shaping the step): one
//! factorisation, two solves, a normal step δ_n for [0; 2π − θ] (the least-H-norm step, i.e.
//! the least deformation, that the linearised constraints ask for) and a tangential one δ_t for
//! [−∇f; 0]; the trial is δ_n + w δ_t. While not flattenable, a trial is taken when Σ(2π − θ)²
//! falls by at least 1e-4 of the fall its linearisation predicts, and the Levenberg–Marquardt
//! damping λ in the (2,2) block, −(ε + λ)I, follows Nielsen's rule on that ratio (a large λ
//! shortens the normal step where θ's linearisation is poor); w is halved after a refused
//! trial, doubled after a good one, and cut further when δ_t would spoil more than half the
//! predicted fall (with λ > 0 it is not exactly tangent). Once flattenable (the objective
//! phase), the (1,1) block is H + σI, a Levenberg–Marquardt trust region (σ ÷ 3 after a taken
//! step, × 4 after a refused one), λ is off so the constraint rows are exact, and the trial
//! δ_n + δ_t is pulled back onto the constraints by up to four corrections (re-solves with the same
//! factorisation against the residual at the trial, kept while g_max falls fast enough to reach
//! the tolerance in the corrections left); it is taken when it is flattenable, lowers
//! f and keeps the shape (the smallest corner of the mesh stays at 1° or above, or at the
//! smallest the input or the first flattenable iterate had if lower, and the count of folds
//! does not grow; `ShapeFloor`). While not flattenable, up to four such corrections follow a
//! taken step as long as each quarters Σ(2π − θ)². Trials that make a triangle degenerate are
//! refused. A refused trial is first shortened on the same factorisation, α(δ_n + w δ_t) with
//! α halved (restoring, twice) or quartered (objective phase, four times), each shortening
//! bookkept as the refusal it replaces (λ doubles, or σ quadruples, whose step is about 1/σ as
//! long): a refusal then costs an evaluation instead of a factorisation. Measured (issue 16
//! note, 2026-11-29): t-shirt 69 → 56 iterations (restoration 49 → 41), every halved
//! restoration trial taken; the 35-case subset 3872 → 3498, all still converged, δS lower on
//! 13 (saddle-2000-0.1 12.9 → 12.0 %), higher on 6 (saddle-7700-0.1 11.8 → 14.8 %, the rest
//! by at most 0.16 % points).
//!
//! In the objective phase H also holds the constraints' curvature, the rest of the Hessian
//! of the Lagrangian f + yᵀ(θ − 2π): Σ_c (y_c ∇²α_c)₊ over the corners at constrained
//! vertices, y the multipliers of the previous iteration's solve and each corner's term
//! replaced by its positive semidefinite part in closed form ([`corner_angle_hessian`]), so H
//! stays positive definite and the pattern is unchanged. Why: E's Gauss–Newton Hessian is
//! blind to bending (an isometric bend leaves every edge length), and there the constraints'
//! curvature is all the curvature there is; |y| reaches 50–90 on the t-shirt, so the term
//! outweighs H's O(1) diagonal, and without it σ stood in for it at 8–380 (steps of
//! 0.004–0.06 h̄, f falling as in gradient descent). Measured (issue 16 note, 2026-11-30) on
//! the 35-case subset: Σ δS 191.2 → 155.9 % points, folds left 12 → 9, all still
//! converged, δS lower on 13 cases (saddle-7700-0.01 13.56 → 6.62 %, mh_shoes01 66.0 →
//! 50.0 %, gc_tee_sim 9.66 → 6.87 %, the t-shirt 8.34 → 7.91 % in the same 200 iterations),
//! higher on 2 (fixture-hemisphere_cap 7.76 → 8.40 %, its smallest corner 3.0 → 18.1°;
//! dome-2000-0.1 3.00 → 3.10 %); σ now stays at 1–40 on the t-shirt.
//!
//! The objective phase replaced (issue 16 note, 2026-11-26) a step weight w halved
//! after each refusal with λ left where restoration ended and κ lowered ÷ 10 at each stationary
//! point: E's Gauss–Newton Hessian ignores the constraints' curvature, so the undamped step was
//! 10–70 h̄ long and only w ≈ 2e-3 of it was taken; w never grew back, λ = 1e-4 kept the
//! corrections from closing the residual, and each κ stage ended after ten refusals without a
//! step (now κ goes from `smoothness` straight to 0). On the 12 flattenable open shared meshes:
//! t-shirt 3.2 s → 1.3 s, 200 → 69 iterations, δS 9.89 → 9.91 %, folds 17 → 10, smallest corner
//! 0.08° → 1.9°; δS lower on 6 (gf_skirt_3D_0 2.07 → 1.90 %, gc_tee_sim 16.8 → 13.1 %), higher
//! on 3 (mh_female_sportsuit01 21.7 → 26.8 %, mh_classicshoes_medium 10.1 → 12.4 %,
//! gf_shirtfront 8.86 → 9.04 %) where the old run had bought its stretch with corners of
//! 0.00–0.04°. Measured with κ = 0 against the first version (ℓ1 merit with Armijo backtracking
//! and λ on H's diagonal, issue 16 note): on the t-shirt g_max 6.2e-3 with δS 14 % became
//! 2.0e-2 with δS 2.9 %; on mh_shoes01 0.48 → 0.037; gf_dress 0.127 (no step taken) → 4.6e-3.
//! Neither converges yet on most real garments (they stall with every interior vertex at a
//! similar g: a local minimum of Σ(2π − θ)² that fl-mesh leaves by refinement and non-monotone
//! steps).
//!
//! Stop: converged when g_max ≤ `tolerance`, κ = 0 and the run is stationary: σ has passed 1e6,
//! the step (times 1 + σ, the shortening σ causes) is below `step_tolerance` h̄, or f fell by
//! less than 0.02 % over the last two iterations (a stationary point of Eq. 8 for practical
//! purposes, not just the first flattenable iterate; a run that is flattenable but not there
//! yet says so in its detail). The creep rate is the former 0.1 % over ten iterations; with
//! refusals shortened in place each iteration takes a step, and the shorter windows changed
//! no δS of the 35-case subset by more than 0.01 % points (ten → four iterations: 3086 → 2978
//! iterations; four → two, 2026-11-29: 2892 → 2832, the t-shirt 50 → 48); `stall`
//! when g_max has not halved in `stall_iterations`;
//! `line_search` when λ passes 1e8, or when the objective phase's σ passes 1e6 while its
//! unshortened step is still longer than `step_tolerance` (the shape floor or the constraints
//! refused every step: flattenable, not stationary, and the detail says so; found on
//! mh_male_worksuit01 with the corner barrier at 6°, issue 16 note 2026-11-30, where such a
//! stop was reported as `tolerance`). The best iterate is returned: the feasible one with the
//! least f, else the one with the least g_max.

// Index loops over xyz read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use super::energy::{g_max, Model};
use super::{HistoryEntry, Params, Run, Stop};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::geometry::{
    corner_angle_gradient, corner_angle_hessian, fold_count_at, smallest_corner_at, SLIVER_DEGREES,
};
use crate::linalg::LdltSolver;
use crate::mesh::{dot, is_degenerate_triangle, sub, Mesh, NONE};

/// The (2,2) block's floor −εI: keeps the system solvable where a constraint's gradient
/// vanishes (a planar vertex, where θ is stationary at 2π), biasing θ by at most ε|y|.
pub(super) const REGULARISATION: f64 = 1e-10;
/// Levenberg–Marquardt damping λ of the (2,2) block, −(ε + λ)I: the step then minimises
/// ½δᵀHδ + ∇f·δ + |Λδ − (2π − θ)|²/(2λ), so a large λ shortens the part of the step that
/// chases the constraints where their linearisation is poor; λ → 0 is the exact SQP step.
const DAMPING_START: f64 = 1e-4;
const DAMPING_MIN: f64 = 1e-10;
const DAMPING_MAX: f64 = 1e8;
/// A step is taken when Σ(2π − θ)² falls by at least this share of what the model predicts.
const ACCEPT: f64 = 1e-4;
/// Once flattenable, the objective's steps solve with H + σI (a Levenberg–Marquardt trust
/// region): σ ÷ 3 after a taken step, × 4 after a refused one, stationary past SIGMA_MAX.
/// In units of h̄, where H's diagonal is O(1): the first steps are short gradient-like ones.
const SIGMA_START: f64 = 10.0;
const SIGMA_MIN: f64 = 1e-8;
const SIGMA_MAX: f64 = 1e6;
/// Once flattenable, stationary enough when f fell by less than this share over the last
/// CREEP_WINDOW iterations (1e-4 per iteration; the paper's η plays the same part for its
/// phases).
const CREEP: f64 = 2e-4;
const CREEP_WINDOW: usize = 2;
/// Shortenings of a refused trial on the same factorisation before the next one: halving
/// while restoring (where λ would double), quartering on the constraints (where σ would
/// quadruple, and the step shrinks about as 1/σ).
const BACKTRACKS_RESTORATION: usize = 2;
const BACKTRACKS_OBJECTIVE: usize = 4;
/// Most corrections after an accepted step (each one solve with the same factorisation).
const MAX_CORRECTIONS: usize = 4;
/// The objective phase's hinge barrier starts at this turning angle (a fold is 120°), or at
/// the input's own angle across an edge where that is sharper.
const BARRIER_DEGREES: f64 = 90.0;
/// The objective phase's corner barrier starts at this corner angle (three times the shape
/// floor's 1°), or at the input's own corner where that is smaller.
const CORNER_BARRIER_DEGREES: f64 = 3.0;

/// Eq. 8 from `start` (the input v0, or a flattenable point found by a restoration phase),
/// with the closeness and smoothness terms measured from v0. A flattenable v0 is returned
/// as it is; a flattenable start other than v0 is where the objective phase begins.
pub(super) fn run(
    model: &Model<'_>,
    v0: &[[f64; 3]],
    start: &[[f64; 3]],
    movable: &[bool],
    params: &Params,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let tol = params.tolerance();
    let mut g = vec![0.0; v0.len()];
    model.g(start, &mut g);
    let mut run = Run::new(start, g_max(&g));
    if run.g_max <= tol && start == v0 {
        run.stop = Stop::Tolerance;
        return Ok(run);
    }
    let mut kkt = Kkt::new(model, movable, control)?;
    let cons = kkt.cons.clone();
    let h = crate::geometry::mean_edge_length(model.mesh());
    if !(h > 0.0 && h.is_finite()) {
        return Err(AlgoError::Input(
            "mesh has no edge of positive length".into(),
        ));
    }
    let mu = params.closeness;
    let mut kappa = params.smoothness;
    let f_of = |pos: &[[f64; 3]], kappa: f64| {
        let c: f64 = pos
            .iter()
            .zip(v0)
            .map(|(p, q)| {
                let d = sub(*p, *q);
                dot(d, d)
            })
            .sum();
        let k: f64 = model
            .mesh()
            .conn()
            .edges()
            .iter()
            .map(|e| {
                let (a, b) = (e[0] as usize, e[1] as usize);
                let d = [0, 1, 2].map(|i| (pos[a][i] - v0[a][i]) - (pos[b][i] - v0[b][i]));
                dot(d, d)
            })
            .sum();
        (model.e(pos) + mu * c + kappa * k) / (h * h)
    };
    let sq = |g: &[f64]| cons.iter().map(|&v| g[v as usize].powi(2)).sum::<f64>();
    let barrier = ShapeBarrier::new(model.mesh(), v0, params.fold_barrier, params.corner_barrier);
    // f once flattenable: the deformation plus the shape barrier.
    let f_on = |pos: &[[f64; 3]]| f_of(pos, 0.0) + barrier.value(pos);
    let mut pos = start.to_vec();
    let mut trial = start.to_vec();
    let mut trial_g = g.clone();
    let mut grad_e = vec![[0.0; 3]; v0.len()];
    let mut lin = vec![0.0; cons.len()];
    let mut lin_t = vec![0.0; cons.len()];
    let mut trial2 = start.to_vec();
    let mut trial_g2 = g.clone();
    let mut direction = vec![0.0; 3 * kkt.m];
    let mut f = f_of(&pos, kappa);
    let (mut damping, mut growth) = (DAMPING_START, 2.0);
    let mut weight = 1.0f64;
    // A flattenable start is the best so far until a flattenable iterate lowers f.
    let mut best_f = if run.g_max <= tol { f } else { f64::INFINITY };
    let mut since_halving = 0;
    let mut stall_ref = run.g_max;
    let m3 = 3 * kkt.m;
    let dim = kkt.rhs.len() / 2;
    run.stop = Stop::MaxIterations;
    // Objective phase: the trust-region damping σ, f over the last CREEP_WINDOW iterations
    // (a ring), and the shape floor set on entering it.
    let mut sigma = SIGMA_START;
    let mut f_ring = [0.0; CREEP_WINDOW];
    let mut objective_its = 0usize;
    let mut shape_floor: Option<ShapeFloor> = None;
    // The unshortened step's length (h̄) when the objective phase's trust region collapsed.
    let mut collapsed: Option<f64> = None;
    for it in 1..=params.max_iterations {
        if control.cancelled_before(kkt.solver.predicted_factor_seconds()) {
            return Err(AlgoError::Cancelled);
        }
        run.iterations = it;
        let feasible_now = g_max(&g) <= tol;
        if feasible_now && shape_floor.is_none() {
            // The smoothing term got the run onto the constraints; from here minimise the
            // deformation itself along them (κ = 0), with the hinge barrier. Once flattenable
            // the run stays so (the objective phase takes flattenable trials only), and this
            // iterate is its best.
            kappa = 0.0;
            f = f_on(&pos);
            best_f = f;
        }
        model.e_gradient(&pos, &mut grad_e);
        if kappa > 0.0 {
            for e in model.mesh().conn().edges() {
                let (a, b) = (e[0] as usize, e[1] as usize);
                for i in 0..3 {
                    let d = (pos[a][i] - v0[a][i]) - (pos[b][i] - v0[b][i]);
                    grad_e[a][i] += 2.0 * kappa * d;
                    grad_e[b][i] -= 2.0 * kappa * d;
                }
            }
        }
        // Two right-hand sides on one factorisation: normal [0; 2π − θ], tangential [−∇f; 0].
        kkt.rhs.fill(0.0);
        for (c, &v) in cons.iter().enumerate() {
            kkt.rhs[m3 + c] = g[v as usize];
        }
        for (s, &v) in kkt.verts.iter().enumerate() {
            let v = v as usize;
            for k in 0..3 {
                kkt.rhs[dim + 3 * s + k] = -(grad_e[v][k] + 2.0 * mu * (pos[v][k] - v0[v][k])) / h;
            }
        }
        kkt.extra.fill([0.0; 6]);
        if feasible_now {
            barrier.add_to(&pos, h, &mut kkt);
        }
        if feasible_now && shape_floor.is_none() {
            shape_floor = Some(ShapeFloor::new(model.mesh(), v0, &pos));
        }
        // On the constraints: H + σI (the objective's trust region) and the exact constraint
        // rows (λ, which shortens the normal step while restoring, would keep the corrections
        // from closing the residual).
        // σI enters H as its 2μ I does (f's closeness term), hence μ + σ/2.
        let (sigma_now, damping_now) = if feasible_now {
            (sigma, DAMPING_MIN)
        } else {
            (0.0, damping)
        };
        if let Err(e) = kkt
            .fill(model, &pos, h, mu + 0.5 * sigma_now, kappa, damping_now)
            .and_then(|()| kkt.solve_two())
        {
            // A failed factorisation ends the run with the best iterate, not the job.
            run.stop = Stop::LineSearch;
            run.stop_detail = format!("{e}; the best iterate is returned");
            break;
        }
        if feasible_now {
            // y = y_n + y_t of the step δ_n + δ_t: the next fill's constraint curvature.
            let (normal, tangential) = kkt.rhs.split_at(dim);
            for (c, y) in kkt.multipliers.iter_mut().enumerate() {
                *y = normal[m3 + c] + tangential[m3 + c];
            }
            kkt.curvature = true;
        }
        // The objective's part may not spoil the predicted fall of Σ(2π − θ)² by more than
        // half (with λ > 0 it is not exactly tangent to the constraints).
        let (normal, tangential) = kkt.rhs.split_at(dim);
        kkt.lambda_times(&normal[..m3], &mut lin);
        kkt.lambda_times(&tangential[..m3], &mut lin_t);
        let predicted_at = |alpha: f64, w: f64| {
            cons.iter()
                .enumerate()
                .map(|(c, &v)| {
                    let gv = g[v as usize];
                    gv * gv - (gv - alpha * (lin[c] + w * lin_t[c])).powi(2)
                })
                .sum::<f64>()
        };
        let mut w = if feasible_now { 1.0 } else { weight };
        if !feasible_now {
            let floor = 0.5 * predicted_at(1.0, 0.0);
            let mut cuts = 0;
            while predicted_at(1.0, w) < floor && cuts < 20 {
                w *= 0.5;
                cuts += 1;
            }
            if predicted_at(1.0, w) < floor {
                w = 0.0;
            }
        }
        for i in 0..m3 {
            kkt.step[i] = normal[i] + w * tangential[i];
        }
        direction.copy_from_slice(&kkt.step);
        let step_max = kkt
            .step
            .chunks(3)
            .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
            .fold(0.0, f64::max);
        let fk = |p: &[[f64; 3]]| {
            if feasible_now {
                f_on(p)
            } else {
                f_of(p, kappa)
            }
        };
        // The trial α(δ_n + w δ_t), α = 1 first; a refused one is shortened on the same
        // factorisation (BACKTRACKS_RESTORATION halvings, BACKTRACKS_OBJECTIVE quarterings),
        // each shortening bookkept as the refusal it replaces (λ or σ grows as if the system
        // had been refactored), so only a taken step or a run of refusals costs a factorisation.
        let (backtracks, shrink) = if feasible_now {
            (BACKTRACKS_OBJECTIVE, 0.25)
        } else {
            (BACKTRACKS_RESTORATION, 0.5)
        };
        let mut alpha = 1.0f64;
        let mut tries = 0;
        let mut trial_f;
        let accepted = loop {
            kkt.step.copy_from_slice(&direction);
            kkt.place(&pos, alpha, h, &mut trial);
            trial_f = evaluate(model, &trial, &mut trial_g, &fk);
            let taken = match trial_f {
                None => false,
                Some(_)
                    if feasible_now
                        && shape_floor
                            .as_ref()
                            .is_some_and(|floor| !floor.kept(model.mesh(), &trial)) =>
                {
                    // Refused before its corrections: they move the trial back onto the
                    // constraints by a chord step far shorter than the step, and did not
                    // once make a broken shape floor whole again (measured on seven shared
                    // meshes: 80 trials, every one refused after its corrections too).
                    false
                }
                Some(_) if feasible_now => {
                    // Back onto the constraints by corrections from the trial, kept while
                    // g_max falls fast enough to reach the tolerance within the corrections
                    // left at its last rate (a chord iteration converges linearly; a slower
                    // one cannot make it, and a trial costs its corrections), then the
                    // objective must have fallen.
                    for k in 0..MAX_CORRECTIONS {
                        let before = g_max(&trial_g);
                        if before <= tol || kkt.correct(&trial_g, &cons).is_err() {
                            break;
                        }
                        kkt.place(&trial, 1.0, h, &mut trial2);
                        let Some(f2) = evaluate(model, &trial2, &mut trial_g2, &fk) else {
                            break;
                        };
                        let after = g_max(&trial_g2);
                        if after >= before {
                            break;
                        }
                        std::mem::swap(&mut trial, &mut trial2);
                        std::mem::swap(&mut trial_g, &mut trial_g2);
                        trial_f = Some(f2);
                        let left = (MAX_CORRECTIONS - 1 - k) as i32;
                        if after > tol && after * (after / before).powi(left) > tol {
                            break;
                        }
                    }
                    g_max(&trial_g) <= tol
                        && trial_f.is_some_and(|ft| ft < f)
                        && shape_floor
                            .as_ref()
                            .is_none_or(|floor| floor.kept(model.mesh(), &trial))
                }
                Some(_) => {
                    // Levenberg–Marquardt ratio of the actual to the predicted fall of
                    // Σ(2π − θ)².
                    let predicted = predicted_at(alpha, w);
                    let ratio = (sq(&g) - sq(&trial_g)) / predicted;
                    if predicted > 0.0 && ratio > ACCEPT {
                        damping = (damping * (1.0f64 / 3.0).max(1.0 - (2.0 * ratio - 1.0).powi(3)))
                            .max(DAMPING_MIN);
                        growth = 2.0;
                        if ratio > 0.75 && alpha == 1.0 {
                            weight = (2.0 * weight).min(1.0);
                        }
                        true
                    } else {
                        false
                    }
                }
            };
            if !taken {
                if feasible_now {
                    // The trust region, after any refusal (a degenerate trial too, which
                    // would otherwise be built again from the same system).
                    sigma *= 4.0;
                } else {
                    weight *= 0.5;
                    damping *= growth;
                    growth *= 2.0;
                }
            }
            if taken || tries == backtracks {
                break taken;
            }
            // A shortened trial with its corrections can take seconds on a big mesh.
            if control.cancelled() {
                return Err(AlgoError::Cancelled);
            }
            tries += 1;
            run.inner += 1;
            alpha *= shrink;
        };
        if accepted {
            std::mem::swap(&mut pos, &mut trial);
            std::mem::swap(&mut g, &mut trial_g);
            f = trial_f.unwrap_or(f);
            // Corrections: re-solve with the same factorisation against the new residual,
            // kept while each halves Σ(2π − θ)² (a chord step on the constraints).
            for _ in 0..MAX_CORRECTIONS {
                let before = sq(&g);
                if g_max(&g) <= tol || kkt.correct(&g, &cons).is_err() {
                    break;
                }
                kkt.place(&pos, 1.0, h, &mut trial);
                match evaluate(model, &trial, &mut trial_g, &fk) {
                    Some(ft) if sq(&trial_g) <= 0.25 * before => {
                        std::mem::swap(&mut pos, &mut trial);
                        std::mem::swap(&mut g, &mut trial_g);
                        f = ft;
                        run.inner += 1;
                    }
                    _ => break,
                }
            }
        }
        if feasible_now && accepted {
            sigma = (sigma / 3.0).max(SIGMA_MIN);
        }
        let gm = g_max(&g);
        run.history.push(HistoryEntry {
            iteration: it,
            max_flattenability: gm,
            big_g: super::energy::big_g(&g),
            e: model.e(&pos),
            rho: None,
            cg_steps: None,
            step_length: Some(if accepted { alpha * w } else { 0.0 }),
            damping: Some(damping_now),
        });
        control.progress(&Progress {
            stage: "sqp".into(),
            iteration: it,
            max_flattenability: Some(gm),
            step_norm: Some(alpha * step_max),
        });
        let feasible = gm <= tol;
        if accepted {
            let improves = if feasible {
                run.g_max > tol || f < best_f
            } else {
                run.g_max > tol && gm < run.g_max
            };
            if improves {
                run.g_max = gm;
                run.best_iteration = it;
                run.positions.copy_from_slice(&pos);
                if feasible {
                    best_f = f;
                }
            }
        }
        // Stationary on the constraints: the trust region shrank to nothing, the step (in
        // Newton terms: σ shortens it about 1 + σ times) is below `step_tolerance`, or f fell by
        // less than CREEP over the last CREEP_WINDOW iterations.
        if feasible_now {
            let slot = objective_its % CREEP_WINDOW;
            let creeping = objective_its >= CREEP_WINDOW && f_ring[slot] - f < CREEP * f;
            f_ring[slot] = f;
            objective_its += 1;
            // A collapsed trust region is stationary only if the unshortened step is short
            // too; otherwise the shape floor or the constraints refused every step (seen on
            // a crumpled garment: σ 10 → 1e6 in three iterations, Newton step 52 h̄).
            let newton = step_max * (1.0 + sigma_now);
            if sigma > SIGMA_MAX && newton > params.step_tolerance {
                run.stop = Stop::LineSearch;
                collapsed = Some(newton);
                break;
            }
            if creeping
                || sigma > SIGMA_MAX
                || (accepted && alpha * step_max * (1.0 + sigma_now) <= params.step_tolerance)
            {
                run.stop = Stop::Tolerance;
                break;
            }
        }
        if damping > DAMPING_MAX {
            run.stop = Stop::LineSearch;
            break;
        }
        if gm <= 0.5 * stall_ref {
            stall_ref = gm;
            since_halving = 0;
        } else if !feasible {
            since_halving += 1;
            if since_halving >= params.stall_iterations {
                run.stop = Stop::Stall;
                break;
            }
        }
    }
    if run.g_max <= tol && run.stop != Stop::Tolerance {
        // Flattenable but not yet stationary: still a usable answer; say so.
        let why = match collapsed {
            Some(newton) => format!(
                "line_search: no step the shape floor and the constraints accept; the trust \
                 region collapsed with the unshortened step {newton:.3} mean edge lengths"
            ),
            None => run.stop.as_str().to_string(),
        };
        run.stop_detail = format!(
            "flattenable after {} iterations, not yet stationary ({why})",
            run.best_iteration,
        );
    }
    Ok(run)
}

/// What the objective phase may not make worse, so that lowering the deformation never buys
/// slivers or folds (measured without it: corners of 0.00–0.01° on 5 of 11 flattened shared
/// meshes). The smallest corner may fall to SLIVER_DEGREES, or to the input's or the first
/// flattenable iterate's smallest if lower; the fold count may not pass theirs.
struct ShapeFloor {
    corner: f64,
    folds: usize,
}

impl ShapeFloor {
    fn new(mesh: &Mesh, v0: &[[f64; 3]], start: &[[f64; 3]]) -> Self {
        Self {
            corner: smallest_corner_at(mesh, start)
                .min(smallest_corner_at(mesh, v0))
                .min(SLIVER_DEGREES.to_radians()),
            folds: fold_count_at(mesh, start).max(fold_count_at(mesh, v0)),
        }
    }

    fn kept(&self, mesh: &Mesh, pos: &[[f64; 3]]) -> bool {
        smallest_corner_at(mesh, pos) >= self.corner && fold_count_at(mesh, pos) <= self.folds
    }
}

/// Added to f once the run is flattenable (beyond the papers), so that the objective phase
/// bends its steps away from what the shape floor would refuse instead of being refused at
/// it:
/// - β Σ_e (φ_e − t_e)₊² over the interior edges: φ_e is the turning angle across edge e,
///   t_e = max(BARRIER_DEGREES, φ_e of the input), so the input's own creases are left alone.
///   Measured on the 35-case subset (issue 16 note, 2026-11-29), β = 1 against none: Σ δS
///   235.1 → 219.4 % points, folds left 20 → 14, iterations 2832 → 3491.
/// - γ Σ_c (t_c − a_c)₊² over the corners: a_c is the corner angle, t_c =
///   min(CORNER_BARRIER_DEGREES, a_c of the input). Without it, on the t-shirt, one corner
///   at the 1° floor refused every full step, σ grew 4/3 per iteration and the run stopped
///   by creep far from stationary (f 309, where 240 is reachable). γ = 1000 (the angles are
///   in radians, f in h̄²): on the 35-case subset (issue 16 note, 2026-11-29) Σ δS 219.4 →
///   195.5 % points (mh_classicshoes_medium 9.9 → 3.2 %, mh_female_sportsuit01 24.7 →
///   12.2 %, the t-shirt 9.8 → 8.3 %), smallest corners 1° → 3° on most, iterations 3491 →
///   4210; γ = 100 and 10000 gave the t-shirt the same δS within 0.03 points.
///
/// Gradients join ∇f; the Gauss–Newton Hessians 2β ∇φ∇φᵀ and 2γ ∇a∇aᵀ enter H as the
/// block-diagonal majorisers k · 2w Σ_v ∇_v ∇_vᵀ (w = β or γ; (Σ_k a_k)² ≤ k Σ_k a_k² over a
/// term's k vertices: 4 for a hinge, 3 for a corner), on blocks the pattern already has.
struct ShapeBarrier {
    beta: f64,
    hinges: Vec<[u32; 4]>,
    /// t_e per hinge, radians, and its cosine.
    limit: Vec<(f64, f64)>,
    gamma: f64,
    /// Each corner (its vertex, then the next two of its face), t_c (radians) and cos t_c.
    corners: Vec<([u32; 3], f64, f64)>,
}

impl ShapeBarrier {
    fn new(mesh: &Mesh, v0: &[[f64; 3]], beta: f64, gamma: f64) -> Self {
        let hinges: Vec<[u32; 4]> = if beta > 0.0 {
            (0..mesh.conn().edges().len() as u32)
                .filter_map(|e| crate::algorithms::unfold::hinge_of(mesh, e))
                .collect()
        } else {
            Vec::new()
        };
        let limit = hinges
            .iter()
            .map(|&q| turning_at(v0, q).0.max(BARRIER_DEGREES.to_radians()))
            .map(|t| (t, t.cos()))
            .collect();
        let corners = if gamma > 0.0 {
            let floor = CORNER_BARRIER_DEGREES.to_radians();
            mesh.triangles()
                .iter()
                .flat_map(|t| (0..3).map(move |k| [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]))
                .map(|q| {
                    let t = corner_at(v0, q).min(floor);
                    (q, t, t.cos())
                })
                .collect()
        } else {
            Vec::new()
        };
        Self {
            beta,
            hinges,
            limit,
            gamma,
            corners,
        }
    }

    fn value(&self, pos: &[[f64; 3]]) -> f64 {
        let hinges: f64 = self
            .hinges
            .iter()
            .zip(&self.limit)
            .filter(|&(&q, &(_, cos))| hinge_may_pass(pos, q, cos))
            .map(|(&q, &(t, _))| (turning_at(pos, q).0 - t).max(0.0).powi(2))
            .sum();
        let corners: f64 = self
            .corners
            .iter()
            .filter(|&&(q, _, cos)| corner_may_pass(pos, q, cos))
            .map(|&(q, t, _)| (t - corner_at(pos, q)).max(0.0).powi(2))
            .sum();
        self.beta * hinges + self.gamma * corners
    }

    /// Each term past its limit: its vertices, its weight (β or γ), the derivative of its
    /// value with respect to its angle, and that angle's gradient (the corner's at its vertex
    /// and the next two).
    fn for_each_active(
        &self,
        pos: &[[f64; 3]],
        mut visit: impl FnMut(&[u32], f64, f64, &[[f64; 3]]),
    ) {
        for (&q, &(t, cos)) in self.hinges.iter().zip(&self.limit) {
            if !hinge_may_pass(pos, q, cos) {
                continue;
            }
            let (phi, grad) = turning_at(pos, q);
            if phi > t {
                visit(&q, self.beta, 2.0 * self.beta * (phi - t), &grad);
            }
        }
        for &(q, t, cos) in &self.corners {
            if !corner_may_pass(pos, q, cos) {
                continue;
            }
            let [a, b, c] = q.map(|v| pos[v as usize]);
            let angle = crate::geometry::corner_angle(a, b, c);
            if angle < t {
                let (gb, gc) = corner_angle_gradient(a, b, c);
                // A degenerate face has no gradient (the trials refuse such faces anyway).
                if !gb.iter().chain(&gc).all(|x| x.is_finite()) {
                    continue;
                }
                let ga = [0, 1, 2].map(|i| -(gb[i] + gc[i]));
                visit(
                    &q,
                    self.gamma,
                    -2.0 * self.gamma * (t - angle),
                    &[ga, gb, gc],
                );
            }
        }
    }

    /// The barrier's part of the tangential right-hand side and of H, in the KKT system's
    /// units of h̄ (as E's: the gradient times h̄, the Hessian times h̄²).
    fn add_to(&self, pos: &[[f64; 3]], h: f64, kkt: &mut Kkt) {
        let dim = kkt.rhs.len() / 2;
        self.for_each_active(pos, |q, w, r, grad| {
            // (Σ_k a_k)² ≤ k Σ_k a_k² over the term's k vertices.
            let majoriser = q.len() as f64 * h * h * 2.0 * w;
            for (gv, &v) in grad.iter().zip(q) {
                let s = kkt.slot[v as usize];
                if s == NONE {
                    continue;
                }
                let s = s as usize;
                for k in 0..3 {
                    kkt.rhs[dim + 3 * s + k] -= h * r * gv[k];
                }
                let mut idx = 0;
                for i in 0..3 {
                    for j in 0..=i {
                        kkt.extra[s][idx] += majoriser * gv[i] * gv[j];
                        idx += 1;
                    }
                }
            }
        });
    }
}

/// Whether hinge q's turning angle φ may exceed its limit t, from `cos_limit` = cos t: false
/// when cos φ ≥ cos t, which needs no atan2 (the barrier's value and gradient cost a sixth
/// of a develop run otherwise, almost all of it on hinges far from their limits).
fn hinge_may_pass(pos: &[[f64; 3]], q: [u32; 4], cos_limit: f64) -> bool {
    let [i, j, k, l] = q.map(|v| pos[v as usize]);
    let e = sub(j, i);
    let n1 = crate::mesh::cross(e, sub(k, i));
    let n2 = crate::mesh::cross(sub(l, j), e);
    dot(n1, n2) < cos_limit * (dot(n1, n1) * dot(n2, n2)).sqrt()
}

/// Whether the corner at q[0] may be below its limit t, from `cos_limit` = cos t: false when
/// its cosine is at most cos t on a face whose two edges at q[0] have length (the angle is
/// 0 otherwise).
fn corner_may_pass(pos: &[[f64; 3]], q: [u32; 3], cos_limit: f64) -> bool {
    let [a, b, c] = q.map(|v| pos[v as usize]);
    let (u, w) = (sub(b, a), sub(c, a));
    let lengths = (dot(u, u) * dot(w, w)).sqrt();
    !(lengths > 0.0 && dot(u, w) <= cos_limit * lengths)
}

/// The corner angle at q[0] in the face (q[0], q[1], q[2]) at `pos`.
fn corner_at(pos: &[[f64; 3]], q: [u32; 3]) -> f64 {
    let [a, b, c] = q.map(|v| pos[v as usize]);
    crate::geometry::corner_angle(a, b, c)
}

/// Turning angle across hinge q at `pos` and its gradient (`geometry::turning_angle_gradient`).
fn turning_at(pos: &[[f64; 3]], q: [u32; 4]) -> (f64, [[f64; 3]; 4]) {
    let [i, j, k, l] = q.map(|v| pos[v as usize]);
    crate::geometry::turning_angle_gradient(i, j, k, l)
}

/// f at `pos` and g into `g`, or None when a triangle is degenerate or a value not finite.
fn evaluate(
    model: &Model<'_>,
    pos: &[[f64; 3]],
    g: &mut [f64],
    f_of: &dyn Fn(&[[f64; 3]]) -> f64,
) -> Option<f64> {
    if model.mesh().triangles().iter().any(|t| {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        is_degenerate_triangle(a, b, c)
    }) {
        return None;
    }
    model.g(pos, g);
    let f = f_of(pos);
    (f.is_finite() && g.iter().all(|x| x.is_finite())).then_some(f)
}

/// The KKT system of one mesh: fixed pattern, symbolic factorisation, value slots.
pub(super) struct Kkt {
    /// Movable vertices (slot s ↔ vertex verts[s]) and constrained ones (row c ↔ cons[c]).
    verts: Vec<u32>,
    cons: Vec<u32>,
    slot: Vec<u32>,
    m: usize,
    values: Vec<f64>,
    /// Per slot: where its lower 3×3 block's six values start.
    diag_at: Vec<usize>,
    /// Per edge: where its 3×3 off-diagonal block starts (usize::MAX unless both ends move).
    edge_at: Vec<usize>,
    /// Per face corner (3f + k) with a constrained vertex: where Λ's three 3-value blocks
    /// (the corner's vertex and the next two) start (usize::MAX for a fixed vertex).
    corner_at: Vec<[usize; 3]>,
    /// Per entry of `corner_at`: its constraint row and the slots of its three vertices.
    corner_slots: Vec<(u32, [u32; 3])>,
    reg_at: usize,
    /// Added to each vertex's lower 3×3 block of H at the next `fill` (the hinge barrier).
    extra: Vec<[f64; 6]>,
    solver: LdltSolver,
    rhs: Vec<f64>,
    step: Vec<f64>,
    /// The multipliers y of the last objective-phase solve, one per constraint, whose
    /// constraint curvature Σ_c (y_c ∇²α_c)₊ `fill` adds to H when `curvature` is set.
    multipliers: Vec<f64>,
    curvature: bool,
    /// Each corner's curvature term convexified (false only in a test, which checks the
    /// exact Σ y_c ∇²α_c against finite differences of Σ y_i ∇θ_i).
    positive_part: bool,
}

impl Kkt {
    /// The pattern and its symbolic factorisation; not started when `control` says the
    /// step (~3 s on a Loop-subdivided 205k-face mesh, uninterruptible) would end too late.
    pub(super) fn new(
        model: &Model<'_>,
        movable: &[bool],
        control: &dyn Control,
    ) -> Result<Self, AlgoError> {
        let faces = model.mesh().num_faces() as f64;
        if control.cancelled_before(crate::cost::DEVELOP_SETUP.seconds(faces)) {
            return Err(AlgoError::Cancelled);
        }
        let setup = std::time::Instant::now();
        let kkt = Self::unchecked(model, movable)?;
        crate::cost::DEVELOP_SETUP.learn(faces, setup.elapsed().as_secs_f64());
        Ok(kkt)
    }

    fn unchecked(model: &Model<'_>, movable: &[bool]) -> Result<Self, AlgoError> {
        let mesh = model.mesh();
        let nv = mesh.num_vertices();
        let mut slot = vec![NONE; nv];
        let mut verts = Vec::new();
        for v in 0..nv {
            if movable[v] {
                slot[v] = verts.len() as u32;
                verts.push(v as u32);
            }
        }
        let mut crow = vec![NONE; nv];
        let mut cons = Vec::new();
        for v in 0..nv {
            if model.is_interior(v) && movable[v] {
                crow[v] = cons.len() as u32;
                cons.push(v as u32);
            }
        }
        let m = verts.len();
        let dim = 3 * m + cons.len();
        let mut entries = Vec::new();
        let mut diag_at = Vec::with_capacity(m);
        for s in 0..m {
            diag_at.push(entries.len());
            for i in 0..3 {
                for j in 0..=i {
                    entries.push((3 * s + i, 3 * s + j));
                }
            }
        }
        let mut edge_at = Vec::with_capacity(mesh.conn().edges().len());
        for e in mesh.conn().edges() {
            let (sa, sb) = (slot[e[0] as usize], slot[e[1] as usize]);
            if sa == NONE || sb == NONE || sa == sb {
                edge_at.push(usize::MAX);
                continue;
            }
            let (hi, lo) = (sa.max(sb) as usize, sa.min(sb) as usize);
            edge_at.push(entries.len());
            for i in 0..3 {
                for j in 0..3 {
                    entries.push((3 * hi + i, 3 * lo + j));
                }
            }
        }
        let mut corner_at = Vec::with_capacity(3 * mesh.num_faces());
        let mut corner_slots = Vec::with_capacity(3 * mesh.num_faces());
        for t in mesh.triangles() {
            for k in 0..3 {
                let a = t[k] as usize;
                let mut at = [usize::MAX; 3];
                let mut slots = [NONE; 3];
                if crow[a] != NONE {
                    let r = 3 * m + crow[a] as usize;
                    for x in 0..3 {
                        let s = slot[t[(k + x) % 3] as usize];
                        if s != NONE {
                            at[x] = entries.len();
                            slots[x] = s;
                            for i in 0..3 {
                                entries.push((r, 3 * s as usize + i));
                            }
                        }
                    }
                }
                corner_at.push(at);
                corner_slots.push((crow[a], slots));
            }
        }
        let reg_at = entries.len();
        for c in 0..cons.len() {
            entries.push((3 * m + c, 3 * m + c));
        }
        let signs = (0..dim).map(|i| if i < 3 * m { 1 } else { -1 }).collect();
        let groups: Vec<u32> = (0..dim)
            .map(|i| {
                if i < 3 * m {
                    (i / 3) as u32
                } else {
                    slot[cons[i - 3 * m] as usize]
                }
            })
            .collect();
        let ncons = cons.len();
        let solver = LdltSolver::new(dim, &entries, signs, Some(&groups))
            .map_err(|e| AlgoError::Input(format!("KKT system: {e}")))?;
        Ok(Kkt {
            verts,
            cons,
            slot,
            m,
            values: vec![0.0; entries.len()],
            diag_at,
            edge_at,
            corner_at,
            corner_slots,
            reg_at,
            extra: vec![[0.0; 6]; m],
            solver,
            rhs: vec![0.0; 2 * dim],
            step: vec![0.0; 3 * m],
            multipliers: vec![0.0; ncons],
            curvature: false,
            positive_part: true,
        })
    }

    /// H (Gauss–Newton, times h̄², with the constraint curvature once `curvature` is set) and
    /// h̄Λ at `pos`, then the numeric factorisation.
    pub(super) fn fill(
        &mut self,
        model: &Model<'_>,
        pos: &[[f64; 3]],
        h: f64,
        mu: f64,
        kappa: f64,
        damping: f64,
    ) -> Result<(), AlgoError> {
        let mesh = model.mesh();
        self.values.fill(0.0);
        for &d in &self.diag_at {
            // Lower 3×3 in the order (0,0), (1,0), (1,1), (2,0), (2,1), (2,2).
            for idx in [0, 2, 5] {
                self.values[d + idx] = 2.0 * mu;
            }
        }
        for (e, ends) in mesh.conn().edges().iter().enumerate() {
            let d = sub(pos[ends[0] as usize], pos[ends[1] as usize]);
            let l = dot(d, d).sqrt();
            if l == 0.0 {
                continue;
            }
            let u = d.map(|x| x / l);
            for &v in ends {
                let s = self.slot[v as usize];
                if s == NONE {
                    continue;
                }
                let at = self.diag_at[s as usize];
                let mut idx = 0;
                for i in 0..3 {
                    for j in 0..=i {
                        self.values[at + idx] += 2.0 * u[i] * u[j];
                        if i == j {
                            self.values[at + idx] += 2.0 * kappa;
                        }
                        idx += 1;
                    }
                }
            }
            let at = self.edge_at[e];
            if at != usize::MAX {
                for i in 0..3 {
                    for j in 0..3 {
                        self.values[at + 3 * i + j] = -2.0 * u[i] * u[j];
                    }
                    self.values[at + 4 * i] -= 2.0 * kappa;
                }
            }
        }
        for (f, t) in mesh.triangles().iter().enumerate() {
            for k in 0..3 {
                let at = self.corner_at[3 * f + k];
                if at == [usize::MAX; 3] {
                    continue;
                }
                let p = [0, 1, 2].map(|x| pos[t[(k + x) % 3] as usize]);
                let (gb, gc) = corner_angle_gradient(p[0], p[1], p[2]);
                let grads = [
                    [0, 1, 2].map(|i| -(gb[i] + gc[i]) * h),
                    gb.map(|x| x * h),
                    gc.map(|x| x * h),
                ];
                for (x, &a) in at.iter().enumerate() {
                    if a != usize::MAX {
                        self.values[a..a + 3].copy_from_slice(&grads[x]);
                    }
                }
            }
        }
        if self.curvature {
            self.add_constraint_curvature(model, pos, h);
        }
        for c in 0..self.cons.len() {
            self.values[self.reg_at + c] = -(REGULARISATION + damping);
        }
        for (&d, extra) in self.diag_at.iter().zip(&self.extra) {
            for (v, x) in self.values[d..d + 6].iter_mut().zip(extra) {
                *v += x;
            }
        }
        self.solver
            .factor(&self.values)
            .map_err(|e| AlgoError::Input(format!("KKT factorisation: {e}")))
    }

    /// Σ_c h̄² (y_c ∇²α_c)₊ over the corners at constrained vertices: the constraints'
    /// curvature in the Hessian of the Lagrangian f + yᵀ(θ − 2π), each corner's term replaced
    /// by its positive semidefinite part ([`corner_angle_hessian`]) so that H stays positive
    /// definite and the pattern (a corner couples its triangle's vertices, already coupled by
    /// edges) does not change.
    fn add_constraint_curvature(&mut self, model: &Model<'_>, pos: &[[f64; 3]], h: f64) {
        let mesh = model.mesh();
        for (f, t) in mesh.triangles().iter().enumerate() {
            for k in 0..3 {
                let (c, slots) = self.corner_slots[3 * f + k];
                if c == NONE || self.multipliers[c as usize] == 0.0 {
                    continue;
                }
                let y = self.multipliers[c as usize] * h * h;
                let p = [0, 1, 2].map(|x| pos[t[(k + x) % 3] as usize]);
                let Some(block) = corner_blocks(p, y, self.positive_part) else {
                    continue;
                };
                for x in 0..3 {
                    if slots[x] == NONE {
                        continue;
                    }
                    let at = self.diag_at[slots[x] as usize];
                    let mut idx = 0;
                    for i in 0..3 {
                        for j in 0..=i {
                            self.values[at + idx] += block[x][x][i][j];
                            idx += 1;
                        }
                    }
                }
                for x in 0..3 {
                    let z = (x + 1) % 3;
                    if slots[x] == NONE || slots[z] == NONE {
                        continue;
                    }
                    // Half-edge 3f + j runs from corner j to corner j + 1.
                    let edge = mesh.conn().edge_of((3 * f + (k + x) % 3) as u32);
                    let at = self.edge_at[edge as usize];
                    if at == usize::MAX {
                        continue;
                    }
                    // The edge's block is (3·hi + i, 3·lo + j) for its higher and lower slot.
                    let (hi, lo) = if slots[x] > slots[z] { (x, z) } else { (z, x) };
                    for i in 0..3 {
                        for j in 0..3 {
                            self.values[at + 3 * i + j] += block[hi][lo][i][j];
                        }
                    }
                }
            }
        }
    }

    /// Solve for the two right-hand sides in `rhs` (normal, then tangential), overwritten by
    /// the solutions.
    fn solve_two(&mut self) -> Result<(), AlgoError> {
        self.solver
            .solve_many_in_place(&mut self.rhs, 2)
            .map_err(|e| AlgoError::Input(format!("KKT solve: {e}")))
    }

    /// The normal step for residual `g` alone (right-hand side [0; g]) into `step`.
    fn correct(&mut self, g: &[f64], cons: &[u32]) -> Result<(), AlgoError> {
        let dim = self.rhs.len() / 2;
        let m3 = 3 * self.m;
        let rhs = &mut self.rhs[..dim];
        rhs.fill(0.0);
        for (c, &v) in cons.iter().enumerate() {
            rhs[m3 + c] = g[v as usize];
        }
        self.solver
            .solve_in_place(rhs)
            .map_err(|e| AlgoError::Input(format!("KKT solve: {e}")))?;
        self.step.copy_from_slice(&self.rhs[..m3]);
        Ok(())
    }

    /// x = P⁻¹ r for P = H + 2μI + (h̄²/ε) ΛᵀΛ, with −ε the (2,2) block as filled: the upper
    /// block of the KKT solve for [r; 0] (eliminating y = (h̄Λ x)/ε). Vertices that do not move
    /// get 0.
    pub(super) fn precondition(
        &mut self,
        r: &[[f64; 3]],
        out: &mut [[f64; 3]],
    ) -> Result<(), AlgoError> {
        let dim = self.rhs.len() / 2;
        let rhs = &mut self.rhs[..dim];
        rhs.fill(0.0);
        for (s, &v) in self.verts.iter().enumerate() {
            for k in 0..3 {
                rhs[3 * s + k] = r[v as usize][k];
            }
        }
        self.solver
            .solve_in_place(rhs)
            .map_err(|e| AlgoError::Input(format!("KKT solve: {e}")))?;
        for o in out.iter_mut() {
            *o = [0.0; 3];
        }
        for (s, &v) in self.verts.iter().enumerate() {
            for k in 0..3 {
                out[v as usize][k] = self.rhs[3 * s + k];
            }
        }
        Ok(())
    }

    /// Λδ per constraint (scaled units: h̄Λ times the step in h̄) into `out`.
    fn lambda_times(&self, step: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for (at, (c, slots)) in self.corner_at.iter().zip(&self.corner_slots) {
            for x in 0..3 {
                if at[x] != usize::MAX {
                    let s = 3 * slots[x] as usize;
                    let v = &self.values[at[x]..at[x] + 3];
                    out[*c as usize] += v[0] * step[s] + v[1] * step[s + 1] + v[2] * step[s + 2];
                }
            }
        }
    }

    /// `out` = `pos` moved by α h̄ δ.
    fn place(&self, pos: &[[f64; 3]], alpha: f64, h: f64, out: &mut [[f64; 3]]) {
        out.copy_from_slice(pos);
        for (s, &v) in self.verts.iter().enumerate() {
            for k in 0..3 {
                out[v as usize][k] += alpha * h * self.step[3 * s + k];
            }
        }
    }
}

/// (y ∇²α)₊ (or y ∇²α itself) of the corner at p[0] in triangle p as 3 × 3 blocks over its
/// three vertices, block[x][z][i][j] = ∂²/∂p_x,i ∂p_z,j, from the blocks over
/// (u, w) = (p₁ − p₀, p₂ − p₀) (∂/∂p₀ = −∂/∂u − ∂/∂w). `None` for a degenerate corner.
fn corner_blocks(p: [[f64; 3]; 3], y: f64, positive_part: bool) -> Option<[[[[f64; 3]; 3]; 3]; 3]> {
    let [uu, uw, ww] = if positive_part {
        corner_angle_hessian(p[0], p[1], p[2], Some(y))?
    } else {
        corner_angle_hessian(p[0], p[1], p[2], None)?.map(|m| m.map(|r| r.map(|x| y * x)))
    };
    let mut b = [[[[0.0; 3]; 3]; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let wu = uw[j][i];
            b[1][1][i][j] = uu[i][j];
            b[2][2][i][j] = ww[i][j];
            b[1][2][i][j] = uw[i][j];
            b[2][1][i][j] = wu;
            b[0][1][i][j] = -(uu[i][j] + wu);
            b[1][0][i][j] = -(uu[i][j] + uw[i][j]);
            b[0][2][i][j] = -(uw[i][j] + ww[i][j]);
            b[2][0][i][j] = -(wu + ww[i][j]);
            b[0][0][i][j] = uu[i][j] + uw[i][j] + wu + ww[i][j];
        }
    }
    Some(b)
}

#[cfg(test)]
mod tests {
    use super::ShapeBarrier;
    use crate::mesh::Mesh;

    /// A 4 × 3 grid of unit squares, each split in two, vertex (i, j) at `at(i, j, index)`.
    fn grid(at: impl Fn(usize, usize, usize) -> [f64; 3]) -> Mesh {
        let cells = crate::fixtures::grid(4, 3, false, |i, j| at(i, j, 5 * j + i), |_, _| true);
        crate::corpus::grid_mesh(cells, "grid")
    }

    /// The gradient `for_each_active` gives, summed over the active terms, against central
    /// differences of `value`, to 1e-6 of its largest component; some terms must be active
    /// and some not.
    fn check_gradient(barrier: &ShapeBarrier, pos: &[[f64; 3]], terms: usize) {
        let mut grad = vec![[0.0; 3]; pos.len()];
        let mut active = 0;
        barrier.for_each_active(pos, |q, _, r, g| {
            active += 1;
            for (gv, &v) in g.iter().zip(q) {
                for k in 0..3 {
                    grad[v as usize][k] += r * gv[k];
                }
            }
        });
        assert!(
            active > 0 && active < terms,
            "{active} of {terms} terms active"
        );
        let eps = 1e-6;
        let scale = grad.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for v in 0..pos.len() {
            for k in 0..3 {
                let mut p = pos.to_vec();
                p[v][k] += eps;
                let up = barrier.value(&p);
                p[v][k] -= 2.0 * eps;
                let down = barrier.value(&p);
                let fd = (up - down) / (2.0 * eps);
                assert!(
                    (fd - grad[v][k]).abs() <= 1e-6 * scale,
                    "vertex {v} axis {k}: analytic {} against {fd}",
                    grad[v][k]
                );
            }
        }
    }

    /// The constraint curvature `fill` adds, assembled with the exact corner Hessians, times
    /// a random direction against central differences of Σ_i y_i ∇θ_i (the angle-sum
    /// gradients of Props. 1–2, an independent code path) on a noisy grid.
    #[test]
    fn constraint_curvature_matches_central_differences() {
        use super::{Kkt, Model, NONE};
        let noise = |v: usize, k: usize| ((v * 7 + k * 3) as f64 * 0.9).sin() * 0.3;
        let mesh = grid(|i, j, v| [i as f64 + noise(v, 0), j as f64 + noise(v, 1), noise(v, 2)]);
        let model = Model::new(&mesh);
        let n = mesh.num_vertices();
        let mut kkt = Kkt::new(
            &model,
            &vec![true; n],
            &crate::algorithms::Silent::default(),
        )
        .expect("KKT system");
        assert!(kkt.cons.len() >= 4, "{} constraints", kkt.cons.len());
        let pos = mesh.positions().to_vec();
        kkt.fill(&model, &pos, 1.0, 0.5, 0.0, 0.0)
            .expect("factorises");
        let plain = kkt.values.clone();
        for (c, y) in kkt.multipliers.iter_mut().enumerate() {
            *y = 1.5 * ((c as f64) * 1.3).cos();
        }
        kkt.curvature = true;
        kkt.positive_part = false;
        // The exact Hessian is indefinite; only its values are read.
        let _ = kkt.fill(&model, &pos, 1.0, 0.5, 0.0, 0.0);
        let added: Vec<f64> = kkt.values.iter().zip(&plain).map(|(a, b)| a - b).collect();
        let dir: Vec<[f64; 3]> = (0..n)
            .map(|v| [0, 1, 2].map(|k| ((v * 5 + k * 11) as f64 * 1.7).cos()))
            .collect();
        let mut hv = vec![[0.0; 3]; n];
        for (s, &at) in kkt.diag_at.iter().enumerate() {
            let v = kkt.verts[s] as usize;
            let lower = [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2)];
            for (idx, &(i, j)) in lower.iter().enumerate() {
                hv[v][i] += added[at + idx] * dir[v][j];
                if i != j {
                    hv[v][j] += added[at + idx] * dir[v][i];
                }
            }
        }
        for (e, ends) in mesh.conn().edges().iter().enumerate() {
            let at = kkt.edge_at[e];
            if at == usize::MAX {
                continue;
            }
            let (sa, sb) = (kkt.slot[ends[0] as usize], kkt.slot[ends[1] as usize]);
            assert!(sa != NONE && sb != NONE);
            let (hi, lo) = if sa > sb {
                (ends[0], ends[1])
            } else {
                (ends[1], ends[0])
            };
            let (hi, lo) = (hi as usize, lo as usize);
            for i in 0..3 {
                for j in 0..3 {
                    hv[hi][i] += added[at + 3 * i + j] * dir[lo][j];
                    hv[lo][j] += added[at + 3 * i + j] * dir[hi][i];
                }
            }
        }
        let weighted_gradient = |p: &[[f64; 3]]| {
            let mut g = vec![[0.0; 3]; n];
            let mut out = Vec::new();
            for (c, &q) in kkt.cons.iter().enumerate() {
                crate::geometry::theta_gradient_with(&mesh, p, q, &mut out);
                for &(v, d) in &out {
                    for k in 0..3 {
                        g[v as usize][k] += kkt.multipliers[c] * d[k];
                    }
                }
            }
            g
        };
        let eps = 1e-5;
        let moved = |t: f64| -> Vec<[f64; 3]> {
            pos.iter()
                .zip(&dir)
                .map(|(p, d)| [0, 1, 2].map(|k| p[k] + t * d[k]))
                .collect()
        };
        let (up, down) = (
            weighted_gradient(&moved(eps)),
            weighted_gradient(&moved(-eps)),
        );
        let scale = hv.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.1, "the curvature term is empty");
        for v in 0..n {
            for k in 0..3 {
                let fd = (up[v][k] - down[v][k]) / (2.0 * eps);
                assert!(
                    (fd - hv[v][k]).abs() <= 1e-6 * scale,
                    "vertex {v} axis {k}: assembled {} against {fd}",
                    hv[v][k]
                );
            }
        }
    }

    /// The hinge term on a crumpled grid where some hinges pass 90° and others do not; the
    /// flat input sets every limit to 90°, and the flat grid itself costs nothing.
    #[test]
    fn hinge_gradient_matches_central_differences() {
        let mesh = grid(|i, j, _| [i as f64, j as f64, 0.0]);
        let v0 = mesh.positions().to_vec();
        let barrier = ShapeBarrier::new(&mesh, &v0, 1.0, 0.0);
        assert_eq!(barrier.value(&v0), 0.0);
        // Alternate columns up and down by more than an edge: sharp folds.
        let crumpled = grid(|i, j, v| {
            let z = if i % 2 == 0 {
                0.0
            } else {
                1.6 + 0.1 * (v % 3) as f64
            };
            [i as f64, j as f64 + 0.05 * (v % 4) as f64, z]
        });
        check_gradient(&barrier, crumpled.positions(), barrier.hinges.len());
    }

    /// The corner term on the grid with two interior vertices pushed almost onto a neighbour's
    /// edge, so that a few corners close below 3° (and the rest do not).
    #[test]
    fn corner_gradient_matches_central_differences() {
        let mesh = grid(|i, j, _| [i as f64, j as f64, 0.0]);
        let v0 = mesh.positions().to_vec();
        let barrier = ShapeBarrier::new(&mesh, &v0, 0.0, 1000.0);
        assert_eq!(barrier.value(&v0), 0.0);
        assert!(barrier.hinges.is_empty());
        let squeezed = grid(|i, j, v| match (i, j) {
            (1, 1) => [1.97, 1.02, 0.01 * v as f64],
            (3, 1) => [3.0, 1.96, -0.02],
            _ => [i as f64, j as f64, 0.0],
        });
        assert!(barrier.value(squeezed.positions()) > 0.0);
        check_gradient(&barrier, squeezed.positions(), barrier.corners.len());
    }

    /// A hinge the input already bends past 90° is limited at its own angle, not pulled back.
    #[test]
    fn the_inputs_own_creases_are_free() {
        let mesh = grid(|i, j, _| [i as f64, j as f64, if i % 2 == 0 { 0.0 } else { 1.6 }]);
        let v0 = mesh.positions().to_vec();
        let barrier = ShapeBarrier::new(&mesh, &v0, 1.0, 1000.0);
        assert!(barrier.limit.iter().any(|&(t, _)| t > 100f64.to_radians()));
        assert_eq!(barrier.value(&v0), 0.0);
    }

    /// A corner the input already has below 3° is limited at its own angle, not pried open.
    #[test]
    fn the_inputs_own_slivers_are_free() {
        let mesh = grid(|i, j, _| match (i, j) {
            (1, 1) => [1.97, 1.02, 0.0],
            _ => [i as f64, j as f64, 0.0],
        });
        let v0 = mesh.positions().to_vec();
        let barrier = ShapeBarrier::new(&mesh, &v0, 1.0, 1000.0);
        assert!(barrier
            .corners
            .iter()
            .any(|&(_, t, _)| t < 2f64.to_radians()));
        assert_eq!(barrier.value(&v0), 0.0);
    }
}
