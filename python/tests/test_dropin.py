"""octolinear.OcTree against octomap-python's octomap.OcTree (OctoMap 1.10):
the same calls must give the same answers and the same file bytes."""

import numpy as np
import octomap
import pytest
from conftest import random_scan, tree_pair

import octolinear


def value_or_none(node):
    """A node's log-odds, None for a null node (of either module)."""
    try:
        return node.getValue()
    except (octomap.NullPointerException, octolinear.NullPointerException):
        return None


def assert_same_files(theirs, ours):
    assert ours.write() == theirs.write()
    assert ours.writeBinary() == theirs.writeBinary()


@pytest.mark.parametrize("resolution", [0.05, 0.1, 0.37])
@pytest.mark.parametrize("maxrange", [-1.0, 2.0, 5.5])
@pytest.mark.parametrize("discretize", [False, True])
def test_insert_point_cloud_writes_identical_files(resolution, maxrange, discretize):
    rng = np.random.default_rng(int(resolution * 1000) + int(maxrange * 10) + discretize)
    scans = [random_scan(rng, 1500) for _ in range(3)]
    theirs, ours = tree_pair(resolution, scans, maxrange=maxrange, discretize=discretize)
    assert ours.size() == theirs.size()
    assert ours.getNumLeafNodes() == theirs.getNumLeafNodes()
    assert ours.calcNumNodes() == theirs.calcNumNodes()
    assert_same_files(theirs, ours)


def test_lazy_eval_then_update_inner_occupancy(rng):
    scans = [random_scan(rng, 2000) for _ in range(2)]
    theirs, ours = tree_pair(0.1, scans, lazy_eval=True)
    assert ours.write() == theirs.write()
    theirs.updateInnerOccupancy()
    ours.updateInnerOccupancy()
    assert_same_files(theirs, ours)


def test_float32_and_fortran_order_input_match_float64(rng):
    points, origin = random_scan(rng, 2000)
    theirs, _ = tree_pair(0.1, [(points, origin)])
    variants = (
        points.astype(np.float32),
        np.asfortranarray(points),
        np.asfortranarray(points.astype(np.float32)),
        points[:, [0, 1, 2]],
    )
    for variant in variants:
        ours = octolinear.OcTree(0.1)
        ours.insertPointCloud(variant, origin.astype(np.float32))
        assert ours.write() == theirs.write()
    for strided in (np.repeat(points, 2, axis=0)[::2], np.repeat(points.astype(np.float32), 2, axis=0)[::2]):
        ours = octolinear.OcTree(0.1)
        ours.insertPointCloud(strided, list(origin))
        assert ours.write() == theirs.write()
        assert np.array_equal(ours.getLabels(strided), theirs.getLabels(points))


def test_get_labels_and_search(small_pair, rng):
    theirs, ours = small_pair
    queries = rng.uniform(-5, 5, (3000, 3))
    labels = ours.getLabels(queries)
    assert labels.dtype == np.int32
    assert np.array_equal(labels, theirs.getLabels(queries))
    assert set(np.unique(labels)) == {-1, 0, 1}
    # outside the map octomap-python's unchecked coordToKey wraps around
    resolution = ours.getResolution()
    far = queries[:500] + 65536 * resolution * rng.choice([-1.0, 1.0], (500, 3))
    assert np.array_equal(ours.getLabels(far), theirs.getLabels(far))
    assert (ours.getLabels(far) != -1).any()
    for p in queries[:400]:
        for depth in (0, 12, 16):
            a, b = theirs.search(p, depth), ours.search(p, depth)
            try:
                expected = (a.getValue(), a.hasChildren(), theirs.isNodeOccupied(a), theirs.isNodeAtThreshold(a))
            except octomap.NullPointerException:
                expected = None
            if expected is None:
                assert not b
                with pytest.raises(octolinear.NullPointerException):
                    b.getValue()
            else:
                got = (b.getValue(), b.hasChildren(), ours.isNodeOccupied(b), ours.isNodeAtThreshold(b))
                assert got == expected
                assert b.getOccupancy() == a.getOccupancy()


