//! The map's markdown report: the verdicts, then one table per family (slice A) or per group
//! of conditions (slices B and C), then the long runs.

use std::io::Write;

use anyhow::Result;
use estimator_core::{InvalidReason, State};

use super::classify::Class;
use super::conditions::{readout_name, Condition, Slice};
use super::long::{LongResult, FIRST_DECADE};
use super::probes::probe_label;
use super::run::{distinct, Outcome, SliceResult};
use super::verdict::{f32_goal, failure_counts_text, failure_summary, long_f32_goal};
use crate::estimate::state_name;
use crate::montecarlo::Precision;

/// Table rows: a name and the (condition, probe) of each column.
type TableRows = Vec<(String, Vec<(usize, usize)>)>;

fn markdown_slice(
    slice: &SliceResult,
    out: &mut impl Write,
    rows_of: &dyn Fn(&SliceResult) -> TableRows,
    columns: &[String],
) -> Result<()> {
    for r in 0..2 {
        writeln!(out, "\nAt {}:\n", readout_name(r))?;
        write!(out, "| |")?;
        for column in columns {
            write!(out, " {column} |")?;
        }
        writeln!(out)?;
        writeln!(out, "|---|{}", "---|".repeat(columns.len()))?;
        for (name, cells) in rows_of(slice) {
            write!(out, "| {name} |")?;
            for (c, p) in cells {
                write!(out, " {} |", slice.cells[c][p][r].text())?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}

fn long_rows(long: &LongResult, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "| method | first flag (sample, reason) | oracle: PD lost at | 10³–10⁴ | 10⁴–10⁵ | 10⁵–10⁶ | 10⁶–10⁷ | at the end |"
    )?;
    writeln!(out, "|---|---|---|---|---|---|---|---|")?;
    for run in &long.runs {
        write!(
            out,
            "| `{}` | {} | {} |",
            run.probe.method,
            run.first_flag
                .map(|(k, reason)| format!("{k}, {}", &state_name(State::Invalid(reason))[8..]))
                .unwrap_or_else(|| "none".into()),
            run.lost_definiteness_at
                .map(|k| k.to_string())
                .unwrap_or_else(|| "–".into())
        )?;
        for j in FIRST_DECADE..7 {
            match run.decade(j) {
                Some(d) if d.readings > 0 => {
                    let non_finite = run
                        .first_flag
                        .is_some_and(|(_, r)| r == InvalidReason::NonFiniteUpdate);
                    let lost = run.lost_definiteness_at.is_some();
                    let (class, silent) = d.class(lost, non_finite);
                    let flagged = 100.0 * d.flagged as f64 / d.readings as f64;
                    let mark = match (class, silent) {
                        (Class::Ok, _) => String::new(),
                        (Class::OkPartly, _) => format!(" ({flagged:.0}% flagged)"),
                        (Class::Refused, _) => " F".into(),
                        (_, true) => format!(" **{}, silent**", class.name()),
                        (_, false) => format!(" {} F", class.name()),
                    };
                    if d.valid > 0 {
                        write!(out, " {:.2}{mark} |", d.normalised_rms())?;
                    } else {
                        write!(out, "{mark} |")?;
                    }
                }
                _ => write!(out, " |")?,
            }
        }
        match run.last {
            Outcome::Valid(error) => {
                writeln!(out, " {error:+.2e} g (bound {:.1e}) |", run.bound_end_g)?
            }
            Outcome::Flagged(reason) => writeln!(out, " {} |", state_name(State::Invalid(reason)))?,
            Outcome::WarmingUp => writeln!(out, " warming up |")?,
        }
    }
    Ok(())
}

/// Write the markdown report.
pub fn write_markdown(
    slices: &[SliceResult],
    long: Option<&LongResult>,
    command: &str,
    wall_s: f64,
    out: &mut impl Write,
) -> Result<()> {
    write_preamble(slices, command, wall_s, out)?;
    write_failure_modes(slices, out)?;
    write_f32_goal(slices, long, out)?;
    for slice in slices {
        match slice.conditions.first().map(|c| c.slice) {
            Some(Slice::OrderSnr) => write_order_slice(slice, out)?,
            Some(kind) => write_probe_slice(slice, kind, out)?,
            None => {}
        }
    }
    if let Some(long) = long {
        write_long_section(long, out)?;
    }
    Ok(())
}

/// The title, the command and how to read a cell.
fn write_preamble(
    slices: &[SliceResult],
    command: &str,
    wall_s: f64,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(out, "# Stability map\n")?;
    writeln!(
        out,
        "`{command}`: {} runs a Monte Carlo cell, {wall_s:.0} s wall on {} threads. Cell text: RMS error of the valid runs over the CRLB (known model, onset, tare), then a mark: `S` silent > 10× CRLB; `F` most runs flagged; `·` not yet determined; `(x% valid)` some runs flagged or not yet; **PD!**/**NaN!**/**DIV!** silent loss of definiteness, non-finite value, divergence (`PD F`, `NaN F`: the same, flagged).\n",
        slices.first().map(|s| s.runs).unwrap_or(0),
        rayon::current_num_threads()
    )?;
    Ok(())
}

/// The failure modes per family, every slice.
fn write_failure_modes(slices: &[SliceResult], out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "## Failure modes found (cells × readouts, every slice)\n"
    )?;
    writeln!(out, "| family (slice) | cells |")?;
    writeln!(out, "|---|---|")?;
    for (family, counts) in failure_summary(slices) {
        writeln!(
            out,
            "| {family} | {} |",
            failure_counts_text(&counts, " (SILENT)", " (flagged)")
        )?;
    }
    Ok(())
}

/// The f32 goal, per family and for the long runs.
fn write_f32_goal(
    slices: &[SliceResult],
    long: Option<&LongResult>,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(
        out,
        "\n## f32 against f64 (goal: f32 RMS within 10% of f64 where f64 is valid)\n"
    )?;
    for (family, checked, failures) in f32_goal(slices) {
        if failures.is_empty() {
            writeln!(out, "- PASS {family}: {checked} cells")?;
        } else {
            let list: Vec<String> = failures
                .iter()
                .take(12)
                .map(|f| {
                    format!(
                        "{} ({}{})",
                        f.what,
                        f.class.name(),
                        f.ratio.map(|r| format!(", {r:.2}")).unwrap_or_default()
                    )
                })
                .collect();
            writeln!(
                out,
                "- FAIL {family}: {} of {checked} cells: {}{}",
                failures.len(),
                list.join("; "),
                if failures.len() > 12 { "; …" } else { "" }
            )?;
        }
    }
    if let Some(long) = long {
        let failures = long_f32_goal(long);
        if failures.is_empty() {
            writeln!(out, "- PASS long runs: every decade from 10⁴ samples on")?;
        } else {
            writeln!(out, "- FAIL long runs: {}", failures.join("; "))?;
        }
    }
    Ok(())
}

/// Slice A: a table per family and precision, SNR against order.
fn write_order_slice(slice: &SliceResult, out: &mut impl Write) -> Result<()> {
    writeln!(out, "\n## A: order × SNR (white noise)")?;
    let families = distinct(
        slice
            .probes
            .iter()
            .map(|probe| (probe.family.clone(), probe.method.precision())),
    );
    let orders = slice.orders();
    for (family, precision) in families {
        writeln!(
            out,
            "\n### {family}, {}",
            if precision == Precision::F32 {
                "f32"
            } else {
                "f64"
            }
        )?;
        let columns: Vec<String> = orders.iter().map(|n| format!("n={n}")).collect();
        let rows = |s: &SliceResult| -> TableRows {
            s.conditions
                .iter()
                .enumerate()
                .map(|(c, condition)| {
                    (
                        format!("{} dB", condition.snr_db),
                        orders
                            .iter()
                            .filter_map(|&n| s.probe_at(&family, n, precision).map(|p| (c, p)))
                            .collect(),
                    )
                })
                .collect()
        };
        markdown_slice(slice, out, &rows, &columns)?;
    }
    Ok(())
}

/// Slices B and C: a table per group of conditions (noise type, or white-noise level),
/// probes against the conditions.
fn write_probe_slice(slice: &SliceResult, kind: Slice, out: &mut impl Write) -> Result<()> {
    type Grouping = Box<dyn Fn(&Condition) -> String>;
    let (title, group): (&str, Grouping) = match kind {
        Slice::NoiseType => (
            "B: noise type × SNR (the disturbance has the white noise's RMS; judged against the white-noise CRLB at the total power)",
            Box::new(|c: &Condition| c.noise.name().to_string()),
        ),
        _ => (
            "C: off-calibration (resonance with the load over the one at the 200 g calibration; the white noise held at the reference scene's SNR)",
            Box::new(|c: &Condition| format!("{} dB", c.snr_db)),
        ),
    };
    writeln!(out, "\n## {title}")?;
    for g in distinct(slice.conditions.iter().map(&group)) {
        writeln!(out, "\n### {g}")?;
        let members: Vec<usize> = (0..slice.conditions.len())
            .filter(|&c| group(&slice.conditions[c]) == g)
            .collect();
        let columns: Vec<String> = members
            .iter()
            .map(|&c| {
                let condition = &slice.conditions[c];
                match kind {
                    Slice::NoiseType => format!("{} dB", condition.snr_db),
                    _ => format!(
                        "×{} ({:.0} g)",
                        condition.resonance_ratio, condition.truth_g
                    ),
                }
            })
            .collect();
        let rows = |s: &SliceResult| -> TableRows {
            s.probes
                .iter()
                .enumerate()
                .map(|(p, probe)| {
                    (
                        format!("{} (`{}`)", probe_label(probe), probe.method),
                        members.iter().map(|&c| (c, p)).collect(),
                    )
                })
                .collect()
        };
        markdown_slice(slice, out, &rows, &columns)?;
    }
    Ok(())
}

/// Slice D: the long runs' table.
fn write_long_section(long: &LongResult, out: &mut impl Write) -> Result<()> {
    writeln!(
        out,
        "\n## D: long runs (one run of {} samples a cell, a steady 138.32 g at 50 dB)\n",
        long.samples
    )?;
    writeln!(
        out,
        "RMS error over the steady-state bound `σ²/D·(1−λ)(1+λᵐ)/((1+λ)(1−λᵐ))` (m decimated rows; σ² = {:.4} g², white + quantisation + amplifier) of the valid readings in each decade of samples; the first decade holds the drop's transient, where this bound does not apply.\n",
        long.raw_variance_g2
    )?;
    long_rows(long, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::run::tests::known_slice;

    #[test]
    fn slice_a_has_a_table_per_family_and_precision_with_the_cell_text() {
        let mut out = Vec::new();
        write_order_slice(&known_slice(2.0), &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text.matches("\n### ").count(), 10);
        assert!(text.contains(
            "\n### step D=16, f64\n\nAt 100 ms:\n\n| | n=7 |\n|---|---|\n| 50 dB | **20.0** S |\n"
        ));
    }

    #[test]
    fn the_failure_modes_table_lists_each_family_once_per_slice() {
        let mut out = Vec::new();
        write_failure_modes(&[known_slice(2.0)], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.contains("| step D=16 (order_snr) | 4 over_10x_crlb (SILENT) |\n"));
        assert_eq!(text.lines().filter(|l| l.starts_with("| ")).count(), 1 + 5);
    }
}
