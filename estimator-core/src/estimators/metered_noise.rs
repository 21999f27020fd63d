//! The step estimator's `u` on noise whose colour was metered on the empty pan.
//!
//! ## Why
//! The sandwich of `crate::estimators::step_uncertainty` takes the equation error's
//! autocovariance from a model (white block-mean noise through the fit's own moving average
//! `h`) or from the residuals' own lags, and states the larger. Neither knows noise that is
//! coloured: floor vibration near the resonance, or the amplifier's noise through the
//! anti-alias filter. `host-sim study coverage --runs 1000 --seed 1` on the rig's noise and
//! on floor vibration, with the noise already running when the load lands (as on a real
//! pan), found the shipped `u` over-confident at 70–80 dB 100 ms after landing (±2u held
//! 85–89 % of the errors; 400 runs) and 91–99 % later. A first-order sandwich with the
//! noise's true autocovariance held 92–98 % at every SNR and readout time there (a
//! throwaway oracle; with the residuals' 8 lags it fell to 76 %, with 16 lags it held).
//!
//! ## What is computed
//! With the block means' autocovariance `γ` metered on the empty pan
//! ([`crate::AutocovarianceMeter`], lags up to [`AUTOCOVARIANCE_LAGS`]), the equation error
//! `ε(k) = Σ_m h_m·e(k−m)` has the autocovariance
//!
//! ```text
//! γ_ε(l) = Σ_{m=−n..n} ρ(|m|)·γ(|l + m|),   ρ(m) = Σ_a h_a·h_{a+m}
//! ```
//!
//! and the level's variance is the sandwich `Σ_l γ_ε(l)·zᵀ(S_l + S_lᵀ)z` over the lags
//! `0..=C` (the estimator's colour lags, `3L` = 24 for the configured method; beyond the
//! order `n` the rows' cross-products keep their constant column's part, from the rows'
//! running totals, as in `step_uncertainty`). The errors-in-variables bias is the same
//! first-order term with the coloured noise: `N·Σ_i z_i·Σ_m h_m·(γ(|m − (n−1−i)|) − γ(|m −
//! (n−i)|))`, added to the variance. Evaluated on one run's own `ℓ` and `z` it is mostly
//! its own estimation noise, and until stop 55 it kept the rig's noise at 70–80 dB 100 ms
//! after the landing cautious (±2u 98.6–99.1 %, `host-sim study coverage --runs 1000 --seed 1`):
//! there it exceeded the sandwich's standard deviation in 453 of 1,000 runs at 80 dB (three
//! times over in 178), its correlation with the run's error was −0.10 (−0.01 to −0.20 in
//! every scene, SNR and time looked at), subtracting it from the estimate made the RMS
//! error larger in every one of them, and the mean error over the runs, the bias it stands
//! for, stayed within a third of the error's standard deviation. Left out, ±2u held
//! 94.6–95.8 % there, but with a tail: at 80 dB 6 of 1,000 runs lay beyond 5u (RMS error/u
//! 1.25), four of them with u = 0.0006–0.0013 g on errors of 0.003–0.018 g (up to 16u), a
//! sandwich all but cancelled (a fit whose moving average nearly annihilates the vibration,
//! we take it); with it none lay beyond 4u. Stop 51 found those runs' cause: `f32`
//! rounding, not the noise. The lag forms are small differences of large products where
//! the level's row of `P` is large, and the metered sandwich came out negative in 71 of
//! 1,000 runs at 80 dB (1 in `f64` on the same data) or far too small; the bias stood in
//! for it. The sandwich is now stated at the upper end of its rounding
//! (`LagSums::rounding`) and one that is not positive states no `u` (`with_bias`). The
//! bias stays, less its own scatter (since stop 55): `E[b̂²] = b² + var(b̂)`, and
//! `var(b̂) ≈ γ_ε(0)·gᵀ·P·g` to first order in `ℓ` (`LagSums::metered_uncertainty`), which
//! brought those cells to 97.5 % and 97.8 % (f64 96.2 % and 96.4 %) with every other cell
//! of the step method's tables within 92–98 %. Weighed instead by `1 − ρ`, `ρ` the
//! regressors' expected noise along the level's row of `P` as a share of what the rows
//! hold along it, it brought those cells to
//! 97.8 % and 97.9 %, but the scale then showed a pan emptied by hand as empty 0.056 g off
//! with u = 0.011 g, 1.08 s after the removal (`host-sim torture --runs 10000 --seed 1`,
//! run 1796: 16 lines shown settled wrong instead of 9), where the full bias's u of
//! 0.07 g covered the error. Cautious on average, it holds what a bare sandwich misses
//! after a change that is not quite a step. The noise is known to
//! thousands of block means, so no t-factor is applied, unless the residuals leave more
//! than the metered noise explains (their mean square above the 95 % point of `χ²_ν/ν`
//! times `γ_ε(0)`: a fit that does not explain its data, a load that adds noise of its
//! own): then the variance is the larger of the metered sandwich and the residuals' own
//! (their autocovariance over the lags kept, as without a metering), the bias is scaled by
//! that ratio and the t-factor of the residuals' `ν` applies. Until stop 50 the variance
//! too was scaled by the ratio, which made floor vibration at 80 dB cautious 400 ms after
//! the landing (±2u 98.3 %; the firmware's scale 98.4–99.2 % at 70–80 dB): an excess of
//! narrow-band vibration near the loaded resonance reaches the level far less than its
//! power says.
//!
//! Cost: the rows' totals for `C` lags (`2CL + L` numbers and `2C` of `γ`; `C = 0`, the
//! default, keeps `L` numbers and a count; the configured step method keeps
//! `crate::weighing::COLOUR_LAGS`), one copy of a row's totals per block while a colour is
//! held; per uncertainty `C + 1` lags of `2n + 1` products each, `(n + 1)²` for the bias
//! and one weighted sum of the totals (`cargo xtask bench`: the shipped n = 5, D = 24 at
//! 952 instructions per 4 kHz sample with the colour in use over 24 lags (949
//! before the rounding allowance, 946 before the residuals' own sandwich where they
//! exceed the colour), 901 over 16, 789 without).

