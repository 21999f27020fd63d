//! [`tune`] step by step (see the module docs of `tuning` for what each step does and
//! why): check and identify the drops, measure the noise, plan the loads, synthesise the
//! scenes and detect their onsets, score the candidates, confirm on the recorded drops,
//! choose.
//!
//! Fixed memory: the drops and the Monte Carlo's run slots are the caller's; one estimator
//! at a time on the stack. What it must never do: hand out a configuration that did not
//! meet the target at every scored load, or hide why.

use super::loads;
use super::onset::{summarise, summarise_drop, DropError, DropSummary};
use super::synthetic::{
    run_key, score, upper_order_statistic, RunSlot, Scoring, Synthetic, MIN_RUNS,
};
use super::{
    CandidateGrid, CandidateScore, RecordedCheck, Tuned, TuningError, TuningSettings, CONFIDENCE,
    DEFAULT_RANGE_RELATIVE, MAX_DROPS, MIN_RUNS_WHEN_FAILING, QUANTILE,
};
use crate::estimators::noise_meter::NoiseMeter;
use crate::numerics::real::Real;
use crate::reading::{ConfigError, Estimator};
use crate::sensor::{identify, Identified};
use crate::weighing::{
    cover_ratios, LoadCoverage, LoadScore, Prediction, WeighingConfig, WeighingEstimator,
    WeighingMethod, MAX_LOADS, MAX_SCENES,
};

/// Calibrate: see the module docs. `drops` are raw samples (ADC codes) in `T`, each an
/// empty-pan stretch then the drop of `settings.mass_g`; they are tared in place. `runs`
/// holds the Monte Carlo's slots: `runs.len() / settings.max_scenes()` runs for each scene
/// (at least [`MIN_RUNS`] each). `report` sees every candidate evaluated, in order. `N` is
/// the capacity of the data-driven estimators, `S` the model's states (2 + filter order),
/// `K` the bank's size.
// See `identify_drops` on the error's size.
#[allow(clippy::result_large_err)]
pub fn tune<T: Real, const N: usize, const S: usize, const K: usize>(
    drops: &mut [&mut [T]],
    settings: &TuningSettings,
    grid: &CandidateGrid<'_>,
    runs: &mut [RunSlot],
    report: impl FnMut(&CandidateScore),
) -> Result<Tuned, TuningError> {
    check_drops(drops, settings)?;
    let max_scenes = settings.max_scenes();
    let runs_per_scene = runs.len() / max_scenes;
    let Some(upper_index) = upper_order_statistic(runs_per_scene, QUANTILE, CONFIDENCE) else {
        return Err(TuningError::TooFewRuns {
            runs: runs.len(),
            needed: MIN_RUNS * max_scenes,
        });
    };
    if grid.is_empty() {
        return Err(TuningError::NoCandidates);
    }
    let readout = settings.readout_samples();

    let (identified, summaries) = identify_drops::<T, S>(drops, settings)?;
    let drops: &[&mut [T]] = drops;
    let noise = measure_noise(drops, &summaries)?;
    let loads = plan_loads::<S>(settings, &identified, &noise, readout)?;
    let scenes = synthesise_scenes::<S>(settings, &identified, &noise, &loads.plan, readout)?;
    let detection_lag = detect_onsets(settings, &loads.plan, &scenes, runs, runs_per_scene);
    let config = base_config(
        settings,
        grid,
        &identified,
        &noise,
        &loads,
        detection_lag,
        runs_per_scene,
        drops.len(),
    )?;
    let search = Search {
        settings,
        drops,
        summaries: &summaries,
        plan: &loads.plan,
        scenes: &scenes,
        ratios: (loads.ratio_low, loads.ratio_high),
        raw_variance: noise.raw_variance,
        readout,
        runs_per_scene,
        upper_index,
        recorded_lag: libm::round(detection_lag).max(0.0) as usize,
    };
    let outcome = search.candidates::<N, K>(grid, &config, runs, report)?;
    choose(config, outcome).map(|(config, chosen, evaluated)| Tuned {
        config,
        chosen,
        identified,
        drops: summaries,
        evaluated,
        noise_relative_standard_error: noise.relative_error,
        monte_carlo_noise_variance_counts2: noise.monte_carlo_variance,
        synthetic_empty_samples: scenes.empty,
        runs_per_scene,
    })
}

