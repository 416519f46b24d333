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

mod source;

pub use source::{GraphFile, GraphInput, GraphSource, WINDOW};

use crate::geometry::{graph2tree_in_place, graph2tree_transform, Point3, PointCloud, Pose6D, Quaternion};

/// One scan: points in the sensor frame plus the pose they were taken from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanNode {
    /// The node's id, which edges refer to (OctoMap's `ScanNode::id`).
    pub id: u32,
    /// Pose of the sensor, in the world frame, when the scan was taken.
    pub pose: Pose6D,
    /// The scan's points, in the sensor frame.
    pub scan: PointCloud,
}

impl ScanNode {
    /// World-frame points and sensor origin exactly as `graph2tree` computes them.
    pub fn graph2tree(&self) -> (PointCloud, Point3) {
        graph2tree_transform(&self.pose, &self.scan)
    }

    /// [`Self::graph2tree`] of a node given up for it: its points are
    /// transformed where they are, not copied first.
    pub fn into_graph2tree(self) -> (PointCloud, Point3) {
        graph2tree_in_place(&self.pose, self.scan)
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
    /// Id of the node the edge starts at.
    pub first: u32,
    /// Id of the node the edge ends at.
    pub second: u32,
    /// Pose of `second` relative to `first` (`first.pose.inv() * second.pose`
    /// for edges made by [`ScanGraph::connect_previous`]).
    pub constraint: Pose6D,
    /// Edge weight, stored as f64 in the file.
    pub weight: f64,
}

/// OctoMap's `ScanGraph`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanGraph {
    /// The scans, in file order.
    pub nodes: Vec<ScanNode>,
    /// The constraints between scans, in file order.
    pub edges: Vec<ScanEdge>,
}

impl ScanGraph {
    /// An empty graph.
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
    /// The underlying reader failed.
    #[error("I/O error at byte offset {offset}")]
    Io {
        /// Byte offset of the read that failed.
        offset: u64,
        /// The reader's error.
        #[source]
        source: io::Error,
    },
    /// The input ends inside a value.
    #[error("input ends at byte offset {offset} inside {context} ({missing} more bytes needed)")]
    Truncated {
        /// Byte offset where the input ends.
        offset: u64,
        /// Bytes still needed to complete the value.
        missing: u64,
        /// What was being read, e.g. "weight of edge 3".
        context: String,
    },
    /// A vector's or quaternion's leading `i32` marker is not `3` or `4`.
    #[error("marker {found} at byte offset {offset} in {context}, expected {expected}")]
    BadMarker {
        /// Byte offset of the marker.
        offset: u64,
        /// The marker required there (3 for a vector, 4 for a quaternion).
        expected: i32,
        /// The marker read.
        found: i32,
        /// Where the marker is: the translation or rotation of which pose.
        context: String,
    },
    /// A node, edge or point count announces more items than the rest of
    /// the input (of known length) can hold.
    #[error("{what} count {count} at byte offset {offset} needs at least {needed} bytes, only {remaining} remain")]
    CountTooLarge {
        /// Byte offset of the count.
        offset: u64,
        /// What is counted: "node", "edge" or "point".
        what: &'static str,
        /// The count read.
        count: u32,
        /// Smallest number of bytes that many items take.
        needed: u64,
        /// Bytes left in the input after the count.
        remaining: u64,
    },
    /// A file read again ([`GraphFile`]) was changed in place since it
    /// was opened: replace inputs by renaming a new file over them.
    #[error(
        "the file changed while it was read (length {opened} bytes when opened, {now} now, or a new modification time)"
    )]
    Changed {
        /// The length when the file was opened.
        opened: u64,
        /// The length now.
        now: u64,
    },
    /// A file to be read more than once ([`GraphFile`]) is a pipe, FIFO,
    /// socket or device, which cannot be read again.
    #[error("not a regular file: a file read more than once cannot be a pipe, FIFO or device")]
    NotRegular,
    /// The memory for what the data holds so far could not be had.
    #[error("at byte offset {offset}, {context}: cannot allocate memory for {count} {what}")]
    OutOfMemory {
        /// Byte offset reached when allocation failed.
        offset: u64,
        /// What was being stored: "nodes", "edges" or "points".
        what: &'static str,
        /// Number of items the allocation was for.
        count: u64,
        /// Which list was being read, e.g. "edge list (5 announced)".
        context: String,
    },
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
    /// Room for the bytes of a source that copies them.
    buffer: Vec<u8>,
}

