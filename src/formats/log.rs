//! The plain-text log that OctoMap's `log2graph` converts (`ScanGraph::readPlainASCII`).
//!
//! ```text
//! NODE x y z roll pitch yaw
//! x y z
//! ...
//! ```
//! Reproduced quirks (see `formats/log.md`): lines starting with `#` or a
//! space are skipped; any line starting with `NODE` starts a node (its first
//! token is discarded); all seven numbers are read as `float`, the angles then
//! widened to double for `Pose6D(x, y, z, roll, pitch, yaw)`; tokens after the
//! expected ones are ignored; consecutive nodes are linked by
//! `connectPrevious` edges; and a final line without `\n` is ignored.
//!
//! Deliberate differences: node ids are 0, 1, 2, ... (OctoMap leaves them
//! uninitialised), and lines where OctoMap would store uninitialised or
//! zeroed values (too few or unparsable numbers, a `\r`-only line, points
//! before the first `NODE`) are errors instead of garbage or an empty graph.

use std::io::{self, BufRead, BufWriter, Write};

use super::bounded::{read_line, LineEnd, MAX_LINE_BYTES};
use super::graph::ScanGraph;
use super::xyz::{c_tokens, parse_c_float, parse_point, token_str, FloatError, XyzError};
use crate::geometry::{PointCloud, Pose6D};

/// Why a log could not be read. Lines count from 1.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// Opening or reading failed.
    #[error("I/O error at line {line}")]
    Io {
        /// The line being read (0 when the file could not be opened).
        line: u64,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// A point line comes before any `NODE` line.
    #[error("line {line}: point before the first NODE line")]
    PointBeforeNode {
        /// The line.
        line: u64,
    },
    /// A `NODE` line has fewer than 7 tokens, or a point line fewer than 3.
    #[error("line {line}: expected at least {expected} tokens, found {found}")]
    TooFewTokens {
        /// The line.
        line: u64,
        /// Tokens needed: 7 for `NODE` lines (the keyword and six numbers), 3 for points.
        expected: usize,
        /// Tokens found.
        found: usize,
    },
    /// A token is not a decimal number as C++ `>>` reads a float
    /// (`nan`, `inf` and hex numbers are refused).
    #[error("line {line}: {token:?} is not a decimal number")]
    NotANumber {
        /// The line.
        line: u64,
        /// The token as found.
        token: String,
    },
    /// A token overflows `f32`.
    #[error("line {line}: {token:?} is not finite as a float")]
    NotFinite {
        /// The line.
        line: u64,
        /// The token as found.
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

impl From<XyzError> for LogError {
    fn from(e: XyzError) -> Self {
        match e {
            XyzError::Io { line, source } => LogError::Io { line, source },
            XyzError::TokenCount { line, found } => LogError::TooFewTokens { line, expected: 3, found },
            XyzError::NotANumber { line, token } => LogError::NotANumber { line, token },
            XyzError::NotFinite { line, token } => LogError::NotFinite { line, token },
            XyzError::LineTooLong { line, limit } => LogError::LineTooLong { line, limit },
        }
    }
}

fn float(t: &[u8], line: u64) -> Result<f32, LogError> {
    parse_c_float(t).map_err(|e| match e {
        FloatError::NotANumber => LogError::NotANumber { line, token: token_str(t) },
        FloatError::NotFinite => LogError::NotFinite { line, token: token_str(t) },
    })
}

/// Parses a log into a graph exactly as `log2graph` builds it. A line
/// longer than [`MAX_LINE_BYTES`] is an error.
pub fn read(mut reader: impl BufRead) -> Result<ScanGraph, LogError> {
    let mut graph = ScanGraph::new();
    let mut current: Option<(Pose6D, PointCloud)> = None;
    let mut buf = Vec::new();
    let mut line = 0u64;
    let finish = |graph: &mut ScanGraph, node: Option<(Pose6D, PointCloud)>| {
        if let Some((pose, scan)) = node {
            graph.add_node(scan, pose);
            graph.connect_previous();
        }
    };
    loop {
        line += 1;
        match read_line(&mut reader, &mut buf, MAX_LINE_BYTES).map_err(|source| LogError::Io { line, source })? {
            LineEnd::Newline => {}
            LineEnd::TooLong => return Err(LogError::LineTooLong { line, limit: MAX_LINE_BYTES }),
            // getline hitting EOF (no '\n') ends the loop even if it read text.
            LineEnd::Eof | LineEnd::Unterminated => {
                finish(&mut graph, current.take());
                return Ok(graph);
            }
        }
        let text = &buf[..buf.len() - 1];
        if text.is_empty() || text[0] == b'#' || text[0] == b' ' {
            continue;
        }
        let tokens: Vec<&[u8]> = c_tokens(text).collect();
        if text.starts_with(b"NODE") {
            finish(&mut graph, current.take());
            if tokens.len() < 7 {
                return Err(LogError::TooFewTokens { line, expected: 7, found: tokens.len() });
            }
            let mut v = [0f32; 6];
            for (slot, t) in v.iter_mut().zip(&tokens[1..7]) {
                *slot = float(t, line)?;
            }
            let pose = Pose6D::from_euler(v[0], v[1], v[2], v[3] as f64, v[4] as f64, v[5] as f64);
            current = Some((pose, PointCloud::new()));
        } else {
            let Some((_, scan)) = current.as_mut() else {
                return Err(LogError::PointBeforeNode { line });
            };
            if tokens.len() < 3 {
                return Err(LogError::TooFewTokens { line, expected: 3, found: tokens.len() });
            }
            scan.push(parse_point(&tokens[..3], line)?);
        }
    }
}

/// Reads a log file (buffered).
pub fn read_file(path: impl AsRef<std::path::Path>) -> Result<ScanGraph, LogError> {
    let f = std::fs::File::open(path).map_err(|source| LogError::Io { line: 0, source })?;
    read(io::BufReader::with_capacity(1 << 16, f))
}

/// Writes a log `log2graph` can read. Lossy for poses: the rotation goes
/// through `toEuler` (floats) and back through the Euler constructor, so only
/// the points and translations round-trip exactly. Edges are not written
/// (reading recreates the chain edges).
pub fn write(graph: &ScanGraph, writer: impl Write) -> io::Result<()> {
    use super::xyz::format_f32 as f;
    let mut out = BufWriter::with_capacity(1 << 16, writer);
    writeln!(out, "# written by octolinear")?;
    for node in &graph.nodes {
        let t = node.pose.translation;
        let e = node.pose.rotation.to_euler();
        writeln!(out, "NODE {} {} {} {} {} {}", f(t.x), f(t.y), f(t.z), f(e.x), f(e.y), f(e.z))?;
        for (i, p) in node.scan.iter().enumerate() {
            if !p.is_finite() {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("node {} point {i} is not finite", node.id),
                ));
            }
            writeln!(out, "{} {} {}", f(p.x), f(p.y), f(p.z))?;
        }
    }
    out.flush()
}