/// Step 3: the noise pooled over the drops' empty stretches, the upper confidence value the
/// Monte Carlo uses, and the zero the empty stretches show.
struct Noise {
    raw_variance: f64,
    relative_error: f64,
    monte_carlo_variance: f64,
    /// The Monte Carlo's noise standard deviation, counts.
    sigma: f64,
    zero_counts: f64,
    /// The shortest empty stretch before an onset, samples.
    shortest_empty: usize,
}

#[allow(clippy::result_large_err)]
fn measure_noise<T: Real>(
    drops: &[&mut [T]],
    summaries: &[Option<DropSummary>; MAX_DROPS],
) -> Result<Noise, TuningError> {
    let (raw_variance, relative_error) =
        pooled_noise(drops, summaries, 1).ok_or(TuningError::Settings(ConfigError::Model))?;
    let monte_carlo_variance = raw_variance * (1.0 + 2.0 * relative_error);
    let sigma = libm::sqrt(monte_carlo_variance);
    let (mut zero_sum, mut zero_weight) = (0.0, 0.0);
    let mut shortest_empty = usize::MAX;
    for summary in summaries.iter().flatten() {
        zero_sum += summary.zero * summary.empty_samples as f64;
        zero_weight += summary.empty_samples as f64;
        shortest_empty = shortest_empty.min(summary.onset);
    }
    Ok(Noise {
        raw_variance,
        relative_error,
        monte_carlo_variance,
        sigma,
        zero_counts: zero_sum / zero_weight,
        shortest_empty,
    })
}

/// Step 4: the load range (its top within what the converter takes), the scenes to score
/// and the span of their resonances.
struct LoadRange {
    plan: loads::Plan,
    min_g: f64,
    max_g: f64,
    ratio_low: f64,
    ratio_high: f64,
}

#[allow(clippy::result_large_err)]
fn plan_loads<const S: usize>(
    settings: &TuningSettings,
    identified: &Identified,
    noise: &Noise,
    readout: usize,
) -> Result<LoadRange, TuningError> {
    let mass_g = settings.mass_g;
    let saturation = |high_g: f64| {
        loads::saturation_limit::<S>(
            &identified.model,
            mass_g,
            high_g,
            settings.platform_mass_g,
            noise.zero_counts,
            (settings.onset.rail_low, settings.onset.rail_high),
            libm::sqrt(noise.raw_variance),
            readout,
        )
    };
    let (default_low, default_high) = DEFAULT_RANGE_RELATIVE;
    let max_g = match settings.max_load_g {
        Some(high) => {
            let limit_g = saturation(high)?;
            if limit_g < high {
                return Err(TuningError::LoadSaturates {
                    mass_g: high,
                    limit_g,
                });
            }
            high.max(mass_g)
        }
        None => saturation(default_high * mass_g)?,
    };
    let min_g = settings
        .min_load_g
        .unwrap_or(default_low * mass_g)
        .min(mass_g);
    if min_g > max_g {
        return Err(TuningError::Settings(ConfigError::Range));
    }
    let plan = if settings.calibration_mass_only() {
        loads::Plan::new(mass_g, mass_g, mass_g, 1, Some(0.0))
    } else {
        loads::Plan::new(
            mass_g,
            min_g,
            max_g,
            settings.loads,
            settings.platform_mass_g,
        )
    };
    let (mut ratio_low, mut ratio_high) = (1.0f64, 1.0f64);
    for scene in &plan.scenes[..plan.count] {
        ratio_low = ratio_low.min(scene.frequency_ratio);
        ratio_high = ratio_high.max(scene.frequency_ratio);
    }
    Ok(LoadRange {
        plan,
        min_g,
        max_g,
        ratio_low,
        ratio_high,
    })
}

/// Step 5, first half: each scene's synthetic drops (the identified model moved to the
/// scene's load) and its noise floor.
struct Scenes<const S: usize> {
    synthetics: [Option<Synthetic<S>>; MAX_SCENES],
    floors: [f64; MAX_SCENES],
    /// Empty samples before each synthetic drop.
    empty: usize,
}

