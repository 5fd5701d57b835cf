//! Thin wrappers over faer's sparse LU and LDLᵀ: a fixed sparsity pattern assembled once from
//! (row, column) pairs, whose values are refilled every iteration in the same order, and
//! solvers that compute the ordering and symbolic factorisation once and only the numeric one
//! afterwards (../shared/CRATES.md: the pattern of the FL-mesh KKT system never changes).

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
/// block) factored as LDLᵀ with a fill-reducing ordering computed once. Only the lower
/// triangle of the pattern is read; `signs` gives the expected sign of each pivot (+1 for the
/// (1,1) block, −1 for the (2,2) block) so that a pivot that comes out tiny or of the wrong
/// sign is regularised instead of breaking the factorisation.
///
/// The ordering is AMD, either on the whole matrix or, when unknowns come in groups that
/// share their couplings (x, y, z and λ of one vertex), on the graph of the groups with each
/// group kept together. On the FL-mesh KKT system of ipc_skirt4K (14k unknowns) the grouped
/// ordering is 4× cheaper to compute and its factor 3% sparser and ~10% faster to compute.
/// The ordering is applied to the pattern once and the values are scattered straight into the
/// permuted CSC triangle the factorisation reads, at positions worked out once, so refactoring
/// neither allocates nor permutes (faer permutes on every factorisation otherwise: measured
/// 7 % of a develop run on the t-shirt, which now takes 3.1–3.4 s instead of 3.8 s).
pub struct LdltSolver {
    n: usize,
    /// The permuted matrix's pattern on `side` (sorted, no duplicates).
    symbolic: SymbolicSparseColMat<usize>,
    /// For each input entry, its slot in `csc_values` (`usize::MAX` above the diagonal).
    slot: Vec<usize>,
    csc_values: Vec<f64>,
    chol: faer::sparse::linalg::cholesky::SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    /// Pivot signs in the permuted order.
    signs: Vec<i8>,
    /// The triangle `symbolic` holds (the one the numeric factorisation reads).
    side: faer::Side,
    /// The fill-reducing order: permuted unknown k is unknown fwd[k].
    fwd: Vec<usize>,
    /// Scratch for right-hand sides in the permuted order.
    permuted_rhs: Vec<f64>,
    mem: faer::dyn_stack::MemBuffer,
    /// Operations of one numeric factorisation ([`LdltSolver::factor_flops`]).
    flops: f64,
    /// How long the last numeric factorisation took (0 before the first).
    last_factor_seconds: f64,
    factored: bool,
}

impl std::fmt::Debug for LdltSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LdltSolver").field("n", &self.n).finish()
    }
}

/// Most right-hand sides one `solve_many_in_place` call takes (its scratch is sized for them).
pub const MAX_RHS: usize = 4;

