//! `host-sim monitor`: a live view of a weighing board. Reads lines (the console, the
//! firmware's log through probe-rs or QEMU, or `host-sim replay`'s CSV), shows the latest
//! reading and a terminal plot of mass with its ±2u band, and logs every reading as CSV
//! `t_s,mass_g,u_g,state,final`.
//!
//! Interactive on a terminal; without one (a pipe, CI) it takes the whole input and prints
//! the last frame as text, so the same view can be checked and quoted.

pub mod parse;
pub mod view;

use std::io::Write;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

use anyhow::Result;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{self, Event, KeyCode};
use ratatui::Terminal;

use parse::{parse_line, MonitorReading};
use view::History;

/// How the monitor runs.
#[derive(Clone, Debug)]
pub struct MonitorSettings {
    /// Seconds of readings on the plot.
    pub window_s: f64,
    /// The sample rate that times the firmware's log lines, Hz.
    pub sample_rate_hz: f64,
    /// Draw on the terminal (else print the last frame as text).
    pub interactive: bool,
    /// Size of the text frame: columns, rows.
    pub text_size: (u16, u16),
}

/// The CSV row of a reading.
pub fn csv_row(reading: &MonitorReading) -> String {
    let value = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
    format!(
        "{},{},{},{},{}",
        reading.t_s,
        value(reading.mass_g),
        value(reading.u_g),
        reading.state,
        u8::from(reading.is_final)
    )
}

/// Take one line: a reading goes on the plot and into the CSV.
fn take(
    line: &str,
    settings: &MonitorSettings,
    history: &mut History,
    csv: &mut Option<Box<dyn Write>>,
) -> Result<()> {
    match parse_line(line, settings.sample_rate_hz) {
        Some(reading) => {
            if let Some(out) = csv.as_mut() {
                writeln!(out, "{}", csv_row(&reading))?;
            }
            history.readings.push(reading);
        }
        None => history.other_lines += 1,
    }
    Ok(())
}

/// Run the monitor on the lines arriving on `lines` until they end (and, interactive, until
/// `q`). Returns what it saw.
pub fn run(
    lines: Receiver<String>,
    settings: &MonitorSettings,
    mut csv: Option<Box<dyn Write>>,
    csv_name: Option<String>,
) -> Result<History> {
    let mut history = History {
        csv: csv_name,
        ..History::default()
    };
    if let Some(out) = csv.as_mut() {
        writeln!(out, "t_s,mass_g,u_g,state,final")?;
    }
    if !settings.interactive {
        for line in lines {
            take(&line, settings, &mut history, &mut csv)?;
        }
        history.ended = true;
        if let Some(out) = csv.as_mut() {
            out.flush()?;
        }
        return Ok(history);
    }
    let mut terminal = ratatui::init();
    let result = (|| -> Result<()> {
        loop {
            match lines.recv_timeout(Duration::from_millis(40)) {
                Ok(line) => {
                    take(&line, settings, &mut history, &mut csv)?;
                    while let Ok(line) = lines.try_recv() {
                        take(&line, settings, &mut history, &mut csv)?;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => history.ended = true,
                Err(RecvTimeoutError::Timeout) => {}
            }
            terminal.draw(|frame| view::draw(frame, frame.area(), &history, settings.window_s))?;
            if event::poll(Duration::from_millis(0))? {
                if let Event::Key(key) = event::read()? {
                    if matches!(key.code, KeyCode::Char('q') | KeyCode::Esc) {
                        return Ok(());
                    }
                }
            }
            if history.ended {
                std::thread::sleep(Duration::from_millis(40));
            }
        }
    })();
    ratatui::restore();
    if let Some(out) = csv.as_mut() {
        out.flush()?;
    }
    result.map(|()| history)
}

/// The monitor's frame for `history` as text, `size` columns by rows.
pub fn text_frame(history: &History, window_s: f64, size: (u16, u16)) -> Result<String> {
    let mut terminal = Terminal::new(TestBackend::new(size.0, size.1))?;
    terminal.draw(|frame| view::draw(frame, frame.area(), history, window_s))?;
    let buffer = terminal.backend().buffer();
    let mut text = String::new();
    for y in 0..size.1 {
        let mut row = String::new();
        for x in 0..size.0 {
            row.push_str(buffer[(x, y)].symbol());
        }
        text.push_str(row.trim_end());
        text.push('\n');
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replayed_demo_is_plotted_and_logged() {
        let (sender, receiver) = std::sync::mpsc::channel();
        for line in [
            "config method=step n=5 D=24",
            "readout sample=1400 mass_g=none state=Estimating since=200 dropped=0 changes=1",
            "readout sample=1600 mass_g=138.30377 state=Estimating since=400 dropped=0 changes=1",
            "readout sample=1800 mass_g=138.32162 state=Stable since=600 dropped=0 changes=1",
        ] {
            sender.send(line.to_string()).unwrap();
        }
        drop(sender);
        let csv = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u8>::new()));
        struct Shared(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);
        impl Write for Shared {
            fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(bytes);
                Ok(bytes.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let settings = MonitorSettings {
            window_s: 5.0,
            sample_rate_hz: 4000.0,
            interactive: false,
            text_size: (80, 20),
        };
        let history = run(
            receiver,
            &settings,
            Some(Box::new(Shared(csv.clone()))),
            Some("m.csv".into()),
        )
        .unwrap();
        assert_eq!((history.readings.len(), history.other_lines), (3, 1));
        let logged = String::from_utf8(csv.lock().unwrap().clone()).unwrap();
        assert_eq!(
            logged,
            "t_s,mass_g,u_g,state,final\n0.35,,,estimating,0\n0.4,138.30377,,estimating,0\n0.45,138.32162,,stable,0\n"
        );
        let frame = text_frame(&history, 5.0, (80, 20)).unwrap();
        assert!(frame.contains("138.322 g"), "{frame}");
        assert!(frame.contains("stable"), "{frame}");
        assert!(
            frame.contains("3 readings, 1 other lines, CSV: m.csv, input ended"),
            "{frame}"
        );
    }
}
