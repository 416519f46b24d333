//! OctoMap `.graph` files (`ScanGraph::readBinary` / `writeBinary`).
//!
//! Layout (little endian, see `formats/graph.md`): `u32 n_nodes`, nodes,
//! `u32 n_edges`, edges. Vectors are `i32 3` + 3 x f64, quaternions `i32 4` +
//! 4 x f64 (u, x, y, z); all values are floats widened to double, and reading
//! rounds them back to float exactly like OctoMap's `(float) val`.
//!
//! Differences from OctoMap, all on inputs OctoMap mishandles: a wrong `3`/`4`
//! marker, a truncated file or an impossible count is an error here, whereas
//! OctoMap ignores markers and silently keeps a partial graph. Counts never
//! drive an allocation larger than the data actually present.

use std::fs;
use std::io::{self, BufWriter, Read, Write};
use std::path::Path;

use crate::geometry::{graph2tree_transform, Point3, PointCloud, Pose6D, Quaternion};

/// One scan: points in the sensor frame plus the pose they were taken from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanNode {
    pub id: u32,
    pub pose: Pose6D,
    pub scan: PointCloud,
}

impl ScanNode {
    /// World-frame points and sensor origin exactly as `graph2tree` computes them.
    pub fn graph2tree(&self) -> (PointCloud, Point3) {
        graph2tree_transform(&self.pose, &self.scan)
    }
}

/// `graph2tree`'s per-scan transform; see [`graph2tree_transform`].
pub fn graph2tree_scan(node: &ScanNode) -> (PointCloud, Point3) {
    node.graph2tree()
}

/// A constraint between two nodes, referenced by id as in the file. Ids are
/// not checked against the nodes (OctoMap only prints an error for them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanEdge {
    pub first: u32,
    pub second: u32,
    pub constraint: Pose6D,
    pub weight: f64,
}

/// OctoMap's `ScanGraph`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanGraph {
    pub nodes: Vec<ScanNode>,
    pub edges: Vec<ScanEdge>,
}

impl ScanGraph {
    pub fn new() -> Self {
        Self::default()
    }

    /// `ScanGraph::addNode`: the id is the node count before insertion.
    pub fn add_node(&mut self, scan: PointCloud, pose: Pose6D) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(ScanNode { id, pose, scan });
        id
    }

    /// `ScanGraph::connectPrevious`: edge from the second-to-last to the last
    /// node with constraint `first.pose.inv() * second.pose`, weight 1.
    pub fn connect_previous(&mut self) {
        let n = self.nodes.len();
        if n >= 2 {
            let (a, b) = (&self.nodes[n - 2], &self.nodes[n - 1]);
            self.edges.push(ScanEdge { first: a.id, second: b.id, constraint: a.pose.inv() * b.pose, weight: 1.0 });
        }
    }

    /// First node with this id (`getNodeByID`).
    pub fn node_by_id(&self, id: u32) -> Option<&ScanNode> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// Total number of points over all scans.
    pub fn num_points(&self) -> usize {
        self.nodes.iter().map(|n| n.scan.len()).sum()
    }
}

/// Why a `.graph` file could not be read. Offsets are bytes from the start.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    #[error("I/O error at byte offset {offset}: {source}")]
    Io {
        offset: u64,
        #[source]
        source: io::Error,
    },
    #[error("input ends at byte offset {offset} inside {context} ({missing} more bytes needed)")]
    Truncated { offset: u64, missing: u64, context: String },
    #[error("marker {found} at byte offset {offset} in {context}, expected {expected}")]
    BadMarker { offset: u64, expected: i32, found: i32, context: String },
    #[error("{what} count {count} at byte offset {offset} needs at least {needed} bytes, only {remaining} remain")]
    CountTooLarge { offset: u64, what: &'static str, count: u32, needed: u64, remaining: u64 },
}

const POINT_BYTES: usize = 4 + 3 * 8;
const POSE_BYTES: usize = POINT_BYTES + 4 + 4 * 8;
/// Smallest node: empty cloud, pose, id.
const MIN_NODE_BYTES: u64 = 4 + POSE_BYTES as u64 + 4;
const EDGE_BYTES: usize = 4 + 4 + POSE_BYTES + 8;
/// Points decoded per read call; bounds the scratch buffer.
const POINT_CHUNK: usize = 4096;
/// Without a known input length, never reserve more than this many elements up front.
const BLIND_RESERVE: usize = 1 << 14;

/// Byte source that tracks the offset and, when known, the total length.
struct Input<R> {
    inner: R,
    offset: u64,
    len: Option<u64>,
}

