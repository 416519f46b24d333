"""Bad input: every mistake is a Python exception with a clear message,
never a crash, and leaves the tree as it was."""

import numpy as np
import pytest
from conftest import SAMPLE_GRAPH, random_scan

import octolinear


@pytest.fixture
def tree(rng):
    t = octolinear.OcTree(0.1)
    t.insertPointCloud(*random_scan(rng, 500))
    return t


@pytest.mark.parametrize(
    "points, error, message",
    [
        (np.zeros((10, 2)), ValueError, r"shape \(N, 3\), got \(10, 2\)"),
        (np.zeros(3), ValueError, r"got \(3,\)"),
        (np.zeros((4, 3, 1)), ValueError, r"got \(4, 3, 1\)"),
        (np.zeros((10, 3), dtype=np.int64), TypeError, "dtype float64 or float32, got int64"),
        (np.zeros((10, 3), dtype=np.float16), TypeError, "got float16"),
        (np.zeros((10, 3), dtype=np.complex128), TypeError, "got complex128"),
        ([["a", "b", "c"]], TypeError, "numpy cannot convert"),
        ("not points", TypeError, "got str that numpy cannot convert"),
        (None, ValueError, r"shape \(N, 3\), got \(\)"),
    ],
)
def test_wrong_point_arrays_are_refused(tree, points, error, message):
    before = tree.write()
    with pytest.raises(error, match=message):
        tree.insertPointCloud(points, np.zeros(3))
    with pytest.raises(error, match=message):
        tree.occupancy(points)
    with pytest.raises(error, match=message):
        tree.getLabels(points)
    assert tree.write() == before


def test_lists_of_points_are_accepted(tree):
    assert tree.getLabels([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]).shape == (2,)


@pytest.mark.parametrize(
    "origin, error",
    [(np.zeros(2), ValueError), ("xyz", TypeError), (None, TypeError), ([0, 0, "a"], TypeError)],
)
def test_wrong_origins_are_refused(tree, origin, error):
    with pytest.raises(error, match="origin"):
        tree.insertPointCloud(np.zeros((3, 3)), origin)


def test_non_finite_points_are_skipped_and_a_non_finite_origin_refused(rng):
    points, origin = random_scan(rng, 1000)
    clean = octolinear.OcTree(0.1)
    clean.insertPointCloud(points, origin)
    dirty = points.copy()
    dirty[::50, 1] = np.nan
    dirty[1::50, 2] = np.inf
    with_nan = octolinear.OcTree(0.1)
    with_nan.insertPointCloud(np.concatenate([points, dirty[::50], dirty[1::50]]), origin)
    assert with_nan.write() == clean.write()
    with pytest.raises(ValueError, match="sensor origin"):
        with_nan.insertPointCloud(points, np.array([np.nan, 0, 0]))
    with pytest.raises(ValueError, match="maxrange is NaN"):
        with_nan.insertPointCloud(points, origin, maxrange=float("nan"))
    assert with_nan.write() == clean.write()


@pytest.mark.parametrize("resolution", [0.0, -0.1, float("nan"), float("inf")])
def test_bad_resolutions_are_refused(resolution):
    with pytest.raises(ValueError, match="resolution"):
        octolinear.OcTree(resolution)
    with pytest.raises(ValueError, match="resolution"):
        octolinear.build(SAMPLE_GRAPH, resolution=resolution)


@pytest.mark.parametrize("resolution", [1e-300, 1e300, 1e-40, 1e40])
def test_resolutions_outside_the_usable_range_are_refused(resolution, tmp_path, tree):
    usable = r"resolution .* m is (below the smallest|above the largest) usable resolution"
    for make in (octolinear.OcTree, octolinear.ColorOcTree, octolinear.OcTreeStamped, octolinear.CountingOcTree):
        with pytest.raises(ValueError, match=usable):
            make(resolution)
    with pytest.raises(ValueError, match=usable):
        octolinear.build(SAMPLE_GRAPH, resolution=resolution)
    with pytest.raises(ValueError, match=usable):
        octolinear.build_tiles(SAMPLE_GRAPH, tmp_path / "t.tiles", resolution=resolution, tile_depth=4)
    with pytest.raises(ValueError, match=usable):
        octolinear.plan_tiles(SAMPLE_GRAPH, resolution=resolution, tile_depth=4, tasks=2)
    before = tree.write()
    with pytest.raises(ValueError, match=usable):
        tree.setResolution(resolution)
    assert tree.getResolution() == 0.1 and tree.write() == before


