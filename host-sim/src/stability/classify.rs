//! A cell's class at a readout, from the counts of what its runs did there. A cell is valid
//! only on the strength of its valid runs; a failure is silent when a run failing it still
//! carried a valid reading.

use estimator_core::InvalidReason;

use super::run::{Outcome, RunOutcome};

/// A cell whose valid readings' RMS exceeds this many CRLBs fails.
pub const BOUND_FACTOR: f64 = 10.0;
/// A valid reading further than this many loads from the truth has diverged.
pub const DIVERGED_FACTOR: f64 = 10.0;

/// Every reason the core flags, in a fixed order (for counts and columns).
pub const REASONS: [InvalidReason; 9] = [
    InvalidReason::NonFiniteInput,
    InvalidReason::OutOfRange,
    InvalidReason::IllConditioned,
    InvalidReason::NonFiniteUpdate,
    InvalidReason::MissingSample,
    InvalidReason::LostDefiniteness,
    InvalidReason::OutsideModelRange,
    InvalidReason::ModelMismatch,
    InvalidReason::Unconfigured,
];

fn reason_index(reason: InvalidReason) -> usize {
    // Exhaustive, so a new reason cannot be miscounted silently.
    match reason {
        InvalidReason::NonFiniteInput => 0,
        InvalidReason::OutOfRange => 1,
        InvalidReason::IllConditioned => 2,
        InvalidReason::NonFiniteUpdate => 3,
        InvalidReason::MissingSample => 4,
        InvalidReason::LostDefiniteness => 5,
        InvalidReason::OutsideModelRange => 6,
        InvalidReason::ModelMismatch => 7,
        InvalidReason::Unconfigured => 8,
    }
}

/// What a cell's runs did at one readout.
#[derive(Clone, Debug, Default)]
pub struct Cell {
    /// Runs.
    pub runs: u32,
    /// Runs with a valid, finite reading.
    pub valid: u32,
    /// Runs not yet determined.
    pub warming: u32,
    /// Flagged runs, by reason ([`REASONS`]).
    pub flagged: [u32; REASONS.len()],
    /// Σ error² over the valid runs, g².
    pub sum_squared_g2: f64,
    /// Largest |error| of a valid run, g.
    pub max_error_g: f64,
    /// Runs that gave a non-finite valid reading by the readout.
    pub non_finite: u32,
    /// Runs that gave a valid reading 10 loads off between 100 ms and the readout.
    pub diverged: u32,
    /// Runs whose state lost positive definiteness by the readout.
    pub lost_definiteness: u32,
    /// Of those, runs with a valid reading at the readout (silent).
    pub lost_definiteness_valid: u32,
    /// f32 probes: Σ error² of this probe and of its f64 twin over the runs valid in both.
    pub paired_g2: (f64, f64),
    /// Runs valid in both.
    pub paired: u32,
    /// The CRLB at the readout, g.
    pub crlb_g: f64,
}

/// A cell's class at a readout (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Every run valid and the RMS within 10× the CRLB.
    Ok,
    /// Within 10× the CRLB on the valid runs; some runs flagged or not yet determined.
    OkPartly,
    /// No run determined yet.
    NotYet,
    /// Most runs flagged: the method refuses here (safe).
    Refused,
    /// The valid readings' RMS is above 10× the CRLB.
    OverBound,
    /// The state lost positive definiteness in some run.
    LostDefiniteness,
    /// A non-finite value: a valid reading (silent) or a latched `NonFiniteUpdate` (flagged).
    NonFinite,
    /// A valid reading 10 loads off.
    Diverged,
}

impl Class {
    /// Name in tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Class::Ok => "ok",
            Class::OkPartly => "ok_partly_flagged",
            Class::NotYet => "not_yet",
            Class::Refused => "refused",
            Class::OverBound => "over_10x_crlb",
            Class::LostDefiniteness => "lost_definiteness",
            Class::NonFinite => "non_finite",
            Class::Diverged => "diverged",
        }
    }

    /// Inside the valid region (the method works here, possibly refusing some runs).
    pub fn is_valid(self) -> bool {
        matches!(self, Class::Ok | Class::OkPartly)
    }
}

