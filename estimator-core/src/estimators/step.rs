//! The data-driven step-input estimator (Markovsky 2015; Quintana-Carapia 2020, ch. 3).
//!
//! For a step input `u` on an LTI sensor of order `n` with static gain `G`, every sample
//! after the first `n` satisfies
//!
//! ```text
//! y(k) = G·u + Σ_{i=1..n} ℓ_i · Δy(k−n+i−1),     Δy(j) = y(j+1) − y(j)
//! ```
//!
//! (thesis eq. 3.15). We divide by `G` first, so the unknowns are `[ℓ'; u]` with the
//! constant column equal to one and `u` in the caller's unit, and solve the growing (or
//! exponentially weighted) least-squares problem recursively.
//!
//! ## The recursive form
//! The thesis uses the textbook covariance RLS (eq. 3.24), initialised by inverting the
//! first `(n+1)×(n+1)` block; in `f32` that form drifts on the ill-conditioned Hankel data
//! of a fast-sampled sensor (see `CovarianceStepEstimator` and the long-run test). We solve
//! the same problem in square-root information form with square-root-free Givens rotations
//! (the shared engine in `factor.rs`): exact initialisation, backward stable, no square
//! roots, and the step level — the last unknown — read off the factor directly.
//!
//! ## Found by the stability map (host-sim `study stability`)
//! - A reading right where the fit becomes determined can be noise amplified by orders of
//!   magnitude: readings with an identifiability at or below [`MIN_IDENTIFIABILITY`] are
//!   `Invalid(IllConditioned)` (test `tests/stability.rs`).
//! - In `f32` over long runs the step level stalled: stored as the load itself, updates of
//!   `1/N_eff` of a deviation fall below the load's rounding step. The targets are therefore
//!   folded relative to an
//!   origin that follows the estimate (`offset`), so the factor holds deviations, not the
//!   load (`Factor::shift_target`); the reading adds the origin back.
//! - Silent without a noise reference: the bias of an order below the sensor's (n = 1, 2 at
//!   D = 16). Given the noise metered at tare ([`StepConfig::with_noise_reference`]), the
//!   estimator compares what its fit leaves unexplained with what that noise would leave
//!   and flags `Invalid(ModelMismatch)` beyond chance (`crate::estimators::consistency`).
//! - Not detectable here, and so stated: the errors-in-variables bias of the fast-sampled
//!   regression (D = 1): the fit absorbs the regressors' noise, so its residuals are smaller
//!   than the noise model's, not larger. Calibration must choose a configuration inside the
//!   map's valid region (`tuning::WeighingConfig::check_region`).

use crate::estimators::consistency::{NoiseReference, ResidualCheck};
use crate::estimators::input::{Decimator, DifferenceWindow};
use crate::estimators::intake::{estimator_via_intake, intake_config_builders, Intake};
use crate::estimators::metered_noise::MeteredNoise;
use crate::estimators::noise_meter::Autocovariance;
use crate::estimators::step_uncertainty::{Hankel, LagSums, NoiseFloor};
use crate::numerics::factor::Factor;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, InvalidReason};

/// The largest block length the decimator accepts.
pub const MAX_DECIMATION: u16 = 1024;

/// Readings whose identifiability (the squared sine of the angle between the constant column
/// and the difference columns) is not above this floor are `Invalid(IllConditioned)`: their
/// noise gain is more than √1000 ≈ 32 times that of a plain mean of the same rows. The
/// stability map found such readings right where a fit becomes determined (`n + 1` rows, no
/// redundancy), with errors orders of magnitude above those of the next row's.
pub const MIN_IDENTIFIABILITY: f64 = 1e-3;

/// The identifiability floor of `T`: [`MIN_IDENTIFIABILITY`], or the rounding level
/// `100·ε` where that is higher.
pub(crate) fn identifiability_floor<T: Real>() -> T {
    let rounding = T::from_f64(100.0) * T::EPSILON;
    let floor = T::from_f64(MIN_IDENTIFIABILITY);
    if rounding > floor {
        rounding
    } else {
        floor
    }
}

