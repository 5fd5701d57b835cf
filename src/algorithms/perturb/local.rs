//! Algorithm 2 (LocalFlattenablePerturbation) of wang-flattenable-laplacian-meshes, Sec. 4.
//! See the module doc of [`super`] for the choices made where the paper is vague.

use super::body::Body;
use super::{HistoryEntry, Params, Run, Stop};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::geometry::{angle_sum_with, theta_gradient_with};
use crate::mesh::{Mesh, NONE};
use faer::Mat;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::f64::consts::TAU;

/// Singular values below this fraction of the largest are treated as zero (paper-notes A.3
/// item 10: the paper gives no cutoff).
const SVD_CUTOFF: f64 = 1e-3;

/// Rounds of the active set of body rows in one inner iteration.
const ACTIVE_SET_ROUNDS: usize = 8;

/// Longest move of a vertex in one damped step, in mean edge lengths (beyond the paper).
const STEP_CAP: f64 = 0.05;

/// Step halvings tried when a damped step still takes a vertex below its floor.
const HALVINGS: usize = 10;

/// A heap entry: ϖ of a vertex (max first; ties by lower vertex, for determinism).
#[derive(PartialEq)]
struct Key(f64, u32);
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Key {
    fn cmp(&self, o: &Self) -> Ordering {
        self.0.total_cmp(&o.0).then_with(|| o.1.cmp(&self.1))
    }
}

/// ϖ at every interior vertex of `pos` (0 elsewhere) and its maximum.
pub(super) fn varpi(mesh: &Mesh, pos: &[[f64; 3]]) -> (Vec<f64>, f64) {
    let conn = mesh.conn();
    let w: Vec<f64> = (0..mesh.num_vertices() as u32)
        .map(|v| {
            if conn.is_interior(v) {
                (TAU - angle_sum_with(mesh, pos, v)).abs()
            } else {
                0.0
            }
        })
        .collect();
    let max = w.iter().copied().fold(0.0, f64::max);
    (w, max)
}

/// N_{r+1}(c) in breadth-first order (`c` first) and |N_r(c)|: the first |N_r| entries are
/// N_r(c), the rest its (r+1)-th ring.
fn rings(mesh: &Mesh, c: u32, r: usize, mark: &mut [u32], stamp: u32) -> (Vec<u32>, usize) {
    let conn = mesh.conn();
    let mut out = vec![c];
    mark[c as usize] = stamp;
    let (mut begin, mut n_r) = (0, 1);
    for depth in 0..=r {
        let end = out.len();
        for i in begin..end {
            for &n in conn.ring_of(out[i]) {
                if mark[n as usize] != stamp {
                    mark[n as usize] = stamp;
                    out.push(n);
                }
            }
        }
        begin = end;
        if depth + 1 == r {
            n_r = out.len();
        }
    }
    (out, n_r)
}

/// Thin SVD Λ = U Σ Vᵀ on the calling thread: (U, the singular values, V).
fn thin_svd_seq(lambda: &Mat<f64>) -> Option<(Mat<f64>, faer::Col<f64>, Mat<f64>)> {
    use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors};
    let (m, n) = (lambda.nrows(), lambda.ncols());
    let k = m.min(n);
    let thin = ComputeSvdVectors::Thin;
    let req = svd_scratch::<f64>(m, n, thin, thin, faer::Par::Seq, Default::default());
    let mut mem = faer::dyn_stack::MemBuffer::try_new(req).ok()?;
    let (mut u, mut v) = (Mat::<f64>::zeros(m, k), Mat::<f64>::zeros(n, k));
    let mut s = faer::diag::Diag::<f64>::zeros(k);
    svd(
        lambda.as_ref(),
        s.as_mut(),
        Some(u.as_mut()),
        Some(v.as_mut()),
        faer::Par::Seq,
        faer::dyn_stack::MemStack::new(&mut mem),
        Default::default(),
    )
    .ok()?;
    Some((u, s.column_vector().to_owned(), v))
}

