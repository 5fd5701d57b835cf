//! `method = "local"`: the paper's local optimisation (Sec. 5, Algorithm
//! LocalDevelopabilityOptimize). A max-heap of interior vertices keyed by |g| (the same order
//! as g², and the stop is on |g|: paper-notes B.4.1); the top vertex q moves along its
//! original normal n_q (the unweighted mean of its face normals, fixed for the whole run) to
//! q⁰ + δ n_q, δ clamped to ±δ_T, to lower T(δ) = g(q)² + Σ_j g(q_j)² (Eq. 15) over its
//! interior neighbours; then g of q and its neighbours is updated and they are re-keyed.
//!
//! Updates (`update`):
//! - `gauss_newton` (default): δ ← δ − ω (r·r′)/(r′·r′) on the residuals r = (g_q, g_qj…),
//!   r′ = dr/dδ = −(∂θ/∂q)·n_q (Props. 1–2), accepted only if T falls by at least 1e-4 of
//!   the decrease its slope predicts and by at least 0.1 % of T (the change is halved up to
//!   five times first, until the parabola through T, Ṫ and the refused trial promises less
//!   than half the decrease at every smaller one, `HALVING_PROMISE`; a move whose quadratic
//!   model promises less than three quarters of it is refused untried, `PROMISE`). A move
//!   changes g only at q and its ring, which is all of T, so G falls with every move.
//!   ω = `relaxation` (default 1.8): with ω = 1 each move minimises T along the normal, a
//!   Gauss–Seidel sweep on G that zigzags; over-relaxation is the classic cure. Measured on
//!   the noisy cone fixture (ε = 1e-4, δ_T = L̄): ω = 1 ran out of 500000 pops at 2.2e-4,
//!   1.5 stalled at 1.1e-4 after 102505, 1.8 reached 1e-4 in 919 (Newton: 674).
//! - `newton`: the paper's Eq. 19, δ ← δ − T/Ṫ, always taken (only the clamp bounds it).
//!
//! `min_gain` (Gauss–Newton only; default 1e-2, 0 = off): a move must also lower G = Σg² (Eq. 4) by
//! that share of its mean per interior vertex, G/n. The 0.1 % of T above is relative to the
//! vertex's own T, so on a garment that cannot become developable by moves along the normals,
//! the heap spends most of its budget on vertices whose |g| is already near ε, each move
//! gaining a thousandth of almost nothing, while g_max sits on stalled vertices: the t-shirt
//! used all 500000 pops (G 0.412, g_max 0.134). The floor falls with G, so a run that
//! converges is not held back; when the heap runs dry, every stalled vertex above ε gets
//! another try under the lower floor, while such sweeps still move something. Measured (CLI,
//! defaults otherwise, 0 → 1e-2 → 2e-2): t-shirt pops 500000 → 118243 → 82571, G 0.412 →
//! 0.436 → 0.467, g_max 0.134 → 0.136 → 0.131, δS 1.84 → 1.55 → 1.39 %; over six more shared
//! garments and shoes pops fell 1.4–3.3× at 1e-2 with G 3–16 % higher and δS 10–21 % lower;
//! over the develop corpus the cases that reach ε are unchanged (the noisy cone: 919 pops).
//! A move gaining less than 1 % of an average vertex's share buys little of the paper's
//! objective, and the length change it costs is E's. Measured again after the speed-ups of
//! `HALVING_PROMISE`, `PROMISE` 0.75 and `SlopeCache` (develop_corpus, 0 → 1e-2): t-shirt
//! pops 440798 → 59201, G 0.382 → 0.425, g_max 0.111 → 0.123, δS 1.91 → 1.49 %, 0.54 →
//! 0.09 s; over the 50 cases that stop above ε, G with the floor is a median 1.01× G
//! without it (0.92–1.34×, the worst mh_classicshoes_medium).
//!
//! Beyond the paper (paper-notes B.4.5): a vertex whose move is refused, clamped to no change,
//! or has r′ = 0 (Ṫ = 0: "we just simply fix the vertex") is marked stalled and leaves the
//! heap until a vertex within two rings of it moves (which changes its T) and, if its own fan
//! did not move, its cached slopes and the new g say a trial would be made (`SlopeCache`);
//! the paper would pop it again until N_max. The run stops when the heap's top is at most ε and the global
//! max |g| is too (`tolerance`), when only stalled vertices are above ε (`stalled`, naming
//! them; with `min_gain`, once a sweep over them moved none), or after `max_moves` pops. Seam
//! and boundary vertices never move (Sec. 5.2); every output vertex is q⁰ + δ n_q with
//! |δ| ≤ δ_T; a move that would make a triangle of the fan degenerate is refused (halved, like
//! one that does not lower T). If the moves together made g_max worse (the paper's Newton
//! update does on real garments), the input is returned.

