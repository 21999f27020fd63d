//! Recordings a board wrote on its serial console (`record`): `RECORD begin samples=N
//! before=B rate_hz=R`, then `D <index> <code>…` lines (`L` a lost sample, `S` a saturated
//! one), then `RECORD end samples=N lost=… saturated=…`, with reading and answer lines
//! anywhere between them. [`unpack`] turns a transcript into recordings and
//! [`ConsoleRecording::to_csv`] into the CSV every host command reads (`t,y`, an empty `y` for a
//! sample the board did not have), so `host-sim records` hands `calibrate` and `replay`
//! exactly what the board saw.
//!
//! What it must never do: pass on a recording with a gap, a repeated or a missing sample,
//! or one the transcript cut short (a port that dropped bytes): each is an error naming
//! the transcript line. A recording the board abandoned (`RECORD abandoned`: its port
//! dropped part of a line) is passed over.

use std::fmt::{self, Write as _};

/// One recording from a board's console.
#[derive(Clone, Debug, PartialEq)]
pub struct ConsoleRecording {
    /// The raw codes in time order; `None` for a lost or saturated sample.
    pub samples: Vec<Option<i64>>,
    /// Samples before the load change the board detected.
    pub before: usize,
    /// The board's sample rate, Hz.
    pub rate_hz: u32,
    /// Lost samples, as the board counted them.
    pub lost: usize,
    /// Saturated samples, as the board counted them.
    pub saturated: usize,
}

impl ConsoleRecording {
    /// The recording as CSV `t,y` (t in s from its first sample, y the code).
    pub fn to_csv(&self) -> String {
        let mut text = String::from("t,y\n");
        for (index, sample) in self.samples.iter().enumerate() {
            let t = index as f64 / f64::from(self.rate_hz);
            let _ = match sample {
                Some(code) => writeln!(text, "{t:.6},{code}"),
                None => writeln!(text, "{t:.6},"),
            };
        }
        text
    }
}

/// Why a transcript's recording was refused: its line (from 1) and what was wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnpackError {
    /// The transcript line.
    pub line: usize,
    /// What was expected there.
    pub problem: String,
}

impl fmt::Display for UnpackError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.problem)
    }
}

impl std::error::Error for UnpackError {}

/// A recording being read.
struct Open {
    begin_line: usize,
    len: usize,
    before: usize,
    rate_hz: u32,
    samples: Vec<Option<i64>>,
    lost: usize,
    saturated: usize,
}

/// Every complete recording in `transcript` (a board's console lines), in order.
pub fn unpack<'a>(
    transcript: impl IntoIterator<Item = &'a str>,
) -> Result<Vec<ConsoleRecording>, UnpackError> {
    let mut done = Vec::new();
    let mut open: Option<Open> = None;
    let mut last_line = 0;
    for (index, line) in transcript.into_iter().enumerate() {
        let number = index + 1;
        last_line = number;
        let fail = |problem: String| UnpackError {
            line: number,
            problem,
        };
        let line = line.trim_end();
        if let Some(rest) = line.strip_prefix("RECORD begin ") {
            if let Some(open) = &open {
                return Err(fail(format!(
                    "a recording begins before the one from line {} ended (RECORD end expected)",
                    open.begin_line
                )));
            }
            let len = field(rest, "samples").ok_or_else(|| fail(BEGIN.into()))?;
            let before = field(rest, "before").ok_or_else(|| fail(BEGIN.into()))?;
            let rate_hz = field(rest, "rate_hz")
                .and_then(|rate| u32::try_from(rate).ok())
                .filter(|rate| *rate > 0)
                .ok_or_else(|| fail(BEGIN.into()))?;
            if before > len {
                return Err(fail(format!("before={before} is more than samples={len}")));
            }
            open = Some(Open {
                begin_line: number,
                len,
                before,
                rate_hz,
                samples: Vec::with_capacity(len),
                lost: 0,
                saturated: 0,
            });
        } else if let Some(rest) = line.strip_prefix("D ") {
            let Some(open) = open.as_mut() else {
                return Err(fail(
                    "a D line outside a recording (RECORD begin expected first)".into(),
                ));
            };
            read_samples(rest, open).map_err(fail)?;
        } else if line.starts_with("RECORD abandoned") {
            // The board gave the recording up (its port dropped bytes); it says so, and
            // what came of it is not a recording.
            open = None;
        } else if let Some(rest) = line.strip_prefix("RECORD end ") {
            let Some(finished) = open.take() else {
                return Err(fail("RECORD end without RECORD begin".into()));
            };
            let expected = (
                field(rest, "samples"),
                field(rest, "lost"),
                field(rest, "saturated"),
            );
            let found = (
                Some(finished.samples.len()),
                Some(finished.lost),
                Some(finished.saturated),
            );
            if finished.samples.len() != finished.len || expected != found {
                return Err(fail(format!(
                    "the recording from line {} holds {} samples ({} lost, {} saturated); its begin said {} and its end `{rest}`: bytes were lost on the way",
                    finished.begin_line,
                    finished.samples.len(),
                    finished.lost,
                    finished.saturated,
                    finished.len
                )));
            }
            done.push(ConsoleRecording {
                samples: finished.samples,
                before: finished.before,
                rate_hz: finished.rate_hz,
                lost: finished.lost,
                saturated: finished.saturated,
            });
        }
    }
    if let Some(open) = open {
        return Err(UnpackError {
            line: last_line,
            problem: format!(
                "the recording from line {} never ended (RECORD end expected)",
                open.begin_line
            ),
        });
    }
    Ok(done)
}

