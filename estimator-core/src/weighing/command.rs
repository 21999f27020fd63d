//! Operator commands around a [`Scale`]: tare, clear tare, calibration with a known mass.
//!
//! The boards only move bytes and button levels here: a UART byte becomes a [`Command`]
//! (QEMU), a debounced [`crate::weighing::KeyPress`] becomes one (STM32F411), and [`Commands::handle`]
//! decides against the scale's current reading, with a typed [`CommandRefusal`] when it says
//! no. A tare is taken from the estimate when the reading is stable, which can be as early
//! as 50 ms into a load; while that load stays on, [`Commands::poll`] re-takes it from the
//! estimator's longer average, within the stability band around the first value, so the
//! early estimate's error does not stay in every net reading (it freezes at the next load
//! change, and the band bounds what a slow, undetected change could pull into it).
//! Calibration takes two settled readings in ADC counts: the empty pan when the command
//! arrives, then the known mass once it is on and settled ([`Commands::poll`]); the result
//! goes through [`crate::weighing::store_calibration`] (encode, write, read back through the CRC decoder) and
//! only what the store gives back is applied ([`Scale::recalibrate`]), so the calibration
//! in use is always the one the board would load after a reset. Both points are checked
//! against the board's [`CalibrationLimits`] (the front end's nominal gain and zero and
//! their tolerances), never against the calibration in use: a wrong calibration cannot
//! widen the window for the next one.
//!
//! What it must never do: take a tare or a calibration point from a reading that is not
//! settled, accept a calibration that makes no physical sense (no span, a gain or zero far
//! from the nominal ones), apply a record the store cannot give back intact, or block:
//! every function returns at once, so a board may call it from any task.

use super::calibration::{Calibration, CalibrationError, CalibrationLimits};
use super::scale::{
    Scale, ScaleEstimator, ScaleFault, ScaleReading, ScaleState, TareError, ZeroError,
};

/// What the operator asked for.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Take the current gross mass as tare.
    Tare,
    /// Remove the tare.
    ClearTare,
    /// Set the zero to the current gross reading (semi-automatic zero setting).
    Zero,
    /// Start a calibration: the empty pan now, then `known_mass_g` put on.
    Calibrate {
        /// The reference mass the operator will put on, in grams.
        known_mass_g: f32,
    },
    /// Abandon a calibration in progress (the calibration in use stays).
    CancelCalibration,
}

impl Command {
    /// The command a console byte stands for: `t` tare, `u` clear tare (untare), `z` set
    /// the zero, `c` calibrate with `known_mass_g`, `x` cancel a calibration (either case). `None` for any
    /// other byte; the board decides whether to report it.
    pub fn from_byte(byte: u8, known_mass_g: f32) -> Option<Self> {
        match byte.to_ascii_lowercase() {
            b't' => Some(Self::Tare),
            b'u' => Some(Self::ClearTare),
            b'z' => Some(Self::Zero),
            b'c' => Some(Self::Calibrate { known_mass_g }),
            b'x' => Some(Self::CancelCalibration),
            _ => None,
        }
    }
}

/// What an accepted command did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandOutcome {
    /// The tare is now `tare_g` grams: the display reads net of it.
    Tared {
        /// The gross mass taken as tare.
        tare_g: f32,
    },
    /// The tare is zero again.
    TareCleared,
    /// The current gross reading is the new zero.
    Zeroed,
    /// The empty-pan zero is taken; the calibration completes once `known_mass_g` is on
    /// the pan and settled (see [`Commands::poll`]).
    CalibrationStarted {
        /// The empty pan in ADC counts.
        zero_counts: f32,
        /// The mass the operator must put on.
        known_mass_g: f32,
    },
    /// The calibration in progress was abandoned.
    CalibrationCancelled,
}

/// Why a command was refused. Nothing changed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandRefusal {
    /// The reading is not settled (still estimating, or not stable for long enough).
    Unstable,
    /// The reading is stable but not yet known well enough for a tare (within ±0.25 e,
    /// see `scale::TARE_ACCURACY_E`): try again in a moment.
    Uncertain,
    /// The scale shows no mass, and why.
    Invalid(ScaleFault),
    /// A calibration zero needs an empty pan, and the pan holds a good part of the known
    /// mass already.
    NotEmpty,
    /// A calibration is in progress: only cancelling it is accepted.
    CalibrationInProgress,
    /// There is no calibration in progress to cancel.
    NotCalibrating,
    /// Zero setting: the pan holds more than the zero-setting range allows
    /// (`scale::ZERO_SETTING_RANGE_OF_MAX` of Max from the calibrated zero).
    OutOfZeroRange,
    /// Zero setting while a tare is in use: clear the tare first.
    Tared,
    /// The known mass is not a positive, finite number of grams.
    BadKnownMass,
    /// The empty-pan zero is outside the board's limits (on a rail, or far from the
    /// nominal zero): a fault in the chain, or a pan that is not empty.
    Implausible(CalibrationError),
}

/// Why a calibration in progress ended without a result. The calibration in use stays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationFailure {
    /// The known mass made no positive change in counts.
    NoSpan,
    /// The measured calibration is outside the board's limits, and why: a gain off the
    /// nominal one by more than the tolerance (`GainOffNominal`, the wrong reference mass
    /// or a fault in the analogue chain) or an implausible zero.
    Implausible(CalibrationError),
    /// No settled known mass within the timeout.
    TimedOut,
    /// A load was put on after the zero and the pan was empty again before it settled: the
    /// operator took the reference mass off (the next load on the pan is not it).
    MassRemoved,
}

