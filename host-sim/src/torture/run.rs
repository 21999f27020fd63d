//! One torture run: the simulated cell plays the plan, the firmware's scale and command
//! state machine (estimator-core, unchanged) read it, and every readout line is judged.

use estimator_core::weighing::{
    Calibration, CalibrationLimits, Command, CommandConfig, CommandOutcome, Commands, CountsScale,
    FrontEnd, RawSample, ScaleFault, ScaleReading, ScaleState, WeighingConfig,
};
use estimator_core::InvalidReason;

use super::judge::{
    Evidence, Limits, Line, LineScatter, NoMass, Steadiness, Tallies, Truth, SCATTER_STILL_S,
};
use super::plan::PLAN_EVENTS;
use super::plan::{ActKind, Instrument, Plan, PlannedCommand};
use super::TortureSettings;
use crate::replay::ConfiguredScale;
use crate::sensor::SensorChain;
use crate::simulated::run_seed;
use crate::simulated::SimulatedAdc;
use std::io::Write as _;

/// Raw samples per readout line (the firmware's 20 Hz readout at 4 kHz).
const READOUT_SAMPLES: u64 = crate::replay::READOUT_SAMPLES as u64;

/// The samples a silent wrong reading's evidence is sought in (4 s; `Evidence`).
const EVIDENCE_SAMPLES: usize = 16_000;

/// A command refused is pressed again each readout for this many samples (2 s).
const RETRY_SAMPLES: u64 = 8000;

