//! Point cloud files for `build --points`: PLY (ASCII, binary little or big
//! endian), PCD (ascii, binary, binary_compressed), LAS/LAZ and plain xyz,
//! each with a sensor pose.
//!
//! Colours (for `build --color`) are read from PLY's `red`, `green`, `blue`
//! vertex properties (integers 0..=255 of any integer type, or floats in
//! 0..=1, scaled by 255 and rounded) and from PCD's `rgb` or `rgba` field
//! (4 bytes holding `0x00RRGGBB` / `0xAARRGGBB` as PCL packs them, whether
//! typed `F`, `U` or `I`; in ASCII files an `F` field is the float whose
//! bits are the packed colour, as PCL prints it). Colours are only decoded
//! when asked for, so a file with odd colour values still builds a plain map.

use anyhow::{bail, Context, Result};
use octolinear::formats::xyz;
use octolinear::{Point3, PointCloud, Pose6D};
use std::path::Path;

/// An RGB colour per point.
pub type Colors = Vec<[u8; 3]>;

/// The points of a file and, when asked for and present, their colours.
pub struct Scan {
    pub cloud: PointCloud,
    /// One colour per point; `None` when not asked for or the file has none.
    pub colors: Option<Colors>,
}

/// Reads the points of a file, by extension; with `colors`, also the
/// points' colours where the format has them (PLY, PCD).
pub fn read_scan(path: &Path, colors: bool) -> Result<Scan> {
    let ext = super::common::extension(path, &["ply", "pcd", "las", "laz", "xyz", "txt"])?;
    let ctx = || format!("{}: not a valid .{ext} file", path.display());
    let plain = |cloud| Scan { cloud, colors: None };
    match ext.as_str() {
        "las" | "laz" => return read_las(path).map(plain).with_context(ctx),
        "xyz" | "txt" => {
            let f = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
            return xyz::read(std::io::BufReader::new(f)).map(plain).with_context(ctx);
        }
        _ => {}
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot open {}", path.display()))?;
    match ext.as_str() {
        "ply" => read_ply(&bytes, colors),
        _ => read_pcd(&bytes, colors),
    }
    .with_context(ctx)
}

// ----- scalar types shared by PLY and PCD ---------------------------------

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
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
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    fn ply(name: &str) -> Option<Scalar> {
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

    fn pcd(kind: &str, size: usize) -> Option<Scalar> {
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

    /// Decodes one value; `b` holds at least `size()` bytes.
    fn decode(self, b: &[u8], little: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().expect("length checked");
                (if little { <$t>::from_le_bytes(a) } else { <$t>::from_be_bytes(a) }) as f64
            }};
        }
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::I64 => get!(i64, 8),
            Scalar::U64 => get!(u64, 8),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

/// Splits off the text header ending with the line `end`; returns its
/// lines and the offset of the data.
fn header_lines<'a>(bytes: &'a [u8], end: &str, max_lines: usize) -> Result<(Vec<&'a str>, usize)> {
    let mut lines = Vec::new();
    let mut at = 0;
    while at < bytes.len() && lines.len() < max_lines {
        let stop = bytes[at..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |p| at + p);
        let line = std::str::from_utf8(&bytes[at..stop]).context("header is not text")?.trim_end_matches('\r').trim();
        at = (stop + 1).min(bytes.len());
        let done = line.split_whitespace().next() == Some(end);
        lines.push(line);
        if done {
            return Ok((lines, at));
        }
    }
    bail!("header has no {end:?} line")
}

fn xyz_index(names: &[&str]) -> Result<[usize; 3]> {
    let find = |n: &str| names.iter().position(|&x| x == n).with_context(|| format!("no {n} field"));
    Ok([find("x")?, find("y")?, find("z")?])
}

