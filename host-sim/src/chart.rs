//! Charts (SVG and PNG, plotters) of the Monte Carlo studies: (a) error against time,
//! (b) time to accuracy against SNR, (c) RMS error at the readout against SNR with the CRLB,
//! (d) MSE against the order n; for the speed study over every method (`host-sim study
//! speed`), (e) RMS error against the readout time and (f) time to 0.1% against SNR. The PNG
//! text uses DejaVu Sans, shipped in `assets/` (its licence beside it), so charts render the
//! same on a headless machine.
//!
//! What it must never do: compute a figure (a chart draws what a study computed), or depend
//! on a font the machine may lack.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::montecarlo::{StudyResult, TOLERANCES};

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

pub(crate) fn register_font() -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("the shipped DejaVu Sans font does not parse"))
}

/// One line on a chart.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points; non-finite ones are left out.
    pub points: Vec<(f64, f64)>,
    /// Draw as a reference (thin, dark): the CRLB, the sensor's own settling.
    pub reference: bool,
}

/// A chart with a linear x axis and a logarithmic y axis.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title (state the run count here).
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

/// The line colours, in turn (plotters' default palette order).
pub(crate) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
];

/// The legend panel's width, px, right of the plot.
pub(crate) const LEGEND_WIDTH: u32 = 270;

/// Dash and gap lengths, px, of the reference lines in turn.
const DASHES: [(u32, u32); 4] = [(6, 4), (2, 3), (12, 4), (8, 3)];

/// How a legend entry's sample is drawn.
pub(crate) enum LegendLine {
    /// A line in this style.
    Solid(ShapeStyle),
    /// A dashed line: style, dash and gap in px.
    Dashed(ShapeStyle, (u32, u32)),
    /// A filled box (a band).
    Filled(ShapeStyle),
}

/// The legend in its own panel (split off right of the plot, [`LEGEND_WIDTH`] wide): one
/// sample and the name (wrapped) per entry, top down.
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(impl AsRef<str>, LegendLine)],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    const LINE_HEIGHT: i32 = 16;
    const TEXT_X: i32 = 44;
    // Characters a line holds at 12 px (about 6.5 px a character).
    let columns = ((LEGEND_WIDTH as i32 - TEXT_X - 8) * 2 / 13) as usize;
    let font = ("sans-serif", 12).into_font().color(&BLACK);
    let mut y = 50;
    for (name, line) in entries {
        let sample = vec![(8, y + 6), (38, y + 6)];
        match line {
            LegendLine::Solid(style) => area.draw(&PathElement::new(sample, *style))?,
            LegendLine::Dashed(style, (dash, gap)) => {
                area.draw(&DashedPathElement::new(sample, *dash, *gap, *style))?
            }
            LegendLine::Filled(style) => {
                area.draw(&Rectangle::new([(8, y + 1), (38, y + 11)], *style))?
            }
        }
        for text in wrap(name.as_ref(), columns) {
            area.draw(&Text::new(text, (TEXT_X, y), font.clone()))?;
            y += LINE_HEIGHT;
        }
        y += 6;
    }
    Ok(())
}

/// `text` in lines of at most `columns` characters, broken at spaces where it can be.
fn wrap(text: &str, columns: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut current = String::new();
    for word in text.split(' ') {
        if !current.is_empty() && current.chars().count() + 1 + word.chars().count() > columns {
            lines.push(std::mem::take(&mut current));
        }
        if !current.is_empty() {
            current.push(' ');
        }
        current.push_str(word);
    }
    if !current.is_empty() {
        lines.push(current);
    }
    lines
}

/// A linear axis's tick as a plain number: `30`, not `30.0`; `0.25`, not `0.25000`.
fn plain_label(x: f64) -> String {
    let rounded = (x * 1e6).round() / 1e6;
    format!("{rounded}")
}

