//! Recordings as users bring them: one raw sample a row in a CSV, with or without a UTF-8
//! BOM, separated by `,`, `;` or tabs (found from the first line), headers quoted or not, the
//! sample column chosen by its header name (default `y`, as `simulate` writes it) or, in a
//! file without a header, by its 0-based index. Every command that reads a recording
//! (`estimate`, `replay`, `calibrate`) reads it here, so they all take the same files.
//!
//! What it must never do: skip a bad row, guess a column, or panic on a file. A problem is a
//! [`RecordingError`] naming the file, the line and what was expected there. An empty cell
//! is a lost sample ([`Row::sample`] is `None`); `NaN` and `inf` parse as numbers and are
//! passed on, for the command to flag or refuse as it does any non-finite sample.

pub mod console;
mod error;
mod separator;
#[cfg(test)]
mod tests;

use std::path::Path;

use csv::StringRecord;

pub use error::{Problem, RecordingError};

/// The sample column of a file with a header, unless told otherwise.
pub const DEFAULT_COLUMN: &str = "y";

const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// Where a recording's samples are.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    /// The sample column: its name in the header (default [`DEFAULT_COLUMN`]), or with
    /// `no_header` its 0-based index (default: the only column).
    pub column: Option<String>,
    /// The file has no header: every row holds samples.
    pub no_header: bool,
}

/// One row of samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Its line in the file, from 1.
    pub line: u64,
    /// The sample; `None` for an empty cell (a lost sample).
    pub sample: Option<f64>,
}

/// A recording read: the sample column of every row, in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// The file as the user named it.
    pub file: String,
    /// The sample column as the user names it (`` `y` ``, or an index without a header).
    pub column: String,
    /// The rows, blank lines passed over.
    pub rows: Vec<Row>,
}

impl Recording {
    /// Every sample, for a command that needs each one: an empty cell is an error naming
    /// its line.
    pub fn every_sample(&self) -> Result<Vec<f64>, RecordingError> {
        self.rows
            .iter()
            .map(|row| {
                row.sample.ok_or_else(|| RecordingError {
                    file: self.file.clone(),
                    problem: Problem::EmptyCell {
                        line: row.line,
                        column: self.column.clone(),
                    },
                })
            })
            .collect()
    }
}

/// Read the recording at `path` laid out as `layout`.
pub fn read(path: &Path, layout: &Layout) -> Result<Recording, RecordingError> {
    let file = path.display().to_string();
    match std::fs::read(path) {
        Ok(bytes) => parse(&bytes, &file, layout),
        Err(error) => Err(RecordingError {
            file,
            problem: Problem::Unreadable {
                reason: error.to_string(),
            },
        }),
    }
}

/// Parse the bytes of a recording; `file` names it in errors.
pub fn parse(bytes: &[u8], file: &str, layout: &Layout) -> Result<Recording, RecordingError> {
    let fail = |problem| RecordingError {
        file: file.to_string(),
        problem,
    };
    let text = bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes);
    let reader = csv::ReaderBuilder::new()
        .delimiter(separator::sniff(text))
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text);
    let mut records = reader
        .into_records()
        .filter(|record| !record.as_ref().is_ok_and(is_blank));
    let first = match records.next() {
        Some(record) => record.map_err(|e| fail(reader_problem(&e, text)))?,
        None => {
            return Err(fail(Problem::Empty {
                expected: expected_first_line(layout),
            }))
        }
    };
    let header_line = line_at(first.position(), text);
    let (index, column) = locate(&first, header_line, layout).map_err(fail)?;
    let first_is_data = layout.no_header.then_some(Ok(first));
    let mut rows = Vec::new();
    for record in first_is_data.into_iter().chain(records) {
        let record = record.map_err(|e| fail(reader_problem(&e, text)))?;
        let line = line_at(record.position(), text);
        rows.push(row(&record, line, index, &column).map_err(fail)?);
    }
    Ok(Recording {
        file: file.to_string(),
        column,
        rows,
    })
}

/// A line of nothing but spaces (the reader passes over empty lines itself).
fn is_blank(record: &StringRecord) -> bool {
    record.len() == 1 && record[0].is_empty()
}

/// The line a record (or an error) is on in `text`, counting `\n`, `\r\n` and a lone `\r`
/// each as one line end (the reader ends records at all three; counting `\n` alone gave
/// every row of a file with old Mac line ends line 1, found by tests/reader_fuzz.rs). The
/// reader's position is where it began reading, before the empty lines it passed over, so
/// those are counted here.
fn line_at(position: Option<&csv::Position>, text: &[u8]) -> u64 {
    let Some(position) = position else { return 0 };
    let mut at = usize::try_from(position.byte()).map_or(text.len(), |byte| byte.min(text.len()));
    while at < text.len() && (text[at] == b'\n' || text[at] == b'\r') {
        at += 1;
    }
    let before = &text[..at];
    let line_ends = before
        .iter()
        .enumerate()
        .filter(|&(i, &byte)| byte == b'\n' || (byte == b'\r' && before.get(i + 1) != Some(&b'\n')))
        .count();
    1 + line_ends as u64
}

fn expected_first_line(layout: &Layout) -> String {
    if layout.no_header {
        "a line of samples".to_string()
    } else {
        let column = layout.column.as_deref().unwrap_or(DEFAULT_COLUMN);
        format!("a header naming a column `{column}`")
    }
}

/// The sample column's index and its name for messages, from the first line (`line`).
fn locate(first: &StringRecord, line: u64, layout: &Layout) -> Result<(usize, String), Problem> {
    if !layout.no_header {
        let wanted = layout.column.as_deref().unwrap_or(DEFAULT_COLUMN);
        let index = first
            .iter()
            .position(|name| name == wanted)
            .ok_or_else(|| Problem::UnknownColumn {
                line,
                wanted: wanted.to_string(),
                found: first.iter().map(str::to_string).collect(),
            })?;
        return Ok((index, format!("`{wanted}`")));
    }
    let index = match &layout.column {
        Some(given) => given
            .parse::<usize>()
            .map_err(|_| Problem::ColumnNotAnIndex {
                given: given.clone(),
            })?,
        None if first.len() == 1 => 0,
        None => {
            return Err(Problem::SeveralColumns {
                line,
                fields: first.len(),
            })
        }
    };
    if index >= first.len() {
        return Err(Problem::IndexBeyondLine {
            line,
            index,
            fields: first.len(),
        });
    }
    Ok((index, index.to_string()))
}

/// The sample of one record; a row too short for the column has an empty cell.
fn row(record: &StringRecord, line: u64, index: usize, column: &str) -> Result<Row, Problem> {
    let cell = record.get(index).unwrap_or("");
    if cell.is_empty() {
        return Ok(Row { line, sample: None });
    }
    match cell.parse::<f64>() {
        Ok(sample) => Ok(Row {
            line,
            sample: Some(sample),
        }),
        Err(_) => Err(Problem::NotANumber {
            line,
            column: column.to_string(),
            value: cell.to_string(),
        }),
    }
}

/// The CSV reader's error as a problem on its line of `text`.
fn reader_problem(error: &csv::Error, text: &[u8]) -> Problem {
    let line = line_at(error.position(), text);
    match error.kind() {
        csv::ErrorKind::Utf8 { .. } => Problem::NotText { line },
        _ => Problem::Malformed {
            line,
            reason: error.to_string(),
        },
    }
}
