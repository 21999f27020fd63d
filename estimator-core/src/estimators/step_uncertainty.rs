//! The standard uncertainty of the step estimator's level, online, in O(n³) per block.
//!
//! ## Why not the textbook `s²·(ΦᵀΦ)⁻¹`
//! The regression `x(k) = u + Σ ℓ_i·Δx(k−n+i)` has the measured differences on the right,
//! and the newest difference holds `x(k)` itself. Its equation error is therefore not
//! white: with block-mean noise `e`,
//!
//! ```text
//! ε(k) = Σ_{m=0..n} h_m·e(k−m),   h_0 = 1 − ℓ_{n−1},  h_m = ℓ_{n−m} − ℓ_{n−1−m},  h_n = ℓ_0
//! ```
//!
//! a moving average of order `n`, correlated with the regressors (errors in variables).
//! The white-noise formula ignores both, and a Monte Carlo of the shipped method found it
//! over-confident: ±2u held only 60–74 % of the errors (`tests/uncertainty.rs`).
//!
//! ## What is computed instead (a sandwich with the model's own noise structure)
//! To first order the error of the level is `zᵀ·Φᵀ·ε`, `z` the level's row of
//! `P = (ΦᵀΦ)⁻¹`. Its variance is `zᵀ·(Σ_l r_l·(S_l + S_lᵀ))·z` (the `l = 0` term once),
//! with `r_l` the autocovariance of `ε` at lag `l` (zero beyond `n`) and
//! `S_l = Σ_k φ_k·φ_{k−l}ᵀ` the lagged cross-products of the regression rows. `S_0 = ΦᵀΦ`
//! needs nothing stored (`zᵀ·S_0·z` is `z`'s last entry); the lags `1..=n` are summed here,
//! row by row, from a ring of the last `L` rows (`L ≥ n`, the lags kept; the step sums up
//! to `L`, below). The autocovariance comes from `h` (the current `ℓ`) and the noise level
//! from the residuals: `r_l = s²·Σ_m h_m h_{m+l} / Σ_m h_m²`, `s²` the residual mean
//! square. The regressors' noise also biases the level, by
//! `N·σ²·Σ_i z_i·(h_{n−1−i} − h_{n−i})` to first order (thesis eq. 4.15 in this form); it
//! is added to the variance, not corrected, so the estimate stays the thesis's.
//!
//! Noise that is not white (vibration near the resonance) is not that moving average: the
//! same sandwich is also taken with the residuals' own autocovariance, a truncated
//! (Hansen–White) long-run variance, and the larger of the two is stated. For the step
//! estimator over all `L` lags kept, not only the model's `n`: at D = 24 the reference
//! cell's 25 Hz period is 6.7 blocks, and with lags up to `n = 5` the rig's vibration at
//! 80 dB made ±2u cover 86.5 % at 400 ms (95.7 % with `L = 8`; `host-sim study coverage
//! --runs 1000 --seed 1`). Beyond `n` the lags taper linearly to zero after `L` (a Bartlett
//! window): untapered the sum's own scatter widened `u` on white noise enough to delay
//! the command scene's tare by 0.15 s on 2 of 10 noise seeds (98.7 % at 400 ms then),
//! tapered by 0.1 s on 1 of 10. Beyond `n` the rows' cross-products keep only their constant
//! column's part (from the rows' running total, O(n) per row for every lag):
//! the step's difference columns die out with the transient, and with the full products
//! every cell of that study's tables for the firmware default on the rig's noise and the
//! reference drop came out the same to 0.1 %, at 45 more instructions per sample. Not for
//! the ramp, whose regressors do not die out (its input is a line), nor for IV and bias
//! compensation: they sum their order's lags only.
//!
//! With few rows `s²` is itself uncertain: the stated `u` is multiplied by
//! `t_{0.975}(ν)/2` where that exceeds 1 (ν = rows − (n + 1)), so that ±2u is a 95 %
//! interval (GUM G.3); below [`MIN_DEGREES_OF_FREEDOM`] there is no `u` at all. Where the
//! empty pan's noise has been metered (the consistency check's reference), the residuals'
//! noise level is not taken below it. Where the empty pan's noise *colour* has been metered
//! (its block means' autocovariance, a step estimator with colour lags `C > 0`), none of
//! this applies: the sandwich takes the equation error's autocovariance from the metering
//! (`crate::estimators::metered_noise`, `LagSums::metered_uncertainty`).
//!
//! Only the growing window (λ = 1): with forgetting the lag-0 term needs `ΦᵀW²Φ` as well,
//! which is not kept, and the estimator states no `u`.

use crate::estimators::metered_noise::{chi_square_mean_95, MeteredNoise, MIN_METERED_BLOCKS};
use crate::estimators::noise_meter::AUTOCOVARIANCE_LAGS;
use crate::numerics::real::Real;
use crate::numerics::student::t_quantile;

/// Fewer residual degrees of freedom than this: no uncertainty is stated.
pub const MIN_DEGREES_OF_FREEDOM: u32 = 3;

/// A floor for the residuals' noise level, metered apart from the fit: the noise variance
/// of one block mean (the residuals' unit²) and the degrees of freedom it rests on. Where
/// the residuals' level lies below it the floor is the level stated, and `u`'s coverage
/// factor is the floor's degrees', not the residuals' few: the t-factor allows for a level
/// estimated from the residuals, not for one taken from elsewhere. Before stop 49 the
/// factor stayed the residuals': the firmware's scale 100 ms after the landing at 30–40 dB,
/// its run restarted on the landing it had just found and its `u` on the floor, covered
/// 99.3–99.4 % (RMS error/u 0.67–0.72) where the goal is 95 %, and 95.8–96.2 % with the
/// floor's factor (`host-sim study coverage --runs 1000 --seed 1`, the scale's tables).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct NoiseFloor<T> {
    /// The noise variance of one block mean.
    pub(crate) variance: T,
    /// What it was metered over; `None` where that is not known (the residuals' degrees
    /// then stay).
    pub(crate) degrees: Option<u32>,
}

impl<T: Real> NoiseFloor<T> {
    /// A floor of `variance` (none unless positive) metered over `degrees`.
    pub(crate) fn new(variance: T, degrees: Option<u32>) -> Option<Self> {
        (variance > T::ZERO).then_some(Self { variance, degrees })
    }

    /// The higher of two floors.
    pub(crate) fn higher(a: Option<Self>, b: Option<Self>) -> Option<Self> {
        match (a, b) {
            (Some(a), Some(b)) => Some(if b.variance > a.variance { b } else { a }),
            (a, b) => a.or(b),
        }
    }
}

/// The lagged cross-products of the regression rows for lags `1..=L`, and the residual
/// sum of squares, for orders `n ≤ L` (`L³ + 3L² + 3L` numbers with [`PerLag`], `6L² + 3L`
/// with [`Hankel`], whatever the estimator's capacity `N`). `L = 0` keeps nothing and gives
/// no uncertainty.
#[derive(Clone, Debug)]
pub(crate) struct LagSums<
    T: Real,
    const N: usize,
    const L: usize,
    const BEYOND_ORDER: bool = false,
    F: CrossForm<T, L> = PerLag,
