//! The recursive least-squares engine shared by the data-driven estimators.
//!
//! It keeps the square-root information factor `R = D^{1/2}·U` of a weighted regression
//! (unit upper-triangular `U`, diagonal `D`) and the transformed right-hand side, and folds
//! each new row in with Gentleman's square-root-free Givens rotations (Gentleman 1973;
//! Miller, AS 274). The columns are split into `N` *leading* columns (the Hankel columns,
//! of which the first `n ≤ N` are active) and `E` *trailing* columns (the input model: `[1]`
//! for a step, `[t, 1]` for a ramp). The trailing unknowns are the ones read out, and they
//! come last, so reading them needs a back substitution over `E` entries only.
//!
//! Why this form: it is a QR factorisation, backward stable in `f32`; starting from `D = 0`
//! it needs no prior and gives the exact least-squares solution as soon as the rows
//! determine it; there are no square roots; forgetting scales only the diagonal `D`; and the
//! row left after the rotations is the a-priori residual.

use crate::numerics::real::Real;

/// The factor of a regression with `N` leading and `E` trailing columns.
#[derive(Clone, Debug)]
pub(crate) struct Factor<T: Real, const N: usize, const E: usize> {
    /// Strict upper triangle of `U` among the leading columns.
    lead_coupling: [[T; N]; N],
    /// Block of `U` coupling each leading column to the trailing ones.
    cross_coupling: [[T; E]; N],
    /// Strict upper triangle of `U` among the trailing columns.
    tail_coupling: [[T; E]; E],
    lead_weight: [T; N],
    /// `D` of the trailing columns: the squared norm of the part of each trailing column
    /// orthogonal to all columns before it.
    tail_weight: [T; E],
    lead_rhs: [T; N],
    tail_rhs: [T; E],
}

/// What folding one row leaves behind.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Folded<T> {
    /// The a-priori residual of the row (meaningful once the problem was determined).
    pub residual: T,
    /// The product of the rotations' cosines: zero while the row only fills the factor.
    pub row_weight: T,
}

impl<T: Real, const N: usize, const E: usize> Factor<T, N, E> {
    pub(crate) fn new() -> Self {
        Self::EMPTY
    }

    /// The factor of no rows, as a constant (a `static` estimator's starting value).
    pub(crate) const EMPTY: Self = Self {
        lead_coupling: [[T::ZERO; N]; N],
        cross_coupling: [[T::ZERO; E]; N],
        tail_coupling: [[T::ZERO; E]; E],
        lead_weight: [T::ZERO; N],
        tail_weight: [T::ZERO; E],
        lead_rhs: [T::ZERO; N],
        tail_rhs: [T::ZERO; E],
    };

    /// Exponential forgetting: every earlier row's weight is multiplied by λ.
    pub(crate) fn forget(&mut self, active: usize, lambda: T) {
        for d in self.lead_weight[..active].iter_mut() {
            *d *= lambda;
        }
        for d in self.tail_weight.iter_mut() {
            *d *= lambda;
        }
    }

    /// Fold the row `[lead[..active], tail] θ = target` into the factor.
    #[inline]
    pub(crate) fn fold(
        &mut self,
        active: usize,
        lead: [T; N],
        tail: [T; E],
        target: T,
    ) -> Folded<T> {
        self.fold_weighted(active, lead, tail, target, T::ONE)
    }

