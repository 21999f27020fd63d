//! What can be wrong with a recording, as a value: each problem names its line and what was
//! expected there, so a user can open the file and fix it.

use std::fmt;

/// A recording that cannot be read as asked, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingError {
    /// The file as the user named it.
    pub file: String,
    /// What is wrong.
    pub problem: Problem,
}

/// What is wrong with a recording. Lines are counted from 1, as an editor shows them.
#[derive(Clone, Debug, PartialEq)]
pub enum Problem {
    /// The file could not be read at all.
    Unreadable {
        /// The system's reason.
        reason: String,
    },
    /// No line holds anything.
    Empty {
        /// What the first line should have been.
        expected: String,
    },
    /// A line is not UTF-8 text.
    NotText {
        /// Its line.
        line: u64,
    },
    /// The CSV reader refused a line (e.g. a quote never closed).
    Malformed {
        /// Its line.
        line: u64,
        /// The reader's reason.
        reason: String,
    },
    /// The header has no column of the asked name.
    UnknownColumn {
        /// The header's line.
        line: u64,
        /// The name asked for.
        wanted: String,
        /// The columns the header names.
        found: Vec<String>,
    },
    /// Without a header a column is chosen by its 0-based index, and this is none.
    ColumnNotAnIndex {
        /// What was given.
        given: String,
    },
    /// The chosen column index is beyond the first line's fields.
    IndexBeyondLine {
        /// The first line.
        line: u64,
        /// The index asked for.
        index: usize,
        /// Fields on that line.
        fields: usize,
    },
    /// No header, several fields a line and no column chosen: which one holds the samples
    /// is not for us to guess.
    SeveralColumns {
        /// The first line.
        line: u64,
        /// Fields on it.
        fields: usize,
    },
    /// A cell that is not a number.
    NotANumber {
        /// Its line.
        line: u64,
        /// Its column, as the user names it (`` `y` `` or an index).
        column: String,
        /// What the cell holds.
        value: String,
    },
    /// An empty cell (a lost sample) where every sample is needed.
    EmptyCell {
        /// Its line.
        line: u64,
        /// Its column.
        column: String,
    },
}

impl fmt::Display for RecordingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = &self.file;
        match &self.problem {
            Problem::Unreadable { reason } => write!(f, "cannot read {file}: {reason}"),
            Problem::Empty { expected } => write!(f, "{file}: empty file, expected {expected}"),
            Problem::NotText { line } => write!(f, "{file}: line {line}: not UTF-8 text"),
            Problem::Malformed { line, reason } => write!(f, "{file}: line {line}: {reason}"),
            Problem::UnknownColumn {
                line,
                wanted,
                found,
            } => {
                let names: Vec<String> = found.iter().map(|name| format!("`{name}`")).collect();
                write!(
                    f,
                    "{file}: line {line}: expected a column `{wanted}` in the header, found the columns {} (--column NAME chooses one",
                    names.join(", ")
                )?;
                if found.iter().all(|name| name.parse::<f64>().is_ok()) {
                    // A file of bare numbers read as if its first line were a header.
                    write!(f, "; a file without a header needs --no-header")?;
                }
                write!(f, ")")
            }
            Problem::ColumnNotAnIndex { given } => write!(
                f,
                "{file}: without a header the column is a 0-based index, found `{given}`"
            ),
            Problem::IndexBeyondLine {
                line,
                index,
                fields,
            } => write!(
                f,
                "{file}: line {line}: expected a column {index} (0-based), found {fields} fields"
            ),
            Problem::SeveralColumns { line, fields } => write!(
                f,
                "{file}: line {line}: {fields} fields and no header: expected --column INDEX (0-based) to choose the samples"
            ),
            Problem::NotANumber {
                line,
                column,
                value,
            } => write!(
                f,
                "{file}: line {line}: column {column}: expected a number, found `{value}`"
            ),
            Problem::EmptyCell { line, column } => write!(
                f,
                "{file}: line {line}: column {column}: expected a number (every sample is needed here), found an empty cell"
            ),
        }
    }
}

impl std::error::Error for RecordingError {}