> {
    /// The lagged cross-products of the difference columns, as `F` keeps them.
    cross: F::Sums,
    /// `C(K) = Σ_{k ≤ K} φ_k`, the rows' running total (padded to `L`). The sums the
    /// sandwich needs at lag `l`, `Σ_{k=l..K} φ_k` and `Σ_{k=l..K} φ_{k−l}` (the constant
    /// column of either row against the other's differences), are `C(K) − C(l−1)` and
    /// `C(K−l)`: from the totals, O(n) per row instead of O(L·n) for a sum per lag.
    total: [T; L],
    /// `C(l−1)` for `l = 1..=L`: the total after each of the first `L` rows.
    early: [[T; L]; L],
    /// The total before each of the last `L` rows was added, in `history`'s slots: the slot
    /// of row `K − l + 1` holds `C(K − l)`.
    totals_before: [[T; L]; L],
    /// The last `L` rows, the newest at `latest` (`u32`: an index below `L`, and the
    /// bare estimator's size stays within its goal).
    history: [[T; L]; L],
    latest: u32,
    /// Rows folded.
    rows: u32,
    /// Weighted a-priori residuals squared: the residual sum of squares.
    residual_sum: T,
    /// `Σ_k e_k·e_{k−l}` of the a-posteriori residuals `e`, lag `l` at index `l − 1` (over
    /// `residuals − l` pairs): the residuals' own autocovariance, for noise that is not white.
    residual_lags: [T; L],
    /// The last `L` a-posteriori residuals, the newest at `residual_latest`, and how many.
    residual_history: [T; L],
    residual_latest: u32,
    residuals: u32,
    /// The white noise's share of one block mean's variance (the residuals' unit²), below
    /// which the noise level is not taken (0 when not known), and the degrees of freedom it
    /// rests on: a [`NoiseFloor`] kept as its two numbers ([`Self::white_floor`]), since an
    /// `Option<NoiseFloor>` takes 8 bytes more and the order-7 estimator is at its 512-byte
    /// goal. Kept over resets by the estimator (`StepEstimator::set_white_noise`).
    white_variance: T,
    white_degrees: u32,
}

impl<T: Real, const N: usize, const L: usize, const BEYOND_ORDER: bool, F: CrossForm<T, L>>
    LagSums<T, N, L, BEYOND_ORDER, F>
{
    pub(crate) fn new() -> Self {
        Self {
            cross: F::zero(),
            total: [T::ZERO; L],
            early: [[T::ZERO; L]; L],
            totals_before: [[T::ZERO; L]; L],
            history: [[T::ZERO; L]; L],
            latest: 0,
            rows: 0,
            residual_sum: T::ZERO,
            residual_lags: [T::ZERO; L],
            residual_history: [T::ZERO; L],
            residual_latest: 0,
            white_variance: T::ZERO,
            white_degrees: 0,
            residuals: 0,
        }
    }

    /// The lags summed for an order `n`: every lag kept (`L`) where `BEYOND_ORDER` (the
    /// step estimator's residuals' autocovariance, see the module docs; beyond `n` the rows'
    /// cross-products keep only their constant column's part), else the order's `n`.
    #[inline]
    fn lags_for(&self, n: usize) -> usize {
        if BEYOND_ORDER {
            L
        } else {
            n
        }
    }

    /// Rows pushed.
    pub(crate) fn rows(&self) -> u32 {
        self.rows
    }

    /// The residual sum of squares of the residuals pushed.
    pub(crate) fn residual_sum(&self) -> T {
        self.residual_sum
    }

    /// Whether lags up to the order `n` are kept.
    pub(crate) fn covers(n: usize) -> bool {
        L >= n
    }

    /// One regression row `row[..n]` (the constant column implied), before it is folded.
    ///
    /// The rows are kept padded with zeros to `L` and the inner loops run over the constant
    /// `L`, which the compiler unrolls: bounded by `n` they cost about 9 instructions per
    /// product on the Cortex-M4F (a QEMU profile of `cargo xtask bench step`). The sums'
    /// entries below `n` are the same, bit for bit: the padding adds exact zeros.
    #[inline]
    pub(crate) fn push_row(&mut self, row: &[T; N], n: usize) {
        if !Self::covers(n) || L == 0 {
            return;
        }
        let row = pad::<T, N, L>(row, n);
        // The lags' full cross-products, for the model's lags (1..=n) only, those with a row
        // `lag` before this one.
        let held = (self.rows as usize).min(n);
        F::push(
            &mut self.cross,
            &NewRow {
                row: &row,
                n,
                held,
                number: self.rows,
                history: &self.history,
                latest: self.latest as usize,
            },
        );
        let latest = (self.latest as usize + 1) % L;
        self.latest = latest as u32;
        self.history[latest] = row;
        self.totals_before[latest] = self.total;
        for (total, &x) in self.total.iter_mut().zip(&row) {
            *total += x;
        }
        if let Some(early) = self.early.get_mut(self.rows as usize) {
            *early = self.total;
        }
        self.rows = self.rows.saturating_add(1);
    }

    /// The white-noise floor of a block mean's variance (see `white_variance`).
    pub(crate) fn white_floor(&self) -> Option<NoiseFloor<T>> {
        NoiseFloor::new(self.white_variance, Some(self.white_degrees))
    }

    /// Set the white-noise floor of a block mean's variance (see `white_variance`).
    pub(crate) fn set_white_floor(&mut self, floor: Option<NoiseFloor<T>>) {
        self.white_variance = floor.map_or(T::ZERO, |floor| floor.variance);
        self.white_degrees = floor.and_then(|floor| floor.degrees).unwrap_or(0);
    }

    /// The a-priori residual of a row folded into a determined problem and the row's
    /// weight (`1/(1 + φᵀPφ)`): `weight·residual²` is its contribution to the residual sum
    /// of squares, `weight·residual` its a-posteriori residual.
    pub(crate) fn push_residual(&mut self, residual: T, weight: T, n: usize) {
        let posterior = weight * residual;
        self.residual_sum += posterior * residual;
        if L == 0 || !Self::covers(n) {
            return;
        }
        let held = (self.residuals as usize).min(self.lags_for(n));
        for lag in 1..=held {
            let before = self.residual_history[ring_back::<L>(self.residual_latest as usize, lag)];
            self.residual_lags[lag - 1] += posterior * before;
        }
        let latest = (self.residual_latest as usize + 1) % L;
        self.residual_latest = latest as u32;
        self.residual_history[latest] = posterior;
        self.residuals = self.residuals.saturating_add(1);
    }

    /// The level's standard uncertainty (see the module docs) from `z` (the level's row of
    /// `P`: leading entries, then the constant's) and the current `ℓ` (`lead[..n]`);
    /// `None` when it cannot be stated. `block_noise_floor`: the noise variance of one
    /// block mean as metered on the empty pan, where known; the residuals' noise level is
    /// not taken below it.
    pub(crate) fn uncertainty(
        &self,
        n: usize,
        z: &[T; N],
        z_level: T,
        lead: &[T; N],
        block_noise_floor: Option<NoiseFloor<T>>,
    ) -> Option<(T, u32)> {
        if !Self::covers(n) {
            return None;
        }
        let noise_model = NoiseModel::first_differences(lead, n);
        let quadratic = Quadratic {
            z,
            z_level,
            lag0: z_level,
        };
        let (variance, noise, degrees) = self.variance(
            n,
            &noise_model,
            quadratic,
            self.residual_sum,
            block_noise_floor,
        )?;
        let bias = self.errors_in_variables_bias(n, z, &noise_model, noise);
        stated(with_bias(variance, bias)?, degrees)
    }

    /// The first-order errors-in-variables bias of the least-squares level whose row of `P`
    /// is `z` (leading entries): `E[φ_k·ε_k]` per row, times the rows (thesis eq. 4.15), for
    /// the first-difference regression with block-mean noise variance `noise`.
    fn errors_in_variables_bias(
        &self,
        n: usize,
        z: &[T; N],
        noise_model: &NoiseModel<T, L>,
        noise: T,
    ) -> T {
        let mut bias = T::ZERO;
        for (i, &zi) in z[..n].iter().enumerate() {
            bias += zi * (noise_model.at(n, n - 1 - i) - noise_model.at(n, n - i));
        }
        bias * (T::from_u32(self.rows) * noise)
    }

    /// The variance of `zᵀ·θ̂` for a consistent estimator of the first-difference
    /// regression (instrumental variables, bias compensation), the block means' noise
    /// variance and the degrees of freedom: `z` is how the rows' equation errors reach the
    /// estimate (`δ = zᵀ·Σ_k ψ_k·ε_k`, `ψ_k` the rows pushed) and `lag0` = `zᵀ·S_0·z`;
    /// `residual_sum` is the sum of squares of the estimate's own residuals over the rows
    /// (`rows − (n + 1)` degrees of freedom) and `lead` its `ℓ`. No errors-in-variables bias
    /// is added: the caller removes it. [`stated`] turns the variance into `u`.
    pub(crate) fn consistent_variance(
        &self,
        n: usize,
        quadratic: Quadratic<'_, T, N>,
        lead: &[T; N],
        residual_sum: T,
        block_noise_floor: Option<NoiseFloor<T>>,
    ) -> Option<(T, T, u32)> {
        if !Self::covers(n) {
            return None;
        }
        let noise_model = NoiseModel::first_differences(lead, n);
        self.variance(n, &noise_model, quadratic, residual_sum, block_noise_floor)
    }

    /// The sandwich's variance, the block-mean noise variance and the degrees of freedom,
    /// for `lags` lags of an equation error whose moving average is `noise_model` and whose
    /// residual sum of squares is `residual_sum` (`rows − (lags + 1)` degrees of freedom:
    /// `lags` leading columns and the constant); `None` below [`MIN_DEGREES_OF_FREEDOM`].
    pub(crate) fn variance(
        &self,
        lags: usize,
        noise_model: &NoiseModel<T, L>,
        quadratic: Quadratic<'_, T, N>,
        residual_sum: T,
        block_noise_floor: Option<NoiseFloor<T>>,
    ) -> Option<(T, T, u32)> {
        if !Self::covers(lags) || L == 0 {
            return None;
        }
        let degrees = self.rows.checked_sub(lags as u32 + 1)?;
        if degrees < MIN_DEGREES_OF_FREEDOM {
            return None;
        }
        let mean_square = residual_sum / T::from_u32(degrees);
        let (variance, noise, floored) =
            self.sandwich(lags, noise_model, quadratic, mean_square, block_noise_floor)?;
        // The level stated is the floor's: its degrees of freedom, where known.
        let degrees = match (floored, block_noise_floor.and_then(|floor| floor.degrees)) {
            (true, Some(metered)) => metered,
            _ => degrees,
        };
        Some((variance, noise, degrees))
    }

    /// The variance of `zᵀ·Σ_k ψ_k·ε_k` for the moving-average equation error (module docs)
    /// whose level is `mean_square` (the residuals'), the block means' noise variance it
    /// implies, and whether that is the floor's (the model's lags stated, the residuals'
    /// level below the floor); `None` for a moving average without power.
    fn sandwich(
        &self,
        lags: usize,
        noise_model: &NoiseModel<T, L>,
        quadratic: Quadratic<'_, T, N>,
        mean_square: T,
        block_noise_floor: Option<NoiseFloor<T>>,
    ) -> Option<(T, T, bool)> {
        let n = lags;
        let Quadratic { z, z_level, lag0 } = quadratic;
        let mut power = noise_model.h_last * noise_model.h_last;
        for &value in &noise_model.h[..n] {
            power += value * value;
        }
        if !(power > T::ZERO) {
            return None;
        }
        // e's variance (block means), and the level's variance term by term; never below
        // the metered noise where there is one: a fresh fit of few rows on a signal
        // without a transient (a run restarted on a trickle) all but interpolated its
        // data, its residual level 170 times below the block means' noise, and stated
        // u = 0.0016 g on 1 g of raw noise, shown final 0.13 g off (test
        // `a_fit_without_a_transient_is_not_overconfident_with_metered_noise`).
        let mut noise = mean_square / power;
        let mut mean_square = mean_square;
        let mut floored = false;
        if let Some(floor) = block_noise_floor {
            if noise < floor.variance {
                noise = floor.variance;
                mean_square = floor.variance * power;
                floored = true;
            }
        }
        // Padded to `L` for the constant-bound loops (see `push_row`).
        let z = pad::<T, N, L>(z, n);
        let mut variance = mean_square * lag0;
        // The same with the residuals' own autocovariance at lags 1..L (noise that is not
        // white: vibration near the resonance made the model's `u` over-confident, 73 % at
        // 80 dB on the rig's noise, and 86.5 % at 400 ms with the lags up to `n = 5` only:
        // at D = 24 a 25 Hz vibration's period is 6.7 blocks); the larger of the two is
        // stated.
        let mut observed = variance;
        // The step's residuals' autocovariance is summed over every lag kept (`L`, whatever
        // the order): a vibration near the resonance stays correlated for longer than `n`
        // blocks (see the module docs). Without residuals only the model's lags count.
        let observed_lags = if self.residuals > 0 {
            self.lags_for(n)
        } else {
            n
        };
        let total = self.total_along(&z);
        let forms = F::forms(&self.cross, n, &z);
        // Σ_l 2·|r_l| over the lags whose forms `rounding` speaks for, model's and observed.
        let (mut model_spread, mut observed_spread) = (T::ZERO, T::ZERO);
        for lag in 1..=observed_lags {
            // The model's lags (1..=n): its moving average's autocovariance, and the rows'
            // full cross-products. Beyond n the model's covariance is zero and only the
            // constant column's part is kept.
            let model_lag = lag <= n;
            let mut covariance = T::ZERO;
            if model_lag {
                // Σ_{m=0..n−lag} h_m·h_{m+lag}, the last term's h_n kept apart (as `at` has it).
                let h = &noise_model.h;
                for (&early, &late) in h[..n - lag].iter().zip(&h[lag..n]) {
                    covariance += early * late;
                }
                covariance += h[n - lag] * noise_model.h_last;
            }
            let quadratic = self.lag_quadratic(lag, n, &z, z_level, total, &forms);
            if model_lag {
                let weight = T::from_f64(2.0) * noise * covariance;
                variance += weight * quadratic;
                model_spread += weight.abs();
            }
            if let Some(lagged) = self.residual_autocovariance(lag, n) {
                let weight = T::from_f64(2.0) * lagged;
                observed += weight * quadratic;
                if model_lag {
                    observed_spread += weight.abs();
                }
            }
        }
        let rounding = self.rounding(n, &z, z_level, total, &forms, lag0);
        variance += model_spread * rounding;
        observed += observed_spread * rounding;
        // Only where residuals were pushed to observe (the estimators without them have
        // `observed` at lag 0 alone, which would undo the lags).
        if self.residuals > 0 && observed > variance {
            variance = observed;
            floored = false;
        }
        Some((variance, noise, floored))
    }
}

