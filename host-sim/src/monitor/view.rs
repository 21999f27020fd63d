//! What the monitor draws: the latest reading, and mass with its ±2u band over the last
//! seconds.

use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph};
use ratatui::Frame;

use super::parse::MonitorReading;

/// What the monitor has seen.
#[derive(Clone, Debug, Default)]
pub struct History {
    /// Readings, oldest first (only the window is drawn).
    pub readings: Vec<MonitorReading>,
    /// Lines that carried no reading.
    pub other_lines: u64,
    /// The input has ended.
    pub ended: bool,
    /// Where the CSV goes, if anywhere.
    pub csv: Option<String>,
}

/// The points of one series over the window: (t, value).
type Points = Vec<(f64, f64)>;

/// Mass, mass + 2u and mass − 2u over the last `window_s`, and the axes' bounds.
fn series(history: &History, window_s: f64) -> (Points, Points, Points, [f64; 2], [f64; 2]) {
    let end = history.readings.last().map_or(0.0, |r| r.t_s);
    let start = (end - window_s).max(0.0);
    let (mut mass, mut high, mut low) = (Vec::new(), Vec::new(), Vec::new());
    for reading in history.readings.iter().filter(|r| r.t_s >= start) {
        let Some(m) = reading.mass_g else { continue };
        mass.push((reading.t_s, m));
        if let Some(u) = reading.u_g {
            high.push((reading.t_s, m + 2.0 * u));
            low.push((reading.t_s, m - 2.0 * u));
        }
    }
    let values = mass.iter().chain(&high).chain(&low).map(|p| p.1);
    let (min, max) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let y = if min.is_finite() {
        let margin = ((max - min) * 0.1).max(0.05);
        [min - margin, max + margin]
    } else {
        [0.0, 1.0]
    };
    (
        mass,
        high,
        low,
        [start, start.max(end).max(start + 1e-3)],
        y,
    )
}

/// The latest reading as the headline.
fn headline(history: &History) -> Line<'static> {
    let Some(last) = history.readings.last() else {
        return Line::from("waiting for readings…");
    };
    let mass = last
        .mass_g
        .map_or("---".to_string(), |m| format!("{m:.3} g"));
    let u = last
        .u_g
        .map_or(String::new(), |u| format!("  ±{:.3} g (2u)", 2.0 * u));
    let colour = match last.state.as_str() {
        "stable" | "empty" => Color::Green,
        "estimating" => Color::Yellow,
        _ => Color::Red,
    };
    Line::from(vec![
        Span::styled(mass, Style::default().add_modifier(Modifier::BOLD)),
        Span::raw(u),
        Span::raw("  "),
        Span::styled(last.state.clone(), Style::default().fg(colour)),
        Span::raw(if last.is_final { "  FINAL" } else { "" }),
        Span::raw(format!("  t={:.2} s", last.t_s)),
    ])
}

/// Draw the monitor into `area` of `frame`.
pub fn draw(frame: &mut Frame<'_>, area: Rect, history: &History, window_s: f64) {
    let parts = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(3),
            Constraint::Min(8),
            Constraint::Length(1),
        ])
        .split(area);
    frame.render_widget(
        Paragraph::new(headline(history))
            .block(Block::default().borders(Borders::ALL).title(" reading ")),
        parts[0],
    );
    let (mass, high, low, x, y) = series(history, window_s);
    let band = Style::default().fg(Color::DarkGray);
    let mass_style = Style::default().fg(Color::Cyan);
    // Only series with points get a legend entry.
    let datasets: Vec<Dataset<'_>> = [
        ("mass + 2u", &high, band),
        ("mass − 2u", &low, band),
        ("mass, g", &mass, mass_style),
    ]
    .into_iter()
    .filter(|(_, points, _)| !points.is_empty())
    .map(|(name, points, style)| {
        Dataset::default()
            .name(name)
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(style)
            .data(points)
    })
    .collect();
    let label = |v: f64| Span::raw(format!("{v:.2}"));
    let chart = Chart::new(datasets)
        .block(
            Block::default()
                .borders(Borders::ALL)
                .title(format!(" mass over the last {window_s} s ")),
        )
        .x_axis(Axis::default().title("t, s").bounds(x).labels([
            label(x[0]),
            label(0.5 * (x[0] + x[1])),
            label(x[1]),
        ]))
        .y_axis(Axis::default().title("g").bounds(y).labels([
            label(y[0]),
            label(0.5 * (y[0] + y[1])),
            label(y[1]),
        ]));
    frame.render_widget(chart, parts[1]);
    let status = format!(
        "{} readings, {} other lines{}{}  (q quits)",
        history.readings.len(),
        history.other_lines,
        history
            .csv
            .as_ref()
            .map_or(String::new(), |path| format!(", CSV: {path}")),
        if history.ended { ", input ended" } else { "" },
    );
    frame.render_widget(Paragraph::new(status), parts[2]);
}