    /// Fold a row with weight `weight`. A negative weight *removes* the row's contribution
    /// from the information matrix (a hyperbolic downdate): the bias-compensated estimator
    /// uses it to subtract the expected noise contribution. A downdate that would make the
    /// matrix indefinite leaves a weight ≤ 0, which the caller must check.
    #[inline(always)]
    pub(crate) fn fold_weighted(
        &mut self,
        active: usize,
        mut lead: [T; N],
        mut tail: [T; E],
        mut target: T,
        weight: T,
    ) -> Folded<T> {
        let mut row_weight = weight;
        for i in 0..active {
            let xi = lead[i];
            if xi == T::ZERO {
                continue;
            }
            let (cbar, sbar) = rotation(&mut self.lead_weight[i], &mut row_weight, xi);
            let coupling = &mut self.lead_coupling[i];
            for j in (i + 1)..active {
                apply(&mut lead[j], &mut coupling[j], xi, cbar, sbar);
            }
            let cross = &mut self.cross_coupling[i];
            for e in 0..E {
                apply(&mut tail[e], &mut cross[e], xi, cbar, sbar);
            }
            apply(&mut target, &mut self.lead_rhs[i], xi, cbar, sbar);
            if row_weight == T::ZERO {
                // Column i had no weight yet: the whole row now defines it.
                return Folded {
                    residual: target,
                    row_weight,
                };
            }
        }
        for e in 0..E {
            let xe = tail[e];
            if xe == T::ZERO {
                continue;
            }
            let (cbar, sbar) = rotation(&mut self.tail_weight[e], &mut row_weight, xe);
            let coupling = &mut self.tail_coupling[e];
            for f in (e + 1)..E {
                apply(&mut tail[f], &mut coupling[f], xe, cbar, sbar);
            }
            apply(&mut target, &mut self.tail_rhs[e], xe, cbar, sbar);
            if row_weight == T::ZERO {
                break;
            }
        }
        Folded {
            residual: target,
            row_weight,
        }
    }

    /// Move the origin of every target folded so far by `delta` along trailing column `e`:
    /// afterwards the factor is that of the targets `x − delta·t_e` (`t_e` the column's
    /// entries), whose solution differs only in trailing unknown `e`, by `−delta`. The
    /// right-hand side is `U·θ`, so it moves by `−delta` times column `e` of `U`.
    ///
    /// Why: a step level of 138 g is stored in `f32` to 1.5e-5 g, and a recursion that adds
    /// updates of `1/N_eff` of a deviation to it stalls once they fall below half that (a
    /// dead band of ±0.08 g at `N_eff` = 10⁴). Kept near zero, the same value carries the
    /// deviation to ~1e-7 of itself.
    pub(crate) fn shift_target(&mut self, active: usize, e: usize, delta: T) {
        for i in 0..active {
            self.lead_rhs[i] -= delta * self.cross_coupling[i][e];
        }
        for f in 0..e {
            self.tail_rhs[f] -= delta * self.tail_coupling[f][e];
        }
        self.tail_rhs[e] -= delta;
    }

    /// The least-squares values of the trailing unknowns (back substitution over `E`).
    pub(crate) fn tail_solution(&self) -> [T; E] {
        let mut theta = [T::ZERO; E];
        for e in (0..E).rev() {
            let mut value = self.tail_rhs[e];
            for f in (e + 1)..E {
                value -= self.tail_coupling[e][f] * theta[f];
            }
            theta[e] = value;
        }
        theta
    }

    /// `D` of the trailing columns.
    pub(crate) fn tail_weight(&self) -> [T; E] {
        self.tail_weight
    }

    /// `D` of the leading columns (the first `active` entries are meaningful).
    pub(crate) fn lead_weight(&self) -> [T; N] {
        self.lead_weight
    }

    /// The last trailing unknown's row of `P = (ΦᵀWΦ)⁻¹`, leading entries then trailing:
    /// the weights `z` with which the rows' equation errors reach that unknown
    /// (`δθ_last = zᵀ·Φᵀ·W·ε`). `P = U⁻¹·D⁻¹·U⁻ᵀ`, and `U⁻ᵀ` leaves the last unit vector
    /// as it is (`U` is unit upper triangular), so `z = U⁻¹·e_last / D_last`: one back
    /// substitution, O((n+E)²). `None` while the last column has no weight.
    pub(crate) fn last_unknown_influence(&self, active: usize) -> Option<([T; N], [T; E])> {
        let d = self.tail_weight[E - 1];
        if !(d > T::ZERO) {
            return None;
        }
        let mut tail = [T::ZERO; E];
        tail[E - 1] = T::ONE / d;
        Some(self.back_substitute(active, [T::ZERO; N], tail))
    }