impl<R: GraphSource> Input<R> {
    /// The next `n` bytes, or where the input ended or failed.
    fn take(&mut self, n: usize, context: &dyn Fn(usize) -> String) -> Result<&[u8], GraphError> {
        let offset = self.offset;
        match self.inner.lend(n, &mut self.buffer) {
            Ok(bytes) if bytes.len() == n => {
                self.offset += n as u64;
                Ok(bytes)
            }
            Ok(bytes) => Err(GraphError::Truncated {
                offset: offset + bytes.len() as u64,
                missing: (n - bytes.len()) as u64,
                context: context(bytes.len()),
            }),
            Err((read, source)) => Err(GraphError::Io { offset: offset + read as u64, source }),
        }
    }

    /// The next `N` bytes as an array.
    fn array<const N: usize>(&mut self, context: &dyn Fn(usize) -> String) -> Result<[u8; N], GraphError> {
        let bytes = self.take(N, context)?;
        Ok(bytes.try_into().expect("take gives N bytes"))
    }

    fn u32(&mut self, context: &dyn Fn(usize) -> String) -> Result<u32, GraphError> {
        Ok(u32::from_le_bytes(self.array(context)?))
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

    /// Makes room for `more` elements in `v`, or names what could not be had.
    fn reserve<T>(
        &self,
        v: &mut Vec<T>,
        more: usize,
        what: &'static str,
        context: &dyn Fn() -> String,
    ) -> Result<(), GraphError> {
        v.try_reserve(more).map_err(|_| GraphError::OutOfMemory {
            offset: self.offset,
            what,
            count: (v.len() + more) as u64,
            context: context(),
        })
    }
}

/// The little-endian double at `at`. Inlined: the readers are generic, so
/// other crates compile them, and without the hint they called this once
/// per coordinate (a quarter of the time a build spent reading a `.graph`
/// file).
#[inline]
fn f64_at(b: &[u8], at: usize) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    f64::from_le_bytes(a)
}

/// The little-endian `i32` at `at` (inlined, like [`f64_at`]).
#[inline]
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

fn read_pose<R: GraphSource>(input: &mut Input<R>, context: &dyn Fn() -> String) -> Result<Pose6D, GraphError> {
    let base = input.offset;
    let b: [u8; POSE_BYTES] = input.array(&|_| context())?;
    let t = vector_at(&b, 0, base, &|| format!("translation of {}", context()))?;
    check_marker(i32_at(&b, POINT_BYTES), 4, base + POINT_BYTES as u64, || format!("rotation of {}", context()))?;
    let q = |i: usize| f64_at(&b, POINT_BYTES + 4 + 8 * i) as f32;
    Ok(Pose6D::new(t, Quaternion::new(q(0), q(1), q(2), q(3))))
}

