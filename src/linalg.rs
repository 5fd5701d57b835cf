//! Thin wrappers over faer's sparse LU: a fixed sparsity pattern assembled once from
//! (row, column) pairs, whose values are refilled every iteration in the same order, and a
//! solver that computes the symbolic factorisation once and only the numeric one afterwards
//! (../shared/CRATES.md: the pattern of the FL-mesh KKT system never changes).

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};

/// Why a sparse solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinalgError {
    /// The pattern could not be built (index out of range, too many entries).
    #[error("sparse pattern: {0}")]
    Pattern(String),
    /// The numeric factorisation failed (singular matrix, out of memory).
    #[error("sparse factorisation: {0}")]
    Factor(String),
    /// The solution holds a NaN or an infinity (numerically singular system).
    #[error("sparse solve produced a non-finite value")]
    NonFinite,
}

/// A square sparse matrix with a fixed pattern, its symbolic LU, and the order in which the
/// caller's value array maps onto it. Duplicate (row, column) pairs are summed.
pub struct LuSolver {
    n: usize,
    symbolic: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
    lu_symbolic: SymbolicLu<usize>,
    lu: Option<Lu<usize, f64>>,
}

impl std::fmt::Debug for LuSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LuSolver").field("n", &self.n).finish()
    }
}

impl LuSolver {
    /// Build the pattern of an `n × n` matrix from `(row, col)` pairs and its symbolic LU
    /// (column ordering and elimination structure), once.
    pub fn new(n: usize, entries: &[(usize, usize)]) -> Result<Self, LinalgError> {
        let pairs: Vec<Pair<usize, usize>> = entries
            .iter()
            .map(|&(row, col)| Pair { row, col })
            .collect();
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| LinalgError::Pattern(format!("{e:?}")))?;
        let lu_symbolic = SymbolicLu::try_new(symbolic.as_ref())
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        Ok(Self {
            n,
            symbolic,
            argsort,
            lu_symbolic,
            lu: None,
        })
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Numeric LU of the matrix whose values are `values[k]` at `entries[k]` (the order given
    /// to [`LuSolver::new`]); reuses the symbolic factorisation.
    pub fn factor(&mut self, values: &[f64]) -> Result<(), LinalgError> {
        if values.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        let a = SparseColMat::new_from_argsort(self.symbolic.clone(), &self.argsort, values)
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let lu = Lu::try_new_with_symbolic(self.lu_symbolic.clone(), a.as_ref())
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        self.lu = Some(lu);
        Ok(())
    }

    /// Solve `A x = rhs` in place with the last numeric factorisation.
    pub fn solve_in_place(&self, rhs: &mut [f64]) -> Result<(), LinalgError> {
        let lu = self
            .lu
            .as_ref()
            .ok_or_else(|| LinalgError::Factor("solve before factor".into()))?;
        if rhs.len() != self.n {
            return Err(LinalgError::Pattern(format!(
                "right-hand side of length {} for a {}×{} system",
                rhs.len(),
                self.n,
                self.n
            )));
        }
        let m = faer::MatMut::from_column_major_slice_mut(rhs, self.n, 1);
        lu.solve_in_place(m);
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        Ok(())
    }
}

/// A symmetric quasi-definite matrix (positive definite (1,1) block, negative definite (2,2)
/// block) factored as LDLᵀ with a fill-reducing AMD ordering computed once. Only the lower
/// triangle of the pattern is read; `signs` gives the expected sign of each pivot (+1 for the
/// (1,1) block, −1 for the (2,2) block) so that a pivot that comes out tiny or of the wrong
/// sign is regularised instead of breaking the factorisation.
pub struct LdltSolver {
    n: usize,
    symbolic: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
    chol: faer::sparse::linalg::cholesky::SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    signs: Vec<i8>,
    mem: faer::dyn_stack::MemBuffer,
    factored: bool,
}

impl std::fmt::Debug for LdltSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LdltSolver").field("n", &self.n).finish()
    }
}

