"""Shared helpers: random scans, the sample graph, tree pairs built the
same way in octolinear and in octomap-python (the real OctoMap 1.10)."""

import pathlib

import numpy as np
import octomap
import pytest

import octolinear

REPO = pathlib.Path(__file__).resolve().parents[2]
SAMPLE_GRAPH = REPO / "samples" / "indoor.graph"


def random_scan(rng, n, spread=3.0):
    """Points around a room-sized box and an origin near its centre."""
    points = rng.uniform(-spread, spread, (n, 3))
    # a share of points on planes, as walls and floors give
    points[: n // 3, 2] = -1.0
    points[n // 3 : n // 2, 0] = spread * 0.8
    origin = rng.uniform(-0.5, 0.5, 3)
    return points, origin


def tree_pair(resolution, scans, **kwargs):
    """The same scans inserted into an octomap.OcTree and an octolinear.OcTree."""
    theirs, ours = octomap.OcTree(resolution), octolinear.OcTree(resolution)
    for points, origin in scans:
        theirs.insertPointCloud(points, origin, **kwargs)
        ours.insertPointCloud(points, origin, **kwargs)
    return theirs, ours


@pytest.fixture
def rng():
    return np.random.default_rng(20261203)


@pytest.fixture(scope="session")
def small_pair():
    """A pair of trees of three random scans at 0.1 m."""
    rng = np.random.default_rng(7)
    return tree_pair(0.1, [random_scan(rng, 3000) for _ in range(3)], maxrange=4.0)