/// Run `plan` (drawn for run `run` of `settings`) on the scale of `weighing`, converting with the chain's
/// own gain and zero (a board calibrated right), and tally every readout line.
pub fn run_plan(
    run: u64,
    plan: &Plan,
    settings: &TortureSettings,
    chain: &SensorChain,
    weighing: &WeighingConfig,
    tallies: &mut Tallies,
    trace: Option<&mut dyn std::io::Write>,
) -> Result<(), estimator_core::ConfigError> {
    let limits = &settings.limits;
    // The noise of the cell: another stream than the plan's, of the same run.
    let seed = run_seed(settings.seed, run) ^ 0x5eed;
    let mut trace = trace;
    if let Some(out) = trace.as_mut() {
        let _ = writeln!(
            out,
            "t_s,truth_low_g,truth_high_g,mass_g,u_g,state,final,act,tare_truth_g,event"
        );
        // What the run's noise is: an event row before the first line.
        let _ = writeln!(out, ",,,,,,,,,\"{:?}\"", plan.disturbances);
    }
    let mut adc = SimulatedAdc::<PLAN_EVENTS>::new(*chain, plan.script, plan.disturbances, seed);
    let calibration = CountsScale {
        counts_per_gram: adc.counts_per_gram() as f32,
        zero_counts: adc.zero_code() as f32,
    };
    let mut scale = Box::new(ConfiguredScale::configured(weighing, calibration)?);
    let rate_hz = 1.0 / chain.conversion_period_s();
    // The board checks every calibration against its front end's nominal values: here
    // the chain's own, the design the simulated cell is built to.
    let nominal = Calibration {
        counts_per_gram: calibration.counts_per_gram,
        zero_counts: calibration.zero_counts,
    };
    let calibration_limits = CalibrationLimits {
        nominal,
        gain_tolerance: FrontEnd::GAIN_TOLERANCE,
        zero_tolerance_counts: FrontEnd::ZERO_TOLERANCE_OF_SPAN
            * nominal.counts_per_gram
            * chain.cell.capacity_g as f32,
        max_code: chain.adc.max_code(),
    };
    let mut commands = Commands::new(CommandConfig::weighing_default(
        rate_hz as f32,
        calibration_limits,
    ));
    let mut next_command = 0;
    let mut pending: Option<(u64, PlannedCommand)> = None;
    let mut next_loss = 0;
    let mut losing_until = 0;
    let mut next_act = 0;
    let mut act = ActKind::Boot;
    let mut tare_truth_g = 0.0;
    let mut low = f64::INFINITY;
    let mut high = f64::NEG_INFINITY;
    let mut steadiness = Steadiness::new(0.0);
    // A sample is the mean of the converter's conversions, each with the white noise.
    let oversampling = f64::from(chain.adc.oversampling.max(1));
    let mut evidence = Evidence::new(
        EVIDENCE_SAMPLES,
        plan.disturbances.white_noise_g / oversampling.sqrt(),
    );
    // The raw samples of the line in progress, for the pan's line scatter: their sum in
    // counts, and whether every one was good.
    let mut scatter = LineScatter::default();
    let counts_per_gram = adc.counts_per_gram();
    let mut line_counts = 0.0;
    let mut line_good = true;
    for sample in 0..plan.samples {
        while next_act < plan.acts.len() && plan.acts[next_act].0 <= sample {
            act = plan.acts[next_act].1;
            next_act += 1;
        }
        if next_loss < plan.losses.len() && plan.losses[next_loss].0 <= sample {
            losing_until = sample + plan.losses[next_loss].1;
            next_loss += 1;
        }
        let read = RawSample::read(&mut adc);
        let raw = if sample < losing_until {
            RawSample::Lost
        } else {
            read
        };
        match raw {
            RawSample::Counts(counts) => line_counts += f64::from(counts),
            RawSample::Saturated | RawSample::Lost => line_good = false,
        }
        let reading = scale.push(raw);
        let gross = adc.load_g();
        steadiness.push(sample, gross, limits);
        evidence.push(gross);
        low = low.min(gross);
        high = high.max(gross);
        if (sample + 1) % READOUT_SAMPLES != 0 {
            continue;
        }
        let now = (sample + 1) as u32;
        let steady_s = steadiness.steady_s(sample + 1, rate_hz);
        // A still line: the load the same throughout it, and long enough that a drop's
        // ringing is over (the zero cancels in the differences).
        let still = line_good && low == high && steady_s >= SCATTER_STILL_S;
        scatter.push(still.then(|| line_counts / READOUT_SAMPLES as f64 / counts_per_gram));
        (line_counts, line_good) = (0.0, true);
        let line = line_of(
            &reading,
            low,
            high,
            tare_truth_g,
            steady_s,
            scatter.sigma_g(),
        );
        let time_s = (sample + 1) as f64 / rate_hz;
        let at = (run, time_s, state_name(&reading.state));
        tallies.judge(act, line, limits, at, |shown_g| {
            evidence.z(shown_g + tare_truth_g)
        });
        if let Some(out) = trace.as_mut() {
            let _ = writeln!(
                out,
                "{time_s:.3},{:.4},{:.4},{},{},{},{},{},{tare_truth_g:.4},",
                line.truth.low_g,
                line.truth.high_g,
                line.mass_g.map_or(String::new(), |m| format!("{m:.4}")),
                reading
                    .uncertainty_g
                    .map_or(String::new(), |u| format!("{u:.4}")),
                crate::replay::state_word(&reading.state),
                u8::from(reading.is_final),
                act.key()
            );
        }
        let polled = commands.poll(&mut scale, now);
        if let (Some(out), Some(result)) = (trace.as_mut(), polled.as_ref()) {
            let _ = writeln!(out, ",,,,,,,,,\"calibration {result:?}\"");
        }
        if let Some(Ok(calibration)) = polled {
            scale.recalibrate(calibration.counts_scale());
            tare_truth_g = 0.0;
        }
        while next_command < plan.commands.len() && plan.commands[next_command].0 <= sample {
            pending = Some(plan.commands[next_command]);
            next_command += 1;
        }
        if let Some((at, command)) = pending {
            let command = match command {
                PlannedCommand::Tare => Command::Tare,
                PlannedCommand::ClearTare => Command::ClearTare,
                PlannedCommand::Calibrate { known_mass_g } => Command::Calibrate { known_mass_g },
            };
            let outcome = commands.handle(command, &mut scale, now);
            if let Some(out) = trace.as_mut() {
                let _ = writeln!(out, ",,,,,,,,,\"{command:?} -> {outcome:?}\"");
            }
            match outcome {
                Ok(done) => {
                    pending = None;
                    match (command, done) {
                        (Command::Tare, CommandOutcome::Tared { tare_g }) => {
                            tare_truth_g = tare_truth(f64::from(tare_g), low, high, adc.load_g());
                        }
                        (Command::Tare, _) => tare_truth_g = adc.load_g(),
                        (Command::ClearTare, _) => tare_truth_g = 0.0,
                        _ => {}
                    }
                }
                Err(_) if sample >= at + RETRY_SAMPLES => pending = None,
                Err(_) => {}
            }
        }
        low = gross;
        high = gross;
    }
    tallies.runs += 1;
    Ok(())
}

