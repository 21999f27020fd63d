//! A small square system of size `n + 1` (n ≤ N) held in blocks, because stable Rust cannot
//! size an array `N + 1`: the `n × n` block of the leading unknowns, the column and row of the
//! trailing unknown (the step level) and their corner. Solved by LU with partial pivoting
//! after row and column equilibration; used by the instrumental-variable estimator, whose
//! normal equations are square but not symmetric.

use crate::numerics::real::Real;

/// A vector of length `n + 1`: `n` leading entries and the trailing one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Column<T, const N: usize> {
    pub lead: [T; N],
    pub last: T,
}

impl<T: Real, const N: usize> Column<T, N> {
    pub(crate) fn zero() -> Self {
        Self {
            lead: [T::ZERO; N],
            last: T::ZERO,
        }
    }
}

impl<T: Copy, const N: usize> Column<T, N> {
    #[inline(always)]
    pub(crate) fn get(&self, i: usize, n: usize) -> T {
        if i < n {
            self.lead[i]
        } else {
            self.last
        }
    }

    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize, n: usize, value: T) {
        if i < n {
            self.lead[i] = value;
        } else {
            self.last = value;
        }
    }

    #[inline(always)]
    fn swap(&mut self, i: usize, k: usize, n: usize) {
        let (a, b) = (self.get(i, n), self.get(k, n));
        self.set(i, n, b);
        self.set(k, n, a);
    }
}

/// An `(n+1) × (n+1)` matrix in blocks: `lead` (`n × n`), `right` (column `n`, rows `< n`),
/// `bottom` (row `n`, columns `< n`) and `corner`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Square<T, const N: usize> {
    pub lead: [[T; N]; N],
    pub right: [T; N],
    pub bottom: [T; N],
    pub corner: T,
}

/// What solving `M θ = b` gives, besides θ.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Solved<T, const N: usize> {
    pub theta: Column<T, N>,
    /// `Σ_i ω_i·g_i²` with `g = M⁻ᵀ e_last`: the squared norm of the last row of `M⁻¹`
    /// weighted by the caller's row weights ω (how noise on the rows reaches the last unknown).
    pub last_row_norm2: T,
    /// `g = M⁻ᵀ e_last` itself, the last row of `M⁻¹`.
    pub last_row: Column<T, N>,
}

/// Why a solve failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SolveError {
    /// A matrix or right-hand-side entry is NaN or infinite: the state is corrupted.
    NonFinite,
    /// An equilibrated pivot fell to the rounding level (or a row or column is zero).
    Singular,
}

impl<T: Real, const N: usize> Square<T, N> {
    /// Entry `(i, j)` of the `(n+1) × (n+1)` matrix.
    #[inline(always)]
    pub(crate) fn get(&self, i: usize, j: usize, n: usize) -> T {
        match (i < n, j < n) {
            (true, true) => self.lead[i][j],
            (true, false) => self.right[i],
            (false, true) => self.bottom[j],
            (false, false) => self.corner,
        }
    }

    #[inline(always)]
    fn set(&mut self, i: usize, j: usize, n: usize, value: T) {
        match (i < n, j < n) {
            (true, true) => self.lead[i][j] = value,
            (true, false) => self.right[i] = value,
            (false, true) => self.bottom[j] = value,
            (false, false) => self.corner = value,
        }
    }

    fn swap_rows(&mut self, i: usize, k: usize, n: usize) {
        for j in 0..=n {
            let (a, b) = (self.get(i, j, n), self.get(k, j, n));
            self.set(i, j, n, b);
            self.set(k, j, n, a);
        }
    }