/// Tuning of the command decisions. Durations in raw samples.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CommandConfig {
    /// A calibration point (the zero, then the known mass) is taken only from a reading
    /// that is stable (or empty) and this long after the last load change.
    pub calibration_settle_samples: u32,
    /// The calibration zero is refused (`NotEmpty`) when the pan reads more than this
    /// fraction of the known mass with the calibration in use.
    pub zero_limit_fraction: f32,
    /// The window a calibration must fall in: the board's nominal gain and zero and their
    /// tolerances (`FrontEnd::calibration_limits` on hardware).
    pub limits: CalibrationLimits,
    /// A calibration waiting this long for the known mass gives up (`TimedOut`).
    pub calibration_timeout_samples: u32,
    /// Once a load is seen on the pan, the known mass must be measured within this long,
    /// or the calibration gives up (`TimedOut`): a mass the scale could not read settled
    /// may be taken off and another load put on unseen.
    pub calibration_settle_timeout_samples: u32,
}

impl CommandConfig {
    /// Defaults for the weighing firmware.
    ///
    /// Why these numbers:
    /// - settle 0.5 s: the estimate of a settled load is within 0.1 % 100 ms after the
    ///   change and then only gains averaging (growing window); 0.5 s keeps a hand that
    ///   just let go of the pan or the button out of the calibration;
    /// - zero limit 10 % of the known mass: far above any zero offset of a working chain
    ///   (the board's REF pin tolerance is about a gram), far below the known mass itself;
    /// - `limits`: the board's, passed in (the tolerances are argued at
    ///   `FrontEnd::GAIN_TOLERANCE`);
    /// - timeout 60 s: time to fetch the reference mass, not so long that a forgotten
    ///   calibration waits forever.
    pub fn weighing_default(sample_rate_hz: f32, limits: CalibrationLimits) -> Self {
        Self {
            calibration_settle_samples: (0.5 * sample_rate_hz) as u32,
            zero_limit_fraction: 0.1,
            limits,
            calibration_timeout_samples: (60.0 * sample_rate_hz) as u32,
            // A reference mass put on settles within about 1.5 s (the raw tests' arming);
            // 5 s leaves room for a placement by hand.
            calibration_settle_timeout_samples: (5.0 * sample_rate_hz) as u32,
        }
    }
}

/// Where a calibration stands.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Idle,
    AwaitingMass {
        known_mass_g: f32,
        zero_counts: f32,
        changes_at_zero: u32,
        started_sample: u32,
        /// When a load (at least the zero limit, a tenth of the known mass, or a reading
        /// with no mass) was first seen since the zero.
        seen_at: Option<u32>,
    },
}

/// A tare being refined: the gross mass when it was taken, and the load-change count then.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TareRefinement {
    tare_g: f32,
    load_changes: u32,
}

/// The command state machine: decides each command against a scale, refines a fresh tare
/// and carries a calibration from its zero to its known mass.
#[derive(Clone, Debug, PartialEq)]
pub struct Commands {
    config: CommandConfig,
    phase: Phase,
    refining: Option<TareRefinement>,
}