/// The minimum-norm correction of Eq. 22–24: δ = B_p − Λᵀλ with Λδ = B_λ in the least-squares
/// sense, through a thin SVD of Λ itself (Λ = U Σ Vᵀ: Λᵀλ = V Σ⁻¹ Uᵀ (Λ B_p − B_λ), and
/// λ = U Σ⁻² Uᵀ (Λ B_p − B_λ)), singular values below [`SVD_CUTOFF`]·σ_max dropped. The
/// paper forms ΛΛᵀ (Eq. 23), which squares the condition number; the solution is the same
/// where that system is well posed. Returns (δ, λ).
pub fn min_norm_step(lambda: &Mat<f64>, bp: &[f64], bl: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (m, n) = (lambda.nrows(), lambda.ncols());
    if m == 0 {
        return (bp.to_vec(), vec![]);
    }
    let mut r = vec![0.0; m];
    for i in 0..m {
        let mut s = -bl[i];
        for j in 0..n {
            s += lambda[(i, j)] * bp[j];
        }
        r[i] = s;
    }
    // Sequential: on matrices this small faer's default (rayon) parallelism spent more time
    // waking and parking its workers than computing (perf: 42 % of samples in idle rayon
    // workers on benches/perturb's sleeve).
    let Some((u, s, v)) = thin_svd_seq(lambda) else {
        // No decomposition (non-finite entries): no step.
        return (vec![0.0; n], vec![0.0; m]);
    };
    let k = s.nrows();
    let smax = (0..k).map(|i| s[i].abs()).fold(0.0, f64::max);
    let mut z = vec![0.0; k];
    let mut zl = vec![0.0; k];
    for i in 0..k {
        let si = s[i];
        if si.abs() > SVD_CUTOFF * smax && si != 0.0 {
            let mut y = 0.0;
            for row in 0..m {
                y += u[(row, i)] * r[row];
            }
            z[i] = y / si;
            zl[i] = y / (si * si);
        }
    }
    let mut delta = bp.to_vec();
    for j in 0..n {
        let mut t = 0.0;
        for i in 0..k {
            t += v[(j, i)] * z[i];
        }
        delta[j] -= t;
    }
    let mut lam = vec![0.0; m];
    for row in 0..m {
        let mut t = 0.0;
        for i in 0..k {
            t += u[(row, i)] * zl[i];
        }
        lam[row] = t;
    }
    (delta, lam)
}

/// The run's fixed data.
struct Ctx<'a> {
    mesh: &'a Mesh,
    body: Option<&'a Body>,
    params: &'a Params,
    anchor: &'a [[f64; 3]],
    /// Per vertex, the least signed clearance it may end at: min(clearance, where it started).
    floor: Vec<f64>,
    /// Mean edge length (row scaling).
    h: f64,
}