#[allow(clippy::result_large_err)]
fn synthesise_scenes<const S: usize>(
    settings: &TuningSettings,
    identified: &Identified,
    noise: &Noise,
    plan: &loads::Plan,
    readout: usize,
) -> Result<Scenes<S>, TuningError> {
    let reference = settings.onset.min_empty_samples;
    let empty = noise
        .shortest_empty
        .min(2 * reference)
        .max(reference + settings.onset.guard_samples + 1);
    let tare_samples = empty - settings.onset.guard_samples;
    let mut synthetics: [Option<Synthetic<S>>; MAX_SCENES] = [None; MAX_SCENES];
    let mut floors = [0.0f64; MAX_SCENES];
    for (index, scene) in plan.scenes[..plan.count].iter().enumerate() {
        let synthetic = Synthetic {
            model: identified
                .model
                .with_frequency_ratio(scene.frequency_ratio)
                .sensor_model::<f64, S>()?,
            mass_g: scene.mass_g,
            sigma: noise.sigma,
            empty,
            length: empty + readout + 1,
        };
        floors[index] = loads::noise_floor_g(
            &synthetic,
            readout,
            tare_samples,
            identified.model.counts_per_gram,
        );
        synthetics[index] = Some(synthetic);
    }
    Ok(Scenes {
        synthetics,
        floors,
        empty,
    })
}

/// Step 5, second half: the onset of every synthetic drop, once (it does not depend on the
/// method), into its run slot; the scene scored k-th in the plan's order takes the slots
/// [k·R, (k + 1)·R), so the calibration mass has runs 0..R. Returns the mean detection lag
/// at the calibration mass.
fn detect_onsets<const S: usize>(
    settings: &TuningSettings,
    plan: &loads::Plan,
    scenes: &Scenes<S>,
    runs: &mut [RunSlot],
    runs_per_scene: usize,
) -> f64 {
    // The synthetic drops have no rails.
    let mut synthetic_onset = settings.onset;
    synthetic_onset.rail_low = f64::NEG_INFINITY;
    synthetic_onset.rail_high = f64::INFINITY;
    let (mut lag_sum, mut detected) = (0.0, 0usize);
    for (position, &scene) in plan.order[..plan.count].iter().enumerate() {
        let Some(synthetic) = &scenes.synthetics[scene] else {
            continue;
        };
        let first = position * runs_per_scene;
        for (run, slot) in runs[first..first + runs_per_scene].iter_mut().enumerate() {
            let run = (first + run) as u32;
            let key = run_key(settings.seed, u64::from(run));
            *slot = RunSlot {
                run,
                ..RunSlot::EMPTY
            };
            if let Ok(summary) = summarise(|| synthetic.samples(key, 0), &synthetic_onset) {
                slot.onset = summary.onset as u32;
                slot.zero = summary.zero;
                if scene == plan.calibration {
                    lag_sum += summary.onset as f64 - scenes.empty as f64;
                    detected += 1;
                }
            }
        }
    }
    lag_sum / detected.max(1) as f64
}