    /// `P·v` for `v` zero on the leading columns and `combination` on the trailing ones
    /// (`P = (ΦᵀWΦ)⁻¹ = U⁻¹·D⁻¹·U⁻ᵀ`): the weights with which the rows' equation errors reach
    /// `combinationᵀ·θ_tail`. `U⁻ᵀ·v` stays on the trailing columns (`U` is unit upper
    /// triangular), so one forward and one back substitution, O((n+E)²). `None` while a
    /// trailing column has no weight.
    pub(crate) fn tail_influence(
        &self,
        active: usize,
        combination: [T; E],
    ) -> Option<([T; N], [T; E])> {
        let tail = self.tail_forward(combination)?;
        Some(self.back_substitute(active, [T::ZERO; N], tail))
    }

    /// `D_tail⁻¹·U_tail⁻ᵀ·combination`: the trailing part of the forward substitution and
    /// its weights, for a right-hand side from which the leading columns' part is already
    /// taken (nothing, for [`Self::tail_influence`]). `None` while a trailing column has no
    /// weight.
    fn tail_forward(&self, combination: [T; E]) -> Option<[T; E]> {
        let mut tail = [T::ZERO; E];
        for e in 0..E {
            let mut value = combination[e];
            for f in 0..e {
                value -= self.tail_coupling[f][e] * tail[f];
            }
            tail[e] = value;
        }
        for (value, &d) in tail.iter_mut().zip(&self.tail_weight) {
            if !(d > T::ZERO) {
                return None;
            }
            *value = *value / d;
        }
        Some(tail)
    }

    /// `P·v` for any `v` (`lead[..active]` then `tail`; `P = U⁻¹·D⁻¹·U⁻ᵀ`): one forward and
    /// one back substitution, O((n+E)²). `None` while a column has no weight.
    pub(crate) fn influence(
        &self,
        active: usize,
        lead: [T; N],
        tail: [T; E],
    ) -> Option<([T; N], [T; E])> {
        // `U⁻ᵀ·v`: `Uᵀ` is unit lower triangular.
        let mut x = [T::ZERO; N];
        for i in 0..active {
            let mut value = lead[i];
            for j in 0..i {
                value -= self.lead_coupling[j][i] * x[j];
            }
            x[i] = value;
        }
        let mut shifted = tail;
        for (e, value) in shifted.iter_mut().enumerate() {
            for i in 0..active {
                *value -= self.cross_coupling[i][e] * x[i];
            }
        }
        let y = self.tail_forward(shifted)?;
        // `D⁻¹` on the leading columns (the trailing ones had theirs).
        for (value, &d) in x[..active].iter_mut().zip(&self.lead_weight) {
            if !(d > T::ZERO) {
                return None;
            }
            *value = *value / d;
        }
        // `U⁻¹`: the back substitution, the leading entries now not zero.
        Some(self.back_substitute(active, x, y))
    }

    /// `U⁻¹·v` for `v` `rhs` on the leading columns (zero for the influences of trailing
    /// combinations) and `tail` on the trailing ones: the back substitution of the
    /// influences above. The last trailing entry has nothing after it and stays as it is.
    #[inline]
    fn back_substitute(&self, active: usize, rhs: [T; N], mut tail: [T; E]) -> ([T; N], [T; E]) {
        for e in (0..E - 1).rev() {
            let mut value = tail[e];
            for f in (e + 1)..E {
                value -= self.tail_coupling[e][f] * tail[f];
            }
            tail[e] = value;
        }
        let mut lead = [T::ZERO; N];
        for i in (0..active).rev() {
            let mut value = rhs[i];
            for j in (i + 1)..active {
                value -= self.lead_coupling[i][j] * lead[j];
            }
            for e in 0..E {
                value -= self.cross_coupling[i][e] * tail[e];
            }
            lead[i] = value;
        }
        (lead, tail)
    }