use super::energy::{big_g, g_max, Model};
use super::{Params, Run, Stop, Update};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::mesh::{cross, dot, sub, Mesh, DEGENERATE_REL_AREA};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_6, PI};

/// Pops between progress reports and cancellation checks.
const REPORT_EVERY: usize = 1024;
/// Halvings of a Gauss–Newton change before the vertex counts as stalled.
const HALVINGS: usize = 5;
const ARMIJO: f64 = 1e-4;
/// A Gauss–Newton move must also lower T by this share, else the vertex stalls. Without it the
/// few vertices with the highest |g| keep the top of the heap with ever smaller gains: on the
/// t-shirt 500000 pops moved 31 vertices (g_max 0.52 → 0.24); with it, 0.13 (shoes01 0.44 →
/// 0.19, gf_dress 0.043 → 0.020; the noisy cone still 919 pops; 1e-2 stalls everything early).
const MIN_PROGRESS: f64 = 1e-3;
/// A Gauss–Newton move whose model promises less than this share of the decrease it must make
/// is refused without evaluating T. The model is rarely pessimistic: of the t-shirt's 20059
/// accepted moves 74 had been promised less than 0.8 of it, 267 less than 1, against 33604
/// and 38746 of its 39412 refused ones. From 0.25 (chosen when every refused pop cost six
/// evaluations) to 0.75: t-shirt pops 84990 → 59201, G 0.431 → 0.425, 0.14 → 0.10 s
/// (alternating runs); over the develop corpus G changed by −19 % to +23 % (the runs are
/// chaotic in which moves they make), +0.07 % in the mean of the logs, and the cases that
/// reach ε are unchanged. 0.5 gave +0.7 %.
const PROMISE: f64 = 0.75;
/// A refused trial ends the halvings when the parabola it fixes promises less than this share
/// of the decrease a move must make at every smaller trial (`halving_may_pay`). On the
/// t-shirt 37567 of 56933 tried pops were refused, each after all six trials, while only 124
/// moves were accepted after the second: this cut 253379 evaluations of T to 97095 (G 0.436 →
/// 0.431, g_max 0.136 → 0.135, pops 118243 → 124594); over the develop corpus ϖ_out moved by
/// a few per cent either way, and the cases that reach ε are unchanged.
const HALVING_PROMISE: f64 = 0.5;

