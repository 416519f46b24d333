//! Files truncated in place while mapped, with the crate's `SIGBUS` guard
//! installed: a read past the new end finds zeros, the mapping is marked
//! truncated and the process lives on; a `SIGBUS` anywhere else still
//! kills it (checked in child processes: this test binary run again).
//! Its own binary, as it installs a signal handler for the whole process.

#![cfg(target_os = "linux")]

use octolinear::formats::graph::{self, GraphError, GraphInput, ScanGraph, ScanReader};
use octolinear::geometry::{Point3, PointCloud, Pose6D};
use octolinear::mapped::{self, OlmError, Truncated};
use octolinear::{OccupancyTree, ScanOptions};
use std::fs::OpenOptions;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::Command;

fn truncate(path: &Path, len: u64) {
    OpenOptions::new().write(true).open(path).unwrap().set_len(len).unwrap();
}

fn is_truncated(err: &Truncated, path: &Path) -> bool {
    err.path.as_deref() == Some(path)
}

/// A map of some thousand leaves over many pages.
fn tree() -> OccupancyTree {
    let mut tree = OccupancyTree::new(0.05).unwrap();
    let scan: Vec<Point3> =
        (0..4000).map(|i| Point3::new((i % 63) as f32 * 0.07 - 2.0, (i / 63) as f32 * 0.07 - 2.0, 1.5)).collect();
    tree.insert_point_cloud(&scan, Point3::new(0.0, 0.0, 0.0), &ScanOptions::default()).unwrap();
    tree
}

/// An `.olm` map truncated under an open mapping: the queries complete
/// (on zeros), the map says it was truncated, and verifying or loading it
/// fails with the file named; a map opened again reads the short file.
#[test]
fn a_truncated_map_is_marked_and_the_process_lives() {
    mapped::guard_truncated_files().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.olm");
    let tree = tree();
    mapped::write_file(&tree, &path).unwrap();
    let map = mapped::open(&path).unwrap();
    assert_eq!(map.view().leaves(0).count(), tree.leaves(0).count());
    assert!(map.check_mapping().is_ok());
    map.verify().unwrap();

    truncate(&path, 0);
    let _ = map.view().leaves(0).count();
    let err = map.check_mapping().unwrap_err();
    assert!(is_truncated(&err, &path), "{err:?}");
    assert!(err.to_string().contains("m.olm: the file was truncated while memory-mapped"), "{err}");
    assert!(matches!(map.verify(), Err(OlmError::Truncated(e)) if is_truncated(&e, &path)));
    assert!(matches!(map.to_tree(), Err(OlmError::Truncated(_))));
    drop(map);
    assert!(matches!(mapped::open(&path), Err(OlmError::TooShort { .. })));
}

/// A `.graph` file truncated between two scans: the next read fails with
/// an I/O error naming the file, and the watch reports the truncation.
#[test]
fn a_truncated_graph_fails_its_next_read() {
    mapped::guard_truncated_files().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scans.graph");
    let mut g = ScanGraph::new();
    for s in 0..3 {
        let cloud: PointCloud = (0..20_000).map(|i| Point3::new(i as f32 * 1e-4, s as f32, 0.5)).collect();
        g.add_node(cloud, Pose6D::from_euler(0.0, 0.0, 0.0, 0.0, 0.0, 0.0));
    }
    graph::write_file(&g, &path).unwrap();
    let input = GraphInput::open(&path).unwrap();
    let watch = input.watch();
    let len = input.file_len();
    let mut reader = ScanReader::with_len(input, len).unwrap();
    assert_eq!(reader.next().unwrap().unwrap(), g.nodes[0]);
    assert!(watch.check().is_ok());

    truncate(&path, 64);
    let mut errors = reader.by_ref().filter_map(Result::err);
    let err = errors.next().expect("a read of the truncated file fails");
    assert!(errors.next().is_none());
    let err = watch.check().err().map(|e| (e, err)).expect("the watch saw the truncation");
    assert!(is_truncated(&err.0, &path), "{:?}", err.0);
    // the error is the truncation or what the zeros read before it made of them
    if let GraphError::Io { source, .. } = &err.1 {
        let inner = source.get_ref().and_then(|e| e.downcast_ref::<Truncated>());
        assert!(inner.is_some_and(|t| is_truncated(t, &path)), "{source}");
    }
}

const CHILD: &str = "OCTOLINEAR_SIGBUS_CHILD";

/// Runs this test binary again, only `test`, with `CHILD=what`.
fn child(test: &str, what: &str) -> std::process::ExitStatus {
    Command::new(std::env::current_exe().unwrap())
        .args([test, "--exact", "--test-threads=1", "--nocapture"])
        .env(CHILD, what)
        .output()
        .unwrap()
        .status
}

/// A fault in a mapping the crate did not make, or a `SIGBUS` sent by a
/// process, is not the guard's to handle: it kills the process as before.
#[test]
fn other_sigbus_still_kill() {
    match std::env::var(CHILD).as_deref() {
        Ok("foreign") => {
            mapped::guard_truncated_files().unwrap();
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("other");
            std::fs::write(&path, vec![7u8; 1 << 16]).unwrap();
            let file = std::fs::File::open(&path).unwrap();
            // SAFETY: the file is truncated on purpose: the read below
            // faults and the process is meant to die of it
            let map = unsafe { memmap2::Mmap::map(&file) }.unwrap();
            truncate(&path, 0);
            println!("read {}", std::hint::black_box(&map[1 << 15]));
            std::process::exit(0)
        }
        Ok("sent") => {
            mapped::guard_truncated_files().unwrap();
            // SAFETY: raise has no preconditions
            unsafe { libc::raise(libc::SIGBUS) };
            std::process::exit(0)
        }
        Ok(_) => std::process::exit(3),
        Err(_) => {
            for what in ["foreign", "sent"] {
                let status = child("other_sigbus_still_kill", what);
                assert_eq!(status.signal(), Some(libc::SIGBUS), "{what}: {status:?}");
            }
        }
    }
}

/// A tile file truncated under a tile set's query: the query that read it
/// fails naming the tile file instead of answering from zeros.
#[test]
fn a_truncated_tile_fails_the_query_that_read_it() {
    use octolinear::tiles::{TileSet, TiledMap};
    mapped::guard_truncated_files().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("m.tiles");
    let tree = tree();
    let mut tiles = TiledMap::new(0.05, *tree.sensor(), octolinear::NodeKind::Plain, 4).unwrap();
    let scan: Vec<Point3> = tree
        .leaves(0)
        .filter(|l| tree.is_occupied(l.value))
        .map(|l| l.center())
        .map(|[x, y, z]| Point3::new(x as f32, y as f32, z as f32))
        .collect();
    tiles.insert_point_cloud(&scan, Point3::new(0.0, 0.0, 0.0), &ScanOptions::default()).unwrap();
    let manifest = tiles.flush(&set_dir).unwrap();
    let set = TileSet::open(&set_dir).unwrap();
    let p = scan[0];
    assert!(set.search_point(p, 0).unwrap().is_some());
    let key = set.key_space().key(p).unwrap();
    let tile = manifest.tiles.iter().find(|t| t.id == octolinear::tiles::TileId::of_key(key, 4)).unwrap();
    let path = set_dir.join(tile.id.file_name());
    truncate(&path, 0);
    let err = set.search_point(p, 0).unwrap_err().to_string();
    assert!(err.contains(&*path.to_string_lossy()), "{err}");
}