/// Configuration of a [`StepEstimator`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepConfig<T> {
    /// Model order `n` used by the regression (1 ≤ n ≤ capacity).
    pub order: usize,
    /// Static gain `G`: raw units per unit of the estimate (e.g. counts per gram).
    pub gain: T,
    /// Forgetting factor λ ∈ (0, 1]; 1 keeps a growing window.
    pub forgetting: T,
    /// Block-average this many raw samples before each regression update (1 = full rate).
    pub decimation: u16,
    /// Raw samples outside `[min, max]` invalidate the reading (saturation, wiring faults).
    pub valid_min: T,
    /// See `valid_min`.
    pub valid_max: T,
    /// The noise measured at tare, for the consistency check (`None`: no check, the
    /// default). With it, a fit that leaves more unexplained than this noise can explain is
    /// flagged `Invalid(ModelMismatch)` (see `crate::estimators::consistency`).
    pub noise_reference: Option<NoiseReference<T>>,
}

impl<T: Real> StepConfig<T> {
    /// Order `n`, gain `G`, growing window, full rate, no range limit, no consistency check.
    pub fn new(order: usize, gain: T) -> Self {
        Self {
            order,
            gain,
            forgetting: T::ONE,
            decimation: 1,
            valid_min: T::from_f64(f64::NEG_INFINITY),
            valid_max: T::from_f64(f64::INFINITY),
            noise_reference: None,
        }
    }

    intake_config_builders!();

    /// Set the forgetting factor λ.
    pub fn with_forgetting(mut self, forgetting: T) -> Self {
        self.forgetting = forgetting;
        self
    }

    /// Check the configuration against an estimator capacity.
    pub fn validate(&self, capacity: usize) -> Result<(), ConfigError> {
        if self.order == 0 || self.order > capacity {
            return Err(ConfigError::Order {
                requested: self.order,
                capacity,
            });
        }
        if !self.gain.is_finite() || self.gain == T::ZERO {
            return Err(ConfigError::Gain);
        }
        // Written so that NaN fails too.
        if !(self.forgetting > T::ZERO && self.forgetting <= T::ONE) {
            return Err(ConfigError::Forgetting);
        }
        if self.decimation == 0 || self.decimation > MAX_DECIMATION {
            return Err(ConfigError::Decimation);
        }
        if !(self.valid_min < self.valid_max) {
            return Err(ConfigError::Range);
        }
        if let Some(reference) = &self.noise_reference {
            reference.validate()?;
        }
        Ok(())
    }

    /// The intake this configuration asks for: gain, valid range and decimation.
    pub(crate) fn intake(&self) -> Intake<T> {
        Intake::new(
            T::ONE / self.gain,
            self.valid_min,
            self.valid_max,
            Decimator::new(self.decimation),
        )
    }

    /// The consistency check this configuration asks for, over residuals in the estimate's
    /// unit (raw units over the gain).
    pub(crate) fn residual_check(&self) -> Option<ResidualCheck<T>> {
        self.noise_reference.as_ref().map(|reference| {
            ResidualCheck::new(
                reference,
                T::ONE / self.gain,
                self.decimation,
                self.forgetting,
            )
        })
    }
}