def test_search_by_key_and_key_conversions(small_pair, rng):
    theirs, ours = small_pair
    for p in rng.uniform(-4, 4, (200, 3)):
        ka, kb = theirs.coordToKey(p), ours.coordToKey(p)
        assert tuple(kb) == (ka[0], ka[1], ka[2])
        for depth in (1, 9, 16):
            kad, kbd = theirs.coordToKey(p, depth), ours.coordToKey(p, depth)
            assert (kbd[0], kbd[1], kbd[2]) == (kad[0], kad[1], kad[2])
            assert np.array_equal(ours.keyToCoord(kb, depth), theirs.keyToCoord(ka, depth))
        assert np.array_equal(ours.keyToCoord(kb), theirs.keyToCoord(ka))
        assert value_or_none(ours.search(kb)) == value_or_none(theirs.search(ka))
    ok_a, _ = theirs.coordToKeyChecked(np.array([1e7, 0.0, 0.0]))
    ok_b, key_b = ours.coordToKeyChecked(np.array([1e7, 0.0, 0.0]))
    assert (ok_b, key_b) == (ok_a, None)


@pytest.mark.parametrize("ignore_unknown", [False, True])
@pytest.mark.parametrize("max_range", [-1.0, 1.5])
def test_cast_ray(small_pair, rng, ignore_unknown, max_range):
    theirs, ours = small_pair
    for _ in range(300):
        origin = rng.uniform(-1, 1, 3)
        direction = rng.normal(size=3)
        end_a, end_b = np.full(3, 7.0), np.full(3, 7.0)
        hit_a = theirs.castRay(origin, direction, end_a, ignoreUnknownCells=ignore_unknown, maxRange=max_range)
        hit_b = ours.castRay(origin, direction, end_b, ignoreUnknownCells=ignore_unknown, maxRange=max_range)
        assert hit_b == hit_a
        assert np.array_equal(end_b, end_a)


def test_cast_ray_that_cannot_start_leaves_end_alone(small_pair):
    theirs, ours = small_pair
    for origin, direction in [((1e7, 0, 0), (1, 0, 0)), ((0, 0, 0), (0, 0, 0))]:
        end_a, end_b = np.full(3, 7.0), np.full(3, 7.0)
        assert ours.castRay(np.array(origin, float), np.array(direction, float), end_b) is False
        assert theirs.castRay(np.array(origin, float), np.array(direction, float), end_a) is False
        assert np.array_equal(end_b, end_a)


def test_iterators_list_the_same_nodes(small_pair):
    theirs, ours = small_pair

    def listing(it, with_leaf):
        out = []
        for node in it:
            row = (tuple(node.getCoordinate()), node.getSize(), node.getDepth(), node.getValue(), node.getOccupancy())
            row += (node.getX(), node.getY(), node.getZ(), tuple(node.getKey()[i] for i in range(3)))
            out.append(row + ((node.isLeaf(),) if with_leaf else ()))
        return out

    assert listing(ours.begin_leafs(), False) == listing(theirs.begin_leafs(), False)
    assert listing(ours.begin_leafs(12), False) == listing(theirs.begin_leafs(12), False)
    assert listing(ours.begin_tree(), True) == listing(theirs.begin_tree(), True)
    assert listing(ours.begin_tree(10), True) == listing(theirs.begin_tree(10), True)
    lo, hi = np.array([-1.0, -0.5, -1.2]), np.array([0.7, 1.1, 0.3])
    assert listing(ours.begin_leafs_bbx(lo, hi), False) == listing(theirs.begin_leafs_bbx(lo, hi), False)
    occupied_a, empty_a = theirs.extractPointCloud()
    occupied_b, empty_b = ours.extractPointCloud()
    assert np.array_equal(occupied_b, occupied_a) and np.array_equal(empty_b, empty_a)


def test_iterator_protocol_matches():
    theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
    for t in (theirs, ours):
        t.updateNode(np.array([0.05, 0.05, 0.05]), True)
        t.updateNode(np.array([1.05, 0.05, 0.05]), False)
    it_a, it_b = theirs.begin_leafs(), ours.begin_leafs()
    assert it_b.getDepth() == it_a.getDepth()
    assert np.array_equal(it_b.next().getCoordinate(), it_a.next().getCoordinate())


