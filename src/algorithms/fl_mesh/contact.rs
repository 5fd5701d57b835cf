//! Keeping the free vertices clear of an obstacle (perturb's reference body, FL Eq. 20's
//! inequality) inside the fl-mesh SQP.
//!
//! Every free vertex r owns one row of the KKT system, so its pattern (and the symbolic
//! factorisation) never changes: an active row is ∇s(v_r)·δ_r = c − s(v_r) with a tiny
//! regularised diagonal, an inactive one is −μ_r = 0 (diagonal −1, nothing coupled). The
//! active set: rows with s < c, rows a refused trial would have crossed, and rows whose full
//! step is predicted to cross; after a solve, a row whose multiplier pulls its vertex towards
//! the body (λ > 0 with Eq. 7's signs, paper-notes A.3 item 9) is dropped and the system
//! solved again (a few rounds).
//!
//! The linearisation is not trusted: every trial is checked with the exact signed distance and
//! refused when a vertex ends below its floor min(c, s at the input) (less 1e-10·h̄ of
//! rounding), so a vertex that started at least c outside never ends closer and none that
//! started outside ends inside. For a closed obstacle the signed distance is 1-Lipschitz, so
//! a vertex with s − |Δ| ≥ c needs no query; an open one may change sign beside its border,
//! so there every moved vertex is queried. (This assumes the closed components neither
//! intersect nor nest, as a body does; where they do, the nearest feature's sign can flip
//! away from the surface and a skipped query could miss a crossing.)

use crate::mesh::dot;

/// A surface the free vertices must stay outside of.
pub trait Obstacle: Sync {
    /// Signed distance of `p` (positive outside) and its unit gradient there.
    fn clearance(&self, p: [f64; 3]) -> (f64, [f64; 3]);
    /// Whether every component is closed (the signed distance is then 1-Lipschitz).
    fn is_closed(&self) -> bool;
}

/// An obstacle and the least signed distance to keep from it.
#[derive(Clone, Copy)]
pub struct Keep<'a> {
    /// The obstacle.
    pub obstacle: &'a dyn Obstacle,
    /// The clearance c, in mesh units (≥ 0).
    pub clearance: f64,
}

impl Keep<'_> {
    /// The floor of a vertex at `p` before the run: min(c, s(p)).
    pub(super) fn floor_at(&self, p: [f64; 3]) -> f64 {
        self.obstacle.clearance(p).0.min(self.clearance)
    }
}

/// The contact state of one refinement round (rows = the system's free vertices).
pub(super) struct Contact<'a> {
    keep: Keep<'a>,
    /// The vertex of each row.
    free: Vec<u32>,
    /// Least signed distance a trial may leave, per row.
    floor: Vec<f64>,
    /// Signed distance at the current positions: exact where `exact`, else a lower bound.
    s: Vec<f64>,
    exact: Vec<bool>,
    grad: Vec<[f64; 3]>,
    /// The same for the last trial.
    trial_s: Vec<f64>,
    trial_exact: Vec<bool>,
    trial_grad: Vec<[f64; 3]>,
    /// Rows whose constraint is in the system.
    pub(super) active: Vec<bool>,
    /// Rows a refused trial took below their floor (activated at the next iteration).
    refused: Vec<u32>,
    /// Rows activated that way for the current iteration: not dropped by `revise`.
    forced: Vec<bool>,
}

/// Rounds of dropping wrong-signed rows and adding predicted crossings per iteration.
pub(super) const ACTIVE_SET_ROUNDS: usize = 3;

impl<'a> Contact<'a> {
    /// Rows for the vertices `free`; `floor` and `pos` per vertex; `slack` is subtracted from
    /// every floor (rounding).
    pub(super) fn new(
        keep: Keep<'a>,
        free: &[u32],
        floor: &[f64],
        pos: &[[f64; 3]],
        slack: f64,
    ) -> Self {
        let n = free.len();
        let mut c = Contact {
            keep,
            free: free.to_vec(),
            floor: free.iter().map(|&v| floor[v as usize] - slack).collect(),
            s: vec![0.0; n],
            exact: vec![false; n],
            grad: vec![[0.0; 3]; n],
            trial_s: vec![0.0; n],
            trial_exact: vec![false; n],
            trial_grad: vec![[0.0; 3]; n],
            active: vec![false; n],
            refused: Vec::new(),
            forced: vec![false; n],
        };
        for r in 0..n {
            c.query(r, pos[free[r] as usize], false);
        }
        c
    }

    fn query(&mut self, r: usize, p: [f64; 3], trial: bool) {
        let (s, g) = self.keep.obstacle.clearance(p);
        if trial {
            (self.trial_s[r], self.trial_grad[r], self.trial_exact[r]) = (s, g, true);
        } else {
            (self.s[r], self.grad[r], self.exact[r]) = (s, g, true);
        }
    }

