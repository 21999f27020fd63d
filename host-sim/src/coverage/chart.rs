//! The coverage chart: the share of runs within ±2u against the readout time, one line per
//! SNR, with the 95 % goal, its ±3 % tolerance and the Monte Carlo band of the run count
//! (a true 95 % is observed inside the band 95 % of the time). Linear axes: the study's
//! other charts are logarithmic in the error, which a share is not.
//!
//! What it must never do: compute a figure (it draws what `study` computed).

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{SnrRow, TIMES_MS};
use crate::chart::{draw_legend, LegendLine, LEGEND_WIDTH, PALETTE};

/// Write `<base>.svg` and `<base>.png`: `title` names the method, scene and runs.
pub fn write(rows: &[SnrRow], title: &str, base: &Path) -> Result<()> {
    crate::chart::register_font()?;
    let size = (1000 + LEGEND_WIDTH, 650);
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
    rows: &[SnrRow],
    title: &str,
    root: &DrawingArea<DB, Shift>,
) -> Result<()> {
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
    root.fill(&WHITE).map_err(error)?;
    // The legend has a panel of its own right of the plot: never over the data.
    let (width, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let mut entries = Vec::new();
    let x_max = f64::from(*TIMES_MS.last().unwrap()) + 10.0;
    let lowest = rows
        .iter()
        .flat_map(|row| row.cells.iter())
        .filter_map(|cell| cell.coverage())
        .fold(0.85f64, f64::min);
    let y_min = (100.0 * lowest - 5.0).floor().max(0.0);
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..x_max, y_min..101.0)
        .map_err(error)?;
    chart
        .configure_mesh()
        .x_desc("readout time after the landing (ms)")
        .y_desc("runs within ±2u (%)")
        .label_style(("sans-serif", 14))
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(error)?;
    // The band of the largest run count stated anywhere: the narrowest a reader should
    // trust; cells with fewer stated runs are noisier.
    let band = rows
        .iter()
        .flat_map(|row| row.cells.iter())
        .filter_map(|cell| cell.band())
        .fold(f64::INFINITY, f64::min);
    if band.is_finite() {
        let (low, high) = (100.0 * (0.95 - band), 100.0 * (0.95 + band));
        let shade = BLACK.mix(0.12).filled();
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, low), (x_max, high)],
                shade,
            )))
            .map_err(error)?;
        entries.push((
            format!("Monte Carlo band of a true 95 % (±{:.1} %)", 100.0 * band),
            LegendLine::Filled(shade),
        ));
    }
    let goal = BLACK.stroke_width(1);
    chart
        .draw_series(LineSeries::new([(0.0, 95.0), (x_max, 95.0)], goal))
        .map_err(error)?;
    entries.push(("goal 95 %".to_string(), LegendLine::Solid(goal)));
    let tolerance = BLACK.mix(0.5).stroke_width(1);
    for edge in [92.0, 98.0] {
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, edge), (x_max, edge)],
                6,
                4,
                tolerance,
            ))
            .map_err(error)?;
    }
    entries.push((
        "goal's tolerance, 95 ± 3 %".to_string(),
        LegendLine::Dashed(tolerance, (6, 4)),
    ));
    for (row, colour) in rows.iter().zip(PALETTE.iter().cycle()) {
        let points: Vec<(f64, f64)> = TIMES_MS
            .iter()
            .zip(&row.cells)
            .filter_map(|(t, cell)| cell.coverage().map(|c| (f64::from(*t), 100.0 * c)))
            .collect();
        if points.is_empty() {
            continue;
        }
        let style = colour.stroke_width(2);
        chart
            .draw_series(points.iter().map(|p| Circle::new(*p, 3, style.filled())))
            .map_err(error)?;
        chart
            .draw_series(LineSeries::new(points, style))
            .map_err(error)?;
        entries.push((format!("{} dB", row.snr_db), LegendLine::Solid(style)));
    }
    draw_legend(&legend, &entries).map_err(error)?;
    root.present().map_err(error)?;
    Ok(())
}
