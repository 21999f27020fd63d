//! The instrumental-variable (IV) form of the data-driven step estimator (thesis §4.1.4,
//! eq. 4.23–4.26).
//!
//! The least-squares estimator ([`crate::StepEstimator`]) regresses `x(k) = y(k)/G` on the
//! row `φ(k) = [Δx(k−n) … Δx(k−1), 1]`: the regressor is built from the same noisy samples as
//! the target, so its noise biases the estimate (an errors-in-variables problem). IV replaces
//! the normal equations `Kᵀ K θ = Kᵀ x` by `Zᵀ K θ = Zᵀ x`, with instruments `z(k)`
//! correlated with `φ(k)` through the signal but not through the noise.
//!
//! ## The instruments and their delay
//! `z(k) = φ(k − d) = [Δx(k−n−d) … Δx(k−1−d), 1]`: the regressor `d` rows earlier. With
//! white noise `e` on the samples, `Δx(j)` carries `e(j)` and `e(j+1)`, so the row
//! `(φ(k), x(k))` carries `e(k−n) … e(k)` and `z(k)` carries `e(k−n−d) … e(k−d)`. They share
//! no noise sample when `k − d < k − n`, i.e. **`d ≥ n + 1`**; that is the default
//! ([`IvConfig::new`]) and the smallest delay accepted. The thesis's instrument matrix
//! (eq. 4.25) is delayed by about `2n` rows (first estimate after `4n + 1` samples);
//! [`IvConfig::with_instrument_delay`] sets any delay up to [`max_instrument_delay`]. A longer
//! delay also tolerates noise correlated over `d − n − 1` samples, at the price of a weaker
//! instrument (the signal decorrelates) and a later first estimate. With decimation the rows
//! are block means, whose noise stays white, so the same rule holds at the decimated rate.
//!
//! ## The recursive solution
//! Forming `Zᵀ K` squares the conditioning of the fast-sampled Hankel data. Instead, the
//! instrument rows are folded into a QR factorisation `Z = Q R` with Gentleman's
//! square-root-free Givens rotations (the engine of `factor.rs`), and the same rotations are
//! applied to the row of `[K x]`, which keeps `M = Qᵀ K` and `Qᵀ x` (scaled). Since `R` is
//! square and invertible, `Zᵀ K θ = Zᵀ x ⇔ Rᵀ Qᵀ K θ = Rᵀ Qᵀ x ⇔ M θ = Qᵀ x`: an
//! `(n+1) × (n+1)` system whose condition number is that of `K` over the cosines of the
//! angles between the instrument and regressor spaces, not their product. It is solved when
//! a reading is due (every decimated sample) by LU with partial pivoting after row and column
//! equilibration.
//!
//! Cost per decimated sample, `p = n + 1`: the fold ≈ `1.5·n²` Givens applications (each
//! 2 multiplies, 2 adds; ≈ 75 at n = 7, about twice the least-squares fold), then the solve
//! ≈ `p³/3 + 4p²` multiply–adds (≈ 430 at n = 7). Roughly 5× the cost of `StepEstimator`.
//! Memory: printed by `tests/eiv_bad_input.rs`.
//!
//! ## Identifiability and flags
//! With white equation error the IV estimate's covariance is `σ²·M⁻¹M⁻ᵀ`, so the noise gain
//! into `u` is the norm of the last row of `M⁻¹`. [`IvStepEstimator::identifiability`] is
//! `1 / (rows·‖e_uᵀ M⁻¹‖²)`, in (0, 1]; for least squares (`Z = K`) it is exactly
//! `StepEstimator::identifiability`. A singular system or an identifiability at the rounding
//! level (≤ 100·ε, as in `StepEstimator`) gives `Invalid(IllConditioned)`, not latched; a
//! non-finite state latches `NonFiniteUpdate`; bad samples latch as in `StepEstimator`.
//!
//! ## The standard uncertainty
//! With lag sums for orders up to `L` (`IvStepEstimator<T, N, L>`, `L = 0` by default) each
//! reading states the level's `u` from the instrument rows' sandwich
//! (`crate::estimators::iv_uncertainty`), except with forgetting and where the instruments
//! are weak (the load cell), where the first-order `u` does not hold.
//!
//! ## Where it wins and where it loses
//! Pinned by `tests/eiv.rs`; the verdict is in [`crate::estimators::bias_compensated`]'s
//! docs. On the thesis's second-order scene IV removes the LS bias at the same variance
//! (thesis §4.2.4). On the 4 kHz load cell at D = 1 the delayed differences are weak, noisy
//! instruments: IV removes most of the LS bias, but without the identifiability floor a few
//! readings in a hundred are off by orders of magnitude; with the default floor a few
//! percent of readings are flagged and the rest beat LS, still far above the Cramér–Rao
//! bound. At D ≈ 12 LS has no bias left to remove and IV only adds variance. A delay of
//! `2n + 1` helps at D = 1 and hurts at D ≈ 12.

