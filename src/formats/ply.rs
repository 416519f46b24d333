//! PLY point clouds (see `formats/ply.md`): the `x`, `y`, `z` of the
//! `vertex` element, from ASCII or binary files of either byte order, and
//! optionally its `red`, `green`, `blue`; and the vertex-only files
//! `octolinear to-points` writes.
//!
//! Colours are integers 0..=255 of any integer type, or floats in 0..=1
//! (scaled by 255 and rounded). They are decoded only when asked for, so a
//! file with odd colour values still gives its points.

use super::bounded::{read_file_headed, read_headed, HeaderShape, WholeError, MAX_LINE_BYTES, MAX_STREAM_BYTES};
use super::scalar::{capacity, header_lines, point, HeaderEnd, Scalar};
use super::ColoredCloud;
use crate::geometry::{Point3, PointCloud};
use std::io::{self, BufRead, Write};
use std::path::Path;

/// Header lines read at most before `end_header` must have come.
const MAX_HEADER_LINES: usize = 10_000;

/// Why a PLY file could not be read. Offsets count bytes from the start of
/// the file; lines and rows count from 1 and 0.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
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
    /// No line starts with `end_header` within the first 10 000 lines.
    #[error("the header has no \"end_header\" line within its first {MAX_HEADER_LINES} lines")]
    NoEndHeader,
    /// The first line is not `ply`.
    #[error("does not start with a \"ply\" line")]
    NotPly,
    /// A header line that cannot be used: an unknown keyword or format,
    /// or an `element` or `property` line missing or misnaming a part.
    #[error("header line {line} (byte {offset}): {reason}: {text:?}")]
    HeaderLine {
        /// The line's number.
        line: usize,
        /// Byte offset of the start of the line.
        offset: usize,
        /// What is wrong with it.
        reason: &'static str,
        /// The line, trimmed.
        text: String,
    },
    /// The header has no `format` line.
    #[error("the header has no format line")]
    NoFormat,
    /// The header declares no `vertex` element.
    #[error("the header has no vertex element")]
    NoVertex,
    /// The `vertex` element lacks the `x`, `y` or `z` property (named).
    #[error("the vertex element has no {0} field")]
    MissingProperty(&'static str),
    /// A coordinate or colour property (named) is declared as a list.
    #[error("vertex property {0} is a list, not a number")]
    ListProperty(String),
    /// ASCII data that is not UTF-8.
    #[error("the ASCII data starting at byte {offset} is not text")]
    DataNotText {
        /// Byte offset of the start of the data.
        offset: usize,
    },
    /// The data ends before the `vertex` element's last row (or that of
    /// an element before it) is complete.
    #[error("the data ends in {element} {row} of {count} (byte {offset})")]
    Truncated {
        /// The element being read, e.g. `vertex`.
        element: String,
        /// The row being read.
        row: usize,
        /// Rows the header announces for the element.
        count: usize,
        /// Byte offset of the missing value in binary files; the file's
        /// length in ASCII ones.
        offset: usize,
    },
    /// An ASCII token does not parse as a number.
    #[error("{element} {row}: {token:?} is not a number")]
    NotANumber {
        /// The element being read.
        element: String,
        /// The row being read.
        row: usize,
        /// The token as found.
        token: String,
    },
    /// A list property's length is negative, fractional or too large.
    #[error("{element} {row}: list length {value} is not a count")]
    BadListLength {
        /// The element being read.
        element: String,
        /// The row being read.
        row: usize,
        /// The length as read.
        value: f64,
    },
    /// A colour channel lies outside its range (checked only when colours
    /// are asked for).
    ///
    /// `kind` is "colour" or "float colour", `range` what it must lie in.
    #[error("vertex {row} {property}: {kind} {value} is outside {range}")]
    Color {
        /// The vertex's row.
        row: usize,
        /// `red`, `green` or `blue`.
        property: String,
        /// `colour` for integer types, `float colour` for floats.
        kind: &'static str,
        /// The value as read.
        value: f64,
        /// `0..255` for integers, `0..1` for floats.
        range: &'static str,
    },
}

