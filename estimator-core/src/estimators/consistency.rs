//! The run-time consistency check (opt-in): what an estimator's fit leaves unexplained,
//! against what the noise measured at tare alone would leave.
//!
//! A valid-looking reading can be far off when the model behind it does not describe the
//! data: an order below the sensor's, one model used off its load, a baseline that calls a
//! still-ringing pan stable. The estimator cannot see that from the data alone, but a scale
//! has a noise reference: the variance of the empty pan, metered at tare by
//! [`crate::NoiseMeter`]. Given it ([`NoiseReference`]), an estimator compares the mean
//! square of its residuals with the variance the noise alone would give them and flags
//! [`crate::InvalidReason::ModelMismatch`] when the excess is beyond chance. It must never
//! flag a correctly modelled record more often than designed ([`MISMATCH_FALSE_ALARM`]),
//! and never change a reading of an estimator configured without a reference.
//!
//! ## What the noise alone leaves
//! The estimators fit block means of `D` raw samples, whose noise has variance
//! `v = σ²/D` (σ² the raw-rate variance the meter reports, already at the estimator's `D`).
//! - **Model-based** ([`crate::ModelEstimator`]): the residual of a row is the block mean
//!   minus the model's prediction, so its noise is one block mean's: variance `v`.
//! - **Data-driven** ([`crate::StepEstimator`] and its forms): the residual of the row of
//!   block `k` is `x(k) − Σ_{i=1..n} ℓ_i·Δx(k−n+i−1) − u` with `Δx(j) = x(j+1) − x(j)`, and the
//!   regressors carry noise too (errors in variables). With `e` the block means' noise, its
//!   noise is `e(k) − Σ ℓ_i·(e(k−n+i) − e(k−n+i−1)) = Σ_{m=0..n} c_m·e(k−n+m)` with
//!
//!   ```text
//!   c_0 = ℓ_1,   c_m = ℓ_{m+1} − ℓ_m  (0 < m < n),   c_n = 1 − ℓ_n
//!   ```
//!
//!   (`Σ c_m = 1`), so its variance is `v·Σ c_m²`, from the current `ℓ`. O(n) a row.
//!
//! ## The statistic
//! Each row's a-priori residual `e` comes with its weight `w = 1/(1 + φᵀ(ΦᵀΦ)⁻¹φ)` (the
//! product of the rotations' cosines, `factor.rs`): `w·e²` is the row's increment of the
//! residual sum of squares, and for a correctly modelled regression with white equation
//! error of variance `s²` these standardised recursive residuals are independent with mean
//! `s²` (Brown, Durbin & Evans 1975). Each is divided by its own predicted variance
//! (`v·Σc²` or `v`), and the quotients `q` are averaged **with the fit's own weights**: all
//! rows since the reset for a growing window, `λʲ` with forgetting. The ratio
//! `r = Σ λʲ q / Σ λʲ` is near 1 when the fit explains everything but the noise. The window
//! is the estimate's: a transient that the model could not follow still biases a
//! growing-window estimate after it has decayed, and so it still counts here (an order
//! below the sensor's is then flagged at 1.5 s, not only while the ring is large). The
//! instrumental-variable and bias-compensated forms have no standardising weight for their
//! own solution; they use the a-posteriori residual, whose mean square is the noise model's
//! times `1 − leverage` (smaller, so they err towards not flagging while few rows are in).
//!
//! ## The threshold, from the false-alarm rate
//! Under the model `r` is a mean of `ν` χ²₁/1 variables (`ν = (Σλʲ)²/Σλ²ʲ`, Kish's effective
//! count: the rows for λ = 1), correlated because a data-driven residual's noise is a moving
//! average of the block means' noise: adjacent squares correlate by `ρ_h² = (γ_h/γ_0)²` with
//! `γ_h = Σ_m c_m c_{m+h}`, so the mean has the variance of `ν·γ_0²/(γ_0² + 2Σ_h γ_h²)`
//! independent ones. The reference is itself an estimate: over `M` differences of block
//! means its relative variance is `3/M` ([`crate::NoiseMeter`]), that of a χ² with
//! `ν_t = 2M/3` degrees of freedom, and it is common to the whole run. So `r` is
//! F-distributed with `(ν_eff, ν_t)` degrees of freedom; its upper [`MISMATCH_FALSE_ALARM`]
//! quantile comes from Paulson's normal approximation (only square roots; above the exact
//! quantile, within 12% of it from 1 degree of freedom and within 3% from 6: test
//! `the_threshold_is_the_f_quantile_from_above`). The correlation correction costs O(n²)
//! and is computed only when `r` is above the threshold without it.
//!
//! A reading is flagged when `r` exceeds [`MISMATCH_ALLOWANCE`] = 2 times that quantile.
//! The allowance is for noise the tare cannot show as the loaded pan sees it, measured on
//! host-sim's reference cell at n = 7, D = 16 and n = 5, D = 24 (100 runs per cell): the
//! INA114's noise, coloured by the 100 Hz filter, is the same at every block and dominates
//! the block means at 80 dB, where the differences the meter uses see little of it (`r` ≈ 1.4
//! at 1.5 s against 1.0 at 30–50 dB); a vibration near the *loaded* resonance moves the
//! loaded pan more than the empty one the tare saw (1 in 100 runs went above the bare
//! quantile, at `r` ≈ 4 against 3.4); and a 0.3 s tare holds a few cycles of a 1 Hz wide
//! vibration, so its variance can come out low (1 run in 300 flagged with the allowance, at
//! 20 and 30 dB). Mains pickup is in the tare and the fit absorbs it (`r` ≈ 0.1). With the
//! allowance the threshold at D = 24 with the 0.3 s tare host-sim meters (`M` = 49, `ν_t` ≈ 33)
//! is 17.9 after 6 rows and 7.9 after 240 (1.5 s); at D = 16 (`ν_t` ≈ 49), 15.2 and 5.9; with
//! a reference known exactly, 11.4 and 2.9. What it still flags: an order below the sensor's
//! (`r` of 10²–10⁸ at n = 1, 2), one model off its load, a still-ringing pan called stable by
//! a baseline, and at high SNR a model barely good enough (n = 3 at 80 dB, n = 2 at
//! 1.5 s from 60 dB), whose estimate the stability map still counted within 10× the bound.
//!
//! ## What it cannot see
//! A bias that leaves the residuals at the noise: the errors-in-variables bias of the
//! full-rate regression once the transient is over (the least-squares fit absorbs the
//! regressors' noise; at D = 1 it flags most readings at 100 ms but few at 1.5 s, where the
//! estimate is still 40–500× the bound from 50 dB), a slope fitted to mains by the ramp
//! estimator (the mains is in the tare), and a model bank's grid (see [`crate::ModelBank`]).
//! The first is refused by configuration instead (`crate::tuning::WeighingConfig::check_region`).