impl<T: Real, const N: usize, const L: usize, const BEYOND_ORDER: bool, F: CrossForm<T, L>>
    LagSums<T, N, L, BEYOND_ORDER, F>
{
    /// The level's standard uncertainty from the empty pan's metered autocovariance
    /// (`crate::estimators::metered_noise`) for `z`, `z_level` and `ℓ` (`lead[..n]`) as in
    /// [`Self::uncertainty`]; `None` without a metering that saw every row of the run, below
    /// [`MIN_DEGREES_OF_FREEDOM`], or for an equation error without power. The module docs
    /// of `metered_noise` say what it computes.
    #[inline(never)]
    pub(crate) fn metered_uncertainty<const C: usize>(
        &self,
        n: usize,
        z: &[T; N],
        z_level: T,
        lead: &[T; N],
        metered: &MeteredNoise<T, L, C>,
        influence: impl Fn(&[T; N]) -> Option<[T; N]>,
    ) -> Option<(T, u32)> {
        if !Self::covers(n) || L == 0 || !metered.covers_run(self.rows) {
            return None;
        }
        let degrees = self.rows.checked_sub(n as u32 + 1)?;
        if degrees < MIN_DEGREES_OF_FREEDOM {
            return None;
        }
        let model = NoiseModel::<T, L>::first_differences(lead, n);
        // h_0..h_n in one array (n < the metered lags: `MeteredNoise::lags`), for loops
        // over slices.
        let mut h = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        h[..n].copy_from_slice(&model.h[..n]);
        h[n] = model.h_last;
        let h = &h[..=n];
        // ρ(m) = Σ_a h_a·h_{a+m}, m = 0..=n.
        let mut rho = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        for (m, value) in rho[..=n].iter_mut().enumerate() {
            for (&early, &late) in h.iter().zip(&h[m..]) {
                *value += early * late;
            }
        }
        let rho = &rho[..=n];
        let gamma = metered.lags_array();
        // γ_ε(l) = Σ_{m=−n..n} ρ(|m|)·γ(|l + m|) for the sandwich's lags (`l + n` is within
        // the metered lags: `MeteredNoise::lags`).
        let lags = metered.lags(n).min(self.rows.saturating_sub(1) as usize);
        let mut equation_error = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        for (lag, value) in equation_error[..=lags].iter_mut().enumerate() {
            let mut sum = rho[0] * gamma[lag];
            for (&weight, &later) in rho[1..].iter().zip(&gamma[lag + 1..]) {
                sum += weight * later;
            }
            if lag >= n {
                for (&weight, &earlier) in rho[1..].iter().zip(gamma[lag - n..lag].iter().rev()) {
                    sum += weight * earlier;
                }
            } else {
                for (m, &weight) in rho.iter().enumerate().skip(1) {
                    sum += weight * gamma[lag.abs_diff(m)];
                }
            }
            *value = sum;
        }
        let power = equation_error[0];
        if !(power > T::ZERO) {
            return None;
        }
        let z_padded = pad::<T, N, L>(z, n);
        let total = self.total_along(&z_padded);
        let forms = F::forms(&self.cross, n, &z_padded);
        let mut variance = power * z_level;
        // Σ_l 2·|γ_ε(l)| over the lags whose forms `rounding` speaks for.
        let mut spread = T::ZERO;
        // `[z; z_level]ᵀ·S_lag·[z; z_level]` by lag (at `lag − 1`), kept for the residuals'
        // own sandwich below should they need it.
        let mut quadratics = [T::ZERO; L];
        for (lag, &covariance) in equation_error[1..=lags.min(n)].iter().enumerate() {
            let lag = lag + 1;
            let quadratic = self.lag_quadratic(lag, n, &z_padded, z_level, total, &forms);
            quadratics[lag - 1] = quadratic;
            let weight = T::from_f64(2.0) * covariance;
            variance += weight * quadratic;
            spread += weight.abs();
        }
        let rounding = self.rounding(n, &z_padded, z_level, total, &forms, z_level);
        variance += spread * rounding;
        if lags > n {
            variance += T::from_f64(2.0)
                * metered.constant_parts(
                    &equation_error[..=lags],
                    n + 1,
                    &z_padded,
                    z_level,
                    self.rows,
                );
        }
        // The errors-in-variables bias with the coloured noise (module docs of
        // `metered_noise`): E[φ_k·ε_k] per row, entry i, is d(n−1−i) − d(n−i) with
        // d(k) = Σ_m h_m·γ(|m − k|).
        let mut shifted = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        for (k, value) in shifted[..=n].iter_mut().enumerate() {
            for (m, &hm) in h.iter().enumerate() {
                *value += hm * gamma[m.abs_diff(k)];
            }
        }
        let mut bias = T::ZERO;
        for (&zi, pair) in z[..n].iter().rev().zip(shifted[..=n].windows(2)) {
            bias += zi * (pair[0] - pair[1]);
        }
        bias *= T::from_u32(self.rows);
        // The bias's own scatter. Evaluated on the run's own `ℓ`, which a fit of few rows
        // knows poorly, `E[b̂²] = b² + var(b̂)`: `b̂²` alone overstates the bias it stands
        // for, and kept the rig's noise at 70–80 dB 100 ms after the landing cautious
        // (±2u 98.8 % and 99.1 %). To first order in `ℓ` (for the run's `z`), `b̂ = a + gᵀℓ`
        // with `g_j = N·Σ_i z_i·(e_j(n−1−i) − e_j(n−i))`, `e_j(k) = γ(|n−j−k|) −
        // γ(|n−1−j−k|)` (`h_m` holds `+ℓ_j` at `m = n − j` and `−ℓ_j` at `m = n − 1 − j`),
        // and `var(b̂) ≈ γ_ε(0)·gᵀ·P·g`: the lag-0 term of `ℓ`'s sandwich, `P·[g; 0]` by one
        // forward and one back substitution (`influence`). Not the whole sandwich along
        // `P·[g; 0]`: its lag forms are small differences of large products at 11 rows, and
        // in `f32` their rounding allowance was as large as the scatter itself (at its
        // lower end, 98.7 % and 99.1 % again; at its upper end 97.6 % and 98.1 %, f64 96.5 %
        // and 96.7 %). With the lag-0 term: 97.5 % and 97.8 % (f64 96.2 % and 96.4 %), every
        // other cell of the step method's tables within 92–98 % as before (`host-sim study
        // coverage --runs 1000 --seed 1`).
        // `g_j` with `s = n − j`: `N·Σ_i z_i·Δ²γ(s − (n−1−i))`, `Δ²γ(m) = γ(|m|) −
        // 2γ(|m − 1|) + γ(|m − 2|)` for `m` in `2 − n..=n` (kept at `m + n − 2`).
        let mut second = [T::ZERO; 2 * AUTOCOVARIANCE_LAGS];
        for (index, value) in second[..2 * n - 1].iter_mut().enumerate() {
            let m = index as isize + 2 - n as isize;
            let at = |k: isize| gamma[k.unsigned_abs()];
            *value = at(m) - (at(m - 1) + at(m - 1)) + at(m - 2);
        }
        let mut g = [T::ZERO; N];
        for (j, value) in g[..n].iter_mut().enumerate() {
            // m = (n − j) − (n − 1 − i) = i + 1 − j, at index i + n − 1 − j.
            let mut sum = T::ZERO;
            for (&zi, &d2) in z[..n].iter().zip(&second[n - 1 - j..2 * n - 1 - j]) {
                sum += zi * d2;
            }
            *value = sum * T::from_u32(self.rows);
        }
        let scatter = influence(&g).map_or(T::ZERO, |w| {
            let mut along = T::ZERO;
            for (&gj, &wj) in g[..n].iter().zip(&w[..n]) {
                along += gj * wj;
            }
            power * along
        });
        // Residuals above what the metered noise explains: the residuals' own sandwich
        // (their autocovariance over the lags kept, as without a metering) where it is the
        // larger, the bias scaled by the ratio, and the t-factor. Not the metered variance
        // scaled by the ratio: an excess of narrow-band vibration near the loaded resonance
        // reaches the level far less than its power says, and the scaled variance held
        // ±2u in 98.3 % of the runs 400 ms after the landing under floor vibration at 80 dB
        // (RMS error/u 0.83; the firmware's scale 98.4–99.2 % at 70–80 dB), the residuals'
        // sandwich 95.7 % (scale 95.1–96.0 %; `host-sim study coverage --runs 1000 --seed 1`).
        let mean_square = self.residual_sum / T::from_u32(degrees);
        let ratio = mean_square / power;
        // Otherwise the noise level rests on the metering's block means, not on the
        // residuals: at least MIN_METERED_BLOCKS degrees of freedom (what the final
        // reading's bound on the noise level reads, `Reading::uncertainty_bound`).
        let (variance, bias_scale, factor, degrees) = if ratio > chi_square_mean_95::<T>(degrees) {
            let factor = coverage_factor::<T>(degrees);
            let mut observed = mean_square * z_level;
            let mut observed_spread = T::ZERO;
            for lag in 1..=self.lags_for(n) {
                if let Some(lagged) = self.residual_autocovariance(lag, n) {
                    // Those up to the metered lags and the order were computed above.
                    let quadratic = if lag <= lags.min(n) {
                        quadratics[lag - 1]
                    } else {
                        self.lag_quadratic(lag, n, &z_padded, z_level, total, &forms)
                    };
                    let weight = T::from_f64(2.0) * lagged;
                    observed += weight * quadratic;
                    if lag <= n {
                        observed_spread += weight.abs();
                    }
                }
            }
            observed += observed_spread * rounding;
            let variance = if observed > variance {
                observed
            } else {
                variance
            };
            (variance, ratio, factor, degrees)
        } else {
            (variance, T::ONE, T::ONE, MIN_METERED_BLOCKS)
        };
        let total_variance = with_bias_scatter(
            variance,
            bias * bias_scale,
            scatter * bias_scale * bias_scale,
        )?;
        if !total_variance.is_finite() {
            return None;
        }
        Some((total_variance.sqrt() * factor, degrees))
    }

    /// The residuals' own autocovariance at `lag` (`1..=L`) for an order `n`, tapered beyond
    /// `n` linearly to zero after `L` (Bartlett; see the module docs); `None` without a pair
    /// of residuals `lag` apart.
    #[inline]
    fn residual_autocovariance(&self, lag: usize, n: usize) -> Option<T> {
        // The pairs of residuals `lag` apart: every residual after the first `lag`.
        let pairs = self
            .residuals
            .checked_sub(lag as u32)
            .filter(|&pairs| pairs > 0)?;
        let lagged = self.residual_lags[lag - 1] / T::from_u32(pairs);
        let taper = if lag <= n {
            T::ONE
        } else {
            T::from_u32((L + 1 - lag) as u32) / T::from_u32((L + 1 - n) as u32)
        };
        Some(taper * lagged)
    }

    /// How far the lags' quadratic forms along `[z; z_level]` (`z` padded) may be off in
    /// `T`'s rounding: the lag-0 form computed from the sums as theirs are, against its
    /// value `lag0` known without them (`z_level` for the step's row of `P`); zero where
    /// `F` keeps no `S_0`.
    ///
    /// The forms are small differences of large products where the fit's row of `P` is
    /// large (few rows, columns nearly collinear), and in `f32` they can lose every digit:
    /// 100 ms after the landing on the rig's noise at 80 dB the step's metered sandwich
    /// came out negative in 71 of 1,000 runs (1 in `f64` on the same data), and positive
    /// but far too small in others (one run's error was 16 times its `u`). Each lag's form
    /// is taken to be off by as much as the lag-0 one, so the variance is stated at
    /// `Σ_l 2·|r_l|·rounding` above the sum (its upper end).
    fn rounding(&self, n: usize, z: &[T; L], z_level: T, total: T, forms: &F::Forms, lag0: T) -> T {
        match F::square_products(forms, z, n) {
            Some(square) => {
                let rows = T::from_u32(self.rows);
                let computed = square + z_level * (T::from_f64(2.0) * total + z_level * rows);
                (computed - lag0).abs()
            }
            None => T::ZERO,
        }
    }

    /// `zᵀ·C(K)` for `z` padded to `L`: the newest rows' share of every lag's
    /// constant-column part (see `total`), the same for every lag.
    #[inline]
    fn total_along(&self, z: &[T; L]) -> T {
        let mut total = T::ZERO;
        for (&sum, &zi) in self.total.iter().zip(z) {
            total += sum * zi;
        }
        total
    }

    /// `[z; z_level]ᵀ·S_lag·[z; z_level]` (module docs) for `z` padded to `L` and
    /// `total = self.total_along(z)`: the rows' full cross-products for the model's lags
    /// (`lag ≤ n`), and beyond them the constant column's part only, over the rows with a
    /// row `lag` before them.
    #[inline]
    fn lag_quadratic(
        &self,
        lag: usize,
        n: usize,
        z: &[T; L],
        z_level: T,
        total: T,
        forms: &F::Forms,
    ) -> T {
        let index = lag - 1;
        // The rows with a row `lag` before them.
        let pairs = self.rows.saturating_sub(lag as u32);
        let has_pairs = pairs > 0;
        let mut quadratic = if lag <= n {
            F::lag_products(
                &self.cross,
                forms,
                &Lag {
                    lag,
                    n,
                    z,
                    has_pairs,
                },
            )
        } else {
            T::ZERO
        };
        if has_pairs {
            // Σ_{k=lag..K} (φ_k + φ_{k−lag})·z = zᵀ·(C(K) − C(lag−1) + C(K−lag)).
            let older = &self.totals_before[ring_back::<L>(self.latest as usize, lag)];
            let mut sides = total;
            for ((&early, &older), &zi) in self.early[index].iter().zip(older).zip(z) {
                sides += (older - early) * zi;
            }
            quadratic += z_level * (sides + z_level * T::from_u32(pairs));
        }
        quadratic
    }
}