impl<R: Read> Input<R> {
    /// Fills `buf` completely or reports where the input ended.
    fn fill(&mut self, buf: &mut [u8], context: &dyn Fn(usize) -> String) -> Result<(), GraphError> {
        let mut filled = 0;
        while filled < buf.len() {
            match self.inner.read(&mut buf[filled..]) {
                Ok(0) => {
                    return Err(GraphError::Truncated {
                        offset: self.offset + filled as u64,
                        missing: (buf.len() - filled) as u64,
                        context: context(filled),
                    })
                }
                Ok(n) => filled += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(source) => return Err(GraphError::Io { offset: self.offset + filled as u64, source }),
            }
        }
        self.offset += buf.len() as u64;
        Ok(())
    }

    fn u32(&mut self, context: &dyn Fn(usize) -> String) -> Result<u32, GraphError> {
        let mut b = [0u8; 4];
        self.fill(&mut b, context)?;
        Ok(u32::from_le_bytes(b))
    }

    /// Checks that `count` items of at least `each` bytes (+ `tail`) can fit.
    fn check_count(&self, what: &'static str, count: u32, each: u64, tail: u64) -> Result<(), GraphError> {
        if let Some(len) = self.len {
            let remaining = len.saturating_sub(self.offset);
            let needed = count as u64 * each + tail;
            if needed > remaining {
                return Err(GraphError::CountTooLarge { offset: self.offset - 4, what, count, needed, remaining });
            }
        }
        Ok(())
    }

    fn reserve_hint(&self, count: u32) -> usize {
        if self.len.is_some() {
            count as usize // already checked against the input length
        } else {
            (count as usize).min(BLIND_RESERVE)
        }
    }
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    f64::from_le_bytes(a)
}

fn i32_at(b: &[u8], at: usize) -> i32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[at..at + 4]);
    i32::from_le_bytes(a)
}

fn check_marker(found: i32, expected: i32, offset: u64, context: impl Fn() -> String) -> Result<(), GraphError> {
    if found == expected {
        Ok(())
    } else {
        Err(GraphError::BadMarker { offset, expected, found, context: context() })
    }
}

/// Decodes a `Vector3` record (marker + 3 doubles) at `at`.
fn vector_at(b: &[u8], at: usize, base: u64, context: &dyn Fn() -> String) -> Result<Point3, GraphError> {
    check_marker(i32_at(b, at), 3, base + at as u64, context)?;
    Ok(Point3::new(f64_at(b, at + 4) as f32, f64_at(b, at + 12) as f32, f64_at(b, at + 20) as f32))
}

fn read_pose<R: Read>(input: &mut Input<R>, context: &dyn Fn() -> String) -> Result<Pose6D, GraphError> {
    let mut b = [0u8; POSE_BYTES];
    let base = input.offset;
    input.fill(&mut b, &|_| context())?;
    let t = vector_at(&b, 0, base, &|| format!("translation of {}", context()))?;
    check_marker(i32_at(&b, POINT_BYTES), 4, base + POINT_BYTES as u64, || format!("rotation of {}", context()))?;
    let q = |i: usize| f64_at(&b, POINT_BYTES + 4 + 8 * i) as f32;
    Ok(Pose6D::new(t, Quaternion::new(q(0), q(1), q(2), q(3))))
}

fn read_cloud<R: Read>(input: &mut Input<R>, node: usize) -> Result<PointCloud, GraphError> {
    let count = input.u32(&|_| format!("point count of node {node}"))?;
    input.check_count("point", count, POINT_BYTES as u64, POSE_BYTES as u64 + 4)?;
    let mut cloud = PointCloud::with_capacity(input.reserve_hint(count));
    let mut buf = vec![0u8; POINT_CHUNK.min(count as usize) * POINT_BYTES];
    let mut done = 0usize;
    let total = count as usize;
    while done < total {
        let n = (total - done).min(POINT_CHUNK);
        let chunk = &mut buf[..n * POINT_BYTES];
        let base = input.offset;
        input.fill(chunk, &|filled| format!("point {} of node {node}", done + filled / POINT_BYTES)).map_err(|e| {
            match e {
                // Report what the interrupted point lacks, not the whole chunk.
                GraphError::Truncated { offset, context, .. } => GraphError::Truncated {
                    offset,
                    missing: (POINT_BYTES - (offset - base) as usize % POINT_BYTES) as u64,
                    context,
                },
                e => e,
            }
        })?;
        for i in 0..n {
            let ctx = || format!("point {} of node {node}", done + i);
            cloud.push(vector_at(chunk, i * POINT_BYTES, base, &ctx)?);
        }
        done += n;
    }
    Ok(cloud)
}

