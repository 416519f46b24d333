//! PCL's PCD point clouds (see `formats/pcd.md`): the `x`, `y`, `z`
//! fields of `ascii`, `binary` and `binary_compressed` (LZF) files, and
//! optionally the packed `rgb` or `rgba` field.
//!
//! A colour is 4 bytes holding `0x00RRGGBB` / `0xAARRGGBB` as PCL packs
//! it, whether typed `F`, `U` or `I`; in ASCII files an `F` field is the
//! float whose bits are the packed colour, as PCL prints it.

use super::bounded::{read_file_headed, read_headed, HeaderShape, WholeError, MAX_LINE_BYTES, MAX_STREAM_BYTES};
use super::ply::first_token;
use super::scalar::{capacity, header_lines, point, HeaderEnd, Scalar};
use super::ColoredCloud;
use crate::geometry::PointCloud;
use std::io::BufRead;
use std::path::Path;

/// Header lines read at most before `DATA` must have come.
const MAX_HEADER_LINES: usize = 1000;

/// Why a PCD file could not be read. Offsets count bytes from the start of
/// the file; points count from 0.
#[derive(Debug, thiserror::Error)]
pub enum PcdError {
    /// A header line is not UTF-8.
    #[error("header line at byte {offset} is not text")]
    HeaderNotText {
        /// Byte offset of the start of that line.
        offset: usize,
    },
    /// The file could not be read whole: opening or reading failed, a
    /// header line is longer than [`MAX_LINE_BYTES`], or a stream holds
    /// more than [`MAX_STREAM_BYTES`].
    #[error(transparent)]
    Read(#[from] WholeError),
    /// A header line is longer than [`MAX_LINE_BYTES`].
    #[error("header line {line} (byte {offset}) is longer than {limit} bytes")]
    HeaderLineTooLong {
        /// The line's number, from 1.
        line: usize,
        /// Byte offset of the start of the line.
        offset: usize,
        /// The bound, in bytes.
        limit: usize,
    },
    /// No line starts with `DATA` within the first 1000 lines.
    #[error("no DATA line within the first {MAX_HEADER_LINES} lines")]
    NoData,
    /// A `SIZE`, `COUNT`, `WIDTH`, `HEIGHT` or `POINTS` value is not a
    /// non-negative integer.
    #[error("header line at byte {offset}: {key} value {token:?} is not a count")]
    BadCount {
        /// Byte offset of the start of the header line.
        offset: usize,
        /// The line's keyword, e.g. `SIZE`.
        key: &'static str,
        /// The value as found.
        token: String,
    },
    /// `FIELDS` is empty or missing, or `SIZE`, `TYPE` and `COUNT` do not
    /// give one value per field.
    #[error("FIELDS ({fields}), SIZE ({sizes}), TYPE ({types}) and COUNT ({counts}) do not match")]
    FieldsMismatch {
        /// Names on the `FIELDS` line.
        fields: usize,
        /// Values on the `SIZE` line.
        sizes: usize,
        /// Values on the `TYPE` line.
        types: usize,
        /// Values on the `COUNT` line (one per field when there is no such line).
        counts: usize,
    },
    /// Neither `POINTS` nor both `WIDTH` and `HEIGHT` are given.
    #[error("no POINTS (or WIDTH and HEIGHT) line")]
    NoPointCount,
    /// A size computed from the header overflows `usize`; names which one
    /// (`WIDTH x HEIGHT`, the point size or the data size).
    #[error("{0} overflows")]
    Overflow(&'static str),
    /// A `TYPE` and `SIZE` pair that is no PCD number type (`I`/`U` of 1, 2,
    /// 4 or 8 bytes, `F` of 4 or 8).
    #[error("unknown TYPE {kind} of SIZE {size}")]
    UnknownType {
        /// The `TYPE` letter.
        kind: String,
        /// The `SIZE` in bytes.
        size: usize,
    },
    /// The `x`, `y` or `z` field (named) is missing.
    #[error("no {0} field")]
    MissingField(&'static str),
    /// The colour field is not a single 4-byte value.
    #[error("field {field} has SIZE {size} COUNT {count}: a packed colour needs SIZE 4 COUNT 1")]
    ColorField {
        /// `rgb` or `rgba`.
        field: String,
        /// Its `SIZE` in bytes.
        size: usize,
        /// Its `COUNT`.
        count: usize,
    },
    /// The `x`, `y` or `z` field (named) has `COUNT 0`.
    #[error("field {0} has COUNT 0")]
    ZeroCount(String),
    /// The `DATA` value is not `ascii`, `binary` or `binary_compressed`.
    #[error("unknown DATA kind {0:?}")]
    UnknownDataKind(String),
    /// `ascii` data that is not UTF-8.
    #[error("the ascii data starting at byte {offset} is not text")]
    DataNotText {
        /// Byte offset of the start of the data.
        offset: usize,
    },
    /// `ascii` data with fewer non-blank lines than points.
    #[error("the data ends after {read} of {points} points")]
    Truncated {
        /// Points read.
        read: usize,
        /// Points the header announces.
        points: usize,
    },
    /// An `ascii` data line lacks a coordinate or colour, or holds one
    /// that does not parse.
    #[error("point {row}: cannot read {what} from {line:?}")]
    BadPoint {
        /// The point's index.
        row: usize,
        /// `x y z`, or the name of the colour field.
        what: String,
        /// The data line.
        line: String,
    },
    /// `binary` data shorter than the announced points.
    #[error("the binary data holds {have} bytes, {points} points need {need}")]
    ShortBinary {
        /// Bytes after the header.
        have: usize,
        /// Points the header announces.
        points: usize,
        /// Bytes they need (points times the point size).
        need: usize,
    },
    /// `binary_compressed` data with fewer than the 8 bytes of its two
    /// size words.
    #[error("the compressed data at byte {offset} has no size words")]
    NoSizeWords {
        /// Byte offset of the start of the data.
        offset: usize,
    },
    /// The uncompressed size word does not match the announced points.
    #[error("the compressed data decompresses to {raw} bytes, {points} points need {need}")]
    RawSize {
        /// The uncompressed size the file gives, in bytes.
        raw: usize,
        /// Points the header announces.
        points: usize,
        /// Bytes they need (points times the point size).
        need: usize,
    },
    /// The file ends before the compressed size word says the compressed
    /// data does.
    #[error("the compressed data is shorter than its {comp} bytes: the file holds {have} after its size words")]
    ShortCompressed {
        /// The compressed size the file gives, in bytes.
        comp: usize,
        /// Bytes in the file after the size words.
        have: usize,
    },
    /// The compressed data is not valid LZF or does not decompress to
    /// exactly the uncompressed size.
    #[error("LZF data, input byte {offset}: {reason}")]
    Lzf {
        /// Byte offset within the compressed data (from just after the
        /// size words), not from the start of the file.
        offset: usize,
        /// What is wrong.
        reason: &'static str,
    },
}

/// LZF decompression (liblzf's format, as PCL's `binary_compressed` uses)
/// of `input` into exactly `out_len` bytes.
pub(crate) fn lzf_decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>, PcdError> {
    let lzf = |offset, reason| PcdError::Lzf { offset, reason };
    // three input bytes give at most 264 output bytes (a long back
    // reference): a lying size fails here, and the reservation is bounded
    if out_len / 88 > input.len() {
        return Err(lzf(input.len(), "too short for the announced size"));
    }
    let mut out = Vec::with_capacity(out_len.min(64 * input.len()));
    let mut i = 0;
    while i < input.len() {
        let at = i;
        let ctrl = usize::from(input[i]);
        i += 1;
        if ctrl < 32 {
            let lit = input.get(i..i + ctrl + 1).ok_or(lzf(at, "a literal runs past the input"))?;
            out.extend_from_slice(lit);
            i += lit.len();
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(i).ok_or(lzf(at, "the input ends in a back reference"))?);
                i += 1;
            }
            len += 2;
            let low = usize::from(*input.get(i).ok_or(lzf(at, "the input ends in a back reference"))?);
            i += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            let start = out.len().checked_sub(back).ok_or(lzf(at, "a back reference before the start"))?;
            // byte by byte: the source may overlap what is being written
            for k in start..start + len {
                out.push(out[k]);
            }
        }
        if out.len() > out_len {
            return Err(lzf(at, "decompresses to more than the announced size"));
        }
    }
    if out.len() != out_len {
        return Err(lzf(input.len(), "decompresses to less than the announced size"));
    }
    Ok(out)
}

/// A colour packed by PCL (`0x00RRGGBB`, alpha or padding in the top byte).
fn unpack_pcl(v: u32) -> [u8; 3] {
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

fn le_u32(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// How a PCD header ends, for reading a stream whole.
const SHAPE: HeaderShape =
    HeaderShape { is_last: |line| first_token(line) == Some(b"DATA"), max_lines: MAX_HEADER_LINES };

/// Reads a PCD file as [`read`] does: a regular file to its length, a
/// FIFO or device as [`read_from`] reads a stream.
pub fn read_file(path: impl AsRef<Path>, want_colors: bool) -> Result<ColoredCloud, PcdError> {
    read(&read_file_headed(path.as_ref(), &SHAPE)?, want_colors)
}

/// Reads a PCD stream as [`read`] does: its header line by line, each at
/// most [`MAX_LINE_BYTES`], and the whole stream at most
/// [`MAX_STREAM_BYTES`].
pub fn read_from(reader: impl BufRead, want_colors: bool) -> Result<ColoredCloud, PcdError> {
    read(&read_headed(reader, &SHAPE, MAX_STREAM_BYTES)?, want_colors)
}

/// The x, y, z fields of a PCD file and, with `want_colors`, its `rgb` or
/// `rgba` field if there is one.
pub fn read(bytes: &[u8], want_colors: bool) -> Result<ColoredCloud, PcdError> {
    let (lines, data) = header_lines(bytes, "DATA", MAX_HEADER_LINES).map_err(|e| match e {
        HeaderEnd::NotText { offset } => PcdError::HeaderNotText { offset },
        HeaderEnd::Missing => PcdError::NoData,
        HeaderEnd::LineTooLong { line, offset } => PcdError::HeaderLineTooLong { line, offset, limit: MAX_LINE_BYTES },
    })?;
    let (mut fields, mut sizes, mut types, mut counts) = (vec![], vec![], vec![], vec![]);
    let (mut points, mut width, mut height, mut kind) = (None, None, None, "");
    for &(offset, line) in &lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, rest)) = t.split_first() else { continue };
        let nums = |key: &'static str| -> Result<Vec<usize>, PcdError> {
            rest.iter()
                .map(|s| s.parse().map_err(|_| PcdError::BadCount { offset, key, token: s.to_string() }))
                .collect()
        };
        match key {
            "FIELDS" => fields = rest.to_vec(),
            "SIZE" => sizes = nums("SIZE")?,
            "TYPE" => types = rest.to_vec(),
            "COUNT" => counts = nums("COUNT")?,
            "WIDTH" => width = nums("WIDTH")?.first().copied(),
            "HEIGHT" => height = nums("HEIGHT")?.first().copied(),
            "POINTS" => points = nums("POINTS")?.first().copied(),
            "DATA" => kind = rest.first().copied().unwrap_or(""),
            _ => {}
        }
    }
    if counts.is_empty() {
        counts = vec![1; fields.len()];
    }
    if fields.is_empty() || [sizes.len(), types.len(), counts.len()].iter().any(|&l| l != fields.len()) {
        return Err(PcdError::FieldsMismatch {
            fields: fields.len(),
            sizes: sizes.len(),
            types: types.len(),
            counts: counts.len(),
        });
    }
    let n = match (points, width, height) {
        (Some(p), _, _) => p,
        (None, Some(w), Some(h)) => w.checked_mul(h).ok_or(PcdError::Overflow("WIDTH x HEIGHT"))?,
        _ => return Err(PcdError::NoPointCount),
    };
    let scalars: Vec<Scalar> = types
        .iter()
        .zip(&sizes)
        .map(|(t, &s)| scalar_type(t, s).ok_or_else(|| PcdError::UnknownType { kind: t.to_string(), size: s }))
        .collect::<Result<_, _>>()?;
    let find = |n: &'static str| fields.iter().position(|&f| f == n).ok_or(PcdError::MissingField(n));
    let idx = [find("x")?, find("y")?, find("z")?];
    if let Some(&i) = idx.iter().find(|&&i| counts[i] == 0) {
        return Err(PcdError::ZeroCount(fields[i].to_string()));
    }
    let rgb = if want_colors { fields.iter().position(|&f| f == "rgb" || f == "rgba") } else { None };
    if let Some(c) = rgb {
        if sizes[c] != 4 || counts[c] != 1 {
            return Err(PcdError::ColorField { field: fields[c].to_string(), size: sizes[c], count: counts[c] });
        }
    }
    // byte offset of each field within a point, and the point size
    let mut offsets = Vec::with_capacity(fields.len());
    let mut stride = 0usize;
    for (s, c) in sizes.iter().zip(&counts) {
        offsets.push(stride);
        stride = s.checked_mul(*c).and_then(|b| stride.checked_add(b)).ok_or(PcdError::Overflow("the point size"))?;
    }
    // what the data can hold: a binary point takes `stride` bytes, an ascii
    // one at least a digit and a space per coordinate
    let room = capacity(n, bytes.len() - data, if kind == "ascii" { 6 } else { stride });
    let mut out =
        ColoredCloud { cloud: PointCloud::with_capacity(room), colors: rgb.map(|_| Vec::with_capacity(room)) };
    match kind {
        "ascii" => {
            // one point per line; each field takes COUNT tokens
            let text = std::str::from_utf8(&bytes[data..]).map_err(|_| PcdError::DataNotText { offset: data })?;
            let mut token_of = Vec::with_capacity(fields.len());
            let mut at = 0;
            for &c in &counts {
                token_of.push(at);
                at += c; // no overflow: the counts sum to at most the point size
            }
            let mut rows = text.lines().filter(|l| !l.trim().is_empty());
            for row in 0..n {
                let line = rows.next().ok_or(PcdError::Truncated { read: row, points: n })?;
                let t: Vec<&str> = line.split_whitespace().collect();
                let bad = |what: &str| PcdError::BadPoint { row, what: what.to_string(), line: line.to_string() };
                let v = idx.map(|i| t.get(token_of[i]).and_then(|s| s.parse::<f64>().ok()));
                let [Some(x), Some(y), Some(z)] = v else { return Err(bad("x y z")) };
                out.cloud.push(point([x, y, z]));
                if let (Some(colors), Some(c)) = (out.colors.as_mut(), rgb) {
                    let t = t.get(token_of[c]).copied().unwrap_or("");
                    let packed = match types[c] {
                        "F" => t.parse::<f32>().ok().filter(|v| !v.is_nan()).map(f32::to_bits),
                        "U" => t.parse::<u32>().ok(),
                        _ => t.parse::<i32>().ok().map(|v| v as u32),
                    };
                    colors.push(unpack_pcl(packed.ok_or_else(|| bad(fields[c]))?));
                }
            }
        }
        "binary" => {
            let need = n.checked_mul(stride).ok_or(PcdError::Overflow("the data size"))?;
            let have = bytes.len() - data;
            let d = data.checked_add(need).and_then(|end| bytes.get(data..end));
            let d = d.ok_or(PcdError::ShortBinary { have, points: n, need })?;
            for row in d.chunks_exact(stride) {
                // every field lies inside the point: its offset plus its size
                // is at most the stride
                let v = idx.map(|i| scalars[i].decode(&row[offsets[i]..], true).unwrap_or(f64::NAN));
                out.cloud.push(point(v));
                if let (Some(colors), Some(c)) = (out.colors.as_mut(), rgb) {
                    colors.push(unpack_pcl(le_u32(&row[offsets[c]..])));
                }
            }
        }
        "binary_compressed" => {
            let head = bytes.get(data..data + 8).ok_or(PcdError::NoSizeWords { offset: data })?;
            let comp = le_u32(head) as usize;
            let raw = le_u32(&head[4..]) as usize;
            let need = n.checked_mul(stride).ok_or(PcdError::Overflow("the data size"))?;
            if raw != need {
                return Err(PcdError::RawSize { raw, points: n, need });
            }
            let have = bytes.len() - data - 8;
            let c = bytes.get(data + 8..data + 8 + comp).ok_or(PcdError::ShortCompressed { comp, have })?;
            let d = lzf_decompress(c, raw)?;
            // fields are stored one after the other (structure of arrays);
            // each field's block is n * size * count <= need bytes
            let mut field_start = Vec::with_capacity(fields.len());
            let mut at = 0;
            for (s, c) in sizes.iter().zip(&counts) {
                field_start.push(at);
                at += n * s * c;
            }
            for row in 0..n {
                let v = idx.map(|i| {
                    let at = field_start[i] + row * sizes[i] * counts[i];
                    scalars[i].decode(&d[at..], true).unwrap_or(f64::NAN)
                });
                out.cloud.push(point(v));
                if let (Some(colors), Some(c)) = (out.colors.as_mut(), rgb) {
                    colors.push(unpack_pcl(le_u32(&d[field_start[c] + row * 4..])));
                }
            }
        }
        other => return Err(PcdError::UnknownDataKind(other.to_string())),
    }
    Ok(out)
}