use crate::estimators::consistency::{
    difference_correlation, difference_noise_gain, NoiseReference, ResidualCheck,
};
use crate::estimators::input::row_residual;
use crate::estimators::intake::{estimator_via_intake, step_wrapper_accessors, Intake};
use crate::estimators::iv_uncertainty::{IvUncertainty, STRONG_INSTRUMENTS};
use crate::estimators::step::StepConfig;
use crate::estimators::step_uncertainty::stated;
use crate::numerics::factor::{apply, rotation};
use crate::numerics::real::Real;
use crate::numerics::square::{Column, SolveError, Solved, Square};
use crate::reading::{ConfigError, InvalidReason};

/// The ring of past differences holds `HISTORY_BLOCKS · N` values.
const HISTORY_BLOCKS: usize = 4;

/// The largest instrument delay (in decimated rows) an estimator of capacity `capacity`
/// accepts at order `order`: the difference history holds `4·capacity` values and a row needs
/// `order + delay` of them.
pub const fn max_instrument_delay(capacity: usize, order: usize) -> usize {
    HISTORY_BLOCKS * capacity - order
}

/// Configuration of an [`IvStepEstimator`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IvConfig<T> {
    /// Order, gain, forgetting, decimation and valid range, exactly as for `StepEstimator`.
    pub step: StepConfig<T>,
    /// Delay `d` of the instruments in decimated rows: `z(k) = φ(k − d)`. Must be at least
    /// `order + 1` (see the module docs) and at most [`max_instrument_delay`].
    pub instrument_delay: usize,
    /// Readings whose [`IvStepEstimator::identifiability`] is not above this floor are
    /// `Invalid(IllConditioned)`. The identifiability is the ratio of a least-squares fit's
    /// noise variance to the IV estimate's, so the default, [`DEFAULT_MIN_IDENTIFIABILITY`]
    /// = 0.1, flags readings whose noise gain exceeds least squares' by more than √10. The
    /// rounding-level floor `100·ε` of `StepEstimator` always applies as well.
    pub min_identifiability: T,
}

/// The default [`IvConfig::min_identifiability`]: flag weak-instrument readings whose noise
/// gain exceeds that of least squares on the same rows by more than √10 ≈ 3.2 (chosen from
/// the load-cell study in `tests/eiv.rs`, where the rare IV outliers of tens of grams all
/// have identifiability below 0.1, and the median reading has about 0.95).
pub const DEFAULT_MIN_IDENTIFIABILITY: f64 = 0.1;

impl<T: Real> IvConfig<T> {
    /// The given step configuration with the shortest safe delay, `order + 1`.
    pub fn new(step: StepConfig<T>) -> Self {
        Self {
            step,
            instrument_delay: step.order + 1,
            min_identifiability: T::from_f64(DEFAULT_MIN_IDENTIFIABILITY),
        }
    }

    /// Set the instrument delay in decimated rows.
    pub fn with_instrument_delay(mut self, rows: usize) -> Self {
        self.instrument_delay = rows;
        self
    }

    /// Set the identifiability floor (0 keeps only the rounding-level test).
    pub fn with_min_identifiability(mut self, floor: T) -> Self {
        self.min_identifiability = floor;
        self
    }