    /// Choose the rows for the next solve at positions `pos` (per vertex): those below the
    /// clearance, those a trial was refused for, and those already active that are still
    /// within `band` of it.
    pub(super) fn choose(&mut self, pos: &[[f64; 3]], band: f64) {
        let c = self.keep.clearance;
        self.forced.fill(false);
        for r in self.refused.drain(..) {
            self.forced[r as usize] = true;
        }
        for r in 0..self.s.len() {
            if !self.exact[r] && (self.s[r] < c + band || self.active[r] || self.forced[r]) {
                self.query(r, pos[self.free[r] as usize], false);
            }
            self.active[r] =
                self.forced[r] || self.s[r] < c || (self.active[r] && self.s[r] < c + band);
        }
    }

    /// ‖(c − s)₊‖₂ / `h` over the rows, at the current positions or the last trial: the
    /// obstacle's part of the merit (exact: a row is only left unqueried when provably ≥ c).
    pub(super) fn residual(&self, trial: bool, h: f64) -> f64 {
        let s = if trial { &self.trial_s } else { &self.s };
        let c = self.keep.clearance;
        s.iter()
            .map(|&x| ((c - x).max(0.0) / h).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Whether every row is at ≥ c − `tol` at `pos` (per vertex); rows whose lower bound says
    /// otherwise are queried.
    pub(super) fn satisfied(&mut self, pos: &[[f64; 3]], tol: f64) -> bool {
        let target = self.keep.clearance - tol;
        let mut ok = true;
        for r in 0..self.s.len() {
            if self.s[r] >= target {
                continue;
            }
            if !self.exact[r] {
                self.query(r, pos[self.free[r] as usize], false);
            }
            ok &= self.s[r] >= target;
        }
        ok
    }

    /// The row's coefficients and right-hand side c − s when active.
    pub(super) fn row(&self, r: usize) -> Option<([f64; 3], f64)> {
        self.active[r].then(|| (self.grad[r], self.keep.clearance - self.s[r]))
    }

    /// After a solve (`rhs`: the normal then the tangential solution, `dim` unknowns each, rows
    /// laid out as in fl-mesh's System), for the full step normal + `scale`·tangential: drop
    /// rows whose multiplier pulls their vertex inwards (λ > 0) and add rows the step is
    /// predicted to take below the clearance. `pos` per vertex. Whether the set changed.
    pub(super) fn revise(&mut self, pos: &[[f64; 3]], rhs: &[f64], dim: usize, scale: f64) -> bool {
        let c = self.keep.clearance;
        let n = self.s.len();
        let mut changed = false;
        for r in 0..n {
            if self.active[r] {
                let lambda = rhs[4 * n + r] + scale * rhs[dim + 4 * n + r];
                if lambda > 0.0 && !self.forced[r] {
                    self.active[r] = false;
                    changed = true;
                }
                continue;
            }
            let delta = [0, 1, 2].map(|k| rhs[k * n + r] + scale * rhs[dim + k * n + r]);
            let len = dot(delta, delta).sqrt();
            if self.s[r] - len >= c && self.exact_is_optional() {
                continue;
            }
            if !self.exact[r] {
                self.query(r, pos[self.free[r] as usize], false);
            }
            if self.s[r] + dot(self.grad[r], delta) < c {
                self.active[r] = true;
                changed = true;
            }
        }
        changed
    }

    fn exact_is_optional(&self) -> bool {
        self.keep.obstacle.is_closed()
    }

    /// Check a trial: positions `from` and `to` per vertex. False when a vertex ends below its
    /// floor (its row is remembered and activated at the next iteration).
    pub(super) fn check_trial(&mut self, from: &[[f64; 3]], to: &[[f64; 3]]) -> bool {
        let mut ok = true;
        for r in 0..self.s.len() {
            let v = self.free[r] as usize;
            let d = crate::mesh::sub(to[v], from[v]);
            let len = dot(d, d).sqrt();
            if len == 0.0 {
                (self.trial_s[r], self.trial_grad[r], self.trial_exact[r]) =
                    (self.s[r], self.grad[r], self.exact[r]);
                continue;
            }
            // Skipped only when provably still at ≥ c (so that `residual` is exact).
            if self.exact_is_optional() && self.s[r] - len >= self.keep.clearance {
                (self.trial_s[r], self.trial_exact[r]) = (self.s[r] - len, false);
                continue;
            }
            self.query(r, to[v], true);
            if self.trial_s[r] < self.floor[r] {
                self.refused.push(r as u32);
                ok = false;
            }
        }
        ok
    }

    /// Make the last checked trial the current state.
    pub(super) fn accept_trial(&mut self) {
        std::mem::swap(&mut self.s, &mut self.trial_s);
        std::mem::swap(&mut self.exact, &mut self.trial_exact);
        std::mem::swap(&mut self.grad, &mut self.trial_grad);
        // Rows refused by trials that were not taken still count for the next iteration.
    }
}
