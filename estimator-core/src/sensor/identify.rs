//! Identification at calibration: the mechanical mode `(f_n, ζ)` and the static gain of a
//! [`LoadCellModel`] from one or more recorded drops of a known mass.
//!
//! For a candidate `(f_n, ζ)` the model is fixed and linear in the unknowns `[x₀; u]`, so
//! [`ModelEstimator`] fits it exactly and its residual sum of squares is the profile
//! likelihood of `(f_n, ζ)` under white noise. Identification minimises that residual
//! summed over the drops: a coarse log-spaced grid, then cyclic golden-section searches in
//! `ln f_n` and `ln ζ` (the two are nearly orthogonal in the residual: frequency moves the
//! phase of the ringing, damping its envelope) until both brackets are below the tolerance.
//! The gain is the fitted step over the known mass.
//!
//! The initial state is estimated in every fit, so a drop need not start exactly at its
//! onset: it may start a few samples after it (never before: samples of the empty pan are not
//! a step response). Memory is fixed: two estimators on the stack; the drops are the caller's
//! slices. Time is `evaluations × samples` estimator updates (printed by host-sim's
//! `model_based` figures).
//!
//! What it must never do: return parameters it could not identify. Short, flat or
//! non-finite data, and a minimum on the edge of the search range, are typed errors.

use crate::estimators::model::{InitialState, ModelConfig, ModelEstimator};
use crate::estimators::step::MAX_DECIMATION;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, Estimator};
use crate::sensor::LoadCellModel;

/// What identification needs to know and where it searches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyConfig {
    /// The known mass dropped in every recording, g.
    pub mass_g: f64,
    /// Order of the known Butterworth low-pass.
    pub filter_order: u8,
    /// Cut-off of the known low-pass, Hz.
    pub filter_cutoff_hz: f64,
    /// Raw samples per second, Hz.
    pub sample_rate_hz: f64,
    /// Search range of the natural frequency with the calibration mass on, Hz.
    pub frequency_min_hz: f64,
    /// See `frequency_min_hz`.
    pub frequency_max_hz: f64,
    /// Search range of the damping ratio.
    pub damping_min: f64,
    /// See `damping_min`.
    pub damping_max: f64,
    /// Points of the coarse grid in frequency (log-spaced, ≥ 3).
    pub frequency_points: u16,
    /// Points of the coarse grid in damping ratio (log-spaced, ≥ 3).
    pub damping_points: u16,
    /// The coarse grid fits only this much of each drop, s (the golden sections fit all of
    /// it): the grid only has to find the valley, and a short window makes it wide.
    pub coarse_window_s: f64,
    /// Fit block means of this many raw samples (see [`ModelConfig::decimation`]).
    pub decimation: u16,
    /// Stop when both brackets are below this relative width.
    pub tolerance: f64,
}

impl IdentifyConfig {
    /// Search 5–200 Hz and ζ 0.005–0.5 on a 64 × 8 grid over the first 0.25 s of each drop
    /// (points 5.9% and 93% apart: a candidate with a larger ζ than the truth, or a short
    /// window, has a wide residual valley in frequency, so the grid finds the valley and the
    /// golden sections the minimum), block means of 8 samples, relative tolerance 1e-7.
    pub fn new(mass_g: f64, filter_order: u8, filter_cutoff_hz: f64, sample_rate_hz: f64) -> Self {
        Self {
            mass_g,
            filter_order,
            filter_cutoff_hz,
            sample_rate_hz,
            frequency_min_hz: 5.0,
            frequency_max_hz: 200.0,
            damping_min: 0.005,
            damping_max: 0.5,
            frequency_points: 64,
            damping_points: 8,
            coarse_window_s: 0.25,
            decimation: 8,
            tolerance: 1e-7,
        }
    }
}

/// What identification found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Identified {
    /// The model with the identified frequency, damping ratio and gain, and the known
    /// filter and sample rate.
    pub model: LoadCellModel,
    /// RMS of the fit residual of block means, raw units.
    pub fit_rms: f64,
    /// The white noise per raw sample that residual implies (`fit_rms·√D`), raw units.
    pub noise_rms: f64,
    /// Model fits evaluated (each one pass over every drop).
    pub evaluations: u32,
}