impl LdltSolver {
    /// Pattern from `(row, col)` pairs (entries above the diagonal are ignored but may be
    /// given; repeated pairs are summed) and the symbolic factorisation, once. `groups`, when
    /// given, holds a group id per unknown (ids `0..g`, every id used): the ordering then
    /// keeps each group's unknowns together.
    pub fn new(
        n: usize,
        entries: &[(usize, usize)],
        signs: Vec<i8>,
        groups: Option<&[u32]>,
    ) -> Result<Self, LinalgError> {
        use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymmetricOrdering};
        if signs.len() != n {
            return Err(LinalgError::Pattern(format!(
                "{} signs for dimension {n}",
                signs.len()
            )));
        }
        if let Some(&(r, c)) = entries.iter().find(|&&(r, c)| r >= n || c >= n) {
            return Err(LinalgError::Pattern(format!(
                "entry ({r}, {c}) outside a {n}×{n} matrix"
            )));
        }
        // The fill-reducing permutation, applied here once: the pattern is stored already
        // permuted and factored in the identity order, so faer does not permute the values
        // on every numeric factorisation (7 % of a develop run on the t-shirt).
        let (fwd, inv) = match groups {
            Some(g) => group_amd(n, entries, g)?,
            None => group_amd(n, entries, &(0..n as u32).collect::<Vec<_>>())?,
        };
        // faer analyses an unpermuted pattern as its upper triangle; its supernodal numeric
        // factorisation reads the lower one and its simplicial one the upper one, and any
        // other side costs a transposition per factorisation. So: the upper pattern for the
        // analysis, then the values stored on the side the chosen factorisation reads.
        let upper = |&(r, c): &(usize, usize)| {
            let (a, b) = (inv[r], inv[c]);
            (a.min(b), a.max(b))
        };
        let (upper_pattern, _) = permuted_csc(n, entries, upper);
        let chol = factorize_symbolic_cholesky(
            upper_pattern.as_ref(),
            faer::Side::Upper,
            SymmetricOrdering::Identity,
            Default::default(),
        )
        .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let side = match chol.raw() {
            faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Simplicial(_) => faer::Side::Upper,
            faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(_) => faer::Side::Lower,
        };
        let (symbolic, slot) = match side {
            faer::Side::Upper => permuted_csc(n, entries, upper),
            faer::Side::Lower => permuted_csc(n, entries, |e| {
                let (r, c) = upper(e);
                (c, r)
            }),
        };
        let nnz = symbolic.row_idx().len();
        let signs = fwd.iter().map(|&i| signs[i]).collect();
        let par = faer::Par::Seq;
        let req = chol
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default())
            .or(chol.solve_in_place_scratch::<f64>(MAX_RHS, par));
        let mem = faer::dyn_stack::MemBuffer::try_new(req)
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let l_values = vec![0.0; chol.len_val()];
        Ok(Self {
            n,
            symbolic,
            slot,
            csc_values: vec![0.0; nnz],
            chol,
            l_values,
            signs,
            side,
            fwd,
            permuted_rhs: vec![0.0; n * MAX_RHS],
            mem,
            factored: false,
            flops: 0.0,
            last_factor_seconds: 0.0,
        }
        .with_flops())
    }

    /// Numeric factorisation for `values` (in the order of the constructor's `entries`).
    pub fn factor(&mut self, values: &[f64]) -> Result<(), LinalgError> {
        use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
        self.factored = false;
        if values.len() != self.slot.len() {
            return Err(LinalgError::Pattern(format!(
                "{} values for {} entries",
                values.len(),
                self.slot.len()
            )));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        self.csc_values.fill(0.0);
        for (&s, &v) in self.slot.iter().zip(values) {
            if s != usize::MAX {
                self.csc_values[s] += v;
            }
        }
        let a = faer::sparse::SparseColMatRef::new(self.symbolic.as_ref(), &self.csc_values);
        let reg = LdltRegularization {
            dynamic_regularization_signs: Some(&self.signs),
            dynamic_regularization_delta: 1e-10,
            dynamic_regularization_epsilon: 1e-14,
        };
        let stack = faer::dyn_stack::MemStack::new(&mut self.mem);
        let start = std::time::Instant::now();
        self.chol
            .factorize_numeric_ldlt(
                &mut self.l_values,
                a,
                self.side,
                reg,
                faer::Par::Seq,
                stack,
                Default::default(),
            )
            .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
        let seconds = start.elapsed().as_secs_f64();
        if self.last_factor_seconds == 0.0 {
            crate::cost::FIRST_LDLT_FACTOR.learn(self.flops, seconds);
        }
        self.last_factor_seconds = seconds.max(f64::MIN_POSITIVE);
        self.factored = true;
        Ok(())
    }

    /// How long the next numeric factorisation should take: the last one's time, or before
    /// the first, its operations at the rate of this process's first factorisations (slower
    /// than later ones, whose factor's pages are already touched: 1.7 s against 0.9 s on a
    /// 205k-face fl-mesh system). Lets a caller with a deadline refuse to start one it
    /// cannot finish.
    pub fn predicted_factor_seconds(&self) -> f64 {
        if self.last_factor_seconds > 0.0 {
            self.last_factor_seconds
        } else {
            crate::cost::FIRST_LDLT_FACTOR.seconds(self.flops)
        }
    }

    fn with_flops(mut self) -> Self {
        self.flops = self.factor_flops();
        self
    }

    /// Floating-point operations of one numeric factorisation, from the symbolic structure:
    /// per supernode of width w with r rows below it, w³/3 (its diagonal block) + r·w²
    /// (the panel) + r²·w (the update of its ancestors); per column of count c of a
    /// simplicial factor, c².
    pub fn factor_flops(&self) -> f64 {
        use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
        match self.chol.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => {
                let rows = s.col_ptr_for_row_idx();
                (0..s.n_supernodes())
                    .map(|k| {
                        let w = (s.supernode_end()[k] - s.supernode_begin()[k]) as f64;
                        let r = (rows[k + 1] - rows[k]) as f64;
                        w * w * w / 3.0 + r * w * w + r * r * w
                    })
                    .sum()
            }
            SymbolicCholeskyRaw::Simplicial(s) => s
                .col_ptr()
                .windows(2)
                .map(|c| ((c[1] - c[0]) as f64).powi(2))
                .sum(),
        }
    }

    /// Solve with the last factorisation; `rhs` is overwritten by the solution.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<(), LinalgError> {
        self.solve_many_in_place(rhs, 1)
    }

    /// Solve for `k` right-hand sides stored one after another (column-major, `k ≤ MAX_RHS`)
    /// in one pass over the factor.
    pub fn solve_many_in_place(&mut self, rhs: &mut [f64], k: usize) -> Result<(), LinalgError> {
        if !self.factored {
            return Err(LinalgError::Factor("solve before factor".into()));
        }
        if k == 0 || k > MAX_RHS || rhs.len() != self.n * k {
            return Err(LinalgError::Pattern(format!(
                "right-hand side of length {} for dimension {} and {k} column(s) (at most {MAX_RHS})",
                rhs.len(),
                self.n
            )));
        }
        let ldlt = faer::sparse::linalg::cholesky::LdltRef::<'_, usize, f64>::new(
            &self.chol,
            &self.l_values,
        );
        let n = self.n;
        let y = &mut self.permuted_rhs[..n * k];
        for (col, ycol) in rhs.chunks_exact(n).zip(y.chunks_exact_mut(n)) {
            for (yk, &i) in ycol.iter_mut().zip(&self.fwd) {
                *yk = col[i];
            }
        }
        let m = faer::MatMut::from_column_major_slice_mut(y, n, k);
        let stack = faer::dyn_stack::MemStack::new(&mut self.mem);
        ldlt.solve_in_place_with_conj(faer::Conj::No, m, faer::Par::Seq, stack);
        for (col, ycol) in rhs.chunks_exact_mut(n).zip(y.chunks_exact(n)) {
            for (&yk, &i) in ycol.iter().zip(&self.fwd) {
                col[i] = yk;
            }
        }
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(LinalgError::NonFinite);
        }
        Ok(())
    }
}