struct Property {
    name: String,
    scalar: Scalar,
    /// The length's type, for a list property.
    list: Option<Scalar>,
}

struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

/// The parsed header: the data's byte order (`None`: ASCII), the elements,
/// and where the data starts.
struct Header {
    little: Option<bool>,
    elements: Vec<Element>,
    data: usize,
}

fn header(bytes: &[u8]) -> Result<Header, PlyError> {
    let first = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    if first.strip_suffix(b"\r").unwrap_or(first).trim_ascii() != b"ply" {
        return Err(PlyError::NotPly);
    }
    let (lines, data) = header_lines(bytes, "end_header", MAX_HEADER_LINES).map_err(|e| match e {
        HeaderEnd::NotText { offset } => PlyError::HeaderNotText { offset },
        HeaderEnd::Missing => PlyError::NoEndHeader,
        HeaderEnd::LineTooLong { line, offset } => PlyError::HeaderLineTooLong { line, offset, limit: MAX_LINE_BYTES },
    })?;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (n, &(offset, line)) in lines.iter().enumerate().skip(1) {
        let t: Vec<&str> = line.split_whitespace().collect();
        let bad = |reason| PlyError::HeaderLine { line: n + 1, offset, reason, text: line.to_string() };
        match t.first().copied() {
            Some("format") => {
                format = Some(match t.get(1).copied() {
                    Some("ascii") => None,
                    Some("binary_little_endian") => Some(true),
                    Some("binary_big_endian") => Some(false),
                    _ => return Err(bad("unknown format")),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2).and_then(|c| c.parse().ok())) else {
                    return Err(bad("an element needs a name and a count"));
                };
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let e = elements.last_mut().ok_or_else(|| bad("property before any element"))?;
                let scalar = |i: usize| t.get(i).and_then(|s| scalar_type(s));
                let p = if t.get(1) == Some(&"list") {
                    match (scalar(2), scalar(3), t.get(4)) {
                        (Some(c), Some(s), Some(name)) => Property { name: name.to_string(), scalar: s, list: Some(c) },
                        _ => return Err(bad("a list property needs two known types and a name")),
                    }
                } else {
                    match (scalar(1), t.get(2)) {
                        (Some(s), Some(name)) => Property { name: name.to_string(), scalar: s, list: None },
                        _ => return Err(bad("a property needs a known type and a name")),
                    }
                };
                e.props.push(p);
            }
            Some("comment") | Some("obj_info") | Some("end_header") | None => {}
            Some(_) => return Err(bad("unknown keyword")),
        }
    }
    Ok(Header { little: format.ok_or(PlyError::NoFormat)?, elements, data })
}

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

/// A colour channel's value as a byte: integers must lie in 0..=255,
/// floats in 0..=1 (scaled by 255, rounded).
fn color_byte(scalar: Scalar, v: f64, row: usize, property: &str) -> Result<u8, PlyError> {
    let (ok, kind, range) = if scalar.is_float() {
        ((0.0..=1.0).contains(&v), "float colour", "0..1")
    } else {
        ((0.0..=255.0).contains(&v), "colour", "0..255")
    };
    if !ok {
        return Err(PlyError::Color { row, property: property.to_string(), kind, value: v, range });
    }
    Ok(if scalar.is_float() { (v * 255.0).round() as u8 } else { v as u8 })
}

/// A list length as a count.
fn list_length(v: f64, e: &Element, row: usize) -> Result<usize, PlyError> {
    if v >= 0.0 && v.fract() == 0.0 && v < usize::MAX as f64 {
        Ok(v as usize)
    } else {
        Err(PlyError::BadListLength { element: e.name.clone(), row, value: v })
    }
}

