//! Slice D: long runs of a steady load, one record shared by every probe, judged per
//! log-spaced bin against the steady-state noise floor of the forgetting factor.

use std::time::Instant;

use anyhow::{anyhow, Result};
use estimator_core::sensor::AdcSource;
use estimator_core::{InvalidReason, Reading, State};
use rayon::prelude::*;

use super::classify::{Class, BOUND_FACTOR, DIVERGED_FACTOR};
use super::oracle::Tracked;
use super::probes::{push_pair, Probe};
use super::run::Outcome;
use crate::crlb;
use crate::method::{BuildContext, Method};
use crate::montecarlo::{self, tare_record};
use crate::scene::Scene;
use crate::simulated::{run_seed, LoadEvent, Script};

/// Forgetting factors of slice D, at the decimated rate.
pub const LONG_FORGETTING: [f64; 3] = [1.0, 0.9999, 0.999];
/// Block lengths of slice D.
pub const LONG_DECIMATIONS: [u16; 2] = [1, 16];
/// The default length of the long runs, samples (2,500 s at 4 kHz).
pub const LONG_SAMPLES: usize = 10_000_000;
/// The steady load of slice D, g.
pub const LONG_LOAD_G: f64 = 138.32;

/// Bins per decade of the long runs' log-spaced statistics.
pub const BINS_PER_DECADE: usize = 10;
/// The long runs' statistics start at 10³ samples.
pub const FIRST_DECADE: u32 = 3;

/// Slice D's probes: step, covariance, iv and bc at n = 7, every block length and forgetting
/// factor, f64 and f32.
pub fn long_probes() -> Vec<Probe> {
    let mut probes = Vec::new();
    for decimation in LONG_DECIMATIONS {
        for lambda in LONG_FORGETTING {
            for family in ["step", "covariance", "iv", "bc"] {
                push_pair(
                    &mut probes,
                    &format!("{family} D={decimation} λ={lambda}"),
                    &format!("{family}:n=7,D={decimation},lambda={lambda}"),
                    Some(7),
                );
            }
        }
    }
    probes
}

/// Statistics of one log-spaced bin of a long run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Bin {
    /// Readings in the bin.
    pub readings: u64,
    /// Valid, finite readings.
    pub valid: u64,
    /// Flagged readings.
    pub flagged: u64,
    /// Σ (error / bound)² over the valid readings.
    pub sum_normalised: f64,
    /// Largest |error| of a valid reading, g.
    pub max_error_g: f64,
    /// Valid readings after the oracle saw positive definiteness lost.
    pub valid_after_loss: u64,
    /// Valid readings that were not finite.
    pub non_finite: u64,
    /// Valid readings 10 loads off.
    pub diverged: u64,
}

/// One long run of one method.
#[derive(Clone, Debug)]
pub struct LongRun {
    /// The probe.
    pub probe: Probe,
    /// Bins from 10³ samples on, [`BINS_PER_DECADE`] a decade.
    pub bins: Vec<Bin>,
    /// The first flag: sample count and reason.
    pub first_flag: Option<(usize, InvalidReason)>,
    /// The sample count at which the oracle first saw positive definiteness lost.
    pub lost_definiteness_at: Option<usize>,
    /// The state and error at the end.
    pub last: Outcome,
    /// The steady-state bound at the end, g.
    pub bound_end_g: f64,
    /// CPU seconds.
    pub cpu_s: f64,
}

fn bin_of(count: usize) -> Option<usize> {
    let position = (count as f64).log10() - f64::from(FIRST_DECADE);
    (position >= 0.0).then(|| (position * BINS_PER_DECADE as f64 + 1e-9).floor() as usize)
}

