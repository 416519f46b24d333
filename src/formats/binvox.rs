//! Patrick Min's binvox voxel grids (see `formats/binvox.md`), as
//! OctoMap's `binvox2bt` reads them: a text header, then run-length pairs.

use super::bounded::{read_file_headed, read_headed, HeaderShape, WholeError, MAX_STREAM_BYTES};
use std::io::BufRead;
use std::ops::Range;
use std::path::Path;

/// Header lines a stream's header is read in, line by line, before the
/// rest is read as data.
const MAX_HEADER_LINES: usize = 10_000;

/// Why a binvox file could not be read. Offsets count bytes from the start
/// of the file.
#[derive(Debug, thiserror::Error)]
pub enum BinvoxError {
    /// The file could not be read whole: opening or reading failed, a
    /// header line is longer than [`super::bounded::MAX_LINE_BYTES`], or a stream holds
    /// more than [`MAX_STREAM_BYTES`].
    #[error(transparent)]
    Read(#[from] WholeError),
    /// The file does not start with the token `#binvox`.
    #[error("the first token is {found:?} instead of \"#binvox\"")]
    NotBinvox {
        /// The first token (empty when the file has none).
        found: String,
    },
    /// The file ends where the header needs another number.
    #[error("the header ends before the {what}")]
    HeaderEnds {
        /// What was expected: `version`, `dimension`, `translation` or `scale`.
        what: &'static str,
    },
    /// A header token that should be a number does not parse as one.
    #[error("header, byte {offset}: the {what} {token:?} is not a number")]
    NotANumber {
        /// Byte offset of the token.
        offset: usize,
        /// What the token should be: `version`, `dimension`, `translation` or `scale`.
        what: &'static str,
        /// The token as found.
        token: String,
    },
    /// The file ends before the `data` token that closes the header.
    #[error("the header has no \"data\" line")]
    NoData,
    /// The header has no `dim` line.
    #[error("the header has no \"dim\" line")]
    NoDim,
    /// A side of the grid (`dim` as written: depth, height, width) is 0.
    #[error("dimension {0:?} is empty")]
    EmptyDim([usize; 3]),
    /// The grid (`dim` as written) has more than `usize::MAX` voxels or a
    /// side longer than `i32::MAX`.
    #[error("dimension {0:?} is too large")]
    TooLarge([usize; 3]),
    /// The scale is not positive and finite, or a translation is not finite.
    #[error("scale {scale} / translation {translate:?} is not usable")]
    BadPlacement {
        /// The `scale` value.
        scale: f32,
        /// The `translate` values.
        translate: [f32; 3],
    },
    /// The run-length data ends before covering every voxel.
    #[error("the data ends after {read} of {size} voxels (byte {offset})")]
    DataEnds {
        /// Byte offset of the end of the data (the file's length).
        offset: usize,
        /// Voxels covered by the complete runs read.
        read: usize,
        /// Voxels in the grid.
        size: usize,
    },
    /// A run reaches beyond the last voxel of the grid.
    #[error("the run at byte {offset} goes past the {size} voxels of the grid")]
    Overrun {
        /// Byte offset of the run's (value, count) pair.
        offset: usize,
        /// Voxels in the grid.
        size: usize,
    },
}

/// A binvox header and its run-length data.
#[derive(Clone, Debug, PartialEq)]
pub struct Binvox {
    /// `dim` as written: depth, height, width.
    pub dim: [usize; 3],
    /// `translate`: the world position of the grid's origin (default 0 0 0).
    pub translate: [f32; 3],
    /// `scale`: the grid's extent along its largest side, in world units
    /// (default 1); the voxel size is `scale` / max(`dim`).
    pub scale: f32,
    /// Voxels in the grid (the product of `dim`).
    pub size: usize,
    /// Pairs of (value, count) bytes, from byte `data_offset` of the file.
    data: Vec<u8>,
    data_offset: usize,
}

/// A byte cursor reading like a C++ istream with `>>`.
struct Cursor<'a> {
    b: &'a [u8],
    i: usize,
}

impl Cursor<'_> {
    fn token(&mut self) -> Option<(usize, &str)> {
        while self.i < self.b.len() && self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        let start = self.i;
        while self.i < self.b.len() && !self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        (self.i > start).then(|| (start, std::str::from_utf8(&self.b[start..self.i]).unwrap_or("\u{fffd}")))
    }

    fn number<T: std::str::FromStr>(&mut self, what: &'static str) -> Result<T, BinvoxError> {
        let (offset, t) = self.token().ok_or(BinvoxError::HeaderEnds { what })?;
        t.parse().map_err(|_| BinvoxError::NotANumber { offset, what, token: t.to_string() })
    }
}

/// How a binvox header ends, for reading a stream whole: with the line
/// holding the `data` token.
const SHAPE: HeaderShape = HeaderShape {
    is_last: |line| line.split(|b| b.is_ascii_whitespace()).any(|t| t == b"data"),
    max_lines: MAX_HEADER_LINES,
};

/// Reads a binvox file as [`read`] does: a regular file to its length, a
/// FIFO or device as [`read_from`] reads a stream.
pub fn read_file(path: impl AsRef<Path>) -> Result<Binvox, BinvoxError> {
    read(&read_file_headed(path.as_ref(), &SHAPE)?)
}

/// Reads a binvox stream as [`read`] does: its header line by line (at
/// most 10 000 lines, each at most [`super::bounded::MAX_LINE_BYTES`]), and the whole
/// stream at most [`MAX_STREAM_BYTES`].
pub fn read_from(reader: impl BufRead) -> Result<Binvox, BinvoxError> {
    read(&read_headed(reader, &SHAPE, MAX_STREAM_BYTES)?)
}