/// Run the local method from the input positions.
pub(super) fn run(
    model: &Model<'_>,
    start: &[[f64; 3]],
    params: &Params,
    control: &dyn Control,
) -> Result<Run, AlgoError> {
    let mesh = model.mesh();
    let nv = start.len();
    let eps = params.tolerance();
    let delta_t = params
        .delta_t
        .unwrap_or_else(|| crate::geometry::mean_edge_length(mesh));
    let normals = vertex_normals_unweighted(mesh, start);
    let mut g = vec![0.0; nv];
    model.g(start, &mut g);
    let mut run = Run::new(start, g_max(&g));
    let mut pos = start.to_vec();
    let mut delta = vec![0.0f64; nv];
    let mut stalled = vec![false; nv];
    let mut heap = MaxHeap::new(nv);
    for (v, &gv) in g.iter().enumerate() {
        if model.is_interior(v) && gv != 0.0 {
            heap.set(v as u32, gv.abs());
        }
    }
    let mut scratch = Local::default();
    let mut cache = face_corners(mesh, &pos);
    let mut slopes = SlopeCache::new(mesh);
    let rule = Rule {
        delta_t,
        update: params.update,
        relaxation: params.relaxation,
    };
    let mut pops = 0usize;
    let floor_share = match params.update {
        Update::GaussNewton => params.min_gain,
        Update::Newton => 0.0,
    };
    let interior = (0..nv).filter(|&v| model.is_interior(v)).count().max(1) as f64;
    let floor = |big_g: f64| (floor_share * big_g / interior).max(0.0);
    // G, kept by each move's change (a move changes g only in `scratch.verts`).
    let mut big_g_now = big_g(&g);
    let mut moved_since_sweep = false;
    let out_of_moves = loop {
        if pops >= params.max_moves {
            break true;
        }
        let top = heap.peek().filter(|&(_, key)| key > eps);
        let Some((q, key)) = top else {
            // Dry: every vertex above ε is stalled. Under `min_gain` they may have stalled
            // under a floor that has fallen since: all get another try, while such sweeps
            // still move something.
            if floor_share > 0.0 && moved_since_sweep {
                moved_since_sweep = false;
                let floor = floor(big_g_now);
                for v in 0..nv {
                    if stalled[v] && g[v].abs() > eps && slopes.may_move(v, &g, &delta, rule, floor)
                    {
                        stalled[v] = false;
                        heap.set(v as u32, g[v].abs());
                    }
                }
                continue;
            }
            break false;
        };
        pops += 1;
        if pops % REPORT_EVERY == 0 {
            if control.cancelled() {
                return Err(AlgoError::Cancelled);
            }
            control.progress(&Progress {
                stage: "local".into(),
                iteration: pops,
                max_flattenability: Some(key),
                step_norm: None,
            });
        }
        let qi = q as usize;
        let n = normals[qi];
        let moved = if delta_t > 0.0 && dot(n, n) > 0.0 {
            scratch.load(model, &pos, q, n, &g, &cache);
            slopes.store(q, &scratch.slope);
            step(
                &mut pos,
                q,
                start[qi],
                n,
                &mut delta[qi],
                rule,
                floor(big_g_now),
                &mut scratch,
            )
        } else {
            false
        };
        if !moved {
            stalled[qi] = true;
            heap.remove(q);
            continue;
        }
        // g changed at q and its ring; T changed for every vertex within two rings.
        moved_since_sweep = true;
        for (k, &v) in scratch.verts.iter().enumerate() {
            big_g_now += scratch.g_after[k] * scratch.g_after[k] - g[v as usize] * g[v as usize];
            g[v as usize] = scratch.g_after[k];
        }
        scratch.commit(&mut cache);
        for &v in &scratch.verts {
            let vi = v as usize;
            // q moved: the fans of q and its ring changed shape.
            slopes.valid[vi] = false;
            if !model.is_interior(vi) {
                continue;
            }
            stalled[vi] = false;
            if g[vi] != 0.0 {
                heap.set(v, g[vi].abs());
            } else {
                heap.remove(v);
            }
        }
        // The second ring's g did not change: only its stalled vertices need a new key, and
        // only those that would now try a move (their fans did not move, so their slopes hold).
        let floor = floor(big_g_now);
        for &v in &scratch.verts {
            for &p in mesh.conn().ring_of(v) {
                let pi = p as usize;
                if stalled[pi]
                    && model.is_interior(pi)
                    && slopes.may_move(pi, &g, &delta, rule, floor)
                {
                    stalled[pi] = false;
                    if g[pi] != 0.0 {
                        heap.set(p, g[pi].abs());
                    }
                }
            }
        }
    };
    // g was kept by increments; the stop and the report read it afresh.
    model.g(&pos, &mut g);
    run.stop = if out_of_moves {
        Stop::MaxMoves
    } else {
        finish(&g, eps)
    };
    run.inner = pops;
    run.iterations = pops;
    run.g_max = g_max(&g);
    let mut stuck: Vec<u32> = (0..nv as u32)
        .filter(|&v| stalled[v as usize] && g[v as usize].abs() > eps)
        .collect();
    stuck.sort_by(|a, b| g[*b as usize].abs().total_cmp(&g[*a as usize].abs()));
    run.stalled = stuck;
    if run.g_max <= run.g_max_input || run.g_max_input == 0.0 {
        run.positions = pos;
        run.best_iteration = pops;
    } else {
        run.g_max = run.g_max_input;
        run.stalled.clear();
        run.stop_detail = format!(
            "{} after {pops} pops, but the moves together made g_max worse ({:.2e} > {:.2e}); \
             the input is returned",
            run.stop.as_str(),
            g_max(&g),
            run.g_max_input
        );
    }
    Ok(run)
}

fn finish(g: &[f64], eps: f64) -> Stop {
    if g_max(g) <= eps {
        Stop::Tolerance
    } else {
        Stop::Stalled
    }
}

/// One update of vertex `q` (scratch loaded at the current positions); a Gauss–Newton move
/// must lower T by at least `floor` (`min_gain`). Returns whether q moved; `scratch.g_after`
/// then holds g of `scratch.verts` at the new position.
#[allow(clippy::too_many_arguments)]
fn step(
    pos: &mut [[f64; 3]],
    q: u32,
    q0: [f64; 3],
    n: [f64; 3],
    delta: &mut f64,
    rule: Rule,
    floor: f64,
    s: &mut Local,
) -> bool {
    let (t0, tdot, rr) = t_slope_rr(&s.g_before, &s.slope);
    let Some(target) = plan(rule, t0, tdot, rr, *delta, floor) else {
        return false;
    };
    let update = rule.update;
    let qi = q as usize;
    let old = pos[qi];
    let mut change = target - *delta;
    let required = (MIN_PROGRESS * t0).max(floor);
    for _ in 0..=HALVINGS {
        let d = *delta + change;
        pos[qi] = [0, 1, 2].map(|k| q0[k] + d * n[k]);
        let Some(t1) = s.evaluate(pos) else {
            change *= 0.5;
            continue;
        };
        // Armijo on T: a move must buy a decrease in proportion to its predicted one, else
        // ever smaller moves keep a vertex popping without getting anywhere.
        if update == Update::Newton
            || (t1 <= t0 + ARMIJO * change * tdot
                && t1 <= (1.0 - MIN_PROGRESS) * t0
                && t0 - t1 >= floor)
        {
            *delta = d;
            return true;
        }
        if update == Update::GaussNewton && !halving_may_pay(t0, tdot, t1, change, required) {
            break;
        }
        change *= 0.5;
    }
    pos[qi] = old;
    false
}