/// The noise floor of a steady load estimated with forgetting λ over `rows` decimated rows of
/// variance `block_variance_g2` each: the variance of the exponentially weighted mean,
/// `σ²_D·(1−λ)(1+λ^m)/((1+λ)(1−λ^m))` (→ σ²_D/m at λ = 1), g. A constant in white noise has
/// no better unbiased estimate from those weights; the data-driven estimators also fit `ℓ`.
pub fn steady_bound_g(block_variance_g2: f64, lambda: f64, rows: f64) -> f64 {
    if rows < 1.0 {
        return f64::NAN;
    }
    let factor = if lambda >= 1.0 {
        1.0 / rows
    } else {
        let power = lambda.powf(rows);
        (1.0 - lambda) * (1.0 + power) / ((1.0 + lambda) * (1.0 - power))
    };
    (block_variance_g2 * factor).sqrt()
}

fn run_long(
    probe: &Probe,
    context: &BuildContext,
    codes: &[u16],
    zero: f64,
    raw_variance_g2: f64,
) -> Result<LongRun> {
    let start = Instant::now();
    let (decimation, lambda) = match probe.method {
        Method::Step(s)
        | Method::Covariance { setup: s, .. }
        | Method::BiasCompensated { setup: s, .. } => (s.decimation, s.forgetting),
        Method::InstrumentalVariable { setup, .. } => (setup.decimation, setup.forgetting),
        _ => (1, 1.0),
    };
    let block_variance = raw_variance_g2 / f64::from(decimation);
    let mut estimator = Tracked::new(&probe.method, context)?;
    let period = match probe.method {
        Method::Step(_) | Method::Covariance { .. } => usize::from(decimation),
        _ => usize::MAX,
    };
    let bins_total = bin_of(codes.len()).unwrap_or(0) + 1;
    let mut bins = vec![Bin::default(); bins_total];
    let mut run = LongRun {
        probe: probe.clone(),
        bins: Vec::new(),
        first_flag: None,
        lost_definiteness_at: None,
        last: Outcome::WarmingUp,
        bound_end_g: f64::NAN,
        cpu_s: 0.0,
    };
    let mut determined = false;
    // The bound changes slowly: refresh it once per decimated row.
    let mut bound = f64::NAN;
    for (k, &code) in codes.iter().enumerate() {
        let count = k + 1;
        let reading = estimator.push(f64::from(code) - zero);
        if period != usize::MAX
            && count % period == 0
            && run.lost_definiteness_at.is_none()
            && !estimator.definite(determined)
        {
            run.lost_definiteness_at = Some(count);
        }
        if let (State::Invalid(reason), None) = (reading.state, run.first_flag) {
            run.first_flag = Some((count, reason));
        }
        if count % usize::from(decimation) == 0 {
            bound = steady_bound_g(
                block_variance,
                lambda,
                (count / usize::from(decimation)) as f64,
            );
        }
        determined |= reading.estimate.is_some();
        let Some(bin) = bin_of(count) else {
            continue;
        };
        bins[bin].add(&reading, bound, run.lost_definiteness_at.is_some());
        if count == codes.len() {
            run.last = match (reading.state, reading.estimate) {
                (State::Invalid(reason), _) => Outcome::Flagged(reason),
                (_, Some(estimate)) => Outcome::Valid(estimate - LONG_LOAD_G),
                (_, None) => Outcome::WarmingUp,
            };
            run.bound_end_g = bound;
        }
    }
    run.bins = bins;
    run.cpu_s = start.elapsed().as_secs_f64();
    Ok(run)
}

/// Slice D's results.
pub struct LongResult {
    /// One run per probe.
    pub runs: Vec<LongRun>,
    /// Samples per run.
    pub samples: usize,
    /// Raw-sample noise variance the bounds use, g².
    pub raw_variance_g2: f64,
}