/// How [`LagSums`] keeps the rows' lagged cross-products `S_l = Σ_{k=l..K} φ_k·φ_{k−l}ᵀ`
/// (difference columns padded to `L`, lags up to the order): [`PerLag`] for rows of any
/// structure, [`Hankel`] for the step's window of differences. A type, not a flag: each
/// keeps only its own sums (the bias-compensated estimator without lag sums stays within
/// its size goal).
pub(crate) trait CrossForm<T: Real, const L: usize> {
    /// The sums kept.
    type Sums: Clone + core::fmt::Debug;
    /// What one uncertainty needs of them along its `z`, computed once for every lag.
    type Forms;
    /// Nothing summed yet.
    fn zero() -> Self::Sums;
    /// Fold a new row.
    fn push(sums: &mut Self::Sums, new: &NewRow<'_, T, L>);
    /// The products along `z` (padded to `L`) for an order `n`.
    fn forms(sums: &Self::Sums, n: usize, z: &[T; L]) -> Self::Forms;
    /// `zᵀ·S_lag·z` over the leading columns (`lag ≤ n`).
    fn lag_products(sums: &Self::Sums, forms: &Self::Forms, lag: &Lag<'_, T, L>) -> T;
    /// `zᵀ·S_0·z` over the leading columns, computed from the sums as the lags' products
    /// are; `None` where `S_0` is not kept.
    fn square_products(forms: &Self::Forms, z: &[T; L], n: usize) -> Option<T>;
}

/// A row for [`CrossForm::push`]: the padded `row` (row number `number`, 0 for the first),
/// to fold for the lags `1..=held` (`held ≤ n`, those with a row `lag` before it);
/// `history[latest]` is the previous row, `history[latest − (lag − 1)]` the one `lag` back.
pub(crate) struct NewRow<'a, T, const L: usize> {
    row: &'a [T; L],
    n: usize,
    held: usize,
    number: u32,
    history: &'a [[T; L]; L],
    latest: usize,
}

impl<T: Copy, const L: usize> NewRow<'_, T, L> {
    /// The row `lag` rows before this one.
    fn before(&self, lag: usize) -> &[T; L] {
        &self.history[ring_back::<L>(self.latest, lag)]
    }
}

