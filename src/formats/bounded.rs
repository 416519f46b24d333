//! Reading within bounds: text lines of at most [`MAX_LINE_BYTES`], and
//! inputs read whole, which a regular file limits to its length and a
//! stream (a pipe, FIFO, character device or standard input) to
//! [`MAX_STREAM_BYTES`]. An endless input (`/dev/zero`, `yes`) is refused
//! after at most that many bytes instead of being read until memory runs
//! out.

use std::io::{self, BufRead, Read};
use std::path::Path;

/// The longest line the line-based readers accept (xyz points, scan logs,
/// trajectories, the text headers of PLY, PCD, binvox, `.bt` and `.ot`
/// files): 1 MiB, not counting its `\n`.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// The most bytes a stream read whole may hold: 4 GiB. Regular files are
/// read to their length.
pub const MAX_STREAM_BYTES: u64 = 1 << 32;

/// How [`read_line`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineEnd {
    /// The input had ended: nothing was read.
    Eof,
    /// A line and its `\n` were read.
    Newline,
    /// The input ended after some bytes but before a `\n`.
    Unterminated,
    /// The line is longer than the bound: its first `limit` bytes were
    /// read, the rest is left unread.
    TooLong,
}

/// Reads a line into `buf` (cleared first), with its `\n` if it has one,
/// but never more than `limit` bytes before the `\n`.
pub fn read_line(reader: &mut impl BufRead, buf: &mut Vec<u8>, limit: usize) -> io::Result<LineEnd> {
    buf.clear();
    loop {
        let chunk = match reader.fill_buf() {
            Ok(c) => c,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if chunk.is_empty() {
            return Ok(if buf.is_empty() { LineEnd::Eof } else { LineEnd::Unterminated });
        }
        let room = limit - buf.len();
        match chunk.iter().position(|&b| b == b'\n') {
            Some(i) if i <= room => {
                buf.extend_from_slice(&chunk[..=i]);
                reader.consume(i + 1);
                return Ok(LineEnd::Newline);
            }
            None if chunk.len() <= room => {
                let n = chunk.len();
                buf.extend_from_slice(chunk);
                reader.consume(n);
            }
            // the line goes on past the bound
            _ => {
                buf.extend_from_slice(&chunk[..room]);
                reader.consume(room);
                return Ok(LineEnd::TooLong);
            }
        }
    }
}

/// Why an input could not be read whole.
#[derive(Debug, thiserror::Error)]
pub enum WholeError {
    /// Opening or reading failed.
    #[error(transparent)]
    Io(#[from] io::Error),
    /// A header line is longer than [`MAX_LINE_BYTES`].
    #[error("header line {line} is longer than {limit} bytes")]
    LineTooLong {
        /// The line, counted from 1.
        line: usize,
        /// The bound, in bytes.
        limit: usize,
    },
    /// A stream holds more than the bound.
    #[error("the input holds more than {limit} bytes, the most read from a pipe or device")]
    TooLarge {
        /// The bound, in bytes.
        limit: u64,
    },
}

/// How a text header that precedes data ends, for [`read_headed`].
pub(crate) struct HeaderShape {
    /// Whether a line (with its `\n`) is the header's last.
    pub is_last: fn(&[u8]) -> bool,
    /// Lines read at most before the last must have come; after them the
    /// rest is read as data (the format's reader then finds no header end).
    pub max_lines: usize,
}

/// Reads a file whole: a regular file to its length, anything else as
/// [`read_headed`] reads a stream.
pub(crate) fn read_file_headed(path: &Path, shape: &HeaderShape) -> Result<Vec<u8>, WholeError> {
    let mut file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if meta.is_file() {
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(meta.len() as usize)
            .map_err(|_| io::Error::new(io::ErrorKind::OutOfMemory, format!("cannot allocate {} bytes", meta.len())))?;
        (&mut file).take(meta.len()).read_to_end(&mut bytes)?;
        return Ok(bytes);
    }
    read_headed(io::BufReader::with_capacity(1 << 16, file), shape, MAX_STREAM_BYTES)
}

/// Reads a stream whole: its header line by line, each line at most
/// [`MAX_LINE_BYTES`], then the rest, at most `limit` bytes in all.
pub(crate) fn read_headed(mut reader: impl BufRead, shape: &HeaderShape, limit: u64) -> Result<Vec<u8>, WholeError> {
    let mut bytes = Vec::new();
    let mut line = Vec::new();
    for n in 1..=shape.max_lines {
        match read_line(&mut reader, &mut line, MAX_LINE_BYTES)? {
            LineEnd::Eof => return Ok(bytes),
            LineEnd::TooLong => return Err(WholeError::LineTooLong { line: n, limit: MAX_LINE_BYTES }),
            LineEnd::Newline | LineEnd::Unterminated => {}
        }
        bytes.extend_from_slice(&line);
        if bytes.len() as u64 > limit {
            return Err(WholeError::TooLarge { limit });
        }
        if (shape.is_last)(&line) {
            break;
        }
    }
    read_rest(reader, bytes, limit)
}

/// Reads a stream to its end, at most `limit` bytes.
pub fn read_stream(reader: impl Read, limit: u64) -> Result<Vec<u8>, WholeError> {
    read_rest(reader, Vec::new(), limit)
}

/// Appends the rest of `reader` to `bytes`, at most `limit` bytes in all.
fn read_rest(reader: impl Read, mut bytes: Vec<u8>, limit: u64) -> Result<Vec<u8>, WholeError> {
    let room = limit.saturating_sub(bytes.len() as u64);
    // one byte past the bound tells a stream of exactly `limit` bytes from a longer one
    reader.take(room.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(WholeError::TooLarge { limit });
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(text: &[u8], limit: usize) -> Vec<(LineEnd, Vec<u8>)> {
        let mut r = io::BufReader::with_capacity(3, text);
        let mut out = Vec::new();
        let mut buf = Vec::new();
        loop {
            let end = read_line(&mut r, &mut buf, limit).unwrap();
            out.push((end, buf.clone()));
            if matches!(end, LineEnd::Eof | LineEnd::TooLong | LineEnd::Unterminated) {
                return out;
            }
        }
    }

    #[test]
    fn lines_end_at_newlines_within_the_bound() {
        use LineEnd::*;
        assert_eq!(
            lines(b"ab\n\nabcd\nx", 4),
            [
                (Newline, b"ab\n".to_vec()),
                (Newline, b"\n".to_vec()),
                (Newline, b"abcd\n".to_vec()),
                (Unterminated, b"x".to_vec())
            ]
        );
        assert_eq!(lines(b"abcd", 4), [(Unterminated, b"abcd".to_vec())]);
        assert_eq!(lines(b"abcde\n", 4), [(TooLong, b"abcd".to_vec())]);
        assert_eq!(lines(b"abcdefghij", 4), [(TooLong, b"abcd".to_vec())]);
        assert_eq!(lines(b"", 4), [(Eof, vec![])]);
    }

    #[test]
    fn an_endless_line_stops_at_the_bound() {
        let mut zeros = io::BufReader::new(io::repeat(0));
        let mut buf = Vec::new();
        assert_eq!(read_line(&mut zeros, &mut buf, MAX_LINE_BYTES).unwrap(), LineEnd::TooLong);
        assert_eq!(buf.len(), MAX_LINE_BYTES);
    }

    #[test]
    fn streams_read_whole_stop_at_their_bound() {
        let shape = HeaderShape { is_last: |l| l.starts_with(b"end"), max_lines: 10 };
        let read = |r: &[u8], limit| read_headed(r, &shape, limit);
        assert_eq!(read(b"a\nend\n\x00\x01", 100).unwrap(), b"a\nend\n\x00\x01");
        assert_eq!(read(b"a\nend\n\x00\x01", 8).unwrap().len(), 8);
        assert!(matches!(read(b"a\nend\n\x00\x01\x02", 8), Err(WholeError::TooLarge { limit: 8 })));
        let endless = read_headed(io::BufReader::new(io::repeat(0)), &shape, MAX_STREAM_BYTES);
        assert!(matches!(endless, Err(WholeError::LineTooLong { line: 1, .. })), "{endless:?}");
        let data = io::BufReader::new(io::Cursor::new(b"end\n".to_vec()).chain(io::repeat(7)));
        assert!(matches!(read_headed(data, &shape, 1 << 20), Err(WholeError::TooLarge { .. })));
        assert!(matches!(read_stream(io::repeat(1), 1000), Err(WholeError::TooLarge { limit: 1000 })));
    }
}
