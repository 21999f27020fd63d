//! The map's heat maps (slices A–C) and the long runs' chart (slice D). A cell's colour says
//! its class and whether the failure was silent; a silent failure must never share a colour
//! with a flagged one.

use std::path::Path;

use anyhow::{anyhow, Result};
use estimator_core::InvalidReason;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::classify::{Cell, Class};
use super::conditions::{readout_name, Condition};
use super::long::{LongResult, BINS_PER_DECADE, FIRST_DECADE};
use super::probes::{precision_name, probe_label};
use super::run::{distinct, SliceResult};
use crate::chart;
use crate::method::Method;
use crate::montecarlo::Precision;

/// A cell's colour on the heat maps, by class and whether the failure was silent.
fn colour(class: Class, silent: bool) -> RGBColor {
    match (class, silent) {
        (Class::Ok, _) => RGBColor(44, 160, 44),
        (Class::OkPartly, _) => RGBColor(161, 217, 155),
        (Class::NotYet, _) => RGBColor(215, 215, 215),
        (Class::Refused, _) => RGBColor(158, 202, 225),
        (Class::OverBound, _) => RGBColor(253, 141, 60),
        (Class::LostDefiniteness | Class::NonFinite | Class::Diverged, false) => {
            RGBColor(49, 130, 189)
        }
        (_, true) => RGBColor(203, 24, 29),
    }
}

/// The legend of the heat maps: colour and meaning.
const LEGEND: [(Class, bool, &str); 8] = [
    (Class::Ok, false, "ok (≤ 10× CRLB, all runs valid)"),
    (Class::OkPartly, false, "ok, some runs flagged / not yet"),
    (Class::NotYet, false, "not yet determined"),
    (Class::Refused, false, "flagged: most runs refused"),
    (
        Class::LostDefiniteness,
        false,
        "flagged failure (lost PD, non-finite)",
    ),
    (Class::OverBound, true, "SILENT: > 10× CRLB"),
    (
        Class::Diverged,
        true,
        "SILENT: diverged / lost PD / non-finite",
    ),
    (Class::NotYet, false, ""),
];

/// One panel of a heat map: `cells[y][x]`.
pub struct Panel {
    /// Panel title.
    pub title: String,
    /// Column labels.
    pub x_labels: Vec<String>,
    /// Row labels, bottom up.
    pub y_labels: Vec<String>,
    /// x axis name.
    pub x_name: String,
    /// (class, silent, text) per cell.
    pub cells: Vec<Vec<(Class, bool, String)>>,
}

/// A grid of heat-map panels, written as SVG and PNG.
pub struct HeatMap {
    /// Figure title.
    pub title: String,
    /// Panels, row-major in a grid of `columns`.
    pub panels: Vec<Panel>,
    /// Panels per row.
    pub columns: usize,
    /// Pixels per panel (width, height).
    pub panel_size: (u32, u32),
    /// Width of the row-label area, px.
    pub label_width: u32,
}

