//! Plain-text point clouds: one `x y z` per line (see `formats/xyz.md`).
//!
//! OctoMap's `Pointcloud::read` extracts floats with C++ `>>` from a token
//! stream and silently stops at the first token it cannot parse. We accept
//! exactly the inputs on which that yields the whole file and produce the same
//! floats (glibc `strtof` and Rust's parser both round correctly); anything
//! OctoMap would cut short or regroup (comments, two or four numbers on a
//! line, `nan`, `inf`, overflow, `1.5.3`) is an error with its line number.

use std::io::{self, BufRead, BufWriter, Write};

use crate::geometry::{Point3, PointCloud};

#[derive(Debug, thiserror::Error)]
pub enum XyzError {
    #[error("I/O error at line {line}: {source}")]
    Io {
        line: u64,
        #[source]
        source: io::Error,
    },
    #[error("line {line}: expected 3 numbers, found {found} tokens")]
    TokenCount { line: u64, found: usize },
    #[error("line {line}: {token:?} is not a decimal number")]
    NotANumber { line: u64, token: String },
    #[error("line {line}: {token:?} is not finite as a float (OctoMap stops reading here)")]
    NotFinite { line: u64, token: String },
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

/// Reads a cloud. Blank (whitespace-only) lines are skipped; every other line
/// must hold exactly three numbers. Lines are 1-based in errors.
pub fn read(mut reader: impl BufRead) -> Result<PointCloud, XyzError> {
    let mut cloud = PointCloud::new();
    let mut buf = Vec::new();
    let mut line = 0u64;
    loop {
        buf.clear();
        line += 1;
        let n = reader.read_until(b'\n', &mut buf).map_err(|source| XyzError::Io { line, source })?;
        if n == 0 {
            return Ok(cloud);
        }
        let tokens: Vec<&[u8]> = c_tokens(&buf).collect();
        match tokens.len() {
            0 => continue,
            3 => cloud.push(parse_point(&tokens, line)?),
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