use crate::estimators::step_uncertainty::NoiseFloor;
use crate::numerics::real::Real;
use crate::reading::ConfigError;

/// The designed probability that one reading of a correctly modelled record with white noise
/// is flagged [`crate::InvalidReason::ModelMismatch`] (upper tail of the F distribution of the
/// residual ratio; see the module docs). Readings close in time share rows, so flags come in
/// runs: the probability that a run of readings has any flag is below this times the number
/// of windows it spans.
pub const MISMATCH_FALSE_ALARM: f64 = 1e-5;
/// The standard normal quantile of `1 − MISMATCH_FALSE_ALARM`.
const MISMATCH_Z: f64 = 4.264_890_793_922_602;
/// The allowance for noise the tare cannot show as the loaded pan sees it (see the module
/// docs): the flag needs the residual ratio above this many times the F quantile.
pub const MISMATCH_ALLOWANCE: f64 = 2.0;
/// The noise measured at tare, as the consistency check takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NoiseReference<T> {
    /// The raw-rate noise variance in raw units² at the estimator's block length `D`, as
    /// [`crate::NoiseMeter::noise_variance`] reports it (metered at the same `D`).
    pub variance: T,
    /// The differences of block means it was metered over ([`crate::NoiseMeter::differences`]):
    /// its own uncertainty (relative variance `3/M`). 0: known exactly (a simulation).
    pub differences: u32,
}

impl<T: Real> NoiseReference<T> {
    /// A reference metered over `differences` differences of block means.
    pub fn new(variance: T, differences: u32) -> Self {
        Self {
            variance,
            differences,
        }
    }

    /// A reference known exactly (no uncertainty of its own).
    pub fn exact(variance: T) -> Self {
        Self::new(variance, 0)
    }