impl HeatMap {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
        root.fill(&WHITE).map_err(error)?;
        let (width, height) = root.dim_in_pixel();
        let (top, rest) = root.split_vertically(40);
        // 20 px, or smaller where the title would run past the right edge (a character
        // is about 0.55 of the font size wide).
        let characters = self.title.chars().count().max(1) as f64;
        let title_size = (1.8 * f64::from(width) / characters).min(20.0);
        top.draw(&Text::new(
            self.title.clone(),
            (10, 10),
            ("sans-serif", title_size).into_font(),
        ))
        .map_err(error)?;
        let legend_height = LEGEND_ROW_HEIGHT * legend_rows(width);
        let (body, legend) = rest.split_vertically(height - 40 - legend_height);
        let rows = self.panels.len().div_ceil(self.columns);
        let areas = body.split_evenly((rows, self.columns));
        for (panel, area) in self.panels.iter().zip(areas.iter()) {
            self.draw_panel(panel, area)?;
        }
        draw_legend(&legend, width)?;
        root.present().map_err(error)?;
        Ok(())
    }

    /// One panel: the axes with their labels, then a coloured rectangle and a text per cell.
    fn draw_panel<DB: DrawingBackend>(
        &self,
        panel: &Panel,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<()> {
        let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
        let nx = panel.x_labels.len() as i32;
        let ny = panel.y_labels.len() as i32;
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 15))
            .margin(6)
            .x_label_area_size(38)
            .y_label_area_size(self.label_width)
            .build_cartesian_2d((0..nx).into_segmented(), (0..ny).into_segmented())
            .map_err(error)?;
        let x_labels = panel.x_labels.clone();
        let y_labels = panel.y_labels.clone();
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(nx as usize + 1)
            .y_labels(ny as usize + 1)
            .x_desc(panel.x_name.as_str())
            .label_style(("sans-serif", 12))
            .x_label_formatter(&|v| segment_label(&x_labels, v))
            .y_label_formatter(&|v| segment_label(&y_labels, v))
            .draw()
            .map_err(error)?;
        for (j, row) in panel.cells.iter().enumerate() {
            for (i, (class, silent, text)) in row.iter().enumerate() {
                let (i, j) = (i as i32, j as i32);
                let fill = colour(*class, *silent);
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [
                            (SegmentValue::Exact(i), SegmentValue::Exact(j)),
                            (SegmentValue::Exact(i + 1), SegmentValue::Exact(j + 1)),
                        ],
                        fill.filled(),
                    )))
                    .map_err(error)?;
                let ink = if *silent && *class != Class::OverBound {
                    WHITE
                } else {
                    BLACK
                };
                let style = TextStyle::from(("sans-serif", 10).into_font())
                    .color(&ink)
                    .pos(Pos::new(HPos::Center, VPos::Center));
                chart
                    .draw_series(std::iter::once(Text::new(
                        text.clone(),
                        (SegmentValue::CenterOf(i), SegmentValue::CenterOf(j)),
                        style,
                    )))
                    .map_err(error)?;
            }
        }
        Ok(())
    }

    /// Write `<base>.svg` and `<base>.png`.
    pub fn write(&self, base: &Path) -> Result<()> {
        chart::register_font()?;
        let rows = self.panels.len().div_ceil(self.columns) as u32;
        let width = self.panel_size.0 * self.columns as u32;
        let size = (
            width,
            self.panel_size.1 * rows + 40 + LEGEND_ROW_HEIGHT * legend_rows(width),
        );
        let svg = base.with_extension("svg");
        self.draw(&SVGBackend::new(&svg, size).into_drawing_area())?;
        let png = base.with_extension("png");
        self.draw(&BitMapBackend::new(&png, size).into_drawing_area())?;
        Ok(())
    }
}

/// The label at the centre of segment `i`, none between segments.
fn segment_label(labels: &[String], value: &SegmentValue<i32>) -> String {
    match value {
        SegmentValue::CenterOf(i) => labels.get(*i as usize).cloned().unwrap_or_default(),
        _ => String::new(),
    }
}

/// The height of one row of the legend, px.
const LEGEND_ROW_HEIGHT: u32 = 30;

/// Where each legend entry goes in an image `width` px wide: (x, row), in order; entries
/// that would run past the right edge start a new row.
fn legend_layout(width: u32) -> Vec<(i32, u32)> {
    let mut places = Vec::new();
    let (mut x, mut row) = (10i32, 0u32);
    for (_, _, text) in LEGEND.iter().filter(|l| !l.2.is_empty()) {
        let entry = 24 + 8 * text.chars().count() as i32 + 24;
        if x > 10 && x + entry > width as i32 {
            x = 10;
            row += 1;
        }
        places.push((x, row));
        x += entry;
    }
    places
}

/// The rows the legend takes in an image `width` px wide.
fn legend_rows(width: u32) -> u32 {
    legend_layout(width).last().map_or(1, |&(_, row)| row + 1)
}