/// A lag for [`CrossForm::lag_products`]: `lag ≤ n`, `z` padded to `L`, and whether a row
/// `lag` before the newest exists (`has_pairs`).
pub(crate) struct Lag<'a, T, const L: usize> {
    lag: usize,
    n: usize,
    z: &'a [T; L],
    has_pairs: bool,
}

/// Each lag's `S_l`, lag `l` at index `l − 1`: O(n²) per lag and row.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PerLag;

impl<T: Real, const L: usize> CrossForm<T, L> for PerLag {
    type Sums = [[[T; L]; L]; L];
    type Forms = ();

    fn zero() -> Self::Sums {
        [[[T::ZERO; L]; L]; L]
    }

    #[inline]
    fn push(products: &mut Self::Sums, new: &NewRow<'_, T, L>) {
        let &NewRow { row, n, held, .. } = new;
        for lag in 1..=held {
            // A copy: held in registers across the products (a reference is reloaded).
            let before = *new.before(lag);
            for (products, &x) in products[lag - 1][..n].iter_mut().zip(row) {
                for (product, &y) in products.iter_mut().zip(&before) {
                    *product += x * y;
                }
            }
        }
    }

    fn forms(_: &Self::Sums, _: usize, _: &[T; L]) -> Self::Forms {}

    fn square_products(_: &Self::Forms, _: &[T; L], _: usize) -> Option<T> {
        None
    }

    #[inline]
    fn lag_products(products: &Self::Sums, _: &Self::Forms, lag: &Lag<'_, T, L>) -> T {
        let &Lag { lag, n, z, .. } = lag;
        let mut quadratic = T::ZERO;
        for (products, &zi) in products[lag - 1][..n].iter().zip(z) {
            let mut row = T::ZERO;
            for (&product, &zj) in products.iter().zip(z) {
                row += product * zj;
            }
            quadratic += zi * row;
        }
        quadratic
    }
}