/// The data-driven step-input estimator with capacity for orders up to `N`, stating the
/// standard uncertainty of its level for orders up to `L` (the default 0 states none and
/// keeps the bare estimator's size: the lag sums take `6L² + 3L` numbers, see
/// `crate::estimators::step_uncertainty`), and able to rest that `u` on the empty pan's
/// metered noise colour over `C` lags (`3L` is what the coverage study measured; the
/// default 0 keeps nothing and costs nothing: `crate::estimators::metered_noise`).
///
/// Fixed size, no allocation, never panics on data. See the module docs for the method.
#[derive(Clone, Debug)]
pub struct StepEstimator<T: Real, const N: usize, const L: usize = 0, const C: usize = 0> {
    config: StepConfig<T>,
    intake: Intake<T>,
    differences: DifferenceWindow<T, N, 1>,
    /// Leading columns: the differences; one trailing column: the constant, whose unknown is
    /// the step level.
    factor: Factor<T, N, 1>,
    /// Regression rows folded in (saturating).
    rows: u32,
    /// Exponentially weighted row count, the scale for the conditioning test.
    effective_rows: T,
    /// The origin of the targets folded into `factor` (see the module docs): the factor's
    /// step level is the estimate minus this.
    offset: T,
    /// The consistency check, when configured with a noise reference.
    check: Option<ResidualCheck<T>>,
    /// `Σc²` of the latest solution: the next residual's noise in block-mean variances.
    noise_gain: T,
    /// The rows' lagged cross-products and residual sum of squares, for the uncertainty
    /// (the residuals' autocovariance over every lag kept: `true`, see `step_uncertainty`).
    lags: LagSums<T, N, L, true, Hankel>,
    /// The empty pan's metered noise colour and the rows' totals its `u` needs
    /// (`crate::estimators::metered_noise`); kept over resets.
    metered: MeteredNoise<T, L, C>,
}