/// Run slice D: one record of `samples` samples (the reference load at 50 dB, steady after
/// the drop), every long probe on it, in parallel over probes.
pub fn run_long_slice(base: &Scene, samples: usize, seed: u64) -> Result<LongResult> {
    let mut scene = base.with_snr_db(50.0);
    let mut script = Script::new(samples as f64 / scene.chain.sample_rate_hz);
    script
        .push(LoadEvent::step(0.0, LONG_LOAD_G))
        .map_err(|e| anyhow!("slice D: {e:?}"))?;
    scene.script = script;
    let mut adc = scene.adc(run_seed(seed, 0));
    // A 16-bit code fits; the record of 10⁷ samples takes 20 MB.
    let codes: Vec<u16> = (0..samples)
        .map(|_| {
            adc.read()
                .map(|c| c.min(u32::from(u16::MAX)) as u16)
                .unwrap_or(0)
        })
        .collect();
    let chain = scene.chain;
    let gain = chain.counts_per_gram();
    let lsb_g = 1.0 / gain;
    let white = scene.disturbances.white_noise_g;
    // The amplifier's noise at the filter output (lag 0); coloured, but 1/65 of the white.
    let amplifier_g2 = crlb::amplifier_autocovariance_g2(&chain, 1)[0];
    let raw_variance_g2 = white * white + lsb_g * lsb_g / 12.0 + amplifier_g2;
    let tare = tare_record(&scene, seed, 0);
    let probes = long_probes();
    let progress = montecarlo::progress_bar(probes.len() as u64);
    let runs: Vec<Result<LongRun>> = probes
        .par_iter()
        .map(|probe| {
            let base = BuildContext {
                noise_check: true,
                ..BuildContext::new(chain, gain).with_adc_rails(chain.zero_code())
            };
            let context = match probe.method.reference_decimation() {
                Some(decimation) => base.with_tare(&tare, decimation),
                None => base,
            };
            let run = run_long(probe, &context, &codes, chain.zero_code(), raw_variance_g2);
            progress.inc(1);
            run
        })
        .collect();
    progress.finish_and_clear();
    Ok(LongResult {
        runs: runs.into_iter().collect::<Result<_>>()?,
        samples,
        raw_variance_g2,
    })
}

impl LongRun {
    /// The decade `[10^j, 10^{j+1})` (the last one closed), aggregated; `None` beyond the run
    /// or when the run covers less than half of it.
    pub fn decade(&self, j: u32) -> Option<Bin> {
        if j < FIRST_DECADE
            || ((self.bins.len() as f64 - 1.0) / BINS_PER_DECADE as f64)
                < f64::from(j - FIRST_DECADE) + 0.5
        {
            return None;
        }
        let first = (j - FIRST_DECADE) as usize * BINS_PER_DECADE;
        let bins = self.bins.get(first..)?;
        if bins.is_empty() {
            return None;
        }
        let mut total = Bin::default();
        for bin in bins.iter().take(BINS_PER_DECADE + 1) {
            total.readings += bin.readings;
            total.valid += bin.valid;
            total.flagged += bin.flagged;
            total.sum_normalised += bin.sum_normalised;
            total.max_error_g = total.max_error_g.max(bin.max_error_g);
            total.valid_after_loss += bin.valid_after_loss;
            total.non_finite += bin.non_finite;
            total.diverged += bin.diverged;
        }
        Some(total)
    }
}

impl Bin {
    /// Count one reading of the steady load, its error judged against `bound`.
    fn add(&mut self, reading: &Reading<f64>, bound: f64, after_loss: bool) {
        self.readings += 1;
        match (reading.state, reading.estimate) {
            (State::Invalid(_), _) => self.flagged += 1,
            (_, Some(estimate)) => {
                let error = estimate - LONG_LOAD_G;
                if !estimate.is_finite() {
                    self.non_finite += 1;
                } else {
                    self.valid += 1;
                    self.sum_normalised += (error / bound) * (error / bound);
                    self.max_error_g = self.max_error_g.max(error.abs());
                    if error.abs() > DIVERGED_FACTOR * LONG_LOAD_G {
                        self.diverged += 1;
                    }
                    if after_loss {
                        self.valid_after_loss += 1;
                    }
                }
            }
            _ => {}
        }
    }