/// The pattern of the entries on and below the diagonal (`r ≥ c`), each placed at
/// `place(entry)` = (row, column), in CSC order with repeats merged, and every entry's slot in
/// its values (`usize::MAX` for entries above the diagonal). Counting sort by column, then
/// each column's few rows sorted.
fn permuted_csc(
    n: usize,
    entries: &[(usize, usize)],
    place: impl Fn(&(usize, usize)) -> (usize, usize),
) -> (SymbolicSparseColMat<usize>, Vec<usize>) {
    let mut count = vec![0usize; n + 1];
    for e in entries.iter().filter(|e| e.0 >= e.1) {
        count[place(e).1 + 1] += 1;
    }
    for c in 0..n {
        count[c + 1] += count[c];
    }
    let mut order = vec![0usize; count[n]];
    let mut next = count.clone();
    for (k, e) in entries.iter().enumerate() {
        if e.0 >= e.1 {
            let c = place(e).1;
            order[next[c]] = k;
            next[c] += 1;
        }
    }
    let mut slot = vec![usize::MAX; entries.len()];
    let mut col_ptr = vec![0usize; n + 1];
    let mut row_idx: Vec<usize> = Vec::with_capacity(order.len());
    for c in 0..n {
        let col = &mut order[count[c]..count[c + 1]];
        col.sort_unstable_by_key(|&k| place(&entries[k]).0);
        let mut last = usize::MAX;
        for &k in col.iter() {
            let r = place(&entries[k]).0;
            if r != last {
                row_idx.push(r);
                last = r;
            }
            slot[k] = row_idx.len() - 1;
        }
        col_ptr[c + 1] = row_idx.len();
    }
    (
        SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
        slot,
    )
}