const BEGIN: &str = "RECORD begin samples=<n> before=<n> rate_hz=<Hz>";

/// `key=<whole number>` among the words of `text`.
fn field(text: &str, key: &str) -> Option<usize> {
    text.split_whitespace()
        .find_map(|word| word.strip_prefix(key)?.strip_prefix('='))
        .and_then(|value| value.parse().ok())
}

/// A `D <index> <code>…` line's samples, which must continue the recording exactly.
fn read_samples(rest: &str, open: &mut Open) -> Result<(), String> {
    let mut words = rest.split_whitespace();
    let index: usize = words
        .next()
        .and_then(|word| word.parse().ok())
        .ok_or("D <index> <code>… expected")?;
    if index != open.samples.len() {
        return Err(format!(
            "D line from sample {index}, expected {} (a line was lost or repeated)",
            open.samples.len()
        ));
    }
    for word in words {
        let sample = match word {
            "L" => {
                open.lost += 1;
                None
            }
            "S" => {
                open.saturated += 1;
                None
            }
            code => Some(
                code.parse::<i64>()
                    .map_err(|_| format!("`{code}` is no code (a whole number, L or S)"))?,
            ),
        };
        open.samples.push(sample);
    }
    if open.samples.len() > open.len {
        return Err(format!(
            "{} samples, more than the {} its begin said",
            open.samples.len(),
            open.len
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRANSCRIPT: &str = "# fast-weighing console: type help
OK record armed; the next load change is recorded (5 samples, 1 before it)
R t=1.00 mass=0.0 u=0.1 unit=g state=empty final=0
RECORD begin samples=5 before=1 rate_hz=4000
D 0 100 101 L
R t=1.05 mass=- u=- unit=g state=estimating final=0
D 3 9000 S
RECORD end samples=5 lost=1 saturated=1
";

    #[test]
    fn a_recording_is_unpacked_with_its_gaps_marked() {
        let recordings = unpack(TRANSCRIPT.lines()).unwrap();
        assert_eq!(
            recordings,
            [ConsoleRecording {
                samples: vec![Some(100), Some(101), None, Some(9000), None],
                before: 1,
                rate_hz: 4000,
                lost: 1,
                saturated: 1,
            }]
        );
        assert_eq!(
            recordings[0].to_csv(),
            "t,y\n0.000000,100\n0.000250,101\n0.000500,\n0.000750,9000\n0.001000,\n"
        );
    }

    /// A transcript that lost a line, repeated one, lost its end or garbled a code is
    /// refused at the line where it shows.
    #[test]
    fn a_damaged_transcript_is_refused_at_its_line() {
        let refused = |text: &str| unpack(text.lines()).unwrap_err();
        let lost_line = TRANSCRIPT.replace("D 0 100 101 L\n", "");
        assert_eq!(refused(&lost_line).line, 6);
        let repeated = TRANSCRIPT.replace("D 3 9000 S\n", "D 0 100 101 L\nD 3 9000 S\n");
        assert_eq!(refused(&repeated).line, 7);
        let cut = TRANSCRIPT.replace("RECORD end samples=5 lost=1 saturated=1\n", "");
        assert!(refused(&cut).problem.contains("never ended"));
        let garbled = TRANSCRIPT.replace("9000", "9O00");
        assert!(refused(&garbled).problem.contains("9O00"));
        let miscounted = TRANSCRIPT.replace("lost=1 saturated=1", "lost=0 saturated=1");
        assert!(refused(&miscounted).problem.contains("bytes were lost"));
        assert!(unpack("nothing here\n".lines()).unwrap().is_empty());
        let abandoned = TRANSCRIPT.replace(
            "D 3 9000 S\n",
            "D 3 90\nRECORD abandoned (the port dropped bytes; type record again)\n",
        );
        let abandoned = abandoned.replace("RECORD end samples=5 lost=1 saturated=1\n", "");
        assert_eq!(unpack(abandoned.lines()), Ok(Vec::new()));
    }
}