    /// Solve `M θ = rhs` for the `(n+1) × (n+1)` matrix `self`, and weigh the last row of
    /// `M⁻¹` by `row_weight` (ω_i, one per row of M). Consumes a copy: O((n+1)³/3)
    /// multiply–adds for the LU, O((n+1)²) for equilibration and the three triangular solves.
    ///
    /// Rows and columns are scaled to a largest entry of one first, so that partial pivoting
    /// compares like with like (the difference columns of a fast-sampled sensor are orders
    /// of magnitude smaller than the constant column) and the singularity test is relative.
    pub(crate) fn solve(
        mut self,
        n: usize,
        rhs: Column<T, N>,
        row_weight: Column<T, N>,
    ) -> Result<Solved<T, N>, SolveError> {
        let mut rows = RowSide {
            rhs,
            row_weight,
            origin: Column {
                lead: core::array::from_fn(|i| i),
                last: n,
            },
        };
        let row_scale = self.scale_rows(n, &mut rows)?;
        let column_scale = self.scale_columns(n)?;
        self.factor_lu(n, &mut rows)?;
        let RowSide {
            rhs,
            row_weight,
            origin,
        } = rows;
        // U y = (L⁻¹ P b), then θ = S_c y.
        let p = n + 1;
        let mut theta = Column::<T, N>::zero();
        for i in (0..p).rev() {
            let mut value = rhs.get(i, n);
            for j in (i + 1)..p {
                value -= self.get(i, j, n) * theta.get(j, n);
            }
            theta.set(i, n, value / self.get(i, i, n));
        }
        for j in 0..p {
            theta.set(j, n, theta.get(j, n) * column_scale.get(j, n));
        }
        let (last_row_norm2, last_row) =
            self.last_row(n, &column_scale, &row_weight, &row_scale, &origin);
        Ok(Solved {
            theta,
            last_row_norm2,
            last_row,
        })
    }

    /// Scale each row (and its right-hand side) to a largest entry of one, and return the
    /// scales `S_r`; refuse a matrix or right-hand side that is not finite, or a zero row.
    fn scale_rows(
        &mut self,
        n: usize,
        rows: &mut RowSide<T, N>,
    ) -> Result<Column<T, N>, SolveError> {
        let RowSide {
            rhs, row_weight, ..
        } = rows;
        let p = n + 1;
        let mut row_scale = Column::<T, N>::zero();
        for i in 0..p {
            let mut largest = T::ZERO;
            for j in 0..p {
                let v = self.get(i, j, n);
                if !v.is_finite() {
                    return Err(SolveError::NonFinite);
                }
                largest = max_abs(largest, v);
            }
            if !rhs.get(i, n).is_finite() {
                return Err(SolveError::NonFinite);
            }
            if !(largest > T::ZERO) {
                return Err(SolveError::Singular);
            }
            let scale = T::ONE / largest;
            for j in 0..p {
                self.set(i, j, n, self.get(i, j, n) * scale);
            }
            rhs.set(i, n, rhs.get(i, n) * scale);
            // M⁻¹ = (row-scaled)⁻¹·S_r, so row i of the scaled problem carries weight ω_i·s_i².
            row_weight.set(i, n, row_weight.get(i, n) * scale * scale);
            row_scale.set(i, n, scale);
        }
        Ok(row_scale)
    }

    /// Scale each column to a largest entry of one; the scales `S_c`, or `Singular` for a
    /// zero column.
    fn scale_columns(&mut self, n: usize) -> Result<Column<T, N>, SolveError> {
        let p = n + 1;
        let mut column_scale = Column::<T, N>::zero();
        for j in 0..p {
            let mut largest = T::ZERO;
            for i in 0..p {
                largest = max_abs(largest, self.get(i, j, n));
            }
            if !(largest > T::ZERO) {
                return Err(SolveError::Singular);
            }
            let scale = T::ONE / largest;
            column_scale.set(j, n, scale);
            for i in 0..p {
                self.set(i, j, n, self.get(i, j, n) * scale);
            }
        }
        Ok(column_scale)
    }