/// How a PLY header ends, for reading a stream whole.
const SHAPE: HeaderShape =
    HeaderShape { is_last: |line| first_token(line) == Some(b"end_header"), max_lines: MAX_HEADER_LINES };

/// A line's first whitespace-separated word.
pub(crate) fn first_token(line: &[u8]) -> Option<&[u8]> {
    line.split(|b| b.is_ascii_whitespace()).find(|t| !t.is_empty())
}

/// Reads a PLY file as [`read`] does: a regular file to its length, a
/// FIFO or device as [`read_from`] reads a stream.
pub fn read_file(path: impl AsRef<Path>, want_colors: bool) -> Result<ColoredCloud, PlyError> {
    read(&read_file_headed(path.as_ref(), &SHAPE)?, want_colors)
}

/// Reads a PLY stream as [`read`] does: its header line by line, each at
/// most [`MAX_LINE_BYTES`], and the whole stream at most
/// [`MAX_STREAM_BYTES`].
pub fn read_from(reader: impl BufRead, want_colors: bool) -> Result<ColoredCloud, PlyError> {
    read(&read_headed(reader, &SHAPE, MAX_STREAM_BYTES)?, want_colors)
}

/// The vertices of a PLY file and, with `want_colors`, their `red`,
/// `green`, `blue` properties if all three exist.
pub fn read(bytes: &[u8], want_colors: bool) -> Result<ColoredCloud, PlyError> {
    let Header { little, elements, data } = header(bytes)?;
    let vi = elements.iter().position(|e| e.name == "vertex").ok_or(PlyError::NoVertex)?;
    let vertex = &elements[vi];
    let find = |n: &str| vertex.props.iter().position(|p| p.name == n);
    let xyz = [("x", find("x")), ("y", find("y")), ("z", find("z"))];
    let mut wanted = Vec::with_capacity(6);
    for (name, i) in xyz {
        wanted.push(i.ok_or(PlyError::MissingProperty(name))?);
    }
    if want_colors {
        if let (Some(r), Some(g), Some(b)) = (find("red"), find("green"), find("blue")) {
            wanted.extend([r, g, b]);
        }
    }
    if let Some(&i) = wanted.iter().find(|&&i| vertex.props[i].list.is_some()) {
        return Err(PlyError::ListProperty(vertex.props[i].name.clone()));
    }
    // each vertex takes at least a byte (a token and a space in ASCII)
    let room = capacity(vertex.count, bytes.len() - data, if little.is_some() { 3 } else { 6 });
    let mut out = ColoredCloud {
        cloud: PointCloud::with_capacity(room),
        colors: (wanted.len() == 6).then(|| Vec::with_capacity(room)),
    };
    // the wanted properties' values of the current vertex
    let mut picked = [0f64; 6];
    let mut push_vertex = |picked: &[f64; 6], row: usize| -> Result<(), PlyError> {
        out.cloud.push(point([picked[0], picked[1], picked[2]]));
        if let Some(colors) = out.colors.as_mut() {
            let mut c = [0u8; 3];
            for k in 0..3 {
                let p = &vertex.props[wanted[3 + k]];
                c[k] = color_byte(p.scalar, picked[3 + k], row, &p.name)?;
            }
            colors.push(c);
        }
        Ok(())
    };
    // the elements up to the vertex one; rows of an element without
    // properties take no data (and may be as many as the count says)
    let elements = elements[..=vi].iter().enumerate().filter(|(_, e)| !e.props.is_empty());
    match little {
        None => {
            let text = std::str::from_utf8(&bytes[data..]).map_err(|_| PlyError::DataNotText { offset: data })?;
            let mut tokens = text.split_whitespace();
            for (ei, e) in elements {
                for row in 0..e.count {
                    for (pi, p) in e.props.iter().enumerate() {
                        let mut next = || -> Result<f64, PlyError> {
                            let t = tokens.next().ok_or_else(|| PlyError::Truncated {
                                element: e.name.clone(),
                                row,
                                count: e.count,
                                offset: bytes.len(),
                            })?;
                            t.parse::<f64>().map_err(|_| PlyError::NotANumber {
                                element: e.name.clone(),
                                row,
                                token: t.to_string(),
                            })
                        };
                        let v = next()?;
                        if p.list.is_some() {
                            for _ in 0..list_length(v, e, row)? {
                                next()?;
                            }
                        } else if ei == vi {
                            for (slot, &w) in picked.iter_mut().zip(&wanted) {
                                if w == pi {
                                    *slot = v;
                                }
                            }
                        }
                    }
                    if ei == vi {
                        push_vertex(&picked, row)?;
                    }
                }
            }
        }
        Some(little) => {
            let mut at = data;
            for (ei, e) in elements {
                for row in 0..e.count {
                    let truncated =
                        |at: usize| PlyError::Truncated { element: e.name.clone(), row, count: e.count, offset: at };
                    for (pi, p) in e.props.iter().enumerate() {
                        let n = match p.list {
                            Some(c) => {
                                let v = c.decode(&bytes[at..], little).ok_or_else(|| truncated(at))?;
                                at += c.size();
                                list_length(v, e, row)?
                            }
                            None => 1,
                        };
                        let len = n.checked_mul(p.scalar.size()).ok_or_else(|| truncated(at))?;
                        let b = bytes.get(at..at.saturating_add(len)).ok_or_else(|| truncated(at))?;
                        if ei == vi && p.list.is_none() {
                            let v = p.scalar.decode(b, little).ok_or_else(|| truncated(at))?;
                            for (slot, &w) in picked.iter_mut().zip(&wanted) {
                                if w == pi {
                                    *slot = v;
                                }
                            }
                        }
                        at += len;
                    }
                    if ei == vi {
                        push_vertex(&picked, row)?;
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Writes `points` as the `vertex` element of a PLY file with float `x`,
/// `y`, `z`: binary little endian, or ASCII with each float in the
/// shortest form that reads back to the same bits.
pub fn write(points: &[Point3], ascii: bool, mut w: impl Write) -> io::Result<()> {
    let format = if ascii { "ascii" } else { "binary_little_endian" };
    write!(
        w,
        "ply\nformat {format} 1.0\ncomment written by octolinear\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    )?;
    for p in points {
        if ascii {
            use super::xyz::format_f32 as f;
            writeln!(w, "{} {} {}", f(p.x), f(p.y), f(p.z))?;
        } else {
            for c in p.to_array() {
                w.write_all(&c.to_le_bytes())?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ply(format: &str, body: &[u8]) -> Vec<u8> {
        let mut f = format!(
            "ply\nformat {format} 1.0\nelement face 2\nproperty list uchar int vertex_indices\n\
             element vertex 2\nproperty float x\nproperty uchar red\nproperty float y\nproperty float z\n\
             property uchar green\nproperty uchar blue\nend_header\n"
        )
        .into_bytes();
        f.extend_from_slice(body);
        f
    }

    #[test]
    fn ascii_and_binary_give_the_same_points_and_colours() {
        let ascii = ply("ascii", b"3 0 1 2\n2 5 6\n1.5 255 -2 0.25 0 7\n-1e3 1 2 3 4 5\n");
        let mut bin = Vec::new();
        for face in [&[0i32, 1, 2][..], &[5, 6]] {
            bin.push(face.len() as u8);
            face.iter().for_each(|i| bin.extend_from_slice(&i.to_le_bytes()));
        }
        for (x, r, y, z, g, b) in [(1.5f32, 255u8, -2f32, 0.25f32, 0u8, 7u8), (-1e3, 1, 2.0, 3.0, 4, 5)] {
            bin.extend_from_slice(&x.to_le_bytes());
            bin.push(r);
            bin.extend_from_slice(&y.to_le_bytes());
            bin.extend_from_slice(&z.to_le_bytes());
            bin.extend_from_slice(&[g, b]);
        }
        let want = vec![Point3::new(1.5, -2.0, 0.25), Point3::new(-1e3, 2.0, 3.0)];
        for file in [ascii, ply("binary_little_endian", &bin)] {
            let c = read(&file, true).unwrap();
            assert_eq!(c.cloud.iter().copied().collect::<Vec<_>>(), want);
            assert_eq!(c.colors, Some(vec![[255, 0, 7], [1, 4, 5]]));
            assert_eq!(read(&file, false).unwrap().colors, None);
        }
    }

    #[test]
    fn bad_files_name_what_is_wrong() {
        let err = |b: &[u8]| read(b, true).unwrap_err().to_string();
        assert!(err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n").contains("no y field"));
        assert!(err(&ply("ascii", b"3 0 1 2\n2 5 6\n1.5 255 -2")).contains("data ends in vertex 0 of 2"));
        assert!(err(&ply("ascii", b"2.5 0 1\n")).contains("list length 2.5"));
        assert!(err(&ply("ascii", b"0\n0\n1 256 2 3 0 0\n")).contains("colour 256 is outside 0..255"));
        assert!(err(b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n").contains("header line 3 (byte 21)"));
        assert!(err(b"plyx\n").contains("\"ply\""));
        assert!(err(&ply("binary_big_endian", &[3, 0, 0])).contains("data ends in face 0 of 2 (byte"));
    }

    #[test]
    fn streams_are_read_within_bounds() {
        let file = ply("ascii", b"3 0 1 2\n2 5 6\n1.5 255 -2 0.25 0 7\n-1e3 1 2 3 4 5\n");
        assert_eq!(read_from(&file[..], true).unwrap(), read(&file, true).unwrap());
        let endless = read_from(io::BufReader::new(io::repeat(0)), false).unwrap_err();
        assert_eq!(endless.to_string(), format!("header line 1 is longer than {MAX_LINE_BYTES} bytes"));
        let mut long = b"ply\ncomment ".to_vec();
        long.resize(long.len() + MAX_LINE_BYTES, b'x');
        long.extend_from_slice(b"\nend_header\n");
        assert_eq!(
            read(&long, false).unwrap_err().to_string(),
            format!("header line 2 (byte 4) is longer than {MAX_LINE_BYTES} bytes")
        );
    }

    /// Rows of an element without properties take no data, whatever their
    /// count: reading them must not loop over the count.
    #[test]
    fn an_element_without_properties_costs_nothing() {
        let f = b"ply\nformat ascii 1.0\nelement nothing 18446744073709551615\n\
                  element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
        assert_eq!(read(f, false).unwrap().cloud.len(), 1);
    }

    /// The example of `formats/ply.md`.
    #[test]
    fn a_binary_point_is_three_little_endian_floats() {
        let mut out = Vec::new();
        write(&[Point3::new(1.0, -2.0, 0.5)], false, &mut out).unwrap();
        let head = "ply\nformat binary_little_endian 1.0\ncomment written by octolinear\nelement vertex 1\n\
                    property float x\nproperty float y\nproperty float z\nend_header\n";
        assert_eq!(&out[..head.len()], head.as_bytes());
        assert_eq!(out[head.len()..], [0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x00, 0x3f]);
    }

    #[test]
    fn written_points_read_back_bit_for_bit() {
        let points = [Point3::new(0.1, -3.25e-7, 1e30), Point3::new(-0.0, 7.0, f32::MIN_POSITIVE)];
        for ascii in [false, true] {
            let mut out = Vec::new();
            write(&points, ascii, &mut out).unwrap();
            let back = read(&out, true).unwrap();
            let bits = |p: &Point3| p.to_array().map(f32::to_bits);
            assert_eq!(back.cloud.iter().map(bits).collect::<Vec<_>>(), points.iter().map(bits).collect::<Vec<_>>());
            assert_eq!(back.colors, None);
        }
    }
}
