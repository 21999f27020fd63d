//! Time to a final reading: when, after the landing, twice the stated `u` first falls to
//! the final target (`[scale] final_target_g`; the scale's `is_final` also needs four `u`
//! within the permissible error, `VOUCHING_COVERAGE_FACTOR`), per run, against
//! the fixed 100 ms readout, at each SNR; and how far those first final readings are from
//! the truth. The estimator alone with the onset known, as the coverage table (the scale
//! adds its onset detection's lag, a few samples).
//!
//! What it must never do: call a run final that never stated a `u` within the target (it
//! is counted as not final by the scene's end, the chart's lines end below 100 %).

use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, Result};
use estimator_core::sensor::AdcSource;
use plotters::coord::Shift;
use plotters::prelude::*;
use rayon::prelude::*;

use super::Colour;
use crate::chart::{draw_legend, LegendLine, LEGEND_WIDTH, PALETTE};
use crate::method::{BuildContext, Method};
use crate::scene::Scene;
use crate::simulated::run_seed;

/// The last readout time looked at, ms after the landing.
pub const HORIZON_MS: f64 = 400.0;

/// One SNR's runs.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalRow {
    /// Signal-to-noise ratio, dB.
    pub snr_db: f64,
    /// Runs.
    pub runs: usize,
    /// Per run that became final within [`HORIZON_MS`]: the time (ms after the landing) and
    /// the error of that first final reading (g), sorted by time.
    pub finals: Vec<(f64, f64)>,
}

impl FinalRow {
    /// The share of runs final by `ms`.
    pub fn final_by(&self, ms: f64) -> f64 {
        self.finals.iter().filter(|(t, _)| *t <= ms).count() as f64 / self.runs as f64
    }

    /// The `q`-quantile of the time to final over all runs (`None` when fewer than that
    /// share became final).
    pub fn quantile_ms(&self, q: f64) -> Option<f64> {
        let rank = (q * self.runs as f64).ceil() as usize;
        (rank >= 1 && rank <= self.finals.len()).then(|| self.finals[rank - 1].0)
    }

    /// The share of first final readings with |error| above `limit_g`.
    pub fn beyond(&self, limit_g: f64) -> f64 {
        if self.finals.is_empty() {
            return 0.0;
        }
        self.finals
            .iter()
            .filter(|(_, e)| e.abs() > limit_g)
            .count() as f64
            / self.finals.len() as f64
    }
}

/// Run `runs` drops of `scene` per SNR through `method`; a reading is final once
/// `2u ≤ target_g`. With [`Colour::Metered`] as the coverage study runs them (the noise
/// running before the landing, a step method's `u` on the empty pan's metered colour:
/// [`super::prepared`]); with [`Colour::Unknown`] from the scene's first sample, the `u`
/// from the residuals alone (as `host-sim study speed` runs them, on the same records).
pub fn study(
    scene: &str,
    method: &Method,
    runs: u64,
    seed: u64,
    snrs_db: &[f64],
    target_g: f64,
    colour: Colour,
) -> Result<Vec<FinalRow>> {
    let base = Scene::load(scene)?;
    let (_, mass_g, _) = base.studied_step();
    snrs_db
        .iter()
        .map(|&snr_db| {
            let (scene, context) = match colour {
                Colour::Metered => super::prepared(&base, snr_db, method, seed, colour)?,
                Colour::Unknown => {
                    let scene = base.with_snr_db(snr_db);
                    let context = BuildContext::new(scene.chain, scene.chain.counts_per_gram());
                    (scene, context)
                }
            };
            method.build(&context)?;
            let per_run: Vec<Result<Option<(f64, f64)>>> = (0..runs)
                .into_par_iter()
                .map(|run| {
                    one_run(
                        &scene,
                        method,
                        &context,
                        run_seed(seed, run),
                        mass_g,
                        target_g,
                    )
                })
                .collect();
            let mut finals = Vec::new();
            for run in per_run {
                finals.extend(run?);
            }
            finals.sort_by(|a, b| a.0.total_cmp(&b.0));
            Ok(FinalRow {
                snr_db,
                runs: runs as usize,
                finals,
            })
        })
        .collect()
}

fn one_run(
    scene: &Scene,
    method: &Method,
    context: &BuildContext,
    seed: u64,
    mass_g: f64,
    target_g: f64,
) -> Result<Option<(f64, f64)>> {
    let mut estimator = method.build(context)?;
    let mut adc = scene.adc(seed);
    let (onset, _, _) = scene.studied_step();
    for _ in 0..onset {
        let _ = adc.read();
    }
    let zero = scene.chain.zero_code();
    let rate_hz = 1.0 / scene.chain.conversion_period_s();
    let last = (HORIZON_MS * 1e-3 * rate_hz).round() as u64;
    for k in 1..=last {
        let reading = match adc.read() {
            Ok(code) => estimator.push(f64::from(code) - zero),
            Err(_) => estimator.push_missing(),
        };
        if let (Some(estimate), Some(bound)) = (reading.estimate, reading.uncertainty_bound()) {
            if 2.0 * bound <= target_g {
                return Ok(Some((k as f64 / rate_hz * 1e3, estimate - mass_g)));
            }
        }
    }
    Ok(None)
}