/// Parses a binvox file's header; its runs are checked by
/// [`Binvox::for_each_run`].
pub fn read(bytes: &[u8]) -> Result<Binvox, BinvoxError> {
    let mut c = Cursor { b: bytes, i: 0 };
    match c.token() {
        Some((_, "#binvox")) => {}
        other => return Err(BinvoxError::NotBinvox { found: other.map_or("", |t| t.1).to_string() }),
    }
    let _version: i64 = c.number("version")?;
    let (mut dim, mut translate, mut scale) = (None, [0f32; 3], 1f32);
    loop {
        let Some((_, t)) = c.token() else { return Err(BinvoxError::NoData) };
        match t {
            "data" => break,
            "dim" => dim = Some([c.number("dimension")?, c.number("dimension")?, c.number("dimension")?]),
            "translate" => {
                for v in &mut translate {
                    *v = c.number("translation")?;
                }
            }
            "scale" => scale = c.number("scale")?,
            _ => {
                while c.i < bytes.len() && bytes[c.i] != b'\n' {
                    c.i += 1;
                }
            }
        }
    }
    let dim: [usize; 3] = dim.ok_or(BinvoxError::NoDim)?;
    if dim.contains(&0) {
        return Err(BinvoxError::EmptyDim(dim));
    }
    let size = dim[0].checked_mul(dim[1]).and_then(|s| s.checked_mul(dim[2])).ok_or(BinvoxError::TooLarge(dim))?;
    // the largest side becomes an i32 in binvox2bt's resolution
    if dim.iter().any(|&d| d > i32::MAX as usize) {
        return Err(BinvoxError::TooLarge(dim));
    }
    if !(scale.is_finite() && scale > 0.0) || translate.iter().any(|t| !t.is_finite()) {
        return Err(BinvoxError::BadPlacement { scale, translate });
    }
    // the byte after "data" (its line feed) is skipped
    let data_offset = (c.i + 1).min(bytes.len());
    Ok(Binvox { dim, translate, scale, size, data: bytes[data_offset..].to_vec(), data_offset })
}

impl Binvox {
    /// Calls `f` with each run's value and its voxels (linear indices),
    /// in order; fails when the runs do not cover the grid exactly. Bytes
    /// after the last needed run are ignored, as binvox2bt does.
    pub fn for_each_run(&self, mut f: impl FnMut(u8, Range<usize>)) -> Result<(), BinvoxError> {
        let mut index = 0;
        let mut pairs = self.data.chunks_exact(2).enumerate();
        while index < self.size {
            let Some((n, &[value, count])) = pairs.next() else {
                let offset = self.data_offset + self.data.len();
                return Err(BinvoxError::DataEnds { offset, read: index, size: self.size });
            };
            let end = index + usize::from(count);
            if end > self.size {
                return Err(BinvoxError::Overrun { offset: self.data_offset + 2 * n, size: self.size });
            }
            f(value, index..end);
            index = end;
        }
        Ok(())
    }

    /// The grid coordinates (x, y, z) of voxel `j`, as binvox2bt assigns
    /// them: y varies fastest, then z, then x.
    pub fn coords(&self, j: usize) -> [usize; 3] {
        let [_, height, width] = self.dim;
        [j / (width * height), j % width, (j / width) % height]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_cover_the_grid_in_order() {
        let mut f = b"#binvox 1\ndim 2 2 3\ntranslate -1 0.5 2\nscale 3\ndata\n".to_vec();
        f.extend_from_slice(&[0, 5, 1, 7, 9, 9]);
        let bv = read(&f).unwrap();
        assert_eq!((bv.dim, bv.translate, bv.scale, bv.size), ([2, 2, 3], [-1.0, 0.5, 2.0], 3.0, 12));
        let mut runs = Vec::new();
        bv.for_each_run(|v, r| runs.push((v, r))).unwrap();
        assert_eq!(runs, [(0, 0..5), (1, 5..12)]);
        assert_eq!(bv.coords(7), [1, 1, 0]);
    }

    #[test]
    fn bad_files_name_what_is_wrong() {
        let err = |b: &[u8]| match read(b) {
            Ok(bv) => bv.for_each_run(|_, _| {}).unwrap_err().to_string(),
            Err(e) => e.to_string(),
        };
        assert!(err(b"#binvox 1\ndim 2 2 3\ndata\n\x00\x05").contains("ends after 5 of 12 voxels (byte 27)"));
        assert!(err(b"#binvox 1\ndim 2 2 3\ndata\n\x00\x05\x01\x08").contains("run at byte 27 goes past"));
        assert!(err(b"#binvox 1\ndim 2 x 3\ndata\n").contains("byte 16: the dimension \"x\""));
        assert!(err(b"#binvox 1\ndim 0 2 3\ndata\n").contains("empty"));
        assert!(err(b"#binvox 1\ndim 4294967296 4294967296 2\ndata\n").contains("too large"));
        assert!(err(b"#binvox 1\ndim 1 1 1\nscale -1\ndata\n").contains("not usable"));
        assert!(err(b"binvox").contains("instead of"));
        assert!(err(b"#binvox 1\ndim 1 1 1\n").contains("no \"data\" line"));
    }

    #[test]
    fn streams_are_read_within_bounds() {
        let mut f = b"#binvox 1\ndim 1 1 2\ndata\n".to_vec();
        f.extend_from_slice(&[1, 2, 10, 10]);
        assert_eq!(read_from(&f[..]).unwrap(), read(&f).unwrap());
        let endless = read_from(std::io::BufReader::new(std::io::repeat(0))).unwrap_err();
        let limit = super::super::bounded::MAX_LINE_BYTES;
        assert_eq!(endless.to_string(), format!("header line 1 is longer than {limit} bytes"));
    }
}