    /// `ConfigError::NoiseReference` unless the variance is finite and positive.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // Written so that NaN fails too.
        if self.variance > T::ZERO && self.variance.is_finite() {
            Ok(())
        } else {
            Err(ConfigError::NoiseReference)
        }
    }

    /// The variance of a white noise an estimator's `u` is floored at (`None`: not known, 0),
    /// or `ConfigError::NoiseReference` unless it is finite and non-negative (a white noise
    /// metered as none is a floor of nothing, not a refusal, unlike [`Self::validate`]).
    pub(crate) fn white_variance(white: Option<Self>) -> Result<T, ConfigError> {
        let variance = white.map_or(T::ZERO, |white| white.variance);
        // Written so that NaN fails too.
        if variance >= T::ZERO && variance.is_finite() {
            Ok(variance)
        } else {
            Err(ConfigError::NoiseReference)
        }
    }

    /// Put `reference` in `slot` (an estimator's configured reference, used from its next
    /// reset) if it is valid ([`Self::validate`]); a refused one leaves `slot` as it was.
    pub(crate) fn replace(
        slot: &mut Option<Self>,
        reference: Option<Self>,
    ) -> Result<(), ConfigError> {
        if let Some(reference) = &reference {
            reference.validate()?;
        }
        *slot = reference;
        Ok(())
    }

    /// The reference's degrees of freedom `2M/3`, or 0 when exact.
    pub(crate) fn degrees_of_freedom(&self) -> T {
        T::from_f64(2.0 / 3.0) * T::from_u32(self.differences)
    }

    /// The same as a count for a `u`'s coverage factor: `2M/3`, or no end of them when
    /// exact.
    pub(crate) fn degrees(&self) -> u32 {
        if self.differences == 0 {
            u32::MAX
        } else {
            (2 * u64::from(self.differences) / 3) as u32
        }
    }
}

/// The running residual ratio of one estimator (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct ResidualCheck<T> {
    /// `v`: the noise variance of one block mean, in the residuals' unit².
    block_variance: T,
    /// The reference itself, for its degrees of freedom (`ν_t`).
    reference: NoiseReference<T>,
    /// The estimator's own forgetting factor: the check weighs the rows as the fit does.
    forgetting: T,
    /// Σ βʲ q, Σ βʲ, Σ β²ʲ.
    sum: T,
    weight: T,
    weight2: T,
}

impl<T: Real> ResidualCheck<T> {
    /// The reference as a floor for a fit's noise level: the noise variance of one block
    /// mean it predicts, in the residuals' unit², and the reference's degrees of freedom
    /// ([`NoiseReference::degrees`]).
    pub(crate) fn noise_floor(&self) -> Option<NoiseFloor<T>> {
        NoiseFloor::new(self.block_variance, Some(self.reference.degrees()))
    }

    /// The check for residuals in a unit where one raw unit is `scale` (e.g. `1/G`), of
    /// block means of `decimation` raw samples, of a fit with forgetting factor `forgetting`.
    pub(crate) fn new(
        reference: &NoiseReference<T>,
        scale: T,
        decimation: u16,
        forgetting: T,
    ) -> Self {
        Self {
            block_variance: reference.variance * scale * scale
                / T::from_u32(u32::from(decimation.max(1))),
            reference: *reference,
            forgetting,
            sum: T::ZERO,
            weight: T::ZERO,
            weight2: T::ZERO,
        }
    }

    /// Fold one row: `standardised` = `w·e²` (its increment of the residual sum of squares),
    /// `noise_gain` = the residual's noise variance in block-mean variances (`Σc²`, or 1).
    #[inline]
    pub(crate) fn push(&mut self, standardised: T, noise_gain: T) {
        let predicted = self.block_variance * noise_gain;
        let quotient = standardised / predicted;
        if !quotient.is_finite() {
            // A degenerate prediction (ℓ not yet finite): no evidence either way.
            return;
        }
        let beta = self.forgetting;
        self.sum = self.sum * beta + quotient;
        self.weight = self.weight * beta + T::ONE;
        self.weight2 = self.weight2 * beta * beta + T::ONE;
    }