    /// Check against a capacity; a delay out of range, or a floor outside `[0, 1)`, is
    /// [`ConfigError::Model`].
    pub fn validate(&self, capacity: usize) -> Result<(), ConfigError> {
        self.step.validate(capacity)?;
        let order = self.step.order;
        if self.instrument_delay < order + 1
            || self.instrument_delay > max_instrument_delay(capacity, order)
        {
            return Err(ConfigError::Model);
        }
        // Written so that NaN fails too.
        if !(self.min_identifiability >= T::ZERO && self.min_identifiability < T::ONE) {
            return Err(ConfigError::Model);
        }
        Ok(())
    }
}

/// The last `4·N` first differences of the decimated sequence, newest at age 0.
#[derive(Clone, Debug)]
struct DifferenceHistory<T, const N: usize> {
    ring: [[T; N]; HISTORY_BLOCKS],
    /// Flat index of the newest difference.
    head: usize,
    previous: T,
    /// Values pushed so far (saturating); differences available = seen − 1.
    seen: u32,
}

impl<T: Real, const N: usize> DifferenceHistory<T, N> {
    fn new() -> Self {
        Self {
            ring: [[T::ZERO; N]; HISTORY_BLOCKS],
            head: 0,
            previous: T::ZERO,
            seen: 0,
        }
    }

    fn push(&mut self, x: T) {
        if self.seen > 0 {
            self.head = (self.head + 1) % (HISTORY_BLOCKS * N);
            self.ring[self.head / N][self.head % N] = x - self.previous;
        }
        self.previous = x;
        self.seen = self.seen.saturating_add(1);
    }

    fn differences(&self) -> usize {
        self.seen.saturating_sub(1) as usize
    }

    /// `Δx` pushed `age` differences ago (age < 4N).
    #[inline(always)]
    fn at(&self, age: usize) -> T {
        let len = HISTORY_BLOCKS * N;
        let index = (self.head + len - age) % len;
        self.ring[index / N][index % N]
    }

    /// The `n` differences from `age_of_newest + n − 1` (oldest) to `age_of_newest`.
    fn window(&self, n: usize, age_of_newest: usize) -> [T; N] {
        let mut window = [T::ZERO; N];
        for (i, slot) in window.iter_mut().enumerate().take(n) {
            *slot = self.at(age_of_newest + n - 1 - i);
        }
        window
    }
}

/// The square-root-free QR factor of the instrument matrix `Z` (leading: the `n` delayed
/// differences; trailing: the constant), with `Qᵀ [K x]` carried along, scaled by `D^{-1/2}`.
#[derive(Clone, Debug)]
struct InstrumentFactor<T, const N: usize> {
    /// Strict upper triangle of `U` among the difference instruments.
    lead_coupling: [[T; N]; N],
    /// `U` coupling each difference instrument to the constant instrument.
    constant_coupling: [T; N],
    lead_weight: [T; N],
    constant_weight: T,
    /// `D^{-1/2}·Qᵀ K` and `D^{-1/2}·Qᵀ x`, row by pivot.
    system: Square<T, N>,
    rhs: Column<T, N>,
}

impl<T: Real, const N: usize> InstrumentFactor<T, N> {
    fn new() -> Self {
        Self {
            lead_coupling: [[T::ZERO; N]; N],
            constant_coupling: [T::ZERO; N],
            lead_weight: [T::ZERO; N],
            constant_weight: T::ZERO,
            system: Square {
                lead: [[T::ZERO; N]; N],
                right: [T::ZERO; N],
                bottom: [T::ZERO; N],
                corner: T::ZERO,
            },
            rhs: Column::zero(),
        }
    }

    fn forget(&mut self, n: usize, lambda: T) {
        for d in self.lead_weight[..n].iter_mut() {
            *d *= lambda;
        }
        self.constant_weight *= lambda;
    }