def chain_cut(depth):
    """The library's `.bt` of one occupied voxel, its chain of single
    children cut to the last `depth` records (and the header's node count
    to theirs): a root whose one child is an occupied leaf at `depth`,
    standing for 8^(16 - depth) voxels."""
    t = octolinear.OcTree(0.1)
    t.updateNode(np.array([0.05, 0.05, 0.05]), True)
    data = t.writeBinary()
    start = data.index(b"\ndata\n") + 6
    assert len(data) == start + 2 * 16
    header = data[:start].replace(b"\nsize 17\n", b"\nsize %d\n" % (depth + 1))
    return header + data[len(data) - 2 * depth :]


def test_outputs_that_grow_with_the_extent_are_counted_and_refused(tmp_path):
    coarse = chain_cut(1)
    assert len(coarse) == 138
    path = tmp_path / "coarse.bt"
    path.write_bytes(coarse)
    t = octolinear.OcTree(str(path))
    assert (t.size(), t.getNumLeafNodes()) == (2, 1)
    points, nodes = 8**15, (8**16 - 8) // 7
    with pytest.raises(MemoryError, match=rf"extractPointCloud: {points} points exceed the limit of 268435456 \(2\^28\).*max_points"):
        t.extractPointCloud()
    with pytest.raises(MemoryError, match=rf"expand: {nodes} nodes to add exceed the limit of 268435456 \(2\^28\).*max_nodes"):
        t.expand()
    with pytest.raises(MemoryError, match="limit of 1000;"):
        t.expand(max_nodes=1000)
    assert (t.size(), t.getNumLeafNodes()) == (2, 1)
    # a leaf at depth 14: 64 voxels, 8 + 64 nodes to add
    fine = octolinear.OcTree(0.1)
    assert fine.readBinary(chain_cut(14))
    with pytest.raises(MemoryError, match="64 points exceed the limit of 63;"):
        fine.extractPointCloud(max_points=63)
    occupied, free = fine.extractPointCloud(max_points=64)
    assert occupied.shape == (64, 3) and free.shape == (0, 3)
    assert np.array_equal(fine.extractPointCloud()[0], occupied)
    with pytest.raises(MemoryError, match="72 nodes to add exceed the limit of 71;"):
        fine.expand(max_nodes=71)
    fine.expand(max_nodes=72)
    assert fine.size() == 15 + 72


def test_bad_arguments(tree):
    with pytest.raises(TypeError, match="OcTree\\(resolution\\)"):
        octolinear.OcTree(True)
    with pytest.raises(ValueError, match="depth 17"):
        tree.search(np.zeros(3), 17)
    with pytest.raises(ValueError, match="depth 20"):
        tree.leaves(max_depth=20)
    with pytest.raises(ValueError, match=r"setProbHit: probability 1.5"):
        tree.setProbHit(1.5)
    with pytest.raises(TypeError, match="update"):
        tree.updateNode(np.zeros(3), "yes")
    with pytest.raises(TypeError, match="OcTreeNode"):
        tree.isNodeOccupied(3)
    with pytest.raises(TypeError):
        tree.castRay(np.zeros(3), np.ones(3), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="bbox min"):
        tree.leaves(bbox=((1e9, 0, 0), (1, 1, 1)))
    with pytest.raises(ValueError, match="3 origins for 2 directions"):
        tree.cast_rays(np.zeros((3, 3)), np.ones((2, 3)))
    with pytest.raises(ValueError, match="max_range"):
        octolinear.build(SAMPLE_GRAPH, max_range=-2.0)
    with pytest.raises(ValueError, match="MissAboveHalf|miss|0.5"):
        octolinear.build(SAMPLE_GRAPH, sensor=(0.7, 0.9))
    with pytest.raises(ValueError, match="at most 1024"):
        octolinear.set_num_threads(5000)
    with pytest.raises(ValueError, match="at least 1"):
        octolinear.build(SAMPLE_GRAPH, threads=0)
    tree.setBBXMin(np.array([-1e9, 0, 0]))
    tree.useBBXLimit(True)
    with pytest.raises(ValueError, match="bounding box"):
        tree.insertPointCloud(np.ones((2, 3)), np.zeros(3))


def test_null_nodes_and_exhausted_iterators_raise(tree):
    node = tree.search(np.array([30.0, 30.0, 30.0]))
    assert not node
    for call in (node.getValue, node.getOccupancy, node.hasChildren, lambda: tree.isNodeOccupied(node)):
        with pytest.raises(octolinear.NullPointerException):
            call()
    it = tree.end_leafs()
    with pytest.raises(octolinear.NullPointerException):
        it.getCoordinate()
    with pytest.raises(StopIteration):
        it.next()
    with pytest.raises(NotImplementedError, match="snapshots"):
        tree.search(tree.leaves()[0].tolist()[:3]).setValue(1.0)