impl Chart {
    fn bounds(&self) -> (f64, f64, f64, f64) {
        let points = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite() && *y > 0.0);
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in points {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            return (0.0, 1.0, 1e-3, 1.0);
        }
        if x0 == x1 {
            x1 = x0 + 1.0;
        }
        (x0, x1, y0 / 1.5, y1 * 1.5)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
        root.fill(&WHITE).map_err(error)?;
        // The legend has a panel of its own right of the plot: never over the data.
        let (width, _) = root.dim_in_pixel();
        let (plot, legend) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
        let (x0, x1, y0, y1) = self.bounds();
        let mut chart = ChartBuilder::on(&plot)
            .caption(&self.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(75)
            .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
            .map_err(error)?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style(("sans-serif", 14))
            .x_label_formatter(&|x| plain_label(*x))
            .y_label_formatter(&|y| log_label(*y))
            .draw()
            .map_err(error)?;
        let mut entries = Vec::new();
        let (mut colour, mut references) = (0, 0);
        for series in &self.series {
            let points: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite() && *y > 0.0)
                .collect();
            // A series with nothing to draw takes neither a colour nor a legend entry: a
            // legend names only what the reader can find on the chart.
            let (Some(&first), Some(&last)) = (points.first(), points.last()) else {
                continue;
            };
            let line = if series.reference {
                // Each reference its own dash and its name under the line (at alternate
                // ends, so neighbouring references do not write over each other; a bound
                // lies below the data it bounds).
                let dash = DASHES[references % DASHES.len()];
                let at_right = references % 2 == 0;
                references += 1;
                let style = BLACK.mix(0.8).stroke_width(1);
                chart
                    .draw_series(DashedLineSeries::new(points, dash.0, dash.1, style))
                    .map_err(error)?;
                let (at, anchor) = if at_right {
                    (last, HPos::Right)
                } else {
                    (first, HPos::Left)
                };
                let font = ("sans-serif", 12)
                    .into_font()
                    .color(&BLACK)
                    .pos(Pos::new(anchor, VPos::Top));
                chart
                    .draw_series(std::iter::once(Text::new(series.name.clone(), at, font)))
                    .map_err(error)?;
                LegendLine::Dashed(style, dash)
            } else {
                let style = PALETTE[colour % PALETTE.len()].stroke_width(2);
                colour += 1;
                let marked = points.len() <= 40;
                if marked {
                    chart
                        .draw_series(points.iter().map(|p| Circle::new(*p, 3, style.filled())))
                        .map_err(error)?;
                }
                chart
                    .draw_series(LineSeries::new(points, style))
                    .map_err(error)?;
                LegendLine::Solid(style)
            };
            entries.push((series.name.as_str(), line));
        }
        draw_legend(&legend, &entries).map_err(error)?;
        root.present().map_err(error)?;
        Ok(())
    }

    /// Write `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<()> {
        register_font()?;
        let size = (1000, 650);
        let svg = base.with_extension("svg");
        self.draw(&SVGBackend::new(&svg, size).into_drawing_area())?;
        let png = base.with_extension("png");
        self.draw(&BitMapBackend::new(&png, size).into_drawing_area())?;
        Ok(())
    }
}

/// (a) |relative error| against time: one run and the Monte Carlo RMS, with the CRLB.
pub fn error_against_time(result: &StudyResult) -> Chart {
    let rate = result.sample_rate_hz;
    let mut series = Vec::new();
    for (stats, example) in result.setups.iter().zip(&result.example_relative_error) {
        series.push(Series {
            name: format!("{}: one run", stats.setup.label()),
            points: example
                .iter()
                .enumerate()
                .step_by(4)
                .map(|(k, e)| (k as f64 / rate, e.abs()))
                .collect(),
            reference: false,
        });
        series.push(Series {
            name: format!("{}: RMS over runs", stats.setup.label()),
            points: (0..stats.valid.len())
                .step_by(4)
                .filter(|k| stats.valid[*k] > 1)
                .map(|k| (k as f64 / rate, stats.rms(k) / result.truth_g))
                .collect(),
            reference: false,
        });
    }
    series.push(Series {
        name: "CRLB (known model, onset, tare)".into(),
        points: result
            .crlb_g2
            .iter()
            .enumerate()
            .step_by(4)
            .map(|(k, v)| (k as f64 / rate, v.sqrt() / result.truth_g))
            .collect(),
        reference: true,
    });
    Chart {
        title: format!(
            "(a) {} at {} dB: |relative error| vs time ({} runs, seed {})",
            result.scene, result.snr_db, result.runs, result.seed
        ),
        x_label: "time after the drop, s".into(),
        y_label: "|relative error|".into(),
        series,
    }
}