fn read_input<R: Read>(mut input: Input<R>) -> Result<ScanGraph, GraphError> {
    let n_nodes = input.u32(&|_| "node count".to_string())?;
    input.check_count("node", n_nodes, MIN_NODE_BYTES, 4)?;
    let mut nodes = Vec::with_capacity(input.reserve_hint(n_nodes));
    for i in 0..n_nodes as usize {
        let scan = read_cloud(&mut input, i)?;
        let pose = read_pose(&mut input, &|| format!("pose of node {i}"))?;
        let id = input.u32(&|_| format!("id of node {i}"))?;
        nodes.push(ScanNode { id, pose, scan });
    }
    let n_edges = input.u32(&|_| "edge count".to_string())?;
    input.check_count("edge", n_edges, EDGE_BYTES as u64, 0)?;
    let mut edges = Vec::with_capacity(input.reserve_hint(n_edges));
    for i in 0..n_edges as usize {
        let mut ids = [0u8; 8];
        input.fill(&mut ids, &|_| format!("node ids of edge {i}"))?;
        let constraint = read_pose(&mut input, &|| format!("constraint of edge {i}"))?;
        let mut w = [0u8; 8];
        input.fill(&mut w, &|_| format!("weight of edge {i}"))?;
        edges.push(ScanEdge {
            first: u32::from_le_bytes([ids[0], ids[1], ids[2], ids[3]]),
            second: u32::from_le_bytes([ids[4], ids[5], ids[6], ids[7]]),
            constraint,
            weight: f64::from_le_bytes(w),
        });
    }
    // Trailing bytes are ignored, as in OctoMap.
    Ok(ScanGraph { nodes, edges })
}

/// Reads a graph from a stream (buffer it yourself for files, or use [`read_file`]).
pub fn read(reader: impl Read) -> Result<ScanGraph, GraphError> {
    read_input(Input { inner: reader, offset: 0, len: None })
}

/// Reads a graph from memory; counts are checked against the slice length.
pub fn read_bytes(bytes: &[u8]) -> Result<ScanGraph, GraphError> {
    read_input(Input { inner: bytes, offset: 0, len: Some(bytes.len() as u64) })
}

/// Reads a `.graph` file; counts are checked against the file length.
pub fn read_file(path: impl AsRef<Path>) -> Result<ScanGraph, GraphError> {
    let io_err = |source| GraphError::Io { offset: 0, source };
    let file = fs::File::open(path).map_err(io_err)?;
    let len = file.metadata().map_err(io_err)?.len();
    read_input(Input { inner: io::BufReader::with_capacity(1 << 16, file), offset: 0, len: Some(len) })
}

fn put_vector(out: &mut impl Write, v: Point3) -> io::Result<()> {
    let mut b = [0u8; POINT_BYTES];
    b[..4].copy_from_slice(&3i32.to_le_bytes());
    for (i, c) in v.to_array().into_iter().enumerate() {
        b[4 + 8 * i..12 + 8 * i].copy_from_slice(&(c as f64).to_le_bytes());
    }
    out.write_all(&b)
}

fn put_pose(out: &mut impl Write, p: &Pose6D) -> io::Result<()> {
    put_vector(out, p.translation)?;
    let mut b = [0u8; 4 + 32];
    b[..4].copy_from_slice(&4i32.to_le_bytes());
    for (i, c) in p.rotation.to_array().into_iter().enumerate() {
        b[4 + 8 * i..12 + 8 * i].copy_from_slice(&(c as f64).to_le_bytes());
    }
    out.write_all(&b)
}

fn count_u32(n: usize, what: &str) -> io::Result<u32> {
    u32::try_from(n).map_err(|_| {
        io::Error::new(io::ErrorKind::InvalidInput, format!("{what} count {n} does not fit the format's u32"))
    })
}

/// Writes the graph byte-identically to `ScanGraph::writeBinary`. Counts above
/// `u32::MAX` are refused before anything is written (OctoMap would write a
/// corrupt file).
pub fn write(graph: &ScanGraph, writer: impl Write) -> io::Result<()> {
    let n_nodes = count_u32(graph.nodes.len(), "node")?;
    let n_edges = count_u32(graph.edges.len(), "edge")?;
    for n in &graph.nodes {
        count_u32(n.scan.len(), "point")?;
    }
    let mut out = BufWriter::with_capacity(1 << 16, writer);
    out.write_all(&n_nodes.to_le_bytes())?;
    for node in &graph.nodes {
        out.write_all(&(node.scan.len() as u32).to_le_bytes())?;
        for p in &node.scan {
            put_vector(&mut out, *p)?;
        }
        put_pose(&mut out, &node.pose)?;
        out.write_all(&node.id.to_le_bytes())?;
    }
    out.write_all(&n_edges.to_le_bytes())?;
    for e in &graph.edges {
        out.write_all(&e.first.to_le_bytes())?;
        out.write_all(&e.second.to_le_bytes())?;
        put_pose(&mut out, &e.constraint)?;
        out.write_all(&e.weight.to_le_bytes())?;
    }
    out.flush()
}

/// Writes atomically (see [`super::write_atomically`]).
pub fn write_file(graph: &ScanGraph, path: impl AsRef<Path>) -> io::Result<()> {
    super::write_atomically(path.as_ref(), |w| write(graph, w))
}
