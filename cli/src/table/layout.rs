//! How a table's file is laid out and read: its separator, its encoding and the preamble before its
//! header ([`Layout`]), and the byte-rewriting readers that present it to the CSV reader with its lines
//! (and so the line numbers of errors) kept.

use std::io::BufRead;
use std::path::Path;

use anyhow::Context;

use super::{Role, column};

/// How the columns of a table are separated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Separator {
    Byte(u8),
    /// Runs of spaces (and tabs), read through [`runs_of_spaces`].
    Spaces,
}

/// How a table's file is laid out: the separator of its header line (a tab, else `;`, else `,`, else runs
/// of spaces), whether it is Latin-1 rather than UTF-8 (a line before the data is not UTF-8: an
/// instrument's µ saved as byte 0xB5), and the lines before its header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Layout {
    pub(super) sep: Separator,
    latin1: bool,
    /// Lines before the header that are not `#` comments: an instrument's preamble (its settings, one
    /// per line), read as comments.
    pub(super) preamble: usize,
    /// Whether a line names a time, a depth and a force (else the first line that is not a comment is
    /// taken as the header, for its error to say what it lacks).
    pub(super) found: bool,
}

/// Lines searched for a header that names time, depth and force: an instrument's preamble is shorter.
pub(super) const MAX_PREAMBLE: usize = 500;

/// The separator of one line, see [`Layout`].
fn separator_of(line: &str) -> Separator {
    if line.contains('\t') {
        Separator::Byte(b'\t')
    } else if line.contains(';') {
        Separator::Byte(b';')
    } else if line.contains(',') {
        Separator::Byte(b',')
    } else {
        Separator::Spaces
    }
}

/// Whether a line names a time, a depth and a force column, each with a unit it reads.
fn is_header(line: &str, sep: Separator) -> bool {
    let cells: Vec<String> = match sep {
        Separator::Byte(b) => line.split(char::from(b)).map(str::to_string).collect(),
        Separator::Spaces => {
            let mut out = Vec::new();
            let mut rewrite = runs_of_spaces();
            line.bytes().for_each(|b| rewrite(b, &mut out));
            String::from_utf8_lossy(&out).split('\t').map(str::to_string).collect()
        }
    };
    let roles: Vec<Role> =
        cells.iter().filter_map(|c| column(c, 0)).filter(|(_, unit)| unit.is_ok()).map(|(role, _)| role).collect();
    roles.contains(&Role::Time) && roles.contains(&Role::Force) && roles.iter().any(|r| matches!(r, Role::Depth(_)))
}

/// The file's [`Layout`]: the header is the first line that is not a comment and names time, depth and
/// force (lines before it are a preamble), or the first line that is not a comment where none within
/// [`MAX_PREAMBLE`] lines does (its error then says what it lacks).
pub(super) fn layout(path: &Path) -> anyhow::Result<Layout> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let (mut first, mut latin1) = (None, false);
    for (number, line) in std::io::BufReader::new(file).split(b'\n').take(MAX_PREAMBLE).enumerate() {
        let line = line.with_context(|| format!("reading {}", path.display()))?;
        let text = match String::from_utf8(line) {
            Ok(text) => text,
            Err(e) => {
                latin1 = true;
                e.into_bytes().iter().map(|&b| char::from(b)).collect()
            }
        };
        // A byte-order mark before the first line, a comment or the header.
        let line = text.trim_start_matches('\u{feff}').trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let sep = separator_of(line);
        if is_header(line, sep) {
            let preamble = first.map_or(0, |_| number);
            return Ok(Layout { sep, latin1, preamble, found: true });
        }
        first.get_or_insert(Layout { sep, latin1, preamble: 0, found: false });
    }
    first
        .map(|l| Layout { latin1, ..l })
        .ok_or_else(|| anyhow::anyhow!("{} has no header line (e.g. `t [s],x [mm],f [N]`)", path.display()))
}

pub(super) fn reader(path: &Path, layout: Layout) -> anyhow::Result<csv::Reader<Box<dyn std::io::Read>>> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut text: Box<dyn std::io::Read> = if layout.latin1 {
        Box::new(Transcode::new(std::io::BufReader::new(file), latin1_to_utf8))
    } else {
        Box::new(file)
    };
    if layout.preamble > 0 {
        text = Box::new(Transcode::new(std::io::BufReader::new(text), commented(layout.preamble)));
    }
    let (input, delimiter): (Box<dyn std::io::Read>, u8) = match layout.sep {
        Separator::Byte(b) => (text, b),
        Separator::Spaces => (Box::new(Transcode::new(std::io::BufReader::new(text), runs_of_spaces())), b'\t'),
    };
    Ok(csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(false)
        .from_reader(input))
}

/// The first `lines` lines read as comments: `#` before each (lines and their numbers are kept).
fn commented(lines: usize) -> impl FnMut(u8, &mut Vec<u8>) {
    let (mut seen, mut at_line_start) = (0, true);
    move |b, out| {
        if at_line_start && seen < lines {
            out.push(b'#');
        }
        at_line_start = b == b'\n';
        seen += usize::from(at_line_start);
        out.push(b);
    }
}

/// A reader that rewrites each byte of `inner` into zero or more bytes, keeping its lines.
struct Transcode<R, F> {
    inner: R,
    rewrite: F,
    out: Vec<u8>,
    at: usize,
}

impl<R: BufRead, F: FnMut(u8, &mut Vec<u8>)> Transcode<R, F> {
    fn new(inner: R, rewrite: F) -> Self {
        Transcode { inner, rewrite, out: Vec::new(), at: 0 }
    }
}

impl<R: BufRead, F: FnMut(u8, &mut Vec<u8>)> std::io::Read for Transcode<R, F> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at == self.out.len() {
            self.out.clear();
            self.at = 0;
            let chunk = self.inner.fill_buf()?;
            if chunk.is_empty() {
                return Ok(0);
            }
            for &b in chunk {
                (self.rewrite)(b, &mut self.out);
            }
            let n = chunk.len();
            self.inner.consume(n);
        }
        let n = buf.len().min(self.out.len() - self.at);
        buf[..n].copy_from_slice(&self.out[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// Latin-1 to UTF-8: each byte is the code point of its value.
fn latin1_to_utf8(b: u8, out: &mut Vec<u8>) {
    if b < 0x80 {
        out.push(b);
    } else {
        out.extend([0xC0 | (b >> 6), 0x80 | (b & 0x3F)]);
    }
}

/// A table whose columns are separated by runs of spaces or tabs, read as tab-separated: each run
/// becomes one tab, except at the start or end of a line and before `[` or `(` (a unit belongs to the
/// name before it). Lines (and so the line numbers of errors) are kept.
fn runs_of_spaces() -> impl FnMut(u8, &mut Vec<u8>) {
    // A run of blanks seen and not yet written (written as a tab once the next byte says so).
    let (mut pending, mut at_line_start) = (false, true);
    move |b, out| match b {
        b' ' | b'\t' => pending = !at_line_start,
        b'\n' | b'\r' => {
            pending = false;
            at_line_start = true;
            out.push(b);
        }
        _ => {
            if pending {
                out.push(if b == b'[' || b == b'(' { b' ' } else { b'\t' });
            }
            pending = false;
            at_line_start = false;
            out.push(b);
        }
    }
}