/// The update's fixed settings.
#[derive(Clone, Copy)]
struct Rule {
    delta_t: f64,
    update: Update,
    relaxation: f64,
}

/// (T, dT/dδ, Σ r′²) from the residuals r = g of q and its ring and their slopes r′ = dr/dδ.
fn t_slope_rr(r: &[f64], slope: &[f64]) -> (f64, f64, f64) {
    let t = r.iter().map(|x| x * x).sum();
    let d = 2.0 * r.iter().zip(slope).map(|(r, s)| r * s).sum::<f64>();
    (t, d, slope.iter().map(|x| x * x).sum())
}

/// Where a vertex at offset `delta` along its normal, with T = `t0`, dT/dδ = `tdot` and
/// Σ r′² = `rr`, should move to; None where no trial would be accepted (or none is possible).
/// It depends on nothing else, so a stalled vertex whose fan has not moved can be asked again
/// with new g values without loading it.
fn plan(rule: Rule, t0: f64, tdot: f64, rr: f64, delta: f64, floor: f64) -> Option<f64> {
    let Rule {
        delta_t,
        update,
        relaxation,
    } = rule;
    let wanted = match update {
        Update::Newton if tdot != 0.0 => delta - t0 / tdot,
        Update::GaussNewton if rr > 0.0 => delta - relaxation * 0.5 * tdot / rr,
        _ => return None,
    };
    let target = wanted.clamp(-delta_t, delta_t);
    if !target.is_finite() || target == delta {
        return None;
    }
    if update == Update::GaussNewton {
        // Where T's quadratic model T + c Ṫ + c² r′·r′, at its best within the clamp, promises
        // less than `PROMISE` of the decrease a move must make, the trials would all be
        // refused: skip them.
        let c = (-0.5 * tdot / rr).clamp(-delta_t - delta, delta_t - delta);
        if -(c * tdot + c * c * rr) < PROMISE * (MIN_PROGRESS * t0).max(floor) {
            return None;
        }
    }
    Some(target)
}

/// Each vertex's slopes r′ = dr/dδ over itself and its ring (`Local::slope`) from its last
/// load, while its fan has not moved since. Most re-pops of a stalled vertex follow a move two
/// rings away, which changes its neighbours' g but not its slopes, and most are refused by
/// `plan` alone: asking `plan` before re-queueing took the t-shirt from 124594 pops to 84990
/// with the same output.
struct SlopeCache<'m> {
    mesh: &'m Mesh,
    offset: Vec<usize>,
    slope: Vec<f64>,
    valid: Vec<bool>,
}

impl<'m> SlopeCache<'m> {
    fn new(mesh: &'m Mesh) -> Self {
        let nv = mesh.num_vertices();
        let mut offset = Vec::with_capacity(nv + 1);
        offset.push(0);
        for v in 0..nv as u32 {
            offset.push(offset[v as usize] + 1 + mesh.conn().ring_of(v).len());
        }
        Self {
            mesh,
            slope: vec![0.0; offset[nv]],
            offset,
            valid: vec![false; nv],
        }
    }

    fn store(&mut self, q: u32, slope: &[f64]) {
        let q = q as usize;
        self.slope[self.offset[q]..self.offset[q + 1]].copy_from_slice(slope);
        self.valid[q] = true;
    }

    /// Whether a stalled vertex `v` may move under `floor`: true unless its slopes are known
    /// and `plan` (the same figures a load would give) says no trial would be made.
    fn may_move(&self, v: usize, g: &[f64], delta: &[f64], rule: Rule, floor: f64) -> bool {
        if !self.valid[v] {
            return true;
        }
        let slope = &self.slope[self.offset[v]..self.offset[v + 1]];
        let mut r = [0.0; 32];
        let ring = self.mesh.conn().ring_of(v as u32);
        if ring.len() + 1 > r.len() {
            return true;
        }
        r[0] = g[v];
        for (x, &p) in r[1..].iter_mut().zip(ring) {
            *x = g[p as usize];
        }
        let (t0, tdot, rr) = t_slope_rr(&r[..=ring.len()], slope);
        plan(rule, t0, tdot, rr, delta[v], floor).is_some()
    }
}

/// Whether a smaller trial than `change` (which gave T = `t1`) may still make the `required`
/// decrease: the parabola through T(0) = `t0`, T′(0) = `tdot` and T(change) = `t1` is asked at
/// each remaining halving, and must promise at least [`HALVING_PROMISE`] of it at one.
fn halving_may_pay(t0: f64, tdot: f64, t1: f64, change: f64, required: f64) -> bool {
    let a = (t1 - t0 - tdot * change) / (change * change);
    let mut c = change;
    (0..HALVINGS).any(|_| {
        c *= 0.5;
        -(tdot * c + a * c * c) >= HALVING_PROMISE * required
    }) || !a.is_finite()
}