    /// `‖D^{1/2}·U·δ‖²`: how much the weighted residual sum of squares grows when the
    /// unknowns move by `δ` (leading `lead[..active]`, then trailing) away from the
    /// least-squares solution, since that sum is `‖D^{1/2}·(U·θ − rhs)‖²` plus the part no θ
    /// explains. O((n+E)²).
    pub(crate) fn weighted_norm2(&self, active: usize, lead: &[T; N], tail: &[T; E]) -> T {
        let mut sum = T::ZERO;
        for i in 0..active {
            let mut value = lead[i];
            for j in (i + 1)..active {
                value += self.lead_coupling[i][j] * lead[j];
            }
            for e in 0..E {
                value += self.cross_coupling[i][e] * tail[e];
            }
            sum += self.lead_weight[i] * value * value;
        }
        for e in 0..E {
            let mut value = tail[e];
            for f in (e + 1)..E {
                value += self.tail_coupling[e][f] * tail[f];
            }
            sum += self.tail_weight[e] * value * value;
        }
        sum
    }

    /// All unknowns, leading then trailing (full back substitution, O((n+E)²)).
    pub(crate) fn solution(&self, active: usize) -> ([T; N], [T; E]) {
        let tail = self.tail_solution();
        let mut lead = [T::ZERO; N];
        for i in (0..active).rev() {
            let mut value = self.lead_rhs[i];
            for j in (i + 1)..active {
                value -= self.lead_coupling[i][j] * lead[j];
            }
            for e in 0..E {
                value -= self.cross_coupling[i][e] * tail[e];
            }
            lead[i] = value;
        }
        (lead, tail)
    }
}

impl<T: Real, const N: usize> Factor<T, N, 1> {
    /// Whether every column has weight: then a row's zero entry rotates nothing, and
    /// [`Self::fold_weighted_all`] folds it as [`Self::fold`] does. Weights never shrink
    /// without forgetting, so once true it stays true.
    pub(crate) fn all_weighted(&self) -> bool {
        self.lead_weight.iter().all(|&d| d > T::ZERO) && self.tail_weight[0] > T::ZERO
    }

    /// [`Self::fold`] of a row with every leading column active into a factor whose
    /// columns all have weight ([`Self::all_weighted`]): the same rotations in the same
    /// order without the checks a factor still filling needs (a zero entry, a row that
    /// defines a column), so the compiler unrolls it for `N`. A model bank folds one row
    /// per candidate per block, and the checks and the run-time column count cost it half
    /// its time. The result differs from [`Self::fold`]'s at most in the sign of a zero
    /// (a zero entry rotates by `c̄ = 1, s̄ = 0`).
    #[inline(always)]
    pub(crate) fn fold_weighted_all(&mut self, lead: [T; N], tail: T, target: T) -> Folded<T> {
        self.fold_from(0, lead, tail, target, T::ONE)
    }

    /// The rotations of [`Self::fold_weighted_all`] from leading column `from` on, and the
    /// trailing column's: the row's entries before `from` have been folded already (into
    /// this factor, or into a common copy of its first columns), leaving the row's weight
    /// `row_weight`, its target `target` and the rest of its entries as given.
    #[inline(always)]
    fn fold_from(
        &mut self,
        from: usize,
        mut lead: [T; N],
        mut tail: T,
        mut target: T,
        mut row_weight: T,
    ) -> Folded<T> {
        for i in from..N {
            let xi = lead[i];
            let (cbar, sbar) = rotation(&mut self.lead_weight[i], &mut row_weight, xi);
            for j in (i + 1)..N {
                apply(&mut lead[j], &mut self.lead_coupling[i][j], xi, cbar, sbar);
            }
            apply(&mut tail, &mut self.cross_coupling[i][0], xi, cbar, sbar);
            apply(&mut target, &mut self.lead_rhs[i], xi, cbar, sbar);
        }
        let (cbar, sbar) = rotation(&mut self.tail_weight[0], &mut row_weight, tail);
        apply(&mut target, &mut self.tail_rhs[0], tail, cbar, sbar);
        Folded {
            residual: target,
            row_weight,
        }
    }
}

/// The rotations with which a row's first `shared` leading entries were folded into the
/// leading columns of a factor that several regressions have in common (their rows agree
/// there and their factors' leading columns are the same): what each of those regressions
/// needs to fold the rest of the row ([`Factor::fold_after_shared`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SharedRotations<T, const N: usize> {
    /// Each shared column's row entry as the column met it, and its rotation's c̄ and s̄
    /// (the first `shared` entries are meaningful).
    entry: [T; N],
    cbar: [T; N],
    sbar: [T; N],
    /// The row's weight and target after the shared columns.
    row_weight: T,
    target: T,
}