fn point(v: [f64; 3]) -> Point3 {
    Point3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

// ----- PLY -----------------------------------------------------------------

struct PlyProperty {
    name: String,
    scalar: Scalar,
    /// Count type of a list property.
    list: Option<Scalar>,
}

struct PlyElement {
    name: String,
    count: usize,
    props: Vec<PlyProperty>,
}

/// A colour channel's value as a byte: integers must lie in 0..=255,
/// floats in 0..=1 (scaled by 255, rounded).
fn color_byte(scalar: Scalar, v: f64, what: &str) -> Result<u8> {
    let float = matches!(scalar, Scalar::F32 | Scalar::F64);
    if float {
        if !(0.0..=1.0).contains(&v) {
            bail!("{what}: float colour {v} is outside 0..1");
        }
        Ok((v * 255.0).round() as u8)
    } else {
        if !(0.0..=255.0).contains(&v) {
            bail!("{what}: colour {v} is outside 0..255");
        }
        Ok(v as u8)
    }
}

/// The vertices of a PLY file (x, y, z of the `vertex` element) and, with
/// `want_colors`, their `red`, `green`, `blue` properties if all three exist.
pub fn read_ply(bytes: &[u8], want_colors: bool) -> Result<Scan> {
    let (lines, data) = header_lines(bytes, "end_header", 10_000)?;
    if lines.first() != Some(&"ply") {
        bail!("does not start with \"ply\"");
    }
    let mut format = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    for (n, line) in lines.iter().enumerate().skip(1) {
        let t: Vec<&str> = line.split_whitespace().collect();
        let bad = || format!("header line {}: {line:?}", n + 1);
        match t.first().copied() {
            Some("format") => {
                format = Some(match t.get(1).copied() {
                    Some("ascii") => None,
                    Some("binary_little_endian") => Some(true),
                    Some("binary_big_endian") => Some(false),
                    _ => bail!("{}: unknown format", bad()),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2).and_then(|c| c.parse().ok())) else {
                    bail!("{}", bad());
                };
                elements.push(PlyElement { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let e = elements.last_mut().with_context(|| format!("{}: property before any element", bad()))?;
                let p = if t.get(1) == Some(&"list") {
                    match (t.get(2).and_then(|s| Scalar::ply(s)), t.get(3).and_then(|s| Scalar::ply(s)), t.get(4)) {
                        (Some(c), Some(s), Some(name)) => {
                            PlyProperty { name: name.to_string(), scalar: s, list: Some(c) }
                        }
                        _ => bail!("{}: bad list property", bad()),
                    }
                } else {
                    match (t.get(1).and_then(|s| Scalar::ply(s)), t.get(2)) {
                        (Some(s), Some(name)) => PlyProperty { name: name.to_string(), scalar: s, list: None },
                        _ => bail!("{}: bad property", bad()),
                    }
                };
                e.props.push(p);
            }
            Some("comment") | Some("obj_info") | Some("end_header") | None => {}
            Some(_) => bail!("{}: unknown keyword", bad()),
        }
    }
    let format = format.context("header has no format line")?;
    let vi = elements.iter().position(|e| e.name == "vertex").context("no vertex element")?;
    let vertex = &elements[vi];
    let names: Vec<&str> = vertex.props.iter().map(|p| p.name.as_str()).collect();
    let idx = xyz_index(&names)?;
    if idx.iter().any(|&i| vertex.props[i].list.is_some()) {
        bail!("vertex x/y/z are lists");
    }
    // the colour properties, when asked for and all three present
    let rgb_idx = if want_colors {
        let find = |n: &str| names.iter().position(|&x| x == n);
        match (find("red"), find("green"), find("blue")) {
            (Some(r), Some(g), Some(b)) => {
                if [r, g, b].iter().any(|&i| vertex.props[i].list.is_some()) {
                    bail!("vertex red/green/blue are lists");
                }
                Some([r, g, b])
            }
            _ => None,
        }
    } else {
        None
    };
    let mut cloud = PointCloud::with_capacity(vertex.count.min(1 << 24));
    let mut colors = rgb_idx.map(|_| Vec::with_capacity(vertex.count.min(1 << 24)));
    // wanted vertex properties: x, y, z, then red, green, blue if read
    let wanted: Vec<usize> = idx.iter().chain(rgb_idx.iter().flatten()).copied().collect();
    let mut push_vertex = |values: &[f64], row: usize| -> Result<()> {
        cloud.push(point([values[0], values[1], values[2]]));
        if let (Some(colors), Some(rgb_idx)) = (colors.as_mut(), rgb_idx) {
            let mut c = [0u8; 3];
            for k in 0..3 {
                let p = &vertex.props[rgb_idx[k]];
                c[k] = color_byte(p.scalar, values[3 + k], &format!("vertex {row} {}", p.name))?;
            }
            colors.push(c);
        }
        Ok(())
    };
    let mut picked = vec![0f64; wanted.len()];
    match format {
        None => {
            let text = std::str::from_utf8(&bytes[data..]).context("ASCII data is not text")?;
            let mut tokens = text.split_whitespace();
            for (ei, e) in elements[..=vi].iter().enumerate() {
                for row in 0..e.count {
                    for (pi, p) in e.props.iter().enumerate() {
                        let mut next = || -> Result<f64> {
                            let t = tokens
                                .next()
                                .with_context(|| format!("data ends in {} {row} of {}", e.name, e.count))?;
                            t.parse::<f64>().ok().with_context(|| format!("{} {row}: {t:?} is not a number", e.name))
                        };
                        let v = next()?;
                        if p.list.is_some() {
                            for _ in 0..(v as usize) {
                                next()?;
                            }
                        }
                        if ei == vi {
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
            for (ei, e) in elements[..=vi].iter().enumerate() {
                for row in 0..e.count {
                    for (pi, p) in e.props.iter().enumerate() {
                        let truncated = || format!("data ends in {} {row} of {}", e.name, e.count);
                        let n = match p.list {
                            Some(c) => {
                                let b = bytes.get(at..at + c.size()).with_context(truncated)?;
                                at += c.size();
                                c.decode(b, little) as usize
                            }
                            None => 1,
                        };
                        let len = n.checked_mul(p.scalar.size()).with_context(truncated)?;
                        let b = bytes.get(at..at.saturating_add(len)).with_context(truncated)?;
                        if ei == vi && p.list.is_none() {
                            for (slot, &w) in picked.iter_mut().zip(&wanted) {
                                if w == pi {
                                    *slot = p.scalar.decode(b, little);
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
    Ok(Scan { cloud, colors })
}

// ----- PCD -----------------------------------------------------------------

/// LZF decompression (liblzf's format, as PCL's binary_compressed uses).
pub fn lzf_decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(out_len);
    let mut i = 0;
    while i < input.len() {
        let ctrl = usize::from(input[i]);
        i += 1;
        if ctrl < 32 {
            let n = ctrl + 1;
            let lit = input.get(i..i + n).context("LZF literal runs past the input")?;
            out.extend_from_slice(lit);
            i += n;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(i).context("LZF data ends in a back reference")?);
                i += 1;
            }
            len += 2;
            let low = usize::from(*input.get(i).context("LZF data ends in a back reference")?);
            i += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            if back > out.len() {
                bail!("LZF back reference before the start of the output");
            }
            let start = out.len() - back;
            for k in 0..len {
                let b = out[start + k];
                out.push(b);
            }
        }
        if out.len() > out_len {
            bail!("LZF data decompresses to more than the announced {out_len} bytes");
        }
    }
    if out.len() != out_len {
        bail!("LZF data decompresses to {} bytes, expected {out_len}", out.len());
    }
    Ok(out)
}

/// A colour packed by PCL (`0x00RRGGBB`, alpha or padding in the top byte).
fn unpack_pcl(v: u32) -> [u8; 3] {
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

/// The x, y, z fields of a PCD file and, with `want_colors`, its `rgb` or
/// `rgba` field if there is one.
pub fn read_pcd(bytes: &[u8], want_colors: bool) -> Result<Scan> {
    let (lines, data) = header_lines(bytes, "DATA", 1000)?;
    let (mut fields, mut sizes, mut types, mut counts) = (vec![], vec![], vec![], vec![]);
    let (mut points, mut width, mut height, mut kind) = (None, None, None, "");
    for line in &lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, rest)) = t.split_first() else {
            continue;
        };
        let nums = |what: &str| -> Result<Vec<usize>> {
            rest.iter().map(|s| s.parse().ok().with_context(|| format!("{what}: {s:?} is not a count"))).collect()
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
    if fields.is_empty() || sizes.len() != fields.len() || types.len() != fields.len() || counts.len() != fields.len() {
        bail!("FIELDS, SIZE, TYPE and COUNT do not match");
    }
    let n = match (points, width, height) {
        (Some(p), _, _) => p,
        (None, Some(w), Some(h)) => w.checked_mul(h).context("WIDTH x HEIGHT overflows")?,
        _ => bail!("no POINTS (or WIDTH and HEIGHT) line"),
    };
    let scalars: Vec<Scalar> = types
        .iter()
        .zip(&sizes)
        .map(|(t, &s)| Scalar::pcd(t, s).with_context(|| format!("unknown TYPE {t} of SIZE {s}")))
        .collect::<Result<_>>()?;
    let idx = xyz_index(&fields)?;
    let rgb = if want_colors { fields.iter().position(|&f| f == "rgb" || f == "rgba") } else { None };
    if let Some(c) = rgb {
        if sizes[c] != 4 || counts[c] != 1 {
            bail!(
                "field {} has SIZE {} COUNT {}; a packed colour needs SIZE 4 COUNT 1",
                fields[c],
                sizes[c],
                counts[c]
            );
        }
    }
    let mut colors = rgb.map(|_| Vec::with_capacity(n.min(1 << 24)));
    // byte offset of each field within a point, and the point size
    let mut offsets = Vec::with_capacity(fields.len());
    if let Some(&i) = idx.iter().find(|&&i| counts[i] == 0) {
        bail!("field {} has COUNT 0", fields[i]);
    }
    let mut stride = 0usize;
    for (s, c) in sizes.iter().zip(&counts) {
        offsets.push(stride);
        stride = s.checked_mul(*c).and_then(|b| stride.checked_add(b)).context("point size overflows")?;
    }
    let mut cloud = PointCloud::with_capacity(n.min(1 << 24));
    match kind {
        "ascii" => {
            // one point per line; each field takes COUNT tokens
            let text = std::str::from_utf8(&bytes[data..]).context("ascii data is not text")?;
            let mut token_of = Vec::with_capacity(fields.len());
            let mut at = 0;
            for &c in &counts {
                token_of.push(at);
                at += c;
            }
            let mut rows = text.lines().filter(|l| !l.trim().is_empty());
            for row in 0..n {
                let line = rows.next().with_context(|| format!("data ends after {row} of {n} points"))?;
                let t: Vec<&str> = line.split_whitespace().collect();
                let v = idx.map(|i| t.get(token_of[i]).map(|s| s.parse::<f64>()));
                match v {
                    [Some(Ok(x)), Some(Ok(y)), Some(Ok(z))] => cloud.push(point([x, y, z])),
                    _ => bail!("point {row}: cannot read x y z from {line:?}"),
                }
                if let (Some(colors), Some(c)) = (colors.as_mut(), rgb) {
                    let t = t.get(token_of[c]).copied().unwrap_or("");
                    let packed = match types[c] {
                        "F" => t.parse::<f32>().ok().filter(|v| !v.is_nan()).map(f32::to_bits),
                        "U" => t.parse::<u32>().ok(),
                        _ => t.parse::<i32>().ok().map(|v| v as u32),
                    };
                    let packed =
                        packed.with_context(|| format!("point {row}: cannot read {} from {t:?}", fields[c]))?;
                    colors.push(unpack_pcl(packed));
                }
            }
        }
        "binary" => {
            let need = n.checked_mul(stride).context("size overflows")?;
            let d = bytes
                .get(data..data.saturating_add(need))
                .with_context(|| format!("binary data holds {} bytes, {n} points need {need}", bytes.len() - data))?;
            for row in d.chunks_exact(stride) {
                cloud.push(point(idx.map(|i| scalars[i].decode(&row[offsets[i]..], true))));
                if let (Some(colors), Some(c)) = (colors.as_mut(), rgb) {
                    let b = &row[offsets[c]..offsets[c] + 4];
                    colors.push(unpack_pcl(u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
                }
            }
        }
        "binary_compressed" => {
            let head = bytes.get(data..data + 8).context("compressed data has no size words")?;
            let comp = u32::from_le_bytes(head[..4].try_into().expect("4 bytes")) as usize;
            let raw = u32::from_le_bytes(head[4..].try_into().expect("4 bytes")) as usize;
            let need = n.checked_mul(stride).context("size overflows")?;
            if raw != need {
                bail!("compressed data decompresses to {raw} bytes, {n} points need {need}");
            }
            let c = bytes
                .get(data + 8..data + 8 + comp)
                .with_context(|| format!("compressed data is shorter than {comp} bytes"))?;
            let d = lzf_decompress(c, raw)?;
            // fields are stored one after the other (structure of arrays)
            let mut field_start = Vec::with_capacity(fields.len());
            let mut at = 0;
            for (s, c) in sizes.iter().zip(&counts) {
                field_start.push(at);
                at += n * s * c;
            }
            for row in 0..n {
                cloud.push(point(idx.map(|i| {
                    let at = field_start[i] + row * sizes[i] * counts[i];
                    scalars[i].decode(&d[at..], true)
                })));
                if let (Some(colors), Some(c)) = (colors.as_mut(), rgb) {
                    let at = field_start[c] + row * 4;
                    let b = &d[at..at + 4];
                    colors.push(unpack_pcl(u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
                }
            }
        }
        other => bail!("unknown DATA kind {other:?}"),
    }
    Ok(Scan { cloud, colors })
}

// ----- LAS / LAZ -----------------------------------------------------------

fn read_las(path: &Path) -> Result<PointCloud> {
    let mut reader = las::Reader::from_path(path)?;
    let data = reader.read_all()?;
    let mut cloud = PointCloud::new();
    for p in data.points() {
        let p = p?;
        cloud.push(point([p.x, p.y, p.z]));
    }
    Ok(cloud)
}

// ----- poses ---------------------------------------------------------------

/// A pose from `x y z roll pitch yaw`.
pub fn pose(v: &[f64]) -> Result<Pose6D> {
    if v.len() != 6 || v.iter().any(|c| !c.is_finite()) {
        bail!("a pose needs six finite numbers (x y z roll pitch yaw), got {v:?}");
    }
    Ok(Pose6D::from_euler(v[0] as f32, v[1] as f32, v[2] as f32, v[3], v[4], v[5]))
}

/// A trajectory file: one pose `x y z roll pitch yaw` per line (blank
/// lines and lines starting with `#` skipped).
pub fn read_trajectory(path: &Path) -> Result<Vec<Pose6D>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut poses = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split_whitespace().map(str::parse).collect();
        let v = v.ok().with_context(|| format!("{} line {}: {line:?} is not six numbers", path.display(), n + 1))?;
        poses.push(pose(&v).with_context(|| format!("{} line {}", path.display(), n + 1))?);
    }
    Ok(poses)
}
