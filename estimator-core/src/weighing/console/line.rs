//! Bytes in, lines out: the console's receive buffer.

/// The longest line the console takes, bytes (without its end).
pub const MAX_LINE: usize = 64;

/// What a completed line holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineEnd<'a> {
    /// The line's bytes (without CR/LF).
    Line(&'a [u8]),
    /// The line was longer than [`MAX_LINE`]: its bytes are gone, the next line starts
    /// clean.
    TooLong,
}

/// Collects received bytes into lines. CR, LF or CR LF end a line (an empty line is
/// skipped, so CR LF counts once); backspace and DEL take back a byte; a line longer than
/// [`MAX_LINE`] is reported once as too long when it ends, never cut and half-executed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LineBuffer {
    bytes: [u8; MAX_LINE],
    len: usize,
    overflowed: bool,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            bytes: [0; MAX_LINE],
            len: 0,
            overflowed: false,
        }
    }

    /// Take one received byte; `Some` when it ended a non-empty line.
    pub fn push(&mut self, byte: u8) -> Option<LineEnd<'_>> {
        match byte {
            b'\r' | b'\n' => {
                let len = core::mem::take(&mut self.len);
                if core::mem::take(&mut self.overflowed) {
                    return Some(LineEnd::TooLong);
                }
                if len == 0 {
                    return None;
                }
                self.bytes.get(..len).map(LineEnd::Line)
            }
            0x08 | 0x7f => {
                self.len = self.len.saturating_sub(1);
                None
            }
            _ => {
                match self.bytes.get_mut(self.len) {
                    Some(slot) if !self.overflowed => {
                        *slot = byte;
                        self.len += 1;
                    }
                    _ => self.overflowed = true,
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(input: &[u8]) -> ([Option<(usize, bool)>; 4], usize) {
        let mut buffer = LineBuffer::new();
        let mut found = [None; 4];
        let mut count = 0;
        for &byte in input {
            if let Some(end) = buffer.push(byte) {
                if let Some(slot) = found.get_mut(count) {
                    *slot = Some(match end {
                        LineEnd::Line(bytes) => (bytes.len(), false),
                        LineEnd::TooLong => (0, true),
                    });
                }
                count += 1;
            }
        }
        (found, count)
    }

    #[test]
    fn cr_lf_and_crlf_end_one_line_each_and_backspace_takes_back() {
        let (found, count) = lines(b"tare\r\ncal 200\nunit kg\rab\x08c\n");
        assert_eq!(count, 4);
        assert_eq!(found[0], Some((4, false)));
        assert_eq!(found[1], Some((7, false)));
        assert_eq!(found[3], Some((2, false)));
        let mut buffer = LineBuffer::new();
        for &byte in b"ab\x7fc" {
            assert_eq!(buffer.push(byte), None);
        }
        assert_eq!(buffer.push(b'\n'), Some(LineEnd::Line(b"ac")));
    }

    #[test]
    fn an_overlong_line_is_reported_once_and_the_next_starts_clean() {
        let mut input = [b'x'; MAX_LINE + 10];
        input[MAX_LINE + 9] = b'\n';
        let mut buffer = LineBuffer::new();
        let mut ends = 0;
        for &byte in &input {
            if let Some(end) = buffer.push(byte) {
                assert_eq!(end, LineEnd::TooLong);
                ends += 1;
            }
        }
        assert_eq!(ends, 1);
        for &byte in b"tare" {
            buffer.push(byte);
        }
        assert_eq!(buffer.push(b'\r'), Some(LineEnd::Line(b"tare")));
        // Exactly MAX_LINE bytes still fit.
        for _ in 0..MAX_LINE {
            buffer.push(b'y');
        }
        assert!(matches!(buffer.push(b'\n'), Some(LineEnd::Line(l)) if l.len() == MAX_LINE));
    }
}