fn read_cloud<R: GraphSource>(input: &mut Input<R>, node: usize) -> Result<PointCloud, GraphError> {
    let count = input.u32(&|_| format!("point count of node {node}"))?;
    input.check_count("point", count, POINT_BYTES as u64, POSE_BYTES as u64 + 4)?;
    let mut cloud = PointCloud::new();
    let total = count as usize;
    let context = || format!("points of node {node} ({total} announced)");
    input.reserve(&mut cloud.points, input.reserve_hint(count), "points", &context)?;
    let mut done = 0usize;
    while done < total {
        let n = (total - done).min(POINT_CHUNK);
        // grows with the data actually present (the count alone may lie)
        input.reserve(&mut cloud.points, n, "points", &context)?;
        let base = input.offset;
        let chunk = input
            .take(n * POINT_BYTES, &|read| format!("point {} of node {node}", done + read / POINT_BYTES))
            .map_err(|e| match e {
                // Report what the interrupted point lacks, not the whole chunk.
                GraphError::Truncated { offset, context, .. } => GraphError::Truncated {
                    offset,
                    missing: (POINT_BYTES - (offset - base) as usize % POINT_BYTES) as u64,
                    context,
                },
                e => e,
            })?;
        // markers first, then the coordinates in a loop without exits
        let records = chunk.chunks_exact(POINT_BYTES);
        if let Some(i) = records.clone().position(|r| i32_at(r, 0) != 3) {
            let ctx = || format!("point {} of node {node}", done + i);
            vector_at(chunk, i * POINT_BYTES, base, &ctx)?;
        }
        cloud
            .points
            .extend(records.map(|r| Point3::new(f64_at(r, 4) as f32, f64_at(r, 12) as f32, f64_at(r, 20) as f32)));
        done += n;
    }
    Ok(cloud)
}

/// Decodes a graph scan by scan from any [`GraphSource`] (a [`Read`] or a
/// mapped file, [`GraphInput`]): the node count when
/// created, then one [`ScanNode`] per [`Iterator::next`], so that a caller
/// inserting scans into a map holds one scan at a time, whether the input
/// is a file, a pipe or standard input. After the last scan,
/// [`ScanReader::edges`] reads the edge list. The first error ends the
/// iteration; errors name the node and the byte offset.
pub struct ScanReader<R> {
    input: Input<R>,
    nodes: u32,
    next: u32,
    failed: bool,
}

impl<R: GraphSource> ScanReader<R> {
    /// Reads the node count of a stream of unknown length (buffer it
    /// yourself: reads are small).
    pub fn new(reader: R) -> Result<Self, GraphError> {
        Self::with_len(reader, None)
    }

    /// As [`Self::new`], with the input's total length when it is known (a
    /// regular file, a slice): counts that cannot fit are refused up front.
    pub fn with_len(reader: R, len: Option<u64>) -> Result<Self, GraphError> {
        let mut input = Input { inner: reader, offset: 0, len, buffer: Vec::new() };
        let nodes = input.u32(&|_| "node count".to_string())?;
        input.check_count("node", nodes, MIN_NODE_BYTES, 4)?;
        Ok(ScanReader { input, nodes, next: 0, failed: false })
    }

    /// The node count the input announces.
    pub fn announced(&self) -> u32 {
        self.nodes
    }

    /// Bytes consumed so far.
    pub fn offset(&self) -> u64 {
        self.input.offset
    }

    fn node(&mut self) -> Result<ScanNode, GraphError> {
        let i = self.next as usize;
        let scan = read_cloud(&mut self.input, i)?;
        let pose = read_pose(&mut self.input, &|| format!("pose of node {i}"))?;
        let id = self.input.u32(&|_| format!("id of node {i}"))?;
        Ok(ScanNode { id, pose, scan })
    }