/// Hankel rows, `φ_k[i] = d(k + i)` (the step's window of differences): then
/// `S_l[i][j] = S_{l−1}[i][j−1] − d(l−1+i)·d(j−1)` (the sum over rows `l−1..K` less its
/// first row), so every `S_l` follows from `S_0`, each lag's first column and the first `L`
/// rows (`d(p + i) = φ_p[i]`): O(n²) per row for all lags instead of O(n³), and O(n²) per
/// uncertainty instead of O(n³). At n = 7, D = 16 on the Cortex-M4F: 1,008.5 → 977.3
/// instructions per sample (`cargo xtask bench step`, stop 29).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Hankel;

/// [`Hankel`]'s sums.
#[derive(Clone, Debug)]
pub(crate) struct HankelSums<T, const L: usize> {
    /// `S_0 = Σ_k φ_k·φ_kᵀ`.
    square: [[T; L]; L],
    /// `S_l[·][0]`, lag `l` at index `l − 1`.
    first_column: [[T; L]; L],
    /// The first `L` rows.
    first_rows: [[T; L]; L],
}

/// [`Hankel`]'s products along the uncertainty's `z`: `square[m] = (S_0·z)_m`,
/// `first_column[l−1] = zᵀ·S_l[·][0]`, `leading[p] = Σ_i z_i·d(p+i)` and
/// `trailing[t] = Σ_j z_{j+t}·d(j)`.
pub(crate) struct HankelForms<T, const L: usize> {
    square: [T; L],
    first_column: [T; L],
    leading: [T; L],
    trailing: [T; L],
}

impl<T: Real, const L: usize> CrossForm<T, L> for Hankel {
    type Sums = HankelSums<T, L>;
    type Forms = HankelForms<T, L>;

    fn zero() -> Self::Sums {
        HankelSums {
            square: [[T::ZERO; L]; L],
            first_column: [[T::ZERO; L]; L],
            first_rows: [[T::ZERO; L]; L],
        }
    }

    #[inline]
    fn push(sums: &mut Self::Sums, new: &NewRow<'_, T, L>) {
        let &NewRow {
            row,
            n,
            held,
            number,
            ..
        } = new;
        for (products, &x) in sums.square[..n].iter_mut().zip(row) {
            for (product, &y) in products.iter_mut().zip(row) {
                *product += x * y;
            }
        }
        for lag in 1..=held {
            let y = new.before(lag)[0];
            for (product, &x) in sums.first_column[lag - 1].iter_mut().zip(row) {
                *product += x * y;
            }
        }
        if let Some(first) = sums.first_rows.get_mut(number as usize) {
            *first = *row;
        }
    }

    fn forms(sums: &Self::Sums, n: usize, z: &[T; L]) -> Self::Forms {
        let mut forms = HankelForms {
            square: [T::ZERO; L],
            first_column: [T::ZERO; L],
            leading: [T::ZERO; L],
            trailing: [T::ZERO; L],
        };
        for (products, &zi) in sums.square[..n].iter().zip(z) {
            for (form, &product) in forms.square.iter_mut().zip(products) {
                *form += product * zi;
            }
        }
        for (form, products) in forms.first_column[..n].iter_mut().zip(&sums.first_column) {
            for (&product, &zi) in products.iter().zip(z) {
                *form += product * zi;
            }
        }
        // d(p + i) is the first rows' φ_p[i], and d(j) for j < n row 0's φ_0[j].
        for (form, row) in forms.leading[..n].iter_mut().zip(&sums.first_rows) {
            for (&x, &zi) in row.iter().zip(z) {
                *form += x * zi;
            }
        }
        let row = &sums.first_rows[0];
        for (t, form) in forms.trailing[..n].iter_mut().enumerate().skip(1) {
            for (&zj, &x) in z[t..n].iter().zip(row) {
                *form += zj * x;
            }
        }
        forms
    }

    fn square_products(forms: &Self::Forms, z: &[T; L], n: usize) -> Option<T> {
        let mut products = T::ZERO;
        for (&form, &zi) in forms.square[..n].iter().zip(z) {
            products += form * zi;
        }
        Some(products)
    }

    /// `S_l[i][j]` is `S_{l−j}[i][0]` (j < l) or `S_0[i][j−l]` (j ≥ l), less the first
    /// rows' products `Σ_{t=1..min(l,j)} d(l−t+i)·d(j−t)`; with no pair yet `S_l` is zero.
    #[inline]
    fn lag_products(_: &Self::Sums, forms: &Self::Forms, lag: &Lag<'_, T, L>) -> T {
        let &Lag {
            lag,
            n,
            z,
            has_pairs,
        } = lag;
        if !has_pairs {
            return T::ZERO;
        }
        let mut columns = T::ZERO;
        for j in 0..lag {
            columns += z[j] * forms.first_column[lag - 1 - j];
        }
        let mut square = T::ZERO;
        for j in lag..n {
            square += z[j] * forms.square[j - lag];
        }
        let mut first = T::ZERO;
        for t in 1..=lag.min(n - 1) {
            first += forms.leading[lag - t] * forms.trailing[t];
        }
        (columns + square) - first
    }
}

/// How an estimate reaches the rows' equation errors, for [`LagSums`]' sandwich: `z` (its
/// leading entries) and `z_level` (the constant column's) weigh the rows, and `lag0` is the
/// lag-0 term `zᵀ·S_0·z` (the rows' own cross-products, which the lag sums do not keep).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Quadratic<'a, T, const N: usize> {
    pub z: &'a [T; N],
    pub z_level: T,
    pub lag0: T,
}

/// The moving-average coefficients `h_0..h_q` of an equation error (`q ≤ L` lags), `h_q`
/// apart because `L + 1` is no array length.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NoiseModel<T, const L: usize> {
    pub h: [T; L],
    pub h_last: T,
}

impl<T: Real, const L: usize> NoiseModel<T, L> {
    /// The moving average of the first-difference regression's equation error (module
    /// docs), of order `n ≤ L` (checked by the caller), from its `ℓ` (`lead[..n]`).
    pub(crate) fn first_differences<const N: usize>(lead: &[T; N], n: usize) -> Self {
        let mut h = [T::ZERO; L];
        for (m, value) in h[..n].iter_mut().enumerate() {
            *value = moving_average(lead, n, m);
        }
        Self {
            h,
            h_last: moving_average(lead, n, n),
        }
    }

    /// `h_m` of a moving average of order `q`.
    #[inline]
    fn at(&self, q: usize, m: usize) -> T {
        if m < q {
            self.h[m]
        } else {
            self.h_last
        }
    }
}

/// The slot of a ring of `L` whose newest entry is at `latest`, `lag` entries before it
/// counted from 1 (`lag = 1`: the newest itself).
#[inline]
fn ring_back<const L: usize>(latest: usize, lag: usize) -> usize {
    (latest + L - (lag - 1)) % L
}

/// `v[..n]` followed by zeros, `L` long (`n ≤ L`, checked by the caller).
#[inline]
fn pad<T: Real, const N: usize, const L: usize>(v: &[T; N], n: usize) -> [T; L] {
    let mut padded = [T::ZERO; L];
    padded[..n].copy_from_slice(&v[..n]);
    padded
}

/// The sandwich's `variance` with the errors-in-variables `bias` added (module docs);
/// `None` unless the variance itself is positive. In `f32` the lag sums' quadratic forms
/// cancel on a fit of few rows whose level row of `P` is large (the step 100 ms after the
/// landing on the rig's noise at 80 dB: the metered sandwich came out negative in 71 of
/// 1,000 runs, positive in all but one in `f64` on the same data), and the sum of
/// the terms is then no variance at all: with the bias added it stated a `u` that was the
/// bias alone (`host-sim study coverage`, instrumented, stop 51). Without a variance there
/// is no `u`; the next block's usually has one.
pub(crate) fn with_bias<T: Real>(variance: T, bias: T) -> Option<T> {
    (variance > T::ZERO).then(|| variance + bias * bias)
}