    /// One row of a data-driven regression whose a-priori residual the fit standardises
    /// before the update (`StepEstimator`, `RampEstimator`, `ORDER` their difference
    /// order): `standardised` (`w·e²`, `None` while the fit was not yet determined) is
    /// judged with `noise_gain`, the gain of the coefficients that predicted it, which then
    /// moves to the updated coefficients `lead` (of order `n`). True on a mismatch.
    pub(crate) fn push_a_priori_row<const ORDER: usize>(
        &mut self,
        standardised: Option<T>,
        noise_gain: &mut T,
        lead: &[T],
        n: usize,
    ) -> bool {
        if let Some(standardised) = standardised {
            self.push(standardised, *noise_gain);
        }
        *noise_gain = difference_noise_gain::<T, ORDER>(lead, n);
        self.mismatch(|| difference_correlation::<T, ORDER>(lead, n))
    }

    /// The residual ratio `r` (≈ 1 when the fit leaves only noise); `None` before a row.
    pub(crate) fn ratio(&self) -> Option<T> {
        (self.weight > T::ZERO).then(|| self.sum / self.weight)
    }

    /// Kish's effective number of rows behind [`Self::ratio`].
    pub(crate) fn effective_rows(&self) -> T {
        if self.weight2 > T::ZERO {
            self.weight * self.weight / self.weight2
        } else {
            T::ZERO
        }
    }

    /// True when the ratio exceeds the threshold for the effective rows times
    /// `correlation()` (the residuals' degrees-of-freedom factor, in (0, 1]), computed only
    /// when the ratio exceeds the threshold without it (the lowest the threshold can be).
    pub(crate) fn mismatch(&self, correlation: impl FnOnce() -> T) -> bool {
        match self.ratio() {
            Some(ratio) => self.mismatch_at(ratio, correlation),
            None => false,
        }
    }

    /// [`Self::mismatch`] for a given ratio over the same rows. The threshold is never
    /// below [`MISMATCH_ALLOWANCE`] (an upper quantile of F is above 1: test
    /// `the_threshold_is_never_below_the_allowance`), so a ratio at or under it, as on
    /// nearly every row of a fit that explains its data, is answered before the threshold's
    /// divisions and roots: 1,002.0 → 996.0 instructions per sample at n = 7, D = 16 with
    /// the check live (`cargo xtask bench step`).
    fn mismatch_at(&self, ratio: T, correlation: impl FnOnce() -> T) -> bool {
        if self.weight <= T::ZERO || !(ratio > T::from_f64(MISMATCH_ALLOWANCE)) {
            return false;
        }
        let rows = self.effective_rows();
        let reference_dof = self.reference.degrees_of_freedom();
        if !(ratio > mismatch_threshold(rows, reference_dof)) {
            return false;
        }
        let factor = correlation();
        let factor = if factor > T::ZERO && factor <= T::ONE {
            factor
        } else {
            T::ONE
        };
        ratio > mismatch_threshold(rows * factor, reference_dof)
    }
}

/// The flag's threshold on a ratio with `nu1` degrees of freedom against a reference with
/// `nu2` (0: exact): the allowance times the F quantile.
pub(crate) fn mismatch_threshold<T: Real>(nu1: T, nu2: T) -> T {
    T::from_f64(MISMATCH_ALLOWANCE) * threshold(nu1, nu2)
}

/// The upper [`MISMATCH_FALSE_ALARM`] quantile of F(ν₁, ν₂) by Paulson's approximation
/// (ν₂ = 0: the χ²_ν₁/ν₁ limit, Wilson–Hilferty); infinite where the approximation has no
/// root (a reference too uncertain to ever flag).
pub(crate) fn threshold<T: Real>(nu1: T, nu2: T) -> T {
    let infinite = T::from_f64(f64::INFINITY);
    if !(nu1 > T::ZERO) {
        return infinite;
    }
    let z = T::from_f64(MISMATCH_Z);
    let z2 = z * z;
    let ninth = T::from_f64(2.0 / 9.0);
    let (b1, b2) = (
        ninth / nu1,
        if nu2 > T::ZERO { ninth / nu2 } else { T::ZERO },
    );
    let (a1, a2) = (T::ONE - b1, T::ONE - b2);
    // Solve (a₂y − a₁)² = z²(b₂y² + b₁) for the cube root y of the quantile.
    let a = a2 * a2 - z2 * b2;
    if !(a > T::ZERO) {
        return infinite;
    }
    let b = a1 * a2;
    let c = a1 * a1 - z2 * b1;
    let discriminant = b * b - a * c;
    let root = if discriminant > T::ZERO {
        discriminant.sqrt()
    } else {
        T::ZERO
    };
    let y = (b + root) / a;
    if !(y > T::ZERO) {
        return infinite;
    }
    y * y * y
}