/// q, its ring, their g before and after, and the residuals' slopes dr/dδ.
#[derive(Default)]
struct Local {
    verts: Vec<u32>,
    g_before: Vec<f64>,
    g_after: Vec<f64>,
    slope: Vec<f64>,
    /// q's fan: per triangle (q, b, c) the indices in `verts` of q, b and c (usize::MAX for
    /// one whose g is not counted) and their corners before and after the move. Moving q
    /// changes only these corners, so a trial updates g by their change: 3 corners per fan
    /// triangle instead of every corner around q and its ring (atan2 was 68 % of a run), and
    /// the corners before come from the run's per-face cache.
    fan: Vec<FanCorners>,
}

struct FanCorners {
    verts: [u32; 3],
    index: [usize; 3],
    face: usize,
    /// Where q is in the face's corner order.
    k: usize,
    before: [f64; 3],
    after: [f64; 3],
}

/// Every face's three corners, in its vertex order, at `pos`.
fn face_corners(mesh: &Mesh, pos: &[[f64; 3]]) -> Vec<[f64; 3]> {
    mesh.triangles()
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize]);
            corners(a, b, c)
        })
        .collect()
}

impl Local {
    fn load(
        &mut self,
        model: &Model<'_>,
        pos: &[[f64; 3]],
        q: u32,
        n: [f64; 3],
        g: &[f64],
        cache: &[[f64; 3]],
    ) {
        let mesh = model.mesh();
        let (ring, fan) = (mesh.conn().ring_of(q), mesh.conn().fan_of(q));
        self.verts.clear();
        self.verts.push(q);
        self.verts.extend_from_slice(ring);
        self.g_before.clear();
        self.g_before
            .extend(self.verts.iter().map(|&v| g[v as usize]));
        self.g_after.clear();
        self.g_after.extend_from_slice(&self.g_before);
        self.slope.clear();
        self.slope.resize(self.verts.len(), 0.0);
        let counted = |i: usize| {
            if model.is_interior(self.verts[i] as usize) {
                i
            } else {
                usize::MAX
            }
        };
        let closed = ring.len() == fan.len();
        let pq = pos[q as usize];
        self.fan.clear();
        for (j, &hf) in fan.iter().enumerate() {
            let t = mesh.triangles()[hf as usize / 3];
            let k = hf as usize % 3;
            let (b, c) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            // Face j spans ring[j] → ring[j + 1] (`Connectivity::fan_of`, `ring_of`).
            let (jb, jc) = (1 + j, 1 + if closed { (j + 1) % ring.len() } else { j + 1 });
            debug_assert_eq!((self.verts[jb], self.verts[jc]), (b, c));
            let index = [counted(0), counted(jb), counted(jc)];
            self.fan.push(FanCorners {
                verts: [q, b, c],
                index,
                face: hf as usize / 3,
                k,
                before: [0, 1, 2].map(|x| cache[hf as usize / 3][(k + x) % 3]),
                after: [0.0; 3],
            });
            // dθ/dδ of the corners at b and c (the one at q is minus their sum, the three
            // summing to π): with N = (b − q) × (c − q), ∂θ_b/∂q = N̂ × (q − b)/|q − b|² and
            // ∂θ_c/∂q = −N̂ × (q − c)/|q − c|², so along n each is (q − x)·(n × N) over
            // |N||q − x|², a cross product and two dot products instead of three
            // `corner_angle_gradient`s (the same gradients, Props. 1–2).
            let (eb, ec) = (sub(pq, pos[b as usize]), sub(pq, pos[c as usize]));
            let normal = cross(sub(pos[b as usize], pq), sub(pos[c as usize], pq));
            let m = cross(n, normal);
            let len = dot(normal, normal).sqrt();
            let at_b = dot(eb, m) / (len * dot(eb, eb));
            let at_c = -dot(ec, m) / (len * dot(ec, ec));
            // r = g = 2π − θ, so dr/dδ = −dθ/dδ.
            for (i, d) in index.into_iter().zip([-(at_b + at_c), at_b, at_c]) {
                if i != usize::MAX {
                    self.slope[i] -= d;
                }
            }
        }
        for x in self.slope.iter_mut() {
            if !x.is_finite() {
                *x = 0.0;
            }
        }
    }

    /// The accepted move's corners into the per-face cache.
    fn commit(&self, cache: &mut [[f64; 3]]) {
        for f in &self.fan {
            for x in 0..3 {
                cache[f.face][(f.k + x) % 3] = f.after[x];
            }
        }
    }