/// The configuration every candidate starts from: the first candidate's method, the
/// measured gain, zero and noise, the load range, and no scores yet.
#[allow(clippy::too_many_arguments, clippy::result_large_err)]
fn base_config(
    settings: &TuningSettings,
    grid: &CandidateGrid<'_>,
    identified: &Identified,
    noise: &Noise,
    loads: &LoadRange,
    detection_lag: f64,
    runs_per_scene: usize,
    count: usize,
) -> Result<WeighingConfig, TuningError> {
    let identified_gain = identified.model.counts_per_gram;
    let gain = settings.counts_per_gram.unwrap_or(identified_gain);
    let mut model = identified.model;
    model.counts_per_gram = gain;
    Ok(WeighingConfig {
        method: grid
            .get(0, settings.identify.sample_rate_hz)
            .ok_or(TuningError::NoCandidates)?,
        counts_per_gram: gain,
        zero_counts: noise.zero_counts,
        noise_variance_counts2: noise.raw_variance,
        raw_noise_variance_counts2: noise.raw_variance,
        onset: settings.onset,
        detection_lag_samples: detection_lag,
        model,
        identified_counts_per_gram: identified_gain,
        calibration_mass_g: settings.mass_g,
        readout_s: settings.readout_s,
        target_relative: settings.target_relative,
        prediction: Prediction {
            runs: 0,
            planned_runs: runs_per_scene as u32,
            valid_runs: 0,
            within_target_runs: 0,
            detection_failures: 0,
            bias_g: 0.0,
            rms_g: 0.0,
            p95_g: f64::INFINITY,
            p95_upper_g: f64::INFINITY,
        },
        recorded_drops: count as u32,
        recorded_worst_error_g: f64::INFINITY,
        capacity_g: crate::weighing::WeighingConfig::REFERENCE_CAPACITY_G,
        scale_interval_g: crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        final_target_g: crate::weighing::WeighingConfig::FINAL_TARGET_E
            * crate::weighing::WeighingConfig::REFERENCE_SCALE_INTERVAL_G,
        loads: LoadCoverage {
            min_g: loads.min_g,
            max_g: loads.max_g,
            loads: if settings.calibration_mass_only() {
                1
            } else {
                settings.loads as u32
            },
            platform_mass_g: settings.platform_mass_g,
            scores: [None; MAX_SCENES],
        },
    })
}

/// Steps 5 (scores) and 6 (confirmation) for each candidate: what they share.
struct Search<'a, 'd, T, const S: usize> {
    settings: &'a TuningSettings,
    drops: &'a [&'d mut [T]],
    summaries: &'a [Option<DropSummary>; MAX_DROPS],
    plan: &'a loads::Plan,
    scenes: &'a Scenes<S>,
    /// The span of the scenes' resonances over the calibration mass's.
    ratios: (f64, f64),
    raw_variance: f64,
    readout: usize,
    runs_per_scene: usize,
    upper_index: usize,
    /// Samples before the detected onset where the recorded drops are also started.
    recorded_lag: usize,
}

/// What the candidates gave: the first that met the target (with its noise variance), the
/// best by rank, and how many were evaluated.
struct Outcome {
    chosen: Option<(CandidateScore, f64)>,
    best: Option<CandidateScore>,
    evaluated: usize,
}

impl<T: Real, const S: usize> Search<'_, '_, T, S> {
    /// Candidates, smallest first, until the first that meets the target (or all, with
    /// `evaluate_all`). At each, the scenes in the plan's order, except that the scene that
    /// stopped the previous candidate comes right after the calibration mass (neighbouring
    /// candidates tend to fail at the same load, and a failing one stops there).
    #[allow(clippy::result_large_err)]
    fn candidates<const N: usize, const K: usize>(
        &self,
        grid: &CandidateGrid<'_>,
        config: &WeighingConfig,
        runs: &mut [RunSlot],
        mut report: impl FnMut(&CandidateScore),
    ) -> Result<Outcome, TuningError> {
        let target = self.settings.target_relative;
        let mut outcome = Outcome {
            chosen: None,
            best: None,
            evaluated: 0,
        };
        let mut last_failed: Option<usize> = None;
        for index in 0..grid.len() {
            let Some(method) = grid.get(index, self.settings.identify.sample_rate_hz) else {
                break;
            };
            let (scored, method_variance) =
                self.candidate::<N, K>(index, method, config, runs, &mut last_failed)?;
            outcome.evaluated += 1;
            report(&scored);
            if outcome
                .best
                .is_none_or(|b| scored.rank(target) < b.rank(target))
            {
                outcome.best = Some(scored);
            }
            if scored.meets && outcome.chosen.is_none() {
                outcome.chosen = Some((scored, method_variance));
                if !self.settings.evaluate_all {
                    break;
                }
            }
        }
        Ok(outcome)
    }

