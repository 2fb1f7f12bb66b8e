//! Text from outside made safe to print: file names, CSV fields and blob
//! serials may hold control characters (terminal escape sequences, newlines
//! that forge lines); every human-readable print shows them escaped.

use std::borrow::Cow;
use std::io::Write;
use std::path::Path;

/// `s` with every control character (C0, DEL, C1; `\n` and `\t` too)
/// written as its Rust escape (`\n`, `\u{1b}`): for fragments that come from
/// outside, such as file names, CSV fields and serial numbers.
pub fn escape_controls(s: &str) -> Cow<'_, str> {
    escape_where(s, char::is_control)
}

/// `s` with every control character but `\n` and `\t` escaped: for whole
/// messages and tables, whose line structure is the program's own.
pub fn terminal_safe(s: &str) -> Cow<'_, str> {
    escape_where(s, |c| c.is_control() && c != '\n' && c != '\t')
}

fn escape_where(s: &str, escape: impl Fn(char) -> bool) -> Cow<'_, str> {
    if !s.chars().any(&escape) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if escape(c) {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    Cow::Owned(out)
}

/// The path that names standard input on a command line.
pub const STDIN_PATH: &str = "-";

/// A path as messages name it: `<stdin>` for `-`, control characters escaped.
pub fn path(p: &Path) -> String {
    if p.as_os_str() == STDIN_PATH {
        return "<stdin>".to_owned();
    }
    escape_controls(&p.to_string_lossy()).into_owned()
}

/// A writer that escapes control characters other than `\n` and `\t` on
/// their way through ([`terminal_safe`]); what `trainer` prints goes through one.
pub struct SafeWriter<W: Write> {
    inner: W,
    /// The start of a UTF-8 sequence split across two writes.
    pending: Vec<u8>,
}

impl<W: Write> SafeWriter<W> {
    /// Wraps `inner`.
    pub fn new(inner: W) -> Self {
        SafeWriter {
            inner,
            pending: Vec::new(),
        }
    }
}

impl<W: Write> Write for SafeWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.pending.extend_from_slice(buf);
        let valid = match std::str::from_utf8(&self.pending) {
            Ok(s) => s.len(),
            // An incomplete sequence at the end waits for the next write;
            // invalid bytes pass as the lossy replacement character.
            Err(e) if e.error_len().is_none() => e.valid_up_to(),
            Err(_) => self.pending.len(),
        };
        let text = String::from_utf8_lossy(&self.pending[..valid]).into_owned();
        self.inner.write_all(terminal_safe(&text).as_bytes())?;
        self.pending.drain(..valid);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Line and column (1-based, the column in characters) of byte `offset` in `source`: where
/// an error in a TOML manifest or spec points.
pub fn line_col(source: &str, offset: usize) -> (usize, usize) {
    let before = source.get(..offset).unwrap_or(source);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fragments_from_outside_show_every_control_character_escaped() {
        assert_eq!(escape_controls("SN-42"), "SN-42");
        assert_eq!(
            escape_controls("a\x1b[31mred\nx\t\u{9b}"),
            "a\\u{1b}[31mred\\nx\\t\\u{9b}"
        );
        assert_eq!(
            terminal_safe("table\n\trow\x1b]0;title\x07"),
            "table\n\trow\\u{1b}]0;title\\u{7}"
        );
        assert_eq!(path(Path::new("-")), "<stdin>");
        assert_eq!(path(Path::new("run\n.csv")), "run\\n.csv");
    }

    #[test]
    fn the_safe_writer_escapes_across_split_writes_and_keeps_line_structure() {
        let mut w = SafeWriter::new(Vec::new());
        w.write_all(b"ok \x1b[2J\nnext ").unwrap();
        let euro = "€".as_bytes();
        w.write_all(&euro[..1]).unwrap();
        w.write_all(&euro[1..]).unwrap();
        w.write_all("\u{85}".as_bytes()).unwrap();
        assert_eq!(String::from_utf8(w.inner).unwrap(), "ok \\u{1b}[2J\nnext €\\u{85}");
    }
}