/// The table: share final by 50 and 100 ms, the median and 95th percentile of the time to
/// final, and the share of first final readings beyond `limit_g`.
pub fn write_markdown(
    rows: &[FinalRow],
    header: &str,
    limit_g: f64,
    out: &mut impl Write,
) -> Result<()> {
    writeln!(out, "{header}")?;
    writeln!(out)?;
    writeln!(
        out,
        "| SNR | final by 50 ms | final by 100 ms | final by {HORIZON_MS:.0} ms | median time to final | 95th percentile | first finals beyond ±{limit_g} g |"
    )?;
    writeln!(out, "|---|---:|---:|---:|---:|---:|---:|")?;
    let ms = |q: Option<f64>| q.map_or("—".to_string(), |t| format!("{t:.1} ms"));
    for row in rows {
        writeln!(
            out,
            "| {} dB | {:.1} % | {:.1} % | {:.1} % | {} | {} | {:.1} % |",
            row.snr_db,
            100.0 * row.final_by(50.0),
            100.0 * row.final_by(100.0),
            100.0 * row.final_by(HORIZON_MS),
            ms(row.quantile_ms(0.5)),
            ms(row.quantile_ms(0.95)),
            100.0 * row.beyond(limit_g)
        )?;
    }
    Ok(())
}

/// The chart: the share of runs final by each time (one line per SNR), with the fixed
/// 100 ms readout marked. Writes `<base>.svg` and `<base>.png`.
pub fn write_chart(rows: &[FinalRow], title: &str, base: &Path) -> Result<()> {
    crate::chart::register_font()?;
    let size = (1000, 650);
    let svg = base.with_extension("svg");
    draw(
        rows,
        title,
        &SVGBackend::new(&svg, size).into_drawing_area(),
    )?;
    let png = base.with_extension("png");
    draw(
        rows,
        title,
        &BitMapBackend::new(&png, size).into_drawing_area(),
    )?;
    Ok(())
}

fn draw<DB: DrawingBackend>(
    rows: &[FinalRow],
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> Result<()> {
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
    root.fill(&WHITE).map_err(error)?;
    // The legend has a panel of its own right of the plot: never over the data.
    let (width, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let mut entries = Vec::new();
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..HORIZON_MS, 0.0..101.0)
        .map_err(error)?;
    chart
        .configure_mesh()
        .x_desc("time after the landing (ms)")
        .y_desc("runs with a final reading (%)")
        .label_style(("sans-serif", 14))
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(error)?;
    let readout = BLACK.stroke_width(1);
    chart
        .draw_series(DashedLineSeries::new(
            [(100.0, 0.0), (100.0, 101.0)],
            6,
            4,
            readout,
        ))
        .map_err(error)?;
    entries.push((
        "the fixed readout, 100 ms".to_string(),
        LegendLine::Dashed(readout, (6, 4)),
    ));
    for (row, colour) in rows.iter().zip(PALETTE.iter().cycle()) {
        // A step line: the share final by each run's time.
        let mut points = vec![(0.0, 0.0)];
        for (i, (t, _)) in row.finals.iter().enumerate() {
            let before = 100.0 * i as f64 / row.runs as f64;
            let after = 100.0 * (i + 1) as f64 / row.runs as f64;
            points.push((*t, before));
            points.push((*t, after));
        }
        points.push((
            HORIZON_MS,
            100.0 * row.finals.len() as f64 / row.runs as f64,
        ));
        let style = colour.stroke_width(2);
        chart
            .draw_series(LineSeries::new(points, style))
            .map_err(error)?;
        entries.push((format!("{} dB", row.snr_db), LegendLine::Solid(style)));
    }
    draw_legend(&legend, &entries).map_err(error)?;
    root.present().map_err(error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_shares_count_runs_that_never_became_final() {
        let row = FinalRow {
            snr_db: 50.0,
            runs: 4,
            finals: vec![(80.0, 0.01), (90.0, -0.2), (120.0, 0.0)],
        };
        assert_eq!(row.final_by(100.0), 0.5);
        assert_eq!(row.quantile_ms(0.5), Some(90.0));
        assert_eq!(row.quantile_ms(0.75), Some(120.0));
        // The fourth run never became final: no 95th percentile within the horizon.
        assert_eq!(row.quantile_ms(0.95), None);
        assert!((row.beyond(0.1) - 1.0 / 3.0).abs() < 1e-12);
    }
}
