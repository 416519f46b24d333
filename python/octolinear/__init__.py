"""octolinear: OctoMap's probabilistic 3D occupancy maps, bit-compatible and fast.

``OcTree`` is a drop-in for octomap-python's ``octomap.OcTree``: the same
method names, argument order and answers, and byte-identical ``.bt`` and
``.ot`` files. Beyond it, array methods answer whole numpy arrays in one
call without the GIL (``OcTree.occupancy``, ``OcTree.cast_rays``,
``OcTree.leaves``), and module functions read and build maps:
``read`` (``.bt``, ``.ot``, ``.olm``), ``open_mapped`` (``.olm`` queried in
place), ``read_graph``, ``build``, ``read_points``. Tile sets, built in
parts by separate processes: ``build_tiles``, ``plan_tiles``,
``write_tile_manifest``, ``convert_tiles``; ``octolinear.dask`` (needs
``dask[distributed]``, imported only when asked for) shares such a build
among a Dask cluster's workers.
"""

from ._octolinear import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    ColorOcTree,
    CountingOcTree,
    MappedOcTree,
    NodeIterator,
    NullPointerException,
    OcTree,
    OcTreeKey,
    OcTreeNode,
    OcTreeStamped,
    build,
    build_tiles,
    convert_tiles,
    get_num_threads,
    open_mapped,
    plan_tiles,
    read,
    read_graph,
    read_points,
    set_num_threads,
    write_tile_manifest,
)

# octomap-python's three iterator classes are one class here
tree_iterator = leaf_iterator = leaf_bbx_iterator = NodeIterator

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "ColorOcTree",
    "CountingOcTree",
    "MappedOcTree",
    "NodeIterator",
    "NullPointerException",
    "OcTree",
    "OcTreeKey",
    "OcTreeNode",
    "OcTreeStamped",
    "build",
    "build_tiles",
    "convert_tiles",
    "get_num_threads",
    "leaf_bbx_iterator",
    "leaf_iterator",
    "open_mapped",
    "plan_tiles",
    "read",
    "read_graph",
    "read_points",
    "set_num_threads",
    "tree_iterator",
    "write_tile_manifest",
]