    /// T at `pos` (q moved), filling `g_after`: g = 2π − θ falls by each corner's growth.
    /// None if a triangle of q's fan is degenerate there.
    fn evaluate(&mut self, pos: &[[f64; 3]]) -> Option<f64> {
        self.g_after.copy_from_slice(&self.g_before);
        for f in self.fan.iter_mut() {
            f.after = corners_checked(
                pos[f.verts[0] as usize],
                pos[f.verts[1] as usize],
                pos[f.verts[2] as usize],
            )?;
            for ((&i, a), b) in f.index.iter().zip(f.after).zip(f.before) {
                if i != usize::MAX {
                    self.g_after[i] -= a - b;
                }
            }
        }
        let t: f64 = self.g_after.iter().map(|x| x * x).sum();
        Some(if t.is_finite() { t } else { f64::INFINITY })
    }
}

/// The corners of triangle (a, b, c) at a, b and c: the two at the ends of the longest edge
/// by `atan2(2·area, dot)` (as `geometry::corner_angle`, full relative precision), the third,
/// which is at least 60°, as π minus them. One cross product and two atan2 instead of three
/// each: atan2 was 56 % of a run (perf, t-shirt, 500k pops); [`atan2_upper`] then halved it.
fn corners(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    corners_of(a, b, c).0
}

/// atan2(y, x) for y ≥ 0 (0 at y = x = 0), within 5e-16 rad of `f64::atan2` and with its
/// relative precision for small angles. The argument is reduced to [0, 1] by the octant
/// (y ≷ |x|), then to |u| ≤ tan(π/12) by atan t = π/6 + atan((t√3 − 1)/(t + √3)), folded into
/// the one division; atan u is its Taylor series to u²⁷ (the first term left out is below
/// 1e-18 there), summed by Estrin's scheme. Written here because libm's atan2 (glibc's,
/// correctly rounded) was a quarter of a `local` run: this one takes 11 ns against its 20 ns
/// (the `libm` crate's: 29 against 35 on the same machine), random arguments, this VM.
fn atan2_upper(y: f64, x: f64) -> f64 {
    const TAN_PI_12: f64 = 0.267_949_192_431_122_7;
    const SQRT_3: f64 = 1.732_050_807_568_877_2;
    // (−1)^k / (2k + 1), k = 0..13.
    const C: [f64; 14] = [
        1.0,
        -1.0 / 3.0,
        1.0 / 5.0,
        -1.0 / 7.0,
        1.0 / 9.0,
        -1.0 / 11.0,
        1.0 / 13.0,
        -1.0 / 15.0,
        1.0 / 17.0,
        -1.0 / 19.0,
        1.0 / 21.0,
        -1.0 / 23.0,
        1.0 / 25.0,
        -1.0 / 27.0,
    ];
    let ax = x.abs();
    let swap = y > ax;
    let (num, den) = if swap { (ax, y) } else { (y, ax) };
    let (num, den, base) = if num > TAN_PI_12 * den {
        (num * SQRT_3 - den, num + den * SQRT_3, FRAC_PI_6)
    } else {
        (num, den, 0.0)
    };
    // den = 0 only at y = x = 0; a NaN passes through.
    let u = if den == 0.0 { 0.0 } else { num / den };
    let z = u * u;
    let (z2, z4) = (z * z, z * z * z * z);
    let pair = |k: usize| C[k] + C[k + 1] * z;
    let low = (pair(0) + z2 * pair(2)) + z4 * (pair(4) + z2 * pair(6));
    let high = (pair(8) + z2 * pair(10)) + z4 * pair(12);
    let a = base + u * (low + z4 * z4 * high);
    let a = if swap { FRAC_PI_2 - a } else { a };
    if x < 0.0 {
        PI - a
    } else {
        a
    }
}