impl Cell {
    pub(super) fn add(&mut self, outcome: &RunOutcome, r: usize, truth_g: f64) {
        let _ = truth_g;
        self.runs += 1;
        match outcome.at[r] {
            Outcome::WarmingUp => self.warming += 1,
            Outcome::Flagged(reason) => self.flagged[reason_index(reason)] += 1,
            Outcome::Valid(error) if error.is_finite() => {
                self.valid += 1;
                self.sum_squared_g2 += error * error;
                self.max_error_g = self.max_error_g.max(error.abs());
            }
            Outcome::Valid(_) => {}
        }
        self.non_finite += u32::from(outcome.non_finite_by[r]);
        self.diverged += u32::from(outcome.diverged_by[r]);
        if outcome.lost_definiteness_by[r] {
            self.lost_definiteness += 1;
            if matches!(outcome.at[r], Outcome::Valid(_)) {
                self.lost_definiteness_valid += 1;
            }
        }
    }

    /// Flagged runs, every reason.
    pub fn flagged_total(&self) -> u32 {
        self.flagged.iter().sum()
    }

    /// RMS error of the valid runs, g (NaN without).
    pub fn rms_g(&self) -> f64 {
        (self.sum_squared_g2 / f64::from(self.valid)).sqrt()
    }

    /// RMS over CRLB (NaN without valid runs).
    pub fn ratio(&self) -> f64 {
        self.rms_g() / self.crlb_g
    }

    /// f32 RMS over f64 RMS on the runs valid in both (f32 probes only).
    pub fn f32_over_f64(&self) -> Option<f64> {
        (self.paired > 0).then(|| (self.paired_g2.0 / self.paired_g2.1).sqrt())
    }

    /// The class, and whether a failure was silent (a run failing it gave a valid reading).
    pub fn class(&self) -> (Class, bool) {
        let non_finite_flagged = self.flagged[reason_index(InvalidReason::NonFiniteUpdate)];
        if self.non_finite > 0 {
            return (Class::NonFinite, true);
        }
        if self.diverged > 0 {
            return (Class::Diverged, true);
        }
        if self.lost_definiteness > 0 {
            return (Class::LostDefiniteness, self.lost_definiteness_valid > 0);
        }
        if non_finite_flagged > 0 {
            return (Class::NonFinite, false);
        }
        if self.valid == 0 {
            return if self.warming == self.runs {
                (Class::NotYet, false)
            } else {
                (Class::Refused, false)
            };
        }
        if self.ratio() > BOUND_FACTOR {
            return (Class::OverBound, true);
        }
        if 2 * self.flagged_total() > self.runs {
            return (Class::Refused, false);
        }
        if self.valid < self.runs {
            return (Class::OkPartly, false);
        }
        (Class::Ok, false)
    }

    /// A short text for tables: the RMS/CRLB ratio and a mark of the class.
    pub fn text(&self) -> String {
        let (class, silent) = self.class();
        let ratio = ratio_text(self.ratio());
        let share = |count: u32| format!("{:.0}%", 100.0 * f64::from(count) / f64::from(self.runs));
        match class {
            Class::Ok => ratio,
            Class::OkPartly => format!("{ratio} ({} valid)", share(self.valid)),
            Class::NotYet => "·".into(),
            Class::Refused => format!("F {}", share(self.flagged_total())),
            Class::OverBound => format!("**{ratio}** S"),
            Class::LostDefiniteness if silent => format!("**PD!** {ratio}"),
            Class::LostDefiniteness => "PD F".into(),
            Class::NonFinite if silent => "**NaN!**".into(),
            Class::NonFinite => "NaN F".into(),
            Class::Diverged => format!("**DIV!** {}", share(self.diverged)),
        }
    }
}

