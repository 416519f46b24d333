//! Inputs of `build` and `eval`: `.graph` files read scan by scan, and
//! point cloud files for `build --points`: PLY (ASCII, binary little or big
//! endian), PCD (ascii, binary, binary_compressed), LAS/LAZ and plain xyz,
//! each with a sensor pose. Colours (for `build --color`) come from PLY and
//! PCD files (the readers in `octolinear::formats` say how). `-` stands for
//! standard input; pipes, FIFOs and `/dev/stdin` are read as streams.

use anyhow::{bail, Context, Result};
use octolinear::formats::bounded::{self, read_line, LineEnd, MAX_LINE_BYTES};
use octolinear::formats::graph::{GraphInput, ScanReader};
use octolinear::formats::{pcd, ply, xyz, ColoredCloud as Scan};
use octolinear::{Point3, PointCloud, Pose6D};
use std::io::{BufRead, BufReader, Read, Seek};
use std::path::Path;

/// An RGB colour per point.
pub type Colors = Vec<[u8; 3]>;

/// How an input is named in messages: `-` is standard input.
pub fn name(path: &Path) -> String {
    if is_stdin(path) {
        "standard input".to_string()
    } else {
        path.display().to_string()
    }
}

fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// A `.graph` read scan by scan from a file, pipe or FIFO, or from standard
/// input for `-`. A regular file is memory-mapped a window at a time and
/// its counts are checked against its length before reading; the others
/// are read as streams and checked as their data arrives.
pub fn open_graph(path: &Path) -> Result<ScanReader<GraphInput>> {
    let input = if is_stdin(path) {
        GraphInput::stream(BufReader::with_capacity(1 << 16, std::io::stdin()))
    } else {
        GraphInput::open(path).with_context(|| format!("cannot open {}", path.display()))?
    };
    let len = input.file_len();
    ScanReader::with_len(input, len).with_context(|| format!("cannot read {}", name(path)))
}

/// Point formats, by extension or by content.
#[derive(Clone, Copy, PartialEq, Eq)]
enum PointFormat {
    Ply,
    Pcd,
    Las,
    Xyz,
}

/// The format of a file's first bytes: the PLY magic, the LAS signature,
/// a PCD header keyword after `#` comment lines; anything else is xyz text.
fn sniff(bytes: &[u8]) -> PointFormat {
    if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
        return PointFormat::Ply;
    }
    if bytes.starts_with(b"LASF") {
        return PointFormat::Las;
    }
    let first = bytes.split(|&b| b == b'\n').map(|l| l.trim_ascii()).find(|l| !l.is_empty() && l[0] != b'#');
    let keyword = first.and_then(|l| l.split(|b| b.is_ascii_whitespace()).next()).unwrap_or_default();
    const PCD_KEYS: [&[u8]; 10] =
        [b"VERSION", b"FIELDS", b"SIZE", b"TYPE", b"COUNT", b"WIDTH", b"HEIGHT", b"VIEWPOINT", b"POINTS", b"DATA"];
    if PCD_KEYS.contains(&keyword) {
        PointFormat::Pcd
    } else {
        PointFormat::Xyz
    }
}

/// Bytes a stream's format is recognised by when its name has no
/// extension: its first line, at most [`MAX_LINE_BYTES`].
const SNIFF_BYTES: usize = MAX_LINE_BYTES;