impl LdltSolver {
    /// Pattern from `(row, col)` pairs (entries above the diagonal are ignored in the
    /// factorisation but may be given) and the symbolic factorisation, once.
    pub fn new(n: usize, entries: &[(usize, usize)], signs: Vec<i8>) -> Result<Self, LinalgError> {
        use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymmetricOrdering};
        if signs.len() != n {
            return Err(LinalgError::Pattern(format!(
                "{} signs for dimension {n}",
                signs.len()
            )));
        }
        let pairs: Vec<Pair<usize, usize>> = entries
            .iter()
            .map(|&(row, col)| Pair { row, col })
            .collect();
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| LinalgError::Pattern(format!("{e:?}")))?;
        let chol = factorize_symbolic_cholesky(
            symbolic.as_ref(),
            faer::Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let par = faer::Par::Seq;
        let req = chol
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default())
            .or(chol.solve_in_place_scratch::<f64>(1, par));
        let mem = faer::dyn_stack::MemBuffer::try_new(req)
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let l_values = vec![0.0; chol.len_val()];
        Ok(Self {
            n,
            symbolic,
            argsort,
            chol,
            l_values,
            signs,
            mem,
            factored: false,
        })
    }

    /// Numeric LDLᵀ of the matrix with `values[k]` at `entries[k]`.
    pub fn factor(&mut self, values: &[f64]) -> Result<(), LinalgError> {
        use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
        if values.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        let a = SparseColMat::new_from_argsort(self.symbolic.clone(), &self.argsort, values)
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let reg = LdltRegularization {
            dynamic_regularization_signs: Some(&self.signs),
            dynamic_regularization_delta: 1e-10,
            dynamic_regularization_epsilon: 1e-14,
        };
        let stack = faer::dyn_stack::MemStack::new(&mut self.mem);
        self.chol
            .factorize_numeric_ldlt(
                &mut self.l_values,
                a.as_ref(),
                faer::Side::Lower,
                reg,
                faer::Par::Seq,
                stack,
                Default::default(),
            )
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        self.factored = true;
        Ok(())
    }

    /// Solve in place with the last factorisation.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<(), LinalgError> {
        if !self.factored {
            return Err(LinalgError::Factor("solve before factor".into()));
        }
        if rhs.len() != self.n {
            return Err(LinalgError::Pattern(format!(
                "right-hand side of length {} for dimension {}",
                rhs.len(),
                self.n
            )));
        }
        let ldlt = faer::sparse::linalg::cholesky::LdltRef::<'_, usize, f64>::new(
            &self.chol,
            &self.l_values,
        );
        let m = faer::MatMut::from_column_major_slice_mut(rhs, self.n, 1);
        let stack = faer::dyn_stack::MemStack::new(&mut self.mem);
        ldlt.solve_in_place_with_conj(faer::Conj::No, m, faer::Par::Seq, stack);
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_small_nonsymmetric_system_and_refactors() {
        // [[4, 1, 0], [2, 5, 1], [0, 3, 6]] with a duplicate entry split in two.
        let entries = [
            (0, 0),
            (0, 1),
            (1, 0),
            (1, 1),
            (1, 2),
            (2, 1),
            (2, 2),
            (0, 0),
        ];
        let mut s = LuSolver::new(3, &entries).unwrap();
        s.factor(&[3.0, 1.0, 2.0, 5.0, 1.0, 3.0, 6.0, 1.0]).unwrap();
        let x = [1.0, -2.0, 0.5];
        let mut b = [
            4.0 * x[0] + x[1],
            2.0 * x[0] + 5.0 * x[1] + x[2],
            3.0 * x[1] + 6.0 * x[2],
        ];
        s.solve_in_place(&mut b).unwrap();
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-12);
        }
        // Same pattern, new values: 2·A.
        s.factor(&[6.0, 2.0, 4.0, 10.0, 2.0, 6.0, 12.0, 2.0])
            .unwrap();
        let mut b = [
            4.0 * x[0] + x[1],
            2.0 * x[0] + 5.0 * x[1] + x[2],
            3.0 * x[1] + 6.0 * x[2],
        ];
        s.solve_in_place(&mut b).unwrap();
        for i in 0..3 {
            assert!((2.0 * b[i] - x[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn ldlt_solves_quasi_definite_kkt_and_refactors() {
        // [[4, 1, 1], [1, 3, 2], [1, 2, -1]]: SPD (1,1) block, negative (2,2) block; the
        // upper triangle is given too and ignored.
        let entries = [
            (0, 0),
            (1, 0),
            (1, 1),
            (2, 0),
            (2, 1),
            (2, 2),
            (0, 1),
            (0, 2),
            (1, 2),
        ];
        let vals = [4.0, 1.0, 3.0, 1.0, 2.0, -1.0, 1.0, 1.0, 2.0];
        let mut s = LdltSolver::new(3, &entries, vec![1, 1, -1]).unwrap();
        let x = [0.5, -1.0, 2.0];
        for scale in [1.0, 3.0] {
            let v: Vec<f64> = vals.iter().map(|v| v * scale).collect();
            s.factor(&v).unwrap();
            let mut b = [
                4.0 * x[0] + x[1] + x[2],
                x[0] + 3.0 * x[1] + 2.0 * x[2],
                x[0] + 2.0 * x[1] - x[2],
            ];
            s.solve_in_place(&mut b).unwrap();
            for i in 0..3 {
                assert!((scale * b[i] - x[i]).abs() < 1e-12, "{b:?}");
            }
        }
    }
}