impl Commands {
    /// No calibration in progress.
    pub fn new(config: CommandConfig) -> Self {
        Self {
            config,
            phase: Phase::Idle,
            refining: None,
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &CommandConfig {
        &self.config
    }

    /// True while a calibration waits for its known mass.
    pub fn is_calibrating(&self) -> bool {
        matches!(self.phase, Phase::AwaitingMass { .. })
    }

    /// Decide `command` against the scale's current reading. `now_sample` is the board's
    /// sample count (wrapping), used for the calibration timeout only.
    pub fn handle<E: ScaleEstimator>(
        &mut self,
        command: Command,
        scale: &mut Scale<E>,
        now_sample: u32,
    ) -> Result<CommandOutcome, CommandRefusal> {
        if self.is_calibrating() && command != Command::CancelCalibration {
            return Err(CommandRefusal::CalibrationInProgress);
        }
        match command {
            Command::Tare => {
                let reading = scale.reading();
                settled(&reading, 0)?;
                scale.tare().map_err(|error| match error {
                    TareError::NotStable => CommandRefusal::Unstable,
                    TareError::Uncertain => CommandRefusal::Uncertain,
                })?;
                self.refining = Some(TareRefinement {
                    tare_g: scale.tare_g(),
                    load_changes: reading.load_changes,
                });
                Ok(CommandOutcome::Tared {
                    tare_g: scale.tare_g(),
                })
            }
            Command::Zero => {
                settled(&scale.reading(), 0)?;
                scale.set_zero().map_err(|error| match error {
                    ZeroError::NotStable => CommandRefusal::Unstable,
                    ZeroError::Uncertain => CommandRefusal::Uncertain,
                    ZeroError::OutOfRange => CommandRefusal::OutOfZeroRange,
                    ZeroError::Tared => CommandRefusal::Tared,
                })?;
                Ok(CommandOutcome::Zeroed)
            }
            Command::ClearTare => {
                scale.clear_tare();
                self.refining = None;
                Ok(CommandOutcome::TareCleared)
            }
            Command::Calibrate { known_mass_g } => {
                if !(known_mass_g.is_finite() && known_mass_g > 0.0) {
                    return Err(CommandRefusal::BadKnownMass);
                }
                let reading = scale.reading();
                settled(&reading, self.config.calibration_settle_samples)?;
                let zero_counts = scale.gross_counts().ok_or(CommandRefusal::Unstable)?;
                let in_use = scale.counts_scale();
                let gross_g = (zero_counts - in_use.zero_counts) / in_use.counts_per_gram;
                if !(gross_g.abs() <= self.config.zero_limit_fraction * known_mass_g) {
                    return Err(CommandRefusal::NotEmpty);
                }
                self.config
                    .limits
                    .check_zero(zero_counts)
                    .map_err(CommandRefusal::Implausible)?;
                // The calibration ends in a new scale without a tare; stop refining this one.
                self.refining = None;
                self.phase = Phase::AwaitingMass {
                    known_mass_g,
                    zero_counts,
                    changes_at_zero: reading.load_changes,
                    started_sample: now_sample,
                    seen_at: None,
                };
                Ok(CommandOutcome::CalibrationStarted {
                    zero_counts,
                    known_mass_g,
                })
            }
            Command::CancelCalibration => {
                if self.is_calibrating() {
                    self.phase = Phase::Idle;
                    Ok(CommandOutcome::CalibrationCancelled)
                } else {
                    Err(CommandRefusal::NotCalibrating)
                }
            }
        }
    }

    /// Refine a fresh tare and advance a calibration in progress; call it regularly (each
    /// readout). `Some` when a calibration ends: the measured calibration, which the board
    /// stores with [`crate::weighing::store_calibration`] and applies with [`Scale::recalibrate`], or why it
    /// failed. The known mass counts once a load change happened after the zero and the
    /// reading has been stable for `calibration_settle_samples` since that change; an empty
    /// pan after a bump does not.
    pub fn poll<E: ScaleEstimator>(
        &mut self,
        scale: &mut Scale<E>,
        now_sample: u32,
    ) -> Option<Result<Calibration, CalibrationFailure>> {
        self.refine_tare(scale);
        let Phase::AwaitingMass {
            known_mass_g,
            zero_counts,
            changes_at_zero,
            started_sample,
            seen_at,
        } = self.phase
        else {
            return None;
        };
        if now_sample.wrapping_sub(started_sample) > self.config.calibration_timeout_samples {
            self.phase = Phase::Idle;
            return Some(Err(CalibrationFailure::TimedOut));
        }
        let reading = scale.reading();
        // Only the first load put on after the zero can be the reference mass: once one has
        // been seen, an empty pan ends the calibration (a torture run's operator took the
        // mass off while its reading was still unsettled, put another item on, and that
        // item, 6 % lighter, was taken as the mass: within the gain tolerance, accepted).
        // A reading with no mass after the zero counts as a load too: the scale could not
        // measure what was on the pan (a torture run's reference mass read
        // `invalid:model_mismatch` for 6 s, was taken off unseen, and the 172 g put on next
        // was taken as the 200 g: a gain 14 % off, inside the tolerance, accepted).
        // And a mass seen must be measured within the settle timeout: one that read
        // `invalid:model_mismatch` until it was taken off never showed the empty pan, and a
        // 173 g load put on 9 s later was taken as the 200 g (`host-sim torture --runs
        // 10000`, run 6798).
        let gross_g = reading.mass_g.map(|net| net + scale.tare_g());
        let seen_now = matches!(reading.state, ScaleState::Invalid(_))
            || gross_g.is_some_and(|g| g >= self.config.zero_limit_fraction * known_mass_g);
        let seen_at = seen_at.or(seen_now.then_some(now_sample));
        if seen_at.is_some() && reading.state == ScaleState::Empty {
            self.phase = Phase::Idle;
            return Some(Err(CalibrationFailure::MassRemoved));
        }
        if seen_at.is_some_and(|at| {
            now_sample.wrapping_sub(at) > self.config.calibration_settle_timeout_samples
        }) {
            self.phase = Phase::Idle;
            return Some(Err(CalibrationFailure::TimedOut));
        }
        if let Phase::AwaitingMass { seen_at: seen, .. } = &mut self.phase {
            *seen = seen_at;
        }
        let loaded = reading.load_changes != changes_at_zero
            && reading.state == ScaleState::Stable
            && reading.samples_since_change >= self.config.calibration_settle_samples;
        if !loaded {
            return None;
        }
        let loaded_counts = scale.gross_counts()?;
        self.phase = Phase::Idle;
        let measured = match Calibration::from_known_mass(zero_counts, loaded_counts, known_mass_g)
        {
            Ok(measured) => measured,
            Err(_) => return Some(Err(CalibrationFailure::NoSpan)),
        };
        Some(
            self.config
                .limits
                .check(&measured)
                .map_err(CalibrationFailure::Implausible),
        )
    }
}

impl Commands {
    /// Re-take the tare from the current estimate while the tared load is still on (no load
    /// change since), the reading is stable, the estimate is within the stability band of
    /// the tare first taken, and better known than the tare; stop refining otherwise,
    /// keeping the last value.
    fn refine_tare<E: ScaleEstimator>(&mut self, scale: &mut Scale<E>) {
        let Some(refinement) = self.refining else {
            return;
        };
        let reading = scale.reading();
        if reading.load_changes != refinement.load_changes {
            self.refining = None;
            return;
        }
        if settled(&reading, 0).is_err() {
            // Momentarily unstable (or invalid): keep the tare, try again next time.
            return;
        }
        let config = scale.config();
        let band = config.stable_band_g + config.stable_band_relative * refinement.tare_g.abs();
        let gross_g = reading.mass_g.map(|net| net + scale.tare_g());
        match gross_g {
            Some(gross_g) if (gross_g - refinement.tare_g).abs() <= band => {
                // Only a better-known estimate replaces the tare (`tare` itself refuses one
                // outside the tare accuracy).
                let better = scale
                    .gross_u_bound_g()
                    .is_none_or(|bound| bound < scale.tare_u_bound_g());
                if better {
                    let _ = scale.tare();
                }
            }
            _ => self.refining = None,
        }
    }
}

/// Stable (or empty) and at least `min_samples` after the last load change.
fn settled(reading: &ScaleReading, min_samples: u32) -> Result<(), CommandRefusal> {
    match reading.state {
        ScaleState::Invalid(fault) => Err(CommandRefusal::Invalid(fault)),
        ScaleState::Stable | ScaleState::Empty if reading.samples_since_change >= min_samples => {
            Ok(())
        }
        _ => Err(CommandRefusal::Unstable),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::weighing::calibration::test_store::RamStore;
    use crate::weighing::calibration::{load_calibration, store_calibration, CalibrationSource};
    use crate::weighing::scale::test_scene::{calibration, Cell, CPG, FS, LIMITS, ZERO};
    use crate::weighing::{CountsScale, RawSample, StepScale};

    const KNOWN_MASS_G: f32 = 200.0;

    /// A scale, its cell, the command machine and a sample clock.
    struct Bench {
        scale: StepScale<8>,
        cell: Cell,
        commands: Commands,
        now: u32,
    }

    impl Bench {
        fn new(gain_factor: f64) -> Self {
            Self::with_noise(0.2, gain_factor)
        }

        fn with_noise(noise_g: f64, gain_factor: f64) -> Self {
            Self {
                scale: StepScale::step_default(FS, calibration()).unwrap(),
                cell: Cell::replaced(noise_g, gain_factor),
                commands: Commands::new(CommandConfig::weighing_default(FS, LIMITS)),
                now: 0,
            }
        }

        fn run_s(&mut self, seconds: f32) -> ScaleReading {
            let mut last = self.scale.reading();
            for _ in 0..(seconds * FS) as u32 {
                last = self.scale.push(self.cell.sample());
                self.now = self.now.wrapping_add(1);
            }
            last
        }

        fn command(&mut self, command: Command) -> Result<CommandOutcome, CommandRefusal> {
            self.commands.handle(command, &mut self.scale, self.now)
        }

        /// Start a calibration with [`KNOWN_MASS_G`] on the settled empty pan.
        fn start_calibration(&mut self) {
            assert!(matches!(
                self.command(Command::Calibrate {
                    known_mass_g: KNOWN_MASS_G
                }),
                Ok(CommandOutcome::CalibrationStarted { .. })
            ));
        }

        /// Run, polling at the readout cadence (every 200 samples), until the calibration
        /// ends or `seconds` pass.
        fn poll_for_s(&mut self, seconds: f32) -> Option<Result<Calibration, CalibrationFailure>> {
            for _ in 0..(seconds * 20.0) as u32 {
                self.run_s(0.05);
                if let Some(result) = self.commands.poll(&mut self.scale, self.now) {
                    return Some(result);
                }
            }
            None
        }
    }

    #[test]
    fn console_bytes_map_to_commands() {
        assert_eq!(Command::from_byte(b't', 200.0), Some(Command::Tare));
        assert_eq!(Command::from_byte(b'T', 200.0), Some(Command::Tare));
        assert_eq!(Command::from_byte(b'u', 200.0), Some(Command::ClearTare));
        assert_eq!(
            Command::from_byte(b'c', 200.0),
            Some(Command::Calibrate {
                known_mass_g: 200.0
            })
        );
        assert_eq!(
            Command::from_byte(b'x', 200.0),
            Some(Command::CancelCalibration)
        );
        for byte in [b'\n', b'\r', b' ', b'q', 0, 0xFF] {
            assert_eq!(Command::from_byte(byte, 200.0), None, "byte {byte:#04x}");
        }
    }

    #[test]
    fn tare_is_refused_while_the_reading_moves_and_taken_once_stable() {
        let mut bench = Bench::new(1.0);
        bench.run_s(0.5);
        bench.cell.load_g = 138.32;
        // Until the drop is detected the pan still reads empty (and a tare then takes the
        // empty pan); once it is, the cell rings and the estimate is not stable.
        let mut ringing = bench.scale.reading();
        for _ in 0..(0.1 * FS) as u32 {
            ringing = bench.scale.push(bench.cell.sample());
            if ringing.load_changes == 1 {
                break;
            }
        }
        assert_eq!(ringing.state, ScaleState::Estimating, "{ringing:?}");
        assert_eq!(bench.command(Command::Tare), Err(CommandRefusal::Unstable));
        assert_eq!(bench.scale.tare_g(), 0.0, "a refused tare changes nothing");

        let settled = bench.run_s(1.0);
        assert_eq!(settled.state, ScaleState::Stable, "{settled:?}");
        let Ok(CommandOutcome::Tared { tare_g }) = bench.command(Command::Tare) else {
            panic!("tare refused on a stable reading");
        };
        // The 0.1 % target at the readout; the tare is the gross estimate itself.
        assert!((tare_g - 138.32).abs() < 0.1383, "tare {tare_g}");
        let net = bench.run_s(0.5).mass_g.unwrap();
        // The empty-pan criterion applies to a tared reading too.
        assert!(net.abs() <= 0.05, "net {net}");

        assert_eq!(
            bench.command(Command::ClearTare),
            Ok(CommandOutcome::TareCleared)
        );
        let gross = bench.run_s(0.05).mass_g.unwrap();
        assert!((gross - 138.32).abs() < 0.1383, "gross {gross}");
    }

    /// Drop `mass_g` and tare as soon as a tare is accepted (stable, and known to within
    /// ±0.25 e); the tare.
    fn tare_once_known(bench: &mut Bench, mass_g: f64) -> f32 {
        bench.run_s(0.5);
        bench.cell.load_g = mass_g;
        for _ in 0..(3.0 * FS) as u32 {
            bench.now += 1;
            if bench.scale.push(bench.cell.sample()).state != ScaleState::Stable {
                continue;
            }
            match bench.command(Command::Tare) {
                Ok(CommandOutcome::Tared { tare_g }) => return tare_g,
                Err(CommandRefusal::Uncertain) => {}
                other => panic!("{other:?}"),
            }
        }
        panic!("no tare accepted within 3 s of the drop")
    }

    const NOISY_G: f64 = 0.4;

    /// A tare carries its error into every net reading after it, so it waits until the
    /// load is known to ±0.25 e (OIML R 76): at the first stable reading of a 138 g drop on
    /// a cell of [`NOISY_G`] noise the estimate is within the 0.1 g that load permits but
    /// not within 0.025 g, and the tare was taken there. (On the bench's 0.2 g the first
    /// stable reading knows it to 0.025 g since stop 49, its `u` resting on the noise
    /// floor with the floor's degrees of freedom: the tare taken there was 0.008 g off.)
    /// Once taken, its `u` is part of every net reading's.
    #[test]
    fn a_tare_waits_until_the_load_is_known_to_a_quarter_interval() {
        let mut bench = Bench::with_noise(NOISY_G, 1.0);
        bench.run_s(0.5);
        bench.cell.load_g = 138.32;
        while bench.scale.push(bench.cell.sample()).state != ScaleState::Stable {
            bench.now += 1;
        }
        assert_eq!(bench.command(Command::Tare), Err(CommandRefusal::Uncertain));
        assert_eq!(bench.scale.tare_g(), 0.0, "a refused tare changes nothing");
        let mut bench = Bench::new(1.0);
        let tare_g = tare_once_known(&mut bench, 138.32);
        let e = bench.scale.config().scale_interval_g;
        assert!((tare_g - 138.32).abs() <= 0.25 * e, "tare {tare_g}");
        let tare_u_bound = bench.scale.tare_u_bound_g();
        assert!(tare_u_bound > 0.0 && 2.0 * tare_u_bound <= 0.25 * e);
        bench.run_s(0.05);
        let net_u = bench.scale.reading().uncertainty_g.unwrap();
        bench.scale.clear_tare();
        let gross_u = bench.scale.reading().uncertainty_g.unwrap();
        assert!(net_u > gross_u, "net u {net_u}, gross u {gross_u}");
    }

    #[test]
    fn a_fresh_tare_follows_the_estimate_within_the_stability_band_until_a_change() {
        let mut bench = Bench::new(1.0);
        let first_g = tare_once_known(&mut bench, 138.32);
        assert_eq!(bench.poll_for_s(2.0), None);
        let config = *bench.scale.config();
        let band = config.stable_band_g + config.stable_band_relative * first_g;
        let refined_g = bench.scale.tare_g();
        assert!(
            (refined_g - first_g).abs() <= band,
            "{first_g} → {refined_g}"
        );
        // The refined tare is the estimate of at most one readout period (50 ms) ago: the
        // net reading is what the estimator moved since, far inside the 0.05 g criterion.
        let net = bench.scale.reading().mass_g.unwrap();
        assert!(net.abs() < 0.01, "net {net}");

        // A second load: the tare freezes, the net reading is the new load.
        bench.cell.load_g += 20.0;
        bench.poll_for_s(1.0);
        let frozen_g = bench.scale.tare_g();
        bench.poll_for_s(1.0);
        assert_eq!(bench.scale.tare_g(), frozen_g);
        let net = bench.scale.reading().mass_g.unwrap();
        assert!((net - 20.0).abs() < 0.02 + 0.05, "net {net}");
    }

    #[test]
    fn a_slow_undetected_change_cannot_pull_the_tare_beyond_the_band() {
        let mut bench = Bench::new(1.0);
        let first_g = tare_once_known(&mut bench, 100.0);
        bench.poll_for_s(0.2);
        // 0.5 g crept on over 1 s, polled at the readout cadence: ten times the band.
        for _ in 0..20 {
            bench.cell.load_g += 0.5 / 20.0;
            bench.run_s(0.05);
            let _ = bench.commands.poll(&mut bench.scale, bench.now);
        }
        let config = *bench.scale.config();
        let band = config.stable_band_g + config.stable_band_relative * first_g;
        let tare_g = bench.scale.tare_g();
        assert!((tare_g - first_g).abs() <= band, "{first_g} → {tare_g}");
        // Nor later, whether the scale catches the creep as a change or not.
        bench.poll_for_s(2.0);
        let tare_g = bench.scale.tare_g();
        assert!((tare_g - first_g).abs() <= band, "{first_g} → {tare_g}");
    }

    #[test]
    fn tare_of_an_empty_pan_is_accepted_and_an_invalid_reading_gives_its_fault() {
        let mut bench = Bench::new(1.0);
        let empty = bench.run_s(1.0);
        assert_eq!(empty.state, ScaleState::Empty);
        assert!(matches!(
            bench.command(Command::Tare),
            Ok(CommandOutcome::Tared { .. })
        ));
        bench.scale.push(RawSample::Saturated);
        assert_eq!(
            bench.command(Command::Tare),
            Err(CommandRefusal::Invalid(ScaleFault::Saturated))
        );
    }

    /// The whole procedure on a cell 2 % more sensitive than the calibration in use: the
    /// known mass reads 2 % high before, within the 0.1 % target after the new record is
    /// stored, read back and applied; a different mass then reads right too.
    #[test]
    fn calibration_with_a_known_mass_corrects_the_gain() {
        let mut bench = Bench::new(1.02);
        bench.run_s(1.0);
        let Ok(CommandOutcome::CalibrationStarted { zero_counts, .. }) =
            bench.command(Command::Calibrate {
                known_mass_g: KNOWN_MASS_G,
            })
        else {
            panic!("calibration refused on an empty, settled pan");
        };
        // The zero is the empty pan: within the empty band of the true zero.
        assert!(
            (zero_counts - ZERO).abs() < 0.25 * CPG,
            "zero {zero_counts}"
        );
        assert!(bench.commands.is_calibrating());
        // Nothing happens until the mass is on.
        assert_eq!(bench.poll_for_s(1.0), None);

        bench.cell.load_g = KNOWN_MASS_G as f64;
        let before = bench.run_s(0.2).mass_g.unwrap();
        assert!((before / KNOWN_MASS_G - 1.02).abs() < 0.001, "{before}");
        let measured = bench.poll_for_s(2.0).expect("no result").expect("failed");
        assert!(!bench.commands.is_calibrating());
        let true_gain = 1.02 * CPG;
        assert!(
            (measured.counts_per_gram / true_gain - 1.0).abs() < 0.001,
            "{measured:?}"
        );

        let mut store = RamStore::default();
        let stored = store_calibration(&mut store, &measured).unwrap();
        assert_eq!(stored, measured);
        assert_eq!(
            load_calibration(&mut store, &LIMITS),
            (measured, CalibrationSource::Stored)
        );
        let changes = bench.scale.reading().load_changes;
        bench.scale.recalibrate(stored.counts_scale());
        assert_eq!(bench.scale.reading().load_changes, changes + 1);
        let after = bench.run_s(0.2).mass_g.unwrap();
        assert!(
            (after - KNOWN_MASS_G).abs() < 0.001 * KNOWN_MASS_G,
            "{after}"
        );

        bench.cell.load_g = 83.0;
        let other = bench.run_s(0.5).mass_g.unwrap();
        assert!((other - 83.0).abs() < 0.083, "{other}");
    }

    /// The reference mass on while the scale can measure nothing (here saturated samples;
    /// in the torture run, a consistency flag), taken off, another item put on: the
    /// calibration must end with the empty pan, not take the other item as the mass.
    #[test]
    fn a_mass_the_scale_could_not_measure_is_not_replaced_by_the_next_item() {
        let mut bench = Bench::new(1.0);
        bench.run_s(1.0);
        bench.start_calibration();
        for _ in 0..40 {
            for _ in 0..200 {
                bench.scale.push(RawSample::Saturated);
                bench.now += 1;
            }
            assert_eq!(bench.commands.poll(&mut bench.scale, bench.now), None);
        }
        bench.cell.load_g = 0.0;
        assert_eq!(
            bench.poll_for_s(3.0),
            Some(Err(CalibrationFailure::MassRemoved))
        );
        bench.cell.load_g = 172.0;
        assert_eq!(bench.poll_for_s(3.0), None);
        let reading = bench.scale.reading();
        assert!((reading.mass_g.unwrap() - 172.0).abs() < 0.1, "{reading:?}");
    }

    /// A mass the scale cannot read for longer than the settle timeout (saturated here; a
    /// consistency flag in the torture run), taken off and replaced while still unread:
    /// the calibration gives up instead of taking whatever settles next.
    #[test]
    fn a_mass_never_measured_within_the_settle_timeout_ends_the_calibration() {
        let mut bench = Bench::new(1.0);
        bench.run_s(1.0);
        bench.start_calibration();
        let mut ended = None;
        for _ in 0..(8.0 * 20.0) as u32 {
            for _ in 0..200 {
                bench.scale.push(RawSample::Saturated);
                bench.now += 1;
            }
            ended = bench.commands.poll(&mut bench.scale, bench.now);
            if ended.is_some() {
                break;
            }
        }
        assert_eq!(ended, Some(Err(CalibrationFailure::TimedOut)));
        let timeout_s = bench.commands.config.calibration_settle_timeout_samples as f32 / FS;
        assert!(
            bench.now as f32 / FS <= 1.0 + timeout_s + 0.1,
            "{}",
            bench.now
        );
        bench.cell.load_g = 172.0;
        assert_eq!(bench.poll_for_s(3.0), None);
    }

    /// The reference mass taken off before its reading settled, another item put on: the
    /// calibration must end there, not take the other item as the mass (a torture run took
    /// 187.5 g for 200 g, a gain 6 % off, inside the tolerance, and every reading after it
    /// 6 % off, stable).
    #[test]
    fn a_mass_taken_off_before_it_settled_ends_the_calibration() {
        let mut bench = Bench::new(1.0);
        bench.run_s(1.0);
        bench.start_calibration();
        // On for 60 ms (polled at the readout cadence: not yet settled), then off.
        bench.cell.load_g = KNOWN_MASS_G as f64;
        assert_eq!(bench.poll_for_s(0.1), None);
        bench.cell.load_g = 0.0;
        let ended = bench.poll_for_s(3.0);
        assert_eq!(ended, Some(Err(CalibrationFailure::MassRemoved)));
        assert!(!bench.commands.is_calibrating());
        // The next item is weighed with the calibration in use, not taken as the mass.
        bench.cell.load_g = 187.5;
        assert_eq!(bench.poll_for_s(2.0), None);
        let reading = bench.scale.reading();
        assert!((reading.mass_g.unwrap() - 187.5).abs() < 0.1, "{reading:?}");
        // A new calibration whose mass stays on completes as before.
        assert!(matches!(
            {
                bench.cell.load_g = 0.0;
                bench.run_s(2.0);
                bench.command(Command::Calibrate {
                    known_mass_g: KNOWN_MASS_G,
                })
            },
            Ok(CommandOutcome::CalibrationStarted { .. })
        ));
        assert_eq!(bench.poll_for_s(1.0), None);
        bench.cell.load_g = KNOWN_MASS_G as f64;
        assert!(matches!(bench.poll_for_s(3.0), Some(Ok(_))));
    }

    #[test]
    fn gross_counts_ignore_the_tare_and_an_impossible_recalibration_is_a_fault() {
        let mut bench = Bench::new(1.0);
        bench.cell.load_g = 100.0;
        // On from power-up: the first run's `u` rests on the raw samples' white noise once
        // metered (1 g of it here), so the load is known to the tare's ±0.25 e after 4.4 s,
        // not at 1 s as when that run's `u` went without the floor.
        let mut gross = None;
        for _ in 0..200 {
            bench.run_s(0.05);
            let before = bench.scale.gross_counts();
            match bench.command(Command::Tare) {
                Ok(_) => {
                    gross = before;
                    break;
                }
                Err(CommandRefusal::Uncertain | CommandRefusal::Unstable) => {}
                Err(other) => panic!("{other:?}"),
            }
        }
        let gross = gross.expect("no tare within 10 s");
        bench.run_s(0.01);
        let tared = bench.scale.gross_counts().unwrap();
        // The same load: the estimate moves by noise only (well under 0.1 g = 5 counts).
        assert!((tared - gross).abs() < 5.0, "{gross} vs {tared}");
        assert!((gross - (ZERO + 100.0 * CPG)).abs() < 5.0, "{gross}");

        let impossible = CountsScale {
            counts_per_gram: f32::NAN,
            zero_counts: ZERO,
        };
        bench.scale.recalibrate(impossible);
        let reading = bench.run_s(0.01);
        assert_eq!(reading.state, ScaleState::Invalid(ScaleFault::Uncalibrated));
        assert_eq!(reading.mass_g, None);
        assert_eq!(bench.scale.gross_counts(), None);
        assert_eq!(
            bench.command(Command::Tare),
            Err(CommandRefusal::Invalid(ScaleFault::Uncalibrated))
        );
    }

    #[test]
    fn calibration_is_refused_unless_empty_and_settled() {
        let mut bench = Bench::new(1.0);
        let calibrate = Command::Calibrate {
            known_mass_g: KNOWN_MASS_G,
        };
        bench.run_s(1.0);
        for known_mass_g in [0.0, -200.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                bench.command(Command::Calibrate { known_mass_g }),
                Err(CommandRefusal::BadKnownMass)
            );
        }
        bench.cell.load_g = 138.32;
        bench.run_s(0.3);
        // Stable, but settled for less than the 0.5 s a calibration point needs.
        assert_eq!(bench.command(calibrate), Err(CommandRefusal::Unstable));
        bench.run_s(1.0);
        // Settled, but the pan holds 69 % of the known mass.
        assert_eq!(bench.command(calibrate), Err(CommandRefusal::NotEmpty));
        assert!(!bench.commands.is_calibrating());
        assert_eq!(
            bench.command(Command::CancelCalibration),
            Err(CommandRefusal::NotCalibrating)
        );
    }

    #[test]
    fn a_calibration_in_progress_blocks_other_commands_until_cancelled() {
        let mut bench = Bench::new(1.0);
        let calibrate = Command::Calibrate {
            known_mass_g: KNOWN_MASS_G,
        };
        bench.run_s(1.0);
        assert!(bench.command(calibrate).is_ok());
        assert_eq!(
            bench.command(Command::Tare),
            Err(CommandRefusal::CalibrationInProgress)
        );
        assert_eq!(
            bench.command(calibrate),
            Err(CommandRefusal::CalibrationInProgress)
        );
        assert_eq!(
            bench.command(Command::CancelCalibration),
            Ok(CommandOutcome::CalibrationCancelled)
        );
        bench.cell.load_g = KNOWN_MASS_G as f64;
        assert_eq!(bench.poll_for_s(1.5), None, "a cancelled calibration ends");
        assert!(matches!(
            bench.command(Command::Tare),
            Ok(CommandOutcome::Tared { .. })
        ));
    }

    /// Calibrate on the bench's cell with `placed_g` on the pan where 200 g was promised,
    /// once the pan reads empty again (within 3 s: a load taken off rings on, and a
    /// calibration starts only from an empty pan at rest).
    fn calibrate_with(
        bench: &mut Bench,
        placed_g: f64,
    ) -> Option<Result<Calibration, CalibrationFailure>> {
        bench.cell.load_g = 0.0;
        bench.run_s(1.0);
        for _ in 0..40 {
            if bench.scale.reading().state == ScaleState::Empty {
                break;
            }
            bench.run_s(0.05);
        }
        assert!(bench
            .command(Command::Calibrate {
                known_mass_g: KNOWN_MASS_G
            })
            .is_ok());
        bench.cell.load_g = placed_g;
        let result = bench.poll_for_s(2.0);
        assert!(!bench.commands.is_calibrating());
        result
    }

    /// The hostile tester's case: 140, 250 or 290 g put on for 200 g (gains 30 % low to 45 %
    /// high) were accepted, being within 50 % of the gain in use. Each is refused now, with
    /// how far off the nominal gain it is.
    #[test]
    fn the_wrong_reference_mass_is_refused_with_how_far_off_it_is() {
        for (placed_g, percent) in [(140.0, -30), (250.0, 25), (290.0, 45), (100.0, -50)] {
            let mut bench = Bench::new(1.0);
            assert_eq!(
                calibrate_with(&mut bench, placed_g),
                Some(Err(CalibrationFailure::Implausible(
                    CalibrationError::GainOffNominal { percent }
                ))),
                "{placed_g} g"
            );
        }
    }

    /// A wrong calibration that got in (here: applied by hand, 40 % high) must not become
    /// the reference for the next one: the window stays around the nominal gain, so the
    /// same wrong mass again is refused, not accepted as "within 50 % of the gain in use",
    /// and the right mass brings the gain back.
    #[test]
    fn repeated_wrong_calibrations_cannot_drift_away_from_nominal() {
        let mut bench = Bench::new(1.0);
        bench.scale.recalibrate(CountsScale {
            counts_per_gram: 1.4 * CPG,
            zero_counts: ZERO,
        });
        assert!(matches!(
            calibrate_with(&mut bench, 290.0),
            Some(Err(CalibrationFailure::Implausible(
                CalibrationError::GainOffNominal { percent: 45 }
            )))
        ));
        let measured = calibrate_with(&mut bench, 200.0)
            .expect("a result")
            .expect("the right mass is accepted");
        assert!(
            (measured.counts_per_gram / CPG - 1.0).abs() < 0.001,
            "{measured:?}"
        );
    }

    /// A calibration zero outside the board's window is refused at the command, with the
    /// reason: here the pan is empty but the chain's offset has moved by 400 g of counts
    /// (a broken bridge arm), where the scale's own zero tracking and empty-pan test see
    /// nothing wrong after a recalibration at that offset.
    #[test]
    fn an_absurd_calibration_zero_is_refused_with_the_reason() {
        let mut bench = Bench::new(1.0);
        let offset = ZERO + 400.0 * CPG;
        bench.cell.offset_counts = offset as f64;
        bench.scale.recalibrate(CountsScale {
            counts_per_gram: CPG,
            zero_counts: offset,
        });
        bench.run_s(1.0);
        assert!(matches!(
            bench.command(Command::Calibrate {
                known_mass_g: KNOWN_MASS_G
            }),
            Err(CommandRefusal::Implausible(CalibrationError::ZeroOffNominal { counts }))
                if counts > 19_000
        ));
        assert!(!bench.commands.is_calibrating());
    }

    #[test]
    fn a_bump_is_not_the_known_mass_and_the_wait_times_out() {
        let mut bench = Bench::new(1.0);
        bench.commands.config.calibration_timeout_samples = (3.0 * FS) as u32;
        bench.run_s(1.0);
        assert!(bench
            .command(Command::Calibrate {
                known_mass_g: KNOWN_MASS_G
            })
            .is_ok());
        let changes = bench.scale.reading().load_changes;
        // A hand rests 50 g on the pan for 40 ms and lets go: a load change, then empty.
        bench.cell.load_g = 50.0;
        bench.run_s(0.04);
        bench.cell.load_g = 0.0;
        assert_eq!(bench.poll_for_s(1.5), None);
        assert!(
            bench.scale.reading().load_changes > changes,
            "the bump was seen"
        );
        assert_eq!(
            bench.poll_for_s(2.0),
            Some(Err(CalibrationFailure::TimedOut))
        );
    }
}