/// Reads the points of a `--points` argument; with `colors`, also the
/// points' colours where the format has them (PLY, PCD). The format comes
/// from the extension; a name without one (`-`, `/dev/stdin`, a `<(...)`
/// pipe) is recognised by its first bytes (see [`sniff`]). The file is
/// opened once: a regular file is read to its length (LAS/LAZ in batches,
/// its header's offsets and lengths checked against its size first), a
/// pipe, FIFO or device as a stream, within the bounds of
/// [`octolinear::formats::bounded`]; text files are read line by line.
pub fn read_scan(path: &Path, colors: bool) -> Result<Scan> {
    let ext = if path.extension().is_some() && !is_stdin(path) {
        Some(super::common::extension(path, &["ply", "pcd", "las", "laz", "xyz", "txt"])?)
    } else {
        None
    };
    let format = ext.as_deref().map(|e| match e {
        "ply" => PointFormat::Ply,
        "pcd" => PointFormat::Pcd,
        "las" | "laz" => PointFormat::Las,
        _ => PointFormat::Xyz,
    });
    let name = name(path);
    let ctx = |format: PointFormat| {
        let described = match (&ext, format) {
            (Some(e), _) => format!(".{e}"),
            (None, PointFormat::Ply) => "PLY".into(),
            (None, PointFormat::Pcd) => "PCD".into(),
            (None, PointFormat::Las) => "LAS/LAZ".into(),
            (None, PointFormat::Xyz) => "xyz".into(),
        };
        format!("{name}: not a valid {described} file")
    };
    let plain = |cloud| Scan { cloud, colors: None };
    let (source, regular): (Box<dyn Read + Send>, Option<std::fs::File>) = if is_stdin(path) {
        (Box::new(std::io::stdin()), None)
    } else {
        let file = std::fs::File::open(path).with_context(|| format!("cannot open {name}"))?;
        let regular = file.metadata().with_context(|| format!("cannot read {name}"))?.is_file();
        if regular {
            let again = file.try_clone().with_context(|| format!("cannot read {name}"))?;
            (Box::new(file), Some(again))
        } else {
            (Box::new(file), None)
        }
    };
    let mut reader = BufReader::with_capacity(1 << 16, source);
    let (format, mut reader): (_, Box<dyn BufRead + Send>) = match format {
        Some(f) => (f, Box::new(reader)),
        None => {
            let mut head = Vec::new();
            (&mut reader)
                .take(SNIFF_BYTES as u64)
                .read_to_end(&mut head)
                .with_context(|| format!("cannot read {name}"))?;
            (sniff(&head), Box::new(std::io::Cursor::new(head).chain(reader)))
        }
    };
    let read_whole = |mut reader: Box<dyn BufRead + Send>| -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        reader.read_to_end(&mut bytes).with_context(|| format!("cannot read {name}"))?;
        Ok(bytes)
    };
    match (format, regular) {
        (PointFormat::Las, Some(file)) => without_panics(|| read_las(file)).map(plain),
        (PointFormat::Las, None) => {
            // the signature first: a stream of anything else is not read on
            let mut signature = Vec::with_capacity(4);
            (&mut reader).take(4).read_to_end(&mut signature).with_context(|| format!("cannot read {name}"))?;
            if signature != b"LASF" {
                bail!("{name}: not a LAS/LAZ file: it does not start with \"LASF\"");
            }
            let bytes = bounded::read_stream(std::io::Cursor::new(signature).chain(reader), bounded::MAX_STREAM_BYTES)
                .with_context(|| ctx(PointFormat::Las))?;
            without_panics(|| read_las(std::io::Cursor::new(bytes))).map(plain)
        }
        (PointFormat::Xyz, _) => xyz::read(&mut reader).map(plain).map_err(anyhow::Error::from),
        (PointFormat::Ply, Some(_)) => ply::read(&read_whole(reader)?, colors).map_err(anyhow::Error::from),
        (PointFormat::Ply, None) => ply::read_from(reader, colors).map_err(anyhow::Error::from),
        (PointFormat::Pcd, Some(_)) => pcd::read(&read_whole(reader)?, colors).map_err(anyhow::Error::from),
        (PointFormat::Pcd, None) => pcd::read_from(reader, colors).map_err(anyhow::Error::from),
    }
    .with_context(|| ctx(format))
}

/// Refuses a pipe, FIFO or device (or `-`) named more than once among
/// `paths` (the arguments of `flag`): it can be read only once, and a
/// FIFO opened again would wait for a writer that never comes. Regular
/// files may repeat.
pub fn check_read_once(paths: &[impl AsRef<Path>], flag: &str) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let mut seen = std::collections::HashSet::new();
    for path in paths {
        let path = path.as_ref();
        let id = if is_stdin(path) {
            None
        } else {
            match std::fs::metadata(path) {
                Ok(m) if !m.is_file() => Some((m.dev(), m.ino())),
                // regular files, and names that opening will report
                _ => continue,
            }
        };
        if !seen.insert(id) {
            bail!("{flag} names {} more than once: a pipe, FIFO or device is read only once", name(path));
        }
    }
    Ok(())
}

// ----- LAS / LAZ -----------------------------------------------------------

fn read_las(mut source: impl Read + Seek + Send + Sync + 'static) -> Result<PointCloud> {
    check_las_layout(&mut source)?;
    check_laz_chunk_table(&mut source)?;
    source.rewind()?;
    let mut reader = las::Reader::new(BufReader::with_capacity(1 << 16, source))?;
    // in batches: `read_all` reserves what the header's point count says,
    // which a damaged header makes terabytes (an allocation failure aborts)
    let mut batch = las::PointDataBuilder::new().for_header(reader.header()).build();
    let mut cloud = PointCloud::new();
    while reader.fill_points(1 << 16, &mut batch)? > 0 {
        for p in batch.points() {
            let p = p?;
            cloud.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
        }
    }
    Ok(cloud)
}