/// Why the drops do not identify the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IdentifyError {
    /// The configuration is impossible (ranges empty or not finite, too few grid points,
    /// filter order not `S − 2`, mass not positive, decimation out of range).
    Config(ConfigError),
    /// No drops were given.
    NoData,
    /// A drop is shorter than two periods of the lowest frequency searched (and than the
    /// blocks the fit needs).
    TooShort {
        /// Index of the drop.
        drop: usize,
        /// Samples it has.
        samples: usize,
        /// Samples it needs.
        needed: usize,
    },
    /// A sample is NaN or infinite.
    NonFinite {
        /// Index of the drop.
        drop: usize,
        /// Index of the sample in it.
        sample: usize,
    },
    /// A drop shows no step: the mean of its second half is below 10 times its noise
    /// (20 dB; the noise estimated from second differences, free of any model), too little
    /// to identify a resonance.
    Flat {
        /// Index of the drop.
        drop: usize,
    },
    /// The best fit lies on the edge of the search range: widen the range.
    AtRangeEdge,
    /// No candidate could be fitted (every fit was ill-conditioned).
    NotIdentifiable,
}

impl From<ConfigError> for IdentifyError {
    fn from(e: ConfigError) -> Self {
        IdentifyError::Config(e)
    }
}

/// One fit of a candidate over all drops.
#[derive(Clone, Copy, Debug)]
struct Fit {
    residual_sum: f64,
    /// Rows contributing to the residual (after each drop's first estimate).
    residual_rows: u32,
    /// Sum over the drops of the fitted step, raw units.
    step_sum: f64,
}

struct Problem<'a, T, const S: usize> {
    drops: &'a [&'a [T]],
    config: &'a IdentifyConfig,
    evaluations: u32,
}

impl<T: Real, const S: usize> Problem<'_, T, S> {
    fn model(&self, frequency_hz: f64, damping_ratio: f64) -> LoadCellModel {
        LoadCellModel {
            natural_frequency_hz: frequency_hz,
            damping_ratio,
            filter_order: self.config.filter_order,
            filter_cutoff_hz: self.config.filter_cutoff_hz,
            // Unit gain: the fitted step is then gain × mass, in raw units.
            counts_per_gram: 1.0,
            sample_rate_hz: self.config.sample_rate_hz,
        }
    }

    /// Fit `(f, ζ)` to the first `limit` samples of each drop; `None` when the fit is not
    /// determined or not finite.
    fn fit(&mut self, frequency_hz: f64, damping_ratio: f64, limit: usize) -> Option<Fit> {
        self.evaluations = self.evaluations.saturating_add(1);
        let model = self
            .model(frequency_hz, damping_ratio)
            .sensor_model::<T, S>()
            .ok()?;
        let config = ModelConfig::new(model)
            .with_decimation(self.config.decimation)
            .with_initial_state(InitialState::Unknown);
        let fresh = ModelEstimator::new(config).ok()?;
        let mut fit = Fit {
            residual_sum: 0.0,
            residual_rows: 0,
            step_sum: 0.0,
        };
        for drop in self.drops {
            let mut estimator = fresh.clone();
            let mut first_estimate_row = None;
            let mut last = None;
            for &sample in drop.iter().take(limit) {
                let reading = estimator.push(sample);
                if reading.is_invalid() {
                    return None;
                }
                if reading.estimate.is_some() && first_estimate_row.is_none() {
                    first_estimate_row = Some(estimator.rows());
                }
                last = reading.estimate;
            }
            let step = last?.to_f64();
            let residual = estimator.residual_sum().to_f64();
            if !(step.is_finite() && residual.is_finite()) {
                return None;
            }
            fit.residual_sum += residual;
            fit.residual_rows += estimator.rows() - first_estimate_row.unwrap_or(0);
            fit.step_sum += step;
        }
        Some(fit)
    }

    fn cost(&mut self, ln_frequency: f64, ln_damping: f64, limit: usize) -> f64 {
        match self.fit(libm::exp(ln_frequency), libm::exp(ln_damping), limit) {
            Some(fit) => fit.residual_sum,
            None => f64::INFINITY,
        }
    }
}

/// Golden-section search of `cost` over `[low, high]` until the bracket is below `width`;
/// returns the best point seen.
fn golden_section(
    mut cost: impl FnMut(f64) -> f64,
    mut low: f64,
    mut high: f64,
    width: f64,
) -> (f64, f64) {
    const INVERSE_PHI: f64 = 0.618_033_988_749_894_8;
    let mut left = high - INVERSE_PHI * (high - low);
    let mut right = low + INVERSE_PHI * (high - low);
    let (mut cost_left, mut cost_right) = (cost(left), cost(right));
    // At most 100 steps: a bracket shrinks by 0.618 per step, 1e-20 of any start.
    for _ in 0..100 {
        if !(high - low > width) {
            break;
        }
        // `!(a > b)` so that a NaN cost never wins.
        if !(cost_left > cost_right) {
            high = right;
            right = left;
            cost_right = cost_left;
            left = high - INVERSE_PHI * (high - low);
            cost_left = cost(left);
        } else {
            low = left;
            left = right;
            cost_left = cost_right;
            right = low + INVERSE_PHI * (high - low);
            cost_right = cost(right);
        }
    }
    if !(cost_left > cost_right) {
        (left, cost_left)
    } else {
        (right, cost_right)
    }
}