    /// Fold the instrument row `[z, 1]` with its regression row `[φ, 1]` and target `x`.
    /// Returns the row weight left (zero while the row only fills the factor).
    fn fold(&mut self, n: usize, mut z: [T; N], mut phi: [T; N], mut x: T) -> T {
        let mut row_weight = T::ONE;
        let mut z_constant = T::ONE;
        let mut phi_constant = T::ONE;
        for i in 0..n {
            let zi = z[i];
            if zi == T::ZERO {
                continue;
            }
            let (cbar, sbar) = rotation(&mut self.lead_weight[i], &mut row_weight, zi);
            let coupling = &mut self.lead_coupling[i];
            for j in (i + 1)..n {
                apply(&mut z[j], &mut coupling[j], zi, cbar, sbar);
            }
            apply(
                &mut z_constant,
                &mut self.constant_coupling[i],
                zi,
                cbar,
                sbar,
            );
            let companion = &mut self.system.lead[i];
            for j in 0..n {
                apply(&mut phi[j], &mut companion[j], zi, cbar, sbar);
            }
            apply(&mut phi_constant, &mut self.system.right[i], zi, cbar, sbar);
            apply(&mut x, &mut self.rhs.lead[i], zi, cbar, sbar);
            if row_weight == T::ZERO {
                return row_weight;
            }
        }
        if z_constant != T::ZERO {
            let (cbar, sbar) = rotation(&mut self.constant_weight, &mut row_weight, z_constant);
            for j in 0..n {
                apply(
                    &mut phi[j],
                    &mut self.system.bottom[j],
                    z_constant,
                    cbar,
                    sbar,
                );
            }
            apply(
                &mut phi_constant,
                &mut self.system.corner,
                z_constant,
                cbar,
                sbar,
            );
            apply(&mut x, &mut self.rhs.last, z_constant, cbar, sbar);
        }
        row_weight
    }

    /// Whether the instruments determine every direction of `ℓ` well above the noise
    /// (`crate::estimators::iv_uncertainty`): the Cragg–Donald statistic, the smallest
    /// eigenvalue of `MᵀM` (the constant partialled out) over the regressors' noise
    /// covariance `noise·JJᵀ` per instrument, above [`STRONG_INSTRUMENTS`], tested as
    /// `MᵀM − c·n·noise·JJᵀ` positive definite (LDLᵀ without pivoting). O(n³).
    fn instruments_strong(&self, n: usize, noise: T) -> bool {
        let weight = |i: usize| {
            if i < n {
                self.lead_weight[i]
            } else {
                self.constant_weight
            }
        };
        // MᵀM = Σ_i D_i·s_iᵀ·s_i over the rows s_i of `system`.
        let gram = |a: usize, b: usize| {
            let mut sum = T::ZERO;
            for i in 0..=n {
                sum += weight(i) * self.system.get(i, a, n) * self.system.get(i, b, n);
            }
            sum
        };
        let constant = gram(n, n);
        if !(constant > T::ZERO) {
            return false;
        }
        let mut constant_column = [T::ZERO; N];
        for (a, value) in constant_column[..n].iter_mut().enumerate() {
            *value = gram(a, n);
        }
        // The constant partialled out, less c·n·noise·JJᵀ (2 on the diagonal, −1 beside).
        let limit = T::from_f64(STRONG_INSTRUMENTS) * T::from_u32(n as u32) * noise;
        let mut matrix = [[T::ZERO; N]; N];
        for a in 0..n {
            for b in a..n {
                let mut value = gram(a, b) - constant_column[a] * constant_column[b] / constant;
                if a == b {
                    value -= T::from_f64(2.0) * limit;
                } else if b == a + 1 {
                    value += limit;
                }
                matrix[a][b] = value;
                matrix[b][a] = value;
            }
        }
        positive_definite(&mut matrix, n)
    }

    /// `g = R⁻¹·D^{-1/2}·a = U⁻¹·D⁻¹·a'` for `a' = system⁻ᵀ·e_u` (`M = D^{1/2}·system`,
    /// `a = M⁻ᵀ·e_u`): the weights with which the instrument rows carry the equation errors
    /// into the level, `δu = gᵀ·Zᵀ·ε` (`Qᵀ = R⁻ᵀ·Zᵀ`). One back substitution, O(n²); the
    /// weights are positive (`solve` checked them).
    fn instrument_weights(&self, n: usize, last_row: &Column<T, N>) -> Column<T, N> {
        let mut g = Column::<T, N>::zero();
        g.last = last_row.last / self.constant_weight;
        for i in (0..n).rev() {
            let mut value = last_row.lead[i] / self.lead_weight[i];
            for j in (i + 1)..n {
                value -= self.lead_coupling[i][j] * g.lead[j];
            }
            value -= self.constant_coupling[i] * g.last;
            g.lead[i] = value;
        }
        g
    }
}