/// Refuses a LAS/LAZ file whose header places records beyond the file's
/// end: the las crate allocates what a (extended) variable length record's
/// length says before reading it, so a 455-byte file claiming 2^40 bytes
/// would abort the process. Checked against the file's length: the header
/// size, the offset to the point data, each VLR (54 bytes and its length,
/// from the end of the header), the point records of an uncompressed file
/// (count times record length from the offset to the point data), and in
/// LAS 1.4 each EVLR (60 bytes and its length, from the start of the
/// first). A file too short for a header, or without the `LASF`
/// signature, is left to the las crate's own checks.
fn check_las_layout(f: &mut (impl Read + Seek)) -> Result<()> {
    use std::io::SeekFrom;
    let len = f.seek(SeekFrom::End(0))?;
    f.rewind()?;
    let mut head = Vec::with_capacity(375);
    f.by_ref().take(375).read_to_end(&mut head)?;
    if head.len() < 227 || &head[..4] != b"LASF" {
        return Ok(());
    }
    let le = |at: usize, n: usize| -> Option<u64> {
        let b = head.get(at..at + n)?;
        Some(b.iter().rev().fold(0u64, |v, &b| v << 8 | u64::from(b)))
    };
    let version = (head[24], head[25]);
    let version_size = match version {
        v if v <= (1, 2) => 227,
        (1, 3) => 235,
        _ => 375,
    };
    let header_size = le(94, 2).expect("in the first 227 bytes");
    let data = le(96, 4).expect("in the first 227 bytes");
    let vlrs = le(100, 4).expect("in the first 227 bytes");
    let compressed = head[104] & 0x80 != 0;
    let record = le(105, 2).expect("in the first 227 bytes");
    let beyond = |field: &str, value: u64| {
        anyhow::anyhow!("the LAS header's {field} ({value}) lies beyond the end of the file ({len} bytes)")
    };
    if header_size > len {
        return Err(beyond("header size", header_size));
    }
    if data > len {
        return Err(beyond("offset to point data", data));
    }
    let mut at = header_size.max(version_size);
    if vlrs > len.saturating_sub(at) / 54 {
        bail!("the LAS header's number of VLRs ({vlrs}) needs more than the file's {len} bytes (54 bytes a record)");
    }
    let mut word = [0u8; 8];
    let mut length_at = |f: &mut dyn ReadSeek, offset: u64, n: usize| -> Result<u64> {
        f.seek(SeekFrom::Start(offset))?;
        f.read_exact(&mut word[..n])?;
        Ok(word[..n].iter().rev().fold(0u64, |v, &b| v << 8 | u64::from(b)))
    };
    for i in 0..vlrs {
        if at + 54 > len {
            bail!("VLR {i} at byte {at} runs past the end of the file ({len} bytes)");
        }
        let length = length_at(f, at + 20, 2)?;
        at += 54 + length;
        if at > len {
            bail!("VLR {i}'s record length ({length}) runs past the end of the file ({len} bytes)");
        }
    }
    let points = match le(107, 4).expect("in the first 227 bytes") {
        0 if version >= (1, 4) => le(247, 8).unwrap_or(0),
        n => n,
    };
    if !compressed {
        let need = points.checked_mul(record).and_then(|b| b.checked_add(data));
        if need.is_none_or(|end| end > len) {
            bail!(
                "the LAS header's {points} point records of {record} bytes from byte {data} need more than the file's {len} bytes"
            );
        }
    }
    let (Some(start), Some(count)) = (le(235, 8), le(243, 4)) else { return Ok(()) };
    if version < (1, 4) || start == 0 || count == 0 {
        return Ok(());
    }
    if start > len {
        return Err(beyond("start of the first EVLR", start));
    }
    if count > (len - start) / 60 {
        bail!("the LAS header's number of EVLRs ({count}) needs more than the file's {len} bytes (60 bytes a record)");
    }
    let mut at = start;
    for i in 0..count {
        if at + 60 > len {
            bail!("EVLR {i} at byte {at} runs past the end of the file ({len} bytes)");
        }
        let length = length_at(f, at + 20, 8)?;
        match (at + 60).checked_add(length) {
            Some(end) if end <= len => at = end,
            _ => bail!("EVLR {i}'s record length ({length}) runs past the end of the file ({len} bytes)"),
        }
    }
    Ok(())
}

/// A source the LAS checks read and seek in.
trait ReadSeek: Read + Seek {}
impl<T: Read + Seek> ReadSeek for T {}