/// Identify `(f_n, ζ)` and the gain of a load cell with `S = 2 + filter_order` states from
/// `drops`: raw samples (tare removed) from each drop's onset of `config.mass_g`.
pub fn identify<T: Real, const S: usize>(
    drops: &[&[T]],
    config: &IdentifyConfig,
) -> Result<Identified, IdentifyError> {
    check_config::<S>(config)?;
    if drops.is_empty() {
        return Err(IdentifyError::NoData);
    }
    let decimation = usize::from(config.decimation);
    // Two periods of the lowest frequency, and four times the blocks that determine a fit.
    let needed = (2.0 * config.sample_rate_hz / config.frequency_min_hz) as usize;
    let needed = needed.max(4 * (S + 1) * decimation);
    check_drops(drops, needed)?;
    let mut problem = Problem::<T, S> {
        drops,
        config,
        evaluations: 0,
    };
    let ln_f = (
        libm::log(config.frequency_min_hz),
        libm::log(config.frequency_max_hz),
    );
    let ln_z = (libm::log(config.damping_min), libm::log(config.damping_max));
    let f_step = (ln_f.1 - ln_f.0) / f64::from(config.frequency_points - 1);
    let z_step = (ln_z.1 - ln_z.0) / f64::from(config.damping_points - 1);
    // At least the samples the length check asks for, so every coarse fit is determined.
    let coarse = ((config.coarse_window_s * config.sample_rate_hz) as usize).max(needed);
    let start = problem.coarse_grid(ln_f.0, f_step, ln_z.0, z_step, coarse)?;
    let (lf, lz) = problem.refine(start, (ln_f, f_step), (ln_z, z_step));
    let width = config.tolerance;
    let (frequency_hz, damping_ratio) = (libm::exp(lf), libm::exp(lz));
    let fit = problem
        .fit(frequency_hz, damping_ratio, usize::MAX)
        .ok_or(IdentifyError::NotIdentifiable)?;
    // Degrees of freedom: each drop's rows minus the two shared parameters.
    let dof = f64::from(fit.residual_rows.saturating_sub(2).max(1));
    let fit_rms = libm::sqrt(fit.residual_sum / dof);
    let noise_rms = fit_rms * libm::sqrt(decimation as f64);
    let step = fit.step_sum / drops.len() as f64;
    let edge = 2.0 * width;
    if lf - ln_f.0 < edge || ln_f.1 - lf < edge || lz - ln_z.0 < edge || ln_z.1 - lz < edge {
        return Err(IdentifyError::AtRangeEdge);
    }
    let mut model = problem.model(frequency_hz, damping_ratio);
    model.counts_per_gram = step / config.mass_g;
    // The final model must itself be valid (gain finite and non-zero).
    model.check(S)?;
    Ok(Identified {
        model,
        fit_rms,
        noise_rms,
        evaluations: problem.evaluations,
    })
}

/// Refuse drops shorter than `needed`, with a sample that is not finite, or flat.
fn check_drops<T: Real>(drops: &[&[T]], needed: usize) -> Result<(), IdentifyError> {
    for (index, drop) in drops.iter().enumerate() {
        if drop.len() < needed {
            return Err(IdentifyError::TooShort {
                drop: index,
                samples: drop.len(),
                needed,
            });
        }
        if let Some(sample) = drop.iter().position(|v| !v.is_finite()) {
            return Err(IdentifyError::NonFinite {
                drop: index,
                sample,
            });
        }
        if is_flat(drop) {
            return Err(IdentifyError::Flat { drop: index });
        }
    }
    Ok(())
}

