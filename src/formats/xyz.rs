//! Plain-text point clouds: one `x y z` per line (see `formats/xyz.md`).
//!
//! OctoMap's `Pointcloud::read` extracts floats with C++ `>>` from a token
//! stream and silently stops at the first token it cannot parse. We read
//! every file on which that yields the whole file to the same floats (glibc
//! `strtof` and Rust's parser both round correctly), and also what other
//! tools write and OctoMap would cut short: `#` comments (whole lines or
//! after the numbers) and values separated by commas or semicolons. Anything
//! else OctoMap would cut short or regroup (two or four numbers on a line,
//! `nan`, `inf`, overflow, `1.5.3`) is an error with its line number.

use std::io::{self, BufRead, BufWriter, Write};

use super::bounded::{read_line, LineEnd, MAX_LINE_BYTES};
use crate::geometry::{Point3, PointCloud};

/// Why an `x y z` file could not be read. Lines count from 1.
#[derive(Debug, thiserror::Error)]
pub enum XyzError {
    /// Opening or reading failed, or the points did not fit in memory.
    #[error("I/O error at line {line}")]
    Io {
        /// The line being read (0 when the file could not be opened).
        line: u64,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// A line (comment removed) holds neither 0 nor 3 values.
    #[error("line {line}: expected 3 numbers, found {found} values")]
    TokenCount {
        /// The line.
        line: u64,
        /// How many values it holds.
        found: usize,
    },
    /// A value is not a decimal number as C++ `>>` reads a float
    /// (`nan`, `inf` and hex numbers are refused).
    #[error("line {line}: {token:?} is not a decimal number")]
    NotANumber {
        /// The line.
        line: u64,
        /// The value as found.
        token: String,
    },
    /// A value overflows `f32`.
    #[error("line {line}: {token:?} is not finite as a float (OctoMap stops reading here)")]
    NotFinite {
        /// The line.
        line: u64,
        /// The value as found.
        token: String,
    },
    /// A line is longer than [`MAX_LINE_BYTES`] (no `\n` within it).
    #[error("line {line} is longer than {limit} bytes")]
    LineTooLong {
        /// The line.
        line: u64,
        /// The bound, in bytes.
        limit: usize,
    },
}

/// C++ `isspace` in the "C" locale (Rust's ASCII whitespace lacks `\v`).
pub(crate) fn is_c_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\x0b' | b'\x0c' | b'\r')
}

pub(crate) fn c_tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|&b| is_c_space(b)).filter(|t| !t.is_empty())
}

/// Why a token is not a float that C++ `>>` would read completely.
pub(crate) enum FloatError {
    NotANumber,
    NotFinite,
}

/// Parses a token the way `std::istream >> float` does when it consumes the
/// whole token: sign, digits, one `.`, optional exponent; no `inf`/`nan`/hex.
/// Overflow is rejected (libstdc++ sets failbit); underflow to 0 or a
/// subnormal is accepted like `strtof`.
pub(crate) fn parse_c_float(token: &[u8]) -> Result<f32, FloatError> {
    if !token.iter().all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'e' | b'E')) {
        return Err(FloatError::NotANumber);
    }
    let s = std::str::from_utf8(token).map_err(|_| FloatError::NotANumber)?;
    let v: f32 = s.parse().map_err(|_| FloatError::NotANumber)?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(FloatError::NotFinite)
    }
}

pub(crate) fn token_str(t: &[u8]) -> String {
    String::from_utf8_lossy(t).into_owned()
}

/// Parses three leading tokens as a point; extra tokens are the caller's business.
pub(crate) fn parse_point(tokens: &[&[u8]], line: u64) -> Result<Point3, XyzError> {
    let mut c = [0f32; 3];
    for (v, t) in c.iter_mut().zip(tokens) {
        *v = parse_c_float(t).map_err(|e| match e {
            FloatError::NotANumber => XyzError::NotANumber { line, token: token_str(t) },
            FloatError::NotFinite => XyzError::NotFinite { line, token: token_str(t) },
        })?;
    }
    Ok(Point3::from_array(c))
}

/// The values of a line (its comment already cut off): split at commas or
/// semicolons when it has any, each value trimmed of whitespace (an empty
/// one is kept, to be refused as not a number), else at whitespace.
fn values(text: &[u8]) -> Vec<&[u8]> {
    let separator = |b: &u8| *b == b',' || *b == b';';
    if !text.iter().any(separator) {
        return c_tokens(text).collect();
    }
    text.split(separator)
        .map(|v| {
            let start = v.iter().position(|&b| !is_c_space(b)).unwrap_or(v.len());
            let end = v.iter().rposition(|&b| !is_c_space(b)).map_or(start, |e| e + 1);
            &v[start..end]
        })
        .collect()
}