use crate::estimators::noise_meter::{Autocovariance, AUTOCOVARIANCE_LAGS};
use crate::numerics::real::Real;

/// Block means an autocovariance must rest on before the `u` rests on it: a narrow-band
/// noise's lags are known only over many of its periods. `host-sim study coverage` (400
/// runs, the rig's noise and floor vibration at 30–80 dB, D = 24) with the empty pan
/// metered over 10 s (1,667 block means): ±2u held 91.0–99.0 %; over 20 s (3,333):
/// 93.8–98.8 %; over 60 s: 93.0–98.8 %.
pub const MIN_METERED_BLOCKS: u32 = 3_000;

/// The metered autocovariance (in the residuals' unit²) and the rows' running totals for
/// the lags beyond the order (see the module docs). `L`: the lags the estimator keeps (its
/// rows are padded to `L`); `C`: the sandwich's lags with a metered colour (3L = 24 for the
/// coverage study's and the firmware's D = 24), which needs `γ` up to `C + n`. Nothing for
/// `C = 0` (the estimator's default: no colour, no cost): the rows are counted by the
/// caller's [`LagSums`].
///
/// [`LagSums`]: crate::estimators::step_uncertainty::LagSums
#[derive(Clone, Debug)]
pub(crate) struct MeteredNoise<T, const L: usize, const C: usize> {
    /// `γ(g)` for `g < 2C` at `[g / C][g % C]`; all zero when nothing is metered (a metered
    /// `γ(0)` is positive).
    gamma: [[T; C]; 2],
    /// `C(K) = Σ_{k ≤ K} φ_k`, padded to `L`.
    total: [T; L],
    /// `C(l − 1)` for `l = 1..=C` (the total after each of the first `C` rows), at `l − 1`.
    early: [[T; L]; C],
    /// The total before row `r` was added, at slot `r mod C` (the last `C` rows).
    before: [[T; L]; C],
    /// Rows folded while a colour was held: the sandwich needs every row of the run (a
    /// colour set in the middle of a run serves from the next one on).
    rows: u32,
}

impl<T: Real, const L: usize, const C: usize> MeteredNoise<T, L, C> {
    pub(crate) fn new() -> Self {
        Self {
            gamma: [[T::ZERO; C]; 2],
            total: [T::ZERO; L],
            early: [[T::ZERO; L]; C],
            before: [[T::ZERO; L]; C],
            rows: 0,
        }
    }

    /// Take `other`'s noise for a fresh run (this one new: no rows).
    pub(crate) fn keep_noise_of(&mut self, other: &Self) {
        self.gamma = other.gamma;
    }

    /// Whether every one of the run's `rows` was folded with a colour held.
    pub(crate) fn covers_run(&self, rows: u32) -> bool {
        self.is_known() && self.rows == rows
    }

    /// Take `autocovariance` (raw units² of block means), times `scale²` (the residuals'
    /// unit per raw unit squared); `None` forgets it, and one metered over fewer than
    /// [`MIN_METERED_BLOCKS`] block means is not taken.
    pub(crate) fn set(&mut self, autocovariance: Option<&Autocovariance<T>>, scale2: T) {
        self.gamma = [[T::ZERO; C]; 2];
        let Some(autocovariance) = autocovariance else {
            return;
        };
        if C == 0 || autocovariance.blocks < MIN_METERED_BLOCKS {
            return;
        }
        let lags = AUTOCOVARIANCE_LAGS.min(2 * C - 1);
        for (g, &value) in autocovariance.lags[..=lags].iter().enumerate() {
            self.gamma[g / C][g % C] = value * scale2;
        }
    }