/// [`with_bias`] with the bias's own scatter `scatter` (its estimate's variance) taken off
/// its square, never below zero: `E[b̂²] = b² + var(b̂)` (see
/// `LagSums::metered_uncertainty`). A scatter that is not a number takes nothing off.
pub(crate) fn with_bias_scatter<T: Real>(variance: T, bias: T, scatter: T) -> Option<T> {
    let square = bias * bias;
    // Written so that a NaN scatter keeps the whole square.
    let square = if square - scatter >= T::ZERO {
        square - scatter
    } else if scatter > square {
        T::ZERO
    } else {
        square
    };
    (variance > T::ZERO).then(|| variance + square)
}

/// `u = √variance`, times the t-factor of `degrees`; `None` for a variance that is not
/// finite and positive.
pub(crate) fn stated<T: Real>(variance: T, degrees: u32) -> Option<(T, u32)> {
    if !(variance > T::ZERO && variance.is_finite()) {
        return None;
    }
    Some((variance.sqrt() * coverage_factor::<T>(degrees), degrees))
}

/// The moving-average coefficient `h_m` (`m ≤ n`) of the equation error (module docs):
/// window entry `i` is the difference `x(k−n+1+i) − x(k−n+i)`, so it puts `−ℓ_i` on
/// `e(k−(n−1−i))` and `+ℓ_i` on `e(k−(n−i))`; the target puts 1 on `e(k)`.
fn moving_average<T: Real, const N: usize>(lead: &[T; N], n: usize, m: usize) -> T {
    let mut h = if m == 0 { T::ONE } else { T::ZERO };
    if m >= 1 {
        h += lead[n - m];
    }
    if m < n {
        h -= lead[n - 1 - m];
    }
    h
}

/// `max(1, t_{0.975}(ν)/2)`: the factor that makes ±2u a 95 % interval when the noise
/// level rests on ν degrees of freedom ([`t_quantile`]: 3.16 at ν = 3 against 3.182),
/// evaluated at compile time into [`COVERAGE_FACTORS`].
pub(crate) fn coverage_factor<T: Real>(degrees: u32) -> T {
    let index = degrees.max(1) as usize;
    T::from_f64(match COVERAGE_FACTORS.get(index) {
        Some(&factor) => factor,
        None => 1.0,
    })
}

/// `t_{0.975}(ν)/2` for ν = 0..=60 (entry 0 unused), at least 1; beyond ν = 60 it is 1.
const COVERAGE_FACTORS: [f64; 61] = coverage_factors();

