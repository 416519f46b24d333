//! What the PLY and PCD readers share: the typed values of their binary
//! data, their text headers, and the cloud they give.

use super::bounded::MAX_LINE_BYTES;
use crate::geometry::{Point3, PointCloud};

/// The points of a file and, when asked for and present, their colours.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColoredCloud {
    /// The points, in file order.
    pub cloud: PointCloud,
    /// One RGB colour per point; `None` when not asked for or the file has
    /// none.
    pub colors: Option<Vec<[u8; 3]>>,
}

/// A number type of a PLY property or a PCD field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes the value at the start of `b`; `None` when `b` is shorter
    /// than [`Self::size`].
    pub fn decode(self, b: &[u8], little: bool) -> Option<f64> {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b.get(..$n)?.try_into().ok()?;
                (if little { <$t>::from_le_bytes(a) } else { <$t>::from_be_bytes(a) }) as f64
            }};
        }
        Some(match self {
            Scalar::I8 => f64::from(*b.first()? as i8),
            Scalar::U8 => f64::from(*b.first()?),
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::I64 => get!(i64, 8),
            Scalar::U64 => get!(u64, 8),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        })
    }
}

/// Why a text header could not be split off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum HeaderEnd {
    /// The line starting at this byte offset is not UTF-8.
    NotText { offset: usize },
    /// No line starts with the closing keyword within the line limit.
    Missing,
    /// Line `line` (from 1), starting at byte `offset`, is longer than
    /// [`MAX_LINE_BYTES`].
    LineTooLong { line: usize, offset: usize },
}

/// A header line, trimmed, and the byte offset it starts at.
pub(crate) type Line<'a> = (usize, &'a str);

/// Splits off the text header whose last line starts with `end`: its
/// lines and the offset of the data after it. At most `max_lines` lines
/// are read, each at most [`MAX_LINE_BYTES`] long.
pub(crate) fn header_lines<'a>(
    bytes: &'a [u8],
    end: &str,
    max_lines: usize,
) -> Result<(Vec<Line<'a>>, usize), HeaderEnd> {
    let mut lines = Vec::new();
    let mut at = 0;
    while at < bytes.len() && lines.len() < max_lines {
        let rest = &bytes[at..bytes.len().min(at.saturating_add(MAX_LINE_BYTES + 1))];
        let stop = match rest.iter().position(|&b| b == b'\n') {
            Some(p) => at + p,
            None if rest.len() > MAX_LINE_BYTES => {
                return Err(HeaderEnd::LineTooLong { line: lines.len() + 1, offset: at })
            }
            None => bytes.len(),
        };
        let line = std::str::from_utf8(&bytes[at..stop]).map_err(|_| HeaderEnd::NotText { offset: at })?;
        let line = line.trim_end_matches('\r').trim();
        lines.push((at, line));
        at = (stop + 1).min(bytes.len());
        if line.split_whitespace().next() == Some(end) {
            return Ok((lines, at));
        }
    }
    Err(HeaderEnd::Missing)
}

/// The point from three coordinates, each rounded to float.
pub(crate) fn point(v: [f64; 3]) -> Point3 {
    Point3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

/// A capacity for `count` announced items of at least `min_bytes` each in
/// `data_len` bytes: what the data can hold, so that a lying count cannot
/// make a small file reserve gigabytes.
pub(crate) fn capacity(count: usize, data_len: usize, min_bytes: usize) -> usize {
    count.min(data_len / min_bytes.max(1))
}