impl<T: Real, const S: usize> Problem<'_, T, S> {
    /// The best point `(ln f, ln ζ)` of the coarse grid, fitting the first `coarse` samples.
    fn coarse_grid(
        &mut self,
        ln_f0: f64,
        f_step: f64,
        ln_z0: f64,
        z_step: f64,
        coarse: usize,
    ) -> Result<(f64, f64), IdentifyError> {
        let mut best = (ln_f0, ln_z0, f64::INFINITY);
        for i in 0..self.config.frequency_points {
            let lf = ln_f0 + f_step * f64::from(i);
            for j in 0..self.config.damping_points {
                let lz = ln_z0 + z_step * f64::from(j);
                let cost = self.cost(lf, lz, coarse);
                if cost < best.2 {
                    best = (lf, lz, cost);
                }
            }
        }
        if !best.2.is_finite() {
            return Err(IdentifyError::NotIdentifiable);
        }
        Ok((best.0, best.1))
    }

    /// Cyclic golden sections from `start` over the whole drops. The first cycle searches
    /// one grid step either side; later ones twice the distance the previous cycle moved
    /// (coordinate descent on a nearly separable valley moves less every cycle), never less
    /// than the tolerance. Each axis is `((low, high), grid step)` in logarithms.
    fn refine(
        &mut self,
        start: (f64, f64),
        (ln_f, f_step): ((f64, f64), f64),
        (ln_z, z_step): ((f64, f64), f64),
    ) -> (f64, f64) {
        let (mut lf, mut lz) = start;
        let mut cost = self.cost(lf, lz, usize::MAX);
        let (mut f_half, mut z_half) = (f_step, z_step);
        let width = self.config.tolerance;
        for _ in 0..12 {
            let (lf_before, lz_before) = (lf, lz);
            (lf, cost) = improve(lf, cost, f_half, ln_f, width, |x| {
                self.cost(x, lz, usize::MAX)
            });
            (lz, cost) = improve(lz, cost, z_half, ln_z, width, |x| {
                self.cost(lf, x, usize::MAX)
            });
            let (moved_f, moved_z) = ((lf - lf_before).abs(), (lz - lz_before).abs());
            if moved_f <= width && moved_z <= width {
                break;
            }
            // A minimum at a bracket's edge (moved almost the whole half-width) may lie
            // beyond it: search twice as wide next time.
            f_half = next_half(f_half, moved_f, width);
            z_half = next_half(z_half, moved_z, width);
        }
        (lf, lz)
    }
}

/// A golden-section search of `cost` within `half` of `x` (clipped to `range`): the point
/// found and its cost when no worse than `current`, else `(x, current)`.
fn improve(
    x: f64,
    current: f64,
    half: f64,
    range: (f64, f64),
    width: f64,
    cost: impl FnMut(f64) -> f64,
) -> (f64, f64) {
    let low = (x - half).max(range.0);
    let high = (x + half).min(range.1);
    let (found, found_cost) = golden_section(cost, low, high, width);
    if found_cost <= current {
        (found, found_cost)
    } else {
        (x, current)
    }
}

/// True when the mean of the drop's second half is not above 10 times its noise. The noise
/// comes from second differences (`var(Δ²e) = 6σ²` for white noise); the signal's own
/// second difference, `(ωh)²` of its ringing, only raises that estimate a little while the
/// resonance is well below the sample rate, and scales with the step, so a real step
/// always passes.
fn is_flat<T: Real>(drop: &[T]) -> bool {
    let half = drop.len() / 2;
    let mut mean = 0.0;
    for v in &drop[half..] {
        mean += v.to_f64();
    }
    mean /= (drop.len() - half).max(1) as f64;
    let mut second = 0.0;
    for w in drop.windows(3) {
        let d2 = w[2].to_f64() - 2.0 * w[1].to_f64() + w[0].to_f64();
        second += d2 * d2;
    }
    let noise = libm::sqrt(second / (6.0 * drop.len().saturating_sub(2).max(1) as f64));
    !(libm::fabs(mean) > 10.0 * noise)
}

/// The next half-width of a coordinate's bracket after the search moved by `moved`.
fn next_half(half: f64, moved: f64, width: f64) -> f64 {
    if moved > 0.9 * half {
        2.0 * half
    } else {
        (2.0 * moved).max(4.0 * width)
    }
}

fn check_config<const S: usize>(config: &IdentifyConfig) -> Result<(), IdentifyError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let ranges = positive(config.frequency_min_hz)
        && positive(config.damping_min)
        && config.frequency_max_hz.is_finite()
        && config.damping_max.is_finite()
        && config.frequency_max_hz > config.frequency_min_hz
        && config.damping_max > config.damping_min
        && config.damping_max <= crate::sensor::MAX_DAMPING_RATIO
        && config.frequency_points >= 3
        && config.damping_points >= 3
        && positive(config.tolerance)
        && config.coarse_window_s.is_finite()
        && config.coarse_window_s >= 0.0
        && config.tolerance < 0.1;
    if !ranges {
        return Err(ConfigError::Model.into());
    }
    if !positive(config.mass_g) {
        return Err(ConfigError::Gain.into());
    }
    if config.decimation == 0 || config.decimation > MAX_DECIMATION {
        return Err(ConfigError::Decimation.into());
    }
    // The filter, sample rate and S are checked by the model itself.
    let probe = LoadCellModel {
        natural_frequency_hz: config.frequency_min_hz,
        damping_ratio: config.damping_min,
        filter_order: config.filter_order,
        filter_cutoff_hz: config.filter_cutoff_hz,
        counts_per_gram: 1.0,
        sample_rate_hz: config.sample_rate_hz,
    };
    probe.check(S)?;
    Ok(())
}