def test_statistics_and_bounds(small_pair):
    theirs, ours = small_pair
    for name in ("getMetricMin", "getMetricMax", "getMetricSize"):
        assert np.array_equal(getattr(ours, name)(), getattr(theirs, name)()), name
    assert ours.volume() == theirs.volume()
    assert ours.memoryFullGrid() == theirs.memoryFullGrid()
    assert ours.memoryUsageOctoMap() == theirs.memoryUsage()
    assert ours.memoryUsage() < theirs.memoryUsage()
    assert ours.getResolution() == theirs.getResolution()
    assert ours.getTreeDepth() == theirs.getTreeDepth()
    assert ours.getTreeType() == theirs.getTreeType()
    assert ours.memoryUsageNode() == theirs.memoryUsageNode()


def test_update_node_variants(rng):
    theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
    points = rng.uniform(-2, 2, (300, 3))
    for i, p in enumerate(points):
        update = [True, False, 0.3, -1.1, 2][i % 5]
        lazy = i % 7 == 0
        a, b = theirs.updateNode(p, update, lazy), ours.updateNode(p, update, lazy)
        assert b.getValue() == a.getValue()
        key_a, key_b = theirs.coordToKey(p), ours.coordToKey(p)
        assert ours.updateNode(key_b, True).getValue() == theirs.updateNode(key_a, True).getValue()
    theirs.updateNodes(points[:50], False)
    ours.updateNodes(points[:50], False)
    theirs.updateInnerOccupancy()
    ours.updateInnerOccupancy()
    assert_same_files(theirs, ours)


def test_update_node_outside_the_map_gives_a_null_node():
    ours = octolinear.OcTree(0.1)
    node = ours.updateNode(np.array([1e7, 0.0, 0.0]), True)
    assert not node
    with pytest.raises(octolinear.NullPointerException):
        ours.isNodeOccupied(node)


def test_delete_node_and_max_likelihood(small_pair):
    theirs_src, ours_src = small_pair
    theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
    theirs.readBinary(theirs_src.write()[0:0] or theirs_src.writeBinary())
    ours.readBinary(ours_src.writeBinary())
    theirs, ours = octomap.OcTree.read(theirs_src.write()), octolinear.OcTree.read(ours_src.write())
    for p, depth in [((0.05, 0.05, -0.95), 16), ((1.0, 1.0, -1.0), 12), ((-2.0, 0.5, 0.5), 1)]:
        p = np.array(p)
        assert ours.deleteNode(p, depth) == theirs.deleteNode(p, depth)
    assert ours.write() == theirs.write()
    theirs.toMaxLikelihood()
    ours.toMaxLikelihood()
    assert ours.write() == theirs.write()


def test_sensor_model_setters_change_insertion_alike(rng):
    theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
    for setter, value in [
        ("setProbHit", 0.8),
        ("setProbMiss", 0.35),
        ("setClampingThresMin", 0.2),
        ("setClampingThresMax", 0.9),
        ("setOccupancyThres", 0.6),
    ]:
        getattr(theirs, setter)(value)
        getattr(ours, setter)(value)
    for getter in (
        "getProbHit",
        "getProbHitLog",
        "getProbMiss",
        "getProbMissLog",
        "getClampingThresMin",
        "getClampingThresMinLog",
        "getClampingThresMax",
        "getClampingThresMaxLog",
        "getOccupancyThres",
        "getOccupancyThresLog",
    ):
        assert getattr(ours, getter)() == getattr(theirs, getter)(), getter
    for _ in range(3):
        points, origin = random_scan(rng, 2000)
        theirs.insertPointCloud(points, origin)
        ours.insertPointCloud(points, origin)
    queries = rng.uniform(-3, 3, (2000, 3))
    assert np.array_equal(ours.getLabels(queries), theirs.getLabels(queries))
    assert_same_files(theirs, ours)


def test_bounding_box_limit(rng):
    theirs, ours = octomap.OcTree(0.1), octolinear.OcTree(0.1)
    lo, hi = np.array([-1.0, -1.5, -2.0]), np.array([1.2, 0.8, 1.0])
    for t in (theirs, ours):
        t.setBBXMin(lo)
        t.setBBXMax(hi)
        t.useBBXLimit(True)
    for name in ("getBBXMin", "getBBXMax", "getBBXBounds", "getBBXCenter"):
        assert np.array_equal(getattr(ours, name)(), getattr(theirs, name)()), name
    assert ours.bbxSet() == theirs.bbxSet()
    for p in rng.uniform(-2, 2, (50, 3)):
        assert ours.inBBX(p) == theirs.inBBX(p)
    for _ in range(2):
        points, origin = random_scan(rng, 2000)
        theirs.insertPointCloud(points, origin)
        ours.insertPointCloud(points, origin)
    assert_same_files(theirs, ours)