def test_missing_files(tmp_path):
    missing = tmp_path / "missing"
    for call in (
        lambda: octolinear.read(str(missing) + ".bt"),
        lambda: octolinear.read(missing),
        lambda: octolinear.OcTree.read(str(missing) + ".ot"),
        lambda: octolinear.OcTree(str(missing) + ".bt"),
        lambda: octolinear.open_mapped(str(missing) + ".olm"),
        lambda: octolinear.read_graph(str(missing) + ".graph"),
        lambda: octolinear.build(str(missing) + ".graph"),
        lambda: octolinear.read_points(str(missing) + ".ply"),
    ):
        with pytest.raises(FileNotFoundError, match="missing"):
            call()
    with pytest.raises(FileNotFoundError):
        octolinear.OcTree(0.1).write(str(tmp_path / "no" / "dir.ot"))
    with pytest.raises(ValueError, match="unknown map format"):
        octolinear.OcTree(0.1).save(tmp_path / "map.png")
    with pytest.raises(ValueError, match="point cloud format"):
        octolinear.read_points(tmp_path / "cloud.las")
    with pytest.raises(TypeError, match="file name"):
        octolinear.read(42)


def corruptions(data, rng):
    """Truncations at many offsets, flipped bytes and garbage."""
    for cut in sorted({1, 10, 40, 60, 100, len(data) // 2, len(data) - 1} | set(rng.integers(1, len(data), 20))):
        yield data[:cut]
    for at in rng.integers(0, len(data), 60):
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        yield bytes(flipped)
    yield b""
    yield bytes(rng.integers(0, 256, 5000, dtype=np.uint8))


@pytest.mark.parametrize("suffix", [".bt", ".ot", ".olm", ".graph"])
def test_corrupt_files_raise_and_never_crash(tree, tmp_path, rng, suffix):
    path = tmp_path / ("good" + suffix)
    if suffix == ".graph":
        path.write_bytes(SAMPLE_GRAPH.read_bytes())
    else:
        tree.save(path)
    data = path.read_bytes()
    bad = tmp_path / ("bad" + suffix)
    refused = 0
    for corrupt in corruptions(data, rng):
        bad.write_bytes(corrupt)
        try:
            if suffix == ".olm":
                octolinear.open_mapped(bad, verify=True).occupancy(np.zeros((4, 3)))
            elif suffix == ".graph":
                octolinear.read_graph(bad)
            else:
                octolinear.read(bad)
        except (ValueError, OSError) as e:
            assert str(bad) in str(e), str(e)
            refused += 1
    assert refused > 20
    with pytest.raises(ValueError, match=r"byte|offset|ends"):
        octolinear.OcTree.read(tree.write()[:-7])
    with pytest.warns(RuntimeWarning, match="binary map data"):
        assert octolinear.OcTree(0.1).readBinary(tree.writeBinary()[:-3] + b"\xff" * 1) is False


def run_isolated(script, cwd, *args):
    """Runs `script` in a fresh interpreter in `cwd` (away from the source
    package), so that a death by a signal fails the test instead of ending
    pytest."""
    import subprocess
    import sys

    command = [sys.executable, "-c", script, *map(str, args)]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=120)


TRUNCATED_OLM = r"""
import faulthandler, os, sys
import numpy as np
import octolinear
# a handler installed after the module's: opening a map puts the guard back in front
faulthandler.enable()
path = sys.argv[1]
rng = np.random.default_rng(5)
tree = octolinear.OcTree(0.05)
tree.insertPointCloud(rng.uniform(-3, 3, (20000, 3)), np.zeros(3))
tree.save(path)
mapped = octolinear.open_mapped(path)
points = rng.uniform(-3, 3, (20000, 3))
mapped.occupancy(points)
os.truncate(path, 0)
for name, call in [
    ("occupancy", lambda: mapped.occupancy(points)),
    ("leaves", lambda: mapped.leaves()),
    ("search", lambda: mapped.search(points[0])),
    ("size", lambda: mapped.size()),
    ("verify", lambda: mapped.verify()),
    ("to_tree", lambda: mapped.to_tree()),
]:
    try:
        call()
        print(name, "answered")
    except OSError as e:
        print(name, "OSError", e)
print("alive", repr(mapped))
"""


def test_a_mapped_file_truncated_under_queries_raises(tmp_path):
    path = tmp_path / "m.olm"
    done = run_isolated(TRUNCATED_OLM, tmp_path, path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 7 and lines[-1].startswith("alive"), done.stdout
    for line in lines[:-1]:
        assert "OSError" in line and f"{path}: the file was truncated while memory-mapped" in line, line


TRUNCATED_GRAPH = r"""
import os, sys, threading, time
import numpy as np
import octolinear

path, attempts = sys.argv[1], int(sys.argv[2])

def write_graph(path, scans=3, points=200_000):
    rng = np.random.default_rng(3)
    record = np.dtype([("marker", "<i4"), ("xyz", "<f8", 3)])
    with open(path, "wb") as f:
        f.write(np.uint32(scans).tobytes())
        for s in range(scans):
            cloud = np.zeros(points, record)
            cloud["marker"] = 3
            cloud["xyz"] = rng.uniform(-0.3, 0.3, (points, 3)) + [0.5, 0.0, 0.0]
            f.write(np.uint32(points).tobytes() + cloud.tobytes())
            pose = np.zeros(1, [("t", record), ("rm", "<i4"), ("q", "<f8", 4), ("id", "<u4")])
            pose["t"]["marker"], pose["rm"], pose["q"], pose["id"] = 3, 4, [1, 0, 0, 0], s
            f.write(pose.tobytes())
        f.write(np.uint32(0).tobytes())

def truncate_once_mapped(real):
    # waits until build maps the file, then cuts it short
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with open("/proc/self/maps") as maps:
            if real in maps.read():
                os.truncate(real, 8)
                return
        time.sleep(0.0005)

for attempt in range(attempts):
    write_graph(path)
    real = os.path.realpath(path)
    cutter = threading.Thread(target=truncate_once_mapped, args=(real,))
    cutter.start()
    try:
        octolinear.build(path, resolution=0.1, threads=1)
        outcome = "built"
    except OSError as e:
        outcome = "OSError " + str(e)
    cutter.join()
    print(outcome, flush=True)
    if outcome.startswith("OSError"):
        break
"""


def test_a_graph_truncated_during_build_raises(tmp_path):
    path = tmp_path / "scans.graph"
    done = run_isolated(TRUNCATED_GRAPH, tmp_path, path, 5)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    # the build may finish before the cut; it never reports anything but the truncation
    assert lines and all(line == "built" for line in lines[:-1]), done.stdout
    assert lines[-1] == f"OSError {path}: the file was truncated while memory-mapped " \
        "(replace files by renaming a new file over them, never in place)", done.stdout


def test_read_binary_and_read_fail_as_octomap_python(tree, tmp_path):
    import octomap

    bad_ot, bad_bt, missing = tmp_path / "bad.ot", tmp_path / "bad.bt", tmp_path / "missing.bt"
    bad_ot.write_bytes(b"garbage")
    bad_bt.write_bytes(b"garbage")
    data = tree.writeBinary()
    for arg in (b"", "", str(missing).encode(), str(missing), bad_bt, data[:20], data[: len(data) // 2]):
        theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
        ours.updateNode([1.0, 1.0, 1.0], True)
        before = ours.write()
        with pytest.warns(RuntimeWarning, match="readBinary"):
            assert ours.readBinary(arg) is False
        assert theirs.readBinary(arg) is False, arg
        assert ours.write() == before, "a failed read leaves the tree as it was"
    for arg in (bad_ot, str(bad_ot).encode()):
        with pytest.raises(OSError, match="failed to read OcTree from"):
            octomap.OcTree.read(arg)
        with pytest.raises(OSError, match=f"failed to read OcTree from '{bad_ot}'"):
            octolinear.OcTree.read(arg)
    for arg in (b"", str(tmp_path / "missing.ot")):
        with pytest.raises(FileNotFoundError):
            octomap.OcTree.read(arg)
        with pytest.raises(FileNotFoundError):
            octolinear.OcTree.read(arg)
    with pytest.raises(TypeError, match="file name"):
        octolinear.OcTree(0.1).readBinary(42)


def test_get_color_needs_a_color_tree_iterator(tree):
    import octomap

    theirs = octomap.OcTree(0.1)
    theirs.updateNode(np.array([1.0, 1.0, 1.0]), True)
    for ours_it, theirs_it in ((tree.begin_leafs(), theirs.begin_leafs()), (tree.begin_tree(), theirs.begin_tree())):
        with pytest.raises(TypeError, match="only available on ColorOcTree iterators"):
            next(iter(theirs_it)).getColor()
        with pytest.raises(TypeError, match="only available on ColorOcTree iterators"):
            next(iter(ours_it)).getColor()
    color = octolinear.ColorOcTree(0.1)
    color.updateNode([1.0, 1.0, 1.0], True)
    assert next(iter(color.begin_leafs())).getColor() == (255, 255, 255)


@pytest.mark.parametrize("corner", [0, 1])
def test_nan_boxes_raise_in_both_box_queries(tree, corner):
    box = [np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])]
    box[corner][1] = np.nan
    with pytest.raises(ValueError, match="bbox (min|max).*NaN") as leaves:
        tree.leaves(bbox=tuple(box))
    with pytest.raises(ValueError) as iterated:
        tree.begin_leafs_bbx(*box)
    assert str(iterated.value) == str(leaves.value)
    # a corner merely outside the map still gives an empty iteration, as in OctoMap
    assert list(tree.begin_leafs_bbx(np.array([-1e9, 0.0, 0.0]), np.array([1.0, 1.0, 1.0]))) == []