    /// Whether a metered autocovariance is held.
    pub(crate) fn is_known(&self) -> bool {
        C > 0 && L > 0 && self.gamma[0][0] > T::ZERO
    }

    /// The lags of the sandwich for an order `n`: `C`, as far as `γ` reaches (`l + n`).
    pub(crate) fn lags(&self, n: usize) -> usize {
        if C == 0 {
            return 0;
        }
        C.min(AUTOCOVARIANCE_LAGS.min(2 * C - 1).saturating_sub(n))
    }

    /// Regression row number `number` (0 for the first), `row[..n]` (the constant column
    /// implied); orders above `L` are not kept (their `u` is not stated).
    #[inline]
    pub(crate) fn push_row<const N: usize>(&mut self, row: &[T; N], n: usize, number: u32) {
        if C == 0 || n > L || !self.is_known() {
            return;
        }
        self.rows = self.rows.saturating_add(1);
        let slot = number as usize % C;
        self.before[slot] = self.total;
        for (total, &x) in self.total[..n].iter_mut().zip(row) {
            *total += x;
        }
        let number = number as usize;
        if number < C {
            self.early[number] = self.total;
        }
    }

    /// `γ(g)` for `g = 0..=`[`AUTOCOVARIANCE_LAGS`], 0 beyond the metered lags.
    pub(crate) fn lags_array(&self) -> [T; AUTOCOVARIANCE_LAGS + 1] {
        let mut lags = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        let metered = self.gamma.as_flattened();
        let kept = metered.len().min(lags.len());
        lags[..kept].copy_from_slice(&metered[..kept]);
        lags
    }

    /// The constant column's part of `[z; z_level]ᵀ·(S_lag + S_lagᵀ)/2·[z; z_level]` for
    /// `1 ≤ lag ≤ C` (`z` padded to `L`) after `rows` rows: `z_level·(zᵀ(C(K) − C(lag−1)
    /// + C(K−lag)) + z_level·pairs)` over the rows with a row `lag` before them (one lag of
    /// [`Self::constant_parts`], for the tests).
    #[cfg(test)]
    pub(crate) fn constant_part(&self, lag: usize, z: &[T; L], z_level: T, rows: u32) -> T {
        let mut weights = [T::ZERO; AUTOCOVARIANCE_LAGS + 1];
        if lag < weights.len() {
            weights[lag] = T::ONE;
        }
        self.constant_parts(
            &weights[..=lag.min(AUTOCOVARIANCE_LAGS)],
            lag,
            z,
            z_level,
            rows,
        )
    }

    /// `Σ_{lag = from..} weights[lag]·constant_part(lag)` (lags up to `C`), summed as one
    /// weighted total of the rows' totals and one product with `z`.
    pub(crate) fn constant_parts(
        &self,
        weights: &[T],
        from: usize,
        z: &[T; L],
        z_level: T,
        rows: u32,
    ) -> T {
        if C == 0 {
            return T::ZERO;
        }
        let mut along = T::ZERO;
        for (&total, &zi) in self.total.iter().zip(z) {
            along += total * zi;
        }
        // Σ_l w_l·(C(K−l) − C(l−1)), and Σ_l w_l·(zᵀC(K) + z_level·pairs).
        let mut weighted = [T::ZERO; L];
        let mut scalar = T::ZERO;
        for (lag, &weight) in weights.iter().enumerate().skip(from.max(1)) {
            let pairs = rows.saturating_sub(lag as u32);
            if pairs == 0 || lag > C {
                continue;
            }
            // C(K − lag) is the total before row K − lag + 1 = rows − lag.
            let older = &self.before[pairs as usize % C];
            let early = &self.early[lag - 1];
            for ((sum, &older), &early) in weighted.iter_mut().zip(older).zip(early) {
                *sum += weight * (older - early);
            }
            scalar += weight * (along + z_level * T::from_u32(pairs));
        }
        let mut sides = scalar;
        for (&sum, &zi) in weighted.iter().zip(z) {
            sides += sum * zi;
        }
        z_level * sides
    }
}

/// The 95 % point of `χ²_ν/ν` (Wilson–Hilferty): residuals of pure noise exceed it with
/// 5 % probability.
pub(crate) fn chi_square_mean_95<T: Real>(degrees: u32) -> T {
    let nine_nu = T::from_f64(9.0) * T::from_u32(degrees.max(1));
    let a = T::from_f64(2.0) / nine_nu;
    let root = T::ONE - a + T::from_f64(1.644_853_6) * a.sqrt();
    root * root * root
}