/// (b) median time to reach and stay within 0.5%, 0.1%, 0.05% against SNR.
pub fn time_against_snr(results: &[StudyResult]) -> Chart {
    let mut series = Vec::new();
    let Some(first) = results.first() else {
        return empty("(b) no results");
    };
    for (index, setup) in first.setups.iter().map(|s| s.setup.label()).enumerate() {
        for (t, tolerance) in TOLERANCES.iter().enumerate() {
            series.push(Series {
                name: format!("{setup}: within {}%", tolerance * 100.0),
                points: results
                    .iter()
                    .map(|r| (r.snr_db, r.setups[index].settle_quantile(t, 0.5)))
                    .collect(),
                reference: false,
            });
        }
    }
    for (t, tolerance) in TOLERANCES.iter().enumerate() {
        let settle = first.sensor_settle_s[t];
        series.push(Series {
            name: format!(
                "sensor itself settles within {}%: {settle:.3} s",
                tolerance * 100.0
            ),
            points: results.iter().map(|r| (r.snr_db, settle)).collect(),
            reference: true,
        });
    }
    against_snr(
        format!(
            "(b) {}: median time to reach and stay within tolerance ({} runs per point)",
            first.scene, first.runs
        ),
        "time after the drop, s (missing: not within 1.5 s)",
        series,
    )
}

/// A chart whose x axis is the SNR.
fn against_snr(title: String, y_label: &str, series: Vec<Series>) -> Chart {
    Chart {
        title,
        x_label: "SNR, dB (thesis eq. 4.39)".into(),
        y_label: y_label.into(),
        series,
    }
}

/// (c) RMS relative error at the readout time against SNR, with the CRLB.
pub fn rms_against_snr(results: &[StudyResult], readout_s: f64) -> Chart {
    let Some(first) = results.first() else {
        return empty("(c) no results");
    };
    let k = |r: &StudyResult| {
        ((readout_s * r.sample_rate_hz).round() as usize).min(r.crlb_g2.len().saturating_sub(1))
    };
    let mut series: Vec<Series> = first
        .setups
        .iter()
        .enumerate()
        .map(|(index, stats)| Series {
            name: stats.setup.label(),
            points: results
                .iter()
                .map(|r| (r.snr_db, r.setups[index].rms(k(r)) / r.truth_g))
                .collect(),
            reference: false,
        })
        .collect();
    series.push(Series {
        name: "CRLB (known model, onset, tare)".into(),
        points: results
            .iter()
            .map(|r| (r.snr_db, r.crlb_g2[k(r)].sqrt() / r.truth_g))
            .collect(),
        reference: true,
    });
    against_snr(
        format!(
            "(c) {}: RMS relative error at {} ms vs SNR ({} runs per point)",
            first.scene,
            readout_s * 1e3,
            first.runs
        ),
        "RMS relative error",
        series,
    )
}