/// The instrumental-variable data-driven step estimator with capacity for orders up to `N`,
/// stating the standard uncertainty of its level for orders up to `L` (the default 0 states
/// none and keeps the bare estimator's size; see `crate::estimators::iv_uncertainty`).
///
/// Same reading semantics as [`crate::StepEstimator`]; see the module docs for the method,
/// its cost and where it loses.
#[derive(Clone, Debug)]
pub struct IvStepEstimator<T: Real, const N: usize, const L: usize = 0> {
    config: IvConfig<T>,
    intake: Intake<T>,
    history: DifferenceHistory<T, N>,
    factor: InstrumentFactor<T, N>,
    /// Regression rows folded in (saturating).
    rows: u32,
    /// Exponentially weighted row count.
    effective_rows: T,
    /// The origin of the targets folded into `factor`, moved to each valid estimate as in
    /// `StepEstimator` (the system's step unknown is the estimate minus this): in `f32` a
    /// right-hand side holding the load itself stalls over long runs.
    offset: T,
    /// The latest determined solution `[ℓ; u]`, for the next row's a-priori residual.
    solution: Option<Column<T, N>>,
    identifiability: T,
    /// The consistency check, when configured with a noise reference (on the a-posteriori
    /// residuals: IV has no standardising row weight).
    check: Option<ResidualCheck<T>>,
    /// What the level's standard uncertainty needs.
    uncertainty: IvUncertainty<T, N, L>,
}

impl<T: Real, const N: usize, const L: usize> IvStepEstimator<T, N, L> {
    /// A new estimator, or the reason the configuration is impossible.
    pub fn new(config: IvConfig<T>) -> Result<Self, ConfigError> {
        config.validate(N)?;
        Ok(Self {
            config,
            intake: config.step.intake(),
            history: DifferenceHistory::new(),
            factor: InstrumentFactor::new(),
            rows: 0,
            effective_rows: T::ZERO,
            offset: T::ZERO,
            solution: None,
            identifiability: T::ZERO,
            check: config.step.residual_check(),
            uncertainty: IvUncertainty::new(),
        })
    }

    step_wrapper_accessors!(IvConfig);

    /// `1 / (rows·‖e_uᵀ M⁻¹‖²)` at the latest solve, in (0, 1]; zero before the first. The
    /// IV estimate's noise is amplified by `1/√·` relative to an ideal regression on the same
    /// number of rows, so a small value means a weak instrument (see the module docs).
    pub fn identifiability(&self) -> T {
        self.identifiability
    }

    /// Samples needed (at the raw rate) before the first estimate: `(2n + d + 1)·D`.
    pub fn warm_up_samples(&self) -> u32 {
        let step = &self.config.step;
        (2 * step.order as u32 + self.config.instrument_delay as u32 + 1) * step.decimation as u32
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        Self::new(self.config)
    }

    /// Mark the current reading invalid; the solution goes with the estimate.
    fn invalidate(&mut self, reason: InvalidReason) {
        self.solution = None;
        self.intake.invalidate(reason);
    }

    /// Invalidate and stay invalid until the reset.
    fn latch(&mut self, reason: InvalidReason) {
        self.solution = None;
        self.intake.latch(reason);
    }