    /// `P M = L U` in place (L strictly below the diagonal, unit diagonal implied), applying
    /// L⁻¹ P to `rhs` and P to the row weights and origins.
    fn factor_lu(&mut self, n: usize, rows: &mut RowSide<T, N>) -> Result<(), SolveError> {
        let RowSide {
            rhs,
            row_weight,
            origin,
        } = rows;
        let p = n + 1;
        // Every entry is now at most one in magnitude; a pivot at the rounding level of the
        // elimination (ε·(n+1)) means the matrix is numerically singular.
        let singular = T::EPSILON * T::from_u32(p as u32);
        for k in 0..p {
            let mut pivot_row = k;
            let mut pivot = self.get(k, k, n).abs();
            for i in (k + 1)..p {
                let v = self.get(i, k, n).abs();
                if v > pivot {
                    pivot = v;
                    pivot_row = i;
                }
            }
            if !(pivot > singular) {
                return Err(SolveError::Singular);
            }
            if pivot_row != k {
                self.swap_rows(k, pivot_row, n);
                rhs.swap(k, pivot_row, n);
                row_weight.swap(k, pivot_row, n);
                origin.swap(k, pivot_row, n);
            }
            let inv_pivot = T::ONE / self.get(k, k, n);
            for i in (k + 1)..p {
                let factor = self.get(i, k, n) * inv_pivot;
                // Store L below the diagonal.
                self.set(i, k, n, factor);
                for j in (k + 1)..p {
                    let v = self.get(i, j, n) - factor * self.get(k, j, n);
                    self.set(i, j, n, v);
                }
                rhs.set(i, n, rhs.get(i, n) - factor * rhs.get(k, n));
            }
        }
        Ok(())
    }

    /// `Σ ω_i g_i²` for `g = M⁻ᵀ e_last`, from the LU factors: with P M = L U,
    /// Uᵀ w = S_c e_last, Lᵀ v = w, and g = S_r Pᵀ v; the row weights were permuted with the
    /// rows, so Σ ω_i g_i² = Σ ω'_k v_k². Returns the sum and `g`.
    fn last_row(
        &self,
        n: usize,
        column_scale: &Column<T, N>,
        row_weight: &Column<T, N>,
        row_scale: &Column<T, N>,
        origin: &Column<usize, N>,
    ) -> (T, Column<T, N>) {
        let p = n + 1;
        let mut w = Column::<T, N>::zero();
        for i in 0..p {
            let mut value = if i == n {
                column_scale.get(n, n)
            } else {
                T::ZERO
            };
            for j in 0..i {
                value -= self.get(j, i, n) * w.get(j, n);
            }
            w.set(i, n, value / self.get(i, i, n));
        }
        let mut last_row_norm2 = T::ZERO;
        for i in (0..p).rev() {
            let mut value = w.get(i, n);
            for j in (i + 1)..p {
                value -= self.get(j, i, n) * w.get(j, n);
            }
            w.set(i, n, value);
            last_row_norm2 += row_weight.get(i, n) * value * value;
        }
        let mut last_row = Column::<T, N>::zero();
        for k in 0..p {
            let row = origin.get(k, n);
            last_row.set(row, n, row_scale.get(row, n) * w.get(k, n));
        }
        (last_row_norm2, last_row)
    }
}

/// What moves with the rows of `M` in the solve: the right-hand side, the row weights, and
/// each row's index before pivoting.
struct RowSide<T, const N: usize> {
    rhs: Column<T, N>,
    row_weight: Column<T, N>,
    origin: Column<usize, N>,
}

#[inline(always)]
fn max_abs<T: Real>(current: T, value: T) -> T {
    let a = value.abs();
    if a > current {
        a
    } else {
        current
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `last_row` is the last row of `M⁻¹` (`Mᵀ·g = e_last`) whatever the pivoting and the
    /// scaling, and `last_row_norm2` its weighted squared norm.
    #[test]
    fn the_last_row_is_that_of_the_inverse() {
        // Rows of very different scales, and a first column that makes pivoting swap.
        let matrix = Square {
            lead: [[1e-3, 2.0, 0.5], [3.0, -1.0, 0.25], [0.5, 4.0, -2.0]],
            right: [1.0, 1e3, -0.5],
            bottom: [2.0, 0.125, 7.0],
            corner: 0.75,
        };
        let n = 3;
        let weight = Column {
            lead: [1.0, 2.0, 0.5],
            last: 4.0,
        };
        let solved = matrix.solve(n, Column::zero(), weight).unwrap();
        let g = solved.last_row;
        let mut norm2 = 0.0;
        for j in 0..=n {
            let mut value = 0.0;
            for i in 0..=n {
                value += matrix.get(i, j, n) * g.get(i, n);
            }
            let expected = if j == n { 1.0 } else { 0.0 };
            assert!((value - expected).abs() < 1e-12, "column {j}: {value}");
            norm2 += weight.get(j, n) * g.get(j, n) * g.get(j, n);
        }
        assert!((solved.last_row_norm2 / norm2 - 1.0).abs() < 1e-12);
    }
}