    /// One candidate: built on `config`, scored scene by scene until one fails, confirmed on
    /// the recorded drops if none did, and checked against the valid region. Returns its
    /// score and the noise variance it was built with.
    #[allow(clippy::result_large_err)]
    fn candidate<const N: usize, const K: usize>(
        &self,
        index: usize,
        mut method: WeighingMethod,
        config: &WeighingConfig,
        runs: &mut [RunSlot],
        last_failed: &mut Option<usize>,
    ) -> Result<(CandidateScore, f64), TuningError> {
        if let WeighingMethod::ModelBank {
            candidates,
            ratio_min,
            ratio_max,
            ..
        } = &mut method
        {
            let (ratio_low, ratio_high) = self.ratios;
            cover_ratios(*candidates, ratio_min, ratio_max, ratio_low, ratio_high);
        }
        // The bias-compensated method takes the noise as its block means see it.
        let method_variance = pooled_noise(self.drops, self.summaries, method.decimation())
            .map(|(variance, _)| variance)
            .unwrap_or(self.raw_variance);
        let mut candidate = *config;
        candidate.method = method;
        candidate.noise_variance_counts2 = method_variance;
        // Tared data, and neither the synthetic nor the (checked) recorded drops reach a rail.
        candidate.onset.rail_low = f64::NEG_INFINITY;
        candidate.onset.rail_high = f64::INFINITY;
        let mut estimator = WeighingEstimator::<T, N, S, K>::with_method(&candidate, &method, 0.0)
            .map_err(|error| TuningError::Candidate { method, error })?;

        let (load_scores, loads_met, failed_load) =
            self.score_scenes(&mut estimator, runs, last_failed);
        let prediction = load_scores[self.plan.calibration]
            .map_or(config.prediction, |s: LoadScore| s.prediction);
        let recorded = failed_load
            .is_none()
            .then(|| self.confirm_recorded(&mut estimator));
        // Never choose a configuration outside the stability map's valid region, whatever it
        // scored: its failures there would not be flagged at run time
        // (`WeighingConfig::check_region`).
        let outside_region = candidate.check_region().err();
        // Nor one a board's scale could never show stable (no `u` there).
        let states_no_uncertainty = !method.states_uncertainty_on_board();
        let meets = matches!(recorded, Some(check) if check.failing == 0)
            && outside_region.is_none()
            && !states_no_uncertainty;
        let scored = CandidateScore {
            index,
            method,
            prediction,
            loads: load_scores,
            loads_met,
            failed_load,
            recorded,
            meets,
            outside_region,
            states_no_uncertainty,
        };
        Ok((scored, method_variance))
    }

    /// Step 5: the candidate's Monte Carlo at each scene, the calibration mass first, then
    /// the scene that stopped the previous candidate, then the plan's order; stopped at the
    /// first scene it cannot meet (which `last_failed` then names).
    fn score_scenes<E: Estimator<T>>(
        &self,
        estimator: &mut E,
        runs: &mut [RunSlot],
        last_failed: &mut Option<usize>,
    ) -> ([Option<LoadScore>; MAX_SCENES], u32, Option<LoadScore>) {
        let plan = self.plan;
        let mut sequence = [0usize; MAX_SCENES];
        let mut length = 0;
        let mut push = |scene: usize| {
            if !sequence[..length].contains(&scene) {
                sequence[length] = scene;
                length += 1;
            }
        };
        push(plan.calibration);
        if let Some(scene) = *last_failed {
            push(scene);
        }
        for &scene in &plan.order[..plan.count] {
            push(scene);
        }
        let mut load_scores = [None; MAX_SCENES];
        let (mut loads_met, mut failed_load) = (0u32, None);
        for &scene in &sequence[..length] {
            let Some(synthetic) = &self.scenes.synthetics[scene] else {
                continue;
            };
            let position = plan.order[..plan.count]
                .iter()
                .position(|&s| s == scene)
                .unwrap_or(0);
            let first = position * self.runs_per_scene;
            let target_g = self.settings.target_relative * synthetic.mass_g;
            let scoring = Scoring {
                readout_samples: self.readout,
                target_g,
                upper_index: self.upper_index,
                min_runs: MIN_RUNS_WHEN_FAILING,
            };
            let prediction = score(
                estimator,
                synthetic,
                self.settings.seed,
                &mut runs[first..first + self.runs_per_scene],
                &scoring,
            );
            let load_score = LoadScore {
                scene: plan.scenes[scene],
                noise_floor_g: self.scenes.floors[scene],
                prediction,
            };
            load_scores[scene] = Some(load_score);
            if prediction.p95_upper_g <= target_g {
                loads_met += 1;
            } else {
                failed_load = Some(load_score);
                *last_failed = Some(scene);
                break;
            }
        }
        (load_scores, loads_met, failed_load)
    }