    fn update(&mut self, x: T) {
        let n = self.config.step.order;
        let delay = self.config.instrument_delay;
        self.history.push(x);
        if self.history.differences() < n + delay {
            return;
        }
        let phi = self.history.window(n, 0);
        let z = self.history.window(n, delay);
        let prior_residual = self
            .solution
            .map(|theta| row_residual(x, &phi, &theta.lead, theta.last, n));
        let lambda = self.config.step.forgetting;
        if lambda < T::ONE {
            self.factor.forget(n, lambda);
        }
        self.effective_rows = self.effective_rows * lambda + T::ONE;
        if lambda == T::ONE {
            self.uncertainty.push(n, &z, &phi, x - self.offset);
        }
        let row_weight = self.factor.fold(n, z, phi, x - self.offset);
        self.rows = self.rows.saturating_add(1);
        if !(row_weight.is_finite() && self.factor.constant_weight.is_finite()) {
            self.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < n + 1 {
            return;
        }
        let Some(solved) = self.solve(n) else {
            return;
        };
        let step = self.offset + solved.theta.last;
        let identifiability = T::ONE / (self.effective_rows * solved.last_row_norm2);
        self.identifiability = if identifiability.is_finite() {
            identifiability
        } else {
            T::ZERO
        };
        // The rounding-level test of StepEstimator, and the weak-instrument floor; neither
        // latches, more rows may cure both.
        let rounding = T::from_f64(100.0) * T::EPSILON;
        if !(self.identifiability > rounding)
            || !(self.identifiability > self.config.min_identifiability)
            || !step.is_finite()
        {
            self.invalidate(InvalidReason::IllConditioned);
            return;
        }
        // The consistency check on the a-posteriori residual of this row: its mean square is
        // the noise model's times (1 − leverage) for a correct model, so the check errs
        // towards not flagging while few rows are in.
        let mismatch = match self.check.as_mut() {
            Some(check) => {
                let lead = &solved.theta.lead;
                let residual = row_residual(x, &phi, lead, step, n);
                check.push(residual * residual, difference_noise_gain::<T, 1>(lead, n));
                check.mismatch(|| difference_correlation::<T, 1>(lead, n))
            }
            None => false,
        };
        if mismatch {
            // Not latched; the origin stays where it was (the next solve starts from it).
            self.invalidate(InvalidReason::ModelMismatch);
            return;
        }
        let mut theta = solved.theta;
        theta.last = step;
        self.solution = Some(theta);
        self.intake.estimating(step, prior_residual);
        self.intake
            .state_uncertainty(self.level_uncertainty(n, &solved));
        self.recentre(n, step);
    }

    /// The level's standard uncertainty (`crate::estimators::iv_uncertainty`): `None` for
    /// `L < n`, with forgetting, with too few rows, or with weak instruments.
    fn level_uncertainty(&self, n: usize, solved: &Solved<T, N>) -> Option<(T, u32)> {
        if !(IvUncertainty::<T, N, L>::covers(n) && self.config.step.forgetting == T::ONE) {
            return None;
        }
        let g = self.factor.instrument_weights(n, &solved.last_row);
        let (variance, noise, degrees) = self.uncertainty.variance(
            n,
            &solved.theta,
            &g,
            solved.last_row_norm2,
            self.check.as_ref().and_then(ResidualCheck::noise_floor),
        )?;
        if !self.factor.instruments_strong(n, noise) {
            return None;
        }
        stated(variance, degrees)
    }

    /// Solve the system for the rows so far; `None` after invalidating (or latching, when
    /// the system is not finite).
    fn solve(&mut self, n: usize) -> Option<Solved<T, N>> {
        // ‖e_uᵀM⁻¹‖² with M = D^{1/2}·system: row i of `system` carries weight 1/D_i.
        let mut row_weight = Column::<T, N>::zero();
        for i in 0..=n {
            let d = if i < n {
                self.factor.lead_weight[i]
            } else {
                self.factor.constant_weight
            };
            if !(d > T::ZERO) {
                self.invalidate(InvalidReason::IllConditioned);
                return None;
            }
            row_weight.set(i, n, T::ONE / d);
        }
        match self.factor.system.solve(n, self.factor.rhs, row_weight) {
            Ok(solved) => Some(solved),
            Err(SolveError::NonFinite) => {
                self.latch(InvalidReason::NonFiniteUpdate);
                None
            }
            Err(SolveError::Singular) => {
                self.identifiability = T::ZERO;
                self.invalidate(InvalidReason::IllConditioned);
                None
            }
        }
    }

    /// Move the origin to the estimate `step`: the right-hand side `Qᵀx` moves by the shift
    /// times `Qᵀ1`, the system's step column. The shift is the exact difference of the
    /// stored origins, as in `step::recentre`.
    fn recentre(&mut self, n: usize, step: T) {
        let origin = self.offset + (step - self.offset);
        let applied = origin - self.offset;
        if applied != T::ZERO {
            for i in 0..n {
                self.factor.rhs.lead[i] -= applied * self.factor.system.right[i];
            }
            self.factor.rhs.last -= applied * self.factor.system.corner;
            self.uncertainty.shift(n, applied);
            self.offset = origin;
        }
    }
}

/// Whether the symmetric `matrix[..n][..n]` is positive definite: every pivot of its LDLᵀ
/// (without pivoting, in place) positive.
fn positive_definite<T: Real, const N: usize>(matrix: &mut [[T; N]; N], n: usize) -> bool {
    for k in 0..n {
        let pivot = matrix[k][k];
        if !(pivot > T::ZERO) {
            return false;
        }
        for i in (k + 1)..n {
            let factor = matrix[i][k] / pivot;
            for j in (k + 1)..=i {
                matrix[i][j] -= factor * matrix[j][k];
            }
        }
    }
    true
}

estimator_via_intake!(IvStepEstimator<T, const N, const L>);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::step_uncertainty::coverage_factor;
    use crate::reading::Estimator;

