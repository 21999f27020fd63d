//! Which separator a recording uses, found from its first line: spreadsheets write `,`,
//! `;` (where the comma is the decimal mark) or tabs, and users should not have to say which.

/// The separators taken, in the order they win: a tab or a `;` on the first line means the
/// file is not comma-separated (in `;` files a comma is the decimal mark), so they go first.
const SEPARATORS: [u8; 3] = [b'\t', b';', b','];

/// The separator of the first non-blank line of `text` (outside double quotes, so a quoted
/// header may hold any of them); `,` when the line has none (a single column).
pub fn sniff(text: &[u8]) -> u8 {
    let first_line = text
        .split(|&byte| byte == b'\n')
        .find(|line| line.iter().any(|byte| !byte.is_ascii_whitespace()))
        .unwrap_or(&[]);
    let outside_quotes = unquoted(first_line);
    SEPARATORS
        .into_iter()
        .find(|separator| outside_quotes.contains(separator))
        .unwrap_or(b',')
}

/// The bytes of `line` outside double-quoted stretches.
fn unquoted(line: &[u8]) -> Vec<u8> {
    let mut quoted = false;
    let mut outside = Vec::with_capacity(line.len());
    for &byte in line {
        if byte == b'"' {
            quoted = !quoted;
        } else if !quoted {
            outside.push(byte);
        }
    }
    outside
}

#[cfg(test)]
mod tests {
    use super::sniff;

    #[test]
    fn each_separator_is_found_from_the_first_line() {
        assert_eq!(sniff(b"t,y\n0,1\n"), b',');
        assert_eq!(sniff(b"t;y\n0,5;1\n"), b';');
        assert_eq!(sniff(b"t\ty\n0\t1\n"), b'\t');
        assert_eq!(sniff(b"\n  \ny\n1\n"), b',');
    }

    #[test]
    fn a_decimal_comma_does_not_outvote_the_semicolon() {
        assert_eq!(sniff(b"0,25;16764,5;138,32\n"), b';');
    }

    #[test]
    fn separators_inside_quotes_are_not_counted() {
        assert_eq!(sniff(b"\"mass; g\",y\n"), b',');
        assert_eq!(sniff(b"\"t, s\";\"y\"\n"), b';');
    }
}