impl<T: Real, const N: usize> SharedRotations<T, N> {
    /// No rotations yet (a placeholder until the first shared fold).
    pub(crate) fn new() -> Self {
        Self {
            entry: [T::ZERO; N],
            cbar: [T::ZERO; N],
            sbar: [T::ZERO; N],
            row_weight: T::ONE,
            target: T::ZERO,
        }
    }
}

impl<T: Real, const N: usize> Factor<T, N, 1> {
    /// The first half of [`Self::fold_weighted_all`], for regressions whose rows agree in
    /// their first `shared` leading entries and whose factors agree in those columns: fold
    /// the row's shared entries into this factor's shared columns (the common copy), once
    /// for all of them. Only this factor's shared columns change: their weights, their
    /// couplings among themselves and their right-hand side.
    #[inline(always)]
    pub(crate) fn fold_shared(
        &mut self,
        shared: usize,
        mut lead: [T; N],
        target: T,
    ) -> SharedRotations<T, N> {
        let mut rotations = SharedRotations::new();
        rotations.target = target;
        for i in 0..shared {
            let xi = lead[i];
            let (cbar, sbar) = rotation(&mut self.lead_weight[i], &mut rotations.row_weight, xi);
            for j in (i + 1)..shared {
                apply(&mut lead[j], &mut self.lead_coupling[i][j], xi, cbar, sbar);
            }
            apply(&mut rotations.target, &mut self.lead_rhs[i], xi, cbar, sbar);
            rotations.entry[i] = xi;
            rotations.cbar[i] = cbar;
            rotations.sbar[i] = sbar;
        }
        rotations
    }

    /// The second half: fold the rest of the row (leading entries `shared..N` and the
    /// trailing one) into this regression's own columns, after the shared columns'
    /// `rotations`. With [`Self::fold_shared`] on the common copy it does what
    /// [`Self::fold_weighted_all`] does here, the same operations on the same values (a
    /// test compares them bit for bit); this factor's own copy of the shared columns is
    /// left as it was (the common copy holds them).
    #[inline(always)]
    pub(crate) fn fold_after_shared(
        &mut self,
        shared: usize,
        rotations: &SharedRotations<T, N>,
        mut lead: [T; N],
        tail: T,
    ) -> Folded<T> {
        let mut tail = tail;
        for i in 0..shared {
            let (xi, cbar, sbar) = (rotations.entry[i], rotations.cbar[i], rotations.sbar[i]);
            for j in shared..N {
                apply(&mut lead[j], &mut self.lead_coupling[i][j], xi, cbar, sbar);
            }
            apply(&mut tail, &mut self.cross_coupling[i][0], xi, cbar, sbar);
        }
        self.fold_from(shared, lead, tail, rotations.target, rotations.row_weight)
    }
}

/// Gentleman's rotation for a column with weight `d` meeting a row entry `x` of weight `w`:
/// updates both weights and returns the (c̄, s̄) that transform the rest of the row.
#[inline(always)]
pub(crate) fn rotation<T: Real>(d: &mut T, w: &mut T, x: T) -> (T, T) {
    let wx = *w * x;
    let new_d = *d + wx * x;
    let cbar = *d / new_d;
    let sbar = wx / new_d;
    *w *= cbar;
    *d = new_d;
    (cbar, sbar)
}