fn scalar_type(kind: &str, size: usize) -> Option<Scalar> {
    Some(match (kind, size) {
        ("I", 1) => Scalar::I8,
        ("U", 1) => Scalar::U8,
        ("I", 2) => Scalar::I16,
        ("U", 2) => Scalar::U16,
        ("I", 4) => Scalar::I32,
        ("U", 4) => Scalar::U32,
        ("I", 8) => Scalar::I64,
        ("U", 8) => Scalar::U64,
        ("F", 4) => Scalar::F32,
        ("F", 8) => Scalar::F64,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n\
                        WIDTH 2\nHEIGHT 1\nPOINTS 2\n";

    fn file(kind: &str, body: &[u8]) -> Vec<u8> {
        let mut f = format!("{HEAD}DATA {kind}\n").into_bytes();
        f.extend_from_slice(body);
        f
    }

    /// The points as structure of arrays, LZF-"compressed" into literal
    /// runs (valid LZF that any decoder must accept).
    fn compressed(raw: &[u8]) -> Vec<u8> {
        let mut comp = Vec::new();
        for run in raw.chunks(32) {
            comp.push(run.len() as u8 - 1);
            comp.extend_from_slice(run);
        }
        let mut body = (comp.len() as u32).to_le_bytes().to_vec();
        body.extend_from_slice(&(raw.len() as u32).to_le_bytes());
        body.extend_from_slice(&comp);
        body
    }

    #[test]
    fn the_three_data_kinds_give_the_same_points() {
        let pts = [(1.5f32, -2.0f32, 0.25f32, 0x00ff_0007u32), (-1e3, 2.0, 3.0, 0x0001_0405)];
        let mut bin = Vec::new();
        for &(x, y, z, c) in &pts {
            for v in [x.to_bits(), y.to_bits(), z.to_bits(), c] {
                bin.extend_from_slice(&v.to_le_bytes());
            }
        }
        let mut soa = Vec::new();
        for f in 0..4 {
            for &(x, y, z, c) in &pts {
                soa.extend_from_slice(&[x.to_bits(), y.to_bits(), z.to_bits(), c][f].to_le_bytes());
            }
        }
        let ascii = file("ascii", format!("1.5 -2 0.25 {}\n\n-1e3 2 3 {}\n", 0x00ff_0007, 0x0001_0405).as_bytes());
        for f in [ascii, file("binary", &bin), file("binary_compressed", &compressed(&soa))] {
            let c = read(&f, true).unwrap();
            let want = [[1.5, -2.0, 0.25], [-1e3, 2.0, 3.0]];
            assert_eq!(c.cloud.iter().map(|p| p.to_array()).collect::<Vec<_>>(), want);
            assert_eq!(c.colors, Some(vec![[255, 0, 7], [1, 4, 5]]));
        }
    }

    #[test]
    fn lzf_back_references_may_overlap_their_output() {
        // "ab", then 6 bytes from 2 back: "ababab" + "ab"
        assert_eq!(lzf_decompress(&[1, b'a', b'b', 4 << 5, 1], 8).unwrap(), b"abababab");
        let e = |input: &[u8], n| lzf_decompress(input, n).unwrap_err().to_string();
        assert!(e(&[1, b'a', b'b', 4 << 5, 5], 8).contains("byte 3: a back reference before the start"));
        assert!(e(&[1, b'a'], 2).contains("byte 0: a literal runs past the input"));
        assert!(e(&[0, b'a'], 1 << 20).contains("too short for the announced size"));
    }

    #[test]
    fn streams_are_read_within_bounds() {
        let f = file("ascii", b"1 2 3 4\n5 6 7 8\n");
        assert_eq!(read_from(&f[..], true).unwrap(), read(&f, true).unwrap());
        let endless = read_from(std::io::BufReader::new(std::io::repeat(0)), false).unwrap_err();
        assert_eq!(endless.to_string(), format!("header line 1 is longer than {MAX_LINE_BYTES} bytes"));
        let mut long = b"# ".to_vec();
        long.resize(MAX_LINE_BYTES + 1, b'x');
        long.extend_from_slice(&file("ascii", b"1 2 3 4\n5 6 7 8\n"));
        let err = read(&long, false).unwrap_err().to_string();
        assert_eq!(err, format!("header line 1 (byte 0) is longer than {MAX_LINE_BYTES} bytes"));
    }

    #[test]
    fn bad_files_name_what_is_wrong() {
        let err = |b: &[u8]| read(b, true).unwrap_err().to_string();
        assert!(err(&file("binary", &[0; 20])).contains("holds 20 bytes, 2 points need 32"));
        assert!(err(&file("ascii", b"1 2 3 4\n")).contains("ends after 1 of 2 points"));
        assert!(err(&file("ascii", b"1 2 x 4\n")).contains("point 0: cannot read x y z"));
        assert!(err(&file("zip", b"")).contains("unknown DATA kind \"zip\""));
        assert!(err(b"FIELDS x y z\nSIZE 4 4\nDATA ascii\n").contains("do not match"));
        assert!(err(b"FIELDS x y z\nSIZE 4 4 -4\nDATA ascii\n").contains("byte 13: SIZE value \"-4\""));
        assert!(err(&file("binary_compressed", &compressed(&[0; 16]))).contains("to 16 bytes, 2 points need 32"));
        // a size that fits a usize, but not once added to the header's
        let huge = HEAD.replace("POINTS 2", &format!("POINTS {}", usize::MAX / 16)) + "DATA binary\n";
        assert!(err(huge.as_bytes()).contains("holds 0 bytes"));
    }
}