/// [`corners`], or None where `mesh::is_degenerate_triangle` holds: the same cross product and
/// edge lengths serve both, so a trial costs one pass over its fan.
fn corners_checked(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Option<[f64; 3]> {
    let (angles, twice_area, longest) = corners_of(a, b, c);
    // As `is_degenerate_triangle`, term for term (a test checks they agree).
    (twice_area > DEGENERATE_REL_AREA * longest && twice_area.is_finite()).then_some(angles)
}

/// The corners, twice the area and the longest edge squared.
fn corners_of(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> ([f64; 3], f64, f64) {
    let (ab, bc, ca) = (sub(b, a), sub(c, b), sub(a, c));
    // ab × (c − a), as `is_degenerate_triangle` computes it.
    let n = cross(ab, sub(c, a));
    let twice_area = dot(n, n).sqrt();
    let at = |d: f64| atan2_upper(twice_area, d);
    // The corner at a is between ab and ac = −ca; at b between ba = −ab and bc; at c between
    // ca and cb = −bc.
    let (da, db, dc) = (-dot(ab, ca), -dot(ab, bc), -dot(bc, ca));
    let (lab, lbc, lca) = (dot(ab, ab), dot(bc, bc), dot(ca, ca));
    let longest = lab.max(lbc).max(lca);
    let angles = if lbc >= lab && lbc >= lca {
        let (x, y) = (at(db), at(dc));
        [PI - x - y, x, y]
    } else if lca >= lab {
        let (x, y) = (at(da), at(dc));
        [x, PI - x - y, y]
    } else {
        let (x, y) = (at(da), at(db));
        [x, y, PI - x - y]
    };
    (angles, twice_area, longest)
}

/// (T, dT/dδ) for vertex `q` at positions `pos`, moving along `n`: T(δ) = g(q)² + Σ_j g(q_j)²
/// (Eq. 15). Public for the finite-difference tests.
pub fn t_and_slope(model: &Model<'_>, pos: &[[f64; 3]], q: u32, n: [f64; 3]) -> (f64, f64) {
    let mut g = vec![0.0; pos.len()];
    model.g(pos, &mut g);
    let mut s = Local::default();
    s.load(model, pos, q, n, &g, &face_corners(model.mesh(), pos));
    let (t, slope, _) = t_slope_rr(&s.g_before, &s.slope);
    (t, slope)
}

/// Unit mean of the face normals at each vertex (unweighted, as Sec. 5.1 says: "the average
/// normal of q's adjacent faces"); zero where they cancel.
pub fn vertex_normals_unweighted(mesh: &Mesh, pos: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut acc = vec![[0.0; 3]; pos.len()];
    for t in mesh.triangles() {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        let n = crate::geometry::normalize(crate::mesh::cross(
            crate::mesh::sub(b, a),
            crate::mesh::sub(c, a),
        ));
        for &v in t {
            for k in 0..3 {
                acc[v as usize][k] += n[k];
            }
        }
    }
    acc.into_iter().map(crate::geometry::normalize).collect()
}

/// An indexed binary max-heap over vertex ids with f64 keys: set (insert or re-key), remove
/// and peek in O(log n). Written here because the ids are dense u32s, so a position array does
/// what a hashed priority queue crate would do with a hash per operation.
struct MaxHeap {
    heap: Vec<u32>,
    at: Vec<u32>,
    key: Vec<f64>,
}

const ABSENT: u32 = u32::MAX;

impl MaxHeap {
    fn new(n: usize) -> Self {
        MaxHeap {
            heap: Vec::new(),
            at: vec![ABSENT; n],
            key: vec![0.0; n],
        }
    }

    fn peek(&self) -> Option<(u32, f64)> {
        self.heap.first().map(|&v| (v, self.key[v as usize]))
    }

    fn set(&mut self, v: u32, key: f64) {
        let vi = v as usize;
        if self.at[vi] == ABSENT {
            self.at[vi] = self.heap.len() as u32;
            self.heap.push(v);
            self.key[vi] = key;
            self.up(self.heap.len() - 1);
        } else {
            let old = self.key[vi];
            self.key[vi] = key;
            let i = self.at[vi] as usize;
            if key > old {
                self.up(i);
            } else {
                self.down(i);
            }
        }
    }

    fn remove(&mut self, v: u32) {
        let vi = v as usize;
        let i = self.at[vi];
        if i == ABSENT {
            return;
        }
        let i = i as usize;
        let last = self.heap.len() - 1;
        self.swap(i, last);
        self.heap.pop();
        self.at[vi] = ABSENT;
        if i < self.heap.len() {
            self.up(i);
            self.down(i);
        }
    }

    fn swap(&mut self, i: usize, j: usize) {
        self.heap.swap(i, j);
        self.at[self.heap[i] as usize] = i as u32;
        self.at[self.heap[j] as usize] = j as u32;
    }

    fn up(&mut self, mut i: usize) {
        while i > 0 {
            let p = (i - 1) / 2;
            if self.key[self.heap[i] as usize] <= self.key[self.heap[p] as usize] {
                break;
            }
            self.swap(i, p);
            i = p;
        }
    }

    fn down(&mut self, mut i: usize) {
        loop {
            let (l, r) = (2 * i + 1, 2 * i + 2);
            let mut m = i;
            for c in [l, r] {
                if c < self.heap.len()
                    && self.key[self.heap[c] as usize] > self.key[self.heap[m] as usize]
                {
                    m = c;
                }
            }
            if m == i {
                break;
            }
            self.swap(i, m);
            i = m;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{atan2_upper, corners, corners_checked};
    use crate::geometry::corner_angle;
    use crate::mesh::is_degenerate_triangle;

    /// A reproducible uniform sequence in [0, 1) (a 64-bit LCG's top 53 bits).
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// [`uniform`] shifted to [−0.5, 0.5).
    fn centred(seed: u64) -> impl FnMut() -> f64 {
        let mut u = uniform(seed);
        move || u() - 0.5
    }

    /// Against `geometry::corner_angle` at every corner, on random triangles and on slivers
    /// (a corner of 1e-9 rad, and one near π): within 1e-14 rad, and the small corners to 1e-9
    /// of their size; the three sum to π.
    #[test]
    fn corners_agree_with_corner_angle() {
        let mut rand = centred(7);
        let mut cases: Vec<[[f64; 3]; 3]> = (0..2000)
            .map(|_| {
                [
                    [rand(), rand(), rand()],
                    [rand(), rand(), rand()],
                    [rand(), rand(), rand()],
                ]
            })
            .collect();
        cases.push([[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1e-9, 0.0]]);
        cases.push([[0.0; 3], [1.0, 0.0, 0.0], [0.5, 1e-9, 0.0]]);
        cases.push([[0.0; 3], [1.0, 0.0, 0.0], [1e-3, 1e-9, 0.0]]);
        for [a, b, c] in cases {
            let got = corners(a, b, c);
            let want = [
                corner_angle(a, b, c),
                corner_angle(b, c, a),
                corner_angle(c, a, b),
            ];
            for k in 0..3 {
                let err = (got[k] - want[k]).abs();
                assert!(
                    err <= 1e-14 && (want[k] > 1e-3 || err <= 1e-9 * want[k]),
                    "{a:?} {b:?} {c:?}: corner {k} {} against {}",
                    got[k],
                    want[k]
                );
            }
            assert!((got.iter().sum::<f64>() - std::f64::consts::PI).abs() <= 1e-14);
        }
    }

    /// Against `f64::atan2` over the upper half-plane, spread over many scales, and at its
    /// edges (zero, the octant and reduction boundaries, tiny angles): within 5e-16 rad and,
    /// for angles below 1e-3, 1e-15 of their size. NaN stays NaN.
    #[test]
    fn atan2_upper_agrees_with_std() {
        let mut rand = uniform(3);
        let mut cases: Vec<(f64, f64)> = (0..200_000)
            .map(|_| {
                let s = 10f64.powf(rand() * 40.0 - 20.0);
                (
                    rand() * s,
                    (rand() - 0.5) * 10f64.powf(rand() * 40.0 - 20.0),
                )
            })
            .collect();
        let t = 0.267_949_192_431_122_7;
        for (y, x) in [
            (0.0, 1.0),
            (0.0, -1.0),
            (0.0, 0.0),
            (1.0, 0.0),
            (1.0, 1.0),
            (1.0, -1.0),
            (t, 1.0),
            (1.0, t),
            (1e-300, 1.0),
            (1e-12, -1.0),
            (1.0, 1e-300),
        ] {
            cases.push((y, x));
            cases.push((f64::from_bits(y.to_bits() + 1), x));
        }
        for (y, x) in cases {
            let (got, want) = (atan2_upper(y, x), y.atan2(x));
            let err = (got - want).abs();
            assert!(
                err <= 5e-16 && (want >= 1e-3 || err <= 1e-15 * want),
                "atan2({y:e}, {x:e}) = {got:e}, not {want:e}"
            );
        }
        assert!(atan2_upper(f64::NAN, 1.0).is_nan() && atan2_upper(1.0, f64::NAN).is_nan());
    }

    /// `corners_checked` refuses exactly the triangles `is_degenerate_triangle` calls
    /// degenerate: random ones, slivers either side of the threshold, a zero-area one and ones
    /// with non-finite coordinates.
    #[test]
    fn corners_checked_refuses_the_degenerate() {
        let mut rand = centred(11);
        let mut cases: Vec<[[f64; 3]; 3]> = (0..2000)
            .map(|_| {
                let s = 10f64.powf(rand() * 30.0);
                [
                    [rand(), rand(), rand()],
                    [rand(), rand(), rand()],
                    [rand() * s, rand() * s, rand()],
                ]
            })
            .collect();
        for h in [0.0, 1e-13, 4.9e-13, 5e-13, 5.1e-13, 1e-12, 1e-11] {
            cases.push([[0.0; 3], [1.0, 0.0, 0.0], [0.5, h, 0.0]]);
            cases.push([[0.0; 3], [1.0, 0.0, 0.0], [0.3, h, h]]);
        }
        cases.push([[0.0; 3], [1.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0]]);
        cases.push([[0.0; 3], [1.0, 0.0, 0.0], [f64::INFINITY, 1.0, 0.0]]);
        let mut refused = 0;
        for [a, b, c] in cases {
            let degenerate = is_degenerate_triangle(a, b, c);
            refused += usize::from(degenerate);
            assert_eq!(
                corners_checked(a, b, c).is_none(),
                degenerate,
                "{a:?} {b:?} {c:?}"
            );
        }
        assert!(refused >= 8, "only {refused} degenerate cases");
    }
}
