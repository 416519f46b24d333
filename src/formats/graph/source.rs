//! Where a [`ScanReader`](super::ScanReader) takes its bytes from: any
//! [`Read`], whose bytes are copied into the reader's buffer, or a
//! [`GraphInput`], which maps a regular file a window at a time and lends
//! the reader its bytes where they lie (a build spent a tenth of its time
//! in the kernel copying a large file into the buffer).

use super::GraphError;
use crate::mapped::MappingWatch;
use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::Path;

/// Hidden behind [`GraphSource`], so that only this module implements it.
pub(super) mod lend {
    use std::io;

    /// The next bytes of an input.
    pub trait Lend {
        /// The next `n` bytes (fewer only where the input ends), in
        /// `buffer` or where they already lie; on an I/O error, the error
        /// and how many bytes were read before it.
        fn lend<'a>(&'a mut self, n: usize, buffer: &'a mut Vec<u8>) -> Result<&'a [u8], (usize, io::Error)>;
    }
}

/// What a [`ScanReader`](super::ScanReader) reads: every [`Read`] (a
/// file, a pipe, a byte slice), or a [`GraphInput`].
pub trait GraphSource: lend::Lend {}

impl<R: Read> GraphSource for R {}

impl<R: Read> lend::Lend for R {
    fn lend<'a>(&'a mut self, n: usize, buffer: &'a mut Vec<u8>) -> Result<&'a [u8], (usize, io::Error)> {
        if buffer.len() < n {
            buffer.resize(n, 0);
        }
        let mut filled = 0;
        while filled < n {
            match self.read(&mut buffer[filled..n]) {
                Ok(0) => break,
                Ok(read) => filled += read,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err((filled, e)),
            }
        }
        Ok(&buffer[..filled])
    }
}

/// A `.graph` input for [`ScanReader`](super::ScanReader): a regular file
/// memory-mapped a window of [`WINDOW`] bytes at a time (so that the
/// process holds at most a window of it, however large the file), or any
/// other stream read through a buffer.
///
/// A mapped file must not be truncated while it is read: reading past its
/// new end faults (`SIGBUS`), as for [`crate::mapped::open`]. With
/// [`crate::mapped::guard_truncated_files`] installed, such a read finds
/// zeros instead and the next read fails with an I/O error naming the
/// file; [`GraphInput::watch`] tells about the bytes already lent.
pub struct GraphInput(Input);

enum Input {
    Mapped(Windows),
    Stream(Box<dyn Read + Send>),
}

/// Bytes of the file a window maps.
pub const WINDOW: u64 = 4 << 20;

/// Windows start at multiples of this (a multiple of every page size).
const ALIGN: u64 = 1 << 16;

/// A regular file mapped one window at a time.
struct Windows {
    file: File,
    len: u64,
    /// Bytes a window maps at least ([`WINDOW`]; less in tests).
    size: u64,
    /// The window and the file offset it starts at.
    window: Option<Window>,
    /// Whether a read of a window faulted past the file's end.
    watch: MappingWatch,
    /// The offset of the next byte to lend.
    at: u64,
}

impl GraphInput {
    /// Opens the file at `path`: mapped when it is a regular file, else
    /// read as a stream.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        let path = path.as_ref();
        Self::named(File::open(path)?, Some(path))
    }

    /// Reads an open file: mapped when it is a regular file, else read as
    /// a stream.
    pub fn from_file(file: File) -> io::Result<Self> {
        let path = opened_path(&file);
        Self::named(file, path.as_deref())
    }

    /// An open file known by `path` in messages.
    fn named(file: File, path: Option<&Path>) -> io::Result<Self> {
        Ok(match super::stream_len(&file)? {
            Some(len) => {
                let watch = MappingWatch::new(path);
                GraphInput(Input::Mapped(Windows { file, len, size: WINDOW, window: None, watch, at: 0 }))
            }
            None => Self::stream(BufReader::with_capacity(1 << 16, file)),
        })
    }

    /// A stream (standard input, a socket) read as it comes; buffer it
    /// yourself, reads may be small.
    pub fn stream(reader: impl Read + Send + 'static) -> Self {
        GraphInput(Input::Stream(Box::new(reader)))
    }

    /// Whether the mapped file was found truncated under the reader (with
    /// [`crate::mapped::guard_truncated_files`] installed): check it after
    /// the last scan, as the bytes of the last window are read after they
    /// were lent. Never truncated for a stream.
    pub fn watch(&self) -> MappingWatch {
        match &self.0 {
            Input::Mapped(w) => w.watch.clone(),
            Input::Stream(_) => MappingWatch::new(None),
        }
    }

    /// The length of a mapped file; `None` for a stream.
    pub fn file_len(&self) -> Option<u64> {
        match &self.0 {
            Input::Mapped(w) => Some(w.len),
            Input::Stream(_) => None,
        }
    }
}