/// Noise coefficient `c_m` (m = 0..n + ORDER − 1, oldest first) of a data-driven residual
/// whose `n` regressors are differences of order `ORDER` (1: the step estimators, 2: the
/// ramp), from their coefficients `lead[..n]` = ℓ (see the module docs): the target's own
/// noise, minus each regressor's difference stencil `(−1)^(ORDER−t)·C(ORDER, t)` weighted by ℓ.
#[inline]
pub(crate) fn coefficient<T: Real, const ORDER: usize>(lead: &[T], n: usize, m: usize) -> T {
    let mut c = if m == n + ORDER - 1 { T::ONE } else { T::ZERO };
    // The stencil's taps t with a regressor i = m − t < n, in increasing t: an exclusive
    // range with no skip inside. The check runs this on every row; an inclusive range with
    // a `continue` per tap cost 21 more instructions per sample at n = 7, D = 16
    // (`cargo xtask bench step`, with the check live).
    for t in (m + 1).saturating_sub(n)..ORDER.min(m) + 1 {
        // Binomial stencils of the first and second difference.
        let stencil = match (ORDER, t) {
            (1, 0) => -T::ONE,
            (1, _) => T::ONE,
            (_, 1) => T::from_f64(-2.0),
            _ => T::ONE,
        };
        c -= lead[m - t] * stencil;
    }
    c
}

/// `Σ c_m²`: the data-driven residual's noise variance in block-mean variances.
pub(crate) fn difference_noise_gain<T: Real, const ORDER: usize>(lead: &[T], n: usize) -> T {
    let mut gain = T::ZERO;
    for m in 0..n + ORDER {
        let c = coefficient::<T, ORDER>(lead, n, m);
        gain += c * c;
    }
    gain
}