    /// RMS of error / bound over the valid readings.
    pub fn normalised_rms(&self) -> f64 {
        (self.sum_normalised / self.valid as f64).sqrt()
    }

    /// The class of a long-run stretch, and whether a failure was silent.
    pub fn class(&self, lost_before_end: bool, non_finite_flagged: bool) -> (Class, bool) {
        if self.non_finite > 0 {
            return (Class::NonFinite, true);
        }
        if self.diverged > 0 {
            return (Class::Diverged, true);
        }
        if lost_before_end {
            return (Class::LostDefiniteness, self.valid_after_loss > 0);
        }
        if non_finite_flagged {
            return (Class::NonFinite, false);
        }
        if self.valid == 0 {
            return (Class::Refused, false);
        }
        if self.normalised_rms() > BOUND_FACTOR {
            return (Class::OverBound, true);
        }
        if 2 * self.flagged > self.readings {
            return (Class::Refused, false);
        }
        if self.flagged > 0 {
            return (Class::OkPartly, false);
        }
        (Class::Ok, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_start_at_a_thousand_samples_ten_a_decade() {
        assert_eq!(bin_of(999), None);
        assert_eq!(bin_of(1000), Some(0));
        assert_eq!(bin_of(1258), Some(0));
        assert_eq!(bin_of(1259), Some(1));
        assert_eq!(bin_of(10_000), Some(BINS_PER_DECADE));
        assert_eq!(bin_of(10_000_000), Some(4 * BINS_PER_DECADE));
    }

    #[test]
    fn the_steady_bound_is_the_mean_of_the_rows_without_forgetting() {
        assert!(steady_bound_g(4.0, 1.0, 0.5).is_nan());
        assert!((steady_bound_g(4.0, 1.0, 100.0) - 0.2).abs() < 1e-15);
        // With forgetting it levels off at σ²·(1−λ)/(1+λ), and is never below the mean's.
        let lambda: f64 = 0.999;
        let floor = (4.0 * (1.0 - lambda) / (1.0 + lambda)).sqrt();
        assert!((steady_bound_g(4.0, lambda, 1e7) - floor).abs() < 1e-12);
        assert!(steady_bound_g(4.0, lambda, 100.0) >= steady_bound_g(4.0, 1.0, 100.0));
    }

    /// A stretch of `readings`, `flagged` of them flagged, the rest valid at `rms` bounds.
    fn stretch(readings: u64, flagged: u64, rms: f64) -> Bin {
        let valid = readings - flagged;
        Bin {
            readings,
            valid,
            flagged,
            sum_normalised: valid as f64 * rms * rms,
            ..Bin::default()
        }
    }

    #[test]
    fn a_long_stretch_is_classified_like_a_cell() {
        let good = stretch(10, 0, 1.0);
        assert_eq!(good.class(false, false), (Class::Ok, false));
        assert_eq!(good.class(true, false), (Class::LostDefiniteness, false));
        let after_loss = Bin {
            valid_after_loss: 1,
            ..good
        };
        let lost = after_loss.class(true, false);
        assert_eq!(lost, (Class::LostDefiniteness, true));
        assert_eq!(
            stretch(10, 0, 11.0).class(false, false),
            (Class::OverBound, true)
        );
        assert_eq!(
            stretch(10, 6, 1.0).class(false, false),
            (Class::Refused, false)
        );
        assert_eq!(
            stretch(10, 3, 1.0).class(false, false),
            (Class::OkPartly, false)
        );
        assert_eq!(good.class(false, true), (Class::NonFinite, false));
    }

    #[test]
    fn slice_d_probes_every_form_block_length_and_forgetting_factor() {
        let probes = long_probes();
        assert_eq!(
            probes.len(),
            LONG_DECIMATIONS.len() * LONG_FORGETTING.len() * 4 * 2
        );
        assert_eq!(probes[0].family, "step D=1 λ=1");
        assert_eq!(probes[0].method.to_string(), "step:n=7,D=1");
    }
}