impl GraphSource for GraphInput {}

impl lend::Lend for GraphInput {
    fn lend<'a>(&'a mut self, n: usize, buffer: &'a mut Vec<u8>) -> Result<&'a [u8], (usize, io::Error)> {
        match &mut self.0 {
            Input::Mapped(windows) => windows.lend(n).map_err(|e| (0, e)),
            Input::Stream(reader) => reader.lend(n, buffer),
        }
    }
}

impl Windows {
    /// The next `n` bytes (fewer at the end of the file), from a window
    /// that holds them all: a new one when the current one does not.
    fn lend(&mut self, n: usize) -> io::Result<&[u8]> {
        // the bytes lent before came from a truncated file
        self.watch.check().map_err(io::Error::other)?;
        let end = self.at.saturating_add(n as u64).min(self.len);
        if end == self.at {
            return Ok(&[]);
        }
        let covers = |w: &Window| w.start <= self.at && end <= w.start + w.map.len() as u64;
        if !self.window.as_ref().is_some_and(covers) {
            // the old window goes first, so that two are never held
            self.window = None;
            let start = self.at / ALIGN * ALIGN;
            let len = (end - start).max(self.size).min(self.len - start);
            let map = crate::mapped::mapping::map_range(&self.file, start, len as usize)?;
            let _registration = self.watch.register(&map);
            self.window = Some(Window { _registration, map, start });
        }
        let Window { map, start, .. } = self.window.as_ref().expect("a window was mapped above");
        let bytes = &map[(self.at - start) as usize..(end - start) as usize];
        self.at = end;
        Ok(bytes)
    }
}

/// A regular `.graph` file opened once and read from the start as often
/// as needed (a build in groups reads every scan once per group). Every
/// pass reads the file first opened, whatever the path names by then: a
/// file renamed over it mid-build is not mixed in. A pass started after the
/// file changed in place (its length or modification time differ from
/// when it was opened) fails with [`GraphError::Changed`].
pub struct GraphFile {
    file: File,
    /// The length and modification time when opened.
    seen: (u64, Option<std::time::SystemTime>),
}

impl GraphFile {
    /// Opens `path`, which must be a regular file (a pipe or device cannot
    /// be read again): [`GraphError::NotRegular`] otherwise.
    pub fn open(path: impl AsRef<Path>) -> Result<GraphFile, GraphError> {
        let io = |source| GraphError::Io { offset: 0, source };
        let file = File::open(path).map_err(io)?;
        let meta = file.metadata().map_err(io)?;
        if !meta.is_file() {
            return Err(GraphError::NotRegular);
        }
        Ok(GraphFile { seen: (meta.len(), meta.modified().ok()), file })
    }

    /// The file's length when opened.
    pub fn len(&self) -> u64 {
        self.seen.0
    }

    /// True when the file was empty when opened.
    pub fn is_empty(&self) -> bool {
        self.seen.0 == 0
    }

    /// A reader of the whole file from its first byte, after checking that
    /// it has not changed since it was opened.
    pub fn reader(&self) -> Result<super::ScanReader<GraphInput>, GraphError> {
        let io = |source| GraphError::Io { offset: 0, source };
        let meta = self.file.metadata().map_err(io)?;
        let now = (meta.len(), meta.modified().ok());
        if now != self.seen {
            return Err(GraphError::Changed { opened: self.seen.0, now: now.0 });
        }
        // a second descriptor of the same open file: windows are mapped at
        // their own offsets, so the shared file position does not matter
        let input = GraphInput::from_file(self.file.try_clone().map_err(io)?).map_err(io)?;
        super::ScanReader::with_len(input, Some(self.seen.0))
    }
}

/// A mapped window of a file.
struct Window {
    /// Dropped before `map` is unmapped (fields drop in order).
    _registration: Option<crate::mapped::fault::Registration>,
    map: memmap2::Mmap,
    /// The file offset the window starts at.
    start: u64,
}

/// The path an open file was opened by, where the system tells it.
fn opened_path(file: &File) -> Option<std::path::PathBuf> {
    #[cfg(any(target_os = "linux", target_os = "android"))]
    {
        use std::os::fd::AsRawFd;
        std::fs::read_link(format!("/proc/self/fd/{}", file.as_raw_fd())).ok()
    }
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    {
        let _ = file;
        None
    }
}

#[cfg(test)]
mod tests {
    use super::super::{open, read_bytes, write, GraphError, ScanGraph, ScanReader};
    use super::*;
    use crate::geometry::{Point3, PointCloud, Pose6D};
    use std::io::Write;