/// Run Algorithm 2 from `mesh`'s positions.
pub(super) fn run(
    mesh: &Mesh,
    body: Option<&Body>,
    params: &Params,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let anchor = mesh.positions();
    let h = crate::geometry::mean_edge_length(mesh).max(f64::MIN_POSITIVE);
    let floor = match body {
        Some(b) => anchor
            .iter()
            .map(|&p| b.clearance(p).signed.min(params.clearance) - 1e-12 * h)
            .collect(),
        None => vec![f64::NEG_INFINITY; anchor.len()],
    };
    let ctx = Ctx {
        mesh,
        body,
        params,
        anchor,
        floor,
        h,
    };
    let mut pos = anchor.to_vec();
    let (mut w, start) = varpi(mesh, &pos); // l.1
    let mut best = start;
    let mut best_pos = pos.clone(); // l.2
    let mut run = Run {
        positions: vec![],
        iterations: 0,
        best_iteration: 0,
        centres: 0,
        stop: Stop::Tolerance,
        stop_detail: "within the tolerance".into(),
        history: vec![],
        max_flattenability: start,
    };
    if start <= params.tolerance() {
        run.positions = best_pos;
        return Ok(run);
    }
    let mut mark = vec![0u32; pos.len()];
    let mut stamp = 0u32;
    let mut since_best = 0;
    loop {
        // l.4 / l.18: the heap holds every interior vertex keyed by its current ϖ.
        let mut heap: BinaryHeap<Key> = w
            .iter()
            .enumerate()
            .filter(|(v, _)| mesh.conn().is_interior(*v as u32))
            .map(|(v, &x)| Key(x, v as u32))
            .collect();
        // l.5–14 with the stale keys of l.18: the centres of this outer iteration are the
        // vertices above the threshold, in heap order.
        let mut centres = Vec::new();
        while let Some(Key(key, c)) = heap.pop() {
            if key <= params.heap_fraction * best {
                break; // l.6
            }
            centres.push(c); // l.7
        }
        let popped = centres.len();
        perturb_in_waves(&ctx, &mut pos, centres, &mut mark, &mut stamp, control)?;
        run.centres += popped;
        run.iterations += 1;
        let now;
        (w, now) = varpi(mesh, &pos);
        if now < best {
            // l.15–16
            best = now;
            best_pos.clone_from(&pos);
            run.best_iteration = run.iterations;
            since_best = 0;
        } else {
            since_best += 1;
        }
        run.history.push(HistoryEntry {
            iteration: run.iterations,
            max_flattenability: now,
            best,
            centres: popped,
        });
        control.progress(&Progress {
            stage: "local".into(),
            iteration: run.iterations,
            max_flattenability: Some(best),
            step_norm: None,
        });
        // l.19: the three terminal conditions.
        let stop = if best <= params.tolerance() {
            Some(Stop::Tolerance)
        } else if since_best >= params.stall_outer {
            Some(Stop::Stall)
        } else if run.iterations >= params.max_outer {
            Some(Stop::MaxOuter)
        } else {
            None
        };
        if let Some(s) = stop {
            run.stop = s;
            run.stop_detail = match s {
                Stop::Tolerance => "within the tolerance".into(),
                Stop::Stall => format!(
                    "no new best ϖ_max in {} outer iterations",
                    params.stall_outer
                ),
                _ => format!("{} outer iterations", params.max_outer),
            };
            break;
        }
    }
    run.positions = best_pos;
    run.max_flattenability = best;
    Ok(run)
}

/// l.8–13 for every centre of an outer iteration; with `parallel` (default), in waves: each
/// wave takes, in heap order, the centres whose (r+1)-ring disks are disjoint from those
/// already in it (so they are ≥ 2r+3 rings apart: none reads a position another writes, which
/// reach r and r+2 rings), and runs them on the rayon pool, each thread on its own copy of the
/// positions; the moves are then written back in wave order. The result is that of running the
/// wave's centres one after the other in any order, so it is deterministic; it differs from the
/// paper's strict heap order only in that a later centre may run before an earlier one it does
/// not touch.
fn perturb_in_waves(
    ctx: &Ctx<'_>,
    pos: &mut [[f64; 3]],
    mut pending: Vec<u32>,
    mark: &mut [u32],
    stamp: &mut u32,
    control: &dyn Control,
) -> Result<(), AlgoError> {
    use rayon::prelude::*;
    let nv = pos.len();
    if !ctx.params.parallel {
        // The paper's strict heap order, one centre after the other.
        let mut col = vec![NONE; nv];
        for c in pending {
            if control.cancelled() {
                return Err(AlgoError::Cancelled);
            }
            *stamp = stamp.wrapping_add(1).max(1);
            let (near, n_r) = rings(ctx.mesh, c, ctx.params.rings, mark, *stamp); // l.8
            perturb_centre(ctx, pos, &near, n_r, &mut col);
        }
        return Ok(());
    }
    let mut claim = vec![0u32; nv];
    let mut wave_id = 0u32;
    while !pending.is_empty() {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        wave_id += 1;
        let mut wave = Vec::new();
        let mut rest = Vec::new();
        for c in pending {
            *stamp = stamp.wrapping_add(1).max(1);
            let (near, n_r) = rings(ctx.mesh, c, ctx.params.rings, mark, *stamp); // l.8
            if near.iter().any(|&v| claim[v as usize] == wave_id) {
                rest.push(c);
                continue;
            }
            for &v in &near {
                claim[v as usize] = wave_id;
            }
            wave.push((near, n_r));
        }
        pending = rest;
        let moved: Vec<Vec<(u32, [f64; 3])>> = wave
            .par_iter()
            .map_init(
                || (pos.to_vec(), vec![NONE; nv]),
                |(local, col), (near, n_r)| {
                    perturb_centre(ctx, local, near, *n_r, col);
                    near[..*n_r]
                        .iter()
                        .map(|&v| (v, local[v as usize]))
                        .collect()
                },
            )
            .collect();
        for (v, p) in moved.into_iter().flatten() {
            pos[v as usize] = p;
        }
    }
    Ok(())
}

