//! What steps that cannot be interrupted cost on this machine, learnt from the ones that ran
//! in this process, so that a caller with a deadline can refuse to start one it could not
//! finish ([`crate::algorithms::Control::cancelled_before`]).
//!
//! Each [`Rate`] is seconds per unit of work (operations of a factorisation, faces of a
//! system to set up), an average weighted towards the latest run. It starts at about twice
//! the slowest rate measured on the 2-core VM this was written on: an overestimate only stops
//! a job near its deadline a little early, an underestimate lets it overrun.

use std::sync::atomic::{AtomicU64, Ordering};

/// Seconds per unit of one kind of step.
#[derive(Debug)]
pub struct Rate {
    bits: AtomicU64,
    /// Runs smaller than this many units are not learnt from (timing noise dominates).
    smallest: f64,
}

impl Rate {
    /// A rate starting at `start` seconds per unit.
    pub const fn new(start: f64, smallest: f64) -> Self {
        Self {
            bits: AtomicU64::new(start.to_bits()),
            smallest,
        }
    }

    /// Expected seconds of a step of `units`.
    pub fn seconds(&self, units: f64) -> f64 {
        let s = units * f64::from_bits(self.bits.load(Ordering::Relaxed));
        if s.is_finite() {
            s.max(0.0)
        } else {
            0.0
        }
    }

    /// Learn from a step of `units` that took `seconds`.
    pub fn learn(&self, units: f64, seconds: f64) {
        if !(units >= self.smallest && units.is_finite() && seconds > 0.0 && seconds.is_finite()) {
            return;
        }
        let seen = seconds / units;
        let _ = self
            .bits
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |old| {
                Some((0.7 * f64::from_bits(old) + 0.3 * seen).to_bits())
            });
    }
}

/// A first numeric LDLᵀ factorisation, per operation ([`crate::linalg::LdltSolver::factor_flops`]):
/// 3.7e-11–6.4e-11 s measured on fl-mesh systems of 20k–205k faces, twice a later one's (the
/// fresh factor's pages are touched for the first time).
pub static FIRST_LDLT_FACTOR: Rate = Rate::new(1e-10, 1e8);

/// Setting up one fl-mesh round's KKT system (pattern, ordering, symbolic factorisation), per
/// face: 2.7e-6 s measured at 51k and 205k faces.
pub static FL_MESH_SETUP: Rate = Rate::new(6e-6, 1e4);

/// Setting up develop's SQP KKT system (pattern, grouped ordering, symbolic factorisation),
/// per face: 1.4e-5 s measured at 205k faces (a Loop-subdivided saddle).
pub static DEVELOP_SETUP: Rate = Rate::new(3e-5, 1e4);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rate_learns_towards_what_it_sees_and_ignores_noise() {
        let r = Rate::new(1.0, 10.0);
        assert_eq!(r.seconds(3.0), 3.0);
        r.learn(5.0, 100.0); // below `smallest`
        r.learn(f64::NAN, 1.0);
        r.learn(20.0, 0.0);
        assert_eq!(r.seconds(1.0), 1.0);
        for _ in 0..60 {
            r.learn(100.0, 50.0);
        }
        assert!((r.seconds(1.0) - 0.5).abs() < 1e-6, "{}", r.seconds(1.0));
        assert_eq!(r.seconds(f64::INFINITY), 0.0);
    }
}