    /// Reads the scans not read yet (dropping them) and then the edge
    /// list. Bytes after the edges are ignored, as in OctoMap.
    pub fn edges(mut self) -> Result<Vec<ScanEdge>, GraphError> {
        if self.failed {
            let source = io::Error::other("the edge list follows a node that could not be read");
            return Err(GraphError::Io { offset: self.input.offset, source });
        }
        for node in self.by_ref() {
            node?;
        }
        let input = &mut self.input;
        let n_edges = input.u32(&|_| "edge count".to_string())?;
        input.check_count("edge", n_edges, EDGE_BYTES as u64, 0)?;
        let mut edges = Vec::new();
        let context = || format!("edge list ({n_edges} announced)");
        input.reserve(&mut edges, input.reserve_hint(n_edges), "edges", &context)?;
        for i in 0..n_edges as usize {
            let ids: [u8; 8] = input.array(&|_| format!("node ids of edge {i}"))?;
            let constraint = read_pose(input, &|| format!("constraint of edge {i}"))?;
            let w: [u8; 8] = input.array(&|_| format!("weight of edge {i}"))?;
            input.reserve(&mut edges, 1, "edges", &context)?;
            edges.push(ScanEdge {
                first: u32::from_le_bytes([ids[0], ids[1], ids[2], ids[3]]),
                second: u32::from_le_bytes([ids[4], ids[5], ids[6], ids[7]]),
                constraint,
                weight: f64::from_le_bytes(w),
            });
        }
        Ok(edges)
    }

    /// The whole graph: every node, then the edges.
    pub fn into_graph(mut self) -> Result<ScanGraph, GraphError> {
        let mut nodes = Vec::new();
        let context = || "node list".to_string();
        self.input.reserve(&mut nodes, self.input.reserve_hint(self.nodes), "nodes", &context)?;
        while let Some(node) = self.next() {
            let node = node?;
            self.input.reserve(&mut nodes, 1, "nodes", &context)?;
            nodes.push(node);
        }
        let edges = self.edges()?;
        Ok(ScanGraph { nodes, edges })
    }
}

impl<R: GraphSource> Iterator for ScanReader<R> {
    type Item = Result<ScanNode, GraphError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed || self.next == self.nodes {
            return None;
        }
        let node = self.node();
        self.failed = node.is_err();
        self.next += 1;
        Some(node)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = if self.failed { 0 } else { (self.nodes - self.next) as usize };
        (0, Some(left))
    }
}

/// Reads a graph from a stream (buffer it yourself for files, or use [`read_file`]).
pub fn read(reader: impl Read) -> Result<ScanGraph, GraphError> {
    ScanReader::new(reader)?.into_graph()
}

/// Reads a graph from memory; counts are checked against the slice length.
pub fn read_bytes(bytes: &[u8]) -> Result<ScanGraph, GraphError> {
    ScanReader::with_len(bytes, Some(bytes.len() as u64))?.into_graph()
}

/// Opens a `.graph` file for reading scan by scan: a regular file is
/// memory-mapped a window at a time ([`GraphInput`]) and its counts are
/// checked against its length; a pipe, FIFO or device is read as a stream.
pub fn open(path: impl AsRef<Path>) -> Result<ScanReader<GraphInput>, GraphError> {
    let input = GraphInput::open(path).map_err(|source| GraphError::Io { offset: 0, source })?;
    let len = input.file_len();
    ScanReader::with_len(input, len)
}

/// The length of a regular file; `None` for a pipe, FIFO, socket or device,
/// whose metadata says nothing about what can be read from it.
pub fn stream_len(file: &fs::File) -> io::Result<Option<u64>> {
    let meta = file.metadata()?;
    Ok(meta.is_file().then_some(meta.len()))
}