/// `γ₀² / (γ₀² + 2 Σ_h γ_h²)`: the share of independent rows in the squared residuals of a
/// moving average with coefficients `c` (O(n²)).
pub(crate) fn difference_correlation<T: Real, const ORDER: usize>(lead: &[T], n: usize) -> T {
    let terms = n + ORDER;
    let mut lag0 = T::ZERO;
    let mut lags = T::ZERO;
    for h in 0..terms {
        let mut gamma = T::ZERO;
        for m in 0..terms - h {
            gamma += coefficient::<T, ORDER>(lead, n, m) * coefficient::<T, ORDER>(lead, n, m + h);
        }
        if h == 0 {
            lag0 = gamma * gamma;
        } else {
            lags += gamma * gamma;
        }
    }
    let total = lag0 + lags + lags;
    if total > T::ZERO {
        lag0 / total
    } else {
        T::ONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_threshold_is_the_f_quantile_from_above() {
        // Exact upper 1e-5 quantiles of χ²_ν/ν and F(ν₁, ν₂) (mpmath: regularised incomplete
        // gamma and beta functions solved for the quantile). Paulson's approximation must
        // stay above them (a lower false-alarm rate than designed, never higher) and within
        // 12% (within 3% from 6 degrees of freedom).
        let exact: [(f64, f64, f64); 8] = [
            (1.0, 0.0, 19.511),
            (2.0, 0.0, 11.513),
            (6.0, 0.0, 5.5178),
            (64.0, 0.0, 1.9391),
            (1.0, 98.0 / 3.0, 27.216),
            (6.0, 98.0 / 3.0, 8.7814),
            (20.0, 148.0 / 3.0, 4.4477),
            (64.0, 98.0 / 3.0, 4.3062),
        ];
        for (nu1, nu2, quantile) in exact {
            let approximation = threshold(nu1, nu2);
            let excess = approximation / quantile - 1.0;
            let allowed = if nu1 >= 6.0 { 0.03 } else { 0.12 };
            assert!(
                (0.0..allowed).contains(&excess),
                "F({nu1}, {nu2}): {approximation} vs {quantile}"
            );
            let single = threshold(nu1 as f32, nu2 as f32) as f64;
            assert!((single / approximation - 1.0).abs() < 1e-5);
        }
        // No root: a reference from two differences can never flag.
        assert_eq!(threshold(10.0, 4.0 / 3.0), f64::INFINITY);
        assert_eq!(threshold(0.0, 0.0), f64::INFINITY);
    }

    /// `mismatch_at` answers a ratio at or below the allowance without the threshold: that
    /// holds only while the F quantile's approximation is at least 1, from 0.1 row to a
    /// million, with references from a few differences to exact, in f32 as in f64.
    #[test]
    fn the_threshold_is_never_below_the_allowance() {
        for nu2 in [0.0, 1.5, 2.0, 98.0 / 3.0, 1e3, 1e6] {
            let mut nu1 = 0.1;
            while nu1 < 1e6 {
                assert!(threshold(nu1, nu2) >= 1.0, "F({nu1}, {nu2})");
                assert!(
                    threshold(nu1 as f32, nu2 as f32) >= 1.0,
                    "F({nu1}, {nu2}) in f32"
                );
                nu1 *= 1.1;
            }
        }
        // Ratios just above the allowance still reach the threshold (large rows, exact
        // reference: the threshold is within a hair of the allowance).
        let reference = NoiseReference::exact(1.0);
        let mut check = ResidualCheck::new(&reference, 1.0, 1, 1.0);
        for _ in 0..100_000 {
            check.push(2.2, 1.0);
        }
        assert!(check.mismatch(|| 1.0));
        let mut check = ResidualCheck::new(&reference, 1.0, 1, 1.0);
        for _ in 0..100_000 {
            check.push(2.0, 1.0);
        }
        assert!(!check.mismatch(|| 1.0));
    }

    #[test]
    fn the_noise_coefficients_of_a_data_driven_residual() {
        // First differences, ℓ = [0.2, 0.5]: residual noise
        // e(k) − 0.2·(e(k−1) − e(k−2)) − 0.5·(e(k) − e(k−1)): c = [0.2, 0.3, 0.5], Σc = 1,
        // Σc² = 0.38; γ₁ = 0.06 + 0.15 = 0.21, γ₂ = 0.1: share 0.38²/(0.38² + 2·(0.21² + 0.1²)).
        let lead = [0.2, 0.5, 99.0];
        assert!((difference_noise_gain::<f64, 1>(&lead, 2) - 0.38).abs() < 1e-12);
        let share = 0.38f64.powi(2) / (0.38f64.powi(2) + 2.0 * (0.21f64.powi(2) + 0.01));
        assert!((difference_correlation::<f64, 1>(&lead, 2) - share).abs() < 1e-12);
        // Second differences (the ramp), ℓ = [0.2, 0.5]: residual noise
        // e(k) − 0.2·(e(k−3) − 2e(k−2) + e(k−1)) − 0.5·(e(k−2) − 2e(k−1) + e(k)):
        // c = [−0.2, 0.4 − 0.5, −0.2 + 1.0, 1 − 0.5] = [−0.2, −0.1, 0.8, 0.5], Σc = 1.
        let gain = 0.04 + 0.01 + 0.64 + 0.25;
        assert!((difference_noise_gain::<f64, 2>(&lead, 2) - gain).abs() < 1e-12);
        // ℓ all zero: the residual is the target's own noise, independent rows.
        assert_eq!(difference_noise_gain::<f64, 1>(&[0.0; 3], 3), 1.0);
        assert_eq!(difference_correlation::<f64, 1>(&[0.0; 3], 3), 1.0);
        assert_eq!(difference_noise_gain::<f64, 2>(&[0.0; 3], 3), 1.0);
    }

    #[test]
    fn the_ratio_is_the_weighted_mean_of_the_quotients() {
        let reference = NoiseReference::exact(8.0f64);
        // Raw unit = 1/2 of the residuals' unit (gain 2), D = 2: v = 8/(4·2) = 1.
        let mut check = ResidualCheck::new(&reference, 0.5, 2, 63.0 / 65.0);
        assert_eq!(check.ratio(), None);
        check.push(2.0, 1.0);
        assert_eq!(check.ratio(), Some(2.0));
        assert_eq!(check.effective_rows(), 1.0);
        check.push(4.0, 2.0);
        let beta = 63.0 / 65.0;
        assert!((check.ratio().unwrap() - (2.0 * beta + 2.0) / (beta + 1.0)).abs() < 1e-12);
        // A non-finite quotient is no evidence.
        check.push(1.0, 0.0);
        assert!(check.effective_rows() < 2.0 + 1e-12);
        assert!(!check.mismatch(|| 1.0));
        for _ in 0..10 {
            check.push(100.0, 1.0);
        }
        assert!(check.mismatch(|| 1.0));
        // Correlated residuals have fewer degrees of freedom: a higher threshold.
        assert!(!check.mismatch(|| 0.01));
    }
}