    /// A damped oscillation towards 1 with a little deterministic noise, order 2.
    fn response() -> [f64; 60] {
        let mut state = 1u64;
        core::array::from_fn(|k| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let noise = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            let t = k as f64;
            1.0 - (-t * 0.1).exp() * (t * 0.7).cos() + 0.01 * noise
        })
    }

    /// The instrument weights solve `(ZᵀK)ᵀ·g = e_u`, and `u` is exactly the standard
    /// deviation of `gᵀ·Zᵀ·ε` for the moving average of the estimated `ℓ` at the residuals'
    /// level (`s²·‖h ∗ w‖²/Σh²`, `w = Z·g`), times the t-factor: the sandwich by brute force.
    #[test]
    fn the_level_uncertainty_is_the_variance_of_the_instrumented_errors() {
        let (n, d) = (2, 3);
        let xs = response();
        let mut iv =
            IvStepEstimator::<f64, 4, 4>::new(IvConfig::new(StepConfig::new(n, 1.0))).unwrap();
        for &x in &xs {
            iv.push(x);
        }
        let row = |k: usize, delay: usize| {
            let j = k - delay;
            [xs[j - 1] - xs[j - 2], xs[j] - xs[j - 1], 1.0]
        };
        let mut normal = [[0.0f64; 3]; 3];
        for k in (n + d)..xs.len() {
            let (z, phi) = (row(k, d), row(k, 0));
            for (line, &zi) in normal.iter_mut().zip(&z) {
                for (entry, &phij) in line.iter_mut().zip(&phi) {
                    *entry += zi * phij;
                }
            }
        }
        let solved = iv.solve(n).unwrap();
        let g = iv.factor.instrument_weights(n, &solved.last_row);
        for j in 0..=n {
            let column: f64 = (0..=n).map(|i| normal[i][j] * g.get(i, n)).sum();
            let expected = if j == n { 1.0 } else { 0.0 };
            assert!((column - expected).abs() < 1e-9, "column {j}: {column}");
        }
        let theta = solved.theta;
        let h = [
            1.0 - theta.lead[1],
            theta.lead[1] - theta.lead[0],
            theta.lead[0],
        ];
        let (mut weights, mut residual_sum) = ([0.0f64; 60], 0.0);
        for k in (n + d)..xs.len() {
            let (z, phi) = (row(k, d), row(k, 0));
            weights[k] = (0..=n).map(|i| z[i] * g.get(i, n)).sum();
            let fitted = iv.offset + theta.last + phi[0] * theta.lead[0] + phi[1] * theta.lead[1];
            residual_sum += (xs[k] - fitted).powi(2);
        }
        let mut filtered = 0.0;
        for j in 0..weights.len() + n {
            let value: f64 = (0..=n)
                .filter(|&m| j >= m && j - m < weights.len())
                .map(|m| h[m] * weights[j - m])
                .sum();
            filtered += value * value;
        }
        let degrees = (xs.len() - n - d - (n + 1)) as u32;
        let power: f64 = h.iter().map(|v| v * v).sum();
        let variance = residual_sum / f64::from(degrees) / power * filtered;
        let expected = variance.sqrt() * coverage_factor::<f64>(degrees);
        let (u, stated_degrees) = iv.level_uncertainty(n, &solved).unwrap();
        assert_eq!(stated_degrees, degrees);
        assert!((u / expected - 1.0).abs() < 1e-9, "{u} vs {expected}");
    }
}