/// l.8–13 for one centre: `near` is N_{r+1}(c), its first `n_r` entries N_r(c).
fn perturb_centre(ctx: &Ctx<'_>, pos: &mut [[f64; 3]], near: &[u32], n_r: usize, col: &mut [u32]) {
    let conn = ctx.mesh.conn();
    let act: Vec<u32> = near[..n_r]
        .iter()
        .copied()
        .filter(|&v| conn.is_interior(v))
        .collect(); // Eq. 18
    let dev: Vec<u32> = near
        .iter()
        .copied()
        .filter(|&v| conn.is_interior(v))
        .collect(); // Eq. 19
    if act.is_empty() {
        return;
    }
    for (i, &v) in act.iter().enumerate() {
        col[v as usize] = i as u32;
    }
    let mut grad = Vec::new();
    // Per active vertex, a lower bound of its signed clearance (unknown at first).
    let mut bound = vec![f64::NEG_INFINITY; act.len()];
    for _ in 0..ctx.params.inner_iterations {
        if !inner_step(ctx, pos, &act, &dev, col, &mut grad, &mut bound) {
            break;
        }
    }
    for &v in &act {
        col[v as usize] = NONE;
    }
}

/// One damped SQP iteration (l.10–11) with the active set of body rows; false when no step
/// could be taken.
fn inner_step(
    ctx: &Ctx<'_>,
    pos: &mut [[f64; 3]],
    act: &[u32],
    dev: &[u32],
    col: &[u32],
    grad: &mut Vec<(u32, [f64; 3])>,
    bound: &mut [f64],
) -> bool {
    let mesh = ctx.mesh;
    // A closed body's signed distance is 1-Lipschitz: a vertex whose lower bound clears what is
    // asked needs no query (`bound` falls by each move's length).
    let lipschitz = ctx.body.is_some_and(|b| b.is_closed());
    let n = 3 * act.len();
    let h = ctx.h;
    // θ rows (scaled by h̄ so that their entries, like the body rows', are O(1)).
    let mut theta_rows: Vec<(Vec<(usize, f64)>, f64)> = Vec::with_capacity(dev.len());
    for &q in dev {
        theta_gradient_with(mesh, pos, q, grad);
        let mut row = Vec::with_capacity(3 * grad.len());
        for &(p, g) in grad.iter() {
            let j = col[p as usize];
            if j != NONE {
                for (k, gk) in g.iter().enumerate() {
                    row.push((3 * j as usize + k, h * gk));
                }
            }
        }
        theta_rows.push((row, h * (TAU - angle_sum_with(mesh, pos, q))));
    }
    let bp: Vec<f64> = act
        .iter()
        .flat_map(|&v| {
            let (a, p) = (ctx.anchor[v as usize], pos[v as usize]);
            [a[0] - p[0], a[1] - p[1], a[2] - p[2]]
        })
        .collect();
    // Body rows: V_collid = the active vertices below the clearance (paper-notes A.3 item 7),
    // then an active set (item 9).
    let mut clear: Vec<Option<super::body::Clearance>> = act
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let b = ctx.body?;
            if lipschitz && bound[i] >= ctx.params.clearance {
                return None; // not colliding
            }
            let c = b.clearance(pos[v as usize]);
            bound[i] = c.signed;
            Some(c)
        })
        .collect();
    let mut active: Vec<usize> = (0..act.len())
        .filter(|&i| clear[i].is_some_and(|c| c.signed < ctx.params.clearance))
        .collect();
    let mut tau = ctx.params.tau;
    for _round in 0..ACTIVE_SET_ROUNDS {
        let m = theta_rows.len() + active.len();
        let mut lam = Mat::<f64>::zeros(m, n);
        let mut bl = vec![0.0; m];
        for (i, (row, rhs)) in theta_rows.iter().enumerate() {
            for &(j, x) in row {
                lam[(i, j)] += x;
            }
            bl[i] = *rhs;
        }
        for (k, &a) in active.iter().enumerate() {
            let c = clear[a].expect("body rows only with a body");
            let i = theta_rows.len() + k;
            for d in 0..3 {
                lam[(i, 3 * a + d)] = c.gradient[d];
            }
            bl[i] = ctx.params.clearance - c.signed;
        }
        let (delta, mult) = min_norm_step(&lam, &bp, &bl);
        if delta.iter().any(|x| !x.is_finite()) {
            return false;
        }
        // Rows pulling a vertex towards the body (λ > 0) are not binding: drop and re-solve.
        let before = active.len();
        let keep: Vec<usize> = active
            .iter()
            .enumerate()
            .filter(|(k, _)| mult[theta_rows.len() + k] <= 0.0)
            .map(|(_, &a)| a)
            .collect();
        if keep.len() < before {
            active = keep;
            continue;
        }
        // The damped step, checked against every vertex's floor with the exact distance.
        let mut violators = Vec::new();
        let longest = (0..act.len())
            .map(|i| (0..3).map(|d| delta[3 * i + d].powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let mut t = tau.min(STEP_CAP * h / longest.max(f64::MIN_POSITIVE));
        for _ in 0..=HALVINGS {
            violators.clear();
            if let Some(body) = ctx.body {
                for (i, &v) in act.iter().enumerate() {
                    let p = pos[v as usize];
                    let q = [0, 1, 2].map(|d| p[d] + t * delta[3 * i + d]);
                    let moved = t * (0..3).map(|d| delta[3 * i + d].powi(2)).sum::<f64>().sqrt();
                    if lipschitz && bound[i] - moved >= ctx.floor[v as usize] {
                        continue;
                    }
                    if body.clearance(q).signed < ctx.floor[v as usize] {
                        violators.push(i);
                    }
                }
            }
            let fresh: Vec<usize> = violators
                .iter()
                .copied()
                .filter(|i| !active.contains(i))
                .collect();
            if !fresh.is_empty() {
                break;
            }
            if violators.is_empty() {
                for (i, &v) in act.iter().enumerate() {
                    for d in 0..3 {
                        pos[v as usize][d] += t * delta[3 * i + d];
                    }
                    bound[i] -= t * (0..3).map(|d| delta[3 * i + d].powi(2)).sum::<f64>().sqrt();
                }
                return true;
            }
            t *= 0.5;
        }
        let fresh: Vec<usize> = violators
            .into_iter()
            .filter(|i| !active.contains(i))
            .collect();
        if fresh.is_empty() {
            return false;
        }
        // A row needs its vertex's exact clearance (skipped above when the bound cleared it).
        for &i in &fresh {
            if clear[i].is_none() {
                if let Some(b) = ctx.body {
                    let c = b.clearance(pos[act[i] as usize]);
                    bound[i] = c.signed;
                    clear[i] = Some(c);
                }
            }
        }
        active.extend(fresh);
        active.sort_unstable();
        tau = ctx.params.tau;
    }
    false
}