    /// Step 6: the candidate on the recorded drops.
    fn confirm_recorded<E: Estimator<T>>(&self, estimator: &mut E) -> RecordedCheck {
        let mass_g = self.settings.mass_g;
        confirm(
            estimator,
            self.drops,
            self.summaries,
            self.recorded_lag,
            self.readout,
            mass_g,
            self.settings.target_relative * mass_g,
        )
    }
}

/// Step 7: the first candidate that met the target, written into `config`; else why none
/// did, naming the best.
#[allow(clippy::result_large_err)]
fn choose(
    mut config: WeighingConfig,
    outcome: Outcome,
) -> Result<(WeighingConfig, CandidateScore, usize), TuningError> {
    let Outcome {
        chosen,
        best,
        evaluated,
    } = outcome;
    let Some((chosen, method_variance)) = chosen else {
        return Err(match best {
            Some(best) => TuningError::NoneMeetsTarget {
                best: best.method,
                prediction: best.prediction,
                failed_load: best.failed_load,
                recorded_failing: best.recorded.map(|check| check.failing),
                evaluated,
            },
            None => TuningError::NoCandidates,
        });
    };
    config.method = chosen.method;
    config.noise_variance_counts2 = method_variance;
    config.prediction = chosen.prediction;
    config.loads.scores = chosen.loads;
    if let Some(check) = chosen.recorded {
        config.recorded_worst_error_g = check.worst_error_g;
    }
    Ok((config, chosen, evaluated))
}

/// Steps 1 and 2 of [`tune`] on their own: each drop checked (and required to hold the
/// readout after its onset), its zero, noise and onset found and the drop tared **in
/// place**, then the model identified from the onsets at `settings.mass_g`. Calibration
/// calls it; a caller that has drops of a second mass uses it to identify the resonance there
/// and then the platform mass ([`super::platform_mass_from_resonances`]).
// The error is ~200 bytes (the best candidate's figures where it failed) and there is no
// heap to box it into; it is returned once per calibration.
#[allow(clippy::result_large_err)]
pub fn identify_drops<T: Real, const S: usize>(
    drops: &mut [&mut [T]],
    settings: &TuningSettings,
) -> Result<(Identified, [Option<DropSummary>; MAX_DROPS]), TuningError> {
    check_drops(drops, settings)?;
    let summaries = summarise_and_tare(drops, settings)?;
    // The sensor, from each drop's onset.
    let mut slices: [&[T]; MAX_DROPS] = [&[]; MAX_DROPS];
    for ((slice, drop), summary) in slices.iter_mut().zip(drops.iter()).zip(&summaries) {
        if let Some(summary) = summary {
            *slice = &drop[summary.onset..];
        }
    }
    let identified = identify::<T, S>(&slices[..drops.len()], &settings.identify)
        .map_err(TuningError::Identify)?;
    Ok((identified, summaries))
}

/// The settings valid, and between one and [`MAX_DROPS`] drops.
#[allow(clippy::result_large_err)]
fn check_drops<T>(drops: &[&mut [T]], settings: &TuningSettings) -> Result<(), TuningError> {
    check_settings(settings)?;
    if drops.is_empty() {
        return Err(TuningError::NoDrops);
    }
    if drops.len() > MAX_DROPS {
        return Err(TuningError::TooManyDrops { drops: drops.len() });
    }
    Ok(())
}

/// Step 1: each drop checked (NaN, saturation, long enough for the readout after its
/// onset), its zero, noise and onset found; then the drop tared in place.
#[allow(clippy::result_large_err)]
fn summarise_and_tare<T: Real>(
    drops: &mut [&mut [T]],
    settings: &TuningSettings,
) -> Result<[Option<DropSummary>; MAX_DROPS], TuningError> {
    let readout = settings.readout_samples();
    let mut summaries: [Option<DropSummary>; MAX_DROPS] = [None; MAX_DROPS];
    for (index, drop) in drops.iter_mut().enumerate() {
        let summary = summarise_drop(drop, &settings.onset)
            .map_err(|error| TuningError::Drop { drop: index, error })?;
        let needed = summary.onset + readout + 1;
        if drop.len() < needed {
            return Err(TuningError::Drop {
                drop: index,
                error: DropError::TooShort {
                    samples: drop.len(),
                    needed,
                },
            });
        }
        for y in drop.iter_mut() {
            *y = T::from_f64(y.to_f64() - summary.zero);
        }
        summaries[index] = Some(summary);
    }
    Ok(summaries)
}