/// Eliminate `x` from one further entry of the row and update the factor entry.
#[inline(always)]
pub(crate) fn apply<T: Real>(row_entry: &mut T, factor_entry: &mut T, x: T, cbar: T, sbar: T) {
    let old = *row_entry;
    *row_entry = old - x * *factor_entry;
    *factor_entry = cbar * *factor_entry + sbar * old;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a regression on five columns and a trailing one, with entries that fill
    /// the factor, decay, and now and then are exactly zero (xorshift, deterministic).
    fn rows<T: Real>(count: usize) -> impl Iterator<Item = ([T; 5], T, T)> {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..count).map(move |k| {
            let decay = libm::pow(0.97, k as f64);
            let mut lead = [T::ZERO; 5];
            for (i, v) in lead.iter_mut().enumerate() {
                // Every seventh row leaves a column out.
                if (k + i) % 7 != 0 {
                    *v = T::from_f64(next() * decay * 1e3);
                }
            }
            let tail = T::from_f64(1.0 - decay + 0.1 * next());
            (lead, tail, T::from_f64(1e4 + next() * 30.0))
        })
    }

    /// Once every column has weight, the unrolled fold gives the general fold's factor and
    /// residuals to the last bit (zero entries included), in both precisions.
    #[test]
    fn the_fold_for_a_weighted_factor_is_the_general_fold() {
        fn compare<T: Real + core::fmt::Debug>() {
            let mut general = Factor::<T, 5, 1>::new();
            let mut fast = Factor::<T, 5, 1>::new();
            let mut fast_rows = 0;
            for (k, (lead, tail, target)) in rows::<T>(2000).enumerate() {
                let expected = general.fold(5, lead, [tail], target);
                let folded = if fast.all_weighted() {
                    fast_rows += 1;
                    fast.fold_weighted_all(lead, tail, target)
                } else {
                    fast.fold(5, lead, [tail], target)
                };
                assert_eq!(folded.residual, expected.residual, "row {k}");
                assert_eq!(folded.row_weight, expected.row_weight, "row {k}");
                assert_eq!(fast.tail_solution(), general.tail_solution(), "row {k}");
                assert_eq!(fast.tail_weight(), general.tail_weight(), "row {k}");
            }
            assert!(fast_rows > 1900);
            assert_eq!(fast.solution(5), general.solution(5));
            assert_eq!(fast.lead_weight(), general.lead_weight());
        }
        compare::<f64>();
        compare::<f32>();
    }

    /// Regressions whose rows agree in their first three entries, folded with those
    /// columns' rotations done once on a common copy, get the factors and residuals of
    /// each folding its own rows, to the last bit, in both precisions.
    #[test]
    fn a_shared_fold_is_each_regressions_own_fold() {
        fn compare<T: Real + core::fmt::Debug>() {
            const SHARED: usize = 3;
            let mut own = [Factor::<T, 5, 1>::new(), Factor::new()];
            let mut split = own.clone();
            let mut common: Option<Factor<T, 5, 1>> = None;
            let mut shared_rows = 0;
            for (k, (lead, tail, target)) in rows::<T>(2000).enumerate() {
                // The second regression's own entries and step column differ.
                let other = |mut lead: [T; 5]| {
                    lead[3] = lead[3] * T::from_f64(0.9) + T::from_f64(0.5);
                    lead[4] *= T::from_f64(1.1);
                    lead
                };
                let leads = [lead, other(lead)];
                let tails = [tail, tail * T::from_f64(0.95)];
                let expected: [Folded<T>; 2] = core::array::from_fn(|r| {
                    if own[r].all_weighted() {
                        own[r].fold_weighted_all(leads[r], tails[r], target)
                    } else {
                        own[r].fold(5, leads[r], [tails[r]], target)
                    }
                });
                if common.is_none() && split.iter().all(Factor::all_weighted) {
                    common = Some(split[0].clone());
                }
                let folded: [Folded<T>; 2] = if let Some(common) = common.as_mut() {
                    shared_rows += 1;
                    let rotations = common.fold_shared(SHARED, lead, target);
                    core::array::from_fn(|r| {
                        split[r].fold_after_shared(SHARED, &rotations, leads[r], tails[r])
                    })
                } else {
                    core::array::from_fn(|r| split[r].fold(5, leads[r], [tails[r]], target))
                };
                for r in 0..2 {
                    assert_eq!(folded[r].residual, expected[r].residual, "row {k}");
                    assert_eq!(folded[r].row_weight, expected[r].row_weight, "row {k}");
                    assert_eq!(split[r].tail_solution(), own[r].tail_solution(), "row {k}");
                    assert_eq!(split[r].tail_weight(), own[r].tail_weight(), "row {k}");
                }
            }
            assert!(shared_rows > 1900);
            let common = common.unwrap();
            for r in 0..2 {
                // The shared columns live in the common copy, the rest in each factor.
                assert_eq!(
                    common.lead_weight()[..SHARED],
                    own[r].lead_weight()[..SHARED]
                );
                assert_eq!(
                    split[r].lead_weight()[SHARED..],
                    own[r].lead_weight()[SHARED..]
                );
            }
        }
        compare::<f64>();
        compare::<f32>();
    }

    #[test]
    fn a_tail_combinations_influence_is_p_times_the_combination() {
        // Rows [lead, t, 1]: P·[0 … 0, τ, 1] is τ times P's t row plus its constant row, and
        // P's constant row is `last_unknown_influence`. P's t row comes from the same
        // factor with the columns [1, t] swapped (P is symmetric, and its t row there is the
        // last one).
        let mut factor = Factor::<f64, 5, 2>::new();
        let mut swapped = Factor::<f64, 5, 2>::new();
        for (k, (lead, tail, target)) in rows::<f64>(40).enumerate() {
            let t = k as f64 * 0.1 + tail;
            factor.fold(5, lead, [t, 1.0], target);
            swapped.fold(5, lead, [1.0, t], target);
        }
        let tau = 2.5;
        let (lead, tail) = factor.tail_influence(5, [tau, 1.0]).unwrap();
        let (constant_lead, constant_tail) = factor.last_unknown_influence(5).unwrap();
        let (t_lead, t_tail) = swapped.last_unknown_influence(5).unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
        for i in 0..5 {
            let expected = tau * t_lead[i] + constant_lead[i];
            assert!(close(lead[i], expected), "{i}: {} vs {expected}", lead[i]);
        }
        assert!(close(tail[0], tau * t_tail[1] + constant_tail[0]));
        assert!(close(tail[1], tau * t_tail[0] + constant_tail[1]));
    }

    /// `influence` is `P·v` for any `v`: `ΦᵀΦ` (summed from the same rows) times it gives
    /// `v` back, for a `v` on every column; with `v` the last unit vector it is
    /// `last_unknown_influence`.
    #[test]
    fn the_influence_of_any_combination_is_p_times_it() {
        let mut factor = Factor::<f64, 5, 1>::new();
        let mut gram = [[0.0; 6]; 6];
        for (lead, tail, target) in rows::<f64>(40) {
            factor.fold(5, lead, [tail], target);
            let row: [f64; 6] = core::array::from_fn(|i| if i < 5 { lead[i] } else { tail });
            for (i, gram_row) in gram.iter_mut().enumerate() {
                for (j, value) in gram_row.iter_mut().enumerate() {
                    *value += row[i] * row[j];
                }
            }
        }
        let v = [0.3, -1.2, 2.0, 0.7, -0.4, 1.5];
        let (lead, [tail]) = factor
            .influence(5, core::array::from_fn(|i| v[i]), [v[5]])
            .unwrap();
        let w: [f64; 6] = core::array::from_fn(|i| if i < 5 { lead[i] } else { tail });
        for (i, gram_row) in gram.iter().enumerate() {
            let back: f64 = gram_row.iter().zip(&w).map(|(g, w)| g * w).sum();
            assert!(
                (back - v[i]).abs() <= 1e-8 * (1.0 + v[i].abs()),
                "{i}: {back} vs {}",
                v[i]
            );
        }
        let (lead, tail) = factor.influence(5, [0.0; 5], [1.0]).unwrap();
        assert_eq!((lead, tail), factor.last_unknown_influence(5).unwrap());
    }

    #[test]
    fn a_factor_is_weighted_once_every_column_has_a_row() {
        let mut factor = Factor::<f64, 2, 1>::new();
        assert!(!factor.all_weighted());
        factor.fold(2, [1.0, 0.0], [0.0], 1.0);
        factor.fold(2, [0.0, 1.0], [0.0], 1.0);
        assert!(!factor.all_weighted());
        factor.fold(2, [0.0, 0.0], [1.0], 1.0);
        assert!(factor.all_weighted());
    }
}