def test_files_round_trip_between_the_two(small_pair, tmp_path):
    theirs, ours = small_pair
    theirs.write(str(tmp_path / "theirs.ot"))
    ours.write(str(tmp_path / "ours.ot"))
    assert (tmp_path / "ours.ot").read_bytes() == (tmp_path / "theirs.ot").read_bytes()
    # bytes names, pathlib names and data given as bytes
    back = octolinear.OcTree.read(str(tmp_path / "theirs.ot").encode())
    assert back.write() == theirs.write()
    assert octolinear.OcTree.read(tmp_path / "theirs.ot").write() == theirs.write()
    assert octolinear.OcTree.read(theirs.write()).write() == theirs.write()
    copy_a, copy_b = octomap.OcTree.read(theirs.write()), octolinear.OcTree.read(ours.write())
    copy_a.writeBinary(str(tmp_path / "theirs.bt").encode())
    assert copy_b.writeBinary(str(tmp_path / "ours.bt")) is True
    assert (tmp_path / "ours.bt").read_bytes() == (tmp_path / "theirs.bt").read_bytes()
    fresh = octolinear.OcTree(0.1)
    assert fresh.readBinary(str(tmp_path / "theirs.bt")) is True
    assert fresh.writeBinary() == copy_a.writeBinary()
    assert octolinear.OcTree(str(tmp_path / "theirs.bt")).writeBinary() == copy_a.writeBinary()
    from_data = octolinear.OcTree(0.1)
    from_data.readBinary(copy_a.writeBinary())
    assert from_data.writeBinary() == copy_a.writeBinary()


def test_write_binary_converts_the_tree_like_octomap(small_pair):
    theirs_src, ours_src = small_pair
    theirs, ours = octomap.OcTree.read(theirs_src.write()), octolinear.OcTree.read(ours_src.write())
    theirs.writeBinary()
    ours.writeBinary()
    assert ours.write() == theirs.write()
    assert ours.size() == theirs.size()


@pytest.mark.parametrize("resolution", [0.2, 0.0537, 1.0 / 3.0])
def test_set_resolution_scales_the_map(small_pair, rng, resolution):
    theirs_src, ours_src = small_pair
    theirs, ours = octomap.OcTree.read(theirs_src.write()), octolinear.OcTree.read(ours_src.write())
    theirs.setResolution(resolution)
    ours.setResolution(resolution)
    assert ours.getResolution() == theirs.getResolution() == resolution
    queries = rng.uniform(-8, 8, (3000, 3))
    assert np.array_equal(ours.getLabels(queries), theirs.getLabels(queries))
    assert np.array_equal(ours.getMetricMax(), theirs.getMetricMax())
    assert_same_files(theirs, ours)
    with pytest.raises(ValueError, match="resolution"):
        ours.setResolution(0.0)


def test_root_and_clear(small_pair):
    theirs_src, ours_src = small_pair
    theirs, ours = octomap.OcTree.read(theirs_src.write()), octolinear.OcTree.read(ours_src.write())
    assert ours.getRoot().getValue() == theirs.getRoot().getValue()
    assert ours.getRoot().hasChildren() == theirs.getRoot().hasChildren()
    theirs.clear()
    ours.clear()
    assert ours.size() == theirs.size() == 0
    assert ours.writeBinary() == theirs.writeBinary()


def test_color_octree_matches(rng):
    theirs, ours = octomap.ColorOcTree(0.1), octolinear.ColorOcTree(0.1)
    points, origin = random_scan(rng, 1500)
    for t in (theirs, ours):
        t.insertPointCloud(points, origin)
    for i, p in enumerate(points[:300]):
        rgb = (i % 256, (3 * i) % 256, (7 * i) % 256)
        method = ("setNodeColor", "averageNodeColor", "integrateNodeColor")[i % 3]
        getattr(theirs, method)(p, *rgb)
        getattr(ours, method)(p, *rgb)
    theirs.updateInnerOccupancy()
    ours.updateInnerOccupancy()
    assert ours.getTreeType() == theirs.getTreeType() == b"ColorOcTree"
    assert ours.write() == theirs.write()
    colors_a = [it.getColor() for it in theirs.begin_leafs()]
    colors_b = [it.getColor() for it in ours.begin_leafs()]
    assert colors_b == colors_a