fn check_settings(settings: &TuningSettings) -> Result<(), ConfigError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(settings.mass_g) || settings.identify.mass_g != settings.mass_g {
        return Err(ConfigError::Gain);
    }
    if let Some(gain) = settings.counts_per_gram {
        if !gain.is_finite() || gain == 0.0 {
            return Err(ConfigError::Gain);
        }
    }
    if !positive(settings.readout_s)
        || settings.readout_samples() == 0
        || !positive(settings.target_relative)
        || !settings.onset.is_valid()
    {
        return Err(ConfigError::Model);
    }
    let range_ok = settings.min_load_g.is_none_or(positive)
        && settings.max_load_g.is_none_or(positive)
        && match (settings.min_load_g, settings.max_load_g) {
            (Some(low), Some(high)) => low <= high,
            _ => true,
        };
    let platform_ok = settings
        .platform_mass_g
        .is_none_or(|m| m.is_finite() && m >= 0.0);
    if !range_ok || !platform_ok || !(1..=MAX_LOADS).contains(&settings.loads) {
        return Err(ConfigError::Range);
    }
    Ok(())
}

/// The pooled noise variance over the drops' empty stretches with block means of
/// `decimation`, and its relative standard error.
fn pooled_noise<T: Real>(
    drops: &[&mut [T]],
    summaries: &[Option<DropSummary>; MAX_DROPS],
    decimation: u16,
) -> Option<(f64, f64)> {
    let mut meter = NoiseMeter::<f64>::new(decimation).ok()?;
    for (drop, summary) in drops.iter().zip(summaries.iter()) {
        let summary = summary.as_ref()?;
        for &y in &drop[..summary.empty_samples] {
            meter.push(y.to_f64()).ok()?;
        }
        meter.push_missing();
    }
    Some((meter.noise_variance()?, meter.relative_standard_error()?))
}

/// Run `method` on each drop (tared) from its detected onset and from `lag` samples before
/// it (the estimate of the landing), read both at the readout after the earlier start, and
/// keep the larger |error|.
fn confirm<T: Real, E: Estimator<T>>(
    estimator: &mut E,
    drops: &[&mut [T]],
    summaries: &[Option<DropSummary>; MAX_DROPS],
    lag: usize,
    readout: usize,
    mass_g: f64,
    target_g: f64,
) -> RecordedCheck {
    let mut check = RecordedCheck {
        drops: 0,
        errors_g: [0.0; MAX_DROPS],
        failing: 0,
        worst_drop: 0,
        worst_error_g: 0.0,
    };
    for (index, (drop, summary)) in drops.iter().zip(summaries.iter()).enumerate() {
        let Some(summary) = summary else { continue };
        let landing = summary.onset.saturating_sub(lag);
        // The caller checked that every drop holds the readout after its onset.
        let end = (landing + readout + 1).min(drop.len());
        let mut error = 0.0f64;
        for start in [summary.onset, landing] {
            estimator.reset();
            let mut last = None;
            for &y in &drop[start.min(end)..end] {
                last = estimator.push(y).estimate;
            }
            let this = match last {
                Some(estimate) if estimate.is_finite() => estimate.to_f64() - mass_g,
                _ => f64::INFINITY,
            };
            if !(libm::fabs(this) <= libm::fabs(error)) {
                error = this;
            }
        }
        check.errors_g[index] = error;
        check.drops += 1;
        if !(libm::fabs(error) <= target_g) {
            check.failing += 1;
        }
        if !(libm::fabs(error) <= check.worst_error_g) {
            check.worst_error_g = libm::fabs(error);
            check.worst_drop = index as u32;
        }
    }
    check
}