/// AMD on the quotient graph of `groups` (two groups adjacent when an entry couples them),
/// expanded so that each group's unknowns stay together in increasing order: (forward,
/// inverse) permutation of `0..n`.
fn group_amd(
    n: usize,
    entries: &[(usize, usize)],
    groups: &[u32],
) -> Result<(Vec<usize>, Vec<usize>), LinalgError> {
    if groups.len() != n {
        return Err(LinalgError::Pattern(format!(
            "{} group ids for dimension {n}",
            groups.len()
        )));
    }
    let g = groups.iter().map(|&x| x as usize + 1).max().unwrap_or(0);
    let mut size = vec![0usize; g];
    for &x in groups {
        size[x as usize] += 1;
    }
    if let Some(empty) = size.iter().position(|&c| c == 0) {
        return Err(LinalgError::Pattern(format!(
            "group {empty} has no unknown"
        )));
    }
    // Quotient graph, both triangles, no diagonal: bucket the coupled pairs by column, then
    // drop repeats with a marker (no sort needed: AMD takes unsorted columns).
    let mut count = vec![0usize; g + 1];
    for &(r, c) in entries {
        let (a, b) = (groups[r] as usize, groups[c] as usize);
        if a != b {
            count[a + 1] += 1;
            count[b + 1] += 1;
        }
    }
    for x in 0..g {
        count[x + 1] += count[x];
    }
    let mut bucket = vec![0usize; count[g]];
    let mut next = count.clone();
    for &(r, c) in entries {
        let (a, b) = (groups[r] as usize, groups[c] as usize);
        if a != b {
            bucket[next[a]] = b;
            next[a] += 1;
            bucket[next[b]] = a;
            next[b] += 1;
        }
    }
    let mut seen = vec![usize::MAX; g];
    let mut col_ptr = vec![0usize; g + 1];
    let mut row_idx = Vec::new();
    for x in 0..g {
        for &y in &bucket[count[x]..count[x + 1]] {
            if seen[y] != x {
                seen[y] = x;
                row_idx.push(y);
            }
        }
        col_ptr[x + 1] = row_idx.len();
    }
    let nnz = row_idx.len();
    let quotient = SymbolicSparseColMat::new_unsorted_checked(g, g, col_ptr, None, row_idx);
    let mut perm = vec![0usize; g];
    let mut perm_inv = vec![0usize; g];
    let mut mem = faer::dyn_stack::MemBuffer::try_new(
        faer::sparse::linalg::amd::order_maybe_unsorted_scratch::<usize>(g, nnz),
    )
    .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
    faer::sparse::linalg::amd::order_maybe_unsorted(
        &mut perm,
        &mut perm_inv,
        quotient.as_ref(),
        Default::default(),
        faer::dyn_stack::MemStack::new(&mut mem),
    )
    .map_err(|e| LinalgError::Factor(format!("{e:?}")))?;
    // Unknowns of each group, in increasing order.
    let mut start = vec![0usize; g + 1];
    for x in 0..g {
        start[x + 1] = start[x] + size[x];
    }
    let mut members = vec![0usize; n];
    let mut fill = start.clone();
    for (i, &x) in groups.iter().enumerate() {
        members[fill[x as usize]] = i;
        fill[x as usize] += 1;
    }
    let mut fwd = Vec::with_capacity(n);
    for &x in &perm {
        fwd.extend_from_slice(&members[start[x]..start[x + 1]]);
    }
    let mut inv = vec![0usize; n];
    for (k, &i) in fwd.iter().enumerate() {
        inv[i] = k;
    }
    Ok((fwd, inv))
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
        let mut s = LdltSolver::new(3, &entries, vec![1, 1, -1], None).unwrap();
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

    /// Grouped ordering, repeated entries summed, two right-hand sides at once: checked
    /// against the LU solver on the same (symmetric) matrix.
    #[test]
    fn ldlt_grouped_ordering_and_two_rhs_match_lu() {
        // A quasi-definite KKT on a path of m "vertices": H = tridiagonal SPD on 2m unknowns
        // (two per vertex), and one constraint row per vertex coupling it with its neighbours.
        let m = 30;
        let n = 3 * m;
        let mut entries = Vec::new();
        let mut values = Vec::new();
        let push = |e: &mut Vec<(usize, usize)>, v: &mut Vec<f64>, r, c, x: f64| {
            e.push((r, c));
            v.push(x);
            if r != c {
                e.push((c, r));
                v.push(x);
            }
        };
        for i in 0..2 * m {
            // Diagonal given as two halves: repeated entries are summed.
            push(&mut entries, &mut values, i, i, 2.0);
            push(&mut entries, &mut values, i, i, 2.0);
            if i + 2 < 2 * m {
                push(&mut entries, &mut values, i + 2, i, -1.0);
            }
        }
        for k in 0..m {
            let row = 2 * m + k;
            for j in k.saturating_sub(1)..(k + 2).min(m) {
                let x = 0.3 + 0.1 * (j as f64) - 0.05 * (k as f64);
                push(&mut entries, &mut values, row, 2 * j, x);
                push(&mut entries, &mut values, row, 2 * j + 1, 1.0 - x);
            }
            push(&mut entries, &mut values, row, row, -1e-3);
        }
        let signs: Vec<i8> = (0..n).map(|i| if i < 2 * m { 1 } else { -1 }).collect();
        // Groups: vertex k owns 2k, 2k+1 and 2m+k.
        let groups: Vec<u32> = (0..n)
            .map(|i| {
                if i < 2 * m {
                    (i / 2) as u32
                } else {
                    (i - 2 * m) as u32
                }
            })
            .collect();
        let mut ldlt = LdltSolver::new(n, &entries, signs, Some(&groups)).unwrap();
        ldlt.factor(&values).unwrap();
        let mut lu = LuSolver::new(n, &entries).unwrap();
        lu.factor(&values).unwrap();
        let mut rhs: Vec<f64> = (0..2 * n).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
        let mut a = rhs[..n].to_vec();
        let mut b = rhs[n..].to_vec();
        lu.solve_in_place(&mut a).unwrap();
        lu.solve_in_place(&mut b).unwrap();
        ldlt.solve_many_in_place(&mut rhs, 2).unwrap();
        let scale = a.iter().chain(&b).fold(0.0f64, |m, x| m.max(x.abs()));
        for i in 0..n {
            assert!((rhs[i] - a[i]).abs() <= 1e-10 * scale, "{i}");
            assert!((rhs[n + i] - b[i]).abs() <= 1e-10 * scale, "{i}");
        }
        // Bad calls are refused, not panics.
        assert!(ldlt.solve_many_in_place(&mut rhs, 3).is_err());
        assert!(ldlt.factor(&values[1..]).is_err());
        assert!(LdltSolver::new(n, &[(n, 0)], vec![1; n], None).is_err());
        let mut holes = groups.clone();
        holes[0] = 10 * m as u32;
        assert!(LdltSolver::new(n, &entries, vec![1; n], Some(&holes)).is_err());
    }
}
