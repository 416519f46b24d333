//! The text header shared by `.bt` and `.ot` files, and a byte-counting
//! reader so that errors can name the offset where they happened.

use super::bounded::MAX_LINE_BYTES;
use super::TreeFileError;
use std::io::{self, BufRead, Write};

pub const OT_FIRST_LINE: &str = "# Octomap OcTree file";
pub const BT_FIRST_LINE: &str = "# Octomap OcTree binary file";
const COMMENT_LINE: &str = "# (feel free to add / change comments, but leave the first line as it is!)";

/// A reader that counts the bytes consumed.
pub struct CountingReader<R> {
    inner: R,
    pub offset: u64,
}

impl<R: BufRead> CountingReader<R> {
    pub fn new(inner: R) -> Self {
        CountingReader { inner, offset: 0 }
    }

    /// Reads exactly `buf.len()` bytes or reports what was being read.
    #[inline]
    pub fn read_exact(&mut self, buf: &mut [u8], what: &'static str) -> Result<(), TreeFileError> {
        match self.inner.read_exact(buf) {
            Ok(()) => {
                self.offset += buf.len() as u64;
                Ok(())
            }
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
                Err(TreeFileError::Truncated { offset: self.offset, what })
            }
            Err(e) => Err(TreeFileError::Io(e)),
        }
    }

    /// Next byte without consuming it, `None` at the end.
    pub fn peek_byte(&mut self) -> Result<Option<u8>, TreeFileError> {
        Ok(self.inner.fill_buf()?.first().copied())
    }

    /// The bytes buffered next (empty at the end), without consuming them.
    #[inline]
    pub fn chunk(&mut self) -> Result<&[u8], TreeFileError> {
        Ok(self.inner.fill_buf()?)
    }

    /// Consumes `n` bytes of [`Self::chunk`].
    #[inline]
    pub fn advance(&mut self, n: usize) {
        self.inner.consume(n);
        self.offset += n as u64;
    }

    fn consume(&mut self) {
        self.inner.consume(1);
        self.offset += 1;
    }

    /// Reads a line (without its `\n`), at most `limit` bytes.
    fn read_line(&mut self, limit: usize) -> Result<Vec<u8>, TreeFileError> {
        let start = self.offset;
        let mut line = Vec::new();
        while let Some(b) = self.peek_byte()? {
            self.consume();
            if b == b'\n' {
                return Ok(line);
            }
            if line.len() >= limit {
                return Err(TreeFileError::Header { offset: start, reason: "header line too long".into() });
            }
            line.push(b);
        }
        Ok(line)
    }

    /// `istream >> std::string`: skips white space (at most
    /// [`MAX_LINE_BYTES`] of it), reads up to the next.
    fn read_token(&mut self) -> Result<Option<(u64, String)>, TreeFileError> {
        let space = self.offset;
        while let Some(b) = self.peek_byte()? {
            if b.is_ascii_whitespace() {
                if self.offset - space >= MAX_LINE_BYTES as u64 {
                    let reason = format!("more than {MAX_LINE_BYTES} bytes of white space");
                    return Err(TreeFileError::Header { offset: space, reason });
                }
                self.consume();
            } else {
                break;
            }
        }
        let start = self.offset;
        let mut tok = Vec::new();
        while let Some(b) = self.peek_byte()? {
            if b.is_ascii_whitespace() {
                break;
            }
            if tok.len() >= 4096 {
                return Err(TreeFileError::Header { offset: start, reason: "header token too long".into() });
            }
            tok.push(b);
            self.consume();
        }
        if tok.is_empty() {
            return Ok(None);
        }
        Ok(Some((start, String::from_utf8_lossy(&tok).into_owned())))
    }

    /// Skips to just after the next `\n`, at most [`MAX_LINE_BYTES`] on.
    fn skip_line(&mut self) -> Result<(), TreeFileError> {
        let start = self.offset;
        while let Some(b) = self.peek_byte()? {
            if self.offset - start > MAX_LINE_BYTES as u64 {
                let reason = format!("header line longer than {MAX_LINE_BYTES} bytes");
                return Err(TreeFileError::Header { offset: start, reason });
            }
            self.consume();
            if b == b'\n' {
                break;
            }
        }
        Ok(())
    }
}

/// The fields of a header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// The tree type from the `id` line (e.g. `OcTree`; the legacy id `1`
    /// becomes `OcTree`).
    pub id: String,
    /// The node count from the `size` line; 0 when absent.
    pub size: u64,
    /// The voxel edge length from the `res` line, in metres (checked
    /// positive and finite).
    pub resolution: f64,
    /// Byte offset of the `id` value, for errors about it.
    pub id_offset: u64,
}

/// Which first line a file starts with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FirstLine {
    Full,
    Binary,
    /// Neither: possibly a pre-1.4 binary file without a text header.
    Other,
}

