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
//!   five times first; a move whose quadratic model promises less than a quarter of that
//!   0.1 % is refused untried, `PROMISE`). A move changes g only at q and its ring, which is
//!   all of T, so G falls with every move.
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
//! objective, and the length change it costs is E's.
//!
//! Beyond the paper (paper-notes B.4.5): a vertex whose move is refused, clamped to no change,
//! or has r′ = 0 (Ṫ = 0: "we just simply fix the vertex") is marked stalled and leaves the
//! heap until a vertex within two rings of it moves (which changes its T); the paper would pop
//! it again until N_max. The run stops when the heap's top is at most ε and the global
//! max |g| is too (`tolerance`), when only stalled vertices are above ε (`stalled`, naming
//! them; with `min_gain`, once a sweep over them moved none), or after `max_moves` pops. Seam
//! and boundary vertices never move (Sec. 5.2); every output vertex is q⁰ + δ n_q with
//! |δ| ≤ δ_T; a move that would make a triangle of the fan degenerate is refused (halved, like
//! one that does not lower T). If the moves together made g_max worse (the paper's Newton
//! update does on real garments), the input is returned.

use super::energy::{big_g, g_max, Model};
use super::{Params, Run, Stop, Update};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::geometry::corner_angle_gradient;
use crate::mesh::{cross, dot, sub, Mesh};
use std::f64::consts::PI;

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
/// A Gauss–Newton move whose model promises less than this share of [`MIN_PROGRESS`] is
/// refused without evaluating T: 82 % of the t-shirt's 500000 pops are refused, each after six
/// evaluations of T (the halvings). Measured (t-shirt, 500000 pops): 1 skipped nearly all of
/// them but also moves that would have passed (G 0.4121 → 0.4139, and worse on 13 of 19 shared
/// meshes); 0.5 likewise; 0.25 gave results identical to full evaluation on the t-shirt,
/// shoes01, gf_jumpsuit_front1 and mh_female_elegantsuit01, with 2.0 evaluations a pop
/// instead of 5.1.
const PROMISE: f64 = 0.25;

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
    let mut pops = 0usize;
    let floor_share = match params.update {
        Update::GaussNewton => params.min_gain,
        Update::Newton => 0.0,
    };
    let interior = (0..nv).filter(|&v| model.is_interior(v)).count().max(1) as f64;
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
                for v in 0..nv {
                    if stalled[v] && g[v].abs() > eps {
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
            step(
                model,
                &mut pos,
                q,
                start[qi],
                n,
                &mut delta[qi],
                delta_t,
                params.update,
                params.relaxation,
                (floor_share * big_g_now / interior).max(0.0),
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
            for &p in std::iter::once(&v).chain(mesh.conn().ring_of(v)) {
                let pi = p as usize;
                if !model.is_interior(pi) {
                    continue;
                }
                stalled[pi] = false;
                if g[pi] != 0.0 {
                    heap.set(p, g[pi].abs());
                } else {
                    heap.remove(p);
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

/// Whether a triangle of q's fan is degenerate at `pos`.
fn fan_degenerate(mesh: &Mesh, pos: &[[f64; 3]], q: u32) -> bool {
    mesh.conn().fan_of(q).iter().any(|&h| {
        let [a, b, c] = mesh.triangles()[h as usize / 3].map(|v| pos[v as usize]);
        crate::mesh::is_degenerate_triangle(a, b, c)
    })
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
    model: &Model<'_>,
    pos: &mut [[f64; 3]],
    q: u32,
    q0: [f64; 3],
    n: [f64; 3],
    delta: &mut f64,
    delta_t: f64,
    update: Update,
    relaxation: f64,
    floor: f64,
    s: &mut Local,
) -> bool {
    let (t0, tdot) = s.t_and_slope();
    let rr: f64 = s.slope.iter().map(|x| x * x).sum();
    let wanted = match update {
        Update::Newton if tdot != 0.0 => *delta - t0 / tdot,
        Update::GaussNewton if rr > 0.0 => *delta - relaxation * 0.5 * tdot / rr,
        _ => return false,
    };
    let target = wanted.clamp(-delta_t, delta_t);
    if !target.is_finite() || target == *delta {
        return false;
    }
    if update == Update::GaussNewton {
        // Where T's quadratic model T + c Ṫ + c² r′·r′, at its best within the clamp, promises
        // less than a quarter of the decrease a move must make, the trials below would all be
        // refused: skip them (see `PROMISE`).
        let c = (-0.5 * tdot / rr).clamp(-delta_t - *delta, delta_t - *delta);
        if -(c * tdot + c * c * rr) < PROMISE * (MIN_PROGRESS * t0).max(floor) {
            return false;
        }
    }
    let qi = q as usize;
    let old = pos[qi];
    let mut change = target - *delta;
    for _ in 0..=HALVINGS {
        let d = *delta + change;
        pos[qi] = [0, 1, 2].map(|k| q0[k] + d * n[k]);
        if fan_degenerate(model.mesh(), pos, q) {
            change *= 0.5;
            continue;
        }
        let t1 = s.evaluate(pos);
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
        change *= 0.5;
    }
    pos[qi] = old;
    false
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
        self.verts.clear();
        self.verts.push(q);
        self.verts.extend_from_slice(mesh.conn().ring_of(q));
        self.g_before.clear();
        self.g_before
            .extend(self.verts.iter().map(|&v| g[v as usize]));
        self.g_after.clear();
        self.g_after.extend_from_slice(&self.g_before);
        self.slope.clear();
        self.slope.resize(self.verts.len(), 0.0);
        let index = |v: u32, verts: &[u32]| verts.iter().position(|&x| x == v);
        let pq = pos[q as usize];
        self.fan.clear();
        for &hf in mesh.conn().fan_of(q) {
            let t = mesh.triangles()[hf as usize / 3];
            let k = hf as usize % 3;
            let (b, c) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let (pb, pc) = (pos[b as usize], pos[c as usize]);
            let counted = |v: u32| {
                index(v, &self.verts)
                    .filter(|_| model.is_interior(v as usize))
                    .unwrap_or(usize::MAX)
            };
            self.fan.push(FanCorners {
                verts: [q, b, c],
                index: [counted(q), counted(b), counted(c)],
                face: hf as usize / 3,
                k,
                before: [0, 1, 2].map(|x| cache[hf as usize / 3][(k + x) % 3]),
                after: [0.0; 3],
            });
            // dθ/dq for the corners at q, at b (angle (b, c, q)) and at c (angle (c, q, b)).
            let (gb, gc) = corner_angle_gradient(pq, pb, pc);
            let at_q = [0, 1, 2].map(|i| -(gb[i] + gc[i]));
            let at_b = corner_angle_gradient(pb, pc, pq).1;
            let at_c = corner_angle_gradient(pc, pq, pb).0;
            for (v, d) in [(q, at_q), (b, at_b), (c, at_c)] {
                if let Some(i) = index(v, &self.verts) {
                    if model.is_interior(v as usize) {
                        // r = g = 2π − θ, so dr/dδ = −∂θ/∂q · n.
                        self.slope[i] -= dot(d, n);
                    }
                }
            }
        }
        for x in self.slope.iter_mut() {
            if !x.is_finite() {
                *x = 0.0;
            }
        }
    }

    /// (T, dT/dδ) before the move.
    fn t_and_slope(&self) -> (f64, f64) {
        let t = self.g_before.iter().map(|x| x * x).sum();
        let d = 2.0
            * self
                .g_before
                .iter()
                .zip(&self.slope)
                .map(|(r, s)| r * s)
                .sum::<f64>();
        (t, d)
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
    fn evaluate(&mut self, pos: &[[f64; 3]]) -> f64 {
        self.g_after.copy_from_slice(&self.g_before);
        for f in self.fan.iter_mut() {
            f.after = corners(
                pos[f.verts[0] as usize],
                pos[f.verts[1] as usize],
                pos[f.verts[2] as usize],
            );
            for ((&i, a), b) in f.index.iter().zip(f.after).zip(f.before) {
                if i != usize::MAX {
                    self.g_after[i] -= a - b;
                }
            }
        }
        let t: f64 = self.g_after.iter().map(|x| x * x).sum();
        if t.is_finite() {
            t
        } else {
            f64::INFINITY
        }
    }
}

/// The corners of triangle (a, b, c) at a, b and c: the two at the ends of the longest edge
/// by `atan2(2·area, dot)` (as `geometry::corner_angle`, full relative precision), the third,
/// which is at least 60°, as π minus them. One cross product and two atan2 instead of three
/// each: atan2 was 56 % of a run (perf, t-shirt, 500k pops).
fn corners(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (ab, bc, ca) = (sub(b, a), sub(c, b), sub(a, c));
    let n = cross(ab, bc);
    let twice_area = dot(n, n).sqrt();
    let at = |d: f64| twice_area.atan2(d);
    // The corner at a is between ab and ac = −ca; at b between ba = −ab and bc; at c between
    // ca and cb = −bc.
    let (da, db, dc) = (-dot(ab, ca), -dot(ab, bc), -dot(bc, ca));
    let (lab, lbc, lca) = (dot(ab, ab), dot(bc, bc), dot(ca, ca));
    if lbc >= lab && lbc >= lca {
        let (x, y) = (at(db), at(dc));
        [PI - x - y, x, y]
    } else if lca >= lab {
        let (x, y) = (at(da), at(dc));
        [x, PI - x - y, y]
    } else {
        let (x, y) = (at(da), at(db));
        [x, y, PI - x - y]
    }
}

/// (T, dT/dδ) for vertex `q` at positions `pos`, moving along `n`: T(δ) = g(q)² + Σ_j g(q_j)²
/// (Eq. 15). Public for the finite-difference tests.
pub fn t_and_slope(model: &Model<'_>, pos: &[[f64; 3]], q: u32, n: [f64; 3]) -> (f64, f64) {
    let mut g = vec![0.0; pos.len()];
    model.g(pos, &mut g);
    let mut s = Local::default();
    s.load(model, pos, q, n, &g, &face_corners(model.mesh(), pos));
    s.t_and_slope()
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
    use super::corners;
    use crate::geometry::corner_angle;

    /// Against `geometry::corner_angle` at every corner, on random triangles and on slivers
    /// (a corner of 1e-9 rad, and one near π): within 1e-14 rad, and the small corners to 1e-9
    /// of their size; the three sum to π.
    #[test]
    fn corners_agree_with_corner_angle() {
        let mut seed = 7u64;
        let mut rand = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
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
}