/// (d) MSE (relative) against the order n at the readout sample, one line per SNR and
/// decimation; each result holds the configurations of one SNR.
pub fn mse_against_order(by_snr: &[StudyResult], readout_samples: usize) -> Chart {
    let Some(first) = by_snr.first() else {
        return empty("(d) no results");
    };
    // Only step configurations have an order; other methods in the study are left out.
    let step = |s: &crate::montecarlo::SetupStats| s.setup.step_setup().copied();
    let mut decimations: Vec<u16> = first
        .setups
        .iter()
        .filter_map(|s| step(s).map(|setup| setup.decimation))
        .collect();
    decimations.sort_unstable();
    decimations.dedup();
    let mut series = Vec::new();
    for &decimation in &decimations {
        for result in by_snr {
            let k = readout_samples.min(result.crlb_g2.len()).saturating_sub(1);
            series.push(Series {
                name: format!("{} dB, D = {decimation}", result.snr_db),
                points: result
                    .setups
                    .iter()
                    .filter_map(|s| step(s).map(|setup| (setup, s)))
                    .filter(|(setup, s)| {
                        setup.decimation == decimation && s.valid[k] as usize == result.runs
                    })
                    .map(|(setup, s)| (setup.order as f64, (s.rms(k) / result.truth_g).powi(2)))
                    .collect(),
                reference: false,
            });
        }
    }
    for result in by_snr {
        let k = readout_samples.min(result.crlb_g2.len()).saturating_sub(1);
        let crlb = result.crlb_g2[k] / (result.truth_g * result.truth_g);
        let orders = first
            .setups
            .iter()
            .filter_map(|s| step(s).map(|setup| setup.order as f64));
        series.push(Series {
            name: format!("CRLB {} dB", result.snr_db),
            points: orders.map(|n| (n, crlb)).collect(),
            reference: true,
        });
    }
    Chart {
        title: format!(
            "(d) {}: relative MSE at {} samples vs order n ({} runs per point)",
            first.scene, readout_samples, first.runs
        ),
        x_label: "order n".into(),
        y_label: "relative MSE".into(),
        series,
    }
}

/// (e) speed against accuracy: RMS relative error against the readout time, one line per
/// method (`names` in the order of the result's methods), with the CRLB. A method shows only
/// where it is valid in every run, so no line stands on a subset of the runs.
pub fn rms_against_readout(
    result: &StudyResult,
    names: &[String],
    from_s: f64,
    to_s: f64,
) -> Chart {
    let rate = result.sample_rate_hz;
    let first = (from_s * rate).round() as usize;
    let last = ((to_s * rate).round() as usize).min(result.crlb_g2.len().saturating_sub(1));
    // One point a millisecond.
    let step = ((rate / 1000.0).round() as usize).max(1);
    let indices = move || (first..=last).step_by(step);
    let mut series: Vec<Series> = result
        .setups
        .iter()
        .zip(names)
        .map(|(stats, name)| {
            let points: Vec<(f64, f64)> = indices()
                .filter(|&k| stats.valid[k] as usize == result.runs)
                .map(|k| (k as f64 / rate * 1e3, stats.rms(k) / result.truth_g))
                .collect();
            Series {
                name: name.clone(),
                points,
                reference: false,
            }
        })
        .collect();
    series.push(Series {
        name: "CRLB (known model, onset, tare)".into(),
        points: indices()
            .map(|k| {
                (
                    k as f64 / rate * 1e3,
                    result.crlb_g2[k].sqrt() / result.truth_g,
                )
            })
            .collect(),
        reference: true,
    });
    Chart {
        title: format!(
            "(e) {} at {} dB: RMS relative error at the readout time ({} runs, seed {})",
            result.scene, result.snr_db, result.runs, result.seed
        ),
        x_label: "readout time after the drop, ms (a line starts when valid in every run)".into(),
        y_label: "RMS relative error".into(),
        series,
    }
}