/// The legend along the bottom: a swatch and a meaning per entry, in as many rows as the
/// width needs.
fn draw_legend<DB: DrawingBackend>(legend: &DrawingArea<DB, Shift>, width: u32) -> Result<()> {
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing failed: {e:?}");
    let entries = LEGEND.iter().filter(|l| !l.2.is_empty());
    for ((class, silent, text), (x, row)) in entries.zip(legend_layout(width)) {
        let y = 8 + (row * LEGEND_ROW_HEIGHT) as i32;
        legend
            .draw(&Rectangle::new(
                [(x, y), (x + 18, y + 18)],
                colour(*class, *silent).filled(),
            ))
            .map_err(error)?;
        legend
            .draw(&Text::new(
                text.to_string(),
                (x + 24, y + 2),
                ("sans-serif", 13).into_font(),
            ))
            .map_err(error)?;
    }
    Ok(())
}

fn cell_mark(cell: &Cell) -> (Class, bool, String) {
    let (class, silent) = cell.class();
    let text = match class {
        Class::NotYet => "·".into(),
        Class::Refused => "F".into(),
        Class::LostDefiniteness | Class::NonFinite if !silent => "F".into(),
        Class::Diverged => "DIV".into(),
        _ => compact(cell.ratio()),
    };
    (class, silent, text)
}

/// A ratio in at most four characters.
fn compact(ratio: f64) -> String {
    if !ratio.is_finite() {
        "–".into()
    } else if ratio >= 1000.0 {
        format!(
            "{:.0}e{}",
            ratio / 10f64.powi(ratio.log10().floor() as i32),
            ratio.log10().floor()
        )
    } else if ratio >= 10.0 {
        format!("{ratio:.0}")
    } else {
        format!("{ratio:.1}")
    }
}

/// Slice A's heat map at readout `r`: a panel per family and precision, SNR against order;
/// a family's f64 and f32 panels side by side, a row per family (two panels across stay
/// readable at a page's 800 px; ten across were 160 px each).
pub fn order_heat_map(slice: &SliceResult, r: usize) -> HeatMap {
    let families = distinct(slice.probes.iter().map(|p| p.family.clone()));
    let orders = slice.orders();
    let mut panels = Vec::new();
    for family in &families {
        for precision in [Precision::F64, Precision::F32] {
            let cells = slice
                .conditions
                .iter()
                .enumerate()
                .map(|(c, _)| {
                    orders
                        .iter()
                        .map(|&order| {
                            slice
                                .probe_at(family, order, precision)
                                .map(|p| cell_mark(&slice.cells[c][p][r]))
                                .unwrap_or((Class::NotYet, false, String::new()))
                        })
                        .collect()
                })
                .collect();
            panels.push(Panel {
                title: format!(
                    "{family}, {}",
                    if precision == Precision::F32 {
                        "f32"
                    } else {
                        "f64"
                    }
                ),
                x_labels: orders.iter().map(|o| o.to_string()).collect(),
                y_labels: slice
                    .conditions
                    .iter()
                    .map(|c| format!("{} dB", c.snr_db))
                    .collect(),
                x_name: "order n".into(),
                cells,
            });
        }
    }
    HeatMap {
        title: format!(
            "Stability map A: RMS at {} over the CRLB, white noise, reference drop ({} runs a cell; cell text: RMS/CRLB)",
            readout_name(r),
            slice.runs
        ),
        columns: 2,
        panels,
        panel_size: (600, 330),
        label_width: 55,
    }
}

