//! The map's CSV: one line per slice, condition, probe and readout, every count the class
//! was computed from, so a reader can redo the classification.

use std::io::Write;

use anyhow::Result;
use estimator_core::State;

use super::classify::REASONS;
use super::conditions::{Condition, READOUTS_S};
use super::probes::precision_name;
use super::run::SliceResult;
use crate::estimate::state_name;

fn condition_axes(condition: &Condition) -> String {
    format!(
        "{},{},{},{:.4},{:.3}",
        condition.slice.name(),
        condition.noise.name(),
        condition.snr_db,
        condition.resonance_ratio,
        condition.truth_g
    )
}

/// Write every Monte Carlo cell: one line per slice, condition, probe and readout.
pub fn write_csv(slices: &[SliceResult], out: &mut impl Write) -> Result<()> {
    write!(
        out,
        "slice,noise,snr_db,resonance_ratio,mass_g,family,spec,precision,order,readout_s,runs,valid,warming,flagged"
    )?;
    for reason in REASONS {
        write!(out, ",flagged_{}", &state_name(State::Invalid(reason))[8..])?;
    }
    writeln!(
        out,
        ",rms_g,max_error_g,crlb_g,rms_over_crlb,non_finite,diverged,lost_definiteness,lost_definiteness_valid,class,silent,f32_over_f64"
    )?;
    for slice in slices {
        for (condition, cells) in slice.conditions.iter().zip(&slice.cells) {
            for (probe, pair) in slice.probes.iter().zip(cells) {
                for (r, cell) in pair.iter().enumerate() {
                    let (class, silent) = cell.class();
                    write!(
                        out,
                        "{},{},{},{},{},{},{},{},{},{}",
                        condition_axes(condition),
                        probe.family.replace(',', ";"),
                        probe.method.to_string().replace(',', " "),
                        precision_name(&probe.method),
                        probe.order.map(|n| n.to_string()).unwrap_or_default(),
                        READOUTS_S[r],
                        cell.runs,
                        cell.valid,
                        cell.warming,
                        cell.flagged_total(),
                    )?;
                    for count in cell.flagged {
                        write!(out, ",{count}")?;
                    }
                    writeln!(
                        out,
                        ",{:.6e},{:.6e},{:.6e},{:.4},{},{},{},{},{},{},{}",
                        cell.rms_g(),
                        cell.max_error_g,
                        cell.crlb_g,
                        cell.ratio(),
                        cell.non_finite,
                        cell.diverged,
                        cell.lost_definiteness,
                        cell.lost_definiteness_valid,
                        class.name(),
                        silent,
                        cell.f32_over_f64()
                            .map(|v| format!("{v:.5}"))
                            .unwrap_or_default()
                    )?;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::run::tests::known_slice;

    #[test]
    fn every_row_has_the_header_s_columns_and_the_cell_s_figures() {
        let mut out = Vec::new();
        write_csv(&[known_slice(0.2)], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // 5 families × 1 order × 2 precisions × 2 readouts.
        assert_eq!(lines.len(), 1 + 20);
        let columns = lines[0].split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == columns));
        assert_eq!(
            lines[1],
            "order_snr,white,50,1.2500,138.320,step D=16,step:n=7 D=16,f64,7,0.1,1,1,0,0,0,0,0,0,0,0,0,0,0,2.000000e-1,2.000000e-1,1.000000e-1,2.0000,0,0,0,0,ok,false,"
        );
        assert!(lines[4].ends_with(",1.5,1,1,0,0,0,0,0,0,0,0,0,0,0,2.000000e-1,2.000000e-1,1.000000e-1,2.0000,0,0,0,0,ok,false,1.00000"));
    }
}