const fn coverage_factors() -> [f64; 61] {
    let mut table = [1.0; 61];
    let mut degrees = 1;
    while degrees < 61 {
        let half = t_quantile(1.959_964, degrees as f64) / 2.0;
        table[degrees] = if half > 1.0 { half } else { 1.0 };
        degrees += 1;
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_coverage_factor_follows_the_t_tables() {
        // t_{0.975}(ν) from the tables: 3.182 (3), 2.228 (10), 2.042 (30), 1.96 (∞).
        for (degrees, t) in [(3, 3.182), (5, 2.571), (10, 2.228), (30, 2.042)] {
            let factor: f64 = coverage_factor(degrees);
            assert!((factor * 2.0 / t - 1.0).abs() < 0.01, "{degrees}: {factor}");
        }
        // t_{0.975}(60) = 2.000: the table ends there, and beyond it the factor is 1.
        assert!((coverage_factor::<f64>(60) - 1.0).abs() < 1e-3);
        assert_eq!(coverage_factor::<f64>(61), 1.0);
        assert_eq!(coverage_factor::<f64>(10_000), 1.0);
    }

    /// The lag sums kept per row (full cross-products up to the order, running totals for
    /// the constant column) give each lag's quadratic form as the rows themselves do, before
    /// and after the ring of kept rows wraps and for every lag kept.
    #[test]
    fn each_lags_quadratic_form_matches_the_rows_summed_directly() {
        fn kept<const L: usize, F: CrossForm<f64, L>>(
            sums: &LagSums<f64, L, L, true, F>,
            lag: usize,
            n: usize,
            z: &[f64; L],
            z_level: f64,
        ) -> f64 {
            let total = sums.total_along(z);
            let forms = F::forms(&sums.cross, n, z);
            sums.lag_quadratic(lag, n, z, z_level, total, &forms)
        }
        use crate::weighing::test_scene::unit_noise;
        const L: usize = 5;
        const COUNT: usize = 20;
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut noise = move || unit_noise(&mut state);
        for n in 1..=L {
            // Hankel rows, as the step's window of differences makes them: φ_k[i] = d(k+i).
            let mut d = [0.0; COUNT + L];
            d.iter_mut().for_each(|d| *d = noise());
            let rows: [[f64; L]; COUNT] = core::array::from_fn(|k| {
                core::array::from_fn(|i| if i < n { d[k + i] } else { 0.0 })
            });
            let mut per_lag = LagSums::<f64, L, L, true>::new();
            let mut hankel = LagSums::<f64, L, L, true, Hankel>::new();
            let z = pad::<f64, L, L>(&core::array::from_fn(|_| noise()), n);
            let z_level = noise();
            for count in 1..=COUNT {
                per_lag.push_row(&rows[count - 1], n);
                hankel.push_row(&rows[count - 1], n);
                let rows = &rows[..count];
                for lag in 1..=L {
                    // [φ_k; 1]ᵀ·w · [φ_{k−lag}; 1]ᵀ·w summed, entries beyond n dropped.
                    let along = |row: &[f64; L]| -> f64 {
                        (0..n).map(|i| row[i] * z[i]).sum::<f64>() + z_level
                    };
                    let mut direct = 0.0;
                    for k in lag..rows.len() {
                        let (newer, older) = (along(&rows[k]), along(&rows[k - lag]));
                        direct += if lag <= n {
                            newer * older
                        } else {
                            // Beyond the order: the constant column against the other row.
                            (newer + older - z_level) * z_level
                        };
                    }
                    let kept = [
                        kept(&per_lag, lag, n, &z, z_level),
                        kept(&hankel, lag, n, &z, z_level),
                    ];
                    for (form, kept) in ["per lag", "hankel"].into_iter().zip(kept) {
                        assert!(
                            (kept - direct).abs() <= 1e-9 * (1.0 + direct.abs()),
                            "{form}: n {n}, rows {count}, lag {lag}: kept {kept}, direct {direct}",
                        );
                    }
                }
            }
        }
    }

    /// The metered sandwich's running totals (`MeteredNoise`, `2L` lags) give the constant
    /// column's part of every lag beyond the order as the rows summed directly do, before
    /// and after their ring of `2L` rows wraps, and the same as the lag sums' own for the
    /// lags both keep.
    #[test]
    fn the_metered_totals_give_each_lags_constant_part_as_the_rows_do() {
        use crate::weighing::test_scene::unit_noise;
        const L: usize = 5;
        const COUNT: usize = 30;
        let mut state = 0x0DDB_1A5E_5BAD_5EEDu64;
        let mut noise = move || unit_noise(&mut state);
        for n in 1..=L {
            let rows: [[f64; L]; COUNT] = core::array::from_fn(|_| {
                core::array::from_fn(|i| if i < n { noise() } else { 0.0 })
            });
            let mut sums = LagSums::<f64, L, L, true, Hankel>::new();
            let mut metered = MeteredNoise::<f64, L, { 2 * L }>::new();
            // Rows are kept only while a colour is held (any will do here).
            let mut lags = [0.0; crate::AUTOCOVARIANCE_LAGS + 1];
            lags[0] = 1.0;
            let colour = crate::Autocovariance {
                lags,
                blocks: crate::MIN_METERED_BLOCKS,
            };
            metered.set(Some(&colour), 1.0);
            let z = pad::<f64, L, L>(&core::array::from_fn(|_| noise()), n);
            let z_level = noise();
            for count in 1..=COUNT {
                metered.push_row(&rows[count - 1], n, sums.rows());
                sums.push_row(&rows[count - 1], n);
                let rows = &rows[..count];
                let along = |row: &[f64; L]| (0..n).map(|i| row[i] * z[i]).sum::<f64>() + z_level;
                for lag in n + 1..=2 * L {
                    let direct: f64 = (lag..rows.len())
                        .map(|k| (along(&rows[k]) + along(&rows[k - lag]) - z_level) * z_level)
                        .sum();
                    let kept = metered.constant_part(lag, &z, z_level, sums.rows());
                    assert!(
                        (kept - direct).abs() <= 1e-9 * (1.0 + direct.abs()),
                        "n {n}, rows {count}, lag {lag}: kept {kept}, direct {direct}",
                    );
                    if lag <= L {
                        let total = sums.total_along(&z);
                        let forms = Hankel::forms(&sums.cross, n, &z);
                        let own = sums.lag_quadratic(lag, n, &z, z_level, total, &forms);
                        assert!((kept - own).abs() <= 1e-9 * (1.0 + own.abs()));
                    }
                }
            }
        }
    }

    /// With white block-mean noise metered (`γ = σ²·δ`), the metered sandwich is the model
    /// sandwich with the noise level known: the same `u` as the residual-based one where the
    /// residuals' level happens to equal σ², apart from the latter's t-factor.
    #[test]
    fn white_metered_noise_gives_the_model_sandwich() {
        use crate::estimators::noise_meter::{Autocovariance, AUTOCOVARIANCE_LAGS};
        use crate::weighing::test_scene::unit_noise;
        const L: usize = 8;
        let n = 3;
        let mut state = 0x1234_5678_9ABC_DEF1u64;
        let mut noise = move || unit_noise(&mut state);
        let mut sums = LagSums::<f64, L, L, true, Hankel>::new();
        let mut metered = MeteredNoise::<f64, L, { 2 * L }>::new();
        let mut lags = [0.0; AUTOCOVARIANCE_LAGS + 1];
        lags[0] = 2.0;
        metered.set(
            Some(&Autocovariance {
                lags,
                blocks: crate::MIN_METERED_BLOCKS,
            }),
            1.0,
        );
        assert!(metered.is_known());
        let rows = 200;
        // Rows of a decaying transient plus noise, residuals whose mean square is 2·Σh²
        // for the ℓ below, so that both noise levels agree.
        let lead: [f64; L] =
            core::array::from_fn(|i| if i < n { 0.1 * (i as f64 + 1.0) } else { 0.0 });
        let h: [f64; 4] = core::array::from_fn(|m| moving_average(&lead, n, m));
        let power: f64 = h.iter().map(|h| h * h).sum();
        for k in 0..rows {
            let row: [f64; L] = core::array::from_fn(|i| {
                if i < n {
                    (-(k as f64 + i as f64) / 30.0).exp() + 0.1 * noise()
                } else {
                    0.0
                }
            });
            metered.push_row(&row, n, sums.rows());
            sums.push_row(&row, n);
        }
        sums.residual_sum = 2.0 * power * (rows - n - 1) as f64;
        let z: [f64; L] =
            core::array::from_fn(|i| if i < n { 0.01 * (i as f64 - 1.0) } else { 0.0 });
        let z_level = 0.02;
        let (from_metering, degrees) = sums
            .metered_uncertainty(n, &z, z_level, &lead, &metered, |_| None)
            .unwrap();
        assert_eq!(degrees, crate::MIN_METERED_BLOCKS);
        let noise_model = NoiseModel::first_differences(&lead, n);
        let quadratic = Quadratic {
            z: &z,
            z_level,
            lag0: z_level,
        };
        // The model's lags only (no residual lags pushed), and its bias with σ² = 2.
        let (variance, block_noise, _) = sums
            .variance(n, &noise_model, quadratic, sums.residual_sum, None)
            .unwrap();
        assert!((block_noise - 2.0).abs() < 1e-12);
        let bias = sums.errors_in_variables_bias(n, &z, &noise_model, block_noise);
        let expected = (variance + bias * bias).sqrt();
        assert!(
            (from_metering / expected - 1.0).abs() < 1e-9,
            "metered {from_metering}, model {expected}"
        );
    }

    #[test]
    fn a_variance_that_is_not_positive_states_no_u_whatever_the_bias() {
        // A sandwich cancelled to zero or below (or lost to NaN) is no variance: the bias
        // alone must not stand in for it.
        assert_eq!(with_bias(-1.0e-4_f32, 0.03), None);
        assert_eq!(with_bias(0.0_f32, 0.03), None);
        assert_eq!(with_bias(f32::NAN, 0.03), None);
        assert_eq!(with_bias(0.25_f64, 0.5), Some(0.5));
        assert_eq!(with_bias(0.25_f64, 0.0), Some(0.25));
        // The bias's scatter comes off its square, never below zero; a scatter that is not
        // a number takes nothing off, and the variance must still be positive.
        assert_eq!(with_bias_scatter(0.25_f64, 0.5, 0.0), Some(0.5));
        assert_eq!(with_bias_scatter(0.25_f64, 0.5, 0.125), Some(0.375));
        assert_eq!(with_bias_scatter(0.25_f64, 0.5, 1.0), Some(0.25));
        assert_eq!(with_bias_scatter(0.25_f64, 0.5, f64::NAN), Some(0.5));
        assert_eq!(with_bias_scatter(0.0_f64, 0.5, 0.1), None);
    }

    #[test]
    fn the_moving_average_matches_the_equation_error_by_hand() {
        // n = 2, ℓ = [a, b]: ε = e(k) − a·(e(k−1) − e(k−2)) − b·(e(k) − e(k−1))
        //   = (1 − b)·e(k) + (b − a)·e(k−1) + a·e(k−2).
        let lead = [0.3, 0.7, 0.0, 0.0];
        let h: [f64; 3] = core::array::from_fn(|m| moving_average(&lead, 2, m));
        assert_eq!(h, [1.0 - 0.7, 0.7 - 0.3, 0.3]);
    }

    /// A run started on a pan whose load is not moving (no transient: a restart caught a
    /// trickle) has difference columns of pure noise, and a fit of a few rows all but
    /// interpolates its data: its first stated `u` can be far below the error (the scale
    /// showed 0.13 g off as final with u = 0.0016 g on 1 g of raw noise). With the noise
    /// metered on the empty pan as the floor, or the raw samples' white noise (what the
    /// scale measures on any pan), ±2u covers the first stated errors.
    #[test]
    fn a_fit_without_a_transient_is_not_overconfident_with_metered_noise() {
        use crate::estimators::consistency::NoiseReference;
        use crate::estimators::step::{StepConfig, StepEstimator};
        use crate::reading::Estimator;
        use crate::weighing::test_scene::unit_noise;
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut noise = move || unit_noise(&mut state);
        let runs = 400;
        let bare = StepConfig::new(7, 1.0f64).with_decimation(16);
        let metered = bare.with_noise_reference(NoiseReference::exact(1.0));
        // (configuration, white noise per raw sample)
        let cases = [(bare, None), (metered, None), (bare, Some(1.0))];
        let mut outside = [0u32; 3];
        for ((config, white), outside) in cases.into_iter().zip(&mut outside) {
            for _ in 0..runs {
                let mut estimator = StepEstimator::<f64, 8, 8>::new(config).unwrap();
                estimator
                    .set_white_noise(white.map(NoiseReference::exact))
                    .unwrap();
                for _ in 0..4000 {
                    let reading = estimator.push(noise());
                    if let (Some(estimate), Some(u)) = (reading.estimate, reading.uncertainty) {
                        if estimate.abs() > 2.0 * u {
                            *outside += 1;
                        }
                        break;
                    }
                }
            }
        }
        let [without, metered, white] = outside;
        // Without a floor 54 of the 400 first errors lie beyond 2u (13.5 %, where a 95 %
        // interval allows 5 %); with the metered floor 7, with the white one 9 (the floor
        // is the noise's expectation, known exactly here, so the `u` resting on it has no
        // t-factor since stop 49: `NoiseFloor`; with the residuals' factor, 1.6 at 3
        // degrees of freedom, none lay beyond).
        assert!(without > runs / 10, "without a floor: {without} of {runs}");
        assert!(metered <= runs / 20, "metered: {metered} of {runs}");
        assert!(white <= runs / 20, "white noise: {white} of {runs}");
    }
}