/// Reads a cloud: one point per line, three numbers separated by
/// whitespace, or by commas or semicolons (whitespace around them
/// allowed). Blank lines and everything from a `#` to the end of its line
/// are skipped. Lines are 1-based in errors; a line longer than
/// [`MAX_LINE_BYTES`] is an error (an endless input without a `\n` is
/// refused after that many bytes).
pub fn read(mut reader: impl BufRead) -> Result<PointCloud, XyzError> {
    let mut cloud = PointCloud::new();
    let mut buf = Vec::new();
    let mut line = 0u64;
    loop {
        line += 1;
        match read_line(&mut reader, &mut buf, MAX_LINE_BYTES).map_err(|source| XyzError::Io { line, source })? {
            LineEnd::Eof => return Ok(cloud),
            LineEnd::TooLong => return Err(XyzError::LineTooLong { line, limit: MAX_LINE_BYTES }),
            LineEnd::Newline | LineEnd::Unterminated => {}
        }
        let text = buf.split(|&b| b == b'#').next().unwrap_or_default();
        let values = values(text);
        match values.len() {
            0 => continue,
            3 => {
                cloud.points.try_reserve(1).map_err(|_| {
                    let why = format!("cannot allocate memory for {} points", cloud.len() + 1);
                    XyzError::Io { line, source: io::Error::new(io::ErrorKind::OutOfMemory, why) }
                })?;
                cloud.push(parse_point(&values, line)?)
            }
            found => return Err(XyzError::TokenCount { line, found }),
        }
    }
}

/// Reads a whole file (buffered).
pub fn read_file(path: impl AsRef<std::path::Path>) -> Result<PointCloud, XyzError> {
    let f = std::fs::File::open(path).map_err(|source| XyzError::Io { line: 0, source })?;
    read(io::BufReader::with_capacity(1 << 16, f))
}

/// Formats a float with the shortest digits that read back to the same bits
/// (in Rust and with C++ `>>`), using an exponent only for extreme magnitudes.
pub fn format_f32(v: f32) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-4..1e16).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Writes `x y z\n` per point with round-trip-exact numbers. Non-finite
/// coordinates are refused (neither reader could read them back).
pub fn write(cloud: &PointCloud, writer: impl Write) -> io::Result<()> {
    let mut out = BufWriter::with_capacity(1 << 16, writer);
    for (i, p) in cloud.iter().enumerate() {
        if !p.is_finite() {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("point {i} ({:?}) is not finite", p)));
        }
        writeln!(out, "{} {} {}", format_f32(p.x), format_f32(p.y), format_f32(p.z))?;
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(text: &str) -> Vec<[f32; 3]> {
        read(text.as_bytes()).unwrap().iter().map(|p| p.to_array()).collect()
    }

    fn error(text: &str) -> String {
        read(text.as_bytes()).unwrap_err().to_string()
    }

    #[test]
    fn comments_blank_lines_commas_and_semicolons() {
        let text = "# x y z written by a scanner\n\n1 2 3\n4,5,6 # trailing note\n  7 ; 8;9\r\n\t# indented comment\n-1.5, +.25 ,1e-3\n";
        assert_eq!(points(text), [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0], [-1.5, 0.25, 0.001]]);
        assert_eq!(points("#only comments\n#\n"), Vec::<[f32; 3]>::new());
        assert_eq!(points("1 2 3#no space before the comment"), [[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn bad_rows_name_their_line() {
        assert_eq!(error("1,2,3\n1,,3\n"), "line 2: \"\" is not a decimal number");
        assert_eq!(error("# header\n1,2,3,\n"), "line 2: expected 3 numbers, found 4 values");
        assert_eq!(error("1 2 3\n\n1,2\n"), "line 3: expected 3 numbers, found 2 values");
        assert_eq!(error("1 2 3 4 # four\n"), "line 1: expected 3 numbers, found 4 values");
        assert_eq!(error("1 2,3,4\n"), "line 1: \"1 2\" is not a decimal number");
        // a decimal comma is not a separator here: the values do not count up
        assert_eq!(error("1,5;2,5;3,5\n"), "line 1: expected 3 numbers, found 6 values");
        assert_eq!(error("1;nan;3\n"), "line 1: \"nan\" is not a decimal number");
        assert_eq!(error("1 2 1e39\n"), "line 1: \"1e39\" is not finite as a float (OctoMap stops reading here)");
    }

    #[test]
    fn an_endless_line_is_refused_at_the_bound() {
        let endless = read(io::BufReader::new(io::repeat(0))).unwrap_err();
        assert_eq!(endless.to_string(), format!("line 1 is longer than {MAX_LINE_BYTES} bytes"));
        let long = format!("1 2 3\n{}\n", " ".repeat(MAX_LINE_BYTES + 1));
        assert_eq!(error(&long), format!("line 2 is longer than {MAX_LINE_BYTES} bytes"));
        // a line of exactly the bound is read
        let exact = format!("1 2 3{}\n", " ".repeat(MAX_LINE_BYTES - 5));
        assert_eq!(points(&exact), [[1.0, 2.0, 3.0]]);
    }
}