/// Slices B and C: a panel per (readout, group of conditions), probes against the conditions.
pub fn probe_heat_map(
    slice: &SliceResult,
    title: &str,
    group: impl Fn(&Condition) -> String,
    x_label: impl Fn(&Condition) -> String,
    x_name: &str,
) -> HeatMap {
    let groups = distinct(slice.conditions.iter().map(&group));
    let mut panels = Vec::new();
    for r in 0..2 {
        for g in &groups {
            let members: Vec<usize> = (0..slice.conditions.len())
                .filter(|&c| group(&slice.conditions[c]) == *g)
                .collect();
            let cells = (0..slice.probes.len())
                .rev()
                .map(|p| {
                    members
                        .iter()
                        .map(|&c| cell_mark(&slice.cells[c][p][r]))
                        .collect()
                })
                .collect();
            panels.push(Panel {
                title: format!("{g}, at {}", readout_name(r)),
                x_labels: members
                    .iter()
                    .map(|&c| x_label(&slice.conditions[c]))
                    .collect(),
                y_labels: slice.probes.iter().rev().map(probe_label).collect(),
                x_name: x_name.into(),
                cells,
            });
        }
    }
    HeatMap {
        title: format!("{title} ({} runs a cell; cell text: RMS/CRLB)", slice.runs),
        // One panel across: each is read row by row against its probe labels.
        columns: 1,
        panels,
        panel_size: (760, 560),
        label_width: 230,
    }
}

/// The long runs' chart for block length `decimation`: RMS of error over the steady-state
/// bound per log-spaced bin, step and covariance forms, f64 and f32.
pub fn long_chart(long: &LongResult, decimation: u16) -> chart::Chart {
    let mut series = Vec::new();
    for run in &long.runs {
        let (family, d, lambda) = match run.probe.method {
            Method::Step(s) => ("step", s.decimation, s.forgetting),
            Method::Covariance { setup, .. } => ("covariance", setup.decimation, setup.forgetting),
            _ => continue,
        };
        if d != decimation || lambda == 0.999 {
            continue;
        }
        let points = run
            .bins
            .iter()
            .enumerate()
            .filter(|(_, b)| b.valid > 0)
            .map(|(i, b)| {
                (
                    f64::from(FIRST_DECADE) + (i as f64 + 0.5) / BINS_PER_DECADE as f64,
                    b.normalised_rms(),
                )
            })
            .collect();
        series.push(chart::Series {
            name: format!(
                "{family} λ={lambda} {}{}",
                precision_name(&run.probe.method),
                match run.first_flag {
                    Some((at, InvalidReason::LostDefiniteness)) =>
                        format!(": flagged lost PD at {at}"),
                    _ => String::new(),
                }
            ),
            points,
            reference: false,
        });
    }
    let last = (long.samples as f64).log10();
    series.push(chart::Series {
        name: "10× the bound".into(),
        points: vec![(f64::from(FIRST_DECADE), 10.0), (last, 10.0)],
        reference: true,
    });
    chart::Chart {
        title: format!(
            "Stability map D: a steady 138.32 g at 50 dB, n = 7, D = {decimation}, one run of {:.0e} samples",
            long.samples as f64
        ),
        x_label: "log10(samples since the drop) (4 kHz)".into(),
        y_label: "RMS error / steady-state bound, per bin".into(),
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_silent_failure_never_shares_a_colour_with_a_flagged_one() {
        let failures = [Class::LostDefiniteness, Class::NonFinite, Class::Diverged];
        for class in failures {
            assert_ne!(colour(class, true), colour(class, false), "{class:?}");
        }
        assert_ne!(colour(Class::OverBound, true), colour(Class::Ok, false));
        assert_eq!(LEGEND.iter().filter(|l| !l.2.is_empty()).count(), 7);
    }

    #[test]
    fn cell_marks_fit_in_four_characters() {
        assert_eq!(compact(0.94), "0.9");
        assert_eq!(compact(12.4), "12");
        assert_eq!(compact(2345.0), "2e3");
        assert_eq!(compact(f64::INFINITY), "–");
        let refused = Cell {
            runs: 2,
            flagged: [2, 0, 0, 0, 0, 0, 0, 0, 0],
            ..Cell::default()
        };
        assert_eq!(cell_mark(&refused), (Class::Refused, false, "F".into()));
        let labels = ["a".to_string(), "b".to_string()];
        assert_eq!(segment_label(&labels, &SegmentValue::CenterOf(1)), "b");
        assert_eq!(segment_label(&labels, &SegmentValue::Exact(1)), "");
    }
}