    /// A graph of `scans` scans of `points` points each, as bytes.
    fn graph_bytes(scans: usize, points: usize) -> Vec<u8> {
        let mut g = ScanGraph::new();
        for s in 0..scans {
            let cloud: PointCloud = (0..points).map(|i| Point3::new(i as f32 * 0.01, s as f32, -0.5)).collect();
            g.add_node(cloud, Pose6D::from_euler(s as f32, 2.0, 0.5, 0.1, 0.2, 0.3));
            g.connect_previous();
        }
        let mut bytes = Vec::new();
        write(&g, &mut bytes).unwrap();
        bytes
    }

    /// `path` opened with windows of `size` bytes.
    fn small_windows(path: &Path, size: u64) -> Result<ScanReader<GraphInput>, GraphError> {
        let mut input = GraphInput::open(path).unwrap();
        let Input::Mapped(windows) = &mut input.0 else { panic!("a regular file is mapped") };
        windows.size = size;
        let len = input.file_len();
        ScanReader::with_len(input, len)
    }

    /// A mapped file reads as the same bytes in memory do, with windows of
    /// the default size and with windows smaller than a chunk of points (a
    /// request then straddles windows); a truncated file fails as the
    /// truncated bytes do.
    #[test]
    fn mapped_files_read_as_their_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let bytes = graph_bytes(5, 9000);
        let want = read_bytes(&bytes).unwrap();
        let path = dir.path().join("scans.graph");
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(open(&path).unwrap().into_graph().unwrap(), want);
        for size in [ALIGN, 3 * ALIGN] {
            assert_eq!(small_windows(&path, size).unwrap().into_graph().unwrap(), want, "windows of {size}");
        }
        for cut in [3, 100, ALIGN as usize + 5, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let expected = read_bytes(&bytes[..cut]).unwrap_err().to_string();
            let got = open(&path).and_then(ScanReader::into_graph).unwrap_err().to_string();
            assert_eq!(got, expected, "cut at {cut}");
            let got = small_windows(&path, ALIGN).and_then(ScanReader::into_graph).unwrap_err().to_string();
            assert_eq!(got, expected, "cut at {cut}, small windows");
        }
        std::fs::write(&path, []).unwrap();
        assert_eq!(open(&path).err().unwrap().to_string(), read_bytes(&[]).unwrap_err().to_string());
    }

    /// Every pass of a [`GraphFile`] reads the file first opened: a file
    /// renamed over its path is not read, one changed in place is refused,
    /// and a FIFO is refused at opening.
    #[test]
    fn a_graph_file_reads_the_file_first_opened() {
        let dir = tempfile::tempdir().unwrap();
        let (first, second) = (graph_bytes(3, 500), graph_bytes(4, 700));
        let path = dir.path().join("scans.graph");
        std::fs::write(&path, &first).unwrap();
        let file = GraphFile::open(&path).unwrap();
        assert_eq!(file.len(), first.len() as u64);
        let want = read_bytes(&first).unwrap();
        assert_eq!(file.reader().unwrap().into_graph().unwrap(), want);

        let other = dir.path().join("other.graph");
        std::fs::write(&other, &second).unwrap();
        std::fs::rename(&other, &path).unwrap();
        assert_eq!(file.reader().unwrap().into_graph().unwrap(), want, "after a rename over the path");
        assert_eq!(open(&path).unwrap().into_graph().unwrap(), read_bytes(&second).unwrap());

        let file = GraphFile::open(&path).unwrap();
        std::fs::OpenOptions::new().append(true).open(&path).unwrap().write_all(&[0; 8]).unwrap();
        let err = file.reader().err().unwrap();
        assert!(matches!(err, GraphError::Changed { opened, now } if now == opened + 8), "{err}");

        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        // opening a FIFO for reading blocks until a writer comes: give it one
        let writer = {
            let fifo = fifo.clone();
            std::thread::spawn(move || drop(std::fs::OpenOptions::new().write(true).open(fifo)))
        };
        assert!(matches!(GraphFile::open(&fifo), Err(GraphError::NotRegular)));
        writer.join().unwrap();
    }

    /// A stream reads through the buffer, however it hands out its bytes.
    #[test]
    fn streams_read_through_the_buffer() {
        let bytes = graph_bytes(2, 300);
        let want = read_bytes(&bytes).unwrap();
        let input = GraphInput::stream(std::io::Cursor::new(bytes));
        assert_eq!(input.file_len(), None);
        assert_eq!(ScanReader::new(input).unwrap().into_graph().unwrap(), want);
    }
}