impl<T: Real, const N: usize, const L: usize, const C: usize> StepEstimator<T, N, L, C> {
    /// A new estimator, or the reason the configuration is impossible.
    pub fn new(config: StepConfig<T>) -> Result<Self, ConfigError> {
        config.validate(N)?;
        Ok(Self {
            config,
            intake: config.intake(),
            differences: DifferenceWindow::new(),
            factor: Factor::new(),
            rows: 0,
            effective_rows: T::ZERO,
            offset: T::ZERO,
            check: config.residual_check(),
            noise_gain: T::ONE,
            lags: LagSums::new(),
            metered: MeteredNoise::new(),
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &StepConfig<T> {
        &self.config
    }

    /// Check the runs after the next [`crate::Estimator::reset`] against `reference` (`None`: no
    /// check); the current run keeps the check it started with. A reference that is not
    /// finite and positive is refused and nothing changes.
    pub fn set_noise_reference(
        &mut self,
        reference: Option<NoiseReference<T>>,
    ) -> Result<(), ConfigError> {
        NoiseReference::replace(&mut self.config.noise_reference, reference)
    }

    /// Never rest the level's `u` on a noise level below the raw samples' white noise,
    /// `white`: the variance in raw units² per sample as their sample-to-sample differences
    /// show it, and how many differences (`None`: not known, the default), from now on and
    /// after every reset: a fresh fit of a few rows can all but interpolate its data and
    /// state a `u` far below what the noise allows (see
    /// `crate::estimators::step_uncertainty`). Its share of a block mean (`/D`) is the
    /// floor; where the `u` rests on it, the coverage factor is that of its degrees of
    /// freedom ([`NoiseReference::differences`]: `2M/3`, none for an exact one). One whose
    /// variance is not finite and non-negative is refused and nothing changes.
    pub fn set_white_noise(&mut self, white: Option<NoiseReference<T>>) -> Result<(), ConfigError> {
        let variance = NoiseReference::white_variance(white)?;
        let config = &self.config;
        let block = T::from_u32(u32::from(config.decimation));
        self.lags.set_white_floor(white.and_then(|white| {
            NoiseFloor::new(
                variance / (config.gain * config.gain * block),
                Some(white.degrees()),
            )
        }));
        Ok(())
    }

    /// Rest the level's `u` on the empty pan's metered noise colour: `autocovariance` of
    /// block means of this estimator's `D` raw samples, raw units²
    /// ([`crate::AutocovarianceMeter`]); `None` (the default) forgets it. From now on and
    /// after every reset; see `crate::estimators::metered_noise` for what it changes. One
    /// metered over fewer than [`crate::MIN_METERED_BLOCKS`] block means, or with `C = 0`,
    /// is taken as none;
    /// one that is no autocovariance ([`Autocovariance::validate`]) is refused and nothing
    /// changes. Orders above `L`, and `L = 0`, state no `u` either way.
    #[inline(never)]
    pub fn set_noise_autocovariance(
        &mut self,
        autocovariance: Option<&Autocovariance<T>>,
    ) -> Result<(), ConfigError> {
        if let Some(autocovariance) = autocovariance {
            autocovariance.validate()?;
        }
        let scale = T::ONE / self.config.gain;
        self.metered.set(autocovariance, scale * scale);
        Ok(())
    }

    /// Whether the level's `u` rests on a metered noise colour (one was set with enough block
    /// means: [`Self::set_noise_autocovariance`]).
    pub fn rests_on_metered_colour(&self) -> bool {
        self.metered.is_known()
    }

    /// The raw samples' white noise the level's `u` rests on at least (raw units² per
    /// sample; see [`Self::set_white_noise`]), `None` when not known.
    pub fn white_noise_variance(&self) -> Option<T> {
        let config = &self.config;
        self.lags.white_floor().map(|floor| {
            floor.variance * config.gain * config.gain * T::from_u32(u32::from(config.decimation))
        })
    }

    /// The consistency check's residual ratio: the weighted mean square of the residuals
    /// over what the noise reference predicts for them (≈ 1 when the fit leaves only
    /// noise); `None` without a reference or before the first determined row.
    pub fn residual_ratio(&self) -> Option<T> {
        self.check.as_ref().and_then(ResidualCheck::ratio)
    }

    /// The capacity `N`: the largest order this instance accepts.
    pub const fn capacity() -> usize {
        N
    }

    /// How well the step level is identified: the squared sine of the angle between the
    /// constant column and the span of the difference columns, in (0, 1]. It is the factor
    /// by which noise on the data is amplified into the estimate (as 1/√·); the estimator
    /// flags [`InvalidReason::IllConditioned`] when it is not above [`MIN_IDENTIFIABILITY`]
    /// (or the rounding level of `T`, if higher).
    pub fn identifiability(&self) -> T {
        if self.effective_rows > T::ZERO {
            self.factor.tail_weight()[0] / self.effective_rows
        } else {
            T::ZERO
        }
    }

    /// Samples needed (at the raw rate) before the first estimate: `(2n+1)·D`.
    pub fn warm_up_samples(&self) -> u32 {
        (2 * self.config.order as u32 + 1) * self.config.decimation as u32
    }

    fn fresh(&self) -> Result<Self, ConfigError> {
        let mut fresh = Self::new(self.config)?;
        fresh.lags.set_white_floor(self.lags.white_floor());
        fresh.metered.keep_noise_of(&self.metered);
        Ok(fresh)
    }

    /// One decimated sample `x` (in the estimate's unit) into the regression.
    fn update(&mut self, x: T) {
        let n = self.config.order;
        if !self.differences.push(x, n) {
            return;
        }
        let lambda = self.config.forgetting;
        if lambda < T::ONE {
            self.factor.forget(n, lambda);
        }
        self.effective_rows = self.effective_rows * lambda + T::ONE;
        let had_estimate = self.intake.estimate().is_some();
        let determined_before = self.rows as usize > n;
        let window = self.differences.window();
        self.metered.push_row(&window, n, self.lags.rows());
        self.lags.push_row(&window, n);
        let folded = self.factor.fold(n, window, [T::ONE], x - self.offset);
        self.rows = self.rows.saturating_add(1);
        let [deviation] = self.factor.tail_solution();
        let step = self.offset + deviation;
        let [weight] = self.factor.tail_weight();
        if !(step.is_finite() && weight.is_finite() && folded.row_weight.is_finite()) {
            self.intake.latch(InvalidReason::NonFiniteUpdate);
            return;
        }
        if (self.rows as usize) < n + 1 {
            return;
        }
        if determined_before {
            self.lags
                .push_residual(folded.residual, folded.row_weight, n);
        }
        let mismatch = match self.check.as_mut() {
            Some(check) => {
                let residual = folded.residual;
                let standardised =
                    determined_before.then(|| folded.row_weight * residual * residual);
                let (lead, _) = self.factor.solution(n);
                check.push_a_priori_row::<1>(standardised, &mut self.noise_gain, &lead, n)
            }
            None => false,
        };
        // weight / effective_rows is the squared sine of the angle between the constant
        // column and the span of the difference columns; near zero, u is not identifiable.
        // Not latched: right after warm-up a fast-sampled Hankel system can be too
        // ill-conditioned for the precision, and more rows cure that (the factorisation is
        // backward stable, so the early rounding does not persist).
        // The floor also covers readings whose noise gain is far beyond a mean's (see
        // `MIN_IDENTIFIABILITY`).
        let threshold = identifiability_floor::<T>() * self.effective_rows;
        if !(weight > threshold) {
            self.intake.invalidate(InvalidReason::IllConditioned);
            return;
        }
        self.offset = recentre(&mut self.factor, n, self.offset, step);
        if mismatch {
            // Not latched: the data so far do not fit; more rows may (or a reset will).
            self.intake.invalidate(InvalidReason::ModelMismatch);
            return;
        }
        self.intake
            .estimating(step, had_estimate.then_some(folded.residual));
        self.intake.state_uncertainty(self.uncertainty());
    }

    /// The standard uncertainty of the current level (`crate::estimators::step_uncertainty`):
    /// `None` for `L < n`, with forgetting, or with too few rows. O(n³).
    fn uncertainty(&self) -> Option<(T, u32)> {
        let n = self.config.order;
        if L < n || self.config.forgetting < T::ONE {
            return None;
        }
        let (z, [z_level]) = self.factor.last_unknown_influence(n)?;
        let (lead, _) = self.factor.solution(n);
        let white = self.lags.white_floor();
        let coloured = self.metered.covers_run(self.lags.rows());
        if coloured {
            if let Some(stated) =
                self.lags
                    .metered_uncertainty(n, &z, z_level, &lead, &self.metered, |g| {
                        Some(self.factor.influence(n, *g, [T::ZERO])?.0)
                    })
            {
                return Some(stated);
            }
        }
        // The larger of the empty pan's metered noise and the raw samples' white noise;
        // only the latter where the metered colour left the equation error no power: the
        // fit's moving average cancels the pan's noise (a floor vibration it models as part
        // of the cell), so the pan's noise level does not reach the level, and the
        // residuals say what does (a floor of the empty pan's level stated u = 0.14 g on
        // errors of 0.003 g under floor vibration at 80 dB).
        let metered = if coloured {
            None
        } else {
            self.check.as_ref().and_then(ResidualCheck::noise_floor)
        };
        let floor = NoiseFloor::higher(metered, white);
        self.lags.uncertainty(n, &z, z_level, &lead, floor)
    }
}

/// Move the factor's origin (`offset`) to the estimate `step` and return the new origin.
/// The shift applied to the factor is the exact difference of the stored origins (exact by
/// Sterbenz's lemma whenever they are within a factor of two, as they are once the estimate
/// settles), so the origin and the factor never disagree by a rounding error that could
/// accumulate.
pub(crate) fn recentre<T: Real, const N: usize, const E: usize>(
    factor: &mut Factor<T, N, E>,
    active: usize,
    offset: T,
    step: T,
) -> T {
    let moved = step - offset;
    let origin = offset + moved;
    let applied = origin - offset;
    if applied != T::ZERO {
        factor.shift_target(active, E - 1, applied);
    }
    origin
}

estimator_via_intake!(StepEstimator<T, const N, const L, const C>);
