//! The verdicts over the whole map: the failure modes found per family, and the f32 goal
//! (f32 within 10% of f64 wherever f64 is valid), for the Monte Carlo slices and the long runs.

use super::classify::Class;
use super::conditions::{readout_name, Slice};
use super::long::{LongResult, FIRST_DECADE};
use super::run::SliceResult;

/// The goal: f32 RMS within this fraction of the f64 RMS in the valid region.
pub const F32_TOLERANCE: f64 = 0.10;

/// An f32 cell that fails the goal: f32 RMS more than 10% above the f64 RMS, or not valid,
/// where the f64 twin is valid.
#[derive(Clone, Debug)]
pub struct F32Failure {
    /// Where.
    pub what: String,
    /// f32 RMS over f64 RMS (runs valid in both), if any.
    pub ratio: Option<f64>,
    /// The f32 cell's class.
    pub class: Class,
}

/// The f32 goal over the Monte Carlo slices: per family, the cells checked and the failures.
pub fn f32_goal(slices: &[SliceResult]) -> Vec<(String, usize, Vec<F32Failure>)> {
    let mut out: Vec<(String, usize, Vec<F32Failure>)> = Vec::new();
    for slice in slices {
        for (c, condition) in slice.conditions.iter().enumerate() {
            for (p, probe) in slice.probes.iter().enumerate() {
                let Some(twin) = probe.twin else { continue };
                for r in 0..2 {
                    let reference = &slice.cells[c][twin][r];
                    if !reference.class().0.is_valid() {
                        continue;
                    }
                    let cell = &slice.cells[c][p][r];
                    let index = match out.iter().position(|o| o.0 == probe.family) {
                        Some(i) => i,
                        None => {
                            out.push((probe.family.clone(), 0, Vec::new()));
                            out.len() - 1
                        }
                    };
                    out[index].1 += 1;
                    let ratio = cell.f32_over_f64();
                    let (class, _) = cell.class();
                    let fails = !class.is_valid() || ratio.is_none_or(|v| v > 1.0 + F32_TOLERANCE);
                    if fails {
                        out[index].2.push(F32Failure {
                            what: format!(
                                "{} {} dB{}{} at {}",
                                condition.noise.name(),
                                condition.snr_db,
                                probe.order.map(|n| format!(", n={n}")).unwrap_or_default(),
                                if condition.slice == Slice::OffCalibration {
                                    format!(", f_n ×{}", condition.resonance_ratio)
                                } else {
                                    String::new()
                                },
                                readout_name(r)
                            ),
                            ratio,
                            class,
                        });
                    }
                }
            }
        }
    }
    out
}

/// A family and its count of failing cells per (class, silent).
pub type FamilyFailures = (String, Vec<((Class, bool), usize)>);

/// Counts of (class, silent) per family over every Monte Carlo cell and readout.
pub fn failure_summary(slices: &[SliceResult]) -> Vec<FamilyFailures> {
    let mut out: Vec<FamilyFailures> = Vec::new();
    for slice in slices {
        for cells in &slice.cells {
            for (probe, pair) in slice.probes.iter().zip(cells) {
                for cell in pair {
                    let key = cell.class();
                    if key.0.is_valid() || key.0 == Class::NotYet {
                        continue;
                    }
                    let family = format!("{} ({})", probe.family, slice.conditions[0].slice.name());
                    let index = match out.iter().position(|o| o.0 == family) {
                        Some(i) => i,
                        None => {
                            out.push((family, Vec::new()));
                            out.len() - 1
                        }
                    };
                    match out[index].1.iter_mut().find(|(k, _)| *k == key) {
                        Some((_, count)) => *count += 1,
                        None => out[index].1.push((key, 1)),
                    }
                }
            }
        }
    }
    out
}

/// The long runs' f32 check: in every decade from 10⁴ on where the f64 run is valid, the f32
/// run's RMS/bound within 10% of the f64 one's.
pub fn long_f32_goal(long: &LongResult) -> Vec<String> {
    let mut failures = Vec::new();
    for (p, run) in long.runs.iter().enumerate() {
        let Some(twin) = run.probe.twin else { continue };
        let reference = &long.runs[twin];
        for j in FIRST_DECADE + 1..7 {
            let (Some(mine), Some(theirs)) = (run.decade(j), reference.decade(j)) else {
                continue;
            };
            if theirs.readings == 0
                || !theirs
                    .class(reference.lost_definiteness_at.is_some(), false)
                    .0
                    .is_valid()
            {
                continue;
            }
            let ratio = mine.normalised_rms() / theirs.normalised_rms();
            let (class, _) = mine.class(run.lost_definiteness_at.is_some(), false);
            if !class.is_valid() || !(ratio <= 1.0 + F32_TOLERANCE) {
                failures.push(format!(
                    "`{}` 10^{j}–10^{}: {} (f32/f64 {ratio:.2})",
                    long.runs[p].probe.method,
                    j + 1,
                    class.name()
                ));
            }
        }
    }
    failures
}

/// A family's failure counts as text: `3 diverged<silent>, 2 refused<flagged>`, the mark
/// after each count saying whether that failure was silent.
pub(super) fn failure_counts_text(
    counts: &[((Class, bool), usize)],
    silent_mark: &str,
    flagged_mark: &str,
) -> String {
    let text: Vec<String> = counts
        .iter()
        .map(|((class, silent), n)| {
            format!(
                "{n} {}{}",
                class.name(),
                if *silent { silent_mark } else { flagged_mark }
            )
        })
        .collect();
    text.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failure_counts_read_as_count_class_and_mark() {
        let counts = [((Class::Diverged, true), 3), ((Class::Refused, false), 2)];
        assert_eq!(
            failure_counts_text(&counts, " (SILENT)", " (flagged)"),
            "3 diverged (SILENT), 2 refused (flagged)"
        );
        assert_eq!(failure_counts_text(&[], " S", " F"), "");
    }
}