/// (f) median time to reach and stay within 0.1% against SNR, one line per method, with the
/// sensor's own settling time.
pub fn settle_against_snr(results: &[StudyResult], names: &[String]) -> Chart {
    let Some(first) = results.first() else {
        return empty("(f) no results");
    };
    let tolerance = 1;
    let mut series: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(index, name)| {
            let points: Vec<(f64, f64)> = results
                .iter()
                .map(|r| {
                    (
                        r.snr_db,
                        r.setups[index].settle_quantile(tolerance, 0.5) * 1e3,
                    )
                })
                .collect();
            Series {
                name: name.clone(),
                points,
                reference: false,
            }
        })
        .collect();
    let settle = first.sensor_settle_s[tolerance];
    series.push(Series {
        name: format!("sensor itself settles within 0.1%: {:.0} ms", settle * 1e3),
        points: results.iter().map(|r| (r.snr_db, settle * 1e3)).collect(),
        reference: true,
    });
    against_snr(
        format!(
            "(f) {}: median time to reach and stay within {}% ({} runs per point)",
            first.scene,
            TOLERANCES[tolerance] * 100.0,
            first.runs
        ),
        "time after the drop, ms (missing: not within at 1.5 s)",
        series,
    )
}

/// (k) Median time to the first final reading (twice `u` at its upper 95 % bound within the
/// study's target) against SNR, with the CRLB's earliest final: the information limit for
/// a method whose `u` is honest. Methods that state no `u`, or are never final, draw
/// nothing and take no legend entry.
pub fn final_against_snr(results: &[StudyResult], names: &[String]) -> Chart {
    let Some(first) = results.first() else {
        return empty("(k) no results");
    };
    let Some(target) = first.final_target_g else {
        return empty("(k) no final target");
    };
    let mut series: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(index, name)| Series {
            name: name.clone(),
            points: results
                .iter()
                .map(|r| (r.snr_db, r.setups[index].final_quantile(0.5) * 1e3))
                .collect(),
            reference: false,
        })
        .collect();
    series.push(Series {
        name: "CRLB: earliest final (2 × bound within the target)".into(),
        points: results
            .iter()
            .map(|r| (r.snr_db, crate::montecarlo::crlb_final_s(r, target) * 1e3))
            .collect(),
        reference: true,
    });
    series.push(Series {
        name: "goal: final by 50 ms".into(),
        points: results.iter().map(|r| (r.snr_db, 50.0)).collect(),
        reference: true,
    });
    against_snr(
        format!(
            "(k) {}: median time to a final reading, 2u ≤ {target} g ({} runs per point)",
            first.scene, first.runs
        ),
        "time after the drop, ms (missing: half the runs not final by 1.5 s)",
        series,
    )
}

/// Labels at 1, 2 and 5 times a power of ten only, so a log axis stays readable.
fn log_label(y: f64) -> String {
    if !(y > 0.0) {
        return String::new();
    }
    let exponent = y.log10().floor();
    let mantissa = y / 10f64.powf(exponent);
    let keep = [1.0, 2.0, 5.0]
        .iter()
        .any(|m| (mantissa - m).abs() < 1e-6 * m);
    if !keep {
        String::new()
    } else if (-3.0..=4.0).contains(&exponent) {
        format!("{}", (y * 1e6).round() / 1e6)
    } else {
        format!("{}e{}", mantissa.round(), exponent)
    }
}

fn empty(title: &str) -> Chart {
    Chart {
        title: title.into(),
        x_label: String::new(),
        y_label: String::new(),
        series: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_plain_and_names_wrap_at_spaces() {
        assert_eq!(plain_label(30.0), "30");
        assert_eq!(plain_label(0.25), "0.25");
        assert_eq!(plain_label(12.500000001), "12.5");
        // A log axis: plain from 0.001 to 10,000, powers of ten beyond.
        assert_eq!(log_label(1000.0), "1000");
        assert_eq!(log_label(0.002), "0.002");
        assert_eq!(log_label(1e-4), "1e-4");
        assert_eq!(log_label(3e-4), "");
        let lines = wrap("sensor itself settles within 0.05%: 1.606 s", 20);
        assert_eq!(lines, ["sensor itself", "settles within", "0.05%: 1.606 s"]);
        assert!(lines.iter().all(|l| l.chars().count() <= 20));
        // A word longer than a line stands on a line of its own.
        assert_eq!(wrap("a verylongword b", 5), ["a", "verylongword", "b"]);
    }
}