/// Reads and classifies the first line (OctoMap compares its prefix only).
pub fn read_first_line<R: BufRead>(r: &mut CountingReader<R>) -> Result<(FirstLine, Vec<u8>), TreeFileError> {
    let line = r.read_line(1 << 16)?;
    let kind = if line.starts_with(OT_FIRST_LINE.as_bytes()) {
        FirstLine::Full
    } else if line.starts_with(BT_FIRST_LINE.as_bytes()) {
        FirstLine::Binary
    } else {
        FirstLine::Other
    };
    Ok((kind, line))
}

/// `AbstractOcTree::readHeader`: keyword lines up to `data`, comments and
/// unknown keywords skipped, then the rest of the `data` line.
pub fn read_header<R: BufRead>(r: &mut CountingReader<R>) -> Result<Header, TreeFileError> {
    let mut id = String::new();
    let mut id_offset = r.offset;
    let mut size: u64 = 0;
    let mut resolution: f64 = 0.0;
    let mut res_offset = None;
    let data_offset = loop {
        let Some((offset, token)) = r.read_token()? else {
            return Err(TreeFileError::Header { offset: r.offset, reason: "no `data` line".into() });
        };
        match token.as_str() {
            "data" => {
                r.skip_line()?;
                break offset;
            }
            t if t.starts_with('#') => r.skip_line()?,
            "id" => {
                (id_offset, id) = r.read_token()?.unwrap_or((r.offset, String::new()));
            }
            "res" => {
                let (o, v) = r.read_token()?.unwrap_or((r.offset, String::new()));
                res_offset = Some(o);
                resolution = v.parse().map_err(|_| TreeFileError::Header {
                    offset: o,
                    reason: format!("resolution `{v}` is not a number"),
                })?;
            }
            "size" => {
                let (o, v) = r.read_token()?.unwrap_or((r.offset, String::new()));
                size = v.parse().map_err(|_| TreeFileError::Header {
                    offset: o,
                    reason: format!("size `{v}` is not a non-negative integer"),
                })?;
            }
            _ => r.skip_line()?,
        }
    };
    if id.is_empty() {
        return Err(TreeFileError::Header { offset: data_offset, reason: "no `id` given".into() });
    }
    if crate::key::check_resolution(resolution).is_err() {
        return Err(TreeFileError::BadResolution {
            value: resolution,
            offset: Some(res_offset.unwrap_or(data_offset)),
        });
    }
    if id == "1" {
        id = "OcTree".into();
    }
    Ok(Header { id, size, resolution, id_offset })
}

/// Writes a header exactly as OctoMap's `write`/`writeBinaryConst` do.
pub fn write_header(w: &mut impl Write, first_line: &str, id: &str, size: usize, resolution: f64) -> io::Result<()> {
    write!(w, "{first_line}\n{COMMENT_LINE}\n#\nid {id}\nsize {size}\nres {}\ndata\n", format_double(resolution))
}

/// A double as a C++ stream prints it by default (`%g`, six significant digits).
pub fn format_double(x: f64) -> String {
    const PRECISION: i32 = 6;
    if x == 0.0 {
        return if x.is_sign_negative() { "-0".into() } else { "0".into() };
    }
    if !x.is_finite() {
        return if x.is_nan() {
            "nan".into()
        } else if x > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        };
    }
    let sci = format!("{:.*e}", (PRECISION - 1) as usize, x);
    let (mantissa, exp) = sci.split_once('e').expect("exponent present");
    let exp: i32 = exp.parse().expect("integer exponent");
    fn strip(s: &str) -> &str {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            s
        }
    }
    if !(-4..PRECISION).contains(&exp) {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{}{:02}", strip(mantissa), sign, exp.abs())
    } else {
        let decimals = (PRECISION - 1 - exp).max(0) as usize;
        strip(&format!("{:.*}", decimals, x)).to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endless_header_lines_and_white_space_are_refused() {
        use std::io::Read;
        let header = |rest: Box<dyn Read>| {
            let start = std::io::Cursor::new(b"id OcTree\n# ".to_vec());
            let mut r = CountingReader::new(std::io::BufReader::new(start.chain(rest)));
            read_header(&mut r).unwrap_err().to_string()
        };
        let err = header(Box::new(std::io::repeat(b'x')));
        assert_eq!(err, format!("bad header at byte 11: header line longer than {MAX_LINE_BYTES} bytes"));
        let err = header(Box::new(std::io::Cursor::new(b"\n".to_vec()).chain(std::io::repeat(b' '))));
        assert_eq!(err, format!("bad header at byte 13: more than {MAX_LINE_BYTES} bytes of white space"));
    }

    #[test]
    fn doubles_print_like_cpp_streams() {
        for (x, s) in [
            (0.1, "0.1"),
            (0.05, "0.05"),
            (0.08, "0.08"),
            (1.0, "1"),
            (0.3, "0.3"),
            (0.01, "0.01"),
            (0.123456789, "0.123457"),
            (1234567.0, "1.23457e+06"),
            (0.00001234, "1.234e-05"),
            (100.0, "100"),
            (999999.5, "1e+06"),
        ] {
            assert_eq!(format_double(x), s, "{x}");
        }
    }
}