fn ratio_text(ratio: f64) -> String {
    if !ratio.is_finite() {
        "–".into()
    } else if ratio >= 1e4 {
        format!("{ratio:.0e}")
    } else if ratio >= 100.0 {
        format!("{ratio:.0}")
    } else if ratio >= 10.0 {
        format!("{ratio:.1}")
    } else {
        format!("{ratio:.2}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(at: Outcome) -> RunOutcome {
        RunOutcome {
            at: [at; 2],
            lost_definiteness_by: [false; 2],
            diverged_by: [false; 2],
            non_finite_by: [false; 2],
        }
    }

    fn cell_of(outcomes: &[RunOutcome]) -> Cell {
        let mut cell = Cell {
            crlb_g: 0.1,
            ..Cell::default()
        };
        for outcome in outcomes {
            cell.add(outcome, 1, 100.0);
        }
        cell
    }

    #[test]
    fn runs_are_counted_by_what_they_gave_at_the_readout() {
        let cell = cell_of(&[
            run(Outcome::Valid(0.3)),
            run(Outcome::Valid(-0.4)),
            run(Outcome::Flagged(InvalidReason::IllConditioned)),
            run(Outcome::WarmingUp),
        ]);
        assert_eq!((cell.runs, cell.valid, cell.warming), (4, 2, 1));
        assert_eq!(cell.flagged[reason_index(InvalidReason::IllConditioned)], 1);
        assert_eq!(cell.flagged_total(), 1);
        assert!((cell.rms_g() - (0.25f64 / 2.0 * 1.0).sqrt()).abs() < 1e-12);
        assert_eq!(cell.max_error_g, 0.4);
        // RMS 0.354 g over a CRLB of 0.1 g: within 10×, some runs not valid.
        assert_eq!(cell.class(), (Class::OkPartly, false));
        assert_eq!(cell.text(), "3.54 (50% valid)");
    }

    #[test]
    fn a_failure_is_silent_only_when_a_failing_run_still_gave_a_valid_reading() {
        let mut diverging = run(Outcome::Valid(2000.0));
        diverging.diverged_by = [false, true];
        let cell = cell_of(&[diverging, run(Outcome::Valid(0.0))]);
        assert_eq!(cell.class(), (Class::Diverged, true));
        assert_eq!(cell.text(), "**DIV!** 50%");

        let mut lost_flagged = run(Outcome::Flagged(InvalidReason::LostDefiniteness));
        lost_flagged.lost_definiteness_by = [true; 2];
        let cell = cell_of(&[lost_flagged, run(Outcome::Valid(0.0))]);
        assert_eq!(cell.class(), (Class::LostDefiniteness, false));
        assert_eq!(cell.text(), "PD F");

        let mut lost_valid = run(Outcome::Valid(0.01));
        lost_valid.lost_definiteness_by = [true; 2];
        let cell = cell_of(&[lost_valid]);
        assert_eq!(cell.class(), (Class::LostDefiniteness, true));

        let latched = run(Outcome::Flagged(InvalidReason::NonFiniteUpdate));
        let cell = cell_of(&[latched, run(Outcome::Valid(0.0))]);
        assert_eq!(cell.class(), (Class::NonFinite, false));
        assert_eq!(cell.text(), "NaN F");
    }

    #[test]
    fn a_cell_most_of_whose_runs_are_flagged_is_refused_however_good_the_rest() {
        let flagged = run(Outcome::Flagged(InvalidReason::OutOfRange));
        let cell = cell_of(&[flagged, flagged, run(Outcome::Valid(0.0))]);
        assert_eq!(cell.class(), (Class::Refused, false));
        assert_eq!(cell.text(), "F 67%");
        let cell = cell_of(&[flagged, run(Outcome::WarmingUp)]);
        assert_eq!(cell.class(), (Class::Refused, false));
        let cell = cell_of(&[run(Outcome::WarmingUp)]);
        assert_eq!(cell.class(), (Class::NotYet, false));
        assert_eq!(cell.text(), "·");
    }

    #[test]
    fn ratios_are_written_with_fewer_decimals_as_they_grow() {
        assert_eq!(ratio_text(f64::NAN), "–");
        assert_eq!(ratio_text(1.234), "1.23");
        assert_eq!(ratio_text(12.34), "12.3");
        assert_eq!(ratio_text(123.4), "123");
        assert_eq!(ratio_text(12_345.0), "1e4");
        let over = cell_of(&[run(Outcome::Valid(1.5))]);
        assert_eq!(over.class(), (Class::OverBound, true));
        assert_eq!(over.text(), "**15.0** S");
    }

    #[test]
    fn every_reason_has_its_own_column() {
        let mut seen = [false; REASONS.len()];
        for reason in REASONS {
            seen[reason_index(reason)] = true;
        }
        assert!(seen.iter().all(|&s| s));
    }
}