/// Reads a `.graph` file (see [`open`]).
pub fn read_file(path: impl AsRef<Path>) -> Result<ScanGraph, GraphError> {
    open(path)?.into_graph()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Hands out at most 7 bytes per read, like a pipe between processes.
    struct Trickle<'a>(&'a [u8]);

    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let n = buf.len().min(7).min(self.0.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    fn sample() -> (ScanGraph, Vec<u8>) {
        let mut g = ScanGraph::new();
        for n in [3usize, 0, 5000] {
            let cloud: PointCloud = (0..n).map(|i| Point3::new(i as f32, 1.0, -2.5)).collect();
            g.add_node(cloud, Pose6D::from_euler(1.0, 2.0, 3.0, 0.1, 0.2, 0.3));
            g.connect_previous();
        }
        let mut bytes = Vec::new();
        write(&g, &mut bytes).unwrap();
        (g, bytes)
    }

    #[test]
    fn scans_stream_one_by_one_from_a_pipe() {
        let (g, bytes) = sample();
        let mut reader = ScanReader::new(Trickle(&bytes)).unwrap();
        assert_eq!(reader.announced(), 3);
        assert_eq!(reader.size_hint(), (0, Some(3)));
        let first = reader.next().unwrap().unwrap();
        assert_eq!(first, g.nodes[0]);
        assert_eq!(reader.offset(), 4 + 4 + 3 * 28 + 64 + 4);
        let rest: Vec<ScanNode> = reader.by_ref().map(Result::unwrap).collect();
        assert_eq!(rest, g.nodes[1..]);
        assert_eq!(reader.edges().unwrap(), g.edges);
        assert_eq!(read(Trickle(&bytes)).unwrap(), g);
    }

    #[test]
    fn edges_read_past_the_scans_not_taken() {
        let (g, bytes) = sample();
        let mut reader = ScanReader::new(&bytes[..]).unwrap();
        reader.next().unwrap().unwrap();
        assert_eq!(reader.edges().unwrap(), g.edges);
    }

    #[test]
    fn a_truncated_stream_names_the_scan_and_the_offset() {
        let (g, bytes) = sample();
        // cut inside point 10 of node 2 (the third scan)
        let node2 = 4 + 2 * (4 + 64 + 4) + 3 * 28;
        let cut = node2 + 4 + 10 * 28 + 5;
        let mut reader = ScanReader::new(Trickle(&bytes[..cut])).unwrap();
        assert_eq!(reader.next().unwrap().unwrap(), g.nodes[0]);
        assert_eq!(reader.next().unwrap().unwrap(), g.nodes[1]);
        let err = reader.next().unwrap().unwrap_err();
        match &err {
            GraphError::Truncated { offset, missing, context } => {
                assert_eq!((*offset, *missing), (cut as u64, 23));
                assert_eq!(context, "point 10 of node 2");
            }
            e => panic!("{e}"),
        }
        assert!(err.to_string().contains(&format!("byte offset {cut} inside point 10 of node 2")), "{err}");
        assert!(reader.next().is_none(), "the first error ends the scans");
        assert!(reader.edges().is_err());
    }

    #[test]
    fn a_point_count_larger_than_the_data_is_an_error() {
        // a stream has no length to check counts against: what is reserved
        // grows with the data, which here ends after one point
        let mut bytes = 1u32.to_le_bytes().to_vec();
        bytes.extend(u32::MAX.to_le_bytes());
        let mut one = Vec::new();
        put_vector(&mut one, Point3::new(1.0, 2.0, 3.0)).unwrap();
        bytes.extend(&one);
        let err = ScanReader::new(&bytes[..]).unwrap().next().unwrap().unwrap_err();
        assert!(matches!(err, GraphError::Truncated { offset: 36, .. }), "{err}");
        // with the length known, the count is refused before any reading
        bytes.extend([0u8; 68]);
        let err = ScanReader::with_len(&bytes[..], Some(bytes.len() as u64)).unwrap().next().unwrap().unwrap_err();
        assert!(matches!(err, GraphError::CountTooLarge { offset: 4, what: "point", .. }), "{err}");
    }

    #[test]
    fn pipes_have_no_length_and_files_do() {
        let dir = std::env::temp_dir();
        let path = dir.join(format!("octolinear-graph-len-{}", std::process::id()));
        std::fs::write(&path, [0u8; 10]).unwrap();
        assert_eq!(stream_len(&fs::File::open(&path).unwrap()).unwrap(), Some(10));
        std::fs::remove_file(&path).unwrap();
        #[cfg(target_os = "linux")]
        {
            let (r, _w) = std::io::pipe().unwrap();
            let f = fs::File::from(std::os::fd::OwnedFd::from(r));
            assert_eq!(stream_len(&f).unwrap(), None);
        }
    }
}