/// The load a tare accepted at a readout line stands for: of the loads the pan held since
/// the line before (`low_g..high_g`, the truth that line is judged against), the one
/// nearest the gross mass the scale took as tare (`tare_g`). A tare is taken from the
/// reading shown, and that reading is judged right when it lies within the permissible
/// error of any load of its period; so is the tare. Taken instead as the load at the very
/// sample it was accepted, a tare accepted as an item began to move, from a reading of the
/// load before (right by the judge), charged every later net reading with the item's first
/// few milliseconds of motion: 0.5 g on every line for the rest of the run, 96 silent wrong
/// readings in one run of `host-sim torture --runs 10000 --seed 1` with a variant of the
/// scale that showed fewer lines stable. A tare that is not a number stands for the load
/// at the accepting sample (`now_g`): its net lines are judged against a number, and any
/// wrong one counts.
pub(crate) fn tare_truth(tare_g: f64, low_g: f64, high_g: f64, now_g: f64) -> f64 {
    if tare_g.is_finite() && low_g <= high_g {
        tare_g.clamp(low_g, high_g)
    } else {
        now_g
    }
}

/// The readout line as judged: the reading the sample gave (what the firmware prints), the
/// truth of the period since the last line, how long the load has been steady, and the
/// pan's line scatter so far.
fn line_of(
    reading: &ScaleReading,
    low_g: f64,
    high_g: f64,
    tare_g: f64,
    steady_s: f64,
    line_sigma_g: Option<f64>,
) -> Line {
    let settled =
        matches!(reading.state, ScaleState::Stable | ScaleState::Empty) || reading.is_final;
    Line {
        mass_g: reading
            .mass_g
            .map(f64::from)
            .ok_or_else(|| no_mass_why(&reading.state)),
        settled,
        u_g: reading.uncertainty_g.map(f64::from),
        truth: Truth {
            low_g: low_g - tare_g,
            high_g: high_g - tare_g,
            gross_low_g: low_g,
        },
        steady_s,
        line_sigma_g,
    }
}

/// Why a line in `state` shows no mass.
fn no_mass_why(state: &ScaleState) -> NoMass {
    match state {
        ScaleState::Invalid(ScaleFault::Estimator(InvalidReason::ModelMismatch)) => {
            NoMass::ModelMismatch
        }
        ScaleState::Invalid(ScaleFault::Estimator(_)) => NoMass::EstimatorFlag,
        ScaleState::Invalid(_) => NoMass::Fault,
        _ => NoMass::NotYet,
    }
}

/// The state as the readout line names it.
pub fn state_name(state: &ScaleState) -> &'static str {
    match state {
        ScaleState::Empty => "empty",
        ScaleState::Estimating => "estimating",
        ScaleState::Stable => "stable",
        ScaleState::Invalid(_) => "invalid",
    }
}

/// The reference mass the operator calibrates with, g (the firmware's calibration
/// command asks for the same).
pub const CALIBRATION_MASS_G: f64 = 200.0;

/// The instrument a plan is drawn for.
pub fn instrument(limits: &Limits) -> Instrument {
    Instrument {
        capacity_g: limits.capacity_g,
        scale_interval_g: limits.scale_interval_g,
        calibration_mass_g: CALIBRATION_MASS_G,
    }
}

#[cfg(test)]
mod tests {
    use super::tare_truth;

    #[test]
    fn a_tare_stands_for_the_load_of_its_line_nearest_the_value_taken() {
        // A still pan: the load itself, whatever the scale's own error.
        assert_eq!(tare_truth(100.03, 100.0, 100.0, 100.0), 100.0);
        // Accepted as a removal began (the pan held 15.77-16.39 g since the line before):
        // the load the reading was of, not the one at the accepting sample.
        assert_eq!(tare_truth(16.396, 15.766, 16.391, 15.766), 16.391);
        assert_eq!(tare_truth(0.0, 0.0, 0.494, 0.494), 0.0);
        // A tare off every load of its period is charged: the nearest one stands for it,
        // and the net lines after it carry the difference.
        assert_eq!(tare_truth(20.0, 15.766, 16.391, 15.766), 16.391);
        assert_eq!(tare_truth(-1.0, 0.0, 0.494, 0.494), 0.0);
        // A tare that is not a number: the load at the accepting sample, so the lines
        // after it are still judged (a NaN truth would pass every one).
        assert_eq!(tare_truth(f64::NAN, 15.766, 16.391, 15.766), 15.766);
    }
}