/// Runs the LAS/LAZ reader, whose decompressor panics on some damaged
/// data (the laz crate's byte slicing), and makes such a panic an error,
/// without the panic hook's message on stderr.
fn without_panics<T>(read: impl FnOnce() -> Result<T>) -> Result<T> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(read));
    std::panic::set_hook(hook);
    r.unwrap_or_else(|p| {
        let why = p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned());
        bail!("the LAS/LAZ reader failed on damaged data ({})", why.as_deref().unwrap_or("no message"))
    })
}

/// Refuses a LAZ file whose chunk table announces more chunks than its
/// bytes can hold: the laz crate reserves that many entries before reading
/// them, and an allocation failure aborts the process. Each chunk starts
/// with one uncompressed point record, so it takes at least that many bytes.
/// The table is found as the laz crate finds it: its offset is the first
/// 8 bytes of the point data, or the file's last 8 bytes when those do not
/// point past them. Other files, and files too short to say, are left to
/// the las crate's own checks.
fn check_laz_chunk_table(f: &mut (impl Read + Seek)) -> Result<()> {
    use std::io::SeekFrom;
    let len = f.seek(SeekFrom::End(0))?;
    let mut at = |offset: u64, buf: &mut [u8]| -> Option<()> {
        f.seek(SeekFrom::Start(offset)).ok()?;
        f.read_exact(buf).ok()
    };
    let mut head = [0u8; 107];
    if at(0, &mut head).is_none() || &head[..4] != b"LASF" || head[104] & 0xc0 == 0 {
        return Ok(());
    }
    let data = u64::from(u32::from_le_bytes(head[96..100].try_into().expect("4 bytes")));
    let record = u64::from(u16::from_le_bytes(head[105..107].try_into().expect("2 bytes"))).max(1);
    let mut word = [0u8; 8];
    let Some(()) = at(data, &mut word) else { return Ok(()) };
    let mut table = i64::from_le_bytes(word);
    if table <= data as i64 {
        let Some(()) = at(len.saturating_sub(8), &mut word) else { return Ok(()) };
        table = i64::from_le_bytes(word);
    }
    let mut counts = [0u8; 8];
    if table <= data as i64 || at(table as u64, &mut counts).is_none() {
        return Ok(());
    }
    let chunks = u64::from(u32::from_le_bytes(counts[4..].try_into().expect("4 bytes")));
    if chunks > len / record {
        bail!("the LAZ chunk table announces {chunks} chunks, more than the {len} bytes of the file can hold");
    }
    Ok(())
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
/// lines and lines starting with `#` skipped), each line at most
/// [`MAX_LINE_BYTES`].
pub fn read_trajectory(path: &Path) -> Result<Vec<Pose6D>> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let mut poses = Vec::new();
    let mut buf = Vec::new();
    for n in 1.. {
        let end = read_line(&mut reader, &mut buf, MAX_LINE_BYTES)
            .with_context(|| format!("cannot read {} line {n}", path.display()))?;
        match end {
            LineEnd::Eof => break,
            LineEnd::TooLong => bail!("{} line {n} is longer than {MAX_LINE_BYTES} bytes", path.display()),
            LineEnd::Newline | LineEnd::Unterminated => {}
        }
        let line = std::str::from_utf8(&buf).with_context(|| format!("{} line {n} is not text", path.display()))?;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split_whitespace().map(str::parse).collect();
        let v = v.ok().with_context(|| format!("{} line {n}: {line:?} is not six numbers", path.display()))?;
        poses.push(pose(&v).with_context(|| format!("{} line {n}", path.display()))?);
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_recognised_by_their_first_bytes() {
        let sniffed = |text: &[u8]| match sniff(text) {
            PointFormat::Ply => "ply",
            PointFormat::Pcd => "pcd",
            PointFormat::Las => "las",
            PointFormat::Xyz => "xyz",
        };
        assert_eq!(sniffed(b"ply\nformat ascii 1.0\n"), "ply");
        assert_eq!(sniffed(b"ply\r\nformat ascii 1.0\r\n"), "ply");
        assert_eq!(sniffed(b"LASF\x00\x00"), "las");
        assert_eq!(sniffed(b"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n"), "pcd");
        assert_eq!(sniffed(b"FIELDS x y z\n"), "pcd");
        assert_eq!(sniffed(b"# x y z\n\n1 2 3\n"), "xyz");
        assert_eq!(sniffed(b"1,2,3\n"), "xyz");
        assert_eq!(sniffed(b""), "xyz");
        // a text file that merely mentions a keyword later is still xyz
        assert_eq!(sniffed(b"1 2 3\nVERSION\n"), "xyz");
    }
}
